"""Write canonical frames as an MCAP voyage log, read back by :func:`dracc.ingest.mcap.read_mcap`.

One channel per source and kind, topic ``/<source>/<leaf>`` (leaf: position ``fix``,
heading ``heading``, ground ``velocity``, water ``water``, distance ``distance``, rot
``rot``; raw NMEA ``nmea``), so the reader's source key is the source again.  Log and
publish times are the record's receive time (``recv_ns`` where set, e.g. a simulated
latency, else ``time_ns``); message stamps are ``time_ns`` (the time of fix; a record
without one is stamped on receipt); messages are written in log-time order, or with
``order='line'`` in the frames' line order (the simulator's logger order: a loop or a
clock step goes back in log time).  ``date_shifts`` (a GNSS week rollover): the stamps of
a source's records in a window that many days early (the NMEA encoding: the dates).

Encodings
    ``json``: positions as ``foxglove.LocationFix`` (``timestamp {sec, nsec}``,
    ``latitude``/``longitude`` in degrees, ``altitude`` in metres, plus dracc's
    ``quality`` and ``hdop``), the other kinds as ``dracc.<Kind>`` objects whose keys are
    quantity names with units (``heading_deg``, ``stw_kn`` ...); absent values are null.
    ``ros2``: positions as ``sensor_msgs/msg/NavSatFix`` (status from quality: 0 -> -1,
    1 -> 0, 2 -> 1, 4/5 -> 2, others -> 0; HDOP is not carried), the other kinds as the
    ``dracc_msgs/msg/*`` types below, in SI units, with the schema text embedded.
    ``protobuf``: ``foxglove.LocationFix`` (foxglove's field numbers) and ``dracc.*``
    messages, FileDescriptorSet embedded.  ``nmea``: the sentences of
    :func:`dracc.sim.nmea_out.frames_to_lines`, one per message, schemaless, message
    encoding ``nmea0183``.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterator
from pathlib import Path
from typing import Any, TypeAlias, TypeVar, cast

import numpy as np
import pandas as pd

from dracc.core.atomic import atomic_path
from dracc.frames import KIND_COLUMNS, KINDS, MISSING_NS
from dracc.ingest.csv_quantities import frame_quantities
from dracc.ingest.mcap.cdr import compile_schema, encode_fixed
from dracc.sim.nmea_out import DateShifts, date_shift_days

LEAF = {
    "position": "fix",
    "heading": "heading",
    "ground": "velocity",
    "water": "water",
    "distance": "distance",
    "rot": "rot",
}
TYPE = {
    "heading": "Heading",
    "ground": "GroundVelocity",
    "water": "WaterSpeed",
    "distance": "Distance",
    "rot": "RateOfTurn",
}

#: kind -> protobuf message class, and kind -> its serialized FileDescriptorSet
ProtoClasses: TypeAlias = tuple[dict[str, Any], dict[str, bytes]]
_V = TypeVar("_V")

_TIME = "int32 sec\nuint32 nanosec\n"
_HEADER = "builtin_interfaces/Time stamp\nstring frame_id\n"
_SEP = "=" * 80

NAVSATFIX = (
    "\n".join(
        [
            "std_msgs/Header header",
            "NavSatStatus status",
            "float64 latitude",
            "float64 longitude",
            "float64 altitude",
            "float64[9] position_covariance",
            "uint8 COVARIANCE_TYPE_UNKNOWN = 0",
            "uint8 COVARIANCE_TYPE_APPROXIMATED = 1",
            "uint8 COVARIANCE_TYPE_DIAGONAL_KNOWN = 2",
            "uint8 COVARIANCE_TYPE_KNOWN = 3",
            "uint8 position_covariance_type",
            _SEP,
            "MSG: std_msgs/Header",
            _HEADER.strip(),
            _SEP,
            "MSG: builtin_interfaces/Time",
            _TIME.strip(),
            _SEP,
            "MSG: sensor_msgs/NavSatStatus",
            "int8 STATUS_NO_FIX = -1",
            "int8 STATUS_FIX = 0",
            "int8 STATUS_SBAS_FIX = 1",
            "int8 STATUS_GBAS_FIX = 2",
            "int8 status",
            "uint16 SERVICE_GPS = 1",
            "uint16 service",
        ]
    )
    + "\n"
)


def _dracc_msg(kind: str) -> str:
    """ros2msg text of dracc_msgs/msg/<Type>: the header and the canonical columns (SI)."""
    lines = ["std_msgs/Header header"]
    for c in KIND_COLUMNS[kind]:
        if c == "reference":
            lines.append("uint8 reference  # 84 'T' true, 77 'M' magnetic")
        else:
            lines.append(f"float64 {c}  # NaN where absent")
    lines += [
        _SEP,
        "MSG: std_msgs/Header",
        _HEADER.strip(),
        _SEP,
        "MSG: builtin_interfaces/Time",
        _TIME.strip(),
    ]
    return "\n".join(lines) + "\n"


def _kind_tables(
    frames: dict[str, pd.DataFrame], shifts: DateShifts = ()
) -> Iterator[tuple[str, str, pd.DataFrame]]:
    """(kind, source, rows) per channel; ``time_ns`` early by ``shifts`` (the stamps)."""
    for kind in KINDS:
        df = frames.get(kind)
        if df is None or len(df) == 0:
            continue
        for src, sub in df.groupby(df["source"].astype(str), sort=True, observed=True):
            if shifts:
                t = sub["time_ns"].to_numpy(np.int64)
                days = date_shift_days(np.full(len(sub), str(src), object), t, shifts)
                if days.any():
                    stamp = np.where(days != 0, t - days * 86_400 * 1_000_000_000, t)
                    sub = sub.assign(time_ns=stamp, recv_ns=_log_times(sub))
            yield kind, str(src), sub


def _clean(v: _V) -> _V | None:
    """``v``, or None for NaN (a number or a reference letter goes through unchanged)."""
    return None if v is None or (isinstance(v, float) and math.isnan(v)) else v


def _json_messages(kind: str, src: str, df: pd.DataFrame) -> tuple[str, bytes, list[bytes]]:
    t = df["time_ns"].to_numpy(dtype=np.int64)
    sec, nsec = (t // 1_000_000_000).tolist(), (t % 1_000_000_000).tolist()
    if kind == "position":
        lat = (df["lat_rad"].to_numpy() * 180.0 / math.pi).tolist()
        lon = (df["lon_rad"].to_numpy() * 180.0 / math.pi).tolist()
        alt = df["alt_m"].to_numpy(dtype=np.float64).tolist()
        q = df["quality"].to_numpy(dtype=np.int64).tolist()
        hdop = df["hdop"].to_numpy(dtype=np.float64).tolist()
        msgs = [
            json.dumps(
                {
                    "timestamp": {"sec": s, "nsec": ns},
                    "frame_id": src,
                    "latitude": a,
                    "longitude": b,
                    "altitude": _clean(c),
                    "position_covariance": [0.0] * 9,
                    "position_covariance_type": 0,
                    "quality": qq,
                    "hdop": _clean(h),
                },
                separators=(",", ":"),
            ).encode()
            for s, ns, a, b, c, qq, h in zip(sec, nsec, lat, lon, alt, q, hdop, strict=False)
        ]
        schema = {
            "title": "foxglove.LocationFix",
            "type": "object",
            "properties": {
                "timestamp": {"type": "object"},
                "frame_id": {"type": "string"},
                "latitude": {"type": "number"},
                "longitude": {"type": "number"},
                "altitude": {"type": ["number", "null"]},
                "position_covariance": {"type": "array"},
                "position_covariance_type": {"type": "integer"},
                "quality": {"type": "integer"},
                "hdop": {"type": ["number", "null"]},
            },
        }
        return "foxglove.LocationFix", json.dumps(schema).encode(), msgs
    qs = frame_quantities(kind, df)
    names = list(qs)
    cols = [[_clean(x) for x in (qs[n].tolist())] for n in names]
    msgs = []
    for i, (s, ns) in enumerate(zip(sec, nsec, strict=False)):
        obj: dict[str, object] = {"timestamp": {"sec": s, "nsec": ns}, "frame_id": src}
        for n, c in zip(names, cols, strict=False):
            obj[n] = c[i]
        msgs.append(json.dumps(obj, separators=(",", ":")).encode())
    schema = {
        "title": f"dracc.{TYPE[kind]}",
        "type": "object",
        "properties": {
            "timestamp": {"type": "object"},
            **{n: {"type": ["string" if n == "reference" else "number", "null"]} for n in names},
        },
    }
    return f"dracc.{TYPE[kind]}", json.dumps(schema).encode(), msgs


def _ros2_messages(kind: str, src: str, df: pd.DataFrame) -> tuple[str, bytes, list[bytes]]:
    t = df["time_ns"].to_numpy(dtype=np.int64)
    n = len(df)
    cols: dict[str, np.ndarray] = {
        "header.stamp.sec": t // 1_000_000_000,
        "header.stamp.nanosec": t % 1_000_000_000,
    }
    if kind == "position":
        name, text = "sensor_msgs/msg/NavSatFix", NAVSATFIX
        q = df["quality"].to_numpy(dtype=np.int64)
        status = np.select([q == 0, q == 1, q == 2, (q == 4) | (q == 5)], [-1, 0, 1, 2], 0)
        cols.update(
            {
                "latitude": df["lat_rad"].to_numpy() * 180.0 / math.pi,
                "longitude": df["lon_rad"].to_numpy() * 180.0 / math.pi,
                "altitude": df["alt_m"].to_numpy(dtype=np.float64),
                "status.status": status,
                "status.service": np.ones(n, np.int64),
            }
        )
    else:
        name, text = f"dracc_msgs/msg/{TYPE[kind]}", _dracc_msg(kind)
        for c in KIND_COLUMNS[kind]:
            if c == "reference":
                ref = df["reference"].astype(object).to_numpy()
                cols["reference"] = np.where(ref == "M", 77, np.where(ref == "T", 84, 0))
            else:
                cols[c] = df[c].to_numpy(dtype=np.float64)
    fields = compile_schema(name, text)
    rows, _size = encode_fixed(fields, cols, {"header.frame_id": src}, n)
    return name, text.encode(), [r.tobytes() for r in rows]


def _proto_classes() -> ProtoClasses:
    """foxglove.LocationFix and dracc.* protobuf classes built from descriptors in code."""
    from google.protobuf import descriptor_pb2, descriptor_pool, timestamp_pb2
    from google.protobuf.message_factory import GetMessageClass

    fdp = descriptor_pb2.FieldDescriptorProto
    pool = descriptor_pool.DescriptorPool()
    ts_file = descriptor_pb2.FileDescriptorProto()
    timestamp_pb2.DESCRIPTOR.CopyToProto(ts_file)
    pool.Add(ts_file)
    files = {"google/protobuf/timestamp.proto": ts_file}

    fox = descriptor_pb2.FileDescriptorProto(
        name="foxglove/LocationFix.proto",
        package="foxglove",
        syntax="proto3",
        dependency=["google/protobuf/timestamp.proto"],
    )
    m = fox.message_type.add(name="LocationFix")
    for num, fname, ftype, label in (
        (6, "timestamp", fdp.TYPE_MESSAGE, fdp.LABEL_OPTIONAL),
        (7, "frame_id", fdp.TYPE_STRING, fdp.LABEL_OPTIONAL),
        (1, "latitude", fdp.TYPE_DOUBLE, fdp.LABEL_OPTIONAL),
        (2, "longitude", fdp.TYPE_DOUBLE, fdp.LABEL_OPTIONAL),
        (3, "altitude", fdp.TYPE_DOUBLE, fdp.LABEL_OPTIONAL),
        (4, "position_covariance", fdp.TYPE_DOUBLE, fdp.LABEL_REPEATED),
        (8, "color", fdp.TYPE_MESSAGE, fdp.LABEL_OPTIONAL),
    ):
        if fname == "color":
            continue  # foxglove.Color is optional display styling; not written
        f = m.field.add(name=fname, number=num, type=ftype, label=label)
        if fname == "timestamp":
            f.type_name = ".google.protobuf.Timestamp"
    pool.Add(fox)
    files[fox.name] = fox
    dr = descriptor_pb2.FileDescriptorProto(
        name="dracc/messages.proto",
        package="dracc",
        syntax="proto3",
        dependency=["google/protobuf/timestamp.proto"],
    )
    for kind, tname in TYPE.items():
        m = dr.message_type.add(name=tname)
        f = m.field.add(name="timestamp", number=1, type=fdp.TYPE_MESSAGE, label=fdp.LABEL_OPTIONAL)
        f.type_name = ".google.protobuf.Timestamp"
        m.field.add(name="frame_id", number=2, type=fdp.TYPE_STRING, label=fdp.LABEL_OPTIONAL)
        for i, c in enumerate(KIND_COLUMNS[kind]):
            m.field.add(
                name=c,
                number=3 + i,
                type=fdp.TYPE_STRING if c == "reference" else fdp.TYPE_DOUBLE,
                label=fdp.LABEL_OPTIONAL,
            )
    pool.Add(dr)
    files[dr.name] = dr
    classes = {"position": GetMessageClass(pool.FindMessageTypeByName("foxglove.LocationFix"))}
    for kind, tname in TYPE.items():
        classes[kind] = GetMessageClass(pool.FindMessageTypeByName(f"dracc.{tname}"))

    def fds(names: list[str]) -> bytes:
        s = descriptor_pb2.FileDescriptorSet()
        for nm in names:
            s.file.append(files[nm])
        return cast(bytes, s.SerializeToString())

    sets = {"position": fds(["google/protobuf/timestamp.proto", fox.name])}
    for kind in TYPE:
        sets[kind] = fds(["google/protobuf/timestamp.proto", dr.name])
    return classes, sets


def _proto_messages(
    kind: str, src: str, df: pd.DataFrame, protos: ProtoClasses
) -> tuple[str, bytes, list[bytes]]:
    classes, sets = protos
    cls = classes[kind]
    t = df["time_ns"].to_numpy(dtype=np.int64)
    sec, nsec = (t // 1_000_000_000).tolist(), (t % 1_000_000_000).tolist()
    msgs = []
    if kind == "position":
        lat = (df["lat_rad"].to_numpy() * 180.0 / math.pi).tolist()
        lon = (df["lon_rad"].to_numpy() * 180.0 / math.pi).tolist()
        alt = df["alt_m"].to_numpy(dtype=np.float64).tolist()
        for s, ns, a, b, c in zip(sec, nsec, lat, lon, alt, strict=False):
            m = cls(frame_id=src, latitude=a, longitude=b, altitude=c)
            m.timestamp.seconds, m.timestamp.nanos = s, ns
            msgs.append(m.SerializeToString())
        return "foxglove.LocationFix", sets[kind], msgs
    cols = {
        c: (
            df[c].astype(object).to_numpy()
            if c == "reference"
            else df[c].to_numpy(dtype=np.float64)
        )
        for c in KIND_COLUMNS[kind]
    }
    for i, (s, ns) in enumerate(zip(sec, nsec, strict=False)):
        m = cls(frame_id=src)
        m.timestamp.seconds, m.timestamp.nanos = s, ns
        for c, v in cols.items():
            x = v[i]
            if c == "reference":
                if isinstance(x, str):
                    m.reference = x
            else:
                setattr(m, c, float(x))
        msgs.append(m.SerializeToString())
    return f"dracc.{TYPE[kind]}", sets[kind], msgs


def _log_times(df: pd.DataFrame) -> np.ndarray:
    """Log (receive) time of each record: ``recv_ns`` where set, else ``time_ns``."""
    t: np.ndarray = df["time_ns"].to_numpy(dtype=np.int64)
    if "recv_ns" not in df:
        return t
    r: np.ndarray = df["recv_ns"].to_numpy(dtype=np.int64)
    return np.where(r != MISSING_NS, r, t)


def write_mcap(
    frames: dict[str, pd.DataFrame],
    roles: dict[str, str] | None,
    path: str | Path,
    encoding: str = "json",
    chunk_size: int = 1 << 20,
    compression: str | None = "zstd",
    indexed: bool = True,
    order: str = "time",
    date_shifts: DateShifts = (),
) -> Path:
    """Write ``frames`` (kind -> canonical frame) as MCAP at ``path`` atomically; return the path.

    ``roles`` (source key -> role) goes into a ``dracc.roles`` metadata record and, for
    ``encoding='nmea'``, to the sentence writer (talker IDs).  ``compression``: 'zstd',
    'lz4' or None; ``indexed=False`` writes no message/chunk indexes and no summary
    (as a recorder that stops without finishing does).  ``order``: 'time' (log-time order)
    or 'line' (the frames' line order); ``date_shifts``: see the module docstring.
    """
    from mcap.writer import CompressionType, IndexType, Writer

    if order not in ("time", "line"):
        raise ValueError(f"order must be 'time' or 'line', got {order!r}")
    if encoding not in ("json", "ros2", "protobuf", "nmea"):
        raise ValueError(f"encoding must be json, ros2, protobuf or nmea, got {encoding!r}")
    comp = {
        "zstd": CompressionType.ZSTD,
        "lz4": CompressionType.LZ4,
        None: CompressionType.NONE,
        "none": CompressionType.NONE,
    }.get(compression)
    if comp is None:
        raise ValueError(f"compression must be 'zstd', 'lz4' or None, got {compression!r}")
    path = Path(path)
    streams: list[tuple[str, str, str, bytes, str, np.ndarray, list[bytes]]] = []
    keys: list[np.ndarray] = []  #: per stream the write-order key of each message
    if encoding == "nmea":
        from dracc.sim.nmea_out import frames_to_lines

        t, line_src, lines = frames_to_lines(frames, roles, order, date_shifts)
        pos = np.arange(len(lines), dtype=np.int64)
        line_src = np.asarray(line_src, dtype=object)
        for s in sorted(set(line_src.tolist())):
            m = line_src == s
            streams.append(
                (
                    f"/{s.strip('/')}/nmea",
                    "",
                    "",
                    b"",
                    "nmea0183",
                    np.asarray(t)[m],
                    [ln for ln, k in zip(lines, m, strict=False) if k],
                )
            )
            keys.append(pos[m])
    else:
        protos = _proto_classes() if encoding == "protobuf" else None
        for kind, src, df in _kind_tables(frames, date_shifts):
            if encoding == "json":
                name, sdata, msgs = _json_messages(kind, src, df)
                senc, menc = "jsonschema", "json"
            elif encoding == "ros2":
                name, sdata, msgs = _ros2_messages(kind, src, df)
                senc, menc = "ros2msg", "cdr"
            else:
                assert protos is not None  # built above for encoding 'protobuf'
                name, sdata, msgs = _proto_messages(kind, src, df, protos)
                senc, menc = "protobuf", "protobuf"
            streams.append(
                (f"/{src.strip('/')}/{LEAF[kind]}", name, senc, sdata, menc, _log_times(df), msgs)
            )
            keys.append(df["line"].to_numpy(np.int64))
    # one global log-time order over all channels (a recorder writes in arrival order)
    t_all = np.concatenate([s[5] for s in streams]) if streams else np.zeros(0, np.int64)
    ch_all = np.repeat(np.arange(len(streams)), [len(s[5]) for s in streams])
    row_all = (
        np.concatenate([np.arange(len(s[5])) for s in streams])
        if streams
        else np.zeros(0, np.int64)
    )
    key = t_all if order == "time" else np.concatenate(keys) if keys else t_all
    written = np.lexsort((ch_all, key))
    with atomic_path(path) as tmp, open(tmp, "wb") as fh:
        w = Writer(
            fh,
            chunk_size=chunk_size,
            compression=comp,
            index_types=IndexType.ALL if indexed else IndexType.NONE,
            repeat_channels=indexed,
            repeat_schemas=indexed,
            use_statistics=indexed,
            use_summary_offsets=indexed,
        )
        w.start(profile="ros2" if encoding == "ros2" else "", library="dracc")
        ids = []
        schema_ids: dict[tuple[str, bytes], int] = {}
        for topic, name, senc, sdata, menc, _t, _m in streams:
            sid = 0
            if name:
                known = schema_ids.get((name, sdata))
                if known is None:
                    known = schema_ids[(name, sdata)] = w.register_schema(
                        name=name, encoding=senc, data=sdata
                    )
                sid = known
            ids.append(w.register_channel(topic=topic, message_encoding=menc, schema_id=sid))
        seq = [0] * len(streams)
        add = w.add_message
        for c, r, t in zip(
            ch_all[written].tolist(),
            row_all[written].tolist(),
            t_all[written].tolist(),
            strict=False,
        ):
            seq[c] += 1
            add(
                channel_id=ids[c],
                log_time=t,
                data=streams[c][6][r],
                publish_time=t,
                sequence=seq[c],
            )
        if roles:
            w.add_metadata("dracc.roles", {str(k): str(v) for k, v in roles.items()})
        w.finish()
    return path
