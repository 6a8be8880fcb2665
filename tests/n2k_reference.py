"""canboat's analyzer as the reference for NMEA 2000 readers: its ``-json`` output, kept
as ``tests/data/n2k/*.canboat.json`` (``[pgn, src, dst, prio, {fields}]`` per message,
fields of the navigation PGNs only; how they were made: ``tests/data/n2k/README.md``),
compared with dracc's messages and decoded frames.

canboat prints values rounded: degrees of heading and COG to 0.1, rates of turn in deg/s
to 1e-6, speeds in m/s to 0.01, latitudes and longitudes to 1e-7 degrees.
"""

from __future__ import annotations

import json
import math
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

DATA = Path(__file__).parent / "data" / "n2k"
DEG = 180 / math.pi

#: PGN -> (frame kind, [(canboat field, frame column, scale to canboat's unit, tolerance)])
FIELDS = {
    127250: ("heading", [("Heading", "heading_rad", DEG, 0.05 + 1e-9)]),
    127251: ("rot", [("Rate", "rot_radps", DEG, 5e-7 + 1e-12)]),
    128259: ("water", [("Speed Water Referenced", "stw_mps", 1.0, 0.005 + 1e-9)]),
    129025: (
        "position",
        [("Latitude", "lat_rad", DEG, 5e-8 + 1e-12), ("Longitude", "lon_rad", DEG, 5e-8 + 1e-12)],
    ),
    129029: (
        "position",
        [("Latitude", "lat_rad", DEG, 5e-8 + 1e-12), ("Longitude", "lon_rad", DEG, 5e-8 + 1e-12)],
    ),
    129026: (
        "ground",
        [("COG", "cog_rad", DEG, 0.05 + 1e-9), ("SOG", "sog_mps", 1.0, 0.005 + 1e-9)],
    ),
}


def load(name: str) -> list[list]:
    """The messages of a ``*.canboat.json`` reference."""
    return json.loads((DATA / name).read_text(encoding="utf-8"))["messages"]


def check_messages(msgs, ref: list[list]) -> None:
    """dracc's messages are canboat's, one for one: PGN, source, destination, priority."""
    got = list(
        zip(
            msgs.pgn.tolist(), msgs.src.tolist(), msgs.dst.tolist(), msgs.prio.tolist(), strict=True
        )
    )
    assert got == [tuple(r[:4]) for r in ref]


def canboat_utc_ns(date: str, time: str) -> int:
    """ns since 1970 of canboat's ``"2016.04.09"``, ``"16:41:09.4000"`` (integers only:
    a float has 256 ns steps there)."""
    day = int(datetime.strptime(date, "%Y.%m.%d").replace(tzinfo=UTC).timestamp())
    h, m, s = time.split(":")
    whole, _, frac = s.partition(".")
    frac_ns = int((frac + "000000000")[:9])
    return ((day + int(h) * 3600 + int(m) * 60 + int(whole)) * 1_000_000_000) + frac_ns


def check_fields(msgs, frames: dict, ref: list[list]) -> dict[int, int]:
    """Every navigation value canboat decodes equals dracc's in its frame (within
    canboat's rounding); returns the values compared per PGN."""
    at_line = {int(line): k for k, line in enumerate(msgs.line.tolist())}
    compared: dict[int, int] = {}
    for pgn, (kind, fields) in FIELDS.items():
        df = frames.get(kind)
        want = {k: r[4] for k, r in enumerate(ref) if r[0] == pgn and len(r) > 4}
        if not want:
            continue
        rows = df[df["sentence"].astype(str) == f"PGN{pgn}"]
        have = {at_line[int(ln)]: i for i, ln in enumerate(rows["line"].tolist())}
        for k, values in want.items():
            for field, col, scale, tol in fields:
                v = values.get(field)
                if v is None or (field == "COG" and values.get("COG Reference") != "True"):
                    continue  # not available, or a magnetic COG dracc does not use
                assert k in have, f"PGN{pgn} message {k} ({values}) has no {kind} record"
                got = float(rows[col].iloc[have[k]]) * scale
                if col in ("heading_rad", "cog_rad"):
                    got %= 360.0
                assert abs(got - v) <= tol, (pgn, k, field, got, v)
                compared[pgn] = compared.get(pgn, 0) + 1
            if pgn == 127250 and "Reference" in values:
                ref_code = rows["reference"].iloc[have[k]]
                assert ref_code == {"Magnetic": "M", "True": "T"}[values["Reference"]]
            if pgn == 129029 and "Date" in values and "Time" in values:
                own = int(rows["time_ns"].iloc[have[k]])
                assert own == canboat_utc_ns(values["Date"], values["Time"])
    assert np.all([n > 0 for n in compared.values()])
    return compared
