"""Ingest: logs (NMEA 0183 text, NMEA 2000, Signal K, gpsd JSON, CSV, MCAP) -> canonical
frames with sources and roles.

Public API::

    read_logs(paths, cfg, progress=None) -> Voyage
    detect_format(path) -> "nmea" | "n2k" | "signalk" | "signalk-delta" | "gpsd-json"
                           | "csv" | "mcap"
    read_file(path, cfg, progress=None) -> FileResult
    nmea.read_nmea(path, cfg) -> FileResult
    nmea.parse_sentences(lines, time_ns, source, file, cfg) -> FileResult
    nmea.iter_nmea_blocks(path, cfg, state=None) -> Iterator[Block]   (streaming, bounded memory)
    sources.assign_roles(sources, mapping) -> list[str]
    sources.separate_files(per_file) -> (renames, notes)   (one key in several files)

A key that several files carry is one source only where the files follow each other in
time; overlapping, each file's key becomes ``<file id>:<key>`` (see docs/ingest.md).
"""

from __future__ import annotations

import re
from collections import Counter
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

import numpy as np
import pandas as pd

from dracc.core.errors import DraccError, IngestError
from dracc.frames import KINDS, FileResult, Rejects, SourceInfo, TimeEvents, Voyage, empty_frame
from dracc.ingest import unsupported
from dracc.ingest.compressed import STDIN, Packed, unpacked
from dracc.ingest.demux import relabel, scaled_progress
from dracc.ingest.interleaved import mark_interleaved
from dracc.ingest.nmea import check_readable
from dracc.ingest.role_evidence import choose_roles
from dracc.ingest.sources import (
    assign_roles,
    merge_infos,
    rename_sources,
    separate_files,
    summarize,
)
from dracc.ingest.timebase import count_events, merge_events

if TYPE_CHECKING:  # config imports ingest.frames: no runtime import here
    from dracc.core.config import IngestConfig

MCAP_MAGIC = b"\x89MCAP0\r\n"

__all__ = ["MCAP_MAGIC", "assign_roles", "detect_format", "not_a_log", "read_file", "read_logs"]

#: what a transfer that treats a binary file as text does to the MCAP magic
#: ``\x89MCAP0\r\n``: the bytes at the start of ``MCAP0`` and after it -> what happened
_MAGIC_DAMAGE = {
    b"\n": "CR bytes stripped: was it copied in text mode?",
    b"\r\r\n": "LF bytes turned into CR LF: was it copied in text mode?",
}
#: the magic (intact or damaged as above) as the last bytes of a file (MCAP ends with it)
_FOOTER_MAGIC = re.compile(rb"(?:\x89|\x09|\xc2\x89|\xef\xbf\xbd)MCAP0(?:\r\n|\n|\r\r\n)\Z")
_LEAD_DAMAGE = {
    b"\x09": "its first byte is 0x09, not 0x89: was it sent through a 7-bit channel?",
    b"\xc2\x89": "its bytes were re-encoded as UTF-8 text",
    b"\xef\xbf\xbd": "its bytes were decoded as text (replacement characters)",
    b"": "its first byte is missing",
}


def _damaged_container(head: bytes, tail: bytes) -> str | None:
    """What damage an MCAP file that is not one any more shows, or None: the magic
    ``\x89MCAP0\r\n`` with its CR bytes stripped or its LF turned into CR LF (a copy in
    text mode: FTP ASCII, a Windows text editor, ``unix2dos``), its first byte changed
    (a 7-bit channel, a text re-encoding), or the magic at the end but not at the start."""
    k = head.find(b"MCAP0", 0, 8)
    lead = head[: max(k, 0)]
    if k >= 0 and (lead in _LEAD_DAMAGE or lead == b"\x89" or (len(lead) == 1 and lead[0] >= 0x80)):
        after = head[k + 5 : k + 8]
        if not lead and not after.startswith((b"\r\n", b"\n", b"\r\r\n")):
            return None  # text that happens to start with 'MCAP0'
        why = []
        if lead != b"\x89":
            why.append(_LEAD_DAMAGE.get(lead, f"its first byte is {lead!r}, not b'\\x89'"))
        if not after.startswith(b"\r\n"):
            why.append(
                next(
                    (w for a, w in _MAGIC_DAMAGE.items() if after.startswith(a)),
                    f"the magic ends in {after!r}, not b'\\r\\n'",
                )
            )
        return "; ".join(why) or None
    if _FOOTER_MAGIC.search(tail):
        return (
            "the MCAP magic is at its end but not at its start: its beginning is missing or damaged"
        )
    return None


