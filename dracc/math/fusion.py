"""Fix fusion: position fixes and lines of position by (weighted) least squares.

Sources: the pier-line fusion fragment (seeds/004, equations W1-W4) and the
free-gyro positioning paper (seeds/002, the nadir circle (1) and the DOP (37)-(38),
corrected in METHODS §5 to the conventional trace form).

The unknown is the ship's position, solved as a north/east correction ``dx`` (metres)
about a linearisation point (the prior), iterated (Gauss-Newton) until the step is
below a millimetre::

    z   = u - f(x)                       generalised measurement vector (W2 text)
    G   = df/dx                          Jacobian, one row per scalar measurement (W2)
    dx  = (G^T G)^-1 G^T z               least squares, LS (W1)
    dx  = (G^T R^-1 G)^-1 G^T R^-1 z     weighted least squares, WLS (W4)
    P   = (G^T R^-1 G)^-1                covariance of the WLS position (W3)

Rows are brought to metres across the line of position before LS: a bearing row
(rad per metre) is divided by its gradient norm, so that the unweighted LS (W1)
compares like with like, and the cofactor matrix ``Q = (Psi^T Psi)^-1`` of the unit
rows ``Psi`` is a pure geometry factor (seeds/002 (35)-(36)).  DOP is
``sqrt(q_nn + q_ee)`` (METHODS §5: the paper's (37) squares the diagonal elements,
which is dimensionally wrong; the trace form makes ``rms = DOP * sigma`` (38) hold).

Observations (frozen dataclasses; radians and metres):

``PositionFix``   a full fix with its 2x2 north/east covariance (2 rows)
``RangeLOP``      a range circle about a known mark (radar, DME)
``BearingLOP``    a bearing line: of the mark from the ship (visual, radar) or of the
                  ship from the mark (D/F station, VOR)
``LineLOP``       a straight line through two WGS-84 points, with a signed offset
``PierLine``      a pier line shifted by the vector from the ship's reference point
                  to her side (seeds/004, Figure 1): a ``LineLOP`` with an offset
``NadirCircle``   the free-gyro nadir circle (seeds/002 (1)): a circle of angular
                  radius theta about the sub-point of the gyro spin axis

Every observation has ``linearise(lat_rad, lon_rad) -> Rows``; the position may be an
array (a leading batch axis), which the Kalman filter of :mod:`dracc.math.current` uses.

Distances and azimuths between the ship and a mark come from the chord between the
two points on the WGS-84 ellipsoid (ECEF): the azimuth is that of the normal section
(differs from the geodesic azimuth by < 2e-7 rad at 100 km), the distance is the arc
of the chord on the local Gaussian sphere (differs from the geodesic by < 1 cm at
100 km, < 0.1 mm at 20 km).  Both are checked against GeographicLib in the tests.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal, cast

import numpy as np

from dracc.core.arrays import ArrayLike, FloatArray
from dracc.core.errors import GeometryError
from dracc.core.geodesy import (
    add_offset_ne,
    angdiff,
    ecef_m,
    k_lambda,
    k_phi,
    offset_ne_m,
    range_azimuth,
    wrap_2pi,
)
from dracc.math.ellipse import Ellipse, error_ellipse

OMEGA_E_RADPS = 7.292115e-5  #: WGS-84 Earth rotation rate (seeds/002 (1): omega_e)


# ------------------------------------------------------------------ rows


@dataclass(frozen=True)
class Rows:
    """Linearised measurement rows at a position (leading batch axes ``...``).

    ``g`` (..., k, 2): d(measurement)/d(north_m, east_m); ``residual`` (..., k):
    measured minus predicted; ``cov`` (..., k, k): measurement covariance; all in the
    measurement's own unit (m or rad).  ``kinds``: one label per row.
    """

    g: FloatArray
    residual: FloatArray
    cov: FloatArray
    kinds: tuple[str, ...]


def _rows(g: ArrayLike, residual: ArrayLike, var: ArrayLike, kind: str) -> Rows:
    g = np.asarray(g, float)
    residual = np.asarray(residual, float)
    var = np.broadcast_to(np.asarray(var, float), residual.shape)
    return Rows(g[..., None, :], residual[..., None], var[..., None, None], (kind,))


def _positive(name: str, value: ArrayLike) -> None:
    v = np.asarray(value, float)
    if not np.all(np.isfinite(v)) or np.any(v <= 0):
        raise GeometryError(f"{name} must be finite and > 0, got {value!r}")


# ---------------------------------------------------------------- observations


@dataclass(frozen=True)
class PositionFix:
    """A full position fix with its north/east covariance ``cov_m2`` (2x2, m^2)."""

    lat_rad: float | FloatArray
    lon_rad: float | FloatArray
    cov_m2: FloatArray

    def __post_init__(self) -> None:
        cov = np.asarray(self.cov_m2, float)
        if cov.shape[-2:] != (2, 2) or np.any(np.linalg.eigvalsh(cov) <= 0):
            raise GeometryError(
                f"PositionFix covariance must be 2x2 positive definite, got {self.cov_m2!r}"
            )
        object.__setattr__(self, "cov_m2", cov)

    @classmethod
    def from_sigma(
        cls, lat_rad: float | FloatArray, lon_rad: float | FloatArray, sigma_m: float
    ) -> PositionFix:
        """A fix with sigma_m per axis (circular)."""
        _positive("PositionFix sigma_m", sigma_m)
        return cls(lat_rad, lon_rad, np.eye(2) * sigma_m**2)

    def linearise(self, lat_rad: ArrayLike, lon_rad: ArrayLike) -> Rows:
        n_m, e_m = offset_ne_m(self.lat_rad, self.lon_rad, lat_rad, lon_rad)
        residual = np.stack(np.broadcast_arrays(n_m, e_m), axis=-1)
        g = np.broadcast_to(np.eye(2), residual.shape[:-1] + (2, 2))
        cov = np.broadcast_to(self.cov_m2, residual.shape[:-1] + (2, 2))
        return Rows(g, residual, cov, ("fix_north", "fix_east"))


@dataclass(frozen=True)
class RangeLOP:
    """A range circle: the ship is ``range_m`` (sigma ``sigma_m``) from a known mark."""

    mark_lat_rad: float
    mark_lon_rad: float
    range_m: float | FloatArray
    sigma_m: float

    def __post_init__(self) -> None:
        _positive("RangeLOP sigma_m", self.sigma_m)
        if np.any(np.asarray(self.range_m) < 0):
            raise GeometryError(f"RangeLOP range_m must be >= 0, got {self.range_m!r}")

    def linearise(self, lat_rad: ArrayLike, lon_rad: ArrayLike) -> Rows:
        dist, az_ship_to_mark = range_azimuth(
            lat_rad, lon_rad, self.mark_lat_rad, self.mark_lon_rad
        )
        # d(range)/d(N, E): unit vector from the mark towards the ship, at the ship
        g = -np.stack([np.cos(az_ship_to_mark), np.sin(az_ship_to_mark)], axis=-1)
        return _rows(g, self.range_m - dist, self.sigma_m**2, "range")


@dataclass(frozen=True)
class BearingLOP:
    """A bearing line (true bearing, radians).

    ``observed_at="ship"``: the bearing of the mark taken from the ship (visual, radar);
    ``observed_at="mark"``: the bearing of the ship taken at the mark (D/F, VOR).
    """

    mark_lat_rad: float
    mark_lon_rad: float
    bearing_rad: float | FloatArray
    sigma_rad: float
    observed_at: Literal["ship", "mark"] = "ship"

    def __post_init__(self) -> None:
        _positive("BearingLOP sigma_rad", self.sigma_rad)
        if self.observed_at not in ("ship", "mark"):
            raise GeometryError(
                f"BearingLOP observed_at must be 'ship' or 'mark', got {self.observed_at!r}"
            )

    def linearise(self, lat_rad: ArrayLike, lon_rad: ArrayLike) -> Rows:
        dist, az_sm = range_azimuth(lat_rad, lon_rad, self.mark_lat_rad, self.mark_lon_rad)
        if np.any(dist < 1.0):
            raise GeometryError("BearingLOP: the ship is on the mark; a bearing is undefined there")
        if self.observed_at == "ship":
            predicted = az_sm
            # d(az ship->mark)/d(N, E) = (sin az, -cos az) / d, plus the meridian
            # convergence: moving east turns the ship's north by sin(phi) d(lambda)
            conv = np.sin(np.asarray(lat_rad, float)) * k_lambda(np.asarray(lat_rad, float))
            g = np.stack([np.sin(az_sm) / dist, -np.cos(az_sm) / dist + conv], axis=-1)
        else:
            _, predicted = range_azimuth(self.mark_lat_rad, self.mark_lon_rad, lat_rad, lon_rad)
            away = az_sm + np.pi  # direction from the mark through the ship, at the ship
            g = np.stack([-np.sin(away), np.cos(away)], axis=-1) / dist[..., None]
        return _rows(g, angdiff(self.bearing_rad, predicted), self.sigma_rad**2, "bearing")


@dataclass(frozen=True)
class LineLOP:
    """A straight line of position through A and B (WGS-84).

    The ship lies ``offset_m`` to the right of the directed line A->B (negative: to the
    left), with standard deviation ``sigma_m`` across the line.  The line is the section
    of the ellipsoid by the plane through the Earth's centre, A and B (within a
    millimetre of the geodesic for lines of a few km); the distance is measured from
    that plane (equal to the distance on the surface within d^3/6R^2).
    """

    a_lat_rad: float
    a_lon_rad: float
    b_lat_rad: float
    b_lon_rad: float
    sigma_m: float
    offset_m: float | FloatArray = 0.0

    def __post_init__(self) -> None:
        _positive("LineLOP sigma_m", self.sigma_m)
        n, e = self._b_ne()
        if np.hypot(n, e) < 1.0:
            raise GeometryError(
                "LineLOP: points A and B are less than 1 m apart; the line has no direction"
            )

    def _mid(self) -> tuple[float, float]:
        return 0.5 * (self.a_lat_rad + self.b_lat_rad), self.a_lon_rad + 0.5 * float(
            angdiff(self.b_lon_rad, self.a_lon_rad)
        )

    def _b_ne(self) -> tuple[float, float]:
        return offset_ne_m(self.b_lat_rad, self.b_lon_rad, self.a_lat_rad, self.a_lon_rad)

    @property
    def azimuth_rad(self) -> float:
        """Azimuth of the directed line A->B in the local plane, [0, 2pi)."""
        n, e = self._b_ne()
        return float(wrap_2pi(np.arctan2(e, n)))

    def linearise(self, lat_rad: ArrayLike, lon_rad: ArrayLike) -> Rows:
        # right-hand unit normal of the plane through the Earth's centre, A and B
        normal = np.cross(
            ecef_m(self.b_lat_rad, self.b_lon_rad), ecef_m(self.a_lat_rad, self.a_lon_rad)
        )
        normal = normal / np.linalg.norm(normal)
        distance = ecef_m(lat_rad, lon_rad) @ normal  # signed distance from the plane, right +
        lat = np.asarray(lat_rad, float)
        lon = np.asarray(lon_rad, float)
        north = np.stack(
            [-np.sin(lat) * np.cos(lon), -np.sin(lat) * np.sin(lon), np.cos(lat)], axis=-1
        )
        east = np.stack([-np.sin(lon), np.cos(lon), np.zeros_like(lon)], axis=-1)
        g = np.stack([north @ normal, east @ normal], axis=-1)
        return _rows(g, self.offset_m - distance, self.sigma_m**2, "line")


@dataclass(frozen=True)
class PierLine:
    """A pier line A->B with the ship lying alongside (seeds/004, Figure 1).

    The ship's conventional reference point (to which all measurements are brought) is
    ``ref_transverse_m`` to starboard of the centreline (negative: to port).  Her side
    touching the pier (``side``) is ``half_breadth_m`` from the centreline, plus a
    ``gap_m`` (fenders) to the pier line.  With heading H and the line azimuth alpha,
    the vector from the contact point on the pier line to the reference point is
    ``(y_ref - y_side) * (-sin H, cos H)`` (y to starboard), whose component across the
    line is ``(y_ref - y_side) * cos(H - alpha)``: the offset of the shifted line.
    ``sigma_m`` covers the charted pier line, the gap and the ship's offsets.
    """

    a_lat_rad: float
    a_lon_rad: float
    b_lat_rad: float
    b_lon_rad: float
    heading_rad: float
    side: Literal["port", "starboard"]
    half_breadth_m: float
    sigma_m: float
    ref_transverse_m: float = 0.0
    gap_m: float = 0.0
    max_misalignment_rad: float = np.deg2rad(15.0)

    def __post_init__(self) -> None:
        if self.side not in ("port", "starboard"):
            raise GeometryError(f"PierLine side must be 'port' or 'starboard', got {self.side!r}")
        if self.half_breadth_m <= 0 or self.gap_m < 0:
            raise GeometryError(
                f"PierLine needs half_breadth_m > 0 and gap_m >= 0, got {self.half_breadth_m}, {self.gap_m}"
            )
        alpha = self.line().azimuth_rad
        mis = abs(float(angdiff(self.heading_rad, alpha)))
        mis = min(mis, np.pi - mis)
        if mis > self.max_misalignment_rad:
            raise GeometryError(
                f"PierLine: heading {np.rad2deg(self.heading_rad):.1f} deg is not along the pier "
                f"(azimuth {np.rad2deg(alpha):.1f} deg); misaligned by {np.rad2deg(mis):.1f} deg"
            )

    def line(self, offset_m: float = 0.0) -> LineLOP:
        return LineLOP(
            self.a_lat_rad, self.a_lon_rad, self.b_lat_rad, self.b_lon_rad, self.sigma_m, offset_m
        )

    @property
    def offset_m(self) -> float:
        """Signed offset (right of A->B positive) of the reference point from the pier line."""
        y_side = (self.half_breadth_m + self.gap_m) * (1.0 if self.side == "starboard" else -1.0)
        alpha = self.line().azimuth_rad
        return float((self.ref_transverse_m - y_side) * np.cos(angdiff(self.heading_rad, alpha)))

    def as_line(self) -> LineLOP:
        """The shifted line of position of the reference point."""
        return self.line(self.offset_m)

    def linearise(self, lat_rad: ArrayLike, lon_rad: ArrayLike) -> Rows:
        rows = self.as_line().linearise(lat_rad, lon_rad)
        return Rows(rows.g, rows.residual, rows.cov, ("pier",))


@dataclass(frozen=True)
class NadirCircle:
    """Free-gyro nadir circle (seeds/002 (1)).

    cos(theta) = -u_x cos(phi) cos(lam + w t) - u_y cos(phi) sin(lam + w t) - u_z sin(phi)
    is a circle of angular radius theta (the nadir angle) about the sub-point where
    -u pierces the Earth: phi_s = asin(-u_z), lam_s = atan2(-u_y, -u_x) - w t.
    With geodetic latitude, (cos phi cos lam, cos phi sin lam, sin phi) is the
    ellipsoid normal, so (1) is the angle between the spin axis and the local vertical,
    exact on WGS-84; the sub-point is the point whose normal is -u.
    """

    sub_lat_rad: float
    sub_lon_rad: float
    nadir_rad: float | FloatArray
    sigma_rad: float

    def __post_init__(self) -> None:
        _positive("NadirCircle sigma_rad", self.sigma_rad)

    @classmethod
    def from_gyro_vector(
        cls, u_inertial: ArrayLike, t_s: float, nadir_rad: float | FloatArray, sigma_rad: float
    ) -> NadirCircle:
        """The circle of a gyro spin-axis unit vector u (inertial frame) at time t_s (seeds/002 (1))."""
        u = np.asarray(u_inertial, float)
        norm = np.linalg.norm(u)
        if not np.isclose(norm, 1.0, atol=1e-6):
            raise GeometryError(f"NadirCircle gyro vector must be a unit vector, |u| = {norm:.6f}")
        sub_lat = np.arcsin(-u[2])
        sub_lon = float(angdiff(np.arctan2(-u[1], -u[0]) - OMEGA_E_RADPS * t_s, 0.0))
        return cls(float(sub_lat), sub_lon, nadir_rad, sigma_rad)

    def cos_nadir(self, lat_rad: ArrayLike, lon_rad: ArrayLike) -> FloatArray:
        """cos(theta) at a position: (1) written with the sub-point."""
        lat = np.asarray(lat_rad, float)
        dl = np.asarray(lon_rad, float) - self.sub_lon_rad
        s_s, c_s = np.sin(self.sub_lat_rad), np.cos(self.sub_lat_rad)
        # cast: numpy's stubs type np.sin(float) as Any
        return cast(FloatArray, np.sin(lat) * s_s + np.cos(lat) * c_s * np.cos(dl))  # (1)

    def linearise(self, lat_rad: ArrayLike, lon_rad: ArrayLike) -> Rows:
        lat = np.asarray(lat_rad, float)
        dl = np.asarray(lon_rad, float) - self.sub_lon_rad
        s_s, c_s = np.sin(self.sub_lat_rad), np.cos(self.sub_lat_rad)
        cos_t = np.clip(self.cos_nadir(lat, lon_rad), -1.0, 1.0)
        theta = np.arccos(cos_t)
        sin_t = np.sin(theta)
        if np.any(sin_t < 1e-9):
            raise GeometryError(
                "NadirCircle: the position is at the sub-point or its antipode; no gradient"
            )
        # (30): -sin(theta) d(theta) = d(cos theta)/d(phi) d(phi) + d(cos theta)/d(lam) d(lam)
        dcos_dlat = np.cos(lat) * s_s - np.sin(lat) * c_s * np.cos(dl)
        dcos_dlon = -np.cos(lat) * c_s * np.sin(dl)
        g = np.stack([-dcos_dlat / sin_t * k_phi(lat), -dcos_dlon / sin_t * k_lambda(lat)], axis=-1)
        return _rows(g, np.asarray(self.nadir_rad, float) - theta, self.sigma_rad**2, "nadir")


Observation = PositionFix | RangeLOP | BearingLOP | LineLOP | PierLine | NadirCircle


def stack_rows(observations: Sequence[Observation], lat_rad: ArrayLike, lon_rad: ArrayLike) -> Rows:
    """All observations linearised at one position, stacked (R block-diagonal)."""
    parts = [obs.linearise(lat_rad, lon_rad) for obs in observations]
    k = sum(p.residual.shape[-1] for p in parts)
    batch = np.broadcast_shapes(*(p.residual.shape[:-1] for p in parts))
    g = np.concatenate([np.broadcast_to(p.g, batch + p.g.shape[-2:]) for p in parts], axis=-2)
    z = np.concatenate(
        [np.broadcast_to(p.residual, batch + p.residual.shape[-1:]) for p in parts], axis=-1
    )
    cov = np.zeros(batch + (k, k))
    i = 0
    for p in parts:
        n = p.residual.shape[-1]
        cov[..., i : i + n, i : i + n] = p.cov
        i += n
    kinds = tuple(kind for p in parts for kind in p.kinds)
    return Rows(g, z, cov, kinds)


def to_metres(rows: Rows) -> Rows:
    """Rows scaled to metres across each line: Psi = S G, z = S r, R = S R S, S = 1/|g_i|."""
    scale = 1.0 / np.linalg.norm(rows.g, axis=-1)
    return Rows(
        rows.g * scale[..., None],
        rows.residual * scale,
        rows.cov * scale[..., :, None] * scale[..., None, :],
        rows.kinds,
    )


# ------------------------------------------------------------------------ solution


@dataclass(frozen=True)
class FixSolution:
    """A fused position and its quality.

    Scalars, or arrays with a leading runs axis for a batch (see :func:`fuse_fix`).
    ``cov_m2``: P (north, east; m^2), (W3) for WLS, the sandwich Q Psi^T R Psi Q for LS.
    ``cofactor``: Q = (Psi^T Psi)^-1 of the unit rows (seeds/002 (35)); ``dop`` =
    sqrt(q_nn + q_ee) (METHODS §5).  ``drms_m`` = sqrt(trace P), ``two_drms_m`` = 2 drms
    (the 2M circle, B30-B31).  ``residuals_m``: post-fit residuals, metres across each
    line; ``chi2`` = r^T R^-1 r with ``redundancy`` = rows - 2 degrees of freedom.
    """

    lat_rad: float | FloatArray
    lon_rad: float | FloatArray
    cov_m2: FloatArray
    ellipse: Ellipse
    drms_m: float | FloatArray
    two_drms_m: float | FloatArray
    cofactor: FloatArray
    dop: float | FloatArray
    residuals_m: FloatArray
    kinds: tuple[str, ...]
    chi2: float | FloatArray
    redundancy: int
    iterations: int
    weighted: bool

    @property
    def variance_factor(self) -> float | FloatArray:
        """A posteriori variance of unit weight chi2/redundancy (NaN when redundancy is 0)."""
        return self.chi2 / self.redundancy if self.redundancy > 0 else float("nan")


def _t(m: FloatArray) -> FloatArray:
    return np.swapaxes(m, -1, -2)


def fuse_fix(
    observations: Sequence[Observation],
    prior_lat_rad: float,
    prior_lon_rad: float,
    *,
    weighted: bool = True,
    max_iterations: int = 20,
    tolerance_m: float = 1e-4,
) -> FixSolution:
    """Fuse fixes and lines of position by LS (W1) or WLS (W4), iterated about a prior.

    The prior is only the first linearisation point; to weigh it as information, add
    it as a :class:`PositionFix`.  Observations whose measured values are arrays
    (runs,) give a batch of independent solutions in one call (Monte Carlo): every
    field of the result then carries the leading runs axis.  Raises
    :class:`GeometryError` when the rows cannot fix both coordinates (fewer than 2,
    or parallel lines) or the iteration does not converge.
    """
    if not observations:
        raise GeometryError("fuse_fix: no observations")
    lat, lon = np.asarray(prior_lat_rad, float), np.asarray(prior_lon_rad, float)
    iterations = 0
    while True:
        iterations += 1
        rows = to_metres(stack_rows(observations, lat, lon))
        psi, z, r_m2 = rows.g, rows.residual, rows.cov
        if psi.shape[-2] < 2 or np.any(np.linalg.matrix_rank(psi, tol=1e-6) < 2):
            raise GeometryError(
                f"fuse_fix: {psi.shape[-2]} row(s) ({', '.join(rows.kinds)}) do not fix both "
                "coordinates (need two non-parallel lines of position or a fix)"
            )
        if weighted:
            w = np.linalg.inv(r_m2)
            normal = _t(psi) @ w @ psi
            dx = np.linalg.solve(normal, (_t(psi) @ w @ z[..., None]))[..., 0]  # (W4)
        else:
            dx = np.linalg.solve(_t(psi) @ psi, (_t(psi) @ z[..., None]))[..., 0]  # (W1)
        lat, lon = add_offset_ne(lat, lon, dx[..., 0], dx[..., 1])
        step = float(np.max(np.hypot(dx[..., 0], dx[..., 1])))
        if step < tolerance_m:
            break
        if iterations >= max_iterations:
            raise GeometryError(
                f"fuse_fix: no convergence after {max_iterations} iterations (last step "
                f"{step:.3g} m); check the observations and the prior"
            )
    rows = to_metres(stack_rows(observations, lat, lon))
    psi, z, r_m2 = rows.g, rows.residual, rows.cov
    # casts: numpy's stubs type np.linalg.inv as returning floating[Any]
    q = cast(FloatArray, np.linalg.inv(_t(psi) @ psi))  # cofactor matrix, seeds/002 (35)
    r_inv = np.linalg.inv(r_m2)
    cov: FloatArray
    if weighted:
        cov = cast(FloatArray, np.linalg.inv(_t(psi) @ r_inv @ psi))  # (W3)
    else:
        cov = q @ _t(psi) @ r_m2 @ psi @ q  # covariance of the LS (W1) estimate
    cov = 0.5 * (cov + _t(cov))
    drms = np.sqrt(cov[..., 0, 0] + cov[..., 1, 1])
    dop = np.sqrt(q[..., 0, 0] + q[..., 1, 1])  # (37) in the trace form, METHODS §5
    chi2 = np.einsum("...i,...ij,...j->...", z, r_inv, z)

    def out(v: FloatArray) -> float | FloatArray:
        return float(v) if np.ndim(v) == 0 else v

    return FixSolution(
        lat_rad=out(lat),
        lon_rad=out(lon),
        cov_m2=cov,
        ellipse=error_ellipse(cov),
        drms_m=out(drms),
        two_drms_m=out(2.0 * drms),
        cofactor=q,
        dop=out(dop),
        residuals_m=z,
        kinds=rows.kinds,
        chi2=out(chi2),
        redundancy=int(psi.shape[-2] - 2),
        iterations=iterations,
        weighted=weighted,
    )


def abeam_line(pier: PierLine, mark_lat_rad: float, mark_lon_rad: float, sigma_m: float) -> LineLOP:
    """The line through a pier mark (bollard, berth mark) perpendicular to the pier.

    For a ship whose reference point lies abeam of the mark: the along-pier LOP.
    """
    alpha = pier.line().azimuth_rad
    lat_b, lon_b = add_offset_ne(
        mark_lat_rad,
        mark_lon_rad,
        100.0 * np.cos(alpha + np.pi / 2),
        100.0 * np.sin(alpha + np.pi / 2),
    )
    return LineLOP(mark_lat_rad, mark_lon_rad, float(lat_b), float(lon_b), sigma_m)


def alongside_reference(
    pier: PierLine,
    *,
    fixes: Sequence[Observation] = (),
    abeam_mark: tuple[float, float] | None = None,
    abeam_sigma_m: float = 2.0,
) -> FixSolution:
    """Reference position of a ship lying alongside a known pier (seeds/004), for the INS.

    The pier line fixes the position across the pier; along the pier it comes from a
    mark abeam of the reference point (``abeam_mark`` = (lat_rad, lon_rad), sigma
    ``abeam_sigma_m``) and/or from ``fixes`` (GNSS, the mean of the INS over the berth
    period).  Fused by WLS (W3, W4) about the pier line's midpoint.
    """
    obs: list[Observation] = [pier, *fixes]
    if abeam_mark is not None:
        obs.append(abeam_line(pier, abeam_mark[0], abeam_mark[1], abeam_sigma_m))
    if len(obs) == 1:
        raise GeometryError(
            "alongside_reference: the pier line alone gives no position along the pier; "
            "give an abeam mark or a fix"
        )
    lat0, lon0 = pier.line()._mid()
    return fuse_fix(obs, lat0, lon0, weighted=True)


__all__ = [
    "OMEGA_E_RADPS",
    "BearingLOP",
    "FixSolution",
    "GeometryError",
    "LineLOP",
    "NadirCircle",
    "Observation",
    "PierLine",
    "PositionFix",
    "RangeLOP",
    "Rows",
    "abeam_line",
    "alongside_reference",
    "fuse_fix",
    "stack_rows",
    "to_metres",
]
