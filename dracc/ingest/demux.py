"""One log file holding lines of several formats, read by each format's own reader.

A Signal K server data log interleaves NMEA 0183, NMEA 2000 (canboat plain) and Signal K
delta lines; a gpsfake ``.chk`` file interleaves NMEA sentences and gpsd JSON.  Each
reader is given a *line-preserving copy*: the lines it reads kept (or only their payload,
a prefix cut off), every other line made blank, so every line number a reader reports
is the line's number in the original file.  The blank lines a copy adds are taken off
the ``blank`` count of that reader's result (:func:`take_off_blanks`), and what the
reader says about the copy is said of the original (:func:`relabel`).

Everything is vectorised over the file's bytes: a copy is one boolean mask over the
buffer (:func:`line_copy`), so a copy of a 1 GB log costs a few passes of numpy, not a
Python loop per line.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

import numpy as np

from dracc.core.errors import IngestError
from dracc.frames import FileResult, Rejects
from dracc.ingest.timebase import STEPS_KEPT, CountedTimeEvents, merge_events


def line_bounds(buf: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(start, end, next) of every line of ``buf`` (uint8): ``end`` excludes the line end
    (LF, CR LF) and ``next`` is where the following line starts.  A last line without a
    line end counts; an empty buffer has no lines."""
    n = len(buf)
    lf = np.flatnonzero(buf == 10)
    nxt = lf + 1
    if n and (not len(lf) or lf[-1] != n - 1):
        nxt = np.append(nxt, n)
        lf = np.append(lf, n)
    start = np.concatenate(([0], nxt[:-1])).astype(np.int64) if len(nxt) else np.zeros(0, np.int64)
    end = lf.astype(np.int64)
    has_cr = (end > start) & (buf[np.maximum(end - 1, 0)] == 13) if n else np.zeros(0, bool)
    end = end - has_cr
    return start, end, nxt.astype(np.int64)


def line_copy(
    buf: np.ndarray,
    start: np.ndarray,
    end: np.ndarray,
    nxt: np.ndarray,
    keep: np.ndarray,
    skip: np.ndarray | int = 0,
) -> np.ndarray:
    """The bytes of a copy of ``buf`` with the same lines: line ``i`` holds its bytes
    from ``start[i] + skip[i]`` to its end where ``keep[i]``, nothing otherwise; every
    line keeps its line end (LF only, so the copy has as many lines as the original).

    Each line is four runs of bytes -- before the kept part, the kept part, the CR,
    the LF -- and one ``np.repeat`` of (drop, keep, drop, keep) over their lengths is
    the mask of the bytes copied (one byte of mask per byte of log)."""
    n = len(start)
    if n == 0:
        return np.zeros(0, dtype=np.uint8)
    sk = skip if isinstance(skip, np.ndarray) else np.full(n, skip, dtype=np.int64)
    s = np.where(keep, np.minimum(start + sk, end), start)
    e = np.where(keep, end, s)
    has_lf = buf[nxt - 1] == 10
    lengths = np.stack([s - start, e - s, nxt - has_lf - e, has_lf.astype(np.int64)], axis=1)
    runs = np.tile(np.array([False, True, False, True]), n)
    out = buf[np.repeat(runs, lengths.ravel())]
    if not has_lf[-1]:  # a last line without LF: give it one
        out = np.append(out, np.uint8(10))
    return out


def write_copy(data: np.ndarray, folder: Path, name: str) -> Path:
    """Write ``data`` as ``folder/name``; its path."""
    p = folder / name
    p.write_bytes(data.tobytes())
    return p


def take_off_blanks(r: FileResult, added: int) -> None:
    """Take the ``added`` blank lines a line-preserving copy made off ``r.ignored``."""
    have = r.ignored.get("blank", 0)
    left = have - min(added, have)
    if left:
        r.ignored["blank"] = left
    else:
        r.ignored.pop("blank", None)
        r.ignored_examples.pop("blank", None)


