"""The per-unit statistics table as plain row values, one model for every renderer.

The terminal summary and the HTML report print the same figures of
:class:`~dracc.math.deviation.UnitStats`: the same digits per channel (3 decimals in
degrees, 1 in metres), the same verdict against the a priori RMS and the same
three-cornered-hat figures.  They take them from here and only style them, so the two
reports cannot drift apart.  Every text is plain (no markup, not escaped): the HTML
renderer escapes what it prints.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from dracc.core.vocabulary import CHANNEL_UNITS, CHANNELS, DR_OVER_GROUND
from dracc.math.clock import SourceClock
from dracc.math.deviation import DeviationResult, UnitStats
from dracc.report import fmt

#: the verdict against the a priori RMS
NO_APRIORI, EXCEEDS, WITHIN = "no a priori", "exceeds", "within"

#: the k* column's words for Table 1's mark ('+', '-'): a sign after a number would read
#: as the '-' that means no value
K_STAR_WORDS = {"+": "k ok", "-": "k low"}
#: what the k* column says, under every table that has one (and in the glossary)
K_STAR_NOTE = (
    "k* = m_x / m_u, the factor the reference measured: 'k ok' where k* <= k' (the factor "
    "k in use does not understate the limiting error; Table 1's '+'), 'k low' where k* > k' "
    "(it does; Table 1's '-'); k' is k, 1.5 for the paper's 1.49; '-' alone: no value (no "
    "reference for that unit and channel)"
)


def has_k_star(d: DeviationResult) -> bool:
    """Whether the table has a k* figure (a unit with a reference): its note is then said."""
    return any(u.reference for u in d.whole.units.values())


def k_star_text(k_star: float, mark: str) -> str:
    """A k* cell: '0.53 k ok', '1.61 k low'; '-' where there is no k*."""
    if not math.isfinite(k_star):
        return "-"
    word = K_STAR_WORDS.get(mark)
    return f"{fmt(k_star, 2)} {word}" if word else fmt(k_star, 2)


def channel_digits(channel: str) -> int:
    """Decimals of a channel's figures: 3 in degrees (course), 1 in metres (lat, lon)."""
    return 3 if CHANNEL_UNITS[channel] == "deg" else 1


def sigma_bound(var: float | None, digits: int) -> str:
    """A variance bound shown as a sigma bound: '-' where none, '<0' where negative."""
    if var is None or not math.isfinite(var):
        return "-"
    return "<0" if var < 0 else fmt(math.sqrt(var), digits)


@dataclass(frozen=True)
class UnitRow:
    """One unit and channel, every figure already formatted ('-' where there is none)."""

    unit: str  #: the unit's name (from the configuration or the log: escape it in HTML)
    channel: str  #: 'lat', 'lon' or 'course'
    channel_unit: str  #: 'm' or 'deg'
    n: str
    m_u: str
    m_y: str
    kurtosis: str  #: excess kurtosis, 2 decimals
    limit: str
    apriori: str
    verdict: str  #: NO_APRIORI, EXCEEDS or WITHIN
    new_apriori: str  #: the suggested a priori RMS where the verdict is EXCEEDS
    has_hat: bool  #: a three-cornered-hat figure exists for this channel
    hat_negative: bool  #: the hat variance is negative (reported, never clamped)
    hat_sigma: str
    hat_lower: str  #: bootstrap bounds as sigmas (see :func:`sigma_bound`)
    hat_upper: str
    ref_rms: str  #: RMS error against the reference, '-' without one
    k_star: str  #: k* and its mark in words, e.g. '0.53 k ok' (:func:`k_star_text`)

    @property
    def channel_text(self) -> str:
        """'lat [m]', 'course [deg]'."""
        return f"{self.channel} [{self.channel_unit}]"


def channel_rows(name: str, u: UnitStats) -> list[UnitRow]:
    """The rows of one unit's statistics (one window), in CHANNELS order."""
    rows = []
    for ch in CHANNELS:
        c = u.channels.get(ch)
        if c is None:
            continue
        digits = channel_digits(ch)
        if c.exceeds_apriori is None:
            verdict = NO_APRIORI
        elif c.exceeds_apriori:
            verdict = EXCEEDS
        else:
            verdict = WITHIN
        h = u.hat.get(ch)
        r = u.reference.get(ch)
        rows.append(
            UnitRow(
                unit=name,
                channel=ch,
                channel_unit=CHANNEL_UNITS[ch],
                n=str(c.n),
                m_u=fmt(c.m_u, digits),
                m_y=fmt(c.m_y, digits),
                kurtosis=fmt(c.kurtosis, 2),
                limit=fmt(c.limit, digits),
                apriori=fmt(c.apriori, digits),
                verdict=verdict,
                new_apriori=fmt(c.new_apriori, digits) if verdict == EXCEEDS else "-",
                has_hat=h is not None,
                hat_negative=h is not None and bool(h.negative),
                hat_sigma="-" if h is None else fmt(h.sigma, digits),
                hat_lower="-" if h is None else sigma_bound(h.var_lower, digits),
                hat_upper="-" if h is None else sigma_bound(h.var_upper, digits),
                ref_rms="-" if r is None else fmt(r.rmse, digits),
                k_star="-" if r is None else k_star_text(r.k_star, r.mark),
            )
        )
    return rows


def unit_rows(d: DeviationResult) -> list[tuple[str, list[UnitRow] | None]]:
    """The whole-log table: each unit of ``d.units`` in order with its rows, or None for a
    unit without statistics."""
    out: list[tuple[str, list[UnitRow] | None]] = []
    for name in d.units:
        u = d.whole.units.get(name)
        out.append((name, None if u is None else channel_rows(name, u)))
    return out


#: how each clock method reads in a table cell
_CLOCK_BASIS = {
    "time_of_fix": "own time of fix",
    "heading_rate": "heading against {basis}",
    "course_rate": "against the GNSS course in turns",
    "speed_rate": "against the GNSS speed in speed changes",
    "configured": "configured",
}


def clock_text(c: SourceClock | None) -> str:
    """A source's clock in a cell: '+0.70 ± 0.01 s late (heading against INS2)'; the sign
    says which way: late (stamped after the instant described) or early."""
    if c is None:
        return "-"
    if c.method == "no_clock":
        return "no clock (times are the order of records)"
    if c.method == "own_time":
        return "own time of fix (no receive stamp)"
    if not c.known:
        return "not determinable" + (f" ({c.basis})" if c.basis else "")
    how = _CLOCK_BASIS.get(c.method, c.method).format(basis=c.basis)
    if abs(c.offset_s) < 0.005 and c.offset_sigma_s < 0.005:
        return f"on time ({how})"
    way = "late" if c.offset_s >= 0 else "early"
    return f"{abs(c.offset_s):.2f} ± {c.offset_sigma_s:.2f} s {way} ({how})"


def calibration_method(method: str, n: int, segment_s: float) -> str:
    """How the calibration's numbers were found (CalibrationSection.method, n, segment_s),
    in a few words: the learned filter's fixes or the least-squares segments."""
    if method == "learned":
        return f"learned with the {DR_OVER_GROUND} from {n} fixes"
    return f"least squares, {n} segments of {segment_s:g} s"
