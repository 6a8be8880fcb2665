"""Signal K delta JSON: the own vessel's navigation values into canonical frames.

A delta is one JSON object a line::

    {"context": "vessels.urn:mrn:imo:mmsi:230029970",
     "updates": [{"$source": "n2k.43", "source": {"label": "n2k", "src": "43", "pgn": 129025},
                  "timestamp": "2016-07-16T12:00:08.825Z",
                  "values": [{"path": "navigation.position",
                              "value": {"latitude": 60.08, "longitude": 23.53}}]}]}

Values are SI already (rad, m/s, m, rad/s); a position is in degrees (Signal K keeps
WGS-84 degrees there) and becomes radians.  The paths read (:data:`PATHS`):
``navigation.position`` (with ``navigation.gnss.methodQuality`` and
``navigation.gnss.horizontalDilution`` of the same update as quality and HDOP),
``headingTrue``, ``headingMagnetic`` (with ``magneticVariation`` of the same update),
``speedThroughWater`` (``speedThroughWaterTransverse``), ``courseOverGroundTrue`` +
``speedOverGround``, ``log`` + ``trip.log``, ``rateOfTurn``.  Values of one update that
belong to one frame make one row; a ``null`` value is missing (NaN), a row with nothing
but missing values is counted (ignored ``signalk null``); a value of the wrong type or
out of range is rejected (``bad_value``).  Other paths are counted as ignored by their
first two names (``signalk environment.wind``).

The source key is the update's ``$source``, else ``source.label`` and ``source.src``
(NMEA 2000) or ``source.talker`` (NMEA 0183) joined by a dot as Signal K does, else
``signalk``.  The time is the update's ``timestamp``; a line's receive time (the Signal K
server log's milliseconds) is ``recv_ns``, and the time where the update has none.

Only the own vessel is read: a delta without context, ``vessels.self``, or the context
the log declares as ``self`` (the server's hello line ``{"name": ..., "self": ...}``).
Where nothing is declared, the vessel context with the most updates that are not AIS
(an AIS sentence or PGN) is taken as the own vessel, and a note says so.  Deltas of
other vessels (AIS targets) are counted (ignored ``signalk other vessel``), not read.
A line that is not JSON is rejected (``bad_json``), JSON that is not a delta
(``not_delta``); neither ever raises.
"""

from __future__ import annotations

import json
import math
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd

from dracc.frames import MISSING_NS, FileResult, Rejects, concat_blocks, make_frame
from dracc.ingest.chunks import iter_line_chunks
from dracc.ingest.demux import check_strict
from dracc.ingest.nmea.sentences import MAX_LINE_BYTES
from dracc.ingest.timebase import count_events

if TYPE_CHECKING:  # config imports ingest.frames: no runtime import here
    from dracc.core.config import IngestConfig

try:  # measured: the parse 3.6x faster than json, a whole delta line 1.35-1.6x
    import orjson

    loads: Callable[[bytes | bytearray], Any] = orjson.loads
    JSON_ERRORS: tuple[type[Exception], ...] = (orjson.JSONDecodeError, ValueError)
except ImportError:  # pragma: no cover - orjson is optional
    loads = json.loads
    JSON_ERRORS = (ValueError,)

