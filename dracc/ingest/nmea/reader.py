"""The NMEA text file reader: a file streamed as resolved blocks with bounded memory
(:func:`iter_nmea_blocks`; large files parsed by two worker processes), talkers
fingerprinted in the first block, and a whole file read into a :class:`FileResult`
(:func:`read_nmea`, after :func:`check_readable`)."""

from __future__ import annotations

import os
import stat
from collections import Counter, deque
from collections.abc import Callable, Iterator
from concurrent.futures import Future, ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from contextlib import ExitStack
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import IO, TYPE_CHECKING, Any

import numpy as np

from dracc.core.errors import IngestError
from dracc.frames import FileResult, concat_blocks
from dracc.ingest.memory import handover_dir, trim_heap
from dracc.ingest.nmea.assemble import _source_categorical, assemble, talker_str, time_arrays
from dracc.ingest.nmea.blocks import block_ranges, parse_piece, parse_range, stream_pieces
from dracc.ingest.nmea.groups import join_line_groups
from dracc.ingest.nmea.parsed import ParsedBlock
from dracc.ingest.nmea.pool import (
    load_parsed,
    parse_bytes_to_file,
    parse_range_to_file,
    pool_ok,
    worker_init,
)
from dracc.ingest.nmea.sentences import MAX_LINE_BYTES, SENTENCES
from dracc.ingest.nmea.state import Block, StreamState
from dracc.ingest.timebase import days_from_civil, valid_civil

if TYPE_CHECKING:  # config imports ingest.frames: no runtime import here
    from dracc.core.config import IngestConfig

FIRST_BLOCK_BYTES = 16 * 1024 * 1024  #: the first block (where talkers are fingerprinted)
#: the first block when workers parse the others: parsed by the main process while they
#: start (about 70 000 lines, plenty to fingerprint talkers)
MAIN_FIRST_BLOCK_BYTES = 4 * 1024 * 1024
#: the later blocks: small enough that a worker reuses its memory (fresh pages are dear)
BLOCK_BYTES = 8 * 1024 * 1024
PARALLEL_MIN_BYTES = 32 * 1024 * 1024  #: files at least this large use two processes


