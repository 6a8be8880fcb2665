"""JSON messages (message encoding ``json``) into quantity columns.

A channel's payloads are joined one per line (:func:`_join_lines`) and queued; each
queue is parsed in one pyarrow parse (:func:`_json_columns`, message by message where
pyarrow cannot) once ``_JSON_BATCH`` messages of the channel, or ``_JSON_QUEUED`` of all
channels, wait.  The fields read are planned from the channel's first message
(:func:`_json_plan`): quantity names, foxglove latitude/longitude, a ``timestamp`` /
``header.stamp`` / ``time_ns`` time, or a ``sentence`` of raw NMEA."""

from __future__ import annotations

import json
import math
from io import BytesIO
from typing import Any

import numpy as np

from dracc.core.quantities import REF_QUANTITIES
from dracc.frames import MISSING_NS
from dracc.ingest.csv_quantities import add_rejects
from dracc.ingest.mcap.channels import DecodeContext, _Channel, message_times, quantities_of

_JSON_BATCH = 50000  #: JSON messages of one channel parsed together
_JSON_QUEUED = (
    50000  #: JSON messages of all channels waiting to be parsed (the largest queue goes first)
)


def decode_json(
    ctx: DecodeContext,
    ch: _Channel,
    buf: bytes,
    starts: np.ndarray,
    ends: np.ndarray,
    times: np.ndarray,
    nums: np.ndarray,
) -> None:
    """The :data:`~dracc.ingest.mcap.channels.Decoder` of JSON channels (queued, see
    :func:`json_queue`)."""
    json_queue(ctx, ch, _join_lines(buf, starts, ends), len(starts), times, nums)


def json_queue(
    ctx: DecodeContext, ch: _Channel, joined: bytes, n: int, times: np.ndarray, nums: np.ndarray
) -> None:
    """Collect a channel's JSON payloads (one per line, see :func:`_join_lines`); parse
    them in batches, since each parse has a fixed cost."""
    q = ch.state.setdefault("queue", [[], 0, [], []])
    q[0].append(joined)
    q[1] += n
    q[2].append(np.asarray(times, np.int64))
    q[3].append(np.asarray(nums, np.int64))
    ctx.queued += n
    if q[1] >= _JSON_BATCH:
        json_flush(ctx, ch)
    elif ctx.queued >= _JSON_QUEUED:
        json_flush(ctx, max(ctx.channels.values(), key=lambda c: c.state.get("queue", [0, 0])[1]))


def json_flush(ctx: DecodeContext, ch: _Channel) -> None:
    """Parse what the channel has queued."""
    q = ch.state.pop("queue", None)
    if q:
        ctx.queued -= q[1]
    if not q or not q[1] or ch.mode == "skip":
        return
    _json(ctx, ch, b"".join(q[0]), np.concatenate(q[2]), np.concatenate(q[3]))


def _json(
    ctx: DecodeContext, ch: _Channel, joined: bytes, times: np.ndarray, nums: np.ndarray
) -> None:
    """Decode newline-separated JSON messages of one channel into quantity columns."""
    payloads = None
    if "plan" not in ch.state:
        try:
            first = json.loads(joined[: joined.find(b"\n")])
        except ValueError:
            first = None
        plan = _json_plan(first, ctx.declared)
        if plan is None:
            ch.mode = "skip"
            keys = ", ".join(list(first)[:8]) if isinstance(first, dict) else type(first).__name__
            ch.why = "JSON without navigation fields (no quantity names, no latitude/longitude)"
            ch.state["keys"] = keys
            return
        ch.state["plan"] = plan
    plan = ch.state["plan"]
    n = len(times)
    if plan["nmea"]:
        payloads = joined.split(b"\n")[:-1]
        for p, t, k in zip(payloads, times.tolist(), nums.tolist(), strict=False):
            try:
                obj = json.loads(p)
                ctx.frames.nmea_text(ch, str(obj["sentence"]).encode("utf-8", "replace"), t, k, t)
            except (ValueError, KeyError, TypeError):
                ch.bad += 1
                add_rejects(ctx.rejects, "bad JSON message", ctx.file, np.array([k]), [ch.topic])
        return
    cols = _json_columns(joined, n, plan)
    if cols is None:  # pyarrow could not: message by message, counting the bad ones
        payloads = joined.split(b"\n")[:-1]
        cols = _json_columns_slow(payloads, plan)
    good = cols.pop("_ok")
    if not good.all():
        payloads = payloads or joined.split(b"\n")[:-1]
        ch.bad += int((~good).sum())
        add_rejects(
            ctx.rejects,
            "bad JSON message",
            ctx.file,
            nums[~good],
            [
                bytes(payloads[i][:100]).decode("utf-8", "replace")
                for i in np.flatnonzero(~good)[:5]
            ],
        )
    sec, nsec = cols.pop("_sec", None), cols.pop("_nsec", None)
    tns = cols.pop("_time_ns", None)
    t = np.asarray(times, dtype=np.int64)
    recv = np.full(len(t), MISSING_NS, dtype=np.int64)
    if sec is not None:
        assert nsec is not None  # both or neither
        t, recv = message_times(ctx, sec, nsec, t)
    elif tns is not None:  # the record's own time (dracc's JSON messages)
        have = tns >= 0
        recv = np.where(have, t, MISSING_NS)
        t = t.copy()
        t[have] = tns[have]
    ctx.frames.add_part(ch, t[good], nums[good], {k: v[good] for k, v in cols.items()}, recv[good])


