"""What a log holds, the report of ``dracc inspect``: sources and roles, every sentence
type read (time-only ZDA included), rates, time span and gaps, the lines not used (rejected
by reason, ignored by type, with examples), the account of every line, time-base decisions.

NMEA text files are streamed block by block (memory does not grow with the file); CSV
and MCAP files are read whole by their readers.  Per-source counts are taken on the
frames' categorical codes (:func:`dracc.ingest.summarize_frames`), never by sorting
strings.  The keys are documented in ``docs/ingest.md``;
:mod:`dracc.report.inspect_report` renders the report as tables.

The account of an NMEA text file's lines (``inputs[i]["accounting"]``; summed over the
files in ``accounting``; None for CSV and MCAP): every sentence or line is
counted once, as a sentence giving records (an RMC once, though it gives a position and
a ground row), a time-only sentence (ZDA: it sets the time base and gives no record), a qualifier
(``$PSXN,20``: the quality of the records of another sentence; no record either), an
ignored line or sentence (by type) or a rejected one (by reason), so that ``lines ==
sentences + time_only + qualifiers + ignored + rejected - shared``, ``shared`` being the sentences
found on a line after another one (a truncated sentence followed by a whole one, two
sentences fused on one line).
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from dracc.core.config import IngestConfig
from dracc.core.errors import DraccError
from dracc.core.timefmt import iso_utc
from dracc.frames import ClockStep, FileResult, Rejects, RoleChoice, SourceInfo, TimeEvents
from dracc.ingest import (
    detect_format,
    format_of,
    read_file,
    relabelled,
    scaled,
    summarize_frames,
)
from dracc.ingest.compressed import STDIN, needs_copy, unpacked
from dracc.ingest.demux import check_strict_rejects
from dracc.ingest.embedded_n2k import (
    Opener,
    may_hold_n2k,
    opener_of,
    read_n2k_alone,
    record_times,
    take_n2k_lines,
    take_off,
    text_format,
)
from dracc.ingest.nmea import StreamState, iter_nmea_blocks
from dracc.ingest.role_evidence import choice_note
from dracc.ingest.sources import assign_roles, merge_infos, separate_files
from dracc.ingest.timebase import CountedTimeEvents, merge_events

_EXAMPLES = 5  #: examples kept per ignored type over all files (as per reject reason)
_NO_EVENTS = {"duplicates": 0, "backsteps": 0, "gaps": 0, "max_gap_s": 0.0, "shared_stamps": 0}


@dataclass
class _FileRead:
    """One file's share of the report."""

    format: str
    lines: int
    rejects: Rejects
    time_events: TimeEvents
    notes: list[str]
    #: source -> duplicates, backsteps, gaps, max_gap_s, shared_stamps
    events: dict[str, dict[str, Any]]
    ignored: Counter[str]
    ignored_examples: dict[str, list[tuple[str, int, str]]]
    records: int | None = None  #: frame rows (None: the sum over the file's sources)
    time_only: Counter[str] = field(default_factory=Counter)  #: time-only sentences by type
    qualifiers: Counter[str] = field(default_factory=Counter)  #: qualifying sentences by type
    #: the file has no clock (:attr:`FileResult.clockless`): its sources get no rate
    clockless: bool = False
    #: its NMEA 2000 lines (an NMEA text log's): how many, and the sentences (records),
    #: ignored and rejected they gave
    n2k: dict[str, int] = field(
        default_factory=lambda: {"lines": 0, "sentences": 0, "ignored": 0, "rejected": 0}
    )


def _add_no_record(
    sources: dict[str, SourceInfo], counts: Counter[tuple[str, str, str]], file: str
) -> Counter[str]:
    """Add sentences that give no record (time-only, qualifiers: (source key, type,
    talker) -> n) to the file's sources; return them by type."""
    by_type: Counter[str] = Counter()
    for (key, stype, talker), n in counts.items():
        info = sources.setdefault(key, SourceInfo(key=key))
        info.sentences[stype] += n
        if talker:
            info.talkers[talker] += n
        info.files.add(file)
        by_type[stype] += n
    return by_type


