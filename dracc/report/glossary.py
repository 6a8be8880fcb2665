"""What every column and figure of the reports means, once, with its equation label.

:data:`GLOSSARY` maps a term (as a column header or a row of the reports names it) to
``(meaning, label)``: one or two plain sentences, and the equation label of
``METHODS.md`` (``"(K3b)"``, ``"(B30, B31)"``), a section of it (``"METHODS §2"``) or
``""`` for a plain word of the tables.  The HTML report renders the list once and links
each column header to its entry (:func:`anchor`); the texts are plain (no markup), the
renderer escapes them.
"""

from __future__ import annotations

import re

from dracc.core.vocabulary import AIDED_DR_PAPER, DR_OVER_GROUND, FIX_UPDATED_EP, WATER_TRACK
from dracc.report.rows import K_STAR_NOTE

__all__ = ["GLOSSARY", "JSON_KEYS", "anchor"]

#: the keys of ``analyze --json`` (dotted paths, ``[]`` a list's items) that hold each of
#: the three positions, by the name every report gives it (:mod:`dracc.core.vocabulary`)
JSON_KEYS: dict[str, tuple[str, ...]] = {
    WATER_TRACK: ("dead_reckoning.epochs[].water_lat_deg", "dead_reckoning.epochs[].water_lon_deg"),
    DR_OVER_GROUND: (
        "dead_reckoning.epochs[].lat_deg",
        "dead_reckoning.epochs[].lon_deg",
        "dead_reckoning.epochs[].radius_2m_m",
    ),
    FIX_UPDATED_EP: ("estimated_position",),
}


def _keys(term: str) -> str:
    """' JSON: a, b.' for a position's glossary entry."""
    return f"  JSON: {', '.join(JSON_KEYS[term])}."


