"""What the simulated sensors write: the written precision, the sentence plan of an epoch,
and the canonical frames (:mod:`dracc.frames`) a perfect parser of the log returns
(:func:`sensor_readings`).

Written precision (what the frames carry, and what the NMEA writer prints):
latitude/longitude minutes 6 decimals (1.9 mm), headings and courses 3 decimals of a degree,
speeds 3 decimals of a knot (and km/h), rate of turn 2 decimals of deg/min, distances
3 decimals of a nautical mile, altitude and HDOP 1 decimal; times to the nanosecond in the
frames (the written log carries them to its form's resolution).

Clocks (``SimParams.phases_s``, ``latency_s``): a source samples the truth at its grid
shifted by its phase; a record with its own time of fix (GGA, RMC, ZDA) has ``time_ns``
the sample instant and, for a source with a latency, ``recv_ns`` the instant plus the
latency; a record without one (HDT, THS, HDG, ROT, VHW, VBW, VLW, VTG) is timed by its
receipt, ``time_ns`` the instant plus the latency.  Lines are numbered in the order the
logger receives the sentences (by receive instant, then the plan's order).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd
from pandas.api.types import union_categoricals

from dracc.core.geodesy import add_offset_ne, angdiff, k_lambda, k_phi, wrap_2pi
from dracc.core.units import DEG_RAD, KN_MPS, NMI_M
from dracc.frames import KINDS, MISSING_NS, empty_frame, make_frame
from dracc.sim.faults import OWN_TIME_SENTENCES
from dracc.sim.params import SimParams
from dracc.sim.truth import deviation_curve_rad

# Written precision (see module docstring); shared with nmea_out.
LAT_MICROMIN = 1e6  #: minutes of arc written with 6 decimals
ANGLE_DEC = 3  #: headings/courses in degrees
SPEED_DEC = 3  #: knots and km/h
ROT_DEC = 2  #: deg/min
DIST_DEC = 3  #: nautical miles
ALT_DEC = 1
HDOP_DEC = 1

#: source key -> (role, talker) in emission order within an epoch
SOURCES = {
    "GYRO": ("compass", "HE"),
    "MAG": ("compass", "HC"),
    "LOG": ("log", "VW"),
    "INS1": ("ins1", "IN"),
    "INS2": ("ins2", "IN"),
    "INS3": ("ins3", "IN"),
    "GNSS": ("gnss", "GP"),
}


def q_angle_rad(a_rad: Any) -> np.ndarray:
    """An angle in [0, 2pi) as written: degrees to ANGLE_DEC decimals (360.000 -> 0.000)."""
    s = 10.0**ANGLE_DEC
    v = np.rint(np.asarray(wrap_2pi(a_rad), float) / DEG_RAD * s)
    v = np.where(v >= 360 * s, v - 360 * s, v)
    return v / s * DEG_RAD


def q_signed(x: Any, scale: float, dec: int) -> np.ndarray:
    """``x`` (SI) written as ``x / scale`` to ``dec`` decimals, read back in SI."""
    s = 10.0**dec
    return np.rint(np.asarray(x, float) / scale * s) / s * scale


def q_latlon_rad(a_rad: Any) -> np.ndarray:
    """Latitude or longitude as written: degrees and minutes to 6 decimals of a minute."""
    a = np.asarray(a_rad, float)
    micro = np.rint(np.abs(a) / DEG_RAD * 60.0 * LAT_MICROMIN)
    deg = np.floor_divide(micro, 60.0 * LAT_MICROMIN)
    minutes = (micro - deg * 60.0 * LAT_MICROMIN) / LAT_MICROMIN
    return np.sign(a) * (deg + minutes / 60.0) * DEG_RAD


@dataclass(frozen=True)
class SentencePlan:
    """Which sentences each source writes at which samples, and their line numbers."""

    #: (source, sentence, sample indices) in emission order within an epoch
    order: list[tuple[str, str, np.ndarray]]
    #: (source, sentence) -> line number of each of its sentences
    lines: dict[tuple[str, str], np.ndarray]
    #: source -> its latency in ns (sources with a latency only)
    latency_ns: dict[str, int]

    def idx(self, source: str, sentence: str) -> np.ndarray:
        """The sample indices of ``source``'s ``sentence``."""
        return next(k for s, t, k in self.order if (s, t) == (source, sentence))


