"""Small array helpers shared by the math modules."""

from __future__ import annotations

import numpy as np

__all__ = ["unique_sorted"]


def unique_sorted(a) -> np.ndarray:
    """The sorted distinct values of ``a`` (as ``np.unique(a)``).

    By a sort and a comparison of neighbours: numpy 2.4's ``np.unique`` hashes integer
    arrays, which takes ~2 s for a million int64 timestamps (50x the sort).
    """
    b = np.sort(np.asarray(a).ravel(), kind="stable")
    if b.size == 0:
        return b
    return b[np.r_[True, b[1:] != b[:-1]]]
