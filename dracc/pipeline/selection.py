"""Choosing and assembling the sensor series the dead reckoning runs on.

Which source gives the heading (the compass role, else any non-INS/GNSS heading), the
log speed (through the water, else over the ground) and the restart fixes and reference
(GNSS, else the mean of the INS units, else the position source with most fixes); the
true heading from a magnetic compass through :func:`dracc.math.deadreckoning.true_heading_rad`
(B2)/(B3); and the heading and speed held onto the DR time grid.

Every choice made for the user is said in ``notes``; what is lacking in ``missing``.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
import pandas as pd

from dracc.core.arrays import hold_at, unique_sorted
from dracc.core.config import DeadReckoningConfig
from dracc.core.geodesy import circmean, interp_position, wrap_pi
from dracc.core.units import NS_PER_S
from dracc.core.vocabulary import INS_ROLES
from dracc.frames import Voyage
from dracc.ingest.role_evidence import choice_note, rank_sources
from dracc.math.deadreckoning import TrueHeading, true_heading_rad
from dracc.math.ep import EstimatedPosition

#: the DR time base: heading and speed held onto a grid of this step (seconds)
DR_STEP_S = 1.0
#: a silence of both heading and speed longer than this is left out of the DR grid
DR_SILENCE_S = 3600.0
#: a reference position is interpolated between samples at most this far apart
REF_MAX_GAP_S = 5.0

#: (time_ns, lat_rad, lon_rad, description): the restart fixes, also the reference
Fixes = tuple[np.ndarray, np.ndarray, np.ndarray, str]
#: (time_ns, true heading rad, description)
HeadingSeries = tuple[np.ndarray, np.ndarray, str]
#: (time_ns, longitudinal m/s, transverse m/s, description, mode 'water' or 'ground')
SpeedSeries = tuple[np.ndarray, np.ndarray, np.ndarray, str, str]


# ------------------------------------------------------------------------ helpers


def role_of(voyage: Voyage, key: str) -> str | None:
    """The role of source ``key``, None when it has none."""
    s = voyage.sources.get(key)
    return s.role if s is not None else None


def valid_positions(df: pd.DataFrame) -> pd.DataFrame:
    """Positions with a fix (GGA quality 0 and NaN coordinates left out)."""
    ok = (
        (df["quality"].to_numpy() != 0)
        & np.isfinite(df["lat_rad"].to_numpy())
        & np.isfinite(df["lon_rad"].to_numpy())
    )
    return df[ok]


def sentence_types(df: pd.DataFrame) -> str:
    """'HDT+THS': the sentence types among the rows (unique on the categorical codes,
    not on a million strings)."""
    return "+".join(sorted({str(x) for x in df["sentence"].unique()}))


def dedupe_sorted(t_ns: np.ndarray, *cols: np.ndarray) -> tuple[np.ndarray, ...]:
    """Sort by time and keep one sample per time (strictly increasing times).

    Each column takes the last *finite* value among the samples of one time, so two
    sentences of one instant complement each other whatever order the container put them
    in (a log's VHW and VBW: only VBW carries the transverse speed)."""
    order = np.argsort(t_ns, kind="stable")
    t = t_ns[order]
    starts = np.flatnonzero(np.r_[True, t[1:] != t[:-1]]) if t.size else np.zeros(0, np.int64)
    position = np.arange(t.size)
    out = [t[starts]]
    for c in cols:
        c = c[order]
        if starts.size == 0:
            out.append(c)
            continue
        last_finite = np.maximum.reduceat(np.where(np.isfinite(c), position, -1), starts)
        out.append(np.where(last_finite >= 0, c[np.maximum(last_finite, 0)], np.nan))
    return tuple(out)


# ------------------------------------------------------------------------ heading


def heading_series(
    voyage: Voyage, cfg: DeadReckoningConfig, missing: list[str], notes: list[str]
) -> HeadingSeries | None:
    """True heading (B2)/(B3) from the compass: (time_ns, heading_rad, description)."""
    hdg = voyage.frames.get("heading")
    if hdg is None or hdg.empty:
        missing.append(
            "no heading: the log holds no HDT/THS/HDG/HDM sentence; dead reckoning, "
            "current and calibration need one"
        )
        return None
    valid = np.isfinite(hdg["heading_rad"].to_numpy())  # one selection below: one copy of the rows
    compass = voyage.role_sources("compass")
    if compass:
        use = hdg[valid & hdg["source"].isin(compass).to_numpy()]
        who = "compass " + "+".join(compass)
    else:
        other = [
            k
            for k in hdg["source"][valid].unique().tolist()
            if not (set(voyage.sources[k].roles) & {"ins1", "ins2", "ins3", "gnss"})
        ]
        gives_fixes = not other  # the heading there is comes from a unit giving fixes too
        other = other or [str(k) for k in hdg["source"][valid].unique().tolist()]
        key = _one_by_evidence(voyage, "compass", other, notes)
        if key is not None and gives_fixes:
            notes.append(
                f"no compass and no heading beside the fixes' units: heading taken from {key}, "
                "which also gives fixes (a satellite compass, an INS, or a navigation system "
                "relaying the gyro)"
            )
        elif key is not None:
            notes.append(f"no source has the role compass; heading taken from {key}")
        use = hdg[valid & (hdg["source"] == key).to_numpy()]
        who = f"heading source {key}"
    if use.empty:
        missing.append(
            "no heading: heading sentences exist but none has a value from a compass "
            "(only empty fields or INS/GNSS headings); dead reckoning not computed"
        )
        return None
    refs = set(use["reference"].dropna().unique().tolist())
    if "T" in refs:
        use = use[use["reference"] == "T"]
        t, h = dedupe_sorted(use["time_ns"].to_numpy(np.int64), use["heading_rad"].to_numpy(float))
        sent = sentence_types(use)
        return t, true_heading_rad(h, "T", errors=cfg).heading_rad, f"{who} ({sent}, true)"  # (B3)
    # magnetic: (B2) KDd = KK + d + delta (leeway from the log is added by dead_reckon)
    t, kk, dev, var = dedupe_sorted(
        use["time_ns"].to_numpy(np.int64),
        use["heading_rad"].to_numpy(float),
        use["deviation_rad"].to_numpy(float),
        use["variation_rad"].to_numpy(float),
    )
    desc = f"{who} ({sentence_types(use)}, magnetic"
    if cfg.deviation_table:
        if np.any(~np.isfinite(dev)):
            desc += ", deviation from the configured table"
    elif np.any(~np.isfinite(dev)):
        n_nan = int(np.sum(~np.isfinite(dev)))
        notes.append(
            f"magnetic heading without deviation at {n_nan} of {dev.size} samples and no "
            "[dead_reckoning] deviation_table: deviation taken as 0 there"
        )
    # deviation: the sentence's, else the configured table, else 0; variation: the
    # sentence's, a configured one over none or a 0.0 placeholder, else 0 (true_heading_rad)
    th = true_heading_rad(kk, "M", dev, var, errors=cfg, missing_variation="zero")  # (B2)
    return t, th.heading_rad, desc + _variation_notes(th, cfg, missing, notes) + ")"


def _variation_notes(
    th: TrueHeading, cfg: DeadReckoningConfig, missing: list[str], notes: list[str]
) -> str:
    """Say where the compass's variation came from, from :func:`true_heading_rad`'s counts;
    returns the heading description's suffix.

    Many compasses send a zero placeholder (HDG ...,0.0,E): a configured variation
    (--variation, [dead_reckoning] variation_deg) wins over a zero field, never over a
    non-zero one.  With none sent and none configured the DR takes 0 and says so in
    ``missing`` (the analysis reports what a log lacks instead of failing).
    """
    n_var = th.n_variation_from_config + th.n_variation_missing
    n_zero = th.n_variation_placeholder
    n_own = th.n_variation_from_sentence
    if cfg.variation_deg is not None and (n_var or n_zero):
        what = " and ".join(
            x
            for x in (
                f"none at {n_var}" if n_var else "",
                f"0.0 (a placeholder) at {n_zero}" if n_zero else "",
            )
            if x
        )
        notes.append(
            f"magnetic variation: the configured {cfg.variation_deg:g}° used at "
            f"{n_var + n_zero} of {th.n_magnetic} compass samples (the compass sent {what})"
            + (f"; the compass's own non-zero variation kept at {n_own}" if n_own else "")
        )
        return f", variation {cfg.variation_deg:g}° from the configuration"
    if n_zero:  # none configured: the 0.0 is used as sent
        notes.append(
            f"magnetic variation: the compass sends 0.0 at {n_zero} of {th.n_magnetic} samples "
            "(often a placeholder); it is used as sent (give --variation DEG if the local "
            "variation is not zero)"
        )
    if th.n_variation_missing:  # none sent, none configured: taken as 0
        missing.append(
            f"magnetic variation: the compass sends none at {th.n_variation_missing} of "
            f"{th.n_magnetic} samples and none is configured; the DR takes it as 0 there, so "
            "its course is off by the local variation (give --variation DEG)"
        )
    return ""


def _one_by_evidence(voyage: Voyage, role: str, keys: list[str], notes: list[str]) -> str | None:
    """One of ``keys`` for ``role`` where no source has it (never several merged): the
    only one, else the one the evidence chooses (said in ``notes``)."""
    if len(keys) < 2:
        return keys[0] if keys else None
    c = rank_sources(voyage.frames, role, keys, voyage.sources, voyage.role_sources("gnss"))
    notes.append(choice_note(c))
    return c.chosen


# -------------------------------------------------------------------------- speed


def speed_series(voyage: Voyage, missing: list[str]) -> SpeedSeries | None:
    """The log's speed: (time_ns, longitudinal, transverse, description, mode).

    Through the water (VHW, VBW water components; mode 'water', B7-B12) where the log
    gives it; otherwise over the ground (VBW ground components; mode 'ground', B13-B14).
    """
    water = voyage.frames.get("water")
    logs = voyage.role_sources("log")
    if water is None or water.empty:
        missing.append(
            "no speed log: the log holds no VHW/VBW sentence; dead reckoning, current "
            "and calibration need one"
        )
        return None
    if not logs:  # no log role: one source of speed sentences, chosen by evidence
        keys = [str(k) for k in water["source"].unique().tolist()]
        key = _one_by_evidence(voyage, "log", keys, [])
        logs = [] if key is None else [key]
        frame = water[(water["source"] == key).to_numpy()]
    else:
        frame = water[water["source"].isin(logs)]
    for col, col_y, mode, what in (
        ("stw_mps", "stw_transverse_mps", "water", "through the water"),
        ("sog_long_mps", "sog_transverse_mps", "ground", "over the ground"),
    ):
        use = frame[np.isfinite(frame[col].to_numpy())]
        if use.empty:
            continue
        t, v, vy = dedupe_sorted(
            use["time_ns"].to_numpy(np.int64), use[col].to_numpy(float), use[col_y].to_numpy(float)
        )
        sent = sentence_types(use)
        # read after 'speed' in every report: 'log LOG (VHW, ...)', never 'speed speed ...'
        if voyage.role_sources("log"):
            return t, v, vy, f"log {'+'.join(logs)} ({sent}, {what})", mode
        why = "chosen by evidence: no source has the log role"
        return t, v, vy, f"{'+'.join(logs)} ({sent}, {what}; {why})", mode
    missing.append(
        "no log speed: the log sentences carry no speed value, through the water or "
        "over the ground; dead reckoning not computed"
    )
    return None


# -------------------------------------------------------------------------- fixes


def reference_fixes(
    voyage: Voyage, cfg: DeadReckoningConfig, missing: list[str], notes: list[str]
) -> Fixes | None:
    """Restart fixes and the reference: (time_ns, lat_rad, lon_rad, description) or None."""
    pos = voyage.frames.get("position")
    if pos is None or pos.empty:
        missing.append("no position at all: the DR has no start fix and no reference")
        return None
    pos = valid_positions(pos)
    gnss = voyage.role_sources("gnss")
    if cfg.fix_role == "gnss" and gnss:
        g = pos[pos["source"].isin(gnss[:1])]
        if len(gnss) > 1:
            notes.append(
                f"several GNSS sources ({', '.join(gnss)}): fixes and reference from {gnss[0]}"
            )
        if not g.empty:
            t, la, lo = dedupe_sorted(
                g["time_ns"].to_numpy(np.int64),
                g["lat_rad"].to_numpy(float),
                g["lon_rad"].to_numpy(float),
            )
            return t, la, lo, "gnss"
    ins = [r for r in INS_ROLES if voyage.role_sources(r)]
    if ins:
        # the mean of the INS units at the first unit's times (circular mean of longitude)
        series = []
        for r in ins:
            d = pos[pos["source"].isin(voyage.role_sources(r))]
            series.append(
                dedupe_sorted(
                    d["time_ns"].to_numpy(np.int64),
                    d["lat_rad"].to_numpy(float),
                    d["lon_rad"].to_numpy(float),
                )
            )
        t = series[0][0]
        lats, lons = [], []
        for st, sla, slo in series:
            a, b = interp_position(st, sla, slo, t, REF_MAX_GAP_S * 1e9)
            lats.append(a)
            lons.append(b)
        lat = np.nanmean(np.vstack(lats), axis=0)
        lon = wrap_pi(circmean(np.vstack(lons), axis=0))
        ok = np.isfinite(lat) & np.isfinite(lon)
        if cfg.fix_role == "gnss":
            notes.append(
                f"no GNSS: DR fixes and reference from the mean of the INS units ({', '.join(ins)})"
            )
        return t[ok], lat[ok], lon[ok], "ins_mean"
    # no GNSS or INS role: the position source with the most fixes (e.g. an instrument bus
    # relaying its GPS as II RMC/GLL)
    codes, keys = pd.factorize(pos["source"])  # keys in order of first appearance
    if len(keys):
        key = str(keys[int(np.argmax(np.bincount(codes[codes >= 0], minlength=len(keys))))])
        o = pos[pos["source"] == key]
        role = role_of(voyage, key)
        notes.append(
            f"no GNSS or INS role: DR fixes and reference from position source {key}"
            + (f" (role {role})" if role else "")
            + "; map the receiver with --role KEY=gnss to choose another"
        )
        t, la, lo = dedupe_sorted(
            o["time_ns"].to_numpy(np.int64),
            o["lat_rad"].to_numpy(float),
            o["lon_rad"].to_numpy(float),
        )
        return t, la, lo, key
    missing.append("no position fix: the DR has no start position and no reference")
    return None


def fix_source_key(voyage: Voyage, fdesc: str) -> str | None:
    """The source key of the reference fixes ('gnss': the first GNSS source)."""
    if fdesc == "gnss":
        keys = voyage.role_sources("gnss")
        return keys[0] if keys else None
    if fdesc == "ins_mean":
        return None
    return fdesc


def ref_gap_s(t_ns: np.ndarray) -> float:
    """How far apart two reference positions may be to interpolate between them:
    REF_MAX_GAP_S, or 2.5 typical intervals for a slowly logged reference."""
    if t_ns.size < 2:
        return REF_MAX_GAP_S
    return max(REF_MAX_GAP_S, 2.5 * float(np.median(np.diff(t_ns))) / 1e9)


# ----------------------------------------------------------------- the DR grid


@dataclass(frozen=True)
class GridSeries:
    """Heading and log speed held onto the DR grid (NaN where the held sample is too old)."""

    grid_ns: np.ndarray  #: every DR_STEP_S, silences longer than DR_SILENCE_S left out
    heading_rad: np.ndarray  #: true heading (B2)/(B3)
    speed_mps: np.ndarray  #: longitudinal log speed
    transverse_mps: np.ndarray | None  #: None without a two-component log


def hold(
    t_src_ns: np.ndarray, values: np.ndarray, t_grid_ns: np.ndarray, max_age_ns: int
) -> np.ndarray:
    """The last sample at or before each grid time, NaN where it is older than ``max_age_ns``.

    Sample-and-hold, as (B20) holds the velocity over a step; nothing is interpolated."""
    return hold_at(t_src_ns, values, t_grid_ns, max_age_ns)


def dr_grid(
    th: np.ndarray, tv: np.ndarray, t_first: int, t_last: int, step_ns: int, silence_ns: int
) -> tuple[np.ndarray, list[tuple[int, int]]]:
    """The DR time grid: every ``step_ns`` (aligned to multiples of it) from ``t_first`` to
    ``t_last``, leaving out silences of both heading and speed longer than ``silence_ns``
    (the track breaks over them anyway).  One stray record dated years away used to make
    a grid of years (126 million points; fuzz).  Returns (grid, skipped (from, to) pairs)."""
    u = unique_sorted(np.concatenate([th, tv]))
    u = u[(u >= t_first) & (u <= t_last)]
    cut = np.flatnonzero(np.diff(u) > silence_ns)
    starts = np.concatenate(([u[0]], u[cut + 1]))
    ends = np.concatenate((u[cut], [u[-1]]))
    parts = []
    for a, b in zip(starts.tolist(), ends.tolist(), strict=True):
        a0 = a - a % step_ns + (step_ns if a % step_ns else 0)
        parts.append(np.arange(a0, b + 1, step_ns, dtype=np.int64))
    skipped = list(zip(u[cut].tolist(), u[cut + 1].tolist(), strict=True))
    return np.concatenate(parts), skipped


def _hold_age_ns(t_ns: np.ndarray) -> int:
    """A held sample older than this is missing at the grid time (dead_reckon bridges
    such gaps up to max_gap_s): two grid steps or two typical intervals."""
    typical_s = 2.0 * np.median(np.diff(t_ns)) / 1e9 if t_ns.size > 1 else 0
    return int(max(2.0 * DR_STEP_S, typical_s) * NS_PER_S)


def grid_series(
    heading: HeadingSeries, speed: SpeedSeries, missing: list[str], notes: list[str]
) -> GridSeries | None:
    """Hold ``heading`` (:func:`heading_series`) and ``speed`` (:func:`speed_series`) onto
    the DR grid where both overlap; None (and said in ``missing``) where they do not."""
    th, hdg, _ = heading
    tv, stw, stw_y, _, _ = speed
    step_ns = int(DR_STEP_S * NS_PER_S)
    t_first = max(int(th[0]), int(tv[0]))
    t_last = min(int(th[-1]), int(tv[-1]))
    if t_last - t_first < 2 * step_ns:
        missing.append("dead reckoning: heading and speed do not overlap in time")
        return None
    grid, skipped = dr_grid(th, tv, t_first, t_last, step_ns, int(DR_SILENCE_S * NS_PER_S))
    if grid.size < 3:
        missing.append("dead reckoning: heading and speed do not overlap in time")
        return None
    for a, b in skipped:
        notes.append(
            f"heading and speed both silent for {(b - a) / NS_PER_S / 3600:,.1f} h "
            f"({pd.Timestamp(a, tz='UTC'):%Y-%m-%d %H:%M:%S} to "
            f"{pd.Timestamp(b, tz='UTC'):%Y-%m-%d %H:%M:%S} UTC): the dead-reckoning "
            "grid skips it (the track breaks there)"
        )
    age = _hold_age_ns(tv)
    v_g = hold(tv, stw, grid, age)
    vy_g = hold(tv, stw_y, grid, age) if np.any(np.isfinite(stw_y)) else None
    if vy_g is not None and np.any(~np.isfinite(vy_g) & np.isfinite(v_g)):
        vy_g = np.where(np.isfinite(vy_g), vy_g, 0.0)
    return GridSeries(grid, hold(th, hdg, grid, _hold_age_ns(th)), v_g, vy_g)


@dataclass(frozen=True)
class DRInputs:
    """What the DR ran on, kept for the current filter and the calibration."""

    t0_ns: int
    time_s: np.ndarray
    #: the DR velocity (water mode: through the water, no current), NaN outside legs
    vn_mps: np.ndarray
    ve_mps: np.ndarray
    #: course (B2)/(B3) + leeway or drift angle (B5)/(B6), NaN where missing
    heading_rad: np.ndarray
    speed_mps: np.ndarray  #: speed (B1) through the water or over the ground, NaN where missing
    ref_gap_s: float  #: reference positions are interpolated across gaps up to this
    mode: str  #: 'water' (relative log) or 'ground' (absolute log)
    epoch_interval_s: float = 600.0  #: the DR's epoch spacing (the old filter's fix spacing)
    estimated: EstimatedPosition | None = None  #: where the model was learned (learn = true)


# ---------------------------------------------------------------- NMEA 2000 positions


def without_rapid_positions(voyage: Voyage, notes: list[str]) -> Voyage:
    """``voyage`` without the 129025 positions (rapid update: no time of fix, 1e-7 deg)
    of NMEA 2000 devices that also send 129029 (the full fix with its own time).  Both
    kept, one receiver's fixes interleave on two time bases (the frame's and the fix's,
    ~0.5 s apart on aava-n2k.data) and the steps between them look like jumps to the
    plausibility checks.  The frames of the voyage itself are not changed (``dracc
    records`` gives every record)."""
    pos = voyage.frames.get("position")
    if pos is None or not len(pos):
        return voyage
    names = [str(c) for c in pos["sentence"].cat.categories]
    if "PGN129025" not in names or "PGN129029" not in names:
        return voyage
    sent = pos["sentence"].cat.codes.to_numpy()
    src = pos["source"].cat.codes.to_numpy()
    full = np.unique(src[sent == names.index("PGN129029")])
    rapid = (sent == names.index("PGN129025")) & np.isin(src, full)
    if not rapid.any():
        return voyage
    keys = sorted({str(pos["source"].cat.categories[c]) for c in np.unique(src[rapid])})
    notes.append(
        f"{int(rapid.sum())} rapid positions (PGN129025) of {', '.join(keys)} not used: "
        "the same device sends PGN129029, the full fix with its own time"
    )
    frames = dict(voyage.frames)
    frames["position"] = pos[~rapid].reset_index(drop=True)
    return dataclasses.replace(voyage, frames=frames)
