"""The long fuzz run over what ships send ashore (issue 33): audit documents and audit
databases, mutated, each beside one good document through the whole fleet batch.

    python benchmarks/bench_fleet_fuzz.py [--cases 1000] [--seed 0] [--bound-s 30]

The mutations are those of ``tests/test_fleet_fuzz.py`` (``tests/fleet_hostile.py``):
a document's field given another type, size, range or date, nested deep, cut, flipped
bytes, NaN; a database's value of another type, a damaged JSON column, a dropped table,
a table replaced by a view over an endless or a large recursive query, a trigger, a
generated column, a retyped column, the schema version, many nights, flipped or cut
bytes.  Each case runs as ``dracc fleet`` does, in this process: read (or refused), the
tables, trends, ranking and page built and written.  An exception other than the one
line of a failed input is an *internal error* (what the CLI reports as exit 5); a case
past ``--bound-s`` is *past its bound*.  Prints the counts, the refusals by reason and
the slowest case; a case that fails is kept under ``--crash-dir`` by its seed.
"""

from __future__ import annotations

import argparse
import shutil
import sys
import tempfile
import time
import traceback
from collections import Counter
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "tests"))

from fleet_hostile import GOOD, inbox, write_case  # noqa: E402

from dracc.core.config import Config  # noqa: E402
from dracc.core.errors import DraccError  # noqa: E402
from dracc.pipeline.fleet import discover, run_fleet  # noqa: E402
from dracc.report.fleet_html import fleet_html  # noqa: E402
from dracc.report.fleet_tables import write_tables  # noqa: E402


def _reason(error: str) -> str:
    """A refusal's reason without its file, values and positions (for counting)."""
    text = error.split(": ", 1)[-1]
    for cut in (" (", ": '", ": line ", " at ", " in position"):
        text = text.split(cut)[0]
    return " ".join(w for w in text.split() if not any(c.isdigit() for c in w))[:90]


def run_case(seed: int, work: Path) -> tuple[str, str, float]:
    """(outcome, detail, seconds) of fuzz case ``seed``: 'read', 'refused', 'internal'."""
    shutil.rmtree(work, ignore_errors=True)
    folder = inbox(work)
    write_case(folder, seed)
    t0 = time.monotonic()
    try:
        res = run_fleet(discover([str(folder)]), Config(), work / "out", workers=1)
        write_tables(res, work / "out", extra={"fleet.html": fleet_html(res)})
    except DraccError as err:  # the whole run failed on one input: not a failed row
        return "internal", f"run failed: {err}", time.monotonic() - t0
    except Exception:
        return "internal", traceback.format_exc(limit=-3), time.monotonic() - t0
    elapsed = time.monotonic() - t0
    if GOOD not in set(res.table.loc[res.table.status == "ok", "vessel"]):
        return "internal", "the good vessel's rows are missing", elapsed
    if res.failures:
        return "refused", _reason(res.failures[0]["error"]), elapsed
    return "read", "", elapsed


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cases", type=int, default=1000)
    ap.add_argument("--seed", type=int, default=0, help="the first case's seed")
    ap.add_argument("--bound-s", type=float, default=30.0, help="time bound of one case")
    ap.add_argument("--crash-dir", type=Path, default=Path("fleet-fuzz-crashes"))
    args = ap.parse_args()
    outcomes: Counter[str] = Counter()
    reasons: Counter[str] = Counter()
    past_bound, slowest = [], (0.0, -1)
    t_start = time.monotonic()
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp) / "case"
        for seed in range(args.seed, args.seed + args.cases):
            outcome, detail, elapsed = run_case(seed, work)
            kind = "documents" if seed % 2 == 0 else "databases"
            outcomes[f"{kind} {outcome}"] += 1
            slowest = max(slowest, (elapsed, seed))
            if outcome == "refused":
                reasons[detail] += 1
            if elapsed > args.bound_s:
                past_bound.append(seed)
            if outcome == "internal":
                args.crash_dir.mkdir(parents=True, exist_ok=True)
                write_case(args.crash_dir, seed)
                print(f"INTERNAL seed {seed}: {detail}", file=sys.stderr)
    n_internal = sum(v for k, v in outcomes.items() if k.endswith("internal"))
    print(f"fleet fuzz: {args.cases} cases (seeds {args.seed}..{args.seed + args.cases - 1}) "
          f"in {time.monotonic() - t_start:.0f} s")  # fmt: skip
    for k in sorted(outcomes):
        print(f"  {k:<24} {outcomes[k]:>6}")
    print(f"  internal errors (exit 5) {n_internal:>4}")
    print(f"  past the {args.bound_s:g} s bound {len(past_bound):>7}  {past_bound[:10]}")
    print(f"  slowest case: seed {slowest[1]}, {slowest[0]:.2f} s")
    print("refusals by reason:")
    for reason, n in reasons.most_common(25):
        print(f"  {n:>6}  {reason}")


if __name__ == "__main__":
    main()
