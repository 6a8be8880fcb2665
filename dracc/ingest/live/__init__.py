"""Live inputs for ``dracc watch``, listening only, and the recording of what was heard.

* :mod:`~dracc.ingest.live.sources`: ``open_source(spec) -> LiveSource`` for
  ``udp://HOST:PORT`` (plain NMEA or IEC 61162-450 datagrams), ``tcp://HOST:PORT`` (a
  client that reconnects with backoff) and a growing file (``file:PATH`` or a path,
  ``tail -f`` surviving rotation); ``poll(timeout_s) -> [(recv_ns, line)]``, ``close()``,
  what was dropped counted by reason in ``rejected``.
* :mod:`~dracc.ingest.live.record`: :class:`Recorder`, the received lines with their
  receive times as TAG-block NMEA 0183 in daily files finished atomically, which
  ``dracc inspect``/``analyze``/``audit`` read as any log.
"""

from dracc.ingest.live.record import Recorder, tag_line
from dracc.ingest.live.sources import (
    FileSource,
    LiveSource,
    TcpSource,
    UdpSource,
    open_source,
    poll_all,
)

__all__ = [
    "FileSource",
    "LiveSource",
    "Recorder",
    "TcpSource",
    "UdpSource",
    "open_source",
    "poll_all",
    "tag_line",
]
