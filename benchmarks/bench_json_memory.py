"""Peak memory of the streamed JSON readers (gpsd JSON, Signal K deltas) as logs grow.

Run:  python benchmarks/bench_json_memory.py [--kind gpsd|delta] [--mb 500] [--factors 1 4]
                                             [--reference] [--workdir DIR]

A log of about ``--mb`` MB times each factor is generated (gpsd: ``gpspipe -w`` of a GNSS
receiver with a compass, per second a TPV, a SKY of 12 satellites and an ATT; delta: a
Signal K server's deltas, per 100 ms a heading, per second a position and a course and
speed update, per 10 s an environment update dracc does not read) and read by
``read_gpsd_json`` / ``read_signalk_delta`` in a fresh child process; printed: the size,
the records, the child's peak RSS (``ru_maxrss``), its RSS before the read (the
imports), the frames' own bytes, and the working memory beyond the frames (peak minus
the imports minus the frames), which streaming keeps flat.  ``--reference`` also runs
the whole-file reader the tests keep as the reference
(``tests/test_streamed_json_readers.py``).
"""

from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
T0 = 1714564800  #: 2024-05-01T12:00:00Z

_CHILD = """
import resource, sys, time
sys.path.insert(0, "tests")
from dracc.core.config import IngestConfig
from dracc.ingest.gpsd_json import read_gpsd_json
from dracc.ingest.signalk_delta import read_signalk_delta
kind, path, ref = sys.argv[1], sys.argv[2], sys.argv[3] == "1"
if ref:
    import test_streamed_json_readers as t
    reader = t.old_read_gpsd_json if kind == "gpsd" else t.old_read_signalk_delta
else:
    reader = read_gpsd_json if kind == "gpsd" else read_signalk_delta
before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
t0 = time.perf_counter()
r = reader(path, IngestConfig())
dt = time.perf_counter() - t0
peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
frames = sum(int(df.memory_usage(deep=True).sum()) for df in r.frames.values())
print(before, peak, frames, r.records, r.lines, dt)
"""


def _iso(t: float) -> str:
    s = time.strftime("%Y-%m-%dT%H:%M:%S", time.gmtime(int(t)))
    return f"{s}.{int(round((t % 1) * 1000)):03d}Z"


def _gpsd_epoch(i: int) -> str:
    t = _iso(T0 + i)
    lat = 57.7 + 1e-5 * i
    lon = 11.9 + 1e-5 * math.sin(i / 500)
    sats = ",".join(
        f'{{"PRN":{k + 1},"el":{(7 * k + i // 60) % 90},"az":{(31 * k) % 360},'
        f'"ss":{30 + k % 15},"used":{"true" if k % 3 else "false"},"gnssid":0,"svid":{k + 1}}}'
        for k in range(12)
    )
    return (
        f'{{"class":"TPV","device":"/dev/ttyUSB0","mode":3,"time":"{t}","ept":0.005,'
        f'"lat":{lat:.9f},"lon":{lon:.9f},"altHAE":46.8,"altMSL":2.1,"track":{(i / 10) % 360:.4f},'
        f'"speed":{5 + math.sin(i / 300):.3f},"climb":0.0,"eph":1.4,"epv":2.1}}\n'
        f'{{"class":"SKY","device":"/dev/ttyUSB0","time":"{t}","xdop":0.61,"ydop":0.72,'
        f'"vdop":1.20,"tdop":0.91,"hdop":0.94,"gdop":1.85,"pdop":1.53,"satellites":[{sats}]}}\n'
        f'{{"class":"ATT","device":"/dev/ttyUSB1","time":"{t}","heading":{(i / 10) % 360:.2f},'
        f'"mheading":{(i / 10 + 3) % 360:.2f},"rot":{math.sin(i / 50):.2f}}}\n'
    )


