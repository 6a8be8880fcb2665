"""Issue 33, mixed line forms: every line goes to the reader of its form, whatever the
first 64 KB say.

1. A text log starting with ``$PCDIN`` lines (NMEA 2000 in NMEA 0183) then plain NMEA
   0183 sentences kept only the NMEA 2000 records (142 of 1,138): all are kept.
2. candump lines mixed with Yacht Devices RAW lines gave no record: each gives its own.
3. ``inspect`` counted embedded ``$PCDIN`` as ignored while ``analyze`` decoded them:
   both decode them (one home, :mod:`dracc.ingest.embedded_n2k`), and inspect's account
   of the lines adds up with them.

The logs are built from the real samples (canboat's candump and YDWG captures, the
Signal K server's NMEA 2000 log as ``$PCDIN``) and the simulated NMEA sample.
"""

from __future__ import annotations

import gzip

import pytest
from conftest import SAMPLES, real_path

from dracc.core.config import IngestConfig
from dracc.core.errors import IngestError
from dracc.ingest import detect_format, read_file
from dracc.ingest.inspect import inspect_logs

CFG = IngestConfig()


def _sentence(body: str) -> str:
    x = 0
    for c in body.encode():
        x ^= c
    return f"${body}*{x:02X}"


def _pcdin_lines(n: int) -> list[str]:
    """``n`` messages of the Signal K server's NMEA 2000 log as ``$PCDIN`` sentences."""
    rows = [
        r.split(",") for r in real_path("signalk-server", "aava-n2k.data").read_text().splitlines()
    ]
    return [
        _sentence(f"PCDIN,{int(r[2]):06X},{k:08X},{int(r[3]):02X},{''.join(r[6:]).upper()}")
        for k, r in enumerate(rows[:n])
    ]


def _nmea_lines(n: int) -> list[str]:
    """The simulated log's first ``n`` lines (TAG blocks, times and sources)."""
    return (SAMPLES / "voyage_tag.nmea").read_text().splitlines()[:n]


def _write(path, lines: list[str]) -> None:
    path.write_text("\r\n".join(lines) + "\r\n")


def _by_sentence(r) -> dict[str, int]:
    out: dict[str, int] = {}
    for df in r.frames.values():
        for s, n in df["sentence"].astype(str).value_counts().items():
            out[s] = out.get(s, 0) + int(n)
    return out


@pytest.fixture(scope="module")
def pcdin_then_nmea(tmp_path_factory):
    """3,000 ``$PCDIN`` lines (300 KB: the first 64 KB say NMEA 2000), then 2,000 NMEA
    0183 sentences; and each part alone."""
    d = tmp_path_factory.mktemp("pcdin")
    pcdin, nmea = _pcdin_lines(3000), _nmea_lines(2000)
    _write(d / "mixed.log", pcdin + nmea)
    _write(d / "pcdin.log", pcdin)
    _write(d / "nmea.log", nmea)
    return d


def test_pcdin_first_then_nmea_keeps_every_record(pcdin_then_nmea):
    d = pcdin_then_nmea
    assert detect_format(d / "mixed.log") == "n2k"  # what the first lines say
    got = read_file(d / "mixed.log", CFG)
    nmea = read_file(d / "nmea.log", CFG)
    n2k = read_file(d / "pcdin.log", CFG)
    assert got.records == nmea.records + n2k.records > 2 * n2k.records
    want = {**_by_sentence(nmea), **_by_sentence(n2k)}
    assert _by_sentence(got) == want
    assert got.rejects.total == 0 and "PCDIN" not in got.ignored and got.lines == 5000
    assert any("3,000 $PCDIN" in n for n in got.notes)


def test_inspect_decodes_embedded_pcdin_as_analyze_does(pcdin_then_nmea, tmp_path):
    """The PCDIN lines after the sentences (an NMEA log by its head) and before them:
    inspect gives the records analyze gives, ignores no PCDIN, and its account adds up."""
    d = pcdin_then_nmea
    after = tmp_path / "after.log"
    _write(after, _nmea_lines(2000) + _pcdin_lines(3000))
    for p in (after, d / "mixed.log"):
        r = read_file(p, CFG)
        rep = inspect_logs([p], CFG)
        i0 = rep["inputs"][0]
        assert i0["records"] == r.records and i0["format"] == r.format == "nmea"
        assert "PCDIN" not in rep["ignored"] and rep["ignored"] == dict(sorted(r.ignored.items()))
        acc = rep["accounting"]
        assert acc["n2k"] == 3000 and acc["shared"] == 0
        assert acc["lines"] == sum(
            acc[k] for k in ("sentences", "time_only", "qualifiers", "n2k", "ignored", "rejected")
        )
        assert {k: v["records"] for k, v in rep["sources"].items()} == {
            k: v.records for k, v in _sources(r).items()
        }


