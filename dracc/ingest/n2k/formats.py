"""Which NMEA 2000 log format a file is, and reading any of them into :class:`Messages`.

Formats (names as :func:`sniff_n2k` gives them and :func:`parse_n2k` takes them):

=====================  ===========================================================
``n2k-plain``          canboat PLAIN, a CAN frame a line (fast packets reassembled)
``n2k-fast``           canboat FAST, a whole message a line
``n2k-plain-mix-fast`` canboat PLAIN_MIX_FAST: fast PGNs as frames and whole lines
``n2k-candump``        Linux candump, any of its three forms
``n2k-ydraw``          Yacht Devices RAW (time of day only)
``n2k-pdgy``           Digital Yacht iKonvert ``!PDGY``
``n2k-ebl``            Actisense EBL binary
``n2k-ngt1``           Actisense NGT-1 binary stream (BST over DLE framing; YDNU-02 ``.dle``)
``n2k-garmin-csv1``    Garmin chartplotter CSV, the plotter's ms counter (canboat GARMIN_CSV1)
``n2k-garmin-csv2``    Garmin chartplotter CSV with its clock (canboat GARMIN_CSV2)
``n2k-pcdin``          ``$PCDIN`` sentences
``n2k-mxpgn``          ``$MXPGN`` sentences
=====================  ===========================================================

canboat's own ``# format=NAME`` header line, where a log has one, decides between the
three canboat forms; otherwise a log with whole-message lines is FAST unless some
8-byte lines of fast-packet PGNs are visibly frames (frame 0 followed by frame 1 of
the same sequence), which makes it PLAIN_MIX_FAST.
"""

from __future__ import annotations

import re
from collections import Counter

import numpy as np

from dracc.core.errors import IngestError
from dracc.ingest.n2k.canframes import parse_candump, parse_ydraw
from dracc.ingest.n2k.ebl import parse_ebl, parse_ngt1
from dracc.ingest.n2k.encapsulated import parse_mxpgn, parse_pcdin, parse_pdgy
from dracc.ingest.n2k.fastpacket import is_fast_pgn
from dracc.ingest.n2k.garmin import garmin_form, parse_garmin_csv
from dracc.ingest.n2k.messages import Messages
from dracc.ingest.n2k.plain import parse_plain
from dracc.ingest.n2k.textscan import PAD, Lines, join_lines, pack_lines, split_lines

PLAIN, FAST, MIX = "n2k-plain", "n2k-fast", "n2k-plain-mix-fast"
CANDUMP, YDRAW, PDGY, EBL = "n2k-candump", "n2k-ydraw", "n2k-pdgy", "n2k-ebl"
PCDIN, MXPGN, NGT1 = "n2k-pcdin", "n2k-mxpgn", "n2k-ngt1"
GARMIN1, GARMIN2 = "n2k-garmin-csv1", "n2k-garmin-csv2"
FORMATS = (PLAIN, FAST, MIX, CANDUMP, YDRAW, PDGY, EBL, NGT1, PCDIN, MXPGN, GARMIN1, GARMIN2)
_GARMIN = {"csv1": GARMIN1, "csv2": GARMIN2}
#: how much of a file :func:`sniff_n2k` looks at
SNIFF_BYTES = 65536
#: lines of the head classified
SNIFF_LINES = 400