def detect_format(path: str | Path) -> str:
    """'mcap', 'gpsd-json', 'signalk-delta', 'signalk', 'n2k', 'csv' or 'nmea' from the
    first bytes; IngestError for known non-logs (:mod:`dracc.ingest.unsupported`: packet
    captures, PCAN-View traces, tab-separated tables dracc cannot read, binary files ...)
    and for an MCAP file damaged in transfer (:func:`_damaged_container`), which would
    otherwise be read as NMEA text and give nothing but rejected lines."""
    p = Path(path)
    check_readable(p)
    with p.open("rb") as fh:
        head = fh.read(65536)
        size = fh.seek(0, 2)
        fh.seek(max(0, size - 16))
        tail = fh.read(16)
    return format_of(head, tail, p)


def format_of(head: bytes, tail: bytes, p: Path) -> str:
    """:func:`detect_format` of a log (named ``p``) whose first 64 KiB are ``head`` and
    last 16 bytes ``tail`` (``b""`` where unknown: a log decompressed as it is read)."""
    if not head:
        raise IngestError(f"{p}: empty file")
    if head.startswith(MCAP_MAGIC):
        return "mcap"
    damage = _damaged_container(head, tail)
    if damage is not None:
        raise IngestError(
            f"{p}: not readable: looks like an MCAP file damaged in transfer ({damage}); "
            "copy the original again in binary mode"
        )
    what = unsupported.container(head)
    if what is not None:
        raise IngestError(f"{p}: not a log file: looks like {what}")
    from dracc.ingest.gpsd_json import looks_like_gpsd_json
    from dracc.ingest.n2k import sniff_n2k
    from dracc.ingest.signalk import looks_like_signalk
    from dracc.ingest.signalk_delta import looks_like_signalk_delta

    # before the CSV sniff: a Signal K log's ';' lines and canboat's comma lines are no CSV;
    # Signal K before NMEA 2000: its 'A' lines are canboat lines behind a prefix
    if looks_like_gpsd_json(head):
        return "gpsd-json"
    if looks_like_signalk_delta(head):
        return "signalk-delta"
    if looks_like_signalk(head):
        return "signalk"
    if sniff_n2k(head) is not None:
        return "n2k"
    is_csv: Callable[[bytes], bool] | None
    try:
        from dracc.ingest.csv import looks_like_csv as is_csv
    except ImportError:  # pragma: no cover - the CSV reader is part of the package
        is_csv = None
    if is_csv is not None and is_csv(head):
        return "csv"
    what = unsupported.text_form(head)
    if what is not None:
        raise IngestError(f"{p}: not a log dracc reads: looks like {what}")
    return "nmea"


#: the formats :func:`not_a_log` names as what dracc reads
_READS = "NMEA 0183, NMEA 2000, Signal K, gpsd JSON, CSV and MCAP logs"


