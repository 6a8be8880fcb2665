"""What every live source shares: :class:`LiveSource` (spec, counters, ``poll``,
``close``), :class:`StreamLines` (a byte stream cut into lines with bounded memory, for
TCP, serial devices and files) and the limits they apply.  The sources themselves are in
:mod:`~dracc.ingest.live.sources` and :mod:`~dracc.ingest.live.serial_source`."""

from __future__ import annotations

import selectors
import time
from collections import Counter

#: the IEC 61162-450 header of a datagram of sentences
UDPBC = b"UdPbC\x00"
#: a live line longer than this is dropped (an NMEA sentence is at most 82 characters, a
#: TAG block adds a few tens)
MAX_LIVE_LINE_BYTES = 4096
#: lines returned by one ``poll`` at most (bounded memory per call)
MAX_POLL_LINES = 50_000
#: bytes of one UDP receive (a datagram up to this is whole; larger is ``truncated``)
DATAGRAM_BYTES = 65_536
#: the UDP receive buffer asked of the kernel (it may grant less: net.core.rmem_max)
RCVBUF_BYTES = 8 * 1024 * 1024
#: TCP reconnect backoff: first wait, factor, cap (seconds)
BACKOFF_FIRST_S = 0.25
BACKOFF_FACTOR = 2.0
BACKOFF_CAP_S = 30.0
#: a growing file is checked for new bytes and rotation this often when idle (seconds)
FILE_INTERVAL_S = 0.05
#: bytes read from a file or socket in one go
READ_BYTES = 1 << 20

Line = tuple[int, bytes]
#: bytes not allowed in a line: everything but printable ASCII (for ``bytes.translate``)
_NOT_PRINTABLE = bytes(b for b in range(256) if not 32 <= b <= 126)
_NOT_PRINTABLE_OR_EOL = bytes(b for b in _NOT_PRINTABLE if b not in (10, 13))


def _printable(data: bytes, delete: bytes = _NOT_PRINTABLE) -> bool:
    """Whether ``data`` holds only the allowed bytes (those not in ``delete``)."""
    return len(data.translate(None, delete)) == len(data)


class LiveSource:
    """What every live source has: its spec, counters, ``poll`` and ``close``."""

    kind = ""

    def __init__(self, spec: str, max_line_bytes: int, max_lines: int) -> None:
        self.spec = spec
        self.max_line_bytes = max_line_bytes
        self.max_lines = max_lines
        #: dropped input, by reason (see the module docstring)
        self.rejected: Counter[str] = Counter()
        self.lines = 0  #: lines returned so far
        self.bytes = 0  #: bytes received so far
        self.closed = False

    def poll(self, timeout_s: float = 0.0) -> list[Line]:  # pragma: no cover - abstract
        raise NotImplementedError

    def close(self) -> None:
        self.closed = True

    def __enter__(self) -> LiveSource:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"<{type(self).__name__} {self.spec} lines={self.lines}>"


class StreamLines:
    """Bytes of a stream cut into lines (LF, CR LF or a lone CR), with bounded memory: a
    line longer than ``max_line_bytes`` is dropped as ``too_long`` and its bytes skipped
    up to the next line end."""

    def __init__(self, source: LiveSource) -> None:
        self.src = source
        self.pending = b""
        self.skipping = False

    def feed(self, recv_ns: int, data: bytes, out: list[Line]) -> None:
        src = self.src
        src.bytes += len(data)
        if self.skipping:
            ends = [i for i in (data.find(b"\n"), data.find(b"\r")) if i >= 0]
            if not ends:
                return
            cut = min(ends)
            data = data[cut + 1 :]
            self.skipping = False
        data = self.pending + data
        pieces = data.splitlines()
        if data and data[-1] not in (10, 13):
            self.pending = pieces.pop() if pieces else b""
        else:
            self.pending = b""
        limit = src.max_line_bytes
        for line in pieces:
            if not line:
                continue
            if len(line) > limit:
                src.rejected["too_long"] += 1
            elif not _printable(line):
                src.rejected["binary"] += 1
            else:
                out.append((recv_ns, line))
        if len(self.pending) > limit:
            src.rejected["too_long"] += 1
            self.pending = b""
            self.skipping = True
        src.lines += len(out)

    def drop_partial(self) -> None:
        if self.pending or self.skipping:
            if self.pending:
                self.src.rejected["partial"] += 1
            self.pending = b""
            self.skipping = False


class ReconnectingSource(LiveSource):
    """A stream source that opens (and reopens, after a backoff) its connection or
    device: :meth:`poll` waits for the next attempt when it is closed, else for input,
    at most ``timeout_s`` in all.  Subclasses set ``next_try`` (``time.monotonic()`` of
    the next attempt) and ``selector``, and give :meth:`_is_open`, :meth:`_attempt` and
    :meth:`_ready` (one ready event: read into ``out``)."""

    next_try: float
    selector: selectors.BaseSelector

    def _is_open(self) -> bool:  # pragma: no cover - abstract
        raise NotImplementedError

    def _attempt(self) -> None:  # pragma: no cover - abstract
        raise NotImplementedError

    def _ready(self, out: list[Line]) -> None:  # pragma: no cover - abstract
        raise NotImplementedError

    def poll(self, timeout_s: float = 0.0) -> list[Line]:
        out: list[Line] = []
        end = time.monotonic() + timeout_s
        while not self.closed:
            now = time.monotonic()
            if not self._is_open() and now >= self.next_try:
                self._attempt()
            if not self._is_open():
                wait = min(end, self.next_try) - now
                if wait > 0:
                    time.sleep(wait)
                if time.monotonic() >= end:
                    break
                continue
            for _ in self.selector.select(max(0.0, end - time.monotonic())):
                self._ready(out)
            if out or time.monotonic() >= end:
                break
        return out
