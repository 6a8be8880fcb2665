"""Memory techniques the readers share: what keeps a reader's resident memory flat as
logs grow, and gives it back when a file is done.

- :func:`trim_heap`: glibc ``malloc_trim`` and pyarrow's pool, after each file's decoding;
- :func:`mapped_columns`: output columns in one anonymous mapping, returned to the kernel
  at once when the frames are dropped;
- the file hand-over between processes: a worker writes an object's buffers to a file in
  shared memory (:func:`handover_dir`, :func:`write_handover`) and the reader maps them
  copy-on-write (:func:`load_handover`) instead of receiving them through a pipe; folders
  left by a reader that was killed are removed by the next (:func:`sweep_handover`).

``docs/design/process.md`` explains why each is there and what it measured.
"""

from __future__ import annotations

import contextlib
import mmap
import os
import pickle
import sys
import tempfile
from typing import Any

import numpy as np
from numpy.typing import DTypeLike


def trim_heap() -> None:
    """Give the free memory of the C heap (glibc ``malloc_trim``) and of pyarrow's pool
    back to the kernel.  Freed blocks in the middle of the heap otherwise stay in the
    process, and their amount drifts with the file: a few tens of MiB of decoding
    buffers would sit beside the frames.  Without glibc only pyarrow's pool is trimmed."""
    global _MALLOC_TRIM
    if _MALLOC_TRIM is None:
        try:
            import ctypes

            _MALLOC_TRIM = ctypes.CDLL(None).malloc_trim
        except (OSError, AttributeError, TypeError):  # pragma: no cover - not glibc
            _MALLOC_TRIM = False
    if _MALLOC_TRIM:
        _MALLOC_TRIM(0)
    if "pyarrow" in sys.modules:  # the JSON parser's buffers (arrow's own allocator keeps them)
        sys.modules["pyarrow"].default_memory_pool().release_unused()


_MALLOC_TRIM: Any = None


def mapped_columns(n: int, dtypes: list[DTypeLike]) -> list[np.ndarray]:
    """Uninitialised arrays of ``n`` items, one per dtype, together in one anonymous
    memory mapping: when all of them are garbage the pages go back to the kernel at once
    (a freed malloc block of a few hundred KiB usually stays in the heap, so a run's
    memory would outlive the run).  Pages count towards the RSS only once written.
    Plain arrays where there is no anonymous mmap (not POSIX) or the kernel refuses one
    (e.g. too many mappings)."""
    dts = [np.dtype(d) for d in dtypes]
    offs, size = [], 0
    for dt in dts:
        offs.append(size)
        size += -(-n * dt.itemsize // 64) * 64  # each column 64-byte aligned
    flags = getattr(mmap, "MAP_PRIVATE", None)
    anon = getattr(mmap, "MAP_ANONYMOUS", None)
    if flags is not None and anon is not None and size > 0:
        try:
            mm = mmap.mmap(-1, size, flags=flags | anon)
        except OSError:  # pragma: no cover - the kernel's mapping limit
            mm = None
        if mm is not None:
            return [
                np.frombuffer(mm, dtype=dt, count=n, offset=o)
                for dt, o in zip(dts, offs, strict=True)
            ]
    return [np.empty(n, dtype=dt) for dt in dts]


HANDOVER_PREFIX = "dracc-ingest-"


def handover_dir(
    needed_bytes: int,
) -> tempfile.TemporaryDirectory[str] | contextlib.nullcontext[None]:
    """Where workers leave parsed blocks for the main process: shared memory (tmpfs), else
    the temporary directory, whichever has room for ``needed_bytes`` (a reader of a whole
    file keeps its blocks until the end; a container's /dev/shm may hold only 64 MB); a
    context giving None where neither has: the blocks then come through the pool's pipe.
    The folder's name carries this process's id: folders left by a reader that was killed
    (SIGKILL cannot be caught) are removed by the next reader (:func:`sweep_handover`)."""
    for base in ("/dev/shm", tempfile.gettempdir()):
        try:
            st = os.statvfs(base)
        except OSError:
            continue
        if os.access(base, os.W_OK):
            sweep_handover(base)
            if st.f_bavail * st.f_frsize >= needed_bytes:
                return tempfile.TemporaryDirectory(
                    prefix=f"{HANDOVER_PREFIX}{os.getpid()}-", dir=base
                )
    return contextlib.nullcontext(None)


def pid_folder(prefix: str, base: str | None = None) -> tempfile.TemporaryDirectory[str]:
    """A temporary folder in ``base`` (default: the temporary directory) named
    ``<prefix><pid>-<random>``, removed on exit; the folders of that prefix left by a
    process that is gone (killed: SIGKILL cannot be caught) are removed first
    (:func:`sweep_handover`).  Where dracc copies a log it reads (a compressed log, a
    Signal K or gpsd log's NMEA lines)."""
    where = tempfile.gettempdir() if base is None else base
    sweep_handover(where, prefix)
    return tempfile.TemporaryDirectory(prefix=f"{prefix}{os.getpid()}-", dir=where)


def sweep_handover(base: str, prefix: str = HANDOVER_PREFIX) -> None:
    """Remove the folders ``<prefix><pid>-...`` in ``base`` of this user whose process
    is gone (hand-over folders by default)."""
    import shutil

    try:
        names = [n for n in os.listdir(base) if n.startswith(prefix)]
    except OSError:
        return
    for name in names:
        parts = name[len(prefix) :].split("-", 1)
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


def write_handover(obj: Any, name: str) -> tuple[bytes, list[int], str] | None:
    """``obj`` pickled with its buffers out of band (protocol 5), the buffers written to
    the file ``name`` (in a folder of :func:`handover_dir`): returns (the pickle without
    its buffers, the buffers' sizes, the file) for :func:`load_handover`; None where the
    file cannot be written (a full disk), and then no file is left."""
    buffers: list[pickle.PickleBuffer] = []
    meta = pickle.dumps(obj, protocol=5, buffer_callback=buffers.append)
    views = [b.raw() for b in buffers]
    try:
        with open(name, "wb") as fh:
            for v in views:
                fh.write(v)
    except OSError:
        with contextlib.suppress(OSError):
            os.unlink(name)
        return None
    return meta, [v.nbytes for v in views], name


def load_handover(handed: tuple[bytes, list[int], str]) -> Any:
    """The object :func:`write_handover` left in a file: its buffers are views of the file
    mapped copy-on-write (no copy; the pages are already in memory) and the file is
    removed at once: the mapping lives as long as the views do."""
    meta, sizes, name = handed
    with open(name, "rb") as fh:
        whole = (
            memoryview(mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_COPY)) if sum(sizes) else None
        )
    os.unlink(name)
    views, at = [], 0
    for size in sizes:
        views.append(whole[at : at + size])  # type: ignore[index]
        at += size
    return pickle.loads(meta, buffers=views)
