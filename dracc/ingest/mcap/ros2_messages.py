"""ROS 2 messages (message encoding ``cdr``, schema encoding ``ros2msg``) into quantity
columns: which fields of a schema dracc reads (:func:`setup_ros2`), and the decoder
(:func:`decode_ros2`) over :mod:`dracc.ingest.mcap.cdr`.

NavSatFix-like latitude/longitude/altitude and ``status.status``, the orientation of
``Imu`` and ``QuaternionStamped`` as true heading, top-level fields named as quantities,
a ``reference`` code, and the text of ``nmea_msgs/Sentence`` / ``std_msgs/String``;
``header.stamp`` times the message where it is set."""

from __future__ import annotations

import math

import numpy as np

from dracc.frames import MISSING_NS
from dracc.ingest.csv_quantities import add_rejects, lookup
from dracc.ingest.mcap.cdr import (
    CdrError,
    _Field,
    compile_schema,
    decode_channel,
    scalar_paths,
    string_paths,
)
from dracc.ingest.mcap.channels import DecodeContext, _Channel, message_times
from dracc.ingest.references import ASCII_CODES, ros_constants


def setup_ros2(ch: _Channel, declared: dict[str, str]) -> None:
    """Compile a CDR channel's schema and choose the fields to read (``ch.state``), or
    mark the channel ``skip`` with the reason."""
    sch = ch.schema
    if sch is None or sch.encoding != "ros2msg":
        ch.mode, ch.why = "skip", "CDR without a ros2msg schema"
        return
    try:
        fields = compile_schema(sch.name, sch.data.decode("utf-8"))
    except (
        CdrError,
        UnicodeDecodeError,
        Exception,
    ) as err:  # the IDL parser raises its own
        ch.mode, ch.why = "skip", f"schema not understood ({type(err).__name__}: {err})"
        return
    _choose_fields(ch, fields, declared)


def _choose_fields(ch: _Channel, fields: list[_Field], declared: dict[str, str]) -> None:
    assert ch.schema is not None
    paths = scalar_paths(fields)
    strs = string_paths(fields)
    short = ch.schema.name.split("/")[-1]
    want: dict[str, str] = {}  # path -> quantity name (or a special)
    if "latitude" in paths and "longitude" in paths:
        want.update({"latitude": "lat_deg", "longitude": "lon_deg"})
        if "altitude" in paths:
            want["altitude"] = "alt_m"
        if "status.status" in paths:
            want["status.status"] = "_navsat_status"
    for prefix in ("orientation", "quaternion"):
        if all(f"{prefix}.{c}" in paths for c in "xyzw") and short in (
            "Imu",
            "QuaternionStamped",
        ):
            for c in "xyzw":
                want[f"{prefix}.{c}"] = f"_q{c}"
    for p in paths:
        if "." not in p:
            q = lookup(p, declared)
            if q is not None:
                want[p] = q.name
    if "reference" in paths:
        want["reference"] = "_reference_code"
        # the definition's own constants (compass_msgs/Azimuth: REFERENCE_MAGNETIC=0,
        # REFERENCE_GEOGRAPHIC=1, REFERENCE_UTM=2) win over dracc's ASCII codes 84/77
        ch.state["ref_codes"] = ros_constants(ch.schema.data.decode("utf-8", "replace"))
    text_path = None
    if short == "Sentence" and "sentence" in strs:
        text_path = "sentence"
    elif short == "String" and "data" in strs:
        text_path = "data"
    if text_path:
        ch.state["text_path"] = text_path
    elif not any(not v.startswith("_") or v.startswith(("_q", "_navsat")) for v in want.values()):
        ch.mode, ch.why = "skip", "no navigation fields"
        return
    if "header.stamp.sec" in paths and "header.stamp.nanosec" in paths:
        want["header.stamp.sec"] = "_sec"
        want["header.stamp.nanosec"] = "_nsec"
    ch.state["fields"] = fields
    ch.state["want"] = want
    ch.mode = "cdr"


def decode_ros2(
    ctx: DecodeContext,
    ch: _Channel,
    buf: bytes,
    starts: np.ndarray,
    ends: np.ndarray,
    times: np.ndarray,
    nums: np.ndarray,
) -> None:
    """The :data:`~dracc.ingest.mcap.channels.Decoder` of CDR channels."""
    fields = ch.state["fields"]
    want = ch.state["want"]
    tp = ch.state.get("text_path")
    vals, strs, ok = decode_channel(fields, buf, starts, ends, list(want), [tp] if tp else [])
    if not ok.all():
        ch.bad += int((~ok).sum())
        add_rejects(
            ctx.rejects,
            f"message does not match its schema ({ch.type_name})",
            ctx.file,
            nums[~ok],
            [ch.topic] * 5,
        )
    if "header.stamp.sec" in want:
        t, recv = message_times(ctx, vals["header.stamp.sec"], vals["header.stamp.nanosec"], times)
    else:
        t = np.asarray(times, dtype=np.int64)
        recv = np.full(len(t), MISSING_NS, dtype=np.int64)
    if tp:
        if "nmea" not in ch.state:
            first = next((strs[tp][i] for i in np.flatnonzero(ok) if strs[tp][i]), "")
            if first[:1] not in ("$", "!", "\\"):
                ch.mode, ch.why = "skip", f"text that is not NMEA ({first[:30]!r})"
                return
        for i in np.flatnonzero(ok):
            text = strs[tp][i]
            if text is not None:
                ctx.frames.nmea_text(
                    ch, text.encode("utf-8", "replace"), int(t[i]), int(nums[i]), int(times[i])
                )
        return
    out: dict[str, np.ndarray] = {}
    for path, q in want.items():
        v = np.where(ok, vals[path], np.nan)
        if q == "_navsat_status":
            # NavSatStatus -1 no fix, 0 fix, 1 SBAS, 2 GBAS -> GGA-style quality 0, 1, 2, 4
            out["quality"] = np.select(
                [v == -1, v == 0, v == 1, v == 2], [0.0, 1.0, 2.0, 4.0], np.nan
            )
        elif q == "_reference_code":
            out["reference"] = _references(ch, v)
        elif not q.startswith("_"):
            out[q] = v
    if "_qw" in want.values():
        inv = {q: p for p, q in want.items()}
        x, y, z, w = (np.where(ok, vals[inv[f"_q{c}"]], np.nan) for c in "xyzw")
        yaw_rad = np.arctan2(
            2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z)
        )  # ENU yaw (REP 103)
        out["heading_rad"] = np.mod(math.pi / 2 - yaw_rad, 2 * math.pi)  # from north, clockwise
    keep = ok
    ctx.frames.add_part(ch, t[keep], nums[keep], {k: v[keep] for k, v in out.items()}, recv[keep])


def _references(ch: _Channel, v: np.ndarray) -> np.ndarray:
    """The ``reference`` codes as labels: the schema's declared constants where it has
    them (a declared code dracc cannot use is not understood), else dracc's uint8
    reference (84 'T', 77 'M', 0 not given)."""
    codes = ch.state.get("ref_codes") or {}
    if codes:
        return np.array(
            [None if c != c else (codes.get(int(c)) or f"code {int(c)}") for c in v.tolist()],
            dtype=object,
        )
    return np.array(
        [
            None if (c != c or c == 0) else ASCII_CODES.get(int(c), f"code {int(c)}")
            for c in v.tolist()
        ],
        dtype=object,
    )
