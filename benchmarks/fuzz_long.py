"""The long fuzz run, before each release: at least 100 000 mutated inputs, zero tracebacks.

    python benchmarks/fuzz_long.py [--lines 100000] [--containers 1000] [--seed 1]

Two parts, one process (the machine is shared):

NMEA text
    Windows of 100 consecutive lines of real and simulated logs (the corpus of
    ``tests/test_fuzz.py``); in each window 20-60 lines are mutated (bit flips,
    truncation, garbage and NUL bytes, wrong or missing checksums, fused lines, huge
    lines, non-ASCII, out-of-range values, times out of order, junk lines); the log is
    read with ``dracc.ingest.nmea.read_nmea`` under one of four configurations (default,
    --ignore-checksum, --date, --strict) and the invariants of ``tests/test_fuzz.py`` are
    checked: no exception but DraccError, every silent line counted as a reject with a
    known reason, every untouched line giving the same records as in the clean log.
    One *input* is one mutated line.
Containers
    MCAP and CSV logs (sample and real) cut at a random offset, with a random run of
    bytes overwritten, deleted or repeated, read with ``dracc.ingest.read_file``: a
    result (records counted) or an IngestError (one line), never another exception; a
    file cut short never yields more records than the whole file.

Pipeline
    whole logs (sample and real) with 1-10 % of their lines mutated, through
    ``dracc.pipeline.analysis.analyse`` and every renderer (JSON checked against its schema,
    HTML, terminal): a report or a one-line error, never another exception.  The
    address space is capped (``--max-memory-gb``) so a runaway allocation shows as a
    MemoryError instead of the kernel killing a process on a shared machine.

Prints the inputs tried, the rejects by reason, the outcomes and the number of
tracebacks; a traceback's input is saved under ``--crash-dir`` to reproduce it.
"""

from __future__ import annotations

import argparse
import random
import resource
import sys
import tempfile
import time
import traceback
from collections import Counter
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "tests"))

from test_fuzz import (  # noqa: E402  (the fuzzer lives with its tests)
    REAL,
    SAMPLES,
    WINDOW,
    InvariantError,
    check_mutated,
    clean_records,
    load_corpus,
    mutate,
)

from dracc.core.config import IngestConfig  # noqa: E402
from dracc.core.errors import DraccError, IngestError  # noqa: E402
from dracc.ingest import read_file  # noqa: E402

CONFIGS = {
    "default": IngestConfig(),
    "ignore_checksum": IngestConfig(ignore_checksum=True),
    "date": IngestConfig(date="2014-08-01"),
    "strict": IngestConfig(strict=True),
}
CONTAINERS = [
    SAMPLES / "voyage.mcap",
    SAMPLES / "voyage_long.csv",
    SAMPLES / "voyage_wide.csv",
    REAL / "keelson" / "4a625f9" / "test.mcap",
    REAL / "rosbag2" / "talker.mcap",
    REAL / "rosbag2" / "cdr_test_0.mcap",
]


def _save(crash_dir: Path, tag: str, data: bytes, exc: BaseException) -> None:
    crash_dir.mkdir(parents=True, exist_ok=True)
    (crash_dir / f"{tag}.bin").write_bytes(data)
    (crash_dir / f"{tag}.txt").write_text("".join(traceback.format_exception(exc)))


