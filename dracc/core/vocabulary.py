"""The words every layer shares: sensor roles and the INS accuracy channels.

Defined once here; frames, configuration, methods, audit and reports import them.
"""

from __future__ import annotations

#: the bridge sensors dracc reads, by the part they play
ROLES = ("compass", "log", "ins1", "ins2", "ins3", "gnss")
#: the three INS units compared with the mean of three (METHODS section 4)
INS_ROLES = ("ins1", "ins2", "ins3")

#: the INS accuracy channels: latitude and longitude (as metres) and course
CHANNELS = ("lat", "lon", "course")
#: each channel's key in JSON samples, a priori errors and audit limits (its unit in the name)
CHANNEL_KEYS = {"lat": "lat_m", "lon": "lon_m", "course": "course_deg"}
#: each channel's unit, as reports print it
CHANNEL_UNITS = {"lat": "m", "lon": "m", "course": "deg"}

# ---------------------------------------------------------------- the positions' names
#
# The three positions the reports draw, one name each in every renderer and export
# (terminal, HTML, GPX, KML, GeoJSON, MCAP, notes, glossary; tests/test_terms.py).  JSON
# keys and MCAP topics keep theirs (``water_lat_deg``, ``lat_deg``, ``estimated_position``).

#: the DR from heading and speed through the water alone: no current, nothing learned
WATER_TRACK = "water track"
#: the water track plus the current and the compass and log corrections learned from the
#: fixes before each leg (dracc.math.ep): the DR section's track and its 2M
DR_OVER_GROUND = "DR over the ground"
#: the DR updated at each GNSS fix and line of position (dracc.math.ep.aided)
FIX_UPDATED_EP = "fix-updated EP"
#: the paper the fix-updated EP and the current filter come from, as users read it
AIDED_DR_PAPER = "the aided dead-reckoning paper of Gebre-Egziabher, Powell and Enge"


def dr_name(learned: bool) -> str:
    """The name of the track the DR section scores: the DR over the ground where the
    current and corrections were learned, the water track itself where not (learn = false)."""
    return DR_OVER_GROUND if learned else WATER_TRACK


def as_heading(name: str) -> str:
    """A name at the start of a heading or sentence: 'Fix-updated EP' (not str.capitalize,
    which would lower the 'EP')."""
    return name[:1].upper() + name[1:]


# ---------------------------------------------------------------- the tables' columns
#
# One name for one thing in every table dracc writes (``analyze --out``, ``fleet``,
# ``records``) and in the column headers of the audit history and fleet pages.  The
# rules: a name carries its unit (``_m``, ``_deg``, ``_s``, ``_pct``, ``_kn``); a time is
# ``*_utc``, stored as a timestamp (Parquet ``timestamp[ns, tz=UTC]``, DuckDB
# ``TIMESTAMP WITH TIME ZONE``) and written in CSV as ISO 8601 with ``Z``; a UTC date
# (``day``) is a date (Parquet ``date32``) and ``YYYY-MM-DD`` in CSV; the INS unit is
# ``ins_unit`` (ins1..ins3, or the name the configuration gives it) and the unit a
# channel's figures are in is ``measure_unit`` (``m`` or ``deg``).  No column is called
# plain ``unit``.

#: the kinds a table column can be: how Parquet stores it (and pandas holds it)
COLUMN_KINDS = ("timestamp", "date", "text", "int", "float", "bool")

