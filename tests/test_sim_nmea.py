"""The NMEA writer (checked with pynmea2, an independent parser) and ``dracc simulate``."""

from __future__ import annotations

import json
import re
from functools import reduce

import numpy as np
import pandas as pd
import pytest

pynmea2 = pytest.importorskip("pynmea2")

from dracc.core.errors import DraccError  # noqa: E402
from dracc.core.units import DEG_RAD, KN_MPS, NMI_M  # noqa: E402
from dracc.frames import KINDS, MISSING_NS, make_frame  # noqa: E402
from dracc.sim import SimParams, simulate  # noqa: E402
from dracc.sim.nmea_out import frames_to_lines, write_nmea  # noqa: E402

KMH_MPS = 1000.0 / 3600.0


@pytest.fixture(scope="module")
def voyage():
    # a midnight crossing, both compasses, and a southern/western start to exercise S and W
    return simulate(
        SimParams(
            duration_s=240.0,
            compass="both",
            compass_hz=2.0,
            seed=5,
            start_utc="2025-12-31T23:58:30Z",
            start_lat_deg=-33.9,
            start_lon_deg=-0.01,
            legs=((0.0, 265.0),),
        )
    )


def xor(s: bytes) -> int:
    return reduce(lambda a, b: a ^ b, s, 0)


def test_every_line_has_a_valid_checksum(voyage):
    _, _, lines = frames_to_lines(voyage.frames, voyage.roles)
    assert len(lines) == sum(len(f) for f in voyage.frames.values()) - (
        voyage.frames["ground"]["sentence"] == "RMC"
    ).sum() + len(voyage.zda)
    for ln in lines:
        m = re.fullmatch(rb"\$([A-Z]{5}),([ -~]*)\*([0-9A-F]{2})", ln)
        assert m, ln
        assert int(m.group(3), 16) == xor(ln[1:-3]), ln
        assert len(ln) <= 82  # NMEA 0183 maximum sentence length incl. CR LF is 82
    # a corrupted line no longer matches its checksum (the check above can fail)
    bad = lines[0].replace(b",", b";", 1)
    assert int(bad[-2:], 16) != xor(bad[1:-3])


