"""What the simulated sensors write: the written precision, the sentence plan of an epoch,
and the canonical frames (:mod:`dracc.frames`) a perfect parser of the log returns
(:func:`sensor_readings`).

Written precision (what the frames carry, and what the NMEA writer prints):
latitude/longitude minutes 6 decimals (1.9 mm), headings and courses 3 decimals of a degree,
speeds 3 decimals of a knot (and km/h), rate of turn 2 decimals of deg/min, distances
3 decimals of a nautical mile, altitude and HDOP 1 decimal; times to the nanosecond in the
frames (the written log carries them to its form's resolution).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd
from pandas.api.types import union_categoricals

from dracc.core.geodesy import add_offset_ne, angdiff, k_lambda, k_phi, wrap_2pi
from dracc.core.units import DEG_RAD, KN_MPS, NMI_M
from dracc.frames import KINDS, empty_frame, make_frame
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

    compass: np.ndarray  #: sample indices of the compass rate
    log: np.ndarray
    ins: np.ndarray
    gnss: np.ndarray
    aux: np.ndarray  #: the gyro's THS and ROT (empty when aux_hz is 0)
    #: (source, sentence, sample indices) in emission order within an epoch
    order: list[tuple[str, str, np.ndarray]]
    #: (source, sentence) -> line number of each of its sentences
    lines: dict[tuple[str, str], np.ndarray]


@dataclass(frozen=True)
class Readings:
    """The canonical frames of a simulated log and what :func:`simulate` reports with them."""

    frames: dict[str, pd.DataFrame]  #: kind -> canonical frame
    roles: dict[str, str]  #: source key -> role
    zda: pd.DataFrame  #: (time_ns, source, line) of each GNSS ZDA sentence
    unit_rms: dict[str, dict[str, float]]  #: INS unit -> RMS of its written errors
    trip_m: float  #: the VLW trip at the last sample (the next segment continues from it)


def sentence_plan(p: SimParams, n: int, base_hz: float) -> SentencePlan:
    """The sentences of ``n`` samples at ``base_hz``, numbered by (sample, order in plan)."""

    def idx(hz: float) -> np.ndarray:
        step = int(round(base_hz / hz))
        return np.arange(step if p.skip_first else 0, n, step, dtype=np.int64)

    ic, il, ii, ig = idx(p.compass_hz), idx(p.log_hz), idx(p.ins_hz), idx(p.gnss_hz)
    ia = idx(p.aux_hz) if p.aux_hz > 0 else np.zeros(0, np.int64)
    plan: list[tuple[str, str, np.ndarray]] = []
    if p.compass in ("gyro", "both"):
        plan += [("GYRO", "HDT", ic), ("GYRO", "THS", ia), ("GYRO", "ROT", ia)]
    if p.compass in ("magnetic", "both"):
        plan += [("MAG", "HDG", ic)]
    plan += [("LOG", "VHW", il), ("LOG", "VBW", il), ("LOG", "VLW", il)]
    for j in (1, 2, 3):
        plan += [(f"INS{j}", "GGA", ii), (f"INS{j}", "HDT", ii), (f"INS{j}", "VTG", ii)]
    plan += [("GNSS", "GGA", ig), ("GNSS", "RMC", ig), ("GNSS", "ZDA", ig)]

    # line numbers: sort every sentence by (sample, order in plan)
    sizes = [len(s[2]) for s in plan]
    all_k = np.concatenate([s[2] for s in plan])
    all_o = np.repeat(np.arange(len(plan)), sizes)
    order = np.lexsort((all_o, all_k))
    line_all = np.empty(len(order), np.int64)
    line_all[order] = np.arange(1, len(order) + 1)
    offs = np.concatenate(([0], np.cumsum(sizes)))
    lines = {(s[0], s[1]): line_all[offs[i] : offs[i + 1]] for i, s in enumerate(plan)}
    return SentencePlan(ic, il, ii, ig, ia, plan, lines)


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
        self.time_ns = time_ns

    def __call__(self, kind: str, src: str, sent: str, kidx: np.ndarray, **cols: Any) -> None:
        m = len(kidx)
        d = {
            "time_ns": self.time_ns[kidx],
            "source": _const(m, src),
            "talker": _const(m, self.talkers[src]),
            "sentence": _const(m, sent),
            "line": self.lines[(src, sent)],
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
    ic, ia = plan.compass, plan.aux
    gyro_hdg = psi + errors["gyro_err_rad"]
    if p.compass in ("gyro", "both"):
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
    il = plan.log
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
    ii = plan.ins
    unit_rms: dict[str, dict[str, float]] = {}
    for j in (1, 2, 3):
        src = f"INS{j}"
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
    ig = plan.gnss
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
    plan = sentence_plan(p, len(time_ns), base_hz)
    rec = _Recorder(p, plan, time_ns)
    _compass_readings(rec, p, track, errors, rot_noise, plan)
    trip_m = _log_readings(rec, p, track, errors, plan, 1.0 / base_hz, trip0_m)
    unit_rms = _ins_readings(rec, p, track, errors, plan)
    _gnss_readings(rec, p, track, errors, plan)
    # With both compasses fitted the gyro holds the role 'compass'; MAG is left unassigned.
    roles = {s: SOURCES[s][0] for s, _, _ in plan.order if not (s == "MAG" and p.compass == "both")}
    zda = pd.DataFrame(
        {
            "time_ns": time_ns[plan.gnss],
            "source": np.full(len(plan.gnss), "GNSS", dtype=object),
            "line": plan.lines[("GNSS", "ZDA")],
        }
    )
    return Readings(rec.frames(), roles, zda, unit_rms, trip_m)


def unit_rms_from_frames(
    frames: dict[str, pd.DataFrame],
    time_ns: np.ndarray,
    lat: np.ndarray,
    lon: np.ndarray,
    psi: np.ndarray,
) -> dict[str, dict[str, float]]:
    """RMS of each INS unit's written errors, from the frames (as :func:`sensor_readings`
    computes it from the readings; used when faults changed the frames)."""
    out = {}
    pos, hd = frames["position"], frames["heading"]
    for j in (1, 2, 3):
        f = pos[(pos["source"] == f"INS{j}").to_numpy(bool)]
        k = np.searchsorted(time_ns, f["time_ns"].to_numpy(np.int64))
        en = (f["lat_rad"].to_numpy(float) - lat[k]) / k_phi(lat[k])
        ee = angdiff(f["lon_rad"].to_numpy(float), lon[k]) / k_lambda(lat[k])
        h = hd[(hd["source"] == f"INS{j}").to_numpy(bool)]
        kh = np.searchsorted(time_ns, h["time_ns"].to_numpy(np.int64))
        eh = angdiff(h["heading_rad"].to_numpy(float), psi[kh])
        out[f"ins{j}"] = {"lat_m": _rms(en), "lon_m": _rms(ee), "course_deg": _rms(eh) / DEG_RAD}
    return out