DEG = math.pi / 180.0
SELF = "vessels.self"
#: path -> (kind, column); a position is a dict of degrees (see :func:`_position`)
PATHS: dict[str, tuple[str, str]] = {
    "navigation.position": ("position", "position"),
    "navigation.gnss.methodQuality": ("position", "quality"),
    "navigation.gnss.horizontalDilution": ("position", "hdop"),
    "navigation.headingTrue": ("heading", "T"),
    "navigation.headingMagnetic": ("heading", "M"),
    "navigation.magneticVariation": ("heading", "variation_rad"),
    "navigation.speedThroughWater": ("water", "stw_mps"),
    "navigation.speedThroughWaterTransverse": ("water", "stw_transverse_mps"),
    "navigation.courseOverGroundTrue": ("ground", "cog_rad"),
    "navigation.speedOverGround": ("ground", "sog_mps"),
    "navigation.log": ("distance", "total_water_m"),
    "navigation.trip.log": ("distance", "trip_water_m"),
    "navigation.rateOfTurn": ("rot", "rot_radps"),
}
#: Signal K ``navigation.gnss.methodQuality`` -> the GGA fix quality
METHOD_QUALITY = {
    "no gps": 0,
    "gnss fix": 1,
    "dgnss fix": 2,
    "precise gnss": 3,
    "rtk fixed integer": 4,
    "rtk float": 5,
    "estimated (dr) mode": 6,
    "manual input": 7,
    "simulator mode": 8,
    "error": 0,
}
#: the value columns a row of each kind has (the frame columns, heading built apart)
_COLUMNS = {
    "position": ("lat_rad", "lon_rad", "alt_m", "hdop"),
    "heading": ("heading_rad", "variation_rad"),
    "ground": ("cog_rad", "sog_mps"),
    "water": ("stw_mps", "stw_transverse_mps"),
    "distance": ("total_water_m", "trip_water_m"),
    "rot": ("rot_radps",),
}
#: NMEA 2000 PGNs of AIS reports (their updates do not make a context the own vessel)
AIS_PGNS = {129038, 129039, 129040, 129041, 129793, 129794, 129798, 129801, 129802, 129809, 129810}
_EXAMPLES = 5
#: the frames of one row each besides position and heading, and the paths of their columns
_GROUPS = (
    ("ground", ("navigation.courseOverGroundTrue", "navigation.speedOverGround")),
    ("water", ("navigation.speedThroughWater", "navigation.speedThroughWaterTransverse")),
    ("distance", ("navigation.log", "navigation.trip.log")),
    ("rot", ("navigation.rateOfTurn",)),
)
#: path -> the range of a plausible value (outside it: rejected ``bad_value``)
_RANGES = {
    "navigation.courseOverGroundTrue": (-2 * math.pi, 2 * math.pi),
    "navigation.speedOverGround": (0.0, 1e3),
    "navigation.speedThroughWater": (-1e3, 1e3),
    "navigation.speedThroughWaterTransverse": (-1e3, 1e3),
    "navigation.log": (0.0, 1e12),
    "navigation.trip.log": (0.0, 1e12),
    "navigation.rateOfTurn": (-10.0, 10.0),
}


#: path -> what an ignored path is counted as (its first two names), filled as met
_GROUP: dict[str, str] = {}


class _Bad(Exception):
    """A value of the wrong type or range (rejected ``bad_value``)."""


def _num(v: Any, lo: float = -math.inf, hi: float = math.inf) -> float:
    """A finite number within [lo, hi] as float; NaN for null; _Bad otherwise."""
    if v is None:
        return math.nan
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise _Bad
    x = float(v)
    if not (lo <= x <= hi):  # NaN and infinities fail too
        raise _Bad
    return x


def _position(v: Any) -> tuple[float, float, float]:
    if v is None:
        return math.nan, math.nan, math.nan
    if not isinstance(v, dict):
        raise _Bad
    lat = _num(v.get("latitude"), -90.0, 90.0)
    lon = _num(v.get("longitude"), -180.0, 180.0)
    alt = _num(v.get("altitude"))
    return lat * DEG, lon * DEG, alt


def _source(update: dict[str, Any]) -> tuple[str, str, str, bool]:
    """(source key, talker, sentence, is AIS) of an update."""
    src = update.get("source")
    src = src if isinstance(src, dict) else {}
    talker = src.get("talker")
    talker = talker if isinstance(talker, str) else ""
    sentence = src.get("sentence")
    pgn = src.get("pgn")
    key = update.get("$source")
    if not isinstance(key, str) or not key:
        label = src.get("label")
        sub = src.get("src", talker)
        if isinstance(label, str) and label:
            key = f"{label}.{sub}" if isinstance(sub, (str, int)) and str(sub) else label
        else:
            key = "signalk"
    if isinstance(sentence, str) and sentence:
        what = sentence
    elif isinstance(pgn, int) and not isinstance(pgn, bool):
        what = f"PGN{pgn}"
    else:
        what = "delta"
    ais = sentence in ("VDM", "VDO") or talker == "AI" or (isinstance(pgn, int) and pgn in AIS_PGNS)
    return key, talker, what, ais


