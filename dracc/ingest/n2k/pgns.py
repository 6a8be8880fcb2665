"""NMEA 2000 navigation PGNs decoded with numpy, all messages of a PGN at once.

Field layouts, resolutions and "not available" rules follow canboat's PGN database
(``database/pgns/*.yaml``, ``fieldtypes.yaml``; https://canboat.github.io/canboat/):
little-endian integers; in a field of 8 bits or more the three highest values (for a
signed field the three highest *positive* ones, e.g. 0x7FFD..0x7FFF) mean "unknown",
"out of range" and "reserved", and a 2- or 4-bit lookup's highest value means unknown.
Such values become NaN, never zero; so does a field beyond the end of a short payload.

=========  ========  ====================================================================
PGN        kind      fields used (byte offset: type x resolution)
=========  ========  ====================================================================
129025     position  0: lat i32 x 1e-7 deg, 4: lon i32 x 1e-7 deg
129029     position  1: date u16 days, 3: time u32 x 1e-4 s, 7: lat i64 x 1e-16 deg,
                     15: lon i64 x 1e-16 deg, 23: alt i64 x 1e-6 m, 31 bits 4-7: method,
                     34: HDOP i16 x 0.01 (the number of SVs at 33 has no frame column)
129026     ground    1 bits 0-1: COG reference, 2: COG u16 x 1e-4 rad, 4: SOG u16 x 0.01 m/s
127250     heading   1: heading u16 x 1e-4 rad, 3: deviation i16 x 1e-4 rad,
                     5: variation i16 x 1e-4 rad, 7 bits 0-1: reference (0 true, 1 magnetic)
127251     rot       1: rate i32 x 3.125e-8 rad/s
128259     water     1: speed water referenced u16 x 0.01 m/s, 3: ground referenced u16
128275     distance  6: log u32 m, 10: trip log u32 m
126992     (time)    1 bits 0-3: source, 2: date u16 days, 4: time u32 x 1e-4 s
127258     (heading) 4: variation i16 x 1e-4 rad
129539     (hdop)    2: HDOP i16 x 0.01
60928      (names)   0: NAME u64 (see :mod:`dracc.ingest.n2k.names`)
=========  ========  ====================================================================

Mapping to the canonical frames: the 129029 method (0 no GNSS, 1 GNSS fix, 2 DGNSS,
3 precise, 4 RTK fixed, 5 RTK float, 6 estimated, 7 manual, 8 simulated) is GGA's fix
quality, -1 where unknown (and for 129025, which says nothing of its fix); a 129026 COG
referenced to magnetic north (or flagged in error) is not used (NaN), the SOG is; the
128259 ground-referenced speed is ``sog_long_mps``; a 127250 record without variation
takes the variation of the nearest preceding 127258 (any source; the first following
where none precedes); a 129025 record takes the HDOP of the latest 129539 of the same
address within 10 s.  A record whose values are present but impossible (|lat| > 90 deg,
|lon| > 180 deg, heading >= 360 deg, |deviation| or |variation| > 180 deg, a speed above
100 m/s, |ROT| > 3 rad/s) is rejected with its reason; a payload too short for its main
fields is rejected as ``n2k_short_payload``.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field

import numpy as np

from dracc.ingest.n2k.messages import Messages

DEG = np.pi / 180.0
DAY_NS = 86_400 * 1_000_000_000
MISSING_NS = np.iinfo(np.int64).min
MAX_SPEED_MPS = 100.0  #: a speed above this is rejected (``implausible_speed``)
MAX_ROT_RADPS = 3.0  #: a rate of turn above this (172 deg/s) is rejected
HDOP_WINDOW_NS = 10 * 1_000_000_000  #: a 129539 HDOP older than this is not used

#: navigation PGN -> canonical frame kind it feeds
NAV_PGNS = {
    129025: "position",
    129029: "position",
    129026: "ground",
    127250: "heading",
    127251: "rot",
    128259: "water",
    128275: "distance",
}
#: PGNs used beside them: time anchors, magnetic variation, DOPs, address claims
AUX_PGNS = (126992, 127258, 129539, 60928)
#: bytes each PGN needs for its main fields (shorter: rejected as n2k_short_payload)
MIN_LENGTH = {
    129025: 8,
    129029: 23,
    129026: 6,
    127250: 3,
    127251: 5,
    128259: 3,
    128275: 10,
    126992: 8,
    127258: 6,
    129539: 4,
    60928: 8,
}

_DTYPES = {1: "u1", 2: "<u2", 4: "<u4", 8: "<u8"}


@dataclass
class Decoded:
    """What :func:`decode` found, by message index (``row``) into the Messages."""

    #: kind -> parts, one per PGN: columns with ``row`` (int64 message index), ``pgn``
    #: (a 0-d int64) and the kind's value columns; position parts carry ``fix_ns`` (the
    #: 129029 UTC time of fix, MISSING_NS where none)
    parts: dict[str, list[dict[str, np.ndarray]]] = field(default_factory=dict)
    clock_row: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    clock_utc_ns: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    claim_row: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    claim_name: np.ndarray = field(default_factory=lambda: np.zeros(0, np.uint64))
    #: reason -> message indices rejected for it
    rejects: dict[str, np.ndarray] = field(default_factory=dict)
    #: "PGN<n>" -> count of valid messages not used, and the first such message's index
    ignored: Counter[str] = field(default_factory=Counter)
    ignored_first: dict[str, int] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)
    variation_filled: int = 0  #: 127250 records given a 127258 variation
    magnetic_cog: int = 0  #: 129026 records whose COG is magnetic (not used)


class _Block:
    """The payload bytes of some messages as an (n, width) matrix, gathered once; zero
    beyond each message's length."""

    def __init__(self, m: Messages, rows: np.ndarray, width: int = 40) -> None:
        self.length = m.length[rows]
        width = max(1, min(width, int(self.length.max()) if len(rows) else 1))
        idx = m.start[rows][:, None] + np.arange(width)
        if len(m.payload) == 0:
            self.bytes = np.zeros((len(rows), width), dtype=np.uint8)
        else:
            self.bytes = m.payload[np.minimum(idx, len(m.payload) - 1)]
            if (self.length < width).any():
                self.bytes[self.length[:, None] <= np.arange(width)] = 0
        self.width = width


