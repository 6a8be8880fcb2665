"""Atomic file writes: a temporary file in the same folder, fsync, then rename.

An interrupted run leaves either the old file or the new one, never half of one.  Inside
:func:`together`, the renames wait for the end of the block: several files (a report's
JSON, HTML and tables) then appear as one, or none of them does.

:func:`file_set` goes further for a whole set of outputs in one folder (the fleet
tables): the set is built in a staging folder and published by one ``rename(2)`` of a
symbolic link, so that even a SIGKILL or a power cut at any moment leaves the complete
previous set or the complete new one::

    OUT/fleet.csv   -> .current/fleet.csv       (one link per output, made once)
    OUT/vessels     -> .current/vessels
    OUT/.current    -> .runs/set-<time>-<id>    (replaced atomically to publish)
    OUT/.runs/set-<time>-<id>/fleet.csv ...     (the sets: the current and the previous one)
"""

from __future__ import annotations

import errno
import os
import secrets
import shutil
import signal
import stat
import tempfile
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager, suppress
from contextvars import ContextVar
from pathlib import Path
from types import FrameType
from typing import Any

#: (temporary, target) renames waiting for the end of the innermost ``together`` block
_PENDING: ContextVar[list[tuple[Path, Path]] | None] = ContextVar(
    "dracc_atomic_pending", default=None
)


def _discard(tmp: Path) -> None:
    with suppress(FileNotFoundError):
        os.unlink(tmp)


