"""What a received line is, and its source key, from a cheap look at its bytes.

:func:`classify` is called by ``dracc watch`` for every line heard (tens of thousands a
second, one Python loop), so each test is a first-byte dispatch followed by at most one
anchored regular expression of the reader that reads the form:

* ``nmea0183``: ``$``, ``!`` or a TAG block ``\\...\\`` first (``$PCDIN`` and
  ``$MXPGN`` too: the NMEA reader decodes the NMEA 2000 inside them, TAG block or not);
* ``pdgy``: Digital Yacht iKonvert ``!PDGY,`` / ``$PDGY,``, bare (the NMEA reader
  does not decode them; the NMEA 2000 reader does, from a file of them);
* ``ydwg``: Yacht Devices RAW, ``hh:mm:ss.ddd R 09F80115 01 02 ..``;
* ``candump``: Linux candump, any of its three forms;
* ``plain``: canboat PLAIN or FAST, ``time,prio,pgn,src,dst,len,hex,..``;
* ``signalk_log``: a Signal K server data log line, ``<ms>;<letter>;<payload>``;
* ``signalk_delta``: a JSON object a line (a Signal K delta, or the server's hello);
* ``gpsd_json``: a gpsd report, ``{"class":...``;
* ``other``: anything else (``#`` comments, a logger's prefix, damaged lines).

:mod:`dracc.ingest.live.record` writes ``nmea0183`` and ``other`` lines to the ``.nmea``
recording and each other form to a file of its own.  Measured (one core, CPython 3.11):
a sentence 0.2 µs, a TAG-block line 1.2 µs, a YDWG, candump or canboat line 1.2-1.5 µs,
a Signal K delta 1.8 µs.

The patterns are those of the readers (:mod:`dracc.ingest.n2k.formats`,
:mod:`dracc.ingest.signalk`, :mod:`dracc.ingest.gpsd_json`), compiled for bytes, so a
line this module gives a form is one that form's reader takes; a file of one form's
lines is what its reader's sniffer recognises.

Source keys (what ``dracc watch`` counts a line under):

* NMEA 0183: the key dracc's NMEA reader gives it: the TAG block's ``s:`` where there
  is one, else the talker of ``$TTSSS`` (a proprietary ``$P...`` sentence: its address,
  ``PASHR``); :func:`line_key` also gives the TAG ``c:`` time (seconds up to 10 digits,
  else milliseconds, as :mod:`dracc.ingest.tagblock` reads it);
* NMEA 2000 (``pdgy``, ``ydwg``, ``candump``, ``plain``): ``n2k:addr<source address>``
  from the CAN identifier or the source field (the analysis later names sources by their
  address claims);
* a Signal K delta: ``signalk:<$source>``, else ``signalk:<source.label>.<src>``
  (``.<talker>``) as the delta reader keys it, found by a byte search; ``signalk`` where
  neither is there;
* a Signal K data log line: the key of its payload (``N`` NMEA 0183, ``A`` canboat
  PLAIN, ``I`` a delta), else ``signalk``;
* gpsd JSON: ``gpsd:<device>``, else ``gpsd``.
"""

from __future__ import annotations

from typing import NamedTuple

from dracc.ingest.gpsd_json import _CLASS_RE
from dracc.ingest.n2k.formats import CANDUMP as _CANDUMP_FORM
from dracc.ingest.n2k.formats import LINE_FORMS
from dracc.ingest.n2k.formats import YDRAW as _YDRAW_FORM
from dracc.ingest.signalk import _LINE_RE as _SIGNALK_LINE_RE

NMEA0183, OTHER, PDGY, YDWG, CANDUMP, PLAIN = (
    "nmea0183",
    "other",
    "pdgy",
    "ydwg",
    "candump",
    "plain",
)
SIGNALK_DELTA, SIGNALK_LOG, GPSD_JSON = "signalk_delta", "signalk_log", "gpsd_json"
#: every form :func:`classify` gives
FORMS = (NMEA0183, PDGY, YDWG, CANDUMP, PLAIN, SIGNALK_LOG, SIGNALK_DELTA, GPSD_JSON, OTHER)
#: the forms written to the NMEA 0183 recording (``.nmea``)
NMEA_FORMS = frozenset({NMEA0183, OTHER})

