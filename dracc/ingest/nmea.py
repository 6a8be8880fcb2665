"""NMEA 0183 text ingest, over blocks of bytes.

Where it is built, the compiled kernel ``_nmeascan`` (one pass in C, see ``_parse_c``)
decodes the clean lines of a block and hands every other line to the numpy path below,
which is also the fallback without a compiler and the reference of the differential
tests (tests/test_nmeascan.py).

A block (tens of MB, cut after a line end: LF, CR LF, CR CR LF or a lone CR) is read as
one ``uint8`` array, in pieces of bounded working memory; line ends, sentence starts
(``$``/``!``), commas and ``*`` are found with ``np.flatnonzero``;
checksums are XORs of ranges taken from one cumulative XOR; sentences are grouped by
type and their fields gathered into fixed-width byte matrices converted with
``astype(float)``.  There is no Python loop over lines; loops run over sentence types
and fields only.  Large files are parsed by two worker processes, block by block, with
bounded look-ahead, so memory does not grow with the file (``iter_nmea_blocks``); the
workers die with their parent.  A line longer than ``[ingest] max_line_bytes`` is one
``too_long`` reject, never held whole (only its tail's last sentence is read), so memory
does not grow with the content either: a crashed logger's 256 MB of NUL bytes costs one
line.

Field conversions (edges of the SI world, units per ``dracc.core.units``):

* ``ddmm.mmmm`` / ``dddmm.mmmm`` + hemisphere -> radians:
  ``deg = floor(v/100) + (v - 100 floor(v/100))/60``, S and W negative.
* knots -> m/s: ``* 1852/3600`` (exact); km/h -> m/s: ``/ 3.6`` (used only where the
  knots field is empty); nautical miles -> metres ``* 1852``.
* degrees -> radians; ROT degrees/minute -> rad/s: ``* pi/180/60``.
* ``hhmmss.sss`` -> ns of the day; ``ddmmyy`` -> date (years 80-99 -> 19yy, else 20yy,
  as gpsd does); ZDA ``hhmmss.ss,dd,mm,yyyy``.
* Empty fields are NaN, never zero.

Sentences read: HDT, HDG, HDM, THS, ROT (heading/rot); VHW, VBW (water), VLW
(distance); GGA, GLL, RMC, GNS (position; RMC also ground), VTG (ground); ZDA (time
only).  Other well-formed sentences, ``#`` comments and blank lines are not rejected
but *ignored*: counted by type (the sentence type, e.g. ``GSV``, ``VDM``; the first 5
characters of a proprietary address, e.g. ``PGRME``; ``comment``; ``blank``).
"""

from __future__ import annotations

import contextlib
import mmap
import os
import pickle
import stat
import tempfile
from collections import Counter
from collections.abc import Iterator, Sequence
from concurrent.futures import ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd

from dracc.core.errors import IngestError
from dracc.core.units import KN_MPS, NMI_M
from dracc.frames import (
    KIND_COLUMNS,
    KINDS,
    REFERENCE_DTYPE,
    FileResult,
    Rejects,
    TimeEvents,
    concat_blocks,
    make_frame,
)
from dracc.ingest.tagblock import FORMS, HEX, parse_numbers, parse_prefixes
from dracc.ingest.timebase import (
    MISSING_NS,
    EventCounter,
    TimeBase,
    days_from_civil,
    drop_implausible_ext,
    valid_civil,
)

if TYPE_CHECKING:  # config imports ingest.frames: no runtime import here
    from dracc.core.config import IngestConfig

DEG = np.pi / 180.0
FIRST_BLOCK_BYTES = 16 * 1024 * 1024  #: the first block (where talkers are fingerprinted)
#: the first block when workers parse the others: parsed by the main process while they
#: start (about 70 000 lines, plenty to fingerprint talkers)
MAIN_FIRST_BLOCK_BYTES = 4 * 1024 * 1024
#: the later blocks: small enough that a worker reuses its memory (fresh pages are dear)
BLOCK_BYTES = 8 * 1024 * 1024
PARALLEL_MIN_BYTES = 32 * 1024 * 1024  #: files at least this large use two processes
#: a line whose content (its line end excluded) is longer than this is not parsed: it is
#: one rejected line, reason ``too_long`` (the default of ``[ingest] max_line_bytes``)
MAX_LINE_BYTES = 65536
#: the numpy path works on pieces of at most this many bytes and lines ...
NUMPY_CHUNK_BYTES = 2 * 1024 * 1024
NUMPY_CHUNK_LINES = 1 << 18
#: ... and of at most this estimated working memory: ``8`` bytes per byte, ``200`` per
#: sentence start and ``80`` per line (measured on dense junk: '$,' repeated, 2-byte lines)
PIECE_BUDGET = 96 * 1024 * 1024
_W_BYTE, _W_START, _W_LINE = 8, 200, 80

#: sentence type -> (min, max) number of data fields after the address
FIELD_COUNTS = {
    "HDT": (2, 3),
    "HDM": (2, 3),
    "HDG": (5, 6),
    "THS": (2, 3),
    "ROT": (2, 3),
    "VHW": (8, 9),
    "VBW": (6, 11),
    "VLW": (4, 9),
    "GGA": (12, 15),
    "GLL": (4, 8),
    "RMC": (10, 14),
    "GNS": (12, 14),
    "VTG": (8, 10),
    "ZDA": (4, 7),
}
SENTENCES = tuple(FIELD_COUNTS)
#: talkers of satellite receivers: they cannot measure magnetic heading nor water speed
GNSS_TALKERS = frozenset({"GP", "GN", "GL", "GA", "GB", "GI", "GQ", "BD"})
NO_GNSS = frozenset({"HDG", "HDM", "VHW", "VBW", "VLW"})
#: reasons that do not make --strict fail: ``no_date`` is counted when the times are
#: resolved and reported at the end (valid lines dracc does not use are not rejected at
#: all: they are *ignored*, counted by type, see :data:`IGNORED`)
NON_FATAL = frozenset({"no_date"})

REASONS = {
    "checksum": "checksum does not match",
    "truncated": "sentence cut short (no checksum before the next sentence or end of file)",
    "binary": "non-printable bytes",
    "bad_address": "address field is not 2-character talker + 3-letter type",
    "implausible_talker": "satellite talker on a heading/log sentence (spliced address)",
    "field_count": "wrong number of fields for the sentence type",
    "malformed_field": "a field is not a number / out of range / bad hemisphere",
    "bad_tag": "TAG block unreadable or with a wrong checksum",
    "not_nmea": "no sentence on the line",
    "too_long": "line longer than [ingest] max_line_bytes (not read; e.g. a run of NUL bytes)",
    "no_date": "time of day with no date anywhere in the log (use --date)",
}

#: what the names counted as *ignored* (valid input dracc does not use; never rejected,
#: never a --strict failure) mean.  Besides these: the sentence type of a well-formed
#: standard sentence dracc does not read (``GSV``, ``MWV``, ``DBT``, ``XDR`` ...; also
#: ``VDM``/``VDO`` for AIS ``!AIVDM``/``!AIVDO``), and the address of a proprietary
#: sentence, its first 5 characters (``PGRME``, ``PUHAW``, ``PSRFT`` for ``$PSRFTXT``).
IGNORED = {
    "comment": "comment line ('#')",
    "blank": "empty line",
}
#: examples kept per ignored type (the first in the file)
IGNORED_EXAMPLES = 3


