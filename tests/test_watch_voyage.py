"""Issue 19's "done when", end to end: a simulated voyage sent over UDP to 127.0.0.1 in the
IEC 61162-450 form (``UdPbC\\0`` and several TAG-block lines a datagram) at 20 000 lines/s
to a ``dracc watch`` process; the status counts every source while it runs; a binary
datagram is dropped and counted, a datagram with a truncated and a garbled line goes on
into the recording (the reader rejects both); after SIGTERM (exit 0) the recording holds
>= 99.9 % of the lines sent, and ``dracc inspect --json`` and ``dracc analyze --json`` of
it equal those of the original log.

The voyage is new each run: its seed (and the simulator options drawn from it: sensor
rates, start position, the lines per datagram, where the bad datagrams go) comes from
``random.SystemRandom`` and is in every assertion message; ``DRACC_WATCH_SEED=N`` replays
a run.  The expected values are the simulator's own log (read by the inspect and
analyze commands of the original file) and the lines as sent, parsed here by hand.
"""

from __future__ import annotations

import json
import math
import os
import random
import signal
import socket
import subprocess
import sys
import time
from collections import Counter
from pathlib import Path
from typing import Any

import pytest

REPO = Path(__file__).resolve().parents[1]
HOST = "127.0.0.1"  #: loopback only; never a multicast group
UDPBC = b"UdPbC\x00"  #: IEC 61162-450 header of a datagram of sentences
RATE = 20_000  #: lines/s sent
BATCH_S = 0.01  #: the sender sends what is due, then sleeps this long
READ_EVERY_S = 0.6  #: status reads while sending
TARGET_LINES = 80_000  #: lines of the simulated log, about (4 s at RATE)
INTERVAL = "3min"  #: analyze --interval: a 25-70 min voyage gives 8-23 deviation samples
ENV = {**os.environ, "PYTHONPATH": str(REPO)}


def _dracc(*args: str) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-m", "dracc", *args],
        cwd=REPO,
        env=ENV,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
    )


def _run_all(*commands: list[str], timeout_s: float = 60) -> None:
    """Run dracc commands side by side; each must exit 0."""
    procs = [_dracc(*c) for c in commands]
    for c, p in zip(commands, procs, strict=True):
        _, errtext = p.communicate(timeout=timeout_s)
        assert p.returncode == 0, f"dracc {' '.join(c)} -> {p.returncode}: {errtext.decode()}"


def _source(line: bytes) -> str | None:
    """The TAG ``s:`` of a line, parsed here by hand (None where it has none)."""
    if not line.startswith(b"\\"):
        return None
    block = line[1 : line.index(b"*")]
    for part in block.split(b","):
        if part.startswith(b"s:"):
            return part[2:].decode()
    return None


def _status(path: Path) -> dict[str, Any]:
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        return {}


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind((HOST, 0))
        return s.getsockname()[1]


def _choose(seed: int) -> dict[str, Any]:
    """The simulator options and the send plan of a seed (realistic ranges)."""
    r = random.Random(seed)
    opts: dict[str, Any] = {
        "compass_hz": r.choice([4.0, 10.0, 20.0]),  # every rate divides the fastest
        "aux_hz": r.choice([0.0, 1.0]),
        "log_hz": r.choice([1.0, 2.0]),
        "ins_hz": r.choice([1.0, 2.0]),
        "gnss_hz": r.choice([1.0, 2.0]),
        "lat": round(r.uniform(-65.0, 65.0), 4),
        "lon": round(r.uniform(-170.0, 170.0), 4),
    }
    # lines a second of the simulator's NMEA: HDT at the compass rate, THS and ROT at the
    # aux rate, VHW VBW VLW, three INS of GGA HDT VTG, GNSS GGA RMC ZDA
    per_s = (
        opts["compass_hz"]
        + 2 * opts["aux_hz"]
        + 3 * opts["log_hz"]
        + 9 * opts["ins_hz"]
        + 3 * opts["gnss_hz"]
    )
    opts["hours"] = round(TARGET_LINES / per_s / 3600, 4)
    opts["per_datagram"] = r.randint(5, 25)
    opts["bad_at"] = r.uniform(0.4, 0.6)  # where the binary datagram goes (share of the send)
    opts["garbled_at"] = r.uniform(0.2, 0.35)  # and the one with a truncated, a garbled line
    opts["rng"] = r
    return opts


