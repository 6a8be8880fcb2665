"""Track plots that show where the dead reckoning left its circle: an overview of the
voyage, one panel per leg (the worst legs when there are many) and the fix-updated EP's.

Every panel is north up with an equal metric aspect (kilometres north/east of the first
DR fix, the local tangent plane of :func:`dracc.core.geodesy.offset_ne_m`, where the 2M
circles are true circles), with a latitude/longitude graticule in degrees and minutes
and a scale bar.  The reference track is drawn above the DR in a contrasting colour; at
each DR epoch of a leg panel the 2M circle (B31) and the 95 % error ellipse (the 1-sigma
semi-axes of :class:`~dracc.pipeline.results.DRTrackResult` times sqrt(chi2_2(0.95))) are
drawn; the scored epochs where the reference lay outside 2M are marked with a red cross
at the reference position.  The scale of a leg panel is chosen from the page width
(the report's ``max-width``); circles smaller than :data:`MIN_CIRCLE_PX` there are drawn
as dots and counted in the caption.

Nothing is estimated: "outside" is the analysis's one judgement
(``DRTrackResult.inside``: the reference beyond the drawn 2M at a scored epoch).
"""

from __future__ import annotations

import html
import math
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.patches import Circle, Ellipse, Rectangle

from dracc.core.geodesy import add_offset_ne, circmean, interp_position, offset_ne_m, wrap_pi
from dracc.core.vocabulary import FIX_UPDATED_EP, as_heading, dr_name
from dracc.pipeline.results import Analysis, DRSection
from dracc.report.ep_exports import stretch_starts
from dracc.report.page import data_uri
from dracc.report.plots import (
    _DPI,
    _ROLE_COLOURS,
    DR_LABEL,
    EP_LABEL,
    WATER_LABEL,
    _by_leg,
    _origin,
    metres_text,
    png_bytes,
    px_per_km,
    scale_bar,
)

__all__ = [
    "AIDED_LABEL",
    "CIRCLE_LABEL",
    "ELLIPSE_LABEL",
    "GRATICULE_GID",
    "MAX_LEG_PANELS",
    "MIN_CIRCLE_PX",
    "MISS_LABEL",
    "DrawnPanel",
    "Panel",
    "aided_ep_html",
    "aided_ep_panel",
    "draw_track_panels",
    "figures_html",
    "track_panels",
]

#: a 2M circle is drawn where its radius is at least this many pixels at the embedded size
MIN_CIRCLE_PX = 6.0
#: at most this many leg panels (the worst legs when the voyage has more)
MAX_LEG_PANELS = 8
#: the width of a panel's map in inches at _DPI (96): 864 px, under the report's 1100 px
_MAP_W_IN = 9.0
_MAP_H_MIN_IN, _MAP_H_MAX_IN = 3.5, 8.0
#: the error ellipse's scale: sqrt(chi2_2(0.95)) = sqrt(-2 ln 0.05)
_ELLIPSE_K = math.sqrt(-2.0 * math.log(0.05))
#: epoch insets of a leg panel (for circles too small on the leg's map): at most
#: _MAX_INSETS, _INSETS_PER_ROW to a row, each _INSET_IN square
_MAX_INSETS, _INSETS_PER_ROW, _INSET_IN, _INSET_ROW_IN = 10, 5, 1.5, 2.0

DR_COLOUR, REF_COLOUR, CIRCLE_COLOUR, ELLIPSE_COLOUR, MISS_COLOUR = (
    "black",
    "#d400d4",  # magenta: apart from the DR (black), the circles (orange) and the INS colours
    "#ff7f0e",
    "#1f5fbf",
    "#e00000",
)
#: z-order, bottom up: graticule, other sources, circles and ellipses, DR, reference, misses
Z_GRID, Z_OTHER, Z_CIRCLE, Z_DR, Z_REF, Z_MISS = 0.5, 1.0, 2.0, 3.0, 4.0, 5.0
CIRCLE_LABEL = "2M circle at each DR epoch"
ELLIPSE_LABEL = "95 % error ellipse"
MISS_LABEL = "reference outside 2M"
GRATICULE_GID = "graticule"
#: minutes of arc between graticule lines, tried in order
_STEPS_MIN = (0.05, 0.1, 0.2, 0.5, 1.0, 2.0, 5.0, 10.0, 15.0, 20.0, 30.0, 60.0, 120.0, 300.0)


@dataclass(frozen=True)
class Panel:
    """One rendered track panel."""

    png: bytes
    alt: str
    caption: str
    #: the smallest 2M circle drawn, radius in pixels of the PNG (NaN: none drawn)
    min_circle_px: float
    leg: int | None  #: the DR leg shown; None for the overview
    n_misses: int  #: scored epochs with the reference outside 2M marked in the panel


@dataclass(frozen=True)
class DrawnPanel:
    """A panel still as a matplotlib figure (for tests); :func:`track_panels` renders it."""

    fig: Figure
    ax: Axes
    alt: str
    caption: str
    min_circle_px: float
    leg: int | None
    n_misses: int