def _sources(r):
    from dracc.ingest import summarize_frames

    return summarize_frames(r.frames, r.path)


@pytest.mark.parametrize("order", ["candump_first", "ydwg_first", "interleaved"])
def test_candump_and_ydwg_lines_each_give_their_records(tmp_path, order):
    cd_path = real_path("canboat", "candumpSample3.txt")
    yd_path = real_path("canboat", "merrimac-ydwg-2020.raw")
    cd = [ln for ln in cd_path.read_text().splitlines() if ln and not ln.startswith("#")]
    yd = yd_path.read_text().splitlines()
    if order == "candump_first":
        lines = cd + yd
    elif order == "ydwg_first":
        lines = yd + cd
    else:
        lines = [x for pair in zip(cd, yd, strict=False) for x in pair] + cd[len(yd) :]
    p = tmp_path / "mixed.log"
    _write(p, lines)
    got = read_file(p, CFG)
    a, b = read_file(cd_path, CFG), read_file(yd_path, CFG)
    assert got.records == a.records + b.records > 0
    assert got.format == "n2k-mixed"
    assert inspect_logs([p], CFG)["inputs"][0]["records"] == got.records


def test_nmea_with_candump_lines_among_them(tmp_path):
    """An NMEA 0183 log (by its head) with candump lines later: both read, the candump
    lines no longer rejected as ``not_nmea``."""
    cd = real_path("canboat", "candumpSample3.txt").read_text().splitlines()[10:]
    p = tmp_path / "mixed.log"
    _write(p, _nmea_lines(3000) + cd)
    got = read_file(p, CFG)
    nmea = tmp_path / "nmea.log"
    _write(nmea, _nmea_lines(3000))
    want = (
        read_file(nmea, CFG).records
        + read_file(real_path("canboat", "candumpSample3.txt"), CFG).records
    )
    assert got.records == want and "not_nmea" not in got.rejects.counts


def test_a_compressed_mixed_log_reads_as_the_plain_one(pcdin_then_nmea, tmp_path):
    plain = pcdin_then_nmea / "mixed.log"
    packed = tmp_path / "mixed.log.gz"
    packed.write_bytes(gzip.compress(plain.read_bytes()))
    a, b = read_file(plain, CFG), read_file(packed, CFG)
    assert _by_sentence(a) == _by_sentence(b) and a.records == b.records
    assert inspect_logs([packed], CFG)["accounting"] == inspect_logs([plain], CFG)["accounting"]


def test_strict_judges_each_line_by_its_own_reader(pcdin_then_nmea, tmp_path):
    """--strict: a mixed log of good lines passes; a damaged sentence still fails."""
    strict = IngestConfig(strict=True)
    assert read_file(pcdin_then_nmea / "mixed.log", strict).records > 0
    assert inspect_logs([pcdin_then_nmea / "mixed.log"], strict)["rejected"] == {}
    lines = _pcdin_lines(3000) + _nmea_lines(2000)
    lines[4000] = lines[4000][:-2] + ("00" if not lines[4000].endswith("00") else "11")
    p = tmp_path / "bad.log"
    _write(p, lines)
    with pytest.raises(IngestError, match=r"bad\.log:4001: rejected \(checksum"):
        read_file(p, strict)
    with pytest.raises(IngestError, match=r"bad\.log:4001: rejected \(checksum"):
        inspect_logs([p], strict)


def test_strict_keeps_no_date_non_fatal(tmp_path):
    """Records with no time anywhere are counted ``no_date``, never a --strict failure,
    now that --strict judges a text log once all its lines are read."""
    p = tmp_path / "nodate.log"
    _write(p, [_sentence("HEHDT,59.909,T")] * 20)
    r = read_file(p, IngestConfig(strict=True))
    assert r.rejects.counts.get("no_date") == 20
    assert inspect_logs([p], IngestConfig(strict=True))["rejected"] == {"no_date": 20}
