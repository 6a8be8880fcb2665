"""IEC 61162-450 TAG blocks and logger timestamp prefixes, vectorised.

A TAG block precedes a sentence: ``\\s:INS2,c:1700000000*hh\\$INGGA,...``.  Its
parameters are ``key:value`` pairs separated by commas; the checksum ``hh`` is the
XOR of the bytes between the opening backslash and the ``*`` (IEC 61162-450 §7.3.2,
the same rule as NMEA 0183 sentences).  ``s:`` is the source identification, ``c:``
the UNIX time of the sentence: in seconds (<= 10 digits) or milliseconds (more).
``g:<i>-<n>-<id>`` (§7.3, line grouping) makes the sentence line ``i`` of ``n`` of group
``id``; :func:`parse_groups` reads it, :mod:`dracc.ingest.nmea.groups` joins the lines.

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

from dracc.frames import MISSING_NS

HEX = np.full(256, -1, dtype=np.int16)
for _i, _c in enumerate(b"0123456789ABCDEF"):
    HEX[_c] = _i
for _i, _c in enumerate(b"abcdef"):
    HEX[_c] = 10 + _i

# at most 9 fraction digits (ns): a run of 300 000 digits matched and was widened to an
# 11 GiB fixed-width array (fuzz)
_ISO_RE = (
    r"(?P<iso>\d{4}-\d{2}-\d{2}[T ]\d{2}:\d{2}:\d{2}(?:\.\d{1,9})?)"
    r"(?P<tz>Z|[+-]\d{2}:?\d{2})?\s*$"
)
_UNIX_RE = r"^\s*(?P<u>\d{9,10}(?:\.\d*)?|\d{12,13}(?:\.\d*)?)\s*[,;:]?\s*$"
_SK_RE = r"^(?P<ms>\d{10,13});[A-Za-z];$"


def gather_rows(buf: np.ndarray, s: np.ndarray, w: int) -> np.ndarray:
    """Rows of ``w`` bytes of ``buf`` starting at ``s`` (a copy; zeros past the end).

    ``parse_buffer`` passes buffers with 64 trailing zero bytes, so the fix-up for rows
    running past the end is rarely needed."""
    if len(buf) < w:
        buf = np.concatenate((buf, np.zeros(w, dtype=np.uint8)))
    lim = len(buf) - w
    mat = np.lib.stride_tricks.sliding_window_view(buf, w)[np.minimum(s, lim)]
    for r in np.flatnonzero(s > lim):  # rows starting in the last w bytes of an unpadded buffer
        mat[r] = np.concatenate((buf[s[r] :], np.zeros(w, np.uint8)))[:w]
    rows: np.ndarray = mat
    return rows


def unix_to_ns(v: np.ndarray, is_ms: np.ndarray) -> np.ndarray:
    """Unix seconds (fraction kept to the microsecond) or milliseconds (to the
    nanosecond) -> int64 ns, exactly: the integer part is scaled in int64, not in float
    (1.7e18 ns is beyond float64's 2**53)."""
    iv = np.floor(v)
    frac = v - iv
    whole = iv.astype(np.int64)
    ns: np.ndarray = np.where(
        is_ms,
        whole * 1_000_000 + np.round(frac * 1e6).astype(np.int64),
        whole * 1_000_000_000 + np.round(frac * 1e6).astype(np.int64) * 1000,
    )
    return ns


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


FORMS = ("other", "tag", "iso", "unix", "signalk")  #: prefix forms, by code


@dataclass(frozen=True)
class PrefixResult:
    """Per prefix: external time (MISSING_NS if none), TAG source ('' if none), form and validity."""

    ext_ns: np.ndarray  #: int64
    source: np.ndarray  #: object array of str
    form: np.ndarray  #: int8 codes into FORMS
    bad_tag_checksum: np.ndarray  #: bool
    bad_tag: np.ndarray  #: bool: looks like a TAG block but cannot be read


#: byte classes packed so that one sum per row counts them: digits (bits 0-7), points
#: (bits 8-15), signs (bits 16-23), anything else (bits 24-31); NUL padding counts nothing
_CLASS = np.full(256, 1 << 24, dtype=np.int32)
_CLASS[0] = 0
_CLASS[48:58] = 1
_CLASS[46] = 1 << 8
_CLASS[43] = _CLASS[45] = 1 << 16


def _numbers_arrow(
    buf: np.ndarray, s: np.ndarray, ln: np.ndarray, decimals: bool
) -> tuple[np.ndarray, np.ndarray | None] | None:
    """The common case of :func:`parse_numbers` (non-empty fields of ``[+-.0-9]`` only):
    the fields' bytes gathered end to end into one Arrow string array and cast to
    float64 by Arrow (correctly rounded, like numpy's ``astype`` from bytes, and about
    six times faster).  Returns (value, decimals) or None -- some other byte, or a field
    Arrow cannot read (``1.2.3``, ``-``): then the general path decides row by row."""
    offsets = np.zeros(len(s) + 1, dtype=np.int64)
    np.cumsum(ln, out=offsets[1:])
    total = int(offsets[-1])
    if total >= 1 << 31:  # pragma: no cover - blocks are tens of MB
        return None
    d = buf[np.repeat(s - offsets[:-1], ln) + np.arange(total)]
    if (((d - np.uint8(48)) > 9) & (d != 46) & (d != 45) & (d != 43)).any():
        return None
    arr = pa.StringArray.from_buffers(
        len(s), pa.py_buffer(offsets.astype(np.int32)), pa.py_buffer(d)
    )
    try:
        v = pc.cast(arr, pa.float64()).to_numpy(zero_copy_only=False)
    except pa.ArrowInvalid:
        return None
    dec = None
    if decimals:  # digits after the (one) point; -1 without one
        dots = np.flatnonzero(d == 46)
        row = np.searchsorted(offsets, dots, side="right") - 1
        dec = np.full(len(s), -1, dtype=np.int64)
        dec[row] = offsets[row + 1] - dots - 1
    return v, dec


def parse_numbers(
    buf: np.ndarray, s: np.ndarray, e: np.ndarray, width: int = 20, decimals: bool = True
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Decimal numbers in byte ranges [s, e) of ``buf``, vectorised.

    Returns (value float64 with NaN where empty or invalid, decimals int8 = digits after
    the point or -1, invalid bool).  A valid number is ``[+-]digits[.digits]`` (or
    ``.5``) with at least one digit; longer than ``width`` bytes is invalid.
    """
    ln = e - s
    n = len(s)
    val = np.full(n, np.nan)
    dec = np.full(n, -1, dtype=np.int8)
    invalid = ln > width
    has = (ln > 0) & ~invalid
    if not has.any():
        return val, dec, invalid
    hi = np.flatnonzero(has)
    lh = ln[hi]
    fast = _numbers_arrow(buf, s[hi], lh, decimals)
    if fast is not None:
        val[hi] = fast[0]
        if decimals:
            assert fast[1] is not None  # _numbers_arrow counts decimals when asked
            dec[hi] = fast[1]
        return val, dec, invalid
    w = int(lh.max())
    mat = gather_rows(buf, s[hi], w)  # a fresh copy: masked in place
    mat *= np.arange(w, dtype=np.uint8) < lh.astype(np.uint8)[:, None]
    # a NUL byte inside a field is not padding: after masking, the zeros are the
    # padding (w - length per row) plus any NUL inside
    if np.count_nonzero(mat == 0) != mat.size - int(lh.sum()):
        nul = (mat == 0) & (np.arange(w) < lh[:, None])
    else:
        nul = np.zeros((len(hi), 1), dtype=bool)
    # fast path: only digits, '.', signs and padding, and numpy parses every row
    odd = ((mat - np.uint8(48)) > 9) & (mat != 46) & (mat != 45) & (mat != 43) & (mat != 0)
    v = None
    if not (odd.any() or nul.any()):
        try:
            v = np.ascontiguousarray(mat).view(f"S{w}").ravel().astype(np.float64)
            ok = np.ones(len(hi), dtype=bool)
        except ValueError:
            v = None
    if v is None:  # validate row by row (vectorised): [+-]digits[.digits]
        tot = _CLASS[mat].sum(axis=1)
        nd = tot & 255
        ndot = (tot >> 8) & 255
        nsign = (tot >> 16) & 255
        other = tot >> 24
        sign0 = (mat[:, 0] == 45) | (mat[:, 0] == 43)
        ok = (nd >= 1) & (ndot <= 1) & (other == 0) & ((nsign == 0) | ((nsign == 1) & sign0))
        ok &= ~nul.any(axis=1)
        if not ok.all():
            mat[~ok] = 0
            mat[~ok, 0] = 48
        v = np.ascontiguousarray(mat).view(f"S{w}").ravel().astype(np.float64)
        v[~ok] = np.nan
    val[hi] = v
    invalid[hi[~ok]] = True
    if decimals:
        dot = mat == 46
        dpos = np.where(dot.any(axis=1), dot.argmax(axis=1), -1)
        dec[hi] = np.where(dpos >= 0, lh - dpos - 1, -1)
    return val, dec, invalid


def _key_value(
    buf: np.ndarray,
    colons: np.ndarray,
    commas: np.ndarray,
    start: np.ndarray,
    stop: np.ndarray,
    key: int,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """[s, e) of the value of TAG parameter ``key`` (one letter) in each body [start, stop)."""
    prev = buf[colons - 2]
    kc = colons[(buf[colons - 1] == key) & ((prev == 44) | (prev == 92))]
    i = np.searchsorted(kc, start)
    pos = kc[np.minimum(i, len(kc) - 1)] if len(kc) else np.zeros(len(start), np.int64)
    found = (i < len(kc)) & (pos < stop) if len(kc) else np.zeros(len(start), bool)
    vs = pos + 1
    # the value ends at the next ',' (or at ``stop``): look through a short window of bytes
    w = 32
    mat = gather_rows(buf, np.where(found, vs, 0), w)
    comma = mat == 44
    has = comma.any(axis=1)
    ve = np.where(has, vs + comma.argmax(axis=1), stop)
    far = found & ~has & (stop - vs > w)  # a long value: search the comma table instead
    if far.any():
        j = np.searchsorted(commas, vs[far])
        ve[far] = commas[np.minimum(j, len(commas) - 1)] if len(commas) else stop[far]
    ve = np.minimum(ve, stop)
    return found, np.where(found, vs, 0), np.where(found, ve, 0)


def parse_tags(
    buf: np.ndarray,
    start: np.ndarray,
    end: np.ndarray,
    cum_xor: np.ndarray,
    stars: np.ndarray,
    commas: np.ndarray,
    colons: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """TAG blocks ``buf[start:end]`` (each ``\\...*hh\\``), vectorised with numpy.

    Returns (ok, bad_checksum, ext_ns, source) where ``source`` is an object array.
    """
    n = len(start)
    i = np.searchsorted(stars, start)
    star = stars[np.minimum(i, len(stars) - 1)] if len(stars) else end
    cslen = end - 1 - star - 1
    ok = (i < len(stars)) & (star < end) & (buf[end - 1] == 92) & ((cslen == 1) | (cslen == 2))
    h_lo = HEX[buf[np.maximum(end - 2, 0)]]
    h_hi = np.where(cslen == 2, HEX[buf[np.maximum(end - 3, 0)]], 0)
    ok &= (h_lo >= 0) & (h_hi >= 0)
    star = np.where(ok, star, start + 1)
    x = cum_xor[np.maximum(star - 1, 0)] ^ cum_xor[start]  # XOR over (start, star)
    bad_cs = ok & (x.astype(np.int64) != h_hi.astype(np.int64) * 16 + h_lo)
    fc, cs_, ce = _key_value(buf, colons, commas, start, star, 99)  # 'c'
    cv, _, cbad = parse_numbers(buf, cs_, ce, decimals=False)
    ext, ok = _tag_time_ns(cv, cbad, fc, ok)
    source = np.full(n, "", dtype=object)
    fs, ss, se = _key_value(buf, colons, commas, start, star, 115)  # 's'
    # printable ASCII only (NUL and pairs of equal bytes leave the XOR checksum unchanged),
    # and a source of at most MAX_SOURCE_CHARS (fuzz: 300 000-character source keys)
    for k in np.flatnonzero(ok):  # long TAG blocks only: rare
        blk = buf[start[k] : end[k]]
        ok[k] = not np.any((blk < 32) | (blk > 126))
    ok &= ~(fs & (se - ss > MAX_SOURCE_CHARS))
    fs &= ok & (se > ss)
    if fs.any():
        hi = np.flatnonzero(fs)
        source[hi] = _decode_names(
            gather_rows(buf, ss[hi], int((se[hi] - ss[hi]).max())), se[hi] - ss[hi]
        )
    return ok, bad_cs, ext, source


def _tag_time_ns(
    cv: np.ndarray, cbad: np.ndarray, fc: np.ndarray, ok: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(times in ns, MISSING_NS where none; ok) from parsed ``c:`` values: seconds (up to
    10 integer digits, < 1e10) or milliseconds.  A time beyond the int64 nanosecond range
    (year 2262) is unreadable, not wrapped: its TAG block is not ok."""
    cbad = cbad | (np.abs(np.where(cv < 1e10, cv * 1e9, cv * 1e6)) >= 9.2e18)
    has = ok & fc & ~np.isnan(cv) & ~cbad
    ext = np.full(len(cv), MISSING_NS, dtype=np.int64)
    ext[has] = unix_to_ns(cv[has], cv[has] >= 1e10)
    return ext, ok & ~(fc & cbad)


def _decode_names(rows: np.ndarray, lengths: np.ndarray) -> np.ndarray:
    """Strings from rows of bytes (row i: its first ``lengths[i]`` bytes; a byte outside
    ASCII reads '?'), decoded once per distinct name."""
    cols = np.arange(rows.shape[1])
    rows = np.where(cols < lengths[:, None], rows, 0).astype(np.uint8)
    rows = np.where(rows < 128, rows, 63).astype(np.uint8)
    names = np.ascontiguousarray(rows).view(f"S{rows.shape[1]}").ravel()
    u, inv = np.unique(names, return_inverse=True)
    return np.array([x.decode("ascii") for x in u], dtype=object)[inv]


#: TAG blocks up to this many bytes are read as rows of a byte matrix (the common case);
#: longer ones through the buffer-wide tables of ``parse_tags``
TAG_ROW_BYTES = 128
#: a TAG ``s:`` source identification longer than this is not one (IEC 61162-450 allows 15)
MAX_SOURCE_CHARS = 64


def _key_value_rows(
    mat: np.ndarray, stop: np.ndarray, keys: tuple[int, ...]
) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """[s, e) (relative to each row) of the values of TAG parameters ``keys`` (one
    letter each) in rows of a byte matrix, each row one TAG block from its opening
    backslash, zeros past its end.

    The same rule as :func:`_key_value`: the first ``key:`` preceded by ``,`` or the
    opening backslash before ``stop``; the value runs to the next ``,`` or to ``stop``.
    Returns one (found, s, e) per key.
    """
    n, w = mat.shape
    flat = mat.ravel()
    # the colons and commas of all rows, as positions in the flattened matrix (a few per
    # row), rather than boolean matrices
    colon = np.flatnonzero(flat == 58)
    col = colon % w
    row = colon // w
    colon, col, row = colon[col >= 2], col[col >= 2], row[col >= 2]
    prev2 = flat[colon - 2]
    ok = (col < stop[row]) & ((prev2 == 44) | (prev2 == 92))
    colon, col, row = colon[ok], col[ok], row[ok]
    comma = np.flatnonzero(flat == 44)
    out: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
    for key in keys:
        sel = flat[colon - 1] == key
        c, r = col[sel], row[sel]
        first = np.ones(len(r), dtype=bool)
        first[1:] = r[1:] != r[:-1]  # the first ``key:`` of each row
        c, r = c[first], r[first]
        found = np.zeros(n, dtype=bool)
        found[r] = True
        vs = np.zeros(n, dtype=np.int64)
        vs[r] = c + 1
        # the first comma at or after the value's start in the same row, else the row's end
        j = np.searchsorted(comma, r * w + c + 1)
        nxt = comma[np.minimum(j, len(comma) - 1)] if len(comma) else np.zeros(len(r), np.int64)
        same = (j < len(comma)) & (nxt < (r + 1) * w)
        ve = np.zeros(n, dtype=np.int64)
        ve[r] = np.minimum(np.where(same, nxt - r * w, w), stop[r])
        out.append((found, vs, ve))
    return out


def parse_tag_rows(
    buf: np.ndarray, mat: np.ndarray, start: np.ndarray, length: np.ndarray, cum_xor: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """:func:`parse_tags` for TAG blocks given as rows of a byte matrix.

    ``mat[i, :length[i]]`` are the bytes of TAG block i (``\\...*hh\\``, starting at
    ``start[i]`` in ``buf``), zeros after; the result is the same as
    ``parse_tags(buf, start, start + length, ...)``, without buffer-wide tables of
    stars, commas and colons.
    """
    n, w = mat.shape
    rows = np.arange(n)
    ln = length.astype(np.int64)
    isstar = mat == 42
    star = isstar.argmax(axis=1)  # first '*' of the block
    cslen = ln - star - 2
    ok = isstar.any(axis=1) & (mat[rows, ln - 1] == 92) & ((cslen == 1) | (cslen == 2))
    h_lo = HEX[mat[rows, np.maximum(ln - 2, 0)]]
    h_hi = np.where(cslen == 2, HEX[mat[rows, np.maximum(ln - 3, 0)]], 0)
    ok &= (h_lo >= 0) & (h_hi >= 0)
    star = np.where(ok, star, 1)
    x = cum_xor[np.maximum(start + star - 1, 0)] ^ cum_xor[start]  # XOR over (start, star)
    bad_cs = ok & (x.astype(np.int64) != h_hi.astype(np.int64) * 16 + h_lo)
    (fc, cs_, ce), (fs, ss, se) = _key_value_rows(mat, star, (99, 115))  # 'c', 's'
    # printable ASCII only (NUL and pairs of equal bytes leave the XOR checksum unchanged),
    # and a source of at most MAX_SOURCE_CHARS (fuzz)
    ok &= ~np.any(((mat < 32) | (mat > 126)) & (np.arange(w) < ln[:, None]), axis=1)
    ok &= ~(fs & (se - ss > MAX_SOURCE_CHARS))
    cv, _, cbad = parse_numbers(buf, start + cs_, start + ce, decimals=False)
    ext, ok = _tag_time_ns(np.where(fc, cv, np.nan), cbad, fc, ok)
    source = np.full(n, "", dtype=object)
    fs &= ok & (se > ss)
    if fs.any():
        hi = np.flatnonzero(fs)
        cols = np.arange(int((se[hi] - ss[hi]).max()))
        source[hi] = _decode_names(
            mat[hi[:, None], np.minimum(ss[hi, None] + cols, w - 1)], se[hi] - ss[hi]
        )
    return ok, bad_cs, ext, source


def _num(arr: pa.Array) -> np.ndarray:
    values: np.ndarray = pc.cast(pc.if_else(pc.equal(arr, ""), None, arr), pa.float64()).to_numpy(
        zero_copy_only=False
    )
    return values


def parse_prefixes(
    buf: np.ndarray,
    start: np.ndarray,
    end: np.ndarray,
    cum_xor: np.ndarray,
    stars: np.ndarray | None = None,
    commas: np.ndarray | None = None,
) -> PrefixResult:
    """Classify and read prefixes ``buf[start:end]`` (vectorised with Arrow regexes).

    ``cum_xor`` is ``np.bitwise_xor.accumulate(buf)`` for the TAG checksum:
    XOR over [a, b) = cum_xor[b-1] ^ cum_xor[a-1].
    """
    n = len(start)
    ext = np.full(n, MISSING_NS, dtype=np.int64)
    source = np.full(n, "", dtype=object)
    form = np.zeros(n, dtype=np.int8)
    bad_cs = np.zeros(n, dtype=bool)
    bad_tag = np.zeros(n, dtype=bool)
    if n == 0:
        return PrefixResult(ext, source, form, bad_cs, bad_tag)
    is_tag = buf[start] == 92
    if is_tag.any():
        ti = np.flatnonzero(is_tag)
        form[ti] = FORMS.index("tag")
        tl = end[ti] - start[ti]
        short = tl <= TAG_ROW_BYTES
        if short.any():
            si = ti[short]
            ts, sl = start[si], tl[short]
            w = -(-int(sl.max()) // 8) * 8  # whole 8-byte words, compared as uint64
            mat = gather_rows(buf, ts, w)
            mat *= np.arange(w, dtype=np.uint8) < sl.astype(np.uint8)[:, None]
            # loggers repeat one TAG block on consecutive lines (same source, same
            # second): parse each run of byte-identical TAG blocks once
            words = mat.view(np.uint64)
            head = np.ones(len(si), dtype=bool)
            head[1:] = (sl[1:] != sl[:-1]) | np.any(words[1:] != words[:-1], axis=1)
            run = np.cumsum(head) - 1
            hi = np.flatnonzero(head)
            ok, bcs, e, src = parse_tag_rows(buf, mat[hi], ts[hi], sl[hi], cum_xor)
            bad_tag[si] = ~ok[run]
            bad_cs[si] = bcs[run]
            ext[si] = e[run]
            source[si] = src[run]
        if not short.all():
            li = ti[~short]
            if stars is None:
                stars = np.flatnonzero(buf == 42)
            if commas is None:
                commas = np.flatnonzero(buf == 44)
            colons = np.flatnonzero(buf == 58)
            ok, bcs, e, src = parse_tags(buf, start[li], end[li], cum_xor, stars, commas, colons)
            bad_tag[li] = ~ok
            bad_cs[li] = bcs
            ext[li] = e
            source[li] = src
    rest = np.flatnonzero(~is_tag)
    if len(rest):
        rs = gather_strings(buf, start[rest], end[rest])
        sk = pc.struct_field(pc.extract_regex(rs, _SK_RE), "ms")
        skv = _num(sk.fill_null(""))
        hit = ~np.isnan(skv)
        ext[rest[hit]] = unix_to_ns(skv[hit], np.ones(int(hit.sum()), dtype=bool))
        form[rest[hit]] = FORMS.index("signalk")
        un = pc.struct_field(pc.extract_regex(rs, _UNIX_RE), "u")
        unv = _num(un.fill_null(""))
        hit2 = ~np.isnan(unv) & ~hit
        ext[rest[hit2]] = unix_to_ns(unv[hit2], unv[hit2] >= 1e11)
        form[rest[hit2]] = FORMS.index("unix")
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
                form[idx] = FORMS.index("iso")
    return PrefixResult(ext, source, form, bad_cs, bad_tag)


_GROUP_RE = r"^(?P<i>\d{1,6})-(?P<n>\d{1,6})-(?P<id>\d{1,9})$"


def parse_groups(
    buf: np.ndarray, start: np.ndarray, end: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The line-group parameter ``g:<i>-<n>-<id>`` of TAG blocks ``buf[start:end]`` (each
    ``\\...*hh\\``, well formed), vectorised.

    Returns (found, ok, i, n, id): ``found`` where the block has a ``g:`` (the first one
    counts, found as :func:`parse_tag_rows` finds ``s:`` and ``c:``: after ``\\`` or
    ``,``, before the ``*``); ``ok`` where its value is three decimal integers with
    ``1 <= i <= n`` (``g:3-2-7``, ``g:1-x`` are not); i, n, id int64 (0 where not ok)."""
    k = len(start)
    ln = (end - start).astype(np.int64)
    off = np.zeros(k + 1, dtype=np.int64)
    np.cumsum(ln, out=off[1:])
    d = buf[np.repeat(start - off[:-1], ln) + np.arange(int(off[-1]))]
    d = np.concatenate((d, np.zeros(2, dtype=np.uint8)))
    stars = np.flatnonzero(d == 42)
    srow = np.searchsorted(off, stars, side="right") - 1
    star = off[1:].copy()  # the first '*' of each block (its end where it has none)
    first = np.ones(len(srow), dtype=bool)
    first[1:] = srow[1:] != srow[:-1]
    star[srow[first]] = stars[first]
    gp = np.flatnonzero(d[1:-1] == 103) + 1
    gp = gp[(d[gp + 1] == 58) & ((d[gp - 1] == 92) | (d[gp - 1] == 44))]
    grow = np.searchsorted(off, gp, side="right") - 1
    keep = gp < star[grow]
    gp, grow = gp[keep], grow[keep]
    first = np.ones(len(grow), dtype=bool)
    first[1:] = grow[1:] != grow[:-1]
    gp, grow = gp[first], grow[first]
    found = np.zeros(k, dtype=bool)
    found[grow] = True
    ok = np.zeros(k, dtype=bool)
    gi, gn, gid = (np.zeros(k, dtype=np.int64) for _ in range(3))
    if not len(gp):
        return found, ok, gi, gn, gid
    vs = gp + 2
    commas = np.flatnonzero(d == 44)
    j = np.searchsorted(commas, vs)
    ve = star[grow].copy()  # the value ends at the next ',' or at the '*'
    if len(commas):
        nxt = commas[np.minimum(j, len(commas) - 1)]
        ve = np.where(j < len(commas), np.minimum(nxt, ve), ve)
    m = pc.extract_regex(gather_strings(d, vs, ve), _GROUP_RE)
    valid = m.is_valid().to_numpy(zero_copy_only=False)
    vals = [
        pc.cast(pc.struct_field(m, f).fill_null("0"), pa.int64()).to_numpy(zero_copy_only=False)
        for f in ("i", "n", "id")
    ]
    valid &= (vals[0] >= 1) & (vals[0] <= vals[1])
    ok[grow] = valid
    for o, v in zip((gi, gn, gid), vals, strict=True):
        o[grow] = np.where(valid, v, 0)
    return found, ok, gi, gn, gid


def tag_checksum(body: bytes) -> int:
    """XOR of the TAG block body (between '\\' and '*'); for writers and tests."""
    x = 0
    for b in body:
        x ^= b
    return x