# ------------------------------------------------------------------ what is plotted

#: reference positions: (time_ns, lat_rad, lon_rad)
_Ref = tuple[np.ndarray, np.ndarray, np.ndarray]


@dataclass(frozen=True)
class _Epochs:
    """The DR epochs in plot coordinates (km), with the reference and the scoring."""

    time_ns: np.ndarray
    x: np.ndarray
    y: np.ndarray
    ref_x: np.ndarray  #: the reference at the epoch (NaN where none)
    ref_y: np.ndarray
    leg: np.ndarray
    radius_km: np.ndarray
    semi_major_km: np.ndarray
    semi_minor_km: np.ndarray
    angle_deg: np.ndarray  #: matplotlib's angle of the major axis (counter-clockwise from east)
    shown: np.ndarray  #: after the fix (at the fix the DR is the fix)
    scored: np.ndarray
    outside: np.ndarray
    error_over_m: np.ndarray
    error_km: np.ndarray  #: the analysis's DR error against the reference (NaN where none)
    ref_on_track: bool  #: ref_x/ref_y from the reference track (else the DR epoch itself)


def _reference(a: Analysis) -> _Ref | None:
    """The reference positions (time_ns, lat, lon) from the plotted tracks: the track of
    the reference role, or the mean of the INS units for 'ins_mean'."""
    dr = a.dead_reckoning
    role = dr.reference_role if dr is not None else None
    if role is None:
        return None
    for t in a.tracks:
        if t.role == role and len(t.time_ns):
            return t.time_ns, t.lat_rad, t.lon_rad
    ins = [t for t in a.tracks if (t.role or "").startswith("ins") and len(t.time_ns)]
    if role != "ins_mean" or not ins:
        return None
    times = ins[0].time_ns
    got = [interp_position(t.time_ns, t.lat_rad, t.lon_rad, times, 600e9) for t in ins]
    lat = np.nanmean(np.vstack([g[0] for g in got]), axis=0)
    lon = wrap_pi(circmean(np.vstack([g[1] for g in got]), axis=0))
    ok = np.isfinite(lat) & np.isfinite(lon)
    return times[ok], lat[ok], lon[ok]


def _epochs(dr: DRSection, ref: _Ref | None, lat0: float, lon0: float) -> _Epochs:
    ep = dr.epochs
    n, e = offset_ne_m(ep.lat_rad, ep.lon_rad, lat0, lon0)
    if ref is not None:
        rlat, rlon = interp_position(ref[0], ref[1], ref[2], ep.time_ns, 600e9)
        rn, re_ = offset_ne_m(rlat, rlon, lat0, lon0)
    else:  # no reference track to show: the cross goes on the DR epoch
        rn, re_ = n, e
    shown = (ep.since_fix_s > 0) & np.isfinite(ep.radius_2m_m) & np.isfinite(n)
    scored = shown & np.isfinite(ep.inside)
    with np.errstate(invalid="ignore", divide="ignore"):
        ratio = np.where(scored, 2.0 * ep.ref_error_m / ep.radius_2m_m, np.nan)
    return _Epochs(
        time_ns=np.asarray(ep.time_ns),
        x=e / 1e3,
        y=n / 1e3,
        ref_x=np.asarray(re_) / 1e3,
        ref_y=np.asarray(rn) / 1e3,
        leg=np.asarray(ep.leg),
        radius_km=ep.radius_2m_m / 1e3,
        semi_major_km=_ELLIPSE_K * ep.semi_major_m / 1e3,
        semi_minor_km=_ELLIPSE_K * ep.semi_minor_m / 1e3,
        angle_deg=90.0 - np.degrees(ep.orientation_rad),
        shown=shown,
        scored=scored,
        outside=scored & (ep.inside == 0.0),
        error_over_m=ratio,
        error_km=ep.ref_error_m / 1e3,
        ref_on_track=ref is not None,
    )


def _legs_to_show(ep: _Epochs) -> tuple[list[int], int]:
    """(legs with a DR epoch after the fix, in time order, at most MAX_LEG_PANELS: the
    most misses first, then the largest error/M), and how many legs had epochs."""
    legs = [int(k) for k in np.unique(ep.leg[ep.shown])]
    if len(legs) <= MAX_LEG_PANELS:
        return legs, len(legs)

    def worst(k: int) -> tuple[int, float]:
        sel = ep.leg == k
        r = ep.error_over_m[sel & ep.scored]
        return int(ep.outside[sel].sum()), float(np.max(r)) if r.size else -math.inf

    ranked = sorted(legs, key=lambda k: (worst(k)[0], worst(k)[1]), reverse=True)
    return sorted(ranked[:MAX_LEG_PANELS]), len(legs)


# ---------------------------------------------------------------------- drawing aids


