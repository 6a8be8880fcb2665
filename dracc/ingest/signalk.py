"""Signal K server data logs: ``<milliseconds>;<type>;<payload>`` a line.

The server's data logging (``skserver-raw_YYYY-MM-DDTHH.log``) writes every input line
as it came, after its receive time in Unix milliseconds and a letter saying what it is.
The server's own playback (its ``autodetect`` provider) reads ``N`` (and ``C``, ``G``,
``M``) as NMEA 0183, ``A`` as NMEA 2000 in canboat's plain form
(``2016-07-16T12:00:00.000Z,2,130306,105,255,8,00,d1,...``) and ``I`` as Signal K delta
JSON; so does :func:`read_signalk`:

* NMEA 0183 lines are read by the NMEA reader (:func:`dracc.ingest.nmea.read_nmea`),
  prefix and all (it takes the milliseconds as the receive time), from a
  line-preserving copy with every other line blank (:mod:`dracc.ingest.demux`); the
  blanks the copy adds are taken off its ``blank`` count.  Lines not in the
  multiplexed form go the same way (a bare sentence is read, anything else rejected).
* NMEA 2000 lines: their payloads, prefix cut off, in a line-preserving copy read by
  :func:`dracc.ingest.n2k.read_n2k`; a row without a receive time gets the line's.
* Signal K deltas: :class:`dracc.ingest.signalk_delta.DeltaDecoder`, the milliseconds
  as the receive time (and the time of an update without a timestamp).
* Any other letter: counted as ignored (``signalk X``), as the letter says nothing dracc
  reads.

Every line number (frames, rejects, ignored examples) is the line's in the log.  The
three results become one (format ``signalk``), frames in time order.
"""

from __future__ import annotations

import re
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from dracc.core.errors import IngestError
from dracc.frames import MISSING_NS, FileResult
from dracc.ingest.chunks import Chunk, LineCopy, iter_line_chunks
from dracc.ingest.demux import (
    check_strict,
    merge_results,
    relabel,
    scaled_progress,
    take_off_blanks,
)
from dracc.ingest.memory import pid_folder
from dracc.ingest.signalk_delta import DeltaDecoder, decode_lines

if TYPE_CHECKING:  # config imports ingest.frames: no runtime import here
    from dracc.core.config import IngestConfig

#: the letters the Signal K server reads as NMEA 0183 (``N``; ``C``, ``G``, ``M`` too)
NMEA_LETTERS = b"NCGM"
#: a line in the multiplexed form (10 to 13 digits, as the NMEA reader's prefix takes)
_LINE_RE = re.compile(rb"^\d{10,13};[A-Za-z];")
_HEAD_COLS = 16  #: the first bytes of a line searched for the prefix
_CHUNK_LINES = 1 << 19  #: lines whose prefixes are split at once (bounded memory)


def looks_like_signalk(head: bytes) -> bool:
    """True when at least half the non-blank complete lines of ``head`` (at most 200)
    are in the multiplexed form ``<ms>;<letter>;``."""
    lines = head.split(b"\n")
    lines = lines[:-1] if len(lines) > 1 else lines
    lines = [ln for ln in (x.strip() for x in lines[:400]) if ln][:200]
    if not lines:
        return False
    hits = sum(1 for ln in lines if _LINE_RE.match(ln))
    return hits >= 1 and 2 * hits >= len(lines)