@dataclass(frozen=True)
class Readings:
    """The canonical frames of a simulated log and what :func:`simulate` reports with them."""

    frames: dict[str, pd.DataFrame]  #: kind -> canonical frame
    roles: dict[str, str]  #: source key -> role
    zda: pd.DataFrame  #: (time_ns, source, line) of each GNSS ZDA sentence
    unit_rms: dict[str, dict[str, float]]  #: INS unit -> RMS of its written errors
    trip_m: float  #: the VLW trip at the last sample (the next segment continues from it)
    clocks: dict[str, dict[str, float]]  #: source -> its clock truth (:func:`clock_truth`)


def sentence_plan(p: SimParams, time_ns: np.ndarray, base_hz: float) -> SentencePlan:
    """The sentences of the samples at ``time_ns`` (``base_hz``), each source on its grid
    shifted by its phase (the grid of the whole voyage: ``p.t0_s`` on), numbered by
    (receive instant, order in plan)."""
    n = len(time_ns)
    k0 = int(round(p.t0_s * base_hz))  # this segment's first sample in the voyage's grid
    phase, latency_ns = p.clock_steps()

    def idx(hz: float, src: str) -> np.ndarray:
        if hz <= 0:
            return np.zeros(0, np.int64)
        step = int(round(base_hz / hz))
        first = (phase.get(src, 0) - k0) % step
        if p.skip_first and first == 0:
            first = step
        return np.arange(first, n, step, dtype=np.int64)

    plan: list[tuple[str, str, np.ndarray]] = []
    if p.compass in ("gyro", "both"):
        ia = idx(p.aux_hz, "GYRO")
        plan += [
            ("GYRO", "HDT", idx(p.compass_hz, "GYRO")),
            ("GYRO", "THS", ia),
            ("GYRO", "ROT", ia),
        ]
    if p.compass in ("magnetic", "both"):
        plan += [("MAG", "HDG", idx(p.compass_hz, "MAG"))]
    il = idx(p.log_hz, "LOG")
    plan += [("LOG", "VHW", il), ("LOG", "VBW", il), ("LOG", "VLW", il)]
    for j in (1, 2, 3):
        ii = idx(p.ins_hz, f"INS{j}")
        plan += [(f"INS{j}", "GGA", ii), (f"INS{j}", "HDT", ii), (f"INS{j}", "VTG", ii)]
    ig = idx(p.gnss_hz, "GNSS")
    plan += [("GNSS", "GGA", ig), ("GNSS", "RMC", ig), ("GNSS", "ZDA", ig)]

    # line numbers: sort every sentence by (receive instant, order in plan)
    sizes = [len(s[2]) for s in plan]
    recv = np.concatenate([time_ns[k] + latency_ns.get(s, 0) for s, _, k in plan])
    all_o = np.repeat(np.arange(len(plan)), sizes)
    order = np.lexsort((all_o, recv))
    line_all = np.empty(len(order), np.int64)
    line_all[order] = np.arange(1, len(order) + 1)
    offs = np.concatenate(([0], np.cumsum(sizes)))
    lines = {(s[0], s[1]): line_all[offs[i] : offs[i + 1]] for i, s in enumerate(plan)}
    return SentencePlan(plan, lines, latency_ns)


def _const(m: int, value: str) -> pd.Categorical:
    return pd.Categorical.from_codes(np.zeros(m, np.int8), categories=[value])


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(x**2))) if len(x) else float("nan")  # no sample: NaN


class _Recorder:
    """Collects the columns of each sentence written, per frame kind."""

    def __init__(self, p: SimParams, plan: SentencePlan, time_ns: np.ndarray) -> None:
        self.parts: dict[str, list[dict[str, Any]]] = {kind: [] for kind in KINDS}
        self.talkers = {k: v[1] for k, v in SOURCES.items()}
        self.talkers.update({f"INS{j}": t for j, t in enumerate(p.ins_talkers, start=1)})
        self.lines = plan.lines
        self.latency_ns = plan.latency_ns
        self.time_ns = time_ns

    def __call__(self, kind: str, src: str, sent: str, kidx: np.ndarray, **cols: Any) -> None:
        m = len(kidx)
        instant = self.time_ns[kidx]
        lag = self.latency_ns.get(src)
        own = sent in OWN_TIME_SENTENCES
        d = {
            "time_ns": instant if own or lag is None else instant + lag,
            "source": _const(m, src),
            "talker": _const(m, self.talkers[src]),
            "sentence": _const(m, sent),
            "line": self.lines[(src, sent)],
            "recv_ns": instant + lag if own and lag is not None else np.full(m, MISSING_NS),
        }
        d.update(cols)
        self.parts[kind].append(d)

    def frames(self) -> dict[str, pd.DataFrame]:
        """Kind -> canonical frame, every sentence in line order."""
        frames = {}
        for kind in KINDS:
            parts = self.parts[kind]
            if not parts:
                frames[kind] = empty_frame(kind)
                continue
            names = list(dict.fromkeys(c for d in parts for c in d))
            cat = {}
            for c in names:
                if c in ("source", "talker", "sentence"):
                    cat[c] = union_categoricals([d[c] for d in parts])
                else:
                    # a column one sentence lacks (e.g. HDOP in RMC) is missing there: NaN, never 0
                    cat[c] = np.concatenate(
                        [d[c] if c in d else np.full(len(d["time_ns"]), np.nan) for d in parts]
                    )
            o = np.argsort(cat["line"], kind="stable")
            frames[kind] = make_frame(kind, {c: v[o] for c, v in cat.items()})
        return frames


