"""The forms of received lines (:mod:`dracc.ingest.live.forms`) and their recording in a
file per form (:class:`dracc.ingest.live.Recorder`).

Checked against independent values: the form of every line of the real logs in
shared/data/real/canboat and signalk-server against what dracc's file reader says the
file is; NMEA 2000 source addresses against canboat's own line parser and decoder (the
``nmea2000`` package); NMEA 0183 keys and TAG times against what the NMEA reader gives
each line's records; Signal K delta keys against the delta reader.  There is no real
Signal K delta or data log among the shared files: the deltas here carry the values
canboat decodes from real PGNs of signalk-server/aava-n2k.data, the data-log lines are
real NMEA 0183 and NMEA 2000 lines behind the server's prefix (as in test_signalk.py).
"""

from __future__ import annotations

import json
import re
from collections import Counter
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from conftest import real_path

from dracc.core.config import IngestConfig
from dracc.frames import MISSING_NS
from dracc.ingest import detect_format, read_file, read_logs
from dracc.ingest.live import FORMS, Recorder, classify, form_suffix, line_key
from dracc.ingest.signalk_delta import read_signalk_delta
from dracc.pipeline.audit.logs import choose_logs

CFG = IngestConfig()
DAY_NS = 86_400 * 10**9
T0 = 1397678239 * 10**9  #: 2014-04-16 19:57:19 UTC, the first time of gofree-merrimac.log
SELF = "vessels.urn:mrn:imo:mmsi:244000001"


def _lines(path: Path) -> list[bytes]:
    """The lines of a log as a live source gives them (any line end, none kept)."""
    return [ln for ln in re.split(rb"\r\n|\r|\n", path.read_bytes()) if ln]


# ------------------------------------------------------------------ forms of real lines
#: real log -> (the form of its lines, what dracc's reader says the file is)
REAL_FORMS = {
    ("canboat", "merrimac-ydwg-2020.raw"): ("ydwg", "n2k-ydraw"),
    ("canboat", "candumpSample3.txt"): ("candump", "n2k-candump"),
    ("canboat", "candump-fast-cr.txt"): ("candump", "n2k-candump"),
    ("canboat", "actisense-522.candump.log"): ("candump", "n2k-candump"),
    ("canboat", "scx20.raw"): ("plain", "n2k-fast"),
    ("canboat", "susteranna2020.raw"): ("plain", "n2k-plain-mix-fast"),
    ("canboat", "ikonvert.log"): ("pdgy", "n2k-pdgy"),
    ("signalk-server", "aava-n2k.data"): ("plain", "n2k-fast"),
    ("signalk-server", "gofree-merrimac.log"): ("nmea0183", "nmea"),
    ("signalk-server", "n2kd-183-merrimac.log"): ("nmea0183", "nmea"),
    ("signalk-server", "nais400-merrimac.log"): ("nmea0183", "nmea"),
}


@pytest.mark.parametrize("parts", list(REAL_FORMS), ids=lambda p: p[1])
def test_every_line_has_the_form_of_its_file(parts):
    form, reader_format = REAL_FORMS[parts]
    path = real_path(*parts)
    res = read_file(path, CFG)
    assert res.format == reader_format
    data = [ln for ln in _lines(path) if not ln.startswith(b"#")]
    forms = Counter(classify(ln).form for ln in data)
    # every line the reader reads has the file's form; the others are lines it rejects
    # (ikonvert.log: two sentences fused by the logger)
    assert forms[form] >= len(data) - res.rejects.total
    assert forms[form] > 0.99 * len(data)
    if form == "nmea0183":
        assert set(forms) == {"nmea0183"}


