"""Is the DR's 2M circle honest?  Containment of a reference, per epoch, per leg and overall.

Epochs of one leg share one sensor-error realisation, so each leg is one trial of the
binomial, chi-square and NEES tests of :func:`dr_consistency`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike

from dracc.core import distributions as dist
from dracc.core.arrays import BoolArray, FloatArray, IntArray
from dracc.core.geodesy import interp_position, offset_ne_m
from dracc.math.deadreckoning.track import DRTrack
from dracc.math.uncertainty import GAUSSIAN, drms_m, inside_circle, predictive_cdf, prob_inside

__all__ = ["Consistency", "LegConsistency", "dr_consistency"]


@dataclass(frozen=True)
class LegConsistency:
    """Containment of the reference in the 2M circle over the epochs of one DR leg."""

    leg: int
    start_s: float
    n_epochs: int
    n_inside: int
    inside_fraction: float
    rms_error_over_m: float  #: sqrt(mean (d/M)^2); 1 when the covariance is right
    max_error_m: float
    mean_nees: float = math.nan  #: mean over the leg's epochs of d^T P^-1 d (2 expected)
    last_nees: float = math.nan  #: at the leg's last epoch: one chi^2_2 draw per leg
    nees_upper: float = math.nan  #: chi^2_2 quantile 1 - alpha: a leg above it misses


@dataclass(frozen=True)
class Consistency:
    """DR against a reference, per epoch (after a fix, not at it), per leg and overall.

    Per epoch: error d (DR minus reference, metres north/east), the drawn 2M, inside
    (d <= 2M), d/M, NEES = d^T P^-1 d (expected 2), the probability that the predictive
    puts the reference inside the drawn 2M (0.954-0.982 for a Gaussian, less for a
    Student-t) and the PIT of d (uniform when the stated probabilities are achieved).
    Verdict: see :func:`dr_consistency`.
    """

    time_s: FloatArray
    leg: IntArray
    error_north_m: FloatArray
    error_east_m: FloatArray
    error_m: FloatArray
    radius_2m_m: FloatArray
    inside: BoolArray
    error_over_m: FloatArray
    nees: FloatArray
    p_inside_expected: FloatArray
    legs: tuple[LegConsistency, ...]
    n_epochs: int
    n_inside: int
    inside_fraction: float
    expected_inside_fraction: float
    rms_error_over_m: float
    mean_nees: float
    n_legs: int  #: legs with at least one epoch: the independent trials of the tests
    p_value_too_small: float  #: binomial P(K <= k) under the lowest expected containment
    chi2_statistic: float  #: mean over legs of the leg's mean (d/M)^2
    chi2_upper: float  #: inconsistent above this
    chi2_lower: float  #: conservative below this (with every epoch inside)
    alpha: float
    verdict: str  #: 'consistent', 'inconsistent (circle too small)', 'conservative', 'undetermined'
    nees_statistic: float = math.nan  #: sum over legs of the last epoch's NEES ~ chi^2(2 n_legs)
    nees_lower: float = math.nan  #: chi^2_{alpha/2}(2 n_legs)
    nees_upper: float = math.nan  #: chi^2_{1-alpha/2}(2 n_legs)
    reference_sigma_m: float = 0.0  #: the reference's own noise, added to P for the test
    #: per epoch: the predictive's probability of an error below d (the PIT)
    pit: FloatArray = field(default_factory=lambda: np.zeros(0))
    #: epochs with the error beyond the predictive's 99 % radius (PIT > 0.99)
    n_beyond_99: int = 0


def _leg_summaries(
    track: DRTrack,
    legs_e: IntArray,
    inside: BoolArray,
    ratio: FloatArray,
    d: FloatArray,
    nees: FloatArray,
    alpha: float,
) -> list[LegConsistency]:
    """One :class:`LegConsistency` per leg with epochs, in leg order."""
    legs: list[LegConsistency] = []
    nees_leg_hi = float(dist.chi2_ppf(1 - alpha, 2))
    for leg_id in np.unique(legs_e):
        sel = legs_e == leg_id
        k = int(inside[sel].sum())
        legs.append(
            LegConsistency(
                leg=int(leg_id),
                start_s=float(track.leg_start_s[leg_id]),
                n_epochs=int(sel.sum()),
                n_inside=k,
                inside_fraction=k / int(sel.sum()),
                rms_error_over_m=float(np.sqrt(np.mean(ratio[sel] ** 2))),
                max_error_m=float(d[sel].max()),
                mean_nees=float(np.mean(nees[sel])),
                last_nees=float(nees[sel][-1]),
                nees_upper=nees_leg_hi,
            )
        )
    return legs


@dataclass(frozen=True)
class _Tests:
    """The per-leg tests' statistics, bounds and verdict."""

    verdict: str
    p_value_too_small: float
    chi2_statistic: float
    chi2_upper: float
    chi2_lower: float
    nees_statistic: float
    nees_lower: float
    nees_upper: float


