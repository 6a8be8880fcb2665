"""Live inputs for ``dracc watch``, listening only, and the recording of what was heard.

* :mod:`~dracc.ingest.live.sources`: ``open_source(spec) -> LiveSource`` for
  ``udp://HOST:PORT`` (plain NMEA or IEC 61162-450 datagrams), ``tcp://HOST:PORT`` (a
  client that reconnects with backoff) and a growing file (``file:PATH`` or a path,
  ``tail -f`` surviving rotation); ``poll(timeout_s) -> [(recv_ns, line)]``, ``close()``,
  what was dropped counted by reason in ``rejected``.
* :mod:`~dracc.ingest.live.serial_source`: :class:`SerialSource` for a serial device
  (``serial:///dev/ttyUSB0?baud=38400`` or a device path; 4800 baud 8N1 by default),
  read with pyserial, never written to, reopened with backoff when it goes away.
* :mod:`~dracc.ingest.live.record`: :class:`Recorder`, the received lines with their
  receive times as TAG-block NMEA 0183 in daily files finished atomically, which
  ``dracc inspect``/``analyze``/``audit`` read as any log; NMEA 2000 and Signal K lines
  as received, each form in its own daily file (:func:`form_suffix`).
* :mod:`~dracc.ingest.live.forms`: ``classify(line) -> LineInfo(form, key, c_ns)``,
  what a received line is (NMEA 0183, a NMEA 2000 text form, Signal K) and its source
  key, from a cheap look at its bytes; ``line_key(line) -> (key, c_ns)`` of a sentence.
"""

from dracc.ingest.live.forms import FORMS, LineInfo, classify, line_key
from dracc.ingest.live.record import Recorder, form_suffix, tag_line
from dracc.ingest.live.serial_source import SerialSource
from dracc.ingest.live.sources import (
    FileSource,
    LiveSource,
    TcpSource,
    UdpSource,
    open_source,
    poll_all,
)

__all__ = [
    "FORMS",
    "FileSource",
    "LineInfo",
    "LiveSource",
    "Recorder",
    "SerialSource",
    "TcpSource",
    "UdpSource",
    "classify",
    "form_suffix",
    "line_key",
    "open_source",
    "poll_all",
    "tag_line",
]
