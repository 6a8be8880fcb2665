"""The fleet ranking on a simulated fleet with known faults (issue 20's acceptance).

Eight vessels sail four days each (one ``dracc simulate`` run per vessel and night, 24 h,
low sensor rates, voyages randomised over realistic ranges: position, speed, current).  Three carry a known fault:

- V1: INS2 three times worse than the INS2 of its peers (``--ins-unit-scales 1,3,1``);
- V2: the speed log's scale error is 6 % (the others the simulator's 2 %);
- V3: INS1's error doubles from the third night on.

The ranking must put the first two at its head with q < 0.05, find V3's INS1 with
``since`` the third night after two nights of the change, and give no healthy unit
q < 0.05.  The same nights audited on board (``dracc audit --json`` and its database)
rank the same when the shore office has only the documents.
"""

from __future__ import annotations

import datetime as dt
import json
import os
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from dracc.core.config import load_config
from dracc.pipeline.fleet import discover, run_fleet

VESSELS = ("V1", "V2", "V3", "V4", "V5", "V6", "V7", "V8")
NIGHTS = 4
START = dt.date(2026, 5, 1)
HOURS = 24.0
RATE_HZ = 0.1
CHANGE_NIGHT = 2  #: V3's INS1 doubles from the third night (index 2)


def _options(vessel: str, night: int, seed: int) -> dict:
    """``dracc simulate``'s options for one vessel and night, randomised from ``seed``."""
    rng = np.random.default_rng(seed)
    unit_scales = "1,1,1"
    if vessel == "V1":
        unit_scales = "1,3,1"
    if vessel == "V3" and night >= CHANGE_NIGHT:
        unit_scales = "2,1,1"
    return {
        "hours": HOURS,
        "seed": seed,
        "start": f"{START + dt.timedelta(days=night)}T00:00:00Z",
        "fmt": "nmea",
        "form": "tag",
        "tag_time": "s",
        "compass": "gyro",
        "compass_hz": RATE_HZ,
        "log_hz": RATE_HZ,
        "ins_hz": RATE_HZ,
        "gnss_hz": RATE_HZ,
        "aux_hz": 0.0,
        "lat_deg": float(rng.uniform(50.0, 58.0)),
        "lon_deg": float(rng.uniform(2.0, 9.0)),
        "speed_kn": float(rng.uniform(9.0, 16.0)),
        "legs": "",
        "ins_talkers": "IN,IN,IN",
        "ins_error_scale": 1.0,
        "ins_unit_scales": unit_scales,
        # the healthy units share the simulator's nominal errors (a fleet of one build):
        # only the voyages differ; a unit whose true error differs is what the ranking finds
        "gyro_error_deg": 0.3,
        "log_scale_pct": 6.0 if vessel == "V2" else 2.0,
        "log_bias_kn": 0.05,
        "current_kn": float(rng.uniform(0.1, 0.9)),
        "current_set_deg": float(rng.uniform(0.0, 360.0)),
        "variation_deg": 2.0,
        "noiseless": False,
        "truth_hz": 0.01,
        "segment_hours": 24.0,
        "fault": [],
    }


def _simulate(args: tuple[str, int, int, str]) -> str:
    from dracc.sim.output import simulate_to_folder

    vessel, night, seed, root = args
    out = Path(root) / vessel / f"night{night}"
    written = simulate_to_folder(
        out_dir=out, name=f"{vessel}-{night}", **_options(vessel, night, seed)
    )
    for extra in ("truth.csv", "errors.csv"):
        (out / extra).unlink()
    return str(written.log_path)


def build_fleet(root: Path, seed: int = 20) -> dict[tuple[str, int], str]:
    """Simulate the fleet under ``root/<vessel>/night<k>/``; (vessel, night) -> log path."""
    jobs = [
        (v, n, seed * 1000 + 10 * i + n, str(root))
        for i, v in enumerate(VESSELS)
        for n in range(NIGHTS)
    ]
    with ProcessPoolExecutor(max_workers=min(2, os.cpu_count() or 1)) as pool:
        paths = list(pool.map(_simulate, jobs))
    return {(j[0], j[1]): p for j, p in zip(jobs, paths, strict=True)}


@pytest.fixture(scope="module")
def fleet(tmp_path_factory):
    root = tmp_path_factory.mktemp("simfleet")
    return root, build_fleet(root)


