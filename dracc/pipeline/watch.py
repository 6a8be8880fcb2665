"""The loop of ``dracc watch``: live sources polled, every line recorded, per-source
rolling state in bounded memory, and the ``dracc.watch/2`` status document.

Pure orchestration, no printing: :class:`Watch` ``step(timeout_s)`` polls the sources
once (waiting at most ``timeout_s``), hands every line to the :class:`Recorder` (when
there is one) and to the per-source state, and returns the findings raised or cleared
in that step; :meth:`Watch.status` is the status document; :meth:`Watch.close` closes
the sources and finishes the recording.

A line's form and source key come from :func:`dracc.ingest.live.forms.classify`, a cheap
look at its bytes: for NMEA 0183 the key dracc's reader gives it (the TAG block's ``s:``
where there is one, else the talker of ``$TTSSS``; a proprietary ``$P...`` sentence: its
address, ``PASHR``), ``n2k:addr<src>`` for a NMEA 2000 text line, ``signalk:<source>`` for
a Signal K delta.  ``records`` counts the lines heard (a line the reader will reject for
its checksum is heard all the same).  Per key: the records, the lines a second over the
last minute (60 one-second buckets; ``lines_per_s``: every sentence type counted, so an
INS sending GGA, HDT and VTG at 1 Hz hears 3 lines a second, never called 3 Hz;
``dracc inspect`` gives the epoch rate in Hz), the last receive time and its age, and the
latency (receive time minus the TAG ``c:`` time, where the line has one; ``c:`` in
seconds up to 10 digits, else milliseconds, as :mod:`dracc.ingest.tagblock` reads it).

Findings: ``availability/dropout`` is raised for a source silent longer than
``dropout_s`` and cleared at its next line, each with its evidence (``last_utc``,
``age_s``): no data.  (Data that keeps arriving but does not change is the window's
``frozen`` and ``stuck``.)  One silence is one alarm: the window's own ``dropout`` check
of a source (below) is not raised again for a gap the live alarm already covers
(:func:`dracc.math.integrity.causes.overlaps`); only a gap it did not see is.  With a
:class:`~dracc.pipeline.watch_analysis.LiveAnalyser`, every line also goes into its
rolling window, and each finished analysis of the window (the library's
``analyse_voyage``: the audit's integrity checks) raises a finding for every check that
fails (check, name, source: its message, statistic, threshold and evidence) and clears
an open one when the same check passes again -- at most a window after the fault ended,
when the window no longer holds it.  One cause is one alarm: a failed check the window's
analysis finds caused by another (``cause``; :mod:`dracc.math.integrity.causes`) is
listed under that one's ``consequences``, not raised.  Open findings are all kept; of
the cleared ones the last :data:`KEEP_CLEARED`.

The recording (``Recorder``) writes each line with its receive time; a line with a TAG
block keeps it (its ``s:``), a line without one is recorded with ``c:`` only, so that
the recording reads back with the same source keys (talkers) as the lines heard.  A
write the disk refuses (full, made read-only) stops nothing: ``recording/write_failed``
is raised once, with the lines lost so far as its evidence, the watch goes on listening
and analysing, and the finding is cleared when the recording writes again.
"""

from __future__ import annotations

import datetime as dt
import time
from collections import Counter, deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

from dracc.ingest.live import LiveSource, Recorder, classify, poll_all
from dracc.ingest.live.forms import NMEA_FORMS
from dracc.ingest.live.record import RETRY_S as RECORD_RETRY_S
from dracc.ingest.live.record import tag_line
from dracc.math.integrity.causes import event_span, overlaps
from dracc.pipeline.watch_analysis import LiveAnalyser, WindowResult

SCHEMA = "dracc.watch/2"  #: /2 (issue 32): sources[].lines_per_s replaced rate_hz
RATE_WINDOW_S = 60  #: the rate is over this many seconds (one bucket per second)
KEEP_CLEARED = 200  #: cleared findings kept in the status, the latest
KEEP_SILENCES = 50  #: per source, the silences alarmed live that a window can still hold
MAX_SOURCES = 1000  #: source keys tracked at most (bounded memory against garbage keys)


