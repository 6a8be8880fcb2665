"""The serial live source, with a pseudo-terminal as the device: NMEA lines written into
the master are read through :class:`SerialSource` on the slave.  The line settings are
checked against the kernel's termios of the slave (not against what dracc asked for);
"never transmits" is checked on the master side (nothing to read there); a device that
goes away is a closed master (the slave then reads nothing), and coming back is a
symlink re-pointed to a new pty; ``dracc watch`` end to end on a pty."""

from __future__ import annotations

import json
import os
import select
import termios
import threading
import time
from collections import Counter
from pathlib import Path

import pytest

from dracc.core.errors import IngestError
from dracc.ingest.live import FileSource, SerialSource, UdpSource, open_source, poll_all

REPO = Path(__file__).resolve().parents[1]
SAMPLE = REPO / "sample_logs" / "voyage_tag.nmea"
GGA = b"$GPGGA,120000.00,5400.0000,N,01000.0000,E,1,08,0.9,10.0,M,40.0,M,,*5A"
HDT = b"$HEHDT,123.4,T*2B"


class Pty:
    """A pseudo-terminal: ``write`` into the master, ``path`` the slave device."""

    def __init__(self) -> None:
        self.master, self.slave = os.openpty()
        self.path = os.ttyname(self.slave)

    def write(self, data: bytes) -> None:
        os.write(self.master, data)

    def attrs(self) -> list:
        return termios.tcgetattr(self.slave)

    def transmitted(self) -> bytes:
        """What the reader wrote towards the master (nothing, ever)."""
        out = b""
        while select.select([self.master], [], [], 0.05)[0]:
            out += os.read(self.master, 4096)
        return out

    def unplug(self) -> None:
        for fd in (self.master, self.slave):
            if fd >= 0:
                os.close(fd)
        self.master = self.slave = -1


@pytest.fixture
def pty():
    p = Pty()
    yield p
    p.unplug()


def _lines(src, want: int, timeout_s: float = 3.0) -> list[bytes]:
    got: list[bytes] = []
    end = time.monotonic() + timeout_s
    while len(got) < want and time.monotonic() < end:
        got += [ln for _, ln in src.poll(0.05)]
    return got


def test_lines_split_across_writes_and_rejects(pty):
    with open_source(pty.path) as src:
        assert isinstance(src, SerialSource)
        t0 = time.time_ns()
        for piece in (GGA[:10], GGA[10:40], GGA[40:] + b"\r\n" + HDT[:5], HDT[5:] + b"\r\n"):
            pty.write(piece)
            time.sleep(0.01)
        pty.write(b"$GPXXX,\x01\x02\xff*00\r\n")  # binary: dropped, the rest kept
        pty.write(b"$" + b"A" * 5000 + b"\r\n")  # longer than max_line_bytes
        pty.write(HDT + b"\n" + GGA + b"\r")  # LF and a lone CR end lines too
        got = []
        end = time.monotonic() + 3
        while len(got) < 4 and time.monotonic() < end:
            got += src.poll(0.05)
        assert [ln for _, ln in got] == [GGA, HDT, HDT, GGA]
        assert all(t0 <= t <= time.time_ns() for t, _ in got)
        assert src.rejected == {"binary": 1, "too_long": 1}
        assert src.lines == 4 and src.opens == 1 and src.failures == 0
        assert pty.transmitted() == b""  # listening only: nothing ever went the other way


def test_line_settings_reach_the_device(pty, monkeypatch):
    # the kernel's termios of the slave, read on the test's own descriptor; the pty
    # driver forces CS8 without parity, so those two are checked on the call to the
    # kernel (tcsetattr) instead
    import serial.serialposix

    asked: list = []
    real = serial.serialposix.termios.tcsetattr

    def tcsetattr(fd, when, attrs):
        asked.append(list(attrs))
        return real(fd, when, attrs)

    monkeypatch.setattr(serial.serialposix.termios, "tcsetattr", tcsetattr)
    with open_source(pty.path):
        iflag, _, cflag, lflag, ispeed, ospeed, _ = pty.attrs()
        assert ispeed == ospeed == termios.B4800  # NMEA 0183 default
        assert cflag & termios.CSIZE == termios.CS8
        assert not cflag & (termios.PARENB | termios.CSTOPB | termios.CRTSCTS)
        assert not lflag & (termios.ICANON | termios.ECHO)  # raw: bytes as sent
        assert not iflag & (termios.IXON | termios.ICRNL)
    with open_source(f"serial://{pty.path}?baud=38400&bytesize=7&parity=E&stopbits=2"):
        _, _, cflag, _, ispeed, ospeed, _ = pty.attrs()
        assert ispeed == ospeed == termios.B38400  # IEC 61162-2
        assert cflag & termios.CSTOPB
        sent = asked[-1][2]
        assert sent & termios.CSIZE == termios.CS7
        assert sent & termios.PARENB and not sent & termios.PARODD
    with open_source(pty.path, baud=38400) as src:  # --baud where the spec has none
        assert pty.attrs()[5] == termios.B38400 and src.baud == 38400
    with open_source(f"serial://{pty.path}?baud=9600", baud=38400):  # the spec's wins
        assert pty.attrs()[5] == termios.B9600


def test_the_port_is_locked_against_a_second_watch(pty):
    with open_source(pty.path), pytest.raises(IngestError, match="in use"):
        open_source(pty.path)
    open_source(pty.path).close()  # free again once closed


