"""The Signal K and gpsd JSON readers streamed in chunks give what a whole-file read gave.

Each reader is run with the default chunk size, with 4 KiB chunks and with chunks one
byte longer than a line (cuts in the middle of lines, lines longer than a chunk), and
compared field by field (frames, counts in their order, examples, notes, lines, time
events, progress) with the reader as it was before it streamed: a copy of those
functions below (the commit before, reading the whole file with ``read_bytes``) is the
independent reference.  Inputs: the real gpsd ``.chk`` files, a Signal K data log built
from real NMEA 0183 and NMEA 2000 lines, and generated logs with bad lines, blank lines,
CRLF, a last line without line end and lines longer than the chunk and than
``max_line_bytes``.
"""

from __future__ import annotations

import dataclasses
import json
import tempfile
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from conftest import real_path

import dracc.ingest.chunks as chunks
from dracc.core.config import IngestConfig
from dracc.core.errors import IngestError
from dracc.frames import MISSING_NS, FileResult
from dracc.ingest.demux import (
    check_strict,
    line_bounds,
    line_copy,
    merge_results,
    relabel,
    scaled_progress,
    take_off_blanks,
    write_copy,
)
from dracc.ingest.gpsd_json import GpsdDecoder, read_gpsd_json
from dracc.ingest.signalk import NMEA_LETTERS, raw_line, read_signalk, split_prefixes
from dracc.ingest.signalk_delta import DeltaDecoder, decode_lines, read_signalk_delta

# --- the reference: the readers as they were, reading the whole file at once ----------


def old_read_signalk_delta(
    path: str | Path, cfg: IngestConfig, progress: Callable[[int], object] | None = None
) -> FileResult:
    """Read a file of bare Signal K delta lines into a :class:`FileResult`."""
    p = Path(path)
    raw = p.read_bytes()
    buf = np.frombuffer(raw, dtype=np.uint8)
    start, end, _nxt = line_bounds(buf)
    dec = DeltaDecoder(str(p), max_line_bytes=cfg.max_line_bytes)
    blank = start == end
    if blank.any():
        dec.ignored["blank"] += int(blank.sum())
    keep = np.flatnonzero(~blank)
    decode_lines(dec, raw, start[keep], end[keep], keep + 1)
    res = dec.finish(cfg)
    res.lines = len(start)
    check_strict(res, cfg)
    if progress is not None:
        progress(len(raw))
    return res


def old_read_gpsd_json(
    path: str | Path, cfg: IngestConfig, progress: Callable[[int], object] | None = None
) -> FileResult:
    """Read gpsd JSON (``gpspipe -w``) or a gpsfake ``.chk`` file (JSON and NMEA lines)
    into one :class:`FileResult` of format ``gpsd-json``."""
    from dracc.ingest.nmea import check_readable, read_nmea

    p = Path(path)
    check_readable(p)
    file = str(p)
    raw = p.read_bytes()
    buf = np.frombuffer(raw, dtype=np.uint8)
    start, end, nxt = line_bounds(buf)
    blank = start == end
    first = np.where(blank, 0, buf[np.minimum(start, max(len(buf) - 1, 0))]) if len(buf) else start
    is_json = first == ord("{")
    other = ~is_json & ~blank
    dec = GpsdDecoder(file, max_line_bytes=cfg.max_line_bytes)
    ji = np.flatnonzero(is_json)
    for s, e, n in zip(start[ji].tolist(), end[ji].tolist(), (ji + 1).tolist(), strict=True):
        dec.feed(raw[s:e], n)
    res = dec.finish(cfg)
    check_strict(res, cfg)
    if progress is not None:
        progress(int((nxt - start)[is_json].sum()))
    parts = [res]
    notes = []
    if other.any():
        notes.append(f"{int(other.sum())} lines other than JSON read as NMEA 0183")
        with tempfile.TemporaryDirectory(prefix="dracc-gpsd-") as tmp:
            copy = write_copy(line_copy(buf, start, end, nxt, other), Path(tmp), p.name)
            told = scaled_progress(progress, int((nxt - start)[other].sum()), copy.stat().st_size)
            r = relabel(read_nmea(copy, cfg, told), str(copy), file)
        take_off_blanks(r, int(is_json.sum()))
        parts.append(r)
    elif blank.any():
        res.ignored["blank"] += int(blank.sum())
    out = merge_results(file, "gpsd-json", len(start), parts, notes)
    return out


