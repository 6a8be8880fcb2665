"""Several units behind one source key: positions of one instant far apart.

Three INS writing ``$INGGA`` to one logger without TAG blocks share the key ``IN``; their
fixes of one second interleave, hundreds of metres apart.  Read as one source, every
step between two of them looks like a jump (16 396 "jumps" on a 3 h simulated voyage).
A source is *interleaved* where most of its instants with two or more positions carry
positions more than :data:`SPREAD_M` apart -- one receiver's GGA, RMC and GLL of one
fix agree to the last digit.  It is named as such (``SourceInfo.interleaved``), given no
role, and its steps are not judged as jumps; the note says how to tell the units apart.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from dracc.frames import SourceInfo

__all__ = ["SPREAD_M", "interleaved_note", "mark_interleaved"]

#: positions of one instant further apart than this come from different units
SPREAD_M = 20.0
#: interleaved: at least this share of the multi-position instants, and this many of them
SHARE = 0.5
MIN_INSTANTS = 20
_R_M = 6371000.0  #: a local scale for metres between nearby positions


def mark_interleaved(frames: dict[str, pd.DataFrame], sources: dict[str, SourceInfo]) -> list[str]:
    """Set ``interleaved`` on the sources whose positions interleave several units; the
    notes that say so."""
    pos = frames.get("position")
    if pos is None or not len(pos):
        return []
    ok = np.isfinite(pos["lat_rad"].to_numpy(float)) & (pos["quality"].to_numpy() != 0)
    p = pos[ok]
    codes, keys = pd.factorize(p["source"])
    t = p["time_ns"].to_numpy(np.int64)
    order = np.lexsort((t, codes))
    c, t = codes[order], t[order]
    la, lo = p["lat_rad"].to_numpy(float)[order], p["lon_rad"].to_numpy(float)[order]
    if c.size < 2:
        return []
    starts = np.flatnonzero(np.r_[True, (c[1:] != c[:-1]) | (t[1:] != t[:-1])])
    size = np.diff(np.r_[starts, c.size])
    dlat = np.maximum.reduceat(la, starts) - np.minimum.reduceat(la, starts)
    dlon = np.maximum.reduceat(lo, starts) - np.minimum.reduceat(lo, starts)
    spread = np.hypot(dlat, dlon * np.cos(la[starts])) * _R_M
    notes = []
    for i, key in enumerate(keys):
        mine = (c[starts] == i) & (size >= 2)
        n = int(mine.sum())
        far = mine & (spread > SPREAD_M)
        if n < MIN_INSTANTS or far.sum() < SHARE * n:
            continue
        units = int(np.median(size[far]))
        what = (
            f"{units} positions at {100 * far.sum() / n:.0f} % of its instants, a median "
            f"{np.median(spread[far]):,.0f} m apart"
        )
        sources[str(key)].interleaved = what
        notes.append(interleaved_note(str(key), what))
    return notes


def interleaved_note(key: str, what: str) -> str:
    """The note on a source of several units (``SourceInfo.interleaved``)."""
    return (
        f"{key}: several units behind one key ({what}): given no role and not judged for "
        "jumps; tell them apart (TAG s:, their own talker IDs, or one file each) and map "
        "them with --role KEY=ROLE"
    )
