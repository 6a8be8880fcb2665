"""The NMEA 2000 reader: a log file sniffed, parsed into :class:`Messages`, decoded
(:mod:`dracc.ingest.n2k.pgns`), its sources named by their address claims
(:mod:`dracc.ingest.n2k.names`) and its times put on UTC.

Times (``Messages.time_kind``):

* ``utc``: as the log gives them (a log whose times lie before 2000, a logger without a
  clock, is taken as relative times, and is clockless);
* ``none``: the log has no clock (a candump without times, ``$MXPGN``, a log whose every
  message has the same time): it is *clockless*, its messages are timed by their order,
  one millisecond apart, and ``FileResult.clockless`` says no latency, rate or time
  finding may be drawn from them (the notes say :data:`NO_CLOCK_NOTE`);
* ``time_of_day`` / ``relative``: anchored to UTC by the offset ``median(UTC time -
  frame time)`` over the PGN 126992 system times and PGN 129029 times of fix of the log;
  with neither, placed on the date of ``--date`` / ``ingest.date``, else on the assumed
  date of :mod:`dracc.ingest.timebase` (a note says so).  Times of day are unwrapped at
  midnight first (a drop of more than 12 h is a new day).

A 129029 record carries its own time of fix: its ``time_ns`` is that (where the message
has a valid date and time) and its ``recv_ns`` the frame time, as a GGA with a TAG block
time (:mod:`dracc.frames`).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd

from dracc.core.errors import IngestError
from dracc.frames import (
    MISSING_NS,
    REFERENCE_DTYPE,
    FileResult,
    Rejects,
    TimeEvents,
    concat_blocks,
    make_frame,
)
from dracc.ingest.n2k.formats import SNIFF_BYTES, check_one_form, parse_n2k, sniff_n2k
from dracc.ingest.n2k.messages import TIME_NONE, TIME_OF_DAY, TIME_UTC, Messages
from dracc.ingest.n2k.names import source_keys
from dracc.ingest.n2k.pgns import DAY_NS, Decoded, decode
from dracc.ingest.nmea import check_readable
from dracc.ingest.timebase import (
    ASSUMED_DATE,
    ASSUMED_DATE_DAYS,
    ASSUMED_DATE_NOTE,
    count_events,
    days_from_civil,
    drop_implausible_ext,
    valid_civil,
)

if TYPE_CHECKING:  # config imports ingest.frames: no runtime import here
    from dracc.core.config import IngestConfig

HALF_DAY_NS = DAY_NS // 2
EPOCH_2000_NS = 10957 * DAY_NS  #: 2000-01-01: a UTC log time before it is no clock time
#: what the notes of a log without a clock say
NO_CLOCK_NOTE = "no clock: times are the order of the records"
#: the time between two messages of a log without a clock: their order, nothing more
ORDER_STEP_NS = 1_000_000


#: a ``Messages.rejects`` reason with this prefix counts valid lines that carry no
#: message (iKonvert's ``$PDGY,000000`` status lines): ignored, not rejected
IGNORED_PREFIX = "ignored_"


def cfg_date_days(cfg: IngestConfig) -> int | None:
    """``cfg.date`` (YYYY-MM-DD) as days since the epoch; IngestError where malformed."""
    if cfg.date is None:
        return None
    try:
        y, m, d = (int(x) for x in cfg.date.split("-"))
        if not valid_civil(y, m, d):
            raise ValueError
    except ValueError as err:
        raise IngestError(f"--date {cfg.date!r}: expected YYYY-MM-DD") from err
    return int(days_from_civil(y, m, d))


def resolve_times(
    msgs: Messages, dec: Decoded, date_days: int | None
) -> tuple[np.ndarray, list[str]]:
    """UTC ns of every message (see the module docstring) and notes on what was decided."""
    t = msgs.time_ns.astype(np.int64, copy=True)
    kind = msgs.time_kind
    notes: list[str] = []
    if len(t) == 0:
        return t, notes
    if kind == TIME_NONE:
        notes.append(NO_CLOCK_NOTE)
        t = np.arange(len(t), dtype=np.int64) * ORDER_STEP_NS
        kind = "relative"
    if kind == TIME_UTC:
        if np.median(t) >= EPOCH_2000_NS:
            return t, notes
        notes += [
            "NMEA 2000 log times before 2000 (a logger without a clock): taken as relative",
            NO_CLOCK_NOTE,
        ]
        kind = "relative"
    if kind == TIME_OF_DAY:  # unwrap midnights: a drop of more than 12 h is a new day
        step = np.diff(t, prepend=t[0]) < -HALF_DAY_NS
        if step.any():
            t += np.cumsum(step) * DAY_NS
            notes.append(f"{int(step.sum())} midnight rollovers in the times of day")
    utc, _ = drop_implausible_ext(dec.clock_utc_ns)
    ok = utc != MISSING_NS
    if ok.any():
        off = utc[ok] - t[dec.clock_row[ok]]
        # the (lower) median in int64: a float64 has 256 ns steps at today's ns since 1970
        offset = int(np.sort(off)[(len(off) - 1) // 2])
        spread = float(np.percentile(np.abs(off - offset), 95)) / 1e9
        notes.append(
            f"NMEA 2000 {kind.replace('_', ' ')} times put on UTC by {int(ok.sum())} "
            f"PGN126992/129029 times (offset {offset / 1e9:.3f} s, 95 % within {spread:.3f} s)"
        )
        if kind == "relative":  # a device's timer (iKonvert, candump): its rate too
            t, note = _timer_rate(t, t[dec.clock_row[ok]], off - offset)
            notes.extend(note)
        return t + offset, notes
    days = date_days
    if days is None:
        days = ASSUMED_DATE_DAYS
        notes.append(
            ASSUMED_DATE_NOTE
            if kind == TIME_OF_DAY
            else f"no date or time of day in the log (relative times, no PGN126992/129029) "
            f"and none given: times counted from midnight of an assumed date, {ASSUMED_DATE} "
            "(pass --date YYYY-MM-DD for the real one)"
        )
    else:
        notes.append("no UTC time in the NMEA 2000 log: date taken from --date / ingest.date")
    if kind != TIME_OF_DAY:
        t = t - t.min()
    return t + days * DAY_NS, notes


def _timer_rate(
    t: np.ndarray, at: np.ndarray, resid_ns: np.ndarray
) -> tuple[np.ndarray, list[str]]:
    """A relative timer's rate against the UTC anchors: ``resid = UTC - (t + offset)``
    fitted as a line in ``t`` (least squares over the anchors within 5 s of the median);
    applied where it moves a time by more than 50 ms over the log (a device's RC
    oscillator runs a few per mille off: 4 s an hour), said in a note."""
    keep = np.abs(resid_ns - np.median(resid_ns)) < 5e9
    if keep.sum() < 10:
        return t, []
    x = (at[keep] - at[0]) / 1e9
    if x.max() - x.min() < 60.0:
        return t, []
    slope, icpt = np.polyfit(x, resid_ns[keep] / 1e9, 1)
    span_s = (t.max() - t.min()) / 1e9
    if abs(slope) * span_s < 0.05:
        return t, []
    fixed = t + np.rint((icpt + slope * (t - at[0]) / 1e9) * 1e9).astype(np.int64)
    fast = "fast" if slope < 0 else "slow"
    return fixed, [
        f"the log's timer runs {abs(slope) * 1e6:.0f} ppm {fast} against the "
        f"PGN126992/129029 times ({abs(slope) * span_s:.2f} s over the log): its times rescaled"
    ]


def _hex(msgs: Messages, row: int) -> str:
    s, n = int(msgs.start[row]), int(msgs.length[row])
    body = " ".join(f"{b:02X}" for b in msgs.payload[s : s + min(n, 32)].tolist())
    return f"PGN{int(msgs.pgn[row])} src {int(msgs.src[row])}: {body}"


def n2k_result(
    msgs: Messages, file: str, fmt: str, cfg: IngestConfig, lines: int | None = None
) -> FileResult:
    """Decode ``msgs`` (of the log ``file`` in format ``fmt``) into a :class:`FileResult`."""
    dec = decode(msgs)
    rejects = Rejects()
    skipped: dict[str, tuple[int, list[tuple[int, str]]]] = {}
    for reason, cnt in msgs.rejects.items():
        exs = msgs.examples.get(reason, [])
        if reason.startswith(IGNORED_PREFIX):  # valid lines that hold no message
            skipped[reason.removeprefix(IGNORED_PREFIX).replace("_", " ")] = (cnt, exs)
            continue
        rejects.counts[reason] += cnt
        for ln, text in exs:
            rejects.add(reason, file, ln, text, count=0)
    for reason, rows in dec.rejects.items():
        rejects.counts[reason] += len(rows)
        for r in np.sort(rows)[: rejects.max_examples].tolist():
            rejects.add(reason, file, int(msgs.line[r]), _hex(msgs, r), count=0)
    if cfg.strict and rejects.total:
        reason = next(iter(rejects.counts))
        ex = rejects.examples.get(reason, [(file, 0, "")])[0]
        raise IngestError(f"{file}:{ex[1]}: rejected ({reason}): {ex[2]}")
    t, notes = resolve_times(msgs, dec, cfg_date_days(cfg))
    codes, keys, name_notes = source_keys(msgs.src, dec.claim_row, dec.claim_name, msgs.line)
    frames: dict[str, pd.DataFrame] = {}
    for kind, parts in dec.parts.items():
        row = np.concatenate([p["row"] for p in parts])
        if not len(row):
            continue
        sent = [f"PGN{int(p['pgn'])}" for p in parts]
        scode = np.repeat(np.arange(len(parts)), [len(p["row"]) for p in parts])
        cols: dict[str, np.ndarray] = {
            c: np.concatenate([p[c] for p in parts])
            for c in parts[0]
            if c not in ("row", "pgn", "fix_ns")
        }
        time_ns = t[row]
        if kind == "position":
            fix, _ = drop_implausible_ext(np.concatenate([p["fix_ns"] for p in parts]))
            own = fix != MISSING_NS
            cols["recv_ns"] = np.where(own, time_ns, MISSING_NS)
            time_ns = np.where(own, fix, time_ns)
        if kind == "heading":
            cols["reference"] = pd.Categorical.from_codes(cols["reference"], dtype=REFERENCE_DTYPE)
        cols["time_ns"] = time_ns
        cols["line"] = msgs.line[row]
        cols["source"] = pd.Categorical.from_codes(codes[row], categories=keys)
        cols["sentence"] = pd.Categorical.from_codes(scode, categories=sent)
        cols["talker"] = pd.Categorical.from_codes(np.zeros(len(row), np.int8), categories=[""])
        frames[kind] = make_frame(kind, cols)
    frames = concat_blocks([frames])
    for df in frames.values():
        df["source"] = df["source"].cat.remove_unused_categories()
    # the time events are counted by the caller on the frames (read_n2k: count_events);
    # NMEA 2000 inside NMEA 0183 takes derived times (rule 3), never counted
    events = TimeEvents(decisions=list(notes))
    events.assumed_date = ASSUMED_DATE if any("assumed date" in n for n in notes) else None
    res = FileResult(
        path=file,
        format=fmt if fmt.startswith("n2k") else f"n2k-{fmt}",
        frames=frames,
        lines=int(lines) if lines is not None else len(msgs) + sum(msgs.rejects.values()),
        rejects=rejects,
        time_events=events,
        notes=msgs.notes + notes + dec.notes + name_notes,
        clockless=NO_CLOCK_NOTE in notes,
    )
    for key, (cnt, exs) in skipped.items():
        res.ignored[key] = cnt
        res.ignored_examples[key] = [(file, ln, text) for ln, text in exs[:5]]
    for key, cnt in sorted(dec.ignored.items()):
        res.ignored[key] = cnt
        r = dec.ignored_first[key]
        res.ignored_examples[key] = [(file, int(msgs.line[r]), _hex(msgs, r))]
    return res


def _line_count(data: bytes) -> int | None:
    """Lines of a text log; None for a binary one (EBL: its records are counted)."""
    if b"\x00" in data[:4096] or (data[:1] and data[0] > 0x7E):
        return None
    return data.count(b"\n") + (1 if data and not data.endswith(b"\n") else 0)


def read_n2k(
    path: str | Path, cfg: IngestConfig, progress: Callable[[int], object] | None = None
) -> FileResult:
    """Read a whole NMEA 2000 log (any format :func:`sniff_n2k` knows) into a FileResult."""
    path = Path(path)
    check_readable(path)
    data = path.read_bytes()
    fmt = sniff_n2k(data[:SNIFF_BYTES])
    if fmt is None:
        raise IngestError(f"{path}: not an NMEA 2000 log in a format dracc reads")
    msgs = parse_n2k(data, fmt)
    if msgs.rejects:  # lines not of its form: maybe of another (MixedForms)
        check_one_form(data, fmt, int(cfg.max_line_bytes))
    if len(msgs) > 1 and msgs.time_kind != TIME_NONE and msgs.time_ns.min() == msgs.time_ns.max():
        msgs.time_kind = TIME_NONE  # times that never advance are no clock
    res = n2k_result(msgs, str(path), fmt, cfg, _line_count(data))
    ev = count_events(res, cfg.gap_s, cfg.backstep_tolerance_s)
    res.notes.extend(f"{k}: {v}" for k, v in ev.per_source.items() if v["backsteps"] or v["gaps"])
    if progress is not None:
        progress(len(data))
    return res
