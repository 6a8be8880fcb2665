"""``dracc inspect``: help, JSON keys, table, options, exit codes."""

from __future__ import annotations

import json

from dracc.core.errors import ExitCode


def nmea(body: str) -> str:
    x = 0
    for b in body.encode():
        x ^= b
    return f"${body}*{x:02X}"


def tag(params: str, sentence: str) -> str:
    x = 0
    for b in params.encode():
        x ^= b
    return f"\\{params}*{x:02X}\\{sentence}"


def _log(tmp_path):
    lines = []
    for k in range(120):
        t = 1_700_000_000 + k
        hh, mm, ss = (t // 3600) % 24, (t // 60) % 60, t % 60
        for u in (1, 2, 3):
            lines.append(
                tag(
                    f"s:INS{u},c:{t}",
                    nmea(
                        f"INGGA,{hh:02d}{mm:02d}{ss:02d}.00,5436.0{u},N,01847.0,E,1,,,25.0,M,,M,,"
                    ),
                )
            )
        lines.append(tag(f"s:GYRO,c:{t}", nmea("HEHDT,60.5,T")))
        lines.append(
            tag(
                f"s:GNSS,c:{t}",
                nmea(
                    f"GPRMC,{hh:02d}{mm:02d}{ss:02d}.00,A,5436.0,N,01847.0,E,12.0,60.0,141123,,,A"
                ),
            )
        )
    lines.append(nmea("HEHDT,60.5,T")[:-1] + "0")  # one bad checksum
    p = tmp_path / "v.nmea"
    p.write_text("\n".join(lines) + "\n")
    return p


def test_help(run_cli):
    code, out, _ = run_cli("inspect", "--help")
    assert (
        code == 0
        and "--json" in out
        and "--strict" in out
        and "--ignore-checksum" in out
        and "--date" in out
    )


def test_json_report(run_cli, tmp_path):
    code, out, err = run_cli("inspect", _log(tmp_path), "--json", "-")
    assert code == 0, err
    rep = json.loads(out)
    assert rep["lines"] == 601
    assert rep["rejected"] == {"checksum": 1}
    assert rep["rejected_examples"]["checksum"][0]["line"] == 601
    s = rep["sources"]
    assert {k: v["role"] for k, v in s.items()} == {
        "INS1": "ins1",
        "INS2": "ins2",
        "INS3": "ins3",
        "GYRO": "compass",
        "GNSS": "gnss",
    }
    assert s["INS2"]["records"] == 120 and s["INS2"]["sentences"] == {"GGA": 120}
    assert s["GNSS"]["records"] == 240 and s["GNSS"]["sentences"] == {
        "RMC": 120
    }  # position + ground rows
    assert (
        s["GYRO"]["first_utc"] == "2023-11-14T22:13:20Z"
        and s["GYRO"]["last_utc"] == "2023-11-14T22:15:19Z"
    )
    assert abs(s["INS1"]["rate_hz"] - 1.0) < 1e-9 and s["INS1"]["gaps"] == 0
    assert {
        "duplicates",
        "backsteps",
        "gaps",
        "rollovers",
        "implausible_dates",
        "decisions",
    } <= set(rep["time"])


def test_json_to_a_file_beside_the_tables(run_cli, tmp_path):
    """``--json PATH`` as in every command: the JSON to PATH, the tables still on stdout."""
    code, out, err = run_cli("inspect", _log(tmp_path), "--json", tmp_path / "i.json")
    assert code == 0, err
    assert "time base" in out and f"wrote {tmp_path / 'i.json'}" in err
    code, same, _ = run_cli("inspect", _log(tmp_path), "--json", "-")
    assert json.loads((tmp_path / "i.json").read_text(encoding="utf-8")) == json.loads(same)


def test_table_output(run_cli, tmp_path):
    code, out, _ = run_cli("inspect", _log(tmp_path))
    assert (
        code == 0 and "INS2" in out and "ins2" in out and "checksum" in out and "time base" in out
    )


def test_strict_and_missing_and_bad_date(run_cli, tmp_path):
    code, _, err = run_cli("inspect", _log(tmp_path), "--strict")
    assert code == ExitCode.INPUT and "v.nmea:601: rejected (checksum" in err
    code, _, err = run_cli("inspect", tmp_path / "nope.nmea")
    assert code == ExitCode.INPUT and "no such file" in err
    code, _, err = run_cli("inspect", _log(tmp_path), "--date", "2023-02-30")
    assert code == ExitCode.USAGE and "YYYY-MM-DD" in err  # a bad option value


def test_date_option_places_a_dateless_log(run_cli, tmp_path, real_dir):
    code, out, _ = run_cli("inspect", real_dir / "gpsbabel" / "adddate.nmea", "--json", "-")
    rep = json.loads(out)
    assert code == 0 and rep["sources"] == {} and rep["rejected"] == {"no_date": 500}
    code, out, _ = run_cli(
        "inspect", real_dir / "gpsbabel" / "adddate.nmea", "--json", "-", "--date", "2019-03-09"
    )
    rep = json.loads(out)
    assert rep["sources"]["GP"]["first_utc"] == "2019-03-09T23:56:00Z"
    assert (
        rep["sources"]["GP"]["last_utc"] == "2019-03-10T00:04:19Z" and rep["time"]["rollovers"] == 1
    )


def test_ignore_checksum(run_cli, real_dir):
    f = real_dir / "anemomind/Irene/2013/Flensburg2013/entrainement_31.7/NMEA0023.TXT"
    code, out, _ = run_cli("inspect", f, "--json", "-", "--ignore-checksum")
    rep = json.loads(out)
    assert code == 0 and rep["sources"]["II"]["role"] == "compass+log"
    assert any("wrong checksums accepted" in n for n in rep["notes"])
