"""MCAP ingest speed and memory: dracc's reader against the stock per-message path.

Side by side in one run, on the simulated voyage (``dracc.sim.simulate``, default rates)
written as MCAP (JSON and ROS 2 CDR, zstd chunks of 1 MiB; and raw NMEA sentences, one per
message, for the memory table):

* dracc: :func:`dracc.ingest.mcap.read_mcap` into canonical frames (whole file), and
  :func:`dracc.ingest.inspect.inspect_logs` (``dracc inspect``: the read plus per-source
  summaries and time events; target >= 5x the stock JSON path);
* stock: ``mcap.reader.make_reader(f).iter_messages()`` + ``json.loads`` per message,
  and ``iter_decoded_messages()`` with the ``mcap-ros2-support`` decoder -- only
  decoding, no frames built, so the comparison favours the stock path.  The stock path is
  timed on the first ``--stock-limit`` messages (default 300 000; 0 = all) and its
  per-message time extrapolated to the file; the printout says so.  Each side runs
  ``--repeat`` times, alternating, and the best time counts.

Memory: the peak RSS (``VmHWM``) of a fresh subprocess reading the 6 h and the 24 h file
(ROS 2, JSON and raw NMEA), minus the RSS after imports, minus the returned frames' own arrays
(``memory_usage(deep=False)``): the reader's working memory above its output.  The two
voyages are printed side by side with the verdict: bounded when the 24 h figure is within
``--mem-tolerance`` MiB (default 5) of the 6 h one.  The load average (``os.getloadavg``)
is printed beside every timing.

Usage: ``python benchmarks/bench_mcap.py [--hours 24] [--workdir DIR] [--stock-limit N] [--repeat 2]``
(files are cached in DIR between runs).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

_CHILD = r"""
import sys, json
from dracc.core.config import IngestConfig
from dracc.ingest.mcap import read_mcap
import dracc.ingest.nmea  # noqa: F401  (import cost outside the measurement)
def status_kib(key):  # VmHWM: peak RSS of this process image (ru_maxrss keeps the parent's across exec)
    for line in open("/proc/self/status"):
        if line.startswith(key + ":"):
            return int(line.split()[1])
base = status_kib("VmHWM")
r = read_mcap(sys.argv[1], IngestConfig())
peak = status_kib("VmHWM")
held = status_kib("VmRSS")  # with the frames alive
frames = sum(int(f.memory_usage(deep=False).sum()) for f in r.frames.values())
print(json.dumps({"base_kib": base, "peak_kib": peak, "held_kib": held, "frames_bytes": frames,
                  "messages": r.lines}))
