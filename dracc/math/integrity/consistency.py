"""consistency between independent sources: ``velocity`` (each INS against the others'
mean, GNSS against the INS mean, over Schuler periods), ``heading`` (compass against
the INS mean) and ``speed`` (log against the ground speed less current)."""

from __future__ import annotations

import numpy as np
import pandas as pd

from dracc.core.arrays import FloatArray
from dracc.core.config import IntegrityConfig
from dracc.core.geodesy import angdiff, circmean, offset_ne_m
from dracc.core.timefmt import iso_utc
from dracc.core.units import DEG_RAD, KN_MPS, NS_PER_S
from dracc.core.vocabulary import INS_ROLES
from dracc.frames import Voyage
from dracc.math.deviation.sampling import align_at, sample_unit, unit_series_from_voyage
from dracc.math.integrity.helpers import (
    MAX_EVIDENCE,
    covered_instants,
    not_checked,
    runs,
    shifted_index,
    statistic,
    tail_sigma,
    threshold,
    time_window,
    z_two_sided,
)
from dracc.math.integrity.results import Check

__all__ = ["heading_consistency", "log_residual", "speed_consistency", "velocity_consistency"]

SCHULER_PERIOD_S = 84.4 * 60.0  #: 2 pi sqrt(R/g)
#: IMO A.824(19) speed accuracy: 2 % of the speed or 0.2 kn, whichever is greater
SPEED_ACCURACY_FRACTION = 0.02
SPEED_ACCURACY_MIN_MPS = 0.2 * KN_MPS


def speed_accuracy_mps(speed_mps: float) -> float:
    return max(SPEED_ACCURACY_MIN_MPS, SPEED_ACCURACY_FRACTION * speed_mps)