GLOSSARY: dict[str, tuple[str, str]] = {
    # ------------------------------------------------------------------ INS accuracy
    "unit": (
        "The INS unit (its role ins1, ins2 or ins3, or the name the configuration gives it).",
        "",
    ),
    "channel": (
        "What is compared between the units: latitude and longitude as metres north and "
        "east of the mean of the units, and course in degrees (differenced on the circle).",
        "METHODS §4",
    ),
    "n": ("Number of sampling instants (deviations) the statistic is taken over.", "(K3b)"),
    "deviation": (
        "u = y - y*: a unit's reading minus the mean of the units' readings at the same "
        "instant (y* the mean of three).",
        "(K1a, K1b)",
    ),
    "m_u": (
        "RMS of a unit's deviations from the mean of the units: sqrt(sum u^2 / (n - 1.45)).",
        "(K3b)",
    ),
    "m_y": (
        "The unit's estimated RMS error, m_y = k m_u with k = 1.32 for latitude and 1.49 "
        "for longitude and course (the factors of the deviation paper).",
        "(K5b)",
    ),
    "k": (
        "The factor turning the RMS of the deviations into the RMS error: m_y = k m_u "
        "(sqrt(3/2) = 1.22 for three equal independent units, sqrt(2) for two).",
        "(K5a, K5b)",
    ),
    "excess kurtosis": (
        "E = mean(u^4) / m_u^4 - 3: 0 for a normal distribution, negative for flat or "
        "nearly constant deviations, positive for heavy tails.",
        "(K6)",
    ),
    "limit": (
        "The limiting error at probability P: y(P) = K_PIE(P, E) K_hm(P) m_y, from the RMS "
        "error, the kurtosis and the number of independent samples (none with fewer than "
        "one independent sample).",
        "(K8)",
    ),
    "a priori": (
        "The unit's RMS error as configured ([deviation.apriori]), the yardstick m_y is "
        "judged against.",
        "METHODS §4",
    ),
    "a priori verdict": (
        "'exceeds' where m_y is larger than the a priori RMS (the larger becomes the new "
        "a priori value), 'within' otherwise, 'no a priori' where none is configured "
        "(the deviation estimate is then mandatory).",
        "METHODS §4",
    ),
    "hat σ": (
        "The unit's own error sigma by the three-cornered hat: s1^2 = (s12^2 + s13^2 - "
        "s23^2) / 2 from the pairwise differences, with bounds; it separates a bad unit "
        "from two good ones.",
        "METHODS §4",
    ),
    "negative variance": (
        "A statistical artefact of the three-cornered hat, not a fault: with few samples "
        "(or correlated units) the difference of variances can come out below zero.  It "
        "is reported as it is, never clamped, and says the figure cannot be estimated "
        "from this log.",
        "METHODS §4",
    ),
    "ref RMS": (
        "The unit's RMS error against the reference position (GNSS): the true error, "
        "measurable only where a reference exists.",
        "Table 1",
    ),
    "k*": (K_STAR_NOTE + ".", "Table 1"),
    "window": ("The day (or window) the statistics are taken over.", "METHODS §4"),
    # ---------------------------------------------------------------- dead reckoning
    WATER_TRACK: (
        "The dead reckoning from the heading and the speed through the water alone: no "
        "current, nothing learned (the GPX, KML and GeoJSON track 'dr').  Where nothing is "
        "learned (learn = false) it is the DR the 2M is drawn around." + _keys(WATER_TRACK),
        "METHODS §2",
    ),
    DR_OVER_GROUND: (
        f"The {WATER_TRACK} plus the current and the compass and log corrections learned "
        "from the fixes before each leg's start (never later ones): the DR of the Dead "
        "reckoning section, whose 2M is scored against the reference (the exports' track "
        "'ep')." + _keys(DR_OVER_GROUND),
        "METHODS §3",
    ),
    FIX_UPDATED_EP: (
        f"The {WATER_TRACK} plus a Gauss-Markov current, updated at each GNSS fix and each "
        "line of position of --observations by the filter of "
        f"{AIDED_DR_PAPER}: its 2M grows between updates and shrinks at each (the exports' "
        "track 'aided_ep')." + _keys(FIX_UPDATED_EP),
        "METHODS §3",
    ),
    "leg": ("One dead-reckoning leg: from a restart at a fix to the next restart.", "METHODS §2"),
    "start": ("The first time (UTC) of the leg, fault or record span.", ""),
    "end": ("The last time (UTC) of the leg, fault or record span.", ""),
    "fix": ("Where the leg's start fix came from (gnss, ins_mean, ...).", "METHODS §2"),
    "M": (
        "The DR's position RMS error M = sqrt(sigma_north^2 + sigma_east^2), from its "
        "propagated covariance P.",
        "(B30)",
    ),
    "drms": (
        "Distance RMS: the root of the trace of the position covariance, the same as M.",
        "(B30)",
    ),
    "2M": (
        "The 2M circle: radius 2 drms around the DR position; a correct error model "
        "holds the true position inside it 95.4-98.2 % of the time, depending on the "
        "ellipse's shape.",
        "(B31)",
    ),
    "inside 2M": (
        "Fraction of the scored epochs with the reference position inside the 2M circle "
        "drawn, to compare with the probability stated for it: 95.4-98.2 % for a Gaussian "
        "error (the configured model), less for the learned model's Student-t predictive, "
        "whose tails are heavier while few legs were learned from.  Every export shows the "
        "same judgement per epoch.",
        "(B31)",
    ),
    "stated": (
        "The probability the model states for the reference lying inside the 2M drawn: its "
        "predictive, Gaussian for the configured model, Student-t for the learned one "
        "(the covariance times a factor learned from the earlier legs, whose uncertainty "
        "gives the heavier tails), with the reference's own noise.",
        "issue 31",
    ),
    "PIT": (
        "Probability integral transform: at each scored epoch the stated probability of an "
        "error below the one observed.  Its histogram is flat when the stated "
        "probabilities are achieved; heavy on the right when the circles are too small.",
        "",
    ),
    "misleading": (
        "A scored epoch whose error against the reference exceeds the 2M drawn: below the "
        "diagonal of the Stanford diagram (error against 2M).",
        "",
    ),
    "scored": (
        "Epochs after the fix that have a reference position and a model learned only "
        "from earlier fixes (out of sample): the epochs the 2M is judged on.",
        "METHODS §7",
    ),
    "max error": ("The largest distance between the DR and the reference in the leg (m).", ""),
    "RMS error / M": (
        "sqrt(mean (d/M)^2) over the scored epochs, d the distance to the reference: 1 "
        "when the covariance is right, above 1 when the circle is too small.",
        "(B30)",
    ),
    "NEES": (
        "Normalised estimation error squared: d^T P^-1 d of the error against the "
        "covariance; chi-square with 2 degrees of freedom (mean 2) for an honest "
        "covariance.  Summed over the legs' last epochs it is judged against chi-square "
        "bounds.",
        "METHODS §7",
    ),
    "mean NEES": ("The leg's NEES averaged over its scored epochs (2 expected).", "METHODS §7"),
    "last NEES": ("The NEES at the leg's last scored epoch.", "METHODS §7"),
    "NEES bound": (
        "The upper chi-square bound (2 degrees of freedom) the leg's NEES is compared with.",
        "METHODS §7",
    ),
    "χ² bounds": (
        "The two-sided chi-square interval (2 degrees of freedom per leg) inside which "
        "the summed NEES of an honest covariance falls; above it the circle is too small, "
        "below it too large (conservative).",
        "METHODS §7",
    ),
    # ------------------------------------------------------------------ calibration
    "compass error": (
        "Heading error = compass - true (in degrees): the course the DR used (heading, "
        "variation, deviation and the leeway from the log's transverse speed) minus the "
        "true course; correct the compass by subtracting it.  With a log that gives no "
        "transverse speed it is the compass and leeway error: the compass error minus "
        "the leeway (starboard +).",
        "METHODS §3",
    ),
    "log scale error": (
        "s in V_log = (1 + s) V_true (+ offset b): positive when the log reads high.  "
        f"Learned with the {DR_OVER_GROUND}, an offset is folded into the scale "
        "at the voyage's speeds (s ~ scale + b / V).",
        "METHODS §3",
    ),
    "not determinable": (
        "A sensor error the fixes did not constrain: its σ after the voyage is more than "
        "half its prior σ (learned), or the fit cannot separate it (least squares).  Its "
        "value is left out, never printed as a number, and the reason is said.",
        "METHODS §3",
    ),
    # ----------------------------------------------------------------------- sources
    "source": ("The source key: the TAG source, talker or topic the records came from.", ""),
    "roles": ("The part the source plays: compass, log, ins1-ins3 or gnss.", "METHODS §1"),
    "records": ("Number of records (readings) of the source, or covered by the fault.", ""),
    "sentences": ("Records per NMEA sentence type or message type.", ""),
    "first": ("The time (UTC) of the source's first record.", ""),
    "last": ("The time (UTC) of the source's last record.", ""),
    "clock": (
        "The source's clock, learned from the log: how long after the instant they describe "
        "its records are stamped ('late'), with its 1-sigma, and how it was measured (its own "
        "time of fix beside the receive stamp, its heading against another in the yaw and "
        "the turns, its speed against the GNSS in speed changes). Its records without a time "
        "of fix are moved back by it before any analysis.",
        "",
    ),
    # ------------------------------------------------------------------------ faults
    "kind": (
        "The sensor fault: jump (a position step the ship cannot make), frozen (a "
        "position repeated bit for bit while the ship moves), stuck_heading, out_of_range.",
        "",
    ),
    "role": ("The role of the faulty source (compass, log, ins1-ins3, gnss).", ""),
    "what was seen": ("The raw figures that show the fault.", ""),
}


def anchor(term: str) -> str:
    """The fragment id of a term's glossary entry, e.g. 'g-k-star' for 'k*'."""
    text = term.lower().replace("*", "-star").replace("σ", "sigma").replace("χ²", "chi2")
    text = text.replace("/", " over ").replace("²", "2")
    return "g-" + re.sub(r"[^a-z0-9]+", "-", text).strip("-")
