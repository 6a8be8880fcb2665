"""Actisense binary NMEA 2000 logs (dracc.ingest.n2k.ebl): the bare NGT-1 byte stream
and EBL files -- every valid frame read, each with its own time (the gateway's
millisecond timer of its BST 0x93 message), DLE unstuffing and checksums, a damaged
frame one reject with its byte offset.

The oracle is canboat: ``ydnu02-ev1-head.dle`` is the first 24 KiB of canboat's
``samples/ydnu-02-raymarine-ev1.dle`` (a YDNU-02 gateway in NGT-1 mode on a Raymarine
EV-1 autopilot bus); canboat's text twin of the whole capture, ``raymarine-ev1.raw``, is
``actisense-serial -r`` of those bytes, and its first 913 lines are the 913 messages of
the head, decoded by ``analyzer -json`` into ``ydnu02-ev1-head.canboat.json``.  On the
whole capture (not kept here) dracc reads 23 795 messages, each equal to the twin's line
(PGN, source, destination, priority, data), where it read 21 125 before (11 % lost).
The twin's times are the wall clock of the machine that replayed the file (actisense-serial
skips the gateway timer), so the time oracle is the timer bytes themselves, read by a
plain split of the undamaged stream; speed through water, position and COG/SOG, which
this bus lacks, come from canboat's susteranna NGT-1 text framed back into NGT-1 bytes.
"""

from __future__ import annotations

import re
from datetime import datetime

import numpy as np

from dracc.core.config import IngestConfig
from dracc.ingest.n2k.ebl import frames, message_times, parse_ebl, unwrap_timer
from dracc.ingest.n2k.formats import parse_n2k, sniff_n2k
from dracc.ingest.n2k.messages import TIME_NONE, TIME_RELATIVE, TIME_UTC
from dracc.ingest.n2k.reader import n2k_result, read_n2k
from tests.conftest import real_path
from tests.n2k_reference import DATA, check_fields, check_messages, load

HEAD = DATA / "ydnu02-ev1-head.dle"
DLE_STX, DLE_ETX = b"\x10\x02", b"\x10\x03"


def _timers(raw: bytes) -> list[int]:
    """The time (ms) of every message of an undamaged stream, by a plain split: the 4-byte
    timer of a 0x93 frame; a 0x94 or 0xA0 frame has none and takes the one before it."""
    out: list[int] = []
    for part in raw.split(DLE_ETX + DLE_STX):
        body = part.replace(b"\x10\x10", b"\x10")
        if body[:1] == b"\x93" and len(body) >= 12:
            out.append(int.from_bytes(body[8:12], "little"))
        elif body[:1] in (b"\x94", b"\xa0") and out:
            out.append(out[-1])
    return out


def ngt1_frame(prio: int, pgn: int, dst: int, src: int, timer_ms: int, data: bytes) -> bytes:
    """One received message (BST 0x93) as an NGT-1 sends it: DLE doubled, checksummed."""
    body = bytes([0x93, 11 + len(data), prio, pgn & 255, pgn >> 8 & 255, pgn >> 16, dst, src])
    body += timer_ms.to_bytes(4, "little") + bytes([len(data)]) + data
    body += bytes([-sum(body) & 0xFF])
    return DLE_STX + body.replace(b"\x10", b"\x10\x10") + DLE_ETX


def test_ngt1_stream_reads_every_frame_canboat_reads():
    raw = HEAD.read_bytes()
    assert sniff_n2k(raw) == "n2k-ngt1"
    msgs = parse_n2k(raw, "n2k-ngt1")
    check_messages(msgs, load("ydnu02-ev1-head.canboat.json"))
    # the capture starts with the DLE ETX of a frame it missed, and the head ends inside one
    assert msgs.rejects == {"ngt1_framing": 2}
    first, last = msgs.examples["ngt1_framing"]
    assert first == (1, "byte 0: 10 03")
    assert last[1].startswith(f"byte {raw.rindex(DLE_STX)}: 93 13")


def test_esc_byte_is_data_in_a_bare_ngt1_stream():
    """Regression: ESC (0x1B) was read as an escape as in EBL files, and every frame
    holding one was lost with the frames after it (the ``ebl_framing`` rejects)."""
    raw = HEAD.read_bytes()
    with_esc = sum(b"\x1b" in part for part in raw.split(DLE_ETX + DLE_STX))
    assert with_esc >= 5
    msgs = parse_n2k(raw, "n2k-ngt1")
    assert len(msgs) == 913
    assert "ebl_framing" not in msgs.rejects
    # read as EBL framing, the same bytes lose frames: the defect
    assert len(parse_ebl(raw)) < 913


