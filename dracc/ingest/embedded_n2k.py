"""NMEA 2000 messages carried inside an NMEA 0183 log: ``$PCDIN`` (SeaSmart) and
``$MXPGN`` (Shipmodul MiniPlex) lines among the sentences.

The NMEA reader counts such lines as ignored (``PCDIN``, ``PGN``); where it did, they
are found again in the file, decoded by :mod:`dracc.ingest.n2k` and merged into the
log's result.  A message takes the time of the preceding timed record of the log (the
next one for leading messages: rule 3 of :mod:`dracc.ingest.timebase`), as a sentence
without a time field of its own does; where the log has no timed record, its own time
(``$PCDIN``'s) as the NMEA 2000 reader resolves it.
"""

from __future__ import annotations

import mmap
import re
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from dracc.frames import FileResult
from dracc.ingest.demux import merge_results
from dracc.ingest.n2k.formats import parse_n2k_lines
from dracc.ingest.n2k.messages import TIME_UTC, Messages, concat_messages
from dracc.ingest.n2k.reader import n2k_result

if TYPE_CHECKING:
    from dracc.core.config import IngestConfig

#: the ignored-count keys the NMEA reader gives these lines, and their N2K formats
IGNORED_KEYS = {"PCDIN": "n2k-pcdin", "PGN": "n2k-mxpgn"}
_LINE = re.compile(rb"[^\r\n]*?\$(PCDIN|MXPGN),[^\r\n]*")


def has_embedded(r: FileResult) -> bool:
    """Whether the NMEA reader ignored lines that may carry NMEA 2000 messages."""
    return any(r.ignored.get(k) for k in IGNORED_KEYS)


def _lines(path: Path) -> dict[str, tuple[list[bytes], list[int]]]:
    """Format -> (the lines from their ``$``, their 1-based line numbers)."""
    out: dict[str, tuple[list[bytes], list[int]]] = {}
    with path.open("rb") as fh, mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_READ) as mm:
        line, pos = 1, 0
        for m in _LINE.finditer(mm):
            line += mm[pos : m.start()].count(b"\n")
            pos = m.start()
            fmt = "n2k-pcdin" if m.group(1) == b"PCDIN" else "n2k-mxpgn"
            text = m.group(0)
            lines, numbers = out.setdefault(fmt, ([], []))
            lines.append(text[text.index(b"$" + m.group(1)) :])
            numbers.append(line)
    return out


def _line_times(r: FileResult, msgs: Messages) -> Messages:
    """``msgs`` with the time of the preceding timed record of the log (rule 3)."""
    parts = [(f["line"].to_numpy(), f["time_ns"].to_numpy()) for f in r.frames.values() if len(f)]
    if not parts:
        return msgs
    line = np.concatenate([p[0] for p in parts])
    t = np.concatenate([p[1] for p in parts])
    order = np.argsort(line, kind="stable")
    line, t = line[order], t[order]
    i = np.searchsorted(line, msgs.line, side="right") - 1
    msgs.time_ns = t[np.maximum(i, 0)].astype(np.int64)
    msgs.time_kind = TIME_UTC
    return msgs


def add_embedded(path: str | Path, r: FileResult, cfg: IngestConfig) -> FileResult:
    """``r`` (the NMEA reader's result of ``path``) with the NMEA 2000 messages of its
    ``$PCDIN``/``$MXPGN`` lines decoded and merged in, their ignored counts taken off."""
    found = _lines(Path(path))
    if not found:
        return r
    msgs = concat_messages(
        [
            parse_n2k_lines(lines, np.asarray(numbers, dtype=np.int64), fmt)
            for fmt, (lines, numbers) in found.items()
        ]
    )
    msgs = _line_times(r, msgs)
    fmt = next(iter(found)) if len(found) == 1 else "n2k-embedded"
    n2k = n2k_result(msgs, str(path), fmt, cfg, lines=0)
    n = 0
    for key, f in IGNORED_KEYS.items():
        k = len(found.get(f, ((), ()))[0])
        n += k
        r.ignored[key] -= k
        if r.ignored[key] <= 0:
            del r.ignored[key]
            r.ignored_examples.pop(key, None)
    note = f"{n} NMEA 2000 messages inside NMEA 0183 ($PCDIN/$MXPGN) decoded"
    return merge_results(r.path, r.format, r.lines, [r, n2k], [note])
