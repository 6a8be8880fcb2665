"""Integrity checks of every source over one night: validity, plausibility, latency,
availability and consistency (IMO MSC.252(83) section 5.3-5.4; IEC 61924-2 tests them).

Pure functions over the canonical frames (:mod:`dracc.frames`); no I/O.  Each
check of each source gives one :class:`Check`: ``pass``, ``fail`` (with its evidence) or
``not_checked`` (with why).  The nightly audit turns failed checks into findings.

The checks and their rules (thresholds in :class:`dracc.core.config.IntegrityConfig`)
------------------------------------------------------------------------------
validity / ``invalid_flag``
    the source's own flags: position records flagged invalid (GGA quality 0, RMC/GLL
    status V or mode N, GNS mode N: ``quality == 0``), heading records with an empty
    heading field, course/speed records without either (VTG mode N and RMC status V
    leave them empty).  Flagged spells of at least ``spell_min_s`` fail.  Rule on recorded
    flags: a healthy source cannot trigger it (false-alarm probability 0).
validity / ``contradiction``
    a source flagging fixes valid while they fail a plausibility check.
plausibility / ``jump``
    the step between consecutive fixes against the step the ship's own motion predicts:
    innovation ``r_k = (p_k - p_{k-1}) - v_k dt_k`` with ``v_k`` the running median of
    the source's velocity over 11 steps (what the ship can do: it follows manoeuvres but
    not one displaced fix).  ``r`` is scaled per axis by its robust sigma learned from
    the night (the larger of the MAD sigma and the one its 99th percentile implies); ``(r_n/s_n)^2 + (r_e/s_e)^2`` is chi-square with 2 degrees of freedom
    for Gaussian fix noise, so the gate ``-2 ln(alpha / N)`` over the N steps holds the
    night's false-alarm probability at ``alpha`` (Bonferroni).  A step within
    ``jump_floor_m`` (10 m: the 95 % accuracy IMO A.1046(27) asks of a receiver) is not a
    finding however sure the statistics are (a satellite change moves a fix by metres).
    The check reports the smallest jump it could have seen,
    ``max(sqrt(gate) max(s_n, s_e), jump_floor_m)``.
plausibility / ``dr_2m``
    each reference fix against the DR propagated from the earlier fixes with its
    covariance (:func:`dr_innovation_check`, made by the pipeline after the DR).
plausibility / ``frozen``, ``stuck``, ``out_of_range``
    :mod:`dracc.math.faults` with the integrity windows (``frozen_min_s``): bit-identical
    positions while the other sources show the ship moving, a heading repeating while
    they show it turning, values no sensor can produce.  Rules: probability 0.
latency
    receive time (TAG ``c:``, logger prefix, MCAP log time) minus the record's own time
    of fix, per source, as a distribution (p50, p95, p99, max); spells of at least
    ``spell_min_s`` with ``|latency| > latency_max_s`` fail.
availability / ``dropout``
    gaps in a source's records longer than ``dropout_cadences`` of its own median
    interval and at least ``dropout_min_s`` (also a late start or an early end within the
    night).
consistency / ``velocity``
    each INS against the mean of the others, GNSS against the INS mean: the difference
    ``d(t)`` sampled every ``consistency_interval_s``, and the change of its velocity
    averaged over one Schuler period T (84.4 min) from one period to the next,
    ``|d(t) - 2 d(t - T) + d(t - 2T)| / T``.  The Schuler oscillation of an INS cancels
    in it, its slow 24 h and drift terms nearly so; a unit that starts to drift shows its
    drift rate.  It fails beyond ``velocity_gate_kn`` (0.6 kn: three times the 0.2 kn the
    standards ask of a speed sensor, IMO A.824(19)); healthy simulated units of randomised
    quality stay below about 0.4 kn (``benchmarks/bench_integrity_false_alarms.py`` prints
    the margin), a real INS slower still.  The worst unit is
    judged first; one found inconsistent is left out of the others' mean.  A drift
    present from the first hour is an accuracy matter (m_y), not seen here.
consistency / ``heading``
    compass true heading against the INS mean heading, its constant part (the compass
    error, an accuracy figure) removed: fails beyond ``max(heading_gate_min_deg, z s)`` with ``s`` the robust sigma of the difference and ``z`` the Bonferroni
    normal quantile at ``alpha`` over the instants.
consistency / ``speed``
    log speed against the ground speed less current along the heading (the current a
    one-hour running median of the vector difference, the log's scale fitted over the
    night: both accuracy figures, :func:`_log_residual`): fails beyond
    ``max(A.824 speed accuracy, z s)``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace

import numpy as np
import pandas as pd

from dracc.core import distributions as dist
from dracc.core.config import FaultsConfig, IntegrityConfig
from dracc.core.geodesy import angdiff, circmean, offset_ne_m
from dracc.core.timefmt import iso_utc
from dracc.core.units import DEG_RAD, KN_MPS, NS_PER_S
from dracc.core.vocabulary import INS_ROLES
from dracc.frames import MISSING_NS, Voyage
from dracc.math.deviation.sampling import align_at, sample_unit, unit_series_from_voyage
from dracc.math.ep import OUTLIER_NIS
from dracc.math.faults import SensorFault, detect_faults

__all__ = [
    "Check",
    "SourceSummary",
    "IntegrityResult",
    "check_night",
    "dr_innovation_check",
    "with_dr_check",
    "CHECK_KINDS",
]

#: the check families of the audit document (dracc.audit/1 ``findings[].check``)
CHECK_KINDS = (
    "validity",
    "plausibility",
    "latency",
    "availability",
    "consistency",
    "accuracy",
    "input",
)
CLAUSES = {
    "validity": "IMO MSC.252(83) 5.3: validity of sensor data (the source's own status flags)",
    "plausibility": "IMO MSC.252(83) 5.3: plausibility (values the ship and sensor can produce)",
    "latency": "IMO MSC.252(83) 5.3: latency and age of the data",
    "availability": "IMO MSC.252(83) 5.1.2: availability of the source",
    "consistency": "IMO MSC.252(83) 5.4: consistency between independent sources",
}
SCHULER_PERIOD_S = 84.4 * 60.0  #: 2 pi sqrt(R/g)
#: IMO A.824(19) speed accuracy: 2 % of the speed or 0.2 kn, whichever is greater
SPEED_ACCURACY_FRACTION = 0.02
SPEED_ACCURACY_MIN_MPS = 0.2 * KN_MPS
MAX_EVIDENCE = 10  #: events shown per check (the count of all is in the statistic)


@dataclass(frozen=True)
class Check:
    """One check of one source over the night."""

    check: str  #: validity | plausibility | latency | availability | consistency
    name: str  #: e.g. 'jump', 'invalid_flag', 'dropout', 'velocity'
    source: str | None
    role: str | None
    status: str  #: 'pass', 'fail' or 'not_checked'
    statistic: dict  #: {"name", "value", "unit"}
    threshold: dict  #: {"value", "unit", "rule"}
    window: dict  #: {"start_ns", "end_ns"} the records the check looked at
    false_alarm: float  #: probability that a healthy source fails it on one night
    message: str
    evidence: tuple[dict, ...] = ()
    why_not: str | None = None  #: for 'not_checked'
    detail: dict = field(default_factory=dict)  #: further figures (e.g. min_detectable_m)

    @property
    def clause(self) -> str:
        return CLAUSES.get(self.check, "")


@dataclass(frozen=True)
class SourceSummary:
    """Per-source figures behind the checks."""

    source: str
    role: str | None
    records: int
    cadence_s: float | None  #: median interval between records
    availability: float | None  #: fraction of the night without a drop-out
    latency_s: dict | None  #: {"n", "p50", "p95", "p99", "max", "min"}, None without receive times


@dataclass(frozen=True)
class IntegrityResult:
    checks: tuple[Check, ...]
    sources: tuple[SourceSummary, ...]
    start_ns: int
    end_ns: int
    alpha: float  #: false-alarm probability of each statistical check per night

    @property
    def failed(self) -> tuple[Check, ...]:
        return tuple(c for c in self.checks if c.status == "fail")

    @property
    def false_alarm_per_night(self) -> float:
        """Union (Bonferroni) bound of the checks made: P(any healthy check fails)."""
        return float(min(1.0, sum(c.false_alarm for c in self.checks if c.status != "not_checked")))


# ------------------------------------------------------------------------ helpers


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """[start, stop) index pairs of the runs of True in ``mask``."""
    m = np.concatenate(([False], np.asarray(mask, dtype=bool), [False]))
    edges = np.flatnonzero(m[1:] != m[:-1])
    return list(zip(edges[::2].tolist(), edges[1::2].tolist(), strict=True))


def _robust_sigma(x: np.ndarray) -> float:
    """1.4826 MAD: the normal sigma, unmoved by a minority of outliers."""
    x = x[np.isfinite(x)]
    if len(x) == 0:
        return math.nan
    return float(1.4826 * np.median(np.abs(x - np.median(x))))


def _tail_sigma(x: np.ndarray) -> float:
    """The larger of the MAD sigma and the sigma the 99th percentile of |x| implies (2.576
    sigma for a normal law): a night whose noise has heavier tails than normal widens its
    own gate instead of raising false alarms, and one displaced fix in a hundred moves
    neither."""
    x = x[np.isfinite(x)]
    if len(x) == 0:
        return math.nan
    med = np.median(x)
    return max(_robust_sigma(x), float(np.percentile(np.abs(x - med), 99.0) / 2.576))


def _z_two_sided(alpha: float, n: int) -> float:
    """Normal quantile with two-sided tail alpha / n (Bonferroni over n instants)."""
    return float(dist.norm_ppf(1.0 - alpha / (2.0 * max(n, 1))))


def _window(t_ns: np.ndarray) -> dict:
    if len(t_ns) == 0:
        return {}
    return {"start_ns": int(t_ns[0]), "end_ns": int(t_ns[-1])}


def _stat(name: str, value, unit: str) -> dict:
    v = None if value is None or not np.isfinite(value) else float(value)
    return {"name": name, "value": v, "unit": unit}


def _thr(value, unit: str, rule: str) -> dict:
    v = None if value is None or not np.isfinite(value) else float(value)
    return {"value": v, "unit": unit, "rule": rule}


def _by_source(df: pd.DataFrame):
    """(source key, its rows) for each source of a frame, rows in time order."""
    if df is None or len(df) == 0:
        return
    for key, g in df.groupby("source", sort=True, observed=True):
        yield str(key), g


def _not_checked(
    check: str,
    name: str,
    source: str | None,
    role: str | None,
    statistic: str,
    unit: str,
    rule: str,
    message: str,
    why: str,
) -> Check:
    """A check that could not be made, with why."""
    return Check(
        check,
        name,
        source,
        role,
        "not_checked",
        _stat(statistic, None, unit),
        _thr(None, unit, rule),
        {},
        0.0,
        message,
        why_not=why,
    )


def _role(voyage: Voyage, key: str) -> str | None:
    s = voyage.sources.get(key)
    return s.role if s is not None else None


# ----------------------------------------------------------------------- validity


def _validity(voyage: Voyage, cfg: IntegrityConfig) -> list[Check]:
    checks = []
    spell_ns = int(cfg.spell_min_s * NS_PER_S)
    parts: dict[str, list[tuple[str, pd.DataFrame, np.ndarray]]] = {}
    for key, g in _by_source(voyage.frames["position"]):
        parts.setdefault(key, []).append(("position", g, g["quality"].to_numpy() == 0))
    for key, g in _by_source(voyage.frames["heading"]):
        parts.setdefault(key, []).append(
            ("heading", g, ~np.isfinite(g["heading_rad"].to_numpy(float)))
        )
    for key, g in _by_source(voyage.frames["ground"]):  # VTG mode N, RMC status V: no velocity
        parts.setdefault(key, []).append(
            (
                "ground",
                g,
                ~np.isfinite(g["cog_rad"].to_numpy(float))
                & ~np.isfinite(g["sog_mps"].to_numpy(float)),
            )
        )
    for key in sorted(parts):
        evidence, n_flag, n_all, longest = [], 0, 0, 0.0
        t_first, t_last = None, None
        for kind, g, bad in parts[key]:
            t = g["time_ns"].to_numpy(np.int64)
            n_all += len(t)
            n_flag += int(bad.sum())
            t_first = t[0] if t_first is None else min(t_first, t[0])
            t_last = t[-1] if t_last is None else max(t_last, t[-1])
            lines = g["line"].to_numpy()
            sent = g["sentence"]
            for a, b in _runs(bad):
                dur = (t[b - 1] - t[a]) / NS_PER_S
                longest = max(longest, dur)
                if t[b - 1] - t[a] >= spell_ns and len(evidence) < MAX_EVIDENCE:
                    evidence.append(
                        {
                            "start": iso_utc(unit="ms", time_ns=t[a]),
                            "end": iso_utc(unit="ms", time_ns=t[b - 1]),
                            "duration_s": dur,
                            "records": b - a,
                            "frame": kind,
                            "first_line": int(lines[a]),
                            "sentence": str(sent.iloc[a]),
                        }
                    )
        failed = bool(evidence)
        msg = (
            f"{key}: flagged its own data invalid for {longest:.0f} s at the longest "
            f"({n_flag} of {n_all} records; {len(evidence)} spell(s) of {cfg.spell_min_s:g} s or more)"
            if failed
            else f"{key}: {n_flag} of {n_all} records flagged invalid, no spell of "
            f"{cfg.spell_min_s:g} s"
        )
        checks.append(
            Check(
                "validity",
                "invalid_flag",
                key,
                _role(voyage, key),
                "fail" if failed else "pass",
                _stat("longest_invalid_spell", longest, "s"),
                _thr(
                    cfg.spell_min_s,
                    "s",
                    "a spell of records the source flags "
                    "invalid (GGA quality 0, RMC/GLL status V, GNS/VTG mode N, "
                    "empty heading) at least this long",
                ),
                {"start_ns": int(t_first), "end_ns": int(t_last)},
                0.0,
                msg,
                tuple(evidence),
                detail={"flagged_records": n_flag, "records": n_all},
            )
        )
    return checks


# ------------------------------------------------------------------- plausibility


def _steps_ne(g: pd.DataFrame):
    lat = g["lat_rad"].to_numpy(float)
    lon = g["lon_rad"].to_numpy(float)
    n, e = offset_ne_m(lat, lon, lat[0], lon[0])
    return n, e


def _jump(
    key: str, role: str | None, g: pd.DataFrame, frozen: Sequence[SensorFault], cfg: IntegrityConfig
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
    win = _window(t)
    if len(t) < 30:
        return Check(
            "plausibility",
            "jump",
            key,
            role,
            "not_checked",
            _stat("innovation", None, "m"),
            _thr(None, "m", ""),
            win,
            0.0,
            f"{key}: too few valid fixes ({len(t)}) to learn the step noise",
            why_not=f"{len(t)} valid fixes (30 needed)",
        )
    north, east = _steps_ne(g)
    dt = np.diff(t) / NS_PER_S
    dn, de = np.diff(north), np.diff(east)
    cadence = float(np.median(dt))
    vn = pd.Series(dn / dt).rolling(11, center=True, min_periods=3).median().to_numpy()
    ve = pd.Series(de / dt).rolling(11, center=True, min_periods=3).median().to_numpy()
    rn, re_ = dn - vn * dt, de - ve * dt
    # steps over a drop-out (availability) or out of a frozen run (the unit catching
    # up, a 'frozen' fault) are not jumps
    usable = dt <= 10.0 * cadence
    for f in frozen:
        usable &= ~((t[1:] >= f.start_ns) & (t[1:] <= f.end_ns + int(3 * cadence * NS_PER_S)))
    quantum = 0.05  # m: below any logged resolution that can show a jump
    sn = max(_tail_sigma(rn[usable]), quantum)
    se = max(_tail_sigma(re_[usable]), quantum)
    n_steps = int(usable.sum())
    gate = -2.0 * math.log(cfg.false_alarm / max(n_steps, 1))  # chi2_2 survival exp(-x/2)
    d2 = np.where(usable, (rn / sn) ** 2 + (re_ / se) ** 2, 0.0)
    # a step within the position accuracy the standards ask of a receiver is not a finding,
    # however sure the statistics are that the fix moved (a satellite change, multipath)
    flagged = (d2 > gate) & (np.hypot(rn, re_) > cfg.jump_floor_m)
    min_jump = max(math.sqrt(gate) * max(sn, se), cfg.jump_floor_m)
    evidence = []
    lines = g["line"].to_numpy()
    quality = g["quality"].to_numpy()
    idx = np.flatnonzero(flagged)
    for k in idx[:MAX_EVIDENCE]:
        evidence.append(
            {
                "time": iso_utc(unit="ms", time_ns=t[k + 1]),
                "line": int(lines[k + 1]),
                "step_m": float(math.hypot(dn[k], de[k])),
                "expected_step_m": float(math.hypot(vn[k] * dt[k], ve[k] * dt[k])),
                "innovation_m": float(math.hypot(rn[k], re_[k])),
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
        _stat("max_normalised_innovation", worst, "sigma"),
        _thr(
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


def _fault_checks(
    voyage: Voyage,
    faults: Sequence[SensorFault],
    name: str,
    kinds: tuple[str, ...],
    frames: tuple[str, ...],
    rule: str,
    cfg_value: float,
    unit: str,
) -> list[Check]:
    """One pass/fail check per source of ``frames`` from :mod:`dracc.math.faults` results."""
    checks = []
    times: dict[str, list[np.ndarray]] = {}
    for frame in frames:
        for key, g in _by_source(voyage.frames[frame]):
            times.setdefault(key, []).append(g["time_ns"].to_numpy(np.int64))
    for key in sorted(times):
        mine = [f for f in faults if f.source == key and f.kind in kinds]
        t = np.sort(np.concatenate(times[key]))
        ev = tuple(
            {
                "start": iso_utc(unit="ms", time_ns=f.start_ns),
                "end": iso_utc(unit="ms", time_ns=f.end_ns),
                "duration_s": f.duration_s,
                "records": f.n_records,
                "first_line": f.first_line,
                "kind": f.kind,
                "values": {k: (float(v) if math.isfinite(v) else None) for k, v in f.values},
            }
            for f in mine[:MAX_EVIDENCE]
        )
        longest = max((f.duration_s for f in mine), default=0.0)
        msg = (
            "; ".join(f.message for f in mine[:3])
            if mine
            else f"{key}: no {name.replace('_', ' ')}"
        )
        checks.append(
            Check(
                "plausibility",
                name,
                key,
                _role(voyage, key),
                "fail" if mine else "pass",
                _stat(
                    "longest_s" if name != "out_of_range" else "faults",
                    longest if name != "out_of_range" else len(mine),
                    "s" if name != "out_of_range" else "count",
                ),
                _thr(cfg_value, unit, rule),
                _window(t),
                0.0,
                msg,
                ev,
            )
        )
    return checks


def _plausibility(voyage: Voyage, cfg: IntegrityConfig) -> tuple[list[Check], list[SensorFault]]:
    fcfg = FaultsConfig(frozen_min_s=cfg.frozen_min_s, stuck_min_s=cfg.frozen_min_s)
    faults = detect_faults(voyage, fcfg)
    checks = []
    for key, g in _by_source(voyage.frames["position"]):
        frozen = [f for f in faults if f.source == key and f.kind == "frozen"]
        checks.append(_jump(key, _role(voyage, key), g, frozen, cfg))
    checks += _fault_checks(
        voyage,
        faults,
        "frozen",
        ("frozen",),
        ("position",),
        "bit-identical positions this long while the other sources show the ship moving",
        cfg.frozen_min_s,
        "s",
    )
    checks += _fault_checks(
        voyage,
        faults,
        "stuck",
        ("stuck_heading",),
        ("heading",),
        "a bit-identical heading this long while the other sources show the ship turning",
        cfg.frozen_min_s,
        "s",
    )
    checks += _fault_checks(
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


def _contradictions(
    voyage: Voyage, checks: Sequence[Check], faults: Sequence[SensorFault]
) -> list[Check]:
    """validity / contradiction: a source flagging as valid what fails plausibility."""
    out = []
    pos = voyage.frames["position"]
    for key in sorted({c.source for c in checks if c.check == "plausibility" and c.source}):
        events = []
        for c in checks:
            if c.source == key and c.name == "jump" and c.status == "fail":
                events += [
                    {"what": "jump", "time": e["time"], "line": e["line"]}
                    for e in c.evidence
                    if e.get("flagged_valid")
                ]
        mask_src = (pos["source"] == key).to_numpy()
        for f in faults:
            if f.source != key or f.kind != "frozen" or not mask_src.any():
                continue
            t = pos["time_ns"].to_numpy(np.int64)[mask_src]
            q = pos["quality"].to_numpy()[mask_src]
            inside = (t >= f.start_ns) & (t <= f.end_ns)
            if (q[inside] > 0).any():
                events.append(
                    {
                        "what": "frozen",
                        "time": iso_utc(unit="ms", time_ns=f.start_ns),
                        "line": f.first_line,
                        "records_flagged_valid": int((q[inside] > 0).sum()),
                    }
                )
        if not events:
            continue
        out.append(
            Check(
                "validity",
                "contradiction",
                key,
                _role(voyage, key),
                "fail",
                _stat("implausible_records_flagged_valid", len(events), "count"),
                _thr(0, "count", "a record the source flags valid must pass plausibility"),
                {},
                0.0,
                f"{key}: flagged as valid what fails plausibility: "
                + ", ".join(
                    f"{w} x{sum(e['what'] == w for e in events)}"
                    for w in sorted({e["what"] for e in events})
                ),
                tuple(events[:MAX_EVIDENCE]),
            )
        )
    return out


# ------------------------------------------------------------------------ latency


def _latency(voyage: Voyage, cfg: IntegrityConfig) -> tuple[list[Check], dict[str, dict]]:
    checks, dists = [], {}
    per: dict[str, list[tuple[np.ndarray, np.ndarray, np.ndarray]]] = {}
    for df in voyage.frames.values():
        if len(df) == 0 or "recv_ns" not in df:
            continue
        recv = df["recv_ns"].to_numpy(np.int64)
        has = recv != MISSING_NS
        if not has.any():
            continue
        sub = df[has]
        for key, g in _by_source(sub):
            per.setdefault(key, []).append(
                (
                    g["time_ns"].to_numpy(np.int64),
                    g["recv_ns"].to_numpy(np.int64),
                    g["line"].to_numpy(),
                )
            )
    max_ns = cfg.latency_max_s * NS_PER_S
    spell_ns = int(cfg.spell_min_s * NS_PER_S)
    for key in sorted(per):
        t = np.concatenate([p[0] for p in per[key]])
        r = np.concatenate([p[1] for p in per[key]])
        ln = np.concatenate([p[2] for p in per[key]])
        o = np.argsort(t, kind="stable")
        t, r, ln = t[o], r[o], ln[o]
        lat_s = (r - t) / NS_PER_S
        q = np.percentile(lat_s, [50, 95, 99])
        dists[key] = {
            "n": int(len(lat_s)),
            "p50": float(q[0]),
            "p95": float(q[1]),
            "p99": float(q[2]),
            "max": float(lat_s.max()),
            "min": float(lat_s.min()),
        }
        bad = np.abs(r - t) > max_ns
        evidence, longest = [], 0.0
        for a, b in _runs(bad):
            dur = (t[b - 1] - t[a]) / NS_PER_S
            longest = max(longest, dur)
            if t[b - 1] - t[a] >= spell_ns and len(evidence) < MAX_EVIDENCE:
                evidence.append(
                    {
                        "start": iso_utc(unit="ms", time_ns=t[a]),
                        "end": iso_utc(unit="ms", time_ns=t[b - 1]),
                        "duration_s": dur,
                        "records": b - a,
                        "first_line": int(ln[a]),
                        "median_latency_s": float(np.median(lat_s[a:b])),
                    }
                )
        failed = bool(evidence)
        worst = max((abs(e["median_latency_s"]) for e in evidence), default=0.0)
        msg = (
            f"{key}: data {worst:.2f} s old on receipt for {longest:.0f} s at the longest "
            f"(limit {cfg.latency_max_s:g} s; latency p50 {q[0]:.2f} s, p95 {q[1]:.2f} s)"
            if failed
            else f"{key}: latency p50 {q[0]:.2f} s, p95 {q[1]:.2f} s, max "
            f"{lat_s.max():.2f} s over {len(lat_s)} records"
        )
        checks.append(
            Check(
                "latency",
                "latency",
                key,
                _role(voyage, key),
                "fail" if failed else "pass",
                _stat("longest_late_spell", longest, "s"),
                _thr(
                    cfg.latency_max_s,
                    "s",
                    f"|receive time - time of fix| above this for at least {cfg.spell_min_s:g} s",
                ),
                _window(t),
                0.0,
                msg,
                tuple(evidence),
                detail={"latency_s": dists[key]},
            )
        )
    return checks, dists


# ------------------------------------------------------------------- availability


def _source_times(voyage: Voyage) -> dict[str, np.ndarray]:
    parts: dict[str, list[np.ndarray]] = {}
    for df in voyage.frames.values():
        for key, g in _by_source(df):
            parts.setdefault(key, []).append(g["time_ns"].to_numpy(np.int64))
    return {k: np.unique(np.concatenate(v)) for k, v in parts.items()}


def _availability(
    voyage: Voyage,
    cfg: IntegrityConfig,
    start_ns: int,
    end_ns: int,
    times: Mapping[str, np.ndarray],
) -> tuple[list[Check], dict[str, tuple[float, float]]]:
    checks, summary = [], {}
    span = max(end_ns - start_ns, 1)
    for key in sorted(times):
        t = times[key]
        if len(t) < 3:
            summary[key] = (math.nan, math.nan)
            checks.append(
                Check(
                    "availability",
                    "dropout",
                    key,
                    _role(voyage, key),
                    "not_checked",
                    _stat("longest_dropout", None, "s"),
                    _thr(None, "s", ""),
                    _window(t),
                    0.0,
                    f"{key}: {len(t)} record(s): no cadence to measure against",
                    why_not="fewer than 3 records",
                )
            )
            continue
        d = np.diff(t)
        cadence = float(np.median(d)) / NS_PER_S
        thr_s = max(cfg.dropout_cadences * cadence, cfg.dropout_min_s)
        thr = int(thr_s * NS_PER_S)
        gaps = [(int(t[i]), int(t[i + 1])) for i in np.flatnonzero(d > thr)]
        if t[0] - start_ns > thr:
            gaps.insert(0, (start_ns, int(t[0])))
        if end_ns - t[-1] > thr:
            gaps.append((int(t[-1]), end_ns))
        lost = sum(b - a for a, b in gaps)
        summary[key] = (cadence, 1.0 - lost / span)
        longest = max(((b - a) / NS_PER_S for a, b in gaps), default=0.0)
        ev = tuple(
            {
                "from": iso_utc(unit="ms", time_ns=a),
                "to": iso_utc(unit="ms", time_ns=b),
                "duration_s": (b - a) / NS_PER_S,
                "cadences": (b - a) / NS_PER_S / cadence if cadence > 0 else None,
                "edge": "start" if a == start_ns else ("end" if b == end_ns else None),
            }
            for a, b in sorted(gaps, key=lambda g: g[0] - g[1])[:MAX_EVIDENCE]
        )
        msg = (
            f"{key}: silent for {longest:.0f} s at the longest ({len(gaps)} drop-out(s) "
            f"beyond {thr_s:.0f} s against its {cadence:g} s cadence; available "
            f"{100 * summary[key][1]:.1f} % of the night)"
            if gaps
            else f"{key}: no drop-out beyond {thr_s:.0f} s (cadence {cadence:g} s)"
        )
        checks.append(
            Check(
                "availability",
                "dropout",
                key,
                _role(voyage, key),
                "fail" if gaps else "pass",
                _stat("longest_dropout", longest, "s"),
                _thr(
                    thr_s,
                    "s",
                    f"a gap longer than {cfg.dropout_cadences:g} of the "
                    f"source's own intervals and at least {cfg.dropout_min_s:g} s",
                ),
                {"start_ns": start_ns, "end_ns": end_ns},
                0.0,
                msg,
                ev,
                detail={"cadence_s": cadence, "availability": summary[key][1]},
            )
        )
    return checks, summary


# -------------------------------------------------------------------- consistency


def _speed_accuracy_mps(speed_mps: float) -> float:
    return max(SPEED_ACCURACY_MIN_MPS, SPEED_ACCURACY_FRACTION * speed_mps)


def _position_velocity(
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
                Check(
                    "consistency",
                    "velocity",
                    ",".join(voyage.role_sources(r)),
                    r,
                    "not_checked",
                    _stat("velocity_disagreement", None, "kn"),
                    _thr(gate / KN_MPS, "kn", rule),
                    {},
                    0.0,
                    f"{r}: consistency not checked: {reason}",
                    why_not=reason,
                )
            )
    if why or not targets:
        return checks
    instants = np.arange(start_ns, end_ns, int(step_s * NS_PER_S), dtype=np.int64)
    pos = {}
    for r in roles:
        s = sample_unit(unit_series_from_voyage(voyage, r), instants, cfg.consistency_max_gap_s)
        pos[r] = (s.lat_rad, s.lon_rad)
    lat0 = np.nanmedian(np.concatenate([pos[r][0] for r in ins]))
    lon0 = np.nanmedian(np.concatenate([pos[r][1] for r in ins]))
    ne = {r: np.vstack(offset_ne_m(pos[r][0], pos[r][1], lat0, lon0)) for r in roles}

    def drift(r: str, refs: list[str]) -> np.ndarray:
        """|d(t) - 2 d(t - T) + d(t - 2T)| / T of the difference d to the mean of ``refs``:
        the change of its Schuler-averaged velocity from one period to the next."""
        d = ne[r] - np.mean([ne[x] for x in refs], axis=0)
        v = np.full(len(instants), np.nan)
        v[2 * lag :] = np.hypot(*(d[:, 2 * lag :] - 2 * d[:, lag:-lag] + d[:, : -2 * lag])) / (
            lag * step_s
        )
        return v

    bad: list[str] = []
    stats: dict[str, np.ndarray] = {}
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
                Check(
                    "consistency",
                    "velocity",
                    keys,
                    r,
                    "not_checked",
                    _stat("velocity_disagreement", None, "kn"),
                    _thr(gate / KN_MPS, "kn", rule),
                    {},
                    0.0,
                    f"{r}: no common instants with the other units",
                    why_not="no common instants (or no independent units left)",
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
            for a, b in _runs(over)[:MAX_EVIDENCE]
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
                _stat("velocity_disagreement", vmax / KN_MPS, "kn"),
                _thr(gate / KN_MPS, "kn", rule),
                _window(instants[np.isfinite(v)]),
                0.0,
                msg,
                ev,
            )
        )
    return checks


def _heading_consistency(
    voyage: Voyage, cfg: IntegrityConfig, start_ns: int, end_ns: int
) -> list[Check]:
    keys = voyage.role_sources("compass")
    ins = [r for r in INS_ROLES if voyage.role_sources(r)]
    if not keys:
        return []
    rule = "compass true heading minus the INS mean heading, its constant part removed"

    def skip(message: str, why: str) -> Check:
        return _not_checked(
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
    instants = np.arange(
        start_ns, end_ns, int(cfg.consistency_interval_s * NS_PER_S), dtype=np.int64
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
    s = _tail_sigma(x[ok])
    z = _z_two_sided(cfg.false_alarm, int(ok.sum()))
    gate = max(cfg.heading_gate_min_deg, z * s)
    over = ok & (np.abs(x) > gate)
    ev = tuple(
        {
            "from": iso_utc(unit="ms", time_ns=instants[a]),
            "to": iso_utc(unit="ms", time_ns=instants[b - 1]),
            "max_deg": float(np.nanmax(np.abs(x[a:b]))),
        }
        for a, b in _runs(over)[:MAX_EVIDENCE]
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
            _stat("heading_disagreement", worst, "deg"),
            _thr(
                gate,
                "deg",
                f"max([integrity] heading_gate_min_deg, z s): z {z:.2f} at "
                f"{cfg.false_alarm:g} per night, s {s:.3f} deg the robust tail sigma",
            ),
            _window(instants[ok]),
            cfg.false_alarm,
            msg,
            ev,
            detail={"offset_deg": float(np.median(d[ok])), "sigma_deg": s},
        )
    ]


def _log_residual(
    stw_mps: np.ndarray, ground_ne_mps: np.ndarray, heading_rad: np.ndarray, window: int
) -> np.ndarray:
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


def _speed_consistency(
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
        return _not_checked(
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
    instants = np.arange(start_ns, end_ns, step_ns, dtype=np.int64)
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
    x = _log_residual(stw[0], vel, h[0], int(round(3600.0 / cfg.consistency_interval_s)))
    ok = np.isfinite(x)
    if ok.sum() < 30:
        return [
            skip(
                "log: fewer than 30 instants with log, ground speed and heading",
                "fewer than 30 common instants",
            )
        ]
    s = _tail_sigma(x[ok])
    z = _z_two_sided(cfg.false_alarm, int(ok.sum()))
    speed = float(np.nanmedian(stw[0]))
    gate = max(_speed_accuracy_mps(speed), z * s)
    over = ok & (np.abs(x) > gate)
    ev = tuple(
        {
            "from": iso_utc(unit="ms", time_ns=instants[a]),
            "to": iso_utc(unit="ms", time_ns=instants[b - 1]),
            "max_kn": float(np.nanmax(np.abs(x[a:b])) / KN_MPS),
        }
        for a, b in _runs(over)[:MAX_EVIDENCE]
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
            _stat("speed_disagreement", worst / KN_MPS, "kn"),
            _thr(
                gate / KN_MPS,
                "kn",
                f"max(A.824 speed accuracy, z s): z {z:.2f} at "
                f"{cfg.false_alarm:g} per night, s {s / KN_MPS:.3f} kn the robust tail sigma",
            ),
            _window(instants[ok]),
            cfg.false_alarm,
            msg,
            ev,
            detail={"sigma_kn": s / KN_MPS, "reference": ref_roles[0], "heading": head_roles[0]},
        )
    ]


# ------------------------------------------------------------ against the DR and its 2M

#: a fix whose innovation against the DR exceeds this chi^2_2 value is an outlier, left
#: out of the estimated position (probability exp(-30) ~ 1e-13 per healthy fix)
DR_GATE_NIS = OUTLIER_NIS


def dr_innovation_check(
    source: str | None,
    role: str | None,
    time_ns: np.ndarray,
    nis: np.ndarray,
    gate_m: np.ndarray,
    cfg: IntegrityConfig | None = None,
) -> Check:
    """plausibility / ``dr_2m``: each reference fix against the DR from the previous ones
    with its covariance (the estimated position's filter, dracc.math.ep): the innovation
    ``nu' S^-1 nu`` is chi-square with 2 degrees of freedom for a healthy fix; above
    :data:`DR_GATE_NIS` it is a jump the DR and its 2M cannot explain.  The smallest such
    jump, ``sqrt(gate * largest eigenvalue of S)``, is stated (its median over the fixes)."""
    t = np.asarray(time_ns, np.int64)
    nis = np.asarray(nis, float)
    gate_m = np.asarray(gate_m, float)
    win = _window(t)
    rule = (
        f"innovation chi-square(2) beyond {DR_GATE_NIS:g} against the DR propagated from the "
        "earlier fixes with its covariance (the estimated position's filter)"
    )
    if len(t) == 0:
        return Check(
            "plausibility",
            "dr_2m",
            source,
            role,
            "not_checked",
            _stat("max_nis", None, ""),
            _thr(DR_GATE_NIS, "chi2", rule),
            win,
            0.0,
            "no fix weighed against the DR",
            why_not="no reference fix after the first",
        )
    over = nis > DR_GATE_NIS
    min_jump = float(np.nanmedian(gate_m)) if np.isfinite(gate_m).any() else math.nan
    fa = float(min(1.0, len(t) * math.exp(-DR_GATE_NIS / 2.0)))
    ev = tuple(
        {"time": iso_utc(unit="ms", time_ns=t[k]), "nis": float(nis[k]), "gate_m": float(gate_m[k])}
        for k in np.flatnonzero(over)[:MAX_EVIDENCE]
    )
    who = source or role or "the reference"
    msg = (
        f"{who}: {int(over.sum())} fix(es) outside what the DR and its 2M allow (NIS up to "
        f"{np.nanmax(nis):.0f} > {DR_GATE_NIS:g}; the gate sees jumps of about {min_jump:.0f} m)"
        if len(ev)
        else f"{who}: every fix within the DR and its 2M (the gate sees jumps of "
        f"about {min_jump:.0f} m)"
    )
    return Check(
        "plausibility",
        "dr_2m",
        source,
        role,
        "fail" if len(ev) else "pass",
        _stat("max_nis", float(np.nanmax(nis)), "chi2"),
        _thr(DR_GATE_NIS, "chi2", rule),
        win,
        fa,
        msg,
        ev,
        detail={"min_detectable_m": min_jump, "fixes": int(len(t)), "outliers": int(over.sum())},
    )


def with_dr_check(result: IntegrityResult, check: Check) -> IntegrityResult:
    """``result`` with the DR check added."""
    return replace(result, checks=result.checks + (check,))


# ------------------------------------------------------------------------ the night


def check_night(voyage: Voyage, cfg: IntegrityConfig | None = None) -> IntegrityResult | None:
    """Every integrity check of every source of ``voyage`` (None without records)."""
    cfg = cfg or IntegrityConfig()
    times = _source_times(voyage)
    if not times:
        return None
    start_ns = int(min(t[0] for t in times.values()))
    end_ns = int(max(t[-1] for t in times.values()))
    checks: list[Check] = []
    checks += _validity(voyage, cfg)
    plaus, faults = _plausibility(voyage, cfg)
    checks += plaus
    checks += _contradictions(voyage, plaus, faults)
    lat_checks, lat = _latency(voyage, cfg)
    checks += lat_checks
    avail, summary = _availability(voyage, cfg, start_ns, end_ns, times)
    checks += avail
    checks += _position_velocity(voyage, cfg, start_ns, end_ns)
    checks += _heading_consistency(voyage, cfg, start_ns, end_ns)
    checks += _speed_consistency(voyage, cfg, start_ns, end_ns)
    sources = tuple(
        SourceSummary(
            key,
            _role(voyage, key),
            int(len(times[key])),
            summary[key][0],
            summary[key][1],
            lat.get(key),
        )
        for key in sorted(times)
    )
    return IntegrityResult(tuple(checks), sources, start_ns, end_ns, cfg.false_alarm)