_HEADER_FORMATS = {"PLAIN": PLAIN, "FAST": FAST, "PLAIN_OR_FAST": PLAIN, "PLAIN_MIX_FAST": MIX}
#: one line of each line-based form dracc tells apart line by line (bytes, matched at a
#: line's start; ``re.M`` over a buffer whose CR bytes are made LF: no pattern crosses a
#: line end).  :func:`sniff_n2k` votes with them on a log's first lines and
#: :func:`line_forms` gives every line of a mixed log its form: one home for both.
LINE_FORMS: dict[str, re.Pattern[bytes]] = {
    "plain": re.compile(
        rb"^[^,\n]{1,40},[0-7],\d{1,7},\d{1,3},\d{1,3},(\d{1,4})((?:,[0-9a-fA-F]{1,2})*)[ \t]*$",
        re.M,
    ),
    YDRAW: re.compile(
        rb"^\d{2}:\d{2}:\d{2}\.\d+ [RT] [0-9A-Fa-f]{8}(?: [0-9A-Fa-f]{2}){0,8}[ \t]*$", re.M
    ),
    CANDUMP: re.compile(
        rb"^[ \t]*(?:\(\d+\.\d+\)[ \t]+[^ \t\n]+[ \t]+[0-9A-Fa-f]{3,8}#"
        rb"|(?:\(\d+\.\d+\)[ \t]+)?[^ \t\n]+[ \t]+[0-9A-Fa-f]{3,8}[ \t]+\[\d\]"
        rb"|<0x[0-9A-Fa-f]{1,8}>[ \t]+\[\d\])",
        re.M,
    ),
}
#: NMEA 2000 in NMEA 0183 framing anywhere on a line (after a TAG block or a prefix):
#: group 1 from its ``$``/``!`` to its address (``$PCDIN``, ``$MXPGN``, ``!PDGY``)
EMBEDDED = re.compile(rb"^[^\n]*?(\$PCDIN|\$MXPGN|[!$]PDGY),", re.M)
_EMBEDDED_FORMS = {b"PCDIN": PCDIN, b"MXPGN": MXPGN, b"PDGY": PDGY}
#: an NMEA 0183 sentence (or AIS) anywhere in a text: what the NMEA reader takes
ANY_SENTENCE = re.compile(rb"[$!][A-Z0-9]{2}[A-Z0-9]{2,4},")


def sniff_n2k(head: bytes) -> str | None:
    """The N2K format of a log whose first bytes are ``head`` (up to 64 KiB are read),
    or None if it is none (an NMEA 0183 log with a few ``$PCDIN`` lines is none)."""
    head = head[:SNIFF_BYTES]
    # an EBL file begins with a logger record, and its records end ESC LF before a
    # frame's DLE STX (a bare stream has DLE ETX there)
    if head.startswith(b"\x1b\x01") or head.count(b"\x1b\x0a\x10\x02") >= 2:
        return EBL
    if (
        head.count(b"\x10\x02\x93") + head.count(b"\x10\x02\x94") >= 2
        and sum(b < 9 or 13 < b < 32 for b in head[:2048]) > len(head[:2048]) // 20
    ):
        return NGT1
    text = head.decode("latin-1")
    lines = re.split(r"\r\n|\r|\n", text)
    if len(head) == SNIFF_BYTES and len(lines) > 1:
        lines = lines[:-1]  # maybe cut short
    votes: Counter[str] = Counter()
    plain_rows: list[tuple[int, int, str, int]] = []
    total = 0
    for line in lines:
        s = line.strip()
        if not s:
            continue
        if total == 0 and (form := garmin_form(s)) is not None:
            return _GARMIN[form]
        if s.startswith("#"):
            m = re.match(r"#\s*format=(\w+)", s)
            if m and m.group(1).upper() in _HEADER_FORMATS:
                return _HEADER_FORMATS[m.group(1).upper()]
            continue
        total += 1
        if total > SNIFF_LINES:
            break
        raw = line.encode("latin-1")
        pm = LINE_FORMS["plain"].match(raw)
        if pm:
            votes["plain"] += 1
            fields = line.split(",")
            b0 = int(fields[6], 16) if len(fields) > 6 else -1
            plain_rows.append((int(fields[2]), int(pm.group(1)), fields[3], b0))
        elif (form := _line_form(raw)) is not None:
            votes[form] += 1
    if not votes:
        return None
    best, n = votes.most_common(1)[0]
    if 2 * n <= min(total, SNIFF_LINES):
        return None
    if best != "plain":
        return best
    return _plain_kind(plain_rows)


def _line_form(line: bytes) -> str | None:
    """The form of one line other than canboat's plain one (YDWG RAW, NMEA 2000 in NMEA
    0183, candump), None for none of them."""
    if LINE_FORMS[YDRAW].match(line):
        return YDRAW
    m = EMBEDDED.match(line)
    if m:
        return _EMBEDDED_FORMS[m.group(1)[1:]]
    return CANDUMP if LINE_FORMS[CANDUMP].match(line) else None