def _bad_lines(lines: list[bytes], at: int, r: random.Random) -> list[bytes]:
    """A GNSS GGA near ``at`` cut inside its fields (no checksum, fields missing), and a
    line with one digit of its sentence changed (its checksum now wrong)."""
    gga = next(ln for ln in lines[at:] if b"GGA," in ln and _source(ln) == "GNSS")
    start = gga.index(b"GGA,") + 4
    cut = r.randint(start + 2, gga.index(b",E,") if b",E," in gga else gga.index(b",W,"))
    truncated = gga[:cut]
    other = lines[at + 1]
    body = other.index(b"$") + 7  # past the address
    i = next(k for k in range(body, len(other)) if other[k : k + 1].isdigit())
    digit = (other[i] - 48 + 1) % 10 + 48
    garbled = other[:i] + bytes([digit]) + other[i + 1 :]
    return [truncated, garbled]


@pytest.fixture(scope="module")
def voyage(tmp_path_factory):
    seed = int(os.environ.get("DRACC_WATCH_SEED") or random.SystemRandom().randrange(2**31))
    o = _choose(seed)
    tag = f"seed {seed} (DRACC_WATCH_SEED={seed} replays it): " + ", ".join(
        f"{k}={v}" for k, v in o.items() if k != "rng"
    )
    tmp = tmp_path_factory.mktemp("watch_voyage")
    sim = tmp / "sim"
    _run_all(
        ["simulate", "--out", str(sim), "--hours", str(o["hours"]), "--seed", str(seed)]
        + ["--compass-hz", str(o["compass_hz"]), "--aux-hz", str(o["aux_hz"])]
        + ["--log-hz", str(o["log_hz"]), "--ins-hz", str(o["ins_hz"])]
        + ["--gnss-hz", str(o["gnss_hz"]), "--lat", str(o["lat"]), "--lon", str(o["lon"])]
    )
    original = sim / "voyage.nmea"
    _run_all(
        ["inspect", str(original), "--json", str(tmp / "orig_inspect.json")],
        ["analyze", str(original), "--interval", INTERVAL, "--json", str(tmp / "orig.json")],
    )
    lines = [ln for ln in original.read_bytes().splitlines() if ln]
    n = o["per_datagram"]
    chunks = [lines[i : i + n] for i in range(0, len(lines), n)]
    j_garbled = int(o["garbled_at"] * len(chunks))
    j_bad = int(o["bad_at"] * len(chunks))
    bad_lines = _bad_lines(lines, j_garbled * n, o["rng"])
    half = len(chunks[j_garbled]) // 2
    chunks[j_garbled][half:half] = bad_lines  # inside the datagram, lines either side
    payload = [UDPBC + b"".join(ln + b"\r\n" for ln in c) for c in chunks]
    garbage = bytes(o["rng"].randrange(256) for _ in range(300)) + b"\x00\xff"
    sent = [ln for c in chunks for ln in c]

    port = _free_port()
    status, rec = tmp / "status.json", tmp / "rec"
    proc = _dracc(
        "watch",
        f"udp://{HOST}:{port}",
        "--record",
        str(rec),
        "--status",
        str(status),
        "--status-every",
        "0.2s",
    )
    reads: list[tuple[int, dict[str, Any]]] = []  # (lines sent at the read, the status)
    tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    tx.connect((HOST, port))
    try:
        end = time.monotonic() + 30
        while "received" not in _status(status):
            if proc.poll() is not None:
                _, early = proc.communicate()
                raise AssertionError(f"{tag}: watch ended ({proc.returncode}): {early.decode()}")
            assert time.monotonic() < end, f"{tag}: no status within 30 s"
            time.sleep(0.02)
        n_sent = 0  # lines
        k = 0  # datagrams
        t0 = time.monotonic()
        next_read = t0 + READ_EVERY_S
        while k < len(payload):
            now = time.monotonic()
            due = (now - t0) * RATE
            while k < len(payload) and n_sent < due:
                if k == j_bad:
                    tx.send(garbage)  # between two datagrams of lines
                tx.send(payload[k])
                n_sent += len(chunks[k])
                k += 1
            if now >= next_read:
                next_read += READ_EVERY_S
                reads.append((n_sent, _status(status)))
            time.sleep(BATCH_S)  # never spin: the watch needs the other CPU
        send_s = time.monotonic() - t0
        end = time.monotonic() + 10
        after = _status(status)
        while after.get("received", 0) < len(sent) and time.monotonic() < end:
            time.sleep(0.02)
            after = _status(status)
    finally:
        tx.close()
        proc.send_signal(signal.SIGTERM)
        try:
            _, errtext = proc.communicate(timeout=30)
        except subprocess.TimeoutExpired:
            proc.kill()
            _, errtext = proc.communicate()
    files = sorted(rec.glob("dracc-*.nmea"))
    if files:  # the recording's own reports (the files of one voyage merge by time)
        _run_all(
            ["inspect", *map(str, files), "--json", str(tmp / "rec_inspect.json")],
            ["analyze", *map(str, files), "--interval", INTERVAL, "--json", str(tmp / "rec.json")],
        )

    def doc(name: str) -> dict[str, Any]:
        p = tmp / name
        return json.loads(p.read_text()) if p.exists() else {}

    return {
        "tag": tag,
        "lines": lines,
        "sent": sent,
        "bad_lines": bad_lines,
        "send_s": send_s,
        "reads": reads,
        "after": after,
        "final": _status(status),
        "code": proc.returncode,
        "stderr": errtext.decode(),
        "rec": rec,
        "files": files,
        "orig_inspect": doc("orig_inspect.json"),
        "rec_inspect": doc("rec_inspect.json"),
        "orig": doc("orig.json"),
        "recd": doc("rec.json"),
    }


