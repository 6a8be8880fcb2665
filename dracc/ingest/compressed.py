"""Compressed logs and standard input: decompressed as they are read, or copied within a cap.

logrotate compresses every night's log and pipes are how people chain tools, so a log
may come as gzip, xz, bzip2 or zstd (told by its first bytes, never by its name) or as
``-`` (standard input).

- NMEA text (with whatever NMEA 2000 lines it holds) is decompressed as it is read, a
  piece at a time (:meth:`Packed.open`): no copy on disk, memory flat whatever the size.
- The readers that map or seek a file (MCAP, CSV, Signal K, gpsd JSON, NMEA 2000 logs)
  read a decompressed copy (:meth:`Packed.copy`) of at most ``[ingest] temp_cap_mb``
  (4096 MiB), leaving :data:`MIN_FREE_BYTES` of its disk free; past either, one line
  says so (exit 3).
- Standard input is saved first (at most ``temp_cap_mb`` too), then read as a file.
- A log that decompresses to more than ``[ingest] max_inflate_ratio`` times its size
  (200; never less than :data:`INFLATE_FLOOR`) stops the read with one line (exit 3):
  a decompression bomb (a 9 KB bzip2 of zeros inflates to 12 GB) is counted, not held.

Copies live in a folder of the temporary directory named ``dracc-input-<pid>-...``,
removed when the reading is done, whatever happens; one left by a run that was killed
(SIGKILL cannot be caught) is removed by the next run
(:func:`dracc.ingest.memory.pid_folder`).  A compressed stream that ends early or turns
corrupt loses nothing before the damage: what was decompressed is read, and a note says
where the stream broke.
"""

from __future__ import annotations

import bz2
import gzip
import lzma
import shutil
import sys
import zlib
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, TYPE_CHECKING, Any, BinaryIO, cast

from dracc.core.errors import IngestError
from dracc.ingest.memory import pid_folder

if TYPE_CHECKING:
    from dracc.core.config import IngestConfig

STDIN = "-"
PIECE_BYTES = 1 << 20
#: leave at least this much of the temporary folder's disk free
MIN_FREE_BYTES = 512 << 20
#: a log may always decompress to this much, whatever its ratio
INFLATE_FLOOR = 256 << 20
#: the first bytes of a decompressed log that tell its format
HEAD_BYTES = 65536
INPUT_PREFIX = "dracc-input-"
#: what NMEA text compresses to, about (gzip 5:1, xz 7:1): a compressed log's guessed size
TYPICAL_RATIO = 5

#: first bytes -> (name, suffix the decompressed copy drops)
MAGIC: dict[bytes, tuple[str, str]] = {
    b"\x1f\x8b": ("gzip", ".gz"),
    b"\xfd7zXZ\x00": ("xz", ".xz"),
    b"BZh": ("bzip2", ".bz2"),
    b"\x28\xb5\x2f\xfd": ("zstd", ".zst"),
}


def compression_of(head: bytes) -> str | None:
    """'gzip', 'xz', 'bzip2' or 'zstd' for a stream starting with ``head``, else None."""
    for magic, (name, _) in MAGIC.items():
        if head.startswith(magic):
            return name
    return None


def _opener(name: str) -> Callable[[BinaryIO], IO[bytes]]:
    if name == "gzip":
        return lambda raw: cast(IO[bytes], gzip.GzipFile(fileobj=raw, mode="rb"))
    if name == "xz":
        return lambda raw: lzma.LZMAFile(raw, mode="rb")
    if name == "bzip2":
        return lambda raw: bz2.BZ2File(raw, mode="rb")
    import zstandard

    return lambda raw: zstandard.ZstdDecompressor().stream_reader(raw, read_across_frames=True)


def _damage() -> tuple[type[BaseException], ...]:
    """What a decompressor raises on a damaged or cut stream."""
    kinds: tuple[type[BaseException], ...] = (EOFError, OSError, zlib.error, lzma.LZMAError)
    zstd = sys.modules.get("zstandard")
    return (*kinds, ValueError) if zstd is None else (*kinds, ValueError, zstd.ZstdError)


