"""Is the probability stated beside 2M the one achieved?  The DR section's honesty figures.

From the consistency result (per scored epoch: the drawn 2M, the reference inside it, the
predictive's stated probability and the PIT, :mod:`dracc.math.deadreckoning.consistency`)
and the learned model's covariance matching (:mod:`dracc.math.ep.forecast`): the
inflation applied and the shape of its posterior (the predictive's tails), the epochs
beyond the stated 99 % radius, the PIT histogram and the misleading epochs of a Stanford
diagram (error beyond 2M).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from dracc.math.deadreckoning import Consistency
from dracc.math.ep import EstimatedPosition
from dracc.pipeline.results import DRHonesty

#: bins of the PIT histogram (equal widths over [0, 1])
PIT_BINS = 10


def honesty(cons: Consistency, est: EstimatedPosition | None) -> DRHonesty:
    """The honesty figures of a DR scored in ``cons``; ``est`` the learned model or None
    (the configured model: a Gaussian predictive, no inflation)."""
    n = cons.n_epochs
    counts = np.histogram(np.clip(cons.pit, 0.0, 1.0), bins=PIT_BINS, range=(0.0, 1.0))[0]
    first = cons.leg == cons.leg.min() if n else np.zeros(0, bool)
    if est is not None:
        fc = est.forecast
        scored_legs = np.unique(cons.leg)
        infl = fc.inflation[scored_legs] if scored_legs.size else fc.inflation
        shape = fc.shape[scored_legs] if scored_legs.size else fc.shape
        method = (
            "learned: the mixed model's covariance times a factor matched to the earlier "
            "legs' errors against the reference (inverse-gamma posterior); Student-t predictive"
        )
    else:
        infl = shape = np.full(1, math.nan)
        method = "configured: the [dead_reckoning] error model as given; Gaussian predictive"
    return DRHonesty(
        predictive="student-t" if est is not None else "gaussian",
        method=method,
        inflation_min=_extreme(np.min, infl),
        inflation_max=_extreme(np.max, infl),
        shape_min=_extreme(np.min, shape),
        n_scored=n,
        n_misleading=n - cons.n_inside,
        stated_inside=cons.expected_inside_fraction,
        n_beyond_99=cons.n_beyond_99,
        expected_beyond_99=0.01 * n,
        pit_counts=tuple(int(c) for c in counts),
        first_leg_inside=float(cons.inside[first].mean()) if first.any() else math.nan,
        first_leg_stated=float(cons.p_inside_expected[first].mean()) if first.any() else math.nan,
    )


def _extreme(pick: Callable[[np.ndarray], Any], x: np.ndarray) -> float:
    """min or max over the finite values of x; NaN where there is none."""
    finite = x[np.isfinite(x)]
    return float(pick(finite)) if finite.size else math.nan
