"""Sensor faults (dracc.math.faults): each fault kind injected into a simulated voyage with known
truth is found with its times and raw values; clean simulated and real logs give none; the
[faults] config; the pipeline reports faults and leaves them out only when told to."""

from __future__ import annotations

import math
from dataclasses import replace

import jsonschema
import numpy as np
import pandas as pd
import pytest
from conftest import real_path

from dracc.core.config import Config, FaultsConfig, IngestConfig, config_from_dict, load_config
from dracc.core.errors import ConfigError
from dracc.core.geodesy import add_offset_ne
from dracc.core.units import DEG_RAD, KN_MPS, NMI_M, NS_PER_S
from dracc.frames import Voyage
from dracc.ingest import read_logs
from dracc.math.faults import FAULT_KINDS, SensorFault, detect_faults, exclude_faults
from dracc.pipeline.analysis import analyse_voyage
from dracc.report import html as html_report
from dracc.report import json_report, terminal
from dracc.sim import SimParams, simulate

H = 3600 * NS_PER_S


@pytest.fixture(scope="module")
def sim():
    """3 h at 1 Hz: gyro, log, three INS, GNSS; a 90 deg turn at 1.5 h."""
    return simulate(
        SimParams(
            duration_s=3 * 3600,
            seed=3,
            compass_hz=1,
            log_hz=1,
            ins_hz=1,
            gnss_hz=1,
            aux_hz=0,
            legs=((0, 60), (5400, 150)),
        )
    )


def _frames(sim) -> dict[str, pd.DataFrame]:
    return {k: v.copy() for k, v in sim.frames.items()}


def _rows(df: pd.DataFrame, source: str, a_ns: int, b_ns: int) -> np.ndarray:
    t = df["time_ns"].to_numpy(np.int64)
    return np.flatnonzero(
        (df["source"].astype(str).to_numpy() == source) & (t >= a_ns) & (t <= b_ns)
    )


def _t0(sim) -> int:
    return int(sim.frames["position"]["time_ns"].iloc[0])


def _freeze_ins3_two_hours(sim, pos: pd.DataFrame) -> tuple[int, int, np.ndarray]:
    """INS3 repeats its position from 30 min to 2 h 30 min (in place): (start_ns, end_ns, rows)."""
    a, b = _t0(sim) + H // 2, _t0(sim) + H // 2 + 2 * H
    i = _rows(pos, "INS3", a, b)
    pos.loc[i, "lat_rad"] = pos.loc[i[0], "lat_rad"]
    pos.loc[i, "lon_rad"] = pos.loc[i[0], "lon_rad"]
    return a, b, i


def test_clean_simulated_voyage_has_no_fault(sim):
    assert detect_faults(sim.frames) == []


@pytest.mark.parametrize(
    "name",
    [
        "VDRplayer/Hakefjord.txt",
        "gpsd/bundg_zeus_9.log",
        "anemomind/Irene/2014/20140611/NMEA0048.TXT",
        "signalk-server/gofree-merrimac.log",
        "signalk-server/plaka.log",
        "openrvdas/NBP1406_gyr1-2014-08-01",
    ],
)
def test_real_logs_have_no_fault(name):
    path = real_path(name)
    v = read_logs([path], IngestConfig(date="2014-08-01"))
    assert detect_faults(v) == []


def test_fifty_mile_jump_in_one_second_one_record(sim):
    """One INS2 fix displaced 50 nmi north for one second, then back: one jump fault
    covering exactly that record, jump size 50 nmi (set), implied speed 50 nmi / 1 s."""
    f = _frames(sim)
    pos = f["position"]
    t_jump = _t0(sim) + H + 17 * NS_PER_S
    i = _rows(pos, "INS2", t_jump, t_jump)
    assert i.size == 1
    lat, lon = pos.loc[i, "lat_rad"].to_numpy(), pos.loc[i, "lon_rad"].to_numpy()
    nlat, nlon = add_offset_ne(lat, lon, 50 * NMI_M, 0.0)
    pos.loc[i, "lat_rad"] = nlat
    pos.loc[i, "lon_rad"] = nlon
    faults = detect_faults(f)
    assert len(faults) == 1
    fl = faults[0]
    assert (fl.kind, fl.source, fl.frame) == ("jump", "INS2", "position")
    assert fl.start_ns == fl.end_ns == t_jump
    assert fl.n_records == 1
    v = dict(fl.values)
    # the step from the previous fix (1 s earlier, ~6 m away at 12 kn) plus the 50 nmi offset
    assert v["jump_nmi"] == pytest.approx(50.0, abs=0.01)
    assert v["dt_s"] == pytest.approx(1.0)
    assert v["implied_speed_kn"] == pytest.approx(50 * 3600, rel=1e-3)
    assert "back at" in fl.message and "2026-03-01 01:00:17" in fl.message
    assert fl.first_line == int(pos.loc[i[0], "line"])