def split_prefixes(
    buf: np.ndarray, start: np.ndarray, end: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(letter, receive time ns, payload start) of every line: ``letter`` 0 (and time
    MISSING_NS) where the line is not in the form ``<10-13 digits>;<letter>;``.  Lines
    are taken ``_CHUNK_LINES`` at a time (the first bytes of each as a small matrix)."""
    letter = np.zeros(len(start), dtype=np.uint8)
    recv = np.full(len(start), MISSING_NS, dtype=np.int64)
    pay = start.copy()
    for a in range(0, len(start), _CHUNK_LINES):
        b = min(a + _CHUNK_LINES, len(start))
        letter[a:b], recv[a:b], pay[a:b] = _prefix_chunk(buf, start[a:b], end[a:b])
    return letter, recv, pay


def _prefix_chunk(
    buf: np.ndarray, start: np.ndarray, end: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    n = len(start)
    cols = np.arange(_HEAD_COLS)
    idx = start[:, None] + cols
    inside = idx < end[:, None]
    head = np.where(inside, buf[np.minimum(idx, len(buf) - 1)], 0).astype(np.uint8)
    semi = head == ord(";")
    k = np.where(semi.any(axis=1), semi.argmax(axis=1), -1)  # the first ';'
    digit = (head >= ord("0")) & (head <= ord("9"))
    before = cols[None, :] < k[:, None]
    ok = (k >= 10) & (k <= 13) & ~(before & ~digit).any(axis=1)
    rows = np.arange(n)
    kk = np.clip(k, 0, _HEAD_COLS - 3)
    letter = head[rows, kk + 1]
    is_letter = ((letter >= ord("A")) & (letter <= ord("Z"))) | (
        (letter >= ord("a")) & (letter <= ord("z"))
    )
    ok &= is_letter & (head[rows, kk + 2] == ord(";"))
    ms = np.zeros(n, dtype=np.int64)
    for j in range(13):  # Horner over the digit columns before the ';'
        ms = np.where(j < k, ms * 10 + (head[:, j].astype(np.int64) - ord("0")), ms)
    return (
        np.where(ok, letter, 0).astype(np.uint8),
        np.where(ok, ms * 1_000_000, MISSING_NS),
        start + np.where(ok, k + 3, 0),
    )


def raw_line(buf: np.ndarray, start: np.ndarray, end: np.ndarray, i: int) -> str:
    """The first 120 characters of line ``i`` (0-based) as text."""
    return buf[start[i] : min(end[i], start[i] + 120)].tobytes().decode("utf-8", "replace")


@dataclass
class _Pass:
    """What one pass over a Signal K data log gathered, chunk by chunk."""

    lines: int = 0
    counts: Counter[str] = field(default_factory=Counter)  #: lines by what they are
    nbytes: Counter[str] = field(default_factory=Counter)  #: their bytes (for progress)
    other: dict[int, list[tuple[int, str]]] = field(default_factory=dict)  #: letter: examples
    other_n: Counter[int] = field(default_factory=Counter)
    #: the ``A`` lines: their numbers and receive times (chunk by chunk), first examples
    n2k_lines: list[np.ndarray] = field(default_factory=list)
    n2k_recv: list[np.ndarray] = field(default_factory=list)
    n2k_examples: list[tuple[int, str]] = field(default_factory=list)
    nmea_copy: LineCopy | None = None
    n2k_copy: LineCopy | None = None


def read_signalk(
    path: str | Path, cfg: IngestConfig, progress: Callable[[int], object] | None = None
) -> FileResult:
    """Read a Signal K server data log (see the module docstring) into one
    :class:`FileResult` of format ``signalk``, streamed in chunks of whole lines
    (:func:`iter_line_chunks`); the copies are written chunk by chunk."""
    from dracc.ingest.nmea import check_readable, read_nmea

    p = Path(path)
    check_readable(p)
    file = str(p)
    dec = DeltaDecoder(file, max_line_bytes=cfg.max_line_bytes)
    parts: list[FileResult] = []
    with pid_folder("dracc-signalk-") as tmp:
        folder = Path(tmp)
        acc = _Pass()
        chunks = iter_line_chunks(p, cfg.max_line_bytes)
        while (ch := next(chunks, None)) is not None:  # None at the end: no chunk held on
            _take_chunk(p, cfg, ch, acc, dec, folder)
        c, nb = acc.counts, acc.nbytes
        nmea_copy = acc.nmea_copy.close() if acc.nmea_copy is not None else None
        n2k_copy = acc.n2k_copy.close() if acc.n2k_copy is not None else None
        notes = [_summary(c)]
        if c["nmea"] or not (c["n2k"] or c["delta"]):
            if nmea_copy is None:  # nothing to blank out: the log is read as it is
                parts.append(read_nmea(p, cfg, progress))
            else:
                told = scaled_progress(progress, nb["nmea"], nmea_copy.stat().st_size)
                r = relabel(read_nmea(nmea_copy, cfg, told), str(nmea_copy), file)
                take_off_blanks(r, c["added"])
                parts.append(r)
        if n2k_copy is not None:
            parts.append(_read_n2k_lines(p, cfg, progress, acc, n2k_copy))
        if c["delta"]:
            r = dec.finish(cfg)
            r.format = "signalk"
            check_strict(r, cfg)
            parts.append(r)
            if progress is not None:
                progress(nb["delta"])
    res = merge_results(file, "signalk", acc.lines, parts, notes)
    if acc.other_n:
        for ch_ in sorted(acc.other_n):
            what = f"signalk {chr(ch_)}"
            res.ignored[what] += acc.other_n[ch_]
            res.ignored_examples[what] = [(file, ln, t) for ln, t in acc.other[ch_]]
        if progress is not None:
            progress(nb["other"])
    return res


def _summary(c: Counter[str]) -> str:
    """The note saying how many lines of each kind the log holds."""
    counts = {
        "NMEA 0183": c["nmea"] - c["plain"],
        "NMEA 2000": c["n2k"],
        "Signal K delta": c["delta"],
        "other": c["other"],
        "not multiplexed (read as NMEA 0183)": c["plain"],
    }
    return "Signal K data log: " + ", ".join(f"{n} {what} lines" for what, n in counts.items() if n)


def _take_chunk(
    p: Path, cfg: IngestConfig, ch: Chunk, acc: _Pass, dec: DeltaDecoder, folder: Path
) -> None:
    """Split one chunk's lines by their letter: deltas decoded, NMEA 0183 and NMEA 2000
    lines into their copies (each started where first needed), the rest counted."""
    buf, start, end = ch.buf, ch.start, ch.end
    letter, recv, pay = split_prefixes(buf, start, end)
    blank = start == end
    size = ch.nxt - start
    plain = (letter == 0) & ~blank
    is_nmea = np.isin(letter, np.frombuffer(NMEA_LETTERS, np.uint8)) | plain
    is_n2k = letter == ord("A")
    is_delta = letter == ord("I")
    other = (letter != 0) & ~is_nmea & ~is_n2k & ~is_delta
    added = ~is_nmea & ~blank
    for what, m in (("nmea", is_nmea), ("n2k", is_n2k), ("delta", is_delta), ("other", other)):
        acc.counts[what] += int(m.sum())
        acc.nbytes[what] += int(size[m].sum())
    acc.counts["plain"] += int(plain.sum())
    acc.counts["added"] += int(added.sum())
    if acc.nmea_copy is None and added.any():
        # the lines before are NMEA 0183 or blank: copied as they are (read again)
        (folder / "n").mkdir()
        acc.nmea_copy = LineCopy(p, folder / "n" / p.name)
        for before in iter_line_chunks(p, cfg.max_line_bytes, stop=ch.offset):
            acc.nmea_copy.add(before, np.ones(len(before.start), dtype=bool))
    if acc.nmea_copy is not None:
        acc.nmea_copy.add(ch, is_nmea)
    if is_n2k.any():
        if acc.n2k_copy is None:
            (folder / "a").mkdir()
            acc.n2k_copy = LineCopy(p, folder / "a" / p.name)
            acc.n2k_copy.pad(acc.lines)
        ai = np.flatnonzero(is_n2k)
        acc.n2k_lines.append(ch.numbers(ai))
        acc.n2k_recv.append(recv[ai])
        for i in ai[: max(0, 5 - len(acc.n2k_examples))].tolist():
            acc.n2k_examples.append((i + 1 + ch.line0, raw_line(buf, start, end, i)))
    if acc.n2k_copy is not None:
        acc.n2k_copy.add(ch, is_n2k, pay - start)
    if is_delta.any():
        di = np.flatnonzero(is_delta)
        decode_lines(dec, ch.data, pay[di], end[di], ch.numbers(di), recv[di])
        dec.flush()
    if other.any():
        oi = np.flatnonzero(other)
        for x in np.unique(letter[oi]).tolist():
            rows = oi[letter[oi] == x]
            acc.other_n[x] += len(rows)
            ex = acc.other.setdefault(x, [])
            for i in rows[: max(0, 5 - len(ex))].tolist():
                ex.append((i + 1 + ch.line0, raw_line(buf, start, end, i)))
    acc.lines += len(start)


def _read_n2k_lines(
    p: Path,
    cfg: IngestConfig,
    progress: Callable[[int], object] | None,
    acc: _Pass,
    copy: Path,
) -> FileResult:
    """The ``A`` lines' payloads (canboat plain) read by the NMEA 2000 reader from a
    line-preserving copy; rows without a receive time get their line's."""
    file = str(p)
    n = acc.counts["n2k"]
    told = scaled_progress(progress, acc.nbytes["n2k"], copy.stat().st_size)
    try:
        from dracc.ingest.n2k import read_n2k

        r = relabel(read_n2k(copy, cfg, told), str(copy), file)
    except (ImportError, IngestError) as err:  # no NMEA 2000 reader, or it cannot read them
        if isinstance(err, IngestError) and getattr(cfg, "strict", False):
            raise
        r = FileResult(path=file, format="signalk", frames={}, lines=0)
        why = (
            "no NMEA 2000 reader"
            if isinstance(err, ImportError)
            else str(err).replace(str(copy), file)
        )
        for ln, text in acc.n2k_examples:
            r.rejects.add("n2k_unread", file, ln, text)
        r.rejects.counts["n2k_unread"] += max(0, n - 5)
        r.notes.append(f"{n} NMEA 2000 lines not read: {why}")
        return r
    take_off_blanks(r, acc.lines - n)
    numbers = np.concatenate(acc.n2k_lines)
    recv = np.concatenate(acc.n2k_recv)
    for df in r.frames.values():
        if len(df):
            lines = df["line"].to_numpy()
            have = df["recv_ns"].to_numpy()
            at = np.clip(np.searchsorted(numbers, lines), 0, len(numbers) - 1)
            got = np.where(numbers[at] == lines, recv[at], MISSING_NS)
            df["recv_ns"] = np.where(have == MISSING_NS, got, have)
    return r