@pytest.mark.parametrize(
    "parts", [p for p, (form, _) in REAL_FORMS.items() if form != "nmea0183"], ids=lambda p: p[1]
)
def test_a_file_of_one_form_reads_as_the_original(tmp_path, parts):
    """Every line of a real N2K log recorded (classified by write_many): the file of its
    form is read in the same format with the same records; ``#`` lines go to ``.nmea``."""
    form, reader_format = REAL_FORMS[parts]
    path = real_path(*parts)
    lines = _lines(path)
    rec = Recorder(tmp_path, now_ns=lambda: T0)
    rec.write_many([(T0 + k, ln) for k, ln in enumerate(lines)])
    rec.close()
    comments = sum(ln.startswith(b"#") for ln in lines)
    (out,) = [p for p in rec.files if p.name.endswith(form_suffix(form))]
    back, want = read_file(out, CFG), read_file(path, CFG)
    assert rec.lines_by_form[form] >= len(lines) - comments - want.rejects.total
    assert back.format == reader_format  # susteranna2020: MIX without its '# format=' line
    assert back.records == want.records
    assert back.ignored == want.ignored  # the messages dracc does not use, by PGN
    assert sum(back.ignored.values()) + back.records > 0
    for kind, df in want.frames.items():
        assert df["source"].astype(str).tolist() == back.frames[kind]["source"].astype(str).tolist()


def test_signalk_log_lines_and_their_keys(tmp_path):
    plaka = _lines(real_path("signalk-server", "plaka.log"))[:40]
    aava = _lines(real_path("signalk-server", "aava-n2k.data"))[:40]
    delta = _delta(60.0, 0.5, "n2k.115", "2014-08-15T19:00:00.000Z")
    rows = [b"%d;N;%s" % (1408129200000 + k, ln) for k, ln in enumerate(plaka)]
    rows += [b"%d;A;%s" % (1408129300000 + k, ln) for k, ln in enumerate(aava)]
    rows.append(b"1408129400000;I;" + delta)
    infos = [classify(r) for r in rows]
    assert {i.form for i in infos} == {"signalk_log"}
    assert [i.key for i in infos[:40]] == [line_key(ln)[0] for ln in plaka]
    assert [i.key for i in infos[40:80]] == [classify(ln).key for ln in aava]
    assert infos[-1].key == "signalk:n2k.115"
    log = tmp_path / "sk.log"
    log.write_bytes(b"\n".join(rows) + b"\n")
    assert detect_format(log) == "signalk"  # a file of these lines is a Signal K log


# ------------------------------------------------------------------ keys, independently
def test_can_frame_keys_are_canboat_source_addresses():
    cb = pytest.importorskip("nmea2000._canboat")
    checked = unparsed = 0
    for parts, fmt in (
        (("canboat", "merrimac-ydwg-2020.raw"), "ydwg02"),
        (("canboat", "candumpSample3.txt"), "candump"),
        (("canboat", "candump-fast-cr.txt"), "candump"),
        (("canboat", "actisense-522.candump.log"), "candump"),
        (("canboat", "scx20.raw"), "plain"),
        (("canboat", "susteranna2020.raw"), "plain"),
    ):
        for ln in _lines(real_path(*parts)):
            info = classify(ln)
            if info.form in ("other", "nmea0183"):
                continue
            try:
                got = cb.parse_line(fmt, ln.decode("ascii"))
            except ValueError:  # a frame without data (susteranna2020.raw: one line)
                unparsed += 1
                continue
            assert got is not None, ln
            assert info.key == f"n2k:addr{got[2]}", ln
            checked += 1
    assert checked > 10_000 and unparsed <= 1


def test_candump_screen_forms_keyed_as_canboat_parses_them():
    """candump's two other forms, written from real ``candump -l`` frames."""
    cb = pytest.importorskip("nmea2000._canboat")
    n = 0
    for ln in _lines(real_path("canboat", "candumpSample3.txt"))[9:400]:
        can_id, data = ln.split()[2].split(b"#")
        body = " ".join(data[i : i + 2].decode() for i in range(0, len(data), 2))
        n_bytes = len(data) // 2
        for text in (
            f"  can0  {can_id.decode()}   [{n_bytes}]  {body}",
            f"<0x{can_id.decode().lower()}> [{n_bytes}] {body.lower()}",
        ):
            info = classify(text.encode())
            assert info.form == "candump", text
            assert info.key == f"n2k:addr{cb.parse_line('candump', text)[2]}"
            n += 1
    assert n > 700


def test_pdgy_keys_are_the_sources_canboat_decodes():
    dec_mod = pytest.importorskip("nmea2000.decoder")
    decoder = dec_mod.NMEA2000Decoder()
    n = 0
    for ln in _lines(real_path("canboat", "ikonvert.log"))[:3000]:
        info = classify(ln)
        if info.form != "pdgy" or not ln.startswith(b"!PDGY,"):
            continue
        try:
            msg = decoder.decode(ln.decode("ascii"))
        except ValueError:  # two lines fused by the logger: canboat cannot read it
            continue
        if msg is None:
            continue
        assert info.key == f"n2k:addr{msg.source}", ln
        n += 1
    assert n > 2500
    assert classify(b"$PDGY,000000,4,,5,482,1,0") == ("pdgy", None, None)  # status


