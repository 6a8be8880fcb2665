"""Memory techniques the readers share: what keeps a reader's resident memory flat as
logs grow, and gives it back when a file is done.

- :func:`trim_heap`: glibc ``malloc_trim`` and pyarrow's pool, after each file's decoding;
- :func:`mapped_columns`: output columns in one anonymous mapping, returned to the kernel
  at once when the frames are dropped.

``docs/design/process.md`` explains why each is there and what it measured.
"""

from __future__ import annotations

import mmap
import sys

import numpy as np


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


_MALLOC_TRIM = None


def mapped_columns(n: int, dtypes: list) -> list[np.ndarray]:
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
