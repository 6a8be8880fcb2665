"""consistency / ``compass_witness`` and ``log_witness``: the chosen compass and log
against the candidates not chosen for the role (:class:`dracc.frames.RoleChoice`).

Two gyros, two logs: one fills the role, the other is a witness.  The difference
``d(t)`` between them, sampled every ``consistency_interval_s`` (finer, down to 1 s, where
both report faster), has a constant part (a
compass's error, two logs' different scales) that is an accuracy figure, reported as
evidence ("gyro_2 reads 0.90° above gyro_1, steady"), and a varying part that two
healthy instruments keep within their noise:

- compasses: ``d = w - c`` (true headings), ``x = d - median(d)``;
- logs: the witness's scale against the chosen log ``k = sum(w c) / sum(c^2)`` (least
  squares through the origin), ``x = w - k c``.

Fails beyond ``max(floor, z s)``, ``s`` the robust tail sigma of ``x`` and ``z`` the
Bonferroni normal quantile at ``[integrity] false_alarm`` over the instants (the floors:
``heading_gate_min_deg``; A.824's speed accuracy).  A witness the choice found failed
(a log reading 0.0 kn while the ship moves, a compass that does not turn) fails with
that evidence.  Which of the two departs is for the other checks to say (the compass
against the INS, the log against the ground speed); this one says that they disagree,
when, and by how much.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dracc.core.arrays import FloatArray, IntArray
from dracc.core.config import IntegrityConfig
from dracc.core.geodesy import angdiff
from dracc.core.timefmt import iso_utc
from dracc.core.units import DEG_RAD, KN_MPS, NS_PER_S
from dracc.frames import RoleChoice, Voyage
from dracc.math.deadreckoning import true_heading_rad
from dracc.math.deviation.sampling import align_at
from dracc.math.integrity.consistency import speed_accuracy_mps
from dracc.math.integrity.helpers import (
    MAX_EVIDENCE,
    covered_instants,
    not_checked,
    runs,
    statistic,
    tail_sigma,
    threshold,
    time_window,
    z_two_sided,
)
from dracc.math.integrity.results import Check

__all__ = ["witness_checks"]

#: fewer common instants than this: not checked
MIN_INSTANTS = 30
#: the constant part fails beyond these: two gyros within IMO A.424's settle-point error
#: and a compass's residual deviation stay within 5°; two logs within A.824's 2 % each
#: differ in scale by at most 1.02 / 0.98 - 1 = 4.1 %
OFFSET_GATE_DEG = 5.0
SCALE_GATE = 1.02 / 0.98 - 1.0
#: "steady": the offset's change from the first to the last third of the night, within
#: this share of the gate
STEADY_SHARE = 0.5


def witness_checks(voyage: Voyage, cfg: IntegrityConfig, start_ns: int, end_ns: int) -> list[Check]:
    """One check per witness of the compass and the log."""
    out = []
    for choice in voyage.choices:
        if choice.role not in ("compass", "log"):
            continue
        for key in choice.witnesses:
            out.append(_pair_check(voyage, cfg, choice, key, start_ns, end_ns))
    return out


def _series(voyage: Voyage, role: str, key: str) -> tuple[IntArray, FloatArray]:
    """(time, value): true heading (B2)/(B3) in rad, or speed through the water in m/s."""
    if role == "compass":
        h = voyage.frames["heading"]
        h = h[(h["source"] == key).to_numpy() & np.isfinite(h["heading_rad"].to_numpy(float))]
        v = true_heading_rad(  # (B2) magnetic with the sentence's deviation and variation, (B3)
            h["heading_rad"].to_numpy(float),
            h["reference"].astype(object).to_numpy(),
            h["deviation_rad"].to_numpy(float),
            h["variation_rad"].to_numpy(float),
            missing_variation="zero",
        ).heading_rad
    else:
        w = voyage.frames["water"]
        w = w[(w["source"] == key).to_numpy()]
        v = w["stw_mps"].to_numpy(float)
        if not np.isfinite(v).any():
            v = w["sog_long_mps"].to_numpy(float)
        h = w
    t = h["time_ns"].to_numpy(np.int64)
    ok = np.isfinite(v)
    o = np.argsort(t[ok], kind="stable")
    return t[ok][o], v[ok][o]


@dataclass(frozen=True)
class _Difference:
    """The witness against the chosen instrument at the common instants."""

    instants: IntArray
    ok: np.ndarray  #: instants where both have a reading
    x: FloatArray  #: the varying part (deg or kn)
    level: FloatArray  #: the difference whose drift is reported (deg or kn)
    offset: float  #: median difference (deg or kn)
    scale: float | None  #: the witness log's scale against the chosen one


def _difference(
    voyage: Voyage, cfg: IntegrityConfig, role: str, keys: tuple[str, str], span: tuple[int, int]
) -> _Difference:
    compass = role == "compass"
    (tc, vc), (tw, vw) = (_series(voyage, role, k) for k in keys)
    instants = covered_instants([tc, tw], *span, _step_ns(cfg, tc, tw))
    gap = cfg.consistency_max_gap_s
    c = align_at(tc, vc[None, :], instants, gap, circular=(compass,))[0][0]
    w = align_at(tw, vw[None, :], instants, gap, circular=(compass,))[0][0]
    if compass:
        d = angdiff(w, c) / DEG_RAD
        ok = np.isfinite(d)
        offset = float(np.median(d[ok])) if ok.any() else float("nan")
        return _Difference(instants, ok, d - offset, d, offset, None)
    ok = np.isfinite(w) & np.isfinite(c)
    cc, ww = c[ok], w[ok]
    scale = float(np.sum(ww * cc) / np.sum(cc**2)) if np.any(cc > 0) else float("nan")
    x = (w - scale * c) / KN_MPS
    offset = float(np.median((w - c)[ok]) / KN_MPS) if ok.any() else float("nan")
    return _Difference(instants, ok, x, x, offset, scale)


def _pair_check(
    voyage: Voyage,
    cfg: IntegrityConfig,
    choice: RoleChoice,
    key: str,
    start_ns: int,
    end_ns: int,
) -> Check:
    role, chosen = choice.role, choice.chosen
    compass = role == "compass"
    name, unit = ("compass_witness", "deg") if compass else ("log_witness", "kn")
    rule = (
        "witness true heading minus the compass's, its constant part removed"
        if compass
        else "witness log speed minus the chosen log's scaled to it"
    )

    def skip(message: str, why: str) -> Check:
        return not_checked(
            "consistency", name, key, role, f"{role}_disagreement", unit, rule, message, why
        )

    failed = choice.evidence.get(key, {}).get("failed")
    if not choice.evidence.get(key, {}).get("samples", 1):  # a device silent in this kind
        return skip(
            f"{key}: sends no {role} reading with a value to compare with {chosen}",
            "no readings with a value",
        )
    diff = _difference(voyage, cfg, role, (chosen, key), (start_ns, end_ns))
    ok, x, n = diff.ok, diff.x, int(diff.ok.sum())
    if n < MIN_INSTANTS and not failed:
        return skip(
            f"{key}: fewer than {MIN_INSTANTS} instants beside {chosen} (the {role})",
            "fewer than 30 common instants",
        )
    s = tail_sigma(x[ok]) if n >= MIN_INSTANTS else float("nan")
    z = z_two_sided(cfg.false_alarm, max(n, 1))
    floor = (
        cfg.heading_gate_min_deg if compass else speed_accuracy_mps(_speed(voyage, chosen)) / KN_MPS
    )
    gate = max(floor, z * s) if np.isfinite(s) else floor
    ev = _evidence(voyage, diff, gate, unit, failed, compass, (chosen, key))
    worst = float(np.nanmax(np.abs(x[ok]))) if ok.any() else float("nan")
    drift = _drift(diff.level, ok)
    msg = _message(key, chosen, role, diff, worst, gate, drift, failed, bool(ev))
    return Check(
        "consistency",
        name,
        key,
        role,
        "fail" if ev else "pass",
        statistic(f"{role}_disagreement", worst, unit),
        threshold(
            gate,
            unit,
            f"max({'[integrity] heading_gate_min_deg' if compass else 'A.824 speed accuracy'}"
            f", z s): z {z:.2f} at {cfg.false_alarm:g} per night, s the robust tail sigma",
        ),
        time_window(diff.instants[ok]),
        cfg.false_alarm,
        msg,
        ev,
        detail={
            "against": chosen,
            "offset": diff.offset,
            "scale": diff.scale,
            "drift": drift,
            "sigma": s,
            "unit": unit,
        },
    )


def _speed(voyage: Voyage, key: str) -> float:
    """The median speed through the water of log ``key`` (m/s)."""
    v = _series(voyage, "log", key)[1]
    return float(np.median(v)) if v.size else 0.0


def _evidence(
    voyage: Voyage,
    diff: _Difference,
    gate: float,
    unit: str,
    failed: str | None,
    compass: bool,
    keys: tuple[str, str],
) -> tuple[dict[str, object], ...]:
    """The spells beyond the gate, led by what fails the pair as a whole."""
    over = diff.ok & (np.abs(diff.x) > gate)
    ev: tuple[dict[str, object], ...] = tuple(
        {
            "from": iso_utc(unit="ms", time_ns=diff.instants[a]),
            "to": iso_utc(unit="ms", time_ns=diff.instants[b - 1]),
            f"max_{unit}": float(np.nanmax(np.abs(diff.x[a:b]))),
        }
        for a, b in runs(over)[:MAX_EVIDENCE]
    )
    off, scale = diff.offset, diff.scale
    if failed:
        return ({"why": failed}, *ev)
    if compass and abs(off) > OFFSET_GATE_DEG and _variation_known(voyage, keys):
        return ({"why": f"constant difference {off:+.2f}° beyond {OFFSET_GATE_DEG:g}°"}, *ev)
    if not compass and scale is not None and abs(scale - 1.0) > SCALE_GATE:
        return ({"why": f"scale {scale:.3f} beyond 1 ± {SCALE_GATE:.3f}"}, *ev)
    return ev


def _step_ns(cfg: IntegrityConfig, *times: IntArray) -> int:
    """The comparison step: ``consistency_interval_s``, or finer for two instruments that
    both report faster (two readings of the slower one a step, at least 1 s): a short log
    of two gyros still has its instants."""
    typical = [float(np.median(np.diff(t))) / NS_PER_S for t in times if t.size > 1]
    finest = max([1.0, *(2.0 * x for x in typical)])
    return int(min(cfg.consistency_interval_s, finest) * NS_PER_S)


def _variation_known(voyage: Voyage, keys: tuple[str, ...]) -> bool:
    """Both headings true, or magnetic with a variation sent: their constant difference
    is the compasses' own (not the local variation taken as 0)."""
    h = voyage.frames["heading"]
    h = h[h["source"].isin(keys).to_numpy()]
    magnetic = (h["reference"] == "M").to_numpy()
    return bool(np.all(np.isfinite(h["variation_rad"].to_numpy(float))[magnetic]))