def _limits(
    xs: list[np.ndarray], ys: list[np.ndarray], pad: float = 0.06
) -> tuple[tuple[float, float], tuple[float, float], float]:
    """(xlim, ylim, map height in inches) holding every finite point of ``xs``/``ys`` (km)
    at one scale on both axes, _MAP_W_IN wide (the height follows the extent, within
    limits; the scale is _MAP_W_IN * _DPI / width px per km)."""
    x = np.concatenate([np.ravel(v) for v in xs])
    y = np.concatenate([np.ravel(v) for v in ys])
    ok = np.isfinite(x) & np.isfinite(y)
    x0, x1 = (float(x[ok].min()), float(x[ok].max())) if ok.any() else (-1.0, 1.0)
    y0, y1 = (float(y[ok].min()), float(y[ok].max())) if ok.any() else (-1.0, 1.0)
    dx, dy = max(x1 - x0, 0.05), max(y1 - y0, 0.05)
    dx, dy = dx * (1 + 2 * pad), dy * (1 + 2 * pad)
    h_in = min(max(_MAP_W_IN * dy / dx, _MAP_H_MIN_IN), _MAP_H_MAX_IN)
    if dy / dx > h_in / _MAP_W_IN:  # too tall: widen
        dx = dy * _MAP_W_IN / h_in
    else:
        dy = dx * h_in / _MAP_W_IN
    cx, cy = 0.5 * (x0 + x1), 0.5 * (y0 + y1)
    return (cx - dx / 2, cx + dx / 2), (cy - dy / 2, cy + dy / 2), h_in


def _frame(
    xs: list[np.ndarray], ys: list[np.ndarray], pad: float = 0.06, inset_rows: int = 0
) -> Figure:
    """A figure with the map axes of :func:`_limits` on top and room for ``inset_rows``
    rows of epoch insets below it."""
    xlim, ylim, h_in = _limits(xs, ys, pad)
    fig_w, fig_h = _MAP_W_IN + 1.4, h_in + 1.0 + inset_rows * _INSET_ROW_IN
    fig = Figure(figsize=(fig_w, fig_h), dpi=_DPI)
    bottom = 0.6 + inset_rows * _INSET_ROW_IN
    ax = fig.add_axes((0.9 / fig_w, bottom / fig_h, _MAP_W_IN / fig_w, h_in / fig_h))
    ax.set_xlim(*xlim)
    ax.set_ylim(*ylim)
    ax.set_aspect("equal", adjustable="box")
    return fig


def _insets(
    fig: Figure, ep: _Epochs, idx: np.ndarray, dr_xy: np.ndarray, ref_xy: np.ndarray
) -> None:
    """One small north-up map per epoch ``idx`` (below the leg's map), centred on the DR
    and scaled to its 2M circle: the circle, the ellipse, the DR and the reference there."""
    fig_w, fig_h = fig.get_size_inches()
    for j, i in enumerate(idx):
        row, col = divmod(j, _INSETS_PER_ROW)
        left = 0.9 + col * _MAP_W_IN / _INSETS_PER_ROW
        bottom = 0.35 + (math.ceil(len(idx) / _INSETS_PER_ROW) - 1 - row) * _INSET_ROW_IN
        ax = fig.add_axes((left / fig_w, bottom / fig_h, _INSET_IN / fig_w, _INSET_IN / fig_h))
        cx, cy, r = float(ep.x[i]), float(ep.y[i]), float(ep.radius_km[i])
        d = float(np.hypot(ep.ref_x[i] - cx, ep.ref_y[i] - cy)) if ep.ref_on_track else math.nan
        # half-width: the circle and the reference in view, but the circle never under
        # 3 x MIN_CIRCLE_PX (a reference further off is drawn at the edge, its distance given)
        half = min(
            1.25 * max(r, d if np.isfinite(d) else 0.0, float(ep.semi_major_km[i])),
            r * _INSET_IN * _DPI / 2 / (3 * MIN_CIRCLE_PX),
        )
        ax.set_xlim(cx - half, cx + half)
        ax.set_ylim(cy - half, cy + half)
        ax.set_aspect("equal", adjustable="box")
        ax.set_xticks([])
        ax.set_yticks([])
        ax.plot(dr_xy[:, 0], dr_xy[:, 1], lw=1.2, color=DR_COLOUR, zorder=Z_DR)
        ax.plot(ref_xy[:, 0], ref_xy[:, 1], lw=1.1, color=REF_COLOUR, zorder=Z_REF)
        ax.add_patch(Circle((cx, cy), r, fill=False, color=CIRCLE_COLOUR, lw=1.2, zorder=Z_CIRCLE))
        ax.add_patch(_ellipse(ep, i, (cx, cy)))
        ax.plot([cx], [cy], "+", ms=7, color=DR_COLOUR, zorder=Z_DR)
        title = f"{_utc(int(ep.time_ns[i]))[3:]}  2M {metres_text(r)}"
        if np.isfinite(d):
            far = d > 0.95 * half
            k = 0.95 * half / d if far else 1.0
            px, py = cx + (ep.ref_x[i] - cx) * k, cy + (ep.ref_y[i] - cy) * k
            if ep.outside[i]:
                ax.plot(
                    [px],
                    [py],
                    "x",
                    ms=8,
                    mew=2.0,
                    color=MISS_COLOUR,
                    zorder=Z_MISS,
                    label="_miss_inset",
                )
            else:
                ax.plot([px], [py], "o", ms=4, color=REF_COLOUR, zorder=Z_MISS)
            title += " (ref beyond edge)" if far else ""
        if np.isfinite(ep.error_km[i]):
            title += f"\nerror {metres_text(float(ep.error_km[i]))}"
        ax.set_title(title, fontsize=7)


