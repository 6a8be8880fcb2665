"""The public reader: an MCAP log into a :class:`~dracc.frames.FileResult` -- the
container walk (:mod:`~dracc.ingest.mcap.container`) feeding the channel decoding
(:mod:`~dracc.ingest.mcap.decoding`), whose frames are assembled, merged and summed up
in notes and counts here."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np

from dracc.core.config import IngestConfig
from dracc.core.errors import IngestError
from dracc.frames import FileResult, Rejects
from dracc.ingest.csv_quantities import add_rejects, check_declared
from dracc.ingest.mcap.channels import channel_notes
from dracc.ingest.mcap.container import ContainerWalk
from dracc.ingest.mcap.decoding import ChannelDecoding
from dracc.ingest.mcap.json_messages import json_flush
from dracc.ingest.memory import trim_heap


def read_mcap(
    path: str | Path, cfg: IngestConfig, progress: Callable[[int], object] | None = None
) -> FileResult:
    """Read an MCAP log into canonical frames (see the :mod:`dracc.ingest.mcap` doc);
    ``progress`` is told the file's size in bytes once it is read (the readers' signature)."""
    declared = dict(getattr(cfg, "quantities", {}) or {})
    check_declared(declared, str(path))
    path = Path(path)
    rejects = Rejects()
    decoding = ChannelDecoding(str(path), cfg, rejects)
    walk = ContainerWalk(path, cfg, rejects, [], decoding)
    walk.run()
    result = _result(walk, decoding)
    if progress is not None:
        progress(path.stat().st_size)
    return result


def _result(walk: ContainerWalk, decoding: ChannelDecoding) -> FileResult:
    """What the file gave: the remaining queues and pending columns decoded, the stores
    merged into frames, the notes and counts of the walk, the channels and the stamps."""
    file, cfg, channels, frames = decoding.file, decoding.cfg, decoding.channels, decoding.frames
    trim_heap()
    for ch in channels.values():
        json_flush(decoding, ch)
        frames.to_pieces(ch)
    trim_heap()
    res = FileResult(
        path=file,
        format="mcap",
        frames={},
        lines=walk.msg_no,
        rejects=decoding.rejects,
        notes=[],
    )
    frames.nmea_flush()
    if frames.nmea is not None:
        frames.nmea_store(frames.nmea.finish())
        nres = frames.nmea.result([])
        res.rejects.merge(nres.rejects)
        res.ignored.update(nres.ignored)  # raw sentences dracc does not use: GSV, VDM ...
        res.ignored_examples.update(nres.ignored_examples)
        res.time_events = nres.time_events
        res.notes.extend(nres.notes)
    rolled = frames.rollover_note()
    if rolled is not None:  # counted like the NMEA time base's (implausible_dates)
        res.time_events.implausible_dates += frames.rollovers
        res.time_events.decisions.append(rolled)
    for kind in list(frames.stores):
        store = frames.stores.pop(kind)
        if store.total:
            res.frames[kind] = store.frame()
        del store
    trim_heap()
    res.notes[:0] = walk.notes + channel_notes(channels.values())
    for ch in channels.values():  # valid messages on channels dracc does not decode
        n = ch.messages - ch.bad
        if ch.mode in ("skip", "pending") and n > 0:
            res.ignored[ch.type_name] += n
    if decoding.bad_stamps:
        res.notes.append(
            f"{file}: {decoding.bad_stamps} message stamp(s) out of range; their log time was used"
        )
    if decoding.orphans:
        add_rejects(
            res.rejects,
            "message on an undeclared channel",
            file,
            np.zeros(1, np.int64),
            [f"{decoding.orphans} messages"],
        )
        res.rejects.counts["message on an undeclared channel"] += decoding.orphans - 1
    if not res.frames or res.records == 0:
        if not channels:
            res.notes.append(
                f"{file}: valid MCAP with no channels and {walk.msg_no} messages: nothing to read"
            )
        else:
            res.notes.append(
                f"{file}: no navigation data in {len(channels)} channel(s), "
                f"{walk.msg_no} message(s)"
            )
    if cfg.strict and res.rejects.total:
        reason, ex = next(iter(res.rejects.examples.items()))
        raise IngestError(f"{ex[0][0]}: message {ex[0][1]}: {reason}: {ex[0][2]!r} (--strict)")
    return res