def velocity_consistency(
    voyage: Voyage, cfg: IntegrityConfig, start_ns: int, end_ns: int
) -> list[Check]:
    """consistency / velocity of every INS against the others' mean and GNSS against the INS mean."""
    roles = [r for r in (*INS_ROLES, "gnss") if voyage.role_sources(r)]
    ins = [r for r in roles if r in INS_ROLES]
    step_s = cfg.consistency_interval_s
    lag = int(round(SCHULER_PERIOD_S / step_s))
    gate = cfg.velocity_gate_kn * KN_MPS
    rule = (
        "change of the Schuler-period (84.4 min) velocity of the difference from one period "
        "to the next beyond [integrity] velocity_gate_kn"
    )
    targets = [
        r for r in roles if (r in INS_ROLES and len(ins) >= 3) or (r == "gnss" and len(ins) >= 2)
    ]
    checks: list[Check] = []
    why = None
    if (end_ns - start_ns) / NS_PER_S < 2 * SCHULER_PERIOD_S + 30 * step_s:
        why = "the night is shorter than two Schuler periods (2 x 84.4 min)"
    elif len(ins) < 2:
        why = f"{len(ins)} INS unit(s): no mean of independent units to compare with"
    for r in roles:
        if r not in targets or why:
            reason = why or (
                "only two INS units: a disagreement cannot be attributed to one of them"
                if r in INS_ROLES
                else "fewer than two INS units"
            )
            checks.append(
                not_checked(
                    "consistency",
                    "velocity",
                    ",".join(voyage.role_sources(r)),
                    r,
                    "velocity_disagreement",
                    "kn",
                    rule,
                    f"{r}: consistency not checked: {reason}",
                    reason,
                    threshold_value=gate / KN_MPS,
                )
            )
    if why or not targets:
        return checks
    step_ns = int(step_s * NS_PER_S)
    instants = covered_instants(
        [voyage.frame("position", r)["time_ns"].to_numpy(np.int64) for r in roles],
        start_ns,
        end_ns,
        step_ns,
        setting=True,
    )
    i1, ok1 = shifted_index(instants, lag * step_ns)  # t - T
    i2, ok2 = shifted_index(instants, 2 * lag * step_ns)  # t - 2T
    pos = {}
    for r in roles:
        s = sample_unit(unit_series_from_voyage(voyage, r), instants, cfg.consistency_max_gap_s)
        pos[r] = (s.lat_rad, s.lon_rad)
    # the local origin: the units' median position (none sampled: every figure below is
    # NaN and the checks say "not checked")
    lat_all = np.concatenate([pos[r][0] for r in ins])
    lon_all = np.concatenate([pos[r][1] for r in ins])
    seen = np.isfinite(lat_all) & np.isfinite(lon_all)
    lat0 = float(np.median(lat_all[seen])) if seen.any() else 0.0
    lon0 = float(np.median(lon_all[seen])) if seen.any() else 0.0
    ne = {r: np.vstack(offset_ne_m(pos[r][0], pos[r][1], lat0, lon0)) for r in roles}

    def drift(r: str, refs: list[str]) -> FloatArray:
        """|d(t) - 2 d(t - T) + d(t - 2T)| / T of the difference d to the mean of ``refs``:
        the change of its Schuler-averaged velocity from one period to the next."""
        d = ne[r] - np.mean([ne[x] for x in refs], axis=0)
        v = np.full(len(instants), np.nan)
        ok = ok1 & ok2
        v[ok] = np.hypot(*(d[:, ok] - 2 * d[:, i1[ok]] + d[:, i2[ok]])) / (lag * step_s)
        return v

    bad: list[str] = []
    stats: dict[str, FloatArray] = {}
    # INS: the worst unit first; one found inconsistent leaves the others' mean
    pending = [r for r in targets if r in INS_ROLES]
    while pending:
        cand = {r: drift(r, [x for x in ins if x != r and x not in bad]) for r in pending}
        worst = max(pending, key=lambda r: np.nanmax(cand[r]) if np.isfinite(cand[r]).any() else -1)
        stats[worst] = cand[worst]
        pending.remove(worst)
        if np.nanmax(cand[worst]) > gate if np.isfinite(cand[worst]).any() else False:
            bad.append(worst)
            if len([x for x in ins if x not in bad]) < 2:
                for r in pending:  # one unit against one: no attribution
                    stats[r] = np.full(len(instants), np.nan)
                pending = []
        else:
            for r in pending:
                stats[r] = cand[r]
            pending = []
    if "gnss" in targets:
        good = [x for x in ins if x not in bad]
        stats["gnss"] = drift("gnss", good) if len(good) >= 2 else np.full(len(instants), np.nan)
    for r in targets:
        v = stats[r]
        keys = ",".join(voyage.role_sources(r))
        if not np.isfinite(v).any():
            checks.append(
                not_checked(
                    "consistency",
                    "velocity",
                    keys,
                    r,
                    "velocity_disagreement",
                    "kn",
                    rule,
                    f"{r}: no common instants with the other units",
                    "no common instants (or no independent units left)",
                    threshold_value=gate / KN_MPS,
                )
            )
            continue
        over = np.isfinite(v) & (v > gate)
        ev = tuple(
            {
                "from": iso_utc(unit="ms", time_ns=instants[a]),
                "to": iso_utc(unit="ms", time_ns=instants[b - 1]),
                "max_kn": float(np.nanmax(v[a:b]) / KN_MPS),
            }
            for a, b in runs(over)[:MAX_EVIDENCE]
        )
        vmax = float(np.nanmax(v))
        ref = "the INS mean" if r == "gnss" else "the mean of the other INS units"
        msg = (
            f"{r} ({keys}): starts drifting from {ref}: its Schuler-period velocity changes "
            f"by up to {vmax / KN_MPS:.2f} kn (limit {gate / KN_MPS:.2f} kn), first from "
            f"{ev[0]['from']}"
            if ev
            else f"{r} ({keys}): consistent with {ref}: Schuler-period velocity changes of up to "
            f"{vmax / KN_MPS:.2f} kn (limit {gate / KN_MPS:.2f} kn)"
        )
        checks.append(
            Check(
                "consistency",
                "velocity",
                keys,
                r,
                "fail" if ev else "pass",
                statistic("velocity_disagreement", vmax / KN_MPS, "kn"),
                threshold(gate / KN_MPS, "kn", rule),
                time_window(instants[np.isfinite(v)]),
                0.0,
                msg,
                ev,
            )
        )
    return checks


