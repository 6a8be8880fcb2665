"""The report's plots, drawn with matplotlib (Agg) and returned as PNG bytes.

Each function takes a part of an :class:`~dracc.pipeline.results.Analysis` and draws it;
nothing is estimated here.  The only arithmetic is the plotting projection: positions
are shown as kilometres north/east of the first DR fix (or the first position), where
the 2M circles are true circles (local tangent plane, :func:`dracc.core.geodesy.offset_ne_m`).
"""

from __future__ import annotations

import io

import matplotlib

matplotlib.use("Agg")
import matplotlib.dates as mdates  # noqa: E402
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.axes import Axes  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402
from matplotlib.typing import LegendLocType  # noqa: E402
from mpl_toolkits.axes_grid1.anchored_artists import AnchoredSizeBar  # noqa: E402

from dracc.core.arrays import ArrayLike, FloatArray  # noqa: E402
from dracc.core.vocabulary import (
    CHANNEL_KEYS,
    CHANNEL_UNITS,
    CHANNELS,
    DR_OVER_GROUND,
    WATER_TRACK,
)
from dracc.pipeline.results import Analysis

_DPI = 96
#: lines are drawn through at most this many points (every k-th sample); circles and
#: markers are not thinned
_MAX_LINE_POINTS = 20000


def _stride(n: int) -> int:
    return max(1, -(-n // _MAX_LINE_POINTS))


_UNIT_COLOURS = {"ins1": "#1f77b4", "ins2": "#d62728", "ins3": "#2ca02c"}
_ROLE_COLOURS = {"gnss": "#555555", "ins1": "#1f77b4", "ins2": "#d62728", "ins3": "#2ca02c"}


def png_bytes(fig: Figure, dpi: int = _DPI) -> bytes:
    """The figure as PNG bytes (no software tag, so the bytes are reproducible); closes it."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi, bbox_inches="tight", metadata={"Software": None})
    plt.close(fig)
    return buf.getvalue()


_NM_KM = 1.852


def metres_text(km: float) -> str:
    """'850 m' under 10 km, else '12.3 km'."""
    return f"{km * 1e3:.0f} m" if km < 10 else f"{km:.1f} km"


def px_per_km(ax: Axes) -> float:
    """Pixels per km on the x axis of ``ax`` (its aspect applied)."""
    ax.apply_aspect()
    (x0, _), (x1, _) = ax.transData.transform([(0.0, 0.0), (1.0, 0.0)])
    return float(abs(x1 - x0))


def scale_bar(ax: Axes) -> None:
    """A nautical-mile scale bar about a fifth of the map wide."""
    width_km = abs(np.subtract(*ax.get_xlim()))
    nm = width_km / _NM_KM / 5.0
    nice = max(
        (v for v in (0.05, 0.1, 0.2, 0.5, 1, 2, 5, 10, 20, 50, 100) if v <= nm), default=0.05
    )
    ax.add_artist(
        AnchoredSizeBar(
            ax.transData,
            nice * _NM_KM,
            f"{nice:g} NM",
            "lower left",
            pad=0.5,
            frameon=True,
            size_vertical=0,
            fontproperties={"size": 8},
        )
    )


def _finish(
    fig: Figure, ax: Axes, xlabel: str, ylabel: str, title: str, legend_loc: LegendLocType
) -> bytes:
    """Axis labels, grid, legend and title in the report's style, then the PNG."""
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.grid(True, alpha=0.3)
    ax.legend(loc=legend_loc, fontsize=8)
    ax.set_title(title)
    return png_bytes(fig)


def _utc_axis(fig: Figure, ax: Axes) -> None:
    """A shared UTC date axis ('day hh:mm') at the bottom of ``fig``."""
    ax.xaxis.set_major_formatter(mdates.DateFormatter("%d %H:%M"))
    ax.set_xlabel("UTC")
    fig.autofmt_xdate()


def _dt(time_ns: ArrayLike) -> np.ndarray:
    """int64 ns -> numpy datetime64 for matplotlib's date axis."""
    return np.asarray(time_ns, dtype="int64").astype("datetime64[ns]")


def _origin(a: Analysis) -> tuple[float, float] | None:
    dr = a.dead_reckoning
    if dr is not None and len(dr.track.time_ns):
        return float(dr.track.lat_rad[0]), float(dr.track.lon_rad[0])
    for t in a.tracks:
        if len(t.time_ns):
            return float(t.lat_rad[0]), float(t.lon_rad[0])
    return None


#: legend labels of the track plot (tests find the lines by them): the DR over the ground
#: (learned), the water track as the DR (learn = false) and beside the learned DR
EP_LABEL = DR_OVER_GROUND
DR_LABEL = WATER_TRACK
WATER_LABEL = f"{WATER_TRACK} (heading and log only)"


def _by_leg(n_m: FloatArray, e_m: FloatArray, leg: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """km east and north, thinned for the line, with a break (NaN) at each restart so no
    line joins two legs."""
    k = _stride(len(n_m))
    ns, es, legs = n_m[::k], e_m[::k], leg[::k]
    jumps = np.flatnonzero(np.diff(legs) != 0) + 1
    return np.insert(es / 1e3, jumps, np.nan), np.insert(ns / 1e3, jumps, np.nan)


def deviation_plot(a: Analysis) -> bytes | None:
    """Deviations from the mean per unit and channel at each instant (the paper's Figure 1)."""
    d = a.deviation
    if d is None or not len(d.time_ns):
        return None
    fig, axes = plt.subplots(3, 1, figsize=(10, 8), sharex=True)
    when = _dt(d.time_ns)
    for ax, ch in zip(axes, CHANNELS, strict=True):
        for unit in d.units:
            y = d.samples[unit].get(ch)
            if y is None:
                continue
            ax.plot(when, y, marker="o", ms=3, lw=1.0, color=_UNIT_COLOURS.get(unit), label=unit)
        ax.axhline(0.0, color="black", lw=0.6)
        ax.set_ylabel(f"{CHANNEL_KEYS[ch]} [{CHANNEL_UNITS[ch]}]")
        ax.grid(True, alpha=0.3)
    axes[0].legend(loc="upper right", fontsize=8, ncol=3)
    axes[0].set_title(
        f"Deviations from the mean of {len(d.units)} units, every {d.interval_s / 3600:g} h"
    )
    _utc_axis(fig, axes[-1])
    return png_bytes(fig)


def growth_plot(a: Analysis) -> bytes | None:
    """2M since the last fix against the actual DR error (where a reference exists)."""
    dr = a.dead_reckoning
    if dr is None or not len(dr.track.time_ns):
        return None
    tr = dr.track
    fig, ax = plt.subplots(figsize=(9, 4.5))
    k = _stride(len(tr.time_ns))
    hours = tr.since_fix_s[::k] / 3600.0
    jumps = np.flatnonzero(np.diff(tr.leg[::k]) != 0) + 1

    def by_leg(
        y: ArrayLike,
    ) -> np.ndarray:  # a break (NaN) at each restart, so no line joins two legs
        return np.insert(y, jumps, np.nan)

    ax.plot(
        by_leg(hours), by_leg(tr.radius_2m_m[::k]), color="#ff7f0e", lw=1.2, label="2M (2 drms)"
    )
    if np.isfinite(tr.ref_error_m).any():
        ax.plot(
            by_leg(hours),
            by_leg(tr.ref_error_m[::k]),
            color="black",
            lw=0.8,
            label=f"actual error vs {dr.reference_role}",
        )
    return _finish(
        fig,
        ax,
        "time since the last fix [h]",
        "metres",
        "Growth of 2M since the fix against the actual DR error",
        "upper left",
    )


def current_plot(a: Analysis) -> bytes | None:
    """Drift (with 1-sigma band) and set of the estimated current over time."""
    c = a.current
    if c is None or not len(c.time_ns):
        return None
    when = _dt(c.time_ns)
    fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(9, 5), sharex=True)
    drift_kn = c.drift_mps / (1852.0 / 3600.0)
    sig_kn = c.drift_sigma_mps / (1852.0 / 3600.0)
    ax1.plot(when, drift_kn, color="#1f77b4", lw=1.2, label="drift")
    ax1.fill_between(
        when, drift_kn - sig_kn, drift_kn + sig_kn, color="#1f77b4", alpha=0.2, label="± 1σ"
    )
    ax1.set_ylabel("drift [kn]")
    ax1.grid(True, alpha=0.3)
    ax1.legend(loc="upper right", fontsize=8)
    ax2.plot(when, np.degrees(c.set_rad), ".", ms=2, color="#d62728")
    ax2.set_ylim(0, 360)
    ax2.set_yticks([0, 90, 180, 270, 360])
    ax2.set_ylabel("set (towards) [°]")
    ax2.grid(True, alpha=0.3)
    ax1.set_title("Estimated current")
    _utc_axis(fig, ax2)
    return png_bytes(fig)


def honesty_plot(a: Analysis) -> bytes | None:
    """Is the stated probability achieved?  Left, a Stanford diagram of the scored epochs:
    the error against the reference over the 2M drawn (above the diagonal: inside; below:
    misleading).  Right, the PIT histogram: flat when the stated probabilities are the
    achieved ones, heavy on the right when the circles are too small, on the left when
    too large.  Nothing is computed here: every value is the analysis's."""
    dr = a.dead_reckoning
    if dr is None or dr.honesty is None or not dr.honesty.n_scored:
        return None
    ep = dr.epochs
    judged = np.isfinite(ep.inside)
    err, r2m, inside = ep.ref_error_m[judged], ep.radius_2m_m[judged], ep.inside[judged] == 1.0
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(10, 4.5))
    top = float(np.nanmax(np.concatenate([err, r2m]))) * 1.1
    ax.plot([0, top], [0, top], color="grey", lw=0.8)
    ax.scatter(err[inside], r2m[inside], s=10, color="#1f77b4", label="inside 2M")
    ax.scatter(
        err[~inside],
        r2m[~inside],
        s=18,
        marker="x",
        color="#d62728",
        label=f"misleading: {dr.honesty.n_misleading} of {dr.honesty.n_scored}",
    )
    ax.set_xlim(0, top)
    ax.set_ylim(0, top)
    ax.set_xlabel(f"error against {dr.reference_role} [m]")
    ax.set_ylabel("2M drawn [m]")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="upper left", fontsize=8)
    ax.set_title("Stanford diagram of the scored epochs")
    counts = np.asarray(dr.honesty.pit_counts, float)
    edges = np.linspace(0.0, 1.0, counts.size + 1)
    bx.bar(edges[:-1], counts, width=np.diff(edges), align="edge", color="#9ecae1", ec="white")
    bx.axhline(counts.sum() / counts.size, color="black", lw=1.0, label="honest (flat)")
    return _finish(
        fig,
        bx,
        "P(error below the one observed), as stated",
        "epochs",
        "PIT histogram",
        "upper left",
    )
