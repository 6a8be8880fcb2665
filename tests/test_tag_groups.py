"""IEC 61162-450 TAG line groups (``g:<i>-<n>-<id>``, §7.3): a group's lines without
``s:``/``c:`` read with the source and time of the group's first line
(dracc/ingest/nmea/groups.py).

Expected values are hand calculations (Unix times of the hand-written ``c:`` values,
source keys written into the lines) or the same log read without groups: the simulated
voyage's TAG log, whose consecutive lines of one TAG block are made into groups with
``s:`` and ``c:`` left on the first line only, must read exactly as the original."""

from __future__ import annotations

from functools import reduce
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import dracc.ingest.nmea.engine_c as engine_c
from dracc.core.config import IngestConfig
from dracc.frames import MISSING_NS
from dracc.ingest import read_logs
from dracc.ingest.live.record import tag_line
from dracc.ingest.nmea import StreamState, iter_nmea_blocks, read_nmea
from dracc.ingest.nmea.groups import GROUP_WINDOW_LINES, GroupCarry, resolve_groups, scan_groups

ROOT = Path(__file__).resolve().parents[1]
SAMPLE = ROOT / "sample_logs" / "voyage_tag.nmea"
REAL = ROOT.parent / "shared" / "data" / "real"
S = 1_000_000_000
T0 = 1_700_000_000  # 2023-11-14 22:13:20 UTC


def _xor(b: bytes) -> int:
    return reduce(lambda a, c: a ^ c, b, 0)


def tag(body: str) -> str:
    """A TAG block with its checksum (XOR of the body, IEC 61162-450 §7.3.2)."""
    return f"\\{body}*{_xor(body.encode()):02X}\\"


def sentence(body: str) -> str:
    return f"${body}*{_xor(body.encode()):02X}"


def ais(body: str) -> str:
    return f"!{body}*{_xor(body.encode()):02X}"


GGA = "GPGGA,{t},5730.0000,N,01150.0000,E,1,08,0.9,10.0,M,40.0,M,,"
RMC = "GPRMC,{t},A,5730.0000,N,01150.0000,E,5.0,90.0,141123,,,A"
VTG = "GPVTG,90.0,T,,M,5.0,N,9.3,K,A"
HDT = "HEHDT,{h},T"
ROT = "HEROT,5.0,A"


def _write(path: Path, lines: list[str]) -> Path:
    path.write_text("".join(x + "\r\n" for x in lines), encoding="ascii")
    return path


def _records(frames: dict[str, pd.DataFrame]) -> pd.DataFrame:
    """Every record (line, kind, source, time, receive time), by line and kind."""
    parts = [
        f[["line", "source", "time_ns", "recv_ns"]].assign(kind=k, source=f["source"].astype(str))
        for k, f in frames.items()
        if len(f)
    ]
    return pd.concat(parts).sort_values(["line", "kind"]).reset_index(drop=True)


# the hand-made log: two interleaved sources, a reused id, a missing first line, bad g:
HAND = [
    tag(f"g:1-3-11,s:GNSS1,c:{T0}") + sentence(GGA.format(t="221320.00")),  # 1
    tag(f"g:1-2-12,s:GYRO1,c:{T0 + 1}") + sentence(HDT.format(h="10.0")),  # 2
    tag("g:2-3-11") + sentence(RMC.format(t="221320.00")),  # 3 -> GNSS1
    tag("g:2-2-12") + sentence(ROT),  # 4 -> GYRO1, T0+1
    tag("g:3-3-11") + sentence(VTG),  # 5 -> GNSS1, T0
    tag(f"g:1-2-11,s:GNSS2,c:{T0 + 10}") + sentence(GGA.format(t="221330.00")),  # 6 id reused
    tag("g:2-2-11") + sentence(VTG),  # 7 -> GNSS2, T0+10
    tag(f"c:{T0 + 12}") + sentence(HDT.format(h="11.0")),  # 8 no group
    tag(f"g:2-2-99,c:{T0 + 13}") + sentence(HDT.format(h="12.0")),  # 9 first line missing
    tag(f"g:2-2-12,c:{T0 + 14}") + sentence(HDT.format(h="13.0")),  # 10 group 12 closed
    tag(f"g:3-2-5,s:GYRO1,c:{T0 + 15}") + sentence(HDT.format(h="14.0")),  # 11 bad g:
    tag(f"g:1-x-5,c:{T0 + 16}") + sentence(HDT.format(h="15.0")),  # 12 bad g:
]