def _compass_readings(
    rec: _Recorder,
    p: SimParams,
    track: dict[str, np.ndarray],
    errors: dict[str, np.ndarray],
    rot_noise: np.ndarray,
    plan: SentencePlan,
) -> None:
    psi, kk = track["heading_rad"], track["compass_course_rad"]
    gyro_hdg = psi + errors["gyro_err_rad"]
    if p.compass in ("gyro", "both"):
        ic, ia = plan.idx("GYRO", "HDT"), plan.idx("GYRO", "THS")
        true_ref = np.full(len(ic), "T", dtype=object)
        rec("heading", "GYRO", "HDT", ic, heading_rad=q_angle_rad(gyro_hdg[ic]), reference=true_ref)
        rec(
            "heading",
            "GYRO",
            "THS",
            ia,
            heading_rad=q_angle_rad(gyro_hdg[ia]),
            reference=np.full(len(ia), "T", dtype=object),
        )
        rot = track["rot_radps"]
        rot_w = q_signed(rot[ia] + rot_noise[ia], DEG_RAD / 60.0, ROT_DEC)
        rec("rot", "GYRO", "ROT", ia, rot_radps=rot_w)
    if p.compass in ("magnetic", "both"):
        ic = plan.idx("MAG", "HDG")
        coeffs = tuple(c * DEG_RAD for c in p.deviation_deg)
        var_rad = p.variation_deg * DEG_RAD
        kk_meas = q_angle_rad(kk[ic] + errors["mag_err_rad"][ic])
        dev_w = (
            q_signed(deviation_curve_rad(kk_meas, coeffs), DEG_RAD, ANGLE_DEC)
            if p.hdg_deviation_field
            else np.full(len(ic), np.nan)
        )
        rec(
            "heading",
            "MAG",
            "HDG",
            ic,
            heading_rad=kk_meas,
            reference=np.full(len(ic), "M", dtype=object),
            deviation_rad=dev_w,
            variation_rad=np.full(len(ic), float(q_signed(var_rad, DEG_RAD, ANGLE_DEC))),
        )


def _log_readings(
    rec: _Recorder,
    p: SimParams,
    track: dict[str, np.ndarray],
    errors: dict[str, np.ndarray],
    plan: SentencePlan,
    dt: float,
    trip0_m: float,
) -> float:
    """Records VHW, VBW and VLW; returns the trip at the last sample."""
    il = plan.idx("LOG", "VHW")
    s1 = 1.0 + p.log_scale
    b = p.log_bias_kn * KN_MPS
    m_long = s1 * track["stw_long_mps"] + b + errors["log_noise_long_mps"]
    m_trans = s1 * track["stw_transverse_mps"] + errors["log_noise_transverse_mps"]
    m_glong = s1 * track["sog_long_mps"] + b + errors["log_ground_noise_long_mps"]
    m_gtrans = s1 * track["sog_transverse_mps"] + errors["log_ground_noise_transverse_mps"]
    rec("water", "LOG", "VHW", il, stw_mps=q_signed(m_long[il], KN_MPS, SPEED_DEC))
    rec(
        "water",
        "LOG",
        "VBW",
        il,
        stw_mps=q_signed(m_long[il], KN_MPS, SPEED_DEC),
        stw_transverse_mps=q_signed(m_trans[il], KN_MPS, SPEED_DEC),
        sog_long_mps=q_signed(m_glong[il], KN_MPS, SPEED_DEC),
        sog_transverse_mps=q_signed(m_gtrans[il], KN_MPS, SPEED_DEC),
    )
    trip = trip0_m + np.concatenate(([0.0], np.cumsum(0.5 * (m_long[1:] + m_long[:-1]) * dt)))
    rec(
        "distance",
        "LOG",
        "VLW",
        il,
        total_water_m=q_signed(p.log_total_start_nmi * NMI_M + trip[il], NMI_M, DIST_DEC),
        trip_water_m=q_signed(trip[il], NMI_M, DIST_DEC),
    )
    return float(trip[-1])