"""


def make_files(hours: float, workdir: Path) -> dict[str, Path]:
    from dracc.sim.mcap_out import write_mcap
    from dracc.sim.model import simulate
    from dracc.sim.params import SimParams

    out = {enc: workdir / f"voyage_{hours:g}h_{enc}.mcap" for enc in ("json", "ros2", "nmea")}
    if all(p.exists() for p in out.values()):
        return out
    t = time.perf_counter()
    v = simulate(SimParams(duration_s=hours * 3600.0))
    print(
        f"simulated {hours:g} h in {time.perf_counter() - t:.1f} s: "
        + ", ".join(f"{k} {len(f)}" for k, f in v.frames.items()),
        flush=True,
    )
    for enc, p in out.items():
        t = time.perf_counter()
        write_mcap(v.frames, v.roles, p, encoding=enc)
        print(
            f"wrote {p.name}: {p.stat().st_size / 1e6:.1f} MB in {time.perf_counter() - t:.1f} s",
            flush=True,
        )
    return out


def time_dracc(path: Path) -> tuple[float, int]:
    from dracc.core.config import IngestConfig
    from dracc.ingest.mcap import read_mcap

    t = time.perf_counter()
    r = read_mcap(path, IngestConfig())
    return time.perf_counter() - t, r.lines


def time_inspect(path: Path) -> tuple[float, int]:
    from dracc.core.config import IngestConfig
    from dracc.ingest.inspect import inspect_logs

    t = time.perf_counter()
    rep = inspect_logs([path], IngestConfig())
    return time.perf_counter() - t, rep["lines"]


def time_stock(path: Path, enc: str, limit: int) -> tuple[float, int]:
    from mcap.reader import make_reader

    n = 0
    t = time.perf_counter()
    with open(path, "rb") as fh:
        if enc == "json":
            for _s, _c, m in make_reader(fh).iter_messages():
                json.loads(m.data)
                n += 1
                if n == limit:
                    break
        else:
            from mcap_ros2.decoder import DecoderFactory

            for _s, _c, _m, _d in make_reader(
                fh, decoder_factories=[DecoderFactory()]
            ).iter_decoded_messages():
                n += 1
                if n == limit:
                    break
    return time.perf_counter() - t, n


def memory(path: Path) -> dict:
    res = subprocess.run(
        [sys.executable, "-c", _CHILD, str(path)], capture_output=True, text=True, check=True
    )
    return json.loads(res.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--hours", type=float, default=24.0)
    ap.add_argument(
        "--workdir", type=Path, default=Path(tempfile.gettempdir()) / "dracc_bench_mcap"
    )
    ap.add_argument("--stock-limit", type=int, default=300_000)
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--mem-tolerance", type=float, default=5.0, help="MiB (see the module doc)")
    args = ap.parse_args()
    args.workdir.mkdir(parents=True, exist_ok=True)
    files = make_files(args.hours, args.workdir)
    print(
        f"\n{'encoding':8} {'messages':>9} {'dracc s':>8} {'us/msg':>7} {'stock us/msg':>12} "
        f"{'stock s (full file)':>20} {'speed-up':>8} {'inspect s':>9} {'inspect speed-up':>16}"
        "  load (1/5/15 min)"
    )
    for enc, p in files.items():
        if enc == "nmea":  # raw NMEA sentences: in the memory table only
            continue
        # best of --repeat, alternating, so that load from other jobs hits both sides alike
        runs = [
            (time_dracc(p), time_stock(p, enc, args.stock_limit or -1), time_inspect(p))
            for _ in range(args.repeat)
        ]
        td, n = min(r[0] for r in runs)
        ts, ns = min(r[1] for r in runs)
        ti, ni = min(r[2] for r in runs)
        assert ni == n, (ni, n)
        per_d, per_s = td / n * 1e6, ts / ns * 1e6
        full = per_s * n / 1e6
        note = "" if ns == n else f" (extrapolated from {ns})"
        load = "/".join(f"{x:.2f}" for x in os.getloadavg())
        print(
            f"{enc:8} {n:9d} {td:8.2f} {per_d:7.2f} {per_s:12.2f} {full:12.1f}{note} "
            f"{per_s / per_d:7.1f}x {ti:9.2f} {full / ti:15.1f}x  {load}",
            flush=True,
        )
        if enc == "json":
            print(
                f"json: dracc inspect / stock reader + json.loads: {full / ti:.1f}x (target >= 5x)",
                flush=True,
            )
    print(
        "\nmemory: fresh subprocess per file; working = peak RSS - RSS after imports - frames' own arrays"
    )
    six = make_files(6.0, args.workdir) if args.hours != 6.0 else files
    print(
        f"{'encoding':8} {'voyage':>6} {'file MB':>8} {'messages':>9} {'peak MiB':>9} {'imports':>8} "
        f"{'frames':>7} {'working':>8}  load (1/5/15 min)"
    )
    for enc in files:
        work = []
        for label, p in (("6 h", six[enc]), (f"{args.hours:g} h", files[enc])):
            m = memory(p)
            w = (m["peak_kib"] - m["base_kib"]) / 1024 - m["frames_bytes"] / 2**20
            work.append(w)
            load = "/".join(f"{x:.2f}" for x in os.getloadavg())
            print(
                f"{enc:8} {label:>6} {p.stat().st_size / 1e6:8.1f} {m['messages']:9d} {m['peak_kib'] / 1024:9.1f} "
                f"{m['base_kib'] / 1024:8.1f} {m['frames_bytes'] / 2**20:7.1f} {w:8.1f}  {load}",
                flush=True,
            )
        d = work[1] - work[0]
        verdict = "bounded" if abs(d) <= args.mem_tolerance else "GROWS with the file"
        print(
            f"{enc:8} working memory 6 h {work[0]:.1f} MiB, {args.hours:g} h {work[1]:.1f} MiB: "
            f"difference {d:+.1f} MiB (tolerance {args.mem_tolerance:g}): {verdict}",
            flush=True,
        )


if __name__ == "__main__":
    main()