@pytest.mark.parametrize(
    "parts", [("signalk-server", "gofree-merrimac.log"), ("signalk-server", "nais400-merrimac.log")]
)
def test_nmea_keys_are_the_readers_sources(parts):
    path = real_path(*parts)
    lines = path.read_bytes().splitlines()
    res = read_file(path, CFG)
    n = 0
    for df in res.frames.values():
        for line, source in zip(df["line"].tolist(), df["source"].astype(str), strict=True):
            assert classify(lines[line - 1]).key == source
            n += 1
    assert n == sum(len(df) for df in res.frames.values()) > 50
    # a proprietary sentence is keyed by its address, a short line by nothing
    assert classify(b"$PASHR,1,2*00").key == "PASHR"
    assert classify(b"$GP*0") == ("nmea0183", None, None)
    assert classify(b"$02MWV,327.6,R,1.89,N*62").key == "02"  # canboat n2kd's talkers
    assert classify(b"") == ("other", None, None)


def test_tag_keys_and_times_are_the_readers(tmp_path):
    """Lines recorded with a source and receive times: the key is the TAG ``s:``, the
    time its ``c:`` (the NMEA reader's source and ``recv_ns``)."""
    lines = _lines(real_path("signalk-server", "gps.log"))[:300]
    rec = Recorder(tmp_path)
    for k, ln in enumerate(lines):
        rec.write(ln, T0 + k * 250_000_000, "GPS1" if k % 2 else "GPS2")
    rec.close()
    (path,) = rec.files
    tagged = path.read_bytes().splitlines()
    res = read_file(path, CFG)
    pos = res.frames["position"]
    for line, source, recv in zip(
        pos["line"], pos["source"].astype(str), pos["recv_ns"], strict=True
    ):
        info = classify(tagged[line - 1])
        assert info == ("nmea0183", source, recv)
        assert line_key(tagged[line - 1]) == (source, recv)
    assert len(pos) > 100
    # seconds (up to 10 digits) or milliseconds, as the TAG reader takes them
    assert classify(b"\\c:1397678239*00\\$GPRMC,1").c_ns == T0
    assert classify(b"\\s:X*00\\junk") == ("nmea0183", "X", None)
    assert classify(b"\\c:1397678239") == ("nmea0183", None, None)  # no block end
    for junk in (b"nan", b"inf", b"-inf", b"1e999", b"x"):  # no time, and no crash
        assert classify(b"\\c:%s,s:A*00\\$GPRMC,1" % junk) == ("nmea0183", "A", None)


def _delta(heading: float, sog: float | None, source: str | None, stamp: str, **src) -> bytes:
    values = [{"path": "navigation.headingTrue", "value": heading}]
    if sog is not None:
        values.append({"path": "navigation.speedOverGround", "value": sog})
    update: dict = {"timestamp": stamp, "values": values}
    if src:
        update["source"] = src
    if source:
        update["$source"] = source
    return json.dumps({"context": SELF, "updates": [update]}).encode()


def test_delta_keys_are_the_delta_readers(tmp_path):
    stamp = "2014-04-16T19:57:20.000Z"
    deltas = [
        _delta(1.0, None, "n2k.43", stamp, label="n2k", src="43", pgn=127250),
        _delta(1.1, None, None, stamp, label="can0", src="17"),
        _delta(1.2, None, None, stamp, label="ttyUSB0", talker="HE", sentence="HDT"),
        _delta(1.3, None, None, stamp, label="plain"),
        _delta(1.4, None, None, stamp),
        b'{ "updates": [ { "$source" : "spaced.1", "values": [{"path": '
        b'"navigation.headingTrue", "value": 1.5}], "timestamp": "2014-04-16T19:57:20Z"}]}',
    ]
    path = tmp_path / "d.json"
    path.write_bytes(b"\n".join(deltas) + b"\n")
    res = read_signalk_delta(path, CFG)
    hd = res.frames["heading"]
    keys = dict(zip(hd["line"], hd["source"].astype(str), strict=True))
    assert len(keys) == len(deltas)
    assert keys[5] == "signalk"  # no source at all
    for line, delta in enumerate(deltas, start=1):
        want = "signalk" if keys[line] == "signalk" else f"signalk:{keys[line]}"
        assert classify(delta) == ("signalk_delta", want, None)
    assert classify(b'{"name":"signalk-server","self":"' + SELF.encode() + b'"}').key == "signalk"
    gpsd = b'{"class":"TPV","device":"/dev/ttyUSB0","mode":3,"lat":52.1,"lon":4.9}'
    assert classify(gpsd) == ("gpsd_json", "gpsd:/dev/ttyUSB0", None)


