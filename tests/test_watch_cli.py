"""``dracc watch`` as a process: lines of the sample voyage sent as UDP datagrams to
127.0.0.1, counted per source in the status while it runs; one source silenced then
resumed (``availability/dropout`` raised and cleared); a bad datagram counted; SIGTERM ends it with
exit 0 and a recording that reads back to the same records as the lines sent."""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from collections import Counter
from pathlib import Path

import pandas as pd
import pytest

from dracc.core.config import IngestConfig
from dracc.ingest.nmea import read_nmea

REPO = Path(__file__).resolve().parents[1]
SAMPLE = REPO / "sample_logs" / "voyage_tag.nmea"
SILENT = "GYRO"  #: the source silenced for longer than --dropout, then resumed


def _source(line: bytes) -> str:  # the TAG s: of a sample line, parsed here by hand
    return line[3 : line.index(b",")].decode()


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _status(path: Path) -> dict:
    try:
        return json.loads(path.read_text())
    except (FileNotFoundError, json.JSONDecodeError):
        return {}


def _wait(path: Path, ok, timeout_s: float = 8.0) -> dict:
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        st = _status(path)
        if st and ok(st):
            return st
        time.sleep(0.05)
    raise AssertionError(f"status never satisfied: {_status(path)}")


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("watch")
    lines = SAMPLE.read_bytes().splitlines()
    first, rest = lines[:2000], lines[2000:]
    port = _free_port()
    status, rec = tmp / "status.json", tmp / "rec"
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    proc = subprocess.Popen(
        [sys.executable, "-m", "dracc", "watch", f"udp://127.0.0.1:{port}", "--record", str(rec)]
        + ["--status", str(status), "--status-every", "0.2s", "--dropout", "1s"],
        stderr=subprocess.PIPE,
        env=env,
    )
    tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sent: list[bytes] = []
    try:
        _wait(status, lambda st: "received" in st, timeout_s=15)
        for i, ln in enumerate(first):  # paced: the receive buffer is never the limit
            tx.sendto(ln + b"\r\n", ("127.0.0.1", port))
            sent.append(ln)
            if i % 200 == 199:
                time.sleep(0.01)
        want = Counter(_source(ln) for ln in first)
        during = _wait(
            status, lambda st: {k: v["records"] for k, v in st["sources"].items()} == want
        )
        # the others go on every 0.1 s; SILENT says nothing for 1.6 s (> --dropout), then resumes
        others = iter(ln for ln in rest if _source(ln) != SILENT)
        t_end = time.monotonic() + 1.6
        while time.monotonic() < t_end:
            for _ in range(6):
                ln = next(others)
                tx.sendto(ln + b"\r\n", ("127.0.0.1", port))
                sent.append(ln)
            time.sleep(0.1)
        raised = _wait(status, lambda st: any(f["source"] == SILENT for f in st["findings"]))
        resumed = next(ln for ln in rest if _source(ln) == SILENT)
        tx.sendto(resumed + b"\r\n", ("127.0.0.1", port))
        sent.append(resumed)
        tx.sendto(b"\x00\x01\x02binary\xff\xfe", ("127.0.0.1", port))  # a bad datagram
        cleared = _wait(
            status,
            lambda st: (
                st["dropped"].get("binary") == 1
                and all(f["cleared_utc"] for f in st["findings"] if f["source"] == SILENT)
            ),
        )
    finally:
        tx.close()
        proc.send_signal(signal.SIGTERM)
        _, errtext = proc.communicate(timeout=10)
    return {
        "code": proc.returncode,
        "stderr": errtext.decode(),
        "sent": sent,
        "want": want,
        "during": during,
        "raised": raised,
        "cleared": cleared,
        "final": _status(status),
        "rec": rec,
        "tmp": tmp,
    }


def test_status_counts_every_source_while_running(run):
    st = run["during"]
    assert st["schema"] == "dracc.watch/2"
    assert st["received"] == 2000 and st["dropped"] == {}
    assert set(st["sources"]) == {"GYRO", "MAG", "LOG", "INS1", "INS2", "INS3", "GNSS"}
    for key, s in st["sources"].items():
        assert s["role"] is None and s["records"] == run["want"][key]
        assert s["lines_per_s"] > 0 and s["age_s"] >= 0 and s["last_utc"].endswith("Z")
        # latency = receive time - c: of the source's last line (whole seconds in the sample)
        last = [ln for ln in run["sent"][:2000] if _source(ln) == key][-1]
        c_s = int(last[last.index(b",c:") + 3 : last.index(b"*")])
        recv_s = pd.Timestamp(s["last_utc"]).timestamp()
        assert s["latency_s"] == pytest.approx(recv_s - c_s, abs=0.002)
    # the first analysis of the window is due after --analyse-every (30 s by default)
    assert st["analysis"]["window_s"] == 3600.0 and st["analysis"]["every_s"] == 30.0


