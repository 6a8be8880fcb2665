"""Decoders of the sentences an INS and an own-ship AIS transponder add to a ship's NMEA
0183 stream, read by the numpy path only (the compiled kernel hands their lines over:
a proprietary address or a ``!`` start), so the differential tests compare the same
decoders on both engines and the kernel's common sentences are not slowed:

``$PASHR`` (NovAtel SPAN, Trimble, OxTS: the roll-and-pitch form)
    ``$PASHR,hhmmss.sss,HHH.HH,T,RRR.RR,PPP.PP,heave,rr.rrr,pp.ppp,hh.hhh,Q,I*CC``:
    1 UTC time, 2 true heading (deg), 3 ``T``, 4 roll, 5 pitch, 6 heave, 7-9 roll, pitch
    and heading accuracy (1-sigma deg), 10 GNSS quality, 11 INS status / IMU alignment
    (NovAtel SPAN PASHR log, Trimble "PASHR - proprietary roll and pitch sentence").  The
    short form ends after heave; NovAtel firmware before 7.03 has no field 11.  A heading
    record (reference T), its time of day its time of fix (like GGA: the time base places
    it, and it gets a receive time where the line has one).  Ashtech's other ``$PASHR``
    forms (a word in field 1: ``ATT``, ``HPR``, ``POS`` ...) are ignored as ``PASHR``.

    ``heading_quality`` (0 normal, 1 reduced, 2 invalid, NaN none) from field 11 and 10:
    no field 11 -> NaN; 11 = 0 -> 2 (Trimble "GPS only", NovAtel pre-alignment: no aligned
    inertial heading); 11 = 2 -> 1 (Trimble "degraded solution"); 11 = 1, 3 or 4 -> 0
    (NovAtel aligned; Trimble 3 "aligned", 4 "full navigation"; Trimble's 1, "coarse
    levelling", reads as NovAtel's aligned: the two scales share the code); any other
    value -> NaN; and a 0 becomes 1 where field 10 says no GNSS fix (0: the INS coasts
    unaided).

``$PSXN`` (Kongsberg Seatex Seapath, installation manual appendix "output protocols")
    ``$PSXN,20,horiz-qual,hgt-qual,head-qual,rp-qual`` (0 normal, 1 reduced performance,
    2 invalid data) and ``$PSXN,23,roll,pitch,head,heave`` (heading true, degrees).  A
    ``,23`` is a heading record (reference T, no time of its own: like HDT); its
    ``heading_quality`` is the head-qual of the latest ``,20`` of the same source before
    it, over block boundaries (:func:`~dracc.ingest.nmea.assemble.fill_heading_quality`),
    NaN before the first.  A heading of quality 2 stays a record with quality 2: what is
    used downstream decides.  ``,21`` (event: system restart), ``,22`` (gyro calibration
    and offset), ``,24`` (rates) and other forms are ignored as ``PSXN``.

``!AIVDO`` (own-ship AIS, ITU-R M.1371: message types 1, 2, 3 class A, 18, 19 class B)
    Single-sentence reports only; the six-bit armour (``c - 48``, less 8 above 40) is
    unpacked and read: longitude/latitude (1/10000 min; 181/91 deg not available -> no
    position record), SOG (1/10 kn; 1023 not available), COG (1/10 deg; 3600 not
    available) -> a ground record where one is there, true heading (deg; 511 not
    available) -> a heading record (reference T).  Position ``quality`` is 1 (valid; the
    position-accuracy flag, better or worse than 10 m, is no fix type), except where the
    UTC-second field says 61 manual input (7), 62 dead reckoning (6) or 63 positioning
    system inoperative (0).  Talker ``AI``, sentence ``VDO``, no time of its own: the
    line's external time or the preceding timed record's; the UTC second (0-59) then
    moves it to that second within +-30 s (:func:`~dracc.ingest.nmea.assemble.ais_time`):
    the time of the fix, not of the relay.  Multi-sentence messages (type 5, 24 ...),
    other types and a report with nothing available are ignored as ``VDO``; a value out
    of range (not the not-available code), an armour character outside the alphabet or
    a payload too short for its type is a ``malformed_field``.

Every decoder gives ``{name: (rows, columns)}``: a kind (``heading``, ``position``,
``ground``) or a side table (``psxn_quality``: the ``,20`` head-qual; ``ais_second``),
the rows of the group that give it and its columns over all rows of the group.
"""

from __future__ import annotations

import numpy as np

from dracc.core.units import KN_MPS
from dracc.ingest.nmea.fields import DEG, Fields, _angle, _tod
from dracc.ingest.tagblock import gather_rows

#: what a decoder gives: name -> (rows of the group giving it, columns over all rows)
Decoded = dict[str, tuple[np.ndarray, dict[str, np.ndarray]]]

