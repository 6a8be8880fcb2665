"""NMEA 2000 decoding speed: navigation frames per second on about a million messages.

Run:  python benchmarks/bench_n2k.py [--messages N] [--repeat R]

The messages are the real ``signalk-server/aava-n2k.data`` (a ship under way, canboat
PLAIN, 21 595 messages of which 5 383 navigation ones) repeated to about ``--messages``
(default 1 000 000).  Timed, best of ``--repeat`` (default 3), on one core:

* decode alone: :func:`dracc.ingest.n2k.pgns.decode` (every PGN's fields gathered);
* decode + frames: :func:`dracc.ingest.n2k.reader.n2k_result` (decode, times, source
  keys, canonical frames sorted by time, time events);
* parse + decode + frames: the repeated log text through ``parse_n2k`` then
  ``n2k_result``.

A navigation frame is a decoded record of 129025/129029/129026/127250/127251/128259/
128275.  Shown beside canboat's published figure for its analyzer (380 000 frames/s),
and, where ``CANBOAT_ANALYZER`` names a built ``analyzer`` binary, its time on the same
text here (it decodes every PGN and prints it: a wider job than dracc's navigation
subset, so the comparison is of reading a log for navigation, not of decoders).
dracc's target is >= 1 M navigation frames/s (decode) on one core.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from dracc.core.config import IngestConfig
from dracc.ingest.n2k.formats import SNIFF_BYTES, parse_n2k, sniff_n2k
from dracc.ingest.n2k.messages import TIME_UTC, Messages
from dracc.ingest.n2k.pgns import decode
from dracc.ingest.n2k.reader import n2k_result

REAL = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "real"
AAVA = REAL / "signalk-server" / "aava-n2k.data"
CANBOAT_FPS = 380_000  #: canboat's published analyzer speed, frames/s


def plain_messages(text: str) -> Messages:
    """Messages of a canboat PLAIN log whose every line is a whole message (aava-n2k)."""
    cols: list[list[int]] = [[], [], [], [], [], [], []]
    payload = bytearray()
    for i, line in enumerate(text.splitlines(), 1):
        f = line.split(",")
        if len(f) < 7:
            continue
        sec = np.datetime64(f[0].rstrip("Z"), "ns").astype(np.int64)
        n = int(f[5])
        for c, v in zip(cols, (sec, i, int(f[1]), int(f[2]), int(f[3]), int(f[4]), n), strict=True):
            c.append(int(v))
        payload += bytes(int(x, 16) for x in f[6 : 6 + n])
    length = np.array(cols[6], dtype=np.int64)
    return Messages(
        time_ns=np.array(cols[0], dtype=np.int64),
        line=np.array(cols[1], dtype=np.int64),
        prio=np.array(cols[2], dtype=np.uint8),
        pgn=np.array(cols[3], dtype=np.int64),
        src=np.array(cols[4], dtype=np.uint8),
        dst=np.array(cols[5], dtype=np.uint8),
        start=np.concatenate(([0], np.cumsum(length)[:-1])).astype(np.int64),
        length=length,
        payload=np.frombuffer(bytes(payload), dtype=np.uint8),
        time_kind=TIME_UTC,
    )


def repeated(m: Messages, times: int) -> Messages:
    """``m`` repeated ``times`` times, each copy later by the log's span plus 1 s."""
    span = int(m.time_ns.max() - m.time_ns.min()) + 1_000_000_000
    k = np.repeat(np.arange(times, dtype=np.int64), len(m))
    nl = int(m.line.max())
    return Messages(
        time_ns=np.tile(m.time_ns, times) + k * span,
        line=np.tile(m.line, times) + k * nl,
        prio=np.tile(m.prio, times),
        pgn=np.tile(m.pgn, times),
        src=np.tile(m.src, times),
        dst=np.tile(m.dst, times),
        start=np.tile(m.start, times) + k * len(m.payload),
        length=np.tile(m.length, times),
        payload=np.tile(m.payload, times),
        time_kind=m.time_kind,
    )


def best(fn, repeat: int) -> float:
    t = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        t.append(time.perf_counter() - t0)
    return min(t)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--messages", type=int, default=1_000_000)
    ap.add_argument("--repeat", type=int, default=3)
    a = ap.parse_args()
    if not AAVA.exists():
        print(f"{AAVA} not found", file=sys.stderr)
        return 1
    text = AAVA.read_text()
    base = plain_messages(text)
    times = max(1, round(a.messages / len(base)))
    m = repeated(base, times)
    cfg = IngestConfig()
    nav = sum(len(p["row"]) for parts in decode(m).parts.values() for p in parts)
    print(f"{len(m):,} messages ({times} x aava-n2k.data), {nav:,} navigation frames")
    rows = [("decode alone", best(lambda: decode(m), a.repeat))]
    rows.append(("decode + frames", best(lambda: n2k_result(m, "bench", "plain", cfg), a.repeat)))
    data = (text if text.endswith("\n") else text + "\n").encode() * times
    fmt = sniff_n2k(data[:SNIFF_BYTES])
    assert fmt is not None

    def full() -> None:
        n2k_result(parse_n2k(data, fmt), "bench", fmt, cfg)

    rows.append((f"parse ({fmt}) + decode + frames", best(full, a.repeat)))
    print(f"{'':34s} {'seconds':>8s} {'nav frames/s':>14s} {'messages/s':>12s}")
    for name, s in rows:
        print(f"{name:34s} {s:8.3f} {nav / s:14,.0f} {len(m) / s:12,.0f}")
    print(f"{'canboat analyzer':34s} {'':8s} {CANBOAT_FPS:14,d}   (published, frames/s)")
    analyzer = os.environ.get("CANBOAT_ANALYZER")
    if analyzer:
        with tempfile.NamedTemporaryFile(suffix=".data") as fh:
            fh.write(data)
            fh.flush()

            def run() -> None:
                with open(fh.name, "rb") as inp:
                    subprocess.run(
                        [analyzer],
                        stdin=inp,
                        stdout=subprocess.DEVNULL,
                        stderr=subprocess.DEVNULL,
                        check=False,
                    )

            s = best(run, a.repeat)
        print(f"{'canboat analyzer, here':34s} {s:8.3f} {'':14s} {len(m) / s:12,.0f}")
    print(f"load average {os.getloadavg()[0]:.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
