"""plausibility / ``jump``: the step between consecutive fixes against the step the
ship's own motion predicts (the package docstring gives the rule), and
:func:`plausibility_checks`, which adds the frozen/stuck/out-of-range checks of
:mod:`dracc.math.integrity.sensor_faults`."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import replace
from typing import Any

import numpy as np
import pandas as pd

from dracc.core.arrays import FloatArray
from dracc.core.config import FaultsConfig, IntegrityConfig
from dracc.core.geodesy import offset_ne_m
from dracc.core.timefmt import iso_utc
from dracc.core.units import NS_PER_S
from dracc.frames import Voyage
from dracc.math.faults import RepeatRun, SensorFault, faults_and_repeats
from dracc.math.integrity.helpers import (
    MAX_EVIDENCE,
    by_source,
    not_checked,
    role_of,
    statistic,
    tail_sigma,
    threshold,
    time_window,
)
from dracc.math.integrity.results import Check
from dracc.math.integrity.sensor_faults import fault_checks

__all__ = ["jump_check", "plausibility_checks"]


def steps_ne(g: pd.DataFrame) -> tuple[FloatArray, FloatArray]:
    """North/east metres of the fixes of ``g`` from its first fix."""
    lat = g["lat_rad"].to_numpy(float)
    lon = g["lon_rad"].to_numpy(float)
    n, e = offset_ne_m(lat, lon, lat[0], lon[0])
    return n, e


def _isolated(r: FloatArray, usable: np.ndarray) -> FloatArray:
    """``r_k - (r_{k-1} + r_{k+1}) / 2``: how far a step's innovation stands out from its
    neighbours' (an unusable or missing neighbour counts as 0)."""
    z = np.where(usable, r, 0.0)
    prev = np.concatenate(([0.0], z[:-1]))
    nxt = np.concatenate((z[1:], [0.0]))
    out: FloatArray = z - 0.5 * (prev + nxt)
    return out


#: (time ns, cumulative north m, cumulative east m) of the water track: compass and log
WaterTrack = tuple[np.ndarray, FloatArray, FloatArray]


def water_track(voyage: Voyage) -> WaterTrack | None:
    """The ship's own motion through the water, integrated from the compass and the log
    (true heading; a magnetic one with its deviation and variation where it sends them):
    ``n(t) = integral v cos(h) dt``, ``e(t) = integral v sin(h) dt`` at the heading
    times (trapezoids), the speed interpolated there.  None without both."""
    compass, log = voyage.role_sources("compass"), voyage.role_sources("log")
    if not compass or not log:
        return None
    h = voyage.frames["heading"]
    h = h[h["source"].isin(compass).to_numpy()]
    w = voyage.frames["water"]
    w = w[w["source"].isin(log).to_numpy()]
    ref = h["reference"].astype(object).to_numpy()
    hd = h["heading_rad"].to_numpy(float)
    corr = np.nan_to_num(h["deviation_rad"].to_numpy(float)) + np.nan_to_num(
        h["variation_rad"].to_numpy(float)
    )
    true = np.where(ref == "M", hd + corr, hd)
    ok = np.isfinite(true)
    th, true = h["time_ns"].to_numpy(np.int64)[ok], true[ok]
    stw = w["stw_mps"].to_numpy(float)
    wok = np.isfinite(stw)
    tw, stw = w["time_ns"].to_numpy(np.int64)[wok], stw[wok]
    if len(th) < 2 or len(tw) < 2:
        return None
    order = np.argsort(th, kind="stable")
    th, true = th[order], true[order]
    v = np.interp(th.astype(float), tw.astype(float), stw)
    dt = np.diff(th) / NS_PER_S
    vn, ve = v * np.cos(true), v * np.sin(true)
    cn = np.concatenate(([0.0], np.cumsum(0.5 * (vn[1:] + vn[:-1]) * dt)))
    ce = np.concatenate(([0.0], np.cumsum(0.5 * (ve[1:] + ve[:-1]) * dt)))
    return th, cn, ce


