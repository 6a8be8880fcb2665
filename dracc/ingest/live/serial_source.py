"""A serial device as a live source (NMEA 0183 on RS-422/RS-232 through a USB adapter
or a UART), read with pyserial, listening only.

Specs: ``serial:///dev/ttyUSB0?baud=38400&bytesize=8&parity=N&stopbits=1`` or a plain
device path (``/dev/ttyUSB0``, ``/dev/ttyS0``, ``/dev/pts/3``, or any path naming a
character device, a symlink such as ``/dev/serial/by-id/...`` included).  The line
settings default to 4800 baud 8N1, the NMEA 0183 / IEC 61162-1 rate; IEC 61162-2 ("high
speed") is 38400.  The baud rate is the spec's ``baud=`` where it has one, else the
``baud`` argument (``dracc watch --baud``), else 4800.

Never transmitting: nothing is ever written to the port; no flow control (``rtscts``,
``dsrdtr`` and ``xonxoff`` off), so pyserial leaves DTR and RTS asserted as the kernel
set them when the device was opened (it does not toggle them); the port is locked
(``exclusive=True``, ``flock``) so that two watches never share it.  Reads are
non-blocking (``timeout=0``) and waited on with :mod:`selectors` on the port's file
descriptor, so that :func:`~dracc.ingest.live.sources.poll_all` across sources keeps
working; there are no threads.

Lines are cut as on TCP (:class:`~dracc.ingest.live.base.StreamLines`: ``binary``,
``too_long``, and ``partial`` for the unfinished line of a device that went away).  A
device that goes away (an unplugged USB adapter: the read fails or reports no data) is
not fatal: it is counted in ``failures``, closed, and opened again after a wait that
doubles from ``backoff_first_s`` up to ``backoff_cap_s`` -- TcpSource's backoff, back to
the first wait after an opening that delivered data; ``reopens`` counts the successful
reopenings.  A device that cannot be opened at the start is an IngestError with a
one-line reason.
"""

from __future__ import annotations

import contextlib
import errno
import os
import re
import selectors
import stat
import time
from collections.abc import Callable
from typing import Any
from urllib.parse import parse_qsl, urlsplit

import serial

from dracc.core.errors import IngestError
from dracc.ingest.live.base import (
    BACKOFF_CAP_S,
    BACKOFF_FACTOR,
    BACKOFF_FIRST_S,
    MAX_LIVE_LINE_BYTES,
    MAX_POLL_LINES,
    READ_BYTES,
    Line,
    ReconnectingSource,
    StreamLines,
)

#: missing paths taken for serial devices (others are growing files that may appear)
DEVICE_NAMES = re.compile(r"/dev/(tty|cu\.|pts/|serial/|rfcomm|usb)")
#: NMEA 0183 / IEC 61162-1
DEFAULT_BAUD = 4800
#: IEC 61162-2 ("high speed")
HIGH_SPEED_BAUD = 38400
BYTESIZES = {
    "5": serial.FIVEBITS,
    "6": serial.SIXBITS,
    "7": serial.SEVENBITS,
    "8": serial.EIGHTBITS,
}
PARITIES = {
    "N": serial.PARITY_NONE,
    "E": serial.PARITY_EVEN,
    "O": serial.PARITY_ODD,
    "M": serial.PARITY_MARK,
    "S": serial.PARITY_SPACE,
}
STOPBITS = {
    "1": serial.STOPBITS_ONE,
    "1.5": serial.STOPBITS_ONE_POINT_FIVE,
    "2": serial.STOPBITS_TWO,
}
_OPEN_REASONS = {
    errno.ENOENT: "no such serial device",
    errno.ENODEV: "no such serial device",
    errno.ENXIO: "no such serial device",
    errno.EACCES: "permission denied (is the user in the dialout group?)",
    errno.EPERM: "permission denied (is the user in the dialout group?)",
    errno.EBUSY: "the device is busy",
    errno.EISDIR: "a directory, not a serial device",
}


def is_serial_spec(spec: str) -> bool:
    """Whether ``spec`` names a serial device: ``serial://...``, any path naming a
    character device (through symlinks), a path under ``/dev/`` that is neither a regular
    file nor a folder, or a missing path named as serial devices are (:data:`DEVICE_NAMES`:
    reported as a missing device rather than waited for as a growing file)."""
    if spec.startswith("serial://"):
        return True
    if "://" in spec or spec.startswith("file:"):
        return False
    try:
        mode = os.stat(spec).st_mode
    except OSError:
        return DEVICE_NAMES.match(spec) is not None
    if stat.S_ISCHR(mode):
        return True
    return spec.startswith("/dev/") and not (stat.S_ISREG(mode) or stat.S_ISDIR(mode))


