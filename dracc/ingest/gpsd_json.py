"""gpsd JSON (``gpspipe -w``): TPV and ATT reports into canonical frames.

One JSON object a line, its ``class`` first (gpsd_json(5)):

* ``TPV`` (time, position, velocity): ``time`` (ISO 8601 UTC, or Unix seconds in old
  gpsd), ``lat``/``lon`` (degrees), ``altMSL`` (else ``alt``, else ``altHAE`` minus
  ``geoidSep``: the altitude above the geoid, as GGA gives it), ``track`` (degrees true)
  and ``speed`` (m/s), ``mode`` (0 unknown, 1 no fix, 2 2D, 3 3D) and ``status``.  The
  quality is 0 for mode 0/1; for a fix, the GGA quality the status stands for (DGPS 2,
  RTK fixed 4, RTK float 5, dead reckoning 6, surveyed 7, simulated 8; 1 otherwise).
  gpsd sends several TPVs per epoch as an NMEA receiver dribbles its sentences in; a run
  of TPVs of one device with one ``time`` is one record (each field its last value in
  the run; the line that of the run's last TPV), the others counted as ignored
  (``gpsd TPV repeat``).  A TPV without a time is counted (``gpsd TPV without time``),
  as is one without position, track or speed (``gpsd TPV without fix``).  Track and
  speed are what gpsd reports: where an epoch closes before the receiver's RMC/VTG,
  gpsd gives a track from the heading (HDG plus variation) and a speed from successive
  fixes (bundg_zeus_9: about one epoch in five), which dracc cannot tell apart.
* ``ATT`` (attitude): ``heading`` (degrees true), ``mheading`` (degrees magnetic),
  ``rot`` (degrees per minute).  ATT is synchronous to the GNSS epoch: one without its
  own ``time`` takes the time of the last TPV of its device before it.  gpsd repeats the
  epoch's attitude in each report of the epoch: a run of equal ATTs is one record
  (``gpsd ATT repeat``).
* Every other class (VERSION, DEVICES, WATCH, SKY, GST, AIS, TOFF, PPS, IMU ...) is
  counted as ignored by class (``gpsd SKY``).

The source key is the report's ``device`` (``/dev/ttyUSB0``), else ``gpsd``.  A line
that is not JSON is rejected (``bad_json``), JSON without a class ``not_gpsd``.

gpsfake ``.chk`` files (gpsd's regression expectations) interleave the NMEA sentences
gpsd read with the JSON it made of them.  Both are read: the JSON lines here, every
other line by the NMEA reader from a line-preserving copy (:mod:`dracc.ingest.demux`).
The sentences and gpsd's reports of them are then two sources (the talker, ``gpsd``) of
the same fixes, as in a log recorded from both.
"""

from __future__ import annotations

import math
import re
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd

from dracc.frames import MISSING_NS, FileResult, Rejects, concat_blocks, make_frame
from dracc.ingest.chunks import Chunk, LineCopy, iter_line_chunks
from dracc.ingest.demux import (
    check_strict,
    merge_results,
    relabel,
    scaled_progress,
    take_off_blanks,
)
from dracc.ingest.memory import pid_folder
from dracc.ingest.nmea.sentences import MAX_LINE_BYTES
from dracc.ingest.signalk_delta import JSON_ERRORS, loads
from dracc.ingest.timebase import count_events

if TYPE_CHECKING:  # config imports ingest.frames: no runtime import here
    from dracc.core.config import IngestConfig

DEG = math.pi / 180.0
DEFAULT_SOURCE = "gpsd"
#: gpsd TPV ``status`` -> the GGA fix quality it stands for (a fix of mode 2 or 3)
STATUS_QUALITY = {2: 2, 3: 4, 4: 5, 5: 6, 7: 7, 8: 8}
_CLASS_RE = re.compile(rb'^\s*\{\s*"class"\s*:\s*"([A-Z0-9_]+)"')
#: the classes of gpsd's greeting and replies to commands (no data)
SESSION_CLASSES = {b"VERSION", b"DEVICES", b"DEVICE", b"WATCH", b"ERROR"}
_EXAMPLES = 5


