"""NMEA 0183 text writer for canonical frames: bare sentences, TAG blocks or timestamp prefixes.

Vectorised: every sentence type is laid out as a byte matrix (one row per sentence, one
column per character position) with a mask of the characters kept; numbers become digits
by integer arithmetic, leading zeros are masked away, checksums are an XOR reduction over
the masked payload, and a whole block of lines is ``matrix[mask].tobytes()``.  No Python
code runs per line.

Sentence layouts (NMEA 0183 v4.11 field order; empty field where a value is missing)::

    GGA  hhmmss.ss,ddmm.mmmmmm,N,dddmm.mmmmmm,E,q,sats,hdop,alt,M,,M,,
    RMC  hhmmss.ss,A,ddmm.mmmmmm,N,dddmm.mmmmmm,E,sog_kn,cog_deg,ddmmyy,,,A
    ZDA  hhmmss.ss,dd,mm,yyyy,00,00          (after every RMC of a GNSS source)
    HDT  hdg,T       THS hdg,A       HDM hdg,M
    HDG  hdg,dev,E|W,var,E|W                 (magnetic sensor heading, deviation, variation)
    ROT  rot_dpm,A                            (deg/min, starboard +)
    VHW  ,T,,M,stw_kn,N,stw_kmh,K
    VBW  long_w_kn,trans_w_kn,A,long_g_kn,trans_g_kn,A
    VLW  total_nmi,N,trip_nmi,N
    VTG  cog_deg,T,,M,sog_kn,N,sog_kmh,K,A

Decimals as in :mod:`dracc.sim.model` (6 for minutes of arc, 3 for degrees, knots and
nautical miles, 2 for ROT, 1 for altitude and HDOP), so that frames produced by the
simulator are reproduced exactly.  Line forms:

``bare``    ``$INGGA,...*hh``
``tag``     ``\\s:INS2,c:1772323200*hh\\$INGGA,...*hh`` (IEC 61162-450 TAG block; ``c:`` in
            Unix seconds, or milliseconds with ``tag_time='ms'``)
``prefix``  ``2026-03-01T00:00:00.000Z $INGGA,...*hh`` (ISO 8601 UTC, milliseconds)

The TAG ``c:`` and the prefix carry the receive time: a frame's ``recv_ns`` where it is not
``MISSING_NS`` (a simulated latency), else its ``time_ns``; the sentences' own time fields
(GGA, RMC, ZDA) are always ``time_ns``, the time of fix.  Lines are in time order
(``order='time'``: ``time_ns``, then ``line``) or in the frames' line order
(``order='line'``: the simulator's, the order its logger writes, which a loop or a clock
step takes back in time; :func:`write_nmea` of a :class:`SimVoyage` takes it).
``date_shifts`` (a GNSS week rollover, :func:`dracc.sim.faults.date_shifts`): RMC and ZDA
dates of a source ``days`` early where ``time_ns`` is in a window.
Validity comes from the position frame's ``quality``: GGA writes it as the fix quality,
RMC writes status ``V`` and mode ``N`` where it is 0, and a VTG is written with mode ``N``
where its source's position record at the same time has quality 0.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING, TypeAlias

import numpy as np
import pandas as pd

from dracc.core.arrays import ArrayLike
from dracc.core.atomic import atomic_path
from dracc.core.errors import DraccError
from dracc.core.units import DEG_RAD, KN_MPS, NMI_M
from dracc.frames import MISSING_NS
from dracc.sim.readings import ALT_DEC, ANGLE_DEC, DIST_DEC, HDOP_DEC, ROT_DEC, SPEED_DEC

if TYPE_CHECKING:
    from dracc.sim.model import SimVoyage

KMH_MPS = 1000.0 / 3600.0
FORMS = ("tag", "prefix", "bare")
CHUNK_ROWS = 200_000  #: sentences formatted per block (bounds memory)
GNSS_TALKERS = ("GP", "GN", "GA", "GL", "GB", "BD", "GQ", "GI")
ROLE_TALKER = {"compass": "HE", "log": "VW", "ins1": "IN", "ins2": "IN", "ins3": "IN", "gnss": "GP"}
KIND_TALKER = {
    "position": "GP",
    "heading": "HE",
    "ground": "GP",
    "water": "VW",
    "distance": "VW",
    "rot": "HE",
}
_HEX = np.frombuffer(b"0123456789ABCDEF", dtype=np.uint8)
#: a sentence table as plain numpy columns (see :func:`_arrays`)
_Columns: TypeAlias = dict[str, np.ndarray]


# --------------------------------------------------------------------------- byte blocks


class _Row:
    """Accumulates column blocks (uint8 matrix, keep mask) for ``n`` rows."""

    def __init__(self, n: int):
        self.n = n
        self.mats: list[np.ndarray] = []
        self.masks: list[np.ndarray] = []

    def add(self, mat: np.ndarray, mask: np.ndarray) -> _Row:
        self.mats.append(mat)
        self.masks.append(mask)
        return self

    def lit(self, s: bytes) -> _Row:
        if s:
            m = np.broadcast_to(np.frombuffer(s, dtype=np.uint8), (self.n, len(s)))
            self.add(m, np.ones((self.n, len(s)), bool))
        return self

    def strs(self, values: ArrayLike) -> _Row:
        """A column of short ASCII strings (variable length)."""
        a = np.asarray(values).astype("S")
        w = max(a.dtype.itemsize, 1)
        a = a.astype(f"S{w}")
        m = a.view(np.uint8).reshape(self.n, w)
        return self.add(m, m != 0)

    def uint(self, v: np.ndarray, width: int) -> _Row:
        """Non-negative integers, zero-padded to ``width``."""
        return self.add(_digits(np.asarray(v, np.int64), width), np.ones((self.n, width), bool))

    def num(self, x: ArrayLike, dec: int, pad: int = 1, valid: ArrayLike | None = None) -> _Row:
        """Decimal numbers with ``dec`` decimals, at least ``pad`` integer digits, a leading
        '-' where negative; NaN (or ``valid`` False) gives an empty field."""
        x = np.asarray(x, float)
        ok = np.isfinite(x) if valid is None else (np.asarray(valid, bool) & np.isfinite(x))
        scale = 10**dec
        sc = np.rint(np.abs(np.where(ok, x, 0.0)) * scale).astype(np.int64)
        neg = ok & (x < 0) & (sc > 0)
        ip = sc // scale
        nd = _ndigits(ip)
        w = max(int(nd.max(initial=1)), pad)
        dig = _digits(ip, w)
        keep = np.arange(w)[None, :] >= (w - np.maximum(nd, pad))[:, None]
        self.add(np.where(neg, ord("-"), 0).astype(np.uint8)[:, None], neg[:, None])
        self.add(dig, keep & ok[:, None])
        if dec:
            self.lit(b".")
            self.masks[-1] = np.broadcast_to(ok[:, None], (self.n, 1))
            self.add(_digits(sc % scale, dec), np.broadcast_to(ok[:, None], (self.n, dec)))
        return self

    def choice(self, cond: ArrayLike, a: bytes, b: bytes, valid: ArrayLike | None = None) -> _Row:
        """One character: ``a`` where cond else ``b``; empty where not valid."""
        c = np.where(np.asarray(cond, bool), a[0], b[0]).astype(np.uint8)[:, None]
        ok = np.ones((self.n, 1), bool) if valid is None else np.asarray(valid, bool)[:, None]
        return self.add(c, ok)

    def build(self) -> tuple[np.ndarray, np.ndarray]:
        return np.hstack(self.mats), np.hstack(self.masks)


def _digits(v: np.ndarray, width: int) -> np.ndarray:
    p = 10 ** np.arange(width - 1, -1, -1, dtype=np.int64)
    return ((v[:, None] // p[None, :]) % 10 + 48).astype(np.uint8)


def _ndigits(v: np.ndarray) -> np.ndarray:
    nd = np.ones(v.shape, np.int64)
    t = v // 10
    while np.any(t > 0):
        nd += t > 0
        t //= 10
    return nd


def checksum(mat: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """XOR of the kept bytes of each row (the NMEA and TAG block checksum)."""
    cs: np.ndarray = np.bitwise_xor.reduce(np.where(mask, mat, 0).astype(np.uint8), axis=1)
    return cs


def _hex2(cs: np.ndarray) -> np.ndarray:
    return np.stack([_HEX[cs >> 4], _HEX[cs & 15]], axis=1)


# --------------------------------------------------------------------------- fields


def _hms(r: _Row, t_ns: np.ndarray) -> np.ndarray:
    """hhmmss.ss (UTC time of day, rounded to 1/100 s); returns the rounded centiseconds."""
    cs = (t_ns + 5_000_000) // 10_000_000
    day_cs = cs % 8_640_000
    hh, rem = np.divmod(day_cs, 360_000)
    mm, rem = np.divmod(rem, 6000)
    r.uint(hh, 2).uint(mm, 2).uint(rem // 100, 2).lit(b".").uint(rem % 100, 2)
    return cs


def _latlon(r: _Row, a_rad: np.ndarray, deg_width: int, pos: bytes, neg: bytes) -> None:
    """ddmm.mmmmmm,N (or dddmm.mmmmmm,E); empty fields where NaN."""
    a = np.asarray(a_rad, float)
    ok = np.isfinite(a)
    micro = np.rint(np.abs(np.where(ok, a, 0.0)) / DEG_RAD * 60e6).astype(np.int64)
    deg, rem = np.divmod(micro, 60_000_000)
    okc = ok[:, None]
    r.add(_digits(deg, deg_width), np.broadcast_to(okc, (r.n, deg_width)))
    r.add(_digits(rem // 1_000_000, 2), np.broadcast_to(okc, (r.n, 2)))
    r.lit(b".")
    r.masks[-1] = np.broadcast_to(okc, (r.n, 1))
    r.add(_digits(rem % 1_000_000, 6), np.broadcast_to(okc, (r.n, 6)))
    r.lit(b",").choice(a >= 0, pos, neg, valid=ok)


def _date(cs: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    days = (cs // 8_640_000).astype("datetime64[D]")
    y = days.astype("datetime64[Y]")
    mo = days.astype("datetime64[M]")
    return (
        (days - mo).astype(np.int64) + 1,
        (mo - y).astype(np.int64) + 1,
        y.astype(np.int64) + 1970,
    )


def _col(df: pd.DataFrame, name: str) -> np.ndarray:
    if name in df:
        col: np.ndarray = df[name].to_numpy(dtype=float, na_value=np.nan)
        return col
    return np.full(len(df), np.nan)


def _angle_deg(a_rad: ArrayLike) -> np.ndarray:
    """A heading or course in degrees [0, 360) as written: 359.9996 rounds to 0.000, not 360."""
    a = np.asarray(a_rad, float)
    deg: np.ndarray = np.rint(np.mod(a / DEG_RAD, 360.0) * 10**ANGLE_DEC) / 10**ANGLE_DEC
    return np.where(deg >= 360.0, deg - 360.0, deg)


def _gga(r: _Row, d: _Columns) -> None:
    _hms(r, d["time_ns"])
    r.lit(b",")
    _latlon(r, d["lat_rad"], 2, b"N", b"S")
    r.lit(b",")
    _latlon(r, d["lon_rad"], 3, b"E", b"W")
    q = np.asarray(d["quality"], np.int64)
    hdop = d["hdop"]
    r.lit(b",").uint(np.clip(q, 0, 9), 1).lit(b",")
    has_h = np.isfinite(hdop)
    r.add(
        np.broadcast_to(np.frombuffer(b"10", np.uint8), (r.n, 2)),
        np.broadcast_to(has_h[:, None], (r.n, 2)),
    )
    r.lit(b",").num(hdop, HDOP_DEC).lit(b",").num(d["alt_m"], ALT_DEC).lit(b",M,,M,,")


def _early(d: _Columns, cs: np.ndarray) -> np.ndarray:
    """Centiseconds of the written date: ``date_shift_days`` early where set."""
    return cs - d["date_shift_days"] * 8_640_000 if "date_shift_days" in d else cs


def _rmc(r: _Row, d: _Columns) -> None:
    cs = _hms(r, d["time_ns"])
    ok = np.asarray(d["quality"], np.int64) > 0
    r.lit(b",").choice(ok, b"A", b"V").lit(b",")
    _latlon(r, d["lat_rad"], 2, b"N", b"S")
    r.lit(b",")
    _latlon(r, d["lon_rad"], 3, b"E", b"W")
    r.lit(b",").num(d["sog_mps"] / KN_MPS, SPEED_DEC).lit(b",")
    r.num(_angle_deg(d["cog_rad"]), ANGLE_DEC).lit(b",")
    dd, mm, yy = _date(_early(d, cs))
    r.uint(dd, 2).uint(mm, 2).uint(yy % 100, 2).lit(b",,,").choice(ok, b"A", b"N")


def _zda(r: _Row, d: _Columns) -> None:
    cs = _hms(r, d["time_ns"])
    dd, mm, yy = _date(_early(d, cs))
    r.lit(b",").uint(dd, 2).lit(b",").uint(mm, 2).lit(b",").uint(yy, 4).lit(b",00,00")


def _hdt_like(code: bytes) -> Callable[[_Row, _Columns], None]:
    def f(r: _Row, d: _Columns) -> None:
        r.num(_angle_deg(d["heading_rad"]), ANGLE_DEC).lit(b"," + code)

    return f


def _hdg(r: _Row, d: _Columns) -> None:
    r.num(_angle_deg(d["heading_rad"]), ANGLE_DEC)
    for name in ("deviation_rad", "variation_rad"):
        v = d[name] / DEG_RAD
        r.lit(b",").num(np.abs(v), ANGLE_DEC).lit(b",").choice(
            v >= 0, b"E", b"W", valid=np.isfinite(v)
        )


def _rot(r: _Row, d: _Columns) -> None:
    v = d["rot_radps"] * 60.0 / DEG_RAD
    r.num(v, ROT_DEC).lit(b",").choice(np.isfinite(v), b"A", b"V")


def _vhw(r: _Row, d: _Columns) -> None:
    r.lit(b",T,,M,").num(d["stw_mps"] / KN_MPS, SPEED_DEC).lit(b",N,")
    r.num(d["stw_mps"] / KMH_MPS, SPEED_DEC).lit(b",K")


def _vbw(r: _Row, d: _Columns) -> None:
    w_ok = np.isfinite(d["stw_mps"])
    g_ok = np.isfinite(d["sog_long_mps"])
    r.num(d["stw_mps"] / KN_MPS, SPEED_DEC).lit(b",")
    r.num(d["stw_transverse_mps"] / KN_MPS, SPEED_DEC).lit(b",").choice(w_ok, b"A", b"V")
    r.lit(b",").num(d["sog_long_mps"] / KN_MPS, SPEED_DEC).lit(b",")
    r.num(d["sog_transverse_mps"] / KN_MPS, SPEED_DEC).lit(b",").choice(g_ok, b"A", b"V")


def _vlw(r: _Row, d: _Columns) -> None:
    r.num(d["total_water_m"] / NMI_M, DIST_DEC).lit(b",N,")
    r.num(d["trip_water_m"] / NMI_M, DIST_DEC).lit(b",N")


def _vtg(r: _Row, d: _Columns) -> None:
    r.num(_angle_deg(d["cog_rad"]), ANGLE_DEC).lit(b",T,,M,")
    r.num(d["sog_mps"] / KN_MPS, SPEED_DEC).lit(b",N,").num(d["sog_mps"] / KMH_MPS, SPEED_DEC)
    valid = d["valid"] if "valid" in d else np.ones(r.n, bool)
    r.lit(b",K,").choice(valid, b"A", b"N")


_LAYOUT = {
    "GGA": _gga,
    "RMC": _rmc,
    "ZDA": _zda,
    "HDT": _hdt_like(b"T"),
    "THS": _hdt_like(b"A"),
    "HDM": _hdt_like(b"M"),
    "HDG": _hdg,
    "ROT": _rot,
    "VHW": _vhw,
    "VBW": _vbw,
    "VLW": _vlw,
    "VTG": _vtg,
}
_NUMERIC = {
    "GGA": ("lat_rad", "lon_rad", "hdop", "alt_m"),
    "RMC": ("lat_rad", "lon_rad", "sog_mps", "cog_rad"),
    "ZDA": (),
    "HDT": ("heading_rad",),
    "THS": ("heading_rad",),
    "HDM": ("heading_rad",),
    "HDG": ("heading_rad", "deviation_rad", "variation_rad"),
    "ROT": ("rot_radps",),
    "VHW": ("stw_mps",),
    "VBW": ("stw_mps", "stw_transverse_mps", "sog_long_mps", "sog_transverse_mps"),
    "VLW": ("total_water_m", "trip_water_m"),
    "VTG": ("cog_rad", "sog_mps"),
}


# --------------------------------------------------------------------------- frames -> sentences


#: ``(source, lo_ns, hi_ns or None, days)``: dates written ``days`` early
DateShifts: TypeAlias = "tuple[tuple[str, int, int | None, int], ...]"


def date_shift_days(source: np.ndarray, time_ns: np.ndarray, shifts: DateShifts) -> np.ndarray:
    """Days each row's date is written early (0 outside every window of ``shifts``)."""
    days = np.zeros(len(time_ns), np.int64)
    for src, lo, hi, d in shifts:
        win = (source == src) & (time_ns >= lo) & ((time_ns < hi) if hi is not None else True)
        days[win] += d
    return days


