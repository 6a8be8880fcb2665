"""JSON from elsewhere (a ship's audit document, a column of its database), parsed
within bounds.

Python's parser recurses once per level of nesting: a 200,000-deep array ends in
``RecursionError``, which is no ``ValueError`` and was an internal error (exit 5).
:func:`loads` measures the nesting first, over the bytes with their strings blanked
(:func:`nesting_depth`, a few milliseconds a megabyte, never recursing), and refuses a
text deeper than ``max_depth`` with a ``ValueError`` that says so, as it does for a
text that is not JSON.  A nightly audit document nests 10 levels deep (its embedded
analysis 8).
"""

from __future__ import annotations

import json
from typing import Any

import numpy as np

#: the deepest nesting accepted by default (an audit document has 10 levels)
MAX_DEPTH = 64

#: bytes examined per piece (bounded memory on a file of brackets)
_PIECE = 1 << 20
_QUOTE, _BACKSLASH = ord('"'), ord("\\")
#: +1 for an opening bracket, -1 for a closing one, by byte
_STEP = np.zeros(256, np.int8)
_STEP[np.frombuffer(b"[{", np.uint8)] = 1
_STEP[np.frombuffer(b"]}", np.uint8)] = -1


def nesting_depth(data: bytes) -> int:
    """The deepest nesting of arrays and objects in ``data`` (brackets inside strings
    not counted).  Up to its first syntax error a parser sees the same strings, so no
    parser of ``data`` goes deeper than this.  Vectorised, piece by piece: a quote is
    a string's start or end unless an odd run of backslashes comes before it."""
    depth = deepest = 0
    inside = False  # in a string at the end of the previous piece
    run = 0  # backslashes at the end of the previous piece
    for start in range(0, len(data), _PIECE):
        a = np.frombuffer(data, np.uint8, count=min(_PIECE, len(data) - start), offset=start)
        quote = a == _QUOTE
        backslash = a == _BACKSLASH
        if run or backslash.any():  # drop the escaped quotes
            idx = np.arange(len(a))
            # the last byte that is no backslash, at or before each byte (-1: none)
            last = np.maximum.accumulate(np.where(backslash, -1, idx))
            before = np.empty(len(a), np.int64)  # the backslashes just before each byte
            before[0] = run
            before[1:] = np.where(last[:-1] >= 0, idx[:-1] - last[:-1], idx[1:] + run)
            quote &= before % 2 == 0
            run = int(before[-1]) + 1 if backslash[-1] else 0
        in_string = (np.cumsum(quote, dtype=np.int64) % 2 == 1) ^ inside
        step = _STEP[a]
        step[in_string] = 0
        level = depth + np.cumsum(step, dtype=np.int64)
        deepest = max(deepest, int(level.max()))
        depth, inside = int(level[-1]), bool(in_string[-1])
    return deepest


def loads(data: bytes | str, max_depth: int = MAX_DEPTH) -> Any:
    """``json.loads(data)``, refused (``ValueError``) when it nests deeper than
    ``max_depth`` or is not JSON.  ``NaN`` and ``Infinity`` are refused too: no dracc
    writer emits them."""
    raw = data.encode("utf-8", "surrogatepass") if isinstance(data, str) else data
    depth = nesting_depth(raw)
    if depth > max_depth:
        raise ValueError(f"nested {depth:,} levels deep (at most {max_depth})")
    try:
        return json.loads(raw, parse_constant=_no_constant)
    except RecursionError:  # not reached after the count; a safety net all the same
        raise ValueError(f"nested too deep (at most {max_depth})") from None


def _no_constant(name: str) -> Any:
    raise ValueError(f"{name} is not a JSON number")