def looks_like_gpsd_json(head: bytes) -> bool:
    """True for gpsd JSON (``gpspipe -w``) and gpsfake ``.chk`` files: a complete line of
    ``head`` is a report ``{"class":"...`` of data (not only the VERSION, DEVICES, WATCH
    greeting a raw ``gpspipe -r`` capture starts with: that is an NMEA log), and nearly all
    others (>= 90 %) are reports, NMEA sentences (``$``, ``!``), ``#`` comments or blank."""
    lines = head.split(b"\n")
    lines = (lines[:-1] if len(lines) > 1 else lines)[:400]
    classes = {m.group(1) for m in map(_CLASS_RE.match, lines) if m}
    if not classes - SESSION_CLASSES:
        return False
    known = sum(1 for ln in lines if not ln.strip() or ln.lstrip()[:1] in (b"{", b"$", b"!", b"#"))
    return known >= 0.9 * len(lines)


def _num(v: Any) -> float:
    """A JSON number as float, NaN for anything else (gpsd omits what it does not know)."""
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        return math.nan
    x = float(v)
    return x if math.isfinite(x) else math.nan


def _time_ns(v: Any) -> int | str | None:
    """A report's time: ns for Unix seconds (old gpsd), the ISO text as it is (parsed in
    bulk later), None where absent."""
    if isinstance(v, str) and v:
        return v
    if isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v):
        return int(round(float(v) * 1e9))
    return None