@pytest.fixture(scope="module")
def hand(tmp_path_factory: pytest.TempPathFactory) -> tuple[pd.DataFrame, list[str]]:
    p = _write(tmp_path_factory.mktemp("groups") / "hand.nmea", HAND)
    r = read_nmea(p, IngestConfig())
    return _records(r.frames), r.notes


def test_hand_made_groups_sources_and_times(hand: tuple[pd.DataFrame, list[str]]) -> None:
    recs, _ = hand
    got = {
        (int(r.line), r.kind): (r.source, int(r.time_ns), int(r.recv_ns)) for r in recs.itertuples()
    }
    gga_t0 = (T0) * S  # 22:13:20 on 2023-11-14 = T0
    expect = {
        (1, "position"): ("GNSS1", gga_t0, T0 * S),
        (2, "heading"): ("GYRO1", (T0 + 1) * S, MISSING_NS),
        (3, "position"): ("GNSS1", gga_t0, T0 * S),  # its group's c:, as receive time
        (3, "ground"): ("GNSS1", gga_t0, T0 * S),
        (4, "rot"): ("GYRO1", (T0 + 1) * S, MISSING_NS),  # interleaved group 12
        (5, "ground"): ("GNSS1", T0 * S, MISSING_NS),
        (6, "position"): ("GNSS2", (T0 + 10) * S, (T0 + 10) * S),
        (7, "ground"): ("GNSS2", (T0 + 10) * S, MISSING_NS),  # reused id 11
        (8, "heading"): ("HE", (T0 + 12) * S, MISSING_NS),
        (9, "heading"): ("HE", (T0 + 13) * S, MISSING_NS),  # incomplete: its own
        (10, "heading"): ("HE", (T0 + 14) * S, MISSING_NS),  # incomplete: group 12 ended
        (11, "heading"): ("GYRO1", (T0 + 15) * S, MISSING_NS),  # bad g: read without it
        (12, "heading"): ("HE", (T0 + 16) * S, MISSING_NS),
    }
    assert got == expect


def test_hand_made_groups_notes(hand: tuple[pd.DataFrame, list[str]]) -> None:
    _, notes = hand
    joined = [n for n in notes if "first line" in n and "incomplete" not in n]
    assert joined and joined[0].startswith("4 ")  # lines 3, 4, 5, 7
    incomplete = [n for n in notes if "line group incomplete" in n]
    assert incomplete and incomplete[0].startswith("2 ")  # lines 9, 10
    bad = [n for n in notes if "unreadable TAG line-group" in n]
    assert bad and bad[0].startswith("2 ")  # lines 11, 12


def _resolved(lines: list[str]) -> dict[int, tuple[str, int]]:
    data = "".join(x + "\n" for x in lines).encode()
    table, _ = scan_groups(data)
    from collections import Counter

    res = resolve_groups(table, GroupCarry(), 1, Counter())
    return {
        int(ln): (str(s), int(e))
        for ln, s, e in zip(res["line"], res["source"], res["ext_ns"], strict=True)
    }


