"""``dracc inspect LOG...``: what is in a log — sources, roles, rates, gaps, rejections, time base.

NMEA text files are streamed block by block (memory does not grow with the file);
CSV and MCAP files are read whole by their readers.  The JSON form (``--json``) is
documented in ``docs/ingest.md``.
"""

from __future__ import annotations

import json
from collections import Counter
from pathlib import Path

import numpy as np
import typer
from rich.table import Table
from rich.text import Text

from dracc.cli.app import (
    ConfigOption,
    LogsArgument,
    app,
    check_date,
    err,
    option_values,
    out,
    paths_exist,
    progress,
)
from dracc.core.config import load_config, with_overrides
from dracc.core.safetext import printable
from dracc.core.timefmt import iso_utc
from dracc.frames import Rejects, TimeEvents
from dracc.ingest import detect_format, read_file
from dracc.ingest.nmea import StreamState, iter_nmea_blocks
from dracc.ingest.sources import assign_roles, merge_infos, separate_files, summarize
from dracc.ingest.timebase import EventCounter


def inspect_logs(paths: list[Path], cfg, show_progress: bool = True) -> dict:
    """The inspection report as a JSON-ready dict (the library side of the command)."""
    per_file: list[tuple[str, dict]] = []  # each file's sources: a key two files share is
    per_file_events: list[tuple[str, dict]] = []  # one source only if separate_files says so
    rejects = Rejects()
    te = TimeEvents()
    events: dict[str, dict] = {}
    inputs = []
    lines = 0
    all_sentences: Counter = Counter()
    notes: list[str] = []
    total = sum(p.stat().st_size for p in paths)
    with progress("inspect", total if show_progress else None) as advance:
        for p in paths:
            fmt = detect_format(p)
            sources: dict = {}
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
        span_s = (s.last_ns - s.first_ns) / 1e9 if s.first_ns is not None else 0.0
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


def render(rep: dict) -> None:
    """Rich tables on stdout.  Every text from the log (source keys, talkers, sentence
    types, file names, rejected lines, notes) is shown as Text, never markup, with its
    control characters escaped (:func:`dracc.core.safetext.printable`): a source key
    holding ESC sequences cannot command the terminal."""

    def cell(x) -> Text:
        return Text(printable(x))

    t = Table(title=f"sources ({rep['lines']} lines read)")
    for c in (
        "source",
        "role",
        "talkers",
        "sentences",
        "records",
        "rate Hz",
        "first UTC",
        "last UTC",
        "gaps",
        "max gap s",
        "dup",
        "back",
    ):
        t.add_column(
            c,
            justify="right"
            if c in ("records", "rate Hz", "gaps", "max gap s", "dup", "back")
            else "left",
        )
    for key, s in rep["sources"].items():
        t.add_row(
            *(
                cell(x)
                for x in (
                    key,
                    s["role"] or "-",
                    " ".join(s["talkers"]) or "-",
                    " ".join(f"{k}:{v}" for k, v in s["sentences"].items()),
                    str(s["records"]),
                    f"{s['rate_hz']:.2f}" if s["rate_hz"] else "-",
                    s["first_utc"] or "-",
                    s["last_utc"] or "-",
                    str(s["gaps"]),
                    f"{s['max_gap_s']:.1f}",
                    str(s["duplicates"]),
                    str(s["backsteps"]),
                )
            )
        )
    out.print(t)
    if rep["rejected"]:
        r = Table(title="lines not used, by reason")
        for c in ("reason", "count", "first examples (file:line text)"):
            r.add_column(c)
        for reason, n in rep["rejected"].items():
            ex = rep["rejected_examples"].get(reason, [])[:2]
            # one example per line: the escapes keep a line's own CR/LF from breaking it up
            r.add_row(
                cell(reason),
                cell(str(n)),
                Text(
                    "\n".join(
                        printable(f"{Path(e['file']).name}:{e['line']} {e['text'][:70]}")
                        for e in ex
                    )
                ),
            )
        out.print(r)
    tm = rep["time"]
    out.print(
        f"time base: {tm['duplicates']} duplicates, {tm['backsteps']} back-steps, {tm['gaps']} gaps, "
        f"{tm['rollovers']} midnight rollovers, {tm['implausible_dates']} implausible dates",
        highlight=False,
        markup=False,
    )
    for d in tm["decisions"] + rep["notes"] + rep["roles"]:
        out.print(cell(f"  - {d}"), highlight=False)


@app.command("inspect")
def inspect_cmd(
    logs: list[Path] = LogsArgument,
    config: Path | None = ConfigOption,
    as_json: bool = typer.Option(False, "--json", help="Print the report as JSON on stdout."),
    strict: bool = typer.Option(False, "--strict", help="Fail on the first rejected line."),
    ignore_checksum: bool = typer.Option(
        False, "--ignore-checksum", help="Accept sentences whose checksum is wrong (counted)."
    ),
    date: str | None = typer.Option(
        None, "--date", help="UTC date YYYY-MM-DD for logs that carry none."
    ),
) -> None:
    """Show what a log holds: sources and roles, sentence counts, rates, time span and gaps,
    rejected lines by reason with examples, and the time-base decisions."""
    cfg = load_config(config)
    with option_values():
        cfg = with_overrides(
            cfg,
            "ingest",
            strict=strict or None,
            ignore_checksum=ignore_checksum or None,
            date=check_date(date),
        )
    paths_exist(logs)
    rep = inspect_logs(logs, cfg.ingest)
    if as_json:
        typer.echo(json.dumps(rep, indent=1))
    else:
        render(rep)
    if not rep["sources"] and not as_json:
        err.print("warning: no usable records found", highlight=False)