@dataclass
class GpsdDecoder:
    """gpsd reports fed a line at a time (:meth:`feed`), then :meth:`finish`."""

    file: str
    rejects: Rejects = field(default_factory=Rejects)
    ignored: Counter[str] = field(default_factory=Counter)
    ignored_examples: dict[str, list[tuple[str, int, str]]] = field(default_factory=dict)
    lines: int = 0
    #: a line longer is rejected as ``too_long`` unread (``[ingest] max_line_bytes``)
    max_line_bytes: int = MAX_LINE_BYTES
    #: TPV rows: (time, device, line, lat, lon, alt, track, speed, quality)
    tpv: list[tuple[Any, ...]] = field(default_factory=list)
    #: ATT rows: (time, device, line, heading, mheading, rot)
    att: list[tuple[Any, ...]] = field(default_factory=list)
    _last_tpv_time: dict[str, Any] = field(default_factory=dict)
    #: the rows of earlier chunks as columns (:meth:`flush`), per table: blocks of (time
    #: ns, time readable, device code, line, values, quality)
    _blocks: dict[str, list[list[np.ndarray]]] = field(
        default_factory=lambda: {"tpv": [], "att": []}
    )
    _devices: dict[str, int] = field(default_factory=dict)

    def ignore(self, what: str, line: int, text: str) -> None:
        self.ignored[what] += 1
        ex = self.ignored_examples.setdefault(what, [])
        if len(ex) < _EXAMPLES:
            ex.append((self.file, line, text))

    def feed(self, payload: bytes | bytearray, line: int) -> None:
        self.lines += 1
        text = payload[:120].decode("utf-8", "replace")
        if len(payload) > self.max_line_bytes:  # never parsed whole: one reject
            self.rejects.add("too_long", self.file, line, text)
            return
        try:
            msg = loads(payload)
        except JSON_ERRORS:
            self.rejects.add("bad_json", self.file, line, text)
            return
        cls = msg.get("class") if isinstance(msg, dict) else None
        if not isinstance(cls, str):
            self.rejects.add("not_gpsd", self.file, line, text)
            return
        dev = msg.get("device")
        dev = dev if isinstance(dev, str) and dev else DEFAULT_SOURCE
        if cls == "TPV":
            t = _time_ns(msg.get("time"))
            if t is None:
                self.ignore("gpsd TPV without time", line, text)
                return
            self._last_tpv_time[dev] = t
            mode = msg.get("mode")
            mode = mode if isinstance(mode, int) and not isinstance(mode, bool) else 0
            status = msg.get("status")
            status = status if isinstance(status, int) else 1
            quality = 0 if mode < 2 else STATUS_QUALITY.get(status, 1)
            alt = _num(msg.get("altMSL"))
            if math.isnan(alt):
                alt = _num(msg.get("alt"))
            if math.isnan(alt):
                alt = _num(msg.get("altHAE")) - _num(msg.get("geoidSep"))
            row = (
                t,
                dev,
                line,
                _num(msg.get("lat")),
                _num(msg.get("lon")),
                alt,
                _num(msg.get("track")),
                _num(msg.get("speed")),
                quality,
            )
            if all(math.isnan(x) for x in row[3:8]):
                self.ignore("gpsd TPV without fix", line, text)
                return
            self.tpv.append(row)
        elif cls == "ATT":
            t = _time_ns(msg.get("time"))
            if t is None:
                t = self._last_tpv_time.get(dev)
            vals = (_num(msg.get("heading")), _num(msg.get("mheading")), _num(msg.get("rot")))
            if all(math.isnan(x) for x in vals):
                self.ignore("gpsd ATT without heading", line, text)
            elif t is None:
                self.ignore("gpsd ATT without time", line, text)
            else:
                self.att.append((t, dev, line, *vals))
        else:
            self.ignore(f"gpsd {cls}", line, text)

    def flush(self) -> None:
        """The rows fed so far kept as compact columns (times parsed), their lists emptied:
        a streamed read calls this after each chunk, so its memory is the columns'."""
        code = self._devices
        for name, rows, nv in (("tpv", self.tpv, 5), ("att", self.att, 3)):
            if not rows:
                continue
            t, ok = _times([r[0] for r in rows])
            dev = np.array([code.setdefault(r[1], len(code)) for r in rows], dtype=np.int32)
            line = np.array([r[2] for r in rows], dtype=np.int64)
            vals = np.array([r[3 : 3 + nv] for r in rows], dtype=np.float64).reshape(-1, nv)
            q = np.array([r[8] if name == "tpv" else 0 for r in rows], dtype=np.int8)
            self._blocks[name].append([t, ok, dev, line, vals, q])
            rows.clear()

    def finish(self, cfg: IngestConfig | None = None) -> FileResult:
        """The frames, rejects and ignored counts (called once: it takes the columns)."""
        frames: dict[str, pd.DataFrame] = {}
        bad_time = 0
        self.flush()
        names = np.array(list(self._devices), dtype=object)
        for name in ("tpv", "att"):
            blocks = self._blocks[name]
            if not blocks:
                continue
            cols = []
            for j in range(6):  # column by column, each block's part given up at once
                cols.append(np.concatenate([b[j] for b in blocks]))
                for b in blocks:
                    b[j] = cols[-1][:0]
            blocks.clear()
            t, ok, dev, line, vals, q = cols
            del cols
            bad = int((~ok).sum())
            bad_time += bad
            if bad:
                t, dev, line, vals, q = t[ok], dev[ok], line[ok], vals[ok], q[ok]
            if len(t):
                build = self._tpv_frames if name == "tpv" else self._att_frames
                build(t, names[dev], line, vals, q, frames)
        if bad_time:
            self.rejects.counts["bad_time"] += bad_time
        res = FileResult(
            path=self.file,
            format="gpsd-json",
            frames=concat_blocks([frames]),
            lines=self.lines,
            rejects=self.rejects,
            ignored=self.ignored,
            ignored_examples=self.ignored_examples,
        )
        count_events(res, *((cfg.gap_s, cfg.backstep_tolerance_s) if cfg is not None else ()))
        return res

    def _tpv_frames(
        self,
        t: np.ndarray,
        dev: np.ndarray,
        line: np.ndarray,
        vals: np.ndarray,
        quality: np.ndarray,
        frames: dict[str, pd.DataFrame],
    ) -> None:
        """One record per run of TPVs of one device and time (each field its last value)."""
        new = np.ones(len(t), dtype=bool)
        new[1:] = (t[1:] != t[:-1]) | (dev[1:] != dev[:-1])
        run = np.cumsum(new) - 1
        last = np.flatnonzero(np.append(new[1:], True))  # the last TPV of each run
        nrun = len(last)
        # each field: its last finite value in the run (the run's order kept)
        merged = np.full((nrun, vals.shape[1]), np.nan)
        for j in range(vals.shape[1]):
            fin = np.isfinite(vals[:, j])
            merged[run[fin], j] = vals[fin, j]  # later rows overwrite earlier ones
        repeats = len(t) - nrun
        if repeats:
            self.ignored["gpsd TPV repeat"] += repeats
            ex = self.ignored_examples.setdefault("gpsd TPV repeat", [])
            for i in np.flatnonzero(~np.append(new[1:], True))[:_EXAMPLES].tolist():
                ex.append((self.file, int(line[i]), "a TPV of the same epoch follows"))
        common = {
            "time_ns": t[last],
            "source": dev[last],
            "line": line[last],
        }
        lat, lon, alt, track, speed = merged.T
        pos = np.isfinite(lat) & np.isfinite(lon)
        if pos.any():
            frames["position"] = make_frame(
                "position",
                {
                    **{k: v[pos] for k, v in common.items()},
                    "sentence": np.full(int(pos.sum()), "TPV", dtype=object),
                    "lat_rad": lat[pos] * DEG,
                    "lon_rad": lon[pos] * DEG,
                    "alt_m": alt[pos],
                    "quality": quality[last][pos],
                },
            )
        gr = np.isfinite(track) | np.isfinite(speed)
        if gr.any():
            frames["ground"] = make_frame(
                "ground",
                {
                    **{k: v[gr] for k, v in common.items()},
                    "sentence": np.full(int(gr.sum()), "TPV", dtype=object),
                    "cog_rad": (track[gr] * DEG) % (2 * math.pi),
                    "sog_mps": speed[gr],
                },
            )

    def _att_frames(
        self,
        t: np.ndarray,
        dev: np.ndarray,
        line: np.ndarray,
        vals: np.ndarray,
        _quality: np.ndarray,
        frames: dict[str, pd.DataFrame],
    ) -> None:
        # gpsd repeats the epoch's attitude in each report of the epoch: one record of a
        # run of equal reports (the first), the others counted
        same = np.zeros(len(t), dtype=bool)
        same[1:] = (
            (t[1:] == t[:-1])
            & (dev[1:] == dev[:-1])
            & ((vals[1:] == vals[:-1]) | (np.isnan(vals[1:]) & np.isnan(vals[:-1]))).all(axis=1)
        )
        if same.any():
            self.ignored["gpsd ATT repeat"] += int(same.sum())
            ex = self.ignored_examples.setdefault("gpsd ATT repeat", [])
            for i in np.flatnonzero(same)[:_EXAMPLES].tolist():
                ex.append((self.file, int(line[i]), "the attitude of the report before"))
            keep = ~same
            t, dev, line, vals = t[keep], dev[keep], line[keep], vals[keep]
        hdg, mhdg, rot = vals.T
        parts = []
        for h, ref in ((hdg, "T"), (mhdg, "M")):
            ok = np.isfinite(h)
            if ok.any():
                parts.append(
                    make_frame(
                        "heading",
                        {
                            "time_ns": t[ok],
                            "source": dev[ok],
                            "line": line[ok],
                            "sentence": np.full(int(ok.sum()), "ATT", dtype=object),
                            "heading_rad": (h[ok] * DEG) % (2 * math.pi),
                            "reference": np.full(int(ok.sum()), ref, dtype=object),
                        },
                    )
                )
        if parts:
            frames["heading"] = concat_blocks([{"heading": p} for p in parts])["heading"]
        ok = np.isfinite(rot)
        if ok.any():
            frames["rot"] = make_frame(
                "rot",
                {
                    "time_ns": t[ok],
                    "source": dev[ok],
                    "line": line[ok],
                    "sentence": np.full(int(ok.sum()), "ATT", dtype=object),
                    "rot_radps": rot[ok] * DEG / 60.0,
                },
            )