def _step(span_min: float) -> float:
    for s in _STEPS_MIN:
        if span_min / s <= 7:
            return s
    return _STEPS_MIN[-1]


def _dm(deg: float, pos: str, neg: str, width: int, step_min: float) -> str:
    """54.6083 -> 54°36.5′N (decimals of the minutes as the step needs)."""
    hemi = pos if deg >= 0 else neg
    dec = 0 if step_min >= 1 else (1 if step_min >= 0.1 else 2)
    total = round(abs(deg) * 60.0, dec)
    d, m = divmod(total, 60.0)
    return f"{int(d):0{width}d}°{m:0{3 + dec if dec else 2}.{dec}f}′{hemi}"


def _graticule(ax: Axes, lat0: float, lon0: float) -> None:
    """Parallels and meridians every whole step of minutes, labelled on the axes; the
    meridians are the true (slightly converging) lines of the plotting projection."""
    (x0, x1), (y0, y1) = ax.get_xlim(), ax.get_ylim()
    cn = np.array([y0, y0, y1, y1]) * 1e3
    ce = np.array([x0, x1, x0, x1]) * 1e3
    la, lo = add_offset_ne(np.full(4, lat0), np.full(4, lon0), cn, ce)
    lat_lo, lat_hi = np.degrees(la.min()), np.degrees(la.max())
    lon_c = np.degrees(lon0) + np.degrees(wrap_pi(lo - lon0))
    lon_lo, lon_hi = lon_c.min(), lon_c.max()
    style = {"color": "#9a9a9a", "lw": 0.6, "alpha": 0.8, "zorder": Z_GRID, "gid": GRATICULE_GID}
    s_lat = _step((lat_hi - lat_lo) * 60.0)
    yt, yl = [], []
    for m in np.arange(math.ceil(lat_lo * 60 / s_lat), math.floor(lat_hi * 60 / s_lat) + 1):
        lat = math.radians(m * s_lat / 60.0)
        y = float(offset_ne_m(lat, lon0, lat0, lon0)[0]) / 1e3
        ax.axhline(y, **style)  # type: ignore[arg-type]
        yt.append(y)
        yl.append(_dm(math.degrees(lat), "N", "S", 2, s_lat))
    s_lon = _step((lon_hi - lon_lo) * 60.0)
    xt, xl = [], []
    lats = np.radians(np.linspace(lat_lo, lat_hi, 24))
    for m in np.arange(math.ceil(lon_lo * 60 / s_lon), math.floor(lon_hi * 60 / s_lon) + 1):
        lon = float(wrap_pi(math.radians(m * s_lon / 60.0)))
        n, e = offset_ne_m(lats, np.full(lats.size, lon), lat0, lon0)
        ax.plot(e / 1e3, n / 1e3, **style)  # type: ignore[arg-type]
        xt.append(float(np.interp(y0, n / 1e3, e / 1e3)))
        xl.append(_dm(math.degrees(lon), "E", "W", 3, s_lon))
    ax.set_xticks(xt, xl)
    ax.set_yticks(yt, yl)
    ax.set_xlim(x0, x1)
    ax.set_ylim(y0, y1)
    ax.tick_params(labelsize=8)


def _reference_line(
    ax: Axes, a: Analysis, ref: _Ref | None, lat0: float, lon0: float, t0: int, t1: int
) -> None:
    if ref is None:
        return
    t, la, lo = ref
    sel = (t >= t0) & (t <= t1)
    n, e = offset_ne_m(la[sel], lo[sel], lat0, lon0)
    role = a.dead_reckoning.reference_role if a.dead_reckoning else "reference"
    ax.plot(
        e / 1e3,
        n / 1e3,
        color=REF_COLOUR,
        lw=1.3,
        zorder=Z_REF,
        label=f"reference ({role}), drawn above the DR",
    )


