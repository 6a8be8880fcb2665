"""Watch memory benchmark: ``dracc watch`` fed a simulated month as fast as it goes,
memory sampled once per simulated day (issue 19: "memory flat over 30 days").

Run:  python benchmarks/bench_watch_memory.py [--days 30] [--seed 1] [--tracemalloc]

1. One simulated day: ``python -m dracc simulate --out TMP --hours 24 --seed S
   --compass-hz 1`` (TAG-block NMEA 0183, ``c:`` in seconds; gyro HDT, THS, ROT, log VHW,
   VBW, VLW, three INS units GGA, HDT, VTG, GNSS GGA, RMC, ZDA, all at 1 Hz: 18 lines a
   second, 1 555 200 lines a day once the lines of the closing second, 24:00:00, which
   day 1 begins with, are left out).
2. Day ``k`` (0 .. ``--days`` - 1) is day 0 shifted by ``k`` days: the TAG ``c:`` time
   plus ``k * 86400`` s (``k * 86 400 000`` where it is in ms), the RMC date (field 9,
   ``ddmmyy``) and the ZDA date (``dd,mm,yyyy``) moved ``k`` days -- the only dated
   sentences :mod:`dracc.sim.nmea_out` writes (GGA, VTG and the rest carry a time of
   day at most, which a whole-day shift keeps) -- and the TAG and NMEA checksums made
   anew.  The template is built once from day 0: per line the offsets of ``c:``, of the
   dates and of both checksums, the old values and checksums; a day is then patched in
   blocks with numpy (digits by integer arithmetic, each checksum updated by the XOR of
   the bytes that changed) and split into lines.  A sample of patched lines is checked
   against checksums and dates computed here line by line before the run.  The data time
   runs on without a gap, but the ship jumps back to its start position (and its
   distance log to its start reading) at every midnight: integrity findings at those
   instants (position jumps, DR against GNSS) are expected and fine.
3. The lines are fed in-process, as fast as they go, to ``Watch([replay], Recorder(tmp),
   stale_s=1e9, analyser=LiveAnalyser(Config(), 3600, 1.0, 256 MiB, worker_pool()))``:
   a replay source whose ``poll`` returns up to 20 000 ``(time.time_ns(), line)`` (never
   across a midnight of data time).  Each recording file the Recorder finishes (at
   256 MiB, at a midnight of the wall clock, at the end) is counted (bytes, lines) and
   deleted at once: only the ``.part`` file stays on disk.
4. At the end of every simulated day (by the lines' data time) one row: RSS of this
   process (``VmRSS``), RSS of the analysis worker (the executor's process), the window
   (``analyser.window.size``), the deviation store's readings, the analyses started,
   findings open / raised / cleared so far, lines fed and lines/s so far.

At the end: lines fed, wall time, lines/s, recorded lines / fed, and the flatness
verdict for this process and the worker: the largest RSS of days 10 .. ``--days``
against the RSS at day 5 (target: within +10 % or +20 MiB, whichever is larger), and
the slope of a least-squares line of RSS against day over days 5 .. ``--days`` (target
~0: taken as met within +-0.5 MiB/day, 12.5 MiB over 25 days).  With ``--tracemalloc``
the allocations of this process are traced and the growth between the snapshots at
day 5 and day 20 (or the last day) is printed by file:line (tracing slows the feed
several times over).  Targets: < 10 minutes for 30 days on 2 CPUs.
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time
import tracemalloc
from collections import Counter
from dataclasses import dataclass
from functools import reduce
from operator import xor
from pathlib import Path

import numpy as np

from dracc.core.config import Config
from dracc.ingest.live import Recorder
from dracc.ingest.live.sources import LiveSource
from dracc.pipeline.watch import Watch
from dracc.pipeline.watch_analysis import LiveAnalyser, worker_pool

REPO = Path(__file__).resolve().parents[1]
DAY_S = 86_400
PER_POLL = 20_000  #: lines a poll returns at most
WINDOW_S = 3600.0
EVERY_S = 1.0
MAX_BYTES = 256 << 20
MIB = 1 << 20
FLAT_PCT = 0.10  #: max RSS of days 10.. within +10 % of day 5 ...
FLAT_MIB = 20.0  #: ... or +20 MiB, whichever is larger
SLOPE_MIB_DAY = 0.5  #: |slope| of RSS vs day over days 5.. taken as ~0
TARGET_WALL_S = 600.0  #: 30 days in < 10 minutes
_HEX = np.frombuffer(b"0123456789ABCDEF", np.uint8)
_EPOCH_DAY = np.datetime64("1970-01-01", "D")


# ----------------------------------------------------------------------- the day template


def simulate_day(out: Path, seed: int) -> Path:
    cmd = [sys.executable, "-m", "dracc", "simulate", "--out", str(out), "--hours", "24"]
    cmd += ["--seed", str(seed), "--compass-hz", "1"]
    print("generating:", " ".join(cmd[2:]), flush=True)
    subprocess.run(cmd, check=True, cwd=REPO, stdout=subprocess.DEVNULL)
    return out / "voyage.nmea"


def _digits(v: np.ndarray, width: int) -> np.ndarray:
    """(n, width) ASCII digits of non-negative integers, zero-padded."""
    p = 10 ** np.arange(width - 1, -1, -1, dtype=np.int64)
    return ((v[:, None] // p[None, :]) % 10 + 48).astype(np.uint8)


def _dmy(days: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(day of month, month, year) of days since 1970-01-01."""
    d = _EPOCH_DAY + days.astype("timedelta64[D]")
    mo = d.astype("datetime64[M]")
    y = d.astype("datetime64[Y]")
    return (
        (d - mo).astype(np.int64) + 1,
        (mo - y).astype(np.int64) + 1,
        y.astype(np.int64) + 1970,
    )