@dataclass
class _Rows:
    """The rows of one kind, column by column."""

    ctx: list[int] = field(default_factory=list)
    upd: list[int] = field(default_factory=list)  #: index into the update times
    line: list[int] = field(default_factory=list)
    source: list[str] = field(default_factory=list)
    talker: list[str] = field(default_factory=list)
    sentence: list[str] = field(default_factory=list)
    values: list[tuple[float, ...]] = field(default_factory=list)
    extra: list[Any] = field(default_factory=list)  #: heading reference / position quality
    #: the rows of earlier chunks as columns (:meth:`flush`), the texts as codes
    blocks: list[dict[str, np.ndarray]] = field(default_factory=list)

    def flush(self, codes: dict[str, int]) -> None:
        """The rows so far as compact columns (texts coded in ``codes``), lists emptied."""
        if not self.line:
            return

        def code(texts: list[str]) -> np.ndarray:
            return np.array([codes.setdefault(x, len(codes)) for x in texts], dtype=np.int32)

        self.blocks.append(
            {
                "ctx": np.array(self.ctx, dtype=np.int64),
                "upd": np.array(self.upd, dtype=np.int64),
                "line": np.array(self.line, dtype=np.int64),
                "source": code(self.source),
                "talker": code(self.talker),
                "sentence": code(self.sentence),
                "values": np.array(self.values, dtype=np.float64),
                "extra": np.array(self.extra, dtype=object),
            }
        )
        for col in (self.ctx, self.upd, self.line, self.source, self.talker, self.sentence):
            col.clear()
        self.values.clear()
        self.extra.clear()

    def columns(self, codes: dict[str, int]) -> dict[str, np.ndarray]:
        """All rows as columns (after :meth:`flush`; the texts as codes), the blocks given
        up column by column (the rows are held about once)."""
        self.flush(codes)
        keys = list(self.blocks[0])
        out = {k: np.concatenate([b.pop(k) for b in self.blocks]) for k in keys}
        self.blocks.clear()
        return out