def _sentence_tables(
    frames: dict[str, pd.DataFrame], roles: dict[str, str] | None, shifts: DateShifts = ()
) -> list[tuple[str, pd.DataFrame]]:
    """Group frame rows into sentence tables: {type: DataFrame with time_ns, source, talker,
    line, sub (order after line) and the numeric columns the layout needs}."""
    roles = roles or {}
    tables: list[tuple[str, pd.DataFrame]] = []

    def base(df: pd.DataFrame, kind: str) -> pd.DataFrame:
        out = pd.DataFrame(
            {
                "time_ns": df["time_ns"].to_numpy(np.int64),
                "source": df["source"].astype(str).to_numpy(object),
                "line": (
                    df["line"].to_numpy(np.int64) if "line" in df else np.zeros(len(df), np.int64)
                ),
                "recv_ns": (
                    df["recv_ns"].to_numpy(np.int64)
                    if "recv_ns" in df
                    else np.full(len(df), MISSING_NS, np.int64)
                ),
            }
        )
        talker = (
            df["talker"].astype(str).to_numpy(object)
            if "talker" in df
            else np.full(len(df), "", object)
        )
        empty = talker == ""
        if empty.any():
            role = pd.Series(out["source"].to_numpy(object)[empty]).map(roles)
            fill = role.map(ROLE_TALKER).fillna(KIND_TALKER[kind]).to_numpy(object)
            talker = talker.copy()
            talker[empty] = fill
        out["talker"] = talker
        out["sub"] = 0
        return out

    def table(df: pd.DataFrame, kind: str, cols: Iterable[str]) -> pd.DataFrame:
        """base() with the numeric columns ``cols`` of ``df`` (NaN where df lacks one)."""
        out = base(df, kind)
        for c in cols:
            out[c] = _col(df, c)
        return out

    def sent(df: pd.DataFrame) -> np.ndarray:
        if "sentence" in df:
            sentences: np.ndarray = df["sentence"].astype(str).to_numpy(object)
            return sentences
        return np.full(len(df), "", object)

    pos = frames.get("position")
    gnd = frames.get("ground")
    rmc_pos = pd.DataFrame()
    if pos is not None and len(pos):
        s = sent(pos)
        is_rmc = s == "RMC"
        gga = pos[~is_rmc]
        if len(gga):
            b = table(gga, "position", ("lat_rad", "lon_rad", "hdop", "alt_m"))
            b["quality"] = (
                gga["quality"].to_numpy(np.int64)
                if "quality" in gga
                else np.ones(len(gga), np.int64)
            )
            tables.append(("GGA", b))
        rmc_pos = pos[is_rmc]
    rmc_gnd = pd.DataFrame()
    if gnd is not None and len(gnd):
        s = sent(gnd)
        is_rmc = s == "RMC"
        vtg = gnd[~is_rmc]
        rmc_gnd = gnd[is_rmc]
        if len(vtg):
            b = table(vtg, "ground", ("cog_rad", "sog_mps"))
            b["valid"] = _fix_valid(pos, b)
            tables.append(("VTG", b))
    if len(rmc_pos) or len(rmc_gnd):
        bp = table(rmc_pos, "position", ("lat_rad", "lon_rad")) if len(rmc_pos) else None
        if bp is not None:
            bp["quality"] = (
                rmc_pos["quality"].to_numpy(np.int64)
                if "quality" in rmc_pos
                else np.ones(len(rmc_pos), np.int64)
            )
        bg = table(rmc_gnd, "ground", ("cog_rad", "sog_mps")) if len(rmc_gnd) else None
        keys = ["time_ns", "source", "line", "talker", "sub", "recv_ns"]
        if bp is None:
            assert bg is not None  # RMC rows of a position or a ground frame: one is there
            rmc = bg.assign(lat_rad=np.nan, lon_rad=np.nan, quality=1)
        elif bg is None:
            rmc = bp.assign(cog_rad=np.nan, sog_mps=np.nan)
        else:
            rmc = bp.merge(bg, on=keys, how="outer", sort=False)
            rmc["quality"] = rmc["quality"].fillna(1).astype(np.int64)
        if shifts:
            rmc["date_shift_days"] = date_shift_days(
                rmc["source"].to_numpy(object), rmc["time_ns"].to_numpy(np.int64), shifts
            )
            keys = [*keys, "date_shift_days"]
        tables.append(("RMC", rmc))
        if roles:
            is_gnss = (pd.Series(rmc["source"]).map(roles) == "gnss").to_numpy(bool)
        else:
            is_gnss = pd.Series(rmc["talker"]).isin(GNSS_TALKERS).to_numpy(bool)
        zda = rmc.loc[is_gnss, keys].copy()
        zda["sub"] = 1
        if len(zda):
            tables.append(("ZDA", zda))
    hd = frames.get("heading")
    if hd is not None and len(hd):
        s = sent(hd)
        ref = (
            hd["reference"].astype(str).to_numpy(object)
            if "reference" in hd
            else np.full(len(hd), "T", object)
        )
        has_dv = np.isfinite(_col(hd, "deviation_rad")) | np.isfinite(_col(hd, "variation_rad"))
        typ = np.where(
            np.isin(s, ["HDT", "THS", "HDG", "HDM"]),
            s,
            np.where(ref == "M", np.where(has_dv, "HDG", "HDM"), "HDT"),
        )
        for t in ("HDT", "THS", "HDG", "HDM"):
            sub = hd[typ == t]
            if len(sub):
                tables.append((t, table(sub, "heading", _NUMERIC[t])))
    w = frames.get("water")
    if w is not None and len(w):
        s = sent(w)
        has_vbw = (
            np.isfinite(_col(w, "stw_transverse_mps"))
            | np.isfinite(_col(w, "sog_long_mps"))
            | np.isfinite(_col(w, "sog_transverse_mps"))
        )
        typ = np.where(np.isin(s, ["VHW", "VBW"]), s, np.where(has_vbw, "VBW", "VHW"))
        for t in ("VHW", "VBW"):
            sub = w[typ == t]
            if len(sub):
                tables.append((t, table(sub, "water", _NUMERIC[t])))
    for kind, t in (("distance", "VLW"), ("rot", "ROT")):
        f = frames.get(kind)
        if f is not None and len(f):
            tables.append((t, table(f, kind, _NUMERIC[t])))
    return tables


