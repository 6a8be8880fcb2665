"""The running totals of a stream of NMEA text (:class:`StreamState`: lines, rejects,
ignored types, statistics, time base and events, the sentences that give only a time,
and the notes they give) and one resolved block of a file (:class:`Block`)."""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field

import pandas as pd

from dracc.core.errors import IngestError
from dracc.frames import Rejects
from dracc.ingest.nmea.groups import GroupCarry
from dracc.ingest.nmea.parsed import ParsedBlock
from dracc.ingest.nmea.sentences import IGNORED_EXAMPLES, REASONS
from dracc.ingest.timebase import CountedTimeEvents, EventCounter, TimeBase


@dataclass
class Block:
    """One resolved block from :func:`iter_nmea_blocks`: canonical frames (times resolved,
    in stream order, not yet sorted) and the block's bookkeeping."""

    frames: dict[str, pd.DataFrame]
    lines: int  #: lines in this block
    first_line: int  #: 1-based number of the block's first line in the file
    bytes: int


@dataclass
class StreamState:
    """Running totals of a stream (filled while iterating)."""

    path: str
    lines: int = 0
    blank: int = 0
    bytes: int = 0
    rejects: Rejects = field(default_factory=Rejects)
    #: valid lines/sentences not used, by type (see :data:`IGNORED`), and their first examples
    ignored: Counter[str] = field(default_factory=Counter)
    ignored_examples: dict[str, list[tuple[str, int, str]]] = field(default_factory=dict)
    stats: Counter[str] = field(default_factory=Counter)
    timebase: TimeBase = field(default_factory=TimeBase)
    events: EventCounter = field(default_factory=EventCounter)
    #: sentences parsed, by type (every sentence once: an RMC's ground row is not counted;
    #: records later rejected for want of a date included)
    sentences: Counter[str] = field(default_factory=Counter)
    #: the sentences that give a time and no record (ZDA), by (source key, type, talker):
    #: they set the time base, so no frame holds them (counted by
    #: :func:`~dracc.ingest.nmea.reader.count_by_source`)
    time_only: Counter[tuple[str, str, str]] = field(default_factory=Counter)
    #: the sentences that only qualify records of other sentences (``$PSXN,20``, the
    #: quality of the attitude that follows), likewise: they give no record either
    qualifiers: Counter[tuple[str, str, str]] = field(default_factory=Counter)
    #: the head-qual of the latest ``$PSXN,20`` of each source (its TAG source, '' untagged),
    #: carried from block to block to the ``$PSXN,23`` headings that follow
    psxn_quality: dict[str, float] = field(default_factory=dict)
    split_talkers: dict[str, set[int]] = field(
        default_factory=dict
    )  #: talker -> decimals seen (fingerprint split)
    #: the TAG line groups (``g:``) still open, carried from block to block
    line_groups: GroupCarry = field(default_factory=GroupCarry)

    def time_events(self) -> CountedTimeEvents:
        """What the time base decided and the events counted (with the figures per
        source); the notes on the events last."""
        tb = self.timebase
        decisions = list(dict.fromkeys(tb.decisions))
        if tb.derived:
            decisions.append(
                f"{tb.derived} records without a time field took the time of the "
                "preceding timed record (or the logger/TAG time)"
            )
        if tb.backward_midnight:
            decisions.append(
                f"{tb.backward_midnight} steps back over midnight between interleaved clocks"
            )
        if tb.week_rollovers:
            decisions.append(
                f"{tb.week_rollovers} dates corrected for the GPS week rollover (+1024 weeks)"
            )
        if tb.implausible:
            decisions.append(
                f"{tb.implausible} implausible dates (before 2000 or in the future) not used"
            )
        if tb.date_changes:
            decisions.append(f"the date changed {tb.date_changes} times other than at midnight")
        te = self.events.time_events(decisions)
        te.rollovers = tb.rollovers
        te.implausible_dates = tb.week_rollovers + tb.implausible
        te.assumed_date = tb.assumed_date
        return te

    def count_block(
        self,
        pb: ParsedBlock,
        strict: bool,
        number: Callable[[int, int], int] | None = None,
        label: str = "{path}:{n}",
    ) -> int:
        """Add a parsed block's lines, statistics and rejects; return the stream line of its
        first line.  ``number(ln, line0)``: the number a reject example gets for the block's
        line ``ln`` (default: its line in the stream); ``label``: how the strict-mode error
        names it.  In ``strict`` mode the block's first rejected line raises IngestError."""
        line0 = self.lines + 1
        num = number or (lambda ln, first: ln + first - 1)
        self.lines += pb.n_lines
        self.blank += pb.n_blank
        self.stats.update(pb.stats)
        for reason, c in pb.reject_counts.items():
            self.rejects.counts[reason] += c
            ex = self.rejects.examples.setdefault(reason, [])
            for ln, text in pb.reject_examples.get(reason, [])[: max(0, 5 - len(ex))]:
                ex.append((self.path, num(ln, line0), text))
        self.ignored.update(pb.ignored)
        if pb.n_blank:
            self.ignored["blank"] += pb.n_blank
        for kind, exs in pb.ignored_examples.items():
            ex = self.ignored_examples.setdefault(kind, [])
            for ln, text in exs[: max(0, IGNORED_EXAMPLES - len(ex))]:
                ex.append((self.path, num(ln, line0), text))
        if strict and pb.first_fatal is not None:
            ln, reason, text = pb.first_fatal
            where = label.format(path=self.path, n=num(ln, line0))
            raise IngestError(f"{where}: rejected ({REASONS[reason]}): {text!r} (--strict)")
        return line0

    def notes(self) -> list[str]:
        s = self.stats
        out = []
        if s["no_checksum"]:
            out.append(
                f"{s['no_checksum']} sentences without checksum accepted (field checks only)"
            )
        if s["checksum_ignored"]:
            out.append(f"{s['checksum_ignored']} wrong checksums accepted (--ignore-checksum)")
        if s["tag_checksum_ignored"]:
            out.append(
                f"{s['tag_checksum_ignored']} wrong TAG checksums accepted (--ignore-checksum)"
            )
        if s["tag_group_joined"]:
            out.append(
                f"{s['tag_group_joined']} sentences of TAG line groups (g:) read with the "
                "source (s:) and time (c:) of their group's first line"
            )
        if s["tag_group_incomplete"]:
            out.append(
                f"{s['tag_group_incomplete']} sentences of TAG line groups (g:) without "
                "their group's first line (line group incomplete): read with their own "
                "source and time"
            )
        if s["tag_group_bad"]:
            out.append(f"{s['tag_group_bad']} unreadable TAG line-group parameters (g:) ignored")
        if s["one_digit_checksum"]:
            out.append(f"{s['one_digit_checksum']} one-digit checksums ('*5' for '*05') accepted")
        if s["doubled_start"]:
            out.append(f"{s['doubled_start']} doubled sentence starts ('$$') read as one")
        if s["pool_fallback"]:
            out.append("the worker pool failed; blocks were parsed in the main process")
        if s["prefix_other"]:
            out.append(f"{s['prefix_other']} line prefixes without a recognisable time ignored")
        for k, v in sorted(s.items()):
            if k.startswith("prefix_") and k != "prefix_other" and v:
                out.append(f"{v} lines with {k[7:]} prefix")
        for t, decs in self.split_talkers.items():
            out.append(
                f"talker {t}: position sentences with {sorted(decs)} decimals of minutes "
                f"come from different receivers: source keys {t}/<n>dp"
            )
        return out