@dataclass
class DeltaDecoder:
    """Signal K deltas fed a line at a time (:meth:`feed`), then :meth:`finish`."""

    file: str
    self_context: str | None = None
    rejects: Rejects = field(default_factory=Rejects)
    ignored: Counter[str] = field(default_factory=Counter)
    ignored_examples: dict[str, list[tuple[str, int, str]]] = field(default_factory=dict)
    lines: int = 0
    #: a line longer is rejected as ``too_long`` unread (``[ingest] max_line_bytes``)
    max_line_bytes: int = MAX_LINE_BYTES
    rows: dict[str, _Rows] = field(default_factory=lambda: {k: _Rows() for k in _COLUMNS})
    contexts: list[str | None] = field(default_factory=list)
    _ctx_index: dict[str | None, int] = field(default_factory=dict)
    #: per context: updates not from AIS, lines, the lines' first example, ignored paths
    _ctx_updates: Counter[int] = field(default_factory=Counter)
    _ctx_lines: Counter[int] = field(default_factory=Counter)
    _ctx_example: dict[int, tuple[int, str]] = field(default_factory=dict)
    _ctx_ignored: dict[int, Counter[str]] = field(default_factory=dict)
    _ctx_ignored_ex: dict[int, dict[str, list[tuple[int, str]]]] = field(default_factory=dict)
    _times: list[Any] = field(default_factory=list)  #: update timestamps (str or None)
    _recv: list[int] = field(default_factory=list)  #: the receive time of each update
    #: the updates of earlier chunks (:meth:`flush`): blocks of (time ns, own time, recv)
    _upd_blocks: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = field(default_factory=list)
    _upd_done: int = 0  #: updates in ``_upd_blocks``
    _codes: dict[str, int] = field(default_factory=dict)  #: source, talker, sentence texts

    def ignore(self, what: str, line: int, text: str) -> None:
        self.ignored[what] += 1
        ex = self.ignored_examples.setdefault(what, [])
        if len(ex) < _EXAMPLES:
            ex.append((self.file, line, text[:120]))

    def feed(self, payload: bytes | bytearray, line: int, recv_ns: int = MISSING_NS) -> None:
        """One line of JSON (``line``: its number in the file; ``recv_ns``: its receive
        time or MISSING_NS)."""
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
        if not isinstance(msg, dict):
            self.rejects.add("not_delta", self.file, line, text)
            return
        updates = msg.get("updates")
        if updates is None:
            me = msg.get("self")
            if isinstance(me, str) or ("name" in msg and "version" in msg):
                if isinstance(me, str) and me and self.self_context is None:
                    self.self_context = me
                self.ignore("signalk hello", line, text)
            else:
                self.ignore("signalk other message", line, text)
            return
        ctx = msg.get("context")
        if not isinstance(updates, list) or not (ctx is None or isinstance(ctx, str)):
            self.rejects.add("not_delta", self.file, line, text)
            return
        c = self._ctx_index.get(ctx)
        if c is None:
            c = self._ctx_index[ctx] = len(self.contexts)
            self.contexts.append(ctx)
            self._ctx_example[c] = (line, text[:120])
        self._ctx_lines[c] += 1
        for update in updates:
            if not isinstance(update, dict):
                self.rejects.add("not_delta", self.file, line, text)
                continue
            self._update(update, c, line, recv_ns, text)

    def _update(self, update: dict[str, Any], c: int, line: int, recv_ns: int, text: str) -> None:
        values = update.get("values")
        if values is None:
            self._ignore_path(
                c, "signalk meta" if "meta" in update else "signalk empty update", line, text
            )
            return
        if not isinstance(values, list):
            self.rejects.add("not_delta", self.file, line, text)
            return
        key, talker, sentence, ais = _source(update)
        if not ais:
            self._ctx_updates[c] += 1
        got: dict[str, Any] = {}
        for item in values:
            path = item.get("path") if isinstance(item, dict) else None
            if not isinstance(path, str):
                self.rejects.add("not_delta", self.file, line, text)
                continue
            if path in PATHS:
                got[path] = item.get("value")
            else:
                what = _GROUP.get(path)
                if what is None:
                    what = _GROUP[path] = "signalk " + ".".join(path.split(".")[:2])
                self._ignore_path(c, what, line, text)
        if not got:
            return
        ts = update.get("timestamp")
        u = self._upd_done + len(self._times)
        self._times.append(ts if isinstance(ts, str) else None)
        self._recv.append(recv_ns)
        try:
            rows = self._rows(got)
        except _Bad:
            self.rejects.add("bad_value", self.file, line, text)
            return
        if not rows:
            self._ignore_path(c, "signalk null", line, text)
        for kind, vals, extra in rows:
            r = self.rows[kind]
            r.ctx.append(c)
            r.upd.append(u)
            r.line.append(line)
            r.source.append(key)
            r.talker.append(talker)
            r.sentence.append(sentence)
            r.values.append(vals)
            r.extra.append(extra)

    def _ignore_path(self, c: int, what: str, line: int, text: str) -> None:
        counts = self._ctx_ignored.get(c)
        if counts is None:
            counts = self._ctx_ignored[c] = Counter()
            self._ctx_ignored_ex[c] = {}
        counts[what] += 1
        if counts[what] <= _EXAMPLES:
            self._ctx_ignored_ex[c].setdefault(what, []).append((line, text))

    @staticmethod
    def _rows(got: dict[str, Any]) -> list[tuple[str, tuple[float, ...], Any]]:
        """(kind, values, extra) rows of one update's known values; _Bad for a bad value."""
        out: list[tuple[str, tuple[float, ...], Any]] = []
        g = got.get
        if "navigation.position" in got:
            lat, lon, alt = _position(g("navigation.position"))
            mq = g("navigation.gnss.methodQuality")
            quality = METHOD_QUALITY.get(mq.lower(), 1) if isinstance(mq, str) else 1
            hdop = _num(g("navigation.gnss.horizontalDilution"), 0.0)
            if not (math.isnan(lat) or math.isnan(lon)):
                out.append(("position", (lat, lon, alt, hdop), quality))
        var = _num(g("navigation.magneticVariation"), -math.pi, math.pi)
        for path, ref in (("navigation.headingTrue", "T"), ("navigation.headingMagnetic", "M")):
            if path in got:
                h = _num(g(path), -2 * math.pi, 2 * math.pi)
                if not math.isnan(h):
                    out.append(("heading", (h % (2 * math.pi), var), ref))
        for kind, paths in _GROUPS:
            if any(p in got for p in paths):
                vals = tuple(_num(g(p), *_RANGES[p]) if p in got else math.nan for p in paths)
                if kind == "ground":
                    vals = (vals[0] % (2 * math.pi), vals[1])
                if not all(math.isnan(v) for v in vals):
                    out.append((kind, vals, None))
        return out

    def flush(self) -> None:
        """The updates and rows fed so far kept as compact columns (times parsed), their
        lists emptied: a streamed read calls this after each chunk."""
        if self._times:
            t = _times(self._times, self._recv)
            own = np.array([x is not None for x in self._times], dtype=bool)
            self._upd_blocks.append((t, own, np.array(self._recv, dtype=np.int64)))
            self._upd_done += len(self._times)
            self._times.clear()
            self._recv.clear()
        for r in self.rows.values():
            r.flush(self._codes)

    def own_contexts(self) -> tuple[set[int], list[str]]:
        """The contexts read as the own vessel, and a note where one was chosen."""
        own = {i for i, c in enumerate(self.contexts) if c is None or c == SELF}
        notes: list[str] = []
        if self.self_context is not None:
            own |= {i for i, c in enumerate(self.contexts) if c == self.self_context}
            return own, notes
        named = [i for i in range(len(self.contexts)) if i not in own and self._ctx_updates[i]]
        if named:
            best = max(named, key=lambda i: self._ctx_updates[i])
            own.add(best)
            notes.append(
                f"no own vessel declared: context {self.contexts[best]!r} taken as the own "
                f"vessel ({self._ctx_updates[best]} updates not from AIS)"
            )
        return own, notes

    def finish(self, cfg: IngestConfig | None = None) -> FileResult:
        """The frames of the own vessel, rejects, ignored counts, notes (called once: it
        takes the decoder's columns)."""
        own, notes = self.own_contexts()
        for c in range(len(self.contexts)):
            if c in own:
                for what, n in self._ctx_ignored.get(c, Counter()).items():
                    self.ignored[what] += n
                    ex = self.ignored_examples.setdefault(what, [])
                    for ln, txt in self._ctx_ignored_ex[c][what][: max(0, _EXAMPLES - len(ex))]:
                        ex.append((self.file, ln, txt))
            else:
                ln, txt = self._ctx_example[c]
                self.ignored["signalk other vessel"] += self._ctx_lines[c]
                ex = self.ignored_examples.setdefault("signalk other vessel", [])
                if len(ex) < _EXAMPLES:
                    ex.append((self.file, ln, txt))
        others = sum(1 for c in range(len(self.contexts)) if c not in own)
        if others:
            notes.append(f"{others} other vessels' deltas (AIS targets) not read")
        self.flush()
        ub = self._upd_blocks
        times = np.concatenate([b[0] for b in ub]) if ub else np.zeros(0, np.int64)
        own_time = np.concatenate([b[1] for b in ub]) if ub else np.zeros(0, bool)
        recv = np.concatenate([b[2] for b in ub]) if ub else np.zeros(0, np.int64)
        ub.clear()
        frames: dict[str, pd.DataFrame] = {}
        no_time = 0
        for kind, rows in self.rows.items():
            if not rows.blocks and not rows.line:
                continue
            r = rows.columns(self._codes)
            names = np.array(list(self._codes), dtype=object)
            sel = np.isin(r["ctx"], np.fromiter(own, np.int64, len(own)))
            upd = r["upd"]
            t = times[upd]
            ok = sel & (t != MISSING_NS)
            no_time += int((sel & (t == MISSING_NS)).sum())
            if not ok.any():
                continue
            idx = np.flatnonzero(ok)
            has_own_time = own_time[upd[idx]]
            vals = r["values"][idx]
            data: dict[str, Any] = {
                "time_ns": t[idx],
                "recv_ns": np.where(has_own_time, recv[upd[idx]], MISSING_NS),
                "line": r["line"][idx],
                "source": names[r["source"][idx]],
                "talker": names[r["talker"][idx]],
                "sentence": names[r["sentence"][idx]],
            }
            for j, col in enumerate(_COLUMNS[kind]):
                data[col] = vals[:, j]
            extra = r["extra"][idx]
            if kind == "position":
                data["quality"] = extra.astype(np.int8)
            elif kind == "heading":
                data["reference"] = extra
            frames[kind] = make_frame(kind, data)
        if no_time:
            self.rejects.counts["no_time"] += no_time
            notes.append(f"{no_time} Signal K values without a timestamp or receive time not used")
        res = FileResult(
            path=self.file,
            format="signalk-delta",
            frames=concat_blocks([frames]),
            lines=self.lines,
            rejects=self.rejects,
            notes=notes,
            ignored=self.ignored,
            ignored_examples=self.ignored_examples,
        )
        count_events(res, *((cfg.gap_s, cfg.backstep_tolerance_s) if cfg is not None else ()))
        return res


