"""Field decoders of the numpy path: field boundaries of a group of sentences
(:class:`Fields`), the conversions of their fields to SI values (latitude/longitude,
time of day, date, angles, speeds) and the decoding of one sentence type (:func:`decode`)."""

from __future__ import annotations

import numpy as np

from dracc.core.units import KN_MPS, NMI_M
from dracc.ingest.tagblock import parse_numbers
from dracc.ingest.timebase import days_from_civil, valid_civil

DEG = np.pi / 180.0


class Fields:
    """Field boundaries of a group of sentences (rows) in ``buf``."""

    def __init__(
        self,
        buf: np.ndarray,
        commas: np.ndarray,
        c0: np.ndarray,
        nf: np.ndarray,
        body_end: np.ndarray,
    ) -> None:
        """``commas``: sorted positions of the commas inside sentence bodies; ``c0`` the
        index of each row's first comma (the one after the address), ``nf`` its count."""
        self.buf = buf
        self.nf = nf.astype(np.int64)  # data fields = number of commas
        self.c0 = c0
        self.commas = commas
        self.body_end = body_end
        self.bad = np.zeros(len(nf), dtype=bool)

    def bounds(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        """[start, end) of data field k (1-based); empty where the field is absent."""
        present = self.nf >= k
        ci = np.minimum(self.c0 + k - 1, len(self.commas) - 1)
        s = np.where(present, self.commas[ci] + 1, 0)
        cn = np.minimum(self.c0 + k, len(self.commas) - 1)
        e = np.where(self.nf > k, self.commas[cn], self.body_end)
        e = np.where(present, e, 0)
        return s, e

    def num(self, k: int, width: int = 20, decimals: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """Field k as float64, NaN where empty; rows with a non-number are marked bad.

        Returns (value, decimals) where decimals = digits after the '.' (-1 if none).
        """
        s, e = self.bounds(k)
        val, dec, invalid = parse_numbers(self.buf, s, e, width, decimals)
        self.bad |= invalid
        return val, dec

    def char(self, k: int) -> np.ndarray:
        """Field k as one byte (uint8); 0 where empty; rows with longer text marked bad."""
        s, e = self.bounds(k)
        ln = e - s
        self.bad |= ln > 1
        return np.where(ln == 1, self.buf[np.minimum(s, len(self.buf) - 1)], 0).astype(np.uint8)

    def first_char(self, k: int) -> np.ndarray:
        s, e = self.bounds(k)
        return np.where(e - s >= 1, self.buf[np.minimum(s, len(self.buf) - 1)], 0).astype(np.uint8)


def _latlon(
    F: Fields, k: int, kh: int, pos: int, neg: int, limit_deg: float
) -> tuple[np.ndarray, np.ndarray]:
    """ddmm.mmmm + hemisphere -> radians; malformed rows marked bad."""
    v, dec = F.num(k, decimals=True)
    h = F.char(kh)
    deg = np.floor(v / 100.0)
    minutes = v - 100.0 * deg
    ang = deg + minutes / 60.0  # ddmm.mmmm -> degrees
    sign = np.where(h == neg, -1.0, 1.0)
    has = ~np.isnan(v)
    bad = has & ((h != pos) & (h != neg) | (minutes >= 60.0) | (ang > limit_deg) | (v < 0))
    F.bad |= bad
    return np.where(bad, np.nan, sign * ang * DEG), dec


def _tod(F: Fields, k: int) -> np.ndarray:
    """hhmmss.sss -> ns of the day (-1 where empty); malformed rows marked bad."""
    v, _ = F.num(k)
    has = ~np.isnan(v)
    hh = np.floor(v / 10000.0)
    mm = np.floor(v / 100.0) - 100.0 * hh
    ss = v - 10000.0 * hh - 100.0 * mm
    bad = has & ((hh >= 24) | (mm >= 60) | (ss >= 61) | (v < 0))
    F.bad |= bad
    ok = has & ~bad
    ns = np.full(len(v), -1, dtype=np.int64)
    us = np.round(ss[ok] * 1e6).astype(np.int64)  # seconds to whole microseconds
    ns[ok] = ((hh[ok] * 3600 + mm[ok] * 60).astype(np.int64) * 1_000_000 + us) * 1000
    return ns


def _ymd_days(F: Fields, y: np.ndarray, m: np.ndarray, d: np.ndarray) -> np.ndarray:
    has = ~(np.isnan(y) | np.isnan(m) | np.isnan(d))
    yi = np.where(has, y, 2000).astype(np.int64)
    mi = np.where(has, m, 1).astype(np.int64)
    di = np.where(has, d, 1).astype(np.int64)
    ok = has & valid_civil(yi, mi, di)
    F.bad |= has & ~ok
    return np.where(ok, days_from_civil(yi, mi, di), -1)


def _angle(F: Fields, k: int) -> np.ndarray:
    """Degrees 0..360 -> radians; out of range marked bad."""
    v, _ = F.num(k)
    bad = ~np.isnan(v) & ((v < 0) | (v > 360))
    F.bad |= bad
    v = np.where(bad, np.nan, v)
    rad: np.ndarray = np.where(v >= 360.0, v - 360.0, v) * DEG
    return rad


def _signed(F: Fields, k: int, kh: int) -> np.ndarray:
    """Angle with E/W letter (east positive), radians."""
    v, _ = F.num(k)
    h = F.char(kh)
    bad = ~np.isnan(v) & (h != 69) & (h != 87) & (h != 0)
    F.bad |= bad
    rad: np.ndarray = np.where(h == 87, -v, v) * DEG
    return rad


def _speed(F: Fields, k_kn: int, k_kmh: int | None = None) -> np.ndarray:
    kn, _ = F.num(k_kn)
    v = kn * KN_MPS  # knots -> m/s (exact 1852/3600)
    if k_kmh is not None:
        kmh, _ = F.num(k_kmh)
        v = np.where(np.isnan(v), kmh / 3.6, v)  # km/h -> m/s where knots are empty
    return v


# ------------------------------------------------------------------- per-type decoders
def decode(stype: str, F: Fields) -> tuple[dict[str, dict[str, np.ndarray]], dict[str, np.ndarray]]:
    """Decode rows of one sentence type.

    Returns ({kind: columns}, timing) with timing = {"tod_ns", "date_days", "dec"}.
    """
    n = len(F.nf)
    tod = np.full(n, -1, dtype=np.int64)
    date = np.full(n, -1, dtype=np.int64)
    dec = np.full(n, -1, dtype=np.int8)
    out: dict[str, dict[str, np.ndarray]] = {}
    nanv = np.full(n, np.nan)
    if stype in ("HDT", "HDM", "THS"):
        h = _angle(F, 1)
        ref = F.char(2)
        if stype == "THS":
            h = np.where(ref == 86, np.nan, h)  # mode V: not valid
        # the reference as a byte ('T' 84, 'M' 77): compact between processes
        refs = np.full(n, 77 if stype == "HDM" else 84, dtype=np.uint8)
        out["heading"] = {
            "heading_rad": h,
            "reference": refs,
            "deviation_rad": nanv,
            "variation_rad": nanv,
        }
    elif stype == "HDG":
        out["heading"] = {
            "heading_rad": _angle(F, 1),
            "reference": np.full(n, 77, dtype=np.uint8),
            "deviation_rad": _signed(F, 2, 3),
            "variation_rad": _signed(F, 4, 5),
        }
    elif stype == "ROT":
        v, _ = F.num(1)
        st = F.char(2)
        v = np.where(st == 86, np.nan, v)  # status V: not valid
        out["rot"] = {"rot_radps": v * DEG / 60.0}  # deg/min -> rad/s
    elif stype == "VHW":
        out["water"] = {"stw_mps": _speed(F, 5, 7)}
    elif stype == "VBW":
        lw, _ = F.num(1)
        tw, _ = F.num(2)
        sw = F.char(3)
        lg, _ = F.num(4)
        tg, _ = F.num(5)
        sg = F.char(6)
        vw = sw != 86
        vg = sg != 86
        out["water"] = {
            "stw_mps": np.where(vw, lw * KN_MPS, np.nan),
            "stw_transverse_mps": np.where(vw, tw * KN_MPS, np.nan),
            "sog_long_mps": np.where(vg, lg * KN_MPS, np.nan),
            "sog_transverse_mps": np.where(vg, tg * KN_MPS, np.nan),
        }
    elif stype == "VLW":
        tot, _ = F.num(1)
        trip, _ = F.num(3)
        out["distance"] = {"total_water_m": tot * NMI_M, "trip_water_m": trip * NMI_M}
    elif stype == "GGA":
        tod = _tod(F, 1)
        lat, dec = _latlon(F, 2, 3, 78, 83, 90.0)
        lon, _ = _latlon(F, 4, 5, 69, 87, 180.0)
        q, _ = F.num(6)
        hdop, _ = F.num(8)
        alt, _ = F.num(9)
        out["position"] = {
            "lat_rad": lat,
            "lon_rad": lon,
            "alt_m": alt,
            "hdop": hdop,
            "quality": np.where(np.isnan(q), -1, q).astype(np.int8),
        }
    elif stype == "GNS":
        tod = _tod(F, 1)
        lat, dec = _latlon(F, 2, 3, 78, 83, 90.0)
        lon, _ = _latlon(F, 4, 5, 69, 87, 180.0)
        mode = F.first_char(6)
        qmap = np.full(256, -1, dtype=np.int8)
        for ch, qv in zip(b"NAPDRFEMS", (0, 1, 3, 2, 4, 5, 6, 7, 8), strict=True):
            qmap[ch] = qv
        hdop, _ = F.num(8)
        alt, _ = F.num(9)
        out["position"] = {
            "lat_rad": lat,
            "lon_rad": lon,
            "alt_m": alt,
            "hdop": hdop,
            "quality": qmap[mode],
        }
    elif stype == "GLL":
        lat, dec = _latlon(F, 1, 2, 78, 83, 90.0)
        lon, _ = _latlon(F, 3, 4, 69, 87, 180.0)
        tod = _tod(F, 5)
        st = F.char(6)
        mode = F.char(7)
        q = np.where((st == 65) & (mode != 78), 1, np.where(st == 0, -1, 0)).astype(np.int8)
        out["position"] = {
            "lat_rad": lat,
            "lon_rad": lon,
            "alt_m": nanv,
            "hdop": nanv,
            "quality": q,
        }
    elif stype == "RMC":
        tod = _tod(F, 1)
        st = F.char(2)
        lat, dec = _latlon(F, 3, 4, 78, 83, 90.0)
        lon, _ = _latlon(F, 5, 6, 69, 87, 180.0)
        sog = _speed(F, 7)
        cog = _angle(F, 8)
        dv, _ = F.num(9)
        dd = np.floor(dv / 10000.0)
        mo = np.floor(dv / 100.0) - 100.0 * dd
        yy = dv - 10000.0 * dd - 100.0 * mo
        yyyy = np.where(yy >= 80, 1900.0 + yy, 2000.0 + yy)
        date = _ymd_days(F, yyyy, mo, dd)
        mode = F.char(12)
        q = np.where((st == 65) & (mode != 78), 1, np.where(st == 0, -1, 0)).astype(np.int8)
        out["position"] = {
            "lat_rad": lat,
            "lon_rad": lon,
            "alt_m": nanv,
            "hdop": nanv,
            "quality": q,
        }
        bad = q == 0  # status V or mode N: the velocity is not valid either
        out["ground"] = {
            "cog_rad": np.where(bad, np.nan, cog),
            "sog_mps": np.where(bad, np.nan, sog),
        }
    elif stype == "VTG":
        bad = F.char(9) == 78  # mode N: data not valid
        out["ground"] = {
            "cog_rad": np.where(bad, np.nan, _angle(F, 1)),
            "sog_mps": np.where(bad, np.nan, _speed(F, 5, 7)),
        }
    elif stype == "ZDA":
        tod = _tod(F, 1)
        d, _ = F.num(2)
        m, _ = F.num(3)
        y, _ = F.num(4)
        date = _ymd_days(F, y, m, d)
    return out, {"tod_ns": tod, "date_days": date, "dec": dec}
