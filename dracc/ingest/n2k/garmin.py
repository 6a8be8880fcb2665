"""Garmin chartplotter NMEA 2000 logs (a GPSMAP's "NMEA 2000 log" CSV), in the two forms
canboat's analyzer reads (its GARMIN_CSV1 and GARMIN_CSV2), one whole message a row::

    Sequence #,Timestamp,PGN,Name,Manufacturer,Remote Address,Local Address,Priority,Single Frame,Size,Packet
    0,486942,127508,Battery Status,Garmin,6,255,2,1,8,0x017505FF7FFFFFFF

    Sequence #,Month_Day_Year_Hours_Minutes_Seconds_msTicks,PGN,Processed PGN,Name,Manufacturer,...
    0,6_21_2015_16_11_14_24931648,127508,Processed,Battery Status,Unknown Manufacturer,6,255,2,1,8,0x01...

``Remote Address`` is the source, ``Local Address`` the destination; ``Packet`` the
payload bytes in order (fast packets already joined, ``Size`` of them).  The six last
columns are read from the end of the row, so a comma inside a name does no harm.

Times.  CSV1's ``Timestamp`` is the plotter's millisecond counter since it started:
relative times (put on UTC by the log's 126992/129029 times, :mod:`.reader`).  CSV2
gives the plotter's clock to the second (``6_21_2015_16_11_14``, month first) and the
same millisecond counter (``24931648``): the counter times every row, and is put on the
clock by the offset every row's whole second allows (the clock second of a row is the
floor of its time), the middle of the stretch of offsets the most rows allow.  canboat's sample (GPSMAP 820 beside a
GPSMAP 4008 on one bus, 2015-06-21) shows the clock is UTC: its first row is 16:11:14,
the 4008's 129029 time of fix at that moment 16:11:14.039.  Where some rows' clock
seconds do not fit that offset (that plotter's clock stood still for 10 s, then ran half
a second off its counter) a note says how many and by how much; the counter, which never
stood still, keeps the intervals.

A row that is not such a row is rejected as ``garmin_csv_line`` (``garmin_csv_size``
where ``Size`` and the packet's bytes disagree); the header line is counted as ignored.
"""

from __future__ import annotations

import numpy as np

from dracc.ingest.n2k.fastpacket import MAX_FAST_LENGTH, rows_to_messages
from dracc.ingest.n2k.messages import TIME_RELATIVE, TIME_UTC, Messages, add_reject
from dracc.ingest.n2k.textscan import Lines

CSV1_COLUMNS = (
    "Sequence #,Timestamp,PGN,Name,Manufacturer,Remote Address,Local Address,Priority,"
    "Single Frame,Size,Packet"
)
CSV2_COLUMNS = (
    "Sequence #,Month_Day_Year_Hours_Minutes_Seconds_msTicks,PGN,Processed PGN,Name,"
    "Manufacturer,Remote Address,Local Address,Priority,Single Frame,Size,Packet"
)
#: form -> its header's column names (lower case)
HEADERS = {
    form: tuple(c.lower() for c in cols.split(","))
    for form, cols in (("csv1", CSV1_COLUMNS), ("csv2", CSV2_COLUMNS))
}
#: PGNs are 18 bits
MAX_PGN = (1 << 18) - 1
#: a millisecond counter at or above this (35 years) is no counter
MAX_TICKS = 1 << 40


def garmin_form(line: str) -> str | None:
    """ "csv1" or "csv2" if ``line`` is the header of that Garmin form, else None."""
    cols = tuple(c.strip().lower() for c in line.lstrip("\ufeff").strip().split(","))
    for form, want in HEADERS.items():
        if cols == want:
            return form
    return None