def _leg_tests(
    legs: Sequence[LegConsistency], p_exp: FloatArray, inside: BoolArray, alpha: float
) -> _Tests:
    """Binomial, chi-square and NEES tests over the legs (see :func:`dr_consistency`)."""
    n_legs = len(legs)
    if n_legs == 0:
        nan = float("nan")
        return _Tests("undetermined", nan, nan, nan, nan, nan, nan, nan)
    nees_sum = float(sum(leg.last_nees for leg in legs))
    nees_lo = float(dist.chi2_ppf(alpha / 2, 2 * n_legs))
    nees_hi = float(dist.chi2_ppf(1 - alpha / 2, 2 * n_legs))
    k_eff = int(round(sum(leg.inside_fraction for leg in legs)))
    p_small = float(dist.binom_cdf(k_eff, n_legs, float(p_exp.min())))
    q = float(np.mean([leg.rms_error_over_m**2 for leg in legs]))
    q_hi = float(dist.chi2_ppf(1 - alpha, n_legs) / n_legs)
    q_lo = float(dist.chi2_ppf(alpha, n_legs) / n_legs)
    if p_small < alpha or q > q_hi or nees_sum > nees_hi:
        verdict = "inconsistent (circle too small)"
    elif bool(inside.all()) and (q < q_lo or nees_sum < nees_lo):
        verdict = "conservative"
    else:
        verdict = "consistent"
    return _Tests(verdict, p_small, q, q_hi, q_lo, nees_sum, nees_lo, nees_hi)


