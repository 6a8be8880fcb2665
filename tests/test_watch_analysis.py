"""The rolling statistics of ``dracc watch`` (dracc.pipeline.watch_analysis) against the
offline analysis of the same lines, on randomised simulated voyages: the hourly INS
deviation statistics equal ``analyze``'s, the DR of the window equals an analysis of the
lines of that span cut from the original log, seeded faults are raised and cleared with
their evidence, and the window stays inside its bounds."""

from __future__ import annotations

import random
import re
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from rich.console import Console

from dracc.core.config import Config
from dracc.core.numbers import jsonable
from dracc.ingest.live import LiveSource
from dracc.pipeline.analysis import analyse
from dracc.pipeline.audit.facts import channel_rows
from dracc.pipeline.watch import Watch
from dracc.pipeline.watch_analysis import LineWindow, LiveAnalyser, _near_instants
from dracc.report.watch_view import status_view

SEED = random.SystemRandom().randrange(10_000)


def _simulate(out: Path, hours: float, seed: int, *extra: str) -> Path:
    subprocess.run(
        [sys.executable, "-m", "dracc", "simulate", "--out", str(out), "--hours", str(hours)]
        + ["--seed", str(seed), *extra],
        check=True,
        capture_output=True,
    )
    return out / "voyage.nmea"


class _Replay(LiveSource):
    """A live source replaying a log, ``per`` lines a poll, received now."""

    kind = "replay"

    def __init__(self, lines: list[bytes], per: int) -> None:
        super().__init__("replay", 4096, per)
        self.log, self.per, self.i = lines, per, 0

    def poll(self, timeout_s: float = 0.0) -> list[tuple[int, bytes]]:
        now = time.time_ns()
        out = [(now, ln) for ln in self.log[self.i : self.i + self.per]]
        self.i += self.per
        self.lines += len(out)
        return out


def _replay(log: Path, window_s: float, per: int = 15_000):
    """Feed ``log`` through a Watch with an inline analyser (one analysis a step);
    return the watch, the events and the analyser."""
    lines = log.read_bytes().splitlines()
    tick = [0.0]
    analyser = LiveAnalyser(Config(), window_s, 1.0, 256 << 20, clock=lambda: tick[0])
    src = _Replay(lines, per)
    watch = Watch([src], None, dropout_s=1e9, analyser=analyser)
    events = []
    while src.i < len(src.log):
        tick[0] += 1.0
        events += watch.step(0)
    return watch, events, analyser


@pytest.fixture(scope="module")
def clean(tmp_path_factory):
    rng = random.Random(SEED)
    hours = rng.uniform(5.2, 7.0)
    log = _simulate(
        tmp_path_factory.mktemp("clean"), hours, SEED, "--lat", f"{rng.uniform(-60, 60):.2f}"
    )
    watch, events, analyser = _replay(log, window_s=rng.uniform(2400, 4000))
    return log, watch, events, analyser


def test_live_deviation_statistics_equal_analyze(clean):
    log, watch, _, _ = clean
    live = watch.status()["deviation"]
    offline = channel_rows(analyse([log]).deviation)
    assert live is not None and len(live["channels"]) == len(offline) == 9, SEED
    for got, want in zip(live["channels"], offline, strict=True):
        assert (got["ins_unit"], got["channel"], got["n"]) == (want.unit, want.channel, want.n)
        for k, w in (("m_u", want.m_u), ("m_y", want.m_y), ("kurtosis", want.kurtosis)):
            assert got[k] == pytest.approx(w, rel=1e-9, abs=1e-12), (SEED, got, want)
    assert live["samples"] >= 5  # hourly over > 5 h, though the window is about an hour


def test_window_dr_equals_analysis_of_that_span(clean, tmp_path):
    log, watch, _, analyser = clean
    st = watch.status()
    dr = st["dead_reckoning"]
    # the window is a contiguous run of the original lines (TAG blocks kept byte for byte),
    # the last one the log's; that run cut from the original log and analysed offline
    (held,) = analyser.window.write(tmp_path, "held")
    window_lines = held.read_bytes().splitlines()
    original = log.read_bytes().splitlines()
    i = len(original) - len(window_lines)
    assert i > 0 and original[i:] == window_lines, SEED
    cut = tmp_path / "span.nmea"
    cut.write_bytes(b"\n".join(original[i:]) + b"\n")
    a = analyse([cut])
    assert dr["n_scored"] == a.dead_reckoning.n_scored, SEED
    assert dr["containment_2m"] == pytest.approx(a.dead_reckoning.containment_2m), SEED
    e = a.dead_reckoning.epochs
    assert dr["radius_2m_m"] == pytest.approx(float(e.radius_2m_m[-1])), SEED
    assert dr["error_m"] == pytest.approx(float(e.ref_error_m[-1])), SEED
    assert dr["lat_deg"] == pytest.approx(np.degrees(e.lat_rad[-1]), abs=1e-12)
    assert dr["inside_2m"] == (dr["error_m"] <= dr["radius_2m_m"])
    assert {k: s["role"] for k, s in st["sources"].items()} == {
        "GNSS": "gnss",
        "GYRO": "compass",
        "INS1": "ins1",
        "INS2": "ins2",
        "INS3": "ins3",
        "LOG": "log",
    }


def test_clean_voyage_raises_no_integrity_finding(clean):
    _, _, events, analyser = clean
    assert analyser.runs >= 5 and analyser.error is None
    assert events == [], SEED  # nothing live either: a replay never falls silent