def _drift(d: FloatArray, ok: np.ndarray) -> float:
    """The difference's change from the first third of the instants to the last."""
    i = np.flatnonzero(ok)
    if i.size < 3 * 3:
        return float("nan")
    third = i.size // 3
    return float(np.median(d[i[-third:]]) - np.median(d[i[:third]]))


def _message(
    key: str,
    chosen: str,
    role: str,
    diff: _Difference,
    worst: float,
    gate: float,
    drift: float,
    failed: str | None,
    departs: bool,
) -> str:
    offset, scale = diff.offset, diff.scale
    if role == "compass":
        level = f"reads {abs(offset):.2f}° {'above' if offset >= 0 else 'below'} {chosen}"
        u = "°"
    else:
        pct = 100 * ((float("nan") if scale is None else scale) - 1)
        level = f"reads {abs(pct):.1f} % {'above' if pct >= 0 else 'below'} {chosen}"
        u = " kn"
    steady = (
        "steady"
        if np.isfinite(drift) and abs(drift) <= STEADY_SHARE * gate
        else f"changing by {drift:+.2f}{u} over the night"
        if np.isfinite(drift)
        else ""
    )
    head = f"{key} (witness for the {role}) {level}" + (f", {steady}" if steady else "")
    if failed:
        return f"{key} (witness for the {role}) {failed}"
    if departs and abs(worst) <= gate:  # only the constant part is out of bounds
        return f"{head}: more than two healthy instruments differ by; one of them is wrong"
    if departs:
        return (
            f"{head}; the two depart from each other by up to {worst:.2f}{u} beyond that "
            f"(gate {gate:.2f}{u}): one of them is wrong there"
        )
    return f"{head}; within {worst:.2f}{u} of each other beyond that (gate {gate:.2f}{u})"