_PLAIN = LINE_FORMS["plain"]  # the forms' one home, as the file readers tell them
_YDRAW = LINE_FORMS[_YDRAW_FORM]
_CANDUMP = LINE_FORMS[_CANDUMP_FORM]
_NMEA_FIRST = frozenset({b"$", b"!", b"\\"})
_DIGITS = frozenset(b"0123456789")
_SPACE = b" \t"
_CANDUMP_FIRST = frozenset({b"(", b"<", b" ", b"\t"})


class LineInfo(NamedTuple):
    """What :func:`classify` says of a line."""

    form: str  #: one of :data:`FORMS`
    key: str | None  #: the source key (None: no sentence, nothing to count it under)
    c_ns: int | None  #: the TAG block's ``c:`` time in ns (NMEA 0183 only)


#: talkers whose LineInfo is kept (there are a few hundred real ones)
MAX_TALKERS = 4096
_TALKERS: dict[bytes, LineInfo] = {}
_new = tuple.__new__  # a LineInfo without the generated __new__'s frame (hot path)


def line_key(line: bytes) -> tuple[str | None, int | None]:
    """(source key, TAG ``c:`` time in ns or None) of an NMEA 0183 line; key None where
    the line is no sentence."""
    source = None
    c_ns = None
    if line[:1] == b"\\":
        end = line.find(b"\\", 1)
        if end < 0:
            return None, None
        star = line.rfind(b"*", 1, end)
        for p in line[1 : star if star > 0 else end].split(b","):
            if p[:2] == b"s:" and len(p) > 2:
                source = p[2:].decode("ascii", "replace")
            elif p[:2] == b"c:":
                v = p[2:]
                if v.isdigit():  # the usual whole seconds or milliseconds, exactly
                    n = int(v)
                    c_ns = n * 1_000_000_000 if n < 10_000_000_000 else n * 1_000_000
                else:
                    t = _tag_time(v)
                    c_ns = c_ns if t is None else t
        line = line[end + 1 :]
    if source is None:
        if line[:1] not in (b"$", b"!") or len(line) < 6:
            return None, c_ns
        if line[1:2] == b"P":
            comma = line.find(b",")
            source = line[1 : comma if comma > 0 else 6].decode("ascii", "replace")
        else:
            source = line[1:3].decode("ascii", "replace")
    return source, c_ns


def _tag_time(text: bytes) -> int | None:
    """A TAG ``c:`` value that is not a whole number (``1772344800.25``) in ns: seconds
    below 1e10, else milliseconds; None for no finite number."""
    try:
        f = float(text)
    except ValueError:
        return None
    if f != f or abs(f) == float("inf"):
        return None
    return int(f * 1e9) if f < 1e10 else int(f * 1e6)


def classify(line: bytes) -> LineInfo:
    """The form, source key and TAG ``c:`` time of a received line (without its line
    end); see the module docstring."""
    c = line[:1]
    if (c == b"$" or c == b"!") and len(line) >= 6:
        if line[1:2] != b"P":
            talker = line[1:3]
        else:  # proprietary: its address (``PASHR``) is the key
            comma = line.find(b",")
            talker = line[1 : comma if comma > 0 else 6]
            if talker == b"PDGY":
                return _new(LineInfo, (PDGY, _field_addr(line, 3), None))
        info = _TALKERS.get(talker)  # a sentence of a talker: one LineInfo each
        return info if info is not None else _talker(talker)
    if c == b"\\" or c in _NMEA_FIRST:
        key, c_ns = line_key(line)
        return _new(LineInfo, (NMEA0183, key, c_ns))
    if c == b"{":
        if _CLASS_RE.match(line):
            dev = _json_text(line, b'"device"', 0, len(line))
            return _new(LineInfo, (GPSD_JSON, f"gpsd:{dev}" if dev else "gpsd", None))
        return _new(LineInfo, (SIGNALK_DELTA, delta_key(line), None))
    if c and c[0] in _DIGITS:
        if line[2:3] == b":":
            if _YDRAW.match(line):
                return _new(LineInfo, (YDWG, _hex_addr(line.split(None, 3)[2]), None))
        elif line.find(b";", 10, 14) >= 10 and _SIGNALK_LINE_RE.match(line):
            return _new(LineInfo, (SIGNALK_LOG, _signalk_log_key(line), None))
    return _n2k_text(line)


