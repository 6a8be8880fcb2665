"""Files dracc does not read, named by what they are: one clear refusal instead of
thousands of lines counted as ``not_nmea``.

:func:`container` looks at the first bytes for a binary form's magic number (packet
captures, CAN logs of other tools, documents, archives, databases); :func:`text_form`,
asked only after every reader has declined the file, names text forms of other tools (a
PCAN-View trace, a table without a time column dracc knows, UTF-16 text)
and binary files that are no log at all.  Each answer is what the file is and what dracc
reads instead; :func:`dracc.ingest.detect_format` raises it as an IngestError.
"""

from __future__ import annotations

import re
import struct

__all__ = ["container", "text_form"]

_CAN_INSTEAD = (
    "dracc reads NMEA 2000 from candump text logs (candump -l), canboat/Actisense, "
    "YDWG-02 and iKonvert logs"
)
_MAGIC: dict[bytes, str] = {
    b"\xff\xd8\xff": "a JPEG image",
    b"\x89PNG": "a PNG image",
    b"%PDF": "a PDF document",
    b"SQLite format 3\x00": (
        "an SQLite database (dracc audit's state, or a ROS 2 .db3 bag: convert a bag to "
        "MCAP with `ros2 bag convert`)"
    ),
    b"PAR1": "a Parquet table (dracc's --out tables are results, not logs)",
    b"\xd0\xcf\x11\xe0\xa1\xb1\x1a\xe1": "an Excel .xls (or other MS Office) file: save the sheet as CSV",
    b"#ROSBAG V2.0": "a ROS 1 bag: convert it to MCAP (`mcap convert`) and give that",
    b"LOGG": f"a Vector BLF CAN log; {_CAN_INSTEAD}",
    b"7z\xbc\xaf\x27\x1c": "a 7-Zip archive: unpack it and give the logs inside",
    b"Rar!\x1a\x07": "a RAR archive: unpack it and give the logs inside",
    b"\x7fELF": "a program (ELF executable)",
}
#: pcap's magic in either byte order, microsecond or nanosecond times
_PCAP = {
    b"\xa1\xb2\xc3\xd4": ">",
    b"\xd4\xc3\xb2\xa1": "<",
    b"\xa1\xb2\x3c\x4d": ">",
    b"\x4d\x3c\xb2\xa1": "<",
}
#: link types (tcpdump.org/linktypes.html) a ship's capture holds
_LINKTYPES = {1: "Ethernet", 113: "Linux cooked", 227: "SocketCAN", 276: "Linux cooked v2"}


def _capture(what: str, linktype: int | None) -> str:
    link = _LINKTYPES.get(linktype or -1, f"link type {linktype}") if linktype else None
    if linktype == 227:
        return f"a {what} packet capture of a CAN bus (SocketCAN); {_CAN_INSTEAD}"
    return (
        f"a {what} packet capture{f' ({link})' if link else ''}; dracc reads what was "
        "received, not the packets: record NMEA 0183 over UDP with `dracc watch` or as text, "
        "or extract the payloads (tshark -T fields -e data.text)"
    )


def container(head: bytes) -> str | None:
    """What a binary file that is no log dracc reads is, from its first bytes, or None."""
    if head[:4] in _PCAP:
        order = _PCAP[head[:4]]
        linktype = struct.unpack(order + "I", head[20:24])[0] & 0xFFFF if len(head) >= 24 else None
        return _capture("pcap", linktype)
    if head[:4] == b"\x0a\x0d\x0d\x0a" and head[8:12] in (b"\x1a\x2b\x3c\x4d", b"\x4d\x3c\x2b\x1a"):
        order = ">" if head[8:12] == b"\x1a\x2b\x3c\x4d" else "<"
        linktype = None
        shb = struct.unpack(order + "I", head[4:8])[0]
        idb = head[shb : shb + 10]  # the interface description block follows the header
        if len(idb) == 10 and struct.unpack(order + "I", idb[:4])[0] == 1:
            linktype = struct.unpack(order + "H", idb[8:10])[0]
        return _capture("pcapng", linktype)
    for magic, what in _MAGIC.items():
        if head.startswith(magic):
            return what
    if head.startswith(b"PK\x03\x04"):
        if b"xl/" in head[:4096] or b"[Content_Types].xml" in head[:4096]:
            return "an Excel workbook (.xlsx, a ZIP archive): save the sheet as CSV"
        return "a ZIP archive: unpack it and give the logs inside"
    if len(head) > 262 and head[257:262] == b"ustar":
        return "a tar archive: unpack it and give the logs inside"
    return None


