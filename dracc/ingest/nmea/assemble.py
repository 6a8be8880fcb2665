"""Parsed blocks to canonical frames: the records of a block in stream order for the time
base (:func:`time_arrays`), and the frames built once their times are resolved
(:func:`assemble`: categorical source, talker, sentence and reference columns, receive times)."""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd

from dracc.frames import KINDS, MISSING_NS, REFERENCE_DTYPE, make_frame
from dracc.ingest.nmea.parsed import ParsedBlock
from dracc.ingest.nmea.sentences import SENTENCES
from dracc.ingest.timebase import drop_implausible_ext, feed_frames

if TYPE_CHECKING:  # config imports ingest.frames: no runtime import here
    from dracc.core.config import IngestConfig
    from dracc.ingest.nmea.state import StreamState

_DTYPES: dict[tuple[str, ...], pd.CategoricalDtype] = {}


def _cat(codes: np.ndarray, labels: list[str]) -> pd.Categorical:
    """Categorical from codes with a cached dtype (building dtypes is the slow part)."""
    key = tuple(labels)
    dt = _DTYPES.get(key)
    if dt is None:
        dt = _DTYPES[key] = pd.CategoricalDtype(pd.Index(labels, dtype=object))
    return pd.Categorical.from_codes(codes.astype(np.int32, copy=False), dtype=dt)


def _small_unique(x: np.ndarray, size: int) -> tuple[np.ndarray, np.ndarray]:
    """``np.unique(x, return_inverse=True)`` for integers in [0, size): a count per
    value instead of a sort."""
    u = np.flatnonzero(np.bincount(x, minlength=size))
    lut = np.zeros(size, dtype=np.int64)
    lut[u] = np.arange(len(u))
    return u, lut[x]


def _reference_categorical(codes: np.ndarray) -> pd.Categorical:
    """The heading reference column from its byte codes: 'T' (84), 'M' (77), else NaN."""
    c = np.where(codes == ord("T"), 1, np.where(codes == ord("M"), 0, -1)).astype(np.int8)
    return pd.Categorical.from_codes(c, dtype=REFERENCE_DTYPE)


def talker_str(code: int) -> str:
    """The talker of a code ('' for 0: a proprietary sentence has none)."""
    return int(code).to_bytes(2, "little").decode("ascii", "replace") if code else ""


#: a source key code (see :func:`_source_categorical`) above this is a sentence type:
#: the source of an untagged proprietary sentence (no talker) is its address
_BY_SENTENCE = 1 << 41


def _source_categorical(
    cols: dict[str, np.ndarray], names: list[str], split_talkers: dict[str, set[int]], kind: str
) -> tuple[pd.Categorical, pd.Categorical]:
    """(source, talker) categoricals from codes: the TAG/given source where there is one,
    else the talker, split by decimals of minutes for fingerprinted talkers, or for a
    proprietary sentence (no talker) its address (``PSXN``, ``PASHR``)."""
    talker = cols["talker"].astype(np.int64)
    tag = cols["tag_source"].astype(np.int64)
    has_tag = np.zeros(len(tag), dtype=bool)
    if names:
        named = np.array([bool(n) for n in names])
        has_tag = named[tag]
    dec = cols["dec"].astype(np.int64) if kind in ("position", "ground") else np.full(len(tag), -1)
    split_codes = [int.from_bytes(t.encode(), "little") for t in split_talkers]
    split = ~has_tag & np.isin(talker, split_codes) if split_codes else np.zeros(len(tag), bool)
    # one integer per distinct source: tag code, or talker (+ decimals where split)
    key = np.where(has_tag, tag, (1 << 32) + talker * 64 + np.where(split, dec + 1, 0))
    sentence = cols["sentence"].astype(np.int64)
    key = np.where(~has_tag & (talker == 0), _BY_SENTENCE + sentence, key)
    inv, ukey = pd.factorize(key, sort=True)  # = np.unique(key, return_inverse=True), by hashing
    labels = []
    for k in ukey.tolist():
        if k < (1 << 32):
            labels.append(names[k])
        elif k >= _BY_SENTENCE:
            labels.append(SENTENCES[k - _BY_SENTENCE])
        else:
            t, d = divmod(k - (1 << 32), 64)
            labels.append(talker_str(t) + (f"/{d - 1}dp" if d else ""))
    if len(set(labels)) == len(labels):
        src = _cat(inv, labels)
    else:  # a TAG source named like a talker: one key
        src = pd.Categorical(np.asarray(labels, dtype=object)[inv])
    ut, tinv = _small_unique(talker, 1 << 16)
    tal = _cat(tinv, [talker_str(t) for t in ut.tolist()])
    return src, tal