def test_ngt1_times_are_the_gateway_timer():
    raw = HEAD.read_bytes()
    msgs = parse_n2k(raw, "n2k-ngt1")
    assert msgs.time_kind == TIME_RELATIVE
    assert msgs.time_ns.tolist() == [t * 1_000_000 for t in _timers(raw)]
    assert msgs.time_ns[0] == 679_345_000_000  # b1 5d 0a 00
    assert len(np.unique(msgs.time_ns)) > 600  # not one instant


def test_ngt1_heading_and_rate_of_turn_equal_canboat():
    msgs = parse_n2k(HEAD.read_bytes(), "n2k-ngt1")
    res = n2k_result(msgs, str(HEAD), "n2k-ngt1", IngestConfig())
    compared = check_fields(msgs, res.frames, load("ydnu02-ev1-head.canboat.json"))
    assert compared == {127250: 97, 127251: 97}  # every one canboat decodes
    assert not res.clockless and res.rejects.total == 2


def test_a_damaged_frame_is_one_reject_and_the_next_frame_is_found():
    raw = HEAD.read_bytes()
    # where each frame starts (DLE STX after the DLE ETX of the one before): message k
    # is frame k here, as every frame of the head before its last is a message
    starts = [m.start() + 2 for m in re.finditer(re.escape(DLE_ETX + DLE_STX), raw)]
    k1, k2, k3 = starts[100], starts[300], starts[500]
    bad = bytearray(raw)
    bad[k1 + 9] ^= 0x01  # a data byte of frame 100 (its PGN): the checksum fails
    end2 = raw.index(DLE_ETX, k2 + 2)
    junk = b"\x42\x1b\x00\x55"
    # frame 300 loses its DLE ETX; junk lands between frames 499 and 500
    damaged = bytes(bad[:end2]) + bytes(bad[end2 + 2 : k3]) + junk + bytes(bad[k3:])
    msgs = parse_n2k(damaged, "n2k-ngt1")
    assert len(msgs) == 913 - 2
    assert msgs.rejects == {"ngt1_framing": 4, "checksum": 1}
    offsets = [int(t.split(":")[0].removeprefix("byte ")) for _, t in msgs.examples["ngt1_framing"]]
    assert offsets[1:3] == [k2, k3 - 2]  # the cut frame; the junk (2 bytes fewer before it)
    assert msgs.examples["checksum"][0][1].startswith(f"byte {k1}: 93")
    ref = load("ydnu02-ev1-head.canboat.json")
    check_messages(msgs, [r for k, r in enumerate(ref) if k not in (100, 300)])


def test_susteranna_messages_through_ngt1_frames_equal_canboat():
    """canboat's ``susteranna-actisense-serial.raw`` (an NGT-1 read by actisense-serial,
    first 450 lines) framed back into the bytes an NGT-1 sends, its PC times as the
    gateway timer: dracc reads every message with that time, and decodes heading, rate
    of turn, speed through water, position and COG/SOG as canboat's analyzer does."""
    lines = (DATA / "susteranna-actisense-serial-450.raw").read_text().splitlines()
    rows = [line.split(",") for line in lines]
    rows = [r for r in rows if int(r[5]) > 0]  # canboat's text form cannot hold no data
    t0 = datetime.fromisoformat(rows[0][0]).timestamp()
    ms = [round((datetime.fromisoformat(r[0]).timestamp() - t0) * 1000) + 5_000 for r in rows]
    raw = b"".join(
        ngt1_frame(int(r[1]), int(r[2]), int(r[4]), int(r[3]), t, bytes.fromhex("".join(r[6:])))
        for r, t in zip(rows, ms, strict=True)
    )
    assert raw.count(b"\x10\x10") > 30  # DLE stuffing exercised
    assert sniff_n2k(raw) == "n2k-ngt1"
    msgs = parse_n2k(raw, "n2k-ngt1")
    assert not msgs.rejects
    assert msgs.time_ns.tolist() == [t * 1_000_000 for t in ms]
    ref = load("susteranna-450.canboat.json")
    keep = [k for k, r in enumerate(ref) if r[0] < 1 << 18]
    check_messages(msgs.select(np.array(keep)), [ref[k] for k in keep])
    res = n2k_result(msgs, "x.dle", "n2k-ngt1", IngestConfig())
    compared = check_fields(msgs, res.frames, ref)
    assert set(compared) == {127250, 127251, 128259, 129025, 129026, 129029}
    # put on UTC by the log's own 126992/129029 times: the PC times to within 1 s
    first = int(res.frames["heading"]["time_ns"].min())
    assert abs(first / 1e9 - datetime.fromisoformat(lines[3].split(",")[0]).timestamp()) < 1.0


