"""Live inputs (UDP plain and IEC 61162-450, TCP with reconnection, a growing file with
rotation) and the recording, read back by the NMEA reader.  Everything is sent to
127.0.0.1 only; nothing joins a multicast group."""

from __future__ import annotations

import os
import re
import socket
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from dracc.core.config import IngestConfig
from dracc.core.errors import IngestError
from dracc.ingest.live import Recorder, open_source, poll_all, tag_line
from dracc.ingest.live.sources import FileSource, TcpSource, UdpSource
from dracc.ingest.nmea import read_nmea

REPO = Path(__file__).resolve().parents[1]
SAMPLE = REPO / "sample_logs" / "voyage_tag.nmea"
TAG = re.compile(rb"^\\([^*\\]*)\*([0-9A-F]{2})\\")


def _drain(src, want: int, timeout_s: float = 3.0) -> list[tuple[int, bytes]]:
    got: list[tuple[int, bytes]] = []
    end = time.monotonic() + timeout_s
    while len(got) < want and time.monotonic() < end:
        got.extend(src.poll(0.05))
    return got


@pytest.fixture
def udp():
    src = open_source("udp://127.0.0.1:0")
    tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    yield src, tx
    tx.close()
    src.close()


def test_udp_plain_and_iec450(udp):
    src, tx = udp
    assert isinstance(src, UdpSource)
    t0 = time.time_ns()
    tx.sendto(b"$HEHDT,60.406,T*1B\r\n", src.address)
    tx.sendto(b"$HEHDT,60.5,T*25\r\n$HEROT,12.80,A*20\r\n", src.address)  # two lines
    tx.sendto(b"UdPbC\x00\\s:GYRO,c:1772344800*37\\$HEHDT,60.406,T*1B\r\n", src.address)
    # a line group of two sentences: kept as received, for the NMEA reader
    grp = b"UdPbC\x00\\g:1-2-7,s:AI01*2D\\!AIVDO,2,1,3,A,abc,0*00\r\n\\g:2-2-7*57\\!AIVDO,2,2,3,A,d,0*00\r\n"
    tx.sendto(grp, src.address)
    got = _drain(src, 6)
    lines = [ln for _, ln in got]
    assert lines == [
        b"$HEHDT,60.406,T*1B",
        b"$HEHDT,60.5,T*25",
        b"$HEROT,12.80,A*20",
        b"\\s:GYRO,c:1772344800*37\\$HEHDT,60.406,T*1B",
        b"\\g:1-2-7,s:AI01*2D\\!AIVDO,2,1,3,A,abc,0*00",
        b"\\g:2-2-7*57\\!AIVDO,2,2,3,A,d,0*00",
    ]
    assert all(t0 <= t <= time.time_ns() for t, _ in got)
    assert got[1][0] == got[2][0]  # one datagram, one receive time
    assert src.datagrams == 4 and src.iec450 == 2 and not src.rejected


def test_udp_bad_datagrams_counted_not_fatal(udp):
    src, tx = udp
    tx.sendto(bytes(range(256)), src.address)  # binary
    tx.sendto(b"RaUdP\x00\x01\x02binary file", src.address)  # 61162-450 binary transfer
    tx.sendto(b"UdPbC\x00", src.address)  # a header and nothing after it
    tx.sendto(b"\r\n\r\n", src.address)  # no line
    tx.sendto(b"$" + b"A" * 5000 + b"\r\n$HEHDT,1.0,T*00", src.address)  # one line too long
    tx.sendto(b"$HEHDT,60.406,T*1B", src.address)  # no line end: still a line
    got = _drain(src, 2)
    assert [ln for _, ln in got] == [b"$HEHDT,1.0,T*00", b"$HEHDT,60.406,T*1B"]
    assert src.rejected == {"binary": 2, "empty": 2, "too_long": 1}
    assert src.datagrams == 6


def test_udp_multicast_needs_consent():
    with pytest.raises(IngestError, match="allow_multicast"):
        open_source("udp://239.192.0.1:60001")
    with pytest.raises(IngestError):
        open_source("udp://127.0.0.1")  # no port
    with pytest.raises(IngestError):
        open_source("ftp://127.0.0.1:21")