# ------------------------------------------------------------------ the recording
def _aava_deltas() -> list[tuple[int, bytes, float]]:
    """(time ns, delta line, heading rad) of the 127250 headings of aava-n2k.data as
    canboat decodes them, each a Signal K delta keyed by its source address."""
    dec_mod = pytest.importorskip("nmea2000.decoder")
    decoder = dec_mod.NMEA2000Decoder()
    out = []
    for ln in _lines(real_path("signalk-server", "aava-n2k.data"))[:4000]:
        if b",127250," not in ln[:40]:
            continue
        msg = decoder.decode(ln.decode("ascii"))
        heading = msg.get_field_by_id("heading").value if msg is not None else None
        if heading is None or str(msg.get_field_by_id("reference").value) != "True":
            continue
        stamp = ln.split(b",", 1)[0].decode()
        t = pd.Timestamp(stamp).value
        out.append((t, _delta(float(heading), None, f"n2k.{msg.source}", stamp), heading))
    return out


def _per_line_times(res) -> dict[int, int]:
    """Line -> the time of the first record of the line (the reader's)."""
    times: dict[int, int] = {}
    for df in res.frames.values():
        for line, t in zip(df["line"].tolist(), df["time_ns"].tolist(), strict=True):
            times.setdefault(line, t)
    return times


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """gofree-merrimac.log (NMEA 0183, received at the times the reader gives its lines),
    merrimac-ydwg-2020.raw and a Signal K delta stream, interleaved by receive time and
    recorded; with the originals."""
    folder = tmp_path_factory.mktemp("rec")
    orig = tmp_path_factory.mktemp("orig")
    nmea_path = real_path("signalk-server", "gofree-merrimac.log")
    ydwg_path = real_path("canboat", "merrimac-ydwg-2020.raw")
    nmea = nmea_path.read_bytes().splitlines()
    times = _per_line_times(read_file(nmea_path, CFG))
    t, stream = T0, []
    for k, ln in enumerate(nmea, start=1):
        t = times.get(k, t)
        stream.append((t, 0, k, ln))
    for k, ln in enumerate(_lines(ydwg_path)):
        stream.append((T0 + k * 150_000_000, 1, k, ln))  # 914 frames over 137 s
    deltas = _aava_deltas()
    for k, (_, line, _) in enumerate(deltas):
        stream.append((T0 + k * 400_000_000 + 7, 2, k, line))
    hello = f'{{"name":"signalk-server","version":"2.8.0","self":"{SELF}"}}'.encode()
    stream.append((T0 - 1, 2, -1, hello))
    stream.sort()
    delta_orig = orig / "deltas.json"
    delta_orig.write_bytes(b"".join(s[3] + b"\n" for s in stream if s[1] == 2))
    clock = [T0]
    rec = Recorder(folder, flush_lines=50, now_ns=lambda: clock[0])
    forms: Counter[str] = Counter()
    for i in range(0, len(stream), 64):  # as the watch gets them, a poll at a time
        batch = [(s[0], s[3]) for s in stream[i : i + 64]]
        clock[0] = batch[-1][0] + 1000
        info = [classify(line) for _, line in batch]
        forms.update(x.form for x in info)
        rec.write_many(batch, forms=[x.form for x in info])
        if i == 640:
            current = rec.current_files()
    rec.close()
    return {
        "rec": rec,
        "folder": folder,
        "originals": [nmea_path, ydwg_path, delta_orig],
        "forms": forms,
        "current": current,
        "recv": {k: t for t, src, k, _ in stream if src == 0},
        "deltas": deltas,
    }


