"""Small array helpers shared by the math modules, and the numpy array type aliases.

``FloatArray``, ``IntArray`` and ``BoolArray`` are the annotations of float64, int64 and
boolean arrays everywhere in dracc; ``ArrayLike`` (re-exported from ``numpy.typing``)
annotates what accepts a scalar, a sequence or an array, ``FloatOrArray`` what numpy
returns for either.
"""

from __future__ import annotations

from typing import Any, TypeAlias

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "ArrayLike",
    "BoolArray",
    "FloatArray",
    "FloatOrArray",
    "IntArray",
    "hold_at",
    "unique_sorted",
]

FloatArray: TypeAlias = NDArray[np.float64]  #: an array of float64
IntArray: TypeAlias = NDArray[np.int64]  #: an array of int64 (times in nanoseconds)
BoolArray: TypeAlias = NDArray[np.bool_]  #: an array of booleans (masks)
#: what numpy gives for scalar inputs (a float64, or a 0-d array) or for arrays
FloatOrArray: TypeAlias = "float | FloatArray"


def unique_sorted(a: ArrayLike) -> NDArray[Any]:
    """The sorted distinct values of ``a`` (as ``np.unique(a)``).

    By a sort and a comparison of neighbours: numpy 2.4's ``np.unique`` hashes integer
    arrays, which takes ~2 s for a million int64 timestamps (50x the sort).
    """
    b = np.sort(np.asarray(a).ravel(), kind="stable")
    if b.size == 0:
        return b
    return b[np.r_[True, b[1:] != b[:-1]]]


def hold_at(
    t_src_ns: NDArray[np.int64], values: NDArray[Any], t_at_ns: NDArray[np.int64], max_age_ns: int
) -> NDArray[np.float64]:
    """The last sample at or before each of ``t_at_ns``, NaN where it is older than
    ``max_age_ns`` or there is none (sample-and-hold; ``t_src_ns`` sorted)."""
    i = np.searchsorted(t_src_ns, t_at_ns, side="right") - 1
    ok = i >= 0
    out = np.full(np.shape(t_at_ns), np.nan)
    j = i[ok]
    out[ok] = np.where(t_at_ns[ok] - t_src_ns[j] <= max_age_ns, values[j], np.nan)
    return out