def assemble(
    pb: ParsedBlock,
    times: list[np.ndarray],
    state: StreamState,
    file: str,
    line0: int,
    cfg: IngestConfig,
) -> dict[str, pd.DataFrame]:
    """Turn a parsed block plus resolved times into canonical frames; count events.

    ``$PSXN,23`` headings get the quality of the latest ``$PSXN,20`` of their source
    (:func:`fill_heading_quality`), own-ship AIS records their UTC second
    (:func:`ais_time`)."""
    frames = {}
    own_by_kind: dict[str, np.ndarray] = {}  # the records with a time of their own
    fix_by_kind: dict[str, np.ndarray] = {}  # those whose time is their own time of fix
    order_kinds = [k for k in KINDS if k in pb.kinds]
    filled = fill_heading_quality(pb, state.psxn_quality)
    vdo_seen = np.zeros(0, dtype=np.int64)  # a VDO is one line: its no_date counted once
    for kind, t in zip(order_kinds, times, strict=True):
        cols = pb.kinds[kind]
        if kind == "heading" and filled is not None:
            cols = {**cols, "heading_quality": filled}
        t = ais_time(t, cols, pb)
        line = cols["line"] + line0 - 1
        missing = t == MISSING_NS
        if missing.any():
            vdo = cols["sentence"] == _VDO
            idx = np.flatnonzero(missing)
            if kind == "ground":  # an RMC is one line: counted once, in its position row
                idx = idx[cols["sentence"][idx] != SENTENCES.index("RMC")]
            idx = idx[~(vdo[idx] & np.isin(cols["seq"][idx], vdo_seen))]
            vdo_seen = np.concatenate((vdo_seen, cols["seq"][vdo & missing]))
            if len(idx):
                state.rejects.counts["no_date"] += len(idx)
                ex = state.rejects.examples.setdefault("no_date", [])
                for j in idx[: max(0, 5 - len(ex))]:
                    ex.append(
                        (
                            file,
                            int(line[j]),
                            f"{SENTENCES[cols['sentence'][j]]} time of day without date",
                        )
                    )
            keep = ~missing
            cols = {c: v[keep] for c, v in cols.items()}
            t, line = t[keep], line[keep]
        if len(t) == 0:
            continue
        src, tal = _source_categorical(cols, pb.source_names, state.split_talkers, kind)
        us, sinv = _small_unique(cols["sentence"].astype(np.int64), len(SENTENCES))
        sent = _cat(sinv, [SENTENCES[i] for i in us])
        # an RMC's position and ground records are one record of its stream (one line)
        own = (cols["tod_ns"] >= 0) | (cols["ext_ns"] != MISSING_NS)
        data = {
            c: v
            for c, v in cols.items()
            if c
            not in (
                "seq",
                "tag_source",
                "dec",
                "tod_ns",
                "date_days",
                "ext_ns",
                "talker",
                "sentence",
            )
        }
        data.update(
            talker=tal,
            source=src,
            sentence=sent,
            time_ns=t,
            line=line,
            recv_ns=_recv_ns(cols["tod_ns"], cols["ext_ns"]),
        )
        if "reference" in data:
            data["reference"] = _reference_categorical(data["reference"])
        frames[kind] = make_frame(kind, data)
        own_by_kind[kind], fix_by_kind[kind] = own, cols["tod_ns"] >= 0
    feed_frames(state.events, frames, file, own_by_kind, fix_by_kind)
    return frames


_PSXN, _VDO = SENTENCES.index("PSXN"), SENTENCES.index("VDO")