def _times(stamps: list[Any], recv: list[int]) -> np.ndarray:
    """int64 UTC ns of the update timestamps (ISO 8601); the receive time where an update
    has none or an unreadable one; MISSING_NS where neither."""
    if not stamps:
        return np.zeros(0, dtype=np.int64)
    dt = pd.to_datetime(
        pd.Series(stamps, dtype=object), format="ISO8601", utc=True, errors="coerce"
    )
    t = dt.to_numpy(dtype="datetime64[ns]").astype(np.int64)
    bad = dt.isna().to_numpy()
    t[bad] = np.asarray(recv, dtype=np.int64)[bad]
    return t


def looks_like_signalk_delta(head: bytes) -> bool:
    """True for bare Signal K delta JSON, one object a line (the server's delta logs):
    the first and at least half of the complete lines start with ``{``, one has
    ``"updates"``, none is gpsd's ``{"class":``."""
    lines = [ln.strip() for ln in head.split(b"\n")[:-1] or [head]][:200]
    lines = [ln for ln in lines if ln]
    if not lines or not lines[0].startswith(b"{"):
        return False
    js = [ln for ln in lines if ln.startswith(b"{")]
    if any(ln.startswith(b'{"class":') for ln in js):
        return False
    return 2 * len(js) >= len(lines) and any(b'"updates"' in ln for ln in js)