#: the line forms :func:`line_forms` tells apart, by code (0: none of them); ``plain``
#: is canboat's PLAIN, FAST or PLAIN_MIX_FAST (:func:`plain_kind` says which)
FORM_CODES: tuple[str | None, ...] = (None, "sentence", PCDIN, MXPGN, PDGY, YDRAW, CANDUMP, "plain")
_CODE = {f: i for i, f in enumerate(FORM_CODES)}
#: the forms told line by line (the others are binary, or a CSV with a header)
_TEXT_FORMS = (PLAIN, FAST, MIX, CANDUMP, YDRAW, PDGY, PCDIN, MXPGN)


def line_forms(
    data: bytes, start: np.ndarray, end: np.ndarray, max_line_bytes: int
) -> tuple[np.ndarray, np.ndarray]:
    """The form of every line of ``data`` (lines from ``start`` to ``end``, as the NMEA
    reader cuts them): codes into :data:`FORM_CODES`, and where each line's record starts
    (the ``$``/``!`` of NMEA 2000 in NMEA 0183, the line's start otherwise).  Vectorised:
    NMEA 2000 in NMEA 0183 found by its address (``bytes.find``), a ``sentence`` by a
    ``$`` or ``!`` anywhere on the line (none of the other forms holds one), and the
    remaining lines packed together for one pass of each form's pattern
    (:data:`LINE_FORMS`): a log of NMEA 0183 costs a few passes of numpy.  A line longer
    than ``max_line_bytes`` (too long for any reader) has no form."""
    code = np.zeros(len(start), dtype=np.int8)
    at = start.copy()
    if not len(start):
        return code, at
    short = (end - start) <= max_line_bytes
    pos, form = _embedded_at(data)
    if len(pos):  # the first on its line (of a line longer than the lines around)
        i = np.searchsorted(start, pos, side="right") - 1
        ok = (pos < end[i]) & short[i]
        i, pos, form = i[ok], pos[ok], form[ok]
        _, first = np.unique(i, return_index=True)
        code[i[first]], at[i[first]] = form[first], pos[first]
    buf = np.frombuffer(data, dtype=np.uint8)
    marks = np.flatnonzero((buf == 36) | (buf == 33))  # '$', '!': a sentence's start
    has_mark = np.searchsorted(marks, end) > np.searchsorted(marks, start)
    code[(code == 0) & short & has_mark] = 1  # a line too long has no form (it is cut)
    rest = np.flatnonzero((code == 0) & short & (end > start))
    if len(rest):
        packed, offs = pack_lines(buf, start[rest], end[rest])
        for name in (YDRAW, CANDUMP, "plain"):
            hit = np.fromiter((m.start() for m in LINE_FORMS[name].finditer(packed)), np.int64)
            j = np.minimum(np.searchsorted(offs, hit), len(offs) - 1)
            rows = rest[j[offs[j] == hit]]
            code[rows[code[rows] == 0]] = _CODE[name]
    return code, at


def _embedded_at(data: bytes) -> tuple[np.ndarray, np.ndarray]:
    """Where NMEA 2000 sentences inside NMEA 0183 start in ``data`` (their ``$``/``!``),
    in order, and their form codes."""
    pos: list[int] = []
    form: list[int] = []
    for name, fmt in _EMBEDDED_FORMS.items():
        key, lead = name + b",", b"$!" if name == b"PDGY" else b"$"
        k = data.find(key, 1)
        while k >= 0:
            if data[k - 1] in lead:
                pos.append(k - 1)
                form.append(_CODE[fmt])
            k = data.find(key, k + 1)
    order = np.argsort(np.array(pos, dtype=np.int64), kind="stable")
    return np.array(pos, dtype=np.int64)[order], np.array(form, dtype=np.int8)[order]


