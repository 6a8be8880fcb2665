"""Bounded decompression of MCAP chunks (zstd, lz4, none): at most ``_PIECE`` bytes of
compressed data read and of uncompressed data produced at a time, and never more than
the chunk's declared size (a decompression bomb raises :class:`_TooLarge`)."""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from typing import BinaryIO

_PIECE = 1 << 20


class _TooLarge(Exception):
    """A chunk inflating beyond its declared size (``n`` bytes had come out)."""

    def __init__(self, n: int) -> None:
        super().__init__(f"inflates beyond {n:,} bytes")
        self.n = n


class _Slice:
    """``n`` bytes of an open file from offset ``at``, read as a stream."""

    def __init__(self, fh: BinaryIO, at: int, n: int) -> None:
        self.fh, self.pos, self.left = fh, at, max(n, 0)

    def read(self, k: int = -1) -> bytes:
        k = self.left if k is None or k < 0 else min(k, self.left)
        if k <= 0:
            return b""
        self.fh.seek(self.pos)
        b = self.fh.read(k)
        self.pos += len(b)
        self.left = 0 if not b else self.left - len(b)
        return b


def _inflate(fh: BinaryIO, at: int, n: int, comp: str, limit: int) -> Iterator[bytes]:
    """Yield the uncompressed bytes of the ``n`` compressed bytes at file offset ``at``,
    at most ``_PIECE`` at a time; raise :class:`_TooLarge` as soon as more than ``limit``
    bytes have come out.  The memory is bounded whatever the data says: zstd through a
    stream reader asked for ``_PIECE`` bytes at a time (``ZstdDecompressor.decompress``
    sizes its output by the frame header, not by ``max_output_size``, and a decompressobj
    returns all it can: 98 kB of zstd gave 3 GB at once), lz4 frames with ``max_length``.
    Damaged data raises the library's own error."""
    src = _Slice(fh, at, n)
    pieces: Iterator[bytes]
    if comp == "zstd":
        import zstandard

        reader = zstandard.ZstdDecompressor().stream_reader(
            src,  # type: ignore[arg-type]  # any object with read() will do
            read_size=_PIECE,
            read_across_frames=True,
            closefd=False,
        )
        pieces = iter(lambda: reader.read(_PIECE), b"")
    elif comp == "lz4":
        pieces = _lz4_pieces(src)
    else:
        pieces = iter(lambda: src.read(_PIECE), b"")
    total = 0
    for out in pieces:
        total += len(out)
        if total > limit:
            raise _TooLarge(total)
        yield out


def _lz4_pieces(src: _Slice) -> Iterator[bytes]:
    """lz4 frames (one or several in a row) decompressed ``_PIECE`` bytes at a time."""
    import lz4.frame

    dec = lz4.frame.LZ4FrameDecompressor()
    while True:
        data = src.read(_PIECE)
        if not data:
            return
        while True:
            out = dec.decompress(data, max_length=_PIECE)
            data = b""
            if out:
                yield out
            if dec.eof:  # a frame ended: the next one may follow in the same input
                data = dec.unused_data or b""
                dec = lz4.frame.LZ4FrameDecompressor()
                if data:
                    continue
                break
            if dec.needs_input or not out:  # (no output and no frame end: more input needed)
                break


def _guard(pieces: Iterable[bytes], box: list[BaseException]) -> Iterator[bytes]:
    """The pieces until the first error, which is put in ``box`` (decompression errors
    are the libraries' own types; a bomb is :class:`_TooLarge`)."""
    try:
        yield from pieces
    except Exception as err:  # zstd/lz4 raise their own error types on damaged data
        box.append(err)


def _drain(parts: list[bytes]) -> Iterator[bytes]:
    """The items of ``parts`` in order, each let go of once handed out."""
    parts.reverse()
    while parts:
        yield parts.pop()
