"""Atomic file writes: a temporary file in the same folder, fsync, then rename.

An interrupted run leaves either the old file or the new one, never half of one.  Inside
:func:`together`, the renames wait for the end of the block: several files (a report's
JSON, HTML and tables) then appear as one, or none of them does.
"""

from __future__ import annotations

import os
import tempfile
from contextlib import contextmanager
from contextvars import ContextVar
from pathlib import Path

#: (temporary, target) renames waiting for the end of the innermost ``together`` block
_PENDING: ContextVar[list[tuple[Path, Path]] | None] = ContextVar("dracc_atomic_pending", default=None)


def _discard(tmp: Path) -> None:
    try:
        os.unlink(tmp)
    except FileNotFoundError:
        pass


@contextmanager
def together():
    """Files written atomically inside this block appear together at its end.

    Each is written and synced to its temporary file as usual; the renames onto the
    targets wait until the block ends without an exception and then follow each other
    (milliseconds, where rendering the files took seconds).  On any exception, including
    KeyboardInterrupt, every temporary file is removed and every target left as it was.
    """
    pending: list[tuple[Path, Path]] = []
    token = _PENDING.set(pending)
    try:
        yield
    except BaseException:
        for tmp, _ in pending:
            _discard(tmp)
        raise
    finally:
        _PENDING.reset(token)
    for k, (tmp, path) in enumerate(pending):
        try:
            os.replace(tmp, path)
        except BaseException:
            for left, _ in pending[k:]:
                _discard(left)
            raise


@contextmanager
def atomic_path(path: str | Path):
    """Yield a temporary path beside ``path``; on success rename it onto ``path`` (at the
    end of the enclosing :func:`together` block, if any).

    On any exception (including KeyboardInterrupt) the temporary file is removed
    and ``path`` is left untouched.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".part", dir=path.parent)
    os.close(fd)
    # mkstemp creates 0600; a report should get the mode any new file gets (umask).
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o666 & ~umask)
    try:
        yield Path(tmp)
        with open(tmp, "rb+") as fh:
            os.fsync(fh.fileno())
    except BaseException:
        _discard(Path(tmp))
        raise
    pending = _PENDING.get()
    if pending is not None:  # inside ``together``: renamed at the end of the block
        pending.append((Path(tmp), path))
    else:
        os.replace(tmp, path)


def write_text(path: str | Path, text: str, encoding: str = "utf-8") -> None:
    """Write ``text`` to ``path`` atomically."""
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding=encoding)


def write_bytes(path: str | Path, data: bytes) -> None:
    """Write ``data`` to ``path`` atomically."""
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)