def _day_of(dd: int, mm: int, yyyy: int) -> int:
    return int((np.datetime64(f"{yyyy:04d}-{mm:02d}-{dd:02d}", "D") - _EPOCH_DAY).astype(int))


@dataclass
class _Fields:
    """One kind of field to rewrite: per entry the line, the offset of its digits in the
    day buffer, the old value (``c:`` time, or days since the epoch for a date), and the
    offset of the checksum (2 hex digits) that covers it."""

    line: np.ndarray
    pos: np.ndarray
    old: np.ndarray
    cs_pos: np.ndarray


class DayTemplate:
    """Day 0 as one buffer (lines ending in LF) and the fields a day's shift rewrites:
    ``c:`` times by width (10: seconds, 13: ms), RMC dates (``ddmmyy``), ZDA dates
    (``dd,mm,yyyy``: offsets of dd; mm at +3, yyyy at +6).  Lines whose ``c:`` is at or
    after ``end_s`` (the next midnight) are left out."""

    def __init__(self, path: Path) -> None:
        lines = path.read_bytes().splitlines()
        kept: list[bytes] = []
        c_rows: dict[int, list[tuple[int, int, int, int]]] = {}
        rmc: list[tuple[int, int, int, int]] = []
        zda: list[tuple[int, int, int, int]] = []
        first_s: int | None = None
        off = 0
        for ln in lines:
            if not ln:
                continue
            c = _tag_c(ln)
            if c is not None:
                v_s = c[1] if c[1] < 10**10 else c[1] // 1000
                if first_s is None:
                    first_s = v_s - v_s % DAY_S
                if v_s >= first_s + DAY_S:
                    continue  # 24:00:00: day 1 begins with it
            i = len(kept)
            if c is not None:
                pos, value, width, cs = c
                c_rows.setdefault(width, []).append((i, off + pos, value, off + cs))
            s = ln.find(b"$")
            star = ln.rfind(b"*")
            if s >= 0 and star > s:
                kind = ln[s + 3 : s + 6]
                if kind in (b"RMC", b"ZDA"):
                    f = ln[s:star].split(b",")
                    k = 9 if kind == b"RMC" else 2
                    if len(f) > k + (0 if kind == b"RMC" else 2) and f[k]:
                        pos = s + sum(len(x) + 1 for x in f[:k])
                        if kind == b"RMC":
                            d = f[k]
                            day = _day_of(int(d[:2]), int(d[2:4]), 2000 + int(d[4:6]))
                            rmc.append((i, off + pos, day, off + star + 1))
                        else:
                            day = _day_of(int(f[2]), int(f[3]), int(f[4]))
                            zda.append((i, off + pos, day, off + star + 1))
            kept.append(ln)
            off += len(ln) + 1
        self.n = len(kept)
        self.buf = np.frombuffer(b"\n".join(kept) + b"\n", np.uint8)
        self.start = np.zeros(self.n + 1, np.int64)
        self.start[1:] = np.cumsum([len(x) + 1 for x in kept])
        self.c = {w: _fields(rows) for w, rows in c_rows.items()}
        self.rmc = _fields(rmc)
        self.zda = _fields(zda)
        self.first_s = first_s or 0

    def block(self, k: int, i: int, j: int) -> list[bytes]:
        """Lines ``i .. j-1`` of day ``k`` (without line ends)."""
        a, b = int(self.start[i]), int(self.start[j])
        seg = self.buf[a:b].copy()
        for width, f in self.c.items():
            unit = 1 if width <= 10 else 1000
            self._patch(seg, f, i, j, a, [(0, width)], k * DAY_S * unit, _c_digits(width))
        self._patch(seg, self.rmc, i, j, a, [(0, 6)], k, _rmc_digits)
        self._patch(seg, self.zda, i, j, a, [(0, 2), (3, 2), (6, 4)], k, _zda_digits)
        return seg.tobytes().split(b"\n")[:-1]

    @staticmethod
    def _patch(seg, f: _Fields, i: int, j: int, a: int, spans, shift: int, digits) -> None:
        lo, hi = np.searchsorted(f.line, [i, j])
        if hi <= lo or shift == 0:
            return
        pos = f.pos[lo:hi] - a
        cs_pos = f.cs_pos[lo:hi] - a
        old = digits(f.old[lo:hi])
        new = digits(f.old[lo:hi] + shift)
        cols = np.concatenate([np.arange(o, o + w) for o, w in spans])
        idx = pos[:, None] + cols[None, :]
        seg[idx] = new
        delta = np.bitwise_xor.reduce(old ^ new, axis=1)
        hexv = seg[cs_pos[:, None] + np.arange(2)[None, :]]
        cs = (np.searchsorted(_HEX, hexv[:, 0]) << 4 | np.searchsorted(_HEX, hexv[:, 1])).astype(
            np.uint8
        )
        cs ^= delta
        seg[cs_pos] = _HEX[cs >> 4]
        seg[cs_pos + 1] = _HEX[cs & 15]