def test_ignored_sentence_groups_gsv_txt_aivdm() -> None:
    """GSV triples, a two-part text and a two-fragment AIVDM: sentences dracc does not
    read, but their group lines are joined all the same (the per-line resolution)."""
    lines = [
        tag(f"g:1-3-1234,s:GP0001,c:{T0}") + sentence("GPGSV,3,1,09,01,40,083,46,02,17,308,41"),
        tag("g:2-3-1234") + sentence("GPGSV,3,2,09,03,07,344,39,04,22,228,45"),
        tag(f"g:1-2-7,s:AI0001,c:{T0 + 2}")
        + ais("AIVDM,2,1,3,B,55?MbV02;H;s<HtKR20EHE:0@T4@Dn2222222216L961O5Gf0NSQEp6ClRp8,0"),
        tag("g:3-3-1234") + sentence("GPGSV,3,3,09,05,34,065,38"),
        tag("g:2-2-7") + ais("AIVDM,2,2,3,B,88888888880,2"),
        tag(f"g:1-2-8,s:GP0001,c:{T0 + 3}") + sentence("GPTXT,02,01,02,ANTENNA OK"),
        tag("g:2-2-8") + sentence("GPTXT,02,02,02,JAMMING LOW"),
    ]
    assert _resolved(lines) == {
        2: ("GP0001", T0 * S),
        4: ("GP0001", T0 * S),
        5: ("AI0001", (T0 + 2) * S),
        7: ("GP0001", (T0 + 3) * S),
    }


def test_window_and_repeated_index() -> None:
    """A continuation more than GROUP_WINDOW_LINES after its first line, and an index seen
    twice (a reused id whose first line was lost), are not joined."""
    first = tag(f"g:1-3-5,s:A1,c:{T0}") + sentence("GPGSV,3,1,09")
    cont = tag("g:2-3-5") + sentence("GPGSV,3,2,09")
    filler = ["# filler"] * GROUP_WINDOW_LINES
    assert _resolved([first, *filler, cont]) == {}
    assert _resolved([first, *filler[:-1], cont]) == {GROUP_WINDOW_LINES + 1: ("A1", T0 * S)}
    assert _resolved([first, cont, cont]) == {2: ("A1", T0 * S)}


def test_recorded_continuation_lines(tmp_path: Path) -> None:
    """The form dracc watch records: the recorder added its receive time c: to the
    continuation lines (and none to the first, which has one); they read with the
    group's first line's source and time, as the stream that was recorded."""
    recv = [(T0 + 30) * S + k * 37_000_000 for k in range(3)]  # 37 ms apart
    stream = [
        tag(f"g:1-3-41,s:GNSS1,c:{T0 + 30}") + sentence(GGA.format(t="221350.00")),
        tag("g:2-3-41") + sentence(VTG),
        tag("g:3-3-41") + sentence(RMC.format(t="221350.00")),
    ]
    recorded = [tag_line(x.encode(), t).decode() for x, t in zip(stream, recv, strict=True)]
    assert recorded[0] == stream[0]
    assert all("c:" in x and "s:" not in x for x in recorded[1:])
    a = _records(read_nmea(_write(tmp_path / "s.nmea", stream), IngestConfig()).frames)
    b = _records(read_nmea(_write(tmp_path / "r.nmea", recorded), IngestConfig()).frames)
    pd.testing.assert_frame_equal(a, b)
    assert set(b["source"]) == {"GNSS1"}
    assert b["time_ns"].tolist() == [(T0 + 30) * S] * 4  # GGA, VTG, RMC (position, ground)


def _grouped(src: Path, dst: Path) -> Path:
    """``src`` with each run of consecutive lines of one TAG block (at most 9) made a
    line group: ``s:`` and ``c:`` on its first line only."""
    out, run = [], []
    ids = iter(range(10**9))

    def flush() -> None:
        if not run:
            return
        gid = next(ids) % 999 + 1
        body, sent = run[0]
        out.append(tag(f"g:1-{len(run)}-{gid},{body}") + sent)
        out.extend(tag(f"g:{i}-{len(run)}-{gid}") + s for i, (_, s) in enumerate(run[1:], 2))
        run.clear()

    for line in src.read_text(encoding="ascii").splitlines():
        assert line.startswith("\\")
        end = line.index("\\", 1)
        body = line[1 : line.index("*")]
        if run and (run[0][0] != body or len(run) == 9):
            flush()
        run.append((body, line[end + 1 :]))
    flush()
    return _write(dst, out)


