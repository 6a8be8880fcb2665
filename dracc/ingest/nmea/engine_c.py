"""The compiled engine and the choice of engine: the kernel ``_nmeascan`` (built from
``dracc/ingest/_nmeascan.c`` where a C compiler was there at install time) decodes the
clean lines of a buffer and leaves the others to the numpy engine (:func:`scan_c`,
``_parse_c``); :func:`parse_buffer` parses a buffer with the engine :data:`ENGINE`
selects."""

from __future__ import annotations

import os
from collections import Counter
from typing import Any

import numpy as np

from dracc.frames import KIND_COLUMNS
from dracc.ingest.nmea.engine_numpy import parse_numpy
from dracc.ingest.nmea.groups import attach_groups
from dracc.ingest.nmea.parsed import ParsedBlock
from dracc.ingest.nmea.sentences import MAX_LINE_BYTES, SENTENCES

try:  # optional: built from _nmeascan.c when a C compiler was there at install time
    from dracc.ingest import _nmeascan  # type: ignore[attr-defined]
except ImportError:  # pragma: no cover - exercised on machines without a compiler
    _nmeascan = None

#: "c" (the compiled kernel where built, numpy for what it leaves) or "numpy" (numpy
#: only); the environment variable DRACC_NMEA_ENGINE sets it for benchmarks
ENGINE = os.environ.get("DRACC_NMEA_ENGINE", "c")

#: the kinds in the order the numpy path creates them (first sentence type of each)
_KIND_ORDER = ("heading", "rot", "water", "distance", "position", "ground")
_T = {s: i for i, s in enumerate(SENTENCES)}
#: kind -> sentence type codes giving it; value column -> column of the kernel's r_val
_KIND_TYPES = {
    "heading": (_T["HDT"], _T["HDM"], _T["HDG"], _T["THS"]),
    "rot": (_T["ROT"],),
    "water": (_T["VHW"], _T["VBW"]),
    "distance": (_T["VLW"],),
    "position": (_T["GGA"], _T["GLL"], _T["RMC"], _T["GNS"]),
    "ground": (_T["RMC"], _T["VTG"]),
}
_KIND_VALS: dict[str, dict[str, Any]] = {
    "heading": {"heading_rad": 0, "reference": "code", "deviation_rad": 1, "variation_rad": 2},
    "rot": {"rot_radps": 0},
    "water": {"stw_mps": 0, "stw_transverse_mps": 1, "sog_long_mps": 2, "sog_transverse_mps": 3},
    "distance": {"total_water_m": 0, "trip_water_m": 1},
    "position": {"lat_rad": 0, "lon_rad": 1, "alt_m": 2, "hdop": 3, "quality": "code"},
    "ground": {"cog_rad": 0, "sog_mps": 1},
}


def engine_available() -> bool:
    """True if the compiled kernel is built and selected."""
    return _nmeascan is not None and ENGINE == "c"


def scan_c(data: bytes, max_line_bytes: int = MAX_LINE_BYTES) -> dict[str, Any]:
    """Run the compiled kernel over ``data``; arrays trimmed to their lengths.  The arrays
    are sized by one counting pass (lines, '$'); pages never written cost no memory."""
    cap, cap_rows = _nmeascan.sizes(data)
    cap_long = len(data) // (max_line_bytes + 1) + 1
    nval = _nmeascan.NVAL
    a = {
        "fb_line": np.empty(cap, np.int64),
        "long_line": np.empty(cap_long, np.int64),
        "long_start": np.empty(cap_long, np.int64),
        "long_end": np.empty(cap_long, np.int64),
        "sub": np.empty(len(data), np.uint8),
        "line": np.empty(cap_rows, np.int64),
        "seq": np.empty(cap_rows, np.int64),
        "talker": np.empty(cap_rows, np.uint16),
        "sentence": np.empty(cap_rows, np.int8),
        "src": np.empty(cap_rows, np.int32),
        "ext_ns": np.empty(cap_rows, np.int64),
        "tod_ns": np.empty(cap_rows, np.int64),
        "date_days": np.empty(cap_rows, np.int64),
        "dec": np.empty(cap_rows, np.int8),
        "code": np.empty(cap_rows, np.int8),
        "val": np.empty((cap_rows, nval), np.float64),
    }
    n_lines, n_blank, n_rows, n_fb, n_long, sub_len, n_seg, n_tag, names, first = _nmeascan.scan(
        data,
        cap,
        cap_rows,
        max_line_bytes,
        a["fb_line"],
        a["long_line"],
        a["long_start"],
        a["long_end"],
        a["sub"],
        a["line"],
        a["seq"],
        a["talker"],
        a["sentence"],
        a["src"],
        a["ext_ns"],
        a["tod_ns"],
        a["date_days"],
        a["dec"],
        a["code"],
        a["val"],
    )
    fb = ("fb_line",)
    lg = ("long_line", "long_start", "long_end")
    out: dict[str, Any] = {k: v[:n_rows] for k, v in a.items() if k not in fb + lg + ("sub",)}
    out.update({k: a[k][:n_fb] for k in fb})  # views: the pages beyond were never written
    out.update({k: a[k][:n_long] for k in lg})
    out.update(
        sub=a["sub"][:sub_len].tobytes(),
        n_lines=n_lines,
        n_blank=n_blank,
        n_tag=n_tag,
        n_seg=n_seg,
        names=names,
        first=first,
    )
    return out