def _read_nmea(
    p: Path,
    cfg: IngestConfig,
    sources: dict[str, SourceInfo],
    advance: Callable[[int], object] | None,
    name: str | None = None,
    opener: Opener | None = None,
    size_hint: int | None = None,
) -> _FileRead:
    """Stream an NMEA text file, summarising each block's frames into ``sources``, then
    its NMEA 2000 lines (:func:`_add_n2k`); ``name``: what the file is called (the log as
    given, ``p`` being its plain copy); ``opener``: the log is the stream it opens."""
    file = str(p) if name is None else name
    st = StreamState(file)
    loose = replace(cfg, strict=False) if cfg.strict else cfg  # judged once all is read
    blocks = iter_nmea_blocks(
        p, loose, st, progress=advance, name=file, opener=opener, size_hint=size_hint
    )
    for block in blocks:
        summarize_frames(block.frames, file, into=sources)
    f = _FileRead(
        "nmea",
        st.lines,
        st.rejects,
        st.time_events(),
        st.notes(),
        st.events.per_source,
        st.ignored,
        st.ignored_examples,
        time_only=_add_no_record(sources, st.time_only, file),
        qualifiers=_add_no_record(sources, st.qualifiers, file),
    )
    if may_hold_n2k(st.ignored, st.rejects.counts):
        _add_n2k(f, p, loose, sources, file, opener)
    check_strict_rejects(f.rejects, file, cfg)
    return f


def _add_n2k(
    f: _FileRead,
    p: Path,
    cfg: IngestConfig,
    sources: dict[str, SourceInfo],
    file: str,
    opener: Opener | None,
) -> None:
    """Add the NMEA 2000 lines of an NMEA text log to what its stream gave (``f``,
    ``sources``), decoded as ``analyze`` decodes them
    (:func:`~dracc.ingest.embedded_n2k.take_n2k_lines`); the times of its records, which
    NMEA 2000 inside NMEA 0183 takes, come from reading it once more."""

    def times() -> tuple[np.ndarray, np.ndarray]:
        parts = [
            record_times([b.frames])
            for b in iter_nmea_blocks(p, cfg, StreamState(file), name=file, opener=opener)
        ]
        return np.concatenate([a for a, _ in parts]), np.concatenate([b for _, b in parts])

    nmea_records = sum(s.records for s in sources.values())
    taken = take_n2k_lines(opener or opener_of(p), file, cfg, times)
    if taken is None:
        return
    take_off(taken, f.rejects, f.ignored, f.ignored_examples)
    r = taken.result
    own = summarize_frames(r.frames, file)
    summarize_frames(r.frames, file, into=sources)
    f.n2k = {
        "lines": taken.lines,
        "sentences": sum(sum(s.sentences.values()) for s in own.values()),
        "ignored": sum(r.ignored.values()),
        "rejected": r.rejects.total,
    }
    f.format = text_format(f.format, nmea_records, taken)
    f.rejects.merge(r.rejects)
    f.ignored.update(r.ignored)
    for k, ex in r.ignored_examples.items():
        f.ignored_examples.setdefault(k, []).extend(ex)
    merge_events(f.time_events, r.time_events)
    f.time_events.decisions.extend(r.time_events.decisions)
    if isinstance(r.time_events, CountedTimeEvents):
        f.events.update(r.time_events.per_source)
    f.notes.extend(r.notes)


def _read_packed(
    p: Path,
    cfg: IngestConfig,
    sources: dict[str, SourceInfo],
    advance: Callable[[int], object] | None,
) -> _FileRead:
    """A compressed log or standard input: NMEA text streamed as it is decompressed
    (every sentence type counted, as for a plain file), the others read whole from a
    plain copy (:func:`read_file` says what they hold as of the log given)."""
    with unpacked(p, cfg) as packed:
        assert packed is not None  # needs_copy(p) said so
        if packed.kind is not None and format_of(packed.head(), b"", p) == "nmea":
            told = packed.progress(advance)
            f = _read_nmea(p, cfg, sources, told, str(p), packed.open, packed.size_hint)
        else:
            with packed.copy() as plain:
                try:
                    f = _read_file(plain, cfg, sources, advance, given=p)
                except DraccError as err:  # said of the log as given, not of its copy
                    raise type(err)(str(err).replace(str(plain), str(p))) from err
    f.notes = packed.notes + f.notes
    return f