def _ellipse(ep: _Epochs, i: int, xy: tuple[float, float], label: str | None = None) -> Ellipse:
    """The 95 % error ellipse of epoch ``i`` centred at ``xy`` (km), dashed."""
    return Ellipse(
        xy,
        2 * float(ep.semi_major_km[i]),
        2 * float(ep.semi_minor_km[i]),
        angle=float(ep.angle_deg[i]),
        fill=False,
        color=ELLIPSE_COLOUR,
        lw=0.9,
        ls="--",
        zorder=Z_CIRCLE,
        label=label,
    )


def _circles(ax: Axes, ep: _Epochs, sel: np.ndarray, px_km: float) -> tuple[float, int]:
    """2M circles and 95 % ellipses at the epochs ``sel`` (bool) that are at least
    MIN_CIRCLE_PX at ``px_km``; dots at the others.  (smallest radius drawn in px, dots)."""
    big = sel & (ep.radius_km * px_km >= MIN_CIRCLE_PX)
    first = True
    for i in np.flatnonzero(big):
        xy = (float(ep.x[i]), float(ep.y[i]))
        ax.add_patch(
            Circle(
                xy,
                float(ep.radius_km[i]),
                fill=False,
                color=CIRCLE_COLOUR,
                lw=1.2,
                zorder=Z_CIRCLE,
                label=CIRCLE_LABEL if first else None,
            )
        )
        ax.add_patch(_ellipse(ep, int(i), xy, ELLIPSE_LABEL if first else None))
        first = False
    small = sel & ~big
    if small.any():
        ax.plot(
            ep.x[small],
            ep.y[small],
            "o",
            ms=4,
            mec="white",
            mew=0.6,
            color=CIRCLE_COLOUR,
            zorder=Z_DR + 0.5,
            label=f"DR epoch (2M under {MIN_CIRCLE_PX:g} px here)",
        )
    r = ep.radius_km[big] * px_km
    return (float(r.min()) if r.size else math.nan), int(small.sum())


def _misses(ax: Axes, ep: _Epochs, sel: np.ndarray) -> int:
    out = sel & ep.outside
    if out.any():
        ax.plot(
            ep.ref_x[out],
            ep.ref_y[out],
            "x",
            ms=9,
            mew=2.2,
            color=MISS_COLOUR,
            zorder=Z_MISS,
            label=MISS_LABEL,
        )
    return int(out.sum())


def _measured_min_px(fig: Figure) -> float:
    """The smallest 2M circle's radius in pixels over the figure's axes, from their
    transforms."""
    r = []
    for ax in fig.axes:
        ax.apply_aspect()
        for p in ax.patches:
            if isinstance(p, Circle):  # (an Ellipse is not a Circle; a Circle is an Ellipse)
                (cx, cy) = p.center
                a, b = ax.transData.transform([(cx, cy), (cx + p.radius, cy)])
                r.append(abs(b[0] - a[0]))
    return float(min(r)) if r else math.nan


def _utc(ns: int) -> str:
    return np.datetime64(int(ns), "ns").astype("datetime64[m]").item().strftime("%d %H:%M")


# ------------------------------------------------------------------------ the panels