@pytest.fixture(scope="module")
def sample_pair(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    return SAMPLE, _grouped(SAMPLE, tmp_path_factory.mktemp("grouped") / "voyage_g.nmea")


def test_grouped_voyage_reads_as_original(sample_pair: tuple[Path, Path]) -> None:
    orig, grouped = sample_pair
    text = grouped.read_text()
    assert text.count("\\g:") - text.count("g:1-") > 4000  # continuation lines
    a = read_logs([orig], IngestConfig())
    b = read_logs([grouped], IngestConfig())
    assert a.frames.keys() == b.frames.keys()
    for k in a.frames:
        pd.testing.assert_frame_equal(a.frames[k], b.frames[k])


@pytest.mark.parametrize("engine", ["c", "numpy"])
def test_grouped_voyage_small_blocks(
    sample_pair: tuple[Path, Path], engine: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Groups cut by block boundaries are joined across blocks, with either engine."""
    monkeypatch.setattr(engine_c, "ENGINE", engine)
    orig, grouped = sample_pair
    st = StreamState(str(grouped))
    blocks = list(iter_nmea_blocks(grouped, IngestConfig(), st, block_bytes=20_000, workers=1))
    assert len(blocks) > 30
    b = _records(_concat(blocks))
    a = _records(read_nmea(orig, IngestConfig()).frames)
    pd.testing.assert_frame_equal(a, b)
    assert st.stats["tag_group_incomplete"] == 0 and st.stats["tag_group_joined"] > 0


def _concat(blocks: list) -> dict[str, pd.DataFrame]:
    from dracc.frames import concat_blocks

    return concat_blocks([b.frames for b in blocks])


@pytest.mark.parametrize(
    "path",
    [SAMPLE, REAL / "OpenCPN" / "stupan.se-10112-tcp.log"],
    ids=["voyage_tag", "stupan"],
)
def test_no_groups_no_table(path: Path) -> None:
    """A log without g: has no group lines: its blocks read as without this feature."""
    if not path.exists():
        pytest.skip(f"{path} not present")
    assert scan_groups(path.read_bytes()) == ({}, 0)


def test_real_libais_group_kept() -> None:
    """libais's tagblock.nmea: a two-fragment AIVDM group whose second line carries its
    own s: and c: (the same as the first's), between them another source's line."""
    p = REAL / "libais" / "tagblock.nmea"
    if not p.exists():
        pytest.skip("libais log not present")
    table, bad = scan_groups(p.read_bytes())
    assert bad == 0
    assert table["line"].tolist() == [1, 3]
    assert table["group"].tolist() == [1604, 1604]
    assert _resolved(p.read_text().splitlines()) == {3: ("rORBCOMM008", 1418169601 * S)}
    assert np.all(table["ext_ns"] == 1418169601 * S)


@pytest.mark.parametrize(
    ("body", "want"),
    [
        ("g:1-3-1234,s:GP0001,c:1700000000", (True, True, 1, 3, 1234)),
        ("s:GP0001,g:2-3-7", (True, True, 2, 3, 7)),
        ("g:1-2-5,g:2-2-5", (True, True, 1, 2, 5)),  # the first g: counts
        ("xg:1-2-3,s:A", (False, False, 0, 0, 0)),  # not a key
        ("s:A", (False, False, 0, 0, 0)),
        ("g:0-2-7", (True, False, 0, 0, 0)),
        ("g:3-2-7", (True, False, 0, 0, 0)),
        ("g:1-2-", (True, False, 0, 0, 0)),
        ("g:1-2-3-4", (True, False, 0, 0, 0)),
        ("g:1-x-7,s:A", (True, False, 0, 0, 0)),
    ],
)
def test_parse_groups_values(body: str, want: tuple[bool, bool, int, int, int]) -> None:
    from dracc.ingest.tagblock import parse_groups

    blocks = [tag("s:Z"), tag(body), tag("g:2-2-9")]  # neighbours: one block never leaks
    data = "".join(blocks).encode()
    buf = np.frombuffer(data, dtype=np.uint8)
    ends = np.cumsum([len(b) for b in blocks])
    starts = ends - np.array([len(b) for b in blocks])
    found, ok, i, n, gid = parse_groups(buf, starts, ends)
    assert (bool(found[1]), bool(ok[1]), int(i[1]), int(n[1]), int(gid[1])) == want
    assert not found[0] and (found[2], ok[2], i[2], n[2], gid[2]) == (True, True, 2, 2, 9)