def _raw(b: _Block, offset: int, size: int, signed: bool) -> np.ndarray:
    """Little-endian integers of ``size`` bytes at ``offset`` (int64; 0 where short)."""
    n = len(b.length)
    if offset + size > b.width:
        return np.zeros(n, dtype=np.int64)
    cols = np.ascontiguousarray(b.bytes[:, offset : offset + size])
    dt = _DTYPES[size].replace("u", "i") if signed else _DTYPES[size]
    out: np.ndarray = cols.view(dt).reshape(n).astype(np.int64)
    return out


def _num(b: _Block, offset: int, size: int, signed: bool, scale: float) -> np.ndarray:
    """A number field scaled, NaN where not available (top three values) or short."""
    if size == 8 and not signed:  # not used: u64 does not fit int64
        raise ValueError("unsigned 64-bit number")
    v = _raw(b, offset, size, signed)
    top = (1 << (8 * size - 1)) - 1 if signed else (1 << (8 * size)) - 1
    ok = (b.length >= offset + size) & (v <= top - 3)
    out: np.ndarray = np.where(ok, v * scale, np.nan)
    return out


def _bits(b: _Block, offset: int, shift: int, nbits: int) -> np.ndarray:
    """A bit field of one byte as int64; -1 where the payload is short."""
    v = _raw(b, offset, 1, False)
    out: np.ndarray = np.where(b.length > offset, (v >> shift) & ((1 << nbits) - 1), -1)
    return out.astype(np.int64)


def _utc_ns(date_d: np.ndarray, time_s_e4: np.ndarray) -> np.ndarray:
    """UTC ns from canboat DATE (days) and TIME (1e-4 s) raw fields; MISSING_NS where
    either is unavailable or the time is past 86401 s (canboat's range)."""
    ok = (date_d <= 0xFFFC) & (time_s_e4 <= 0xFFFFFFFC) & (time_s_e4 <= 864_010_000)
    ns = date_d * DAY_NS + time_s_e4 * 100_000
    out: np.ndarray = np.where(ok, ns, MISSING_NS)
    return out