def _recorded(v) -> list[bytes]:
    return [ln for p in v["files"] for ln in p.read_bytes().splitlines() if ln]


def _diff(a: Any, b: Any, path: str = "") -> list[str]:
    """Where two JSON documents differ: floats to 1e-9 relative, all else exactly."""
    if isinstance(a, dict) and isinstance(b, dict):
        out = [f"{path}.{k}: only in one" for k in sorted(set(a) ^ set(b))]
        for k in a.keys() & b.keys():
            out += _diff(a[k], b[k], f"{path}.{k}")
        return out
    if isinstance(a, list) and isinstance(b, list):
        if len(a) != len(b):
            return [f"{path}: {len(a)} items vs {len(b)}"]
        return [
            d
            for i, (x, y) in enumerate(zip(a, b, strict=True))
            for d in _diff(x, y, f"{path}[{i}]")
        ]
    if isinstance(a, float) and isinstance(b, float):
        ok = math.isclose(a, b, rel_tol=1e-9, abs_tol=1e-12) or (math.isnan(a) and math.isnan(b))
        return [] if ok else [f"{path}: {a!r} vs {b!r}"]
    return [] if a == b and type(a) is type(b) else [f"{path}: {a!r} vs {b!r}"]


def _reading_notes(notes: list[str]) -> tuple[list[str], int, list[str]]:
    """(the notes not of one file, the lines of the files' "N lines with tag prefix" notes,
    the files' other notes): a file's notes begin with its name."""
    general, tagged, other = [], 0, []
    for note in notes:
        name, _, text = note.partition(": ")
        if not name.endswith(".nmea"):
            general.append(note)
        elif text.endswith(" lines with tag prefix"):
            tagged += int(text.split()[0])
        else:
            other.append(text)
    return general, tagged, other


def test_the_send_kept_the_pace(voyage):
    v = voyage
    n = len(v["sent"])
    assert 60_000 <= n <= 100_000, v["tag"]
    rate = n / v["send_s"]
    assert 0.9 * RATE <= rate <= 1.02 * RATE, f"{v['tag']}: sent at {rate:.0f} lines/s"


def test_status_counts_every_source_while_running(voyage):
    v = voyage
    keys = set(v["orig_inspect"]["sources"])
    assert keys == {_source(ln) for ln in v["lines"]}, v["tag"]  # the reader's keys: TAG s:
    during = [(n, st) for n, st in v["reads"] if st.get("received")]
    assert len(during) >= 3, f"{v['tag']}: {len(during)} status reads while sending"
    before: dict[str, int] = {}
    for n_sent, st in during:
        assert st["schema"] == "dracc.watch/2", v["tag"]
        assert set(st["sources"]) == keys, f"{v['tag']}: {sorted(st['sources'])}"
        assert 0 < st["received"] <= n_sent, v["tag"]
        sent_by_key = Counter(_source(ln) for ln in v["sent"][:n_sent])
        for key, s in st["sources"].items():
            assert before.get(key, 0) < s["records"] <= sent_by_key[key], (
                f"{v['tag']}: {key} {before.get(key)} -> {s['records']} of {sent_by_key[key]}"
            )
            assert s["lines_per_s"] > 0 and s["age_s"] >= 0, v["tag"]
        before = {k: s["records"] for k, s in st["sources"].items()}


def test_every_line_received_and_counted_per_source(voyage):
    v = voyage
    st = v["final"]
    assert v["after"]["received"] >= len(v["sent"]), (
        f"{v['tag']}: the status showed {v['after'].get('received')} of {len(v['sent'])} "
        f"lines 10 s after the send"
    )
    assert st["received"] == len(v["sent"]) and st["unkeyed"] == 0, v["tag"]
    # records per key are the lines heard with that TAG s: (the two bad lines included)
    want = Counter(_source(ln) for ln in v["sent"])
    assert {k: s["records"] for k, s in st["sources"].items()} == want, v["tag"]