def test_udp_loopback_rate():
    """20 000 IEC 61162-450 datagrams through loopback, none lost, sender and receiver
    in one thread (bursts of 100, well inside the receive buffer); the rate is printed,
    not asserted (a benchmark, not a timed test)."""
    src = open_source("udp://127.0.0.1:0")
    tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    dgram = b"UdPbC\x00\\s:GYRO,c:1772344800*37\\$HEHDT,60.406,T*1B\r\n"
    n, got = 20_000, 0
    t0 = time.perf_counter()
    for _ in range(n // 100):
        for _ in range(100):
            tx.sendto(dgram, src.address)
        got += len(src.poll(0.0))
    while got < n:
        more = src.poll(0.2)
        if not more:
            break
        got += len(more)
    dt = time.perf_counter() - t0
    tx.close()
    src.close()
    print(f"UDP loopback: {got} of {n} lines in {dt:.3f} s = {got / dt:,.0f} lines/s")
    assert got == n and not src.rejected


def _serve(server: socket.socket, payloads: list[bytes]) -> None:
    for data in payloads:
        conn, _ = server.accept()
        conn.sendall(data)
        conn.close()


def test_tcp_reconnects():
    server = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    server.bind(("127.0.0.1", 0))
    server.listen(1)
    port = server.getsockname()[1]
    first = b"$HEHDT,1.0,T*00\r\n$HEHDT,2.0,T*00\r\n$HEHDT,3.0"  # closes mid-line
    second = b"$HEHDT,4.0,T*00\r\n$HEHDT,5.0,T*00\n\n$HEHDT,6.0,T*00\r\n"
    th = threading.Thread(target=_serve, args=(server, [first, second]), daemon=True)
    th.start()
    src = open_source(f"tcp://127.0.0.1:{port}", backoff_first_s=0.05, backoff_cap_s=0.2)
    assert isinstance(src, TcpSource)
    got = _drain(src, 5, timeout_s=5.0)
    src.close()
    th.join(2)
    server.close()
    assert [ln for _, ln in got] == [b"$HEHDT,%d.0,T*00" % k for k in (1, 2, 4, 5, 6)]
    assert src.connects == 2 and src.failures >= 1
    assert src.rejected == {"partial": 1}


def test_tcp_refused_backs_off():
    probe = socket.socket()
    probe.bind(("127.0.0.1", 0))
    port = probe.getsockname()[1]
    probe.close()  # nothing listens there now
    src = TcpSource(f"tcp://127.0.0.1:{port}", backoff_first_s=0.02, backoff_cap_s=0.08)
    t0 = time.monotonic()
    while time.monotonic() - t0 < 0.5:
        assert src.poll(0.05) == []
    src.close()
    # waits 0.02, 0.04, 0.08, 0.08 ...: about 8 attempts in 0.5 s, not hundreds
    assert 3 <= src.failures <= 12
    assert src.backoff_s == pytest.approx(0.08)


def test_growing_file_rotation(tmp_path):
    log = tmp_path / "nav.log"
    log.write_bytes(b"$OLD,before,start*00\r\n")  # there before: tail -f starts at the end
    src = open_source(f"file:{log}")
    assert isinstance(src, FileSource)
    expected = []

    def append(path: Path, k0: int, k1: int) -> None:
        with open(path, "ab") as fh:
            for k in range(k0, k1):
                fh.write(b"$HEHDT,%d.0,T*00\r\n" % k)
                expected.append(b"$HEHDT,%d.0,T*00" % k)

    append(log, 0, 100)
    got = _drain(src, 100)
    with open(log, "ab") as fh:  # half a line: held until its end arrives
        fh.write(b"$HEHDT,100")
    assert src.poll(0.1) == []
    with open(log, "ab") as fh:
        fh.write(b".0,T*00\r\n")
    expected.append(b"$HEHDT,100.0,T*00")
    append(log, 101, 150)
    os.rename(log, tmp_path / "nav.log.1")  # rotation: the writer finishes the old file
    append(tmp_path / "nav.log.1", 150, 160)
    append(log, 160, 300)  # ... and begins a new one
    got += _drain(src, 300 - len(got))
    log.write_bytes(b"")  # truncated in place (copytruncate)
    append(log, 300, 310)
    got += _drain(src, 310 - len(got))
    src.close()
    assert [ln for _, ln in got] == expected
    assert src.rotations == 1 and src.truncations == 1


def test_file_from_start_and_not_yet_there(tmp_path):
    log = tmp_path / "later.log"
    src = open_source(str(log), from_start=True)
    assert src.poll(0.05) == []
    log.write_bytes(b"$HEHDT,1.0,T*00\n\x00\x01\x02\n" + b"$" * 5000 + b"\n$HEHDT,2.0,T*00\n")
    got = _drain(src, 2)
    src.close()
    assert [ln for _, ln in got] == [b"$HEHDT,1.0,T*00", b"$HEHDT,2.0,T*00"]
    assert src.rejected == {"binary": 1, "too_long": 1}


def test_poll_all(tmp_path, udp):
    usrc, tx = udp
    log = tmp_path / "a.log"
    log.write_bytes(b"")
    fsrc = open_source(str(log))
    with open(log, "ab") as fh:
        fh.write(b"$HEHDT,1.0,T*00\n")
    tx.sendto(b"$HEHDT,2.0,T*00\n", usrc.address)
    got: list = []
    end = time.monotonic() + 2
    while len(got) < 2 and time.monotonic() < end:
        got += poll_all([usrc, fsrc], 0.1)
    fsrc.close()
    assert sorted((i, ln) for i, (_, ln) in got) == [
        (0, b"$HEHDT,2.0,T*00"),
        (1, b"$HEHDT,1.0,T*00"),
    ]


# -- the recording --------------------------------------------------------------------


def test_tag_line_checksums():
    # by hand: 's:GYRO,c:1772344800' XORs to 0x37 (the sample log); adding '000' (three
    # times 0x30) and reordering gives 0x37 ^ 0x30 = 0x07
    ns = 1772344800 * 10**9
    assert (
        tag_line(b"$HEHDT,60.406,T*1B", ns, "GYRO")
        == b"\\c:1772344800000,s:GYRO*07\\$HEHDT,60.406,T*1B"
    )
    # a TAG block without c: gets one: 'c:1772344800000,' + 's:GYRO' -> 0x07 as well
    got = tag_line(b"\\s:GYRO*4A\\$HEHDT,60.406,T*1B", ns)
    assert got == b"\\c:1772344800000,s:GYRO*07\\$HEHDT,60.406,T*1B"
    # kept as received: a c: there already, a wrong checksum, not a sentence
    for line in (
        b"\\s:GYRO,c:1772344800*37\\$HEHDT,60.406,T*1B",
        b"\\s:GYRO*00\\$HEHDT,60.406,T*1B",
        b"# a comment",
    ):
        assert tag_line(line, ns, "X") == line


def _lines_and_times(path: Path) -> list[tuple[int, bytes, str]]:
    out = []
    for raw in path.read_bytes().splitlines():
        m = TAG.match(raw)
        assert m
        params = dict(p.split(b":", 1) for p in m.group(1).split(b","))
        out.append((int(params[b"c"]) * 10**9, raw[m.end() :], params[b"s"].decode()))
    return out


@pytest.fixture(scope="module")
def original():
    return read_nmea(SAMPLE, IngestConfig(), workers=1)


def _same_frames(a, b, sources_equal=True):
    assert set(a.frames) == set(b.frames)
    for kind, fa in a.frames.items():
        fb = b.frames[kind]
        assert len(fa) == len(fb), kind
        for col in fa.columns:
            if col == "line" or (col == "source" and not sources_equal):
                continue
            va, vb = fa[col].to_numpy(), fb[col].to_numpy()
            if va.dtype.kind == "f":
                np.testing.assert_array_equal(va, vb, err_msg=f"{kind}.{col}")
            else:
                assert list(va) == list(vb), f"{kind}.{col}"


@pytest.mark.parametrize("form", ["stripped", "kept"])
def test_recording_reads_back_as_the_original(tmp_path, original, form):
    entries = _lines_and_times(SAMPLE)
    rec = Recorder(tmp_path / "rec")
    if form == "stripped":  # lines as heard without TAG blocks, the source given
        for t, line, s in entries:
            rec.write(line, t, s)
    else:  # lines with their TAG blocks: written byte for byte
        for (t, _, _), raw in zip(entries, SAMPLE.read_bytes().splitlines(), strict=True):
            rec.write(raw, t + 123_456_789)  # its c: stays: the receive time is not added
    rec.close()
    assert not list((tmp_path / "rec").glob("*.part"))
    (out,) = rec.files
    assert out.name == "dracc-20260301.nmea"  # the UTC day of the receive times
    if form == "kept":
        assert out.read_bytes() == SAMPLE.read_bytes().replace(b"\r\n", b"\n").replace(
            b"\n", b"\r\n"
        )
    back = read_nmea(out, IngestConfig(), workers=1)
    assert back.rejects.total == original.rejects.total == 0
    assert back.records == original.records > 5000
    _same_frames(original, back)


def test_rotation_by_size_and_day(tmp_path):
    clock = [1772409599 * 10**9]  # 2026-03-01 23:59:59 UTC
    rec = Recorder(tmp_path, max_bytes=400, now_ns=lambda: clock[0])
    line = b"$HEHDT,60.406,T*1B"
    for k in range(20):  # 20 lines of 50 bytes on 2026-03-01: 8 a file
        rec.write(line, clock[0] + k * 1_000_000, "GYRO")
    assert rec.current is not None and rec.current.name.endswith(".part")
    rec.write(line, clock[0] + 2 * 10**9, "GYRO")  # 2026-03-02 00:00:01: a new day
    rec.write(line, None, "GYRO")  # a late line stamped by the clock (23:59:59): its own day
    clock[0] += 10 * 86_400 * 10**9
    rec.tick()  # ten days on, nothing heard: the file of 2026-03-02 is finished
    assert rec.current is None
    rec.close()
    names = [p.name for p in rec.files]
    assert names == [
        "dracc-20260301.nmea",
        "dracc-20260301-1.nmea",
        "dracc-20260301-2.nmea",
        "dracc-20260302.nmea",
        "dracc-20260301-3.nmea",
    ]
    sizes = [p.stat().st_size for p in rec.files]
    assert all(s <= 400 for s in sizes)
    assert sum(len(p.read_bytes().splitlines()) for p in rec.files) == 22
    assert not list(tmp_path.glob("*.part"))


def test_crash_leftover_finished(tmp_path):
    (tmp_path / "dracc-20260301.nmea.part").write_bytes(
        b"\\c:1772344800000,s:GYRO*07\\$HEHDT,60.406,T*1B\r\n\\c:17723"  # cut mid-line
    )
    (tmp_path / "dracc-20260302.nmea.part").write_bytes(b"\\c:177")  # not one line
    rec = Recorder(tmp_path)
    rec.close()
    assert [p.name for p in rec.recovered] == ["dracc-20260301.nmea"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["dracc-20260301.nmea"]
    res = read_nmea(tmp_path / "dracc-20260301.nmea", IngestConfig(), workers=1)
    assert res.records == 1 and res.rejects.total == 0


def test_udp_to_recording(tmp_path, original):
    """The sample voyage sent as IEC 61162-450 datagrams, recorded, read back."""
    raw = SAMPLE.read_bytes().splitlines()
    src = open_source("udp://127.0.0.1:0")
    tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    rec = Recorder(tmp_path)
    got = 0
    for i in range(0, len(raw), 100):
        for line in raw[i : i + 100]:
            tx.sendto(b"UdPbC\x00" + line + b"\r\n", src.address)
        lines = src.poll(0.0)
        got += len(lines)
        rec.write_many(lines)
    while got < len(raw):
        lines = src.poll(0.2)
        if not lines:
            break
        got += len(lines)
        rec.write_many(lines)
    tx.close()
    src.close()
    rec.close()
    assert got == len(raw) and not src.rejected
    back = read_nmea(rec.files[0], IngestConfig(), workers=1)
    _same_frames(original, back)


def test_long_line_across_reads_skipped(tmp_path):
    """A line too long is dropped without being held: its bytes are skipped up to the
    next line end, even when that comes in a later read."""
    log = tmp_path / "long.log"
    log.write_bytes(b"")
    src = FileSource(str(log), max_line_bytes=32)
    with open(log, "ab") as fh:
        fh.write(b"$HEHDT,1.0,T*00\n$" + b"A" * 40)
    first = _drain(src, 1)
    with open(log, "ab") as fh:
        fh.write(b"B" * 40 + b"\n$HEHDT,2.0,T*00\r" + b"C" * 50 + b"\r$HEHDT,3.0,T*00\n")
    rest = _drain(src, 2)
    src.close()
    assert [ln for _, ln in first + rest] == [b"$HEHDT,%d.0,T*00" % k for k in (1, 2, 3)]
    assert src.rejected == {"too_long": 2}
