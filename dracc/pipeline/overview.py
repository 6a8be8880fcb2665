"""What the ingest saw, summarised for the report: the input files, the sources, the time
base's findings, the recording spells, the thinned position tracks for the plots and the
thinned heading tracks for the exports.

Raises :class:`~dracc.core.errors.InsufficientDataError` when the logs hold no usable
record at all, the one case the analysis cannot report on.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np
import pandas as pd

from dracc.core.errors import InsufficientDataError
from dracc.core.units import NS_PER_S
from dracc.frames import Voyage
from dracc.ingest.interleaved import interleaved_note
from dracc.ingest.role_evidence import choice_note
from dracc.math.clock import SourceClock
from dracc.pipeline.results import HeadingTrack, InputFile, SourceRow, TimeSummary, Track
from dracc.pipeline.selection import role_of, valid_positions

#: at most this many points per source in the plotting tracks
TRACK_POINTS = 4000
#: the heading tracks keep the first record of every this many seconds per source
HEADING_STEP_S = 10.0
#: records further apart than this (in every frame) form separate recording spells
SPELL_GAP_S = 6 * 3600.0


def input_files(voyage: Voyage) -> tuple[InputFile, ...]:
    """One row per input file as the ingest saw it."""
    return tuple(
        InputFile(
            path=str(f["path"]),
            format=str(f["format"]),
            lines=int(f["lines"]),
            records=int(f["records"]),
            rejected=dict(f.get("rejected", {})),
            ignored={str(k): int(v) for k, v in f.get("ignored", {}).items()},
        )
        for f in voyage.inputs
    )


def source_rows(
    voyage: Voyage, clocks: dict[str, SourceClock] | None = None
) -> tuple[SourceRow, ...]:
    """One row per source key: roles, records, sentences and time span; where a role had
    several candidates, why each was chosen or kept as a witness; its clock."""
    clocks = clocks or {}
    witness = {k: (c.role, why) for c in voyage.choices for k, why in c.runners_up}
    chosen = {c.chosen: f"chosen for {c.role}: {c.why}" for c in voyage.choices}
    return tuple(
        SourceRow(
            key=str(k),
            roles=tuple(s.roles),
            records=int(s.records),
            sentences={str(a): int(b) for a, b in s.sentences.items()},
            first_ns=s.first_ns,
            last_ns=s.last_ns,
            witness_for=witness.get(k, (None, None))[0],
            choice=witness.get(k, (None, None))[1] or chosen.get(k),
            clock=clocks.get(k),
        )
        for k, s in voyage.sources.items()
    )


def time_span(
    voyage: Voyage, inputs: tuple[InputFile, ...], sources: tuple[SourceRow, ...]
) -> tuple[int, int]:
    """(first ns, last ns) over every source; :class:`InsufficientDataError` saying why
    when no source has a record."""
    firsts = [s.first_ns for s in sources if s.first_ns is not None]
    lasts = [s.last_ns for s in sources if s.last_ns is not None]
    if not firsts:
        why = ", ".join(f"{k} {v}" for k, v in voyage.rejects.counts.most_common(4))
        hint = (
            "; the log carries no date: give it with --date YYYY-MM-DD"
            if voyage.rejects.counts.get("no_date")
            else ""
        )
        raise InsufficientDataError(
            "no usable record in "
            + (", ".join(f.path for f in inputs) or "the input")
            + f" ({voyage.lines} lines read, {voyage.rejects.total} rejected"
            + (f": {why}" if why else "")
            + ")"
            + hint
        )
    return int(min(firsts)), int(max(lasts))


def time_summary(voyage: Voyage) -> TimeSummary:
    """What the time base found (counted, never silently applied)."""
    te = voyage.time_events
    return TimeSummary(
        duplicates=te.duplicates,
        backsteps=te.backsteps,
        gaps=te.gaps,
        rollovers=te.rollovers,
        implausible_dates=te.implausible_dates,
        decisions=tuple(te.decisions),
        assumed_date=te.assumed_date,
    )


def recording_spells(frames: Mapping[str, pd.DataFrame], gap_ns: int) -> list[tuple[int, int, int]]:
    """(first ns, last ns, records) of each spell of recording: the records of all frames,
    cut where none comes for more than ``gap_ns``.  Frames are sorted by time."""
    runs = []
    for df in frames.values():
        if df is None or not len(df):
            continue
        t = df["time_ns"].to_numpy(np.int64)
        cut = np.flatnonzero(np.diff(t) > gap_ns)
        starts, ends = np.r_[0, cut + 1], np.r_[cut, len(t) - 1]
        runs += [(int(t[a]), int(t[b]), int(b - a + 1)) for a, b in zip(starts, ends, strict=True)]
    spells: list[tuple[int, int, int]] = []
    for a, b, n in sorted(runs):
        if spells and a - spells[-1][1] <= gap_ns:
            spells[-1] = (spells[-1][0], max(spells[-1][1], b), spells[-1][2] + n)
        else:
            spells.append((a, b, n))
    return spells


def voyage_notes(
    voyage: Voyage, inputs: tuple[InputFile, ...], sources: tuple[SourceRow, ...]
) -> list[str]:
    """The notes on the input as a whole: merged files, recording spells far apart,
    sources without a role."""
    notes = []
    if len(inputs) > 1:
        notes.append(f"{len(inputs)} files merged by time")
    spells = recording_spells(voyage.frames, int(SPELL_GAP_S * NS_PER_S))
    if len(spells) > 1:

        def when(a: int, b: int) -> str:
            fa, fb = (f"{pd.Timestamp(x, tz='UTC'):%Y-%m-%d %H:%MZ}" for x in (a, b))
            return fa if fa == fb else f"{fa} to {fb}"

        shown = "; ".join(f"{when(a, b)} ({n:,} records)" for a, b, n in spells[:6])
        more = f"; and {len(spells) - 6} more" if len(spells) > 6 else ""
        notes.append(
            f"the records fall in {len(spells)} spells more than {SPELL_GAP_S / 3600:g} h "
            f"apart: {shown}{more}. The period spans them all; the statistics use "
            "the instants with readings only (a stray record with a wrong date shows here)"
        )
    notes.extend(choice_note(c) for c in voyage.choices)
    notes.extend(
        interleaved_note(k, s.interleaved) for k, s in voyage.sources.items() if s.interleaved
    )
    witnesses = {k: c.role for c in voyage.choices for k in c.witnesses}
    if witnesses:
        notes.append(
            "witnesses (candidates not chosen, compared with the chosen source): "
            + ", ".join(f"{k} ({role})" for k, role in witnesses.items())
        )
    unassigned = [
        s.key
        for s in sources
        if not s.roles and s.key not in witnesses and not voyage.sources[s.key].interleaved
    ]
    if unassigned:
        notes.append(
            "sources without a role: " + ", ".join(unassigned) + "; assign one with --role KEY=ROLE"
        )
    return notes


def tracks(voyage: Voyage) -> tuple[Track, ...]:
    """Every position source, thinned to at most TRACK_POINTS points, for the plots."""
    pos = voyage.frames.get("position")
    if pos is None or pos.empty:
        return ()
    out = []
    pos = valid_positions(pos)
    for key, df in pos.groupby("source", observed=True, sort=False):
        if df.empty:
            continue
        step = max(1, math.ceil(len(df) / TRACK_POINTS))
        d = df.iloc[::step]
        out.append(
            Track(
                source=str(key),
                role=role_of(voyage, str(key)),
                time_ns=d["time_ns"].to_numpy(np.int64),
                lat_rad=d["lat_rad"].to_numpy(float),
                lon_rad=d["lon_rad"].to_numpy(float),
            )
        )
    return tuple(out)


def heading_tracks(voyage: Voyage, step_s: float = HEADING_STEP_S) -> tuple[HeadingTrack, ...]:
    """Every heading source, thinned to its first record in each ``step_s`` seconds of
    UTC (bins from the epoch, so sources share them); NaN headings left out."""
    hdg = voyage.frames.get("heading")
    if hdg is None or hdg.empty:
        return ()
    step_ns = int(round(step_s * NS_PER_S))
    out = []
    for key, df in hdg.groupby("source", observed=True, sort=False):
        d = df[np.isfinite(df["heading_rad"].to_numpy(float))]
        if d.empty:
            continue
        t = d["time_ns"].to_numpy(np.int64)
        order = np.argsort(t, kind="stable")
        t = t[order]
        bins = t // step_ns
        keep = order[np.r_[True, bins[1:] != bins[:-1]]]
        ref = d["reference"].astype(object).to_numpy()[keep]
        out.append(
            HeadingTrack(
                source=str(key),
                role=role_of(voyage, str(key)),
                time_ns=d["time_ns"].to_numpy(np.int64)[keep],
                heading_rad=d["heading_rad"].to_numpy(float)[keep],
                reference=np.array([r if r in ("T", "M") else "" for r in ref], dtype=object),
            )
        )
    return tuple(out)
