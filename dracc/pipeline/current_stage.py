"""The current stage: set and drift over the voyage.

With a water log the current is what moves the DR off the reference: the one the
estimated position learned (:mod:`dracc.math.ep`, ``learn = true``) or, without it,
the Kalman filter of the aided-DR paper (:mod:`dracc.math.current`).  A ground log
already moves with the current: nothing to estimate.
"""

from __future__ import annotations

import math

import numpy as np

from dracc.core.arrays import unique_sorted
from dracc.core.config import DeadReckoningConfig
from dracc.core.geodesy import wrap_2pi
from dracc.core.units import KN_MPS
from dracc.math.current import CurrentModel, estimate_current
from dracc.math.fusion import PositionFix
from dracc.pipeline.results import CurrentSection, Estimate
from dracc.pipeline.selection import DR_STEP_S, DRInputs, Fixes

#: the current filter runs on a grid of this step, updated by a fix every epoch interval
CURRENT_STEP_S = 10.0


def current(
    dr: DRInputs, fixes: Fixes, cfg: DeadReckoningConfig, missing: list[str]
) -> CurrentSection | None:
    """The voyage's current for a water log (learned or filtered); None, said in
    ``missing``, for a ground log or too few fixes."""
    if dr.mode == "water" and dr.estimated is not None:
        return current_learned(dr, fixes)
    if dr.mode == "water":
        return current_filtered(dr, fixes, cfg, missing)
    missing.append(
        "current not estimated: the log measures over the ground (VBW ground "
        "components), so the DR already moves with the current"
    )
    return None


def drift_and_set(north_mps: float, east_mps: float) -> tuple[float, float]:
    """Drift (m/s) and set (towards, rad in [0, 2 pi)) of a current (north, east)."""
    return math.hypot(north_mps, east_mps), float(wrap_2pi(math.atan2(east_mps, north_mps)))


def current_learned(dr: DRInputs, fixes: Fixes) -> CurrentSection | None:
    """Set and drift as the estimated position uses them (dracc.math.ep).

    The voyage figures are the persistent current learned from every fix (the filter's
    final posterior of cbar, mixed over its grid of models), with its 1-sigma; the series
    for the plot is the filtered current (cbar plus its variation) at each filter step,
    causal, after the first fix.
    """
    assert dr.estimated is not None  # learn = true
    m = dr.estimated.model
    h = m.history
    upd = np.flatnonzero(h.updated)
    if upd.size < 2:
        return None
    w = m.final_weights
    x = w @ m.final_x
    dev = m.final_x[:, 2:4] - x[2:4]
    P = np.einsum("m,mij->ij", w, m.final_P[:, 2:4, 2:4] + dev[:, :, None] * dev[:, None, :])
    mean_n, mean_e = float(x[2]), float(x[3])
    drift, set_rad = drift_and_set(mean_n, mean_e)
    u = np.array([mean_n, mean_e]) / drift if drift > 0 else np.array([1.0, 0.0])
    sigma_d = math.sqrt(max(float(u @ P @ u), 0.0))  # along the drift
    v = np.array([-u[1], u[0]])
    sigma_set = math.sqrt(max(float(v @ P @ v), 0.0)) / drift if drift > 0 else math.nan
    keep = slice(int(upd[0]) + 1, None)
    cn, ce = h.current_ne_mps[keep, 0], h.current_ne_mps[keep, 1]
    note = (
        f"the current the estimated position uses: a persistent current plus its "
        f"Gauss-Markov variation, filtered causally from the {fixes[3]} fixes every "
        f"{m.step_s:g} s ({upd.size} updates) with the compass and log corrections beside "
        "it; voyage figures: the persistent current learned from every fix, with its "
        "1-sigma; the plot: the filtered current at each step"
    )
    return CurrentSection(
        set_deg=Estimate(math.degrees(set_rad), math.degrees(sigma_set)),
        drift_kn=Estimate(drift / KN_MPS, sigma_d / KN_MPS),
        time_ns=(h.time_s[keep] * 1e9).astype(np.int64) + dr.t0_ns,
        set_rad=wrap_2pi(np.arctan2(ce, cn)),
        drift_mps=np.hypot(cn, ce),
        drift_sigma_mps=h.current_sigma_mps[keep],
        n_updates=int(upd.size),
        notes=(note,),
    )