def relabel(r: FileResult, copy: str, original: str) -> FileResult:
    """``r``, read from the copy ``copy``, saying ``original`` wherever it said the copy."""

    def name(text: str) -> str:
        return text.replace(copy, original)

    def examples(d: dict[str, list[tuple[str, int, str]]]) -> None:
        for key, rows in d.items():
            d[key] = [(name(f), line, text) for f, line, text in rows]

    r.path = original
    examples(r.rejects.examples)
    examples(r.ignored_examples)
    r.notes = [name(n) for n in r.notes]
    r.time_events.decisions = [name(d) for d in r.time_events.decisions]
    r.time_events.examples = [(name(f), line, text) for f, line, text in r.time_events.examples]
    r.time_events.steps = [replace(s, file=name(s.file)) for s in r.time_events.steps]
    return r


def scaled_progress(
    progress: Callable[[int], object] | None, original_bytes: int, copy_bytes: int
) -> Callable[[int], object] | None:
    """Progress told in bytes of a copy, passed on in bytes of the original lines it
    stands for (``original_bytes`` of the log, ``copy_bytes`` of the copy)."""
    if progress is None:
        return None
    ratio = original_bytes / max(copy_bytes, 1)
    return lambda n: progress(int(round(n * ratio)))


def merge_results(
    path: str, fmt: str, lines: int, parts: list[FileResult], notes: list[str]
) -> FileResult:
    """One :class:`FileResult` of ``path`` from the results of its parts (frames by kind
    in time order, rejects, ignored and their examples, time events, notes)."""
    from dracc.frames import concat_blocks

    rejects = Rejects()
    ignored: Counter[str] = Counter()
    ignored_examples: dict[str, list[tuple[str, int, str]]] = {}
    te = CountedTimeEvents()  # the figures per source where every part has them
    out_notes = list(notes)
    for r in parts:
        rejects.merge(r.rejects)
        ignored.update(r.ignored)
        for k, ex in r.ignored_examples.items():
            mine = ignored_examples.setdefault(k, [])
            mine.extend(ex[: max(0, 5 - len(mine))])
        merge_events(te, r.time_events)
        te.decisions.extend(r.time_events.decisions)
        te.examples.extend(r.time_events.examples)
        out_notes.extend(r.notes)
    del te.steps[STEPS_KEPT:]
    frames = concat_blocks([r.frames for r in parts])
    return FileResult(
        path=path,
        format=fmt,
        frames=frames,
        lines=lines,
        rejects=rejects,
        time_events=te,
        notes=out_notes,
        ignored=ignored,
        ignored_examples=ignored_examples,
        # without a clock only where no part has one (a part's own times are the file's)
        clockless=bool(parts) and all(r.clockless for r in parts),
    )


def check_strict(r: FileResult, strict: object) -> None:
    """In strict mode (``strict``: a config with ``strict`` true, or a bool), an
    IngestError naming the first rejected line of ``r``."""
    check_strict_rejects(r.rejects, r.path, strict)


def check_strict_rejects(rejects: Rejects, path: str, strict: object) -> None:
    """:func:`check_strict` of the rejects of the log ``path``."""
    from dracc.ingest.nmea.sentences import NON_FATAL, REASONS

    on = strict if isinstance(strict, bool) else bool(getattr(strict, "strict", False))
    fatal = sum(n for why, n in rejects.counts.items() if why not in NON_FATAL)
    if not on or not fatal:
        return
    rows = [
        (ln, f, t, why)
        for why, ex in rejects.examples.items()
        if why not in NON_FATAL
        for f, ln, t in ex
    ]
    if not rows:
        raise IngestError(f"{path}: {fatal} lines rejected (--strict)")
    ln, f, t, why = min(rows)
    raise IngestError(f"{f}:{ln}: rejected ({REASONS.get(why, why)}): {t!r} (--strict)")
