"""Estimated position over the ground, with a DR error model learned causally from the fixes.

Source: the dead-reckoning paper (seeds/000, B7-B12: the water track plus the current
(Vp, Kp)), the aided dead-reckoning paper (seeds/003: Gauss-Markov errors of the medium
and the sensors estimated from intermittent fixes and blended into the DR); METHODS
sections 2, 3 and 7.

The ship's velocity over the ground is the DR velocity through the water ``v_w`` (B7-B10
without the current) plus what the DR does not know::

    v_g = v_w + cbar + c(t) + n(t) + eps J_eps(t) + s J_s(t)

    cbar    a persistent current (north, east), m/s
    c(t)    the current's variation: first-order Gauss-Markov (sigma_c, tau_c) per axis
    n(t)    short-term velocity noise (log, compass, leeway): Gauss-Markov (sigma_n, tau_n)
    eps     heading error (compass error + leeway), rad: J_eps = d v_w / dC = (-v_E, v_N)
    s       log scale error (fraction):              J_s   = v_w     = ( v_N, v_E)

A Kalman filter with the state ``x = [p, cbar, c, n, eps, s]`` (p: the integral of
``v_g - v_w``, the error of the water track in metres north/east; 10 states) observes
``y = reference position - water track`` every ``step_s``.  Exact discretisation over a
step dt, for each Gauss-Markov process g = c, n (phi = exp(-dt/tau))::

    p+ = p + dt cbar + tau_c (1 - phi_c) c + tau_n (1 - phi_n) n + G [eps, s],  G = int J dt
    g+ = phi g,  Q: the integrated Gauss-Markov process (dracc.math.current.gauss_markov_noise)

The hyper-parameters ``(sigma_c, tau_c, sigma_n, tau_n)``, the fixes' noise and a widening
of the sensor priors are not known: the filter runs for every point of a grid of them at
once (a leading axis), and each point's cumulative log-likelihood of the innovations up to
a time weighs it there (Bayesian model averaging, i.e. maximum likelihood once the data
are many).  A point whose log-likelihood falls PRUNE_LOGLIK below the best is dropped
from the run (its weight is below e^-25 and does not come back).  Everything a leg uses
comes from the fixes *before* its start fix (causal): the posterior at the start, the
weights at the start.

The estimated position of a leg started at a fix at t_s is the fix plus the water track
plus the predicted correction, with h = t - t_s and A(h) = [h I, tau_c (1 - phi_c(h)) I,
tau_n (1 - phi_n(h)) I, G(h)] acting on the posterior of ``(cbar, c, n, eps, s)``::

    mu(h)    = A(h) x_s
    Sigma(h) = A P_s A^T + Q_c(h) + Q_n(h) + sigma_fix^2 I       (per grid point)

and over the grid the moment-matched mixture ``sum w (Sigma + mu mu^T) - mu_bar mu_bar^T``.
So the circle grows with the time since the estimate (the current's uncertainty and its
change), not only with the distance run, and widens where the grid points disagree.

Modules, in the order a run goes through them
    error_model   the state layout, the priors (ErrorPrior), the model grid (Hyperparameters)
    sensitivity   J_eps, J_s from the smoothed water velocity, and their integrals G
    kalman        the Kalman filter over the fixes on every grid point: LearnedModel
    forecast      each leg's correction and covariance, covariance matching: LegForecast
    estimate      estimate_position, the entry point tying these together
    aided         the aided-DR EP of seeds/003 (fixes and single LOPs, fix-interval study)
"""

from __future__ import annotations

from dracc.math.ep.error_model import (
    DELTA,
    EPS,
    N_STATE,
    OUTLIER_NIS,
    PRIOR_WIDENING,
    PRUNE_LOGLIK,
    SCALE,
    TURN_DECORRELATION_RAD,
    ErrorPrior,
    Hyperparameters,
    heading_prior_rad,
    hyperparameter_grid,
)
from dracc.math.ep.estimate import (
    MIN_LEARNED_S,
    MIN_LEARNED_UPDATES,
    EstimatedPosition,
    estimate_position,
    step_ok_of,
)
from dracc.math.ep.forecast import (
    INFLATION_BINS,
    INFLATION_FORGET,
    INFLATION_LEG_CAP,
    INFLATION_PRIOR_LEGS,
    INFLATION_PRIOR_MEAN,
    LegForecast,
    forecast_legs,
)
from dracc.math.ep.kalman import FilterHistory, LearnedModel, learn_error_model
from dracc.math.ep.sensitivity import SENSITIVITY_WINDOW_S, sensitivities

__all__ = [
    "DELTA",
    "EPS",
    "INFLATION_BINS",
    "INFLATION_FORGET",
    "INFLATION_LEG_CAP",
    "INFLATION_PRIOR_LEGS",
    "INFLATION_PRIOR_MEAN",
    "MIN_LEARNED_S",
    "MIN_LEARNED_UPDATES",
    "N_STATE",
    "OUTLIER_NIS",
    "PRIOR_WIDENING",
    "PRUNE_LOGLIK",
    "SCALE",
    "SENSITIVITY_WINDOW_S",
    "TURN_DECORRELATION_RAD",
    "ErrorPrior",
    "EstimatedPosition",
    "FilterHistory",
    "Hyperparameters",
    "LearnedModel",
    "LegForecast",
    "estimate_position",
    "forecast_legs",
    "heading_prior_rad",
    "hyperparameter_grid",
    "learn_error_model",
    "sensitivities",
    "step_ok_of",
]
