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
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from dracc.core.errors import IngestError
from dracc.frames import MISSING_NS, FileResult
from dracc.ingest.demux import (
    check_strict,
    line_bounds,
    line_copy,
    merge_results,
    relabel,
    scaled_progress,
    take_off_blanks,
    write_copy,
)
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


def read_signalk(
    path: str | Path, cfg: IngestConfig, progress: Callable[[int], object] | None = None
) -> FileResult:
    """Read a Signal K server data log (see the module docstring) into one
    :class:`FileResult` of format ``signalk``."""
    from dracc.ingest.nmea import check_readable, read_nmea

    p = Path(path)
    check_readable(p)
    file = str(p)
    raw = p.read_bytes()
    buf = np.frombuffer(raw, dtype=np.uint8)
    start, end, nxt = line_bounds(buf)
    letter, recv, pay = split_prefixes(buf, start, end)
    blank = start == end
    size = nxt - start
    is_nmea = np.isin(letter, np.frombuffer(NMEA_LETTERS, np.uint8)) | ((letter == 0) & ~blank)
    is_n2k = letter == ord("A")
    is_delta = letter == ord("I")
    other = (letter != 0) & ~is_nmea & ~is_n2k & ~is_delta
    parts: list[FileResult] = []
    notes: list[str] = []
    plain = (letter == 0) & ~blank
    counts = {
        "NMEA 0183": int(is_nmea.sum() - plain.sum()),
        "NMEA 2000": int(is_n2k.sum()),
        "Signal K delta": int(is_delta.sum()),
        "other": int(other.sum()),
        "not multiplexed (read as NMEA 0183)": int(plain.sum()),
    }
    notes.append(
        "Signal K data log: " + ", ".join(f"{n} {what} lines" for what, n in counts.items() if n)
    )
    with tempfile.TemporaryDirectory(prefix="dracc-signalk-") as tmp:
        folder = Path(tmp)
        if is_nmea.any() or not (is_n2k.any() or is_delta.any()):
            added = int((~is_nmea & ~blank).sum())
            if added == 0:  # nothing to blank out: the log is read as it is
                parts.append(read_nmea(p, cfg, progress))
            else:
                (folder / "n").mkdir()
                copy = write_copy(line_copy(buf, start, end, nxt, is_nmea), folder / "n", p.name)
                told = scaled_progress(progress, int(size[is_nmea].sum()), copy.stat().st_size)
                r = relabel(read_nmea(copy, cfg, told), str(copy), file)
                take_off_blanks(r, added)
                parts.append(r)
        if is_n2k.any():
            parts.append(
                _read_n2k_lines(p, cfg, progress, buf, start, end, nxt, is_n2k, pay, recv, folder)
            )
        if is_delta.any():
            dec = DeltaDecoder(file, max_line_bytes=cfg.max_line_bytes)
            di = np.flatnonzero(is_delta)
            decode_lines(dec, raw, pay[di], end[di], di + 1, recv[di])
            r = dec.finish(cfg)
            r.format = "signalk"
            check_strict(r, cfg)
            parts.append(r)
            if progress is not None:
                progress(int(size[is_delta].sum()))
    res = merge_results(file, "signalk", len(start), parts, notes)
    if other.any():
        oi = np.flatnonzero(other)
        for ch in np.unique(letter[oi]).tolist():
            rows = oi[letter[oi] == ch]
            what = f"signalk {chr(ch)}"
            res.ignored[what] += len(rows)
            res.ignored_examples[what] = [
                (file, i + 1, raw_line(buf, start, end, i)) for i in rows[:5].tolist()
            ]
        if progress is not None:
            progress(int(size[other].sum()))
    return res


def _read_n2k_lines(
    p: Path,
    cfg: IngestConfig,
    progress: Callable[[int], object] | None,
    buf: np.ndarray,
    start: np.ndarray,
    end: np.ndarray,
    nxt: np.ndarray,
    keep: np.ndarray,
    pay: np.ndarray,
    recv: np.ndarray,
    folder: Path,
) -> FileResult:
    """The ``A`` lines' payloads (canboat plain) read by the NMEA 2000 reader from a
    line-preserving copy; rows without a receive time get their line's."""
    file = str(p)
    rows = np.flatnonzero(keep)
    n = len(rows)
    (folder / "a").mkdir()
    copy = write_copy(line_copy(buf, start, end, nxt, keep, pay - start), folder / "a", p.name)
    told = scaled_progress(progress, int((nxt - start)[keep].sum()), copy.stat().st_size)
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
        for i in rows[:5].tolist():
            r.rejects.add("n2k_unread", file, i + 1, raw_line(buf, start, end, i))
        r.rejects.counts["n2k_unread"] += max(0, n - 5)
        r.notes.append(f"{n} NMEA 2000 lines not read: {why}")
        return r
    take_off_blanks(r, len(start) - n)
    for df in r.frames.values():
        if len(df):
            lines = df["line"].to_numpy()
            have = df["recv_ns"].to_numpy()
            got = recv[np.clip(lines - 1, 0, len(recv) - 1)]
            df["recv_ns"] = np.where(have == MISSING_NS, got, have)
    return r