def _delta_second(i: int) -> str:
    out = []
    for k in range(10):
        t = _iso(T0 + i + k / 10)
        out.append(
            json.dumps(
                {
                    "context": "vessels.self",
                    "updates": [
                        {
                            "$source": "n2k.204",
                            "source": {"label": "n2k", "src": "204", "pgn": 127250},
                            "timestamp": t,
                            "values": [
                                {"path": "navigation.headingMagnetic", "value": (i + k) % 6},
                                {"path": "navigation.magneticVariation", "value": 0.05},
                            ],
                        }
                    ],
                },
                separators=(",", ":"),
            )
        )
    t = _iso(T0 + i)
    gnss = {"$source": "n2k.3", "source": {"label": "n2k", "src": "3"}, "timestamp": t}
    pos = {"latitude": 57.7 + 1e-5 * i, "longitude": 11.9, "altitude": 2.0}
    out.append(
        json.dumps(
            {
                "context": "vessels.self",
                "updates": [
                    {**gnss, "values": [{"path": "navigation.position", "value": pos}]},
                    {
                        **gnss,
                        "values": [
                            {"path": "navigation.courseOverGroundTrue", "value": (i % 600) / 100},
                            {"path": "navigation.speedOverGround", "value": 2.5},
                        ],
                    },
                ],
            },
            separators=(",", ":"),
        )
    )
    if i % 10 == 0:
        env = [{"path": f"environment.outside.v{j}", "value": j} for j in range(20)]
        out.append(json.dumps({"updates": [{"timestamp": t, "values": env}]}))
    return "\n".join(out) + "\n"


def generate(kind: str, path: Path, nbytes: int) -> None:
    make = _gpsd_epoch if kind == "gpsd" else _delta_second
    size, i = 0, 0
    with path.open("w") as fh:
        while size < nbytes:
            block = "".join(make(j) for j in range(i, i + 1000))
            fh.write(block)
            size += len(block)
            i += 1000


def measure(kind: str, path: Path, reference: bool) -> dict[str, float]:
    res = subprocess.run(
        [sys.executable, "-c", _CHILD, kind, str(path), "1" if reference else "0"],
        capture_output=True,
        text=True,
        cwd=REPO,
        check=True,
    )
    before, peak, frames, records, lines, dt = res.stdout.split()
    mib = 1024.0
    return {
        "mb": path.stat().st_size / 1e6,
        "lines": int(lines),
        "records": int(records),
        "imports_mib": int(before) / mib,
        "peak_mib": int(peak) / mib,
        "frames_mib": int(frames) / 2**20,
        "beyond_mib": (int(peak) - int(before)) / mib - int(frames) / 2**20,
        "seconds": float(dt),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--kind", choices=["gpsd", "delta"], default="gpsd")
    ap.add_argument("--mb", type=float, default=500.0)
    ap.add_argument("--factors", type=int, nargs="+", default=[1, 4])
    ap.add_argument("--reference", action="store_true", help="also the whole-file reader")
    ap.add_argument("--workdir", type=Path, default=None)
    a = ap.parse_args()
    with tempfile.TemporaryDirectory(dir=a.workdir) as tmp:
        for f in a.factors:
            log = Path(tmp) / f"{a.kind}-{f}x.log"
            generate(a.kind, log, int(a.mb * 1e6 * f))
            runs = [("streamed", False)] + ([("whole file", True)] if a.reference else [])
            for name, ref in runs:
                m = measure(a.kind, log, ref)
                print(
                    f"{a.kind} {f}x {name}: {m['mb']:.0f} MB, {m['lines']} lines, "
                    f"{m['records']} records in {m['seconds']:.1f} s; peak {m['peak_mib']:.0f} MiB "
                    f"(imports {m['imports_mib']:.0f}, frames {m['frames_mib']:.0f}), "
                    f"beyond the frames {m['beyond_mib']:.0f} MiB",
                    flush=True,
                )
            log.unlink()


if __name__ == "__main__":
    main()