def _times(values: list[Any]) -> tuple[np.ndarray, np.ndarray]:
    """(int64 UTC ns, readable) of report times: ns already, or ISO 8601 text."""
    out = np.full(len(values), MISSING_NS, dtype=np.int64)
    text = [i for i, v in enumerate(values) if isinstance(v, str)]
    for i, v in enumerate(values):
        if isinstance(v, int):
            out[i] = v
    if text:
        dt = pd.to_datetime(
            pd.Series([values[i] for i in text], dtype=object),
            format="ISO8601",
            utc=True,
            errors="coerce",
        )
        good = ~dt.isna().to_numpy()
        v = dt.to_numpy(dtype="datetime64[ns]").astype(np.int64)
        idx = np.asarray(text, dtype=np.int64)
        out[idx[good]] = v[good]
    return out, out != MISSING_NS


def _feed_json(dec: GpsdDecoder, ch: Chunk) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Feed ``dec`` the JSON lines of ``ch`` (those starting with ``{``); the masks of
    the chunk's blank, JSON and other lines."""
    buf, start, end, raw = ch.buf, ch.start, ch.end, ch.data
    blank = start == end
    first = np.where(blank, 0, buf[np.minimum(start, len(buf) - 1)])
    is_json = first == ord("{")
    ji = np.flatnonzero(is_json)
    for s, e, n in zip(start[ji].tolist(), end[ji].tolist(), ch.numbers(ji).tolist(), strict=True):
        dec.feed(raw[s:e], n)
    return blank, is_json, ~is_json & ~blank


def read_gpsd_json(
    path: str | Path, cfg: IngestConfig, progress: Callable[[int], object] | None = None
) -> FileResult:
    """Read gpsd JSON (``gpspipe -w``) or a gpsfake ``.chk`` file (JSON and NMEA lines)
    into one :class:`FileResult` of format ``gpsd-json``, streamed in chunks of whole
    lines (:func:`iter_line_chunks`); the NMEA lines' copy is written chunk by chunk."""
    from dracc.ingest.nmea import check_readable, read_nmea

    p = Path(path)
    check_readable(p)
    file = str(p)
    dec = GpsdDecoder(file, max_line_bytes=cfg.max_line_bytes)
    lines = blanks = n_json = n_other = json_bytes = other_bytes = 0
    with pid_folder("dracc-gpsd-") as tmp:
        copy: LineCopy | None = None  # started at the first line other than JSON
        chunks = iter_line_chunks(p, cfg.max_line_bytes)
        while (ch := next(chunks, None)) is not None:  # None at the end: no chunk held on
            blank, is_json, other = _feed_json(dec, ch)
            size = ch.nxt - ch.start
            blanks += int(blank.sum())
            n_json += int(is_json.sum())
            n_other += int(other.sum())
            json_bytes += int(size[is_json].sum())
            other_bytes += int(size[other].sum())
            if copy is None and other.any():
                copy = LineCopy(p, Path(tmp) / p.name)
                copy.pad(lines)
            if copy is not None:
                copy.add(ch, other)
            dec.flush()
            lines += len(ch.start)
        copied = copy.close() if copy is not None else None
        res = dec.finish(cfg)
        check_strict(res, cfg)
        if progress is not None:
            progress(json_bytes)
        parts = [res]
        notes = []
        if copied is not None:
            notes.append(f"{n_other} lines other than JSON read as NMEA 0183")
            told = scaled_progress(progress, other_bytes, copied.stat().st_size)
            r = relabel(read_nmea(copied, cfg, told), str(copied), file)
            take_off_blanks(r, n_json)
            parts.append(r)
        elif blanks:
            res.ignored["blank"] += blanks
    return merge_results(file, "gpsd-json", lines, parts, notes)