@contextmanager
def together() -> Iterator[None]:
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
def atomic_path(path: str | Path) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; on success rename it onto ``path`` (at the
    end of the enclosing :func:`together` block, if any).

    On any exception (including KeyboardInterrupt) the temporary file is removed
    and ``path`` is left untouched.

    A target that exists and is neither a regular file nor a folder (``/dev/null``,
    ``/dev/stdout``, a FIFO) is yielded as it is and written in place: renaming a file
    onto it would replace the device itself (as root, ``--json /dev/null`` turned
    ``/dev/null`` into a regular file for every program on the machine).
    """
    path = Path(path)
    try:
        mode = os.stat(path).st_mode
    except OSError:
        mode = None
    if mode is not None and not stat.S_ISREG(mode) and not stat.S_ISDIR(mode):
        yield path
        return
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


# ------------------------------------------------------------------ sets of files

#: inside a folder published by :func:`file_set`: the sets, and the link to the current one
RUNS = ".runs"
CURRENT = ".current"


def _umask() -> int:
    umask = os.umask(0)
    os.umask(umask)
    return umask


def _fsync_dir(path: Path) -> None:
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0))
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:  # some file systems cannot sync a folder
        pass
    finally:
        os.close(fd)


def _sync_tree(root: Path) -> None:
    """fsync every file and folder under ``root`` (files first, the folders after)."""
    for here, dirs, files in os.walk(root):
        for name in files:
            p = os.path.join(here, name)
            if not os.path.islink(p):
                with open(p, "rb") as fh:
                    os.fsync(fh.fileno())
        for name in dirs:
            _fsync_dir(Path(here) / name)
    _fsync_dir(root)


@contextmanager
def deferred_signals() -> Iterator[list[int]]:
    """SIGINT and SIGTERM that arrive inside the block are held until its end, then acted
    on as they would have been (a short critical section: a few renames).  Outside the
    main thread Python cannot change handlers; the block then defers nothing."""
    held: list[int] = []
    if threading.current_thread() is not threading.main_thread():
        yield held
        return
    sigs = [signal.SIGINT, signal.SIGTERM]
    old: dict[int, Callable[[int, FrameType | None], Any] | int | None] = {
        s: signal.getsignal(s) for s in sigs
    }
    for s in sigs:
        signal.signal(s, lambda signum, _frame: held.append(signum))
    try:
        yield held
    finally:
        for s in sigs:
            signal.signal(s, old[s])
        for signum in held[:1]:
            handler = old[signum]
            if callable(handler):
                handler(signum, None)
            elif handler == signal.SIG_DFL:
                if signum == signal.SIGINT:
                    raise KeyboardInterrupt
                os.kill(os.getpid(), signum)


def current_set(folder: str | Path) -> str | None:
    """The name of the set ``folder/.current`` points to (None when nothing is published
    through a link)."""
    try:
        return os.path.basename(os.readlink(Path(folder) / CURRENT))
    except OSError:
        return None


def _link(target: str, where: Path) -> None:
    """Make ``where`` a symbolic link to ``target``, atomically (a new link renamed onto it)."""
    tmp = where.parent / f".{where.name}.{secrets.token_hex(4)}.link"
    os.symlink(target, tmp)
    try:
        os.replace(tmp, where)
    except BaseException:
        _discard(tmp)
        raise


def _symlinks_work(folder: Path) -> bool:
    probe = folder / f".probe.{secrets.token_hex(4)}.link"
    try:
        os.symlink(CURRENT, probe)
    except (OSError, NotImplementedError):
        return False
    _discard(probe)
    return True


def _link_or_copy(src: str, dst: str) -> None:
    try:
        os.link(src, dst)
    except OSError:
        shutil.copy2(src, dst)


def _adopt(folder: Path, names: list[str]) -> None:
    """Outputs an older dracc wrote as plain files (no ``.current`` yet) become a set of
    their own, with the same bytes (hard links), and each name a link into it: at every
    step ``folder`` still shows the complete old set."""
    runs = folder / RUNS
    plain = [n for n in names if os.path.lexists(folder / n) and not os.path.islink(folder / n)]
    if not plain:
        return
    if os.path.lexists(folder / CURRENT):
        legacy = None  # already published through links: a plain file put there by hand
    else:
        legacy = runs / f"legacy-{secrets.token_hex(4)}"
        legacy.mkdir()
        for n in plain:
            src = folder / n
            if src.is_dir():
                shutil.copytree(src, legacy / n, symlinks=True, copy_function=_link_or_copy)
            else:
                _link_or_copy(str(src), str(legacy / n))
        _sync_tree(legacy)
        _link(os.path.join(RUNS, legacy.name), folder / CURRENT)
    for n in plain:
        src = folder / n
        if src.is_dir() and not src.is_symlink():
            # a folder cannot be replaced by a link in one rename: moved aside, then the
            # link put in its place (the only moment the name is missing, once per folder)
            os.rename(src, runs / f"old-{secrets.token_hex(4)}")
        _link(os.path.join(CURRENT, n), src)
    _fsync_dir(folder)


def _collect(runs: Path, keep: set[str]) -> None:
    """Remove the sets and staging folders nobody needs: not ``keep``, and not being
    written by a live process."""
    for entry in os.listdir(runs):
        if entry in keep:
            continue
        if entry.startswith("tmp-"):
            try:
                pid = int(entry.split("-")[1])
            except (IndexError, ValueError):
                pid = 0
            if pid and pid != os.getpid() and _alive(pid):
                continue
        shutil.rmtree(runs / entry, ignore_errors=True)


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


@contextmanager
def file_set(folder: str | Path, published: list[str] | None = None) -> Iterator[Path]:
    """Yield a staging folder; the files written into it replace the set published in
    ``folder`` as one, at the end of the block.

    Each top-level name of the staging folder (a file, or a folder of files) appears in
    ``folder`` under that name.  On any exception, KeyboardInterrupt included, the staging
    folder is removed and ``folder`` left as it was.  Publishing is one ``rename(2)`` of
    the ``.current`` link (see the module's docstring): a reader, a SIGKILL or a power
    cut sees the previous set or the new one, whole.  Where the file system has no
    symbolic links, the outputs are renamed into place one after the other with SIGINT
    and SIGTERM held (milliseconds; only a SIGKILL in them could mix the sets).

    ``published``, if given, gets the new set's name appended in the same critical
    section as the publishing step: an interrupt handler that finds it empty knows that
    ``folder`` still holds the previous set, and otherwise that it holds the new one.
    """
    folder = Path(folder)
    runs = folder / RUNS
    runs.mkdir(parents=True, exist_ok=True)
    stage = Path(tempfile.mkdtemp(prefix=f"tmp-{os.getpid()}-", dir=runs))
    os.chmod(stage, 0o777 & ~_umask())  # mkdtemp makes 0700; outputs get the usual mode
    try:
        yield stage
        _sync_tree(stage)
        final = runs / f"set-{time.time_ns()}-{secrets.token_hex(4)}"
        os.rename(stage, final)
        _fsync_dir(runs)
    except BaseException:
        shutil.rmtree(stage, ignore_errors=True)
        raise
    names = sorted(os.listdir(final))
    flag = published if published is not None else []
    if os.path.islink(folder / CURRENT) or _symlinks_work(folder):
        _publish_by_link(folder, final, names, flag)
    else:
        _publish_by_renames(folder, final, names, flag)


def _publish_by_link(folder: Path, final: Path, names: list[str], flag: list[str]) -> None:
    runs = folder / RUNS
    _adopt(folder, names)
    for n in names:  # links made once; they lead to nothing until the first set is current
        where = folder / n
        if not (os.path.islink(where) and os.readlink(where) == os.path.join(CURRENT, n)):
            _link(os.path.join(CURRENT, n), where)
    previous = current_set(folder)
    with deferred_signals():
        _link(os.path.join(RUNS, final.name), folder / CURRENT)  # the one step that publishes
        flag.append(final.name)
        _fsync_dir(folder)
    # what the new set no longer has: its link would lead nowhere
    for entry in os.listdir(folder):
        p = folder / entry
        if (
            entry not in names
            and os.path.islink(p)
            and os.readlink(p) == os.path.join(CURRENT, entry)
        ):
            _discard(p)
    _collect(runs, {final.name, *([previous] if previous else [])})


def _publish_by_renames(folder: Path, final: Path, names: list[str], flag: list[str]) -> None:
    runs = folder / RUNS
    with deferred_signals():
        for n in names:
            src, dst = final / n, folder / n
            if src.is_dir() and dst.is_dir() and not dst.is_symlink():
                os.rename(dst, runs / f"old-{secrets.token_hex(4)}")
            try:
                os.replace(src, dst)
            except OSError as err:  # pragma: no cover - a folder where a file was, or the reverse
                if err.errno not in (errno.EISDIR, errno.ENOTDIR, errno.ENOTEMPTY, errno.EEXIST):
                    raise
                os.rename(dst, runs / f"old-{secrets.token_hex(4)}")
                os.replace(src, dst)
        flag.append(final.name)
        _fsync_dir(folder)
    _collect(runs, set())