def test_recording_is_a_file_per_form(recorded):
    rec = recorded["rec"]
    names = sorted(p.name for p in rec.files)
    assert names == sorted(
        f"dracc-20140416{form_suffix(f)}" for f in ("nmea0183", "ydwg", "signalk_delta")
    )
    assert not list(recorded["folder"].glob("*.part"))
    assert recorded["forms"] == {
        "nmea0183": 6324,
        "ydwg": 914,
        "signalk_delta": 1 + len(recorded["deltas"]),
    }
    assert rec.lines_by_form == recorded["forms"] and rec.lines == sum(recorded["forms"].values())
    cur = recorded["current"]
    assert set(cur) == {"nmea0183", "ydwg", "signalk_delta"}
    assert all(p.name.endswith(form_suffix(f) + ".part") for f, p in cur.items())
    # the N2K and Signal K lines byte for byte as received (YDWG's own CR LF kept)
    by_suffix = {p.name.split(".", 1)[1]: p for p in rec.files}
    ydwg, deltas = recorded["originals"][1:]
    assert by_suffix["ydwg.raw"].read_bytes() == ydwg.read_bytes()
    assert by_suffix["signalk-delta.json"].read_bytes() == deltas.read_bytes()
    # the audit's log chooser takes all of them for the night
    chosen = choose_logs([recorded["folder"]], "2014-04-16", "*").paths
    assert sorted(p.name for p in chosen) == names


def _by_source(frames: dict[str, pd.DataFrame]) -> dict[tuple[str, str], pd.DataFrame]:
    out = {}
    for kind, df in frames.items():
        for src, part in df.groupby(df["source"].astype(str), observed=True):
            out[(kind, src)] = part.sort_values(["time_ns", "line"], kind="stable")
    return out


def test_recording_reads_back_as_the_three_originals(recorded):
    back = read_logs(list(recorded["rec"].files), CFG)
    want = read_logs(recorded["originals"], CFG)
    assert {k: v.records for k, v in back.sources.items()} == {
        k: v.records for k, v in want.sources.items()
    }
    assert {k: dict(v.sentences) for k, v in back.sources.items()} == {
        k: dict(v.sentences) for k, v in want.sources.items()
    }
    assert back.rejects.counts == want.rejects.counts
    a, b = _by_source(back.frames), _by_source(want.frames)
    assert a.keys() == b.keys()
    kinds = {kind for kind, _ in a}
    assert {"position", "heading", "ground", "water"} <= kinds
    sources = {src for _, src in a}
    assert {"GP", "SD", "n2k.160"} <= sources
    assert any(s.startswith("n2k:") for s in sources)
    own_time = 0
    for key, fa in a.items():
        fb = b[key]
        assert len(fa) == len(fb), key
        nmea = key[1] in ("GP", "SD", "II", "WI", "AI")
        for col in fa.columns:
            if col == "recv_ns" and nmea:
                continue  # the recording adds the receive time (checked below)
            va, vb = fa[col].to_numpy(), fb[col].to_numpy()
            if va.dtype.kind == "f":
                np.testing.assert_array_equal(va, vb, err_msg=f"{key} {col}")
            else:
                assert list(map(str, va)) == list(map(str, vb)), (key, col)
        if nmea:  # a sentence with a time of its own keeps the TAG time as recv_ns
            assert (fb["recv_ns"] == MISSING_NS).all()
            recv = np.array([recorded["recv"][ln] for ln in fa["line"].tolist()])
            got = fa["recv_ns"].to_numpy()
            has = got != MISSING_NS
            assert (got[has] == recv[has]).all()
            own_time += int(has.sum())
    assert own_time > 400


def test_recorded_deltas_hold_canboats_values(recorded):
    (path,) = [p for p in recorded["rec"].files if p.name.endswith(".signalk-delta.json")]
    res = read_file(path, CFG)
    hd = res.frames["heading"]
    want = recorded["deltas"]
    assert len(hd) == len(want) > 20
    np.testing.assert_allclose(hd["heading_rad"], [h for _, _, h in want], rtol=0, atol=1e-12)
    assert hd["time_ns"].tolist() == [t for t, _, _ in want]