def old_read_signalk(
    path: str | Path, cfg: IngestConfig, progress: Callable[[int], object] | None = None
) -> FileResult:
    """Read a Signal K server data log (see the module docstring) into one
    :class:`FileResult` of format ``signalk``."""
    from dracc.ingest.nmea import check_readable, read_nmea

    p = Path(path)
    check_readable(p)
    file = str(p)
    raw = p.read_bytes()
    buf = np.frombuffer(raw, dtype=np.uint8)
    start, end, nxt = line_bounds(buf)
    letter, recv, pay = split_prefixes(buf, start, end)
    blank = start == end
    size = nxt - start
    is_nmea = np.isin(letter, np.frombuffer(NMEA_LETTERS, np.uint8)) | ((letter == 0) & ~blank)
    is_n2k = letter == ord("A")
    is_delta = letter == ord("I")
    other = (letter != 0) & ~is_nmea & ~is_n2k & ~is_delta
    parts: list[FileResult] = []
    notes: list[str] = []
    plain = (letter == 0) & ~blank
    counts = {
        "NMEA 0183": int(is_nmea.sum() - plain.sum()),
        "NMEA 2000": int(is_n2k.sum()),
        "Signal K delta": int(is_delta.sum()),
        "other": int(other.sum()),
        "not multiplexed (read as NMEA 0183)": int(plain.sum()),
    }
    notes.append(
        "Signal K data log: " + ", ".join(f"{n} {what} lines" for what, n in counts.items() if n)
    )
    with tempfile.TemporaryDirectory(prefix="dracc-signalk-") as tmp:
        folder = Path(tmp)
        if is_nmea.any() or not (is_n2k.any() or is_delta.any()):
            added = int((~is_nmea & ~blank).sum())
            if added == 0:  # nothing to blank out: the log is read as it is
                parts.append(read_nmea(p, cfg, progress))
            else:
                (folder / "n").mkdir()
                copy = write_copy(line_copy(buf, start, end, nxt, is_nmea), folder / "n", p.name)
                told = scaled_progress(progress, int(size[is_nmea].sum()), copy.stat().st_size)
                r = relabel(read_nmea(copy, cfg, told), str(copy), file)
                take_off_blanks(r, added)
                parts.append(r)
        if is_n2k.any():
            parts.append(
                _old_read_n2k_lines(
                    p, cfg, progress, buf, start, end, nxt, is_n2k, pay, recv, folder
                )
            )
        if is_delta.any():
            dec = DeltaDecoder(file, max_line_bytes=cfg.max_line_bytes)
            di = np.flatnonzero(is_delta)
            decode_lines(dec, raw, pay[di], end[di], di + 1, recv[di])
            r = dec.finish(cfg)
            r.format = "signalk"
            check_strict(r, cfg)
            parts.append(r)
            if progress is not None:
                progress(int(size[is_delta].sum()))
    res = merge_results(file, "signalk", len(start), parts, notes)
    if other.any():
        oi = np.flatnonzero(other)
        for ch in np.unique(letter[oi]).tolist():
            rows = oi[letter[oi] == ch]
            what = f"signalk {chr(ch)}"
            res.ignored[what] += len(rows)
            res.ignored_examples[what] = [
                (file, i + 1, raw_line(buf, start, end, i)) for i in rows[:5].tolist()
            ]
        if progress is not None:
            progress(int(size[other].sum()))
    return res