def _parse_c(
    data: bytes, ignore_checksum: bool, at_eof: bool, max_line_bytes: int = MAX_LINE_BYTES
) -> ParsedBlock:
    """:func:`parse_buffer` with the compiled kernel: it decodes the clean lines and
    copies all others into a side buffer, parsed by :func:`parse_numpy`; the two are
    merged back into stream order (line numbers, ``seq``, TAG source codes in order of
    first appearance), so the result equals the numpy path's.  Lines too long are listed
    by the kernel and rejected here (``too_long``), never copied."""
    r = scan_c(data, max_line_bytes)
    n_lines = r["n_lines"]
    fb_lines = r["fb_line"]
    pbs, firsts_sub = parse_numpy(r["sub"], ignore_checksum, at_eof, max_line_bytes=max_line_bytes)
    if pbs.n_lines != len(fb_lines):  # pragma: no cover - an internal inconsistency
        raise AssertionError(f"_nmeascan: {len(fb_lines)} fallback lines, numpy read {pbs.n_lines}")
    # TAG source names, factorized over all lines in order of first appearance
    first = dict(zip(r["names"], r["first"], strict=True))
    long_line = r["long_line"]
    if len(long_line):  # a line too long with no sentence in its tail has no source ('')
        at = np.minimum(np.searchsorted(fb_lines, long_line), max(len(fb_lines) - 1, 0))
        tailless = long_line[~(fb_lines[at] == long_line)] if len(fb_lines) else long_line
        if len(tailless):
            first[""] = min(first.get("", n_lines), int(tailless[0]))
    for nm, i in firsts_sub.items():
        i = int(fb_lines[i])
        first[nm] = min(first.get(nm, i), i)
    names = sorted(first, key=first.__getitem__)
    code_of = {nm: i for i, nm in enumerate(names)}
    lut_c = np.array([code_of[nm] for nm in r["names"]] or [0], dtype=np.int32)
    lut_sub = np.array([code_of[str(nm)] for nm in pbs.source_names] or [0], dtype=np.int32)
    if not r["n_seg"]:
        names = []  # no sentence anywhere: the numpy path names no sources

    def from_sub(cols: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        # a row's seq: its seq in the side buffer (the segments of the fallback lines before
        # it) plus the kernel's rows (one segment each) on the lines before its line
        out = dict(cols)
        line = fb_lines[cols["line"] - 1] + 1
        out["line"] = line
        out["seq"] = cols["seq"] + np.searchsorted(r["line"], line)
        out["tag_source"] = lut_sub[cols["tag_source"]]
        return out

    sent = r["sentence"]
    common = {
        "line": r["line"],
        "seq": r["seq"],
        "talker": r["talker"],
        "sentence": sent,
        "tag_source": lut_c[r["src"]],
        "ext_ns": r["ext_ns"],
        "tod_ns": r["tod_ns"],
        "date_days": r["date_days"],
        "dec": r["dec"],
    }
    val = r["val"]
    kinds: dict[str, dict[str, np.ndarray]] = {}
    for kind in _KIND_ORDER:
        types = _KIND_TYPES[kind]
        sel = np.flatnonzero(np.isin(sent, types)) if len(sent) else np.zeros(0, np.int64)
        parts = []
        if len(sel):
            cols = {c: v[sel] for c, v in common.items()}
            for c, j in _KIND_VALS[kind].items():
                if j == "code":
                    code = r["code"][sel]
                    cols[c] = code.view(np.uint8) if c == "reference" else code
                elif kind == "ground":  # RMC: (cog, sog) in columns 4, 5
                    rmc = sent[sel] == _T["RMC"]
                    cols[c] = np.where(rmc, val[sel, 4 + j], val[sel, j])
                else:
                    cols[c] = val[sel, j]
            for c, t in KIND_COLUMNS[kind].items():  # columns no kernel type gives: NaN
                if c not in cols and t == "float64":
                    cols[c] = np.full(len(sel), np.nan)
            parts.append(cols)
        if kind in pbs.kinds:
            parts.append(from_sub(pbs.kinds[kind]))
        if parts:
            kinds[kind] = _merge_parts(parts)
    parts = []
    zda = np.flatnonzero(sent == _T["ZDA"]) if len(sent) else np.zeros(0, np.int64)
    if len(zda):
        parts.append({c: v[zda] for c, v in common.items()})
    if pbs.clock:
        parts.append(from_sub(pbs.clock))
    clock = _merge_parts(parts) if parts else {}
    examples = {
        k: [(int(fb_lines[ln - 1]) + 1, tx) for ln, tx in v] for k, v in pbs.reject_examples.items()
    }
    fatal = pbs.first_fatal
    if fatal is not None:
        fatal = (int(fb_lines[fatal[0] - 1]) + 1, fatal[1], fatal[2])
    counts = Counter(pbs.reject_counts)
    if len(r["long_line"]):
        counts["too_long"] += len(r["long_line"])
        examples["too_long"] = [
            (int(li) + 1, data[a : min(int(e), a + 120)].decode("ascii", "replace"))
            for li, a, e in zip(
                r["long_line"][:5].tolist(),
                r["long_start"][:5].tolist(),
                r["long_end"][:5].tolist(),
                strict=True,
            )
        ]
        too_long = (examples["too_long"][0][0], "too_long", examples["too_long"][0][1])
        fatal = too_long if fatal is None else min(fatal, too_long)
    stats = Counter(pbs.stats)
    stats["blank"] += r["n_blank"]
    if r["n_tag"]:
        stats["prefix_tag"] += r["n_tag"]
    ign_examples = {
        k: [(int(fb_lines[ln - 1]) + 1, tx) for ln, tx in v]
        for k, v in pbs.ignored_examples.items()
    }
    return ParsedBlock(
        n_lines,
        r["n_blank"] + pbs.n_blank,
        kinds,
        clock,
        counts,
        examples,
        fatal,
        stats,
        [str(x) for x in names],
        Counter(pbs.ignored),
        ign_examples,
        int(r["n_seg"]),
        {k: from_sub(cols) for k, cols in pbs.aux.items()},  # only the numpy path gives them
    )


def _merge_parts(parts: list[dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
    """Rows from the kernel and from the numpy path, merged in stream order (``seq``)."""
    if len(parts) == 1:
        return parts[0]
    cat = {c: np.concatenate([p[c] for p in parts]) for c in parts[0]}
    order = np.argsort(cat["seq"], kind="stable")
    return {c: v[order] for c, v in cat.items()}


def parse_buffer(
    data: bytes,
    ignore_checksum: bool = False,
    at_eof: bool = True,
    ext_line_ns: np.ndarray | None = None,
    ext_line_source: np.ndarray | None = None,
    engine: str | None = None,
    max_line_bytes: int = MAX_LINE_BYTES,
) -> ParsedBlock:
    """Parse a buffer of whole lines.

    ``engine`` "c" uses the compiled kernel (:mod:`dracc.ingest._nmeascan`) where it is
    built, "numpy" the vectorised numpy core only; None follows :data:`ENGINE`.  Both
    give the same block (tests/test_nmeascan.py).  Lines with an external time/source
    (``ext_line_ns``/``ext_line_source``, for :func:`parse_sentences`) take the numpy core.
    Lines end at LF, CR LF, CR CR LF or a lone CR; a line longer than ``max_line_bytes``
    is one ``too_long`` reject (its bytes are never parsed).  The lines of TAG line
    groups (``g:``) are listed in the block's ``groups``
    (:func:`~dracc.ingest.nmea.groups.attach_groups`; not for lines with an external
    source), for the reader to join.
    """
    use_c = (engine or ENGINE) == "c" and _nmeascan is not None
    if ext_line_ns is not None or ext_line_source is not None:
        return parse_numpy(
            data, ignore_checksum, at_eof, ext_line_ns, ext_line_source, max_line_bytes
        )[0]
    data = data if isinstance(data, bytes) else bytes(data)
    if use_c and len(data):
        pb = _parse_c(data, ignore_checksum, at_eof, max_line_bytes)
    else:
        pb = parse_numpy(data, ignore_checksum, at_eof, None, None, max_line_bytes)[0]
    return attach_groups(pb, data, ignore_checksum)