def _overview(
    a: Analysis,
    lat0: float,
    lon0: float,
    ref: _Ref | None,
    ep: _Epochs | None,
    shown_legs: list[int],
    n_legs: int,
) -> DrawnPanel:
    dr = a.dead_reckoning
    xs, ys, tracks = [], [], []
    for t in a.tracks:
        n, e = offset_ne_m(t.lat_rad, t.lon_rad, lat0, lon0)
        tracks.append((t, e / 1e3, n / 1e3))
        xs.append(e / 1e3)
        ys.append(n / 1e3)
    fig = _frame(xs, ys, pad=0.04)
    ax = fig.axes[0]
    ref_role = dr.reference_role if dr is not None else None
    for t, x, y in tracks:
        if ref is not None and t.role == ref_role:
            continue  # drawn on top below
        label = f"{t.source} ({t.role})" if t.role else t.source
        ax.plot(
            x,
            y,
            lw=0.8,
            alpha=0.7,
            color=_ROLE_COLOURS.get(t.role or ""),
            zorder=Z_OTHER,
            label=label,
        )
    water_note = ""
    if dr is not None and len(dr.track.time_ns):
        tr = dr.track
        n, e = offset_ne_m(tr.lat_rad, tr.lon_rad, lat0, lon0)
        wn, we = offset_ne_m(tr.water_lat_rad, tr.water_lon_rad, lat0, lon0)
        differs = bool(np.any(np.hypot(wn - n, we - e) > 0.5))
        if differs:
            ax.plot(
                *_by_leg(wn, we, tr.leg),
                lw=0.7,
                ls="--",
                color="#7f7f7f",
                zorder=Z_OTHER,
                label=WATER_LABEL,
            )
            water_note = f"; the {WATER_LABEL}, thin dashed"
        est = dr.scored_out_of_sample or differs
        ax.plot(
            *_by_leg(n, e, tr.leg),
            lw=1.4,
            color=DR_COLOUR,
            zorder=Z_DR,
            label=EP_LABEL if est else DR_LABEL,
        )
        _reference_line(ax, a, ref, lat0, lon0, int(tr.time_ns[0]), int(tr.time_ns[-1]))
    elif ref is not None:
        _reference_line(ax, a, ref, lat0, lon0, int(ref[0][0]), int(ref[0][-1]))
    _graticule(ax, lat0, lon0)
    min_px, n_miss, circles_note = math.nan, 0, ""
    if ep is not None and dr is not None:
        px_km = px_per_km(ax)
        min_px, n_dots = _circles(ax, ep, ep.shown & (ep.radius_km * px_km >= MIN_CIRCLE_PX), px_km)
        n_miss = _misses(ax, ep, ep.shown)
        for k in shown_legs:
            sel = ep.shown & (ep.leg == k)
            bx = np.r_[ep.x[sel] - ep.radius_km[sel], ep.x[sel] + ep.radius_km[sel]]
            by = np.r_[ep.y[sel] - ep.radius_km[sel], ep.y[sel] + ep.radius_km[sel]]
            ax.add_patch(
                Rectangle(
                    (bx.min(), by.min()),
                    np.ptp(bx),
                    np.ptp(by),
                    fill=False,
                    lw=0.8,
                    ls=":",
                    color="#444444",
                    zorder=Z_OTHER,
                )
            )
            ax.annotate(
                f"leg {k}",
                (bx.max(), by.max()),
                fontsize=7,
                color="#444444",
                ha="right",
                va="bottom",
            )
        n_scored = int(ep.scored.sum())
        which = f"legs shown below: {', '.join(map(str, shown_legs))}" + (
            f" (the {len(shown_legs)} worst of the {n_legs} with an epoch after their fix: most "
            "misses, then largest error/M)"
            if len(shown_legs) < n_legs
            else ""
        )
        circles_note = (
            f"; {n_miss} of {n_scored} scored epochs had the reference outside 2M (red ×); "
            + (
                "2M circles too small to see at this scale are left out; "
                if math.isnan(min_px) or n_dots
                else ""
            )
            + which
        )
    scale_bar(ax)
    ax.legend(loc="best", fontsize=8, framealpha=0.85)
    ax.set_title("Whole voyage", fontsize=10)
    subject = (
        f"the {EP_LABEL} (black)"
        if dr is not None and dr.scored_out_of_sample
        else f"the dead-reckoning track (the {WATER_LABEL}; black)"
    )
    caption = (
        f"Whole voyage: the track of every source, {subject} and the reference "
        f"(magenta, drawn above){water_note}{circles_note}."
    )
    return DrawnPanel(fig, ax, "track plot", caption, _measured_min_px(fig), None, n_miss)


def _leg_panel(
    a: Analysis, lat0: float, lon0: float, ref: _Ref | None, ep: _Epochs, k: int
) -> DrawnPanel:
    dr = a.dead_reckoning
    assert dr is not None
    tr = dr.track
    rows = tr.leg == k
    n, e = offset_ne_m(tr.lat_rad[rows], tr.lon_rad[rows], lat0, lon0)
    sel = ep.shown & (ep.leg == k)
    t0, t1 = int(tr.time_ns[rows][0]), int(tr.time_ns[rows][-1])
    xs = [e / 1e3, ep.x[sel] - ep.radius_km[sel], ep.x[sel] + ep.radius_km[sel], ep.ref_x[sel]]
    ys = [n / 1e3, ep.y[sel] - ep.radius_km[sel], ep.y[sel] + ep.radius_km[sel], ep.ref_y[sel]]
    xlim, _, _ = _limits(xs, ys)
    px_km = _MAP_W_IN * _DPI / (xlim[1] - xlim[0])
    small = np.flatnonzero(sel & (ep.radius_km * px_km < MIN_CIRCLE_PX))
    if small.size > _MAX_INSETS:  # the worst (largest error/M), in time order
        worst = np.argsort(-np.nan_to_num(ep.error_over_m[small], nan=-1.0), kind="stable")
        small = np.sort(small[worst[:_MAX_INSETS]])
    fig = _frame(xs, ys, inset_rows=math.ceil(small.size / _INSETS_PER_ROW))
    ax = fig.axes[0]
    ax.plot(
        e / 1e3,
        n / 1e3,
        lw=1.4,
        color=DR_COLOUR,
        zorder=Z_DR,
        label=EP_LABEL if dr.scored_out_of_sample else DR_LABEL,
    )
    ax.plot(
        e[:1] / 1e3,
        n[:1] / 1e3,
        "s",
        ms=6,
        color=DR_COLOUR,
        zorder=Z_DR,
        label="fix (start of the leg)",
    )
    _reference_line(ax, a, ref, lat0, lon0, t0, t1)
    _graticule(ax, lat0, lon0)
    _, n_dots = _circles(ax, ep, sel, px_per_km(ax))
    n_miss = _misses(ax, ep, sel)
    scale_bar(ax)
    ax.legend(loc="best", fontsize=8, framealpha=0.85)
    ax.set_title(f"Leg {k}: {_utc(t0)} – {_utc(t1)} UTC", fontsize=10)
    if small.size:
        ref_line = [ln for ln in ax.get_lines() if str(ln.get_label()).startswith("reference (")]
        ref_xy = np.column_stack(ref_line[0].get_data()) if ref_line else np.zeros((0, 2))
        _insets(fig, ep, small, np.column_stack([e / 1e3, n / 1e3]), ref_xy)
    min_px = _measured_min_px(fig)
    leg = next((g for g in dr.legs if g.index == k), None)
    interval = f"{dr.epoch_interval_s / 60:g}-min"
    caption = (
        f"Leg {k}, {_utc(t0)}–{_utc(t1)} UTC"
        + (f" (fix: {leg.fix_source})" if leg is not None else "")
        + f": the {dr_name(dr.scored_out_of_sample)} with its 2M circle (orange) and 95 % error "
        f"ellipse (blue, dashed) at each "
        f"{interval} epoch, the reference ({dr.reference_role}) in magenta above it; "
        f"{n_miss} of {int((sel & ep.scored).sum())} scored epochs outside 2M (red ×)"
        + (f"; smallest circle {min_px:.0f} px" if np.isfinite(min_px) else "")
        + (
            f"; {n_dots} epoch(s) with 2M under {MIN_CIRCLE_PX:g} px at this scale drawn as "
            f"dots on the map and shown below it, each at the scale of its circle "
            f"(centred on the DR, +)"
            if n_dots
            else ""
        )
        + "."
    )
    return DrawnPanel(fig, ax, f"track plot, leg {k}", caption, min_px, k, n_miss)


