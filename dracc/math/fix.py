"""The position fix from the navigator's observations: build, solve, assess.

Over :mod:`dracc.math.fusion` (LS (W1) / WLS (W4), seeds/004; DOP in the trace form,
METHODS §5).  Holds the library observations built from checked observations
(:class:`MeasuredObservation`, e.g. :class:`dracc.ingest.observations.ObsSpec`), the
multi-start solver (:func:`solve`: the default prior and a ring of starts, since two
circles cross twice), the residual statistics (Baarda's w, the chi-square verdict) and
the result :class:`FixReport`.  The solution is in radians and metres; residuals are in
the unit each observation is shown in (metres, or degrees for bearings and nadir angles).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Literal, Protocol

import numpy as np
from numpy.typing import ArrayLike

from dracc.core.distributions import chi2_ppf
from dracc.core.errors import FixUsageError, GeometryError
from dracc.core.geodesy import (
    add_offset_ne,
    circmean,
    distance_m,
    radius_meridian_m,
    radius_prime_vertical_m,
    wrap_pi,
)
from dracc.core.units import NMI_M
from dracc.math.fusion import (
    BearingLOP,
    FixSolution,
    LineLOP,
    NadirCircle,
    Observation,
    PierLine,
    PositionFix,
    RangeLOP,
    abeam_line,
    fuse_fix,
    stack_rows,
    to_metres,
)

# ----------------------------------------------------------------------- observations


class MeasuredObservation(Protocol):
    """A checked observation in degrees and metres (see dracc.ingest.observations.ObsSpec)."""

    @property
    def kind(self) -> str: ...
    @property
    def label(self) -> str: ...
    @property
    def source(self) -> str: ...
    @property
    def text(self) -> str | None: ...
    @property
    def unit(self) -> str: ...
    @property
    def sigma(self) -> float: ...
    @property
    def sigma_default(self) -> bool: ...
    @property
    def points_deg(self) -> tuple[tuple[float, float], ...]: ...
    @property
    def values(self) -> dict[str, float]: ...
    @property
    def side(self) -> str | None: ...


@dataclass(frozen=True)
class FixObservation:
    """One observation and the library object built from it.

    ``unit``: ``"m"`` or ``"deg"``, the unit its residual is shown in; ``sigma``: its
    standard deviation in that unit; ``sigma_default``: True when no sigma was given;
    ``points_deg``: the charted points it names (for the default prior); ``scale_m``: a
    characteristic distance (range, or the circle's radius) for the search for other
    solutions.
    """

    label: str
    source: str
    obs: Observation
    unit: str
    sigma: float
    sigma_default: bool
    points_deg: tuple[tuple[float, float], ...]
    scale_m: float | None = None
    is_fix: bool = False


def _rad(deg: float) -> float:
    return math.radians(deg)


def _library_object(m: MeasuredObservation, piers: Sequence[PierLine]) -> Observation:
    (lat, lon), v = m.points_deg[0], m.values
    if m.kind == "fix":
        return PositionFix.from_sigma(_rad(lat), _rad(lon), m.sigma)
    if m.kind == "range":
        return RangeLOP(_rad(lat), _rad(lon), v["dist_m"], m.sigma)
    if m.kind in ("bearing", "bearing_from_mark"):
        at: Literal["ship", "mark"] = "mark" if m.kind == "bearing_from_mark" else "ship"
        brg = _rad(v["bearing_deg"]) % (2 * math.pi)
        return BearingLOP(_rad(lat), _rad(lon), brg, _rad(m.sigma), observed_at=at)
    if m.kind in ("line", "pier"):
        (a_lat, a_lon), (b_lat, b_lon) = m.points_deg  # the ends A and B
        ends = (_rad(a_lat), _rad(a_lon), _rad(b_lat), _rad(b_lon))
    if m.kind == "line":
        return LineLOP(*ends, m.sigma, v["offset_m"])
    if m.kind == "pier":
        return PierLine(
            *ends,
            _rad(v["heading_deg"]) % (2 * math.pi),
            m.side,  # type: ignore[arg-type]  # str | None; ObsSpec checks port/starboard
            v["half_breadth_m"],
            m.sigma,
            ref_transverse_m=v["ref_stbd_m"],
            gap_m=v["gap_m"],
        )
    if m.kind == "abeam":
        return abeam_line(piers[0], _rad(lat), _rad(lon), m.sigma)
    if m.kind == "nadir":
        return NadirCircle(_rad(lat), _rad(lon), _rad(v["nadir_deg"]), _rad(m.sigma))
    raise AssertionError(m.kind)  # pragma: no cover - kinds come from the parser


def library_observation(m: MeasuredObservation, piers: Sequence[PierLine]) -> FixObservation:
    """The library observation (radians, metres); ``piers``: the pier lines built so far."""
    try:
        obs = _library_object(m, piers)
    except GeometryError as e:  # the library refuses the observation (e.g. a pier misaligned)
        raise GeometryError(
            f"{m.source} {m.text!r}: {e}" if m.text else f"{m.source}: {e}"
        ) from None
    scale_m = None
    if m.kind == "range":
        scale_m = m.values["dist_m"]
    elif m.kind == "nadir":
        lat = _rad(m.points_deg[0][0])
        r_m = float(np.sqrt(radius_meridian_m(lat) * radius_prime_vertical_m(lat)))
        scale_m = r_m * _rad(m.values["nadir_deg"])  # the circle's radius on the Gaussian sphere
    return FixObservation(
        m.label,
        m.source,
        obs,
        m.unit,
        m.sigma,
        m.sigma_default,
        m.points_deg,
        scale_m,
        is_fix=m.kind == "fix",
    )


def fix_observations(measured: Iterable[MeasuredObservation]) -> list[FixObservation]:
    """Each observation built in turn (a lazy ``measured`` is checked one by one)."""
    built: list[FixObservation] = []
    for m in measured:
        piers = [s.obs for s in built if isinstance(s.obs, PierLine)]
        built.append(library_observation(m, piers))
    return built


# ----------------------------------------------------------------- residual statistics


def standardised_residuals(
    psi: ArrayLike, r_m2: ArrayLike, z: np.ndarray, weighted: bool
) -> np.ndarray:
    """Baarda's w statistic of each row: ``w_i = v_i / sqrt(C_v,ii)`` (NaN where C_v,ii ~ 0).

    Rows in metres (``Psi`` (k, 2) unit rows, ``R`` (k, k), post-fit residuals ``v``).
    ``H = Psi (Psi^T W Psi)^-1 Psi^T W`` with ``W = R^-1`` (WLS, W4) or ``I`` (LS, W1);
    ``v = (I - H) z`` so ``C_v = (I - H) R (I - H)^T`` (for WLS: ``R - Psi P Psi^T``).
    Under the sigmas each w is N(0, 1); the largest |w| names the likeliest blunder.
    """
    psi = np.asarray(psi, float)
    r_m2 = np.asarray(r_m2, float)
    w_mat = np.linalg.inv(r_m2) if weighted else np.eye(len(z))
    h = psi @ np.linalg.solve(psi.T @ w_mat @ psi, psi.T @ w_mat)
    i_h = np.eye(len(z)) - h
    c_v = i_h @ r_m2 @ i_h.T
    var = np.diag(c_v)
    tiny = 1e-9 * np.diag(r_m2)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(var > tiny, np.asarray(z, float) / np.sqrt(np.maximum(var, tiny)), np.nan)


@dataclass(frozen=True)
class ResidualRow:
    """One measurement row after the fit: residual (measured - fitted) in its own unit."""

    label: str
    row: str
    unit: str
    residual: float
    residual_m: float
    sigma: float
    sigma_default: bool
    normalised: float
    w: float


@dataclass(frozen=True)
class FixReport:
    """A fused fix with everything the table and the JSON show (the prior in degrees)."""

    solution: FixSolution
    observations: tuple[FixObservation, ...]
    residuals: tuple[ResidualRow, ...]
    prior_lat_deg: float
    prior_lon_deg: float
    prior_source: str
    chi2_bound_95: float | None
    consistent: bool | None
    verdict: str


def residual_rows(specs: Sequence[FixObservation], sol: FixSolution) -> tuple[ResidualRow, ...]:
    """One row per measurement row (a fix has two), in solving order."""
    metres = to_metres(stack_rows([s.obs for s in specs], sol.lat_rad, sol.lon_rad))
    w = standardised_residuals(metres.g, metres.cov, metres.residual, sol.weighted)
    rows: list[ResidualRow] = []
    i = 0
    for spec in specs:
        native = spec.obs.linearise(sol.lat_rad, sol.lon_rad)
        for j, kind in enumerate(native.kinds):
            value = float(native.residual[j])
            sigma_native = float(np.sqrt(native.cov[j, j]))
            if spec.unit == "deg":
                value, sigma_native = math.degrees(value), math.degrees(sigma_native)
            row = {"fix_north": "north", "fix_east": "east"}.get(kind, kind)
            rows.append(
                ResidualRow(
                    spec.label,
                    row,
                    spec.unit,
                    value,
                    float(metres.residual[i]),
                    sigma_native,
                    spec.sigma_default,
                    value / sigma_native,
                    float(w[i]),
                )
            )
            i += 1
    return tuple(rows)


def verdict(sol: FixSolution, rows: Sequence[ResidualRow]) -> tuple[float | None, bool | None, str]:
    """(the 95 % chi-square bound, consistent, the verdict line); None with no redundancy."""
    if sol.redundancy == 0:
        return (
            None,
            None,
            "no redundancy: the fix passes exactly through the observations, "
            "so they cannot be checked against each other",
        )
    bound = float(chi2_ppf(0.95, sol.redundancy))
    if sol.chi2 <= bound:
        return (
            bound,
            True,
            f"residuals consistent with the sigmas (chi-square {sol.chi2:.2f} "
            f"<= {bound:.2f}, the 95 % bound for {sol.redundancy} degree(s) of freedom)",
        )
    ranked = sorted((r for r in rows if math.isfinite(r.w)), key=lambda r: -abs(r.w))
    head = (
        f"chi-square {sol.chi2:.2f} > {bound:.2f} (95 % bound, {sol.redundancy} degree(s) of "
        "freedom)"
    )
    if ranked and (len(ranked) == 1 or abs(ranked[0].w) > 1.01 * abs(ranked[1].w)):
        top = ranked[0]
        what = (
            top.label
            if top.row in ("range", "bearing", "line", "pier", "nadir")
            else f"{top.label} ({top.row})"
        )
        return (
            bound,
            False,
            f"an observation disagrees: {what}, residual {top.residual:+.3g} "
            f"{top.unit} (w = {top.w:+.1f}); {head}; check it or its sigma",
        )
    return (
        bound,
        False,
        f"the observations disagree: {head}; with so little redundancy the "
        "culprit cannot be told apart; check them or their sigmas",
    )


# ---------------------------------------------------------------------------- solving


def format_dm(value_deg: float, axis: str, decimals: int = 3) -> str:
    """Degrees and decimal minutes: ``54°36.500'N``, ``018°48.200'E``."""
    hemi = ("N" if value_deg >= 0 else "S") if axis == "lat" else ("E" if value_deg >= 0 else "W")
    a = abs(value_deg)
    deg = int(a)
    minutes = round((a - deg) * 60.0, decimals)
    if minutes >= 60.0:
        deg, minutes = deg + 1, 0.0
    width = 2 if axis == "lat" else 3
    return f"{deg:0{width}d}°{minutes:0{decimals + 3}.{decimals}f}'{hemi}"


def default_prior_deg(specs: Sequence[FixObservation]) -> tuple[float, float]:
    """Mean of the fixes if any, else of the charted marks and line ends (lon on the circle)."""
    fixes = [pt for s in specs if s.is_fix for pt in s.points_deg]
    pts = fixes or [pt for s in specs for pt in s.points_deg]
    lat = float(np.mean([p[0] for p in pts]))
    lon = math.degrees(float(wrap_pi(circmean(np.radians([p[1] for p in pts])))))
    return lat, lon


def solve(
    specs: Sequence[FixObservation], prior_deg: tuple[float, float] | None, weighted: bool
) -> tuple[FixSolution, float, float, str]:
    """Fuse; with no prior, search for other solutions (two circles cross twice).

    Without ``--prior`` the fix is iterated from the default prior and from eight points
    around it (at the observations' own scale, 100 m to 50 km); converged solutions more
    than 1 m apart whose chi-square passes its 99.9 % bound (any, with no redundancy) are
    all candidates: more than one raises :class:`GeometryError` naming them.
    Returns the solution, the prior (degrees) and where the prior came from.
    """
    obs = [s.obs for s in specs]
    if not obs:
        raise FixUsageError(
            "dracc fix: no observations; give --fix, --range, --bearing, --line, "
            "--pier, --nadir or --file"
        )
    if prior_deg is not None:
        lat, lon = prior_deg
        sol = fuse_fix(obs, _rad(lat), _rad(lon), weighted=weighted)
        return _near(sol, specs, lat, lon), lat, lon, "given"
    if all(isinstance(s.obs, NadirCircle) for s in specs):
        raise FixUsageError(
            "dracc fix: nadir circles are thousands of km wide; give --prior LAT,LON "
            "(the DR position) to choose the intersection"
        )
    lat0, lon0 = default_prior_deg(specs)
    scales = [s.scale_m for s in specs if s.scale_m is not None]
    scales += [
        float(distance_m(_rad(lat0), _rad(lon0), _rad(p[0]), _rad(p[1])))
        for s in specs
        for p in s.points_deg
    ]
    ring_m = float(np.clip(np.median(scales) if scales else 100.0, 100.0, 50_000.0))
    starts = [(_rad(lat0), _rad(lon0))]
    for az in np.radians(np.arange(0.0, 360.0, 45.0) + 22.5):
        la, lo = add_offset_ne(_rad(lat0), _rad(lon0), ring_m * math.cos(az), ring_m * math.sin(az))
        starts.append((float(la), float(lo)))
    found: list[FixSolution] = []
    first_error: GeometryError | None = None
    for la, lo in starts:
        try:
            sol = fuse_fix(obs, la, lo, weighted=weighted)
        except GeometryError as e:
            first_error = first_error or e
            continue
        if all(distance_m(sol.lat_rad, sol.lon_rad, f.lat_rad, f.lon_rad) > 1.0 for f in found):
            found.append(sol)
    if not found:
        assert first_error is not None
        raise first_error
    redundancy = found[0].redundancy
    bound = float(chi2_ppf(0.999, redundancy)) if redundancy > 0 else math.inf
    good = [s for s in found if s.chi2 <= bound or redundancy == 0]
    if len(good) > 1:
        cands = "; ".join(
            f"{format_dm(math.degrees(s.lat_rad), 'lat')} "
            f"{format_dm(math.degrees(s.lon_rad), 'lon')}"
            for s in good[:4]
        )
        raise GeometryError(
            f"the observations fit {len(good)} positions ({cands}); give --prior "
            "LAT,LON near the ship (e.g. the DR position) to choose one"
        )
    best = good[0] if good else min(found, key=lambda s: s.chi2)
    return (
        _near(best, specs, lat0, lon0),
        lat0,
        lon0,
        "mean of the fixes" if any(s.is_fix for s in specs) else "mean of the marks",
    )


def _near(
    sol: FixSolution, specs: Sequence[FixObservation], lat_deg: float, lon_deg: float
) -> FixSolution:
    """Refuse a solution far beyond the observations' own scale (nearly parallel lines).

    Straight lines of position are great circles: two "parallel" transits (e.g. two
    meridians) meet thousands of km away, with an enormous DOP.  A solution more than
    max(100 km, 10 x the largest range or circle radius) from the prior is no fix.
    """
    limit_m = max([100_000.0] + [10.0 * s.scale_m for s in specs if s.scale_m is not None])
    d_m = float(distance_m(_rad(lat_deg), _rad(lon_deg), sol.lat_rad, sol.lon_rad))
    if d_m > limit_m:
        raise GeometryError(
            f"the lines of position meet {d_m / NMI_M:,.0f} nmi from the prior "
            f"(DOP {float(sol.dop):,.0f}): they are nearly parallel (or the prior is far off); no fix"
        )
    return sol


def fix_report(
    measured: Iterable[MeasuredObservation], prior_deg: tuple[float, float] | None, weighted: bool
) -> FixReport:
    """Build, solve and assess: residual rows, Baarda w, chi-square verdict."""
    specs = fix_observations(measured)
    sol, plat, plon, psrc = solve(specs, prior_deg, weighted)
    rows = residual_rows(specs, sol)
    bound, consistent, line = verdict(sol, rows)
    return FixReport(sol, tuple(specs), rows, plat, plon, psrc, bound, consistent, line)


__all__ = [
    "FixObservation",
    "FixReport",
    "MeasuredObservation",
    "ResidualRow",
    "default_prior_deg",
    "fix_observations",
    "fix_report",
    "format_dm",
    "library_observation",
    "residual_rows",
    "solve",
    "standardised_residuals",
    "verdict",
]