def not_a_log(path: str | Path) -> str | None:
    """What the file at ``path`` is when it is no log at all (a photo, a document, an
    archive, a README: text with no record of a format dracc reads), or None for a log,
    including one dracc may fail to read (empty, damaged in transfer, compressed: its
    reading says why).  A batch over folders (``dracc fleet``) skips and lists these
    instead of counting them as failed logs.  Never raises: a file it cannot open is
    None (the reading says why)."""
    try:
        with open(path, "rb") as fh:
            head = fh.read(65536)
            size = fh.seek(0, 2)
            fh.seek(max(0, size - 16))
            tail = fh.read(16)
    except OSError:
        return None
    if not head or head.startswith(MCAP_MAGIC) or _damaged_container(head, tail) is not None:
        return None
    from dracc.ingest.compressed import compression_of

    if compression_of(head) is not None:
        return None
    what = unsupported.container(head)
    if what is not None:
        return what
    try:
        fmt = detect_format(path)
    except IngestError as err:  # unsupported.text_form named it (a CAN trace, a table, ...)
        said = str(err)
        return said.split(": looks like ", 1)[1] if ": looks like " in said else said
    if fmt != "nmea" or _has_sentence(path):
        return None
    return f"text with no NMEA sentence and no record of another format dracc reads ({_READS})"


def _has_sentence(path: str | Path, chunk: int = 1 << 20) -> bool:
    """True when an NMEA 0183 sentence is anywhere in the file (read in pieces)."""
    from dracc.ingest.n2k.formats import ANY_SENTENCE

    keep = b""
    with open(path, "rb") as fh:
        while piece := fh.read(chunk):
            if ANY_SENTENCE.search(keep + piece):
                return True
            keep = piece[-16:]
    return False


def read_file(
    path: str | Path, cfg: IngestConfig, progress: Callable[[int], object] | None = None
) -> FileResult:
    """Read one log with the reader its format needs.  Every reader has this signature:
    (path, config, progress told the bytes read) -> :class:`~dracc.frames.FileResult`.
    A compressed log (gzip, xz, bzip2, zstd) and ``-`` (standard input) go through
    :mod:`dracc.ingest.compressed`: NMEA text decompressed as it is read, the other
    formats from a plain copy; what they say names the log as given."""
    with unpacked(Path(path), cfg) as packed:
        if packed is None:
            return _read_plain(path, cfg, progress)
        return _read_packed(packed, cfg, progress)


def _read_packed(
    packed: Packed, cfg: IngestConfig, progress: Callable[[int], object] | None
) -> FileResult:
    """A compressed log or standard input (:func:`read_file`)."""
    given = packed.given
    if packed.kind is not None and format_of(packed.head(), b"", given) == "nmea":
        from dracc.ingest.embedded_n2k import read_text_log

        told = packed.progress(progress)
        r = read_text_log(given, cfg, told, opener=packed.open, size_hint=packed.size_hint)
        r.notes = packed.notes + r.notes
        return r
    with packed.copy() as plain:
        try:
            result = _read_plain(plain, cfg, scaled(progress, given, plain))
        except DraccError as err:  # said of the log as given, not of its temporary copy
            raise type(err)(str(err).replace(str(plain), str(given))) from err
        return relabelled(result, str(plain), str(given), packed.notes)


def _read_plain(
    path: str | Path, cfg: IngestConfig, progress: Callable[[int], object] | None
) -> FileResult:
    fmt = detect_format(path)
    if fmt == "n2k":
        from dracc.ingest.embedded_n2k import read_n2k_alone

        alone = read_n2k_alone(path, cfg, progress)
        if alone is not None:
            return alone
        fmt = "nmea"  # NMEA 2000 lines of several forms, or with NMEA 0183 ones
    if fmt == "mcap":
        from dracc.ingest.mcap import read_mcap as reader
    elif fmt == "signalk":
        from dracc.ingest.signalk import read_signalk as reader
    elif fmt == "signalk-delta":
        from dracc.ingest.signalk_delta import read_signalk_delta as reader
    elif fmt == "gpsd-json":
        from dracc.ingest.gpsd_json import read_gpsd_json as reader
    elif fmt == "csv":
        from dracc.ingest.csv import read_csv as reader
    else:
        from dracc.ingest.embedded_n2k import read_text_log

        return read_text_log(path, cfg, progress)
    r = reader(path, cfg, progress)
    if fmt in ("csv", "mcap"):  # read whole: their time events counted on the frames
        count_events(r, cfg.gap_s, cfg.backstep_tolerance_s)
    return r


