"""The heading ``reference`` vocabulary of CSV, JSON, protobuf and ROS 2 logs.

NMEA says ``T`` (true) or ``M`` (magnetic) in the sentence itself; the named-quantity
formats spell it as their writers do.  Accepted (case and surrounding blanks ignored):

- true: ``T``, ``true``, ``true north``/``true_north``/``truenorth``, ``geographic``
  (compass_msgs/Azimuth's name for it), ``gyro``;
- magnetic: ``M``, ``mag``, ``magnetic``, ``magnetic north``/``magnetic_north``;
- the ASCII codes 84 ('T') and 77 ('M'), as dracc's ROS 2 ``uint8 reference`` writes;
- a boolean field that says whether the heading is true (``is_true``,
  ``true_heading``, ``is_true_heading``) or magnetic (``is_magnetic``,
  ``magnetic_heading``): JSON ``true``/``false``, ``1``/``0`` or the strings
  ``true``/``false``/``yes``/``no``;
- ROS constants declared in the message definition (``uint8 REFERENCE_MAGNETIC=0``,
  ``uint8 REFERENCE_GEOGRAPHIC=1``, ``..._TRUE=..``): see :func:`ros_constants`.

Anything else (``"grid"``, ``"UTM"``, ``"north"``, a bare JSON ``true`` in a ``reference``
field, which says nothing about which north) is *not* mapped: the record is rejected
from the heading frame as ``heading reference not understood`` with examples, so an
unknown spelling is counted and shown by ``dracc inspect``, never read as magnetic or
true by accident.  An empty or null reference is "not given" (as before).
"""

from __future__ import annotations

import re

import numpy as np
import pandas as pd

from dracc.core.arrays import ArrayLike

TRUE_WORDS = frozenset(
    {"t", "true", "true north", "true_north", "truenorth", "true-north", "geographic", "gyro"}
)
MAGNETIC_WORDS = frozenset(
    {"m", "mag", "magnetic", "magnetic north", "magnetic_north", "magneticnorth", "magnetic-north"}
)
_YES = frozenset({"true", "1", "yes", "y"})
_NO = frozenset({"false", "0", "no", "n"})
ASCII_CODES = {84: "T", 77: "M"}

REJECT_REASON = "heading reference not understood"


def _word(x: object) -> str | None:
    """'T', 'M', '' (not given) or None (not understood) for one reference value."""
    if x is None or x is pd.NA:
        return ""
    if isinstance(x, (bool, np.bool_)):
        return None  # a bare boolean in a reference field: which north?
    if isinstance(x, (int, float, np.integer, np.floating)):
        if isinstance(x, (float, np.floating)) and np.isnan(x):
            return ""
        if float(x).is_integer():
            return ASCII_CODES.get(int(x))
        return None
    s = str(x).strip().lower()
    if not s:
        return ""
    if s in TRUE_WORDS:
        return "T"
    if s in MAGNETIC_WORDS:
        return "M"
    return None


def normalize_reference(values: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """(reference as object array of 'T'/'M'/None, mask of values not understood).

    Each distinct value is looked up once (a day of 10 Hz headings holds two or three)."""
    arr = np.asarray(values, dtype=object)
    if arr.size == 0:
        return np.full(arr.shape, None, dtype=object), np.zeros(arr.shape, dtype=bool)
    given = ~pd.isna(arr)
    tm = (arr == "T") | (arr == "M")
    if np.array_equal(tm, given):  # the common case: the NMEA letters already
        # numpy's stubs have no overload for None as the value where False
        ref = np.where(tm, arr, None)  # type: ignore[call-overload]
        return ref.astype(object), np.zeros(arr.shape, dtype=bool)
    try:
        codes, uniq = pd.factorize(arr)  # None/NaN -> -1 (not given)
    except TypeError:  # unhashable values (a list in a JSON field): one by one
        codes, uniq = np.arange(arr.size), arr
    words = []
    for x in list(uniq):
        try:
            words.append(_word(x))
        except TypeError:
            words.append(None)
    # 'T'/'M', '' not given, '?' not understood; the last entry serves code -1
    w = np.array([("?" if x is None else x) for x in words] + [""], dtype=object)[codes]
    if any(isinstance(x, (bool, np.bool_, int, np.integer)) for x in uniq):
        # factorize folds True into 1 and 1 into True: a bool is never understood
        isbool = np.fromiter(
            (isinstance(x, (bool, np.bool_)) for x in arr.tolist()), dtype=bool, count=arr.size
        )
        w = np.where(isbool, "?", w)
    bad = w == "?"
    # numpy's stubs read np.where(c, x, None) as the one-argument form (a tuple)
    out = np.where((w == "T") | (w == "M"), w, None).astype(object)  # type: ignore[attr-defined]
    return out, bad


def normalize_boolean(values: ArrayLike, means: str) -> tuple[np.ndarray, np.ndarray]:
    """A boolean 'is true'/'is magnetic' field (``means`` the reference of ``true``) as
    (reference, not-understood mask)."""
    other = "M" if means == "T" else "T"
    arr = np.asarray(values, dtype=object)
    out = np.full(arr.shape, None, dtype=object)
    bad = np.zeros(arr.shape, dtype=bool)
    for i, x in enumerate(arr.tolist()):
        if x is None or (isinstance(x, float) and x != x) or (isinstance(x, str) and not x.strip()):
            continue
        if isinstance(x, (bool, np.bool_)):
            out[i] = means if x else other
            continue
        s = (
            str(int(x))
            if isinstance(x, (int, float, np.integer, np.floating)) and float(x).is_integer()
            else str(x).strip().lower()
        )
        if s in _YES:
            out[i] = means
        elif s in _NO:
            out[i] = other
        else:
            bad[i] = True
    return out, bad


_CONST = re.compile(r"^\s*u?int(?:8|16|32|64)\s+REFERENCE_([A-Z_]+)\s*=\s*(\d+)", re.M)


def ros_constants(schema_text: str) -> dict[int, str | None]:
    """Reference codes declared as constants in a ROS message definition: code -> 'T', 'M',
    or None for a declared reference dracc does not use (e.g. REFERENCE_UTM, grid north)."""
    out: dict[int, str | None] = {}
    for name, code in _CONST.findall(schema_text or ""):
        n = name.lower()
        out[int(code)] = (
            "T"
            if n in ("true", "geographic", "true_north", "geographic_north")
            else "M"
            if n in ("magnetic", "magnetic_north")
            else None
        )
    return out
