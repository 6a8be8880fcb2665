"""Live inputs, listening only: UDP (plain NMEA or IEC 61162-450), a TCP client and a
growing file, each polled for ``(recv_ns, line)`` pairs.

Every source has ``poll(timeout_s) -> list[(recv_ns, line_bytes)]`` (waits at most
``timeout_s`` for input, returns at most ``max_lines`` lines, line ends stripped, blank
lines dropped) and ``close()``; ``rejected`` counts what was dropped, by reason:

* ``binary``: a byte outside printable ASCII (0x20-0x7E) -- a whole UDP datagram (not
  NMEA: another protocol on the port, an IEC 61162-450 binary transfer ``RaUdP``/``RrUdP``),
  one line of a stream;
* ``empty``: a UDP datagram with no line in it (nothing after the header);
* ``too_long``: a line longer than ``max_line_bytes`` (never held whole on a stream: its
  bytes are skipped up to the next line end);
* ``truncated``: a UDP datagram larger than the receive buffer (cut by the kernel);
* ``partial``: the unfinished last line of a TCP connection that closed;
* ``kernel_dropped``: UDP datagrams the kernel dropped before dracc could read them, its
  receive buffer full (Linux ``SO_RXQ_OVFL``: the count comes with the next datagram
  received, so drops after the last one are seen when another one arrives).

No source ever transmits: the UDP socket is only bound (a multicast group is joined only
where the host is a multicast address *and* ``allow_multicast=True``), the TCP client
only connects and reads.  Sockets are non-blocking and waited on with :mod:`selectors`;
there are no threads.

IEC 61162-450 (§7): a datagram of sentences begins with the 6-byte header ``UdPbC\\0``,
stripped here; the TAG blocks (``\\s:...,c:...*hh\\``) and line groups (``g:``) are kept
as received, for the NMEA reader to check and reassemble.
"""

from __future__ import annotations

import contextlib
import errno
import ipaddress
import os
import selectors
import socket
import struct
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from urllib.parse import urlsplit

from dracc.core.errors import IngestError
from dracc.ingest.live.base import (
    _NOT_PRINTABLE_OR_EOL,
    BACKOFF_CAP_S,
    BACKOFF_FACTOR,
    BACKOFF_FIRST_S,
    DATAGRAM_BYTES,
    FILE_INTERVAL_S,
    MAX_LIVE_LINE_BYTES,
    MAX_POLL_LINES,
    RCVBUF_BYTES,
    READ_BYTES,
    UDPBC,
    Line,
    LiveSource,
    ReconnectingSource,
    StreamLines,
    _printable,
)
from dracc.ingest.live.serial_source import SerialSource, is_serial_spec


def _host_port(spec: str, scheme: str) -> tuple[str, int]:
    u = urlsplit(spec)
    try:
        port = u.port
    except ValueError as err:
        raise IngestError(f"{spec}: bad port") from err
    if u.scheme != scheme or u.hostname is None or port is None:
        raise IngestError(f"{spec}: expected {scheme}://HOST:PORT")
    return u.hostname, port


def _is_multicast(host: str) -> bool:
    try:
        return ipaddress.ip_address(host).is_multicast
    except ValueError:
        return False


#: the reason of the datagrams the kernel dropped (its receive buffer full)
KERNEL_DROPPED = "kernel_dropped"
#: the socket option that has Linux hand its drop count with each datagram (not in
#: Python's socket module everywhere; 40 on Linux)
SO_RXQ_OVFL: int | None = getattr(
    socket, "SO_RXQ_OVFL", 40 if sys.platform.startswith("linux") else None
)


