"""The current stage: set and drift over the voyage.

With a water log the current is what moves the DR off the reference: the one the
estimated position learned (:mod:`dracc.math.ep`, ``learn = true``) or, without it,
the Kalman filter of the aided-DR paper (:mod:`dracc.math.current`).  A ground log
already moves with the current: nothing to estimate.
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Sequence

import numpy as np

from dracc.core.arrays import unique_sorted
from dracc.core.config import DeadReckoningConfig
from dracc.core.geodesy import wrap_2pi
from dracc.core.units import KN_MPS
from dracc.core.vocabulary import AIDED_DR_PAPER, DR_OVER_GROUND, FIX_UPDATED_EP
from dracc.ingest.timed_observations import TimedObservation
from dracc.math.current import CurrentModel, estimate_current
from dracc.math.ellipse import error_ellipse
from dracc.math.ep.aided import (
    TimedUpdate,
    epoch_rows,
    interval_rows,
    interval_study,
    run_aided,
    thinned_fixes,
)
from dracc.math.ep.interval import StudyModel, learned_interval_study
from dracc.math.fix import library_observation
from dracc.math.fusion import PositionFix
from dracc.pipeline.results import CurrentSection, Estimate, EstimatedPositionSection
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
        f"the current the {DR_OVER_GROUND} uses: a persistent current plus its "
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


# ------------------------------------------------- the estimated position (seeds/003)


def _stretches(dr: DRInputs) -> Iterator[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """(t_s, course_rad, speed_mps) on the CURRENT_STEP_S grid over each stretch of water velocity."""
    step = max(1, int(round(CURRENT_STEP_S / DR_STEP_S)))
    t, vn, ve = dr.time_s[::step], dr.vn_mps[::step], dr.ve_mps[::step]
    ok = np.isfinite(vn) & np.isfinite(ve)
    edges = np.flatnonzero(np.diff(np.concatenate([[0], ok.astype(np.int8), [0]])))
    for a, b in zip(edges[::2], edges[1::2], strict=True):
        if b - a >= 3:
            yield t[a:b], np.arctan2(ve[a:b], vn[a:b]), np.hypot(vn[a:b], ve[a:b])


def _study_note(learned: StudyModel | None) -> str:
    """What the fix-interval study ran on, and what its containment is to be compared with."""
    if learned is None:
        return (
            "fix-interval study: on the configured model ([dead_reckoning] current_kn, "
            "log_noise_kn, compass_noise_deg, fix_sigma_m; learn = false); a fix counts as "
            "inside when its innovation lies in the 95 % ellipse (a correct model gives 95 %)"
        )
    top = int(np.argmax(learned.weights))
    hp = learned.hyper
    return (
        "fix-interval study: on the learned model (the current's variation, the short-term "
        "noise and the fix noise of the "
        f"{learned.weights.size} grid model(s) holding the weight, the best "
        f"{learned.weights[top]:.3f}: σ_c {hp.current_sigma_mps[top] / KN_MPS:.2f} kn, "
        f"τ_c {hp.current_tau_s[top] / 3600:g} h, σ_n {hp.noise_sigma_mps[top] / KN_MPS:.2f} kn, "
        f"fix {hp.fix_sigma_m[top]:.1f} m; the learned heading and log-scale corrections "
        "applied, their uncertainty kept); the current estimated by the study's filter from "
        "its own fixes; runs start every 15 min (one per interval when longer); the "
        "prediction's covariance scaled by a factor learned from the study's earlier fixes "
        f"(covariance matching, as for the {DR_OVER_GROUND}); a fix counts as inside when its "
        "innovation lies in the 95 % ellipse of that prediction, and 'a correct model' is "
        "the probability the study states: the share of its earlier fixes inside their "
        "ellipses, shrunk to the probability the model puts there (worth one fix)"
    )


def estimated_position(
    dr: DRInputs,
    fixes: Fixes,
    cfg: DeadReckoningConfig,
    observations: Sequence[TimedObservation],
    intervals_s: Sequence[float],
    missing: list[str],
) -> EstimatedPositionSection | None:
    """The aided-DR EP (dracc.math.ep.aided) of a water log over each stretch of DR: started
    at a fix, updated by a fix every ``epoch_interval_s`` and by the file's observations;
    with ``intervals_s``, the update-interval study (GNSS fixes only)."""
    if dr.mode != "water":
        if observations or intervals_s:
            missing.append(
                f"{FIX_UPDATED_EP} not computed: the log measures over the ground, so there "
                "is no current for its filter to learn"
            )
        return None
    ft, flat, flon, fdesc = fixes
    fix_s = (ft - dr.t0_ns) / 1e9
    model = CurrentModel.from_config(cfg)
    # the study on the learned model where there is one (learn = true), else the configured
    learned = StudyModel.from_learned(dr.estimated.model) if dr.estimated is not None else None
    obs = [
        ((o.time_ns - dr.t0_ns) / 1e9, library_observation(o.spec, []).obs, o.spec.label)
        for o in observations
    ]
    cols: list[list[np.ndarray]] = [[] for _ in range(5)]
    kinds: list[str] = []
    used: set[int] = set()
    n_fix = n_lop = 0
    study: list[list[tuple[np.ndarray, ...]]] = []
    for ts, course, speed in _stretches(dr):
        if intervals_s and learned is not None:
            vn, ve = speed * np.cos(course), speed * np.sin(course)
            study.append(
                list(learned_interval_study(ts, vn, ve, fix_s, flat, flon, learned, intervals_s))
            )
        elif intervals_s:
            study.append(
                list(
                    interval_study(
                        ts, course, speed, fix_s, flat, flon, cfg.fix_sigma_m, model, intervals_s
                    )
                )
            )
        pick = thinned_fixes(fix_s, ts[0], ts[-1], dr.epoch_interval_s)
        if pick.size == 0:
            continue
        t0 = fix_s[pick[0]]
        keep = ts >= t0
        if keep.sum() < 2:
            continue
        ups = [
            TimedUpdate(
                float(fix_s[i]), PositionFix.from_sigma(flat[i], flon[i], cfg.fix_sigma_m), "gnss"
            )
            for i in pick[1:]
        ]
        mine = [j for j, (t, _, _) in enumerate(obs) if t0 < t <= ts[keep][-1]]
        ups += [TimedUpdate(obs[j][0], obs[j][1], obs[j][2]) for j in mine]
        used.update(mine)
        start = PositionFix.from_sigma(flat[pick[0]], flon[pick[0]], cfg.fix_sigma_m)
        run = run_aided(ts[keep], course[keep], speed[keep], start, ups, model)
        n_fix += sum(u.label == "gnss" for u in run.updates)
        n_lop += sum(u.label != "gnss" for u in run.updates)
        rows = epoch_rows(run, dr.epoch_interval_s)
        tr = run.track
        cols[0].append(tr.t_s[rows.index])
        cols[1].append(tr.lat_rad[rows.index])
        cols[2].append(tr.lon_rad[rows.index])
        cols[3].append(tr.position_cov_m2[rows.index])
        cols[4].append(rows.since_update_s)
        kinds += rows.update_kind
    if not kinds:
        missing.append(f"{FIX_UPDATED_EP} not computed: no fix starts a stretch of dead reckoning")
        return None
    t, lat, lon, P, since = (np.concatenate(c) for c in cols)
    smaj, smin, orient = error_ellipse(P)
    outside = len(obs) - len(used)
    notes = [
        f"{FIX_UPDATED_EP}: the filter of {AIDED_DR_PAPER}, a Gauss-Markov current estimated "
        f"from a {fdesc} fix "
        f"every {dr.epoch_interval_s:g} s"
        + (f" and {n_lop} lines of position or fixes from the observation file" if obs else "")
    ]
    if outside:
        notes.append(
            f"{outside} observation(s) of the file lie outside the dead reckoning: not used"
        )
    if intervals_s:
        notes.append(_study_note(learned))
    for o in observations:  # datums (seeds/004 §2): say what moved each charted position
        rec = o.spec.datum
        if rec is not None:
            op = rec.transformation
            acc = "" if op.accuracy_m is None else f", ±{op.accuracy_m:g} m"
            code = f" ({op.operation_code}{acc})" if op.operation_code else ""
            notes.append(
                f"{o.spec.label}: charted on {op.datum}, moved to WGS-84 by {op.operation}"
                f"{code}: {max(rec.shift_m):.1f} m"
                + (f"; {op.missing_operation} needs a grid not installed" if op.fallback else "")
            )
    return EstimatedPositionSection(
        time_ns=(t * 1e9).astype(np.int64) + dr.t0_ns,
        lat_rad=lat,
        lon_rad=lon,
        radius_2m_m=2.0 * np.sqrt(P[:, 0, 0] + P[:, 1, 1]),
        semi_major_m=smaj,
        semi_minor_m=smin,
        orientation_rad=orient,
        since_update_s=since,
        update_kind=tuple(kinds),
        fix_interval_s=dr.epoch_interval_s,
        n_fix_updates=n_fix,
        n_lop_updates=n_lop,
        observations_outside=outside,
        interval_study=(
            interval_rows(
                intervals_s,
                [
                    tuple(np.concatenate([s[i][j] for s in study]) for j in range(len(study[0][i])))
                    for i in range(len(intervals_s))
                ],
                "configured" if learned is None else "learned",
            )
            if study
            else ()
        ),
        notes=tuple(notes),
    )
