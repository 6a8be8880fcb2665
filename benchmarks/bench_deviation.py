"""Timing of the INS-deviation analysis (dracc.math.deviation.analyse_deviations).

Three INS and a GNSS reference, positions and headings at RATE_HZ for DAYS days
(errors are simple sinusoids: this measures speed, not statistics).  Prints the
figures; keep runs short on shared machines:  python benchmarks/bench_deviation.py [days] [rate_hz]
"""

from __future__ import annotations

import math
import sys
import time

import numpy as np

import dracc.ingest  # noqa: F401  (import order)
from dracc.core.config import DeviationConfig
from dracc.core.geodesy import add_offset_ne
from dracc.math.deviation import UnitSeries, analyse_deviations

NS = 1_000_000_000
T0 = 1_700_006_400 * NS


def main(days: float = 1.0, rate_hz: float = 1.0) -> None:
    rng = np.random.default_rng(0)
    t_s = np.arange(0.0, days * 86400.0, 1.0 / rate_hz)
    t_ns = T0 + np.round(t_s * NS).astype(np.int64)
    lat0, lon0 = math.radians(40.0), math.radians(-20.0)
    lat, lon = add_offset_ne(lat0, lon0, 0.0 * t_s, 6.0 * t_s)
    units = {}
    for j, name in enumerate(("ins1", "ins2", "ins3")):
        ph = rng.uniform(0, 2 * np.pi, 3)
        en = 200 * np.sin(2 * np.pi * t_s / 5064.0 + ph[0])
        ee = 200 * np.sin(2 * np.pi * t_s / 86400.0 + ph[1])
        la, lo = add_offset_ne(lat, lon, en, ee)
        hdg = np.radians(90.0 + 0.1 * np.sin(2 * np.pi * t_s / 5064.0 + ph[2]) + j * 0.01)
        units[name] = UnitSeries(t_ns, la, lo, t_ns, hdg)
    ref = UnitSeries(t_ns, lat, lon, t_ns, np.full(len(t_s), math.pi / 2))
    readings = 4 * 2 * len(t_s)
    best = math.inf
    for _ in range(3):
        t0 = time.perf_counter()
        res = analyse_deviations(units, DeviationConfig(), reference=ref)
        best = min(best, time.perf_counter() - t0)
    t0 = time.perf_counter()
    d = res.to_dict()
    t_dict = time.perf_counter() - t0
    print(
        f"deviation: {days:g} d at {rate_hz:g} Hz, 3 INS + reference = {readings:,} readings, "
        f"{len(res.time_ns)} instants, {len(res.windows)} windows"
    )
    print(
        f"  analyse_deviations: {best * 1e3:.0f} ms (best of 3), "
        f"{readings / best / 1e6:.1f} M readings/s"
    )
    print(f"  to_dict: {t_dict * 1e3:.1f} ms ({len(d['samples'])} samples)")


if __name__ == "__main__":
    args = [float(a) for a in sys.argv[1:3]]
    main(*args)
