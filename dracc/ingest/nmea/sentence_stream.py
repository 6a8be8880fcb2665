"""Sentences that come one by one with an external receive time and source key each
(MCAP raw NMEA messages, CSV columns of sentences), parsed chunk by chunk through one
time base (:class:`SentenceStream`, :func:`parse_sentences`)."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, TypeAlias

import numpy as np
import pandas as pd

from dracc.frames import MISSING_NS, FileResult, concat_blocks
from dracc.ingest.nmea.assemble import assemble, time_arrays
from dracc.ingest.nmea.engine_c import parse_buffer
from dracc.ingest.nmea.parsed import ParsedBlock
from dracc.ingest.nmea.sentences import MAX_LINE_BYTES
from dracc.ingest.nmea.state import StreamState
from dracc.ingest.timebase import drop_implausible_ext

if TYPE_CHECKING:  # config imports ingest.frames: no runtime import here
    from dracc.core.config import IngestConfig

#: a chunk waiting for its times: (parsed block, splitter of its times, first line,
#: message numbers, receive times)
_Held: TypeAlias = tuple[
    ParsedBlock,
    Callable[[np.ndarray], list[np.ndarray]],
    int,
    np.ndarray | None,
    np.ndarray | None,
]


class SentenceStream:
    """Sentences that arrive with an external receive time and source key each (MCAP raw
    NMEA messages: topic as source key), parsed chunk by chunk as they come.

    :meth:`add` a chunk, then :meth:`finish`; each returns the frames of the chunks whose
    times are resolved by then (a dict kind -> frame per chunk, in order), and
    :meth:`result` gives the bookkeeping.  One time base and one set of event counters
    run through all chunks, so the frames are those of one parse over everything, while
    only one chunk of text is held at a time.  Time-of-fix fields are anchored to the
    date of the given time (rule 1 of :mod:`dracc.ingest.timebase`).  ``line`` counts
    sentences from 1 over all chunks, or is the given ``numbers`` (message numbers).
    """

    def __init__(self, file: str, cfg: IngestConfig):
        self.file, self.cfg = file, cfg
        self.st = StreamState(file)
        self.st.events.gap_s = cfg.gap_s
        self.st.events.tolerance_s = cfg.backstep_tolerance_s
        self._held: list[_Held] = []

    def add(
        self,
        lines: Sequence[bytes],
        time_ns: np.ndarray,
        source: Sequence[str],
        numbers: np.ndarray | None = None,
        recv_ns: np.ndarray | None = None,
    ) -> list[dict[str, pd.DataFrame]]:
        """Parse one chunk.  ``time_ns``: each line's external time (the time base anchors
        its time of fix to it); ``recv_ns``: each line's receive time where it differs
        (an MCAP log time beside a message stamp), else ``time_ns`` is its receive time:
        the ``recv_ns`` of its records that have their own time of fix."""
        clean = [bytes(x).replace(b"\r", b"").replace(b"\n", b" ") for x in lines]
        t = np.asarray(time_ns, dtype=np.int64)
        src = np.asarray(list(source), dtype=object)
        if (
            not (len(t) == len(src) == len(clean))
            or (numbers is not None and len(numbers) != len(clean))
            or (recv_ns is not None and len(recv_ns) != len(clean))
        ):
            raise ValueError(
                f"SentenceStream: {len(clean)} lines, {len(t)} times, {len(src)} sources"
            )
        if not clean:
            return []
        pb = parse_buffer(
            b"\n".join(clean) + b"\n",
            ignore_checksum=self.cfg.ignore_checksum,
            at_eof=False,
            ext_line_ns=t,
            ext_line_source=src,
            max_line_bytes=int(getattr(self.cfg, "max_line_bytes", MAX_LINE_BYTES)),
        )
        nos = None if numbers is None else np.asarray(numbers, dtype=np.int64)
        st = self.st
        line0 = st.count_block(
            pb,
            self.cfg.strict,
            label="{path}: message {n}",
            number=None if nos is None else (lambda ln, first: int(nos[ln - 1])),
        )
        tod, date, ext, split = time_arrays(pb)
        recv = (
            None
            if recv_ns is None
            else drop_implausible_ext(np.asarray(recv_ns, dtype=np.int64))[0]
        )
        self._held.append((pb, split, line0, nos, recv))
        return self._release(st.timebase.feed(tod, date, ext))

    def finish(self) -> list[dict[str, pd.DataFrame]]:
        """The frames of the chunks still held (call once, after the last :meth:`add`)."""
        return self._release(self.st.timebase.finish())

    def _release(self, done: list[np.ndarray]) -> list[dict[str, pd.DataFrame]]:
        out = []
        for t in done:
            pb, split, line0, nos, recv = self._held.pop(0)
            frames = assemble(pb, split(t), self.st, self.file, line0, self.cfg)
            for f in frames.values():
                at = f["line"].to_numpy(np.int64) - line0  # the line of each record in the chunk
                if recv is not None:  # a record with a receive time gets the one given
                    has = f["recv_ns"].to_numpy() != MISSING_NS
                    f["recv_ns"] = np.where(has, recv[at], MISSING_NS)
                if nos is not None:
                    f["line"] = nos[at]
            out.append(frames)
        return out

    def result(self, frames: list[dict[str, pd.DataFrame]]) -> FileResult:
        """The :class:`FileResult` of ``frames`` (those returned, concatenated and sorted by
        time) with the counts, rejects, time events and notes of every chunk."""
        st = self.st
        return FileResult(
            path=self.file,
            format="nmea",
            frames=concat_blocks(frames),
            lines=st.lines,
            rejects=st.rejects,
            time_events=st.time_events(),
            notes=st.notes(),
            ignored=st.ignored,
            ignored_examples=st.ignored_examples,
        )


def parse_sentences(
    lines: Sequence[bytes], time_ns: np.ndarray, source: Sequence[str], file: str, cfg: IngestConfig
) -> FileResult:
    """:class:`SentenceStream` over one chunk: sentences with an external receive time
    and source key each, parsed at once."""
    stream = SentenceStream(file, cfg)
    frames = stream.add(lines, time_ns, source)
    return stream.result(frames + stream.finish())
