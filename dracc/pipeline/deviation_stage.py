"""The INS deviation stage (METHODS section 4): each unit's deviation from the mean of
the units, with a reference for the Table 1 check (:mod:`dracc.math.deviation`): GNSS where
it is present, else the berth reference of ``[reference] alongside`` while the ship lay
alongside a known pier (seeds/004; :mod:`dracc.math.deviation.berth`, docs/deviation.md)."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from dracc.core.config import Config
from dracc.core.errors import GeometryError
from dracc.core.reference_config import BerthConfig
from dracc.core.timefmt import iso_utc
from dracc.core.vocabulary import INS_ROLES
from dracc.frames import Voyage
from dracc.math.deviation import DeviationResult, analyse_deviations, unit_series_from_voyage
from dracc.math.deviation.berth import (
    BerthReference,
    alongside_runs,
    berth_position,
    circular_mean_rad,
    pier_line,
)
from dracc.math.deviation.sampling import UnitSeries, sample_unit

#: spacing of the mean INS track on which a berth period is detected or averaged
TRACK_STEP_S = 60.0


def deviation(
    voyage: Voyage, cfg: Config, missing: list[str]
) -> tuple[DeviationResult | None, str | None]:
    """INS deviations from the mean (dracc.math.deviation), against GNSS where present and
    the configured berths where not; returns (result, reference source: 'gnss', 'berth',
    'gnss+berth' or None)."""
    present = [r for r in INS_ROLES if voyage.role_sources(r)]
    if len(present) < 2:
        found = f"only one INS unit ({present[0]}) found" if present else "no INS unit found"
        missing.append(
            f"no INS triple: {found}; the deviation statistics need at least "
            "two units (three for the paper's factors); map sources to ins1..ins3 with "
            "--role KEY=ROLE if they are there under another name"
        )
        return None, None
    units = {r: unit_series_from_voyage(voyage, r) for r in present}
    ref_role = "gnss" if voyage.role_sources("gnss") else None
    reference = unit_series_from_voyage(voyage, ref_role) if ref_role else None
    if reference is not None and reference.lat_rad.size == 0:
        reference, ref_role = None, None
    berths: list[BerthReference] = []
    messages: list[str] = []
    if cfg.reference.alongside:
        berth_series, berths, messages = _berths(voyage, cfg, units, reference, missing)
        if berths and any(b.n_reference for b in berths):
            reference = _merge(reference, berth_series)
            ref_role = "gnss+berth" if ref_role == "gnss" else "berth"
    result = analyse_deviations(units, cfg.deviation, reference)
    if berths or messages:
        result = _with_berths(result, tuple(berths), tuple(messages))
    if len(present) == 2:
        missing.append(
            f"no INS triple: only two units ({', '.join(present)}); statistics use "
            "the first-approximation factor sqrt(2) and no three-cornered hat"
        )
    if ref_role is None:
        what = "GNSS or a berth" if cfg.reference.alongside else "GNSS"
        missing.append(
            f"no reference ({what}) for the INS: the true error RMS and k* (Table 1) are not computed"
        )
    return result, ref_role


def _with_berths(
    result: DeviationResult, berths: tuple[BerthReference, ...], messages: tuple[str, ...]
) -> DeviationResult:
    return replace(result, berths=berths, messages=result.messages + messages)


def _mean_track(
    units: dict[str, UnitSeries], max_gap_s: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The mean position of the units every TRACK_STEP_S (NaN where a unit is missing)."""
    spans = [s for s in (u.span_ns() for u in units.values()) if s is not None]
    step = int(TRACK_STEP_S * 1e9)
    t = np.arange(min(s[0] for s in spans), max(s[1] for s in spans) + 1, step, dtype=np.int64)
    sampled = [sample_unit(u, t, max_gap_s) for u in units.values()]
    lat = np.mean([s.lat_rad for s in sampled], axis=0)
    lon = np.array([circular_mean_rad(c) for c in np.vstack([s.lon_rad for s in sampled]).T])
    lon = np.where(lon > math.pi, lon - 2 * math.pi, lon)
    return t, lat, lon


