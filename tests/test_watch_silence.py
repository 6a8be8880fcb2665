"""One silence, one alarm (issue 32, alarm noise): a source that stops talking to
``dracc watch`` raises one ``availability/dropout`` -- live, after ``--dropout`` -- and
the window's own ``dropout`` check, which fails for the same gap a moment later, raises
no second alarm.  Live UDP datagrams to 127.0.0.1 (the harness of test_watch_cli), each
line stamped now (TAG ``c:``, the GGA time of fix), three sources at 10 Hz."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time

import pytest
from test_watch_cli import REPO, _free_port, _status, _wait

from dracc.core.config import load_config
from dracc.ingest.live.record import checksum, tag_line
from dracc.pipeline.analysis import analyse

SOURCES = ("GPA", "GPB", "GPC")
SILENT = "GPB"
#: the window's dropout check sees a silence of 1 s (10 cadences of 0.1 s) as a drop-out
CONFIG = "[integrity]\ndropout_min_s = 1.0\n"


def _gga(t_ns: int, key: str, k: int) -> bytes:
    """A GGA of ``key`` fixed at ``t_ns`` (its time of fix and its TAG c:), moving north."""
    s = time.gmtime(t_ns // 10**9)
    body = (
        f"GPGGA,{s.tm_hour:02d}{s.tm_min:02d}{s.tm_sec:02d}.{(t_ns // 10**7) % 100:02d},"
        f"{5436.0 + 0.0005 * k:.4f},N,01848.000,E,1,08,0.9,10.0,M,30.0,M,,"
    )
    return tag_line(f"${body}*{checksum(body.encode()):02X}".encode(), t_ns, source=key)


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("silence")
    status, rec, cfg = tmp / "status.json", tmp / "rec", tmp / "dracc.toml"
    cfg.write_text(CONFIG)
    port = _free_port()
    proc = subprocess.Popen(
        [sys.executable, "-m", "dracc", "watch", f"udp://127.0.0.1:{port}", "--record", str(rec)]
        + ["--status", str(status), "--status-every", "0.2s", "--dropout", "1s"]
        + ["--analyse-every", "1s", "--window", "60s", "--config", str(cfg)],
        stderr=subprocess.PIPE,
        env={**os.environ, "PYTHONPATH": str(REPO)},
    )
    tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    silence_ns: list[int] = []
    try:
        _wait(status, lambda st: "received" in st, timeout_s=15)
        start_ns = time.time_ns()

        def send(seconds: float, quiet: tuple[str, ...] = ()) -> None:
            end = time.monotonic() + seconds
            while time.monotonic() < end:
                now = time.time_ns()
                for key in SOURCES:
                    if key not in quiet:
                        k = (now - start_ns) // 10**8
                        tx.sendto(_gga(now, key, k) + b"\r\n", ("127.0.0.1", port))
                time.sleep(0.1)

        send(3.0)
        silence_ns.append(time.time_ns())
        send(2.5, quiet=(SILENT,))  # > --dropout 1s and > the window's 1 s
        silence_ns.append(time.time_ns())
        # on until an analysis of a window holding the whole silence has come back
        runs = _status(status)["analysis"]["runs"]
        end = time.monotonic() + 20
        while time.monotonic() < end and _status(status)["analysis"]["runs"] < runs + 3:
            send(0.5)
    finally:
        tx.close()
        proc.send_signal(signal.SIGTERM)
        _, errtext = proc.communicate(timeout=15)
    return {
        "code": proc.returncode,
        "stderr": errtext.decode(),
        "final": _status(status),
        "rec": rec,
        "cfg": cfg,
        "silence_ns": silence_ns,
    }


def test_the_window_sees_the_silence_as_a_dropout(run):
    """The lines the watch analysed fail the window's dropout check for the silent source
    (so the one alarm below is one alarm of two checks that fired, not of one)."""
    assert run["code"] == 0, run["stderr"]
    st = run["final"]["analysis"]
    assert st["error"] is None and st["runs"] >= 3
    a = analyse(sorted(run["rec"].iterdir()), load_config(run["cfg"]))
    failed = {(c.name, c.source) for c in a.integrity.failed if c.check == "availability"}
    assert failed == {("dropout", SILENT)}, failed


def test_one_silence_raises_one_alarm(run):
    mine = [f for f in run["final"]["findings"] if f["source"] == SILENT]
    assert len(mine) == 1, mine
    (f,) = mine
    assert (f["check"], f["name"]) == ("availability", "dropout")
    assert f["cleared_utc"] and f["evidence"]["age_s"] > 1.0
    assert not [g for g in run["final"]["findings"] if g["source"] != SILENT]
    raised = [ln for ln in run["stderr"].splitlines() if " raised: " in ln]
    assert raised == [ln for ln in raised if f"availability/dropout raised: {SILENT}:" in ln]
    assert len(raised) == 1, run["stderr"]
