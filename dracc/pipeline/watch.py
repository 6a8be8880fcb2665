"""The loop of ``dracc watch``: live sources polled, every line recorded, per-source
rolling state in bounded memory, and the ``dracc.watch/1`` status document.

Pure orchestration, no printing: :class:`Watch` ``step(timeout_s)`` polls the sources
once (waiting at most ``timeout_s``), hands every line to the :class:`Recorder` (when
there is one) and to the per-source state, and returns the findings raised or cleared
in that step; :meth:`Watch.status` is the status document; :meth:`Watch.close` closes
the sources and finishes the recording.

A line's source key is the one dracc's NMEA reader gives it, from a cheap parse: the
TAG block's ``s:`` where there is one, else the talker of ``$TTSSS`` (a proprietary
``$P...`` sentence: its address, ``PASHR``).  Per key: the records, the rate over the
last minute (60 one-second buckets), the last receive time and its age, and the
latency (receive time minus the TAG ``c:`` time, where the line has one; ``c:`` in
seconds up to 10 digits, else milliseconds, as :mod:`dracc.ingest.tagblock` reads it).

Findings: ``stale`` is raised for a source whose age exceeds ``stale_s`` and cleared at
its next line, each with its evidence (``last_utc``, ``age_s``).  Open findings are all
kept; of the cleared ones the last :data:`KEEP_CLEARED`.  The deviation, dead-reckoning
and integrity statistics of ``analyze``/``audit`` are not computed live yet: the status
says so in ``not_yet``.

The recording (``Recorder``) writes each line with its receive time; a line with a TAG
block keeps it (its ``s:``), a line without one is recorded with ``c:`` only, so that
the recording reads back with the same source keys (talkers) as the lines heard.
"""

from __future__ import annotations

import datetime as dt
import time
from collections import Counter, deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

from dracc.ingest.live import LiveSource, Recorder, poll_all

SCHEMA = "dracc.watch/1"
RATE_WINDOW_S = 60  #: the rate is over this many seconds (one bucket per second)
KEEP_CLEARED = 200  #: cleared findings kept in the status, the latest
MAX_SOURCES = 1000  #: source keys tracked at most (bounded memory against garbage keys)
NOT_YET = [
    "role: the roles of the sources (the live role assignment comes next)",
    "deviation: the hourly INS deviations and their statistics over the window",
    "dead_reckoning: the DR from the last fix and its 2M against GNSS",
    "integrity checks other than stale (validity, plausibility, consistency)",
]