class Inflating:
    """A compressed log decompressed as it is read (``read(n)``, a file-like object for
    the readers): past ``limit`` decompressed bytes an IngestError; a damaged stream
    ends where the damage is (said in ``notes``, where given, as is the size at the
    end); one giving nothing at all is an IngestError."""

    def __init__(self, packed: Packed, notes: list[str] | None) -> None:
        self.packed = packed
        self.notes = notes
        self.raw = packed.source.open("rb")
        self.stream = _opener(packed.kind or "")(cast(BinaryIO, self.raw))
        self._read = getattr(self.stream, "read1", self.stream.read)  # what one step gave
        self.n = 0
        self.ended = False

    def read(self, n: int = -1) -> bytes:
        if self.ended:
            return b""
        kind = self.packed.kind
        try:
            piece = self._read(n if n > 0 else PIECE_BYTES)
        except _damage() as err:
            self.ended = True
            if self.n == 0:
                raise IngestError(
                    f"{self.packed.given}: not readable: a damaged {kind} stream that gives "
                    f"nothing ({err})"
                ) from err
            self._say(
                f"the {kind} stream ends damaged after {self.n} decompressed bytes ({err}); "
                "what came before is read"
            )
            return b""
        if not piece:
            self.ended = True
            return b""
        self.n += len(piece)
        if self.n > self.packed.limit:
            raise IngestError(self.packed.bomb())
        return piece

    def _say(self, note: str) -> None:
        if self.notes is not None:
            self.notes.append(note)

    def close(self) -> None:
        if self.ended:
            self._say(f"{self.packed.kind}-compressed, {self.n} bytes decompressed")
            self.notes = None
        self.stream.close()
        self.raw.close()

    def __enter__(self) -> Inflating:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


@dataclass
class Packed:
    """A log given compressed, or as ``-``: ``source`` holds its bytes (the log itself,
    or standard input saved in ``folder``), ``kind`` its compression (None: standard
    input that was not compressed); it may decompress to ``limit`` bytes."""

    given: Path
    source: Path
    kind: str | None
    folder: Path
    limit: int
    ratio: float
    temp_cap: int
    notes: list[str] = field(default_factory=list)
    _streams: list[Inflating] = field(default_factory=list)

    def open(self) -> IO[bytes]:
        """The log, decompressed as it is read; the first stream opened says what it
        found in ``notes``."""
        if self.kind is None:
            return self.source.open("rb")
        s = Inflating(self, self.notes if not self._streams else None)
        self._streams.append(s)
        return cast(IO[bytes], s)

    @property
    def size_hint(self) -> int | None:
        """The size the log may decompress to, as guessed for the NMEA reader (whether
        workers parse it, where they hand blocks over): :data:`TYPICAL_RATIO` times its
        compressed size; None for standard input that was not compressed."""
        return None if self.kind is None else TYPICAL_RATIO * self.source.stat().st_size

    def head(self) -> bytes:
        """The first :data:`HEAD_BYTES` of the log (what tells its format)."""
        if self.kind is None:
            with self.source.open("rb") as fh:
                return fh.read(HEAD_BYTES)
        with Inflating(self, None) as s:
            parts, n = [], 0
            while n < HEAD_BYTES and (piece := s.read(HEAD_BYTES - n)):
                parts.append(piece)
                n += len(piece)
        return b"".join(parts)

    def progress(self, progress: Callable[[int], object] | None) -> Callable[[int], object] | None:
        """``progress`` told in bytes of the log as given (its compressed bytes read by
        the last stream opened) when the reader tells decompressed bytes; nothing for
        standard input, whose size nobody knew."""
        if progress is None or str(self.given) == STDIN:
            return None
        told = [0]

        def tell(_n: int) -> None:
            at = self._streams[-1].raw.tell() if self._streams else 0
            progress(max(0, at - told[0]))
            told[0] = max(told[0], at)

        return tell

    def bomb(self) -> str:
        """The error of a log that decompresses past its limit."""
        return (
            f"{self.given}: decompresses to more than {self.limit:,} bytes, over [ingest] "
            f"max_inflate_ratio = {self.ratio:g} times its {self.source.stat().st_size:,} "
            "bytes (a decompression bomb?); if it is a real log, decompress it first or "
            "raise max_inflate_ratio"
        )

    @contextmanager
    def copy(self) -> Iterator[Path]:
        """A plain file of the log for a reader that maps or seeks it: standard input's
        saved copy as it is, a compressed log decompressed into ``folder`` (named as the
        log without its compression suffix), at most ``temp_cap`` bytes."""
        if self.kind is None:
            yield self.source
            return
        suffix = next(s for k, s in MAGIC.values() if k == self.kind)
        name = self.given.name if str(self.given) != STDIN else "stdin"
        plain = self.folder / (name[: -len(suffix)] if name.endswith(suffix) else f"{name}.log")
        with self.open() as src, plain.open("wb") as out:
            _copy(src, out, str(self.given), self.folder, self.temp_cap)
        try:
            yield plain
        finally:
            plain.unlink(missing_ok=True)