def _read_file(
    p: Path,
    cfg: IngestConfig,
    sources: dict[str, SourceInfo],
    advance: Callable[[int], object] | None,
    given: Path | None = None,
) -> _FileRead:
    """A plain file ``p`` (the plain copy of the log ``given``, where given): NMEA text
    streamed, and so a log of NMEA 2000 lines of several forms (or with NMEA 0183 ones);
    the others read whole by their readers (CSV, MCAP, NMEA 2000 ...)."""
    name = str(p if given is None else given)
    fmt = detect_format(p)
    r = read_n2k_alone(p, cfg) if fmt == "n2k" else None
    if fmt == "nmea" or (fmt == "n2k" and r is None):
        told = advance if given is None else scaled(advance, given, p)
        return _read_nmea(p, cfg, sources, told, name=name)
    r = read_file(p, cfg) if r is None else r
    if given is not None:
        r = relabelled(r, str(p), name, [])
    return _whole(r, sources, p if given is None else given, advance)


def _whole(
    r: FileResult,
    sources: dict[str, SourceInfo],
    p: Path,
    advance: Callable[[int], object] | None,
) -> _FileRead:
    """A file read whole (``r``): its summary into ``sources``; its time events as its
    reader counted them for ``analyze`` (:func:`~dracc.ingest.timebase.feed_frames`),
    with their figures per source."""
    summarize_frames(r.frames, r.path, into=sources)
    tev = r.time_events
    if advance is not None and str(p) != STDIN:
        advance(p.stat().st_size)
    return _FileRead(
        r.format,
        r.lines,
        r.rejects,
        tev,
        r.notes,
        tev.per_source if isinstance(tev, CountedTimeEvents) else {},
        r.ignored,
        r.ignored_examples,
        records=r.records,
        clockless=r.clockless,
    )


def _accounting(f: _FileRead, sentences: Counter[str]) -> dict[str, int] | None:
    """The account of an NMEA text file's lines (see the module doc); ``sentences``: the
    file's sentence counts by type, time-only ones included.  None for CSV and MCAP,
    whose rows and messages are not one record each."""
    if f.format != "nmea":
        return None
    time_only = sum(f.time_only.values())
    qual = sum(f.qualifiers.values())
    n2k = f.n2k
    rec = sum(sentences.values()) - time_only - qual - n2k["sentences"]
    ign = sum(f.ignored.values()) - n2k["ignored"]
    rej = sum(f.rejects.counts.values()) - n2k["rejected"]
    return {
        "lines": f.lines,
        "sentences": rec,
        "time_only": time_only,
        "qualifiers": qual,
        "n2k": n2k["lines"],
        "ignored": ign,
        "rejected": rej,
        "shared": rec + time_only + qual + n2k["lines"] + ign + rej - f.lines,
    }


def _examples(ex: dict[str, list[tuple[str, int, str]]]) -> dict[str, list[dict[str, Any]]]:
    return {
        r: [{"file": f, "line": ln, "text": t} for f, ln, t in e] for r, e in sorted(ex.items())
    }


