"""Protobuf messages (message encoding ``protobuf``) into quantity columns, decoded by the
classes generated from the FileDescriptorSet embedded in the schema
(``mcap-protobuf-support``).  Fields named as quantities (and foxglove latitude /
longitude) are read, timed by a ``google.protobuf.Timestamp`` field ``timestamp``; a
message wrapping one bytes/string field (keelson ``TimestampedBytes``) carries raw NMEA
or JSON text."""

from __future__ import annotations

from typing import Any

import numpy as np

from dracc.core.quantities import REF_QUANTITIES
from dracc.frames import MISSING_NS
from dracc.ingest.csv_quantities import add_rejects
from dracc.ingest.mcap.channels import _NMEA_START, DecodeContext, _Channel, quantities_of
from dracc.ingest.mcap.json_messages import _join_lines, json_queue


def setup_protobuf(ch: _Channel) -> None:
    """Build the channel's message class from its schema (``ch.state['decode']``), or
    mark the channel ``skip`` with the reason."""
    sch = ch.schema
    if sch is None or sch.encoding != "protobuf":
        ch.mode, ch.why = "skip", "protobuf without a schema"
        return
    from mcap.records import Schema
    from mcap_protobuf.decoder import DecoderFactory

    try:
        fn = DecoderFactory().decoder_for(
            "protobuf",
            Schema(id=sch.id, name=sch.name, encoding=sch.encoding, data=sch.data),
        )
    except Exception as err:  # protobuf raises several types on bad descriptors
        ch.mode, ch.why = (
            "skip",
            f"protobuf schema not usable ({type(err).__name__}: {err})",
        )
        return
    ch.state["decode"] = fn
    ch.mode = "protobuf"


def decode_protobuf(
    ctx: DecodeContext,
    ch: _Channel,
    buf: bytes,
    starts: np.ndarray,
    ends: np.ndarray,
    times: np.ndarray,
    nums: np.ndarray,
) -> None:
    """The :data:`~dracc.ingest.mcap.channels.Decoder` of protobuf channels."""
    decode = ch.state["decode"]
    msgs = []
    good = np.ones(len(starts), dtype=bool)
    for i, (s, e) in enumerate(zip(starts.tolist(), ends.tolist(), strict=False)):
        try:
            msgs.append(decode(buf[s:e]))
        except Exception:  # protobuf's DecodeError and friends
            msgs.append(None)
            good[i] = False
    if not good.all():
        ch.bad += int((~good).sum())
        add_rejects(
            ctx.rejects,
            f"message does not decode ({ch.type_name})",
            ctx.file,
            nums[~good],
            [ch.topic] * 5,
        )
    live = [m for m in msgs if m is not None]
    if not live:
        return
    if "pplan" not in ch.state:
        ch.state["pplan"] = _proto_plan(ch, live[0], ctx.declared)
    plan = ch.state["pplan"]
    if plan is None:
        return
    t = np.asarray(times, dtype=np.int64).copy()
    recv = np.full(len(t), MISSING_NS, dtype=np.int64)
    if plan["stamp"]:
        for i, m in enumerate(msgs):
            if m is not None and m.HasField(plan["stamp"]):
                ts = getattr(m, plan["stamp"])
                if ts.seconds or ts.nanos:
                    v = ts.seconds * 1_000_000_000 + ts.nanos
                    if abs(v) < 2**63:
                        recv[i] = t[i]  # the log time of a message timed by its stamp
                        t[i] = v
                    else:
                        ctx.bad_stamps += 1
    if plan["bytes"]:
        _wrapped_text(ctx, ch, plan["bytes"], msgs, t, nums, times)
        return
    out = {
        q: np.array([getattr(m, f) if m is not None else np.nan for m in msgs], dtype=np.float64)
        for f, q in plan["fields"].items()
        if q not in REF_QUANTITIES
    }
    for f, q in plan["fields"].items():
        if q in REF_QUANTITIES:  # text or boolean, normalised by build_frames
            out[q] = np.array(
                [getattr(m, f) if m is not None else None for m in msgs], dtype=object
            )
    ctx.frames.add_part(ch, t[good], nums[good], {k: v[good] for k, v in out.items()}, recv[good])


def _wrapped_text(
    ctx: DecodeContext,
    ch: _Channel,
    fld: str,
    msgs: list[Any],
    t: np.ndarray,
    nums: np.ndarray,
    times: np.ndarray,
) -> None:
    """The text in field ``fld`` of the decoded messages: raw NMEA sentences, else JSON
    (queued as a JSON channel's payloads)."""
    payloads, tt, kk, ll = [], [], [], []
    log_times = np.asarray(times, dtype=np.int64)
    for i, m in enumerate(msgs):
        if m is None:
            continue
        v = getattr(m, fld)
        v = v.encode("utf-8") if isinstance(v, str) else bytes(v)
        payloads.append(v)
        tt.append(t[i])
        kk.append(nums[i])
        ll.append(log_times[i])
    if not payloads:
        return
    if payloads[0][:1] in _NMEA_START:
        for p, ti, k, lt in zip(payloads, tt, kk, ll, strict=False):
            ctx.frames.nmea_text(ch, p, int(ti), int(k), int(lt))
    else:
        sub_t = np.asarray(tt, np.int64)
        lens = np.fromiter((len(x) for x in payloads), dtype=np.int64, count=len(payloads))
        e = np.cumsum(lens)
        json_queue(
            ctx,
            ch,
            _join_lines(b"".join(payloads), e - lens, e),
            len(payloads),
            sub_t,
            np.asarray(kk, np.int64),
        )


def _proto_plan(ch: _Channel, msg: Any, declared: dict[str, str]) -> dict[str, Any] | None:
    """What to read from a channel's protobuf messages, planned from its first one."""
    desc = msg.DESCRIPTOR
    names = {f.name: f for f in desc.fields}
    stamp = None
    ts = names.get("timestamp")
    if (
        ts is not None
        and ts.message_type is not None
        and ts.message_type.full_name == "google.protobuf.Timestamp"
    ):
        stamp = "timestamp"
    fields = quantities_of(names, declared)
    if fields:
        return {"stamp": stamp, "fields": fields, "bytes": None}
    # a wrapper of raw text (keelson TimestampedBytes: timestamp + value)
    from google.protobuf.descriptor import FieldDescriptor

    texts = [
        f.name
        for f in desc.fields
        if f.type in (FieldDescriptor.TYPE_BYTES, FieldDescriptor.TYPE_STRING) and not _repeated(f)
    ]
    if len(texts) == 1:
        ch.state["plan_note"] = f"text in field {texts[0]!r}"
        return {"stamp": stamp, "fields": {}, "bytes": texts[0]}
    ch.mode, ch.why = "skip", "protobuf message without navigation fields"
    return None


def _repeated(f: Any) -> bool:
    """A repeated protobuf field (protobuf >= 6 has ``is_repeated``; older ones ``label``)."""
    rep = getattr(f, "is_repeated", None)
    if rep is not None:
        return bool(rep)
    repeated: bool = f.label == f.LABEL_REPEATED
    return repeated