def utc(ns: int) -> str:
    """ISO 8601 UTC of a time in ns, to the millisecond."""
    t = dt.datetime(1970, 1, 1) + dt.timedelta(microseconds=ns // 1000)
    return t.strftime("%Y-%m-%dT%H:%M:%S.") + f"{t.microsecond // 1000:03d}Z"


def line_key(line: bytes) -> tuple[str | None, int | None]:
    """(source key, TAG ``c:`` time in ns or None) of a received line; key None where the
    line is no sentence."""
    source = None
    c_ns = None
    if line[:1] == b"\\":
        end = line.find(b"\\", 1)
        if end < 0:
            return None, None
        star = line.rfind(b"*", 1, end)
        for p in line[1 : star if star > 0 else end].split(b","):
            if p[:2] == b"s:" and len(p) > 2:
                source = p[2:].decode("ascii", "replace")
            elif p[:2] == b"c:":
                try:
                    v = float(p[2:])
                except ValueError:
                    continue
                c_ns = int(v * 1e9) if v < 1e10 else int(v * 1e6)
        line = line[end + 1 :]
    if source is None:
        if line[:1] not in (b"$", b"!") or len(line) < 6:
            return None, c_ns
        if line[1:2] == b"P":
            comma = line.find(b",")
            source = line[1 : comma if comma > 0 else 6].decode("ascii", "replace")
        else:
            source = line[1:3].decode("ascii", "replace")
    return source, c_ns


@dataclass
class SourceState:
    """Rolling state of one source key, bounded: 60 rate buckets and a few numbers."""

    records: int = 0
    last_ns: int = 0
    latency_s: float | None = None
    buckets: deque[list[int]] = field(default_factory=lambda: deque(maxlen=RATE_WINDOW_S))
    stale: dict[str, Any] | None = None  #: the open stale finding

    def add(self, recv_ns: int, c_ns: int | None) -> None:
        self.records += 1
        self.last_ns = max(self.last_ns, recv_ns)
        sec = recv_ns // 1_000_000_000
        if self.buckets and self.buckets[-1][0] == sec:
            self.buckets[-1][1] += 1
        else:
            self.buckets.append([sec, 1])
        if c_ns is not None:
            self.latency_s = round((recv_ns - c_ns) / 1e9, 3)

    def rate_hz(self, now_ns: int) -> float:
        """Lines per second over the last :data:`RATE_WINDOW_S` seconds (fewer at the
        start: since the first line)."""
        now_s = now_ns // 1_000_000_000
        n = sum(c for s, c in self.buckets if s > now_s - RATE_WINDOW_S)
        if not n or not self.buckets:
            return 0.0
        first = max(self.buckets[0][0], now_s - RATE_WINDOW_S + 1)
        return round(n / max(1.0, now_ns / 1e9 - first), 3)


class Watch:
    """The live loop over ``sources`` (see the module docstring).  ``clock`` gives the
    time in ns (injected by tests); ``stale_s`` the age that raises ``stale``."""

    def __init__(
        self,
        sources: Sequence[LiveSource],
        recorder: Recorder | None = None,
        stale_s: float = 10.0,
        clock: Callable[[], int] = time.time_ns,
    ) -> None:
        self.sources = list(sources)
        self.recorder = recorder
        self.stale_ns = int(stale_s * 1e9)
        self.clock = clock
        self.started_ns = clock()
        self.received = 0
        self.unkeyed = 0  #: lines that are no sentence (recorded, counted, no source)
        self.state: dict[str, SourceState] = {}
        self.cleared: deque[dict[str, Any]] = deque(maxlen=KEEP_CLEARED)

    def step(self, timeout_s: float = 0.1) -> list[dict[str, Any]]:
        """Poll once; record and count the lines; return the findings raised or cleared
        (each a finding dict with ``event``: ``raised`` or ``cleared``)."""
        events: list[dict[str, Any]] = []
        if len(self.sources) == 1:
            got = [(0, ln) for ln in self.sources[0].poll(timeout_s)]
        else:
            got = poll_all(self.sources, timeout_s)
        for _, (recv_ns, line) in got:
            self.received += 1
            if self.recorder is not None:
                self.recorder.write(line, recv_ns)
            key, c_ns = line_key(line)
            if key is None:
                self.unkeyed += 1
                continue
            st = self.state.get(key)
            if st is None:
                if len(self.state) >= MAX_SOURCES:
                    self.unkeyed += 1
                    continue
                st = self.state[key] = SourceState()
            st.add(recv_ns, c_ns)
            if st.stale is not None:
                events.append(self._clear(st, recv_ns))
        if self.recorder is not None:
            self.recorder.tick()
        now = self.clock()
        for key, st in self.state.items():
            if st.stale is None and now - st.last_ns > self.stale_ns:
                events.append(self._raise(key, st, now))
        return events

    def _raise(self, key: str, st: SourceState, now: int) -> dict[str, Any]:
        age = round((now - st.last_ns) / 1e9, 3)
        st.stale = {
            "check": "stale",
            "source": key,
            "raised_utc": utc(now),
            "cleared_utc": None,
            "message": f"{key}: nothing received for {age:.1f} s "
            f"(more than {self.stale_ns / 1e9:g} s)",
            "evidence": {"last_utc": utc(st.last_ns), "age_s": age},
        }
        return {"event": "raised", **st.stale}

    def _clear(self, st: SourceState, recv_ns: int) -> dict[str, Any]:
        assert st.stale is not None
        done = {**st.stale, "cleared_utc": utc(recv_ns)}
        st.stale = None
        self.cleared.append(done)
        return {"event": "cleared", **done}

    def dropped(self) -> dict[str, int]:
        """Input the sources dropped, by reason (summed over the sources)."""
        total: Counter[str] = Counter()
        for s in self.sources:
            total.update(s.rejected)
        return dict(sorted(total.items()))

    def status(self) -> dict[str, Any]:
        """The ``dracc.watch/1`` status document (JSON-ready)."""
        now = self.clock()
        sources = {
            key: {
                "role": None,
                "records": st.records,
                "rate_hz": st.rate_hz(now),
                "last_utc": utc(st.last_ns),
                "age_s": round((now - st.last_ns) / 1e9, 3),
                "latency_s": st.latency_s,
            }
            for key, st in sorted(self.state.items())
        }
        open_ = [st.stale for st in self.state.values() if st.stale is not None]
        findings = sorted([*self.cleared, *open_], key=lambda f: f["raised_utc"])
        return {
            "schema": SCHEMA,
            "started_utc": utc(self.started_ns),
            "now_utc": utc(now),
            "received": self.received,
            "unkeyed": self.unkeyed,
            "dropped": self.dropped(),
            "recording": str(self.recorder.current or "") if self.recorder else None,
            "sources": sources,
            "findings": findings,
            "deviation": None,
            "dead_reckoning": None,
            "not_yet": NOT_YET,
        }

    def close(self) -> None:
        """Close the sources and finish the recording (flush, fsync, rename)."""
        for s in self.sources:
            s.close()
        if self.recorder is not None:
            self.recorder.close()
