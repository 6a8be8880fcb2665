"""The reader's worker processes: whether this process may start them, their set-up
(they die with their parent, keep their freed memory), and a block parsed in a worker
and handed over as a file (:func:`parse_range_to_file`, :func:`load_parsed`; the
technique itself is in :mod:`dracc.ingest.memory`)."""

from __future__ import annotations

import os

from dracc.ingest.memory import load_handover, write_handover
from dracc.ingest.nmea.blocks import parse_range
from dracc.ingest.nmea.engine_c import parse_buffer
from dracc.ingest.nmea.parsed import ParsedBlock
from dracc.ingest.nmea.sentences import MAX_LINE_BYTES


def pool_ok() -> bool:
    """Two cores, and a process that may start children: a daemonic process (a Dask
    worker, a multiprocessing.Pool worker) may not, so there the reader parses alone."""
    import multiprocessing

    return (os.cpu_count() or 1) >= 2 and not multiprocessing.current_process().daemon


def worker_init(parent_pid: int | None = None) -> None:
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


def parse_range_to_file(
    folder: str | None,
    i: int,
    path: str,
    off: int,
    length: int,
    ignore_checksum: bool,
    at_eof: bool,
    max_line_bytes: int = MAX_LINE_BYTES,
) -> ParsedBlock | tuple[bytes, list[int], str]:
    """:func:`~dracc.ingest.nmea.blocks.parse_range` in a worker, its arrays written to a
    file in ``folder`` (:func:`~dracc.ingest.memory.write_handover`).

    A block's arrays (about 1.3x its text) sent through the pool's pipe cost the worker
    more than parsing them (64 KiB at a time, each a switch to the reader); written to
    a file they are two copies.  Returns (pickle of the block without its arrays, the
    arrays' sizes, the file) for :func:`load_parsed`; or the block itself where there is
    no folder or the file cannot be written (a full disk): it then goes through the pipe."""
    pb = parse_range(path, off, length, ignore_checksum, at_eof, max_line_bytes)
    if folder is None:
        return pb
    handed = write_handover(pb, os.path.join(folder, f"block-{i}"))
    return pb if handed is None else handed


def parse_bytes_to_file(
    folder: str | None,
    i: int,
    data: bytes,
    ignore_checksum: bool,
    at_eof: bool,
    max_line_bytes: int = MAX_LINE_BYTES,
) -> ParsedBlock | tuple[bytes, list[int], str]:
    """:func:`parse_range_to_file` of a piece of a stream (its bytes sent to the worker)."""
    pb = parse_buffer(
        data, ignore_checksum=ignore_checksum, at_eof=at_eof, max_line_bytes=max_line_bytes
    )
    if folder is None:
        return pb
    handed = write_handover(pb, os.path.join(folder, f"block-{i}"))
    return pb if handed is None else handed


def load_parsed(handed: ParsedBlock | tuple[bytes, list[int], str]) -> ParsedBlock:
    """The block a worker handed over (:func:`parse_range_to_file`).  From a file, its
    arrays are views of the file mapped copy-on-write (no copy; the pages are already in
    memory) and the file is removed at once (:func:`~dracc.ingest.memory.load_handover`):
    the mapping lives as long as the arrays do."""
    if isinstance(handed, ParsedBlock):
        return handed
    pb: ParsedBlock = load_handover(handed)
    return pb
