"""The estimated position's error model: the state layout, the priors and the model grid.

What the filter (dracc.math.ep.kalman) assumes before it has seen a fix: ErrorPrior, the
sensor and current priors; Hyperparameters, the grid of Gauss-Markov models it weighs;
heading_prior_rad, the compass and leeway prior.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from dracc.core.arrays import FloatArray
from dracc.core.units import KN_MPS

#: state layout: p (0, 1), cbar (2, 3), c (4, 5), n (6, 7), eps (8), s (9), delta (10)
N_STATE = 11
EPS, SCALE, DELTA = 8, 9, 10
#: the heading-dependent error delta decorrelates over this change of course (rad)
TURN_DECORRELATION_RAD = 1.0
#: the sensor priors (IMO limits) are widened by this factor: real logs are often worse
PRIOR_WIDENING = 3.0
#: an innovation that even the widest grid point finds this improbable (NIS, 2 dof) is an
#: outlier (a GNSS jump) and is not used
OUTLIER_NIS = 60.0
#: grid points this far below the best log-likelihood leave the run
PRUNE_LOGLIK = 25.0


@dataclass(frozen=True)
class ErrorPrior:
    """What is assumed before anything is learned (1-sigma, SI units)."""

    current_sigma_mps: (
        float  #: persistent current, per axis (a knot or so: honest about not knowing)
    )
    heading_sigma_rad: float  #: compass error + leeway (IMO gyro limit with sec phi, as 95 %)
    scale_sigma: float  #: log scale error (IMO 2 % or 0.2 kn, as 95 %)
    fix_sigma_m: float  #: the reference fixes, per axis (the grid spans 0.3-3 times this)


@dataclass(frozen=True)
class Hyperparameters:
    """The grid of models the filter weighs, each (M,)."""

    current_sigma_mps: FloatArray  #: sigma_c of the current's variation c
    current_tau_s: FloatArray  #: tau_c
    noise_sigma_mps: FloatArray  #: sigma_n of the short-term velocity noise n
    noise_tau_s: FloatArray  #: tau_n
    turn_sigma_rad: FloatArray  #: sigma of the heading-dependent error delta
    fix_sigma_m: FloatArray  #: the reference fixes' noise, per axis

    @property
    def size(self) -> int:
        return int(self.current_sigma_mps.size)

    def take(self, idx: NDArray[Any]) -> Hyperparameters:
        return Hyperparameters(*(getattr(self, f)[idx] for f in self.__dataclass_fields__))

    @property
    def noise_psd_m2ps(self) -> FloatArray:
        """The short-term noise as white noise at horizons beyond tau_n: 2 sigma_n^2 tau_n."""
        return 2.0 * self.noise_sigma_mps**2 * self.noise_tau_s


def hyperparameter_grid(fix_sigma_m: float = 10.0) -> Hyperparameters:
    """The default grid: the current's variation 0.05-1.5 kn over 0.5-8 h; short-term
    noise 0.03-0.3 kn over 1 or 10 min (a log's 0.1 kn over 5 min lies between); a
    heading-dependent error (residual deviation, leeway that changes side with the tack) of
    0 or 1.5 deg; fix noise 0.1, 0.3, 1 or 3 times ``fix_sigma_m``."""
    axes = (
        np.array([0.05, 0.15, 0.5, 1.5]) * KN_MPS,
        np.array([0.5, 2.0, 8.0]) * 3600.0,
        np.array([0.03, 0.1, 0.3]) * KN_MPS,
        np.array([60.0, 600.0]),
        np.array([0.0, 1.5]) * math.pi / 180.0,
        np.array([0.1, 0.3, 1.0, 3.0]) * fix_sigma_m,
    )
    return Hyperparameters(*(a.ravel() for a in np.meshgrid(*axes, indexing="ij")))


def heading_prior_rad(
    compass_bias_rad: float, leeway_rad: float, lat_rad: float, gyro: bool
) -> float:
    """Prior of the heading error: the compass bias (gyro: x sec phi, METHODS section 6)
    combined with the leeway."""
    sec = 1.0 / max(math.cos(lat_rad), 0.1) if gyro else 1.0
    return math.hypot(compass_bias_rad * sec, leeway_rad)