def _c_digits(width: int):
    return lambda v: _digits(v, width)


def _rmc_digits(days: np.ndarray) -> np.ndarray:
    dd, mm, yy = _dmy(days)
    return np.hstack([_digits(dd, 2), _digits(mm, 2), _digits(yy % 100, 2)])


def _zda_digits(days: np.ndarray) -> np.ndarray:
    dd, mm, yy = _dmy(days)
    return np.hstack([_digits(dd, 2), _digits(mm, 2), _digits(yy, 4)])


def _fields(rows: list[tuple[int, int, int, int]]) -> _Fields:
    a = np.array(rows, np.int64).reshape(-1, 4)
    return _Fields(a[:, 0], a[:, 1], a[:, 2], a[:, 3])


def _tag_c(ln: bytes) -> tuple[int, int, int, int] | None:
    """(offset of the ``c:`` digits, value, width, offset of the TAG checksum) of a line
    with a TAG block ``c:``, else None."""
    if ln[:1] != b"\\":
        return None
    end = ln.find(b"\\", 1)
    star = ln.rfind(b"*", 1, end)
    if end < 0 or star < 0 or end != star + 3:
        return None
    p = 1
    for part in ln[1:star].split(b","):
        if part[:2] == b"c:" and part[2:].isdigit():
            return p + 2, int(part[2:]), len(part) - 2, star + 1
        p += len(part) + 1
    return None