def _ins_readings(
    rec: _Recorder,
    p: SimParams,
    track: dict[str, np.ndarray],
    errors: dict[str, np.ndarray],
    plan: SentencePlan,
) -> dict[str, dict[str, float]]:
    """Records each INS unit's GGA, HDT and VTG; returns the RMS of its written errors."""
    lat, lon, psi = track["lat_rad"], track["lon_rad"], track["heading_rad"]
    vn, ve = track["vn_mps"], track["ve_mps"]
    unit_rms: dict[str, dict[str, float]] = {}
    for j in (1, 2, 3):
        src = f"INS{j}"
        ii = plan.idx(src, "GGA")
        la, lo = add_offset_ne(
            lat[ii], lon[ii], errors[f"ins{j}_north_m"][ii], errors[f"ins{j}_east_m"][ii]
        )
        qla, qlo = q_latlon_rad(la), q_latlon_rad(lo)
        rec(
            "position",
            src,
            "GGA",
            ii,
            lat_rad=qla,
            lon_rad=qlo,
            alt_m=np.full(len(ii), round(p.alt_m, ALT_DEC)),
            quality=np.ones(len(ii), np.int8),
        )
        qh = q_angle_rad(psi[ii] + errors[f"ins{j}_heading_rad"][ii])
        rec(
            "heading", src, "HDT", ii, heading_rad=qh, reference=np.full(len(ii), "T", dtype=object)
        )
        gvn = vn[ii] + errors[f"ins{j}_vn_mps"][ii]
        gve = ve[ii] + errors[f"ins{j}_ve_mps"][ii]
        rec(
            "ground",
            src,
            "VTG",
            ii,
            cog_rad=q_angle_rad(np.arctan2(gve, gvn)),
            sog_mps=q_signed(np.hypot(gvn, gve), KN_MPS, SPEED_DEC),
        )
        # RMS of the written errors (K: the m_y a reference would measure)
        en_w = (qla - lat[ii]) / k_phi(lat[ii])
        ee_w = angdiff(qlo, lon[ii]) / k_lambda(lat[ii])
        eh_w = angdiff(qh, psi[ii])
        unit_rms[f"ins{j}"] = {
            "lat_m": _rms(en_w),
            "lon_m": _rms(ee_w),
            "course_deg": _rms(eh_w) / DEG_RAD,
        }
    return unit_rms


def _gnss_readings(
    rec: _Recorder,
    p: SimParams,
    track: dict[str, np.ndarray],
    errors: dict[str, np.ndarray],
    plan: SentencePlan,
) -> None:
    lat, lon = track["lat_rad"], track["lon_rad"]
    ig = plan.idx("GNSS", "GGA")
    la, lo = add_offset_ne(lat[ig], lon[ig], errors["gnss_north_m"][ig], errors["gnss_east_m"][ig])
    qla, qlo = q_latlon_rad(la), q_latlon_rad(lo)
    for sent in ("GGA", "RMC"):
        extra = (
            {
                "alt_m": np.full(len(ig), round(p.alt_m, ALT_DEC)),
                "hdop": np.full(len(ig), round(p.gnss_hdop, HDOP_DEC)),
            }
            if sent == "GGA"
            else {}
        )
        rec(
            "position",
            "GNSS",
            sent,
            ig,
            lat_rad=qla,
            lon_rad=qlo,
            quality=np.ones(len(ig), np.int8),
            **extra,
        )
    gvn = track["vn_mps"][ig] + errors["gnss_vn_mps"][ig]
    gve = track["ve_mps"][ig] + errors["gnss_ve_mps"][ig]
    rec(
        "ground",
        "GNSS",
        "RMC",
        ig,
        cog_rad=q_angle_rad(np.arctan2(gve, gvn)),
        sog_mps=q_signed(np.hypot(gvn, gve), KN_MPS, SPEED_DEC),
    )


