"""ROS 2 CDR messages decoded a channel at a time onto numpy structured arrays.

A ROS 2 message in MCAP (message encoding ``cdr``, schema encoding ``ros2msg``) is a
4-byte encapsulation header (``00 01`` little-endian CDR, ``00 00`` big-endian) followed
by the fields in order, each primitive aligned to its own size counted from the end of
the header; strings are a uint32 length (with the NUL) and the bytes; sequences a uint32
count and the elements; fixed arrays the elements only (OMG CDR, XCDR1, as used by
rmw_fastrtps and rmw_cyclonedds).

Most navigation messages have a fixed layout for a given channel (the only variable parts,
``header.frame_id`` and short strings, keep their length), so: walk the first message of
each message length to find the byte offset of every scalar field, check that the length
and count fields of all the other messages of that length agree, and read all of them in
one numpy gather.  Messages that do not fit are walked one by one (same walker).  The
schema text is parsed by the ROS IDL parser vendored in ``mcap-ros2-support``.
"""

from __future__ import annotations

import contextlib
import io
import re
import struct
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

_PRIM = {
    "bool": "u1",
    "byte": "u1",
    "char": "u1",
    "int8": "i1",
    "uint8": "u1",
    "int16": "i2",
    "uint16": "u2",
    "int32": "i4",
    "uint32": "u4",
    "int64": "i8",
    "uint64": "u8",
    "float32": "f4",
    "float64": "f8",
}

_BUILTIN = {
    "builtin_interfaces/Time": "int32 sec\nuint32 nanosec\n",
    "builtin_interfaces/Duration": "int32 sec\nuint32 nanosec\n",
    "std_msgs/Header": "builtin_interfaces/Time stamp\nstring frame_id\n",
}


class CdrError(ValueError):
    """A message does not match its schema (too short, bad header)."""


@dataclass
class _Field:
    name: str
    kind: str  #: 'prim', 'string', 'msg'
    type: str  #: primitive code, or message type 'pkg/Name'
    array: int | None = None  #: None scalar, -1 sequence, n fixed
    sub: list[_Field] = field(default_factory=list)


def _split_schema(name: str, text: str) -> dict[str, str]:
    """'pkg/msg/Name' schema text with '===' / 'MSG: pkg/Name' sections -> {pkg/Name: text}."""
    defs: dict[str, str] = {}
    cur = _short(name)
    for part in re.split(r"^={3,}\s*$", text, flags=re.MULTILINE):
        m = re.search(r"^MSG:\s+(\S+)\s*$", part, flags=re.MULTILINE)
        if m:
            cur = _short(m.group(1))
            part = part[: m.start()] + part[m.end() :]
        defs[cur] = part
    return defs


def _short(name: str) -> str:
    parts = name.split("/")
    return f"{parts[0]}/{parts[-1]}" if len(parts) > 1 else name


def compile_schema(name: str, text: str) -> list[_Field]:
    """The field tree of message ``name`` from its ros2msg schema text."""
    from mcap_ros2._vendor.rosidl_adapter.parser import parse_message_string

    defs = {**_BUILTIN, **_split_schema(name, text)}
    cache: dict[str, list[_Field]] = {}

    def build(short: str, depth: int = 0) -> list[_Field]:
        if depth > 32:
            raise CdrError(f"schema {name}: nesting too deep at {short}")
        if short in cache:
            return cache[short]
        if short not in defs:
            raise CdrError(f"schema {name}: no definition of {short}")
        pkg, msg = short.split("/")
        text = "\n".join(ln for ln in defs[short].splitlines() if ln.strip())
        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
            try:  # the IDL parser prints what it rejects, then raises: keep only the exception
                spec = parse_message_string(pkg, msg, text)
            except (
                Exception
            ) as err:  # it raises several types (InvalidResourceName, ValueError ...)
                raise CdrError(f"schema {name}: {short}: {err}") from err
        out = []
        for f in spec.fields:
            t: Any = f.type  # the vendored IDL parser is untyped
            arr = (
                (t.array_size if (t.array_size and not t.is_upper_bound) else -1)
                if t.is_array
                else None
            )
            if t.is_primitive_type():
                if t.type in ("string", "wstring"):
                    out.append(_Field(f.name, "string", "string", arr))
                elif t.type in _PRIM:
                    out.append(_Field(f.name, "prim", _PRIM[t.type], arr))
                else:
                    raise CdrError(f"schema {name}: unsupported type {t.type}")
            else:
                sub_name = f"{t.pkg_name or pkg}/{t.type}"
                out.append(_Field(f.name, "msg", sub_name, arr, build(sub_name, depth + 1)))
        cache[short] = out
        return out

    return build(_short(name))


