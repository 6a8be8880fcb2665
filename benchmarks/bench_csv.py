"""CSV ingest time and memory, long and wide form, for two lengths of voyage.

Run:  python benchmarks/bench_csv.py [--hours 3 6] [--workdir DIR]

For each length, ``dracc simulate --format csv-long`` and ``csv-wide`` (cached in DIR)
are read by :func:`dracc.ingest.csv.read_csv` in a fresh subprocess each; printed: rows,
seconds, the peak RSS above the RSS after imports, the returned frames' own arrays and
the difference (the reader's working memory above its output).  The growth of that
difference from the shorter to the longer voyage says how the reader's memory scales.
The load average is printed beside every run (the machine is shared).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

_CHILD = r"""
import sys, json, time
from dracc.core.config import IngestConfig
from dracc.ingest.csv import read_csv
def status_mib(key):
    for line in open("/proc/self/status"):
        if line.startswith(key + ":"):
            return int(line.split()[1]) / 1024
base = status_mib("VmRSS")
t = time.perf_counter()
r = read_csv(sys.argv[1], IngestConfig())
s = time.perf_counter() - t
frames = sum(int(f.memory_usage(deep=True).sum()) for f in r.frames.values()) / 2**20
print(json.dumps({"s": s, "peak": status_mib("VmHWM") - base, "frames": frames, "rows": r.lines}))
"""


def ensure(hours: float, form: str, workdir: Path) -> Path:
    out = workdir / f"{form}_{hours:g}h"
    path = out / "v.csv"
    if not path.exists():
        subprocess.run(
            [
                sys.executable,
                "-m",
                "dracc",
                "simulate",
                "--hours",
                f"{hours:g}",
                "--format",
                form,
                "--out",
                str(out),
                "--name",
                "v",
            ],
            check=True,
            stdout=subprocess.DEVNULL,
        )
    return path


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--hours", type=float, nargs=2, default=[3.0, 6.0])
    ap.add_argument(
        "--workdir", type=Path, default=Path(os.environ.get("TMPDIR", "/tmp")) / "dracc-bench-csv"
    )
    args = ap.parse_args()
    args.workdir.mkdir(parents=True, exist_ok=True)
    print(
        f"{'form':9} {'voyage':>6} {'file MB':>8} {'rows':>10} {'s':>6} {'peak MiB':>9} {'frames':>7} "
        f"{'working':>8}  load"
    )
    for form in ("csv-long", "csv-wide"):
        work = []
        for h in args.hours:
            path = ensure(h, form, args.workdir)
            res = subprocess.run(
                [sys.executable, "-c", _CHILD, str(path)],
                check=True,
                capture_output=True,
                text=True,
            )
            m = json.loads(res.stdout.strip().splitlines()[-1])
            work.append(m["peak"] - m["frames"])
            print(
                f"{form:9} {h:5g}h {path.stat().st_size / 1e6:8.1f} {m['rows']:10,d} {m['s']:6.2f} "
                f"{m['peak']:9.1f} {m['frames']:7.1f} {work[-1]:8.1f}  {os.getloadavg()[0]:.1f}",
                flush=True,
            )
        print(
            f"{form:9} working memory {args.hours[0]:g} h {work[0]:.0f} MiB, {args.hours[1]:g} h {work[1]:.0f} MiB: "
            f"{(work[1] - work[0]) / (args.hours[1] - args.hours[0]):+.0f} MiB per hour of voyage"
        )


if __name__ == "__main__":
    main()