def fill_heading_quality(pb: ParsedBlock, carry: dict[str, float]) -> np.ndarray | None:
    """The ``heading_quality`` column of ``pb``'s heading records with the ``$PSXN,23``
    rows given the head-qual of the latest ``$PSXN,20`` of the same source before them
    (in this block, else ``carry``: the latest of the blocks before; NaN if none); None
    where the block has neither.  ``carry`` is updated with this block's latest."""
    q = pb.aux.get("psxn_quality")
    h = pb.kinds.get("heading")
    if q is None and (h is None or not (h["sentence"] == _PSXN).any()):
        return None
    names = pb.source_names

    def label(tag: np.ndarray) -> np.ndarray:
        lab = np.array(names + [""], dtype=object) if names else np.array([""], dtype=object)
        return lab[np.where(tag < len(names), tag, len(names))]

    q_src = label(q["tag_source"]) if q is not None else np.zeros(0, dtype=object)
    out = None
    if h is not None:
        out = h["heading_quality"].copy()
        rows = np.flatnonzero(h["sentence"] == _PSXN)
        h_src = label(h["tag_source"][rows])
        for src in pd.unique(h_src).tolist():
            r = rows[h_src == src]
            val = np.full(len(r), carry.get(src, np.nan))
            if q is not None:
                mine = q_src == src
                qs, qv = q["seq"][mine], q["heading_quality"][mine]
                at = np.searchsorted(qs, h["seq"][r], side="right") - 1
                val = np.where(at >= 0, qv[np.maximum(at, 0)] if len(qv) else np.nan, val)
            out[r] = val
    if q is not None:
        for src in pd.unique(q_src).tolist():
            carry[src] = float(q["heading_quality"][q_src == src][-1])
    return out


def ais_time(t: np.ndarray, cols: dict[str, np.ndarray], pb: ParsedBlock) -> np.ndarray:
    """Times of own-ship AIS records moved to their report's UTC second (0-59): the
    nearest time with that second within -30 s .. +30 s of the time the time base gave
    them (the line's external time, or the preceding timed record's); unchanged where
    the report has no second (60-63) or the record no time."""
    a = pb.aux.get("ais_second")
    if a is None or len(a["seq"]) == 0:
        return t
    vdo = np.flatnonzero((cols["sentence"] == _VDO) & (t != MISSING_NS))
    if len(vdo) == 0:
        return t
    at = np.searchsorted(a["seq"], cols["seq"][vdo])
    sec = a["second"][np.minimum(at, len(a["seq"]) - 1)].astype(np.int64)
    ok = (at < len(a["seq"])) & (sec >= 0)
    vdo, sec = vdo[ok], sec[ok]
    minute = 60 * 1_000_000_000
    d = sec * 1_000_000_000 - t[vdo] % minute
    d = (d + minute // 2) % minute - minute // 2  # to [-30 s, 30 s)
    t = t.copy()
    t[vdo] += d
    return t


def _recv_ns(tod_ns: np.ndarray, ext_ns: np.ndarray) -> np.ndarray:
    """The receive time of records with their own time of fix: the external time (TAG
    ``c:``, logger prefix, MCAP log time) the time base used, i.e. after
    :func:`~dracc.ingest.timebase.drop_implausible_ext`; ``MISSING_NS`` where the record
    has no time of fix (HDT, VTG ...) or no usable external time."""
    ext, _ = drop_implausible_ext(ext_ns)
    return np.where((tod_ns >= 0) & (ext != MISSING_NS), ext, MISSING_NS).astype(
        np.int64, copy=False
    )


def time_arrays(
    pb: ParsedBlock,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, Callable[[np.ndarray], list[np.ndarray]]]:
    """All records of a block in stream order: (tod, date, ext, splitter)."""
    parts = [pb.kinds[k] for k in KINDS if k in pb.kinds]
    if pb.clock:
        parts.append(pb.clock)
    if not parts:
        e = np.zeros(0, dtype=np.int64)
        return e, e, e, lambda t: []
    seq = np.concatenate([p["seq"] for p in parts])
    # an RMC gives a position and a ground row: its date counts once (position row)
    dates = [
        np.where(p["sentence"] == SENTENCES.index("RMC"), -1, p["date_days"])
        if k == "ground"
        else p["date_days"]
        for k, p in zip([k for k in KINDS if k in pb.kinds] + ["clock"], parts, strict=False)
    ]
    order = np.argsort(seq, kind="stable")
    tod = np.concatenate([p["tod_ns"] for p in parts])[order]
    date = np.concatenate(dates)[order]
    ext = np.concatenate([p["ext_ns"] for p in parts])[order]
    sizes = [len(p["seq"]) for p in parts]
    n_frames = len(parts) - (1 if pb.clock else 0)

    def split(t_sorted: np.ndarray) -> list[np.ndarray]:
        t = np.empty_like(t_sorted)
        t[order] = t_sorted
        out = np.split(t, np.cumsum(sizes)[:-1])
        return out[:n_frames]

    return tod, date, ext, split
