"""NMEA 2000 lines in a text log read by the NMEA 0183 reader: ``$PCDIN`` (SeaSmart),
``$MXPGN`` (Shipmodul MiniPlex) and ``!PDGY`` (iKonvert) sentences among the others, and
whole lines of another form (candump, Yacht Devices RAW, canboat's plain form) mixed in.

The reader of a log is chosen by its first lines (:func:`dracc.ingest.detect_format`);
every line then goes to the reader of its own form.  The NMEA reader counts the lines
that are not NMEA 0183 as ignored (``PCDIN``, ``PGN``, ``PDGY``) or rejected
(``not_nmea``); where it did, the log is read once more, piece by piece as the NMEA
reader cuts it (:func:`~dracc.ingest.nmea.blocks.stream_pieces`), every line's form told
(:func:`~dracc.ingest.n2k.formats.line_forms`, one regular expression pass per form and
piece), the lines of each NMEA 2000 form decoded by :mod:`dracc.ingest.n2k` and what the
NMEA reader had said of them taken off its counts (those lines parsed by it once more,
so exactly what it said).  A log of NMEA 2000 lines whose first lines are of one form
and later ones of another is read this way too (:class:`MixedForms`).

Time: NMEA 2000 inside NMEA 0183 takes the time of the preceding timed record of the log
(the next one for leading messages: rule 3 of :mod:`dracc.ingest.timebase`), as a
sentence without a time field of its own does; where the log has no timed record, its
own time as the NMEA 2000 reader resolves it.  Whole lines of another form keep their
own times (a candump's, a YDWG's time of day), their time events counted.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import IO, TYPE_CHECKING

import numpy as np
import pandas as pd

from dracc.frames import FileResult, Rejects
from dracc.ingest.demux import check_strict, merge_results
from dracc.ingest.n2k.formats import (
    FORM_CODES,
    MXPGN,
    PCDIN,
    PDGY,
    MixedForms,
    line_forms,
    parse_n2k_numbered,
    plain_kind,
)
from dracc.ingest.n2k.messages import TIME_UTC, Messages, concat_messages
from dracc.ingest.n2k.reader import n2k_result
from dracc.ingest.n2k.textscan import pack_lines
from dracc.ingest.nmea.blocks import stream_pieces
from dracc.ingest.nmea.engine_c import parse_buffer
from dracc.ingest.nmea.lines import line_spans
from dracc.ingest.nmea.parsed import ParsedBlock
from dracc.ingest.timebase import count_events

if TYPE_CHECKING:
    from dracc.core.config import IngestConfig

#: what the NMEA reader says of NMEA 2000 lines: ignored under these names (NMEA 2000 in
#: NMEA 0183) or rejected for this reason (other forms)
IGNORED_KEYS = ("PCDIN", "PGN", "PDGY")
REJECT_REASON = "not_nmea"
#: the forms carried inside NMEA 0183 sentences: timed by the log's records (rule 3)
EMBEDDED_FORMS = (PCDIN, MXPGN, PDGY)
#: how each form is named in the note
FORM_NAMES = {
    PCDIN: "$PCDIN",
    MXPGN: "$MXPGN",
    PDGY: "!PDGY",
    "n2k-ydraw": "YDWG RAW",
    "n2k-candump": "candump",
    "plain": "canboat plain",
}
PIECE_BYTES = 8 * 1024 * 1024  #: bytes of the log looked at at a time
Opener = Callable[[], IO[bytes]]
__all__ = ["MixedForms", "add_n2k_lines", "read_text_log", "take_n2k_lines", "take_off"]


def opener_of(path: str | Path) -> Opener:
    """What opens the plain file ``path`` (an :data:`Opener`)."""

    def open_it() -> IO[bytes]:
        return Path(path).open("rb")  # the caller closes it (a with block)

    return open_it


def may_hold_n2k(ignored: Counter[str], rejected: Counter[str]) -> bool:
    """Whether the NMEA reader's counts show lines that may be NMEA 2000 ones."""
    return any(ignored.get(k) for k in IGNORED_KEYS) or bool(rejected.get(REJECT_REASON))


@dataclass
class Taken:
    """The NMEA 2000 lines of a log: decoded (``result``: frames, ignored PGNs, their own
    rejects, notes), how many of each form, their line numbers, and what the NMEA reader
    had said of them (``said``: its parse of those lines alone)."""

    result: FileResult
    forms: Counter[str]
    numbers: np.ndarray
    said: ParsedBlock

    @property
    def lines(self) -> int:
        return sum(self.forms.values())