def iter_nmea_blocks(
    path: str | Path,
    cfg: IngestConfig,
    state: StreamState | None = None,
    block_bytes: int | None = None,
    workers: int | None = None,
    progress: Callable[[int], object] | None = None,
    name: str | None = None,
    opener: Callable[[], IO[bytes]] | None = None,
    size_hint: int | None = None,
) -> Iterator[Block]:
    """Stream an NMEA text file as resolved blocks with bounded memory.

    ``state`` (a :class:`StreamState`, created if None) accumulates rejections, time
    events and statistics while iterating; read it after the loop.  Files of at least
    ``PARALLEL_MIN_BYTES`` are parsed by up to two worker processes, at most four blocks
    ahead, which hand their blocks over as files (:func:`parse_range_to_file`) and die
    with this process (:func:`worker_init`); this process parses the first block itself
    while they start, then resolves times and builds frames in order.  Blocks are cut
    after a line end; a line longer than ``cfg.max_line_bytes`` across a cut is a block of
    its own, read only at its ends (:func:`block_ranges`).  ``block_bytes`` None: a first block of ``FIRST_BLOCK_BYTES``
    (``MAIN_FIRST_BLOCK_BYTES`` with workers), then blocks of about ``BLOCK_BYTES``, as
    many as the workers share evenly (none waits alone at the end); a number: blocks of that
    size.  ``progress(n_bytes)`` is called as blocks finish.  ``name``: what the file is
    called in examples, events and errors (default its path; the log as given where
    ``path`` is its decompressed copy).  ``opener``: the log is the stream it opens (a
    compressed log decompressed as it is read, :mod:`dracc.ingest.compressed`), read in
    pieces of the same sizes (:func:`stream_pieces`), by the workers where its
    ``size_hint`` (its expected size) would have them; ``path`` only names it.  Raises
    IngestError in ``cfg.strict`` mode at the first rejected line.
    """
    path = Path(path)
    file = str(path) if name is None else name
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
    max_line = int(getattr(cfg, "max_line_bytes", MAX_LINE_BYTES))
    size = (size_hint or 0) if opener is not None else path.stat().st_size
    nworkers = (
        workers if workers is not None else (2 if size >= PARALLEL_MIN_BYTES and pool_ok() else 1)
    )
    if opener is not None:
        ranges = []
    elif block_bytes is not None:
        ranges = list(block_ranges(path, block_bytes, max_line_bytes=max_line))
    else:
        first_bytes = MAIN_FIRST_BLOCK_BYTES if nworkers > 1 else FIRST_BLOCK_BYTES
        rest = max(size - first_bytes, 0)
        n_rest = -(-rest // BLOCK_BYTES)
        if n_rest % nworkers:  # the workers share the blocks after the first evenly
            n_rest += nworkers - n_rest % nworkers
        later = max(-(-rest // n_rest), 1) if n_rest else BLOCK_BYTES
        ranges = list(block_ranges(path, later, first_bytes, max_line))
    #: blocks waiting for their times: (block, splitter of its times, first line, bytes)
    held: list[tuple[ParsedBlock, Callable[[np.ndarray], list[np.ndarray]], int, int]] = []
    first_parsed = [True]  # talkers are fingerprinted in the first block read (not a line too long)

    def handle(pb: ParsedBlock, nbytes: int) -> Iterator[Block]:
        line0 = st.count_block(pb, cfg.strict)
        join_line_groups(pb, st.line_groups, line0, st.stats)
        st.bytes += nbytes
        pos = pb.kinds.get("position")
        pos_types = (
            np.bincount(pos["sentence"].astype(np.int64), minlength=len(SENTENCES)) > 0
            if pos is not None
            else np.zeros(len(SENTENCES), bool)
        )
        for kind, cols in pb.kinds.items():
            c = np.bincount(cols["sentence"].astype(np.int64), minlength=len(SENTENCES))
            if kind != "position" and pos is not None and c[pos_types].any():
                c -= _also_in_position(cols, pos["seq"], pos_types)
            st.sentences.update({SENTENCES[i]: int(c[i]) for i in np.flatnonzero(c).tolist()})
            if kind == "position" and first_parsed[0] and not st.split_talkers:
                _fingerprint(cols, st, pb.source_names)
        if pb.clock:
            st.sentences["ZDA"] += len(pb.clock["seq"])
            count_by_source(pb, pb.clock, st.split_talkers, st.time_only)
        if pb.aux:
            _count_qualifiers(pb, st)
        if pb.n_lines and not (pb.n_lines == 1 and pb.reject_counts.get("too_long") == 1):
            first_parsed[0] = False
        tod, date, ext, split = time_arrays(pb)
        held.append((pb, split, line0, nbytes))
        done = st.timebase.feed(tod, date, ext)
        yield from _release(done)

    def _release(done: list[np.ndarray]) -> Iterator[Block]:
        for t in done:
            pb, split, line0, nbytes = held.pop(0)
            frames = assemble(pb, split(t), st, file, line0, cfg)
            if progress is not None:
                progress(nbytes)
            yield Block(frames, pb.n_lines, line0, nbytes)

    with ExitStack() as stack:
        if opener is not None:
            fh = stack.enter_context(opener())
            first = block_bytes or (MAIN_FIRST_BLOCK_BYTES if nworkers > 1 else FIRST_BLOCK_BYTES)
            jobs = _stream_jobs(
                fh, first, block_bytes or BLOCK_BYTES, cfg.ignore_checksum, max_line
            )
        else:
            jobs = _file_jobs(path, ranges, cfg.ignore_checksum, max_line)
        if nworkers <= 1 or (opener is None and len(ranges) <= 1):
            for job in jobs:
                yield from handle(job.local(), job.nbytes)
        else:
            yield from _pooled(jobs, nworkers, 2 * size, handle, st)
    if opener is not None:
        trim_heap()  # the pieces read (and parsed) here: their buffers given back
    yield from _release(st.timebase.finish())


@dataclass
class _Job:
    """One block to parse: here (``local``) or by a worker (``remote``: the function and
    its arguments after the hand-over folder and the block's number; None: here only)."""

    i: int
    nbytes: int
    local: Callable[[], ParsedBlock]
    remote: tuple[Any, ...] | None


def _file_jobs(
    path: Path, ranges: list[tuple[int, int, bool]], ignore_checksum: bool, max_line: int
) -> Iterator[_Job]:
    """The blocks of a file (:func:`block_ranges`); a line too long is read here."""
    for i, (off, ln, too_long) in enumerate(ranges):
        at_eof = i == len(ranges) - 1
        args = (str(path), off, ln, ignore_checksum, at_eof, max_line)
        remote = None if too_long else (parse_range_to_file, *args)
        yield _Job(i, ln, partial(parse_range, *args, too_long), remote)


def _stream_jobs(
    fh: IO[bytes], first: int, later: int, ignore_checksum: bool, max_line: int
) -> Iterator[_Job]:
    """The pieces of a stream (:func:`stream_pieces`) as they are read; a line too long
    is read here."""
    for i, piece in enumerate(stream_pieces(fh.read, first, later, max_line)):
        args = (piece.data, ignore_checksum, piece.at_eof, max_line)
        remote = None if piece.long is not None else (parse_bytes_to_file, *args)
        yield _Job(i, piece.nbytes, partial(parse_piece, piece, ignore_checksum, max_line), remote)


def _pooled(
    jobs: Iterator[_Job],
    nworkers: int,
    room: int,
    handle: Callable[[ParsedBlock, int], Iterator[Block]],
    st: StreamState,
) -> Iterator[Block]:
    """The blocks of ``jobs`` parsed by ``nworkers`` worker processes, at most
    ``nworkers + 2`` in flight, handed over in a folder with ``room`` bytes
    (:func:`handover_dir`), resolved in order by ``handle``; the first is parsed here
    while the workers start.  A broken pool (a worker killed, e.g. out of memory) falls
    back to parsing the remaining blocks in this process."""
    broken = False
    with (
        handover_dir(room) as folder,
        ProcessPoolExecutor(
            max_workers=nworkers, initializer=worker_init, initargs=(os.getpid(),)
        ) as ex,
    ):
        futures: deque[tuple[Future[Any] | None, _Job]] = deque()
        upcoming = next(jobs, None)

        def submit() -> None:
            nonlocal upcoming, broken
            assert upcoming is not None
            job, upcoming = upcoming, next(jobs, None)
            fut = None  # None: parsed here
            if job.remote is not None and not broken:
                try:
                    fut = ex.submit(job.remote[0], folder, job.i, *job.remote[1:])
                except BrokenProcessPool:
                    broken = True
            futures.append((fut, job))

        first, upcoming = upcoming, next(jobs, None)
        if first is None:
            return
        while upcoming is not None and len(futures) < nworkers + 2:
            submit()
        yield from handle(first.local(), first.nbytes)
        while futures:
            fut, job = futures.popleft()
            pb = None
            if fut is not None and not broken:
                try:
                    pb = load_parsed(fut.result())
                except BrokenProcessPool:
                    broken = True
            if pb is None:
                pb = job.local()
            if upcoming is not None:
                submit()
            yield from handle(pb, job.nbytes)
    if broken:
        st.stats["pool_fallback"] += 1


def _also_in_position(
    cols: dict[str, np.ndarray], pos_seq: np.ndarray, pos_types: np.ndarray
) -> np.ndarray:
    """Per sentence type, the rows of a kind whose sentence gave a position row too (an
    RMC's ground row, an AIS VDO's ground and heading rows): counted in the position.
    Both tables are in stream order (``seq`` ascending); only rows of types the position
    table holds are looked up."""
    rows = np.flatnonzero(pos_types[cols["sentence"]])
    seq = cols["seq"][rows]
    at = np.minimum(np.searchsorted(pos_seq, seq), len(pos_seq) - 1)
    same = rows[pos_seq[at] == seq]
    return np.bincount(cols["sentence"][same].astype(np.int64), minlength=len(pos_types))


def count_by_source(
    pb: ParsedBlock,
    table: dict[str, np.ndarray],
    split_talkers: dict[str, set[int]],
    into: Counter[tuple[str, str, str]],
) -> None:
    """Add the sentences of one of a block's tables (``clock``: ZDA; a side table of
    qualifiers) to ``into`` by (source key, type, talker), the key made as for the
    block's records (TAG ``s:`` or given source, else the talker; see
    :func:`~dracc.ingest.nmea.assemble.assemble`)."""
    if not table or not len(table["seq"]):
        return
    src, tal = _source_categorical(table, pb.source_names, split_talkers, "clock")
    ns, nt, nk = len(src.categories), len(tal.categories), len(SENTENCES)
    key = (src.codes.astype(np.int64) * nk + table["sentence"].astype(np.int64)) * nt
    full = np.bincount(key + tal.codes.astype(np.int64), minlength=ns * nk * nt)
    for j in np.flatnonzero(full).tolist():
        rest, t = divmod(j, nt)
        s, k = divmod(rest, nk)
        into[(str(src.categories[s]), SENTENCES[k], str(tal.categories[t]))] += int(full[j])


def _count_qualifiers(pb: ParsedBlock, st: StreamState) -> None:
    """Count the side-table rows of sentences that gave no record (``$PSXN,20``) in
    ``st.qualifiers`` and ``st.sentences``; a side row of a sentence that did give one
    (the UTC second of an AIS report) is that sentence, counted already."""
    used = [c["seq"] for c in pb.kinds.values()]
    if pb.clock:
        used.append(pb.clock["seq"])
    seqs = np.concatenate(used) if used else np.zeros(0, np.int64)
    for table in pb.aux.values():
        if not table or not len(table["seq"]):
            continue
        alone = ~np.isin(table["seq"], seqs)
        if alone.any():
            sub = {c: v[alone] for c, v in table.items()}
            c = np.bincount(sub["sentence"].astype(np.int64), minlength=len(SENTENCES))
            st.sentences.update({SENTENCES[i]: int(c[i]) for i in np.flatnonzero(c).tolist()})
            count_by_source(pb, sub, st.split_talkers, st.qualifiers)


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
            st.split_talkers[talker_str(tk)] = {int(x) for x in u}


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
    path: str | Path,
    cfg: IngestConfig,
    progress: Callable[[int], object] | None = None,
    workers: int | None = None,
    opener: Callable[[], IO[bytes]] | None = None,
    size_hint: int | None = None,
) -> FileResult:
    """Read a whole NMEA 0183 text file into a :class:`FileResult` (frames sorted by time);
    ``opener``, ``size_hint``: from the stream it opens, ``path`` naming it
    (:func:`iter_nmea_blocks`)."""
    path = Path(path)
    if opener is None:
        check_readable(path)
    st = StreamState(str(path))
    blocks = [
        b.frames
        for b in iter_nmea_blocks(
            path, cfg, st, progress=progress, workers=workers, opener=opener, size_hint=size_hint
        )
    ]
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