def _water_steps(
    t: np.ndarray, water: WaterTrack | None, max_gap_s: float
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """North/east water-track displacement over each step between fix times ``t`` (NaN
    where the water track does not cover the step), and the seconds of each step that
    fall in a hole of the water track (a heading gap longer than ``max_gap_s``): there
    the track holds the heading and speed of the hole's two ends (the trapezoid across
    it), and a turn inside the hole is unseen."""
    n = len(t) - 1
    if water is None or n <= 0:
        nan = np.full(max(n, 0), np.nan)
        return nan, nan.copy(), np.zeros(max(n, 0))
    th, cn, ce = water
    tf, thf = t.astype(float), th.astype(float)
    at_n = np.interp(tf, thf, cn)
    at_e = np.interp(tf, thf, ce)
    inside = (t >= th[0]) & (t <= th[-1])
    # G(t): the time spent in holes before t, piecewise linear over the heading times
    gap = np.diff(th) / NS_PER_S
    in_holes = np.concatenate(([0.0], np.cumsum(np.where(gap > max_gap_s, gap, 0.0))))
    hole = np.diff(np.interp(tf, thf, in_holes))
    good = inside[:-1] & inside[1:]
    dn = np.where(good, np.diff(at_n), np.nan)
    de = np.where(good, np.diff(at_e), np.nan)
    return dn, de, np.where(good, hole, 0.0)


def _running_median(x: FloatArray) -> FloatArray:
    """Centred running median over 11 steps (NaN steps left out; at least 3 needed)."""
    out: FloatArray = pd.Series(x).rolling(11, center=True, min_periods=3).median().to_numpy()
    return out


def jump_check(
    key: str,
    role: str | None,
    g: pd.DataFrame,
    frozen: Sequence[SensorFault | RepeatRun],
    cfg: IntegrityConfig,
    water: WaterTrack | None = None,
) -> Check:
    """Step innovation against the ship's own motion (module docstring)."""
    ok = (
        (g["quality"].to_numpy() != 0)
        & np.isfinite(g["lat_rad"].to_numpy(float))
        & np.isfinite(g["lon_rad"].to_numpy(float))
    )
    g = g[ok]
    t = g["time_ns"].to_numpy(np.int64)
    keep = np.concatenate(([True], np.diff(t) > 0)) if len(t) else np.zeros(0, bool)
    g, t = g[keep], t[keep]
    win = time_window(t)
    if len(t) < 30:
        return not_checked(
            "plausibility",
            "jump",
            key,
            role,
            "innovation",
            "m",
            "",
            f"{key}: too few valid fixes ({len(t)}) to learn the step noise",
            f"{len(t)} valid fixes (30 needed)",
            window=win,
        )
    north, east = steps_ne(g)
    dt = np.diff(t) / NS_PER_S
    dn, de = np.diff(north), np.diff(east)
    cadence = float(np.median(dt))
    # the ship's own motion: the water track (compass and log) over each step, where it
    # covers it, so a turn or a change of speed is predicted; what is left (the current,
    # the compass and log errors) changes slowly: its running median over 11 steps.
    # Where there is no water track, the fixes' own recent velocity (running median)
    wn, we, hole_s = _water_steps(t, water, max_gap_s=max(10.0, cadence))
    has_w = np.isfinite(wn) & np.isfinite(we)
    un, ue = _running_median(dn / dt), _running_median(de / dt)
    vn = np.nan_to_num(_running_median(np.where(has_w, (dn - wn) / dt, np.nan)))
    ve = np.nan_to_num(_running_median(np.where(has_w, (de - we) / dt, np.nan)))
    pn = np.where(has_w, wn + vn * dt, un * dt)
    pe = np.where(has_w, we + ve * dt, ue * dt)
    rn, re_ = dn - pn, de - pe
    # the time of a step no instrument saw the ship move through: a hole in the water
    # track, or, predicted from the fixes, whatever the step lasts beyond one cadence.
    # A manoeuvre at the ship's speed over that time can move the fix by up to
    # speed * unseen: that much of the innovation is no evidence of a jump
    unseen_s = np.where(has_w, hole_s, np.maximum(dt - cadence, 0.0))
    allow_m = np.nan_to_num(np.hypot(un, ue)) * unseen_s
    size = np.hypot(rn, re_)
    with np.errstate(invalid="ignore", divide="ignore"):
        shrink = np.where(size > 0, np.maximum(size - allow_m, 0.0) / size, 0.0)
    rn, re_ = rn * shrink, re_ * shrink
    # steps over a drop-out (availability) or out of a frozen run (the unit catching
    # up, a 'frozen' fault) are not jumps
    usable = dt <= 10.0 * cadence
    for f in frozen:
        # a frozen unit's steps are not fixes at all; a fix held at rest is, but the step
        # out of the hold is the unit catching up
        held_from = (
            f.start_ns if isinstance(f, SensorFault) or f.fault is not None else f.end_ns + 1
        )
        usable &= ~((t[1:] >= held_from) & (t[1:] <= f.end_ns + int(3 * cadence * NS_PER_S)))
    quantum = 0.05  # m: below any logged resolution that can show a jump
    sn = max(tail_sigma(rn[usable]), quantum)
    se = max(tail_sigma(re_[usable]), quantum)
    n_steps = int(usable.sum())
    gate = -2.0 * math.log(cfg.false_alarm / max(n_steps, 1))  # chi2_2 survival exp(-x/2)
    d2 = np.where(usable, (rn / sn) ** 2 + (re_ / se) ** 2, 0.0)
    # a jump is a displaced fix, alone: its innovation stands out from its neighbours'
    # (a fix off and back: +d then -d; a step: +d once).  A change of speed or a turn the
    # running median has not caught up with gives the same innovation on several steps
    # in a row: not a jump.  i_k = r_k - (r_{k-1} + r_{k+1}) / 2, scaled by its own
    # robust sigma, must pass the gate as well
    iso_n, iso_e = _isolated(rn, usable), _isolated(re_, usable)
    isn = max(tail_sigma(iso_n[usable]), quantum)
    ise = max(tail_sigma(iso_e[usable]), quantum)
    d2_iso = np.where(usable, (iso_n / isn) ** 2 + (iso_e / ise) ** 2, 0.0)
    # a step within the position accuracy the standards ask of a receiver is not a finding,
    # however sure the statistics are that the fix moved (a satellite change, multipath)
    flagged = (d2 > gate) & (d2_iso > gate) & (np.hypot(rn, re_) > cfg.jump_floor_m)
    min_jump = max(math.sqrt(gate) * max(sn, se), cfg.jump_floor_m)
    evidence: list[dict[str, Any]] = []
    lines = g["line"].to_numpy()
    quality = g["quality"].to_numpy()
    idx = np.flatnonzero(flagged)
    for k in idx[:MAX_EVIDENCE]:
        evidence.append(
            {
                "time": iso_utc(unit="ms", time_ns=t[k + 1]),
                "line": int(lines[k + 1]),
                "step_m": float(math.hypot(dn[k], de[k])),
                "expected_step_m": float(math.hypot(pn[k], pe[k])),
                "innovation_m": float(math.hypot(dn[k] - pn[k], de[k] - pe[k])),
                # its direction: a fix off and back cancels (dracc.math.integrity.causes)
                "innovation_north_m": float(dn[k] - pn[k]),
                "innovation_east_m": float(de[k] - pe[k]),
                "unseen_s": float(unseen_s[k]),
                "allowance_m": float(allow_m[k]),
                "dt_s": float(dt[k]),
                "flagged_valid": bool(quality[k + 1] > 0),
            }
        )
    worst = float(np.sqrt(d2.max())) if n_steps else math.nan
    if len(idx):
        big = max(e["innovation_m"] for e in evidence)
        msg = (
            f"{key}: {len(idx)} position jump(s) against the ship's motion, the largest "
            f"{big:.0f} m (gate {min_jump:.1f} m: the night's step noise {sn:.2f}/{se:.2f} m "
            f"N/E, at least {cfg.jump_floor_m:g} m)"
        )
    else:
        msg = f"{key}: no jump; the gate would have seen a jump of {min_jump:.1f} m or more"
    return Check(
        "plausibility",
        "jump",
        key,
        role,
        "fail" if len(idx) else "pass",
        statistic("max_normalised_innovation", worst, "sigma"),
        threshold(
            math.sqrt(gate),
            "sigma",
            f"chi-square(2) gate at {cfg.false_alarm:g} per "
            f"night over {n_steps} steps, and an innovation beyond [integrity] "
            f"jump_floor_m = {cfg.jump_floor_m:g} m",
        ),
        win,
        cfg.false_alarm,
        msg,
        tuple(evidence),
        detail={
            "min_detectable_m": min_jump,
            "step_sigma_n_m": sn,
            "step_sigma_e_m": se,
            "steps": n_steps,
            "cadence_s": cadence,
            "jumps": int(len(idx)),
        },
    )


def plausibility_checks(
    voyage: Voyage, cfg: IntegrityConfig, faults_cfg: FaultsConfig | None = None
) -> tuple[list[Check], list[SensorFault]]:
    """The jump, frozen, stuck and out-of-range checks; ``faults_cfg`` the user's
    ``[faults]`` thresholds (what proves motion and a turn), with the night's windows."""
    fcfg = replace(
        faults_cfg or FaultsConfig(), frozen_min_s=cfg.frozen_min_s, stuck_min_s=cfg.frozen_min_s
    )
    faults, repeats = faults_and_repeats(voyage, fcfg)
    checks = []
    water = water_track(voyage)
    for key, g in by_source(voyage.frames["position"]):
        # every held fix, faulty or at rest: the step out of it is the unit catching up
        frozen = [r for r in repeats if r.source == key and r.kind == "frozen"]
        info = voyage.sources.get(key)
        if info is not None and info.interleaved:  # several units: a step is no evidence
            checks.append(
                not_checked(
                    "plausibility",
                    "jump",
                    key,
                    role_of(voyage, key),
                    "innovation",
                    "m",
                    "",
                    f"{key}: several units behind one key ({info.interleaved})",
                    "several units interleaved under one key",
                )
            )
            continue
        checks.append(jump_check(key, role_of(voyage, key), g, frozen, cfg, water))
    checks += fault_checks(
        voyage,
        faults,
        "frozen",
        ("frozen",),
        ("position",),
        "bit-identical positions this long while another source shows the ship moving "
        "farther than three steps of the source's resolution",
        cfg.frozen_min_s,
        "s",
        repeats,
    )
    checks += fault_checks(
        voyage,
        faults,
        "stuck",
        ("stuck_heading",),
        ("heading",),
        "a bit-identical heading this long while another heading source (or COG) turns "
        "beyond its own noise by more than three steps of the source's resolution",
        cfg.frozen_min_s,
        "s",
        repeats,
    )
    checks += fault_checks(
        voyage,
        faults,
        "out_of_range",
        ("out_of_range",),
        ("position", "heading", "ground", "water", "rot"),
        "latitude beyond 90 deg, longitude beyond 180 deg, heading or course "
        "outside [0, 360) deg, negative SOG, speeds beyond [faults] "
        "max_speed_kn, rate of turn beyond [faults] max_rot_deg_per_min",
        0,
        "count",
    )
    return checks, faults