def test_lines_parse_with_pynmea2_to_the_frame_values(voyage):
    """Every written line, parsed by pynmea2, gives the frame values (line numbers agree)."""
    t_ns, src, lines = frames_to_lines(voyage.frames, voyage.roles)
    by_line = {}
    for kind in KINDS:
        for rec in voyage.frames[kind].to_dict("records"):
            by_line.setdefault(rec["line"], {}).update(rec, kind=kind)
    zda_lines = set(voyage.zda["line"])
    seen = set()
    day = pd.Timestamp(int(t_ns[0])).normalize()
    for i, ln in enumerate(lines, start=1):
        text = ln.decode()
        if text[3:6] == "THS":  # pynmea2 has no THS: fields by hand
            hdg, mode = text[7:-3].split(",")
            r = by_line[i]
            assert float(hdg) * DEG_RAD == pytest.approx(r["heading_rad"], abs=1e-12)
            assert mode == "A"
            continue
        msg = pynmea2.parse(text, check=True)
        typ = msg.sentence_type
        if typ == "ZDA":
            assert i in zda_lines
            assert (msg.year, msg.month, msg.day) == (
                pd.Timestamp(int(t_ns[i - 1])).year,
                pd.Timestamp(int(t_ns[i - 1])).month,
                pd.Timestamp(int(t_ns[i - 1])).day,
            )
            continue
        r = by_line[i]
        seen.add(i)
        assert r["sentence"] == typ and r["talker"] == msg.talker and r["source"] == src[i - 1]
        assert r["time_ns"] == t_ns[i - 1]
        if typ in ("GGA", "RMC"):
            lat = (1 if msg.lat_dir == "N" else -1) * (int(msg.lat[:2]) + float(msg.lat[2:]) / 60)
            lon = (1 if msg.lon_dir == "E" else -1) * (int(msg.lon[:3]) + float(msg.lon[3:]) / 60)
            assert lat * DEG_RAD == pytest.approx(r["lat_rad"], abs=1e-13)
            assert lon * DEG_RAD == pytest.approx(r["lon_rad"], abs=1e-13)
            assert msg.lat_dir == "S" and msg.lon_dir in "EW"
            tod = pd.Timestamp(int(r["time_ns"])) - pd.Timestamp(int(r["time_ns"])).normalize()
            assert (msg.timestamp.hour, msg.timestamp.minute, msg.timestamp.second) == (
                tod.components.hours,
                tod.components.minutes,
                tod.components.seconds,
            )
            if typ == "GGA":
                assert int(msg.gps_qual) == r["quality"]
                assert float(msg.altitude) == r["alt_m"] and msg.altitude_units == "M"
                if r["source"] == "GNSS":
                    assert float(msg.horizontal_dil) == r["hdop"]
                else:
                    assert msg.horizontal_dil == "" and np.isnan(r["hdop"])
            else:
                assert msg.status == "A"
                assert float(msg.spd_over_grnd) * KN_MPS == pytest.approx(r["sog_mps"], abs=1e-12)
                assert float(msg.true_course) * DEG_RAD == pytest.approx(r["cog_rad"], abs=1e-12)
                assert msg.datestamp == (pd.Timestamp(int(r["time_ns"])).date())
        elif typ in ("HDT", "HDG"):
            assert float(msg.heading) * DEG_RAD == pytest.approx(r["heading_rad"], abs=1e-12)
            if typ == "HDG":
                dev = float(msg.deviation) * (1 if msg.dev_dir == "E" else -1)
                var = float(msg.variation) * (1 if msg.var_dir == "E" else -1)
                assert dev * DEG_RAD == pytest.approx(r["deviation_rad"], abs=1e-12)
                assert var * DEG_RAD == pytest.approx(r["variation_rad"], abs=1e-12)
        elif typ == "ROT":
            assert float(msg.rate_of_turn) / 60 * DEG_RAD == pytest.approx(
                r["rot_radps"], abs=1e-14
            )
            assert msg.status == "A"
        elif typ == "VHW":
            assert float(msg.water_speed_knots) * KN_MPS == pytest.approx(r["stw_mps"], abs=1e-12)
            assert float(msg.water_speed_km) * KMH_MPS == pytest.approx(r["stw_mps"], abs=3e-4)
        elif typ == "VBW":
            for f, c in (
                ("lon_water_spd", "stw_mps"),
                ("trans_water_spd", "stw_transverse_mps"),
                ("lon_grnd_spd", "sog_long_mps"),
                ("trans_grnd_spd", "sog_transverse_mps"),
            ):
                assert float(getattr(msg, f)) * KN_MPS == pytest.approx(r[c], abs=1e-12)
        elif typ == "VLW":
            # pynmea2 names the fields oddly: the first is the total, the third the trip
            assert float(msg.trip_distance) * NMI_M == pytest.approx(r["total_water_m"], abs=1e-8)
            assert float(msg.trip_distance_reset) * NMI_M == pytest.approx(
                r["trip_water_m"], abs=1e-8
            )
        elif typ == "VTG":
            assert float(msg.true_track) * DEG_RAD == pytest.approx(r["cog_rad"], abs=1e-12)
            assert float(msg.spd_over_grnd_kts) * KN_MPS == pytest.approx(r["sog_mps"], abs=1e-12)
            assert float(msg.spd_over_grnd_kmph) * KMH_MPS == pytest.approx(r["sog_mps"], abs=3e-4)
        else:
            raise AssertionError(f"unexpected sentence {text}")
    assert seen | zda_lines | {i for i in by_line if by_line[i]["sentence"] == "THS"} == set(
        range(1, len(lines) + 1)
    )
    assert day.year == 2025  # the voyage crosses midnight into 2026
    assert pd.Timestamp(int(t_ns[-1])).year == 2026