def test_dropout_raised_then_cleared_with_evidence(run):
    open_ = [f for f in run["raised"]["findings"] if f["source"] == SILENT]
    assert open_ and (open_[0]["check"], open_[0]["name"]) == ("availability", "dropout")
    assert open_[0]["cleared_utc"] is None
    assert open_[0]["evidence"]["age_s"] > 1.0
    done = [f for f in run["final"]["findings"] if f["source"] == SILENT]
    assert len(done) == 1 and done[0]["cleared_utc"] >= done[0]["raised_utc"]
    assert f"availability/dropout raised: {SILENT}:" in run["stderr"]
    assert f"availability/dropout cleared: {SILENT}:" in run["stderr"]


def test_bad_datagram_counted_never_fatal(run):
    assert run["final"]["dropped"] == {"binary": 1}
    assert run["final"]["received"] == len(run["sent"])


def test_sigterm_exits_0_and_the_recording_reads_as_the_lines_sent(run):
    assert run["code"] == 0, run["stderr"]
    files = sorted(run["rec"].iterdir())
    assert files and not [p for p in files if p.name.endswith(".part")]
    recorded = [ln for p in files for ln in p.read_bytes().splitlines()]
    sent = run["sent"]
    assert len(recorded) >= 0.999 * len(sent)
    assert recorded == sent  # TAG blocks with c: kept as received: byte for byte
    original = run["tmp"] / "sent.nmea"
    original.write_bytes(b"".join(ln + b"\r\n" for ln in sent))
    cfg = IngestConfig()
    a = read_nmea(original, cfg).frames
    together = run["tmp"] / "recorded.nmea"  # one file, or two after a UTC midnight
    together.write_bytes(b"".join(p.read_bytes() for p in files))
    b = read_nmea(together, cfg).frames
    assert set(a) == set(b) and {"position", "heading"} <= set(a)
    for kind in a:
        pd.testing.assert_frame_equal(a[kind], b[kind])


def test_tty_gets_the_live_view_and_analysis_fills_it(tmp_path):
    """stdout a terminal (a pty): the rich view is drawn, findings are not printed on
    stderr; with --analyse-every 0.5s the sources get their roles from the analysis."""
    import pty

    master, slave = pty.openpty()
    port = _free_port()
    status = tmp_path / "status.json"
    env = {**os.environ, "PYTHONPATH": str(REPO), "COLUMNS": "120", "LINES": "60"}
    proc = subprocess.Popen(
        [sys.executable, "-m", "dracc", "watch", f"udp://127.0.0.1:{port}", "--status"]
        + [str(status), "--status-every", "0.2s", "--analyse-every", "0.5s"],
        stdout=slave,
        stderr=subprocess.PIPE,
        env=env,
    )
    os.close(slave)
    chunks: list[bytes] = []

    def drain() -> None:  # a terminal is read, or the writer blocks
        while True:
            try:
                chunk = os.read(master, 1 << 16)
            except OSError:  # EIO: the other end closed
                return
            if not chunk:
                return
            chunks.append(chunk)

    reader = threading.Thread(target=drain, daemon=True)
    reader.start()
    tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        _wait(status, lambda st: "received" in st, timeout_s=15)
        for i, ln in enumerate(SAMPLE.read_bytes().splitlines()[:3000]):
            tx.sendto(ln + b"\r\n", ("127.0.0.1", port))
            if i % 200 == 199:
                time.sleep(0.01)
        st = _wait(status, lambda st: st["sources"].get("INS1", {}).get("role"), timeout_s=20)
        proc.send_signal(signal.SIGTERM)
        _, errtext = proc.communicate(timeout=20)
    finally:
        tx.close()
        if proc.poll() is None:
            proc.kill()
    reader.join(timeout=5)
    os.close(master)
    text = b"".join(chunks).decode("utf-8", "replace")
    assert proc.returncode == 0, errtext
    assert st["sources"]["INS1"]["role"] == "ins1" and st["sources"]["GNSS"]["role"] == "gnss"
    assert st["analysis"]["runs"] >= 1 and st["analysis"]["error"] is None
    assert "dracc watch" in text and "sources" in text and "INS1" in text
    assert "\x1b[" in text  # drawn for a terminal (cursor moves, colours)
    assert b"raised" not in errtext  # findings are in the view, not on stderr