@dataclass
class Layout:
    """Where the scalar fields of one message are, and what fixed that layout."""

    offsets: dict[
        str, tuple[int, str]
    ]  #: 'header.stamp.sec' -> (byte offset in message, dtype code)
    strings: dict[str, str]  #: 'header.frame_id' -> value
    checks: list[int]  #: offsets of the uint32 length/count fields that determine the layout
    size: int  #: bytes used (the message may be padded beyond)


def walk(fields: list[_Field], buf: bytes, start: int, end: int) -> Layout:
    """Walk one CDR message in ``buf[start:end]``; raise CdrError if it is too short."""
    if end - start < 4:
        raise CdrError("message shorter than the CDR header")
    little = buf[start + 1] == 1
    e = "<" if little else ">"
    base = start + 4
    offsets: dict[str, tuple[int, str]] = {}
    strings: dict[str, str] = {}
    checks: list[int] = []
    u32 = struct.Struct(e + "I")

    def align(pos: int, n: int) -> int:
        r = (pos - base) % n
        return pos + (n - r if r else 0)

    def need(pos: int, n: int) -> None:
        if pos + n > end:
            raise CdrError(f"message too short ({end - start} bytes) for its schema")

    def read_count(pos: int) -> tuple[int, int]:
        pos = align(pos, 4)
        need(pos, 4)
        checks.append(pos - start)
        return u32.unpack_from(buf, pos)[0], pos + 4

    def one(f: _Field, path: str, pos: int, record: bool) -> int:
        if f.kind == "prim":
            n = int(f.type[1])
            pos = align(pos, n)
            need(pos, n)
            if record:
                offsets[path] = (pos - start, e + f.type)
            return pos + n
        if f.kind == "string":
            ln, pos = read_count(pos)
            need(pos, ln)
            if record:
                strings[path] = bytes(buf[pos : pos + max(ln - 1, 0)]).decode("utf-8", "replace")
            return pos + ln
        return struct_(f.sub, path, pos, record)

    def struct_(fs: list[_Field], prefix: str, pos: int, record: bool) -> int:
        for f in fs:
            path = f"{prefix}.{f.name}" if prefix else f.name
            if f.array is None:
                pos = one(f, path, pos, record)
                continue
            if f.array == -1:
                count, pos = read_count(pos)
            else:
                count = f.array
            if f.kind == "prim":  # a block of primitives: skip it in one step
                n = int(f.type[1])
                if count:
                    pos = align(pos, n)
                    need(pos, n * count)
                    pos += n * count
            else:
                for _ in range(count):
                    pos = one(f, path, pos, False)
        return pos

    size = struct_(fields, "", base, True) - start
    return Layout(offsets, strings, checks, size)