def sensor_readings(
    p: SimParams,
    track: dict[str, np.ndarray],
    errors: dict[str, np.ndarray],
    rot_noise: np.ndarray,
    base_hz: float,
    trip0_m: float = 0.0,
) -> Readings:
    """What every source writes: the true ``track`` plus its ``errors`` at the sentences'
    samples, quantised to the written precision; the VLW trip continues from ``trip0_m``."""
    time_ns = track["time_ns"]
    plan = sentence_plan(p, time_ns, base_hz)
    rec = _Recorder(p, plan, time_ns)
    _compass_readings(rec, p, track, errors, rot_noise, plan)
    trip_m = _log_readings(rec, p, track, errors, plan, 1.0 / base_hz, trip0_m)
    unit_rms = _ins_readings(rec, p, track, errors, plan)
    _gnss_readings(rec, p, track, errors, plan)
    # With both compasses fitted the gyro holds the role 'compass'; MAG is left unassigned.
    roles = {s: SOURCES[s][0] for s, _, _ in plan.order if not (s == "MAG" and p.compass == "both")}
    zda = pd.DataFrame(
        {
            "time_ns": time_ns[plan.idx("GNSS", "ZDA")],
            "source": np.full(len(plan.idx("GNSS", "ZDA")), "GNSS", dtype=object),
            "line": plan.lines[("GNSS", "ZDA")],
        }
    )
    clocks = clock_truth(p, plan, time_ns, base_hz)
    return Readings(rec.frames(), roles, zda, unit_rms, trip_m, clocks)


def clock_truth(
    p: SimParams, plan: SentencePlan, time_ns: np.ndarray, base_hz: float
) -> dict[str, dict[str, float]]:
    """Per source its clock as simulated: ``phase_s`` and ``latency_s`` (as applied: on
    the truth's grid, to the millisecond), ``offset_s`` -- the mean of ``time_ns`` minus
    the true sample instant over its records without a time of fix (what a time base
    has to learn; NaN for a source without such records, the GNSS) -- and
    ``offset_whole_s_stamps``, the same for stamps floored to whole seconds (TAG ``c:``
    in seconds), and ``records``, how many records the means are over."""
    phase, _ = p.clock_steps()
    out: dict[str, dict[str, float]] = {}
    for src in dict.fromkeys(s for s, _, _ in plan.order):
        lag = plan.latency_ns.get(src, 0)
        inst = [time_ns[k] for s, t, k in plan.order if s == src and t not in OWN_TIME_SENTENCES]
        t = np.concatenate(inst) if inst else np.zeros(0, np.int64)
        whole = (t + lag) // 1_000_000_000 * 1_000_000_000 - t
        out[src] = {
            "phase_s": phase.get(src, 0) / base_hz,
            "latency_s": lag / 1e9,
            "offset_s": lag / 1e9 if len(t) else float("nan"),
            "offset_whole_s_stamps": float(whole.mean()) / 1e9 if len(t) else float("nan"),
            "records": float(len(t)),
        }
    return out


def unit_rms_from_frames(
    frames: dict[str, pd.DataFrame],
    time_ns: np.ndarray,
    lat: np.ndarray,
    lon: np.ndarray,
    psi: np.ndarray,
    latency_ns: dict[str, int] | None = None,
) -> dict[str, dict[str, float]]:
    """RMS of each INS unit's written errors, from the frames (as :func:`sensor_readings`
    computes it from the readings; used when faults changed the frames).  ``latency_ns``:
    the sources' latencies (a heading is timed by its receipt)."""
    out = {}
    pos, hd = frames["position"], frames["heading"]
    lags = latency_ns or {}
    for j in (1, 2, 3):
        f = pos[(pos["source"] == f"INS{j}").to_numpy(bool)]
        t = f["time_ns"].to_numpy(np.int64)
        keep = np.isin(t, time_ns)
        k = np.searchsorted(time_ns, t[keep])
        en = (f["lat_rad"].to_numpy(float)[keep] - lat[k]) / k_phi(lat[k])
        ee = angdiff(f["lon_rad"].to_numpy(float)[keep], lon[k]) / k_lambda(lat[k])
        h = hd[(hd["source"] == f"INS{j}").to_numpy(bool)]
        th = h["time_ns"].to_numpy(np.int64) - lags.get(f"INS{j}", 0)
        keep = np.isin(th, time_ns)
        kh = np.searchsorted(time_ns, th[keep])
        eh = angdiff(h["heading_rad"].to_numpy(float)[keep], psi[kh])
        out[f"ins{j}"] = {"lat_m": _rms(en), "lon_m": _rms(ee), "course_deg": _rms(eh) / DEG_RAD}
    return out
