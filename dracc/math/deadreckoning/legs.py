"""The restart rules: where each DR leg starts, from which position, and where it ends.

A leg starts at the given start position or the first usable fix ('start'), runs until
the first step the held data cannot bridge or until the first fix at or after
``leg start + reset_s`` ('reset'), and after a break restarts at the first fix after the
data resume ('after-gap').  A fix starts a leg at the first sample at or after it, from
the fix advanced to that sample by the velocity held then, with P0 = sigma_m^2 I.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike

from dracc.core.arrays import FloatArray
from dracc.core.errors import InsufficientDataError
from dracc.math.deadreckoning.holding import HeldSamples
from dracc.math.deadreckoning.propagation import integrate_ne

__all__ = ["Fixes", "Leg", "as_fixes", "plan_legs"]


class Fixes(NamedTuple):
    """Position fixes with finite time and position, sorted by time (stable)."""

    time_s: FloatArray
    lat_rad: FloatArray
    lon_rad: FloatArray
    sigma_m: FloatArray  #: 1-sigma per axis; the configured fix_sigma_m where not finite


class Leg(NamedTuple):
    """One leg of the track: samples ``start..end`` propagated, ``start..last-1`` kept."""

    start: int  #: first sample
    end: int  #: last sample propagated (the break, or the sample the next leg starts at)
    last: int  #: one past the last sample kept (a reset sample belongs to the next leg)
    lat0_rad: float
    lon0_rad: float
    sigma0_m: float
    reason: str  #: 'start', 'reset', 'after-gap'


def as_fixes(fixes: tuple[ArrayLike, ...] | None, fix_sigma_m: float) -> Fixes | None:
    """``fixes`` = (time_s, lat_rad, lon_rad[, sigma_m]) as :class:`Fixes`; None stays None."""
    if fixes is None:
        return None
    if len(fixes) == 3:
        ft, flat, flon = fixes
        fs: ArrayLike = np.full(np.shape(ft), fix_sigma_m)
    else:
        ft, flat, flon, fs = fixes
    ft = np.asarray(ft, float)
    flat = np.asarray(flat, float)
    flon = np.asarray(flon, float)
    fs = np.broadcast_to(np.asarray(fs, float), ft.shape)
    fs = np.where(np.isfinite(fs), fs, fix_sigma_m)
    ok = np.isfinite(ft) & np.isfinite(flat) & np.isfinite(flon)
    order = np.argsort(ft[ok], kind="stable")
    return Fixes(ft[ok][order], flat[ok][order], flon[ok][order], fs[ok][order])


@dataclass(frozen=True)
class _FixStarts:
    """Legs starting from fixes on the samples' time base."""

    fixes: Fixes | None
    t: FloatArray
    vn: FloatArray
    ve: FloatArray
    held: HeldSamples

    def first_usable(self, k_from: int, t_min: float) -> tuple[int, int] | None:
        """(fix, sample) of the first fix at time >= t_min whose sample (first t_j >= t_fix)
        is >= k_from and can start a leg."""
        fx, t = self.fixes, self.t
        if fx is None:
            return None
        n = t.size
        i = int(np.searchsorted(fx.time_s, t_min, side="left"))
        while i < fx.time_s.size:
            j = int(np.searchsorted(t, fx.time_s[i], side="left"))
            if j >= n:
                return None
            usable = self.held.step_ok[j] if j < n - 1 else self.held.valid[j]
            if j >= k_from and usable:
                return i, j
            i += 1
        return None

    def start_state(self, i_fix: int, j: int) -> tuple[float, float, float]:
        """(lat, lon, sigma) at sample j: fix i_fix advanced by the velocity held then."""
        assert self.fixes is not None
        ft, flat, flon, fs = (column[i_fix] for column in self.fixes)
        lead = self.t[j] - ft  # advance the fix to the sample by the velocity held then
        kv = j - 1 if j > 0 else j
        la, lo = integrate_ne(
            np.array([0.0, lead]),
            np.full(2, self.vn[kv]),
            np.full(2, self.ve[kv]),
            flat,
            flon,
        )
        return float(la[-1]), float(lo[-1]), float(fs)


def plan_legs(
    t: FloatArray,
    vn: FloatArray,
    ve: FloatArray,
    held: HeldSamples,
    fixes: Fixes | None,
    reset_s: float,
    start: tuple[float, float, float] | None,
) -> list[Leg]:
    """The legs of the track, in order.

    ``start`` = (lat0, lon0, sigma0) at t_0, or None to start from the first fix
    (InsufficientDataError when there is none within the samples' span).
    """
    n = t.size
    starts = _FixStarts(fixes, t, vn, ve, held)
    bad_steps = np.flatnonzero(~held.step_ok)  # a bad step k breaks between samples k and k+1
    if start is not None:
        k0 = 0
        s_lat, s_lon, s_sig = start
    else:
        first = starts.first_usable(0, -np.inf)
        if first is None:
            raise InsufficientDataError(
                "dead reckoning needs a start position: give lat0/lon0 or fixes within the log's time span"
            )
        k0 = first[1]
        s_lat, s_lon, s_sig = starts.start_state(*first)
    reason = "start"

    legs: list[Leg] = []
    k_start: int | None = k0
    while k_start is not None and k_start < n:
        # leg end: first bad step at or after k_start, and the next reset fix
        b = int(np.searchsorted(bad_steps, k_start, side="left"))
        k_break = int(bad_steps[b]) if b < bad_steps.size else n - 1  # last sample of the leg
        k_end = k_break
        nxt = None
        if math.isfinite(reset_s):
            nxt = starts.first_usable(k_start + 1, t[k_start] + reset_s)
            if nxt is not None and nxt[1] <= k_break:
                k_end = nxt[1]  # the new leg starts at this sample
            else:
                nxt = None
        last = k_end + 1 if nxt is None else k_end  # the reset sample belongs to the new leg
        legs.append(Leg(k_start, k_end, last, s_lat, s_lon, s_sig, reason))
        if nxt is not None:
            s_lat, s_lon, s_sig = starts.start_state(*nxt)
            k_start, reason = nxt[1], "reset"
            continue
        if k_break >= n - 1:
            break
        # a break: restart at the first fix after the data resume
        resume = int(held.next_valid[k_break + 1]) if k_break + 1 < n else n
        if resume >= n:
            break
        nxt = starts.first_usable(resume, t[resume])
        if nxt is None:
            break
        s_lat, s_lon, s_sig = starts.start_state(*nxt)
        k_start, reason = nxt[1], "after-gap"
    return legs