class UdpSource(LiveSource):
    """Datagrams received on ``HOST:PORT`` (bound; port 0 picks a free one, see
    ``address``), each one or more lines, an IEC 61162-450 ``UdPbC\\0`` header stripped."""

    kind = "udp"

    def __init__(
        self,
        spec: str,
        allow_multicast: bool = False,
        interface: str = "0.0.0.0",
        max_line_bytes: int = MAX_LIVE_LINE_BYTES,
        max_lines: int = MAX_POLL_LINES,
        clock: Callable[[], int] = time.time_ns,
    ) -> None:
        super().__init__(spec, max_line_bytes, max_lines)
        host, port = _host_port(spec, "udp")
        self.clock = clock
        self.datagrams = 0  #: datagrams received
        self.iec450 = 0  #: of which IEC 61162-450 (``UdPbC\0``)
        self._drops_seen = 0  #: the kernel's count of drops, as last received (uint32)
        self._ancillary = 0  #: room for the drop count beside each datagram (0: not asked)
        multicast = _is_multicast(host)
        if multicast and not allow_multicast:
            raise IngestError(
                f"{spec}: {host} is a multicast group; joining it sends IGMP membership "
                "reports on the network: give --join-multicast (allow_multicast=True)"
            )
        family = socket.AF_INET6 if ":" in host else socket.AF_INET
        try:
            infos = socket.getaddrinfo(host, port, family, socket.SOCK_DGRAM)
        except socket.gaierror as err:
            raise IngestError(f"{spec}: {err}") from err
        sock = socket.socket(family, socket.SOCK_DGRAM)
        try:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            with contextlib.suppress(OSError):
                sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, RCVBUF_BYTES)
            if SO_RXQ_OVFL is not None:  # the kernel's drops, with each datagram (Linux)
                with contextlib.suppress(OSError):
                    sock.setsockopt(socket.SOL_SOCKET, SO_RXQ_OVFL, 1)
                    self._ancillary = socket.CMSG_SPACE(4)
            sock.bind(infos[0][4])
            if multicast:
                if family == socket.AF_INET6:
                    mreq6 = socket.inet_pton(family, host) + struct.pack("@I", 0)
                    sock.setsockopt(socket.IPPROTO_IPV6, socket.IPV6_JOIN_GROUP, mreq6)
                else:
                    mreq = socket.inet_aton(host) + socket.inet_aton(interface)
                    sock.setsockopt(socket.IPPROTO_IP, socket.IP_ADD_MEMBERSHIP, mreq)
            sock.setblocking(False)
        except OSError as err:
            sock.close()
            raise IngestError(f"{spec}: {err.strerror or err}") from err
        self.sock = sock
        self.address: tuple[str, int] = sock.getsockname()[:2]
        self.selector = selectors.DefaultSelector()
        self.selector.register(sock, selectors.EVENT_READ)

    def _datagram(self, recv_ns: int, data: bytes, flags: int, out: list[Line]) -> None:
        self.datagrams += 1
        self.bytes += len(data)
        if flags & socket.MSG_TRUNC:
            self.rejected["truncated"] += 1
            return
        if data.startswith(UDPBC):
            self.iec450 += 1
            data = data[len(UDPBC) :]
        if not _printable(data, _NOT_PRINTABLE_OR_EOL):
            self.rejected["binary"] += 1
            return
        lines = [ln for ln in data.splitlines() if ln]
        if not lines:
            self.rejected["empty"] += 1
            return
        limit = self.max_line_bytes
        for line in lines:
            if len(line) > limit:
                self.rejected["too_long"] += 1
            else:
                out.append((recv_ns, line))

    def _kernel_drops(self, anc: list[tuple[int, int, bytes]]) -> None:
        """The kernel's running count of datagrams it dropped on this socket (uint32,
        wrapping), counted as ``kernel_dropped``."""
        for level, kind, data in anc:
            if level == socket.SOL_SOCKET and kind == SO_RXQ_OVFL and len(data) >= 4:
                (total,) = struct.unpack("=I", data[:4])
                self.rejected[KERNEL_DROPPED] += (total - self._drops_seen) % 2**32
                self._drops_seen = total

    def poll(self, timeout_s: float = 0.0) -> list[Line]:
        out: list[Line] = []
        if self.closed:
            return out
        if not self.selector.select(timeout_s):
            return out
        recv, room = self.sock.recvmsg, self._ancillary
        while len(out) < self.max_lines:
            try:
                data, anc, flags, _ = recv(DATAGRAM_BYTES, room)
            except (BlockingIOError, InterruptedError):
                break
            except OSError as err:  # e.g. ICMP errors reported on the socket: not fatal
                self.rejected[f"error_{errno.errorcode.get(err.errno or 0, 'os')}"] += 1
                break
            if anc:
                self._kernel_drops(anc)
            self._datagram(self.clock(), data, flags, out)
        self.lines += len(out)
        return out

    def close(self) -> None:
        if not self.closed:
            self.selector.close()
            self.sock.close()
        super().close()


