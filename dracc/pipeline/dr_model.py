"""The estimated position's error model as the DR section shows it: the prior it starts
from, the model it learned over the voyage (with a ready ``[dead_reckoning]`` block for
logs without a reference), the part that dominates its 2M, and the fixes it weighed.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from dracc.core.config import DeadReckoningConfig
from dracc.core.geodesy import wrap_2pi
from dracc.core.units import DEG_RAD, KN_MPS
from dracc.math.deadreckoning import Consistency, DRTrack, LegConsistency
from dracc.math.ep import ErrorPrior, EstimatedPosition, LearnedModel, heading_prior_rad
from dracc.math.integrity.causes import Span, overlaps

#: what each part of the EP covariance is, and the key that sets its prior
SOURCE_KEYS = {
    "fix": ("the fixes' noise", "fix_sigma_m"),
    "current": ("the current estimate", "current_kn"),
    "current change": ("the change of the current", "current_kn"),
    "heading": ("the compass and leeway error", "compass_bias_deg"),
    "log scale": ("the log scale error", "log_scale"),
    "noise": ("short-term log and compass noise", "log_noise_kn"),
}


def dominant_source(
    est: EstimatedPosition, cons: Consistency, tr: DRTrack, fix_s: np.ndarray
) -> tuple[str, str] | None:
    """The part of the EP covariance largest at the epochs that missed (or, when none did,
    at every scored epoch), with the [dead_reckoning] key of its prior."""
    if not cons.n_epochs:
        return None
    idx = np.searchsorted(tr.time_s, cons.time_s)
    miss = ~cons.inside
    pick = idx[miss] if miss.any() else idx
    parts = {k: float(np.nanmean(v[pick])) for k, v in est.forecast.components_m2.items()}
    name = max(parts, key=lambda k: parts[k])
    return SOURCE_KEYS[name]


def final_posterior(m: LearnedModel) -> tuple[np.ndarray, np.ndarray]:
    """The filter's state at the end of the data mixed over the grid weights: the mean
    (N,) and the covariance (N, N), the spread between grid points included."""
    w = m.final_weights
    x = w @ m.final_x
    dx = m.final_x - x
    return x, np.einsum("m,mij->ij", w, m.final_P + dx[:, :, None] * dx[:, None, :])


def learned_summary(est: EstimatedPosition, cfg: DeadReckoningConfig) -> dict[str, object]:
    """The model learned over the whole voyage (final grid weights) and a ready
    [dead_reckoning] block that reuses it where there is no reference (learn = false).

    The compass and log errors it learned are the calibration section's
    (:mod:`dracc.pipeline.calibration_stage`, in the error convention), not repeated here."""
    m = est.model
    hp = m.hyper
    w = m.final_weights
    j = int(np.argmax(w))
    x, Pm = final_posterior(m)
    cbar = x[2:4]
    drift = float(np.hypot(*cbar))
    eps, s = float(x[8]), float(x[9])
    s_eps, s_s = math.sqrt(max(Pm[8, 8], 0.0)), math.sqrt(max(Pm[9, 9], 0.0))
    sig_c, tau_c = float(hp.current_sigma_mps[j]), float(hp.current_tau_s[j])
    noise_kn, noise_tau = float(hp.noise_sigma_mps[j]) / KN_MPS, float(hp.noise_tau_s[j])
    current_kn = math.sqrt(0.5 * drift**2 + sig_c**2) / KN_MPS
    compass_deg = math.degrees(math.hypot(eps, s_eps))
    scale = math.hypot(s, s_s)
    fix_m = est.reference_sigma_m
    block = (
        "\n".join(
            [
                "[dead_reckoning]",
                "learn = false",
                f'compass_bias_deg = {{ sigma = {compass_deg:.3f}, tau_s = "inf" }}',
                "compass_noise_deg = { sigma = 0.0, tau_s = 120 }",
                "leeway_deg = { sigma = 0.0, tau_s = 1800 }",
                f'log_scale = {{ sigma = {scale:.4f}, tau_s = "inf" }}',
                'log_bias_kn = { sigma = 0.0, tau_s = "inf" }',
                f"log_noise_kn = {{ sigma = {noise_kn:.3f}, tau_s = {noise_tau:g} }}",
                f"current_kn = {{ sigma = {current_kn:.3f}, tau_s = {tau_c:g} }}",
                f"fix_sigma_m = {fix_m:.1f}",
            ]
        )
        + "\n"
    )
    return {
        "current_set_deg": float(math.degrees(wrap_2pi(math.atan2(cbar[1], cbar[0])))),
        "current_drift_kn": drift / KN_MPS,
        "current_variation_kn": sig_c / KN_MPS,
        "current_tau_s": tau_c,
        "noise_kn": noise_kn,
        "noise_tau_s": noise_tau,
        "fix_sigma_m": fix_m,
        "model_weight": float(w[j]),
        "n_models": int(hp.size),
        "filter_step_s": m.step_s,
        "n_fixes_used": int(m.history.updated.sum()),
        "n_outliers": int(m.n_outliers),
        "config_block": block,
    }


def error_prior(
    cfg: DeadReckoningConfig, lat_rad: float, gyro: bool, speed_mps: np.ndarray
) -> ErrorPrior:
    """What the EP assumes before it has learned anything: the configured current as a
    persistent one, the compass bias (gyro: x sec phi, METHODS section 6) with the leeway,
    the log scale with its offset at the median speed."""
    v = float(np.nanmedian(speed_mps)) if np.any(np.isfinite(speed_mps)) else math.nan
    offset_as_scale = cfg.log_bias_kn.sigma * KN_MPS / v if v > 0.5 else 0.0
    return ErrorPrior(
        current_sigma_mps=cfg.current_kn.sigma * KN_MPS,
        heading_sigma_rad=heading_prior_rad(
            cfg.compass_bias_deg.sigma * DEG_RAD, cfg.leeway_deg.sigma * DEG_RAD, lat_rad, gyro
        ),
        scale_sigma=math.hypot(cfg.log_scale.sigma, offset_as_scale),
        fix_sigma_m=cfg.fix_sigma_m,
    )


def fix_innovations(
    est: EstimatedPosition | None, t0_ns: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """(time_ns, NIS, gate_m) of the fixes the estimated position's filter weighed, or None."""
    h = est.model.history if est is not None else None
    if h is None or h.nis is None:
        return None
    assert h.gate_m is not None  # filled with the NIS
    ok = np.isfinite(h.nis)
    return (t0_ns + np.round(h.time_s[ok] * 1e9).astype(np.int64), h.nis[ok], h.gate_m[ok])


def legs_touched(tr: DRTrack, t0_ns: int, spans_s: Sequence[Span]) -> np.ndarray:
    """Per leg of ``tr`` (n_legs,): does it overlap one of ``spans_s`` (Unix s, a jump of
    the reference: :func:`dracc.math.integrity.causes.jump_spans`)?"""
    touched = np.zeros(tr.n_legs, bool)
    if not spans_s:
        return touched
    t_s = t0_ns / 1e9 + tr.time_s
    for k in np.unique(tr.leg[tr.leg >= 0]):
        t = t_s[tr.leg == k]
        touched[k] = overlaps((float(t[0]), float(t[-1])), spans_s)
    return touched


def jump_sentence(source: str, legs: Sequence[LegConsistency], n_legs: int, without: str) -> str:
    """What the DR verdict adds where a jump of its reference touched scored ``legs``:
    the test's verdict without them says whether the jump or the DR's model is the cause."""
    said = f"; the reference {source} jumped in {len(legs)} of {n_legs} scored legs"
    if without in ("consistent", "conservative"):
        return f"{said}: without them the DR is {without}, so the jump is the cause, not its model"
    if without == "undetermined":
        return f"{said}: no leg is left to score without them"
    return f"{said}; without them it is still {without}"
