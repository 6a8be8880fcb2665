"""The recording of what was heard: each line with its receive time, as TAG-block NMEA
0183 (the IEC 61162-450 form every dracc reader reads), in daily files.

A line is written as ``\\c:<unix ms>,s:<source>*hh\\<line>`` (``s:`` only where a source
is given; ``hh`` the XOR of the bytes between the backslash and the ``*``, IEC 61162-450
§7.3.2).  A line that already has a TAG block keeps it: where it has no ``c:`` and its
checksum is right, ``c:`` is put first in it and the checksum made anew; otherwise (a
``c:`` there, or a wrong checksum that must stay wrong) the line is written as received.
Lines that are not sentences (``#`` comments, a logger's prefix) are written as received.

Files: ``DIR/dracc-YYYYMMDD.nmea.part`` while written (the UTC day of the receive
times), then ``dracc-YYYYMMDD-1.nmea.part`` and so on when one reaches ``max_bytes``;
a new file at each UTC midnight (of the receive times, or of the clock in :meth:`tick`
when nothing arrives).  A finished file is flushed, fsynced and renamed to drop
``.part`` (then the folder fsynced), so a reader of ``DIR`` sees whole files only.
Writes go through a buffered file flushed every ``flush_s`` seconds or ``flush_lines``
lines: memory is bounded whatever the rate.  ``.part`` files left by a crash are
finished when a :class:`Recorder` opens the folder (cut after their last line end).
"""

from __future__ import annotations

import contextlib
import datetime as dt
import os
import re
import time
from collections.abc import Callable
from functools import reduce
from operator import xor
from pathlib import Path
from typing import BinaryIO

from dracc.core.errors import IngestError

#: a recording file reaching this size is finished and the next one begun
MAX_BYTES = 256 * 1024 * 1024
FLUSH_S = 1.0  #: the buffered file is flushed at least this often ...
FLUSH_LINES = 10_000  #: ... and after this many lines
_NAME = re.compile(r"^dracc-(\d{8})(?:-(\d+))?\.nmea(\.part)?$")
#: bytes a TAG ``s:`` value may not hold (they end the parameter, the block or the line)
_SOURCE_BAD = re.compile(r"[^!-~]|[,*\\$]")
_HEX = re.compile(rb"^[0-9A-Fa-f]{1,2}$")


def checksum(body: bytes) -> int:
    """The NMEA / TAG-block checksum: the XOR of the bytes."""
    return reduce(xor, body, 0)


def tag_line(line: bytes, recv_ns: int, source: str | None = None) -> bytes:
    """``line`` as recorded (without its line end): with a TAG block carrying its receive
    time in milliseconds (and ``source``), as the module docstring says."""
    ms = recv_ns // 1_000_000
    if source:
        source = _SOURCE_BAD.sub("_", source)
    if line[:1] in (b"$", b"!"):
        b = (f"c:{ms},s:{source}" if source else f"c:{ms}").encode("ascii")
        return b"\\%s*%02X\\%s" % (b, checksum(b), line)
    if line[:1] != b"\\":
        return line
    end = line.find(b"\\", 1)
    star = line.rfind(b"*", 1, end)
    if end < 0 or star < 0 or not _HEX.match(line[star + 1 : end]):
        return line
    old = line[1:star]
    if int(line[star + 1 : end], 16) != checksum(old):
        return line  # a wrong checksum stays wrong
    if any(p.startswith(b"c:") for p in old.split(b",")):
        return line
    b = b"c:%d,%s" % (ms, old)
    return b"\\%s*%02X%s" % (b, checksum(b), line[end:])


