"""`dracc fleet` end to end on simulated logs: local pool, resume, failures, and a real Dask
scheduler with a worker on loopback (subprocesses, bounded waits, always torn down)."""

from __future__ import annotations

import base64
import json
import os
import re
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
import pytest
from conftest import SPARSE_RATES

from dracc.cli.main import main
from dracc.core.errors import ExitCode

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def fleet(tmp_path_factory) -> Path:
    """Two vessels, two 2 h logs each, and one file that is not a log."""
    root = tmp_path_factory.mktemp("fleet")
    for vessel, seeds in (("Aurora", (31, 32)), ("Nordlys ★", (33, 34))):
        for i, seed in enumerate(seeds):
            night = f"2026-11-{18 + i}"
            assert (
                main(
                    [
                        "simulate",
                        "--out",
                        str(root / "sim"),
                        "--hours",
                        "2",
                        "--seed",
                        str(seed),
                        "--start",
                        f"{night}T00:00:00Z",
                        "--name",
                        f"{vessel[:2]}-{night}",
                        *SPARSE_RATES,
                    ]
                )
                == 0
            )
            (root / vessel).mkdir(exist_ok=True)
            (root / "sim" / f"{vessel[:2]}-{night}.nmea").rename(root / vessel / f"{night}.nmea")
    (root / "Nordlys ★" / "notes.txt").write_text("crew list, not a log\n")
    return root


@pytest.fixture(scope="module")
def local_run(fleet, tmp_path_factory):
    out = tmp_path_factory.mktemp("local")
    code = main(
        [
            "fleet",
            str(fleet / "Aurora"),
            str(fleet / "Nordlys ★"),
            "--workers",
            "2",
            "--out",
            str(out),
        ]
    )
    # the tables as this run wrote them (a later test re-runs into the same folder)
    tables = {n: pd.read_parquet(out / f"{n}.parquet") for n in ("fleet", "trends")}
    return code, out, tables


def test_local_pool_tables_failures_and_pages(local_run):
    code, out, tables = local_run
    assert code == ExitCode.OK  # notes.txt is no log: skipped and listed, not failed
    t = tables["fleet"]
    assert sorted(t["vessel"].unique()) == ["Aurora", "Nordlys ★"]
    assert (t["status"] == "ok").all() and "notes.txt" not in set(t["log"])
    ok = t[t["status"] == "ok"]
    assert len(ok) == 4 * 9 and set(ok["ins_unit"]) == {"ins1", "ins2", "ins3"}
    assert (
        ok["m_y"].gt(0).all()
        and ok["apriori_verdict"].isin(["established", "within", "raised"]).all()
    )
    # the DR verdict word of `dracc analyze`, and dr_consistent agreeing with it
    assert ok["dr_verdict"].notna().all()
    assert (
        ok["dr_verdict"].isin(["consistent", "conservative", "inconsistent", "undetermined"]).all()
    )
    judged = ok[ok["dr_verdict"] != "undetermined"]
    assert (judged["dr_consistent"] == (judged["dr_verdict"] != "inconsistent")).all()
    assert ok.loc[ok["dr_verdict"] == "undetermined", "dr_consistent"].isna().all()
    assert ok.loc[ok["dr_verdict"] != "undetermined", "dr_nees"].notna().all()
    first = ok.groupby(["vessel", "ins_unit", "channel"]).head(1)
    assert (first["apriori_verdict"] == "established").all()  # no a priori configured
    csv = pd.read_csv(out / "fleet.csv")
    assert len(csv) == len(t) and list(csv.columns) == list(t.columns)
    summary = json.loads((out / "fleet.json").read_text())
    assert summary["skipped_files"][0]["log"] == "notes.txt" and not summary["failures"]
    assert (summary["logs"], summary["analysed"], summary["skipped"]) == (4, 4, 1)
    assert (out / "vessels" / "Nordlys ★" / "fleet.csv").exists()  # Unicode kept
    page = (out / "fleet.html").read_text()
    pngs = re.findall(r"src='data:image/png;base64,([A-Za-z0-9+/=]+)'", page)
    assert len(pngs) >= 2 and all(base64.b64decode(p)[:4] == b"\x89PNG" for p in pngs)
    assert (
        "notes.txt" in page
        and "http://" not in page
        and "https://" not in page
        and "4 logs of 2 vessels" in page
    )
    assert pd.read_parquet(out / "trends.parquet")["day"].nunique() == 2


