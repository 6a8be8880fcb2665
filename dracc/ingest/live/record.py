"""The recording of what was heard, in daily files: NMEA 0183 lines with their receive
times as TAG-block NMEA 0183 (the IEC 61162-450 form every dracc reader reads), NMEA
2000 and Signal K lines as received, each form in its own file.

A sentence is written as ``\\c:<unix ms>,s:<source>*hh\\<line>`` (``s:`` only where a
source is given; ``hh`` the XOR of the bytes between the backslash and the ``*``, IEC
61162-450 §7.3.2).  A line that already has a TAG block keeps it: where it has no ``c:``
and its checksum is right, ``c:`` is put first in it and the checksum made anew;
otherwise (a ``c:`` there, or a wrong checksum that must stay wrong) the line is written
as received.  Lines that are not sentences (``#`` comments, a logger's prefix) are
written as received.

The form of a line (:func:`dracc.ingest.live.forms.classify`) decides its file:
``nmea0183`` and ``other`` go to the ``.nmea`` file as above; every other form is
written as received (each carries its own times, or they are found from its GNSS
messages as the reader does) to a file of its own, whose suffix :func:`form_suffix`
gives: a file of one form is what that form's reader recognises by its content, which a
file mixing TAG-block NMEA with CAN frames is not.

Files: ``DIR/dracc-YYYYMMDD<suffix>.part`` while written (the UTC day of the receive
times), then ``dracc-YYYYMMDD-1<suffix>.part`` and so on when one reaches ``max_bytes``;
a new file at each UTC midnight (of the receive times, or of the clock in :meth:`tick`
when nothing arrives).  A finished file is flushed, fsynced and renamed to drop
``.part`` (then the folder fsynced), so a reader of ``DIR`` sees whole files only.
Writes go through a buffered file per form, flushed every ``flush_s`` seconds or
``flush_lines`` lines: memory is bounded whatever the rate.  ``.part`` files of these
names left by a crash are finished when a :class:`Recorder` opens the folder (cut after
their last line end).
"""

from __future__ import annotations

import contextlib
import datetime as dt
import os
import re
import tempfile
import time
from collections import Counter
from collections.abc import Callable, Sequence
from functools import reduce
from operator import xor
from pathlib import Path

from dracc.core.atomic import faults_of, make_folder, output_error
from dracc.ingest.live.forms import (
    CANDUMP,
    GPSD_JSON,
    NMEA0183,
    NMEA_FORMS,
    OTHER,
    PDGY,
    PLAIN,
    SIGNALK_DELTA,
    SIGNALK_LOG,
    YDWG,
    classify,
)

#: a recording file reaching this size is finished and the next one begun
MAX_BYTES = 256 * 1024 * 1024
FLUSH_S = 1.0  #: the buffered files are flushed at least this often ...
FLUSH_LINES = 10_000  #: ... and a file after this many lines
#: after a write the disk refused, the lines of this many seconds are counted as lost
#: without a try; then writing is tried again (the disk may have room by then)
RETRY_S = 10.0
NMEA_SUFFIX = ".nmea"
#: form -> the suffix of its files (the NMEA 0183 file takes what has no form of its own)
SUFFIXES = {
    NMEA0183: NMEA_SUFFIX,
    OTHER: NMEA_SUFFIX,
    PDGY: ".pdgy.log",
    YDWG: ".ydwg.raw",
    CANDUMP: ".candump.log",
    PLAIN: ".plain.n2k",
    SIGNALK_LOG: ".signalk.log",
    SIGNALK_DELTA: ".signalk-delta.json",
    GPSD_JSON: ".gpsd.json",
}
#: suffix -> the form :meth:`Recorder.current_files` names its file by
_FORM_OF = {suffix: form for form, suffix in reversed(SUFFIXES.items())}
#: the line end of each file: the sentences' and YDWG-02's own CR LF, else LF (candump,
#: canboat, the Signal K server and gpsd write LF)
_LINE_END = {NMEA_SUFFIX: b"\r\n", SUFFIXES[YDWG]: b"\r\n"}
_NAME = re.compile(r"^dracc-(\d{8})(?:-(\d+))?((?:\.[a-z0-9-]+)+?)(\.part)?$")
#: bytes a TAG ``s:`` value may not hold (they end the parameter, the block or the line)
_SOURCE_BAD = re.compile(r"[^!-~]|[,*\\$]")
_HEX = re.compile(rb"^[0-9A-Fa-f]{1,2}$")


def form_suffix(form: str | None) -> str:
    """The file suffix of a line form (:data:`SUFFIXES`; ``.nmea`` for None)."""
    if form is None:
        return NMEA_SUFFIX
    try:
        return SUFFIXES[form]
    except KeyError:
        raise ValueError(f"unknown line form {form!r} (one of {', '.join(SUFFIXES)})") from None


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


DAY_NS = 86_400 * 10**9


