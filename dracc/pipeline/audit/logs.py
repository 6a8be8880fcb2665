"""Choosing the night's logs, safely: dates in names, globs, hostile folder entries, hashes.

:func:`choose_logs` picks the files of a night from files and folders without ever
opening something that could block (a FIFO, a device) or following a symbolic link out
of its folder; :func:`content_sha256` fingerprints the chosen bytes (the audit is
idempotent on it).  The fleet uses the same guards (:func:`input_problem`,
:func:`outside_link`, :func:`file_sha256`).
"""

from __future__ import annotations

import datetime as dt
import hashlib
import os
import stat
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from dracc.core.errors import IngestError, NoLogsError

_DATE_FORMS = ("%Y-%m-%d", "%Y%m%d", "%Y_%m_%d")


def parse_night(text: str) -> str:
    """Validate ``YYYY-MM-DD``; returns it normalised."""
    try:
        return dt.date.fromisoformat(text).isoformat()
    except ValueError as err:
        raise IngestError(f"--date {text!r}: expected YYYY-MM-DD") from err


def yesterday_utc(now: dt.datetime | None = None) -> str:
    now = now or dt.datetime.now(dt.timezone.utc)
    return (now.date() - dt.timedelta(days=1)).isoformat()


def input_problem(path: str | Path) -> str | None:
    """Why ``path`` cannot be read as a log, or None for a regular file that can be read.

    Decided from ``stat`` alone for everything but a regular file, so nothing that could
    block is opened: opening a FIFO blocks until a writer comes, a device may never end.
    A regular file is opened without blocking (``O_NONBLOCK``), checked to still be a
    regular file and read for one byte.
    """
    path = os.fspath(path)
    try:
        st = os.stat(path)
    except FileNotFoundError:
        if os.path.islink(path):
            try:
                target = os.readlink(path)
            except OSError:
                target = "?"
            return f"is a dangling symbolic link (to {target}), not a log file"
        return "no such file"
    except OSError as err:  # a symbolic link loop, a folder on the way we may not enter
        return f"cannot read: {err.strerror or err}"
    kind = _not_regular(st.st_mode)
    if kind:
        return kind
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_NOCTTY", 0))
    except OSError as err:
        return f"cannot read: {err.strerror or err}"
    try:
        kind = _not_regular(os.fstat(fd).st_mode)  # swapped for a FIFO since the stat?
        if kind:
            return kind
        os.read(fd, 1)
    except OSError as err:
        return f"cannot read: {err.strerror or err}"
    finally:
        os.close(fd)
    return None


def _not_regular(mode: int) -> str | None:
    """What a file of ``mode`` is, when it is not a regular file (None if it is one)."""
    if stat.S_ISREG(mode):
        return None
    if stat.S_ISDIR(mode):
        return "is a directory, not a log file"
    what = (
        "a FIFO (named pipe)"
        if stat.S_ISFIFO(mode)
        else "a socket"
        if stat.S_ISSOCK(mode)
        else "a device"
        if stat.S_ISCHR(mode) or stat.S_ISBLK(mode)
        else "not a regular file"
    )
    return f"is {what}, not a log file; save the log to a file first"


def outside_link(path: Path, root: Path) -> str | None:
    """If ``path`` (found inside the folder ``root``) leads out of ``root`` through a
    symbolic link (its own, or a linked folder on the way), what it points to; else None.

    A log folder may hold links between its own files; a link to ``/etc/passwd`` or to
    another ship's folder is not followed (its first lines would be copied into the
    report as examples of rejected lines)."""
    real_root = os.path.realpath(root)
    real = os.path.realpath(path)  # never raises, not even on a loop
    if real == real_root or real.startswith(real_root.rstrip(os.sep) + os.sep):
        return None
    return real


@dataclass(frozen=True)
class LogChoice:
    """The logs chosen for a night, and the files of the folders that were left out."""

    paths: tuple[Path, ...]
    #: (path, why) per file matching the pattern that was not taken: a symbolic link
    #: leading out of its folder, a FIFO, socket or device, a dangling link
    skipped: tuple[tuple[Path, str], ...] = ()