def decode_lines(
    dec: DeltaDecoder,
    raw: bytes | bytearray,
    start: np.ndarray,
    end: np.ndarray,
    numbers: np.ndarray,
    recv_ns: np.ndarray | None = None,
) -> None:
    """Feed ``dec`` the lines ``raw[start:end]`` (numbered ``numbers``, received at
    ``recv_ns``, MISSING_NS where None)."""
    rv = recv_ns.tolist() if recv_ns is not None else [MISSING_NS] * len(start)
    for s, e, n, r in zip(start.tolist(), end.tolist(), numbers.tolist(), rv, strict=True):
        dec.feed(raw[s:e], n, r)


def read_signalk_delta(
    path: str | Path, cfg: IngestConfig, progress: Callable[[int], object] | None = None
) -> FileResult:
    """Read a file of bare Signal K delta lines into a :class:`FileResult`, streamed in
    chunks of whole lines (:func:`dracc.ingest.chunks.iter_line_chunks`)."""
    p = Path(path)
    dec = DeltaDecoder(str(p), max_line_bytes=cfg.max_line_bytes)
    lines = blanks = nbytes = 0
    chunks = iter_line_chunks(p, cfg.max_line_bytes)
    while (ch := next(chunks, None)) is not None:  # None at the end: no chunk held on
        blank = ch.start == ch.end
        blanks += int(blank.sum())
        keep = np.flatnonzero(~blank)
        decode_lines(dec, ch.data, ch.start[keep], ch.end[keep], ch.numbers(keep))
        dec.flush()
        lines += len(ch.start)
        nbytes += ch.nbytes
    if blanks:  # counted first, as a read of the whole file did
        ignored: Counter[str] = Counter({"blank": blanks})
        ignored.update(dec.ignored)
        dec.ignored = ignored
    res = dec.finish(cfg)
    res.lines = lines
    check_strict(res, cfg)
    if progress is not None:
        progress(nbytes)
    return res
