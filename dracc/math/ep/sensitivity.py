"""The sensitivities J of the ground velocity to the heading and log-scale errors.

J_eps = d v_w / dC = (-v_E, v_N), J_s = v_w = (v_N, v_E), taken from the water velocity
averaged over SENSITIVITY_WINDOW_S, and the prefix sums that integrate them (G = int J dt).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from dracc.core.arrays import ArrayLike, FloatArray

#: the sensitivities J are taken from the water velocity averaged over this window
SENSITIVITY_WINDOW_S = 900.0


def _smooth_velocity(
    time_s: ArrayLike, vn: FloatArray, ve: FloatArray, window_s: float = SENSITIVITY_WINDOW_S
) -> tuple[FloatArray, FloatArray]:
    """The water velocity averaged over ``window_s`` (centred, in time).

    The sensitivities must not carry the log's and compass's own noise: J_s = v_w with the
    log noise in it correlates with the very error it is regressed on (the noise is in the
    water track too), and the scale estimate runs away along a straight leg (errors in
    variables).  Averaged over 15 min the noise (correlated over minutes) is mostly gone
    while turns and speed changes stay."""
    t = np.asarray(time_s, float)
    if t.size < 3:
        return vn, ve
    # time as covered by samples: a silence (a step over a minute) counts as none
    dt = np.diff(t)
    dt = np.where(dt <= 60.0, dt, 0.0)
    u = np.concatenate([[0.0], np.cumsum(dt)])
    out = []
    for v in (vn, ve):
        area = np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * dt)])
        lo = np.interp(u - 0.5 * window_s, u, area)
        hi = np.interp(u + 0.5 * window_s, u, area)
        span = np.minimum(u + 0.5 * window_s, u[-1]) - np.maximum(u - 0.5 * window_s, u[0])
        out.append(np.where(span > 0, (hi - lo) / np.where(span > 0, span, 1.0), v))
    return out[0], out[1]


def sensitivity_steps(t: FloatArray, vn: FloatArray, ve: FloatArray, dt: FloatArray) -> FloatArray:
    """(n-1, 2, 2): J dt over each step, J from the smoothed water velocity held over it."""
    return sensitivities(*_smooth_velocity(t, vn, ve))[:-1] * dt[:, None, None]


def sensitivities(vn_w_mps: ArrayLike, ve_w_mps: ArrayLike) -> FloatArray:
    """(n, 2, 2): d v / d[eps, s] per sample, columns J_eps = (-v_E, v_N), J_s = (v_N, v_E)."""
    vn = np.asarray(vn_w_mps, float)
    ve = np.asarray(ve_w_mps, float)
    return np.stack([np.stack([-ve, vn], -1), np.stack([vn, ve], -1)], -1)


def prefix_sum(a: NDArray[Any]) -> FloatArray:
    """Cumulative sums along axis 0 with a leading zero: sums over [i, k) are S[k] - S[i]."""
    return np.concatenate([np.zeros((1,) + a.shape[1:]), np.cumsum(a, axis=0)])