@pytest.fixture(scope="module")
def raw(fleet, tmp_path_factory):
    """The fleet run from the raw logs (shore office with the logs)."""
    root, _ = fleet
    tasks = discover([str(root / v) for v in VESSELS], "**/*.nmea")
    return run_fleet(tasks, load_config(None), tmp_path_factory.mktemp("raw"), workers=2)


def _row(ranking: pd.DataFrame, vessel: str, unit: str, quantity: str) -> pd.Series:
    r = ranking[
        (ranking.vessel == vessel) & (ranking.ins_unit == unit) & (ranking.quantity == quantity)
    ]
    assert len(r) == 1, (vessel, unit, quantity)
    return r.iloc[0]


@pytest.mark.slow
def test_ranking_finds_the_bad_units_and_only_them(raw):
    res = raw
    r = res.ranking
    assert not res.failures
    bad = {("V1", "ins2"), ("V2", "log"), ("V3", "ins1")}
    found = r[r.q_value < 0.05]
    # every discovery is a seeded fault
    assert set(zip(found.vessel, found.ins_unit, strict=True)) <= bad, found.drop(
        columns="evidence"
    )
    # the two standing faults head the list
    head = set(zip(r.vessel.head(len(found)), r.ins_unit.head(len(found)), strict=True))
    assert {("V1", "ins2"), ("V2", "log")} <= head
    assert _row(r, "V1", "ins2", "lat_m_y").q_value < 0.05
    assert _row(r, "V2", "log", "log_scale").q_value < 0.05
    # the change: found two nights after it began, since naming its first night
    ins1 = r[(r.vessel == "V3") & (r.ins_unit == "ins1") & (r.q_value < 0.05)]
    assert len(ins1) >= 1
    change_night = START + dt.timedelta(days=CHANGE_NIGHT)
    assert (ins1.since == change_night).any(), ins1.drop(columns="evidence")
    ev = json.loads(ins1.iloc[0].evidence)
    assert len(ev["nights"]) == NIGHTS and ev["change"]["night"] == change_night.isoformat()


def _audit_vessel(args: tuple[str, list[str], str]) -> None:
    """The ship's side: the nightly audit of each night in turn (JSON and database)."""
    from dracc.pipeline.audit import run_audit
    from dracc.report.audit_json import write_json

    vessel, logs, out = args
    cfg = load_config(None)
    for k, log in enumerate(logs):
        o = run_audit([Path(log)], cfg, db=Path(out) / "db" / f"{vessel}.sqlite", vessel=vessel)
        # brief documents (no analysis) for half the fleet, whole ones for the rest
        brief = int(vessel[1:]) % 2 == 0
        write_json(o, Path(out) / "json" / vessel / f"audit-{k}.json", without_analysis=brief)


@pytest.mark.slow
def test_ranking_from_audit_documents_equals_ranking_from_logs(fleet, raw, tmp_path):
    _root, logs = fleet
    cfg = load_config(None)
    jobs = [(v, [logs[(v, n)] for n in range(NIGHTS)], str(tmp_path)) for v in VESSELS]
    with ProcessPoolExecutor(max_workers=2) as pool:
        list(pool.map(_audit_vessel, jobs))
    docs = sorted((tmp_path / "json").rglob("*.json"))
    assert len(docs) == len(VESSELS) * NIGHTS
    assert max(d.stat().st_size for d in docs) < 2_000_000
    assert min(d.stat().st_size for d in docs) < 30_000  # a brief document: a few kB
    for inputs in ([str(tmp_path / "json" / v) for v in VESSELS], [str(tmp_path / "db")]):
        shore = run_fleet(discover(inputs), cfg, tmp_path / "shore", workers=1)
        assert not shore.failures
        assert shore.analysed == 0  # nothing analysed ashore: the documents are read
        pd.testing.assert_frame_equal(shore.ranking, raw.ranking)
        # the fleet table's figures are the same too (the log column names the document)
        cols = ["vessel", "day", "ins_unit", "channel", "m_y", "dr_containment_2m", "log_scale_pct"]
        pd.testing.assert_frame_equal(
            shore.table[cols].sort_values(cols[:4]).reset_index(drop=True),
            raw.table[cols].sort_values(cols[:4]).reset_index(drop=True),
        )
