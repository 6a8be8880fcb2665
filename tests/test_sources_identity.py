"""Issue 13: a source is its file (or TAG s:, topic, CSV source) and its talker; merging
one key over several files is a decision the notes state.  Role detection uses what a
sentence type can be; --role with a key that matches nothing is an error."""

from __future__ import annotations

import json
from collections import Counter

import numpy as np
import pytest

from dracc.core.config import IngestConfig
from dracc.core.errors import ExitCode, OptionError
from dracc.frames import SourceInfo
from dracc.ingest import read_logs
from dracc.ingest.sources import assign_roles, file_ids, keys_must_match, separate_files

SEAP = "openrvdas/NBP1406_seap-2014-08-01"
GP02 = "openrvdas/NBP1406_gp02-2014-08-01"


def nmea(body: str) -> str:
    x = 0
    for b in body.encode():
        x ^= b
    return f"${body}*{x:02X}"


def gga_log(path, start_s: int, n: int, lat_min: str) -> None:
    lines = []
    for k in range(n):
        t = start_s + k
        hh, mm, ss = (t // 3600) % 24, (t // 60) % 60, t % 60
        lines.append(
            f"2026-03-01T{hh:02d}:{mm:02d}:{ss:02d}.000Z "
            + nmea(
                f"GPGGA,{hh:02d}{mm:02d}{ss:02d}.00,54{lat_min},N,01847.000,E,1,8,1.0,10.0,M,,M,,"
            )
        )
    path.write_text("\n".join(lines) + "\n")


def test_file_ids_strip_what_the_names_share():
    assert file_ids(["/a/NBP1406_seap-2014-08-01", "/a/NBP1406_gp02-2014-08-01"]) == {
        "/a/NBP1406_seap-2014-08-01": "seap",
        "/a/NBP1406_gp02-2014-08-01": "gp02",
    }
    assert file_ids(["x/gps.nmea", "y/gps.nmea"]) == {"x/gps.nmea": "gps", "y/gps.nmea": "gps~2"}
    assert file_ids(["a1.nmea", "a2.nmea"]) == {
        "a1.nmea": "a1",
        "a2.nmea": "a2",
    }  # no separator: whole stems


def test_real_two_receivers_of_one_ship_are_two_sources(real_dir):
    """Palmer's Seapath and its second GPS both talk GP; 45 m apart, overlapping in time."""
    v = read_logs([real_dir / SEAP, real_dir / GP02], IngestConfig())
    assert set(v.sources) == {"seap:GP", "gp02:GP", "PSXN"}  # PSXN: the Seapath's $PSXN,23
    pos = v.frames["position"]
    assert Counter(pos["source"].astype(str)) == {"gp02:GP": 1667, "seap:GP": 715}
    assert v.sources["seap:GP"].files == {str(real_dir / SEAP)}
    assert any(
        "GP: in 2 files whose times overlap" in d and "seap:GP, gp02:GP" in d
        for d in v.time_events.decisions
    )
    # the two are tens of metres apart, not one jumping receiver
    a = pos[pos["source"] == "seap:GP"].iloc[0]
    b = pos[pos["source"] == "gp02:GP"].iloc[0]
    dist = 6.371e6 * np.hypot(a.lat_rad - b.lat_rad, (a.lon_rad - b.lon_rad) * np.cos(a.lat_rad))
    assert 5 < dist < 200


def test_single_file_keys_do_not_change(real_dir):
    v = read_logs([real_dir / SEAP], IngestConfig())
    assert set(v.sources) == {"GP", "PSXN"}


def test_consecutive_files_of_one_recorder_are_one_source_and_say_so(tmp_path):
    a, b = tmp_path / "gps_day1.log", tmp_path / "gps_day2.log"
    gga_log(a, 0, 300, "30.000")
    gga_log(b, 300, 300, "30.000")
    v = read_logs([a, b], IngestConfig())
    assert set(v.sources) == {"GP"} and v.sources["GP"].records == 600
    assert any(
        d.startswith("GP: one source over 2 files that follow each other")
        for d in v.time_events.decisions
    )


def test_overlapping_files_are_two_sources_in_inspect_too(run_cli, tmp_path):
    a, b = tmp_path / "ship_gps1.log", tmp_path / "ship_gps2.log"
    gga_log(a, 0, 300, "30.000")
    gga_log(b, 100, 300, "30.024")
    code, out, err = run_cli("inspect", a, b, "--json", "-")
    assert code == 0, err
    rep = json.loads(out)
    assert set(rep["sources"]) == {"gps1:GP", "gps2:GP"}
    assert rep["sources"]["gps2:GP"]["records"] == 300
    assert any("kept apart as gps1:GP, gps2:GP" in d for d in rep["time"]["decisions"])


def test_separate_files_tolerates_a_short_overlap_at_the_seam():
    def info(lo, hi):
        return {"GP": SourceInfo(key="GP", first_ns=int(lo * 1e9), last_ns=int(hi * 1e9))}

    renames, notes = separate_files([("a", info(0, 3600)), ("b", info(3590, 7200))])
    assert renames == {"a": {}, "b": {}} and "merged" in notes[0]
    renames, _ = separate_files([("a", info(0, 3600)), ("b", info(3000, 7200))])
    assert renames == {"a": {"GP": "a:GP"}, "b": {"GP": "b:GP"}}


# ------------------------------------------------------------------------------ roles
def src(key: str, talker: str, **sentences: int) -> SourceInfo:
    return SourceInfo(
        key=key,
        talkers=Counter({talker: sum(sentences.values())}),
        sentences=Counter(sentences),
        records=sum(sentences.values()),
    )


def test_a_lone_ins_is_not_the_compass():
    s = {"IN": src("IN", "IN", GGA=30, HDT=30)}
    notes = assign_roles(s, {})
    assert s["IN"].roles == []
    assert any("IN not given the compass role" in n and "--role IN=compass" in n for n in notes)


def test_a_gga_talker_is_never_the_compass_beside_a_gyro():
    s = {
        "GP": src("GP", "GP", GGA=30, RMC=30, HDT=30),
        "HE": src("HE", "HE", HDT=300),
        "IN": src("IN", "IN", GGA=30, HDT=30),
    }
    assign_roles(s, {})
    assert s["HE"].roles == ["compass"] and "compass" not in s["IN"].roles


def test_real_skytraq_gnss_compass_is_not_the_compass(real_dir):
    """GN gives GLL/RMC and HDT/THS: a GNSS compass.  Without any other heading source the
    pipeline still takes its heading, and says so."""
    v = read_logs([real_dir / "gpsd/skytraq-PX1172RH_DS.log"], IngestConfig())
    assert "compass" not in v.sources["GN"].roles
    assert any("GN not given the compass role" in d for d in v.time_events.decisions)
    from dracc.core.config import DeadReckoningConfig
    from dracc.pipeline.selection import heading_series as _heading_series

    missing, notes = [], []
    got = _heading_series(v, DeadReckoningConfig(), missing, notes)
    assert got is not None and "heading source GN" in got[2]
    # GN is the GNSS (chosen by evidence over GP): its heading is taken as from a unit that
    # gives fixes too
    assert v.role_sources("gnss") == ["GN"]
    assert any("heading taken from GN, which also gives fixes" in n for n in notes)


def test_instrument_bus_with_fixes_is_still_compass_and_log():
    s = {"II": src("II", "II", HDG=5, VHW=5, RMC=5)}
    assign_roles(s, {})
    assert s["II"].roles == ["compass", "log"]


def test_role_key_matching_nothing_is_an_error_naming_the_keys():
    s = {"GYRO": src("GYRO", "HE", HDT=5), "GNSS": src("GNSS", "GP", GGA=5)}
    with (
        keys_must_match({"GYR0"}),
        pytest.raises(OptionError, match=r"GYR0.*the sources are GNSS, GYRO"),
    ):
        assign_roles(s, {"GYR0": "compass"})
    notes = assign_roles(s, {"GYR0": "compass"})  # from a config file: a note, as before
    assert any("'GYR0' matches no source" in n for n in notes)
    with keys_must_match({"HE"}):  # a talker ID matches
        assign_roles(dict(s), {"HE": "compass"})


def test_cli_role_key_matching_nothing_is_a_bad_option_value(run_cli, tmp_path):
    """Exit 2, as the README's exit codes say of a bad option value (issue 32: it was 4,
    the configuration file's code); records takes --role the same way."""
    p = tmp_path / "g.log"
    gga_log(p, 0, 60, "30.000")
    code, _out, err = run_cli("records", p, "--out", tmp_path / "r.csv", "--role", "GPS1=gnss")
    assert code == ExitCode.USAGE and "no source has the key 'GPS1'" in err
    assert not (tmp_path / "r.csv").exists()
    code, _out, err = run_cli("analyze", p, "--role", "GPS1=gnss")
    assert code == ExitCode.USAGE
    lines = [ln for ln in err.strip().splitlines() if ln.strip()]
    assert (
        lines[-1].startswith("error: --role GPS1=gnss: no source has the key 'GPS1'")
        and "GP" in lines[-1]
    )
    assert sum(ln.startswith("error:") for ln in lines) == 1


def test_real_two_receivers_analysed_as_two_units_by_their_new_keys(real_dir):
    """The split keys are usable: --role seap:GP=ins1 --role gp02:GP=ins2 gives two units."""
    from dracc.cli.analyze_cmd import build_config
    from dracc.pipeline.analysis import analyse
    from dracc.report.json_report import to_dict

    cfg = build_config(None, interval="1min", window="1h", roles=["seap:GP=ins1", "gp02:GP=ins2"])
    with keys_must_match({"seap:GP", "gp02:GP"}):
        d = to_dict(analyse([real_dir / SEAP, real_dir / GP02], cfg))
    assert d["sources"]["ins1"]["keys"] == ["seap:GP"] and d["sources"]["ins2"]["keys"] == [
        "gp02:GP"
    ]
    assert d["source_keys"]["seap:GP"]["roles"] == ["ins1"]
    units = d["deviation"]["units"]
    assert set(units) == {"ins1", "ins2"} and units["ins1"]["lat"]["n"] > 0
    # half of a 20-60 m separation, never the hundreds of metres of one merged "GP"
    assert 1.0 < units["ins1"]["lat"]["m_u"] < 60.0
