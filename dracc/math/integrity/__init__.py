"""Integrity checks of every source over one night: validity, plausibility, latency,
availability, consistency (IMO MSC.252(83) section 5.3-5.4; IEC 61924-2 tests them) and
time (the logger's clock and the receivers' own times of fix).

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
    a source flagging fixes valid while they fail a plausibility check (a jump, a frozen
    run a witness contradicts; a fix held at rest is no contradiction).
plausibility / ``jump``
    the step between consecutive fixes against the step the ship's own motion predicts:
    innovation ``r_k = (p_k - p_{k-1}) - w_k - v_k dt_k`` with ``w_k`` the water track
    over the step (the compass and the log integrated: the ship's own turns and changes
    of speed; across a heading gap longer than ``max(10 s, cadence)`` inside the step it
    holds the heading and speed of the gap's two ends) and ``v_k`` the running median
    over 11 steps of what is left, ``(p_k - p_{k-1} - w_k) / dt_k`` (the current and
    the sensors' slow errors: it follows them but not one displaced fix).  Where there
    is no water track, ``w_k + v_k dt_k`` is the fixes' own recent velocity (the running
    median of ``(p_k - p_{k-1}) / dt_k``) times ``dt_k``; the two are never mixed in one
    median.  The time of a step no instrument saw (the heading gap inside it; without a
    water track, what the step lasts beyond one cadence) times the ship's speed is what
    a manoeuvre could make of the step: that much of ``|r_k|`` is no evidence of a jump
    (``|r_k|`` is shortened by it), so ordinary motion across a gap is not a jump.
    ``r`` is scaled per axis by its robust sigma learned from
    the night (the larger of the MAD sigma and the one its 99th percentile implies); ``(r_n/s_n)^2 + (r_e/s_e)^2`` is chi-square with 2 degrees of freedom
    for Gaussian fix noise, so the gate ``-2 ln(alpha / N)`` over the N steps holds the
    night's false-alarm probability at ``alpha`` (Bonferroni).  A jump is one displaced
    fix: the step's innovation must also stand out from its neighbours',
    ``i_k = r_k - (r_{k-1} + r_{k+1}) / 2`` scaled by its own robust sigma past the same
    gate, so a change of speed or a turn the running median lags behind (the same
    innovation on several steps in a row) is not a jump.  A step within
    ``jump_floor_m`` (10 m: the 95 % accuracy IMO A.1046(27) asks of a receiver) is not a
    finding however sure the statistics are (a satellite change moves a fix by metres).
    The step out of a held fix (frozen, or at rest) is the unit catching up, not a jump.
    The check reports the smallest jump it could have seen,
    ``max(sqrt(gate) max(s_n, s_e), jump_floor_m)``.
plausibility / ``dr_2m``
    each reference fix against the DR propagated from the earlier fixes with its
    covariance (:func:`dr_innovation_check`, made by the pipeline after the DR).
plausibility / ``frozen``, ``stuck``, ``out_of_range``
    :mod:`dracc.math.faults` with the integrity windows (``frozen_min_s``): bit-identical
    positions while another source shows the ship moving farther than three steps of the
    source's resolution, a heading repeating while the other heading sources (each one)
    turn beyond their noise by more than three steps of the source's resolution (both resolutions
    learned from the values: an AIS heading in whole degrees is not stuck while a gyro
    yaws 0.9 deg; at rest only a swing of ``[faults] turn_min_deg``), values no sensor
    can produce.  A finding needs a witness
    (:mod:`dracc.math.witness`): a repeat the witnesses show at rest passes with that
    evidence ("at rest: SOG 0.0 kn, heading spread 0.4 deg"); one no other source can
    judge is ``not_checked``.  Rules: probability 0.
latency
    receive time (TAG ``c:``, logger prefix, MCAP log time) minus the record's own time
    of fix, per source, as a distribution (p50, p95, p99, max); spells of at least
    ``spell_min_s`` with ``latency > latency_max_s`` (the time of fix behind the logger
    clock) fail.  A negative latency is a time of fix ahead of the logger clock: a clock
    offset, never old data, judged by ``time/leap_second`` (below), not here too.  A
    source of a log without a clock (``Voyage.clockless``) is ``not_checked`` here and
    under availability, with no cadence, availability or latency figures.
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
    night: both accuracy figures,
    :func:`~dracc.math.integrity.consistency.log_residual`): fails beyond
    ``max(A.824 speed accuracy, z s)``.

consistency / ``compass_witness``, ``log_witness``
    the chosen compass and log against each candidate not chosen for the role (two gyros,
    two logs: :mod:`.role_witnesses`): the difference's constant part (an error, a scale) is
    evidence, its varying part fails beyond ``max(floor, z s)``; a witness the choice
    found failed (a log at 0.0 kn while the ship moves) fails with that evidence.

time / ``backstep``, ``loop``, ``leap_second``, ``week_rollover``, ``clock_drift``, ``no_clock``
    the logger's times going back (a clock set back; a replayed recording, the values
    repeating), a time of fix ahead of the logger clock (named by its whole seconds: a
    leap-second count, GPS time without the UTC offset), dates 1024 weeks early (repaired
    by the ingest, said), a receiver's time of fix drifting against the logger clock
    (significant and more than ``clock_drift_max_s`` over the night), a log without a
    clock (``not_checked``): :mod:`.time_checks` and :mod:`.clock_steps`.

The modules
-----------
- :mod:`.results`        :class:`Check`, :class:`SourceSummary`, :class:`IntegrityResult`
- :mod:`.helpers`        runs, robust sigmas, the statistic/threshold records, ``not_checked``
- :mod:`.validity`       ``invalid_flag``, ``contradiction``
- :mod:`.plausibility`   ``jump`` (and the fault checks below)
- :mod:`.role_witnesses` ``compass_witness``, ``log_witness``
- :mod:`.sensor_faults`  ``frozen``, ``stuck``, ``out_of_range``
- :mod:`.latency`        ``latency``
- :mod:`.availability`   ``dropout``
- :mod:`.consistency`    ``velocity``, ``heading``, ``speed``
- :mod:`.time_checks`    ``leap_second``, ``week_rollover``, ``clock_drift``, ``no_clock``
- :mod:`.clock_steps`    ``backstep``, ``loop``
- this package           :func:`check_night`, :func:`dr_innovation_check` (``dr_2m``),
  :func:`with_dr_check`
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from dracc.core.arrays import FloatArray, IntArray
from dracc.core.config import FaultsConfig, IntegrityConfig
from dracc.core.timefmt import iso_utc
from dracc.frames import Voyage
from dracc.math.ep import OUTLIER_NIS
from dracc.math.integrity.availability import availability_checks, source_times
from dracc.math.integrity.consistency import (
    heading_consistency,
    speed_consistency,
    velocity_consistency,
)
from dracc.math.integrity.helpers import (
    MAX_EVIDENCE,
    not_checked,
    role_of,
    statistic,
    threshold,
    time_window,
)
from dracc.math.integrity.latency import latency_checks
from dracc.math.integrity.plausibility import plausibility_checks
from dracc.math.integrity.results import CHECK_KINDS, Check, IntegrityResult, SourceSummary
from dracc.math.integrity.role_witnesses import witness_checks
from dracc.math.integrity.time_checks import time_checks
from dracc.math.integrity.validity import contradiction_checks, validity_checks

__all__ = [
    "CHECK_KINDS",
    "Check",
    "IntegrityResult",
    "SourceSummary",
    "check_night",
    "dr_innovation_check",
    "with_dr_check",
]

#: a fix whose innovation against the DR exceeds this chi^2_2 value is an outlier, left
#: out of the estimated position (probability exp(-30) ~ 1e-13 per healthy fix)
DR_GATE_NIS = OUTLIER_NIS


def dr_innovation_check(
    source: str | None,
    role: str | None,
    time_ns: IntArray,
    nis: FloatArray,
    gate_m: FloatArray,
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
    win = time_window(t)
    rule = (
        f"innovation chi-square(2) beyond {DR_GATE_NIS:g} against the DR propagated from the "
        "earlier fixes with its covariance (the filter of the DR over the ground)"
    )
    if len(t) == 0:
        return not_checked(
            "plausibility",
            "dr_2m",
            source,
            role,
            "max_nis",
            "",
            rule,
            "no fix weighed against the DR",
            "no reference fix after the first",
            threshold_value=DR_GATE_NIS,
            threshold_unit="chi2",
            window=win,
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
        statistic("max_nis", float(np.nanmax(nis)), "chi2"),
        threshold(DR_GATE_NIS, "chi2", rule),
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


def check_night(
    voyage: Voyage, cfg: IntegrityConfig | None = None, faults_cfg: FaultsConfig | None = None
) -> IntegrityResult | None:
    """Every integrity check of every source of ``voyage`` (None without records);
    ``faults_cfg``: the ``[faults]`` thresholds the frozen/stuck witnesses use."""
    cfg = cfg or IntegrityConfig()
    times = source_times(voyage)
    if not times:
        return None
    start_ns = int(min(t[0] for t in times.values()))
    end_ns = int(max(t[-1] for t in times.values()))
    checks: list[Check] = []
    checks += validity_checks(voyage, cfg)
    plaus, faults = plausibility_checks(voyage, cfg, faults_cfg)
    checks += plaus
    checks += contradiction_checks(voyage, plaus, faults)
    lat_checks, lat = latency_checks(voyage, cfg)
    checks += lat_checks
    avail, summary = availability_checks(voyage, cfg, start_ns, end_ns, times)
    checks += avail
    checks += velocity_consistency(voyage, cfg, start_ns, end_ns)
    checks += heading_consistency(voyage, cfg, start_ns, end_ns)
    checks += speed_consistency(voyage, cfg, start_ns, end_ns)
    checks += witness_checks(voyage, cfg, start_ns, end_ns)
    checks += time_checks(voyage, cfg, start_ns, end_ns)
    sources = tuple(
        SourceSummary(
            key,
            role_of(voyage, key),
            int(len(times[key])),
            summary[key][0],
            summary[key][1],
            lat.get(key),
        )
        for key in sorted(times)
    )
    return IntegrityResult(tuple(checks), sources, start_ns, end_ns, cfg.false_alarm)