def _ref_codes(ref: np.ndarray) -> np.ndarray:
    """canboat DIRECTION_REFERENCE (0 true, 1 magnetic) -> REFERENCE_DTYPE codes (M 0, T 1)."""
    out: np.ndarray = np.where(ref == 0, 1, np.where(ref == 1, 0, -1)).astype(np.int8)
    return out


def _reject(d: Decoded, reason: str, rows: np.ndarray) -> None:
    if len(rows):
        prev = d.rejects.get(reason)
        d.rejects[reason] = rows if prev is None else np.concatenate((prev, rows))


def _part(d: Decoded, kind: str, pgn: int, rows: np.ndarray, bad: dict[str, np.ndarray],
          cols: dict[str, np.ndarray]) -> None:  # fmt: skip
    """Store the rows of one PGN not rejected (``bad``: reason -> mask over rows)."""
    keep = np.ones(len(rows), dtype=bool)
    for reason, mask in bad.items():
        mask = mask & keep
        _reject(d, reason, rows[mask])
        keep &= ~mask
    out = {c: v[keep] for c, v in cols.items()}
    out["row"] = rows[keep]
    out["pgn"] = np.asarray(pgn, dtype=np.int64)
    d.parts.setdefault(kind, []).append(out)


def _latlon_bad(lat: np.ndarray, lon: np.ndarray) -> np.ndarray:
    out: np.ndarray = (np.abs(lat) > 90.0) | (np.abs(lon) > 180.0)  # NaN compares False
    return out


def _dec_129025(d: Decoded, m: Messages, r: np.ndarray) -> None:
    b = _Block(m, r)
    lat = _num(b, 0, 4, True, 1e-7)
    lon = _num(b, 4, 4, True, 1e-7)
    nan = np.full(len(r), np.nan)
    cols = {
        "lat_rad": lat * DEG,
        "lon_rad": lon * DEG,
        "alt_m": nan,
        "hdop": nan,
        "quality": np.full(len(r), -1, dtype=np.int8),
        "fix_ns": np.full(len(r), MISSING_NS, dtype=np.int64),
    }
    _part(d, "position", 129025, r, {"implausible_position": _latlon_bad(lat, lon)}, cols)


def _dec_129029(d: Decoded, m: Messages, r: np.ndarray) -> None:
    b = _Block(m, r, 36)
    date = _raw(b, 1, 2, False)
    tod = _raw(b, 3, 4, False)
    lat = _num(b, 7, 8, True, 1e-16)
    lon = _num(b, 15, 8, True, 1e-16)
    alt = _num(b, 23, 8, True, 1e-6)
    method = _bits(b, 31, 4, 4)
    hdop = _num(b, 34, 2, True, 0.01)
    quality = np.where((method >= 0) & (method <= 8), method, -1).astype(np.int8)
    cols = {
        "lat_rad": lat * DEG,
        "lon_rad": lon * DEG,
        "alt_m": alt,
        "hdop": hdop,
        "quality": quality,
        "fix_ns": _utc_ns(date, tod),
    }
    _part(d, "position", 129029, r, {"implausible_position": _latlon_bad(lat, lon)}, cols)


def _dec_129026(d: Decoded, m: Messages, r: np.ndarray) -> None:
    b = _Block(m, r)
    ref = _bits(b, 1, 0, 2)
    cog = _num(b, 2, 2, False, 1e-4)
    sog = _num(b, 4, 2, False, 0.01)
    bad_cog = cog >= 2 * np.pi
    magnetic = (ref == 1) | (ref == 2)
    d.magnetic_cog += int((magnetic & ~np.isnan(cog)).sum())
    cols = {"cog_rad": np.where(magnetic, np.nan, cog), "sog_mps": sog}
    bad = {"implausible_course": bad_cog, "implausible_speed": sog > MAX_SPEED_MPS}
    _part(d, "ground", 129026, r, bad, cols)