#: AIS message types read and the payload characters (6 bits each) they need
AIS_TYPES = {1: 28, 2: 28, 3: 28, 18: 28, 19: 52}
#: an armoured payload longer than this is not a single AIS sentence: malformed
AIS_MAX_CHARS = 128
#: characters unpacked: every field read ends before bit 143 (type 1-3 time stamp)
_AIS_READ_CHARS = 24
_NA_LON, _NA_LAT = 181 * 600_000, 91 * 600_000  # 1/10000 min


def _field_bytes(F: Fields, k: int, width: int) -> np.ndarray:
    """Field k's first ``width`` bytes as one integer (big-endian), -1 unless the field
    has exactly ``width`` bytes."""
    s, e = F.bounds(k)
    v = np.zeros(len(s), dtype=np.int64)
    for j in range(width):
        v = v * 256 + F.buf[np.minimum(s + j, len(F.buf) - 1)]
    return np.where(e - s == width, v, -1)


def _code(text: str) -> int:
    v = 0
    for ch in text.encode():
        v = v * 256 + ch
    return v


def ignored_rows(stype: str, F: Fields) -> np.ndarray:
    """Rows of a group of ``stype`` (one of :data:`~dracc.ingest.nmea.sentences.SPECIAL`)
    that are forms dracc does not read (counted as ignored, never rejected)."""
    if stype == "PASHR":  # Ashtech forms: a word (ATT, HPR, POS ...) in field 1
        c = F.first_char(1)
        return (c >= 65) & (c <= 90)
    if stype == "PSXN":
        sub = _field_bytes(F, 1, 2)
        return (sub != _code("20")) & (sub != _code("23"))
    if stype == "VDO":  # one sentence of one, of a type read
        single = (_field_bytes(F, 1, 1) == _code("1")) & (_field_bytes(F, 2, 1) == _code("1"))
        t = _ais_type(F)
        return ~single | ~np.isin(t, list(AIS_TYPES))
    raise KeyError(stype)


def decode_special(stype: str, F: Fields) -> tuple[Decoded, dict[str, np.ndarray]]:
    """Decode the rows of one special sentence type (none of them ignored; malformed
    rows are marked in ``F.bad``).  Returns (:data:`Decoded`, timing) with timing =
    {"tod_ns", "date_days", "dec"} over all rows."""
    n = len(F.nf)
    timing: dict[str, np.ndarray] = {
        "tod_ns": np.full(n, -1, dtype=np.int64),
        "date_days": np.full(n, -1, dtype=np.int64),
        "dec": np.full(n, -1, dtype=np.int8),
    }
    if stype == "PASHR":
        timing["tod_ns"] = _tod(F, 1)
        return _pashr(F), timing
    if stype == "PSXN":
        return _psxn(F), timing
    if stype == "VDO":
        return _vdo(F), timing
    raise KeyError(stype)


def _heading(h: np.ndarray, q: np.ndarray) -> dict[str, np.ndarray]:
    nanv = np.full(len(h), np.nan)
    return {
        "heading_rad": h,
        "reference": np.full(len(h), 84, dtype=np.uint8),  # 'T'
        "deviation_rad": nanv,
        "variation_rad": nanv,
        "heading_quality": q,
    }


def pashr_quality(ins: np.ndarray, gnss: np.ndarray) -> np.ndarray:
    """``heading_quality`` from PASHR's INS status (field 11) and GNSS quality (field
    10), NaN where absent (the mapping of the module docstring)."""
    q = np.full(len(ins), np.nan)
    q = np.where(ins == 0, 2.0, q)
    q = np.where(ins == 2, 1.0, q)
    q = np.where((ins == 1) | (ins == 3) | (ins == 4), 0.0, q)
    return np.where((q == 0) & (gnss == 0), 1.0, q)  # no GNSS fix: the INS coasts unaided


def _pashr(F: Fields) -> Decoded:
    h = _angle(F, 2)
    ref = F.char(3)
    F.bad |= (ref != 84) & (ref != 0)  # 'T' (true) or empty; nothing else is defined
    gnss, _ = F.num(10)
    ins, _ = F.num(11)
    rows = np.ones(len(h), dtype=bool)
    return {"heading": (rows, _heading(h, pashr_quality(ins, gnss)))}