def _heading(
    voyage: Voyage, b: BerthConfig, units: dict[str, UnitSeries], t0: int, t1: int
) -> tuple[float, str]:
    """H for the offset: configured, else the compass's mean over the period, else the INS's."""
    if b.heading_deg is not None:
        return math.radians(b.heading_deg), "configured"
    candidates = [("compass", [unit_series_from_voyage(voyage, "compass")])]
    candidates.append(("ins", list(units.values())))
    for source, series in candidates:
        h = np.concatenate(
            [s.heading_rad[(s.hdg_time_ns >= t0) & (s.hdg_time_ns <= t1)] for s in series]
        )
        if h.size:
            return circular_mean_rad(h), source
    return math.nan, "none"


def _berth_on_wgs84(b: BerthConfig) -> tuple[BerthConfig, str]:
    """The berth with its pier (and abeam mark) moved from ``b.datum`` to WGS-84
    (seeds/004 §2: all data on one datum before fusion), and what moved them."""
    from dracc.ingest.datums import to_wgs84  # pyproj: loaded only when a datum is given

    lats = [b.pier[0], b.pier[2], *(b.abeam[:1] if b.abeam else ())]
    lons = [b.pier[1], b.pier[3], *(b.abeam[1:2] if b.abeam else ())]
    pos = to_wgs84(lats, lons, str(b.datum))
    la, lo = pos.lat_deg.tolist(), pos.lon_deg.tolist()
    tr = pos.transformation
    acc = "" if tr.accuracy_m is None else f", ±{tr.accuracy_m:g} m"
    moved = (
        f"pier charted on {tr.datum}, moved to WGS-84 by {tr.operation}"
        f"{f' ({tr.operation_code}{acc})' if tr.operation_code else ''}: "
        f"{float(np.max(pos.shift_m)):.1f} m"
    )
    return (
        replace(
            b,
            pier=(la[0], lo[0], la[1], lo[1]),
            abeam=(la[2], lo[2]) if b.abeam else None,
            datum=None,
        ),
        moved,
    )


def _berths(
    voyage: Voyage,
    cfg: Config,
    units: dict[str, UnitSeries],
    gnss: UnitSeries | None,
    missing: list[str],
) -> tuple[UnitSeries, list[BerthReference], list[str]]:
    """The berth references and their readings at the INS readings alongside, left out
    within max_interp_gap_s of a GNSS position (GNSS stays the reference where present)."""
    gap_s = cfg.deviation.max_interp_gap_s
    t, lat, lon = _mean_track(units, gap_s)
    ins_t = np.unique(np.concatenate([u.pos_time_ns for u in units.values()]))
    gnss_t = np.sort(gnss.pos_time_ns) if gnss is not None else np.empty(0, np.int64)
    pos_t, pos_lat, pos_lon, hdg_t, hdg = [], [], [], [], []
    out: list[BerthReference] = []
    messages: list[str] = []
    for i, b in enumerate(cfg.reference.alongside):
        name = f"berth {i} ([reference] alongside[{i}])"
        if b.datum is not None:
            b, moved = _berth_on_wgs84(b)
            messages.append(f"{name}: {moved}")
        if b.start_ns is not None or b.end_ns is not None:
            t0 = b.start_ns if b.start_ns is not None else int(t[0])
            t1 = b.end_ns if b.end_ns is not None else int(t[-1])
            periods, how = [(max(t0, int(t[0])), min(t1, int(t[-1])))], "configured"
            periods = [p for p in periods if p[1] > p[0]]
        else:
            periods, how = alongside_runs(b, t, lat, lon), "detected"
        if not periods:
            missing.append(
                f"{name}: the ship was not found alongside "
                + (
                    "in the configured period (no INS readings there)"
                    if how == "configured"
                    else f"(the INS mean never within {b.tolerance_m:g} m of the pier and "
                    f"slower than {b.max_speed_kn:g} kn); give start_utc and end_utc"
                )
            )
        for t0, t1 in periods:
            sel = (t >= t0) & (t <= t1) & np.isfinite(lat)
            heading, h_src = _heading(voyage, b, units, t0, t1)
            ins_mean = (
                (float(np.mean(lat[sel])), circular_mean_rad(lon[sel])) if sel.any() else None
            )
            if math.isnan(heading) or (ins_mean is None and b.abeam is None):
                missing.append(
                    f"{name}: no heading or no INS position from {iso_utc(t0)} to {iso_utc(t1)}; "
                    "give heading_deg and abeam"
                )
                continue
            try:
                sol, along_src, s_across, s_along = berth_position(b, heading, ins_mean)
            except GeometryError as err:
                missing.append(f"{name}: not used from {iso_utc(t0)} to {iso_utc(t1)}: {err}")
                continue
            keep = _far_from(ins_t[(ins_t >= t0) & (ins_t <= t1)], gnss_t, gap_s)
            lat_r, lon_r = float(sol.lat_rad), float(sol.lon_rad)
            pos_t.append(keep)
            pos_lat.append(np.full(keep.size, lat_r))
            pos_lon.append(np.full(keep.size, lon_r))
            if b.heading_deg is not None:  # a configured heading is a course reference too
                hdg_t.append(keep)
                hdg.append(np.full(keep.size, heading))
            pier = pier_line(b, heading)
            ref = BerthReference(
                i,
                t0,
                t1,
                how,
                lat_r,
                lon_r,
                s_across,
                s_along,
                heading,
                h_src,
                along_src,
                pier.offset_m,
                pier.line().azimuth_rad,
                b.side,
                b.half_breadth_m,
                int(keep.size),
            )
            out.append(ref)
            messages.append(_message(ref))

    def cat(parts: list[np.ndarray], dtype: type) -> np.ndarray:
        return np.concatenate(parts).astype(dtype) if parts else np.empty(0, dtype)

    series = UnitSeries(
        pos_time_ns=cat(pos_t, np.int64),
        lat_rad=cat(pos_lat, float),
        lon_rad=cat(pos_lon, float),
        hdg_time_ns=cat(hdg_t, np.int64),
        heading_rad=cat(hdg, float),
    )
    return series, out, messages