def draw_track_panels(a: Analysis) -> Iterator[DrawnPanel]:
    """The overview, then the leg panels in time order, as figures (the caller closes
    them; :func:`track_panels` renders and closes each).  Nothing when no position."""
    origin = _origin(a)
    if origin is None:
        return
    lat0, lon0 = origin
    ref = _reference(a)
    dr = a.dead_reckoning
    ep = _epochs(dr, ref, lat0, lon0) if dr is not None and len(dr.epochs.time_ns) else None
    legs, n_legs = _legs_to_show(ep) if ep is not None else ([], 0)
    yield _overview(a, lat0, lon0, ref, ep, legs, n_legs)
    for k in legs:
        assert ep is not None and dr is not None
        # each leg on its own tangent plane (origin: the leg's fix), true to scale there
        first = int(np.flatnonzero(dr.track.leg == k)[0])
        la, lo = float(dr.track.lat_rad[first]), float(dr.track.lon_rad[first])
        yield _leg_panel(a, la, lo, ref, _epochs(dr, ref, la, lo), k)


#: legend label of the fix-updated EP (seeds/003's aided DR) in its panel
AIDED_LABEL = FIX_UPDATED_EP
AIDED_COLOUR = "#2ca02c"


def aided_ep_panel(a: Analysis) -> DrawnPanel | None:
    """The fix-updated EP over the DR, with its 95 % ellipse at each epoch
    (1-sigma semi-axes times sqrt(chi2_2(0.95))) where that is at least MIN_CIRCLE_PX."""
    e, dr, origin = a.estimated_position, a.dead_reckoning, _origin(a)
    if e is None or dr is None or origin is None or not len(e.time_ns):
        return None
    lat0, lon0 = origin
    n, east = offset_ne_m(e.lat_rad, e.lon_rad, lat0, lon0)
    x, y, ka = east / 1e3, n / 1e3, _ELLIPSE_K * e.semi_major_m / 1e3
    r_km = e.radius_2m_m / 1e3
    shown = (e.since_update_s > 0) & np.isfinite(r_km) & np.isfinite(x)
    worst = np.flatnonzero(shown)[np.argsort(-r_km[shown], kind="stable")[:_INSETS_PER_ROW]]
    fig = _frame([x - ka, x + ka], [y - ka, y + ka], inset_rows=int(worst.size > 0))
    ax = fig.axes[0]
    tn, te = offset_ne_m(dr.track.lat_rad, dr.track.lon_rad, lat0, lon0)
    label = EP_LABEL if dr.scored_out_of_sample else DR_LABEL
    ax.plot(*_by_leg(tn, te, dr.track.leg), lw=0.9, color=DR_COLOUR, zorder=Z_DR, label=label)
    t0, t1 = int(e.time_ns[0]), int(e.time_ns[-1])
    _reference_line(ax, a, ref := _reference(a), lat0, lon0, t0, t1)
    brk = stretch_starts(e)[1:]  # no line joins two stretches of DR
    ax.plot(np.insert(x, brk, np.nan), np.insert(y, brk, np.nan), lw=1.4, color=AIDED_COLOUR)
    upd = np.array([k != "" for k in e.update_kind], bool)
    ax.plot(x[upd], y[upd], "o", ms=3, color=AIDED_COLOUR, zorder=Z_DR + 0.5, label=AIDED_LABEL)
    _graticule(ax, lat0, lon0)
    px_km = px_per_km(ax)
    big = np.flatnonzero((ka * px_km >= MIN_CIRCLE_PX) & np.isfinite(x))
    for j, i in enumerate(big.tolist()):
        ax.add_patch(
            Ellipse(
                (float(x[i]), float(y[i])),
                2 * float(ka[i]),
                2 * _ELLIPSE_K * float(e.semi_minor_m[i]) / 1e3,
                angle=90.0 - math.degrees(float(e.orientation_rad[i])),
                fill=False,
                color=AIDED_COLOUR,
                lw=0.9,
                ls="--",
                zorder=Z_CIRCLE,
                label=f"{ELLIPSE_LABEL} of the {AIDED_LABEL}" if j == 0 else None,
            )
        )
    scale_bar(ax)
    ax.legend(loc="best", fontsize=8, framealpha=0.85)
    if worst.size:  # the largest 2M, each at the scale of its circle (as the leg panels')
        rn, re_ = (np.full(x.size, np.nan),) * 2
        if ref is not None:
            rn, re_ = offset_ne_m(*interp_position(*ref, e.time_ns, 600e9), lat0, lon0)
        ep = _Epochs(
            e.time_ns, x, y, re_ / 1e3, rn / 1e3, np.zeros(x.size, int), r_km, ka,
            _ELLIPSE_K * e.semi_minor_m / 1e3, 90.0 - np.degrees(e.orientation_rad), shown,
            np.zeros(x.size, bool), np.zeros(x.size, bool), np.full(x.size, np.nan),
            np.hypot(re_ - east, rn - n) / 1e3, ref is not None,
        )  # fmt: skip
        ref_xy = np.column_stack([re_, rn]) / 1e3 if ref is not None else np.zeros((0, 2))
        _insets(fig, ep, np.sort(worst), np.column_stack([x, y]), ref_xy)
    ax.set_title(f"{as_heading(AIDED_LABEL)}: {_utc(t0)} – {_utc(t1)} UTC", fontsize=10)
    r2m = e.radius_2m_m[np.isfinite(e.radius_2m_m)]
    caption = (
        f"The {AIDED_LABEL} (green; dots: the epochs after an update: {e.n_fix_updates} GNSS "
        f"fixes, {e.n_lop_updates} from the observation file) over the "
        f"{dr_name(dr.scored_out_of_sample)} (black) and the "
        f"reference (magenta); 2M up to {float(r2m.max()) if r2m.size else math.nan:,.0f} m; "
        f"its 95 % error ellipse (green, dashed) at {big.size} of {len(e.time_ns)} epochs "
        f"(the others under {MIN_CIRCLE_PX:g} px at this scale)"
        + (
            f"; below, the {worst.size} epochs of largest 2M, each at the scale of its 2M "
            f"circle (orange) with the 95 % ellipse (blue, dashed), centred on the "
            f"{AIDED_LABEL} (+)"
            if worst.size
            else ""
        )
        + "."
    )
    return DrawnPanel(fig, ax, f"{AIDED_LABEL} track plot", caption, math.nan, None, 0)