class MixedForms(IngestError):
    """A log of NMEA 2000 lines holding lines of another form than its first ones (raised
    by :func:`dracc.ingest.n2k.read_n2k` before it decodes anything): it is read line by
    line (:func:`dracc.ingest.embedded_n2k.read_text_log`)."""


def check_one_form(data: bytes, fmt: str, max_line_bytes: int) -> None:
    """Raise :class:`MixedForms` where the text log ``data``, sniffed as ``fmt``, holds
    lines of another form (an NMEA 0183 sentence, another NMEA 2000 form)."""
    if fmt not in _TEXT_FORMS:
        return
    lines = split_lines(data)
    code, _ = line_forms(data, lines.start - PAD, lines.end - PAD, max_line_bytes)
    own = _CODE["plain" if fmt in (PLAIN, FAST, MIX) else fmt]
    other = (code != 0) & (code != own)
    if other.any():
        forms = sorted({str(FORM_CODES[c]) for c in np.unique(code[other]).tolist()})
        raise MixedForms(f"{fmt} log with lines of other forms ({', '.join(forms)})")


def plain_kind(lines: list[bytes]) -> str:
    """PLAIN, FAST or MIX for canboat plain lines (as :func:`sniff_n2k` tells them)."""
    return sniff_n2k(b"\n".join(lines[:SNIFF_LINES])) or PLAIN


def _plain_kind(rows: list[tuple[int, int, str, int]]) -> str:
    """PLAIN, FAST or MIX from (pgn, length, src, byte 0) of plain lines."""
    if not any(n > 8 for _, n, _, _ in rows):
        return PLAIN
    last: dict[tuple[int, str], int] = {}
    for pgn, n, src, b0 in rows:
        if n > 8 or b0 < 0 or not is_fast_pgn(pgn):
            continue
        prev = last.get((pgn, src))
        if prev is not None and prev & 0x1F == 0 and b0 == prev + 1:
            return MIX
        last[(pgn, src)] = b0
    return FAST


def _parse_lines(lines: Lines, fmt: str) -> Messages:
    if fmt in (PLAIN, MIX):
        return parse_plain(lines, reassemble=True)
    if fmt == FAST:
        return parse_plain(lines, reassemble=False)
    if fmt == CANDUMP:
        return parse_candump(lines)
    if fmt == YDRAW:
        return parse_ydraw(lines)
    if fmt == PDGY:
        return parse_pdgy(lines)
    if fmt == PCDIN:
        return parse_pcdin(lines)
    if fmt == MXPGN:
        return parse_mxpgn(lines)
    if fmt in (GARMIN1, GARMIN2):
        return parse_garmin_csv(lines, "csv1" if fmt == GARMIN1 else "csv2")
    raise ValueError(f"not a line-based N2K format: {fmt!r} (one of {', '.join(FORMATS)})")


def parse_n2k(data: bytes, fmt: str, first_line: int = 1) -> Messages:
    """The messages of a whole log ``data`` in format ``fmt`` (line numbers count from
    ``first_line``; for EBL ``line`` is the record number). Bad lines are counted in
    ``Messages.rejects``, never raised."""
    if fmt == EBL:
        return parse_ebl(data)
    if fmt == NGT1:
        return parse_ngt1(data)
    return _parse_lines(split_lines(data, first_line), fmt)


def parse_n2k_lines(lines: list[bytes], line_numbers: np.ndarray, fmt: str) -> Messages:
    """The messages of ``lines`` (each one log line, e.g. the PLAIN part of Signal K
    ``A`` lines) whose line numbers in their file are ``line_numbers``."""
    if len(lines) != len(line_numbers):
        raise ValueError("one line number per line")
    return _parse_lines(join_lines(lines, line_numbers), fmt)


def parse_n2k_numbered(data: bytes, numbers: np.ndarray, fmt: str) -> Messages:
    """The messages of ``data``, lines of one form cut from a log (one a line, none blank),
    whose line numbers in that log are ``numbers``."""
    lines = split_lines(data)
    lines.number = np.asarray(numbers, dtype=np.int64)[lines.number - 1]
    return _parse_lines(lines, fmt)
