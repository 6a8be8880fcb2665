"""The result of a dead reckoning: :class:`DRTrack`, and the data :class:`Gap` it reports."""

from __future__ import annotations

from dataclasses import dataclass

from dracc.core.arrays import FloatArray, IntArray

__all__ = ["DRTrack", "Gap"]


@dataclass(frozen=True)
class Gap:
    """An interval between two valid samples of one channel longer than twice its usual spacing."""

    start_s: float  #: time of the last valid sample before the gap
    end_s: float  #: time of the next valid sample (inf: none before the end of the data)
    bridged: bool  #: True: held over (<= max_gap_s); False: the track breaks here
    channel: str = "heading"  #: 'heading' or 'speed' (the log, both components)

    @property
    def duration_s(self) -> float:
        return self.end_s - self.start_s


@dataclass(frozen=True)
class DRTrack:
    """A dead-reckoned track with its honest covariance, per sample.

    Positions are NaN where no leg runs (before the first start, after a break until the
    next fix).  ``P_m2`` is north/east in m^2; ``radius_2m_m`` = 2 sqrt(tr P) (B30, B31);
    the ellipse is 1 sigma.  ``leg`` is -1 where no leg runs.
    """

    time_s: FloatArray
    lat_rad: FloatArray
    lon_rad: FloatArray
    vn_mps: FloatArray
    ve_mps: FloatArray
    P_m2: FloatArray
    radius_2m_m: FloatArray
    semi_major_m: FloatArray
    semi_minor_m: FloatArray
    orientation_rad: FloatArray
    since_fix_s: FloatArray
    leg: IntArray
    leg_start_s: FloatArray  #: (n_legs,) start time of each leg
    leg_start_reason: tuple[str, ...]  #: 'start', 'reset', 'after-gap'
    epoch_index: IntArray  #: indices of the reported epochs (every epoch_interval_s)
    gaps: tuple[Gap, ...]
    mode: str
    reset_s: float
    n_invalid_samples: int  #: samples without heading or speed (bridged or in breaks)

    @property
    def n_legs(self) -> int:
        return int(self.leg_start_s.size)

    @property
    def n_breaks(self) -> int:
        return sum(not g.bridged for g in self.gaps)