# ------------------------------------------------------------------ rotation, recovery
YDWG = b"00:29:58.617 R 0DFF180D A2 8C 50 C0 FF FF FF FF"  # 47 bytes and CR LF


def test_rotation_by_size_and_day_for_can_frames(tmp_path):
    clock = [T0]
    rec = Recorder(tmp_path, max_bytes=200, now_ns=lambda: clock[0])
    for k in range(10):  # 49 bytes a line: 4 a file
        rec.write(YDWG, T0 + k, form="ydwg")
    rec.write(b"$GPGGA,1*00", T0, form="nmea0183")
    midnight = (T0 // DAY_NS + 1) * DAY_NS
    rec.write(YDWG, midnight + 1, form="ydwg")  # the next UTC day: a new file
    assert set(rec.current_files()) == {"ydwg", "nmea0183"}
    assert rec.current is not None and rec.current.name == "dracc-20140416.nmea.part"
    clock[0] = midnight + 5 * DAY_NS
    rec.tick()  # days on, nothing heard: both files are finished
    assert rec.current_files() == {} and rec.current is None
    rec.close()
    # in the order finished: by size (4 lines a file), at the next day's first line, at
    # the tick on the later day
    assert [p.name for p in rec.files] == [
        "dracc-20140416.ydwg.raw",
        "dracc-20140416-1.ydwg.raw",
        "dracc-20140416-2.ydwg.raw",
        "dracc-20140416.nmea",
        "dracc-20140417.ydwg.raw",
    ]
    raw = [p for p in rec.files if p.suffix == ".raw"]
    assert all(p.stat().st_size <= 200 for p in raw)
    assert b"".join(p.read_bytes() for p in raw) == (YDWG + b"\r\n") * 11
    assert not list(tmp_path.glob("*.part"))


def test_crash_leftovers_of_every_form_finished(tmp_path):
    (tmp_path / "dracc-20140416.ydwg.raw").write_bytes(YDWG + b"\r\n")  # finished before
    (tmp_path / "dracc-20140416.ydwg.raw.part").write_bytes(YDWG + b"\r\n" + YDWG[:20])
    (tmp_path / "dracc-20140416.signalk-delta.json.part").write_bytes(b'{"updates":[')
    (tmp_path / "dracc-20140416.candump.log.part").write_bytes(
        b"(1502984866.421964) slcan0 09F112CC#FF725AFF7FFF7FFD\n(1502984866.4"
    )
    (tmp_path / "notes.part").write_bytes(b"someone else's\n")  # not a recording: left
    (tmp_path / "dracc-20140416.weird.part").write_bytes(b"x\n")
    rec = Recorder(tmp_path)
    rec.close()
    assert sorted(p.name for p in rec.recovered) == [
        "dracc-20140416-1.ydwg.raw",
        "dracc-20140416.candump.log",
    ]
    assert (tmp_path / "dracc-20140416-1.ydwg.raw").read_bytes() == YDWG + b"\r\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        "dracc-20140416-1.ydwg.raw",
        "dracc-20140416.candump.log",
        "dracc-20140416.weird.part",
        "dracc-20140416.ydwg.raw",
        "notes.part",
    ]
    res = read_file(tmp_path / "dracc-20140416.candump.log", CFG)
    assert res.format == "n2k-candump" and res.rejects.total == 0


def test_write_many_classifies_and_suffixes():
    assert form_suffix(None) == form_suffix("nmea0183") == form_suffix("other") == ".nmea"
    suffixes = {form_suffix(f) for f in FORMS}
    assert len(suffixes) == len(FORMS) - 1  # other lines share the .nmea file
    with pytest.raises(ValueError, match="unknown line form"):
        form_suffix("ebl")


def test_write_many_routes_unclassified_lines(tmp_path):
    rec = Recorder(tmp_path)
    rec.write_many(
        [(T0, b"$GPGGA,1*00"), (T0 + 1, YDWG), (T0 + 2, b"# a comment"), (T0 + 3, b"{}")]
    )
    rec.close()
    got = {p.name: p.read_bytes() for p in rec.files}
    assert got == {
        "dracc-20140416.nmea": b"\\c:1397678239000*64\\$GPGGA,1*00\r\n# a comment\r\n",
        "dracc-20140416.ydwg.raw": YDWG + b"\r\n",
        "dracc-20140416.signalk-delta.json": b"{}\n",
    }