_SENTENCE = re.compile(rb"[$!][A-Z0-9]{2}[A-Z0-9]{2,4},")
_TRC_DATA = re.compile(r"^\s*\d+\)?\s+-?\d+(\.\d+)?\s+(\w+\s+)?[0-9A-Fa-f]{3,8}\s")


def _lines(head: bytes, n: int = 40) -> list[str]:
    return [ln for ln in head.decode("latin-1").splitlines()[:n] if ln.strip()]


def text_form(head: bytes) -> str | None:
    """What a file no reader took is, where dracc can name it, or None (read it as NMEA
    text, each bad line counted).  ``head``: its first bytes (up to 64 KiB)."""
    if head.startswith((b"\xff\xfe", b"\xfe\xff")) or (
        len(head) >= 8 and head[1:8:2] == b"\x00\x00\x00\x00" and head[0:8:2].isascii()
    ):
        return "UTF-16 text: convert it to UTF-8 (iconv -f UTF-16 -t UTF-8) and give that"
    lines = _lines(head)
    if not lines:
        return None
    comments = [ln for ln in lines if ln.startswith(";")]
    if comments and (
        any("$FILEVERSION" in ln or "PCAN" in ln or "Message Number" in ln for ln in comments)
        or sum(bool(_TRC_DATA.match(ln)) for ln in lines) >= max(2, len(lines) - len(comments) - 1)
    ):
        version = next(
            (ln.split("=", 1)[1].strip() for ln in comments if ln.startswith(";$FILEVERSION=")),
            None,
        )
        fmt = f"version {version}" if version else "version 1.0"
        return f"a PEAK PCAN-View CAN trace (.trc, {fmt}); {_CAN_INSTEAD}"
    if _SENTENCE.search(head):
        return None  # NMEA sentences in it: read them, count the rest
    start = head.lstrip(b"\xef\xbb\xbf \t\r\n")[:512].lower()
    if start.startswith((b"<?xml", b"<gpx", b"<kml", b"<html", b"<!doctype")):
        kind = next((k for k in ("gpx", "kml", "html") if f"<{k}".encode() in start), "xml")
        article = "a" if kind in ("gpx", "kml") else "an"
        return (
            f"{article} {kind.upper()} document, not a log of the sensors: dracc reads NMEA 0183, "
            "NMEA 2000, Signal K, gpsd JSON, CSV and MCAP logs"
        )
    table = _tab_table(lines)
    if table is not None:
        return table
    sample = head[:4096]
    binary = sum(b < 9 or 13 < b < 32 or b == 127 for b in sample)
    if binary > len(sample) // 10:
        return (
            f"a binary file with no NMEA sentence in it ({binary} of its first {len(sample)} "
            "bytes are not text)"
        )
    return None


_DELIMITERS = {"\t": "tab", ";": "semicolon", ",": "comma"}


def _tab_table(lines: list[str]) -> str | None:
    """A table (an instrument's export, tab-, semicolon- or comma-separated) the CSV
    reader cannot read: its header names no time column dracc knows.  A header is names,
    not numbers, and the rows below it have as many fields."""
    header = lines[0].lstrip("\ufeff\xef\xbb\xbf")
    if header.lstrip().startswith(("{", "[", "<", "#")):
        return None  # JSON, XML, comments: no table
    counts = {d: header.count(d) for d in _DELIMITERS}
    delim = max(counts, key=lambda d: counts[d])  # the first of the most frequent
    n = counts[delim]
    if n < 1:
        return None
    rows = lines[1:11]
    if not rows or sum(r.count(delim) == n for r in rows) < len(rows) / 2:
        return None
    cols = [c.strip().strip('"').strip() for c in header.split(delim)]
    if sum(bool(re.fullmatch(r"[-+\d.:/ TZ]*", c)) for c in cols) > len(cols) // 2:
        return None  # a row of numbers and times, not a header of names
    shown = ", ".join(repr(c) for c in cols[:12]) + (", ..." if len(cols) > 12 else "")
    if delim == ";":
        return (
            f"a semicolon-separated table with columns {shown}: save it as comma-separated "
            "CSV (decimal points) with a time column named time_utc, and map its columns in "
            "[ingest.quantities]"
        )
    what = "a tab-separated" if delim == "\t" else "a"
    return (
        f"{what} table with columns {shown}, none of them a time column dracc knows "
        "(time_utc, timestamp, date_time, 'Time (UTC)' ...): name its time column so, "
        'and map its columns in [ingest.quantities] (e.g. "Lat." = "lat_deg")'
    )