#: every column name of dracc's tables -> (kind, meaning)
TABLE_COLUMNS: dict[str, tuple[str, str]] = {
    # times
    "time_utc": ("timestamp", "the row's time, UTC (a record's time of fix where it has one)"),
    "recv_utc": ("timestamp", "a record's receive time where distinct from its time of fix"),
    "window_start_utc": (
        "timestamp",
        "the start of the statistics window (a check's: of the records it looked at), UTC",
    ),
    "period_start_utc": ("timestamp", "the first record of the log, UTC"),
    "period_end_utc": ("timestamp", "the last record of the log, UTC"),
    "day": ("date", "the UTC date (of the middle of a log's period)"),
    # who and what
    "vessel": ("text", "the vessel (its folder's name)"),
    "log": ("text", "the log file, its path within the vessel folder"),
    "sha256": ("text", "SHA-256 of the log's bytes"),
    "status": ("text", "a log: ok or failed; a check: fail or not_checked"),
    "error": ("text", "why a log failed"),
    "lines": ("int", "lines (records) read from the log"),
    "ins_unit": ("text", "the INS unit: ins1, ins2, ins3, or the name the configuration gives"),
    "channel": ("text", "the INS accuracy channel: lat, lon or course"),
    "measure_unit": ("text", "the unit of the channel's figures: m (lat, lon) or deg (course)"),
    "window": ("text", "the statistics window: 'all' (the whole log) or the day"),
    # INS accuracy (figures in the row's measure_unit)
    "n": ("int", "sampling instants (deviations) the statistic is taken over"),
    "m_u": ("float", "RMS of the unit's deviations from the mean of the units (K3b)"),
    "k": ("float", "the factor of m_y = k m_u (K5a, K5b)"),
    "m_y": ("float", "the unit's estimated RMS error, m_y = k m_u (K5b)"),
    "rms_error": (
        "float",
        "the unit's RMS error of the night as the ranking reads it: against the reference, "
        "else the three-cornered hat, else m_y (rms_error_method)",
    ),
    "rms_error_method": ("text", "how rms_error was found: reference, hat or factor"),
    "kurtosis_excess": ("float", "excess kurtosis of the deviations, 0 for a normal law (K6)"),
    "k_pie": ("float", "K_PIE(P, E) of the limiting error (K8)"),
    "k_hm": ("float", "K_hm(P) of the limiting error (K8)"),
    "limit": ("float", "the limiting error at the configured probability (K8)"),
    "apriori": ("float", "the configured a priori RMS error ([deviation.apriori])"),
    "exceeds_apriori": ("bool", "m_y above the a priori"),
    "new_apriori": ("float", "the a priori after the monitoring rule: max(a priori, m_y)"),
    "apriori_before": ("float", "the a priori before this log or night (the monitoring rule)"),
    "apriori_after": ("float", "the a priori after it: max(before, m_y)"),
    "apriori_verdict": ("text", "established, within, raised or no data"),
    "logs": ("int", "logs pooled into the row"),
    "r_lat_lon": ("float", "correlation of the unit's latitude and longitude deviations"),
    "hat_variance": ("float", "the unit's error variance from the three-cornered hat"),
    "hat_sigma": ("float", "its square root"),
    "hat_negative": ("bool", "the hat's variance came out negative (a statistical artefact)"),
    "ref_rmse": ("float", "RMS error against the reference"),
    "ref_m_x": ("float", "the reference's own RMS error"),
    "k_star": ("float", "k* = ref RMS / m_u, the factor found against the reference"),
    "mark": ("text", "the reference comparison's mark"),
    # dead reckoning
    "lat_deg": ("float", "latitude, degrees north"),
    "lon_deg": ("float", "longitude, degrees east"),
    "since_fix_s": ("float", "seconds since the DR's last fix"),
    "radius_2m_m": ("float", "the 2M (2 drms) radius, metres"),
    "semi_major_m": ("float", "semi-major axis of the 2M ellipse, metres"),
    "semi_minor_m": ("float", "semi-minor axis of the 2M ellipse, metres"),
    "orientation_deg": ("float", "the ellipse's major axis, degrees clockwise from north"),
    "ref_error_m": ("float", "distance from the reference, metres"),
    "leg": ("int", "the DR leg (from one fix to the next)"),
    "water_lat_deg": ("float", "latitude of the water track (heading and log only)"),
    "water_lon_deg": ("float", "longitude of the water track"),
    "scored": ("bool", "the row is scored out of sample"),
    "dr_containment_2m": ("float", "share of DR epochs with the reference inside 2M"),
    "dr_n_scored": ("int", "DR epochs scored"),
    "dr_consistent": ("bool", "the DR consistent or conservative (empty: undetermined)"),
    "dr_verdict": ("text", "consistent, conservative, inconsistent or undetermined"),
    "dr_nees": ("float", "the NEES statistic over the scored legs"),
    # calibration and input
    "compass_error_deg": ("float", "the compass error against the reference, degrees"),
    "compass_error_sigma_deg": ("float", "its standard error, degrees"),
    "log_scale_pct": ("float", "the speed log's scale error, %"),
    "log_scale_sigma_pct": ("float", "its standard error, %"),
    "rejected_rate_pct": ("float", "damaged lines, % of the lines"),
    # records (``dracc records``; their meanings in full in dracc.pipeline.records.COLUMNS)
    "source": (
        "text",
        "the source key (TAG s:, talker, MCAP topic, CSV source); a finding's: else its "
        "subject (DR, compass, inputs)",
    ),
    "role": ("text", "the role(s) of the source, '+'-joined"),
    "talker": ("text", "the NMEA talker ID"),
    "sentence": ("text", "the sentence, PGN or MCAP message"),
    "file": ("text", "the log file the source's records come from"),
    "line": ("int", "1-based line or message number in its file"),
    "alt_m": ("float", "altitude, metres"),
    "fix_quality": ("int", "the position's quality (GGA fix quality)"),
    "hdop": ("float", "horizontal dilution of precision"),
    "heading_deg": ("float", "heading, degrees"),
    "heading_ref": ("text", "T true, M magnetic"),
    "deviation_deg": ("float", "magnetic deviation, degrees east"),
    "variation_deg": ("float", "magnetic variation, degrees east"),
    "heading_quality": (
        "float",
        "the unit's heading quality code (0 normal, 1 reduced, 2 invalid)",
    ),
    "cog_deg": ("float", "course over ground, degrees true"),
    "sog_kn": ("float", "speed over ground, knots"),
    "stw_kn": ("float", "speed through the water, knots"),
    "stw_transverse_kn": ("float", "transverse speed through the water, knots"),
    "sog_long_kn": ("float", "longitudinal ground speed, knots"),
    "sog_transverse_kn": ("float", "transverse ground speed, knots"),
    "total_water_nmi": ("float", "total distance through the water, nautical miles"),
    "trip_water_nmi": ("float", "trip distance through the water, nautical miles"),
    "rot_degpmin": ("float", "rate of turn, degrees per minute"),
    # the audit history page (the history document's figures of a night)
    "night": ("date", "the audited night (UTC date)"),
    "first_night": ("date", "the first night of the logs or nights the row covers"),
    "last_night": ("date", "the last night of the logs or nights the row covers"),
    "findings": ("text", "the night's findings"),
    # the fleet's findings and integrity tables (dracc.pipeline.fleet.findings)
    "check": (
        "text",
        "the check's family: validity, plausibility, latency, availability, consistency, "
        "time, accuracy or input",
    ),
    "name": ("text", "the check, e.g. jump, frozen, dropout, dr_inconsistent"),
    "message": ("text", "what the check found, or why it could not be made"),
    "window_end_utc": ("timestamp", "the end of the window the check looked at, UTC"),
    "consequences": ("text", "the failed checks this finding caused, listed under it"),
    "checks_made": ("int", "integrity checks made (passed + failed)"),
    "checks_passed": ("int", "integrity checks passed"),
    "checks_failed": ("int", "integrity checks failed"),
    "checks_not_checked": ("int", "integrity checks that could not be made"),
}

#: a wide column per INS unit: ``<ins_unit>_<channel key>`` (``ins1_lat_m``) -> (kind, meaning)
TABLE_COLUMN_SUFFIXES: dict[str, tuple[str, str]] = {
    "_" + key: (
        "float",
        f"the unit's {ch} deviation from the mean of the units, {CHANNEL_UNITS[ch]}",
    )
    for ch, key in CHANNEL_KEYS.items()
}


def column_kind(name: str) -> str | None:
    """The kind of table column ``name`` (:data:`TABLE_COLUMNS`, or a per-unit column
    ``<ins_unit>_lat_m`` of :data:`TABLE_COLUMN_SUFFIXES`); None if it is not in the
    vocabulary."""
    if name in TABLE_COLUMNS:
        return TABLE_COLUMNS[name][0]
    for suffix, (kind, _meaning) in TABLE_COLUMN_SUFFIXES.items():
        if name.endswith(suffix) and len(name) > len(suffix):
            return kind
    return None
