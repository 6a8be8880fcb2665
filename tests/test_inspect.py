"""``dracc inspect``: help, JSON keys, table, options, exit codes; every sentence type
read (time-only ZDA included, per source) and the account of every line, against counts
made here by hand (a checksum check of each sentence written for the test) and gpsd's
``.chk`` expectations on real logs."""

from __future__ import annotations

import json
import re
from collections import Counter
from pathlib import Path

import pytest

from dracc.core.errors import ExitCode
from dracc.ingest.timebase import ASSUMED_DATE

#: the sentence types dracc reads (docs/ingest.md); every other valid one is ignored
READ_TYPES = {
    "HDT", "HDM", "HDG", "THS", "ROT", "VHW", "VBW", "VLW",
    "GGA", "GLL", "RMC", "GNS", "VTG", "ZDA",
}  # fmt: skip
_START = re.compile(r"[$!](?=[^$!])")
_WHOLE = re.compile(r"[$!]([A-Z0-9]{2})([A-Z]{3}),[^*]*\*([0-9A-F]{2})\s*")


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
    rep = json.loads(out)  # no date anywhere: placed on the assumed date, and said so
    assert code == 0 and rep["rejected"] == {}
    assert rep["sources"]["GP"]["first_utc"] == f"{ASSUMED_DATE}T23:56:00Z"
    assert any(ASSUMED_DATE in d for d in rep["time"]["decisions"])
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


def _hand_count(path: Path) -> tuple[int, Counter[str], Counter[str], int, int]:
    """(lines, whole sentences with a right checksum by type, the others by reason
    'truncated' / 'checksum', sentences after the first on their line, comment lines),
    counted line by line with a checksum check written here."""
    text = path.read_bytes().decode("ascii", "replace")
    lines = re.split(r"\r\n|\r\r\n|\n|\r", text)
    if lines and lines[-1] == "":
        lines.pop()
    good: Counter[str] = Counter()
    bad: Counter[str] = Counter()
    shared = comments = 0
    for ln in lines:
        if ln.startswith("#"):
            comments += 1
            continue
        starts = [m.start() for m in _START.finditer(ln)]
        shared += max(len(starts) - 1, 0)
        for a, b in zip(starts, [*starts[1:], len(ln)], strict=True):
            seg = ln[a:b]
            m = _WHOLE.fullmatch(seg)
            if not m:
                bad["truncated"] += 1
                continue
            x = 0
            for ch in seg[1 : seg.index("*")].encode():
                x ^= ch
            if x != int(m.group(3), 16):
                bad["checksum"] += 1
                continue
            good[m.group(2)] += 1
    return len(lines), good, bad, shared, comments


def _adds_up(acc: dict[str, int]) -> bool:
    return acc["lines"] == (
        acc["sentences"]
        + acc["time_only"]
        + acc["qualifiers"]
        + acc["n2k"]
        + acc["ignored"]
        + acc["rejected"]
        - acc["shared"]
    )


def _inspect(run_cli, path: Path) -> dict:
    code, out, err = run_cli("inspect", path, "--json", "-")
    assert code == 0, err
    return json.loads(out)


def test_every_sentence_type_counted_as_gpsd_expects(run_cli, real_dir):
    """B&G Zeus log: gpsd's .chk echoes every sentence it took; dracc lists each type it
    read with the same count (ZDA included, in the GPS source), the others as ignored, and
    the lines add up with nothing rejected."""
    log = real_dir / "gpsd" / "bundg_zeus_9.log"
    chk: Counter[str] = Counter()
    talker: Counter[str] = Counter()
    for line in (
        (real_dir / "gpsd" / "bundg_zeus_9.log.chk").read_text(errors="replace").splitlines()
    ):
        m = re.match(r"[$!]([A-Z0-9]{2})([A-Z]{3}),", line)
        if m:
            chk[m.group(2)] += 1
            talker[m.group(1) + m.group(2)] += 1
    rep = _inspect(run_cli, log)
    assert rep["sentences"] == {t: n for t, n in sorted(chk.items()) if t in READ_TYPES}
    comments = sum(1 for ln in log.read_text(errors="replace").splitlines() if ln.startswith("#"))
    assert rep["ignored"] == dict(
        sorted(
            {**{t: n for t, n in chk.items() if t not in READ_TYPES}, "comment": comments}.items()
        )
    )
    assert rep["sentences"]["ZDA"] == 154 == talker["GPZDA"]
    assert rep["sources"]["GP"]["sentences"]["ZDA"] == talker["GPZDA"]
    acc = rep["inputs"][0]["accounting"]
    n_lines = len(log.read_bytes().splitlines())
    assert acc == rep["accounting"]
    assert acc["lines"] == n_lines and acc["time_only"] == 154 and acc["rejected"] == 0
    assert acc["shared"] == 0 and _adds_up(acc)
    assert rep["inputs"][0]["time_only"] == {"ZDA": 154}


