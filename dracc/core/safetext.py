"""Text from a log made harmless where it is shown: on a terminal and in CSV cells.

Source keys (NMEA TAG ``s:``, MCAP topics, CSV sources), file and vessel names and
rejected lines come from outside.  On a terminal a control character is an instruction:
ESC starts a colour, a cursor move or an OSC sequence (window title, hyperlink,
clipboard), CR and backspace overwrite what was printed.  :func:`printable` shows every
such character as a visible escape instead (``\\x1b``, ``\\u202e``), and keeps every
printable character, Unicode letters included (``Nordlys ★``, ``北斗丸``).

In a spreadsheet, a CSV cell starting with ``=``, ``+``, ``-``, ``@``, a tab or a CR is
read as a formula (OWASP "CSV injection"); :func:`csv_cell` puts a single quote in
front of such a text so that it is shown as text.  Parquet keeps the raw value.
"""

from __future__ import annotations

import unicodedata
from typing import TypeVar

_T = TypeVar("_T")

#: the bidirectional controls (Unicode category Cf) that reorder what a terminal shows
_BIDI = frozenset("\u061c\u200e\u200f\u202a\u202b\u202c\u202d\u202e\u2066\u2067\u2068\u2069")

#: first characters that make a spreadsheet read a cell as a formula
FORMULA_START = ("=", "+", "-", "@", "\t", "\r")


def _escape(c: str) -> str:
    n = ord(c)
    return f"\\x{n:02x}" if n < 0x100 else f"\\u{n:04x}"


def printable(text: object, keep: str = "") -> str:
    """``text`` with every control character (C0, DEL, C1: ESC, CR, LF, tab, NUL, ...),
    bidirectional control and lone surrogate (an undecodable byte of a file name) shown
    as a visible escape; printable text unchanged.  ``keep``: characters left as they
    are (``"\\n"`` for a message of several lines)."""
    s = str(text)
    if s.isprintable():  # the common case, fast
        return s
    return "".join(
        _escape(c)
        if c not in keep and (unicodedata.category(c) in ("Cc", "Cs", "Zl", "Zp") or c in _BIDI)
        else c
        for c in s
    )


def csv_cell(value: _T) -> _T | str:
    """A CSV cell value: a text starting like a formula gets a leading single quote;
    anything else (numbers, missing values) is returned as it is."""
    if isinstance(value, str) and value.startswith(FORMULA_START):
        return "'" + value
    return value