def _dec_127250(d: Decoded, m: Messages, r: np.ndarray) -> None:
    b = _Block(m, r)
    hdg = _num(b, 1, 2, False, 1e-4)
    dev = _num(b, 3, 2, True, 1e-4)
    var = _num(b, 5, 2, True, 1e-4)
    ref = _bits(b, 7, 0, 2)
    cols = {
        "heading_rad": hdg,
        "reference": _ref_codes(ref),
        "deviation_rad": dev,
        "variation_rad": var,
        "heading_quality": np.full(len(r), np.nan),
    }
    bad = {
        "implausible_heading": hdg >= 2 * np.pi,
        "implausible_variation": (np.abs(dev) > np.pi) | (np.abs(var) > np.pi),
    }
    _part(d, "heading", 127250, r, bad, cols)


def _dec_127251(d: Decoded, m: Messages, r: np.ndarray) -> None:
    b = _Block(m, r)
    rot = _num(b, 1, 4, True, 3.125e-08)
    bad = {"implausible_rot": np.abs(rot) > MAX_ROT_RADPS}
    _part(d, "rot", 127251, r, bad, {"rot_radps": rot})


def _dec_128259(d: Decoded, m: Messages, r: np.ndarray) -> None:
    b = _Block(m, r)
    stw = _num(b, 1, 2, False, 0.01)
    sog = _num(b, 3, 2, False, 0.01)
    nan = np.full(len(r), np.nan)
    cols = {"stw_mps": stw, "stw_transverse_mps": nan, "sog_long_mps": sog,
            "sog_transverse_mps": nan}  # fmt: skip
    bad = {"implausible_speed": (stw > MAX_SPEED_MPS) | (sog > MAX_SPEED_MPS)}
    _part(d, "water", 128259, r, bad, cols)


def _dec_128275(d: Decoded, m: Messages, r: np.ndarray) -> None:
    b = _Block(m, r)
    cols = {
        "total_water_m": _num(b, 6, 4, False, 1.0),
        "trip_water_m": _num(b, 10, 4, False, 1.0),
    }
    _part(d, "distance", 128275, r, {}, cols)


_DECODERS = {
    129025: _dec_129025,
    129029: _dec_129029,
    129026: _dec_129026,
    127250: _dec_127250,
    127251: _dec_127251,
    128259: _dec_128259,
    128275: _dec_128275,
}


def _fill_variation(d: Decoded, m: Messages, var_rows: np.ndarray, var: np.ndarray) -> None:
    """127250 records without variation take the nearest preceding 127258's (else the
    first following one's)."""
    ok = ~np.isnan(var)
    var_rows, var = var_rows[ok], var[ok]
    if not len(var_rows):
        return
    for part in d.parts.get("heading", []):
        v = part["variation_rad"]
        need = np.isnan(v)
        if not need.any():
            continue
        k = np.searchsorted(var_rows, part["row"][need], side="right") - 1
        v = v.copy()
        v[need] = var[np.maximum(k, 0)]
        part["variation_rad"] = v
        d.variation_filled += int(need.sum())


def _fill_hdop(d: Decoded, m: Messages, dop_rows: np.ndarray, hdop: np.ndarray) -> None:
    """129025 records take the HDOP of the latest 129539 of the same address (<= 10 s)."""
    ok = ~np.isnan(hdop)
    dop_rows, hdop = dop_rows[ok], hdop[ok]
    if not len(dop_rows):
        return
    big = np.int64(len(m)) + 1
    dkey = m.src[dop_rows].astype(np.int64) * big + dop_rows
    srt = np.argsort(dkey, kind="stable")
    dkey, dop_rows, hdop = dkey[srt], dop_rows[srt], hdop[srt]
    for part in d.parts.get("position", []):
        if int(part["pgn"]) != 129025 or not len(part["row"]):
            continue
        rows = part["row"]
        key = m.src[rows].astype(np.int64) * big + rows
        k = np.searchsorted(dkey, key, side="right") - 1
        kk = np.maximum(k, 0)
        same = (k >= 0) & (m.src[dop_rows[kk]] == m.src[rows])
        same &= (m.time_ns[rows] - m.time_ns[dop_rows[kk]]) <= HDOP_WINDOW_NS
        part["hdop"] = np.where(same, hdop[kk], part["hdop"])


