"""MCAP voyage logs into canonical frames: streamed, channel-wise decoding, damage recovered.

Modules
    :mod:`~dracc.ingest.mcap.reader` (:func:`read_mcap`) runs the
    :mod:`~dracc.ingest.mcap.container` walk (records and chunks, :mod:`~.records`,
    bounded decompression in :mod:`~.inflate`) into the per-channel
    :mod:`~dracc.ingest.mcap.decoding` (:mod:`~.channels`; one decoder per message
    encoding: :mod:`~.ros2_messages` over :mod:`~.cdr`, :mod:`~.json_messages`,
    :mod:`~.protobuf_messages`), whose columns :mod:`~.assembly` turns into frame
    pieces kept and merged by :mod:`~.columns`.

Reading
    The file is read front to back as a stream of MCAP records (spec:
    https://mcap.dev/spec), one record at a time, with the record parsers, opcodes and
    compression of the official ``mcap`` package; the summary and the indexes are not
    needed, so indexed and non-indexed files read alike.  dracc decompresses every chunk
    itself (zstd, lz4, none; the ``mcap`` package's own decompression is not bounded):
    its compressed bytes are read in 1 MiB pieces and at most 1 MiB comes out at a time,
    never more than the chunk's declared size (:mod:`dracc.ingest.mcap.inflate`).  A
    complete chunk (at most ``[ingest] max_chunk_bytes``) is decompressed whole and its
    CRC checked before its messages are decoded (through its message index, or walked
    in windows of about 8 MiB); a chunk cut off by the end of the file is streamed and
    walked in windows.
Memory
    Besides the frames it returns, the reader holds a window, the decoded columns of at
    most 100 000 records (all channels) and JSON texts of at most 50 000 messages; frame
    pieces go into sorted runs in their own memory mappings
    (:class:`dracc.ingest.mcap.columns._KindStore`) that are merged step by step into
    the output columns at the end, each run unmapped when used up; the C heap and pyarrow's pool are trimmed every 200 000 records.  So the
    working memory does not grow with the file (``benchmarks/bench_mcap.py``).  Raw NMEA
    text is parsed 100 000 sentences at a time (:class:`dracc.ingest.nmea.SentenceStream`,
    one time base through all chunks), its frames going into the stores like the others.
Decoding
    Messages are grouped by channel within each window and decoded together:
    ROS 2 CDR onto numpy structured arrays (:mod:`dracc.ingest.mcap.cdr`), JSON with one
    pyarrow parse per channel and window, protobuf with the classes generated from the
    FileDescriptorSet embedded in the schema (``mcap-protobuf-support``).
Message types understood (field -> quantity; see ``docs/mcap-csv.md``)
    - ``sensor_msgs/msg/NavSatFix`` (CDR) and ``foxglove.LocationFix`` (JSON, protobuf):
      latitude/longitude in degrees, altitude in metres; NavSatFix ``status.status``
      -1/0/1/2 -> fix quality 0/1/2/4.
    - ``geometry_msgs/msg/QuaternionStamped``, ``sensor_msgs/msg/Imu`` (CDR): true
      heading from the ENU orientation (REP 103): ``heading = pi/2 - yaw``,
      ``yaw = atan2(2(wz + xy), 1 - 2(y^2 + z^2))``.
    - any message (CDR, JSON, protobuf) whose fields are quantity names with units
      (``heading_deg``, ``stw_kn``, ``sog_mps`` ...; :mod:`dracc.ingest.csv_quantities`),
      e.g. the documented ``dracc_msgs/msg/*`` and ``dracc.*`` types dracc writes.
    - raw NMEA 0183: ``nmea_msgs/msg/Sentence`` (CDR), ``std_msgs/msg/String`` holding
      sentences, JSON ``{"sentence": ...}``, protobuf messages with a bytes/string field
      holding sentences (keelson ``TimestampedBytes``), and schema-less text channels;
      these go through :func:`dracc.ingest.nmea.parse_sentences`.
Times
    The message's own stamp where it has one (``header.stamp``, ``timestamp``,
    ``time_ns``) and it is not zero, else the MCAP log time; both int64 ns UTC.  A record
    timed by its own stamp has the log time as ``recv_ns`` (its receive time; none where
    the log time is implausible, e.g. 0); one timed by its log time has ``MISSING_NS``.
    Raw sentences are anchored to the message's stamp (else its log time) and have the
    log time as ``recv_ns`` where they carry a time of fix (the NMEA rule).  A stamp
    1024·k GPS weeks (k = 1, 2; within a day) behind its log time is a receiver's
    week-number rollover: the record's time is repaired (+1024·k weeks), counted in
    ``implausible_dates`` and said in a decision naming the first message
    (:meth:`~dracc.ingest.mcap.assembly.FrameAssembly.add_part`).
Source keys
    The topic without its leading '/' and without a trailing standard leaf (``fix``,
    ``position``, ``heading``, ``velocity``, ``water``, ``distance``, ``rot``, ``nmea``,
    ``sentence``): ``/ins2/fix`` and ``/ins2/heading`` are both source ``ins2``.
    :func:`topic_role` suggests a role from the key (``ins2`` -> ins2, ``gyro`` ->
    compass, ``log`` -> log, ``gps``/``gnss`` -> gnss).  A topic named verbatim in
    ``[ingest.sources]`` is its own source key (``"/nav/a/fix" = "ins1"``).
Damage
    A file that ends early yields every complete message before the cut, and a note
    says at which byte it ended; a damaged chunk keeps its messages before the damage;
    a chunk that inflates beyond its declared size or declares more than
    ``max_chunk_bytes`` (a decompression bomb: ``chunk_too_large``), or whose records do
    not match its CRC (``chunk_crc``), is counted and none of its messages read, the rest
    of the file is; a record outside chunks over the cap is ``record_too_large``; the data
    section and summary CRCs are checked where the writer computed them
    (``data_section_crc``, ``summary_crc``); names from the file (topics, schema names)
    are kept as data, control characters included;
    unusable channels (unknown encoding, no navigation fields) are listed in the notes
    with their message counts, and their messages (valid input dracc does not use) are
    counted in ``FileResult.ignored`` by schema name, never rejected; so are raw
    sentences of types dracc does not read, by sentence type (``GSV``, ``VDM``).  A valid file without navigation data returns empty
    frames and a note saying so (the caller raises InsufficientDataError when no input
    at all holds data); a file that is not MCAP raises IngestError.
"""

from dracc.ingest.mcap.cdr import CdrError, compile_schema, encode_fixed
from dracc.ingest.mcap.channels import LEAVES, topic_role, topic_source
from dracc.ingest.mcap.reader import read_mcap
from dracc.ingest.mcap.records import MAGIC

__all__ = [
    "LEAVES",
    "MAGIC",
    "CdrError",
    "compile_schema",
    "encode_fixed",
    "read_mcap",
    "topic_role",
    "topic_source",
]
