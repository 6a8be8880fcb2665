"""What dracc reads of NMEA 0183 text: the sentence types and their field counts, the
talkers of satellite receivers, the reasons a line is rejected, the names of what is
ignored, and the default longest line."""

from __future__ import annotations

#: a line whose content (its line end excluded) is longer than this is not parsed: it is
#: one rejected line, reason ``too_long`` (the default of ``[ingest] max_line_bytes``)
MAX_LINE_BYTES = 65536

#: sentence type -> (min, max) number of data fields after the address
FIELD_COUNTS = {
    "HDT": (2, 3),
    "HDM": (2, 3),
    "HDG": (5, 6),
    "THS": (2, 3),
    "ROT": (2, 3),
    "VHW": (8, 9),
    "VBW": (6, 11),
    "VLW": (4, 9),
    "GGA": (12, 15),
    "GLL": (4, 8),
    "RMC": (10, 14),
    "GNS": (12, 14),
    "VTG": (8, 10),
    "ZDA": (4, 7),
    # read by the numpy path only (the compiled kernel hands their lines over):
    # proprietary INS sentences and own-ship AIS (:mod:`~dracc.ingest.nmea.ins_ais`)
    "PASHR": (6, 11),  # the short form ends after heave; NovAtel < 7.03 has no field 11
    "PSXN": (5, 5),  # the ,20 (quality) and ,23 (attitude) forms dracc reads
    "VDO": (6, 6),
}
SENTENCES = tuple(FIELD_COUNTS)
#: the standard 3-letter sentence types (the kernel's types, in its order); the others
#: of :data:`SENTENCES` are :data:`SPECIAL` (a proprietary address or AIS armour)
STANDARD = SENTENCES[:14]
SPECIAL = SENTENCES[14:]
#: talkers of satellite receivers: they cannot measure magnetic heading nor water speed
GNSS_TALKERS = frozenset({"GP", "GN", "GL", "GA", "GB", "GI", "GQ", "BD"})
NO_GNSS = frozenset({"HDG", "HDM", "VHW", "VBW", "VLW"})
#: reasons that do not make --strict fail: ``no_date`` is counted when the times are
#: resolved and reported at the end (valid lines dracc does not use are not rejected at
#: all: they are *ignored*, counted by type, see :data:`IGNORED`)
NON_FATAL = frozenset({"no_date"})

REASONS = {
    "checksum": "checksum does not match",
    "truncated": "sentence cut short (no checksum before the next sentence or end of file)",
    "binary": "non-printable bytes",
    "bad_address": "address field is not 2-character talker + 3-letter type",
    "implausible_talker": "satellite talker on a heading/log sentence (spliced address)",
    "field_count": "wrong number of fields for the sentence type",
    "malformed_field": "a field is not a number / out of range / bad hemisphere",
    "bad_tag": "TAG block unreadable or with a wrong checksum",
    "not_nmea": "no sentence on the line",
    "too_long": "line longer than [ingest] max_line_bytes (not read; e.g. a run of NUL bytes)",
    "no_date": "time of day with no date anywhere in the log (use --date)",
}

#: what the names counted as *ignored* (valid input dracc does not use; never rejected,
#: never a --strict failure) mean.  Besides these: the sentence type of a well-formed
#: standard sentence dracc does not read (``GSV``, ``MWV``, ``DBT``, ``XDR`` ...; also
#: ``VDM`` for AIS ``!AIVDM``, other ships), and the address of a proprietary sentence,
#: its first 5 characters (``PGRME``, ``PUHAW``, ``PSRFT`` for ``$PSRFTXT``).  Of the
#: sentences dracc reads, the forms it does not use are ignored under their name too:
#: ``VDO`` (a multi-sentence own-ship message such as type 5, other message types, a
#: report with nothing available), ``PSXN`` (``$PSXN,21``, ``,22``, ``,24`` ...) and
#: ``PASHR`` (Ashtech's ``$PASHR,ATT``, ``,HPR``, ``,POS`` ... with a word in field 1).
IGNORED = {
    "comment": "comment line ('#')",
    "blank": "empty line",
}
#: examples kept per ignored type (the first in the file)
IGNORED_EXAMPLES = 3