def test_jump_that_never_comes_back_covers_the_rest(sim):
    f = _frames(sim)
    pos = f["position"]
    t_jump = _t0(sim) + 2 * H
    i = _rows(pos, "INS1", t_jump, 2**62)
    nlat, nlon = add_offset_ne(
        pos.loc[i, "lat_rad"].to_numpy(), pos.loc[i, "lon_rad"].to_numpy(), 0.0, 50 * NMI_M
    )
    pos.loc[i, "lat_rad"] = nlat
    pos.loc[i, "lon_rad"] = nlon
    (fl,) = detect_faults(f)
    assert (fl.kind, fl.source, fl.start_ns) == ("jump", "INS1", t_jump)
    assert fl.end_ns == int(pos.loc[i[-1], "time_ns"])
    assert fl.n_records == i.size
    assert "did not come back" in fl.message


def test_frozen_unit_for_two_hours(sim):
    """INS3 repeats one position for 2 h while the ship makes 12 kn."""
    f = _frames(sim)
    pos = f["position"]
    a, b, i = _freeze_ins3_two_hours(sim, pos)
    (fl,) = detect_faults(f)
    assert (fl.kind, fl.source, fl.start_ns, fl.end_ns) == ("frozen", "INS3", a, b)
    assert fl.n_records == i.size == 7201
    v = dict(fl.values)
    assert v["duration_s"] == 7200.0
    assert v["other_speed_kn"] == pytest.approx(12.0, abs=0.7)
    assert v["lat_deg"] == pytest.approx(float(pos.loc[i[0], "lat_rad"]) / DEG_RAD, abs=1e-12)
    assert "00:30:00 to 2026-03-01 02:30:00" in fl.message