def test_bad_datagram_counted_never_fatal(voyage):
    v = voyage
    assert v["final"]["dropped"] == {"binary": 1}, v["tag"]
    assert v["code"] == 0, f"{v['tag']}: {v['stderr']}"


def test_recording_holds_the_lines_sent(voyage):
    v = voyage
    assert v["files"], f"{v['tag']}: no recording in {sorted(v['rec'].iterdir())}"
    assert not list(v["rec"].glob("*.part")), v["tag"]
    recorded, sent = _recorded(v), v["sent"]
    assert len(recorded) >= 0.999 * len(sent), f"{v['tag']}: {len(recorded)} of {len(sent)}"
    assert not Counter(recorded) - Counter(sent), f"{v['tag']}: lines never sent recorded"
    if v["final"]["received"] == len(sent):  # nothing lost: every line, as sent
        assert Counter(recorded) == Counter(sent), v["tag"]
        # the lines carry TAG blocks with c:, so the recorder keeps them byte for byte;
        # loopback UDP to one socket keeps the order of the datagrams
        assert recorded == sent, v["tag"]


def test_inspect_of_the_recording_equals_the_original(voyage):
    v = voyage
    a, b = v["orig_inspect"], v["rec_inspect"]
    assert b, f"{v['tag']}: no inspect of the recording"
    assert v["final"]["received"] == len(v["sent"]), f"{v['tag']}: lines lost"

    def per_source(doc: dict) -> dict:
        return {k: {f: x for f, x in s.items() if f != "files"} for k, s in doc["sources"].items()}

    assert _diff(per_source(a), per_source(b)) == [], v["tag"]
    for key in ("sentences", "time", "roles"):
        assert _diff(a[key], b[key]) == [], f"{v['tag']}: {key}"
    # the truncated GGA has too few fields, the garbled line a wrong checksum: rejected,
    # and nothing else differs
    assert a["rejected"] == {} and b["rejected"] == {"field_count": 1, "checksum": 1}, v["tag"]
    texts = sorted(e["text"] for ex in b["rejected_examples"].values() for e in ex)
    assert texts == sorted(ln.decode().split("\\")[-1] for ln in v["bad_lines"]), v["tag"]
    acc_a, acc_b = a["accounting"], b["accounting"]
    assert acc_b == {**acc_a, "lines": acc_a["lines"] + 2, "rejected": 2}, v["tag"]
    assert acc_a["lines"] == len(v["lines"]), v["tag"]
    notes_a, notes_b = _reading_notes(a["notes"]), _reading_notes(b["notes"])
    assert notes_b[0] == notes_a[0] and notes_b[1] == notes_a[1] + 2, v["tag"]


def test_analyze_of_the_recording_equals_the_original(voyage):
    v = voyage
    a, b = v["orig"], v["recd"]
    assert b, f"{v['tag']}: no analysis of the recording"
    assert v["final"]["received"] == len(v["sent"]), f"{v['tag']}: lines lost"
    dr_a, dr_b = a["dead_reckoning"], b["dead_reckoning"]
    assert dr_a["n_scored"] > 0, v["tag"]
    for key in ("containment_2m", "n_scored", "verdict", "consistent", "breaks"):
        assert dr_b[key] == dr_a[key], f"{v['tag']}: dead_reckoning.{key}"
    dev_a, dev_b = a["deviation"], b["deviation"]
    assert len(dev_a["samples"]) >= 5, v["tag"]
    for unit, channels in dev_a["units"].items():
        for name, stats in channels.items():  # lat lon course, and cov_lat_lon_m2 r_lat_lon
            if isinstance(stats, dict):
                assert stats["n"] >= 5 and stats["m_u"] is not None, f"{v['tag']}: {unit} {name}"
            got = dev_b["units"][unit][name]
            assert _diff(stats, got) == [], f"{v['tag']}: {unit} {name}"
    # and the rest of the document, all but the inputs (paths), the two rejected lines and
    # the notes of reading each file (its name, its lines)
    skip = {"inputs", "lines", "rejected", "reject_examples"}
    rest_a = {k: x for k, x in a.items() if k not in skip}
    rest_b = {k: x for k, x in b.items() if k not in skip}
    notes_a = _reading_notes(rest_a["time_events"].pop("decisions"))
    notes_b = _reading_notes(rest_b["time_events"].pop("decisions"))
    assert _diff(rest_a, rest_b) == [], v["tag"]
    assert notes_b[0] == notes_a[0] and notes_b[1] == notes_a[1] + 2, v["tag"]
    assert notes_a[2] == [], v["tag"]
    assert b["lines"] == a["lines"] + 2, v["tag"]
    assert b["rejected"] == {"field_count": 1, "checksum": 1}, v["tag"]