def test_signs_and_missing_fields():
    """Negative ROT and transverse speeds carry '-', NaN gives an empty field (never 0)."""
    fr = {
        "rot": make_frame(
            "rot",
            {
                "time_ns": np.array([0, 1], np.int64),
                "source": ["G", "G"],
                "sentence": ["ROT", "ROT"],
                "line": np.array([1, 2]),
                "talker": ["HE", "HE"],
                "rot_radps": np.array([-0.01, np.nan]),
            },
        ),
        "water": make_frame(
            "water",
            {
                "time_ns": np.array([2], np.int64),
                "source": ["L"],
                "sentence": ["VBW"],
                "line": np.array([3]),
                "talker": ["VD"],
                "stw_mps": np.array([5.0]),
                "stw_transverse_mps": np.array([-0.0001]),
            },
        ),
        "heading": make_frame(
            "heading",
            {
                "time_ns": np.array([3], np.int64),
                "source": ["M"],
                "sentence": ["HDG"],
                "line": np.array([4]),
                "talker": ["HC"],
                "heading_rad": np.array([6.2831853]),
                "reference": ["M"],
                "variation_rad": np.array([-3 * DEG_RAD]),
            },
        ),
    }
    _, _, lines = frames_to_lines(fr)
    text = [ln.decode() for ln in lines]
    assert text[0].startswith("$HEROT,-34.38,A*")
    assert text[1].startswith("$HEROT,,V*")
    assert text[2].startswith("$VDVBW,9.719,0.000,A,,,V*")  # -0.0001 kn rounds to 0.000, not -0
    assert text[3].startswith("$HCHDG,0.000,,,3.000,W*")  # 359.99999 deg wraps, never 360
    for t in text:
        pynmea2.parse(t, check=True)


def test_generic_frames_without_talker_or_roles():
    v = simulate(SimParams(duration_s=5.0, compass_hz=1.0))
    fr = {k: f.assign(talker="", sentence="X") for k, f in v.frames.items()}
    _, _src, lines = frames_to_lines(fr, v.roles)
    heads = {ln[:6].decode() for ln in lines}
    # X -> the default sentence of each kind (VHW where only the speed through water is
    # known, VBW where more); the GNSS ground rows become VTG; no RMC, so no ZDA
    assert heads == {
        "$HEHDT",
        "$HEROT",
        "$VWVHW",
        "$VWVBW",
        "$VWVLW",
        "$INGGA",
        "$INHDT",
        "$INVTG",
        "$GPGGA",
        "$GPVTG",
    }
    assert len(lines) == sum(len(f) for f in fr.values())


def test_tag_and_prefix_forms(voyage, tmp_path):
    for tag_time, unit in (("s", 10**9), ("ms", 10**6)):
        p = tmp_path / f"tag_{tag_time}.nmea"
        write_nmea(voyage, p, form="tag", tag_time=tag_time)
        raw = p.read_bytes()
        assert raw.endswith(b"\r\n") and b"\n" not in raw.replace(b"\r\n", b"")
        t_ns, src, bare = frames_to_lines(voyage.frames, voyage.roles)
        rows = raw.split(b"\r\n")[:-1]
        assert len(rows) == len(bare)
        for ln, t, s, b in zip(rows, t_ns, src, bare, strict=True):
            m = re.fullmatch(rb"\\(s:([A-Z0-9]+),c:([0-9]+))\*([0-9A-F]{2})\\(.*)", ln)
            assert m, ln
            assert int(m.group(4), 16) == xor(m.group(1))
            assert m.group(2).decode() == s
            assert int(m.group(3)) == t // unit
            assert m.group(5) == b
    p = tmp_path / "prefix.nmea"
    write_nmea(voyage, p, form="prefix")
    rows = p.read_bytes().split(b"\r\n")[:-1]
    for ln, t, b in zip(rows, t_ns, bare, strict=True):
        stamp, sentence = ln.split(b" ", 1)
        assert pd.Timestamp(stamp.decode()).value == t // 10**6 * 10**6
        assert stamp.endswith(b"Z") and len(stamp) == 24
        assert sentence == b
    p = tmp_path / "bare.nmea"
    write_nmea(voyage.frames, p, form="bare", roles=voyage.roles, newline=b"\n")
    assert p.read_bytes() == b"\n".join(bare) + b"\n"
    with pytest.raises(DraccError, match="form"):
        write_nmea(voyage, tmp_path / "x.nmea", form="json")


