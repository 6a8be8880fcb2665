"""Issue 33: datagrams the kernel drops (a receive buffer full: 7.16 M lost in the issue's
run, while the status said ``dropped {}``) are counted and shown: ``kernel_dropped`` per
input in the ``dracc.watch/1`` status, in its ``dropped`` total and on the terminal.

A socket with a small receive buffer on 127.0.0.1 is flooded without being read, then
read: the kernel's count comes with the next datagram (Linux ``SO_RXQ_OVFL``)."""

from __future__ import annotations

import io
import socket
import time

import pytest
from rich.console import Console

from dracc.ingest.live.sources import KERNEL_DROPPED, SO_RXQ_OVFL, UdpSource
from dracc.pipeline.watch import Watch
from dracc.report.watch_view import status_view

FLOOD = 5000


def _flooded() -> UdpSource:
    src = UdpSource("udp://127.0.0.1:0")
    if not src._ancillary:
        src.close()
        pytest.skip(f"no SO_RXQ_OVFL here ({SO_RXQ_OVFL}): the kernel does not tell its drops")
    src.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)  # a few datagrams
    tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        for k in range(FLOOD):  # nobody reads meanwhile: the kernel drops most of them
            tx.sendto(b"$GPHDT,%d.5,T*00\r\n" % k, src.address)
        return src
    finally:
        tx.close()


def test_the_kernels_drops_are_counted_per_input_and_shown():
    src = _flooded()
    watch = Watch([src], dropout_s=1e6)
    try:
        watch.step(0.2)  # what the buffer held
        tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        tx.sendto(b"$GPHDT,1.5,T*00\r\n", src.address)  # carries the count
        tx.close()
        end = time.monotonic() + 5
        while watch.received < 2 or not src.rejected[KERNEL_DROPPED]:
            watch.step(0.1)
            assert time.monotonic() < end, dict(src.rejected)
        st = watch.status()
    finally:
        watch.close()
    kernel = st["inputs"][0]["dropped"][KERNEL_DROPPED]
    assert kernel > 0 and kernel + st["received"] == FLOOD + 1  # every datagram accounted for
    assert st["dropped"][KERNEL_DROPPED] == kernel
    console = Console(width=200, record=True, file=io.StringIO())
    console.print(status_view(st))
    assert f"{kernel:,} by the kernel: its receive buffer was full" in console.export_text()