def self_check(tpl: DayTemplate, k: int, n: int = 2000) -> None:
    """Patched lines of day ``k`` checked line by line: checksums from their bytes, the
    ``c:`` k days on from day 0, RMC / ZDA dates k days on."""
    rng = np.random.default_rng(k)
    for i in rng.integers(0, tpl.n - 1, n // 100):
        i = int(i)
        j = min(tpl.n, i + 100)
        old = tpl.block(0, i, j)
        new = tpl.block(k, i, j)
        for a, b in zip(old, new, strict=True):
            _check_line(a, b, k)


def _check_line(a: bytes, b: bytes, k: int) -> None:
    if b[:1] == b"\\":
        end = b.find(b"\\", 1)
        assert int(b[end - 2 : end], 16) == reduce(xor, b[1 : end - 3], 0), b
    s = b.find(b"$")
    star = b.rfind(b"*")
    assert int(b[star + 1 : star + 3], 16) == reduce(xor, b[s + 1 : star], 0), b
    ca, cb = _tag_c(a), _tag_c(b)
    if ca is not None and cb is not None:
        unit = 1 if ca[2] <= 10 else 1000
        assert cb[1] - ca[1] == k * DAY_S * unit, (a, b)
    sa, sb = a[a.find(b"$") :], b[b.find(b"$") :]
    if sa[3:6] == b"RMC":
        da, db = sa.split(b",")[9], sb.split(b",")[9]
        d0 = _day_of(int(da[:2]), int(da[2:4]), 2000 + int(da[4:]))
        assert _day_of(int(db[:2]), int(db[2:4]), 2000 + int(db[4:])) - d0 == k, (a, b)
    elif sa[3:6] == b"ZDA":
        fa, fb = sa.split(b","), sb.split(b",")
        d0 = _day_of(int(fa[2]), int(fa[3]), int(fa[4]))
        assert _day_of(int(fb[2]), int(fb[3]), int(fb[4])) - d0 == k, (a, b)
    else:
        assert sa == sb, (a, b)


# ----------------------------------------------------------------------- the feed


class ReplaySource(LiveSource):
    """Days 0 .. ``days``-1 of the template, up to :data:`PER_POLL` lines a poll (never
    across a midnight of data time), received now."""

    kind = "replay"

    def __init__(self, tpl: DayTemplate, days: int) -> None:
        super().__init__(f"replay:{days}d", 1 << 16, PER_POLL)
        self.tpl = tpl
        self.days = days
        self.day = 0
        self.i = 0
        self.day_done = False  #: the last poll ended a day

    @property
    def finished(self) -> bool:
        return self.day >= self.days

    def poll(self, timeout_s: float = 0.0) -> list[tuple[int, bytes]]:
        self.day_done = False
        if self.finished:
            return []
        j = min(self.tpl.n, self.i + PER_POLL)
        lines = self.tpl.block(self.day, self.i, j)
        self.i = j
        if j == self.tpl.n:
            self.day, self.i, self.day_done = self.day + 1, 0, True
        now = time.time_ns()
        self.lines += len(lines)
        return [(now, ln) for ln in lines]


def rss_mib(pid: int | str = "self") -> float | None:
    """VmRSS of a process in MiB (None where it is gone)."""
    try:
        for row in Path(f"/proc/{pid}/status").read_text().splitlines():
            if row.startswith("VmRSS:"):
                return int(row.split()[1]) / 1024
    except OSError:
        pass
    return None


def worker_pids(executor: object) -> list[int]:
    """The analysis worker: the executor's processes, else the children of this process."""
    procs = getattr(executor, "_processes", None) or {}
    if procs:
        return sorted(int(p) for p in procs)
    try:
        import psutil

        return [c.pid for c in psutil.Process().children()]
    except ImportError:
        kids = Path(f"/proc/self/task/{os.getpid()}/children")
        return [int(x) for x in kids.read_text().split()] if kids.exists() else []


class RecordingCounter:
    """Counts and deletes the files the Recorder finishes."""

    def __init__(self, rec: Recorder) -> None:
        self.rec = rec
        self.seen = 0
        self.files = 0
        self.bytes = 0
        self.lines = 0

    def collect(self) -> None:
        for f in self.rec.files[self.seen :]:
            with f.open("rb") as fh:
                while chunk := fh.read(1 << 22):
                    self.bytes += len(chunk)
                    self.lines += chunk.count(b"\n")
            f.unlink()
            self.files += 1
        self.seen = len(self.rec.files)


@dataclass
class Row:
    day: int
    date: str
    fed: int
    wall_s: float
    rss: float
    worker: float | None
    window: int
    deviation: int
    runs: int
    last_lines: int | None
    last_s: float | None
    open_: int
    raised: int
    cleared: int
    recorded: int
    failed: int = 0


def run(args: argparse.Namespace, tpl: DayTemplate, tmp: Path) -> None:
    executor = worker_pool()
    analyser = LiveAnalyser(Config(), WINDOW_S, EVERY_S, MAX_BYTES, executor)
    rec = Recorder(tmp / "rec")
    src = ReplaySource(tpl, args.days)
    watch = Watch([src], rec, stale_s=1e9, analyser=analyser)
    counter = RecordingCounter(rec)
    rows: list[Row] = []
    raised = cleared = 0
    failed: Counter[str] = Counter()  #: analyses that gave no result, by message
    kinds: Counter[str] = Counter()  #: findings raised, by check/name/source
    snaps: dict[int, tracemalloc.Snapshot] = {}
    snap_days = {5, min(args.snap_day, args.days)}
    if args.tracemalloc:
        tracemalloc.start(1)
    print(
        f"{'day':>3} {'data date':>10} {'lines fed':>10} {'lines/s':>7} {'RSS':>7} "
        f"{'worker':>7} {'window':>8} {'dev rd':>6} {'runs':>5} {'failed':>6} {'last':>12} "
        f"{'open':>4} {'raised':>6} {'clrd':>5} {'recorded':>10}"
    )
    t0 = time.perf_counter()
    try:
        while not src.finished:
            job = analyser.job
            events = watch.step(0.0)
            if job is not None and analyser.job is not job and analyser.error is not None:
                failed[analyser.error[:100]] += 1  # collected, no result
            for ev in events:
                if ev["event"] == "raised":
                    raised += 1
                    kinds[f"{ev['check']}/{ev.get('name', '')}/{ev['source']}"] += 1
                else:
                    cleared += 1
            counter.collect()
            if src.day_done:
                r = _row(src, watch, analyser, executor, counter, raised, cleared, t0)
                r.failed = sum(failed.values())
                rows.append(r)
                _print_row(r)
                if args.tracemalloc and r.day in snap_days:
                    snaps[r.day] = tracemalloc.take_snapshot()
    finally:
        watch.close()
        executor.shutdown(wait=True)
    wall = time.perf_counter() - t0
    counter.collect()
    if rec.current is not None or rec.current_files():  # pragma: no cover - closed above
        print("warning: recording files still open")
    _summary(args, rows, counter, wall, rec, watch)
    print(f"analyses             {analyser.runs} started, {sum(failed.values())} gave no result")
    for msg, n in failed.most_common():
        print(f"  {n:>5} x {msg}")
    print(f"findings raised      {raised} (check/name/source):")
    for kind, n in kinds.most_common():
        print(f"  {n:>5} x {kind}")
    if args.tracemalloc and len(snaps) == 2:
        a, b = (snaps[d] for d in sorted(snaps))
        print(f"\ntracemalloc growth, day {min(snaps)} -> day {max(snaps)} (top 15 by size):")
        for st in b.compare_to(a, "lineno")[:15]:
            print(f"  {st.size_diff / 1024:+10.1f} KiB {st.count_diff:+8d} blocks  {st.traceback}")


def _row(src, watch, analyser, executor, counter, raised, cleared, t0) -> Row:
    pids = worker_pids(executor)
    w = [rss_mib(p) for p in pids]
    w_ok = [x for x in w if x is not None]
    last = analyser.last
    date = np.datetime_as_string(
        np.datetime64(src.tpl.first_s + (src.day - 1) * DAY_S, "s").astype("datetime64[D]")
    )
    open_ = len(watch.open_checks) + sum(st.stale is not None for st in watch.state.values())
    return Row(
        day=src.day,
        date=str(date),
        fed=watch.received,
        wall_s=time.perf_counter() - t0,
        rss=rss_mib() or 0.0,
        worker=sum(w_ok) if w_ok else None,
        window=analyser.window.size,
        deviation=analyser.store.readings(),
        runs=analyser.runs,
        last_lines=last.lines if last else None,
        last_s=last.seconds if last else None,
        open_=open_,
        raised=raised,
        cleared=cleared,
        recorded=watch.recorder.lines if watch.recorder is not None else 0,
    )


def _print_row(r: Row) -> None:
    worker = f"{r.worker:.0f}M" if r.worker is not None else "n/a"
    last = f"{r.last_lines}/{r.last_s:.1f}s" if r.last_lines is not None else "n/a"
    print(
        f"{r.day:>3} {r.date:>10} {r.fed:>10} {r.fed / r.wall_s:>7.0f} {r.rss:>6.0f}M "
        f"{worker:>7} {r.window / MIB:>7.1f}M {r.deviation:>6} {r.runs:>5} {r.failed:>6} {last:>12} "
        f"{r.open_:>4} {r.raised:>6} {r.cleared:>5} {r.recorded:>10}",
        flush=True,
    )


def _flat(rows: list[Row], get) -> tuple[str, str, str]:
    """(max of days 10.. vs day 5, slope over days 5.., verdict) for one process."""
    by = {r.day: get(r) for r in rows if get(r) is not None}
    if 5 not in by or not any(d >= 10 for d in by):
        return "n/a", "n/a", "n/a (needs --days >= 10)"
    base = by[5]
    top = max(v for d, v in by.items() if d >= 10)
    limit = max(base * (1 + FLAT_PCT), base + FLAT_MIB)
    days = np.array([d for d in sorted(by) if d >= 5], float)
    vals = np.array([by[int(d)] for d in days])
    slope = float(np.polyfit(days, vals, 1)[0])
    ok = top <= limit and abs(slope) <= SLOPE_MIB_DAY
    return (
        f"{top:.1f} vs {base:.1f} MiB ({top - base:+.1f}; limit {limit:.1f})",
        f"{slope:+.3f} MiB/day",
        "FLAT" if ok else "NOT flat",
    )


def _summary(args, rows, counter, wall, rec, watch) -> None:
    fed = watch.received
    print()
    print(f"lines fed            {fed} ({args.days} days x {fed // max(1, args.days)} lines)")
    print(f"wall time            {wall:.1f} s (target < {TARGET_WALL_S:.0f} s for 30 days)")
    print(f"lines/s              {fed / wall:.0f}")
    share = counter.lines / fed if fed else 0.0
    print(
        f"recorded / fed       {counter.lines} / {fed} = {share:.4%} "
        f"({counter.files} files, {counter.bytes / 1e9:.2f} GB, deleted as finished; "
        f"Recorder.lines {rec.lines})"
    )
    print(f"dropped              {watch.dropped() or 'nothing'}")
    for name, get in (("this process", lambda r: r.rss), ("analysis worker", lambda r: r.worker)):
        top, slope, verdict = _flat(rows, get)
        print(f"RSS {name:<16} max days 10..: {top}; slope days 5..: {slope}; {verdict}")
    print(
        f"  (targets: max of days 10.. <= day 5 + max({FLAT_PCT:.0%}, {FLAT_MIB:.0f} MiB); "
        f"|slope| <= {SLOPE_MIB_DAY} MiB/day)"
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--days", type=int, default=30, help="simulated days fed")
    ap.add_argument("--seed", type=int, default=1, help="seed of the simulated day")
    ap.add_argument(
        "--tracemalloc", action="store_true", help="trace; diff day 5 -> --snap-day by file:line"
    )
    ap.add_argument("--snap-day", type=int, default=20, help="the later tracemalloc snapshot")
    ap.add_argument("--day-log", type=Path, help="use this simulated day (skip simulate)")
    args = ap.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="dracc-bench-watch-mem-"))
    try:
        log = args.day_log or simulate_day(tmp / "day", args.seed)
        t = time.perf_counter()
        tpl = DayTemplate(log)
        if args.day_log is None:
            shutil.rmtree(tmp / "day")
        print(
            f"template: {tpl.n} lines/day, {tpl.buf.nbytes / 1e6:.1f} MB, "
            f"built in {time.perf_counter() - t:.1f} s",
            flush=True,
        )
        for k in (1, args.days - 1):
            self_check(tpl, k)
        print(f"self-check of days 1 and {args.days - 1}: checksums, c: and dates right")
        print(f"load average before the run: {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
        run(args, tpl, tmp)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()
