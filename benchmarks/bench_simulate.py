"""Time `dracc simulate` for the 24 h benchmark log (compass 10 Hz, everything else 1 Hz).

Prints the simulation time, the NMEA writing time per form, lines and megabytes.
Usage: python benchmarks/bench_simulate.py [HOURS]
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

from dracc.sim import SimParams, simulate
from dracc.sim.nmea_out import write_nmea


def main() -> None:
    hours = float(sys.argv[1]) if len(sys.argv) > 1 else 24.0
    t0, c0 = time.perf_counter(), time.process_time()
    v = simulate(SimParams(duration_s=hours * 3600.0))
    t1, c1 = time.perf_counter(), time.process_time()
    print(
        f"simulate {hours:g} h: {t1 - t0:.1f} s wall, {c1 - c0:.1f} s CPU "
        f"({len(v.truth)} truth samples)"
    )
    with tempfile.TemporaryDirectory() as d:
        for form in ("tag", "prefix", "bare"):
            p = Path(d) / f"{form}.nmea"
            t2, c2 = time.perf_counter(), time.process_time()
            write_nmea(v, p, form=form)
            t3, c3 = time.perf_counter(), time.process_time()
            data = p.read_bytes()
            lines = data.count(b"\n")
            print(
                f"write {form:6s}: {t3 - t2:5.1f} s wall, {c3 - c2:5.1f} s CPU, {lines} lines, "
                f"{len(data) / 1e6:.1f} MB, {lines / (c3 - c2) / 1e6:.2f} M lines per CPU s"
            )
            p.unlink()


if __name__ == "__main__":
    main()