def run_nmea(n_lines: int, rng: random.Random, tmp: Path, crash_dir: Path) -> dict:
    corpus = load_corpus(max_lines=20000)
    windows = [
        (c, a)
        for c in range(len(corpus))
        for a in range(0, max(1, len(corpus[c][0]) - WINDOW), WINDOW)
    ]
    cache: dict[tuple[int, int, str], dict] = {}
    rejects: Counter = Counter()
    ops: Counter = Counter()
    out = Counter()
    tracebacks = violations = 0
    examples: list[str] = []
    while out["lines_mutated"] < n_lines:
        c, a = windows[rng.randrange(len(windows))]
        lines, timed = corpus[c]
        window = lines[a : a + WINDOW]
        cname = rng.choice(tuple(CONFIGS))
        cfg = CONFIGS[cname]
        key = (c, a, cname)
        if key not in cache:
            try:
                cache[key] = clean_records(
                    window, tmp, CONFIGS["default"] if cname == "strict" else cfg
                )
            except DraccError:
                cache[key] = {}
        mut = mutate(window, rng, rng.randint(WINDOW // 5, 3 * WINDOW // 5))
        out["logs"] += 1
        out["lines_mutated"] += mut.n_mutated
        out[f"config_{cname}"] += 1
        ops.update(mut.ops)
        try:
            r = check_mutated(window, timed, mut, cache[key], tmp, cfg)
            rejects.update(r.rejects)
            out["log_lines"] += r.lines
            out["lines_without_record"] += r.silent
        except InvariantError as e:
            violations += 1
            if len(examples) < 10:
                examples.append(f"invariant: {e}")
                _save(crash_dir, f"invariant-{out['logs']}", mut.data, e)
        except IngestError as e:
            if cname == "strict":
                out["strict_refusals"] += 1  # --strict stops at the first bad line: by design
            else:
                out["ingest_errors"] += 1
                if len(examples) < 10:
                    examples.append(f"IngestError: {e}")
        except Exception as e:  # noqa: BLE001 - this is what the run hunts
            tracebacks += 1
            if len(examples) < 10:
                examples.append(f"traceback: {type(e).__name__}: {e}")
            _save(crash_dir, f"traceback-{out['logs']}", mut.data, e)
    return {
        "counts": out,
        "ops": ops,
        "rejects": rejects,
        "tracebacks": tracebacks,
        "violations": violations,
        "examples": examples,
    }


def run_containers(n: int, rng: random.Random, tmp: Path, crash_dir: Path) -> dict:
    files = [p for p in CONTAINERS if p.exists()]
    full = {p: read_file(p, IngestConfig()).records for p in files}
    blobs = {p: p.read_bytes() for p in files}
    out: Counter = Counter()
    errors: Counter = Counter()
    tracebacks = violations = 0
    examples: list[str] = []
    for i in range(n):
        p = files[rng.randrange(len(files))]
        b = bytearray(blobs[p])
        op = rng.choice(("cut", "overwrite", "delete", "repeat", "cut+overwrite"))
        if "overwrite" in op:
            at = rng.randrange(len(b))
            k = rng.randint(1, 2000)
            b[at : at + k] = bytes(rng.randrange(256) for _ in range(min(k, len(b) - at)))
        if op == "delete":
            at = rng.randrange(len(b))
            del b[at : at + rng.randint(1, 5000)]
        if op == "repeat":
            at = rng.randrange(len(b))
            b[at:at] = b[at : at + rng.randint(1, 5000)]
        if op.startswith("cut"):
            b = b[: rng.randrange(len(b))]
        q = tmp / ("c" + p.suffix)
        q.write_bytes(bytes(b))
        out[f"{p.suffix[1:]}_{op}"] += 1
        try:
            r = read_file(q, IngestConfig())
            out["read"] += 1
            out["records"] += r.records
            if op == "cut" and r.records > full[p]:
                violations += 1
                examples.append(f"{p.name} cut at {len(b)}: {r.records} > {full[p]} records")
        except DraccError as e:
            out["one_line_error"] += 1
            msg = str(e).replace(str(q), "FILE")
            errors[msg.split(":")[1].strip()[:60] if ":" in msg else msg[:60]] += 1
        except Exception as e:  # noqa: BLE001
            tracebacks += 1
            if len(examples) < 10:
                examples.append(f"{p.name} {op}: {type(e).__name__}: {e}")
            _save(crash_dir, f"container-{i}{p.suffix}", bytes(b), e)
    return {
        "counts": out,
        "errors": errors,
        "tracebacks": tracebacks,
        "violations": violations,
        "examples": examples,
    }


PIPELINE_LOGS = [
    SAMPLES / "voyage_tag.nmea",
    SAMPLES / "voyage_prefix.nmea",
    REAL / "VDRplayer" / "Hakefjord.txt",
    REAL / "anemomind" / "Irene" / "2014" / "20140611" / "NMEA0048.TXT",
]


def run_pipeline(n: int, rng: random.Random, tmp: Path, crash_dir: Path) -> dict:
    """Whole logs with 1-10 % of their lines mutated, through analyse() and every renderer."""
    import jsonschema

    from dracc.core.config import Config
    from dracc.pipeline.analysis import analyse
    from dracc.report import html as html_report
    from dracc.report import json_report, terminal

    schema = json_report.load_schema()
    logs = [p for p in PIPELINE_LOGS if p.exists()]
    out: Counter = Counter()
    tracebacks = 0
    examples: list[str] = []
    for i in range(n):
        src = logs[rng.randrange(len(logs))]
        lines = [ln for ln in src.read_bytes().replace(b"\r\n", b"\n").split(b"\n") if ln]
        mut = mutate(lines, rng, rng.randint(1, max(1, len(lines) // 10)))
        q = tmp / "voyage.nmea"
        q.write_bytes(mut.data)
        out["lines_mutated"] += mut.n_mutated
        try:
            a = analyse([q], Config())
            jsonschema.validate(json_report.to_dict(a), schema)
            html_report.render_html(a)
            terminal.render_text(a)
            out["analysed"] += 1
            out["sensor_faults"] += len(a.faults)
        except DraccError:
            out["one_line_error"] += 1
        except Exception as e:  # noqa: BLE001 - MemoryError included (address space is capped)
            tracebacks += 1
            if len(examples) < 10:
                examples.append(f"pipeline {src.name}: {type(e).__name__}: {str(e)[:200]}")
            _save(crash_dir, f"pipeline-{i}", mut.data, e)
    return {"counts": out, "tracebacks": tracebacks, "examples": examples}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--lines", type=int, default=100_000, help="mutated NMEA lines to try")
    ap.add_argument("--containers", type=int, default=1000, help="damaged MCAP/CSV files to try")
    ap.add_argument(
        "--pipeline",
        type=int,
        default=60,
        help="whole mutated logs through analyse() and the renderers",
    )
    ap.add_argument(
        "--max-memory-gb",
        type=float,
        default=4.0,
        help="address-space cap: a runaway allocation is a MemoryError, not an OOM kill",
    )
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--crash-dir", type=Path, default=Path("fuzz-crashes"))
    a = ap.parse_args()
    rng = random.Random(a.seed)
    limit = int(a.max_memory_gb * 2**30)
    resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        t0 = time.perf_counter()
        nm = run_nmea(a.lines, rng, tmp, a.crash_dir)
        t1 = time.perf_counter()
        co = run_containers(a.containers, rng, tmp, a.crash_dir)
        t2 = time.perf_counter()
        pi = run_pipeline(a.pipeline, rng, tmp, a.crash_dir)
        t3 = time.perf_counter()
    c = nm["counts"]
    print(f"seed {a.seed}")
    print(
        f"NMEA: {c['lines_mutated']:,} mutated lines in {c['logs']:,} logs of {WINDOW} lines "
        f"({t1 - t0:.0f} s)"
    )
    print(
        "  configurations: "
        + ", ".join(f"{k[7:]} {v}" for k, v in sorted(c.items()) if k.startswith("config_"))
    )
    print("  mutations: " + ", ".join(f"{k} {v:,}" for k, v in nm["ops"].most_common()))
    print(
        f"  rejected lines by reason ({sum(nm['rejects'].values()):,}): "
        + ", ".join(f"{k} {v:,}" for k, v in nm["rejects"].most_common())
    )
    print(
        f"  lines read {c['log_lines']:,} (outside --strict), of which {c['lines_without_record']:,} gave "
        "no record (each counted under a reason)"
    )
    print(
        f"  --strict refusals {c['strict_refusals']:,}; other ingest errors {c['ingest_errors']:,}"
    )
    print(f"  invariant violations {nm['violations']}; tracebacks {nm['tracebacks']}")
    cc = co["counts"]
    print(
        f"containers: {a.containers:,} damaged MCAP/CSV files ({t2 - t1:.0f} s): "
        f"{cc['read']:,} read ({cc['records']:,} records recovered), "
        f"{cc['one_line_error']:,} one-line errors"
    )
    print(
        "  damage: "
        + ", ".join(
            f"{k} {v}"
            for k, v in sorted(cc.items())
            if k not in ("read", "records", "one_line_error")
        )
    )
    print("  errors: " + "; ".join(f"{k} ({v})" for k, v in co["errors"].most_common(8)))
    print(f"  invariant violations {co['violations']}; tracebacks {co['tracebacks']}")
    pc = pi["counts"]
    print(
        f"pipeline: {a.pipeline} whole logs with {pc['lines_mutated']:,} mutated lines through "
        f"analyse, JSON (schema-checked), HTML and terminal ({t3 - t2:.0f} s): "
        f"{pc['analysed']} analysed ({pc['sensor_faults']} sensor faults flagged), "
        f"{pc['one_line_error']} one-line errors; tracebacks {pi['tracebacks']}"
    )
    total_tb = nm["tracebacks"] + co["tracebacks"] + pi["tracebacks"]
    print(
        f"inputs tried {c['lines_mutated'] + a.containers + a.pipeline:,}; tracebacks = {total_tb}; "
        f"invariant violations = {nm['violations'] + co['violations']}"
    )
    for e in nm["examples"] + co["examples"] + pi["examples"]:
        print("  example:", e)
    return 1 if total_tb or nm["violations"] or co["violations"] else 0


if __name__ == "__main__":
    sys.exit(main())