def parse_serial_spec(spec: str, baud: int | None = None) -> tuple[str, dict[str, Any]]:
    """(device path, pyserial line settings) of a spec; ``baud`` is used where the spec
    has no ``baud=``.  Raises IngestError for a bad spec."""
    if not spec.startswith("serial://"):
        path, query = spec, ""
    else:
        u = urlsplit(spec)
        if u.netloc or not u.path:
            raise IngestError(f"{spec}: expected serial:///dev/DEVICE?baud=4800")
        path, query = u.path, u.query
    try:
        params = dict(parse_qsl(query, keep_blank_values=True, strict_parsing=bool(query)))
    except ValueError as err:
        raise IngestError(f"{spec}: bad query ({err})") from err
    unknown = set(params) - {"baud", "bytesize", "parity", "stopbits"}
    if unknown:
        raise IngestError(
            f"{spec}: unknown setting {', '.join(sorted(unknown))} "
            "(baud, bytesize, parity, stopbits)"
        )
    given = params.get("baud", str(baud if baud is not None else DEFAULT_BAUD))
    rate = int(given) if given.isdigit() else 0
    if rate <= 0:
        raise IngestError(f"{spec}: bad baud rate {given!r}")
    settings: dict[str, Any] = {"baudrate": rate}
    for key, table, default in (
        ("bytesize", BYTESIZES, "8"),
        ("parity", PARITIES, "N"),
        ("stopbits", STOPBITS, "1"),
    ):
        value = params.get(key, default).upper()
        if value not in table:
            raise IngestError(f"{spec}: bad {key} {value!r} ({', '.join(table)})")
        settings[key] = table[value]
    return path, settings


def _open_reason(err: Exception) -> str:
    """A one-line reason from pyserial's opening error."""
    code = getattr(err, "errno", None)
    if code in _OPEN_REASONS:
        return _OPEN_REASONS[code]
    text = str(err)
    if "exclusively lock" in text:
        return "in use by another program (the port is locked)"
    if "Inappropriate ioctl" in text or "Could not configure port" in text:
        return "not a serial device"
    return text.splitlines()[0] if text else type(err).__name__


class SerialSource(ReconnectingSource):
    """Lines read from a serial device (see the module docstring)."""

    kind = "serial"
    #: the specs this class opens (found by ``open_source`` through this)

    def __init__(
        self,
        spec: str,
        baud: int | None = None,
        backoff_first_s: float = BACKOFF_FIRST_S,
        backoff_cap_s: float = BACKOFF_CAP_S,
        max_line_bytes: int = MAX_LIVE_LINE_BYTES,
        max_lines: int = MAX_POLL_LINES,
        clock: Callable[[], int] = time.time_ns,
    ) -> None:
        super().__init__(spec, max_line_bytes, max_lines)
        self.path, self.settings = parse_serial_spec(spec, baud)
        self.baud: int = self.settings["baudrate"]  #: the line's baud rate
        self.clock = clock
        self.backoff_first_s = backoff_first_s
        self.backoff_cap_s = backoff_cap_s
        self.backoff_s = backoff_first_s
        self.opens = 0  #: successful openings of the device (the first included)
        self.reopens = 0  #: of which after a loss
        self.failures = 0  #: devices lost and reopenings that failed
        self.last_error = ""  #: the reason of the last loss or failed reopening
        self.port: serial.Serial | None = None
        self.next_try = 0.0  #: time.monotonic() of the next reopening
        self.selector = selectors.DefaultSelector()
        self.stream = StreamLines(self)
        self._got_data = False
        try:
            self._open()
        except (serial.SerialException, OSError, ValueError) as err:
            self.selector.close()
            self.closed = True
            raise IngestError(f"{self.path}: {_open_reason(err)}") from err

    def _open(self) -> None:
        port = serial.Serial(
            self.path,
            timeout=0,
            xonxoff=False,
            rtscts=False,
            dsrdtr=False,
            exclusive=True,
            **self.settings,
        )
        self.port = port
        self.selector.register(port.fileno(), selectors.EVENT_READ)
        self.opens += 1

    def _lost(self, reason: str) -> None:
        if self.port is not None:
            with contextlib.suppress(KeyError, ValueError, OSError):
                self.selector.unregister(self.port.fileno())
            with contextlib.suppress(OSError, serial.SerialException):
                self.port.close()
            self.port = None
        self.stream.drop_partial()
        self.failures += 1
        self.last_error = reason
        if self._got_data:
            self.backoff_s = self.backoff_first_s
        self.next_try = time.monotonic() + self.backoff_s
        self.backoff_s = min(self.backoff_s * BACKOFF_FACTOR, self.backoff_cap_s)
        self._got_data = False

    def _reopen(self) -> None:
        try:
            self._open()
        except (serial.SerialException, OSError, ValueError) as err:
            self._lost(_open_reason(err))
            return
        self.reopens += 1

    def _read(self, out: list[Line]) -> None:
        port = self.port
        assert port is not None
        while len(out) < self.max_lines:
            try:
                data = port.read(READ_BYTES)
            except (serial.SerialException, OSError) as err:
                self._lost(str(err).splitlines()[0] if str(err) else "read failed")
                return
            if not data:
                return
            self._got_data = True
            got: list[Line] = []
            self.stream.feed(self.clock(), data, got)
            out.extend(got)

    def _is_open(self) -> bool:
        return self.port is not None

    def _attempt(self) -> None:
        self._reopen()

    def _ready(self, out: list[Line]) -> None:
        self._read(out)

    def close(self) -> None:
        if not self.closed:
            if self.port is not None:
                with contextlib.suppress(OSError, serial.SerialException):
                    self.port.close()
                self.port = None
            self.selector.close()
        super().close()