def _psxn(F: Fields) -> Decoded:
    n = len(F.nf)
    sub = _field_bytes(F, 1, 2)
    q20 = sub == _code("20")
    hq, _ = F.num(4)  # ,20: head-qual; ,23: the heading
    bad_q = q20 & ~np.isnan(hq) & ~np.isin(hq, (0.0, 1.0, 2.0))
    F.bad |= bad_q
    s23 = ~q20
    h = np.full(n, np.nan)
    if s23.any():
        sub23 = Fields(F.buf, F.commas, F.c0[s23], F.nf[s23], F.body_end[s23])
        h[s23] = _angle(sub23, 4)
        F.bad[s23] |= sub23.bad
    return {
        "heading": (s23, _heading(h, np.full(n, np.nan))),  # quality: from the ,20 before
        "psxn_quality": (q20, {"heading_quality": np.where(q20, hq, np.nan)}),
    }


def _ais_type(F: Fields) -> np.ndarray:
    c = F.first_char(5).astype(np.int64)
    return np.where(c - 48 > 40, c - 56, c - 48)  # the first 6 bits: the message type


def _sixbit(F: Fields) -> tuple[np.ndarray, np.ndarray]:
    """The payload (field 5): (its first :data:`_AIS_READ_CHARS` characters as 6-bit
    values, zero past its end; its length); rows with an armour character outside the
    alphabet or longer than :data:`AIS_MAX_CHARS` marked bad."""
    s, e = F.bounds(5)
    ln = e - s
    F.bad |= ln > AIS_MAX_CHARS
    w = int(min(max(int(ln.max()), _AIS_READ_CHARS), AIS_MAX_CHARS))
    mat = gather_rows(F.buf, s, w).astype(np.int64)
    inside = np.arange(w) < np.minimum(ln, w)[:, None]
    ok = ((mat >= 48) & (mat <= 87)) | ((mat >= 96) & (mat <= 119))
    F.bad |= (inside & ~ok).any(axis=1)
    v = np.where(mat - 48 > 40, mat - 56, mat - 48)
    v = np.where(inside & ok, v, 0)
    return v[:, :_AIS_READ_CHARS], ln


def _bits(v: np.ndarray, start: np.ndarray, width: int, signed: bool = False) -> np.ndarray:
    """Unsigned (or two's-complement) integer of ``width`` bits from bit ``start`` (per
    row) of 6-bit values ``v``: bit i is bit ``5 - i % 6`` of value ``i // 6``."""
    out = np.zeros(len(v), dtype=np.int64)
    rows = np.arange(len(v))
    for j in range(width):
        i = start + j
        out = out * 2 + ((v[rows, i // 6] >> (5 - i % 6)) & 1)
    if signed:
        out = np.where(out >= 1 << (width - 1), out - (1 << width), out)
    return out


def _vdo(F: Fields) -> Decoded:
    v, ln = _sixbit(F)
    t = _ais_type(F)
    need = np.array([AIS_TYPES.get(int(x), 0) for x in range(20)])[np.clip(t, 0, 19)]
    F.bad |= ln < need
    b = np.where(t >= 18, 46, 50)  # the SOG bit: 4 bits earlier in class B reports
    sog = _bits(v, b, 10)
    acc = _bits(v, b + 10, 1)
    lon = _bits(v, b + 11, 28, signed=True)
    lat = _bits(v, b + 39, 27, signed=True)
    cog = _bits(v, b + 66, 12)
    hdg = _bits(v, b + 78, 9)
    sec = _bits(v, b + 87, 6)
    del acc  # better or worse than 10 m: not a fix type (see the module docstring)
    has_pos = (lon != _NA_LON) & (lat != _NA_LAT)
    F.bad |= has_pos & ((np.abs(lon) > 180 * 600_000) | (np.abs(lat) > 90 * 600_000))
    F.bad |= (cog > 3600) | ((hdg > 359) & (hdg != 511))
    has_sog, has_cog, has_hdg = sog != 1023, cog != 3600, hdg != 511
    q = np.select([sec == 61, sec == 62, sec == 63], [7, 6, 0], 1).astype(np.int8)
    n = len(t)
    nanv = np.full(n, np.nan)
    position = {
        "lat_rad": lat / 600_000.0 * DEG,  # 1/10000 min -> degrees -> radians
        "lon_rad": lon / 600_000.0 * DEG,
        "alt_m": nanv,
        "hdop": nanv,
        "quality": q,
    }
    ground = {
        "cog_rad": np.where(has_cog, cog / 10.0 * DEG, np.nan),  # 1/10 deg
        "sog_mps": np.where(has_sog, sog / 10.0 * KN_MPS, np.nan),  # 1/10 kn
    }
    heading = _heading(np.where(has_hdg, hdg * DEG, np.nan), nanv)
    used = has_pos | has_sog | has_cog | has_hdg
    return {
        "position": (has_pos, position),
        "ground": (has_sog | has_cog, ground),
        "heading": (has_hdg, heading),
        "ais_second": (used, {"second": np.where(sec < 60, sec, -1).astype(np.int8)}),
    }