def test_specs_and_their_errors(tmp_path, pty):
    with pytest.raises(IngestError, match=r"^/dev/ttyDRACCNONE: no such serial device$"):
        open_source("/dev/ttyDRACCNONE")
    with pytest.raises(IngestError, match="no such serial device"):
        open_source(f"serial://{tmp_path}/ttyNONE")
    regular = tmp_path / "log.nmea"
    regular.write_bytes(b"")
    with pytest.raises(IngestError, match="not a serial device"):
        SerialSource(str(regular))
    for bad, why in [
        ("?baud=fast", "bad baud"),
        ("?baud=0", "bad baud"),
        ("?parity=X", "bad parity"),
        ("?bytesize=9", "bad bytesize"),
        ("?stopbits=3", "bad stopbits"),
        ("?speed=4800", "unknown setting speed"),
    ]:
        with pytest.raises(IngestError, match=why):
            open_source(f"serial://{pty.path}{bad}")
    with pytest.raises(IngestError, match="expected serial:///dev/"):
        open_source("serial://host/dev/ttyS0")
    # dispatch: a regular file is a growing file; a symlink to a character device is serial
    with open_source(str(regular)) as f:
        assert isinstance(f, FileSource)
    link = tmp_path / "gps"
    link.symlink_to(pty.path)
    with open_source(str(link)) as s:
        assert isinstance(s, SerialSource) and s.path == str(link)
    with open_source("/dev/shm/dracc-not-yet.nmea") as g:  # missing, no device name
        assert isinstance(g, FileSource)
    with open_source("udp://127.0.0.1:0", baud=38400) as u:  # baud: serial sources only
        assert isinstance(u, UdpSource)


def test_unplugged_device_is_reopened_with_backoff(tmp_path):
    first, second = Pty(), Pty()
    link = tmp_path / "ttyNMEA"
    link.symlink_to(first.path)
    src = open_source(str(link), backoff_first_s=0.04, backoff_cap_s=0.16)
    try:
        first.write(GGA + b"\r\n" + HDT[:6])  # an unfinished line when the device goes
        assert _lines(src, 1) == [GGA]
        first.unplug()
        link.unlink()
        link.symlink_to(tmp_path / "nothing")  # away: the device node is missing
        end = time.monotonic() + 3
        while src.failures < 4 and time.monotonic() < end:
            assert src.poll(0.02) == []
        # lost once, then reopenings failed with waits 0.04, 0.08, 0.16 (the cap) ...
        assert src.failures >= 4 and src.port is None and src.reopens == 0
        assert src.backoff_s == pytest.approx(0.16)
        assert src.rejected == {"partial": 1}
        assert "no such serial device" in src.last_error
        tmp = tmp_path / "new"
        tmp.symlink_to(second.path)
        os.replace(tmp, link)  # plugged in again (the kernel may name it anew)
        end = time.monotonic() + 3
        while src.port is None and time.monotonic() < end:
            src.poll(0.02)
        assert src.reopens == 1 and src.opens == 2
        second.write(HDT + b"\r\n" + GGA + b"\r\n")
        assert _lines(src, 2) == [HDT, GGA]
        # a reopening that delivered data: the next wait is the first one again
        second.unplug()
        end = time.monotonic() + 3
        failures = src.failures
        while src.failures == failures and time.monotonic() < end:
            src.poll(0.02)
        assert src.backoff_s == pytest.approx(0.08)  # 0.04 waited, doubled for the next
    finally:
        src.close()
        first.unplug()
        second.unplug()


def test_poll_all_across_two_devices():
    a, b = Pty(), Pty()
    try:
        with open_source(a.path) as sa, open_source(b.path) as sb:
            assert poll_all([sa, sb], 0.05) == []
            a.write(GGA + b"\r\n")
            b.write(HDT + b"\r\n")
            got: list = []
            end = time.monotonic() + 3
            while len(got) < 2 and time.monotonic() < end:
                got += poll_all([sa, sb], 0.2)
            assert sorted((i, ln) for i, (_, ln) in got) == [(0, GGA), (1, HDT)]
    finally:
        a.unplug()
        b.unplug()


def test_the_source_never_writes():
    text = (REPO / "dracc" / "ingest" / "live" / "serial_source.py").read_text()
    assert ".write(" not in text and "send_break" not in text


def test_watch_a_pty_end_to_end(tmp_path, pty, run_cli):
    lines = SAMPLE.read_bytes().splitlines()[:300]
    want = Counter(ln[3 : ln.index(b",")].decode() for ln in lines)  # TAG s:, by hand
    status = tmp_path / "status.json"
    seen: dict = {}

    def device() -> None:  # once the watch has the port open (its first status)
        end = time.monotonic() + 5
        while not status.exists() and time.monotonic() < end:
            time.sleep(0.01)
        seen["ospeed"] = pty.attrs()[5]
        for i in range(0, len(lines), 50):
            pty.write(b"".join(ln + b"\r\n" for ln in lines[i : i + 50]))
        pty.write(b"\x00\x01binary\xfe\r\n")

    writer = threading.Thread(target=device)
    writer.start()
    code, _, err = run_cli(
        "watch", pty.path, "--duration", "1.5s", "--status", status, "--status-every", "0.2s",
        "--baud", "38400",
    )  # fmt: skip
    writer.join()
    st = json.loads(status.read_text())
    assert code == 0, err
    assert seen["ospeed"] == termios.B38400
    assert st["received"] == len(lines) and st["dropped"] == {"binary": 1}
    assert {k: v["records"] for k, v in st["sources"].items()} == dict(want)


def test_watch_a_missing_device_is_one_line(run_cli):
    code, out, err = run_cli("watch", "/dev/ttyDRACCNONE", "--duration", "1s")
    assert code == 3  # ExitCode.INPUT, as for any source that cannot be opened
    assert err.strip() == "error: /dev/ttyDRACCNONE: no such serial device"
    assert "Traceback" not in out + err