def inspect_logs(
    paths: list[Path], cfg: IngestConfig, advance: Callable[[int], object] | None = None
) -> dict[str, Any]:
    """The inspection report of ``paths`` as a JSON-ready dict (``cfg``: the
    :class:`~dracc.core.config.IngestConfig`).  ``advance(n)`` is told each n bytes read."""
    # each file's sources: a key two files share is one source only if separate_files says so
    per_file: list[tuple[str, dict[str, SourceInfo]]] = []
    per_file_events: list[tuple[str, dict[str, Any]]] = []
    per_file_steps: list[tuple[str, list[ClockStep]]] = []
    clockless_files: set[str] = set()
    rejects = Rejects()
    te = TimeEvents()
    inputs: list[dict[str, Any]] = []
    accounts: list[dict[str, int] | None] = []
    lines = 0
    ignored: Counter[str] = Counter()
    ignored_examples: dict[str, list[tuple[str, int, str]]] = {}
    notes: list[str] = []
    for p in paths:
        sources: dict[str, SourceInfo] = {}
        per_file.append((str(p), sources))
        if needs_copy(p):  # compressed, or standard input
            f = _read_packed(p, cfg, sources, advance)
        else:
            f = _read_file(p, cfg, sources, advance)
        lines += f.lines
        rejects.merge(f.rejects)
        ignored.update(f.ignored)
        for k, ex in f.ignored_examples.items():
            kept = ignored_examples.setdefault(k, [])
            kept.extend(ex[: max(0, _EXAMPLES - len(kept))])
        tev = f.time_events
        per_file_steps.append((str(p), tev.steps))
        merge_events(te, tev)  # the back-steps named as the sources are, below
        te.decisions.extend(f"{p.name}: {d}" for d in tev.decisions)
        te.examples.extend(tev.examples[:6])
        notes.extend(f"{p.name}: {n}" for n in f.notes)
        per_file_events.append((str(p), f.events))
        if f.clockless:
            clockless_files.add(str(p))
        file_sent: Counter[str] = Counter()
        for s in sources.values():
            file_sent.update(s.sentences)
        inputs.append(
            {
                "path": str(p),
                "format": f.format,
                "lines": f.lines,
                "records": f.records
                if f.records is not None
                else sum(s.records for s in sources.values()),
                "sentences": dict(sorted(file_sent.items())),
                "time_only": dict(sorted(f.time_only.items())),
                "qualifiers": dict(sorted(f.qualifiers.items())),
                "ignored": dict(sorted(f.ignored.items())),
                "rejected": dict(f.rejects.counts),
                "accounting": _accounting(f, file_sent),
            }
        )
        accounts.append(inputs[-1]["accounting"])
    renames, identity_notes = separate_files(per_file) if len(per_file) > 1 else ({}, [])
    merged = merge_infos(per_file, renames)
    events: dict[str, dict[str, Any]] = {}
    for fname, per_src in per_file_events:
        for key, ev in per_src.items():
            agg = events.setdefault(renames.get(fname, {}).get(key, key), dict(_NO_EVENTS))
            for k in ("duplicates", "backsteps", "gaps", "shared_stamps"):
                agg[k] += ev[k]
            agg["max_gap_s"] = max(agg["max_gap_s"], ev["max_gap_s"])
    te.steps = [
        replace(s, source=renames.get(fname, {}).get(s.source, s.source))
        for fname, steps in per_file_steps
        for s in steps
    ]
    te.decisions.extend(identity_notes)
    candidates: dict[str, list[str]] = {}
    role_notes = assign_roles(merged, dict(cfg.sources), candidates)
    choices = _choices(paths, cfg, merged, candidates, role_notes)
    all_sent: Counter[str] = Counter()
    for s in merged.values():
        all_sent.update(s.sentences)
    return {
        "lines": lines,
        "sentences": dict(sorted(all_sent.items())),
        "sources": {
            key: _source_out(
                merged[key],
                events.get(key, _NO_EVENTS),
                clockless=bool(merged[key].files) and merged[key].files <= clockless_files,
            )
            for key in sorted(merged)
        },
        "rejected": dict(sorted(rejects.counts.items())),
        "rejected_examples": _examples(rejects.examples),
        "ignored": dict(sorted(ignored.items())),
        "ignored_examples": _examples(ignored_examples),
        "accounting": _total_accounting(accounts),
        "time": {
            "duplicates": te.duplicates,
            "backsteps": te.backsteps,
            "gaps": te.gaps,
            "rollovers": te.rollovers,
            "implausible_dates": te.implausible_dates,
            "shared_stamps": sum(ev["shared_stamps"] for ev in events.values()),
            "decisions": te.decisions,
            "examples": [{"file": f, "line": ln, "what": w} for f, ln, w in te.examples],
            "steps": [_step_out(s) for s in te.steps],
        },
        "roles": role_notes,
        "choices": [
            {
                "role": c.role,
                "chosen": c.chosen,
                "why": c.why,
                "witnesses": [{"source": k, "why_not": w} for k, w in c.runners_up],
                "evidence": c.evidence,
            }
            for c in choices
        ],
        "notes": notes,
        "inputs": inputs,
    }