def dr_consistency(
    track: DRTrack,
    ref_time_s: ArrayLike,
    ref_lat_rad: ArrayLike,
    ref_lon_rad: ArrayLike,
    *,
    max_ref_gap_s: float = 5.0,
    alpha: float = 0.01,
    ref_sigma_m: float = 0.0,
    shape: ArrayLike = GAUSSIAN,
) -> Consistency:
    """Does the reference (GNSS, INS mean) lie inside the DR's 2M circle as often as it should?

    Epochs are the track's ``epoch_index`` where time since the fix is > 0 (at the fix
    the DR *is* the fix); the reference is interpolated linearly between samples at most
    ``max_ref_gap_s`` apart.

    The binomial reasoning.  For a correct Gaussian error, 2M (2 drms) contains it with
    probability p between 0.954 (degenerate ellipse) and 0.982 (circle); a learned model
    predicts a Student-t of ``shape`` (per track sample, dracc.math.uncertainty), less.  Epochs of one leg share the same sensor-error realisation
    and are strongly correlated, so each leg (not each epoch) is one trial: n = number of
    legs with epochs, k = round(sum of the legs' inside fractions).  The DR is
    "inconsistent (circle too small)" when P(K <= k | n, p_min) < alpha (one-sided
    binomial, p_min the lowest expected containment over the epochs), or when the mean
    over legs of mean (d/M)^2 -- expected 1, as E|d|^2 = tr P = M^2 -- exceeds
    chi2_{1-alpha}(n)/n (the widest case, a line-shaped ellipse: (d/M)^2 ~ chi2_1), or when
    the sum over legs of the NEES at each leg's last epoch (chi^2 with 2 n degrees of
    freedom) exceeds its two-sided 1 - alpha/2 quantile.
    It is "conservative" when every epoch is inside and that mean, or the NEES sum, is
    below its lower quantile (the circle much larger than the errors).  ``ref_sigma_m``:
    the reference's own noise per axis, added to P in the statistics and the stated
    probability; "inside" is against the drawn 2M of P itself, the circle a user sees.
    Otherwise "consistent"; "undetermined" when no epoch has a reference.
    """
    ei = np.asarray(track.epoch_index, dtype=np.int64)
    ei = ei[track.since_fix_s[ei] > 0]
    t_e = track.time_s[ei]
    rlat, rlon = interp_position(
        np.asarray(ref_time_s, float), ref_lat_rad, ref_lon_rad, t_e, max_ref_gap_s
    )
    has = np.isfinite(rlat)
    ei, t_e, rlat, rlon = ei[has], t_e[has], rlat[has], rlon[has]
    dn, de = offset_ne_m(track.lat_rad[ei], track.lon_rad[ei], rlat, rlon)
    d = np.hypot(dn, de)
    radius = track.radius_2m_m[ei]  # the drawn circle
    inside = inside_circle(d, radius)
    P = track.P_m2[ei] + float(ref_sigma_m) ** 2 * np.eye(2)
    ratio = d / drms_m(P)
    det = P[:, 0, 0] * P[:, 1, 1] - P[:, 0, 1] ** 2
    with np.errstate(divide="ignore", invalid="ignore"):
        nees = (P[:, 1, 1] * dn**2 - 2 * P[:, 0, 1] * dn * de + P[:, 0, 0] * de**2) / det
    shape_e = np.broadcast_to(np.asarray(shape, float), track.time_s.shape)[ei]
    p_exp = prob_inside(P, radius, shape_e) if ei.size else np.zeros(0)
    pit = predictive_cdf(P, d, shape_e) if ei.size else np.zeros(0)
    legs_e = track.leg[ei]

    legs = _leg_summaries(track, legs_e, inside, ratio, d, nees, alpha)
    tests = _leg_tests(legs, p_exp, inside, alpha)
    n_ep = int(ei.size)
    return Consistency(
        time_s=t_e,
        leg=legs_e,
        error_north_m=dn,
        error_east_m=de,
        error_m=d,
        radius_2m_m=radius,
        inside=inside,
        error_over_m=ratio,
        nees=nees,
        p_inside_expected=p_exp,
        legs=tuple(legs),
        n_epochs=n_ep,
        n_inside=int(inside.sum()),
        inside_fraction=float(inside.mean()) if n_ep else float("nan"),
        expected_inside_fraction=float(p_exp.mean()) if n_ep else float("nan"),
        rms_error_over_m=float(np.sqrt(np.mean(ratio**2))) if n_ep else float("nan"),
        mean_nees=float(np.mean(nees)) if n_ep else float("nan"),
        n_legs=len(legs),
        p_value_too_small=tests.p_value_too_small,
        chi2_statistic=tests.chi2_statistic,
        chi2_upper=tests.chi2_upper,
        chi2_lower=tests.chi2_lower,
        alpha=alpha,
        verdict=tests.verdict,
        nees_statistic=tests.nees_statistic,
        nees_lower=tests.nees_lower,
        nees_upper=tests.nees_upper,
        reference_sigma_m=float(ref_sigma_m),
        pit=pit,
        n_beyond_99=int(np.sum(pit > 0.99)),
    )
