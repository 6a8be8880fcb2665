"""One instrument per role, chosen by evidence; the others kept as witnesses.

A bridge often has two gyros, two logs (an EM log beside the ADCP's water track), two
GNSS receivers, an INS relaying heading and an AIS sending its own ship's integer
heading.  Where several sources could fill the compass, log or gnss role
(:func:`dracc.ingest.sources.assign_roles` hands them back as candidates), exactly one
is chosen, never several interleaved into one series.  The evidence, weighed in this
order (the first that tells the best candidates apart decides):

1. **failed**: what the reference contradicts outright -- a log reading 0.0 kn (or
   nothing) while the GNSS, or another log, shows the ship under way; a compass that
   does not turn while the ship turns through tens of degrees;
2. **what its sentences can be**: compass -- true heading (HDT, THS, PGN127250 true)
   before magnetic (HDG, HDM), an INS's own sentences (PSXN, PASHR) after them, an AIS's
   own-ship heading (``VDO``, whole degrees) last; log -- through the water before over
   the ground; gnss -- the order of the content tiers of ``assign_roles``;
3. **availability**: the share of the 10 s bins in which any candidate reports that
   this one reports too (kept if within 80 % of the best);
4. **agreement** with the reference: heading against the GNSS course over ground while
   under way, log speed against the GNSS speed over ground, a receiver against the other
   receivers' median position -- the RMS of the difference, drift angle and current
   included for every candidate alike (kept if within 1.5x the best plus a floor);
5. **resolution**: the step the readings are logged with
   (:func:`dracc.core.resolution.quantum`; kept if within 5x the finest, an unknown step
   counting as fine);
6. more readings, then the key (a deterministic tie).

Every runner-up is named with the step at which it lost: the notes say what was chosen,
over what and why, and the runners-up stay witnesses for the consistency checks.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import pandas as pd

from dracc.core.arrays import FloatArray, IntArray, hold_at
from dracc.core.resolution import (
    HEADING_QUANTA_RAD,
    POSITION_QUANTA_RAD,
    SPEED_QUANTA_MPS,
    quantum,
)
from dracc.core.units import DEG_RAD, KN_MPS, NS_PER_S
from dracc.frames import RoleChoice, SourceInfo
from dracc.ingest.sources import GNSS_FAMILY, N2K_HEADING, N2K_POSITION

__all__ = ["CHOSEN_ROLES", "choice_note", "choose_roles", "rank_sources"]

CHOSEN_ROLES = ("gnss", "compass", "log")  #: the GNSS first: the others' reference
#: availability bins (s); a candidate within AVAILABLE_SHARE of the best is as available
BIN_S = 10.0
AVAILABLE_SHARE = 0.8
#: agreement: within AGREE_FACTOR x the best RMS plus the role's floor is as good
AGREE_FACTOR = 1.5
#: resolution: within RESOLUTION_FACTOR x the finest is as fine
RESOLUTION_FACTOR = 5.0
#: under way: the reference speed over ground above this (m/s, ~2 kn)
UNDER_WAY_MPS = 1.0
#: a log reading below this (m/s, ~0.2 kn) while under way reads nothing
LOG_ZERO_MPS = 0.1
#: a failed log: zero at more than this share of the time under way
LOG_ZERO_SHARE = 0.5
#: a reference (or the others) turning through more than this (deg) while the candidate
#: stays within two quanta of one value: the candidate does not turn
TURN_DEG = 20.0
#: a reading older than this (s) is not held to a reference time
HOLD_S = 5.0
#: the track made good between fixes this far apart (s), where no COG/SOG is sent
TRACK_STEP_S = 10.0
EARTH_RADIUS_M = 6371000.0  #: a local scale for metres between nearby fixes

UNITS = {"compass": ("°", 1.0 / DEG_RAD), "log": (" kn", 1.0 / KN_MPS), "gnss": (" m", 1.0)}
FLOORS = {"compass": 1.0, "log": 0.1, "gnss": 5.0}  #: in display units
KIND_NAMES = {
    "compass": ("true heading", "magnetic heading", "an INS's heading", "AIS own-ship heading"),
    "log": ("speed through the water", "speed over the ground only"),
    "gnss": (
        "satellite talker",
        "NMEA 2000 positions",
        "NMEA 2000 positions beside heading",
        "own-ship AIS",
    ),
}
FRAME_OF = {"compass": "heading", "log": "water", "gnss": "position"}


@dataclass
class Evidence:
    """What was weighed for one candidate (display units: deg, kn, m)."""

    key: str
    kind: int  #: index into KIND_NAMES[role]: lower is what the role is made of
    samples: int
    availability: float = 0.0  #: share of the bins any candidate reports in
    resolution: float = 0.0  #: quantum of the readings
    rms: float | None = None  #: RMS difference from the reference
    offset: float | None = None  #: median difference from the reference
    failed: str | None = None  #: why the reference contradicts it outright

    def figures(self, role: str) -> dict[str, object]:
        return {
            "kind": KIND_NAMES[role][self.kind],
            "samples": self.samples,
            "availability": round(self.availability, 4),
            "resolution": self.resolution,
            "rms_vs_reference": None if self.rms is None else round(self.rms, 4),
            "offset_vs_reference": None if self.offset is None else round(self.offset, 4),
            "failed": self.failed,
        }


# ----------------------------------------------------------------- the figures


def _availability(times: dict[str, IntArray]) -> dict[str, float]:
    """Each candidate's share of the bins in which any candidate reports."""
    bins = {k: np.unique(t // int(BIN_S * NS_PER_S)) for k, t in times.items()}
    union = np.unique(np.concatenate(list(bins.values()))) if bins else np.zeros(0)
    return {k: (b.size / union.size if union.size else 0.0) for k, b in bins.items()}


def _series(df: pd.DataFrame, key: str, col: str) -> tuple[IntArray, FloatArray]:
    d = df[(df["source"] == key).to_numpy()]
    v = d[col].to_numpy(float)
    ok = np.isfinite(v)
    t = d["time_ns"].to_numpy(np.int64)[ok]
    order = np.argsort(t, kind="stable")
    return t[order], v[ok][order]


def _ground_reference(
    frames: dict[str, pd.DataFrame], reference_keys: list[str]
) -> tuple[IntArray, FloatArray, FloatArray] | None:
    """(time, COG rad, SOG m/s) of one source: the GNSS's course and speed over ground
    (else any source's), else the track made good between its fixes (COG NaN where a
    source sends speed without a true course, as NMEA 2000 magnetic COG)."""
    g = frames.get("ground")
    if g is not None and len(g):
        use = _one_source(g, np.isfinite(g["sog_mps"].to_numpy(float)), reference_keys)
        if use is not None and np.isfinite(use["cog_rad"].to_numpy(float)).mean() > 0.5:
            t = use["time_ns"].to_numpy(np.int64)
            o = np.argsort(t, kind="stable")
            return t[o], use["cog_rad"].to_numpy(float)[o], use["sog_mps"].to_numpy(float)[o]
    return _track_made_good(frames.get("position"), reference_keys)


def _one_source(df: pd.DataFrame, ok: np.ndarray, reference_keys: list[str]) -> pd.DataFrame | None:
    """The ``ok`` rows of one source, never two interleaved: of the reference keys where
    they have rows, else of any; the one with most rows; None under 10 rows."""
    mine = ok & df["source"].isin(reference_keys).to_numpy()
    use = df[mine] if mine.any() else df[ok]
    if len(use) < 10:
        return None
    key = use["source"].astype(str).value_counts().index[0]
    return use[(use["source"] == key).to_numpy()]


def _track_made_good(
    pos: pd.DataFrame | None, reference_keys: list[str]
) -> tuple[IntArray, FloatArray, FloatArray] | None:
    """Course and speed made good between fixes at least TRACK_STEP_S apart."""
    if pos is None or not len(pos):
        return None
    ok = (pos["quality"].to_numpy() != 0) & np.isfinite(pos["lat_rad"].to_numpy(float))
    use = _one_source(pos, ok, reference_keys)
    if use is None:
        return None
    t = use["time_ns"].to_numpy(np.int64)
    o = np.argsort(t, kind="stable")
    t, la, lo = t[o], use["lat_rad"].to_numpy(float)[o], use["lon_rad"].to_numpy(float)[o]
    j = np.searchsorted(t, t + int(TRACK_STEP_S * NS_PER_S))
    i = np.flatnonzero(j < t.size)
    if i.size < 10:
        return None
    j = j[i]
    dt = (t[j] - t[i]) / NS_PER_S
    dn = (la[j] - la[i]) * EARTH_RADIUS_M
    de = np.angle(np.exp(1j * (lo[j] - lo[i]))) * EARTH_RADIUS_M * np.cos(la[i])
    return (t[i] + t[j]) // 2, np.arctan2(de, dn), np.hypot(dn, de) / dt


def _held(t: IntArray, v: FloatArray, at: IntArray) -> FloatArray:
    return hold_at(t, v, at, int(HOLD_S * NS_PER_S))


def _rms_offset(d: FloatArray) -> tuple[float | None, float | None]:
    d = d[np.isfinite(d)]
    if d.size < 10:
        return None, None
    return float(np.sqrt(np.mean(d**2))), float(np.median(d))


# ----------------------------------------------------------------- per role


def _compass_evidence(
    frames: dict[str, pd.DataFrame],
    keys: list[str],
    infos: dict[str, SourceInfo],
    ref_keys: list[str],
) -> list[Evidence]:
    hd = frames["heading"]
    ref = _ground_reference(frames, ref_keys)
    out = []
    series = {}
    for k in keys:
        d = hd[(hd["source"] == k).to_numpy()]
        h = d["heading_rad"].to_numpy(float)
        var = d["variation_rad"].to_numpy(float)
        dev = d["deviation_rad"].to_numpy(float)
        magnetic = (d["reference"] == "M").to_numpy()
        # as the DR would take it: magnetic + deviation + variation where sent (B2)
        true_h = h + np.where(magnetic, np.nan_to_num(dev) + np.nan_to_num(var), 0.0)
        ok = np.isfinite(h)
        t = d["time_ns"].to_numpy(np.int64)[ok]
        o = np.argsort(t, kind="stable")
        series[k] = (t[o], true_h[ok][o])
        sents = infos[k].sentences if k in infos else {}
        if sents.get("VDO") and not (set(sents) - {"VDO", "GGA", "GLL", "RMC", "VTG"}):
            kind = 3
        elif any(sents.get(x) for x in ("PSXN", "PASHR")) and not any(
            sents.get(x) for x in ("HDT", "THS", "HDG", "HDM")
        ):
            kind = 2
        elif np.mean(magnetic[ok]) > 0.5 if ok.any() else False:
            kind = 1
        else:
            kind = 0
        res_deg = quantum(h[ok], HEADING_QUANTA_RAD) / DEG_RAD
        e = Evidence(k, kind, int(ok.sum()), resolution=res_deg)
        out.append(e)
    if ref is not None:
        tr, cog, sog = ref
        moving = sog > UNDER_WAY_MPS
        for e in out:
            t, h = series[e.key]
            at = tr[moving]
            hh = _held(t, np.unwrap(h), at) if t.size else np.full(at.shape, np.nan)
            d = np.angle(np.exp(1j * (hh - cog[moving]))) / DEG_RAD
            e.rms, e.offset = _rms_offset(d)
            ref_turn = _turn_deg(cog[moving])
            if ref_turn > TURN_DEG and t.size and _turn_deg(h) <= 2 * e.resolution:
                e.failed = (
                    f"does not turn ({_turn_deg(h):.1f}°) while the GNSS course turns "
                    f"through {ref_turn:.0f}°"
                )
    _availability_into(out, {k: v[0] for k, v in series.items()})
    return out


def _turn_deg(h_rad: FloatArray) -> float:
    """How far a heading series turns: the 1-99 % spread of its unwrapped values (deg)."""
    h = h_rad[np.isfinite(h_rad)]
    if h.size < 2:
        return 0.0
    u = np.unwrap(h)
    lo, hi = np.percentile(u, [1, 99])
    return float(hi - lo) / DEG_RAD


def _log_evidence(
    frames: dict[str, pd.DataFrame], keys: list[str], ref_keys: list[str]
) -> list[Evidence]:
    w = frames["water"]
    ref = _ground_reference(frames, ref_keys)
    out, series = [], {}
    for k in keys:
        t, v = _series(w, k, "stw_mps")
        kind = 0
        if t.size == 0:
            t, v = _series(w, k, "sog_long_mps")
            kind = 1
        series[k] = (t, v)
        res_kn = quantum(v, SPEED_QUANTA_MPS) / KN_MPS
        out.append(Evidence(k, kind, int(t.size), resolution=res_kn))
    if ref is not None:
        tr, _, sog = ref
        moving = sog > UNDER_WAY_MPS
        at = tr[moving]
        for e in out:
            t, v = series[e.key]
            vv = _held(t, v, at) if t.size else np.full(at.shape, np.nan)
            e.rms, e.offset = _rms_offset((vv - sog[moving]) / KN_MPS)
            zero = ~(vv > LOG_ZERO_MPS)  # NaN (silent) counts as nothing read
            if at.size >= 10 and np.mean(zero) > LOG_ZERO_SHARE:
                e.failed = (
                    f"reads 0.0 kn (or nothing) at {100 * np.mean(zero):.0f} % of the time the "
                    f"GNSS shows the ship under way (median SOG {np.median(sog[moving]) / KN_MPS:.1f} kn)"
                )
    else:  # no GNSS: a log reading zero while the others read the ship under way
        for e in out:
            t, v = series[e.key]
            others = [series[o.key] for o in out if o.key != e.key and series[o.key][0].size]
            if not others or not t.size:
                continue
            ot = np.concatenate([x[0] for x in others])
            ov = np.concatenate([x[1] for x in others])
            o = np.argsort(ot, kind="stable")
            at = ot[o][ov[o] > UNDER_WAY_MPS]
            vv = _held(t, v, at)
            if at.size >= 10 and np.mean(~(vv > LOG_ZERO_MPS)) > LOG_ZERO_SHARE:
                e.failed = (
                    f"reads 0.0 kn at {100 * np.mean(~(vv > LOG_ZERO_MPS)):.0f} % of the time "
                    "the other logs read the ship under way"
                )
    _availability_into(out, {k: v[0] for k, v in series.items()})
    return out


def _gnss_evidence(
    frames: dict[str, pd.DataFrame], keys: list[str], kinds: dict[str, int]
) -> list[Evidence]:
    p = frames["position"]
    p = p[(p["quality"].to_numpy() != 0) & np.isfinite(p["lat_rad"].to_numpy(float))]
    out, series = [], {}
    for k in keys:
        d = p[(p["source"] == k).to_numpy()]
        t = d["time_ns"].to_numpy(np.int64)
        o = np.argsort(t, kind="stable")
        la, lo = d["lat_rad"].to_numpy(float)[o], d["lon_rad"].to_numpy(float)[o]
        series[k] = (t[o], la, lo)
        res_m = quantum(la, POSITION_QUANTA_RAD) * EARTH_RADIUS_M  # a minute of latitude is 1852 m
        out.append(Evidence(k, kinds.get(k, 0), int(t.size), resolution=res_m))
    if len(keys) >= 3:  # the others' median position is a reference only among three or more
        for e in out:
            t, la, lo = series[e.key]
            others = [series[x] for x in keys if x != e.key]
            if not t.size:
                continue
            ola = np.vstack([_held(s[0], s[1], t) for s in others])
            olo = np.vstack([_held(s[0], np.unwrap(s[2]), t) for s in others])
            with np.errstate(all="ignore"), warnings.catch_warnings():
                warnings.simplefilter("ignore", RuntimeWarning)  # an instant none covers
                mla, mlo = np.nanmedian(ola, axis=0), np.nanmedian(olo, axis=0)
            dn = (la - mla) * EARTH_RADIUS_M
            de = np.angle(np.exp(1j * (lo - mlo)))
            de = de * EARTH_RADIUS_M * np.cos(la)
            e.rms, e.offset = _rms_offset(np.hypot(dn, de))
    _availability_into(out, {k: v[0] for k, v in series.items()})
    return out


def _availability_into(out: list[Evidence], times: dict[str, IntArray]) -> None:
    for e, (k, a) in zip(out, _availability(times).items(), strict=True):
        assert e.key == k
        e.availability = a


# ----------------------------------------------------------------- the choice


def _decide(role: str, ev: list[Evidence]) -> tuple[Evidence, dict[str, str], str]:
    """The chosen candidate, why each other lost, and why the chosen one won."""
    unit, _ = UNITS[role]
    lost: dict[str, str] = {}
    for e in ev:
        if e.samples == 0:
            e.failed = "no readings with a value"
    pool = [e for e in ev if not e.failed] or list(ev)
    for e in ev:
        if e not in pool:
            lost[e.key] = f"failed: {e.failed}"
    best_kind = min(e.kind for e in pool)
    pool = _keep(
        pool,
        lost,
        lambda e: e.kind == best_kind,
        lambda e: f"{KIND_NAMES[role][e.kind]}, below {KIND_NAMES[role][best_kind]}",
    )
    a_best = max(e.availability for e in pool)
    pool = _keep(
        pool,
        lost,
        lambda e: e.availability >= AVAILABLE_SHARE * a_best,
        lambda e: (
            f"available {100 * e.availability:.0f} % of the time against {100 * a_best:.0f} %"
        ),
    )
    rms = [e.rms for e in pool if e.rms is not None]
    if rms and len(rms) == len(pool):
        r_best = min(rms)
        pool = _keep(
            pool,
            lost,
            lambda e: e.rms is not None and e.rms <= AGREE_FACTOR * r_best + FLOORS[role],
            lambda e: f"{e.rms:.2f}{unit} RMS from the reference against {r_best:.2f}{unit}",
        )
    known = [e.resolution for e in pool if e.resolution > 0]  # 0: fewer than 3 values
    q_best = min(known, default=0.0)
    pool = _keep(
        pool,
        lost,
        lambda e: e.resolution <= RESOLUTION_FACTOR * q_best or not e.resolution,
        lambda e: f"resolution {e.resolution:.3g}{unit} against {q_best:.3g}{unit}",
    )
    chosen = sorted(pool, key=lambda e: (-e.samples, e.key))[0]
    for e in pool:
        if e is not chosen:
            lost[e.key] = (
                f"as good on the evidence; {e.samples:,} readings against {chosen.samples:,}"
                if e.samples != chosen.samples
                else "as good on the evidence; the tie goes to the first key"
            )
    why = [KIND_NAMES[role][chosen.kind], f"{100 * chosen.availability:.0f} % available"]
    if chosen.rms is not None:
        why.append(f"{chosen.rms:.2f}{unit} RMS from the reference")
    if chosen.resolution:
        why.append(f"resolution {chosen.resolution:.3g}{unit}")
    return chosen, lost, ", ".join(why)


def _keep(
    pool: list[Evidence],
    lost: dict[str, str],
    keep: Callable[[Evidence], bool],
    said: Callable[[Evidence], str],
) -> list[Evidence]:
    nxt = [e for e in pool if keep(e)] or pool
    for e in pool:
        if e not in nxt:
            lost[e.key] = said(e)
    return nxt


def rank_sources(
    frames: dict[str, pd.DataFrame],
    role: str,
    keys: list[str],
    infos: dict[str, SourceInfo],
    reference_keys: list[str] = (),  # type: ignore[assignment]
    kinds: dict[str, int] | None = None,
) -> RoleChoice:
    """Choose one of ``keys`` for ``role`` ('compass', 'log' or 'gnss') by the evidence
    of ``frames``; the others are the runners-up, each with why it lost."""
    ref = list(reference_keys)
    if role == "compass":
        ev = _compass_evidence(frames, keys, infos, ref)
    elif role == "log":
        ev = _log_evidence(frames, keys, ref)
    else:
        ev = _gnss_evidence(frames, keys, kinds or {})
    chosen, lost, why = _decide(role, ev)
    return RoleChoice(
        role=role,
        chosen=chosen.key,
        why=why,
        runners_up=tuple((e.key, lost[e.key]) for e in ev if e.key != chosen.key),
        evidence={e.key: e.figures(role) for e in ev},
    )


def choose_roles(
    frames: dict[str, pd.DataFrame],
    sources: dict[str, SourceInfo],
    candidates: dict[str, list[str]],
) -> tuple[list[RoleChoice], list[str]]:
    """Fill each role of ``candidates`` (role -> keys, from ``assign_roles``) with one
    source chosen by evidence, in place on ``sources``; (choices, notes)."""
    choices, notes = [], []
    for role in CHOSEN_ROLES:
        keys = [k for k in candidates.get(role, []) if k in sources]
        holders = [k for k, s in sources.items() if role in s.roles]
        if len(holders) > 1:  # a mapped talker that several sources share: one of them
            keys = holders
            for k in holders:
                sources[k].roles.remove(role)
        frame = frames.get(FRAME_OF[role])
        if frame is None or not len(frame):
            continue
        gnss = [k for k, s in sources.items() if "gnss" in s.roles]
        if len(holders) == 1:  # given by the configuration or by name: the others witness
            others = [] if role == "gnss" else _same_kind(frame, role, sources)
            others = [k for k in others if k != holders[0]]
            if others:
                c = rank_sources(frames, role, [*holders, *others], sources, gnss)
                choices.append(_given(c, holders[0]))
            continue
        if len(keys) < 2:
            continue
        c = rank_sources(frames, role, keys, sources, gnss, _gnss_kinds(sources, keys))
        sources[c.chosen].roles.append(role)
        choices.append(c)
        notes.append(choice_note(c))
    return choices, notes


def _same_kind(frame: pd.DataFrame, role: str, sources: dict[str, SourceInfo]) -> list[str]:
    """The sources that could witness for ``role``: a compass's or a log's readings with a
    value, from a source that is not an INS or a GNSS and sends no fixes of its own."""
    col = "heading_rad" if role == "compass" else "stw_mps"
    keys = frame["source"][np.isfinite(frame[col].to_numpy(float))].astype(str).unique()
    fixes = {"GGA", "GLL", "RMC", "GNS", "VDO", *N2K_POSITION}
    return [
        str(k)
        for k in keys
        if k in sources
        and not (set(sources[k].roles) & {"gnss", "ins1", "ins2", "ins3"})
        and not any(sources[k].sentences.get(x) for x in fixes)
    ]


def _given(c: RoleChoice, holder: str) -> RoleChoice:
    """``c`` with the role kept where the configuration or a name put it."""
    return RoleChoice(
        role=c.role,
        chosen=holder,
        why=f"given by the configuration or its name ({c.evidence[holder]['kind']})",
        runners_up=tuple(
            (k, f"the role is given to {holder}; the evidence would say: {why}")
            if k != c.chosen
            else (k, f"the role is given to {holder}; the evidence would have chosen {k}")
            for k, why in ((k, dict(c.runners_up).get(k, "")) for k in c.evidence)
            if k != holder
        ),
        evidence=c.evidence,
    )


def _gnss_kinds(sources: dict[str, SourceInfo], keys: list[str]) -> dict[str, int]:
    """The content tier of each gnss candidate (the order of ``assign_roles``)."""
    out = {}
    for k in keys:
        s = sources[k]
        talker = s.talkers.most_common(1)[0][0] if s.talkers else ""
        n2k_pos = any(s.sentences.get(y) for y in N2K_POSITION)
        n2k_hdg = any(s.sentences.get(y) for y in N2K_HEADING)
        out[k] = (
            0 if talker in GNSS_FAMILY else 1 if n2k_pos and not n2k_hdg else 2 if n2k_pos else 3
        )
    return out


def choice_note(c: RoleChoice) -> str:
    """The choice in words: chosen, why, and every runner-up with why it lost."""
    others = "; ".join(f"{k}: {why}" for k, why in c.runners_up)
    return (
        f"{c.role}: {c.chosen} chosen by evidence among {len(c.runners_up) + 1} candidates "
        f"({c.why}); kept as witnesses: {others}"
    )
