"""INS accuracy from deviations from the mean of three (METHODS section 4; paper seeds/001).

- :mod:`.sampling`  readings of each unit at the sampling instants (interpolated, never filled)
- :mod:`.stats`     (K1)-(K8): deviations, m_u, m_y, excess kurtosis, covariance, limiting errors
- :mod:`.hat`       the three-cornered hat (each unit's own variance), bootstrap bounds
- :mod:`.reference` the paper's Table 1 check against a reference, and its marks
- :mod:`.channels`  each channel's mode and factor, and its (K3b)-(K8) in one window
- :mod:`.results`   the result types (``to_dict`` gives the report's ``deviation`` section)
- :mod:`.validation` :func:`check_config`, the ``[deviation]`` values the method can use
- :mod:`.analysis`  :func:`analyse_deviations`, the single entry point

Pure numpy/scipy; no I/O.
"""

from __future__ import annotations

from dracc.core.vocabulary import CHANNELS
from dracc.math.deviation.analysis import analyse_deviations
from dracc.math.deviation.hat import HatEstimate, three_cornered_hat
from dracc.math.deviation.results import (
    ChannelMode,
    ChannelStats,
    DeviationResult,
    HatStats,
    KurtosisWindow,
    ReferenceAverage,
    ReferenceStats,
    UnitStats,
    WindowStats,
)
from dracc.math.deviation.sampling import (
    UnitSeries,
    sample_unit,
    sampling_instants,
    unit_series_from_frames,
    unit_series_from_voyage,
)
from dracc.math.deviation.validation import check_config

__all__ = [
    "CHANNELS",
    "ChannelMode",
    "ChannelStats",
    "DeviationResult",
    "HatEstimate",
    "HatStats",
    "KurtosisWindow",
    "ReferenceAverage",
    "ReferenceStats",
    "UnitSeries",
    "UnitStats",
    "WindowStats",
    "analyse_deviations",
    "check_config",
    "sample_unit",
    "sampling_instants",
    "three_cornered_hat",
    "unit_series_from_frames",
    "unit_series_from_voyage",
]