@dataclass
class _Found:
    """Per form: the lines (from their record's start, one a line) and their numbers."""

    blobs: dict[int, list[bytes]] = field(default_factory=dict)
    numbers: dict[int, list[np.ndarray]] = field(default_factory=dict)
    whole: list[bytes] = field(default_factory=list)  #: the lines whole, for the NMEA reader


def _scan(opener: Opener, max_line: int) -> _Found:
    """The lines of NMEA 2000 forms of the log ``opener`` opens, numbered as the NMEA
    reader numbers its lines."""
    found = _Found()
    line0 = 0
    with opener() as fh:
        for piece in stream_pieces(fh.read, PIECE_BYTES, PIECE_BYTES, max_line):
            if piece.long is not None:  # one line too long for any reader
                line0 += 1
                continue
            buf = np.frombuffer(piece.data, dtype=np.uint8)
            start, end, _ = line_spans(buf, np.concatenate((buf, np.zeros(3, np.uint8))))
            code, at = line_forms(piece.data, start, end, max_line)
            take = code >= 2  # 0: none of them, 1: an NMEA 0183 sentence
            for c in np.unique(code[take]).tolist():
                rows = np.flatnonzero(code == c)
                found.blobs.setdefault(c, []).append(pack_lines(buf, at[rows], end[rows])[0])
                found.numbers.setdefault(c, []).append(rows + 1 + line0)
            if take.any():
                found.whole.append(pack_lines(buf, start[take], end[take])[0])
            line0 += len(start)
    return found


def take_n2k_lines(
    opener: Opener,
    file: str,
    cfg: IngestConfig,
    line_times: Callable[[], tuple[np.ndarray, np.ndarray]],
) -> Taken | None:
    """The NMEA 2000 lines of the log ``opener`` opens (named ``file``), decoded; None
    where it has none.  ``line_times()``: the line numbers and times of the log's
    records in line order (:func:`record_times`), asked for only where NMEA 2000 inside
    NMEA 0183 needs them."""
    found = _scan(opener, int(cfg.max_line_bytes))
    if not found.blobs:
        return None
    embedded: list[tuple[str, Messages]] = []
    own: list[tuple[str, Messages]] = []
    forms: Counter[str] = Counter()
    all_numbers = []
    for c, blobs in sorted(found.blobs.items()):
        numbers = np.concatenate(found.numbers[c])
        data = b"".join(blobs)
        form = FORM_CODES[c]
        assert form is not None
        forms[form] = len(numbers)
        fmt = plain_kind(data[:65536].splitlines()) if form == "plain" else form
        msgs = parse_n2k_numbered(data, numbers, fmt)
        (embedded if form in EMBEDDED_FORMS else own).append((fmt, msgs))
        all_numbers.append(numbers)
    parts = []
    if embedded:
        msgs = concat_messages([m for _, m in embedded])
        lines, times = line_times()
        if len(lines):
            msgs = _rule3(msgs, lines, times)
        fmt = embedded[0][0] if len(embedded) == 1 else "n2k-embedded"
        parts.append(n2k_result(msgs, file, fmt, cfg, lines=0))
    for fmt, msgs in own:
        r = n2k_result(msgs, file, fmt, cfg, lines=0)
        count_events(r, cfg.gap_s, cfg.backstep_tolerance_s)
        parts.append(r)
    said = parse_buffer(
        b"".join(found.whole),
        ignore_checksum=cfg.ignore_checksum,
        max_line_bytes=int(cfg.max_line_bytes),
    )
    result = merge_results(file, parts[0].format, 0, parts, [_note(forms)])
    return Taken(result, forms, np.sort(np.concatenate(all_numbers)), said)


def _note(forms: Counter[str]) -> str:
    """What the note says of the NMEA 2000 lines read."""
    each = ", ".join(f"{n:,} {FORM_NAMES.get(f, f)}" for f, n in sorted(forms.items()))
    return (
        f"{sum(forms.values()):,} NMEA 2000 lines among the others read by their own form: {each}"
    )


