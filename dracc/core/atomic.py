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

These names are dracc's own: a link planted in their place is replaced, never followed
(``OUT/.runs`` must be a folder, :func:`own_folder`; issue 33).

A write that fails for a reason of the disk or the folder (full, read-only, not allowed,
a file where a folder is to be, or the reverse) raises :class:`~dracc.core.errors.OutputError`
(one line naming the output and why, exit 6) after the temporary files are removed;
:func:`output_error` is that rule, for the writes made elsewhere.
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

from dracc.core.errors import OutputError

#: (temporary, target) renames waiting for the end of the innermost ``together`` block
_PENDING: ContextVar[list[tuple[Path, Path]] | None] = ContextVar(
    "dracc_atomic_pending", default=None
)


def _discard(tmp: Path) -> None:
    with suppress(FileNotFoundError):
        os.unlink(tmp)


# ------------------------------------------------------------------ write faults

#: what a disk or a folder answers a write it refuses (not a bug; not an input's fault)
_WRITE_ERRNOS = frozenset(
    {
        errno.ENOSPC, errno.EDQUOT, errno.EFBIG, errno.EROFS, errno.EACCES, errno.EPERM,
        errno.EISDIR, errno.ENOTDIR, errno.EEXIST, errno.ENAMETOOLONG, errno.ELOOP, errno.EIO,
        errno.ENOENT, errno.EMLINK, errno.ETXTBSY,
    }
)  # fmt: skip
_REASONS = {
    errno.ENOSPC: "no space left on the device (disk full)",
    errno.EDQUOT: "disk quota exceeded",
    errno.EFBIG: "file too large (for the file system, or the process's size limit)",
    errno.EROFS: "read-only file system",
    errno.EACCES: "permission denied",
    errno.EPERM: "operation not permitted",
}


def _blocker(named: Path) -> Path:
    """The file that stands where a folder is needed on the way to ``named``."""
    for p in (named, *named.parents):
        if os.path.lexists(p) and not p.is_dir():
            return p
    return named


def _near(named: Path, within: Path) -> bool:
    """``named`` is ``within``, in it, or on the way to it."""
    return named == within or within in named.parents or named in within.parents


def output_error(target: object, err: OSError, within: Path | None = None) -> OutputError | None:
    """The one line for ``err``, raised while writing ``target`` (a path, or words such as
    "the reports"); None when ``err`` is not the output's fault: an errno no disk or
    folder gives, or (``within``: the folder the output's files go to) one naming a file
    neither in ``within`` nor on the way to it (an input read while writing)."""
    if err.errno not in _WRITE_ERRNOS:
        return None
    named = Path(os.fsdecode(err.filename)) if err.filename is not None else None
    if named is not None and within is not None and not _near(named, within):
        return None
    if err.errno == errno.EISDIR:
        folder = err.filename2 if err.filename2 is not None else err.filename
        why = _in_the_way(target, folder, "a folder, not a file")
    elif err.errno in (errno.ENOTDIR, errno.EEXIST) and named is not None:
        why = _in_the_way(target, _blocker(named), "a file, not a folder")
    else:
        why = _REASONS.get(err.errno or 0) or err.strerror or str(err)
        if named is not None and within is not None and named in within.parents:
            why = f"{named}: {why}"  # the folder that refused, not the output itself
    return OutputError(f"cannot write {target}: {why}")


def _in_the_way(target: object, where: str | bytes | Path | None, what: str) -> str:
    if where is None or Path(os.fsdecode(where)) == Path(str(target)):
        return f"it is {what}"
    return f"{os.fsdecode(where)} is {what}"


@contextmanager
def faults_of(target: object, within: Path | None = None) -> Iterator[None]:
    """Inside this block an ``OSError`` that :func:`output_error` calls the output's fault
    becomes that :class:`OutputError`; any other passes unchanged."""
    try:
        yield
    except OSError as err:
        converted = output_error(target, err, within)
        if converted is None:
            raise
        raise converted from err


def make_folder(path: str | Path, target: object = None) -> Path:
    """``mkdir -p path``; a folder that cannot be made is an :class:`OutputError` (naming
    ``target``, the output it was for, or else ``path``)."""
    path = Path(path)
    with faults_of(path if target is None else target, path):
        path.mkdir(parents=True, exist_ok=True)
    return path


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
            with faults_of(path, path.parent):
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

    A write the disk or the folder refuses is an :class:`OutputError` (:func:`output_error`),
    raised once the temporary file is removed.
    """
    path = Path(path)
    try:
        mode = os.stat(path).st_mode
    except OSError:
        mode = None
    if mode is not None and not stat.S_ISREG(mode) and not stat.S_ISDIR(mode):
        with faults_of(path, path.parent):
            yield path
        return
    if mode is not None and stat.S_ISDIR(mode):  # found now, not after the work is done
        raise OutputError(f"cannot write {path}: it is a folder, not a file")
    with faults_of(path, path.parent):
        make_folder(path.parent, path)
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".part", dir=path.parent)
        os.close(fd)
        try:
            # mkstemp creates 0600; a report should get the mode any new file gets (umask).
            os.chmod(tmp, 0o666 & ~_umask())
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
    written by a live process.  Nothing is removed where ``runs`` has become a link
    meanwhile (:func:`own_folder`); a link inside it is removed, never followed."""
    if not stat.S_ISDIR(os.lstat(runs).st_mode):
        return
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
        if os.path.islink(runs / entry):
            _discard(runs / entry)  # the link, never what it leads to
        else:
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

    A write the disk or the folder refuses is an :class:`OutputError` naming ``folder``.
    """
    folder = Path(folder)
    with faults_of(folder, folder):
        yield from _file_set(folder, published)


def own_folder(path: str | Path) -> Path:
    """``path``, made if missing (``mkdir -p``), checked to be a folder of its own and not
    a symbolic link: a link planted there (``OUT/.runs -> ~``) would take dracc's writes,
    and its removal of old sets, out of the output folder (issue 33).  Anything else is an
    :class:`OutputError` saying what is in the way."""
    path = Path(path)
    try:
        mode = os.lstat(path).st_mode
    except FileNotFoundError:
        path.mkdir(parents=True, exist_ok=True)
        mode = os.lstat(path).st_mode
    if stat.S_ISDIR(mode):
        return path
    what = f"a symbolic link (to {os.readlink(path)})" if stat.S_ISLNK(mode) else "not a folder"
    raise OutputError(
        f"cannot write {path.parent}: {path} is {what}, not dracc's own folder; "
        "dracc follows no link there: remove it"
    )


def _file_set(folder: Path, published: list[str] | None) -> Iterator[Path]:
    runs = own_folder(folder / RUNS)
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