def heading_consistency(
    voyage: Voyage, cfg: IntegrityConfig, start_ns: int, end_ns: int
) -> list[Check]:
    keys = voyage.role_sources("compass")
    ins = [r for r in INS_ROLES if voyage.role_sources(r)]
    if not keys:
        return []
    rule = "compass true heading minus the INS mean heading, its constant part removed"

    def skip(message: str, why: str) -> Check:
        return not_checked(
            "consistency",
            "heading",
            ",".join(keys),
            "compass",
            "heading_disagreement",
            "deg",
            rule,
            message,
            why,
        )

    if not ins:
        return [skip("compass: no INS heading to compare with", "no INS unit")]
    hd = voyage.frame("heading", "compass")
    hd = hd[(hd["reference"] == "T") & np.isfinite(hd["heading_rad"].to_numpy(float))]
    if len(hd) < 30:
        return [
            skip(
                "compass: no true heading (HDT/THS, or HDG with variation) to compare",
                "fewer than 30 true headings from the compass",
            )
        ]
    instants = covered_instants(
        [hd["time_ns"].to_numpy(np.int64)]
        + [voyage.frame("heading", r)["time_ns"].to_numpy(np.int64) for r in ins],
        start_ns,
        end_ns,
        int(cfg.consistency_interval_s * NS_PER_S),
        setting=True,
    )
    c, _ = align_at(
        hd["time_ns"].to_numpy(np.int64),
        hd["heading_rad"].to_numpy(float)[None, :],
        instants,
        cfg.consistency_max_gap_s,
        circular=(True,),
    )
    hs = [
        sample_unit(
            unit_series_from_voyage(voyage, r), instants, cfg.consistency_max_gap_s
        ).heading_rad
        for r in ins
    ]
    m = circmean(np.vstack(hs), axis=0)
    d = angdiff(c[0], m) / DEG_RAD
    ok = np.isfinite(d)
    if ok.sum() < 30:
        return [
            skip(
                "compass: fewer than 30 instants with both compass and INS heading",
                "fewer than 30 common instants",
            )
        ]
    x = d - np.median(d[ok])
    s = tail_sigma(x[ok])
    z = z_two_sided(cfg.false_alarm, int(ok.sum()))
    gate = max(cfg.heading_gate_min_deg, z * s)
    over = ok & (np.abs(x) > gate)
    ev = tuple(
        {
            "from": iso_utc(unit="ms", time_ns=instants[a]),
            "to": iso_utc(unit="ms", time_ns=instants[b - 1]),
            "max_deg": float(np.nanmax(np.abs(x[a:b]))),
        }
        for a, b in runs(over)[:MAX_EVIDENCE]
    )
    worst = float(np.nanmax(np.abs(x[ok])))
    msg = (
        f"compass ({','.join(keys)}): departs from the INS heading by up to {worst:.2f} deg "
        f"beyond its constant offset {np.median(d[ok]):+.2f} deg (gate {gate:.2f} deg)"
        if ev
        else f"compass ({','.join(keys)}): within {worst:.2f} deg of the INS heading after its "
        f"constant offset {np.median(d[ok]):+.2f} deg (gate {gate:.2f} deg)"
    )
    return [
        Check(
            "consistency",
            "heading",
            ",".join(keys),
            "compass",
            "fail" if ev else "pass",
            statistic("heading_disagreement", worst, "deg"),
            threshold(
                gate,
                "deg",
                f"max([integrity] heading_gate_min_deg, z s): z {z:.2f} at "
                f"{cfg.false_alarm:g} per night, s {s:.3f} deg the robust tail sigma",
            ),
            time_window(instants[ok]),
            cfg.false_alarm,
            msg,
            ev,
            detail={"offset_deg": float(np.median(d[ok])), "sigma_deg": s},
        )
    ]


