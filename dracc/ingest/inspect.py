"""What a log holds, the report of ``dracc inspect``: sources and roles, sentence counts,
rates, time span and gaps, rejected lines by reason with examples, time-base decisions.

NMEA text files are streamed block by block (memory does not grow with the file); CSV
and MCAP files are read whole by their readers.  The keys are documented in
``docs/ingest.md``; :mod:`dracc.report.inspect_report` renders the report as tables.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from dracc.core.config import IngestConfig
from dracc.core.timefmt import iso_utc
from dracc.frames import Rejects, TimeEvents
from dracc.ingest import detect_format, read_file
from dracc.ingest.compressed import STDIN, needs_copy
from dracc.ingest.nmea import StreamState, iter_nmea_blocks
from dracc.ingest.sources import assign_roles, merge_infos, separate_files, summarize
from dracc.ingest.timebase import EventCounter


def inspect_logs(
    paths: list[Path], cfg: IngestConfig, advance: Callable[[int], object] | None = None
) -> dict[str, Any]:
    """The inspection report of ``paths`` as a JSON-ready dict (``cfg``: the
    :class:`~dracc.core.config.IngestConfig`).  ``advance(n)`` is told each n bytes read."""
    per_file: list[tuple[str, dict[str, Any]]] = []  # each file's sources: a key two files share is
    per_file_events: list[
        tuple[str, dict[str, Any]]
    ] = []  # one source only if separate_files says so
    rejects = Rejects()
    te = TimeEvents()
    events: dict[str, dict[str, Any]] = {}
    inputs = []
    lines = 0
    all_sentences: Counter[str] = Counter()
    notes: list[str] = []
    for p in paths:
        packed = needs_copy(p)  # compressed, or standard input: read from a plain copy
        fmt = "packed" if packed else detect_format(p)
        sources: dict[str, Any] = {}
        per_file.append((str(p), sources))
        if fmt == "nmea":
            st = StreamState(str(p))
            for block in iter_nmea_blocks(p, cfg, st, progress=advance):
                summarize(block.frames, str(p), into=sources)
            n_lines, rej, tev, nts = st.lines, st.rejects, st.time_events(), st.notes()
            per_src = st.events.per_source
            all_sentences.update(st.sentences)
            records = None
        else:
            r = read_file(p, cfg)
            fmt = r.format
            summarize(r.frames, r.path, into=sources)
            ec = EventCounter(gap_s=cfg.gap_s, tolerance_s=cfg.backstep_tolerance_s)
            for kind, df in r.frames.items():
                if len(df):
                    ec.add(
                        kind,
                        df["source"].astype(str).to_numpy(),
                        df["time_ns"].to_numpy(),
                        np.ones(len(df), bool),
                        df["line"].to_numpy(),
                        r.path,
                        df["sentence"].astype(str).to_numpy(),
                    )
            n_lines, rej, tev, nts, per_src = (
                r.lines,
                r.rejects,
                r.time_events,
                r.notes,
                ec.per_source,
            )
            tot = ec.totals()
            tev.duplicates, tev.backsteps, tev.gaps = (
                tev.duplicates or tot["duplicates"],
                tev.backsteps or tot["backsteps"],
                tev.gaps or tot["gaps"],
            )
            records = r.records
            if advance is not None and str(p) != STDIN:
                advance(p.stat().st_size)
        lines += n_lines
        rejects.merge(rej)
        for k in ("duplicates", "backsteps", "gaps", "rollovers", "implausible_dates"):
            setattr(te, k, getattr(te, k) + getattr(tev, k))
        te.decisions.extend(f"{p.name}: {d}" for d in tev.decisions)
        te.examples.extend(tev.examples[:6])
        notes.extend(f"{p.name}: {n}" for n in nts)
        per_file_events.append((str(p), per_src))
        inputs.append(
            {
                "path": str(p),
                "format": fmt,
                "lines": n_lines,
                "records": records
                if records is not None
                else sum(s.records for s in sources.values() if str(p) in s.files),
                "rejected": dict(rej.counts),
            }
        )
    renames, identity_notes = separate_files(per_file) if len(per_file) > 1 else ({}, [])
    sources = merge_infos(per_file, renames)
    for f, per_src in per_file_events:
        for key, ev in per_src.items():
            key = renames.get(f, {}).get(key, key)
            agg = events.setdefault(
                key, {"duplicates": 0, "backsteps": 0, "gaps": 0, "max_gap_s": 0.0}
            )
            for k in ("duplicates", "backsteps", "gaps"):
                agg[k] += ev[k]
            agg["max_gap_s"] = max(agg["max_gap_s"], ev["max_gap_s"])
    te.decisions.extend(identity_notes)
    role_notes = assign_roles(sources, dict(cfg.sources))
    src_out = {}
    for key in sorted(sources):
        s = sources[key]
        span_s = (s.last_ns - s.first_ns) / 1e9 if s.first_ns is not None else 0.0  # type: ignore[operator]
        ev = events.get(key, {"duplicates": 0, "backsteps": 0, "gaps": 0, "max_gap_s": 0.0})
        nsent = sum(s.sentences.values())
        src_out[key] = {
            "role": s.role,
            "roles": list(s.roles),
            "records": s.records,
            "sentences": dict(sorted(s.sentences.items())),
            "talkers": dict(sorted(s.talkers.items())),
            "first_utc": iso_utc(s.first_ns),
            "last_utc": iso_utc(s.last_ns),
            "span_s": span_s,
            "rate_hz": (nsent - 1) / span_s if span_s > 0 else None,
            "gaps": ev["gaps"],
            "max_gap_s": ev["max_gap_s"],
            "duplicates": ev["duplicates"],
            "backsteps": ev["backsteps"],
            "files": sorted(s.files),
        }
    return {
        "lines": lines,
        "sources": src_out,
        "rejected": dict(sorted(rejects.counts.items())),
        "rejected_examples": {
            r: [{"file": f, "line": ln, "text": t} for f, ln, t in ex]
            for r, ex in sorted(rejects.examples.items())
        },
        "time": {
            "duplicates": te.duplicates,
            "backsteps": te.backsteps,
            "gaps": te.gaps,
            "rollovers": te.rollovers,
            "implausible_dates": te.implausible_dates,
            "decisions": te.decisions,
            "examples": [{"file": f, "line": ln, "what": w} for f, ln, w in te.examples],
        },
        "roles": role_notes,
        "notes": notes,
        "inputs": inputs,
    }