def current_filtered(
    dr: DRInputs, fixes: Fixes, cfg: DeadReckoningConfig, missing: list[str]
) -> CurrentSection | None:
    """Set and drift from the Kalman filter of the aided-DR paper (dracc.math.current).

    The filter runs on a CURRENT_STEP_S grid over each stretch where the DR has a water
    velocity, updated by a fix every ``epoch_interval_s``.
    """
    ft, flat, flon, fdesc = fixes
    step = max(1, int(round(CURRENT_STEP_S / DR_STEP_S)))
    t = dr.time_s[::step]
    vn = dr.vn_mps[::step]
    ve = dr.ve_mps[::step]
    ok = np.isfinite(vn) & np.isfinite(ve)
    fix_s = (ft - dr.t0_ns) / 1e9
    model = CurrentModel.from_config(cfg)
    # contiguous stretches of valid velocity
    edges = np.flatnonzero(np.diff(np.concatenate([[0], ok.astype(np.int8), [0]])))
    times, sets, drifts, sig, cn_all, ce_all = [], [], [], [], [], []
    n_updates = 0
    for a, b in zip(edges[::2], edges[1::2], strict=True):
        if b - a < 3:
            continue
        ts = t[a:b]
        sel = np.flatnonzero((fix_s >= ts[0]) & (fix_s <= ts[-1]))
        if sel.size < 2:
            continue
        # one fix per epoch interval (the first at or after each multiple)
        grid = np.arange(ts[0], ts[-1], dr.epoch_interval_s)
        pick = unique_sorted(np.searchsorted(fix_s, grid, side="left"))
        pick = pick[(pick < fix_s.size)]
        pick = pick[(fix_s[pick] >= ts[0]) & (fix_s[pick] <= ts[-1])]
        if pick.size < 2:
            continue
        start_i = pick[0]
        obs = [
            (float(fix_s[i]), PositionFix.from_sigma(flat[i], flon[i], cfg.fix_sigma_m))
            for i in pick[1:]
        ]
        t_run = ts[ts >= fix_s[start_i]]
        if t_run.size < 2:
            continue
        i0 = np.searchsorted(ts, t_run[0])
        course = np.arctan2(ve[a + i0 : b], vn[a + i0 : b])
        speed = np.hypot(vn[a + i0 : b], ve[a + i0 : b])
        # the filter starts at the first fix, advanced to the first epoch by the DR velocity
        start = PositionFix.from_sigma(flat[start_i], flon[start_i], cfg.fix_sigma_m)
        obs = [o for o in obs if t_run[0] <= o[0] <= t_run[-1]]
        ct = estimate_current(t_run, course, speed, start, obs, model)
        n_updates += len(ct.updates)
        keep = ct.t_s >= (obs[0][0] if obs else np.inf)  # report after the first update
        times.append((ct.t_s[keep] * 1e9).astype(np.int64) + dr.t0_ns)
        sets.append(ct.set_rad[keep])
        drifts.append(ct.drift_mps[keep])
        sig.append(ct.drift_sigma_mps[keep])
        cn_all.append(ct.current_north_mps[keep])
        ce_all.append(ct.current_east_mps[keep])
    if not times or not sum(x.size for x in times):
        missing.append(
            "current not estimated: fewer than two fixes within a stretch of dead reckoning"
        )
        return None
    cn = np.concatenate(cn_all)
    ce = np.concatenate(ce_all)
    s_d = np.concatenate(sig)
    drift, set_rad = drift_and_set(float(np.mean(cn)), float(np.mean(ce)))
    sigma_d = float(np.sqrt(np.mean(s_d**2)))
    sigma_set = sigma_d / drift if drift > 0 else math.nan
    note = (
        f"voyage figures: the mean of the filtered current over {cn.size} filter epochs "
        f"({CURRENT_STEP_S:g} s grid, a {fdesc} fix every {dr.epoch_interval_s:g} s); sigma: "
        "the filter's RMS 1-sigma (not reduced by averaging). Over a leg the filter cannot tell "
        "current from a constant log or compass error: both are in these figures"
    )
    return CurrentSection(
        set_deg=Estimate(math.degrees(set_rad), math.degrees(sigma_set)),
        drift_kn=Estimate(drift / KN_MPS, sigma_d / KN_MPS),
        time_ns=np.concatenate(times),
        set_rad=np.concatenate(sets),
        drift_mps=np.concatenate(drifts),
        drift_sigma_mps=s_d,
        n_updates=n_updates,
        notes=(note,),
    )