def test_seeded_faults_raised_then_cleared_with_evidence(tmp_path):
    log = _simulate(
        tmp_path,
        3.0,
        SEED,
        "--fault",
        "jump:GNSS@1h=670m",
        "--fault",
        "dropout:INS3@1.6h+10min",
    )
    watch, events, _ = _replay(log, window_s=1800.0)
    raised = {(e["check"], e["name"], e["source"]) for e in events if e["event"] == "raised"}
    cleared = {(e["check"], e["name"], e["source"]) for e in events if e["event"] == "cleared"}
    assert ("plausibility", "jump", "GNSS") in raised, (SEED, raised)
    assert ("availability", "dropout", "INS3") in raised, (SEED, raised)
    # one cause, one alarm: the receiver flagging the displaced fixes valid is the jump's
    # consequence, listed under it, not an alarm of its own
    assert ("validity", "contradiction", "GNSS") not in raised, (SEED, raised)
    assert any(
        (c["check"], c["name"], c["source"]) == ("validity", "contradiction", "GNSS")
        for e in events
        if e["name"] == "jump"
        for c in e["consequences"]
    ), SEED
    # the window (30 min) moves past each fault before the voyage ends: all cleared
    assert raised == cleared, (SEED, raised - cleared)
    jump = next(e for e in events if e["name"] == "jump" and e["event"] == "raised")
    assert jump["evidence"]["statistic"]["value"] > 600  # the 670 m step
    # the 670 m step as measured: the GNSS noise and the ship's own motion move it a few
    # metres either way (669-674 m seen over seeds)
    largest = re.search(r"the largest (\d+) m", jump["message"])
    assert jump["evidence"]["items"] and largest and abs(int(largest[1]) - 670) <= 15, (
        SEED,
        jump["message"],
    )
    drop = next(e for e in events if e["name"] == "dropout" and e["event"] == "raised")
    # the silence as far as the window had heard it when raised: beyond the gate, <= 10 min
    assert 60 < drop["evidence"]["statistic"]["value"] <= 660
    st = watch.status()
    assert st["findings"] and not watch.open_checks
    assert st["inputs"] == [
        {
            "spec": "replay",
            "kind": "replay",
            "lines": 0 + len(log.read_bytes().splitlines()),
            "bytes": 0,
            "dropped": {},
        }
    ]


def test_line_window_bounds_by_time_and_bytes():
    w = LineWindow(window_s=10.0, max_bytes=100)
    s = 10**9
    for i in range(30):
        w.add("nmea0183", i * s, i * s, b"x" * 9 + b"\n")
    # 10 s of data time: the chunks of t >= 19 s (11 of them, 110 bytes) -> the byte bound
    assert w.size == 100 and w.span_ns() == (20 * s, 29 * s)
    # from t = 10 s on, each add leaves 11 chunks (110 bytes) inside the 10 s: the oldest of
    # them goes for size, 20 times 10 bytes
    assert w.trimmed_bytes == 200
    w2 = LineWindow(window_s=5.0, max_bytes=10**6)
    for i in range(30):
        w2.add("nmea0183", i * s, i * s, b"y\n")
    assert w2.span_ns() == (24 * s, 29 * s) and w2.trimmed_bytes == 0


def test_near_instants_marks_the_minutes_around_each_hour():
    cfg = Config()  # hourly, max_interp_gap 120 s: +-180 s kept
    hour = 3600 * 10**9
    t = np.array([0, 179, 181, 1800, 3419, 3421, 3600 * 5 + 100], np.int64) * 10**9 + 7 * hour
    assert _near_instants(t, cfg).tolist() == [True, True, False, False, False, True, True]


def test_status_view_shows_sources_dr_and_findings(clean):
    _, watch, _, _ = clean
    st = jsonable(watch.status())
    st["findings"] = [
        {
            "check": "plausibility",
            "name": "jump",
            "source": "GNSS",
            "raised_utc": "2026-03-01T04:00:00.000Z",
            "cleared_utc": None,
            "message": "GNSS: 1 position jump(s), the largest 670 m",
        }
    ]
    console = Console(record=True, width=120, color_system=None)
    console.print(status_view(st))
    text = console.export_text()
    assert "1 open finding(s)" in text and "plausibility/jump" in text and "670 m" in text
    for key in ("GNSS", "GYRO", "INS1", "INS2", "INS3", "LOG"):
        assert key in text
    assert "dead reckoning:" in text and "since the fix" in text and "2M" in text
    assert "INS deviations:" in text and "hourly sample(s)" in text


def test_audit_of_a_watch_folder_leaves_the_part_file_out(tmp_path):
    """A recording being written (``.part``) is not audited as the night's log."""
    from dracc.core.errors import NoLogsError
    from dracc.ingest.live import Recorder
    from dracc.pipeline.audit.logs import choose_logs

    day_ns = 1_764_547_200 * 10**9  # 2025-12-01T00:00Z
    line = b"$GPGGA,000001,5436.000,N,02000.000,E,1,08,0.9,10.0,M,30.0,M,,*49"
    with Recorder(tmp_path) as rec:
        rec.write(line, day_ns + 10**9)
        rec.write(line, day_ns + 86_400 * 10**9 + 10**9)  # the next day: the first finished
        assert rec.current is not None and rec.current.name.endswith(".part")
        with pytest.raises(NoLogsError, match=r"being written \(\.part\)"):
            choose_logs([tmp_path], "2025-12-02", "*")
        assert [p.name for p in choose_logs([tmp_path], "2025-12-01", "*").paths] == [
            "dracc-20251201.nmea"
        ]
