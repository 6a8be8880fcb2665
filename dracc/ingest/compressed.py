"""Compressed logs and standard input: turned into a plain file the readers can map.

logrotate compresses every night's log and pipes are how people chain tools, so a log
may come as gzip, xz, bzip2 or zstd (told by its first bytes, never by its name) or as
``-`` (standard input).  Either is copied, 1 MiB at a time, into a private temporary
folder (memory stays flat whatever the size), and the copy is read like any file; the
readers then work on it with all their machinery (blocks, workers, the mapped hand-over).

A compressed stream that ends early or turns corrupt loses nothing before the damage:
what was decompressed is read, and a note says where the stream broke.  The folder is
removed when the reading is done, whatever happens.
"""

from __future__ import annotations

import bz2
import gzip
import lzma
import os
import shutil
import sys
import tempfile
import zlib
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import IO, BinaryIO, cast

from dracc.core.errors import IngestError

STDIN = "-"
PIECE_BYTES = 1 << 20
#: leave at least this much of the temporary folder's disk free (a bomb stops here)
MIN_FREE_BYTES = 512 << 20

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


def _copy(src: IO[bytes], dst: BinaryIO, where: str, folder: Path) -> int:
    """Copy ``src`` to ``dst`` a piece at a time; the bytes copied.  Stops with an
    IngestError before the temporary disk fills up."""
    n = 0
    read = getattr(src, "read1", src.read)  # what one step decompressed: lost to no error
    while piece := read(PIECE_BYTES):
        if n // PIECE_BYTES % 64 == 0 and shutil.disk_usage(folder).free < MIN_FREE_BYTES:
            raise IngestError(
                f"{where}: not enough free disk in {folder} to decompress it "
                f"({n} bytes written); decompress it elsewhere first"
            )
        dst.write(piece)
        n += len(piece)
    return n


def needs_copy(path: Path) -> bool:
    """True for ``-`` and for a compressed file: the readers need :func:`plain_copy`."""
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
def plain_copy(path: Path, notes: list[str]) -> Iterator[Path | None]:
    """A plain file for ``path`` when it is ``-`` or compressed (None when it is already a
    plain file): the decompressed copy, named as the log without its compression suffix,
    in a temporary folder removed on exit.  ``notes`` gets what the caller should say."""
    is_stdin = str(path) == STDIN
    head = b""
    if not is_stdin:
        if not path.is_file():  # never open a FIFO or a device here: the readers refuse them
            yield None
            return
        try:
            with path.open("rb") as fh:
                head = fh.read(8)
        except OSError:
            yield None  # the readers say what is wrong with it
            return
        if compression_of(head) is None:
            yield None
            return
    with tempfile.TemporaryDirectory(prefix="dracc-input-") as tmp:
        folder = Path(tmp)
        if is_stdin:
            stdin = folder / "stdin"
            with stdin.open("wb") as out:
                _copy(sys.stdin.buffer, out, "standard input", folder)
            with stdin.open("rb") as fh:
                head = fh.read(8)
            if compression_of(head) is None:
                yield stdin
                return
            source, name = stdin, "stdin"
        else:
            source, name = path, path.name
        kind = compression_of(head)
        assert kind is not None
        suffix = next(s for k, s in MAGIC.values() if k == kind)
        plain = folder / (name[: -len(suffix)] if name.endswith(suffix) else f"{name}.log")
        if plain == source:
            plain = folder / f"{name}.log"
        with source.open("rb") as raw, plain.open("wb") as out:
            stream = _opener(kind)(raw)
            try:
                size = _copy(stream, out, str(path), folder)
            except (EOFError, OSError, zlib.error, lzma.LZMAError, ValueError) as err:
                out.flush()
                size = out.tell()
                if size == 0:
                    raise IngestError(
                        f"{path}: not readable: a damaged {kind} stream that gives nothing ({err})"
                    ) from err
                notes.append(
                    f"the {kind} stream ends damaged after {size} decompressed bytes "
                    f"({err}); what came before is read"
                )
            finally:
                close = getattr(stream, "close", None)
                if close is not None:
                    close()
        if source != path:
            os.unlink(source)  # the stdin copy: only its decompressed form is needed now
        notes.append(f"{kind}-compressed, {size} bytes decompressed")
        yield plain