def _talker(talker: bytes) -> LineInfo:
    """The LineInfo of a sentence of ``talker`` (or proprietary address; kept for the next, up to
    :data:`MAX_TALKERS`: garbage does not grow it without bound)."""
    info = _new(LineInfo, (NMEA0183, talker.decode("ascii", "replace"), None))
    if len(_TALKERS) < MAX_TALKERS:
        _TALKERS[talker] = info
    return info


def _n2k_text(line: bytes) -> LineInfo:
    """A canboat PLAIN/FAST or candump line, or ``other`` (the likelier form tried
    first: a PLAIN line starts with its time, a candump line mostly with ``(``)."""
    if line[:1] in _CANDUMP_FIRST and _CANDUMP.match(line):
        return _new(LineInfo, (CANDUMP, _candump_addr(line), None))
    if _PLAIN.match(line):
        return _new(LineInfo, (PLAIN, _field_addr(line, 3), None))
    if _CANDUMP.match(line):
        return _new(LineInfo, (CANDUMP, _candump_addr(line), None))
    return _new(LineInfo, (OTHER, None, None))


def _addr(value: int) -> str:
    return f"n2k:addr{value}"


def _field_addr(line: bytes, i: int) -> str | None:
    """``n2k:addr<field i>`` of a comma-separated line (decimal), None if it is none."""
    parts = line.split(b",", i + 1)
    if len(parts) > i and parts[i].isdigit():
        return _addr(int(parts[i]))
    return None


def _hex_addr(can_id: bytes) -> str | None:
    """``n2k:addr<source>`` of a hexadecimal CAN identifier (its low byte)."""
    try:
        return _addr(int(can_id, 16) & 0xFF)
    except ValueError:
        return None


def _candump_addr(line: bytes) -> str | None:
    """The source address of a candump line in any of its three forms."""
    s = line.strip()
    if s[:3] == b"<0x":  # <0x18eeff01> [8] ...
        return _hex_addr(s[3 : s.find(b">")])
    h = s.find(b"#")
    if h > 0:  # (1502984866.421964) slcan0 09F112CC#FF725AFF7FFF7FFD
        return _hex_addr(s[s.rfind(b" ", 0, h) + 1 : h])
    b = s.find(b"[")  # [(time)] can0  09F20101   [8]  60 1A ...
    words = s[:b].split() if b > 0 else []
    return _hex_addr(words[-1]) if words else None


def _signalk_log_key(line: bytes) -> str:
    """The source key of a Signal K data log line: that of its payload."""
    semi = line.find(b";")
    letter, payload = line[semi + 1 : semi + 2], line[semi + 3 :]
    if letter == b"I":
        return delta_key(payload)
    info = classify(payload)
    if info.key is None or (letter == b"A") != (info.form == PLAIN):
        return "signalk"
    return info.key


def _json_text(line: bytes, name: bytes, lo: int, hi: int) -> str | None:
    """The value of the first ``"name": <string or number>`` in ``line[lo:hi]`` found by
    a byte search (no JSON parse); None where there is none or it has an escape."""
    i = line.find(name, lo, hi)
    if i < 0:
        return None
    j = i + len(name)
    while line[j : j + 1] in _SPACE:
        j += 1
    if line[j : j + 1] != b":":
        return None
    j += 1
    while line[j : j + 1] in _SPACE:
        j += 1
    if line[j : j + 1] == b'"':
        e = line.find(b'"', j + 1, hi)
        value = line[j + 1 : e]
        if e < 0 or b"\\" in value:
            return None
    else:
        e = j
        while e < hi and line[e] in _DIGITS:
            e += 1
        value = line[j:e]
    return value.decode("utf-8", "replace") if value else None


def delta_key(line: bytes) -> str:
    """``signalk:<source>`` of a Signal K delta line (its first update's ``$source``,
    else ``source.label`` and ``.src`` / ``.talker``), ``signalk`` without either."""
    n = len(line)
    src = _json_text(line, b'"$source"', 0, n)
    if src:
        return f"signalk:{src}"
    i = line.find(b'"label"')
    label = _json_text(line, b'"label"', i, n) if i >= 0 else None
    if not label:
        return "signalk"
    lo = line.rfind(b"{", 0, i)  # the source object around the label
    hi = line.find(b"}", i)
    hi = n if hi < 0 else hi
    sub = _json_text(line, b'"src"', lo, hi) or _json_text(line, b'"talker"', lo, hi)
    return f"signalk:{label}.{sub}" if sub else f"signalk:{label}"
