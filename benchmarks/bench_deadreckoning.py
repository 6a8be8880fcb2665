"""Time dead reckoning with the honest covariance for a 24 h log at 10 Hz (864 000 samples).

Prints wall-clock seconds for: the integration alone (integrate_ne), the full
dead_reckon with hourly restarts from 1 Hz fixes, and with no restarts.  Run:
    python benchmarks/bench_deadreckoning.py
"""

from __future__ import annotations

import time

import numpy as np

from dracc.math.deadreckoning import dead_reckon, integrate_ne


def main() -> None:
    hz = 10.0
    t = np.arange(0.0, 86400.0, 1.0 / hz)
    heading = np.mod(0.7 + 0.8 * np.sin(t / 1500.0), 2 * np.pi)
    speed = 6.0 + 0.5 * np.cos(t / 900.0)
    tf = np.arange(0.0, 86400.0, 1.0)
    fixes = (tf, np.full(tf.size, 1.0), np.full(tf.size, 0.2))
    print(f"samples: {t.size} ({hz:g} Hz, 24 h)")

    t0 = time.perf_counter()
    integrate_ne(t, speed * np.cos(heading), speed * np.sin(heading), 1.0, 0.2)
    print(f"integrate_ne:                 {time.perf_counter() - t0:6.2f} s")

    for reset in ("1h", "never"):
        t0 = time.perf_counter()
        tr = dead_reckon(t, heading, speed, fixes=fixes, reset_s=reset)
        dt = time.perf_counter() - t0
        print(
            f"dead_reckon reset={reset:<6} legs={tr.n_legs:3d}: {dt:6.2f} s "
            f"(2M at the end {tr.radius_2m_m[-1]:.0f} m)"
        )


if __name__ == "__main__":
    main()