def log_residual(
    stw_mps: FloatArray, ground_ne_mps: FloatArray, heading_rad: FloatArray, window: int
) -> FloatArray:
    """Log speed less the ground speed less current, along the heading (m/s).

    The ground velocity is ``g = c + k u h`` (B7-B12 without leeway: ``u`` the log speed,
    ``h`` the heading's unit vector, ``k = 1 / (1 + s)`` the log's scale, ``c`` the
    current).  ``c`` is the running median over ``window`` instants of ``g - k u h`` (a
    vector: it does not change when the ship turns), ``k`` the least-squares fit of the
    along-heading ``(g - c) . h`` on ``u`` over the night; two rounds.  The residual is
    ``k u - (g - c) . h``: what neither the current nor the scale explains."""
    hv = np.vstack([np.cos(heading_rad), np.sin(heading_rad)])
    k = 1.0
    ok = np.isfinite(stw_mps) & np.isfinite(ground_ne_mps).all(axis=0) & np.isfinite(heading_rad)
    c = np.full_like(ground_ne_mps, np.nan)
    for _ in range(2):
        raw = ground_ne_mps - k * stw_mps * hv
        for i in range(2):
            c[i] = (
                pd.Series(np.where(ok, raw[i], np.nan))
                .rolling(window, center=True, min_periods=max(window // 6, 3))
                .median()
                .to_numpy()
            )
        along = ((ground_ne_mps - c) * hv).sum(axis=0)
        use = ok & np.isfinite(along)
        if use.sum() < 3 or not np.any(stw_mps[use] > 0):
            break
        k = float(np.sum(along[use] * stw_mps[use]) / np.sum(stw_mps[use] ** 2))
    along = ((ground_ne_mps - c) * hv).sum(axis=0)
    return np.where(ok, k * stw_mps - along, np.nan)


def speed_consistency(
    voyage: Voyage, cfg: IntegrityConfig, start_ns: int, end_ns: int
) -> list[Check]:
    keys = voyage.role_sources("log")
    if not keys:
        return []
    rule = (
        "log speed (its scale fitted) minus the ground speed less the current (1 h running "
        "median) along the heading"
    )

    def skip(message: str, why: str) -> Check:
        return not_checked(
            "consistency",
            "speed",
            ",".join(keys),
            "log",
            "speed_disagreement",
            "kn",
            rule,
            message,
            why,
        )

    wt = voyage.frame("water", "log")
    wt = wt[np.isfinite(wt["stw_mps"].to_numpy(float))]
    ref_roles = [r for r in ("gnss", *INS_ROLES) if len(voyage.frame("ground", r))]
    head_roles = [r for r in (*INS_ROLES, "compass") if len(voyage.frame("heading", r))]
    if len(wt) < 30 or not ref_roles or not head_roles:
        why = (
            "no speed through the water"
            if len(wt) < 30
            else "no ground velocity (VTG/RMC)"
            if not ref_roles
            else "no heading"
        )
        return [skip(f"log: not checked: {why}", why)]
    step_ns = int(cfg.consistency_interval_s * NS_PER_S)
    instants = covered_instants(
        [
            wt["time_ns"].to_numpy(np.int64),
            voyage.frame("ground", ref_roles[0])["time_ns"].to_numpy(np.int64),
        ],
        start_ns,
        end_ns,
        step_ns,
        setting=True,
    )
    gap = cfg.consistency_max_gap_s
    stw, _ = align_at(
        wt["time_ns"].to_numpy(np.int64), wt["stw_mps"].to_numpy(float)[None, :], instants, gap
    )
    gr = voyage.frame("ground", ref_roles[0])
    gr = gr[np.isfinite(gr["sog_mps"].to_numpy(float)) & np.isfinite(gr["cog_rad"].to_numpy(float))]
    sog, cog = gr["sog_mps"].to_numpy(float), gr["cog_rad"].to_numpy(float)
    vel, _ = align_at(
        gr["time_ns"].to_numpy(np.int64),
        np.vstack([sog * np.cos(cog), sog * np.sin(cog)]),
        instants,
        gap,
    )
    hd = voyage.frame("heading", head_roles[0])
    hd = hd[np.isfinite(hd["heading_rad"].to_numpy(float))]
    h, _ = align_at(
        hd["time_ns"].to_numpy(np.int64),
        hd["heading_rad"].to_numpy(float)[None, :],
        instants,
        gap,
        circular=(True,),
    )
    x = log_residual(stw[0], vel, h[0], int(round(3600.0 / cfg.consistency_interval_s)))
    ok = np.isfinite(x)
    if ok.sum() < 30:
        return [
            skip(
                "log: fewer than 30 instants with log, ground speed and heading",
                "fewer than 30 common instants",
            )
        ]
    s = tail_sigma(x[ok])
    z = z_two_sided(cfg.false_alarm, int(ok.sum()))
    speed = float(np.nanmedian(stw[0]))
    gate = max(speed_accuracy_mps(speed), z * s)
    over = ok & (np.abs(x) > gate)
    ev = tuple(
        {
            "from": iso_utc(unit="ms", time_ns=instants[a]),
            "to": iso_utc(unit="ms", time_ns=instants[b - 1]),
            "max_kn": float(np.nanmax(np.abs(x[a:b])) / KN_MPS),
        }
        for a, b in runs(over)[:MAX_EVIDENCE]
    )
    worst = float(np.nanmax(np.abs(x[ok])))
    msg = (
        f"log ({','.join(keys)}): departs from the ground speed less current by up to "
        f"{worst / KN_MPS:.2f} kn (gate {gate / KN_MPS:.2f} kn)"
        if ev
        else f"log ({','.join(keys)}): within {worst / KN_MPS:.2f} kn of the ground speed less "
        f"current (gate {gate / KN_MPS:.2f} kn)"
    )
    return [
        Check(
            "consistency",
            "speed",
            ",".join(keys),
            "log",
            "fail" if ev else "pass",
            statistic("speed_disagreement", worst / KN_MPS, "kn"),
            threshold(
                gate / KN_MPS,
                "kn",
                f"max(A.824 speed accuracy, z s): z {z:.2f} at "
                f"{cfg.false_alarm:g} per night, s {s / KN_MPS:.3f} kn the robust tail sigma",
            ),
            time_window(instants[ok]),
            cfg.false_alarm,
            msg,
            ev,
            detail={"sigma_kn": s / KN_MPS, "reference": ref_roles[0], "heading": head_roles[0]},
        )
    ]
