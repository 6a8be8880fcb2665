"""The bounds of every numeric setting of the configuration, in one place: the ranges
:data:`dracc.core.config`'s schema checks each key against (physically sensible: a value
beyond them is a typo or a unit mistake, and some asked for unbounded work, an epoch
every microsecond 26.8 GiB, or overflowed), and the work a setting may ask of one log
(:func:`check_work`).  A value out of range is a ConfigError (exit 4) naming the key and
the range.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from dracc.core.errors import ConfigError

__all__ = [
    "DAY_S",
    "FACTOR",
    "FINITE",
    "HALF_TO_ONE",
    "MAX_CONFIG_BYTES",
    "MAX_INSTANTS",
    "MAX_ITEMS",
    "NON_NEGATIVE",
    "RESET_S",
    "SIGMAS",
    "SIGMA_M",
    "SPEED_KN",
    "STEP_S",
    "TAU_S",
    "UP_TO_A_DAY",
    "UP_TO_A_YEAR",
    "YEAR_S",
    "ZERO_TO_A_DAY",
    "Range",
    "check_work",
    "within",
]


@dataclass(frozen=True)
class Range:
    """Closed or open bounds of a number; ``text`` says them in a message."""

    text: str
    lo: float = -math.inf
    hi: float = math.inf
    lo_open: bool = False
    hi_open: bool = False

    def holds(self, v: float) -> bool:
        above = v > self.lo if self.lo_open else v >= self.lo
        below = v < self.hi if self.hi_open else v <= self.hi
        return above and below


NON_NEGATIVE = Range(">= 0", 0.0)
FINITE = Range("finite")
HALF_TO_ONE = Range("in [0.5, 1)", 0.5, 1.0, hi_open=True)


def _num(x: float) -> str:
    """A bound as a reader takes it in: 86400, 31,622,400, 0.1, 1e-06."""
    return f"{x:,.0f}" if float(x).is_integer() and abs(x) >= 1e4 else f"{x:g}"


def within(lo: float, hi: float, unit: str = "", lo_open: bool = False) -> Range:
    """The range ``[lo, hi]`` (``(lo, hi]`` with ``lo_open``) said with its unit."""
    text = f"in {'(' if lo_open else '['}{_num(lo)}, {_num(hi)}]" + (f" {unit}" if unit else "")
    return Range(text, lo, hi, lo_open=lo_open)


DAY_S, YEAR_S = 86_400.0, 366 * 86_400.0
UP_TO_A_DAY = within(0.0, DAY_S, "seconds", lo_open=True)
ZERO_TO_A_DAY = within(0.0, DAY_S, "seconds")
UP_TO_A_YEAR = within(0.0, YEAR_S, "seconds", lo_open=True)
STEP_S = within(0.1, DAY_S, "seconds")  #: a grid of instants over the log
#: the DR's restart interval: auto's shortest (30 s) up to a year (or "never")
RESET_S = within(30.0, YEAR_S, "seconds")
SIGMA_M = Range("in (0, 1,000,000) m", 0.0, 1e6, lo_open=True, hi_open=True)
SPEED_KN = within(0.0, 100.0, "kn", lo_open=True)
FACTOR = within(0.0, 10.0, lo_open=True)
#: an error source's sigma, in the unit of its key
SIGMAS = {
    "compass_bias_deg": within(0.0, 180.0, "degrees"),
    "compass_noise_deg": within(0.0, 180.0, "degrees"),
    "log_scale": within(0.0, 1.0, "(a fraction of the speed)"),
    "log_bias_kn": within(0.0, 50.0, "kn"),
    "log_noise_kn": within(0.0, 50.0, "kn"),
    "current_kn": within(0.0, 20.0, "kn"),
    "leeway_deg": within(0.0, 90.0, "degrees"),
}
#: an error source's correlation time (or "inf", a bias)
TAU_S = within(0.0, 1e9, 'seconds, or "inf"')
#: an array or table of the configuration holds at most this many items
MAX_ITEMS = 1000
#: a configuration file is at most this long (the example, every key commented: 11 kB)
MAX_CONFIG_BYTES = 1 << 20
#: the most instants a setting may ask for over one log (DR epochs, deviation sampling
#: instants, integrity comparison instants): a finer setting is refused for that log
#: (:func:`check_work`), where it used to exhaust the memory or run for hours
#: (the defaults stay within them on any log up to a year: 10 min epochs for 19 years,
#: hourly instants for 22 years, 10 s comparisons for 15 months)
MAX_INSTANTS = {
    ("dead_reckoning", "epoch_interval_s"): 1_000_000,
    ("deviation", "interval_s"): 200_000,
    ("integrity", "consistency_interval_s"): 4_000_000,
}


def check_work(section: str, key: str, step_s: float, span_s: float) -> None:
    """Refuse (ConfigError naming the key) a step ``step_s`` asking more than
    :data:`MAX_INSTANTS` instants over ``span_s`` seconds of log."""
    cap = MAX_INSTANTS[(section, key)]
    n = span_s / step_s
    if n > cap:
        raise ConfigError(
            f"[{section}] {key} = {step_s:g}: {n:,.0f} instants over this log's "
            f"{span_s / 3600:,.1f} h, more than the {cap:,} a setting may ask; "
            f"for this log, {key} >= {span_s / cap:.3g}"
        )