def scaled(
    progress: Callable[[int], object] | None, given: Path, plain: Path
) -> Callable[[int], object] | None:
    """The progress of reading the plain copy, told in bytes of the log as given (its
    compressed size; nothing for standard input, whose size nobody knew)."""
    if progress is None or str(given) == STDIN:
        return None
    return scaled_progress(progress, given.stat().st_size, plain.stat().st_size)


def relabelled(r: FileResult, plain: str, given: str, notes: list[str]) -> FileResult:
    """``r`` read from the plain copy, saying ``given`` wherever it said the copy, with
    ``notes`` (what the copy said: where a stream broke) first."""
    relabel(r, plain, given)
    r.notes = notes + r.notes
    return r


def _merge_frames(results: list[FileResult]) -> dict[str, pd.DataFrame]:
    out: dict[str, pd.DataFrame] = {}
    for kind in KINDS:
        parts = [r.frames[kind] for r in results if kind in r.frames and len(r.frames[kind])]
        if not parts:
            out[kind] = empty_frame(kind)
            continue
        if len(parts) == 1:
            df = parts[0]
        else:
            for p in parts:
                for c in ("source", "talker", "sentence"):
                    p[c] = p[c].astype(str)
            df = pd.concat(parts, ignore_index=True)
        for c in ("source", "talker", "sentence"):
            df[c] = df[c].astype("category")
        t = df["time_ns"].to_numpy()
        if len(parts) == 1 and not (t[1:] < t[:-1]).any():  # one file's frame: sorted already
            out[kind] = df.reset_index(drop=True)
            continue
        order = np.argsort(t, kind="stable")
        out[kind] = df.iloc[order].reset_index(drop=True)
    return out


#: sentences that give rows of several kinds from one line (RMC: position and ground;
#: AIS VDO: position, ground, heading), counted once per line, in the position row
COUNTED_IN_POSITION = {"ground": ("RMC", "VDO"), "heading": ("VDO",)}


def _labels(col: pd.Series) -> tuple[np.ndarray, list[str]] | None:
    """(codes, labels as str) of a categorical column whose labels are distinct strings
    and which has no missing value; None otherwise."""
    if not isinstance(col.dtype, pd.CategoricalDtype):
        return None
    codes = col.cat.codes.to_numpy().astype(np.int64)
    labels = [str(x) for x in col.cat.categories]
    if len(set(labels)) != len(labels) or (len(codes) and codes.min() < 0):
        return None
    return codes, labels


def summarize_frames(
    frames: dict[str, pd.DataFrame], file: str, into: dict[str, SourceInfo] | None = None
) -> dict[str, SourceInfo]:
    """:func:`sources.summarize`, counted on the categorical codes of the frames.

    The same :class:`SourceInfo` values, in the same order (sources in order of first
    appearance per kind, sentences and talkers added in sorted order), from counts per
    code instead of sorting millions of strings.  Frames whose string columns are not
    categoricals go through :func:`sources.summarize`.
    """
    out = {} if into is None else into
    for kind, df in frames.items():
        if df is None or len(df) == 0:
            continue
        parts = [_labels(df[c]) for c in ("source", "sentence", "talker")]
        if any(p is None for p in parts):
            summarize({kind: df}, file, into=out)
            continue
        (src, src_l), (sent, sent_l), (talk, talk_l) = cast(
            "list[tuple[np.ndarray, list[str]]]", parts
        )
        ns, nt, nk = len(src_l), len(sent_l), len(talk_l)
        t = df["time_ns"].to_numpy()
        # one count per (source, sentence, talker); the rest are its sums
        full = np.bincount((src * nt + sent) * nk + talk, minlength=ns * nt * nk).reshape(
            ns, nt, nk
        )
        records = full.sum(axis=(1, 2))
        for one_line in COUNTED_IN_POSITION.get(kind, ()):  # counted in its position row
            if one_line in sent_l:
                full[:, sent_l.index(one_line), :] = 0
        by_sent = full.sum(axis=2)
        tc = full.sum(axis=1)
        lo = np.full(ns, np.iinfo(np.int64).max)
        hi = np.full(ns, np.iinfo(np.int64).min)
        np.minimum.at(lo, src, t)
        np.maximum.at(hi, src, t)
        for i in pd.unique(src).tolist():  # order of first appearance, as pd.factorize
            key = src_l[i]
            info = out.setdefault(key, SourceInfo(key=key))
            if by_sent[i].any():
                js = sorted(np.flatnonzero(by_sent[i]).tolist(), key=sent_l.__getitem__)
                info.sentences.update({sent_l[j]: int(by_sent[i, j]) for j in js})
                jt = sorted(np.flatnonzero(tc[i]).tolist(), key=talk_l.__getitem__)
                info.talkers.update({talk_l[j]: int(tc[i, j]) for j in jt if talk_l[j]})
            info.records += int(records[i])
            a, b = int(lo[i]), int(hi[i])
            info.first_ns = a if info.first_ns is None else min(info.first_ns, a)
            info.last_ns = b if info.last_ns is None else max(info.last_ns, b)
            info.files.add(file)
    return out


