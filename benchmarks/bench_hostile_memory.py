"""Peak memory of damaged input: what a crashed logger, a hostile CSV and a bomb cost.

Run:  python benchmarks/bench_hostile_memory.py [--nul-mb 256] [--csv-field-mb 10]
                                                [--bomb-gb 3] [--workdir DIR]

Each case is a good log with the damage spliced in, analysed by ``dracc analyze --json``
in a child process; printed: the input size, the child's peak RSS (``ru_maxrss`` of
RUSAGE_CHILDREN), the exit code, the records kept and the damage counted, against
``[ingest] memory_cap_mb`` (512).

``nul``       a simulated NMEA log with a run of NUL bytes in the middle (a logger that
              crashed and left its preallocated file), no line end in it
``csv_field`` a long-form CSV log with one row holding a value of ``--csv-field-mb`` MB
``zstd_bomb`` an MCAP log with one extra chunk that declares 1 KB and inflates to
              ``--bomb-gb`` GB of zeros (about 100 KB on disk)
"""

from __future__ import annotations

import argparse
import json
import struct
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
CAP_MB = 512


def _run(log: Path, out: Path) -> dict:
    """Analyse ``log`` in a fresh child; its peak RSS is the growth of the children's maximum."""
    code = (
        "import resource, subprocess, sys; p = subprocess.run([sys.executable, '-m', 'dracc', "
        "'analyze', sys.argv[1], '--json', sys.argv[2]], stdout=subprocess.DEVNULL, "
        "stderr=subprocess.PIPE); r = resource.getrusage(resource.RUSAGE_CHILDREN); "
        "print(p.returncode, r.ru_maxrss, repr(p.stderr.decode()[-300:]))"
    )
    t0 = time.perf_counter()
    res = subprocess.run(
        [sys.executable, "-c", code, str(log), str(out)],
        capture_output=True,
        text=True,
        cwd=REPO,
        check=True,
    )
    rc, rss_kb, err = res.stdout.strip().split(" ", 2)
    doc = json.loads(out.read_text()) if out.exists() else {}
    return {
        "rc": int(rc),
        "peak_mb": int(rss_kb) / 1024,
        "seconds": time.perf_counter() - t0,
        "records": sum(i.get("records", 0) for i in doc.get("inputs", [])),
        "rejected": doc.get("rejected", {}),
        "stderr": err,
    }


def _simulate(work: Path, fmt: str, name: str) -> Path:
    subprocess.run(
        [
            sys.executable,
            "-m",
            "dracc",
            "simulate",
            "--out",
            str(work),
            "--hours",
            "1",
            "--seed",
            "3",
            "--format",
            fmt,
            "--compass-hz",
            "1",
            "--name",
            name,
        ],
        check=True,
        capture_output=True,
        cwd=REPO,
    )
    return next(work.glob(f"{name}.*"))


def nul_case(work: Path, mb: int) -> Path:
    good = _simulate(work / "nul_src", "nmea", "v").read_bytes()
    half = good.rfind(b"\n", 0, len(good) // 2) + 1
    log = work / "nul.nmea"
    with open(log, "wb") as fh:
        fh.write(good[:half])
        block = b"\0" * (1 << 20)
        for _ in range(mb):
            fh.write(block)
        fh.write(good[half:])
    return log


def csv_field_case(work: Path, mb: int) -> Path:
    src = _simulate(work / "csv_src", "csv-long", "v")
    lines = src.read_bytes().splitlines(keepends=True)
    head, rows = lines[0], lines[1:]
    bad = rows[len(rows) // 2].rstrip(b"\r\n").split(b",")
    bad[-1] = b"9" * (mb << 20)
    log = work / "csv_field.csv"
    with open(log, "wb") as fh:
        fh.write(head)
        fh.writelines(rows[: len(rows) // 2])
        fh.write(b",".join(bad) + b"\n")
        fh.writelines(rows[len(rows) // 2 :])
    return log


def _record(op: int, body: bytes) -> bytes:
    return struct.pack("<BQ", op, len(body)) + body


def _zstd_zeros(total: int) -> bytes:
    import zstandard

    cobj = zstandard.ZstdCompressor(level=19).compressobj()
    block = b"\0" * (1 << 24)
    parts = []
    left = total
    while left > 0:
        n = min(left, len(block))
        parts.append(cobj.compress(block[:n]))
        left -= n
    parts.append(cobj.flush())
    return b"".join(parts)


def zstd_bomb_case(work: Path, gb: float) -> Path:
    """A valid MCAP with a bomb chunk spliced in after its header record: the bomb declares
    1 KB of records.  Summary offsets after it would be off, so the good file is written
    without a summary (readers scan it)."""
    src = _simulate(work / "mcap_src", "mcap-json", "v").read_bytes()
    magic = b"\x89MCAP0\r\n"
    assert src.startswith(magic)
    hdr_len = struct.unpack_from("<Q", src, len(magic) + 1)[0]
    after_header = len(magic) + 9 + hdr_len
    comp = _zstd_zeros(int(gb * (1 << 30)))
    body = (
        struct.pack("<QQQI", 0, 0, 1024, 0)
        + struct.pack("<I", 4)
        + b"zstd"
        + struct.pack("<Q", len(comp))
        + comp
    )
    log = work / "bomb.mcap"
    log.write_bytes(src[:after_header] + _record(0x06, body) + src[after_header:])
    return log


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--nul-mb", type=int, default=256)
    ap.add_argument("--csv-field-mb", type=int, default=10)
    ap.add_argument("--bomb-gb", type=float, default=3.0)
    ap.add_argument("--workdir", type=Path, default=None)
    args = ap.parse_args()
    base = args.workdir or Path(tempfile.mkdtemp(prefix="dracc-hostile-"))
    base.mkdir(parents=True, exist_ok=True)
    cases = [
        ("nul", lambda: nul_case(base, args.nul_mb)),
        ("csv_field", lambda: csv_field_case(base, args.csv_field_mb)),
        ("zstd_bomb", lambda: zstd_bomb_case(base, args.bomb_gb)),
    ]
    # the address space of each analysis is not capped here: the figure is what it takes
    print(
        f"{'case':<10} {'input MB':>9} {'peak RSS MB':>12} {'cap MB':>7} {'exit':>5} "
        f"{'records':>8} {'s':>6}  damage counted"
    )
    for name, make in cases:
        log = make()
        r = _run(log, base / f"{name}.json")
        size = log.stat().st_size / 1e6
        verdict = "ok" if r["peak_mb"] <= CAP_MB else "OVER THE CAP"
        print(
            f"{name:<10} {size:>9.1f} {r['peak_mb']:>12.0f} {CAP_MB:>7} {r['rc']:>5} "
            f"{r['records']:>8} {r['seconds']:>6.1f}  {r['rejected']} {verdict}"
            + (f"  stderr: {r['stderr']}" if r["rc"] not in (0,) else "")
        )


if __name__ == "__main__":
    main()
