"""NMEA 0183 text ingest, over blocks of bytes.

Where it is built, the compiled kernel ``_nmeascan`` (one pass in C, see
:mod:`~dracc.ingest.nmea.engine_c`) decodes the clean lines of a block and hands every
other line to the numpy path (:mod:`~dracc.ingest.nmea.engine_numpy`),
which is also the fallback without a compiler and the reference of the differential
tests (tests/test_nmeascan.py).

A block (tens of MB, cut after a line end: LF, CR LF, CR CR LF or a lone CR) is read as
one ``uint8`` array, in pieces of bounded working memory; line ends, sentence starts
(``$``/``!``), commas and ``*`` are found with ``np.flatnonzero``;
checksums are XORs of ranges taken from one cumulative XOR; sentences are grouped by
type and their fields gathered into fixed-width byte matrices converted with
``astype(float)``.  There is no Python loop over lines; loops run over sentence types
and fields only.  Large files are parsed by two worker processes, block by block, with
bounded look-ahead, so memory does not grow with the file (``iter_nmea_blocks``); the
workers die with their parent.  A line longer than ``[ingest] max_line_bytes`` is one
``too_long`` reject, never held whole (only its tail's last sentence is read), so memory
does not grow with the content either: a crashed logger's 256 MB of NUL bytes costs one
line.

Field conversions (edges of the SI world, units per ``dracc.core.units``):

* ``ddmm.mmmm`` / ``dddmm.mmmm`` + hemisphere -> radians:
  ``deg = floor(v/100) + (v - 100 floor(v/100))/60``, S and W negative.
* knots -> m/s: ``* 1852/3600`` (exact); km/h -> m/s: ``/ 3.6`` (used only where the
  knots field is empty); nautical miles -> metres ``* 1852``.
* degrees -> radians; ROT degrees/minute -> rad/s: ``* pi/180/60``.
* ``hhmmss.sss`` -> ns of the day; ``ddmmyy`` -> date (years 80-99 -> 19yy, else 20yy,
  as gpsd does); ZDA ``hhmmss.ss,dd,mm,yyyy``.
* Empty fields are NaN, never zero.

Sentences read: HDT, HDG, HDM, THS, ROT (heading/rot); VHW, VBW (water), VLW
(distance); GGA, GLL, RMC, GNS (position; RMC also ground), VTG (ground); ZDA (time
only); and, by the numpy path alone (:mod:`~dracc.ingest.nmea.ins_ais`), ``$PASHR``
and ``$PSXN,20``/``,23`` (INS heading with its quality) and own-ship AIS ``!AIVDO``
types 1, 2, 3, 18, 19 (position, ground, heading).  Other well-formed sentences, ``#``
comments and blank lines are not rejected but *ignored*: counted by type (the sentence
type, e.g. ``GSV``, ``VDM``; the first 5 characters of a proprietary address, e.g.
``PGRME``; ``comment``; ``blank``).

The modules of the package, in the order a block goes through them:

* :mod:`~dracc.ingest.nmea.sentences`: sentence types, field counts, reject reasons;
* :mod:`~dracc.ingest.nmea.blocks`: a file cut into blocks of whole lines, one parsed;
* :mod:`~dracc.ingest.nmea.lines`: line bounds, chunk cuts, the tail of a line too long;
* :mod:`~dracc.ingest.nmea.engine_c`: the compiled kernel and the engine choice
  (:func:`parse_buffer`);
* :mod:`~dracc.ingest.nmea.engine_numpy` and :mod:`~dracc.ingest.nmea.numpy_core`: the
  numpy engine (pieces of bounded memory, and the vectorised parse of one);
* :mod:`~dracc.ingest.nmea.fields`: the field decoders of the numpy engine;
* :mod:`~dracc.ingest.nmea.ins_ais`: its decoders of ``$PASHR``, ``$PSXN`` and own-ship
  ``!AIVDO`` (the six-bit AIS armour);
* :mod:`~dracc.ingest.nmea.parsed`: :class:`ParsedBlock`, what a parse gives;
* :mod:`~dracc.ingest.nmea.pool`: the worker processes and their hand-over of blocks;
* :mod:`~dracc.ingest.nmea.assemble`: parsed blocks to canonical frames (and the
  ``$PSXN,20`` quality and the AIS UTC second applied to their records);
* :mod:`~dracc.ingest.nmea.groups`: the lines of TAG line groups (``g:``), joined to
  their group's first line (its source and time);
* :mod:`~dracc.ingest.nmea.state`: :class:`StreamState`, the running totals of a stream;
* :mod:`~dracc.ingest.nmea.reader`: the file reader (:func:`iter_nmea_blocks`,
  :func:`read_nmea`, :func:`check_readable`);
* :mod:`~dracc.ingest.nmea.sentence_stream`: sentences with an external time each
  (:class:`SentenceStream`, :func:`parse_sentences`).

The engine in use is ``dracc.ingest.nmea.engine_c.ENGINE`` (set it there, not here).
"""

from dracc.ingest.nmea.engine_c import engine_available, parse_buffer
from dracc.ingest.nmea.parsed import ParsedBlock
from dracc.ingest.nmea.reader import (
    BLOCK_BYTES,
    FIRST_BLOCK_BYTES,
    MAIN_FIRST_BLOCK_BYTES,
    PARALLEL_MIN_BYTES,
    check_readable,
    iter_nmea_blocks,
    read_nmea,
)
from dracc.ingest.nmea.sentence_stream import SentenceStream, parse_sentences
from dracc.ingest.nmea.sentences import (
    FIELD_COUNTS,
    GNSS_TALKERS,
    IGNORED,
    IGNORED_EXAMPLES,
    MAX_LINE_BYTES,
    NO_GNSS,
    NON_FATAL,
    REASONS,
    SENTENCES,
)
from dracc.ingest.nmea.state import Block, StreamState

__all__ = [
    "BLOCK_BYTES",
    "FIELD_COUNTS",
    "FIRST_BLOCK_BYTES",
    "GNSS_TALKERS",
    "IGNORED",
    "IGNORED_EXAMPLES",
    "MAIN_FIRST_BLOCK_BYTES",
    "MAX_LINE_BYTES",
    "NON_FATAL",
    "NO_GNSS",
    "PARALLEL_MIN_BYTES",
    "REASONS",
    "SENTENCES",
    "Block",
    "ParsedBlock",
    "SentenceStream",
    "StreamState",
    "check_readable",
    "engine_available",
    "iter_nmea_blocks",
    "parse_buffer",
    "parse_sentences",
    "read_nmea",
]