def utc(ns: int) -> str:
    """ISO 8601 UTC of a time in ns, to the millisecond."""
    t = dt.datetime(1970, 1, 1) + dt.timedelta(microseconds=ns // 1000)
    return t.strftime("%Y-%m-%dT%H:%M:%S.") + f"{t.microsecond // 1000:03d}Z"


@dataclass
class SourceState:
    """Rolling state of one source key, bounded: 60 rate buckets and a few numbers."""

    records: int = 0
    last_ns: int = 0
    latency_s: float | None = None
    buckets: deque[list[int]] = field(default_factory=lambda: deque(maxlen=RATE_WINDOW_S))
    silent: dict[str, Any] | None = None  #: the open dropout finding (nothing received)
    #: the silences alarmed live, (last line, next line or None while open) in ns
    silences: deque[tuple[int, int | None]] = field(
        default_factory=lambda: deque(maxlen=KEEP_SILENCES)
    )

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

    def lines_per_s(self, now_ns: int) -> float:
        """Lines per second (of every sentence type: not a rate in Hz) over the last
        :data:`RATE_WINDOW_S` seconds (fewer at the start: since the first line)."""
        now_s = now_ns // 1_000_000_000
        n = sum(c for s, c in self.buckets if s > now_s - RATE_WINDOW_S)
        if not n or not self.buckets:
            return 0.0
        first = max(self.buckets[0][0], now_s - RATE_WINDOW_S + 1)
        return round(n / max(1.0, now_ns / 1e9 - first), 3)


class Watch:
    """The live loop over ``sources`` (see the module docstring).  ``clock`` gives the
    time in ns (injected by tests); ``dropout_s`` the silence that raises ``dropout``."""

    def __init__(
        self,
        sources: Sequence[LiveSource],
        recorder: Recorder | None = None,
        dropout_s: float = 10.0,
        clock: Callable[[], int] = time.time_ns,
        analyser: LiveAnalyser | None = None,
    ) -> None:
        self.sources = list(sources)
        self.recorder = recorder
        self.dropout_ns = int(dropout_s * 1e9)
        self.clock = clock
        self.started_ns = clock()
        self.received = 0
        self.unkeyed = 0  #: lines that are no sentence (recorded, counted, no source)
        self.state: dict[str, SourceState] = {}
        self.cleared: deque[dict[str, Any]] = deque(maxlen=KEEP_CLEARED)
        self.analyser = analyser
        #: open integrity findings by (check, name, source)
        self.open_checks: dict[tuple[str, str, str | None], dict[str, Any]] = {}
        self.record_fault: dict[str, Any] | None = None  #: open ``recording/write_failed``

    def step(self, timeout_s: float = 0.1) -> list[dict[str, Any]]:
        """Poll once; record and count the lines; return the findings raised or cleared
        (each a finding dict with ``event``: ``raised`` or ``cleared``)."""
        events: list[dict[str, Any]] = []
        if len(self.sources) == 1:
            got = [(0, ln) for ln in self.sources[0].poll(timeout_s)]
        else:
            got = poll_all(self.sources, timeout_s)
        analyser = self.analyser
        for _, (recv_ns, line) in got:
            self.received += 1
            info = classify(line)
            recorded = None
            if self.recorder is not None:
                recorded = self.recorder.write(line, recv_ns, form=info.form)
            key, c_ns = info.key, info.c_ns
            if analyser is not None:  # the window holds the lines as recorded
                if recorded is None:
                    recorded = tag_line(line, recv_ns) if info.form in NMEA_FORMS else line
                analyser.add(info.form, c_ns or recv_ns, recorded)
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
            if st.silent is not None:
                events.append(self._clear(st, recv_ns))
        now = self.clock()
        if self.recorder is not None:
            self.recorder.tick()
            events += self._recording(now)
        if analyser is not None:
            result = analyser.end_step()
            if result is not None:
                events += self._integrity(result, now)
        for key, st in self.state.items():
            if st.silent is None and now - st.last_ns > self.dropout_ns:
                events.append(self._raise(key, st, now))
        return events

    def _recording(self, now: int) -> list[dict[str, Any]]:
        """Raise ``recording/write_failed`` when the recorder has a fault, once; clear it
        when the recorder writes again."""
        assert self.recorder is not None
        fault, open_ = self.recorder.fault, self.record_fault
        if fault is not None and open_ is None:
            self.record_fault = {
                "check": "recording",
                "name": "write_failed",
                "source": None,
                "raised_utc": utc(now),
                "cleared_utc": None,
                "message": f"{fault}; still listening, the lines heard meanwhile are lost "
                "(counted), the recording is tried again every "
                f"{RECORD_RETRY_S:g} s",
                "evidence": {"lost_lines": self.recorder.lost},
            }
            return [{"event": "raised", **self.record_fault}]
        if fault is None and open_ is not None:
            lost = self._lost()
            done = {
                **open_,
                "cleared_utc": utc(now),
                "message": f"recording again; {lost['lost_lines']} lines heard while the "
                "disk refused them were lost",
                "evidence": lost,
            }
            self.record_fault = None
            self.cleared.append(done)
            return [{"event": "cleared", **done}]
        return []

    def _lost(self) -> dict[str, int]:
        return {"lost_lines": self.recorder.lost if self.recorder is not None else 0}

    def _raise(self, key: str, st: SourceState, now: int) -> dict[str, Any]:
        age = round((now - st.last_ns) / 1e9, 3)
        st.silent = {
            "check": "availability",
            "name": "dropout",
            "source": key,
            "raised_utc": utc(now),
            "cleared_utc": None,
            "message": f"{key}: nothing received for {age:.1f} s "
            f"(more than {self.dropout_ns / 1e9:g} s)",
            "evidence": {"last_utc": utc(st.last_ns), "age_s": age},
        }
        st.silences.append((st.last_ns, None))
        return {"event": "raised", **st.silent}

    def _clear(self, st: SourceState, recv_ns: int) -> dict[str, Any]:
        assert st.silent is not None
        done = {**st.silent, "cleared_utc": utc(recv_ns)}
        st.silent = None
        st.silences[-1] = (st.silences[-1][0], recv_ns)
        self.cleared.append(done)
        return {"event": "cleared", **done}

    def _integrity(self, result: WindowResult, now: int) -> list[dict[str, Any]]:
        """Raise a finding for each failed check not open yet; clear the open ones whose
        check passed in this analysis."""
        events: list[dict[str, Any]] = []
        made = {(c["check"], c["name"], c["source"]): c for c in result.checks}
        for key, c in made.items():
            found = self.open_checks.get(key)
            # a failed check another caused is listed under it, no alarm of its own
            if c["status"] != "fail" or c.get("cause") or self._alarmed_live(c, now):
                continue
            if found is None:
                found = self.open_checks[key] = {
                    "check": c["check"],
                    "name": c["name"],
                    "source": c["source"],
                    "role": c["role"],
                    "raised_utc": utc(now),
                    "cleared_utc": None,
                    "message": c["message"],
                    "evidence": c["evidence"],
                    "consequences": c.get("consequences", []),
                }
                events.append({"event": "raised", **found})
            else:
                found.update(
                    message=c["message"],
                    evidence=c["evidence"],
                    consequences=c.get("consequences", []),
                )
        for key in list(self.open_checks):
            now_made = made.get(key)
            # cleared: the check passed, or it was not reported while its source was
            # analysed (some checks are only reported when they fail)
            if (now_made is None and key[2] in result.roles) or (
                now_made is not None and now_made["status"] == "pass"
            ):
                done = {**self.open_checks.pop(key), "cleared_utc": utc(now)}
                self.cleared.append(done)
                events.append({"event": "cleared", **done})
        return events

    def _alarmed_live(self, c: dict[str, Any], now: int) -> bool:
        """A window's failed ``dropout`` check whose every gap the live dropout of its
        source already alarmed (open or cleared): the same silence, not a new alarm."""
        st = self.state.get(str(c["source"]))
        if c["name"] != "dropout" or st is None or not st.silences:
            return False
        heard = [(a / 1e9, (now if b is None else b) / 1e9) for a, b in st.silences]
        gaps = [event_span(g) for g in c["evidence"]["items"]]
        return bool(gaps) and all(g is not None and overlaps(g, heard) for g in gaps)

    def dropped(self) -> dict[str, int]:
        """Input the sources dropped, by reason (summed over the sources)."""
        total: Counter[str] = Counter()
        for s in self.sources:
            total.update(s.rejected)
        return dict(sorted(total.items()))

    def status(self) -> dict[str, Any]:
        """The ``dracc.watch/2`` status document (JSON-ready)."""
        now = self.clock()
        last = self.analyser.last if self.analyser is not None else None
        roles = last.roles if last is not None else {}
        sources = {
            key: {
                "role": ",".join(roles[key]) if roles.get(key) else None,
                "records": st.records,
                "lines_per_s": st.lines_per_s(now),
                "last_utc": utc(st.last_ns),
                "age_s": round((now - st.last_ns) / 1e9, 3),
                "latency_s": st.latency_s,
            }
            for key, st in sorted(self.state.items())
        }
        open_ = [st.silent for st in self.state.values() if st.silent is not None]
        open_ += list(self.open_checks.values())
        if self.record_fault is not None:
            self.record_fault["evidence"] = self._lost()
            open_.append(self.record_fault)
        findings = sorted([*self.cleared, *open_], key=lambda f: f["raised_utc"])
        return {
            "schema": SCHEMA,
            "started_utc": utc(self.started_ns),
            "now_utc": utc(now),
            "received": self.received,
            "unkeyed": self.unkeyed,
            "dropped": self.dropped(),
            "recording": str(self.recorder.current or "") if self.recorder else None,
            "recording_files": (
                {f: str(p) for f, p in self.recorder.current_files().items()}
                if self.recorder
                else None
            ),
            "recording_lost": self.recorder.lost if self.recorder else None,
            "inputs": [_input_status(src) for src in self.sources],
            "sources": sources,
            "findings": findings,
            "deviation": last.deviation if last is not None else None,
            "dead_reckoning": _dr_status(last),
            "analysis": self._analysis_status(last),
        }

    def _analysis_status(self, last: WindowResult | None) -> dict[str, Any] | None:
        """The analyser's state: window, runs, the last analysis (span, lines, time)."""
        if self.analyser is None:
            return None
        s = self.analyser.summary()
        first, lastn = s.pop("window_first_ns"), s.pop("window_last_ns")
        s["window_first_utc"] = utc(first) if first is not None else None
        s["window_last_utc"] = utc(lastn) if lastn is not None else None
        if last is not None:
            s["last_span_utc"] = [utc(last.span_utc_ns[0]), utc(last.span_utc_ns[1])]
            s["missing"] = last.missing
        return s

    def close(self) -> None:
        """Close the sources and finish the recording (flush, fsync, rename)."""
        for s in self.sources:
            s.close()
        if self.analyser is not None:
            self.analyser.close()
        if self.recorder is not None:
            self.recorder.close()


def _dr_status(last: WindowResult | None) -> dict[str, Any] | None:
    """The DR of the last analysis with its epoch as UTC."""
    if last is None or last.dead_reckoning is None:
        return None
    dr = dict(last.dead_reckoning)
    dr["epoch_utc"] = utc(dr.pop("epoch_utc_ns"))
    return dr


#: counters a live source may have beyond lines, bytes and rejects (TCP, serial, UDP)
_INPUT_COUNTERS = ("connects", "failures", "opens", "reopens", "datagrams", "iec450")


def _input_status(src: LiveSource) -> dict[str, Any]:
    """One live input as the status shows it: spec, kind, what it gave and dropped, its
    connections (TCP) or openings (serial)."""
    out: dict[str, Any] = {
        "spec": src.spec,
        "kind": src.kind,
        "lines": src.lines,
        "bytes": src.bytes,
        "dropped": dict(sorted(src.rejected.items())),
    }
    for name in _INPUT_COUNTERS:
        value = getattr(src, name, None)
        if isinstance(value, int):
            out[name] = value
    if getattr(src, "connected", None) is not None:
        out["connected"] = bool(src.connected)  # type: ignore[attr-defined]
    return out