class TcpSource(ReconnectingSource):
    """A TCP client of ``HOST:PORT`` reading lines; when the connection fails or closes
    it reconnects after a wait that doubles from ``backoff_first_s`` up to
    ``backoff_cap_s`` (back to the first after a connection that delivered data)."""

    kind = "tcp"

    def __init__(
        self,
        spec: str,
        backoff_first_s: float = BACKOFF_FIRST_S,
        backoff_cap_s: float = BACKOFF_CAP_S,
        max_line_bytes: int = MAX_LIVE_LINE_BYTES,
        max_lines: int = MAX_POLL_LINES,
        clock: Callable[[], int] = time.time_ns,
    ) -> None:
        super().__init__(spec, max_line_bytes, max_lines)
        self.host, self.port = _host_port(spec, "tcp")
        self.clock = clock
        self.backoff_first_s = backoff_first_s
        self.backoff_cap_s = backoff_cap_s
        self.backoff_s = backoff_first_s
        self.connects = 0  #: connections made
        self.failures = 0  #: connection attempts failed or connections lost
        self.connected = False
        self.sock: socket.socket | None = None
        self.next_try = 0.0  #: time.monotonic() of the next connection attempt
        self.selector = selectors.DefaultSelector()
        self.stream = StreamLines(self)
        self._got_data = False

    def _start(self) -> None:
        try:
            infos = socket.getaddrinfo(self.host, self.port, 0, socket.SOCK_STREAM)
        except socket.gaierror:
            self._lost()
            return
        family, stype, proto, _, addr = infos[0]
        sock = socket.socket(family, stype, proto)
        sock.setblocking(False)
        err = sock.connect_ex(addr)
        if err not in (0, errno.EINPROGRESS, errno.EWOULDBLOCK):
            sock.close()
            self._lost()
            return
        self.sock = sock
        self.selector.register(sock, selectors.EVENT_WRITE)

    def _lost(self) -> None:
        if self.sock is not None:
            with contextlib.suppress(KeyError, ValueError):
                self.selector.unregister(self.sock)
            self.sock.close()
            self.sock = None
        self.stream.drop_partial()
        self.failures += 1
        if self._got_data:
            self.backoff_s = self.backoff_first_s
        self.next_try = time.monotonic() + self.backoff_s
        self.backoff_s = min(self.backoff_s * BACKOFF_FACTOR, self.backoff_cap_s)
        self.connected = False
        self._got_data = False

    def _connected(self) -> None:
        assert self.sock is not None
        if self.sock.getsockopt(socket.SOL_SOCKET, socket.SO_ERROR):
            self._lost()
            return
        self.selector.modify(self.sock, selectors.EVENT_READ)
        self.connected = True
        self.connects += 1

    def _read(self, out: list[Line]) -> None:
        assert self.sock is not None
        while len(out) < self.max_lines:
            try:
                data = self.sock.recv(READ_BYTES)
            except (BlockingIOError, InterruptedError):
                return
            except OSError:
                self._lost()
                return
            if not data:
                self._lost()
                return
            self._got_data = True
            got: list[Line] = []
            self.stream.feed(self.clock(), data, got)
            out.extend(got)

    def _is_open(self) -> bool:
        return self.sock is not None

    def _attempt(self) -> None:
        self._start()

    def _ready(self, out: list[Line]) -> None:
        if not self.connected:
            self._connected()
        else:
            self._read(out)

    def close(self) -> None:
        if not self.closed:
            if self.sock is not None:
                self.sock.close()
                self.sock = None
            self.selector.close()
        super().close()