def parse_garmin_csv(lines: Lines, form: str) -> Messages:
    """Messages of a Garmin CSV log of ``form`` ("csv1" or "csv2")."""
    absolute = form == "csv2"
    width = len(HEADERS[form])
    cols: list[list[int]] = [[] for _ in range(7)]  # line prio pgn src dst ticks clock_ms
    data: list[bytes] = []
    bad: dict[str, list[int]] = {}
    headers: list[int] = []
    for i in range(len(lines.start)):
        text = lines.text(i).lstrip("\ufeff")
        if garmin_form(text) is not None:
            headers.append(i)
            continue
        got = _row(text, width, absolute)
        if isinstance(got, str):
            bad.setdefault(got, []).append(i)
            continue
        for col, v in zip(cols, (int(lines.number[i]), *got[:6]), strict=True):
            col.append(v)
        data.append(got[6])
    line, prio, pgn, src, dst, ticks, clock = (np.array(c, dtype=np.int64) for c in cols)
    notes: list[str] = []
    if absolute:
        t_ms, notes = _on_the_clock(ticks, clock)
        kind = TIME_UTC
    else:
        t_ms, kind = ticks, TIME_RELATIVE
    msgs = rows_to_messages(
        t_ms * 1_000_000,
        line,
        prio,
        pgn,
        src,
        dst,
        np.array([len(d) for d in data], dtype=np.int64),
        np.frombuffer(b"".join(data), dtype=np.uint8),
        kind,
        reassemble_fast=False,
    )
    msgs.notes = notes
    for reason, rows in bad.items():
        ex = [(int(lines.number[i]), lines.text(i)) for i in rows[:5]]
        add_reject(msgs, reason, len(rows), ex)
    ex = [(int(lines.number[i]), lines.text(i)) for i in headers[:1]]
    add_reject(msgs, "ignored_csv_header", len(headers), ex)
    return msgs


def _row(text: str, width: int, absolute: bool) -> tuple[int, int, int, int, int, int, bytes] | str:
    """(prio, pgn, src, dst, ms counter, clock ms or -1, data) of one row, or the reason
    it is rejected."""
    f = text.rstrip().split(",")
    if len(f) < width:
        return "garmin_csv_line"
    try:
        pgn = int(f[2])
        src, dst, prio, _single, size = (int(x) for x in f[-6:-1])
        packet = f[-1].strip()
        if packet[:2] in ("0x", "0X"):
            packet = packet[2:]
        body = bytes.fromhex(packet)
        clock = -1
        if absolute:
            month, day, year, hour, minute, second, ticks = (int(x) for x in f[1].split("_"))
            clock = _clock_ms(year, month, day, hour, minute, second)
        else:
            ticks = int(f[1])
    except ValueError:
        return "garmin_csv_line"
    if not (0 <= pgn <= MAX_PGN and 0 <= prio <= 7 and 0 <= src <= 255 and 0 <= dst <= 255):
        return "garmin_csv_line"
    if not 0 <= ticks < MAX_TICKS or (absolute and clock < 0):
        return "garmin_csv_line"
    if size != len(body) or size > MAX_FAST_LENGTH:
        return "garmin_csv_size"
    return prio, pgn, src, dst, ticks, clock, body


def _clock_ms(year: int, month: int, day: int, hour: int, minute: int, second: int) -> int:
    """Unix ms of a clock reading; -1 where it is no valid time."""
    if not (1980 <= year <= 2200 and 1 <= month <= 12 and 1 <= day <= 31):
        return -1
    if not (0 <= hour < 24 and 0 <= minute < 60 and 0 <= second < 61):
        return -1
    try:
        days = int(np.datetime64(f"{year:04d}-{month:02d}-{day:02d}", "D").astype(np.int64))
    except ValueError:
        return -1
    return ((days * 24 + hour) * 60 + minute) * 60_000 + second * 1000


def _on_the_clock(ticks: np.ndarray, clock: np.ndarray) -> tuple[np.ndarray, list[str]]:
    """Unix ms of every row from its ms counter and its clock second (see the module
    docstring), and a note on how well the two agree."""
    if len(ticks) == 0:
        return ticks, []
    # a row allows the offsets [clock - ticks, clock - ticks + 1000): the offset most rows
    # allow, the middle of that stretch (a sweep over the stretches' ends)
    lo = clock - ticks
    edge = np.concatenate([lo, lo + 1000])
    step = np.concatenate([np.ones(len(lo), np.int64), -np.ones(len(lo), np.int64)])
    order = np.lexsort((step, edge))  # at one value an end before a start
    edge, cover = edge[order], np.cumsum(step[order])
    best = int(np.argmax(cover))
    offset = (int(edge[best]) + int(edge[best + 1])) // 2
    t = ticks + offset
    off_s = np.abs(t // 1000 * 1000 - clock) / 1000
    agree = int(np.sum(off_s == 0))
    note = (
        f"Garmin CSV times: the plotter's millisecond counter put on its clock (taken as "
        f"UTC) to within {(int(edge[best + 1]) - int(edge[best])) / 2:.0f} ms"
    )
    if agree < len(t):
        note += (
            f"; {len(t) - agree} of {len(t)} rows' clock seconds differ from it, by up to "
            f"{float(off_s.max()):.0f} s (a clock that stopped or was set during the log)"
        )
    return t, [note]