def read_logs(
    paths: list[Path], cfg: IngestConfig, progress: Callable[[int], object] | None = None
) -> Voyage:
    """Read several logs of one voyage, merge them by time, build sources and roles.

    ``progress(n_bytes)`` is called as bytes are read (NMEA text as blocks are parsed,
    MCAP and CSV when each file is done).  A missing
    file, a directory, an empty file, a known non-log or an MCAP file damaged in transfer
    raises :class:`IngestError` naming it, whatever other files are given (one bad file
    fails the run: it is never dropped in silence);
    damaged lines inside a log are counted in ``Voyage.rejects``, valid ones dracc does
    not use (GSV, AIS, proprietary sentences, comments ...) in ``Voyage.ignored`` by type.
    """
    if not paths:
        raise IngestError("no log files given")
    results = [read_file(p, cfg, progress=progress) for p in paths]
    # a source is its file and its key: a key two files share is one source only where
    # the files follow each other in time (separate_files says which, in the notes)
    per_file = [(r.path, summarize_frames(r.frames, r.path)) for r in results]
    renames, identity_notes = separate_files(per_file) if len(results) > 1 else ({}, [])
    for r in results:
        rename_sources(r.frames, renames.get(r.path, {}))
    sources = merge_infos(per_file, renames)
    frames = _merge_frames(results)
    rejects = Rejects()
    ignored: Counter[str] = Counter()
    te = TimeEvents()
    inputs: list[dict[str, Any]] = []
    for r in results:
        rejects.merge(r.rejects)
        ignored.update(r.ignored)
        e = r.time_events
        merge_events(te, e, renames.get(r.path))  # back-steps named as the sources are
        te.decisions.extend(f"{Path(r.path).name}: {d}" for d in e.decisions)
        te.decisions.extend(f"{Path(r.path).name}: {n}" for n in r.notes)
        te.examples.extend(e.examples[:10])
        inputs.append(
            {
                "path": r.path,
                "format": r.format,
                "lines": r.lines,
                "records": r.records,
                "rejected": dict(Counter(r.rejects.counts)),
                "ignored": dict(Counter(r.ignored)),
            }
        )
    te.decisions.extend(identity_notes)
    te.decisions.extend(mark_interleaved(frames, sources))
    candidates: dict[str, list[str]] = {}
    te.decisions.extend(assign_roles(sources, dict(cfg.sources), candidates))
    choices, choice_notes = choose_roles(frames, sources, candidates)
    te.decisions.extend(choice_notes)
    # keys already renamed above (rename_sources changed the frames in place)
    clockless = frozenset(
        k for r in results if r.clockless for k in summarize_frames(r.frames, r.path)
    )
    return Voyage(
        frames=frames,
        sources=sources,
        rejects=rejects,
        time_events=te,
        inputs=inputs,
        lines=sum(r.lines for r in results),
        ignored=ignored,
        clockless=clockless,
        choices=choices,
    )