def _far_from(times_ns: np.ndarray, other_ns: np.ndarray, gap_s: float) -> np.ndarray:
    """The times further than ``gap_s`` from every time of ``other_ns`` (sorted)."""
    if other_ns.size == 0 or times_ns.size == 0:
        return times_ns
    j = np.searchsorted(other_ns, times_ns)
    left = other_ns[np.clip(j - 1, 0, other_ns.size - 1)]
    right = other_ns[np.clip(j, 0, other_ns.size - 1)]
    nearest = np.minimum(np.abs(times_ns - left), np.abs(right - times_ns))
    return times_ns[nearest > gap_s * 1e9]


def _message(r: BerthReference) -> str:
    """The reference line of the text and HTML reports."""
    along = (
        f"along it from the abeam mark (sigma {r.sigma_along_m:.1f} m)"
        if r.along_source == "abeam mark"
        else "along it the INS mean over the period (not independent of the units)"
    )
    used = (
        f"{r.n_reference} readings where there is no GNSS"
        if r.n_reference
        else "not used: GNSS is present throughout"
    )
    return (
        f"Reference alongside berth {r.berth} ({r.period_source} {iso_utc(r.start_ns)} to "
        f"{iso_utc(r.end_ns)}): {math.degrees(r.lat_rad):.6f}, {math.degrees(r.lon_rad):.6f}, "
        f"across the pier from the pier line ({r.side} side to, offset {r.offset_m:+.1f} m, "
        f"sigma {r.sigma_across_m:.1f} m, heading {math.degrees(r.heading_rad):.1f} deg, "
        f"{r.heading_source}), {along}; {used}."
    )


def _merge(a: UnitSeries | None, b: UnitSeries) -> UnitSeries:
    """GNSS readings and berth readings in one reference series (sample_unit sorts them)."""
    if a is None:
        return b
    return UnitSeries(
        pos_time_ns=np.concatenate([a.pos_time_ns, b.pos_time_ns]),
        lat_rad=np.concatenate([a.lat_rad, b.lat_rad]),
        lon_rad=np.concatenate([a.lon_rad, b.lon_rad]),
        hdg_time_ns=np.concatenate([a.hdg_time_ns, b.hdg_time_ns]),
        heading_rad=np.concatenate([a.heading_rad, b.heading_rad]),
        vel_time_ns=a.vel_time_ns,
        vn_mps=a.vn_mps,
        ve_mps=a.ve_mps,
    )