def _count_ignored(d: Decoded, pgn: np.ndarray) -> None:
    """Count the PGNs not decoded, with the index of each one's first message."""
    ours = np.array([*NAV_PGNS, *AUX_PGNS], dtype=np.int64)
    if pgn.min() >= 0 and pgn.max() < 1 << 18:  # a PGN has 18 bits: one counting pass
        c = np.bincount(pgn)
        c[ours[ours < len(c)]] = 0
        seen = np.flatnonzero(c)
        counts = c[seen]
    else:
        seen, counts = np.unique(pgn, return_counts=True)
        keep = ~np.isin(seen, ours)
        seen, counts = seen[keep], counts[keep]
    head = pgn[: 1 << 16]
    u, first = np.unique(head, return_index=True)
    first_of = dict(zip(u.tolist(), first.tolist(), strict=True))
    for p, cnt in zip(seen.tolist(), counts.tolist(), strict=True):
        key = f"PGN{p}"
        d.ignored[key] = int(cnt)
        d.ignored_first[key] = first_of[p] if p in first_of else int(np.argmax(pgn == p))


def decode(m: Messages) -> Decoded:
    """Decode the navigation PGNs of ``m`` (and the time, variation, DOP and address
    claim PGNs beside them); every other PGN is counted in ``ignored`` as ``PGN<n>``."""
    d = Decoded()
    n = len(m)
    if n == 0:
        return d
    var_rows = np.zeros(0, np.int64)
    var = np.zeros(0)
    dop_rows = np.zeros(0, np.int64)
    dop = np.zeros(0)
    _count_ignored(d, m.pgn)
    for pgn in (*NAV_PGNS, *AUX_PGNS):
        rows = np.flatnonzero(m.pgn == pgn)
        if not len(rows):
            continue
        short = m.length[rows] < MIN_LENGTH[pgn]
        _reject(d, "n2k_short_payload", rows[short])
        rows = rows[~short]
        if not len(rows):
            continue
        if pgn in _DECODERS:
            _DECODERS[pgn](d, m, rows)
        elif pgn == 126992:
            bk = _Block(m, rows, 8)
            utc = _utc_ns(_raw(bk, 2, 2, False), _raw(bk, 4, 4, False))
            ok = utc != MISSING_NS
            d.clock_row = np.concatenate((d.clock_row, rows[ok]))
            d.clock_utc_ns = np.concatenate((d.clock_utc_ns, utc[ok]))
        elif pgn == 127258:
            var_rows, var = rows, _num(_Block(m, rows, 6), 4, 2, True, 1e-4)
            bad = np.abs(var) > np.pi
            _reject(d, "implausible_variation", rows[bad])
            var = np.where(bad, np.nan, var)
        elif pgn == 129539:
            dop_rows, dop = rows, _num(_Block(m, rows, 4), 2, 2, True, 0.01)
        elif pgn == 60928:
            idx = m.start[rows][:, None] + np.arange(8)
            d.claim_row = rows
            d.claim_name = np.ascontiguousarray(m.payload[idx]).view("<u8").reshape(-1)
    # 129029 fix times as clock anchors too (the frame time beside the UTC time of fix)
    for part in d.parts.get("position", []):
        if int(part["pgn"]) == 129029:
            ok = part["fix_ns"] != MISSING_NS
            d.clock_row = np.concatenate((d.clock_row, part["row"][ok]))
            d.clock_utc_ns = np.concatenate((d.clock_utc_ns, part["fix_ns"][ok]))
    _fill_variation(d, m, var_rows, var)
    _fill_hdop(d, m, dop_rows, dop)
    if d.variation_filled:
        d.notes.append(
            f"{d.variation_filled} PGN127250 headings without variation given the "
            "variation of the nearest preceding PGN127258"
        )
    if d.magnetic_cog:
        d.notes.append(
            f"{d.magnetic_cog} PGN129026 courses referenced to magnetic north not used "
            "(their SOG is)"
        )
    return d