def _day(ns: int) -> str:
    return (dt.datetime(1970, 1, 1) + dt.timedelta(microseconds=ns // 1000)).strftime("%Y%m%d")


class Recorder:
    """Received lines written to daily TAG-block NMEA files in ``folder`` (see the module
    docstring).  ``write(line, recv_ns=None, source=None)`` per line; ``tick()`` now and
    then (it flushes, and finishes yesterday's file at midnight); ``close()`` finishes
    the current file.  ``now_ns`` is the clock (injected by tests)."""

    def __init__(
        self,
        folder: str | Path,
        max_bytes: int = MAX_BYTES,
        now_ns: Callable[[], int] = time.time_ns,
        flush_s: float = FLUSH_S,
        flush_lines: int = FLUSH_LINES,
    ) -> None:
        self.folder = Path(folder)
        try:
            self.folder.mkdir(parents=True, exist_ok=True)
        except OSError as err:
            raise IngestError(f"{folder}: {err.strerror}") from err
        self.max_bytes = max_bytes
        self.now_ns = now_ns
        self.flush_ns = int(flush_s * 1e9)
        self.flush_lines = flush_lines
        self.files: list[Path] = []  #: finished files, in order
        self.recovered: list[Path] = []  #: ``.part`` files of an earlier run, finished
        self.lines = 0  #: lines written
        self._fh: BinaryIO | None = None
        self._part: Path | None = None
        self._file_day = ""
        self._size = 0
        self._unflushed = 0
        self._last_flush = now_ns()
        self._recover()

    # -- files -------------------------------------------------------------------------
    def _recover(self) -> None:
        for part in sorted(self.folder.glob("dracc-*.nmea.part")):
            data = part.read_bytes()
            cut = max(data.rfind(b"\n"), data.rfind(b"\r")) + 1
            with open(part, "r+b") as fh:
                fh.truncate(cut)
                fh.flush()
                os.fsync(fh.fileno())
            if cut == 0:
                part.unlink()
                continue
            final = part.with_suffix("")
            m = _NAME.match(part.name)
            if final.exists() and m:
                final = self._free_name(m.group(1))
            os.rename(part, final)
            self.recovered.append(final)
        self._sync_folder()

    def _free_name(self, day: str) -> Path:
        """The first name of ``day`` neither finished nor being written."""
        n = 0
        while True:
            name = f"dracc-{day}.nmea" if n == 0 else f"dracc-{day}-{n}.nmea"
            p = self.folder / name
            if not p.exists() and not p.with_name(name + ".part").exists():
                return p
            n += 1

    def _begin(self, day: str) -> None:
        final = self._free_name(day)
        self._part = final.with_name(final.name + ".part")
        self._fh = open(self._part, "xb", buffering=1 << 16)  # noqa: SIM115 - kept open
        self._file_day = day
        self._size = 0

    def _finish(self) -> None:
        if self._fh is None or self._part is None:
            return
        self._fh.flush()
        os.fsync(self._fh.fileno())
        self._fh.close()
        final = self._part.with_suffix("")
        os.rename(self._part, final)
        self._sync_folder()
        self.files.append(final)
        self._fh = None
        self._part = None
        self._unflushed = 0

    def _sync_folder(self) -> None:
        with contextlib.suppress(OSError):
            fd = os.open(self.folder, os.O_RDONLY)
            try:
                os.fsync(fd)
            finally:
                os.close(fd)

    @property
    def current(self) -> Path | None:
        """The ``.part`` file being written (None between files)."""
        return self._part

    # -- writing -----------------------------------------------------------------------
    def write(self, line: bytes, recv_ns: int | None = None, source: str | None = None) -> None:
        """Record one received line (without its line end) and its receive time
        (``now_ns()`` if None)."""
        if recv_ns is None:
            recv_ns = self.now_ns()
        data = tag_line(line, recv_ns, source) + b"\r\n"
        day = _day(recv_ns)
        if self._fh is not None and (
            day != self._file_day or (self._size and self._size + len(data) > self.max_bytes)
        ):
            self._finish()
        if self._fh is None:
            self._begin(day)
        assert self._fh is not None
        self._fh.write(data)
        self._size += len(data)
        self.lines += 1
        self._unflushed += 1
        if self._unflushed >= self.flush_lines:
            self.flush()

    def write_many(self, lines: list[tuple[int, bytes]], source: str | None = None) -> None:
        """Record ``(recv_ns, line)`` pairs (what a live source's ``poll`` returns), then
        :meth:`tick`."""
        for recv_ns, line in lines:
            self.write(line, recv_ns, source)
        self.tick()

    def flush(self) -> None:
        """Hand the buffered lines to the operating system (no fsync: that is at the end
        of each file)."""
        if self._fh is not None:
            self._fh.flush()
        self._unflushed = 0
        self._last_flush = self.now_ns()

    def tick(self) -> None:
        """Flush if ``flush_s`` has passed; finish the current file once the clock is past
        its UTC day."""
        now = self.now_ns()
        if self._fh is not None and _day(now) > self._file_day:
            self._finish()
        elif now - self._last_flush >= self.flush_ns:
            self.flush()

    def close(self) -> None:
        """Finish the current file (flush, fsync, rename)."""
        self._finish()

    def __enter__(self) -> Recorder:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