def _choices(
    paths: list[Path],
    cfg: IngestConfig,
    merged: dict[str, SourceInfo],
    candidates: dict[str, list[str]],
    notes: list[str],
) -> list[RoleChoice]:
    """The roles several sources could fill, chosen by the evidence of the values (as
    ``analyze`` chooses them: the logs are read into frames once more for it; only where
    a role has several candidates).  The roles are set on ``merged``, the choices said in
    ``notes``."""
    if not any(len(v) > 1 for v in candidates.values()):
        return []
    from dracc.ingest import read_logs  # the whole reader, only for a choice to make

    voyage = read_logs(paths, cfg)
    for key, info in voyage.sources.items():
        if key in merged:
            merged[key].roles = list(info.roles)
    notes.extend(choice_note(c) for c in voyage.choices)
    return voyage.choices


def _total_accounting(parts: list[dict[str, int] | None]) -> dict[str, int] | None:
    """The accounts of the NMEA text files summed (None where there is none)."""
    have = [a for a in parts if a is not None]
    return {k: sum(a[k] for a in have) for k in have[0]} if have else None


def _step_out(s: ClockStep) -> dict[str, Any]:
    """One back-step of a source's clock in the report."""
    return {
        "file": s.file,
        "line": s.line,
        "source": s.source,
        "sentence": s.sentence,
        "from_utc": iso_utc(s.from_ns, "ms"),
        "to_utc": iso_utc(s.to_ns, "ms"),
        "step_s": (s.to_ns - s.from_ns) / 1e9,
    }


def rate_of_source(sentences: dict[str, int], span_s: float) -> tuple[float | None, str | None]:
    """(rate in Hz, its sentence type): the rate of the source's most frequent sentence
    type over its span, the epoch rate of a source that sends each type once an epoch (an
    INS at 1 Hz sending GGA, HDT and VTG: 1 Hz, never the 3 sentences a second of them
    all); (None, None) without a span."""
    if span_s <= 0 or not sentences:
        return None, None
    kind, n = max(sorted(sentences.items()), key=lambda kv: kv[1])
    return (n - 1) / span_s, kind


def _source_out(s: SourceInfo, ev: dict[str, Any], clockless: bool = False) -> dict[str, Any]:
    """One source's entry of the report (no rate where its file has no clock: the times
    are only the records' order)."""
    span_s = (
        (s.last_ns - s.first_ns) / 1e9 if s.first_ns is not None and s.last_ns is not None else 0.0
    )
    rate_hz, rate_of = rate_of_source(s.sentences, 0.0 if clockless else span_s)
    return {
        "role": s.role,
        "roles": list(s.roles),
        "records": s.records,
        "sentences": dict(sorted(s.sentences.items())),
        "talkers": dict(sorted(s.talkers.items())),
        "first_utc": iso_utc(s.first_ns),
        "last_utc": iso_utc(s.last_ns),
        "span_s": span_s,
        "rate_hz": rate_hz,
        "rate_sentence": rate_of,
        "clockless": clockless,
        "gaps": ev["gaps"],
        "max_gap_s": ev["max_gap_s"],
        "duplicates": ev["duplicates"],
        "shared_stamps": ev["shared_stamps"],
        "backsteps": ev["backsteps"],
        "files": sorted(s.files),
    }