def test_every_line_accounted_for_with_shared_lines(run_cli, real_dir):
    """GoFree log at the dock: 994 VLW sentences cut short and followed by another on the
    same line, 142 wrong checksums.  Every whole sentence is listed by type (ZDA included),
    read or ignored; the cut ones and wrong checksums are rejected; the lines add up."""
    log = real_dir / "signalk-server" / "gofree-merrimac.log"
    n_lines, good, bad, shared, comments = _hand_count(log)
    assert (good["ZDA"], shared, comments) == (142, 994, 0)  # what the hand count found
    rep = _inspect(run_cli, log)
    assert rep["sentences"] == {t: n for t, n in sorted(good.items()) if t in READ_TYPES}
    assert rep["ignored"] == {t: n for t, n in sorted(good.items()) if t not in READ_TYPES}
    assert rep["rejected"] == dict(sorted(bad.items()))
    acc = rep["accounting"]
    assert acc == {
        "lines": n_lines,
        "sentences": sum(good[t] for t in READ_TYPES) - good["ZDA"],
        "time_only": good["ZDA"],
        "qualifiers": 0,
        "n2k": 0,
        "ignored": sum(good[t] for t in good if t not in READ_TYPES),
        "rejected": sum(bad.values()),
        "shared": shared,
    }
    assert _adds_up(acc)
    gp = rep["sources"]["GP"]
    assert gp["sentences"]["ZDA"] == 142 and gp["records"] == 142 * 5  # GGA GLL RMC(2) VTG


def test_time_only_sentences_per_tag_source(run_cli, tmp_path):
    """ZDA is listed in the source that sent it (TAG s:), also one that sends nothing
    else; it gives no record; RMC is one sentence though it gives two records."""
    lines = []
    for k in range(30):
        t = 1_700_000_000 + k
        hh, mm, ss = (t // 3600) % 24, (t // 60) % 60, t % 60
        hms = f"{hh:02d}{mm:02d}{ss:02d}.00"
        lines.append(
            tag(f"s:GNSS,c:{t}", nmea(f"GPRMC,{hms},A,5436.0,N,01847.0,E,12.0,60.0,141123,,,A"))
        )
        lines.append(tag(f"s:GNSS,c:{t}", nmea(f"GPZDA,{hms},14,11,2023,00,00")))
        lines.append(tag(f"s:CLOCK,c:{t}", nmea(f"ZCZDA,{hms},14,11,2023,00,00")))
    lines += ["", nmea("GPGSV,1,1,00")]
    p = tmp_path / "zda.nmea"
    p.write_text("\n".join(lines) + "\n")
    rep = _inspect(run_cli, p)
    s = rep["sources"]
    assert s["GNSS"]["sentences"] == {"RMC": 30, "ZDA": 30} and s["GNSS"]["records"] == 60
    assert s["GNSS"]["talkers"] == {"GP": 60}
    assert s["CLOCK"]["sentences"] == {"ZDA": 30} and s["CLOCK"]["records"] == 0
    assert s["CLOCK"]["role"] is None and s["CLOCK"]["first_utc"] is None
    assert rep["sentences"] == {"RMC": 30, "ZDA": 60}
    assert rep["ignored"] == {"GSV": 1, "blank": 1}
    assert rep["accounting"] == {
        "lines": 92,
        "sentences": 30,
        "time_only": 60,
        "qualifiers": 0,
        "n2k": 0,
        "ignored": 2,
        "rejected": 0,
        "shared": 0,
    }
    code, out, _ = run_cli("inspect", p)
    assert code == 0 and "92 lines = 30 sentences with records + 60 time-only (ZDA)" in out
    assert "sentences read: RMC:30 ZDA:60" in out and "ignored (valid, not used): GSV:1" in out


@pytest.mark.parametrize("name", ["voyage_tag.nmea", "voyage_long.csv"])
def test_sample_logs(run_cli, name):
    """The 3 h sample: its ZDA sentences counted as a grep counts them; a CSV log (rows are
    not records one to one) has no line account."""
    p = Path(__file__).resolve().parents[1] / "sample_logs" / name
    rep = _inspect(run_cli, p)
    if name.endswith(".csv"):
        assert rep["inputs"][0]["accounting"] is None and rep["accounting"] is None
        assert rep["sources"]
        return
    zda = sum(1 for ln in p.read_text().splitlines() if re.search(r"\$..ZDA,", ln))
    assert zda > 0 and rep["sentences"]["ZDA"] == zda == rep["accounting"]["time_only"]
    assert _adds_up(rep["accounting"]) and rep["accounting"]["shared"] == 0


def test_compressed_log_is_streamed_and_counted_alike(run_cli, real_dir, tmp_path):
    """A gzip copy of the GoFree log: the same sentences (ZDA included), ignored types,
    rejects and line account as the plain file; its examples name the .gz."""
    import gzip

    log = real_dir / "signalk-server" / "gofree-merrimac.log"
    gz = tmp_path / "gofree.log.gz"
    gz.write_bytes(gzip.compress(log.read_bytes()))
    plain, packed = _inspect(run_cli, log), _inspect(run_cli, gz)
    for k in ("sentences", "ignored", "rejected", "accounting"):
        assert packed[k] == plain[k], k
    assert packed["inputs"][0]["time_only"] == {"ZDA": 142}
    assert {e["file"] for ex in packed["rejected_examples"].values() for e in ex} == {str(gz)}
    assert packed["sources"]["GP"]["files"] == [str(gz)]


def test_qualifying_sentences_are_accounted_for(run_cli, real_dir):
    """Seapath log (timestamp-prefixed): ``$PSXN,20`` only qualifies the attitude that
    follows it; counted as a qualifier, not lost, so the 5000 lines add up."""
    log = real_dir / "openrvdas" / "NBP1406_seap-2014-08-01"
    text = log.read_text(errors="replace").splitlines()
    n20 = sum("$PSXN,20," in ln for ln in text)
    zda = sum("$GPZDA," in ln for ln in text)
    rep = _inspect(run_cli, log)
    acc = rep["accounting"]
    assert (acc["lines"], acc["qualifiers"], acc["time_only"]) == (len(text), n20, zda)
    assert n20 > 0 and acc["shared"] == 0 and _adds_up(acc)
    assert rep["inputs"][0]["qualifiers"] == {"PSXN": n20}
