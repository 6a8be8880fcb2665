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
from dracc.ingest.timebase import drop_implausible_ext

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
    return int(code).to_bytes(2, "little").decode("ascii", "replace")


def _source_categorical(
    cols: dict[str, np.ndarray], names: list[str], split_talkers: dict[str, set[int]], kind: str
) -> tuple[pd.Categorical, pd.Categorical]:
    """(source, talker) categoricals from codes: the TAG/given source where there is one,
    else the talker, split by decimals of minutes for fingerprinted talkers."""
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
    inv, ukey = pd.factorize(key, sort=True)  # = np.unique(key, return_inverse=True), by hashing
    labels = []
    for k in ukey.tolist():
        if k < (1 << 32):
            labels.append(names[k])
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
    """Turn a parsed block plus resolved times into canonical frames; count events."""
    frames = {}
    order_kinds = [k for k in KINDS if k in pb.kinds]
    for kind, t in zip(order_kinds, times, strict=True):
        cols = pb.kinds[kind]
        line = cols["line"] + line0 - 1
        missing = t == MISSING_NS
        if missing.any():
            idx = np.flatnonzero(missing)
            if kind == "ground":  # an RMC is one line: counted once, in its position row
                idx = idx[cols["sentence"][idx] != SENTENCES.index("RMC")]
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
        own = (cols["tod_ns"] >= 0) | (cols["ext_ns"] != MISSING_NS)
        if kind == "ground":  # an RMC is counted once, in its position record
            own &= cols["sentence"] != SENTENCES.index("RMC")
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
        df = make_frame(kind, data)
        state.events.add(kind, src, t, own, line, file, sent)
        frames[kind] = df
    return frames


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