def _day(ns: int) -> str:
    return (dt.datetime(1970, 1, 1) + dt.timedelta(microseconds=ns // 1000)).strftime("%Y%m%d")


class _Daily:
    """The file of one suffix being written: its ``.part`` path, UTC day (``lo <= t <
    hi`` in ns), size, and the whole lines not yet handed to the operating system.

    Lines go to the file only whole: a write the disk refuses half-way (full) is cut
    back to the last whole line (:meth:`flush`), so that a recording never holds half a
    line, whatever happened to the disk."""

    __slots__ = ("buf", "fd", "hi", "lo", "part", "size", "suffix", "unflushed", "written")

    def __init__(self, suffix: str, part: Path, lo: int) -> None:
        self.suffix = suffix
        self.part = part
        self.lo = lo
        self.hi = lo + DAY_NS
        flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_CLOEXEC", 0)
        self.fd = os.open(part, flags, 0o666)
        self.buf = bytearray()
        self.size = 0  #: bytes of the file's lines, buffered ones included
        self.written = 0  #: bytes of whole lines on the file
        self.unflushed = 0  #: lines in ``buf``

    def add(self, data: bytes) -> None:
        self.buf += data
        self.size += len(data)
        self.unflushed += 1

    def flush(self) -> None:
        """Hand the buffered lines to the operating system.  When it refuses (``OSError``,
        raised after), the file is cut back to its last whole line and the buffered
        lines are dropped: ``unflushed`` then still says how many."""
        data = bytes(self.buf)
        self.buf.clear()
        done = 0
        try:
            while done < len(data):
                done += os.pwrite(self.fd, data[done:] if done else data, self.written + done)
        except OSError:
            with contextlib.suppress(OSError):
                os.ftruncate(self.fd, self.written)
            self.size = self.written
            raise
        self.written += done
        self.unflushed = 0

    def finish(self) -> Path:
        """Flush, fsync, close and rename to the final name (returned)."""
        self.flush()
        os.fsync(self.fd)
        self.close()
        final = self.part.with_suffix("")
        os.rename(self.part, final)
        return final

    def close(self) -> None:
        if self.fd >= 0:
            os.close(self.fd)
            self.fd = -1


class Recorder:
    """Received lines written to daily files in ``folder``, a file per line form (see
    the module docstring).  ``write(line, recv_ns=None, source=None, form=None)`` per
    line; ``tick()`` now and then (it flushes, and finishes yesterday's files at
    midnight); ``close()`` finishes the current files.  ``now_ns`` is the clock
    (injected by tests).

    A folder that cannot be used at the start is an :class:`~dracc.core.errors.OutputError`.
    A write refused later (the disk full, the folder made read-only) stops nothing: the
    file keeps its whole lines, ``fault`` says why (one line) and ``lost`` counts the
    lines not recorded; writing is tried again every :data:`RETRY_S` seconds, and
    ``fault`` is cleared once writes have worked for :data:`RETRY_S` seconds (a disk
    with a few bytes free takes one small write, then refuses the next)."""

    def __init__(
        self,
        folder: str | Path,
        max_bytes: int = MAX_BYTES,
        now_ns: Callable[[], int] = time.time_ns,
        flush_s: float = FLUSH_S,
        flush_lines: int = FLUSH_LINES,
    ) -> None:
        self.folder = make_folder(folder)
        self.max_bytes = max_bytes
        self.now_ns = now_ns
        self.flush_ns = int(flush_s * 1e9)
        self.flush_lines = flush_lines
        self.files: list[Path] = []  #: finished files, in order
        self.recovered: list[Path] = []  #: ``.part`` files of an earlier run, finished
        self.lines = 0  #: lines given to the recording (``lost`` of them not on a file)
        self.lines_by_form: Counter[str] = Counter()  #: lines given, by form
        self.lost = 0  #: lines not recorded: the disk refused them
        self.fault: str | None = None  #: why the last write failed, until one works again
        self._retry_ns = 0
        self._ok_ns: int | None = None  #: since when writes work again, after a fault
        self._open: dict[str, _Daily] = {}  #: suffix -> the file being written
        self._last_flush = now_ns()
        with faults_of(self.folder, self.folder):
            self._recover()
            fd, probe = tempfile.mkstemp(prefix=".dracc-probe-", dir=self.folder)
            os.close(fd)  # a folder that takes no file is said now, not at the first line
            os.unlink(probe)

    # -- files -------------------------------------------------------------------------
    def _recover(self) -> None:
        known = set(SUFFIXES.values())
        for part in sorted(self.folder.glob("dracc-*.part")):
            m = _NAME.match(part.name)
            if not m or m.group(3) not in known or not part.is_file():
                continue  # not a recording of ours
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
            if final.exists():
                final = self._free_name(m.group(1), m.group(3))
            os.rename(part, final)
            self.recovered.append(final)
        self._sync_folder()

    def _free_name(self, day: str, suffix: str) -> Path:
        """The first name of ``day`` and ``suffix`` neither finished nor being written."""
        n = 0
        while True:
            name = f"dracc-{day}{suffix}" if n == 0 else f"dracc-{day}-{n}{suffix}"
            p = self.folder / name
            if not p.exists() and not p.with_name(name + ".part").exists():
                return p
            n += 1

    def _begin(self, suffix: str, recv_ns: int) -> _Daily:
        lo = recv_ns // DAY_NS * DAY_NS
        final = self._free_name(_day(lo), suffix)
        out = self._open[suffix] = _Daily(suffix, final.with_name(final.name + ".part"), lo)
        return out

    def _finish(self, suffix: str) -> None:
        out = self._open.pop(suffix, None)
        if out is None:
            return
        try:
            self.files.append(out.finish())
        except OSError as err:  # left as .part, whole lines: finished at the next start
            out.close()
            self._refused(err, out.part, out.unflushed)
            return
        self._sync_folder()

    def _flush(self, out: _Daily) -> None:
        lines = out.unflushed
        try:
            out.flush()
        except OSError as err:
            out.unflushed = 0
            self._refused(err, out.part, lines)
            return
        if lines and self.fault is not None:  # cleared after RETRY_S of writes that work
            now = self.now_ns()
            self._ok_ns = now if self._ok_ns is None else self._ok_ns
            if now - self._ok_ns >= int(RETRY_S * 1e9):
                self.fault = self._ok_ns = None

    def _refused(self, err: OSError, path: Path, lines: int) -> None:
        """A write the disk refused: ``lines`` lost, the fault said, a retry later."""
        self.lost += lines
        self._ok_ns = None
        if self.fault is None:
            fault = output_error(path, err, self.folder)
            self.fault = str(fault) if fault else f"cannot write {path}: {err}"
        self._retry_ns = self.now_ns() + int(RETRY_S * 1e9)

    def _sync_folder(self) -> None:
        with contextlib.suppress(OSError):
            fd = os.open(self.folder, os.O_RDONLY)
            try:
                os.fsync(fd)
            finally:
                os.close(fd)

    @property
    def current(self) -> Path | None:
        """The ``.part`` file of NMEA 0183 being written (None between files)."""
        out = self._open.get(NMEA_SUFFIX)
        return out.part if out is not None else None

    def current_files(self) -> dict[str, Path]:
        """Form -> the ``.part`` file being written for it (``nmea0183`` for the
        ``.nmea`` file, which ``other`` lines share)."""
        return {_FORM_OF[s]: out.part for s, out in self._open.items()}

    # -- writing -----------------------------------------------------------------------
    def write(
        self,
        line: bytes,
        recv_ns: int | None = None,
        source: str | None = None,
        form: str | None = None,
    ) -> bytes:
        """Record one received line (without its line end) and its receive time
        (``now_ns()`` if None); return it as recorded, without the line end.  ``form``
        (what :func:`classify` says; None: NMEA 0183) picks the file; ``source`` is
        written (TAG ``s:``) with NMEA 0183 only: the other forms name their sources
        themselves."""
        if recv_ns is None:
            recv_ns = self.now_ns()
        if form is None or form in NMEA_FORMS:
            suffix = NMEA_SUFFIX
            recorded = tag_line(line, recv_ns, source)
        else:
            suffix = form_suffix(form)
            recorded = line
        self.lines += 1
        self.lines_by_form[form or NMEA0183] += 1
        if self.fault is not None and recv_ns < self._retry_ns:
            self.lost += 1  # the disk refused a write moments ago: not tried again yet
            return recorded
        data = recorded + _LINE_END.get(suffix, b"\n")
        out = self._open.get(suffix)
        if out is not None and (
            not out.lo <= recv_ns < out.hi or (out.size and out.size + len(data) > self.max_bytes)
        ):
            self._finish(suffix)
            out = None
        if out is None:
            try:
                out = self._begin(suffix, recv_ns)
            except OSError as err:
                self._refused(err, self.folder, 1)
                return recorded
        out.add(data)
        if out.unflushed >= self.flush_lines:
            self._flush(out)
        return recorded

    def write_many(
        self,
        lines: list[tuple[int, bytes]],
        source: str | None = None,
        forms: Sequence[str | None] | None = None,
    ) -> None:
        """Record ``(recv_ns, line)`` pairs (what a live source's ``poll`` returns), each
        in the file of its form (``forms``, one per line; classified here where not
        given), then :meth:`tick`."""
        if forms is None:
            for recv_ns, line in lines:
                self.write(line, recv_ns, source, classify(line).form)
        else:
            if len(forms) != len(lines):
                raise ValueError("one form per line")
            for (recv_ns, line), form in zip(lines, forms, strict=True):
                self.write(line, recv_ns, source, form)
        self.tick()

    def flush(self) -> None:
        """Hand the buffered lines to the operating system (no fsync: that is at the end
        of each file)."""
        for out in self._open.values():
            self._flush(out)
        self._last_flush = self.now_ns()

    def tick(self) -> None:
        """Flush if ``flush_s`` has passed; finish the current files once the clock is
        past their UTC day."""
        now = self.now_ns()
        done = [s for s, out in self._open.items() if now >= out.hi]
        for suffix in done:
            self._finish(suffix)
        if not done and now - self._last_flush >= self.flush_ns:
            self.flush()

    def close(self) -> None:
        """Finish the current files (flush, fsync, rename)."""
        for suffix in list(self._open):
            self._finish(suffix)

    def __enter__(self) -> Recorder:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
