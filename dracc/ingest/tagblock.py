"""IEC 61162-450 TAG blocks and logger timestamp prefixes, vectorised.

A TAG block precedes a sentence: ``\\s:INS2,c:1700000000*hh\\$INGGA,...``.  Its
parameters are ``key:value`` pairs separated by commas; the checksum ``hh`` is the
XOR of the bytes between the opening backslash and the ``*`` (IEC 61162-450 §7.3.2,
the same rule as NMEA 0183 sentences).  ``s:`` is the source identification, ``c:``
the UNIX time of the sentence: in seconds (<= 10 digits) or milliseconds (more).

Logger prefixes recognised before a sentence (the text between line start and ``$``):

* ISO 8601: ``2014-08-01T00:00:00.316000Z`` (OpenRVDAS), optionally after a data id
  (``gyr1 2014-08-01T00:00:00.183Z``); without a zone it is taken as UTC.
* Unix seconds or milliseconds: ``1700000000.25`` / ``1700000000250`` (a separator
  space, comma, semicolon or colon may follow).
* Signal K / canboat: ``1507112745025;A;`` (milliseconds; the letter is the
  direction, ignored).
* Anything else (e.g. OpenCPN's ``nmea0183 n0183-GPGSV GPGSV``) carries no time;
  it is counted as an unrecognised prefix and the sentence is read without it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.compute as pc

from .timebase import MISSING_NS

HEX = np.full(256, -1, dtype=np.int16)
for _i, _c in enumerate(b"0123456789ABCDEF"):
    HEX[_c] = _i
for _i, _c in enumerate(b"abcdef"):
    HEX[_c] = 10 + _i

_TAG_RE = r"^\\(?P<body>[^\\*]*)\*(?P<cs>[0-9A-Fa-f]{1,2})\\$"
_SRC_RE = r"(?:^|,)s:(?P<s>[^,]*)"
_C_RE = r"(?:^|,)c:(?P<c>[0-9]+(?:\.[0-9]*)?)"
_ISO_RE = (r"(?P<iso>\d{4}-\d{2}-\d{2}[T ]\d{2}:\d{2}:\d{2}(?:\.\d+)?)"
           r"(?P<tz>Z|[+-]\d{2}:?\d{2})?\s*$")
_UNIX_RE = r"^\s*(?P<u>\d{9,10}(?:\.\d*)?|\d{12,13}(?:\.\d*)?)\s*[,;:]?\s*$"
_SK_RE = r"^(?P<ms>\d{10,13});[A-Za-z];$"


def gather_strings(buf: np.ndarray, start: np.ndarray, end: np.ndarray) -> pa.Array:
    """The byte ranges [start, end) of ``buf`` as an Arrow string array (one copy)."""
    n = len(start)
    lens = np.maximum(end - start, 0).astype(np.int64)
    offsets = np.zeros(n + 1, dtype=np.int32)
    np.cumsum(lens, out=offsets[1:])
    total = int(offsets[-1])
    if total:
        rep = np.repeat(start - offsets[:-1], lens)
        idx = rep + np.arange(total)
        data = buf[idx]
        data = np.where(data < 128, data, 63).astype(np.uint8)  # '?' for non-ASCII
    else:
        data = np.zeros(0, dtype=np.uint8)
    return pa.StringArray.from_buffers(n, pa.py_buffer(offsets), pa.py_buffer(data.tobytes()))


@dataclass(frozen=True)
class PrefixResult:
    """Per prefix: external time (MISSING_NS if none), TAG source ('' if none), form and validity."""

    ext_ns: np.ndarray  #: int64
    source: np.ndarray  #: object array of str
    form: np.ndarray  #: object array: 'tag', 'iso', 'unix', 'signalk', 'other'
    bad_tag_checksum: np.ndarray  #: bool
    bad_tag: np.ndarray  #: bool: looks like a TAG block but cannot be read


def _num(arr: pa.Array) -> np.ndarray:
    return pc.cast(pc.if_else(pc.equal(arr, ""), None, arr), pa.float64()).to_numpy(zero_copy_only=False)


def parse_prefixes(buf: np.ndarray, start: np.ndarray, end: np.ndarray,
                   cum_xor: np.ndarray) -> PrefixResult:
    """Classify and read prefixes ``buf[start:end]`` (vectorised with Arrow regexes).

    ``cum_xor`` is ``np.bitwise_xor.accumulate(buf)`` for the TAG checksum:
    XOR over [a, b) = cum_xor[b-1] ^ cum_xor[a-1].
    """
    n = len(start)
    ext = np.full(n, MISSING_NS, dtype=np.int64)
    source = np.full(n, "", dtype=object)
    form = np.full(n, "other", dtype=object)
    bad_cs = np.zeros(n, dtype=bool)
    bad_tag = np.zeros(n, dtype=bool)
    if n == 0:
        return PrefixResult(ext, source, form, bad_cs, bad_tag)
    s = gather_strings(buf, start, end)
    is_tag = buf[start] == 92  # backslash
    if is_tag.any():
        ti = np.flatnonzero(is_tag)
        ts = s.take(pa.array(ti))
        m = pc.extract_regex(ts, _TAG_RE)
        ok = m.is_valid().to_numpy(zero_copy_only=False)
        bad_tag[ti[~ok]] = True
        form[ti] = "tag"
        oi = ti[ok]
        if len(oi):
            # checksum: bytes strictly between the opening '\' and '*'
            mo = m.filter(pa.array(ok))
            cslen = pc.utf8_length(pc.struct_field(mo, "cs")).to_numpy(zero_copy_only=False)
            a = start[oi] + 1
            star = end[oi] - 2 - cslen
            x = cum_xor[star - 1] ^ cum_xor[a - 1]
            hi = np.where(cslen == 2, HEX[buf[end[oi] - 3]], 0)
            lo = HEX[buf[end[oi] - 2]]
            given = (hi * 16 + lo).astype(np.int64)
            bad_cs[oi] = x.astype(np.int64) != given
            body = pc.struct_field(mo, "body")
            src = pc.struct_field(pc.extract_regex(body, _SRC_RE), "s")
            srcs = src.to_numpy(zero_copy_only=False)
            source[oi] = np.where(pd.isna(srcs), "", srcs)
            c = pc.struct_field(pc.extract_regex(body, _C_RE), "c")
            cv = _num(c.fill_null(""))
            has = ~np.isnan(cv)
            # c: in seconds (<= 10 integer digits, i.e. < 1e10) or milliseconds
            ns = np.where(cv < 1e10, cv * 1e9, cv * 1e6)
            e = np.full(len(oi), MISSING_NS, dtype=np.int64)
            e[has] = np.round(ns[has]).astype(np.int64)
            ext[oi] = e
    rest = np.flatnonzero(~is_tag)
    if len(rest):
        rs = s.take(pa.array(rest))
        sk = pc.struct_field(pc.extract_regex(rs, _SK_RE), "ms")
        skv = _num(sk.fill_null(""))
        hit = ~np.isnan(skv)
        ext[rest[hit]] = np.round(skv[hit] * 1e6).astype(np.int64)
        form[rest[hit]] = "signalk"
        un = pc.struct_field(pc.extract_regex(rs, _UNIX_RE), "u")
        unv = _num(un.fill_null(""))
        hit2 = ~np.isnan(unv) & ~hit
        ns = np.where(unv < 1e11, unv * 1e9, unv * 1e6)
        ext[rest[hit2]] = np.round(ns[hit2]).astype(np.int64)
        form[rest[hit2]] = "unix"
        todo = ~(hit | hit2)
        if todo.any():
            ri = rest[todo]
            m = pc.extract_regex(rs.filter(pa.array(todo)), _ISO_RE)
            ok = m.is_valid().to_numpy(zero_copy_only=False)
            if ok.any():
                iso = pc.struct_field(m, "iso").to_numpy(zero_copy_only=False)[ok]
                tz = pc.struct_field(m, "tz").to_numpy(zero_copy_only=False)[ok]
                tz = np.where(pd.isna(tz), "Z", tz)
                txt = pd.Series(iso.astype(str)).str.replace(" ", "T") + pd.Series(tz.astype(str))
                dt = pd.to_datetime(txt, format="ISO8601", utc=True, errors="coerce")
                v = dt.to_numpy(dtype="datetime64[ns]").astype(np.int64)
                good = ~dt.isna().to_numpy()
                idx = ri[ok][good]
                ext[idx] = v[good]
                form[idx] = "iso"
    return PrefixResult(ext, source, form, bad_cs, bad_tag)


def tag_checksum(body: bytes) -> int:
    """XOR of the TAG block body (between '\\' and '*'); for writers and tests."""
    x = 0
    for b in body:
        x ^= b
    return x
