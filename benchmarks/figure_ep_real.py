"""The figure of docs/dead-reckoning.md: the estimated position on a real log.

Run:  python benchmarks/figure_ep_real.py [LOG] [--out docs/img/ep_real.png]

Default LOG: ../shared/data/real/anemomind/psaros33_Banque_Sturdza/2014/20140821/NMEA0010.TXT
(a racing yacht on Lake Geneva: NKE magnetic heading without variation, water speed, GPS).
Analysed with the default configuration; the plot shows, against time, the distance of
the water track (heading and log alone) and of the estimated position from the GPS, and
the estimated position's 2M radius; scored (out-of-sample) epochs are marked.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from dracc.core.config import Config  # noqa: E402
from dracc.core.geodesy import interp_position, offset_ne_m  # noqa: E402
from dracc.pipeline.analysis import analyse  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
DEFAULT = (
    ROOT.parent / "shared/data/real/anemomind/psaros33_Banque_Sturdza/2014/20140821/NMEA0010.TXT"
)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("log", nargs="?", default=str(DEFAULT))
    ap.add_argument("--out", default=str(ROOT / "docs/img/ep_real.png"))
    args = ap.parse_args()
    a = analyse([args.log], Config())
    dr = a.dead_reckoning
    tr, ep = dr.track, dr.epochs
    t_min = (tr.time_ns - tr.time_ns[0]) / 60e9
    # the reference positions (thinned for plotting) at the track's times
    ref = next(k for k in a.tracks if k.source == dr.reference_role or k.role == dr.reference_role)
    rlat, rlon = interp_position(ref.time_ns, ref.lat_rad, ref.lon_rad, tr.time_ns, 30 * 10**9)
    wn, we = offset_ne_m(tr.water_lat_rad, tr.water_lon_rad, rlat, rlon)
    fig, ax = plt.subplots(figsize=(8.0, 3.6), dpi=110)
    ax.plot(
        t_min,
        np.hypot(wn, we),
        color="tab:red",
        lw=0.9,
        ls="--",
        label="water track (heading and log alone) - GPS",
    )
    ax.plot(t_min, tr.ref_error_m, color="tab:green", lw=0.9, label="estimated position - GPS")
    ax.plot(t_min, tr.radius_2m_m, color="tab:blue", lw=1.2, label="2M of the estimated position")
    s = ep.scored & np.isfinite(ep.ref_error_m)
    et = (ep.time_ns - tr.time_ns[0]) / 60e9
    inside = ep.ref_error_m <= ep.radius_2m_m
    ax.scatter(
        et[s & inside],
        ep.ref_error_m[s & inside],
        s=10,
        color="tab:green",
        zorder=3,
        label="scored epoch, inside 2M",
    )
    ax.scatter(
        et[s & ~inside],
        ep.ref_error_m[s & ~inside],
        s=16,
        color="black",
        marker="x",
        zorder=3,
        label="scored epoch, outside 2M",
    )
    ax.set_yscale("log")
    ax.set_ylim(1.0, max(10.0, float(np.nanmax(tr.radius_2m_m[tr.leg > 0])) * 1.5))
    ax.set_xlabel("minutes from the first fix")
    ax.set_ylabel("metres")
    ax.set_title(
        f"{Path(args.log).name}: {dr.reset}, inside 2M at {100 * dr.containment_2m:.0f} % "
        f"of {dr.n_scored} scored epochs",
        fontsize=9,
    )
    ax.legend(fontsize=7, loc="lower right")
    ax.grid(alpha=0.3, which="both")
    fig.tight_layout()
    fig.savefig(args.out)
    print("wrote", args.out, "|", dr.verdict)


if __name__ == "__main__":
    main()