def test_chunking_does_not_change_the_output(voyage):
    from dracc.sim.nmea_out import iter_blocks

    one = b"".join(b for _, _, b in iter_blocks(voyage.frames, voyage.roles, form="tag"))
    many = b"".join(
        b for _, _, b in iter_blocks(voyage.frames, voyage.roles, form="tag", chunk_rows=333)
    )
    assert one == many


# ---------------------------------------------------------------- CLI


def _run(*args):
    """``dracc ARGS`` in-process through the real entry point where it imports."""
    try:
        from dracc.cli.main import main
    except ImportError:  # another command's module is missing in this checkout
        from dracc.cli import simulate_cmd  # noqa: F401
        from dracc.cli.app import app

        def main(a):
            try:
                app(args=a, prog_name="dracc", standalone_mode=False)
                return 0
            except DraccError as e:
                return int(e.exit_code)

    return main([str(a) for a in args])


def test_cli_writes_all_files(tmp_path):
    out = tmp_path / "v"
    code = _run(
        "simulate",
        "--hours",
        "0.05",
        "--seed",
        "3",
        "--form",
        "prefix",
        "--compass",
        "both",
        "--compass-hz",
        "2",
        "--out",
        out,
    )
    assert code == 0
    assert {p.name for p in out.iterdir()} == {
        "voyage.nmea",
        "truth.csv",
        "errors.csv",
        "params.json",
    }
    info = json.loads((out / "params.json").read_text())
    assert info["params"]["seed"] == 3 and info["params"]["compass"] == "both"
    assert info["roles"]["INS2"] == "ins2" and set(info["unit_rms"]) == {"ins1", "ins2", "ins3"}
    truth = pd.read_csv(out / "truth.csv")
    errors = pd.read_csv(out / "errors.csv")
    assert len(truth) == len(errors) == 181  # 0.05 h at --truth-hz 1
    assert truth["time_utc"].iloc[0] == "2026-03-01T00:00:00.000000000Z"
    v = simulate(SimParams(duration_s=180.0, seed=3, compass="both", compass_hz=2.0))
    np.testing.assert_allclose(truth["lat_rad"], v.truth["lat_rad"].iloc[::2], rtol=1e-11)
    first = (out / "voyage.nmea").read_text().splitlines()[0]
    assert first.startswith("2026-03-01T00:00:00.000Z $HEHDT,")
    # TAG form: c: in ms when a sensor writes faster than 1 Hz (auto), else in seconds
    for hz, digits in (("2", 13), ("1", 10)):
        d = tmp_path / f"tag{hz}"
        assert _run("simulate", "--hours", "0.01", "--compass-hz", hz, "--out", d) == 0
        c = re.search(rb",c:([0-9]+)\*", (d / "voyage.nmea").read_bytes()).group(1)
        assert len(c) == digits
        assert json.loads((d / "params.json").read_text())["tag_time"] == (
            "ms" if hz == "2" else "s"
        )


def test_cli_rejects_bad_options(tmp_path):
    assert _run("simulate", "--hours", "-1", "--out", tmp_path) != 0
    assert _run("simulate", "--hours", "1", "--format", "xml", "--out", tmp_path) != 0
    assert (
        _run("simulate", "--hours", "1", "--compass-hz", "3", "--log-hz", "2", "--out", tmp_path)
        != 0
    )
    assert not any(tmp_path.iterdir())


def test_dracc_ingest_reads_back_the_frames(tmp_path):
    """The contract: ``frames`` is what a perfect parser of the written log returns.  The
    project's own NMEA ingest reads the TAG form (c: in ms) back to the same frames."""
    ingest = pytest.importorskip("dracc.ingest")
    from dracc.core.config import IngestConfig

    v = simulate(SimParams(duration_s=120.0, compass="both", compass_hz=2.0, seed=3))
    p = tmp_path / "rt.nmea"
    write_nmea(v, p, form="tag", tag_time="ms")
    got = ingest.read_file(p, IngestConfig())
    assert got.rejects.total == 0
    for kind, want in v.frames.items():
        have = got.frames[kind].sort_values("line").reset_index(drop=True)
        want = want.sort_values("line").reset_index(drop=True)
        assert len(have) == len(want), kind
        for c in want.columns:
            if c == "recv_ns":
                # the simulator sets no receive time (MISSING_NS) without a latency fault;
                # a reader may take the TAG c: (here ms) as the receive time of a record
                # that has its own time of fix
                w, h = want[c].to_numpy(), have[c].to_numpy()
                c_ms = want["time_ns"].to_numpy() // 1_000_000 * 1_000_000
                assert ((h == w) | ((w == MISSING_NS) & (h == c_ms))).all(), kind
            elif c in ("source", "talker", "sentence", "reference"):
                assert (have[c].astype(str).to_numpy() == want[c].astype(str).to_numpy()).all()
            else:
                np.testing.assert_allclose(
                    have[c].to_numpy(float),
                    want[c].to_numpy(float),
                    rtol=0,
                    atol=1e-12,
                    err_msg=f"{kind}.{c}",
                )