def select_logs(inputs: Sequence[Path], night: str | None, pattern: str) -> list[Path]:
    """The log files to audit (see :func:`choose_logs`, which also says what was skipped)."""
    return list(choose_logs(inputs, night, pattern).paths)


def choose_logs(inputs: Sequence[Path], night: str | None, pattern: str) -> LogChoice:
    """The log files to audit.

    A file is taken as given.  In a folder, files matching ``pattern`` (relative glob,
    ``**`` recurses; hidden files skipped) whose path contains ``night`` as
    ``YYYY-MM-DD``, ``YYYYMMDD`` or ``YYYY_MM_DD`` (when a night is given).  Entries of a
    folder that are not regular files (FIFOs, sockets, devices, dangling links) and
    symbolic links that lead out of the folder are skipped, each with why, in
    ``skipped``; a folder entry is never opened before it is known to be a regular file.
    """
    forms = []
    if night is not None:
        d = dt.date.fromisoformat(night)
        forms = [d.strftime(f) for f in _DATE_FORMS]
    chosen: list[Path] = []
    skipped: list[tuple[Path, str]] = []
    for p in inputs:
        p = Path(p)
        if p.is_file():
            chosen.append(p)
        elif p.is_dir():
            found = []
            left_out = []
            for f in sorted(p.glob(pattern)):
                rel = f.relative_to(p)
                if any(part.startswith(".") for part in rel.parts):
                    continue
                if forms and not any(form in str(rel) for form in forms):
                    continue
                if f.name.endswith(".part"):  # dracc watch still writing it (or crashed)
                    left_out.append((f, "being written (.part): not taken"))
                    continue
                target = outside_link(f, p)
                if target is not None:
                    left_out.append(
                        (f, f"symbolic link to {target}, outside the folder {p}: not followed")
                    )
                    continue
                if f.is_dir():
                    continue
                problem = input_problem(f) if not f.is_file() else None
                if problem:
                    left_out.append((f, problem))
                    continue
                found.append(f)
            skipped.extend(left_out)
            if not found:
                what = f" for {night}" if night else ""
                also = (
                    (
                        f" ({len(left_out)} skipped: "
                        + "; ".join(f"{f.relative_to(p)}: {why}" for f, why in left_out[:3])
                        + ("; ..." if len(left_out) > 3 else "")
                        + ")"
                    )
                    if left_out
                    else ""
                )
                raise NoLogsError(f"no logs{what} matching {pattern!r} in {p}{also}")
            chosen.extend(found)
        elif os.path.lexists(p):  # a FIFO, a socket, a device, a dangling link
            raise IngestError(f"{p}: {input_problem(p) or 'not a log file'}")
        else:
            raise IngestError(f"{p}: no such file or folder")
    unique = list(dict.fromkeys(c.resolve() for c in chosen))
    if not unique:
        raise IngestError("no log files given")
    return LogChoice(tuple(unique), tuple(skipped))


def content_sha256(paths: Sequence[Path]) -> str:
    """SHA-256 over the sorted SHA-256 digests of the files: independent of names and order."""
    digests = sorted(file_sha256(p) for p in paths)
    return hashlib.sha256("\n".join(digests).encode()).hexdigest()


def file_sha256(path: Path, chunk: int = 1 << 20) -> str:
    """SHA-256 of a regular file's bytes.  Opened without blocking and checked to be a
    regular file first: a FIFO put in a log's place raises IngestError, never hangs."""
    h = hashlib.sha256()
    try:
        fd = os.open(
            os.fspath(path), os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_NOCTTY", 0)
        )
    except OSError as err:
        raise IngestError(f"{path}: cannot read: {err.strerror or err}") from err
    try:
        kind = _not_regular(os.fstat(fd).st_mode)
        if kind:
            raise IngestError(f"{path}: {kind}")
        with os.fdopen(fd, "rb", closefd=False) as fh:
            while block := fh.read(chunk):
                h.update(block)
    except OSError as err:
        raise IngestError(f"{path}: cannot read: {err.strerror or err}") from err
    finally:
        os.close(fd)
    return h.hexdigest()
