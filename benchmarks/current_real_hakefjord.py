"""EP and current filter on a real log: VDRplayer/Hakefjord.txt (yacht, 22 min, ~5 kn).

Heading IIHDG (magnetic, variation field 0.0 E) and speed through water IIVHW drive the
DR; the Garmin GPGGA positions (1 Hz) are both the intermittent fixes (every
``--fix-every`` seconds) and, at all other epochs, the reference the EP is scored
against.  Prints, for open-loop DR, DR restarted at each fix (no current) and the
blended filter: RMS and maximum error, and the fraction of epochs whose GPS position
lies inside the EP's 2 drms circle; then the final set and drift.

The parser is deliberately minimal and local to this script (line order gives time:
HDG and VHW take the time of the last GPGGA).  Magnetic variation: ``--variation-deg``
(default 3.0 E, WMM-2015 near 58.0 N 11.7 E).

Run:  python benchmarks/current_real_hakefjord.py [--fix-every 300]
"""

from __future__ import annotations

import argparse
import itertools
import time
from pathlib import Path

import numpy as np

from dracc.core.geodesy import offset_ne_m
from dracc.core.units import DEG_RAD, KN_MPS
from dracc.math.current import CurrentModel, estimate_current
from dracc.math.fusion import PositionFix

LOG = (
    Path(__file__).resolve().parents[2] / "shared" / "data" / "real" / "VDRplayer" / "Hakefjord.txt"
)


def _checksum_ok(line: str) -> bool:
    if "*" not in line:
        return False
    body, cs = line[1:].split("*", 1)
    x = 0
    for ch in body:
        x ^= ord(ch)
    return f"{x:02X}" == cs[:2].upper()


def _dm(value: str, hemi: str) -> float:
    d = int(float(value) / 100)
    m = float(value) - 100 * d
    deg = d + m / 60.0
    return np.deg2rad(-deg if hemi in "SW" else deg)