def test_cli_help_legs_and_noiseless(tmp_path, capsys):
    assert _run("simulate", "--help") == 0
    assert "--ins-error-scale" in capsys.readouterr().out
    assert _run("simulate", "--hours", "1", "--legs", "0:60,x", "--out", tmp_path) == 2  # usage
    out = tmp_path / "n"
    assert (
        _run(
            "simulate",
            "--hours",
            "0.02",
            "--noiseless",
            "--compass-hz",
            "1",
            "--legs",
            "0:10,30:100",
            "--format",
            "nmea",
            "--form",
            "bare",
            "--out",
            out,
        )
        == 0
    )
    info = json.loads((out / "params.json").read_text())
    assert info["params"]["legs"] == [[0.0, 10.0], [30.0, 100.0]]
    assert info["params"]["gyro_offset_deg"] == 0.0 and info["params"]["current_drift_kn"] == 0.0
    errors = pd.read_csv(out / "errors.csv")
    assert errors["ins2_north_m"].abs().max() == 0.0 and errors["gyro_err_rad"].abs().max() == 0
    first = (out / "voyage.nmea").read_bytes().split(b"\r\n")[0]
    assert first == b"$HEHDT,10.000,T*" + b"%02X" % xor(b"HEHDT,10.000,T")


def test_cli_help_lists_every_log_format():
    """The --format help names every format the writer knows, though the CLI spells them
    out itself: importing :mod:`dracc.sim` (scipy) would slow every command's start."""
    import subprocess
    import sys

    import typer.main

    from dracc.cli import simulate_cmd  # noqa: F401
    from dracc.cli.app import app
    from dracc.sim.output import FORMATS

    command = typer.main.get_command(app).commands["simulate"]
    fmt = next(p for p in command.params if p.name == "fmt")
    assert fmt.help == "Log format: " + ", ".join(FORMATS) + "."
    code = "import sys, dracc.cli.simulate_cmd; assert 'dracc.sim' not in sys.modules"
    assert subprocess.run([sys.executable, "-c", code], timeout=120).returncode == 0


def test_cli_segments_write_one_continuous_log(tmp_path):
    one, seg = tmp_path / "one", tmp_path / "seg"
    args = ("simulate", "--hours", "0.1", "--compass-hz", "1", "--form", "prefix", "--seed", "4")
    assert _run(*args, "--out", one) == 0
    assert _run(*args, "--segment-hours", "0.03", "--out", seg) == 0
    a = (one / "voyage.nmea").read_bytes().split(b"\r\n")
    b = (seg / "voyage.nmea").read_bytes().split(b"\r\n")
    assert len(a) == len(b)
    stamps = [ln.split(b" ")[0] for ln in b[:-1]]
    assert stamps == sorted(stamps) and stamps == [ln.split(b" ")[0] for ln in a[:-1]]
    truth = pd.read_csv(seg / "truth.csv")
    assert len(truth) == 361 and truth["time_ns"].is_unique
    info = json.loads((seg / "params.json").read_text())
    assert info["records"] == json.loads((one / "params.json").read_text())["records"]
    for unit in ("ins1", "ins2", "ins3"):
        assert info["unit_rms"][unit]["lat_m"] > 0
    for ln in b[:-1]:
        body = ln.split(b" ", 1)[1]
        assert int(body[-2:], 16) == xor(body[1:-3])