def test_ebl_times_are_the_gateway_timer_on_utc():
    path = real_path("canboat", "actisense-523.rx.ebl")
    raw = path.read_bytes()
    msgs = parse_n2k(raw, "n2k-ebl")
    assert msgs.time_kind == TIME_UTC
    # the PC's FILETIME before each message, as canboat gives it
    pc, stamps = -1, []
    timer = []
    for kind, _, body in frames(raw, ebl=True):
        if kind == "header" and body[0] == 3:
            pc = (int.from_bytes(body[1:9], "little") - 116_444_736_000_000_000) // 10_000
        elif kind == "message" and body[0] in (0x93, 0x94, 0xA0):
            stamps.append(pc)
            timer.append(int.from_bytes(body[8:12], "little") if body[0] == 0x93 else -1)
    stamps_a, timer_a = np.array(stamps), np.array(timer)
    t_ms = msgs.time_ns // 1_000_000
    got = timer_a >= 0
    late = stamps_a - t_ms
    assert late.min() >= 0 and late.max() < 100  # the PC stamps after the gateway
    # between messages, exactly the gateway's own intervals
    assert np.array_equal(np.diff(t_ms[got]), np.diff(timer_a[got]))


def test_filetime_envelope_follows_a_drifting_pc_clock():
    """EBL: the PC stamps each batch 0-300 ms after the gateway timed its messages, and
    the two clocks drift apart 50 ppm over two hours (360 ms): the gateway times put on
    UTC follow the drift and stay within 30 ms of the truth."""
    rng = np.random.default_rng(7)
    timer = np.arange(0, 7_200_000, 250, dtype=np.int64) + 1_000_000
    utc = 1_700_000_000_000 + (timer - timer[0]) + (timer - timer[0]) * 50 // 1_000_000
    pc = utc + rng.integers(0, 300, len(timer))
    t, kind = message_times(timer, pc)
    assert kind == TIME_UTC
    assert np.abs(t // 1_000_000 - utc).max() < 30


def test_timer_wraps_and_restarts():
    t = np.array([2**32 - 20, 2**32 - 10, 5, 15, 100_000, 1_000, 1_010])
    dev, run = unwrap_timer(t)
    assert dev.tolist()[:5] == [2**32 - 20, 2**32 - 10, 2**32 + 5, 2**32 + 15, 2**32 + 100_000]
    assert run.tolist() == [0, 0, 0, 0, 0, 1, 1]
    assert dev[5] == dev[4] and dev[6] == dev[4] + 10  # a restart continues the time


def test_a_gateway_restart_is_a_note_and_keeps_the_order():
    data = bytes([0xFF, 0x4B, 0xED, 0xFF, 0x7F, 0xFF, 0x7F, 0xFD])
    timers = [500_000, 500_100, 200, 300]  # the gateway restarted after the second
    raw = b"".join(ngt1_frame(2, 127250, 255, 204, t, data) for t in timers)
    msgs = parse_n2k(raw, "n2k-ngt1")
    assert (msgs.time_ns // 1_000_000).tolist() == [500_000, 500_100, 500_100, 500_200]
    assert any("restarted 1 times" in n for n in msgs.notes)
    res = n2k_result(msgs, "x.dle", "n2k-ngt1", IngestConfig())
    assert any("restarted 1 times" in n for n in res.notes)


def test_other_bst_traffic_is_counted_as_ignored():
    command = bytes([0xA1, 3, 0x11, 0x02, 0x00])  # a command to the NGT, not a bus message
    command += bytes([-sum(command) & 0xFF])
    data = bytes([0xFF, 0x4B, 0xED, 0xFF, 0x7F, 0xFF, 0x7F, 0xFD])
    raw = ngt1_frame(2, 127250, 255, 204, 100, data) + DLE_STX + command + DLE_ETX
    raw += ngt1_frame(2, 127250, 255, 204, 200, data)
    msgs = parse_n2k(raw, "n2k-ngt1")
    assert len(msgs) == 2 and msgs.rejects == {"ignored_bst_command": 1}
    res = n2k_result(msgs, "x.dle", "n2k-ngt1", IngestConfig())
    assert res.ignored["bst command"] == 1 and res.rejects.total == 0


def test_frames_without_timer_or_filetime_have_no_clock():
    sent = bytes([0x94, 6 + 8, 2, 0x12, 0xF1, 0x01, 255, 8]) + bytes(8)
    sent += bytes([-sum(sent) & 0xFF])
    raw = (DLE_STX + sent.replace(b"\x10", b"\x10\x10") + DLE_ETX) * 3
    msgs = parse_n2k(raw, "n2k-ngt1")
    assert len(msgs) == 3 and msgs.time_kind == TIME_NONE


def test_read_ngt1_file_keeps_its_clock():
    res = read_n2k(HEAD, IngestConfig())
    assert res.format == "n2k-ngt1" and not res.clockless
    t = res.frames["heading"]["time_ns"].to_numpy()
    assert len(t) == 97 and np.all(np.diff(t) > 0)