def parse(path: Path):
    t_gga, lat, lon = [], [], []
    t_hdg, hdg = [], []
    t_vhw, stw = [], []
    now = None
    for raw in path.read_text(errors="replace").splitlines():
        line = raw.strip()
        if not line.startswith("$") or not _checksum_ok(line):
            continue
        f = line.split("*")[0].split(",")
        if f[0] == "$GPGGA" and f[2] and f[6] not in ("", "0"):
            hh, mm, ss = int(f[1][:2]), int(f[1][2:4]), float(f[1][4:])
            now = hh * 3600 + mm * 60 + ss
            t_gga.append(now)
            lat.append(_dm(f[2], f[3]))
            lon.append(_dm(f[4], f[5]))
        elif f[0] == "$IIHDG" and now is not None and f[1]:
            t_hdg.append(now)
            hdg.append(float(f[1]))
        elif f[0] == "$IIVHW" and now is not None and f[5]:
            t_vhw.append(now)
            stw.append(float(f[5]))
    return (
        np.array(t_gga),
        np.array(lat),
        np.array(lon),
        np.array(t_hdg),
        np.array(hdg),
        np.array(t_vhw),
        np.array(stw),
    )


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--fix-every", type=float, default=300.0, help="seconds between fixes")
    ap.add_argument("--variation-deg", type=float, default=3.0)
    ap.add_argument("--fix-sigma-m", type=float, default=10.0)
    args = ap.parse_args()
    t_g, lat, lon, t_h, hdg, t_v, stw = parse(LOG)
    # one epoch per GGA second; heading averaged on the circle per second, speed per second
    t = np.unique(t_g)
    first = np.searchsorted(t_g, t)
    lat, lon = lat[first], lon[first]
    h_rad = np.deg2rad(hdg + args.variation_deg)
    idx_h = np.searchsorted(t, t_h)
    idx_h = np.clip(idx_h, 0, t.size - 1)
    s = np.bincount(idx_h, np.sin(h_rad), t.size)
    c = np.bincount(idx_h, np.cos(h_rad), t.size)
    course = np.arctan2(s, c)
    idx_v = np.clip(np.searchsorted(t, t_v), 0, t.size - 1)
    n_v = np.bincount(idx_v, None, t.size)
    speed = np.bincount(idx_v, stw, t.size) / np.where(n_v > 0, n_v, 1)
    # carry the last value forward over seconds without a reading (counted)
    missing = (np.hypot(s, c) == 0) | (n_v == 0)
    for k in np.flatnonzero(missing):
        if k > 0:
            course[k] = course[k - 1] if np.hypot(s[k], c[k]) == 0 else course[k]
            speed[k] = speed[k - 1] if n_v[k] == 0 else speed[k]
    speed = speed * KN_MPS
    t = t - t[0]
    print(
        f"{LOG.name}: {t.size} epochs over {t[-1] / 60:.1f} min, {int(missing.sum())} carried forward"
    )

    model = CurrentModel(
        current_sigma_mps=0.3 * KN_MPS,
        current_tau_s=3600.0,
        speed_sigma_mps=0.2 * KN_MPS,
        speed_tau_s=300.0,
        heading_sigma_rad=2.0 * DEG_RAD,
        heading_tau_s=120.0,
    )
    sig = args.fix_sigma_m
    fix_idx = np.unique(np.searchsorted(t, np.arange(0.0, t[-1], args.fix_every)))
    fixes = [(t[i], PositionFix.from_sigma(lat[i], lon[i], sig)) for i in fix_idx[1:]]
    start = PositionFix.from_sigma(lat[0], lon[0], sig)
    scored = np.ones(t.size, bool)
    scored[fix_idx] = False

    t0 = time.perf_counter()
    blended = estimate_current(t, course, speed, start, fixes, model)
    dt_run = time.perf_counter() - t0
    open_loop = estimate_current(t, course, speed, start, (), model)
    # DR restarted at each fix, no current (the plain DR of METHODS §2)
    reset_lat, reset_lon = np.empty(t.size), np.empty(t.size)
    bounds = list(fix_idx) + [t.size]
    for a, b in itertools.pairwise(bounds):
        leg = estimate_current(
            t[a : b + 1 if b < t.size else b] - t[a],
            course[a : b + 1],
            speed[a : b + 1],
            PositionFix.from_sigma(lat[a], lon[a], sig),
            (),
            CurrentModel(current_sigma_mps=1e-9, current_tau_s=3600.0),
        )
        reset_lat[a:b], reset_lon[a:b] = leg.lat_rad[: b - a], leg.lon_rad[: b - a]

    print(
        f"fixes every {args.fix_every:.0f} s (sigma {sig:.0f} m), variation {args.variation_deg:+.1f} deg; "
        f"scored on {int(scored.sum())} GPS epochs between fixes"
    )
    for name, la, lo, two_drms in (
        ("open-loop DR", open_loop.lat_rad, open_loop.lon_rad, open_loop.two_drms_m),
        ("DR reset at fixes", reset_lat, reset_lon, None),
        ("blended EP (KF)", blended.lat_rad, blended.lon_rad, blended.two_drms_m),
    ):
        err = np.hypot(*offset_ne_m(lat, lon, la, lo))[scored]
        cover = (
            ""
            if two_drms is None
            else f", inside 2drms {np.mean(err < two_drms[scored]) * 100:5.1f} %"
        )
        print(f"  {name:18s} rms {np.sqrt(np.mean(err**2)):7.1f} m, max {err.max():7.1f} m{cover}")
    print(
        f"  final current: set {blended.set_deg[-1]:.0f} deg, drift {blended.drift_kn[-1]:.2f} kn "
        f"(+- {np.rad2deg(blended.set_sigma_rad[-1]):.0f} deg, {blended.drift_sigma_mps[-1] / KN_MPS:.2f} kn)"
    )
    nis = np.array([u.nis for u in blended.updates])
    print(f"  NIS mean {nis.mean():.2f} over {nis.size} fixes (2 expected when consistent)")
    print(
        f"  filter run: {dt_run * 1e3:.1f} ms for {t.size} epochs ({dt_run / t.size * 1e6:.0f} us/epoch)"
    )


if __name__ == "__main__":
    main()