def _old_read_n2k_lines(
    p: Path,
    cfg: IngestConfig,
    progress: Callable[[int], object] | None,
    buf: np.ndarray,
    start: np.ndarray,
    end: np.ndarray,
    nxt: np.ndarray,
    keep: np.ndarray,
    pay: np.ndarray,
    recv: np.ndarray,
    folder: Path,
) -> FileResult:
    """The ``A`` lines' payloads (canboat plain) read by the NMEA 2000 reader from a
    line-preserving copy; rows without a receive time get their line's."""
    file = str(p)
    rows = np.flatnonzero(keep)
    n = len(rows)
    (folder / "a").mkdir()
    copy = write_copy(line_copy(buf, start, end, nxt, keep, pay - start), folder / "a", p.name)
    told = scaled_progress(progress, int((nxt - start)[keep].sum()), copy.stat().st_size)
    try:
        from dracc.ingest.n2k import read_n2k

        r = relabel(read_n2k(copy, cfg, told), str(copy), file)
    except (ImportError, IngestError) as err:  # no NMEA 2000 reader, or it cannot read them
        if isinstance(err, IngestError) and getattr(cfg, "strict", False):
            raise
        r = FileResult(path=file, format="signalk", frames={}, lines=0)
        why = (
            "no NMEA 2000 reader"
            if isinstance(err, ImportError)
            else str(err).replace(str(copy), file)
        )
        for i in rows[:5].tolist():
            r.rejects.add("n2k_unread", file, i + 1, raw_line(buf, start, end, i))
        r.rejects.counts["n2k_unread"] += max(0, n - 5)
        r.notes.append(f"{n} NMEA 2000 lines not read: {why}")
        return r
    take_off_blanks(r, len(start) - n)
    for df in r.frames.values():
        if len(df):
            lines = df["line"].to_numpy()
            have = df["recv_ns"].to_numpy()
            got = recv[np.clip(lines - 1, 0, len(recv) - 1)]
            df["recv_ns"] = np.where(have == MISSING_NS, got, have)
    return r


# --- comparison ------------------------------------------------------------------------


def _run(reader: Callable[..., FileResult], path: Path, cfg: IngestConfig):
    """(result, progress calls) of one read; (error text, None) where it raised."""
    told: list[int] = []
    try:
        return reader(path, cfg, told.append), told
    except IngestError as err:
        return str(err), None


def _assert_same(a: FileResult | str, b: FileResult | str) -> None:
    if isinstance(a, str) or isinstance(b, str):
        assert a == b
        return
    assert (a.path, a.format, a.lines) == (b.path, b.format, b.lines)
    assert list(a.frames) == list(b.frames)
    for kind in a.frames:
        pd.testing.assert_frame_equal(a.frames[kind], b.frames[kind], check_exact=True)
    assert list(a.rejects.counts.items()) == list(b.rejects.counts.items())
    assert a.rejects.examples == b.rejects.examples
    assert list(a.ignored.items()) == list(b.ignored.items())  # in their order too
    assert a.ignored_examples == b.ignored_examples
    assert a.notes == b.notes
    assert dataclasses.asdict(a.time_events) == dataclasses.asdict(b.time_events)


def _check(monkeypatch, new, old, path: Path, cfg: IngestConfig, sizes: tuple[int, ...]):
    """``new`` at the default chunk size and at each of ``sizes`` equals ``old``."""
    ref, ref_told = _run(old, path, cfg)
    got, told = _run(new, path, cfg)
    _assert_same(got, ref)
    assert told == ref_told
    for size in sizes:
        monkeypatch.setattr(chunks, "CHUNK_BYTES", size)
        got, told = _run(new, path, cfg)
        _assert_same(got, ref)
        assert told == ref_told, size
    monkeypatch.undo()
    return ref


def _over_a_line(path: Path) -> int:
    """One byte more than the file's first line with its line end (a cut mid-line next)."""
    data = path.read_bytes()
    return data.find(b"\n") + 2 if b"\n" in data else 2


# --- inputs ----------------------------------------------------------------------------

T0 = "2024-05-01T12:00:"