def decode_channel(
    fields: list[_Field],
    buf: bytes,
    starts: np.ndarray,
    ends: np.ndarray,
    wanted: list[str],
    want_strings: Sequence[str] = (),
) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray], np.ndarray]:
    """Decode the messages ``buf[starts[i]:ends[i]]`` of one channel.

    Returns (values, strings, ok): ``values[path]`` float64/int arrays for the scalar
    fields in ``wanted`` (NaN where a field is missing), ``strings[path]`` object arrays
    for ``want_strings``, ``ok`` False where a message did not match its schema.
    """
    n = len(starts)
    values = {p: np.full(n, np.nan) for p in wanted}
    strings = {p: np.full(n, None, dtype=object) for p in want_strings}
    ok = np.ones(n, dtype=bool)
    if n == 0:
        return values, strings, ok
    u8 = np.frombuffer(buf, dtype=np.uint8)
    lengths = ends - starts
    todo = np.ones(n, dtype=bool)
    for length in np.unique(lengths):
        idx = np.flatnonzero(lengths == length)
        first = int(idx[0])
        try:
            lay = walk(fields, buf, int(starts[first]), int(ends[first]))
        except CdrError:
            continue
        if want_strings:
            break  # strings vary in content: walk each message
        span = int(length)
        rows = u8[starts[idx][:, None] + np.arange(span)]
        same = (rows[:, :4] == rows[0, :4]).all(axis=1)
        for c in lay.checks:
            same &= (rows[:, c : c + 4] == rows[0, c : c + 4]).all(axis=1)
        sel = idx[same]
        rows = rows[same]
        for p in wanted:
            if p not in lay.offsets:
                continue
            off, code = lay.offsets[p]
            size = np.dtype(code).itemsize
            col = np.ascontiguousarray(rows[:, off : off + size]).view(code).ravel()
            values[p][sel] = col.astype(np.float64)
        todo[sel] = False
    for i in np.flatnonzero(todo):
        try:
            lay = walk(fields, buf, int(starts[i]), int(ends[i]))
        except CdrError:
            ok[i] = False
            continue
        for p in wanted:
            if p in lay.offsets:
                off, code = lay.offsets[p]
                values[p][i] = float(
                    np.frombuffer(buf, dtype=code, count=1, offset=int(starts[i]) + off)[0]
                )
        for p in want_strings:
            strings[p][i] = lay.strings.get(p)
    return values, strings, ok


def _leaf_paths(fields: list[_Field], kind: str, prefix: str = "") -> list[str]:
    """Dotted paths of every scalar field of ``kind`` ('prim' or 'string'), not inside arrays."""
    out = []
    for f in fields:
        path = f"{prefix}.{f.name}" if prefix else f.name
        if f.array is not None:
            continue
        if f.kind == kind:
            out.append(path)
        elif f.kind == "msg":
            out.extend(_leaf_paths(f.sub, kind, path))
    return out


def scalar_paths(fields: list[_Field]) -> list[str]:
    """Dotted paths of every scalar primitive field (not inside arrays)."""
    return _leaf_paths(fields, "prim")


def string_paths(fields: list[_Field]) -> list[str]:
    """Dotted paths of every scalar string field (not inside arrays)."""
    return _leaf_paths(fields, "string")


def encode_fixed(
    fields: list[_Field], columns: dict[str, np.ndarray], strings: dict[str, str], n: int
) -> tuple[np.ndarray, int]:
    """Encode ``n`` little-endian CDR messages of a fixed layout at once.

    ``columns`` gives scalar field values by path (absent ones are zero); ``strings`` one
    value per string path, the same for every message (e.g. header.frame_id); arrays are
    written empty (sequences) or zero (fixed arrays).  Returns (uint8 array of shape
    (n, size), size).
    """
    proto = bytearray(b"\x00\x01\x00\x00")
    base = 4
    offs: dict[str, tuple[int, str]] = {}

    def align(n_: int) -> None:
        r = (len(proto) - base) % n_
        if r:
            proto.extend(b"\x00" * (n_ - r))

    def put_struct(fs: list[_Field], prefix: str) -> None:
        for f in fs:
            path = f"{prefix}.{f.name}" if prefix else f.name
            if f.array == -1:
                align(4)
                proto.extend(struct.pack("<I", 0))
                continue
            count = 1 if f.array is None else f.array
            for _ in range(count):
                if f.kind == "prim":
                    size = int(f.type[1])
                    align(size)
                    if f.array is None:
                        offs[path] = (len(proto), "<" + f.type)
                    proto.extend(b"\x00" * size)
                elif f.kind == "string":
                    s = strings.get(path, "").encode() + b"\x00"
                    align(4)
                    proto.extend(struct.pack("<I", len(s)))
                    proto.extend(s)
                else:
                    put_struct(f.sub, path)

    put_struct(fields, "")
    size = len(proto)
    out = np.tile(np.frombuffer(bytes(proto), dtype=np.uint8), (n, 1))
    for path, col in columns.items():
        off, code = offs[path]
        dt = np.dtype(code)
        arr = np.asarray(col).astype(dt)
        out[:, off : off + dt.itemsize] = arr.view(np.uint8).reshape(n, dt.itemsize)
    return out, size