def _json_plan(obj: object, declared: dict[str, str]) -> dict[str, Any] | None:
    """What to read from a channel's JSON messages, planned from its first one."""
    if not isinstance(obj, dict):
        return None
    if isinstance(obj.get("sentence"), str):
        return {"nmea": True}
    fields = quantities_of(obj, declared)
    if not fields:
        return None
    stamp = None
    ts = obj.get("timestamp")
    hd = obj.get("header")
    if isinstance(ts, dict) and "sec" in ts:
        stamp = ("timestamp", "sec", "nsec")
    elif isinstance(hd, dict) and isinstance(hd.get("stamp"), dict):
        stamp = ("header.stamp", "sec", "nanosec")
    return {"nmea": False, "fields": fields, "stamp": stamp, "time_ns": "time_ns" in obj}


def _join_lines(buf: bytes, starts: np.ndarray, ends: np.ndarray) -> bytes:
    """The payloads ``buf[starts[i]:ends[i]]`` as one newline-terminated line each.  A raw
    newline inside a JSON text can only be whitespace (RFC 8259 forbids it inside
    strings), so where there is one it becomes a space."""
    n = len(starts)
    if n == 0:
        return b""
    mv = memoryview(buf)
    parts = [mv[s:e] for s, e in zip(starts.tolist(), ends.tolist(), strict=True)]
    out = b"\n".join(parts) + b"\n"
    if out.count(b"\n") != n:
        out = b"\n".join(bytes(x).replace(b"\n", b" ") for x in parts) + b"\n"
    return out


def _json_columns(joined: bytes, n: int, plan: dict[str, Any]) -> dict[str, np.ndarray] | None:
    """Columns of one channel's JSON messages (one per line) in one pyarrow parse, or None
    if pyarrow cannot (the caller then parses message by message).  The parse allocates
    from the C heap (pyarrow's system pool), which ``trim_heap`` gives back: pyarrow's
    default pool (mimalloc) kept freed parse buffers, 9 MiB more at 24 h than at 6 h
    (``benchmarks/bench_mcap.py``)."""
    import pyarrow as pa
    import pyarrow.json as pj

    fields = [
        pa.field(
            k,
            pa.string()
            if q == "reference"
            else pa.bool_()
            if q in REF_QUANTITIES
            else pa.float64(),
        )
        for k, q in plan["fields"].items()
    ]
    st = plan["stamp"]
    if st:
        inner = pa.struct([pa.field(st[1], pa.float64()), pa.field(st[2], pa.float64())])
        if st[0] == "timestamp":
            fields.append(pa.field("timestamp", inner))
        else:
            fields.append(pa.field("header", pa.struct([pa.field("stamp", inner)])))
    if plan["time_ns"]:
        fields.append(pa.field("time_ns", pa.int64()))
    try:
        table = pj.read_json(
            BytesIO(joined),
            read_options=pj.ReadOptions(
                use_threads=False, block_size=max(len(joined) + 1, 1 << 16)
            ),
            parse_options=pj.ParseOptions(
                explicit_schema=pa.schema(fields), unexpected_field_behavior="ignore"
            ),
            memory_pool=pa.system_memory_pool(),
        )
    except (pa.ArrowInvalid, pa.ArrowNotImplementedError):
        return None
    if table.num_rows != n:
        return None
    cols: dict[str, np.ndarray] = {"_ok": np.ones(n, dtype=bool)}
    for k, q in plan["fields"].items():
        c = table.column(k)
        if q in REF_QUANTITIES:
            cols[q] = np.asarray(c.to_pylist(), dtype=object)
        else:
            cols[q] = c.to_numpy(zero_copy_only=False).astype(np.float64)
    if st:
        s = table.column(st[0]).combine_chunks(memory_pool=pa.system_memory_pool())
        if st[0] == "header":
            s = s.field("stamp")
        sec = s.field(st[1]).to_numpy(zero_copy_only=False).astype(np.float64)
        nsec = s.field(st[2]).to_numpy(zero_copy_only=False).astype(np.float64)
        cols["_sec"], cols["_nsec"] = sec, nsec
    if plan["time_ns"]:
        c = table.column("time_ns").combine_chunks()
        cols["_time_ns"] = c.fill_null(-1).to_numpy(zero_copy_only=False).astype(np.int64)
    return cols


def _num(v: Any) -> float:
    if v is None:
        return math.nan
    if isinstance(v, bool):
        raise ValueError("boolean where a number is expected")
    return float(v)


def _json_columns_slow(payloads: list[bytes], plan: dict[str, Any]) -> dict[str, np.ndarray]:
    n = len(payloads)
    cols: dict[str, np.ndarray] = {
        q: (np.full(n, None, dtype=object) if q in REF_QUANTITIES else np.full(n, np.nan))
        for q in plan["fields"].values()
    }
    ok = np.ones(n, dtype=bool)
    st = plan["stamp"]
    if st:
        cols["_sec"], cols["_nsec"] = np.full(n, np.nan), np.full(n, np.nan)
    if plan["time_ns"]:
        cols["_time_ns"] = np.full(n, -1, dtype=np.int64)
    for i, p in enumerate(payloads):
        try:
            obj = json.loads(p)
            for k, q in plan["fields"].items():
                v = obj.get(k)
                if q in REF_QUANTITIES:
                    cols[q][i] = v
                else:
                    cols[q][i] = _num(v)
            if st:
                s = (
                    obj.get("timestamp")
                    if st[0] == "timestamp"
                    else (obj.get("header") or {}).get("stamp")
                )
                if s:
                    cols["_sec"][i], cols["_nsec"][i] = _num(s.get(st[1])), _num(s.get(st[2]))
            if plan["time_ns"] and obj.get("time_ns") is not None:
                cols["_time_ns"][i] = int(obj["time_ns"])
        except (ValueError, TypeError, AttributeError):
            ok[i] = False
    cols["_ok"] = ok
    return cols
