"""Issue 33: a fuzzer over what ships send ashore, audit documents and audit databases.

Seeded random mutations of a good document (a field's type, size, range or date, deep
nesting, cut or flipped bytes, NaN) and of a good database (a value of another type,
a damaged JSON column, a dropped table, a table replaced by a view over an endless or a
large recursive query, a trigger, a generated column, a column retyped, the schema
version, many rows, flipped or cut bytes).  Each case, beside the good document, must
be read or refused with a reason (never another exception: that is exit 5) within its
time bound; then every case that was read goes through the whole batch with the good
one, tables and page written.  ``benchmarks/bench_fleet_fuzz.py`` is the long form.
"""

from __future__ import annotations

import time

import pytest
from fleet_hostile import GOOD, inbox, write_case

import dracc.pipeline.state_read as state_read
from dracc.core.config import Config
from dracc.pipeline.fleet import discover, run_fleet
from dracc.pipeline.fleet.documents import expand_documents
from dracc.report.fleet_html import fleet_html
from dracc.report.fleet_tables import write_tables

CASES = 50  #: seeds 0..49: 25 documents, 25 databases
BUDGET_S = 2.0  #: a database's read budget here (10 s in use)
BOUND_S = 5.0  #: no case may take longer to read or refuse


def test_fuzzed_documents_and_databases_fail_alone_and_in_bounded_time(tmp_path, monkeypatch):
    monkeypatch.setattr(state_read, "READ_BUDGET_S", BUDGET_S)
    folder = inbox(tmp_path)
    internal, slow, read, refused = [], [], [], []
    nights = 1  # the good document's
    for seed in range(CASES):
        case = write_case(tmp_path / "cases", seed)
        t0 = time.monotonic()
        try:
            _, summaries, failures = expand_documents(discover([str(case)]))
        except Exception as err:  # what the CLI would report as exit 5
            internal.append((seed, f"{type(err).__name__}: {err}"[:200]))
            continue
        finally:
            if time.monotonic() - t0 > BOUND_S:
                slow.append(seed)
        if failures:
            assert all(isinstance(v, str) and v for v in failures.values())
            refused.append(seed)
        else:
            read.append(seed)
            nights += len(summaries)
            case.rename(folder / case.name)
    assert internal == [] and slow == []
    assert len(refused) >= CASES // 2 and read  # the mutations reach both outcomes
    # every case that was read, beside the good document, through the whole batch
    res = run_fleet(discover([str(folder)]), Config(), tmp_path / "out", workers=1)
    write_tables(res, tmp_path / "out", extra={"fleet.html": fleet_html(res)})
    assert not res.failures and GOOD in set(res.table.vessel)
    assert res.documents >= min(nights, 2)  # (a vessel's night given twice is one row)


@pytest.mark.parametrize("seed", [0, 1])
def test_a_fuzz_case_is_repeated_by_its_seed(tmp_path, seed):
    a = write_case(tmp_path / "a", seed).read_bytes()
    b = write_case(tmp_path / "b", seed).read_bytes()
    assert a == b
