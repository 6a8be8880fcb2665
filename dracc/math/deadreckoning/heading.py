"""Course made good and speed from the log and the compass (B1-B6), and the true heading.

Speed and leeway from the log's two components (B1, B4-B6), course made good from a
magnetic compass (B2) or a gyro compass (B3), the deviation curve and table, and
:func:`true_heading_rad`: the one rule turning canonical heading columns into a true
heading.  Paper symbols: see the package docstring.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike

from dracc.core.arrays import BoolArray, FloatArray
from dracc.core.config import DeadReckoningConfig
from dracc.core.errors import ConfigError, InsufficientDataError
from dracc.core.geodesy import wrap_2pi
from dracc.core.units import DEG_RAD

__all__ = [
    "TrueHeading",
    "course_gyro_rad",
    "course_magnetic_rad",
    "deviation_curve_rad",
    "deviation_table_rad",
    "interp_deviation_rad",
    "leeway_from_log_rad",
    "speed_from_components_mps",
    "total_leeway_rad",
    "true_heading_rad",
]


def speed_from_components_mps(vx_mps: ArrayLike, vy_mps: ArrayLike) -> FloatArray:
    """V = sqrt(Vx^2 + Vy^2) (B1), from the longitudinal and transverse log components."""
    return np.hypot(vx_mps, vy_mps)  # (B1)


def leeway_from_log_rad(vx_mps: ArrayLike, vy_mps: ArrayLike) -> FloatArray:
    """Angle of the log's velocity from the ship's head, starboard (transverse > 0) positive.

    Through the water it is the drift angle alpha (B5), over the ground the total
    leeway z (B6).  ``arctan2`` replaces the paper's arctg(Vy/Vx) so that sternway
    (Vx < 0) keeps its direction.
    """
    return np.arctan2(vy_mps, vx_mps)  # (B5), (B6)


def total_leeway_rad(drift_rad: ArrayLike, leeway_rad: ArrayLike) -> FloatArray:
    """z = alpha + beta (B4): drift angle plus leeway angle."""
    return np.asarray(drift_rad, np.float64) + np.asarray(leeway_rad, np.float64)  # (B4)


def course_magnetic_rad(
    compass_rad: ArrayLike,
    variation_rad: FloatArray | float,
    deviation_rad: FloatArray | float,
    leeway_rad: FloatArray | float = 0.0,
) -> FloatArray:
    """Course made good from a magnetic compass, KDd = KK + d + delta + z (B2), in [0, 2 pi)."""
    course: FloatArray = wrap_2pi(
        np.asarray(compass_rad, float) + variation_rad + deviation_rad + leeway_rad  # (B2)
    )
    return course


def course_gyro_rad(
    gyro_rad: ArrayLike,
    correction_rad: FloatArray | float = 0.0,
    leeway_rad: FloatArray | float = 0.0,
) -> FloatArray:
    """Course made good from a gyro compass, KDd = KZ + pz + z (B3), in [0, 2 pi)."""
    course: FloatArray = wrap_2pi(np.asarray(gyro_rad, float) + correction_rad + leeway_rad)  # (B3)
    return course


def deviation_curve_rad(heading_rad: ArrayLike, coefficients_rad: Iterable[float]) -> FloatArray:
    """Deviation curve delta(K) = A + B sin K + C cos K + D sin 2K + E cos 2K.

    ``coefficients_rad`` = (A, B, C, D, E) in radians; K the compass heading.
    """
    a, b, c, d, e = (float(x) for x in coefficients_rad)
    k = np.asarray(heading_rad, np.float64)
    return a + b * np.sin(k) + c * np.cos(k) + d * np.sin(2 * k) + e * np.cos(2 * k)


def deviation_table_rad(
    table_deg: Mapping[str, float] | Mapping[float, float],
) -> tuple[FloatArray, FloatArray]:
    """Parse a deviation table {heading_deg: deviation_deg} (config keys are strings).

    Returns (heading_rad, deviation_rad) sorted by heading in [0, 2 pi).  A key that is
    not a number, a heading outside [0, 360] or a duplicate heading raises ConfigError.
    """
    pts: dict[float, float] = {}
    for key, value in table_deg.items():
        try:
            h_deg = float(key)
            dev_deg = float(value)
        except (TypeError, ValueError) as err:
            raise ConfigError(
                f"[dead_reckoning.deviation_table] {key!r} = {value!r}: heading and "
                "deviation must be numbers in degrees"
            ) from err
        if not (0.0 <= h_deg <= 360.0) or not math.isfinite(dev_deg):
            raise ConfigError(
                f"[dead_reckoning.deviation_table] {key!r} = {value!r}: heading must be in "
                "[0, 360] and the deviation finite"
            )
        h = float(wrap_2pi(h_deg * DEG_RAD))
        if h in pts and pts[h] != dev_deg * DEG_RAD:
            raise ConfigError(
                f"[dead_reckoning.deviation_table] heading {key!r} given twice with "
                "different deviations (0 and 360 are the same heading)"
            )
        pts[h] = dev_deg * DEG_RAD
    if not pts:
        raise ConfigError("[dead_reckoning.deviation_table] is empty")
    h_sorted = np.array(sorted(pts))
    return h_sorted, np.array([pts[h] for h in h_sorted])


def interp_deviation_rad(
    heading_rad: ArrayLike,
    table_heading_rad: FloatArray,
    table_deviation_rad: FloatArray,
) -> FloatArray:
    """Deviation at ``heading_rad`` by linear interpolation on the circle (periodic in 2 pi)."""
    return np.interp(
        wrap_2pi(np.asarray(heading_rad, np.float64)),
        table_heading_rad,
        table_deviation_rad,
        period=2 * np.pi,
    )


@dataclass(frozen=True)
class TrueHeading:
    """True heading per sample and where its corrections came from (for the report).

    The four variation counts split the magnetic samples by what the sentence sent and
    what was applied: a non-zero field, a 0.0 field, no field filled from the config, no
    field taken as 0.
    """

    heading_rad: FloatArray  #: (n,) in [0, 2 pi); NaN where the input heading is NaN
    n_magnetic: int  #: samples from a magnetic compass ((B2) applied)
    n_variation_from_sentence: int  #: the sentence's non-zero variation applied
    n_variation_from_config: int  #: no variation sent: ``variation_deg`` applied
    deviation_source: str  #: 'sentence', 'curve', 'table', 'none' (0), or 'mixed'
    #: the sentence sent 0.0 (often a placeholder): ``variation_deg`` applied where set,
    #: else the 0 as sent
    n_variation_placeholder: int = 0
    #: no variation sent and none configured: 0 applied (``missing_variation="zero"``)
    n_variation_missing: int = 0


def _per_sample_or_nan(values_rad: ArrayLike | None, n: int) -> FloatArray:
    """``values_rad`` broadcast to (n,), or NaN everywhere when not given."""
    if values_rad is None:
        return np.full(n, np.nan)
    return np.broadcast_to(np.asarray(values_rad, float), (n,))


def _is_magnetic(reference: str | ArrayLike, n: int) -> BoolArray:
    """True where the heading reference is 'M' (either case), per sample, vectorised.

    Anything else is not magnetic: 'T', None, NaN, pandas' <NA>.  A pandas Categorical
    (or a Series of one) is tested on its few categories, not on every sample.
    """
    if isinstance(reference, str):
        return np.full(n, reference.upper() == "M")
    ref_obj = getattr(reference, "array", reference)  # a pandas Series: its values
    categories = getattr(ref_obj, "categories", None)
    codes = getattr(ref_obj, "codes", None)
    if categories is not None and codes is not None:  # code -1 (missing): the trailing False
        is_m = np.array([str(c).upper() == "M" for c in categories] + [False])
        return np.broadcast_to(is_m[np.asarray(codes)], (n,))
    ref = np.asarray(ref_obj)
    if ref.dtype.kind == "O":  # None, NaN and <NA> become text other than 'M'
        ref = ref.astype(str)
    magnetic: BoolArray = np.broadcast_to((ref == "M") | (ref == "m"), (n,))
    return magnetic


def true_heading_rad(
    heading_rad: ArrayLike,
    reference: str | ArrayLike,
    deviation_rad: ArrayLike | None = None,
    variation_rad: ArrayLike | None = None,
    *,
    errors: DeadReckoningConfig | None = None,
    deviation_coefficients_rad: Iterable[float] | None = None,
    gyro_correction_rad: FloatArray | float = 0.0,
    missing_variation: Literal["raise", "zero"] = "raise",
) -> TrueHeading:
    """True heading from the canonical heading columns, (B2) for magnetic, (B3) for true.

    ``reference`` 'T' (gyro: KZ + pz, B3) or 'M' (magnetic: KK + d + delta, B2), per
    sample or one string.  Deviation delta: the sentence's field where given, else the
    curve A-E (``deviation_coefficients_rad``), else the config's deviation table, else 0
    (the compass error sources then carry it).  Variation d: the sentence's field where
    given and non-zero; where it is absent, or exactly 0.0 (many compasses send a zero
    placeholder, HDG ...,0.0,E), ``[dead_reckoning] variation_deg`` when set; else a 0.0
    field is used as sent.  A magnetic heading with no variation sent and none configured
    raises InsufficientDataError (``missing_variation="raise"``: dracc does not assume
    zero variation) or takes 0 there (``"zero"``: counted in ``n_variation_missing`` for
    the caller to report).  Leeway is added later (dead_reckon's ``transverse_mps``).
    """
    cfg = errors if errors is not None else DeadReckoningConfig()
    h = np.asarray(heading_rad, float)
    n = h.size
    magnetic = _is_magnetic(reference, n) & np.isfinite(h)
    dev_in = _per_sample_or_nan(deviation_rad, n)
    var_in = _per_sample_or_nan(variation_rad, n)
    out = np.asarray(course_gyro_rad(h, gyro_correction_rad), float).copy()  # (B3)
    if not magnetic.any():
        return TrueHeading(out, 0, 0, 0, "none")
    var = var_in.copy()
    absent = magnetic & ~np.isfinite(var_in)
    placeholder = magnetic & (var_in == 0.0)
    from_sentence = magnetic & np.isfinite(var_in) & ~placeholder
    if cfg.variation_deg is not None:
        var[absent | placeholder] = cfg.variation_deg * DEG_RAD
    elif absent.any():
        if missing_variation != "zero":
            raise InsufficientDataError(
                f"{int(absent.sum())} magnetic heading samples have no variation and "
                "[dead_reckoning] variation_deg is not set; give the local variation "
                "(east positive) in the config"
            )
        var[absent] = 0.0
    dev = dev_in.copy()
    sources = {"sentence"} if np.any(magnetic & np.isfinite(dev_in)) else set()
    need = magnetic & ~np.isfinite(dev)
    if need.any():
        if deviation_coefficients_rad is not None:
            dev[need] = deviation_curve_rad(h[need], deviation_coefficients_rad)
            sources.add("curve")
        elif cfg.deviation_table:
            th, td = deviation_table_rad(cfg.deviation_table)
            dev[need] = interp_deviation_rad(h[need], th, td)
            sources.add("table")
        else:
            dev[need] = 0.0
            sources.add("none")
    out[magnetic] = course_magnetic_rad(h[magnetic], var[magnetic], dev[magnetic])  # (B2)
    n_absent = int(absent.sum())
    configured = cfg.variation_deg is not None
    return TrueHeading(
        heading_rad=out,
        n_magnetic=int(magnetic.sum()),
        n_variation_from_sentence=int(from_sentence.sum()),
        n_variation_from_config=n_absent if configured else 0,
        deviation_source=sources.pop() if len(sources) == 1 else "mixed",
        n_variation_placeholder=int(placeholder.sum()),
        n_variation_missing=0 if configured else n_absent,
    )