def test_rerun_skips_done_logs(local_run, fleet, run_cli):
    _, out, tables = local_run
    before = tables["fleet"]
    code, stdout, err = run_cli(
        "fleet", fleet / "Aurora", fleet / "Nordlys ★", "--workers", "2", "--out", out
    )
    assert code == ExitCode.OK
    assert "fleet: 4 logs: 0 analysed, 4 from the cache, 0 failed; 1 file skipped" in err
    assert "skipped: Nordlys ★/notes.txt — not a log: text with no NMEA sentence" in err
    pd.testing.assert_frame_equal(pd.read_parquet(out / "fleet.parquet"), before)
    assert "Aurora" in stdout  # the terminal table (--force is covered in test_fleet.py)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _stop(procs) -> None:
    for p in procs:
        if p.poll() is None:
            os.killpg(p.pid, signal.SIGTERM)
    deadline = time.monotonic() + 15
    for p in procs:
        try:
            p.wait(timeout=max(0.1, deadline - time.monotonic()))
        except subprocess.TimeoutExpired:
            os.killpg(p.pid, signal.SIGKILL)
            p.wait()


def test_dask_scheduler_gives_the_local_table(local_run, fleet, tmp_path):
    pytest.importorskip("distributed")
    from distributed import Client

    port = _free_port()
    addr = f"tcp://127.0.0.1:{port}"
    common = {"stdout": subprocess.DEVNULL, "stderr": subprocess.DEVNULL, "start_new_session": True}
    procs = []
    try:
        procs.append(
            subprocess.Popen(
                [
                    sys.executable,
                    "-m",
                    "dask",
                    "scheduler",
                    "--host",
                    "127.0.0.1",
                    "--port",
                    str(port),
                    "--no-dashboard",
                ],
                **common,
            )
        )
        procs.append(
            subprocess.Popen(
                [
                    sys.executable,
                    "-m",
                    "dask",
                    "worker",
                    addr,
                    "--nworkers",
                    "1",
                    "--nthreads",
                    "1",
                    "--no-dashboard",
                ],
                **common,
            )
        )
        with Client(addr, timeout=60) as c:  # bounded waits for the scheduler and the worker
            c.wait_for_workers(1, timeout=90)
        out = tmp_path / "dask"
        code = main(
            [
                "fleet",
                str(fleet / "Aurora"),
                str(fleet / "Nordlys ★"),
                "--scheduler",
                addr,
                "--out",
                str(out),
            ]
        )
    finally:
        _stop(procs)
    assert code == ExitCode.OK  # notes.txt skipped, not failed
    _, _, local = local_run
    pd.testing.assert_frame_equal(pd.read_parquet(out / "fleet.parquet"), local["fleet"])
    pd.testing.assert_frame_equal(pd.read_parquet(out / "trends.parquet"), local["trends"])


def test_real_logs_and_an_empty_mcap(real_dir, tmp_path):
    out = tmp_path / "out"
    code = main(
        [
            "fleet",
            str(real_dir / "VDRplayer" / "Hakefjord.txt"),
            str(real_dir / "keelson" / "6389403" / "test.mcap"),
            "--workers",
            "1",
            "--out",
            str(out),
        ]
    )
    assert code == ExitCode.INPUT
    t = pd.read_parquet(out / "fleet.parquet").set_index("log")
    assert (
        t.loc["test.mcap", "status"] == "failed"
        and "no usable record" in t.loc["test.mcap", "error"]
    )
    hk = t.loc["Hakefjord.txt"]
    assert hk["status"] == "ok" and hk["vessel"] == "VDRplayer" and pd.isna(hk["ins_unit"])
    assert str(hk["period_start_utc"].date()) == "2015-07-20" and hk["lines"] > 25000
    # a yacht's many sentences dracc does not use are valid input (ignored), not damaged lines
    assert hk["rejected_rate_pct"] == 0