def _arrays(tb: pd.DataFrame) -> _Columns:
    """A sentence table as plain numpy columns (source and talker as ASCII bytes)."""
    out: _Columns = {}
    for c in tb.columns:
        if c in ("source", "talker"):
            out[c] = tb[c].astype(str).to_numpy(dtype=object).astype("S")
        elif c in ("time_ns", "line", "sub", "quality", "recv_ns", "valid", "date_shift_days"):
            out[c] = tb[c].to_numpy(dtype=np.int64)
        else:
            out[c] = tb[c].to_numpy(dtype=float, na_value=np.nan)
    return out


def _order(
    tables: list[tuple[str, _Columns]], order: str = "time"
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Global order: (time_ns, line, sub, type order), or (line, sub, type order) for
    ``order='line'``; returns (type_id, row, receive time) per line."""
    t = np.concatenate([tb["time_ns"] for _, tb in tables])
    rcv = np.concatenate([_received(tb) for _, tb in tables])
    ln = np.concatenate([tb["line"] for _, tb in tables])
    sub = np.concatenate([tb["sub"] for _, tb in tables])
    sizes = [len(tb["time_ns"]) for _, tb in tables]
    tid = np.repeat(np.arange(len(tables)), sizes)
    row = np.concatenate([np.arange(k) for k in sizes])
    o = np.lexsort((tid, sub, ln) if order == "line" else (tid, sub, ln, t))
    return tid[o], row[o], rcv[o]


def _format_block(
    typ: str, d: _Columns, form: str, tag_time: str, newline: bytes
) -> tuple[np.ndarray, np.ndarray]:
    """Byte matrix and mask of complete lines (with terminator) for the rows of ``d``."""
    n = len(d["time_ns"])
    head = _Row(n)
    stamp = _received(d)  # what the logger stamps: the receive time where there is one
    if form == "tag":
        tag = _Row(n).lit(b"s:").strs(d["source"]).lit(b",c:")
        unit = 1_000_000_000 if tag_time == "s" else 1_000_000
        tag.uint(stamp // unit, _width(stamp // unit))
        tm, tk = tag.build()
        head.lit(b"\\").add(tm, tk).lit(b"*").add(
            _hex2(checksum(tm, tk)), np.ones((n, 2), bool)
        ).lit(b"\\")
    elif form == "prefix":
        iso = np.datetime_as_string(
            stamp.astype("datetime64[ns]").astype("datetime64[ms]"), unit="ms"
        )
        head.strs(iso).lit(b"Z ")
    body = _Row(n).strs(d["talker"]).lit(typ.encode() + b",")
    _LAYOUT[typ](body, d)
    bm, bk = body.build()
    head.lit(b"$").add(bm, bk).lit(b"*").add(_hex2(checksum(bm, bk)), np.ones((n, 2), bool))
    return head.lit(newline).build()


def _received(d: _Columns) -> np.ndarray:
    """The receive time of each row: ``recv_ns`` where set, else ``time_ns``."""
    t = d["time_ns"]
    if "recv_ns" not in d:
        return t
    r = d["recv_ns"]
    return np.where(r != MISSING_NS, r, t)


def _fix_valid(pos: pd.DataFrame | None, vtg: pd.DataFrame) -> np.ndarray:
    """VTG rows whose source's position fix at the same time is not flagged invalid
    (``quality`` 0 there: VTG mode N).  All valid when no position record is invalid."""
    ok = np.ones(len(vtg), np.int64)
    if pos is None or not len(pos) or "quality" not in pos:
        return ok
    bad = pos["quality"].to_numpy(np.int64) == 0
    if not bad.any():
        return ok
    # matched by receive time: a GGA's time of fix precedes its receipt, a VTG's does not
    rcv = _received({c: pos[c].to_numpy(np.int64) for c in ("time_ns", "recv_ns") if c in pos})
    keys = pd.MultiIndex.from_arrays([pos["source"].astype(str).to_numpy(object)[bad], rcv[bad]])
    mine = pd.MultiIndex.from_arrays(
        [
            vtg["source"].to_numpy(object),
            _received({c: vtg[c].to_numpy(np.int64) for c in ("time_ns", "recv_ns")}),
        ]
    )
    ok[mine.isin(keys)] = 0
    return ok


def _width(v: np.ndarray) -> int:
    return int(_ndigits(np.asarray(v, np.int64)).max(initial=1))


def _check_form(form: str, tag_time: str, order: str = "time") -> None:
    if order not in ("time", "line"):
        raise DraccError(f"line order must be 'time' or 'line', got {order!r}")
    if form not in FORMS:
        raise DraccError(f"NMEA line form must be one of {', '.join(FORMS)}, got {form!r}")
    if tag_time not in ("s", "ms"):
        raise DraccError(f"TAG block time unit must be 's' or 'ms', got {tag_time!r}")


def iter_blocks(
    frames: dict[str, pd.DataFrame],
    roles: dict[str, str] | None = None,
    form: str = "bare",
    tag_time: str = "s",
    newline: bytes = b"\r\n",
    chunk_rows: int = CHUNK_ROWS,
    order: str = "time",
    date_shifts: DateShifts = (),
) -> Iterator[tuple[np.ndarray, np.ndarray, bytes]]:
    """Yield ``(time_ns, source, bytes)`` blocks of complete lines in time-of-fix order
    (``order='line'``: the frames' line order; ``source`` as an ASCII bytes array;
    ``time_ns`` the time a logger stamps each line: ``recv_ns`` where set, else
    ``time_ns``).  TAG ``c:`` and prefix times are those receive times; the sentences'
    own time fields are the time of fix (RMC/ZDA dates early by ``date_shifts``)."""
    _check_form(form, tag_time, order)
    tables = [(typ, _arrays(tb)) for typ, tb in _sentence_tables(frames, roles, date_shifts)]
    if not tables:
        return
    tid, row, t = _order(tables, order)
    for start in range(0, len(tid), chunk_rows):
        ctid, crow = tid[start : start + chunk_rows], row[start : start + chunk_rows]
        m = len(ctid)
        parts = []
        src = np.empty(m, dtype="S32")
        for i in np.unique(ctid):
            sel = np.flatnonzero(ctid == i)
            typ, tb = tables[i]
            sub = {c: v[crow[sel]] for c, v in tb.items()}
            mat, mask = _format_block(typ, sub, form, tag_time, newline)
            parts.append((sel, mat, mask))
            src[sel] = sub["source"]
        width = max(p[1].shape[1] for p in parts)
        big = np.zeros((m, width), np.uint8)
        keep = np.zeros((m, width), bool)
        for sel, mat, mask in parts:
            w = mat.shape[1]
            big[sel, :w] = mat
            keep[sel, :w] = mask
        yield t[start : start + m], src, big[keep].tobytes()


def frames_to_lines(
    frames: dict[str, pd.DataFrame],
    roles: dict[str, str] | None = None,
    order: str = "time",
    date_shifts: DateShifts = (),
) -> tuple[np.ndarray, np.ndarray, list[bytes]]:
    """Bare sentences with checksums, time-ordered (or in line order): ``(time_ns int64,
    source str array, lines list[bytes])`` (no line terminators; ``time_ns`` the receive
    time, as :func:`iter_blocks`)."""
    ts, srcs, lines = [], [], []
    blocks = iter_blocks(
        frames, roles, form="bare", newline=b"\n", order=order, date_shifts=date_shifts
    )
    for t, src, blob in blocks:
        ts.append(t)
        srcs.append(src)
        lines.extend(blob.split(b"\n")[:-1])
    if not ts:
        return np.zeros(0, np.int64), np.zeros(0, dtype=str), []
    return np.concatenate(ts), np.concatenate(srcs).astype("U"), lines


def write_nmea(
    voyage_or_frames: SimVoyage | dict[str, pd.DataFrame],
    path: str | Path,
    form: str = "tag",
    tag_time: str = "s",
    roles: dict[str, str] | None = None,
    newline: bytes = b"\r\n",
    order: str | None = None,
    date_shifts: DateShifts | None = None,
) -> None:
    """Write a simulated voyage (or canonical frames) as an NMEA 0183 text log, atomically.

    ``form``: 'tag' (IEC 61162-450 TAG block with ``s:`` source and ``c:`` time), 'prefix'
    (ISO 8601 UTC timestamp, a space, the sentence) or 'bare'.  Lines end in CR LF.
    ``order`` (default: 'line' for a voyage, its logger's order; 'time' for frames) and
    ``date_shifts`` (default: the voyage's) as for :func:`iter_blocks`.
    """
    if isinstance(voyage_or_frames, dict):
        frames = voyage_or_frames
        shifts: DateShifts = ()
    else:
        frames = voyage_or_frames.frames
        roles = roles if roles is not None else voyage_or_frames.roles
        shifts = voyage_or_frames.date_shifts
    order = order or ("time" if isinstance(voyage_or_frames, dict) else "line")
    shifts = shifts if date_shifts is None else date_shifts
    _check_form(form, tag_time, order)
    with atomic_path(path) as tmp, open(tmp, "wb") as fh:
        for _, _, blob in iter_blocks(
            frames, roles, form, tag_time, newline, order=order, date_shifts=shifts
        ):
            fh.write(blob)