def record_times(frames: list[dict[str, pd.DataFrame]]) -> tuple[np.ndarray, np.ndarray]:
    """(line, time) of the records of ``frames`` (kind -> frame: a file's, or each of its
    blocks'), in line order."""
    parts = [
        (f["line"].to_numpy(), f["time_ns"].to_numpy())
        for fr in frames
        for f in fr.values()
        if len(f)
    ]
    if not parts:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    line = np.concatenate([p[0] for p in parts])
    t = np.concatenate([p[1] for p in parts])
    order = np.argsort(line, kind="stable")
    return line[order], t[order]


def _rule3(msgs: Messages, line: np.ndarray, t: np.ndarray) -> Messages:
    """``msgs`` with the time of the preceding timed record of the log (rule 3)."""
    i = np.searchsorted(line, msgs.line, side="right") - 1
    msgs.time_ns = t[np.maximum(i, 0)].astype(np.int64)
    msgs.time_kind = TIME_UTC
    return msgs


def take_off(
    taken: Taken,
    rejects: Rejects,
    ignored: Counter[str],
    ignored_examples: dict[str, list[tuple[str, int, str]]],
) -> None:
    """Take what the NMEA reader said of the NMEA 2000 lines (``taken.said``) off its
    counts and examples."""
    said = taken.said
    nums = taken.numbers

    def keep(rows: list[tuple[str, int, str]]) -> list[tuple[str, int, str]]:
        ln = np.array([r[1] for r in rows], dtype=np.int64)
        at = np.minimum(np.searchsorted(nums, ln), len(nums) - 1)
        return [r for r, hit in zip(rows, nums[at] == ln, strict=True) if not hit]

    for reason, n in said.reject_counts.items():
        rejects.counts[reason] -= n
        if rejects.counts[reason] <= 0:
            del rejects.counts[reason]
            rejects.examples.pop(reason, None)
        elif reason in rejects.examples:
            rejects.examples[reason] = keep(rejects.examples[reason])
    for key, n in said.ignored.items():
        ignored[key] -= n
        if ignored[key] <= 0:
            del ignored[key]
            ignored_examples.pop(key, None)
        elif key in ignored_examples:
            ignored_examples[key] = keep(ignored_examples[key])


def add_n2k_lines(r: FileResult, cfg: IngestConfig, opener: Opener) -> FileResult:
    """``r`` (the NMEA reader's result of the log ``opener`` opens) with the log's NMEA
    2000 lines decoded and merged in, what it had said of them taken off."""
    if not may_hold_n2k(r.ignored, r.rejects.counts):
        return r
    taken = take_n2k_lines(opener, r.path, cfg, lambda: record_times([r.frames]))
    if taken is None:
        return r
    take_off(taken, r.rejects, r.ignored, r.ignored_examples)
    fmt = text_format(r.format, r.records, taken)
    return merge_results(r.path, fmt, r.lines, [r, taken.result], [])


def text_format(nmea_format: str, nmea_records: int, taken: Taken) -> str:
    """The format of a text log whose NMEA 2000 lines were ``taken``: the NMEA reader's
    where its own lines gave records, else the one NMEA 2000 form, or ``n2k-mixed``."""
    if nmea_records or not taken.result.records:
        return nmea_format
    return taken.result.format if len(taken.forms) == 1 else "n2k-mixed"


def read_n2k_alone(
    path: str | Path, cfg: IngestConfig, progress: Callable[[int], object] | None = None
) -> FileResult | None:
    """The NMEA 2000 reader's result of a log of NMEA 2000 lines; None where it holds lines
    of other forms too (:class:`MixedForms`): it is then read by :func:`read_text_log`."""
    from dracc.ingest.n2k import read_n2k

    try:
        return read_n2k(path, cfg, progress)
    except MixedForms:
        return None


def read_text_log(
    path: str | Path,
    cfg: IngestConfig,
    progress: Callable[[int], object] | None = None,
    opener: Opener | None = None,
    size_hint: int | None = None,
) -> FileResult:
    """A text log read line by line: its NMEA 0183 lines by the NMEA reader, its NMEA
    2000 lines by their forms' (:func:`add_n2k_lines`).  ``opener``: the log is the
    stream it opens (a compressed log, ``size_hint`` its guessed size), ``path`` naming
    it.  ``--strict`` judges the lines once every line went to its reader."""
    from dracc.ingest.nmea import read_nmea

    loose = replace(cfg, strict=False) if cfg.strict else cfg
    r = read_nmea(path, loose, progress, opener=opener, size_hint=size_hint)
    r = add_n2k_lines(r, loose, opener or opener_of(path))
    check_strict(r, cfg)
    return r