def aided_ep_html(a: Analysis) -> str:
    """The aided EP panel as a ``<figure id="fig-aided-ep">``; '' without an aided EP."""
    d = aided_ep_panel(a)
    if d is None:
        return ""
    return (
        f'<figure id="fig-aided-ep"><img alt="{d.alt}" '
        f'src="{data_uri(png_bytes(d.fig))}"><figcaption>{html.escape(d.caption)}'
        "</figcaption></figure>"
    )


def track_panels(a: Analysis) -> list[Panel]:
    """The overview and the leg panels as PNG bytes with alt text and captions."""
    out = []
    for d in draw_track_panels(a):
        out.append(Panel(png_bytes(d.fig), d.alt, d.caption, d.min_circle_px, d.leg, d.n_misses))
    return out


def figures_html(a: Analysis) -> str:
    """Every track panel as a ``<figure>`` (ids ``fig-track-0``, ...; the smallest circle's
    radius in PNG pixels in ``data-min-circle-px``), or the 'nothing to plot' note."""
    panels = track_panels(a)
    if not panels:
        return '<p class="missing">Track plot: nothing to plot (see Missing).</p>'
    parts = []
    for i, p in enumerate(panels):
        px = "" if math.isnan(p.min_circle_px) else f"{p.min_circle_px:.1f}"
        parts.append(
            f'<figure id="fig-track-{i}" class="track-panel" data-min-circle-px="{px}">'
            f'<img alt="{html.escape(p.alt, quote=True)}" src="{data_uri(p.png)}">'
            f"<figcaption>{html.escape(p.caption, quote=True)}</figcaption></figure>"
        )
    return "".join(parts)