def test_frozen_position_of_a_ship_lying_still_is_not_a_fault(sim):
    """The same repeated position while every speed source shows 0 kn proves nothing."""
    f = _frames(sim)
    pos = f["position"]
    i = _rows(pos, "INS3", _t0(sim) + H // 2, 2**62)  # to the end: no step out of the run
    pos.loc[i, "lat_rad"] = pos.loc[i[0], "lat_rad"]
    pos.loc[i, "lon_rad"] = pos.loc[i[0], "lon_rad"]
    f["ground"]["sog_mps"] = 0.0
    f["water"]["stw_mps"] = 0.0
    assert detect_faults(f) == []


def test_short_repeat_is_not_frozen(sim):
    f = _frames(sim)
    pos = f["position"]
    i = _rows(pos, "INS3", _t0(sim) + 3 * H - 1700 * NS_PER_S, 2**62)  # under frozen_min_s = 1800 s
    pos.loc[i, "lat_rad"] = pos.loc[i[0], "lat_rad"]
    pos.loc[i, "lon_rad"] = pos.loc[i[0], "lon_rad"]
    assert detect_faults(f) == []
    assert [x.kind for x in detect_faults(f, FaultsConfig(frozen_min_s=1000))] == ["frozen"]


def test_compass_stuck_at_zero_through_a_turn(sim):
    """The gyro reads 0 deg from 1 h to 2 h while the ship turns 90 deg at 1.5 h."""
    f = _frames(sim)
    hd = f["heading"]
    a, b = _t0(sim) + H, _t0(sim) + 2 * H
    i = _rows(hd, "GYRO", a, b)
    hd.loc[i, "heading_rad"] = 0.0
    (fl,) = detect_faults(f)
    assert (fl.kind, fl.source, fl.frame, fl.start_ns, fl.end_ns) == (
        "stuck_heading",
        "GYRO",
        "heading",
        a,
        b,
    )
    v = dict(fl.values)
    assert v["heading_deg"] == 0.0
    assert (
        90.0 <= v["other_turn_deg"] < 100.0
    )  # the INS headings saw the 90 deg turn (+ yaw, noise)
    assert "stuck at 0.00 deg" in fl.message


def test_steady_heading_at_anchor_is_not_stuck(sim):
    f = _frames(sim)
    hd = f["heading"]
    a, b = _t0(sim) + 10 * 60 * NS_PER_S, _t0(sim) + 50 * 60 * NS_PER_S  # steady leg, no turn
    hd.loc[_rows(hd, "GYRO", a, b), "heading_rad"] = 1.0
    for src in ("INS1", "INS2", "INS3"):
        r = _rows(hd, src, a, b)
        hd.loc[r, "heading_rad"] = 1.0 + 0.001 * (np.arange(r.size) % 3)  # jitter, no turn
    f["ground"]["sog_mps"] = 0.0
    f["water"]["stw_mps"] = 0.0
    assert detect_faults(f) == []


def test_out_of_range_values_from_a_reader(sim):
    """Values a CSV/MCAP reader could pass on: SOG -3 kn, latitude 95 deg, ROT 99999 deg/min."""
    f = _frames(sim)
    t = _t0(sim) + H
    g = _rows(f["ground"], "GNSS", t, t + 2 * NS_PER_S)
    f["ground"].loc[g, "sog_mps"] = -3 * KN_MPS
    p = _rows(f["position"], "INS1", t, t)
    f["position"].loc[p, "lat_rad"] = 95 * DEG_RAD
    f["rot"] = pd.concat(
        [
            f["rot"],
            pd.DataFrame(
                {
                    "time_ns": [t],
                    "source": ["GYRO"],
                    "talker": ["HE"],
                    "sentence": ["ROT"],
                    "line": [7],
                    "rot_radps": [99999 * DEG_RAD / 60],
                }
            ),
        ],
        ignore_index=True,
    )
    faults = detect_faults(f)
    got = {(x.source, x.frame, x.values[0][0]): x for x in faults}
    assert {x.kind for x in faults} == {"out_of_range"}
    sog = got[("GNSS", "ground", "min_sog_kn")]
    assert sog.n_records == g.size and dict(sog.values)["min_sog_kn"] == pytest.approx(-3.0)
    lat = got[("INS1", "position", "min_lat_deg")]
    assert lat.start_ns == t and dict(lat.values)["max_lat_deg"] == pytest.approx(95.0)
    rot = got[("GYRO", "rot", "min_rot_deg_per_min")]
    assert dict(rot.values)["max_rot_deg_per_min"] == pytest.approx(99999.0)
    assert rot.first_line == 7
    # the 95 deg latitude is out of range, not also a 300 nmi jump: it is one record of INS1
    assert all(x.kind == "out_of_range" for x in faults if x.source == "INS1")


def test_negative_sog_through_the_nmea_reader(tmp_path):
    """The NMEA reader keeps '-3.0' knots of an RMC (a number); the faults flag it."""

    def cs(body: str) -> str:
        x = 0
        for c in body.encode():
            x ^= c
        return f"${body}*{x:02X}"

    lines = [
        cs(f"GPRMC,1200{s:02d},A,5000.000,N,01000.000,E,{-3.0 if s == 5 else 0.1},90.0,010120,,")
        for s in range(10)
    ]
    p = tmp_path / "neg.nmea"
    p.write_text("\r\n".join(lines) + "\r\n")
    v = read_logs([p], IngestConfig())
    (fl,) = detect_faults(v)
    assert (fl.kind, fl.frame, fl.role, fl.first_line) == ("out_of_range", "ground", "gnss", 6)
    assert fl.start_ns == pd.Timestamp("2020-01-01T12:00:05Z").value


def test_exclude_removes_exactly_the_flagged_records(sim):
    f = _frames(sim)
    pos = f["position"]
    a, b, i = _freeze_ins3_two_hours(sim, pos)
    voy = Voyage(frames=f, sources={}, rejects=None, time_events=None, inputs=[])  # type: ignore[arg-type]
    faults = detect_faults(voy)
    out, removed = exclude_faults(voy, faults)
    assert removed == {"position": i.size}
    assert len(out.frames["position"]) == len(pos) - i.size
    assert len(voy.frames["position"]) == len(pos)  # the input is left alone
    kept = out.frames["position"]
    assert not ((kept["source"].astype(str) == "INS3") & kept["time_ns"].between(a, b)).any()


def test_config_section_and_validation(tmp_path):
    p = tmp_path / "c.toml"
    p.write_text("[faults]\nexclude = true\nmax_speed_kn = 45.0\nfrozen_min_s = 3600\n")
    cfg = load_config(p)
    assert cfg.faults == FaultsConfig(exclude=True, max_speed_kn=45.0, frozen_min_s=3600)
    assert Config().faults.exclude is False
    with pytest.raises(ConfigError, match="unknown key"):
        config_from_dict({"faults": {"max_speed": 4}})
    for bad in (
        {"max_speed_kn": -1.0},
        {"jump_min_m": "big"},
        {"stuck_min_s": math.nan},
        {"exclude": "yes"},
    ):
        with pytest.raises(ConfigError, match=r"\[faults\]"):
            detect_faults({}, replace(FaultsConfig(), **bad))


def test_fault_kinds_and_dict_form(sim):
    f = _frames(sim)
    hd = f["heading"]
    hd.loc[_rows(hd, "GYRO", _t0(sim) + H, _t0(sim) + 2 * H), "heading_rad"] = 0.0
    (fl,) = detect_faults(f)
    assert fl.kind in FAULT_KINDS and isinstance(fl, SensorFault)
    d = fl.to_dict()
    assert d["start"] == "2026-03-01T01:00:00.000000Z" and d["duration_s"] == 3600.0
    assert d["values"]["heading_deg"] == 0.0


@pytest.fixture(scope="module")
def faulty_voyage(tmp_path_factory):
    """The simulated voyage with INS2 frozen for 2 h, written as NMEA and read back."""
    from dracc.sim.nmea_out import write_nmea

    s = simulate(
        SimParams(
            duration_s=4 * 3600, seed=5, compass_hz=1, log_hz=1, ins_hz=1, gnss_hz=1, aux_hz=0
        )
    )
    f = {k: v.copy() for k, v in s.frames.items()}
    pos = f["position"]
    t0 = int(pos["time_ns"].iloc[0])
    i = _rows(pos, "INS2", t0 + H, t0 + 3 * H)
    pos.loc[i, "lat_rad"] = pos.loc[i[0], "lat_rad"]
    pos.loc[i, "lon_rad"] = pos.loc[i[0], "lon_rad"]
    path = tmp_path_factory.mktemp("faulty") / "frozen <b>ins2</b>.nmea"
    write_nmea(f, path, roles=s.roles)
    return read_logs([path], IngestConfig())


def test_pipeline_reports_faults_and_excludes_only_when_told(faulty_voyage):
    kept = analyse_voyage(faulty_voyage, Config())
    dropped = analyse_voyage(faulty_voyage, replace(Config(), faults=FaultsConfig(exclude=True)))
    for a in (kept, dropped):
        assert [(x.kind, x.source) for x in a.faults] == [("frozen", "INS2")]
        d = json_report.to_dict(a)
        jsonschema.validate(d, json_report.load_schema())
        assert d["faults"][0]["kind"] == "frozen" and d["faults"][0]["role"] == "ins2"
        assert "Sensor faults (1)" in terminal.render_text(a)
        page = html_report.render_html(a)
        assert '<section id="faults">' in page and "frozen" in page
    assert any("still in the statistics" in n for n in kept.notes)
    assert any("left out of the statistics" in n for n in dropped.notes)
    # the frozen 2 h make INS2's deviations large; left out, INS2's RMS shrinks
    rms_kept = kept.deviation.to_dict()
    rms_dropped = dropped.deviation.to_dict()
    assert rms_kept != rms_dropped
    # the plotted tracks keep the raw records either way
    ins2 = next(t for t in dropped.tracks if t.source == "INS2")
    assert np.unique(ins2.lat_rad).size < 0.6 * ins2.lat_rad.size  # half of it frozen


def test_jump_and_return_of_a_moving_ship_is_one_fault():
    """A GNSS displaced by 670 m for 10 min while the ship makes 12 kn: one jump fault that
    comes back (the ship moved 3.7 km meanwhile, so the fixes before and after the fault
    are far apart; the two steps still cancel)."""
    from dracc.frames import KINDS, Rejects, SourceInfo, TimeEvents, Voyage, empty_frame
    from dracc.sim import SimParams, simulate
    from dracc.sim.faults import parse_fault

    sv = simulate(
        SimParams(
            duration_s=3600.0,
            seed=2,
            compass_hz=1.0,
            aux_hz=0.0,
            speed_kn=12.0,
            faults=(parse_fault("jump:GNSS@20min+10min=670m"),),
        )
    )
    frames = {k: sv.frames.get(k, empty_frame(k)) for k in KINDS}
    voyage = Voyage(
        frames,
        {k: SourceInfo(k, roles=[r]) for k, r in sv.roles.items()},
        Rejects(),
        TimeEvents(),
        [],
    )
    jumps = [f for f in detect_faults(voyage) if f.kind == "jump"]
    assert len(jumps) == 1 and jumps[0].source == "GNSS"
    assert "back at" in jumps[0].message
    assert abs(jumps[0].duration_s - 600.0) < 5.0