def _delta(i: int, ctx: str | None = "vessels.self") -> str:
    d: dict = {
        "updates": [
            {
                "$source": f"n2k.{i % 3}",
                "timestamp": f"{T0}{i % 60:02d}.{i % 1000:03d}Z",
                "values": [
                    {"path": "navigation.headingTrue", "value": (i % 628) / 100},
                    {"path": "navigation.speedOverGround", "value": (i % 90) / 10},
                    {"path": "navigation.courseOverGroundTrue", "value": (i % 600) / 100},
                    {"path": "environment.depth.belowTransducer", "value": 12.5},
                ],
            }
        ]
    }
    if i % 7 == 0:
        d["updates"][0]["values"].append(
            {"path": "navigation.position", "value": {"latitude": 57.0, "longitude": 11.9}}
        )
    if i % 11 == 0:
        del d["updates"][0]["timestamp"]
    if ctx is not None:
        d["context"] = ctx
    return json.dumps(d, separators=(",", ":"))


def _damage(rows: list[str], long_ok: str, too_long: str) -> list[str]:
    """``rows`` with bad, blank, CRLF and long lines spliced in (every 37th a kind)."""
    out: list[str] = []
    bad = ["{not json", "[1, 2]", "", "   ", "\x00\x01garbage", '{"updates": 3}']
    for i, r in enumerate(rows):
        out.append(r + ("\r" if i % 5 == 0 else ""))
        if i % 37 == 0:
            out.append(bad[(i // 37) % len(bad)])
        if i == 40:
            out.append(long_ok)  # longer than a 4 KiB chunk, shorter than max_line_bytes
        if i == 90:
            out.append(too_long)  # longer than max_line_bytes (+ the slack): cut
    return out


def _write(path: Path, rows: list[str], last_lf: bool) -> Path:
    path.write_bytes(("\n".join(rows) + ("\n" if last_lf else "")).encode())
    return path


CFG = IngestConfig(max_line_bytes=8192)  #: small, so a cut line is cheap to make


# --- the chunks ------------------------------------------------------------------------


@pytest.mark.parametrize("size", [1, 7, 100, 4096, 1 << 20])
def test_chunks_hold_every_line_whole_and_cut_only_those_too_long(tmp_path, size):
    rng = np.random.default_rng(size)
    lens = rng.choice([0, 1, 5, 80, 300, 5000, 9000, 20000], size=400)
    rows = [bytes(rng.integers(32, 127, n, dtype=np.uint8)) for n in lens]
    ends = rng.choice([b"\n", b"\r\n", b"\r\r\n"], size=len(rows))
    data = b"".join(r + e for r, e in zip(rows, ends, strict=True)) + b"tail\r"
    p = tmp_path / "lines.txt"
    p.write_bytes(data)
    buf = np.frombuffer(data, dtype=np.uint8)
    start, end, nxt = line_bounds(buf)
    max_line = 8192
    held = max_line + chunks.LINE_SLACK
    got: list[tuple[int, bytes, int, int, bool]] = []
    for ch in chunks.iter_line_chunks(p, max_line, size):
        assert len(ch.data) <= max(size, held + 2)  # bounded, whatever the lines
        assert ch.offset == (int(nxt[ch.line0 - 1]) if ch.line0 else 0)
        for i in range(len(ch.start)):
            if ch.cut is None:
                text = ch.data[ch.start[i] : ch.end[i]]
                e = ch.offset + int(ch.end[i])
            else:
                text, e = ch.data, ch.cut[0]
            x = ch.offset + int(ch.nxt[i])
            got.append((int(ch.numbers(np.array([i]))[0]), text, e, x, ch.cut is not None))
    assert [g[0] for g in got] == list(range(1, len(start) + 1))
    n_cut = 0
    for (_n, text, e, x, cut), s, e0, x0 in zip(got, start, end, nxt, strict=True):
        whole = data[s:e0]
        assert (e, x) == (e0, x0)
        if cut:  # only a line longer than what is held, and longer than the chunk
            assert len(whole) > max(held, size - 3) and text == whole[: held + 1]
            n_cut += 1
        else:
            assert text == whole
    assert n_cut == (0 if size > 30000 else int((lens == 20000).sum() + (lens == 9000).sum()))


# --- Signal K deltas -------------------------------------------------------------------


def _delta_rows(n: int) -> list[str]:
    hello = '{"name":"signalk-server","version":"2.8.0","self":"vessels.urn:mrn:signalk:uuid:a1"}'
    ctxs = [None, "vessels.self", "vessels.urn:mrn:signalk:uuid:a1", "vessels.urn:mrn:imo:mmsi:2"]
    return [hello] + [_delta(i, ctxs[i % 4]) for i in range(n)]


def _long_delta(nbytes: int) -> str:
    d = json.loads(_delta(3))
    vals = d["updates"][0]["values"]
    while len(json.dumps(d)) < nbytes:
        vals.append({"path": f"environment.pad.v{len(vals)}", "value": len(vals)})
    return json.dumps(d, separators=(",", ":"))


@pytest.mark.parametrize("ending", ["lf", "no_lf", "too_long_last_cr"])
def test_signalk_delta_streamed_equals_whole_file(tmp_path, monkeypatch, ending):
    rows = _damage(_delta_rows(400), _long_delta(6000), _long_delta(30000))
    if ending == "too_long_last_cr":
        rows.append(_long_delta(20000) + "\r")
    p = _write(tmp_path / "delta.log", rows, ending == "lf")
    ref = _check(
        monkeypatch, read_signalk_delta, old_read_signalk_delta, p, CFG, (4096, _over_a_line(p), 1)
    )
    assert isinstance(ref, FileResult)
    assert ref.rejects.counts["too_long"] == 1 + (ending == "too_long_last_cr")
    assert ref.rejects.counts["bad_json"] > 0 and ref.ignored["blank"] > 0
    assert len(ref.frames["heading"]) > 100
    strict = dataclasses.replace(CFG, strict=True)
    _check(monkeypatch, read_signalk_delta, old_read_signalk_delta, p, strict, (4096,))


# --- gpsd JSON -------------------------------------------------------------------------

CHK = [
    "ais-nmea.log.chk",
    "bundg_zeus_9.log.chk",
    "firefly-II.log.chk",
    "gpsdf.log.chk",
    "hemi.log.chk",
    "holux-gm-210.log.chk",
    "hp58534a.log.chk",
    "isync.log.chk",
    "nmea-fuzzy-cases.log.chk",
    "pypilot.log.chk",
    "skytraq-PX1172RH_DS.log.chk",
    "sounder.log.chk",
    "st-teseo-liv4f.log.chk",
    "triton400.log.chk",
]


@pytest.mark.parametrize("name", CHK)
def test_gpsd_real_chk_streamed_equals_whole_file(monkeypatch, name):
    p = real_path("gpsd", name)
    _check(
        monkeypatch, read_gpsd_json, old_read_gpsd_json, p, IngestConfig(), (4096, _over_a_line(p))
    )


@pytest.mark.parametrize("last_lf", [True, False])
def test_gpsd_generated_streamed_equals_whole_file(tmp_path, monkeypatch, last_lf):
    real = real_path("gpsd", "bundg_zeus_9.log.chk").read_text().splitlines()[:1500]
    sky = {"class": "SKY", "device": "/dev/ttyS0", "satellites": []}
    while len(json.dumps(sky)) < 6000:
        sky["satellites"].append({"PRN": len(sky["satellites"]), "el": 10, "az": 20, "ss": 30})
    rows = _damage(real, json.dumps(sky), '{"class":"TPV","x":"' + "y" * 30000 + '"}')
    rows.insert(200, "$GPGGA," + "1" * 20000 + "*00")  # an NMEA line too long: copied whole
    p = _write(tmp_path / "gpsd.log.chk", rows, last_lf)
    ref = _check(
        monkeypatch, read_gpsd_json, old_read_gpsd_json, p, CFG, (4096, _over_a_line(p), 1)
    )
    assert isinstance(ref, FileResult)
    assert ref.rejects.counts["too_long"] >= 2 and len(ref.frames["position"]) > 100


def test_gpsd_json_only_counts_its_blanks(tmp_path, monkeypatch):
    real = real_path("gpsd", "hemi.log.chk").read_text().splitlines()
    rows = [ln for ln in real if ln.startswith("{")]
    rows[10:10] = ["", "\r", ""]
    p = _write(tmp_path / "gpspipe.json", rows, True)
    ref = _check(monkeypatch, read_gpsd_json, old_read_gpsd_json, p, CFG, (4096, 1))
    assert isinstance(ref, FileResult) and ref.ignored["blank"] == 3


# --- Signal K server data logs -----------------------------------------------------------


def _mux_rows() -> list[str]:
    plaka = real_path("signalk-server", "plaka.log").read_text().splitlines()[:2500]
    aava = real_path("signalk-server", "aava-n2k.data").read_text().splitlines()[:2500]
    deltas = _delta_rows(600)
    rows, ms = [], 1408129200000
    for i in range(2500):
        ms += 7
        rows.append(f"{ms};N;{plaka[i].strip()}")
        rows.append(f"{ms + 1};A;{aava[i]}")
        if i % 4 == 0:
            rows.append(f"{ms + 2};I;{deltas[i // 4 % len(deltas)]}")
        if i % 97 == 0:
            rows.append(f"{ms + 3};X;what dracc does not read {i}")
        if i % 131 == 0:
            rows.append(plaka[i + 1].strip())  # not multiplexed: read as NMEA 0183
        if i % 151 == 0:
            rows.append(f"{ms + 4};q;{i}")
    return rows


@pytest.mark.parametrize("ending", ["lf", "no_lf"])
def test_signalk_mux_streamed_equals_whole_file(tmp_path, monkeypatch, ending):
    rows = _damage(
        _mux_rows(), "1408129300000;I;" + _long_delta(6000), "1408129300000;A;" + "1," * 15000
    )
    for at, letter in ((300, "N"), (700, "I"), (900, "X"), (1100, "A")):
        rows.insert(at, f"1408129300000;{letter};" + "$GPGGA,7" * 2000)  # too long
    p = _write(tmp_path / "skserver-raw_2014-08-15T19.log", rows, ending == "lf")
    ref = _check(monkeypatch, read_signalk, old_read_signalk, p, CFG, (4096, _over_a_line(p), 1))
    assert isinstance(ref, FileResult)
    assert {"position", "heading", "ground"} <= set(ref.frames)
    assert ref.ignored["signalk X"] > 10 and ref.rejects.counts["too_long"] >= 2
    a_lines = [i for i, r in enumerate(rows, 1) if r.split(";")[1:2] == ["A"]]
    h = ref.frames["heading"]
    n2k = h[h["line"].isin(a_lines)]
    assert len(n2k) > 50
    assert (n2k["recv_ns"] != MISSING_NS).all()  # the NMEA 2000 rows take their line's time


def test_signalk_logs_of_one_kind_stream_alike(tmp_path, monkeypatch):
    rows = _mux_rows()
    for letters, name in (("N", "nmea.log"), ("Xq", "other.log"), ("IA", "no0183.log")):
        keep = [r for r in rows if r.split(";")[1:2] and r.split(";")[1] in letters]
        keep[5:5] = ["", "\r"]
        p = _write(tmp_path / name, keep, True)
        _check(monkeypatch, read_signalk, old_read_signalk, p, CFG, (4096,))


def test_signalk_unreadable_nmea2000_streamed_alike(tmp_path, monkeypatch):
    import dracc.ingest.n2k as n2k

    def refuse(path, cfg, progress=None):
        raise IngestError(f"{path}: not NMEA 2000")

    p = _write(tmp_path / "mux.log", _mux_rows()[:3000], True)
    monkeypatch.setattr(n2k, "read_n2k", refuse)
    ref, ref_told = _run(old_read_signalk, p, CFG)
    assert isinstance(ref, FileResult) and ref.rejects.counts["n2k_unread"] > 1000
    monkeypatch.setattr(chunks, "CHUNK_BYTES", 4096)
    got, told = _run(read_signalk, p, CFG)
    _assert_same(got, ref)
    assert told == ref_told