# ----------------------------------------------------------------------------- helpers
def _ranges_any(pos: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """True where the sorted positions ``pos`` have an element in [a, b)."""
    return np.searchsorted(pos, b) > np.searchsorted(pos, a)


class _Fields:
    """Field boundaries of a group of sentences (rows) in ``buf``."""

    def __init__(self, buf, commas, c0, nf, body_end):
        """``commas``: sorted positions of the commas inside sentence bodies; ``c0`` the
        index of each row's first comma (the one after the address), ``nf`` its count."""
        self.buf = buf
        self.nf = nf.astype(np.int64)  # data fields = number of commas
        self.c0 = c0
        self.commas = commas
        self.body_end = body_end
        self.bad = np.zeros(len(nf), dtype=bool)

    def bounds(self, k: int):
        """[start, end) of data field k (1-based); empty where the field is absent."""
        present = self.nf >= k
        ci = np.minimum(self.c0 + k - 1, len(self.commas) - 1)
        s = np.where(present, self.commas[ci] + 1, 0)
        cn = np.minimum(self.c0 + k, len(self.commas) - 1)
        e = np.where(self.nf > k, self.commas[cn], self.body_end)
        e = np.where(present, e, 0)
        return s, e

    def num(self, k: int, width: int = 20, decimals: bool = False):
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


def _latlon(F: _Fields, k: int, kh: int, pos: int, neg: int, limit_deg: float):
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


def _tod(F: _Fields, k: int) -> np.ndarray:
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


def _ymd_days(F: _Fields, y, m, d) -> np.ndarray:
    has = ~(np.isnan(y) | np.isnan(m) | np.isnan(d))
    yi = np.where(has, y, 2000).astype(np.int64)
    mi = np.where(has, m, 1).astype(np.int64)
    di = np.where(has, d, 1).astype(np.int64)
    ok = has & valid_civil(yi, mi, di)
    F.bad |= has & ~ok
    return np.where(ok, days_from_civil(yi, mi, di), -1)


def _angle(F: _Fields, k: int) -> np.ndarray:
    """Degrees 0..360 -> radians; out of range marked bad."""
    v, _ = F.num(k)
    bad = ~np.isnan(v) & ((v < 0) | (v > 360))
    F.bad |= bad
    v = np.where(bad, np.nan, v)
    return np.where(v >= 360.0, v - 360.0, v) * DEG


def _signed(F: _Fields, k: int, kh: int) -> np.ndarray:
    """Angle with E/W letter (east positive), radians."""
    v, _ = F.num(k)
    h = F.char(kh)
    bad = ~np.isnan(v) & (h != 69) & (h != 87) & (h != 0)
    F.bad |= bad
    return np.where(h == 87, -v, v) * DEG


def _speed(F: _Fields, k_kn: int, k_kmh: int | None = None) -> np.ndarray:
    kn, _ = F.num(k_kn)
    v = kn * KN_MPS  # knots -> m/s (exact 1852/3600)
    if k_kmh is not None:
        kmh, _ = F.num(k_kmh)
        v = np.where(np.isnan(v), kmh / 3.6, v)  # km/h -> m/s where knots are empty
    return v


# ------------------------------------------------------------------- per-type decoders
def _decode(
    stype: str, F: _Fields
) -> tuple[dict[str, dict[str, np.ndarray]], dict[str, np.ndarray]]:
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


# ---------------------------------------------------------------------- block parsing
@dataclass
class ParsedBlock:
    """What a worker returns for one block (line numbers relative to the block, 1-based)."""

    n_lines: int
    n_blank: int
    #: kind -> columns incl. 'line', 'seq', 'talker', 'sentence', 'tag_source', 'dec', 'tod_ns', 'date_days', 'ext_ns'
    kinds: dict[str, dict[str, np.ndarray]]
    #: the ZDA records (time only): seq, tod_ns, date_days, ext_ns, line
    clock: dict[str, np.ndarray]
    reject_counts: Counter
    reject_examples: dict[str, list[tuple[int, str]]]
    first_fatal: tuple[int, str, str] | None  #: (line, reason, text) of the first fatal rejection
    stats: Counter = field(default_factory=Counter)
    #: names for the 'tag_source' codes (TAG s: / given source keys; '' = none)
    source_names: list[str] = field(default_factory=list)
    #: valid sentences and lines dracc does not use, by type (GSV, VDM, PGRME, comment)
    ignored: Counter = field(default_factory=Counter)
    #: type -> the first few (line, text) of each ignored type
    ignored_examples: dict[str, list[tuple[int, str]]] = field(default_factory=dict)
    #: sentence starts in the block (the range of ``seq``)
    n_seg: int = 0


class _Marked:
    """Where the bytes of one class (here: binary ones) lie in a buffer: their sorted
    positions when they are few, else a boolean mask (one byte per byte, where positions
    would take eight); :meth:`any` tells which ranges [a, b) hold one."""

    def __init__(self, pos: np.ndarray | None = None, mask: np.ndarray | None = None):
        self.pos, self.mask = pos, mask  # mask: one False more than the buffer

    def any(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        if self.pos is not None:
            return _ranges_any(self.pos, a, b)
        out = np.zeros(len(a), dtype=bool)
        ne = np.flatnonzero(b > a)
        if len(ne):
            idx = np.empty(2 * len(ne), dtype=np.int64)
            idx[0::2], idx[1::2] = a[ne], b[ne]
            out[ne] = np.logical_or.reduceat(self.mask, idx)[0::2]
        return out


def _line_bounds(buf: np.ndarray, bufp: np.ndarray):
    """Lines of a buffer: (start, content end, ends with a line end, binary bytes).

    A line ends at LF, CR LF, CR CR LF (CR LF through a text-mode conversion: one line
    end, not an empty line) or a lone CR (old Mac loggers, serial capture tools); the
    content excludes its line end.  ``bufp`` is ``buf`` with zero bytes after it.  One
    pass finds the bytes outside printable ASCII, ``(b - 32) mod 256 > 94``; where they
    are most of the buffer (a run of NUL bytes) no position array per byte is made."""
    n = len(buf)
    m = (buf - np.uint8(32)) > 94
    if np.count_nonzero(m) * 8 <= n:  # text: positions (one line end or so per line)
        ctl = np.flatnonzero(m)
        del m
        cb = buf[ctl]
        isterm = (cb == 10) | (cb == 13)
        term = ctl[isterm]
        bad = _Marked(pos=ctl[~isterm & (cb != 9)])
        del ctl, cb, isterm
    else:  # mostly control bytes: line ends by position, binary bytes by mask if dense
        tm = (buf == 10) | (buf == 13)
        term = np.flatnonzero(tm)
        m &= ~tm
        m &= buf != 9
        del tm
        if np.count_nonzero(m) * 8 <= n:
            bad = _Marked(pos=np.flatnonzero(m))
        else:
            bad = _Marked(mask=np.concatenate((m, np.zeros(1, dtype=bool))))
        del m
    # a CR followed by LF or by CR LF belongs to the line end at that LF
    tb = buf[term]
    nx1 = bufp[term + 1]
    within = (tb == 13) & ((nx1 == 10) | ((nx1 == 13) & (bufp[term + 2] == 10)))
    last = term[~within]  # the last byte of each line end
    del term, tb, nx1, within
    c1 = (buf[last] == 10) & (bufp[last - 1] == 13)  # bufp[-1], bufp[-2]: zero padding
    c2 = c1 & (bufp[last - 2] == 13)
    first = last - c1 - c2  # the first byte of each line end: the end of the content
    ends = bool(len(last)) and int(last[-1]) == n - 1
    line_end = first if ends else np.concatenate((first, [n]))
    line_start = np.concatenate(([0], last[:-1] + 1)) if ends else np.concatenate(([0], last + 1))
    return line_start.astype(np.int64, copy=False), line_end.astype(np.int64, copy=False), ends, bad


def _too_long_block(text: bytes) -> ParsedBlock:
    """The block of one line too long to parse (``text``: its first bytes)."""
    tx = text[:120].decode("ascii", "replace")
    return ParsedBlock(
        1, 0, {}, {}, Counter(too_long=1), {"too_long": [(1, tx)]}, (1, "too_long", tx)
    )


def _tail_start(tail: bytes) -> int:
    """Where the tail of a line too long is read from: its last sentence start ('$' or
    '!'), with the TAG block right before it (``\\...\\``, at most 128 bytes), so that
    one sentence is read and not a run of junk; ``len(tail)`` if it has none, or if the
    TAG block before it is longer (damaged: the sentence's source and time are unknown).
    As the kernel's tail_start."""
    j = max(tail.rfind(b"$"), tail.rfind(b"!"))
    if j < 0:
        return len(tail)
    if j > 0 and tail[j - 1] == 92:  # '\\': the end of a TAG block: with it, or not at all
        k = tail.rfind(b"\\", max(0, j - 1 - 128), j - 1)
        return k if k >= 0 else len(tail)  # a TAG block that long is damaged: source unknown
    return j


def _long_line_block(
    head: bytes,
    tail: bytes,
    line_end: bytes,
    ignore_checksum: bool,
    at_eof: bool,
    max_line_bytes: int,
    ext_ns=None,
    ext_src=None,
) -> tuple[ParsedBlock, dict[str, int]]:
    """The block of one line longer than ``max_line_bytes``: one ``too_long`` reject (its
    example the line's first bytes, ``head``), and the line's ``tail`` (its last
    ``max_line_bytes`` bytes) read from its last sentence start (:func:`_tail_start`), so
    that a sentence written right after a run of NUL bytes (a logger restarted after a
    crash) is not lost; ``line_end``: the line's own line end (none at the end of a file)."""
    k = _tail_start(tail)
    if k == len(tail):
        return _too_long_block(head), {"": 0}
    pb, src = _parse_chunk(
        tail[k:] + line_end,
        ignore_checksum,
        at_eof,
        ext_ns,
        ext_src,
        0,
        max_line_bytes,
        split=False,
    )[0]
    tx = head[:120].decode("ascii", "replace")
    pb.reject_counts["too_long"] += 1
    pb.reject_examples["too_long"] = [(1, tx)]
    pb.first_fatal = min(x for x in (pb.first_fatal, (1, "too_long", tx)) if x is not None)
    return pb, src


def _concat_parsed(
    parts: list[tuple[ParsedBlock, dict[str, int]]],
) -> tuple[ParsedBlock, dict[str, int]]:
    """Blocks of consecutive pieces of a buffer as the block of the whole buffer: line
    numbers and ``seq`` offset, TAG source codes in order of first appearance over all
    lines (from each piece's first lines of its sources, see :func:`_parse_core`),
    examples the first ones in stream order."""
    if len(parts) == 1:
        return parts[0]
    firsts: dict[str, int] = {}
    n_lines = 0
    for pb, fs in parts:
        for nm, i in fs.items():
            if nm not in firsts:
                firsts[nm] = i + n_lines
        n_lines += pb.n_lines
    names = {nm: k for k, nm in enumerate(sorted(firsts, key=firsts.__getitem__))}
    n_lines = n_seg = n_blank = 0
    kinds: dict[str, dict[str, list]] = {}
    clock: dict[str, list] = {}
    counts: Counter = Counter()
    examples: dict[str, list] = {}
    fatal = []
    stats: Counter = Counter()
    ignored: Counter = Counter()
    ign_examples: dict[str, list] = {}
    for pb, _ in parts:
        lut = np.array([names[str(x)] for x in pb.source_names] or [0], dtype=np.int32)
        groups = [(kinds.setdefault(k, {}), cols) for k, cols in pb.kinds.items()]
        if pb.clock:
            groups.append((clock, pb.clock))
        for d, cols in groups:
            for c, v in cols.items():
                if c == "line":
                    v = v + n_lines
                elif c == "seq":
                    v = v + n_seg
                elif c == "tag_source":
                    v = lut[v]
                d.setdefault(c, []).append(v)
        counts.update(pb.reject_counts)
        for r, ex in pb.reject_examples.items():
            examples.setdefault(r, []).extend((ln + n_lines, tx) for ln, tx in ex)
        if pb.first_fatal is not None:
            fatal.append((pb.first_fatal[0] + n_lines,) + tuple(pb.first_fatal[1:]))
        stats.update(pb.stats)
        ignored.update(pb.ignored)
        for k, ex in pb.ignored_examples.items():
            ign_examples.setdefault(k, []).extend((ln + n_lines, tx) for ln, tx in ex)
        n_lines += pb.n_lines
        n_seg += pb.n_seg
        n_blank += pb.n_blank
    cat = {k: {c: np.concatenate(v) for c, v in d.items()} for k, d in kinds.items()}
    clock_np = {c: np.concatenate(v) for c, v in clock.items()}
    pb = ParsedBlock(
        n_lines,
        n_blank,
        cat,
        clock_np,
        counts,
        {r: ex[:5] for r, ex in examples.items()},
        min(fatal) if fatal else None,
        stats,
        list(names) if n_seg else [],
        ignored,
        {k: ex[:IGNORED_EXAMPLES] for k, ex in ign_examples.items()},
        n_seg,
    )
    return pb, firsts


def _chunk_cuts(data: bytes, size: int, max_lines: int) -> list[tuple[int, int]]:
    """[a, b) byte ranges of at most about ``size`` bytes and ``max_lines`` lines, each
    ending after a line end (or at the end of ``data``)."""
    n = len(data)
    out, a = [], 0
    while True:
        b = min(a + size, n)
        k = data.count(b"\n", a, b) + data.count(b"\r", a, b)  # at least the lines in [a, b)
        if k > max_lines:
            b = a + max(1, (b - a) * max_lines // k)
        e = _end_of_line_at(data, b) if b < n else None
        if e is None or e >= n:
            out.append((a, n))
            return out
        out.append((a, e))
        a = e


def _end_of_line_at(data: bytes, pos: int) -> int | None:
    """The offset after the first line end that starts at or after ``pos`` in ``data``."""
    i, j = data.find(b"\n", pos), data.find(b"\r", pos)
    q = i if j < 0 else j if i < 0 else min(i, j)
    if q < 0:
        return None
    return q + _line_end_length(data[q : q + 3])


def _line_end_length(b: bytes) -> int:
    """Bytes of the line end at the start of ``b`` (LF, CR LF, CR CR LF, a lone CR)."""
    if b[:1] == b"\r":
        return 2 if b[1:2] == b"\n" else 3 if b[1:3] == b"\r\n" else 1
    return 1


def _parse_numpy(
    data: bytes,
    ignore_checksum: bool = False,
    at_eof: bool = True,
    ext_line_ns: np.ndarray | None = None,
    ext_line_source: np.ndarray | None = None,
    max_line_bytes: int = MAX_LINE_BYTES,
) -> tuple[ParsedBlock, dict[str, int]]:
    """Parse a buffer of whole lines (the vectorised numpy core).

    ``ext_line_ns``/``ext_line_source`` give a receive time / source key per line (for
    :func:`parse_sentences`); otherwise they come from TAG blocks and prefixes.  Returns
    the block and the first line (0-based) of each source key over all lines ('' for
    lines without one), the order of ``source_names``.

    Memory is bounded by the piece, not by the content: the buffer is parsed in pieces
    of at most :data:`NUMPY_CHUNK_BYTES` and :data:`NUMPY_CHUNK_LINES`, and within
    :data:`PIECE_BUDGET` (estimated), cut at line ends, and merged
    (:func:`_concat_parsed`); a line longer than ``max_line_bytes`` is one ``too_long``
    reject and only its tail is read (:func:`_long_line_block`).
    """
    data = data if isinstance(data, bytes) else bytes(data)
    if not data:
        return ParsedBlock(0, 0, {}, {}, Counter(), {}, None), {}
    parts: list[tuple[ParsedBlock, dict[str, int]]] = []
    line0 = 0
    cuts = _chunk_cuts(data, NUMPY_CHUNK_BYTES, NUMPY_CHUNK_LINES)
    for a, b in cuts:
        chunk = data if len(cuts) == 1 else data[a:b]
        for part in _parse_chunk(
            chunk,
            ignore_checksum,
            at_eof and b == len(data),
            ext_line_ns,
            ext_line_source,
            line0,
            max_line_bytes,
        ):
            parts.append(part)
            line0 += part[0].n_lines
    return _concat_parsed(parts)


def _parse_chunk(
    data: bytes,
    ignore_checksum: bool,
    at_eof: bool,
    ext_ns,
    ext_src,
    line0: int,
    max_line_bytes: int,
    split: bool = True,
) -> list[tuple[ParsedBlock, dict[str, int]]]:
    """:func:`_parse_numpy` of one chunk: its lines too long split off, the rest in pieces
    within :data:`PIECE_BUDGET`; ``line0`` is the chunk's first line in ``ext_ns``/``ext_src``."""
    n = len(data)
    # 64 zero bytes after the data let fields be gathered as fixed-width windows
    bufp = np.frombuffer(data + bytes(64), dtype=np.uint8)
    buf = bufp[:n]
    line_start, line_end, ends_nl, bad = _line_bounds(buf, bufp)
    nl = len(line_start)
    st = np.flatnonzero((buf == 36) | (buf == 33))
    long = (line_end - line_start) > max_line_bytes

    def ext(a: int, b: int):
        return (
            None if ext_ns is None else np.asarray(ext_ns)[line0 + a : line0 + b],
            None if ext_src is None else np.asarray(ext_src, dtype=object)[line0 + a : line0 + b],
        )

    if not split or (
        not long.any() and _W_BYTE * n + _W_START * len(st) + _W_LINE * nl <= PIECE_BUDGET
    ):
        e_ns, e_src = ext(0, nl)
        return [
            _parse_core(
                bufp,
                buf,
                line_start,
                line_end,
                ends_nl,
                bad,
                st,
                ignore_checksum,
                at_eof,
                e_ns,
                e_src,
            )
        ]
    w = np.empty(nl + 1, dtype=np.int64)  # estimated working memory before each line
    w[:nl] = (
        _W_BYTE * line_start + _W_START * np.searchsorted(st, line_start) + _W_LINE * np.arange(nl)
    )
    w[nl] = _W_BYTE * n + _W_START * len(st) + _W_LINE * nl
    long_idx = np.flatnonzero(long).tolist()
    spans, a = [], 0
    for b in long_idx + [nl]:
        while a < b:
            j = int(np.searchsorted(w, w[a] + PIECE_BUDGET, side="right")) - 1
            j = min(max(j, a + 1), b)
            spans.append((False, a, j))
            a = j
        if b < nl:
            spans.append((True, b, b + 1))
            a = b + 1
    at = line_start.tolist() + [n]
    ends = {i: int(line_end[i]) for i in long_idx}
    del bufp, buf, line_start, line_end, bad, st, long, w
    out = []
    for is_long, a, b in spans:
        if is_long:
            e = ends[a]
            e_ns, e_src = ext(a, b)
            out.append(
                _long_line_block(
                    data[at[a] : at[a] + 120],
                    data[max(at[a], e - max_line_bytes) : e],
                    data[e : at[b]],
                    ignore_checksum,
                    at_eof and b == nl,
                    max_line_bytes,
                    e_ns,
                    e_src,
                )
            )
        else:
            e_ns, e_src = ext(a, b)
            out.extend(
                _parse_chunk(
                    data[at[a] : at[b]],
                    ignore_checksum,
                    at_eof and b == nl,
                    e_ns,
                    e_src,
                    0,
                    max_line_bytes,
                    split=False,
                )
            )
    return out


def _parse_core(
    bufp: np.ndarray,
    buf: np.ndarray,
    line_start: np.ndarray,
    line_end: np.ndarray,
    ends_nl: bool,
    bad: _Marked,
    st: np.ndarray,
    ignore_checksum: bool,
    at_eof: bool,
    ext_line_ns: np.ndarray | None,
    ext_line_source: np.ndarray | None,
) -> tuple[ParsedBlock, dict[str, int]]:
    """The vectorised parse of a piece without lines too long (see :func:`_parse_numpy`):
    ``st`` the positions of its '$' and '!' bytes."""
    n_lines = len(line_end)
    blank = line_end == line_start
    stats: Counter = Counter()
    stats["blank"] = int(blank.sum())
    counts: Counter = Counter()
    examples: dict[str, list[tuple[int, str]]] = {}
    fatal: list[tuple[int, str, str]] = []

    def reject(reason: str, lines_idx: np.ndarray, starts: np.ndarray, ends: np.ndarray):
        if len(lines_idx) == 0:
            return
        counts[reason] += len(lines_idx)
        ex = examples.setdefault(reason, [])  # the first 5 of each call: sorted at the end
        for j in range(min(5, len(lines_idx))):
            ex.append(
                (
                    int(lines_idx[j]) + 1,
                    bytes(buf[starts[j] : min(ends[j], starts[j] + 120)]).decode(
                        "ascii", "replace"
                    ),
                )
            )
        if reason not in NON_FATAL:
            j = 0
            fatal.append(
                (
                    int(lines_idx[j]) + 1,
                    reason,
                    bytes(buf[starts[j] : min(ends[j], starts[j] + 120)]).decode(
                        "ascii", "replace"
                    ),
                )
            )

    ignored: Counter = Counter()
    ign_examples: dict[str, list[tuple[int, str]]] = {}

    def ignore(names: np.ndarray, lines_idx: np.ndarray, starts: np.ndarray, ends: np.ndarray):
        """Count valid lines/sentences dracc does not use by type: ``names`` an (n, 8)
        uint8 matrix, the type's ASCII name zero-padded.  One sort over the n rows (as
        integers), a loop over the distinct types only."""
        if len(lines_idx) == 0:
            return
        keys = np.ascontiguousarray(names, dtype=np.uint8).view("<u8").ravel()
        u, inv, cnt = np.unique(keys, return_inverse=True, return_counts=True)
        inv = inv.ravel()
        order = np.argsort(inv, kind="stable")  # the rows of each type, in stream order
        g0 = np.cumsum(cnt) - cnt
        for j, key in enumerate(u.tolist()):
            name = int(key).to_bytes(8, "little").rstrip(b"\0").decode("ascii", "replace")
            ignored[name] += int(cnt[j])
            ex = ign_examples.setdefault(name, [])
            for r in order[g0[j] : g0[j] + min(IGNORED_EXAMPLES, int(cnt[j]))].tolist():
                ex.append(
                    (
                        int(lines_idx[r]) + 1,
                        bytes(buf[starts[r] : min(ends[r], starts[r] + 120)]).decode(
                            "ascii", "replace"
                        ),
                    )
                )

    def named(name: str, n: int) -> np.ndarray:
        m = np.zeros((n, 8), dtype=np.uint8)
        m[:, : len(name)] = np.frombuffer(name.encode(), dtype=np.uint8)
        return m

    # sentence starts: '$' or '!' not immediately followed by another start ('$$GPGGA')
    nxt_is = np.zeros(len(st), dtype=bool)
    nxt_is[:-1] = st[1:] == st[:-1] + 1
    stats["doubled_start"] = int(nxt_is.sum())
    st = st[~nxt_is]
    seg_line = np.searchsorted(line_start, st, side="right") - 1
    # drop starts that sit in the line ends or in comment lines
    keep = st < line_end[seg_line]
    comment_line = ~blank & (buf[np.minimum(line_start, len(buf) - 1)] == 35)
    keep &= ~comment_line[seg_line]
    st, seg_line = st[keep], seg_line[keep]
    nseg = len(st)
    seg_end = np.empty(nseg, dtype=np.int64)
    if nseg:
        seg_end[:-1] = np.where(seg_line[:-1] == seg_line[1:], st[1:], line_end[seg_line[:-1]])
        seg_end[-1] = line_end[seg_line[-1]]
    # trailing spaces/tabs after the checksum are ignored
    # lines without sentences
    has_seg = np.zeros(n_lines, dtype=bool)
    has_seg[seg_line] = True
    noseg = np.flatnonzero(~has_seg & ~blank)
    if len(noseg):
        isbin = bad.any(line_start[noseg], line_end[noseg])
        iscom = comment_line[noseg]
        for reason, m in (("binary", isbin & ~iscom), ("not_nmea", ~isbin & ~iscom)):
            sel = noseg[m]
            reject(reason, sel, line_start[sel], line_end[sel])
        sel = noseg[iscom]
        ignore(named("comment", len(sel)), sel, line_start[sel], line_end[sel])
    if nseg == 0:
        return (
            ParsedBlock(
                n_lines,
                int(blank.sum()),
                {},
                {},
                counts,
                _first_examples(examples, 5),
                min(fatal) if fatal else None,
                stats,
                ignored=ignored,
                ignored_examples=_first_examples(ign_examples, IGNORED_EXAMPLES),
            ),
            {"": 0} if n_lines else {},
        )

    cum_xor = np.bitwise_xor.accumulate(buf)
    commas = np.flatnonzero(buf == 44)
    # prefixes: text before the first sentence of a line
    first_of_line = np.ones(nseg, dtype=bool)
    first_of_line[1:] = seg_line[1:] != seg_line[:-1]
    line_ext = np.full(n_lines, MISSING_NS, dtype=np.int64)
    line_src = np.full(n_lines, "", dtype=object)
    line_bad = np.zeros(n_lines, dtype=bool)
    pre_seg = np.flatnonzero(first_of_line & (st > line_start[seg_line]))
    if len(pre_seg):
        pl = seg_line[pre_seg]
        pr = parse_prefixes(bufp, line_start[pl], st[pre_seg], cum_xor, None, commas)
        line_ext[pl] = pr.ext_ns
        line_src[pl] = pr.source
        badt = pr.bad_tag | (pr.bad_tag_checksum & (not ignore_checksum))
        line_bad[pl[badt]] = True
        stats["tag_checksum_ignored"] += int((pr.bad_tag_checksum & ignore_checksum).sum())
        for code, f in enumerate(FORMS):
            c = int(np.count_nonzero(pr.form == code))
            if c:
                stats[f"prefix_{f}"] += c
    if ext_line_ns is not None:
        line_ext = np.asarray(ext_line_ns, dtype=np.int64)
    if ext_line_source is not None:
        line_src = np.asarray(ext_line_source, dtype=object)
    src_codes, src_names = pd.factorize(line_src)
    src_codes = src_codes.astype(np.int32)
    src_names = [str(x) for x in src_names]
    _, src_first = np.unique(src_codes, return_index=True)  # codes in order of first appearance
    firsts = dict(zip(src_names, src_first.tolist(), strict=True))
    del line_src

    alive = np.ones(nseg, dtype=bool)

    def drop(reason, mask):
        idx = np.flatnonzero(mask & alive)
        reject(reason, seg_line[idx], st[idx], seg_end[idx])
        alive[idx] = False

    drop("bad_tag", line_bad[seg_line])
    # trim trailing blanks after the checksum
    drop("binary", bad.any(st, seg_end))
    seglen = seg_end - st
    star_ok = (seglen >= 4) & (buf[np.maximum(seg_end - 3, 0)] == 42)
    h1 = HEX[buf[np.maximum(seg_end - 2, 0)]]
    h2 = HEX[buf[np.maximum(seg_end - 1, 0)]]
    has_cs2 = star_ok & (h1 >= 0) & (h2 >= 0)
    # some loggers drop the leading zero of the checksum ('*5' for '*05')
    has_cs1 = ~has_cs2 & (seglen >= 3) & (buf[np.maximum(seg_end - 2, 0)] == 42) & (h2 >= 0)
    has_cs = has_cs2 | has_cs1
    body_end = np.where(has_cs2, seg_end - 3, np.where(has_cs1, seg_end - 2, seg_end))
    h1 = np.where(has_cs1, 0, h1)
    # a '*' elsewhere without two hex digits after it: cut short
    # '*' inside a sentence without a checksum at its end: cut short
    stray_star = np.zeros(nseg, dtype=bool)
    nocs = np.flatnonzero(~has_cs)
    if len(nocs):  # rare: the buffer's stars are only looked up for these
        stars = np.flatnonzero(buf == 42)
        stray_star[nocs] = _ranges_any(stars, st[nocs], seg_end[nocs])
    followed = np.zeros(nseg, dtype=bool)
    followed[:-1] = seg_line[1:] == seg_line[:-1]
    eof_cut = np.zeros(nseg, dtype=bool)
    if at_eof and not ends_nl:
        eof_cut[-1] = seg_line[-1] == n_lines - 1
    drop("truncated", ~has_cs & (followed | stray_star | eof_cut))
    x = cum_xor[np.maximum(body_end - 1, 0)] ^ cum_xor[st]  # XOR over (start, body_end)
    given = h1.astype(np.int64) * 16 + h2
    wrong = has_cs & (x.astype(np.int64) != given)
    if ignore_checksum:
        stats["checksum_ignored"] += int((wrong & alive).sum())
    else:
        drop("checksum", wrong)
    stats["no_checksum"] += int((~has_cs & alive).sum())
    stats["one_digit_checksum"] += int((has_cs1 & alive).sum())
    # address
    # the commas of each sentence body: [c_first, c_first + ncomma) in the comma table
    c_first = np.searchsorted(commas, st)
    ncomma = np.searchsorted(commas, body_end) - c_first
    first_comma = np.where(
        ncomma > 0,
        commas[np.minimum(c_first, max(len(commas) - 1, 0))] if len(commas) else 0,
        body_end,
    )
    addr_len = np.where(first_comma < body_end, first_comma - st - 1, body_end - st - 1)
    a5 = st[:, None] + 1 + np.arange(5)
    amat = buf[np.minimum(a5, len(buf) - 1)]
    alnum = ((amat >= 65) & (amat <= 90)) | ((amat >= 48) & (amat <= 57))
    proprietary = amat[:, 0] == 80  # 'P'
    good_addr = (
        (addr_len == 5)
        & alnum.all(axis=1)
        & np.all((amat[:, 2:] >= 65) & (amat[:, 2:] <= 90), axis=1)
    )
    ais = buf[st] == 33

    def drop_ignored(mask, width):
        """Valid sentences dracc does not use: counted by their first ``width`` address
        characters (from the talker on; 'GSV' for the type: width 3 from index 2)."""
        idx = np.flatnonzero(mask & alive)
        if len(idx) == 0:
            return
        m = np.zeros((len(idx), 8), dtype=np.uint8)
        if width == 3:  # the sentence type
            m[:, :3] = amat[idx, 2:5]
        else:  # a proprietary address, up to its first 5 characters
            m[:, :5] = np.where(np.arange(5) < addr_len[idx, None], amat[idx], 0)
        ignore(m, seg_line[idx], st[idx], seg_end[idx])
        alive[idx] = False

    drop_ignored(proprietary & (addr_len >= 2), 5)
    drop_ignored(ais & good_addr, 3)  # AIS: 'VDM', 'VDO' (an unreadable address is damage)
    drop("bad_address", ~good_addr)
    addr = np.ascontiguousarray(amat).view("S5").ravel()
    stype_b = np.ascontiguousarray(amat[:, 2:]).view("S3").ravel()
    talker_b = np.ascontiguousarray(amat[:, :2]).view("S2").ravel()
    known_types = np.array([s.encode() for s in SENTENCES], dtype="S3")
    is_known = np.isin(stype_b, known_types)
    drop_ignored(~is_known, 3)
    gnss_t = np.isin(talker_b, np.array([t.encode() for t in GNSS_TALKERS], dtype="S2"))
    no_gnss = np.isin(stype_b, np.array([t.encode() for t in NO_GNSS], dtype="S3"))
    drop("implausible_talker", gnss_t & no_gnss)
    del addr

    kinds: dict[str, dict[str, list]] = {}
    clock: dict[str, list] = {}
    for stype in SENTENCES:
        rows = np.flatnonzero(alive & (stype_b == stype.encode()))
        if len(rows) == 0:
            continue
        F = _Fields(bufp, commas, c_first[rows], ncomma[rows], body_end[rows])
        lo, hi = FIELD_COUNTS[stype]
        badn = (F.nf < lo) | (F.nf > hi)
        if badn.any():
            drop("field_count", np.isin(np.arange(nseg), rows[badn]))
            rows = rows[~badn]
            if len(rows) == 0:
                continue
            F = _Fields(bufp, commas, c_first[rows], ncomma[rows], body_end[rows])
        cols, timing = _decode(stype, F)
        if F.bad.any():
            drop("malformed_field", np.isin(np.arange(nseg), rows[F.bad]))
            okr = ~F.bad
            rows = rows[okr]
            cols = {k: {c: v[okr] for c, v in d.items()} for k, d in cols.items()}
            timing = {k: v[okr] for k, v in timing.items()}
            if len(rows) == 0:
                continue
        common = {
            "line": seg_line[rows] + 1,
            "seq": rows,
            "talker": talker_b[rows].view(np.uint16),
            "sentence": np.full(len(rows), SENTENCES.index(stype), dtype=np.int8),
            "tag_source": src_codes[seg_line[rows]],
            "ext_ns": line_ext[seg_line[rows]],
            **timing,
        }
        if stype == "ZDA":
            for c, v in common.items():
                clock.setdefault(c, []).append(v)
        for kind, d in cols.items():
            for c, t in KIND_COLUMNS[kind].items():  # every group carries every column
                if c not in d and t == "float64":
                    d[c] = np.full(len(rows), np.nan)
            tgt = kinds.setdefault(kind, {})
            for c, v in {**common, **d}.items():
                tgt.setdefault(c, []).append(v)
    kinds_np = {}
    for k, d in kinds.items():
        cat = {c: np.concatenate(v) for c, v in d.items()}
        order = np.argsort(cat["seq"], kind="stable")  # back to stream order
        kinds_np[k] = {c: v[order] for c, v in cat.items()}
    clock_np = {c: np.concatenate(v) for c, v in clock.items()}
    return (
        ParsedBlock(
            n_lines,
            int(blank.sum()),
            kinds_np,
            clock_np,
            counts,
            _first_examples(examples, 5),
            min(fatal) if fatal else None,
            stats,
            src_names,
            ignored,
            _first_examples(ign_examples, IGNORED_EXAMPLES),
            nseg,
        ),
        firsts,
    )


def _first_examples(
    examples: dict[str, list[tuple[int, str]]], k: int
) -> dict[str, list[tuple[int, str]]]:
    """The first ``k`` examples of each reason or type in stream order (by line; on one
    line in the order they were found): the same whatever pieces a buffer was cut into."""
    return {r: sorted(ex, key=lambda e: e[0])[:k] for r, ex in examples.items()}


# ------------------------------------------------------------- compiled scanning kernel
try:  # optional: built from _nmeascan.c when a C compiler was there at install time
    from dracc.ingest import _nmeascan
except ImportError:  # pragma: no cover - exercised on machines without a compiler
    _nmeascan = None

#: "c" (the compiled kernel where built, numpy for what it leaves) or "numpy" (numpy
#: only); the environment variable DRACC_NMEA_ENGINE sets it for benchmarks
ENGINE = os.environ.get("DRACC_NMEA_ENGINE", "c")

#: the kinds in the order the numpy path creates them (first sentence type of each)
_KIND_ORDER = ("heading", "rot", "water", "distance", "position", "ground")
_T = {s: i for i, s in enumerate(SENTENCES)}
#: kind -> sentence type codes giving it; value column -> column of the kernel's r_val
_KIND_TYPES = {
    "heading": (_T["HDT"], _T["HDM"], _T["HDG"], _T["THS"]),
    "rot": (_T["ROT"],),
    "water": (_T["VHW"], _T["VBW"]),
    "distance": (_T["VLW"],),
    "position": (_T["GGA"], _T["GLL"], _T["RMC"], _T["GNS"]),
    "ground": (_T["RMC"], _T["VTG"]),
}
_KIND_VALS = {
    "heading": {"heading_rad": 0, "reference": "code", "deviation_rad": 1, "variation_rad": 2},
    "rot": {"rot_radps": 0},
    "water": {"stw_mps": 0, "stw_transverse_mps": 1, "sog_long_mps": 2, "sog_transverse_mps": 3},
    "distance": {"total_water_m": 0, "trip_water_m": 1},
    "position": {"lat_rad": 0, "lon_rad": 1, "alt_m": 2, "hdop": 3, "quality": "code"},
    "ground": {"cog_rad": 0, "sog_mps": 1},
}


def engine_available() -> bool:
    """True if the compiled kernel is built and selected."""
    return _nmeascan is not None and ENGINE == "c"


def _scan_c(data: bytes, max_line_bytes: int = MAX_LINE_BYTES) -> dict:
    """Run the compiled kernel over ``data``; arrays trimmed to their lengths.  The arrays
    are sized by one counting pass (lines, '$'); pages never written cost no memory."""
    cap, cap_rows = _nmeascan.sizes(data)
    cap_long = len(data) // (max_line_bytes + 1) + 1
    nval = _nmeascan.NVAL
    a = {
        "fb_line": np.empty(cap, np.int64),
        "long_line": np.empty(cap_long, np.int64),
        "long_start": np.empty(cap_long, np.int64),
        "long_end": np.empty(cap_long, np.int64),
        "sub": np.empty(len(data), np.uint8),
        "line": np.empty(cap_rows, np.int64),
        "seq": np.empty(cap_rows, np.int64),
        "talker": np.empty(cap_rows, np.uint16),
        "sentence": np.empty(cap_rows, np.int8),
        "src": np.empty(cap_rows, np.int32),
        "ext_ns": np.empty(cap_rows, np.int64),
        "tod_ns": np.empty(cap_rows, np.int64),
        "date_days": np.empty(cap_rows, np.int64),
        "dec": np.empty(cap_rows, np.int8),
        "code": np.empty(cap_rows, np.int8),
        "val": np.empty((cap_rows, nval), np.float64),
    }
    n_lines, n_blank, n_rows, n_fb, n_long, sub_len, n_seg, n_tag, names, first = _nmeascan.scan(
        data,
        cap,
        cap_rows,
        max_line_bytes,
        a["fb_line"],
        a["long_line"],
        a["long_start"],
        a["long_end"],
        a["sub"],
        a["line"],
        a["seq"],
        a["talker"],
        a["sentence"],
        a["src"],
        a["ext_ns"],
        a["tod_ns"],
        a["date_days"],
        a["dec"],
        a["code"],
        a["val"],
    )
    fb = ("fb_line",)
    lg = ("long_line", "long_start", "long_end")
    out = {k: v[:n_rows] for k, v in a.items() if k not in fb + lg + ("sub",)}
    out.update({k: a[k][:n_fb] for k in fb})  # views: the pages beyond were never written
    out.update({k: a[k][:n_long] for k in lg})
    out.update(
        sub=a["sub"][:sub_len].tobytes(),
        n_lines=n_lines,
        n_blank=n_blank,
        n_tag=n_tag,
        n_seg=n_seg,
        names=names,
        first=first,
    )
    return out


def _parse_c(
    data: bytes, ignore_checksum: bool, at_eof: bool, max_line_bytes: int = MAX_LINE_BYTES
) -> ParsedBlock:
    """:func:`parse_buffer` with the compiled kernel: it decodes the clean lines and
    copies all others into a side buffer, parsed by :func:`_parse_numpy`; the two are
    merged back into stream order (line numbers, ``seq``, TAG source codes in order of
    first appearance), so the result equals the numpy path's.  Lines too long are listed
    by the kernel and rejected here (``too_long``), never copied."""
    r = _scan_c(data, max_line_bytes)
    n_lines = r["n_lines"]
    fb_lines = r["fb_line"]
    pbs, firsts_sub = _parse_numpy(r["sub"], ignore_checksum, at_eof, max_line_bytes=max_line_bytes)
    if pbs.n_lines != len(fb_lines):  # pragma: no cover - an internal inconsistency
        raise AssertionError(f"_nmeascan: {len(fb_lines)} fallback lines, numpy read {pbs.n_lines}")
    # TAG source names, factorized over all lines in order of first appearance
    first = dict(zip(r["names"], r["first"], strict=True))
    long_line = r["long_line"]
    if len(long_line):  # a line too long with no sentence in its tail has no source ('')
        at = np.minimum(np.searchsorted(fb_lines, long_line), max(len(fb_lines) - 1, 0))
        tailless = long_line[~(fb_lines[at] == long_line)] if len(fb_lines) else long_line
        if len(tailless):
            first[""] = min(first.get("", n_lines), int(tailless[0]))
    for nm, i in firsts_sub.items():
        i = int(fb_lines[i])
        first[nm] = min(first.get(nm, i), i)
    names = sorted(first, key=first.__getitem__)
    code_of = {nm: i for i, nm in enumerate(names)}
    lut_c = np.array([code_of[nm] for nm in r["names"]] or [0], dtype=np.int32)
    lut_sub = np.array([code_of[str(nm)] for nm in pbs.source_names] or [0], dtype=np.int32)
    if not r["n_seg"]:
        names = []  # no sentence anywhere: the numpy path names no sources

    def from_sub(cols: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        # a row's seq: its seq in the side buffer (the segments of the fallback lines before
        # it) plus the kernel's rows (one segment each) on the lines before its line
        out = dict(cols)
        line = fb_lines[cols["line"] - 1] + 1
        out["line"] = line
        out["seq"] = cols["seq"] + np.searchsorted(r["line"], line)
        out["tag_source"] = lut_sub[cols["tag_source"]]
        return out

    sent = r["sentence"]
    common = {
        "line": r["line"],
        "seq": r["seq"],
        "talker": r["talker"],
        "sentence": sent,
        "tag_source": lut_c[r["src"]],
        "ext_ns": r["ext_ns"],
        "tod_ns": r["tod_ns"],
        "date_days": r["date_days"],
        "dec": r["dec"],
    }
    val = r["val"]
    kinds: dict[str, dict[str, np.ndarray]] = {}
    for kind in _KIND_ORDER:
        types = _KIND_TYPES[kind]
        sel = np.flatnonzero(np.isin(sent, types)) if len(sent) else np.zeros(0, np.int64)
        parts = []
        if len(sel):
            cols = {c: v[sel] for c, v in common.items()}
            for c, j in _KIND_VALS[kind].items():
                if j == "code":
                    code = r["code"][sel]
                    cols[c] = code.view(np.uint8) if c == "reference" else code
                elif kind == "ground":  # RMC: (cog, sog) in columns 4, 5
                    rmc = sent[sel] == _T["RMC"]
                    cols[c] = np.where(rmc, val[sel, 4 + j], val[sel, j])
                else:
                    cols[c] = val[sel, j]
            parts.append(cols)
        if kind in pbs.kinds:
            parts.append(from_sub(pbs.kinds[kind]))
        if parts:
            kinds[kind] = _merge_parts(parts)
    parts = []
    zda = np.flatnonzero(sent == _T["ZDA"]) if len(sent) else np.zeros(0, np.int64)
    if len(zda):
        parts.append({c: v[zda] for c, v in common.items()})
    if pbs.clock:
        parts.append(from_sub(pbs.clock))
    clock = _merge_parts(parts) if parts else {}
    examples = {
        k: [(int(fb_lines[ln - 1]) + 1, tx) for ln, tx in v] for k, v in pbs.reject_examples.items()
    }
    fatal = pbs.first_fatal
    if fatal is not None:
        fatal = (int(fb_lines[fatal[0] - 1]) + 1, fatal[1], fatal[2])
    counts = Counter(pbs.reject_counts)
    if len(r["long_line"]):
        counts["too_long"] += len(r["long_line"])
        examples["too_long"] = [
            (int(li) + 1, data[a : min(int(e), a + 120)].decode("ascii", "replace"))
            for li, a, e in zip(
                r["long_line"][:5].tolist(),
                r["long_start"][:5].tolist(),
                r["long_end"][:5].tolist(),
                strict=True,
            )
        ]
        too_long = (examples["too_long"][0][0], "too_long", examples["too_long"][0][1])
        fatal = too_long if fatal is None else min(fatal, too_long)
    stats = Counter(pbs.stats)
    stats["blank"] += r["n_blank"]
    if r["n_tag"]:
        stats["prefix_tag"] += r["n_tag"]
    ign_examples = {
        k: [(int(fb_lines[ln - 1]) + 1, tx) for ln, tx in v]
        for k, v in pbs.ignored_examples.items()
    }
    return ParsedBlock(
        n_lines,
        r["n_blank"] + pbs.n_blank,
        kinds,
        clock,
        counts,
        examples,
        fatal,
        stats,
        [str(x) for x in names],
        Counter(pbs.ignored),
        ign_examples,
        int(r["n_seg"]),
    )


def _merge_parts(parts: list[dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
    """Rows from the kernel and from the numpy path, merged in stream order (``seq``)."""
    if len(parts) == 1:
        return parts[0]
    cat = {c: np.concatenate([p[c] for p in parts]) for c in parts[0]}
    order = np.argsort(cat["seq"], kind="stable")
    return {c: v[order] for c, v in cat.items()}


def parse_buffer(
    data: bytes,
    ignore_checksum: bool = False,
    at_eof: bool = True,
    ext_line_ns: np.ndarray | None = None,
    ext_line_source: np.ndarray | None = None,
    engine: str | None = None,
    max_line_bytes: int = MAX_LINE_BYTES,
) -> ParsedBlock:
    """Parse a buffer of whole lines.

    ``engine`` "c" uses the compiled kernel (:mod:`dracc.ingest._nmeascan`) where it is
    built, "numpy" the vectorised numpy core only; None follows :data:`ENGINE`.  Both
    give the same block (tests/test_nmeascan.py).  Lines with an external time/source
    (``ext_line_ns``/``ext_line_source``, for :func:`parse_sentences`) take the numpy core.
    Lines end at LF, CR LF, CR CR LF or a lone CR; a line longer than ``max_line_bytes``
    is one ``too_long`` reject (its bytes are never parsed).
    """
    use_c = (engine or ENGINE) == "c" and _nmeascan is not None
    if use_c and ext_line_ns is None and ext_line_source is None and len(data):
        return _parse_c(
            data if isinstance(data, bytes) else bytes(data),
            ignore_checksum,
            at_eof,
            max_line_bytes,
        )
    return _parse_numpy(
        data, ignore_checksum, at_eof, ext_line_ns, ext_line_source, max_line_bytes
    )[0]


# ------------------------------------------------------------------ streaming reader
def _block_ranges(
    path: Path,
    block_bytes: int,
    first_bytes: int | None = None,
    max_line_bytes: int = MAX_LINE_BYTES,
) -> Iterator[tuple[int, int, bool]]:
    """(offset, length, too long) of blocks of whole lines: the first about ``first_bytes``
    (default ``block_bytes``), the others about ``block_bytes``, each cut after a line end
    (LF, CR LF, CR CR LF or a lone CR).  A line longer than ``max_line_bytes`` across a
    cut is a block of its own, flagged too long: it is found by reading ahead, never held
    (a block never exceeds its size plus ``max_line_bytes``, whatever the file holds)."""
    size = path.stat().st_size
    fd = os.open(path, os.O_RDONLY)
    try:
        off = 0
        while off < size:
            end = off + ((first_bytes or block_bytes) if off == 0 else block_bytes)
            if end >= size:
                yield off, size - off, False
                return
            nxt = _next_line_end(fd, end, min(size, end + max_line_bytes + 3))
            if nxt is not None:
                yield off, nxt - off, False
                off = nxt
                continue
            # the line across the cut is too long: the block ends where it starts
            s = _line_start_before(fd, off, end)
            if s > off:
                yield off, s - off, False
            nxt = _next_line_end(fd, end, size)
            e = size if nxt is None else nxt
            yield s, e - s, True
            off = e
    finally:
        os.close(fd)


_SCAN_BYTES = 1 << 20  #: bytes read at a time when looking for a line end


def _next_line_end(fd: int, pos: int, limit: int) -> int | None:
    """The offset after the first line end starting in [pos, limit), None if there is none."""
    at = pos
    while at < limit:
        chunk = os.pread(fd, min(_SCAN_BYTES, limit - at), at)
        if not chunk:
            return None
        i, j = chunk.find(b"\n"), chunk.find(b"\r")
        q = i if j < 0 else j if i < 0 else min(i, j)
        if q >= 0:
            return at + q + _line_end_length(os.pread(fd, 3, at + q))
        at += len(chunk)
    return None


def _line_start_before(fd: int, lo: int, hi: int) -> int:
    """The start of the line holding byte ``hi - 1``: after the last CR or LF in [lo, hi),
    else ``lo`` (the caller knows ``hi`` is neither, so that CR is a line end)."""
    at = hi
    while at > lo:
        a = max(lo, at - _SCAN_BYTES)
        chunk = os.pread(fd, at - a, a)
        k = max(chunk.rfind(b"\n"), chunk.rfind(b"\r"))
        if k >= 0:
            return a + k + 1
        at = a
    return lo


def _parse_range(
    path: str,
    off: int,
    length: int,
    ignore_checksum: bool,
    at_eof: bool,
    max_line_bytes: int = MAX_LINE_BYTES,
    too_long: bool = False,
) -> ParsedBlock:
    """Parse one block of a file; a block flagged ``too_long`` (one line, see
    :func:`_block_ranges`) is one ``too_long`` reject and only its first bytes are read."""
    with open(path, "rb") as fh:
        fh.seek(off)
        if too_long:
            head = fh.read(min(length, 120))
            a = max(off, off + length - max_line_bytes - 3)
            fh.seek(a)
            tail = fh.read(off + length - a)
            content = tail.rstrip(b"\r\n")  # a line's content holds no CR or LF
            return _long_line_block(
                head,
                content[-max_line_bytes:],
                tail[len(content) :],
                ignore_checksum,
                at_eof,
                max_line_bytes,
            )[0]
        data = fh.read(length)
    return parse_buffer(
        data, ignore_checksum=ignore_checksum, at_eof=at_eof, max_line_bytes=max_line_bytes
    )


@dataclass
class Block:
    """One resolved block from :func:`iter_nmea_blocks`: canonical frames (times resolved,
    in stream order, not yet sorted) and the block's bookkeeping."""

    frames: dict[str, pd.DataFrame]
    lines: int  #: lines in this block
    first_line: int  #: 1-based number of the block's first line in the file
    bytes: int


@dataclass
class StreamState:
    """Running totals of a stream (filled while iterating)."""

    path: str
    lines: int = 0
    blank: int = 0
    bytes: int = 0
    rejects: Rejects = field(default_factory=Rejects)
    #: valid lines/sentences not used, by type (see :data:`IGNORED`), and their first examples
    ignored: Counter = field(default_factory=Counter)
    ignored_examples: dict = field(default_factory=dict)
    stats: Counter = field(default_factory=Counter)
    timebase: TimeBase = field(default_factory=TimeBase)
    events: EventCounter = field(default_factory=EventCounter)
    sentences: Counter = field(default_factory=Counter)
    split_talkers: dict = field(
        default_factory=dict
    )  #: talker -> decimals seen (fingerprint split)

    def time_events(self) -> TimeEvents:
        tb = self.timebase
        tot = self.events.totals()
        te = TimeEvents(
            duplicates=tot["duplicates"],
            backsteps=tot["backsteps"],
            gaps=tot["gaps"],
            rollovers=tb.rollovers,
            implausible_dates=tb.week_rollovers + tb.implausible,
        )
        te.decisions = list(dict.fromkeys(tb.decisions))
        if tb.derived:
            te.decisions.append(
                f"{tb.derived} records without a time field took the time of the "
                "preceding timed record (or the logger/TAG time)"
            )
        if tb.backward_midnight:
            te.decisions.append(
                f"{tb.backward_midnight} steps back over midnight between interleaved clocks"
            )
        if tb.week_rollovers:
            te.decisions.append(
                f"{tb.week_rollovers} dates corrected for the GPS week rollover (+1024 weeks)"
            )
        if tb.implausible:
            te.decisions.append(
                f"{tb.implausible} implausible dates (before 2000 or in the future) not used"
            )
        if tb.date_changes:
            te.decisions.append(f"the date changed {tb.date_changes} times other than at midnight")
        te.examples = list(self.events.examples)
        return te

    def count_block(
        self, pb: ParsedBlock, strict: bool, number=None, label: str = "{path}:{n}"
    ) -> int:
        """Add a parsed block's lines, statistics and rejects; return the stream line of its
        first line.  ``number(ln, line0)``: the number a reject example gets for the block's
        line ``ln`` (default: its line in the stream); ``label``: how the strict-mode error
        names it.  In ``strict`` mode the block's first rejected line raises IngestError."""
        line0 = self.lines + 1
        num = number or (lambda ln, first: ln + first - 1)
        self.lines += pb.n_lines
        self.blank += pb.n_blank
        self.stats.update(pb.stats)
        for reason, c in pb.reject_counts.items():
            self.rejects.counts[reason] += c
            ex = self.rejects.examples.setdefault(reason, [])
            for ln, text in pb.reject_examples.get(reason, [])[: max(0, 5 - len(ex))]:
                ex.append((self.path, num(ln, line0), text))
        self.ignored.update(pb.ignored)
        if pb.n_blank:
            self.ignored["blank"] += pb.n_blank
        for kind, exs in pb.ignored_examples.items():
            ex = self.ignored_examples.setdefault(kind, [])
            for ln, text in exs[: max(0, IGNORED_EXAMPLES - len(ex))]:
                ex.append((self.path, num(ln, line0), text))
        if strict and pb.first_fatal is not None:
            ln, reason, text = pb.first_fatal
            where = label.format(path=self.path, n=num(ln, line0))
            raise IngestError(f"{where}: rejected ({REASONS[reason]}): {text!r} (--strict)")
        return line0

    def notes(self) -> list[str]:
        s = self.stats
        out = []
        if s["no_checksum"]:
            out.append(
                f"{s['no_checksum']} sentences without checksum accepted (field checks only)"
            )
        if s["checksum_ignored"]:
            out.append(f"{s['checksum_ignored']} wrong checksums accepted (--ignore-checksum)")
        if s["tag_checksum_ignored"]:
            out.append(
                f"{s['tag_checksum_ignored']} wrong TAG checksums accepted (--ignore-checksum)"
            )
        if s["one_digit_checksum"]:
            out.append(f"{s['one_digit_checksum']} one-digit checksums ('*5' for '*05') accepted")
        if s["doubled_start"]:
            out.append(f"{s['doubled_start']} doubled sentence starts ('$$') read as one")
        if s["pool_fallback"]:
            out.append("the worker pool failed; blocks were parsed in the main process")
        if s["prefix_other"]:
            out.append(f"{s['prefix_other']} line prefixes without a recognisable time ignored")
        for k, v in sorted(s.items()):
            if k.startswith("prefix_") and k != "prefix_other" and v:
                out.append(f"{v} lines with {k[7:]} prefix")
        for t, decs in self.split_talkers.items():
            out.append(
                f"talker {t}: position sentences with {sorted(decs)} decimals of minutes "
                f"come from different receivers: source keys {t}/<n>dp"
            )
        return out


def _pool_ok() -> bool:
    """Two cores, and a process that may start children: a daemonic process (a Dask
    worker, a multiprocessing.Pool worker) may not, so there the reader parses alone."""
    import multiprocessing

    return (os.cpu_count() or 1) >= 2 and not multiprocessing.current_process().daemon


def _worker_init(parent_pid: int | None = None) -> None:
    """Set up a reader worker: it dies with its parent, holds none of its parent's
    standard streams, and keeps its freed memory.

    * A worker must not outlive the reader (a ``dracc analyze`` killed by SIGKILL, an
      OOM kill): on Linux the kernel sends it SIGKILL when its parent dies
      (``PR_SET_PDEATHSIG``); elsewhere, and for a parent that died before that was set,
      a watchdog thread ends it once its parent is gone (``os.getppid()`` changes).
    * Its stdin, stdout and stderr are ``/dev/null``: a caller waiting for the end of
      dracc's output (cron mailing it, a pipe) is not held up by a worker's copy of it.
      Results and errors go back through the pool.
    * Freed memory stays in the worker's heap (glibc): every block allocates arrays of
      the same sizes again, and returning them to the kernel after each block made the
      next block pay for fresh, zero-filled pages (about a third of the workers' CPU time
      was system time).  A worker's peak memory is unchanged: its heap never holds more
      than one block's arrays.  Without glibc this does nothing."""
    from dracc.core.workers import detach_worker

    detach_worker(parent_pid)
    try:
        import ctypes

        libc = ctypes.CDLL(None)
        libc.mallopt(-1, 1 << 30)  # M_TRIM_THRESHOLD: do not give freed heap back
        libc.mallopt(-3, 1 << 25)  # M_MMAP_THRESHOLD: arrays up to 32 MiB from the heap
    except (OSError, AttributeError, TypeError):  # pragma: no cover - not glibc
        pass


_HANDOVER_PREFIX = "dracc-ingest-"


def _handover_dir(needed_bytes: int):
    """Where workers leave parsed blocks for the main process: shared memory (tmpfs), else
    the temporary directory, whichever has room for ``needed_bytes`` (a reader of a whole
    file keeps its blocks until the end; a container's /dev/shm may hold only 64 MB); a
    context giving None where neither has: the blocks then come through the pool's pipe.
    The folder's name carries this process's id: folders left by a reader that was killed
    (SIGKILL cannot be caught) are removed by the next reader (:func:`_sweep_handover`)."""
    for base in ("/dev/shm", tempfile.gettempdir()):
        try:
            st = os.statvfs(base)
        except OSError:
            continue
        if os.access(base, os.W_OK):
            _sweep_handover(base)
            if st.f_bavail * st.f_frsize >= needed_bytes:
                return tempfile.TemporaryDirectory(
                    prefix=f"{_HANDOVER_PREFIX}{os.getpid()}-", dir=base
                )
    return contextlib.nullcontext(None)


def _sweep_handover(base: str) -> None:
    """Remove hand-over folders in ``base`` of this user whose reader process is gone."""
    import shutil

    try:
        names = [n for n in os.listdir(base) if n.startswith(_HANDOVER_PREFIX)]
    except OSError:
        return
    for name in names:
        parts = name[len(_HANDOVER_PREFIX) :].split("-", 1)
        if len(parts) != 2 or not parts[0].isdigit():  # not <pid>-<random>: not ours to judge
            continue
        pid_s = parts[0]
        path = os.path.join(base, name)
        try:
            if os.lstat(path).st_uid != os.getuid():
                continue
            os.kill(int(pid_s), 0)
        except ProcessLookupError:  # the reader is gone: its folder is debris
            shutil.rmtree(path, ignore_errors=True)
        except (OSError, AttributeError):  # alive (or not ours to ask about)
            continue


def _parse_range_to_file(
    folder: str | None,
    i: int,
    path: str,
    off: int,
    length: int,
    ignore_checksum: bool,
    at_eof: bool,
    max_line_bytes: int = MAX_LINE_BYTES,
):
    """:func:`_parse_range` in a worker, its arrays written to a file in ``folder``.

    A block's arrays (about 1.3x its text) sent through the pool's pipe cost the worker
    more than parsing them (64 KiB at a time, each a switch to the reader); written to
    a file they are two copies.  Returns (pickle of the block without its arrays, the
    arrays' sizes, the file) for :func:`_load_parsed`; or the block itself where there is
    no folder or the file cannot be written (a full disk): it then goes through the pipe."""
    pb = _parse_range(path, off, length, ignore_checksum, at_eof, max_line_bytes)
    if folder is None:
        return pb
    buffers: list[pickle.PickleBuffer] = []
    meta = pickle.dumps(pb, protocol=5, buffer_callback=buffers.append)
    views = [b.raw() for b in buffers]
    name = os.path.join(folder, f"block-{i}")
    try:
        with open(name, "wb") as fh:
            for v in views:
                fh.write(v)
    except OSError:
        with contextlib.suppress(OSError):
            os.unlink(name)
        return pb
    return meta, [v.nbytes for v in views], name


def _load_parsed(handed) -> ParsedBlock:
    """The block a worker handed over (:func:`_parse_range_to_file`).  From a file, its
    arrays are views of the file mapped copy-on-write (no copy; the pages are already in
    memory) and the file is removed at once: the mapping lives as long as the arrays do."""
    if isinstance(handed, ParsedBlock):
        return handed
    meta, sizes, name = handed
    with open(name, "rb") as fh:
        whole = (
            memoryview(mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_COPY)) if sum(sizes) else None
        )
    os.unlink(name)
    views, at = [], 0
    for size in sizes:
        views.append(whole[at : at + size])
        at += size
    return pickle.loads(meta, buffers=views)


_DTYPES: dict[tuple, pd.CategoricalDtype] = {}


def _cat(codes: np.ndarray, labels: list[str]) -> pd.Categorical:
    """Categorical from codes with a cached dtype (building dtypes is the slow part)."""
    key = tuple(labels)
    dt = _DTYPES.get(key)
    if dt is None:
        dt = _DTYPES[key] = pd.CategoricalDtype(pd.Index(labels, dtype=object))
    return pd.Categorical.from_codes(codes.astype(np.int32, copy=False), dtype=dt)


def _small_unique(x: np.ndarray, size: int) -> tuple[np.ndarray, np.ndarray]:
    """``np.unique(x, return_inverse=True)`` for integers in [0, size): a count per
    value instead of a sort."""
    u = np.flatnonzero(np.bincount(x, minlength=size))
    lut = np.zeros(size, dtype=np.int64)
    lut[u] = np.arange(len(u))
    return u, lut[x]


def _reference_categorical(codes: np.ndarray) -> pd.Categorical:
    """The heading reference column from its byte codes: 'T' (84), 'M' (77), else NaN."""
    c = np.where(codes == ord("T"), 1, np.where(codes == ord("M"), 0, -1)).astype(np.int8)
    return pd.Categorical.from_codes(c, dtype=REFERENCE_DTYPE)


def _talker_str(code: int) -> str:
    return int(code).to_bytes(2, "little").decode("ascii", "replace")


def _source_categorical(
    cols: dict[str, np.ndarray], names: list[str], split_talkers: dict, kind: str
) -> tuple[pd.Categorical, pd.Categorical]:
    """(source, talker) categoricals from codes: the TAG/given source where there is one,
    else the talker, split by decimals of minutes for fingerprinted talkers."""
    talker = cols["talker"].astype(np.int64)
    tag = cols["tag_source"].astype(np.int64)
    has_tag = np.zeros(len(tag), dtype=bool)
    if names:
        named = np.array([bool(n) for n in names])
        has_tag = named[tag]
    dec = cols["dec"].astype(np.int64) if kind in ("position", "ground") else np.full(len(tag), -1)
    split_codes = [int.from_bytes(t.encode(), "little") for t in split_talkers]
    split = ~has_tag & np.isin(talker, split_codes) if split_codes else np.zeros(len(tag), bool)
    # one integer per distinct source: tag code, or talker (+ decimals where split)
    key = np.where(has_tag, tag, (1 << 32) + talker * 64 + np.where(split, dec + 1, 0))
    inv, ukey = pd.factorize(key, sort=True)  # = np.unique(key, return_inverse=True), by hashing
    labels = []
    for k in ukey.tolist():
        if k < (1 << 32):
            labels.append(names[k])
        else:
            t, d = divmod(k - (1 << 32), 64)
            labels.append(_talker_str(t) + (f"/{d - 1}dp" if d else ""))
    if len(set(labels)) == len(labels):
        src = _cat(inv, labels)
    else:  # a TAG source named like a talker: one key
        src = pd.Categorical(np.asarray(labels, dtype=object)[inv])
    ut, tinv = _small_unique(talker, 1 << 16)
    tal = _cat(tinv, [_talker_str(t) for t in ut.tolist()])
    return src, tal


def _assemble(
    pb: ParsedBlock,
    times: list[np.ndarray],
    state: StreamState,
    file: str,
    line0: int,
    cfg: IngestConfig,
) -> dict[str, pd.DataFrame]:
    """Turn a parsed block plus resolved times into canonical frames; count events."""
    frames = {}
    order_kinds = [k for k in KINDS if k in pb.kinds]
    for kind, t in zip(order_kinds, times, strict=True):
        cols = pb.kinds[kind]
        line = cols["line"] + line0 - 1
        missing = t == MISSING_NS
        if missing.any():
            idx = np.flatnonzero(missing)
            if kind == "ground":  # an RMC is one line: counted once, in its position row
                idx = idx[cols["sentence"][idx] != SENTENCES.index("RMC")]
            if len(idx):
                state.rejects.counts["no_date"] += len(idx)
                ex = state.rejects.examples.setdefault("no_date", [])
                for j in idx[: max(0, 5 - len(ex))]:
                    ex.append(
                        (
                            file,
                            int(line[j]),
                            f"{SENTENCES[cols['sentence'][j]]} time of day without date",
                        )
                    )
            keep = ~missing
            cols = {c: v[keep] for c, v in cols.items()}
            t, line = t[keep], line[keep]
        if len(t) == 0:
            continue
        src, tal = _source_categorical(cols, pb.source_names, state.split_talkers, kind)
        us, sinv = _small_unique(cols["sentence"].astype(np.int64), len(SENTENCES))
        sent = _cat(sinv, [SENTENCES[i] for i in us])
        own = (cols["tod_ns"] >= 0) | (cols["ext_ns"] != MISSING_NS)
        if kind == "ground":  # an RMC is counted once, in its position record
            own &= cols["sentence"] != SENTENCES.index("RMC")
        data = {
            c: v
            for c, v in cols.items()
            if c
            not in (
                "seq",
                "tag_source",
                "dec",
                "tod_ns",
                "date_days",
                "ext_ns",
                "talker",
                "sentence",
            )
        }
        data.update(
            talker=tal,
            source=src,
            sentence=sent,
            time_ns=t,
            line=line,
            recv_ns=_recv_ns(cols["tod_ns"], cols["ext_ns"]),
        )
        if "reference" in data:
            data["reference"] = _reference_categorical(data["reference"])
        df = make_frame(kind, data)
        state.events.add(kind, src, t, own, line, file, sent)
        frames[kind] = df
    return frames


def _recv_ns(tod_ns: np.ndarray, ext_ns: np.ndarray) -> np.ndarray:
    """The receive time of records with their own time of fix: the external time (TAG
    ``c:``, logger prefix, MCAP log time) the time base used, i.e. after
    :func:`~dracc.ingest.timebase.drop_implausible_ext`; ``MISSING_NS`` where the record
    has no time of fix (HDT, VTG ...) or no usable external time."""
    ext, _ = drop_implausible_ext(ext_ns)
    return np.where((tod_ns >= 0) & (ext != MISSING_NS), ext, MISSING_NS).astype(
        np.int64, copy=False
    )


def _time_arrays(pb: ParsedBlock):
    """All records of a block in stream order: (tod, date, ext, splitter)."""
    parts = [pb.kinds[k] for k in KINDS if k in pb.kinds]
    if pb.clock:
        parts.append(pb.clock)
    if not parts:
        e = np.zeros(0, dtype=np.int64)
        return e, e, e, lambda t: []
    seq = np.concatenate([p["seq"] for p in parts])
    # an RMC gives a position and a ground row: its date counts once (position row)
    dates = [
        np.where(p["sentence"] == SENTENCES.index("RMC"), -1, p["date_days"])
        if k == "ground"
        else p["date_days"]
        for k, p in zip([k for k in KINDS if k in pb.kinds] + ["clock"], parts, strict=False)
    ]
    order = np.argsort(seq, kind="stable")
    tod = np.concatenate([p["tod_ns"] for p in parts])[order]
    date = np.concatenate(dates)[order]
    ext = np.concatenate([p["ext_ns"] for p in parts])[order]
    sizes = [len(p["seq"]) for p in parts]
    n_frames = len(parts) - (1 if pb.clock else 0)

    def split(t_sorted):
        t = np.empty_like(t_sorted)
        t[order] = t_sorted
        out = np.split(t, np.cumsum(sizes)[:-1])
        return out[:n_frames]

    return tod, date, ext, split


def iter_nmea_blocks(
    path: str | Path,
    cfg: IngestConfig,
    state: StreamState | None = None,
    block_bytes: int | None = None,
    workers: int | None = None,
    progress=None,
) -> Iterator[Block]:
    """Stream an NMEA text file as resolved blocks with bounded memory.

    ``state`` (a :class:`StreamState`, created if None) accumulates rejections, time
    events and statistics while iterating; read it after the loop.  Files of at least
    ``PARALLEL_MIN_BYTES`` are parsed by up to two worker processes, at most four blocks
    ahead, which hand their blocks over as files (:func:`_parse_range_to_file`) and die
    with this process (:func:`_worker_init`); this process parses the first block itself
    while they start, then resolves times and builds frames in order.  Blocks are cut
    after a line end; a line longer than ``cfg.max_line_bytes`` across a cut is a block of
    its own, read only at its ends (:func:`_block_ranges`).  ``block_bytes`` None: a first block of ``FIRST_BLOCK_BYTES``
    (``MAIN_FIRST_BLOCK_BYTES`` with workers), then blocks of about ``BLOCK_BYTES``, as
    many as the workers share evenly (none waits alone at the end); a number: blocks of that
    size.  ``progress(n_bytes)`` is called as blocks finish.  Raises IngestError in
    ``cfg.strict`` mode at the first rejected line.
    """
    path = Path(path)
    file = str(path)
    st = state if state is not None else StreamState(file)
    st.path = file
    if cfg.date is not None:
        try:
            y, m, d = (int(x) for x in cfg.date.split("-"))
            if not valid_civil(y, m, d):
                raise ValueError
            st.timebase.cfg_date_days = int(days_from_civil(y, m, d))
        except ValueError as err:
            raise IngestError(f"--date {cfg.date!r}: expected YYYY-MM-DD") from err
    st.events.gap_s = cfg.gap_s
    st.events.tolerance_s = cfg.backstep_tolerance_s
    size = path.stat().st_size
    nworkers = (
        workers if workers is not None else (2 if size >= PARALLEL_MIN_BYTES and _pool_ok() else 1)
    )
    max_line = int(getattr(cfg, "max_line_bytes", MAX_LINE_BYTES))
    if block_bytes is not None:
        ranges = list(_block_ranges(path, block_bytes, max_line_bytes=max_line))
    else:
        first_bytes = MAIN_FIRST_BLOCK_BYTES if nworkers > 1 else FIRST_BLOCK_BYTES
        rest = max(size - first_bytes, 0)
        n_rest = -(-rest // BLOCK_BYTES)
        if n_rest % nworkers:  # the workers share the blocks after the first evenly
            n_rest += nworkers - n_rest % nworkers
        later = max(-(-rest // n_rest), 1) if n_rest else BLOCK_BYTES
        ranges = list(_block_ranges(path, later, first_bytes, max_line))
    held: list = []
    first_parsed = [True]  # talkers are fingerprinted in the first block read (not a line too long)

    def handle(pb: ParsedBlock, nbytes: int):
        line0 = st.count_block(pb, cfg.strict)
        st.bytes += nbytes
        for kind, cols in pb.kinds.items():
            sc = (
                cols["sentence"][cols["sentence"] != SENTENCES.index("RMC")]
                if kind == "ground"
                else cols["sentence"]
            )
            c = np.bincount(sc.astype(np.int64), minlength=len(SENTENCES))
            st.sentences.update({SENTENCES[i]: int(c[i]) for i in np.flatnonzero(c).tolist()})
            if kind == "position" and first_parsed[0] and not st.split_talkers:
                _fingerprint(cols, st, pb.source_names)
        if pb.clock:
            st.sentences["ZDA"] += len(pb.clock["seq"])
        if pb.n_lines and not (pb.n_lines == 1 and pb.reject_counts.get("too_long") == 1):
            first_parsed[0] = False
        tod, date, ext, split = _time_arrays(pb)
        held.append((pb, split, line0, nbytes))
        done = st.timebase.feed(tod, date, ext)
        yield from _release(done)

    def _release(done):
        for t in done:
            pb, split, line0, nbytes = held.pop(0)
            frames = _assemble(pb, split(t), st, file, line0, cfg)
            if progress is not None:
                progress(nbytes)
            yield Block(frames, pb.n_lines, line0, nbytes)

    at_eof = [i == len(ranges) - 1 for i in range(len(ranges))]

    def local(i: int) -> ParsedBlock:
        off, ln, too_long = ranges[i]
        return _parse_range(file, off, ln, cfg.ignore_checksum, at_eof[i], max_line, too_long)

    if nworkers <= 1 or len(ranges) <= 1:
        for i, (_off, ln, _long) in enumerate(ranges):
            yield from handle(local(i), ln)
    else:
        # at most nworkers + 2 blocks in flight; a broken pool (a worker killed, e.g. out of
        # memory) falls back to parsing the remaining blocks in this process
        pending = list(range(len(ranges)))
        broken = False
        with (
            _handover_dir(2 * size) as folder,
            ProcessPoolExecutor(
                max_workers=nworkers, initializer=_worker_init, initargs=(os.getpid(),)
            ) as ex,
        ):
            futures = []

            def submit():
                i = pending.pop(0)
                off, ln, too_long = ranges[i]
                fut = (
                    None
                    if too_long
                    else ex.submit(
                        _parse_range_to_file,
                        folder,
                        i,
                        file,
                        off,
                        ln,
                        cfg.ignore_checksum,
                        at_eof[i],
                        max_line,
                    )
                )
                futures.append((fut, i))  # None: read here (a line too long: a few bytes)

            # the first block is parsed here while the workers start and take the next ones
            i0 = pending.pop(0)
            while pending and len(futures) < nworkers + 2:
                submit()
            yield from handle(local(i0), ranges[i0][1])
            while futures:
                fut, i = futures.pop(0)
                try:
                    pb = _load_parsed(fut.result()) if fut is not None and not broken else None
                except BrokenProcessPool:
                    broken = True
                    pb = None
                if pb is None:
                    pb = local(i)
                if pending and not broken:
                    try:
                        submit()
                    except BrokenProcessPool:
                        broken = True
                if broken and pending and not futures:
                    futures.append((None, pending.pop(0)))
                yield from handle(pb, ranges[i][1])
        if broken:
            st.stats["pool_fallback"] += 1
    yield from _release(st.timebase.finish())


def _fingerprint(cols: dict[str, np.ndarray], st: StreamState, pb_names: list[str]) -> None:
    """Split a talker whose position sentences come with different numbers of decimals
    of minutes (two receivers behind one talker, e.g. Hakefjord.txt): each decimal
    count seen in at least 10 % of that talker's positions (and >= 10 of them) in the
    file's first block becomes its own source key ``<talker>/<n>dp``."""
    names = np.array([bool(n) for n in pb_names]) if pb_names else np.zeros(1, bool)
    untagged = ~names[cols["tag_source"]] if pb_names else np.ones(len(cols["talker"]), bool)
    talker = cols["talker"]
    dec = cols["dec"]
    for tk in np.unique(talker[untagged]).tolist():
        sel = (talker == tk) & untagged & (dec >= 0)
        u, c = np.unique(dec[sel], return_counts=True)
        big = u[(c >= 10) & (c >= 0.1 * sel.sum())]
        if len(big) >= 2:
            st.split_talkers[_talker_str(tk)] = set(int(x) for x in u)


# ------------------------------------------------------------------------ file reader
def check_readable(path: Path) -> None:
    """Raise IngestError for a path that is not a readable file."""
    if not path.exists():
        raise IngestError(f"{path}: no such file")
    if path.is_dir():
        raise IngestError(f"{path}: is a directory, not a log file")
    mode = path.stat().st_mode
    if not stat.S_ISREG(mode):  # a FIFO would block on open; a device reads as size 0
        what = (
            "a FIFO (named pipe)"
            if stat.S_ISFIFO(mode)
            else "a socket"
            if stat.S_ISSOCK(mode)
            else "a device"
            if stat.S_ISCHR(mode) or stat.S_ISBLK(mode)
            else "not a regular file"
        )
        raise IngestError(f"{path}: is {what}, not a log file; save the log to a file first")
    try:
        with path.open("rb") as fh:
            fh.read(1)
    except OSError as err:
        raise IngestError(f"{path}: cannot read: {err.strerror or err}") from err


def read_nmea(
    path: str | Path, cfg: IngestConfig, progress=None, workers: int | None = None
) -> FileResult:
    """Read a whole NMEA 0183 text file into a :class:`FileResult` (frames sorted by time)."""
    path = Path(path)
    check_readable(path)
    st = StreamState(str(path))
    blocks = [b.frames for b in iter_nmea_blocks(path, cfg, st, progress=progress, workers=workers)]
    frames = concat_blocks(blocks)
    res = FileResult(
        path=str(path),
        format="nmea",
        frames=frames,
        lines=st.lines,
        rejects=st.rejects,
        time_events=st.time_events(),
        notes=st.notes(),
        ignored=st.ignored,
        ignored_examples=st.ignored_examples,
    )
    res.notes.extend(
        f"{k}: {v}" for k, v in st.events.per_source.items() if v["backsteps"] or v["gaps"]
    )
    return res


class SentenceStream:
    """Sentences that arrive with an external receive time and source key each (MCAP raw
    NMEA messages: topic as source key), parsed chunk by chunk as they come.

    :meth:`add` a chunk, then :meth:`finish`; each returns the frames of the chunks whose
    times are resolved by then (a dict kind -> frame per chunk, in order), and
    :meth:`result` gives the bookkeeping.  One time base and one set of event counters
    run through all chunks, so the frames are those of one parse over everything, while
    only one chunk of text is held at a time.  Time-of-fix fields are anchored to the
    date of the given time (rule 1 of :mod:`dracc.ingest.timebase`).  ``line`` counts
    sentences from 1 over all chunks, or is the given ``numbers`` (message numbers).
    """

    def __init__(self, file: str, cfg: IngestConfig):
        self.file, self.cfg = file, cfg
        self.st = StreamState(file)
        self.st.events.gap_s = cfg.gap_s
        self.st.events.tolerance_s = cfg.backstep_tolerance_s
        self._held: list = []

    def add(
        self,
        lines: Sequence[bytes],
        time_ns: np.ndarray,
        source: Sequence[str],
        numbers: np.ndarray | None = None,
        recv_ns: np.ndarray | None = None,
    ) -> list[dict[str, pd.DataFrame]]:
        """Parse one chunk.  ``time_ns``: each line's external time (the time base anchors
        its time of fix to it); ``recv_ns``: each line's receive time where it differs
        (an MCAP log time beside a message stamp), else ``time_ns`` is its receive time:
        the ``recv_ns`` of its records that have their own time of fix."""
        clean = [bytes(x).replace(b"\r", b"").replace(b"\n", b" ") for x in lines]
        t = np.asarray(time_ns, dtype=np.int64)
        src = np.asarray(list(source), dtype=object)
        if (
            not (len(t) == len(src) == len(clean))
            or (numbers is not None and len(numbers) != len(clean))
            or (recv_ns is not None and len(recv_ns) != len(clean))
        ):
            raise ValueError(
                f"SentenceStream: {len(clean)} lines, {len(t)} times, {len(src)} sources"
            )
        if not clean:
            return []
        pb = parse_buffer(
            b"\n".join(clean) + b"\n",
            ignore_checksum=self.cfg.ignore_checksum,
            at_eof=False,
            ext_line_ns=t,
            ext_line_source=src,
            max_line_bytes=int(getattr(self.cfg, "max_line_bytes", MAX_LINE_BYTES)),
        )
        nos = None if numbers is None else np.asarray(numbers, dtype=np.int64)
        st = self.st
        line0 = st.count_block(
            pb,
            self.cfg.strict,
            label="{path}: message {n}",
            number=None if nos is None else (lambda ln, first: int(nos[ln - 1])),
        )
        tod, date, ext, split = _time_arrays(pb)
        recv = (
            None
            if recv_ns is None
            else drop_implausible_ext(np.asarray(recv_ns, dtype=np.int64))[0]
        )
        self._held.append((pb, split, line0, nos, recv))
        return self._release(st.timebase.feed(tod, date, ext))

    def finish(self) -> list[dict[str, pd.DataFrame]]:
        """The frames of the chunks still held (call once, after the last :meth:`add`)."""
        return self._release(self.st.timebase.finish())

    def _release(self, done) -> list[dict[str, pd.DataFrame]]:
        out = []
        for t in done:
            pb, split, line0, nos, recv = self._held.pop(0)
            frames = _assemble(pb, split(t), self.st, self.file, line0, self.cfg)
            for f in frames.values():
                at = f["line"].to_numpy(np.int64) - line0  # the line of each record in the chunk
                if recv is not None:  # a record with a receive time gets the one given
                    has = f["recv_ns"].to_numpy() != MISSING_NS
                    f["recv_ns"] = np.where(has, recv[at], MISSING_NS)
                if nos is not None:
                    f["line"] = nos[at]
            out.append(frames)
        return out

    def result(self, frames: list[dict[str, pd.DataFrame]]) -> FileResult:
        """The :class:`FileResult` of ``frames`` (those returned, concatenated and sorted by
        time) with the counts, rejects, time events and notes of every chunk."""
        st = self.st
        return FileResult(
            path=self.file,
            format="nmea",
            frames=concat_blocks(frames),
            lines=st.lines,
            rejects=st.rejects,
            time_events=st.time_events(),
            notes=st.notes(),
            ignored=st.ignored,
            ignored_examples=st.ignored_examples,
        )


def parse_sentences(
    lines: Sequence[bytes], time_ns: np.ndarray, source: Sequence[str], file: str, cfg: IngestConfig
) -> FileResult:
    """:class:`SentenceStream` over one chunk: sentences with an external receive time
    and source key each, parsed at once."""
    stream = SentenceStream(file, cfg)
    frames = stream.add(lines, time_ns, source)
    return stream.result(frames + stream.finish())