class FileSource(LiveSource):
    """A file that grows, read as ``tail -f`` does, from its end (``from_start`` False)
    or its beginning; it may not exist yet.  Rotation survives: when the path names
    another file (a new inode: rename and create) the rest of the old one is read, then
    the new one from its start; when the file shrinks (truncated in place) it is read
    again from its start."""

    kind = "file"

    def __init__(
        self,
        spec: str,
        from_start: bool = False,
        interval_s: float = FILE_INTERVAL_S,
        max_line_bytes: int = MAX_LIVE_LINE_BYTES,
        max_lines: int = MAX_POLL_LINES,
        clock: Callable[[], int] = time.time_ns,
    ) -> None:
        super().__init__(spec, max_line_bytes, max_lines)
        self.path = Path(spec[5:] if spec.startswith("file:") else spec)
        self.clock = clock
        self.interval_s = interval_s
        self.rotations = 0  #: new files followed (rename and create)
        self.truncations = 0  #: files that shrank and were read again from the start
        self._fd: int | None = None
        self._ino: tuple[int, int] | None = None
        self.pos = 0
        self.stream = StreamLines(self)
        self._open(at_end=not from_start)

    def _open(self, at_end: bool) -> bool:
        try:
            fd = os.open(self.path, os.O_RDONLY)
        except FileNotFoundError:
            return False
        except OSError as err:
            raise IngestError(f"{self.path}: {err.strerror}") from err
        st = os.fstat(fd)
        self._fd = fd
        self._ino = (st.st_dev, st.st_ino)
        self.pos = st.st_size if at_end else 0
        return True

    def _read_some(self, out: list[Line]) -> int:
        """Bytes read from the open file (0 at its end)."""
        if self._fd is None:
            return 0
        total = 0
        while len(out) < self.max_lines:
            data = os.pread(self._fd, READ_BYTES, self.pos)
            if not data:
                break
            self.pos += len(data)
            total += len(data)
            got: list[Line] = []
            self.stream.feed(self.clock(), data, got)
            out.extend(got)
        return total

    def _check_rotation(self) -> None:
        """At the end of the open file: follow a new file at the path or a truncation."""
        try:
            st = os.stat(self.path)
        except FileNotFoundError:
            return  # renamed away, the new one not yet created: keep the old one open
        if self._fd is None:
            self._open(at_end=False)  # created since: read from its start
            return
        if (st.st_dev, st.st_ino) != self._ino:
            os.close(self._fd)
            self._fd = None
            self.stream.drop_partial()
            if self._open(at_end=False):
                self.rotations += 1
        elif st.st_size < self.pos:
            self.truncations += 1
            self.stream.drop_partial()
            self.pos = 0

    def poll(self, timeout_s: float = 0.0) -> list[Line]:
        out: list[Line] = []
        end = time.monotonic() + timeout_s
        while not self.closed:
            if self._read_some(out) == 0 and len(out) < self.max_lines:
                self._check_rotation()
                self._read_some(out)
            now = time.monotonic()
            if out or now >= end:
                break
            time.sleep(min(self.interval_s, end - now))
        return out

    def close(self) -> None:
        if not self.closed and self._fd is not None:
            os.close(self._fd)
            self._fd = None
        super().close()


def open_source(spec: str, **options: object) -> LiveSource:
    """The live source a spec names: ``udp://HOST:PORT``, ``tcp://HOST:PORT``,
    ``serial:///dev/DEVICE?baud=N`` or a device path (``/dev/ttyUSB0``, any character
    device), ``file:PATH`` or a plain path (a growing file).  ``options`` go to the
    source's class (:class:`UdpSource` ``allow_multicast``; :class:`TcpSource`
    ``backoff_first_s``, ``backoff_cap_s``; :class:`FileSource` ``from_start``;
    ``SerialSource`` ``baud`` (None: the spec's or 4800); ``baud`` and ``allow_multicast``
    are ignored by the sources they do not concern;
    ``backoff_first_s``, ``backoff_cap_s``; all ``max_line_bytes``, ``max_lines``,
    ``clock``).  Raises IngestError for a spec it cannot open."""
    scheme = urlsplit(spec).scheme if "://" in spec else ""
    baud = options.pop("baud", None)
    allow_multicast = bool(options.pop("allow_multicast", False))
    try:
        if scheme == "udp":
            return UdpSource(spec, allow_multicast=allow_multicast, **options)  # type: ignore[arg-type]
        if scheme == "tcp":
            return TcpSource(spec, **options)  # type: ignore[arg-type]
        if scheme == "serial" or (not scheme and is_serial_spec(spec)):
            return SerialSource(spec, baud=baud, **options)  # type: ignore[arg-type]
        if scheme:
            raise IngestError(
                f"{spec}: unknown source (udp://, tcp://, serial://, file: or a path)"
            )
        return FileSource(spec, **options)  # type: ignore[arg-type]
    except TypeError as err:
        raise IngestError(f"{spec}: {err}") from err


def poll_all(sources: Sequence[LiveSource], timeout_s: float = 0.0) -> list[tuple[int, Line]]:
    """Lines of several sources as (index of the source, (recv_ns, line)): each polled
    without waiting, then, while none had any, again every few milliseconds until
    ``timeout_s`` has passed."""
    end = time.monotonic() + timeout_s
    while True:
        out = [(i, ln) for i, s in enumerate(sources) for ln in s.poll(0.0)]
        now = time.monotonic()
        if out or now >= end:
            return out
        time.sleep(min(0.005, end - now))
