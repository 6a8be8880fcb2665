"""Issue 32: a fleet run analyses what is a log, skips and lists what is not, and its
counts add up (analysed + cached + failed = logs, skipped apart); the ranking's
``peer_median`` is the peers' median and its unit column is ``ins_unit``."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from conftest import SPARSE_RATES

from dracc.core.errors import ExitCode
from dracc.ingest import not_a_log
from dracc.pipeline.fleet.ranking import RANKING_COLUMNS, rank_fleet


def _counts_add_up(doc: dict) -> None:
    assert doc["analysed"] + doc["cached"] + doc["documents"] + doc["failed"] == doc["logs"]
    assert doc["failed"] == len(doc["failures"]) and doc["skipped"] == len(doc["skipped_files"])


@pytest.fixture(scope="module")
def fleet(tmp_path_factory) -> Path:
    """One vessel: three small simulated logs, a README, a .jpg-named binary."""
    from dracc.cli.main import main

    root = tmp_path_factory.mktemp("counts")
    vessel = root / "Aurora"
    vessel.mkdir()
    for i, seed in enumerate((41, 42, 43)):
        night = f"2026-11-{18 + i}"
        args = ["simulate", "--out", str(root / "sim"), "--hours", "1", "--seed", str(seed)]
        args += ["--start", f"{night}T00:00:00Z", "--name", night, *SPARSE_RATES]
        assert main(args) == 0
        (root / "sim" / f"{night}.nmea").rename(vessel / f"{night}.nmea")
    (vessel / "README.txt").write_text(
        "Aurora logs\n\nCopied from the bridge PC every morning.\nAsk the ETO before deleting.\n"
    )
    rng = np.random.default_rng(7)
    (vessel / "photo.jpg").write_bytes(b"\xff\xd8\xff\xe0" + rng.bytes(20000))
    return root


def test_not_a_log_names_readmes_and_photos_not_logs(fleet, tmp_path):
    v = fleet / "Aurora"
    assert "no NMEA sentence" in (not_a_log(v / "README.txt") or "")
    assert "JPEG" in (not_a_log(v / "photo.jpg") or "")
    assert not_a_log(v / "2026-11-18.nmea") is None
    random = tmp_path / "noise.jpg"  # a binary with no magic number dracc knows
    random.write_bytes(np.random.default_rng(3).bytes(8000))
    assert "binary file" in (not_a_log(random) or "")
    empty = tmp_path / "empty.nmea"  # an empty log fails (its reading says why)
    empty.write_bytes(b"")
    assert not_a_log(empty) is None


def test_skipped_files_are_listed_and_the_run_exits_0(fleet, tmp_path, run_cli):
    out = tmp_path / "out"
    code, _, err = run_cli("fleet", fleet / "Aurora", "--workers", "2", "--out", out)
    assert code == ExitCode.OK, err
    assert "skipped: Aurora/README.txt — not a log: text with no NMEA sentence" in err
    assert "skipped: Aurora/photo.jpg — not a log: a JPEG image" in err
    assert "failed:" not in err
    assert "fleet: 3 logs: 3 analysed, 0 from the cache, 0 failed; 2 files skipped" in err
    doc = json.loads((out / "fleet.json").read_text())
    assert doc["schema"] == "dracc.fleet/2"
    assert (doc["logs"], doc["analysed"], doc["cached"], doc["failed"]) == (3, 3, 0, 0)
    assert [f["log"] for f in doc["skipped_files"]] == ["README.txt", "photo.jpg"]
    _counts_add_up(doc)
    t = pd.read_parquet(out / "fleet.parquet")
    assert set(t["log"]) == {"2026-11-18.nmea", "2026-11-19.nmea", "2026-11-20.nmea"}
    assert (t["status"] == "ok").all()
    page = (out / "fleet.html").read_text()
    assert "Skipped: not a log" in page and "README.txt" in page
    assert "3 logs of 1 vessels" in page


def test_a_corrupt_log_fails_and_the_counts_still_add_up(fleet, tmp_path, run_cli):
    out = tmp_path / "out"
    assert run_cli("fleet", fleet / "Aurora", "--workers", "1", "--out", out)[0] == 0
    # a corrupt log beside them: every sentence's checksum damaged, nothing usable
    good = (fleet / "Aurora" / "2026-11-18.nmea").read_text().splitlines()
    corrupt = tmp_path / "Aurora" / "2026-11-21.nmea"
    corrupt.parent.mkdir()
    bad = [ln[:-2] + ("00" if ln[-2:] != "00" else "11") if "*" in ln else ln for ln in good]
    corrupt.write_text("\n".join(bad) + "\n")
    code, _, err = run_cli(
        "fleet", *sorted((fleet / "Aurora").iterdir()), corrupt, "--workers", "1", "--out", out
    )
    assert code == ExitCode.INPUT  # a real failure, as documented
    assert "failed: Aurora/2026-11-21.nmea:" in err
    assert "skipped: Aurora/README.txt" in err and "skipped: Aurora/photo.jpg" in err
    assert "fleet: 4 logs: 0 analysed, 3 from the cache, 1 failed; 2 files skipped" in err
    doc = json.loads((out / "fleet.json").read_text())
    assert (doc["logs"], doc["analysed"], doc["cached"], doc["failed"], doc["skipped"]) == (
        4,
        0,
        3,
        1,
        2,
    )
    assert doc["failures"][0]["log"] == "2026-11-21.nmea"
    _counts_add_up(doc)
    t = pd.read_parquet(out / "fleet.parquet")
    failed = t[t["status"] == "failed"]
    assert failed["log"].tolist() == ["2026-11-21.nmea"]
    assert "README.txt" not in set(t["log"]) and "photo.jpg" not in set(t["log"])


def _measures(values: dict[str, list[float]], quantity: str, unit: str) -> pd.DataFrame:
    rows = []
    for vessel, nights in values.items():
        for k, v in enumerate(nights):
            rows.append(
                {
                    "vessel": vessel,
                    "night": f"2026-11-{10 + k:02d}",
                    "unit": "log" if quantity == "log_scale" else "ins1",
                    "quantity": quantity,
                    "measure_unit": unit,
                    "value": v,
                    "sigma": 0.05 if quantity == "log_scale" else np.nan,
                    "dof": np.nan if quantity == "log_scale" else 200.0,
                    "n": 500,
                    "method": "calibration" if quantity == "log_scale" else "reference",
                    "lat_deg": 54.0,
                    "lon_deg": 7.0,
                }
            )
    return pd.DataFrame(rows)


@pytest.mark.parametrize(
    ("quantity", "unit", "values"),
    [
        # a linear quantity, six peers for each (even: numpy's mean of the middle two)
        ("log_scale", "%", [1.0, 1.4, 2.0, 2.1, 2.2, 2.6, 3.5]),
        # an RMS (ranked in log): the median of the RMS values, not of their logs
        ("lat_m_y", "m", [150.0, 180.0, 200.0, 210.0, 260.0, 300.0, 320.0]),
    ],
)
def test_peer_median_is_the_median_of_the_peers(quantity, unit, values):
    vessels = {f"V{i}": [v] for i, v in enumerate(values)}
    r = rank_fleet(_measures(vessels, quantity, unit))
    assert "ins_unit" in RANKING_COLUMNS and "unit" not in RANKING_COLUMNS
    assert list(r.columns) == list(RANKING_COLUMNS)
    assert len(r) == len(values)
    for _, row in r.iterrows():
        i = int(str(row["vessel"])[1:])
        peers = [v for j, v in enumerate(values) if j != i]
        assert row["peers"] == len(peers)  # none trimmed in this case
        assert row["peer_median"] == pytest.approx(float(np.median(peers)), rel=1e-12)
        ev = json.loads(row["evidence"])
        assert ev["peer"]["median"] == pytest.approx(float(np.median(peers)), rel=1e-12)
        mean = np.mean(np.log(peers)) if quantity == "lat_m_y" else np.mean(peers)
        expected_mean = np.exp(mean) if quantity == "lat_m_y" else mean
        assert ev["peer"]["mean"] == pytest.approx(float(expected_mean), rel=1e-9)
    assert set(r["ins_unit"]) == {"log" if quantity == "log_scale" else "ins1"}