def _copy(src: IO[bytes], dst: BinaryIO, where: str, folder: Path, cap: int) -> int:
    """Copy ``src`` to ``dst`` a piece at a time; the bytes copied.  Stops with an
    IngestError past ``cap`` bytes or before the temporary disk fills up."""
    n = 0
    read = getattr(src, "read1", src.read)  # what came (a pipe's writer may pause)
    while piece := read(PIECE_BYTES):
        if n + len(piece) > cap:
            raise IngestError(
                f"{where}: its temporary copy would pass [ingest] temp_cap_mb = {cap >> 20} "
                f"MiB (in {folder.parent}); decompress it elsewhere first or raise temp_cap_mb"
            )
        if n // PIECE_BYTES % 64 == 0 and shutil.disk_usage(folder).free < MIN_FREE_BYTES:
            raise IngestError(
                f"{where}: not enough free disk in {folder.parent} for its temporary copy "
                f"({n} bytes written); decompress it elsewhere first"
            )
        dst.write(piece)
        n += len(piece)
    return n


def needs_copy(path: Path) -> bool:
    """True for ``-`` and for a compressed file: the readers take it through
    :func:`unpacked`."""
    if str(path) == STDIN:
        return True
    if not path.is_file():  # never open a FIFO or a device here: the readers refuse them
        return False
    try:
        with path.open("rb") as fh:
            return compression_of(fh.read(8)) is not None
    except OSError:
        return False


@contextmanager
def unpacked(path: Path, cfg: IngestConfig | Any) -> Iterator[Packed | None]:
    """The :class:`Packed` log of ``path`` when it is ``-`` or compressed (None when it is
    a plain file, or no file: its reader says what is wrong with it), in a temporary
    folder of this process removed on exit.  ``cfg``: ``max_inflate_ratio`` and
    ``temp_cap_mb`` of ``[ingest]``."""
    if not needs_copy(path):
        yield None
        return
    ratio = float(getattr(cfg, "max_inflate_ratio", 200))
    cap = int(getattr(cfg, "temp_cap_mb", 4096)) << 20
    with pid_folder(INPUT_PREFIX) as tmp:
        folder = Path(tmp)
        source = path
        if str(path) == STDIN:
            source = folder / "stdin"
            with source.open("wb") as out:
                _copy(sys.stdin.buffer, out, "standard input", folder, cap)
        with source.open("rb") as fh:
            kind = compression_of(fh.read(8))
        size = source.stat().st_size
        yield Packed(path, source, kind, folder, max(INFLATE_FLOOR, int(ratio * size)), ratio, cap)
