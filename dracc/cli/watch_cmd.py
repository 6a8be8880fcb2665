"""``dracc watch SOURCE...``: listen to live sources (never transmitting), record what was
heard, keep a status document; the loop is :class:`dracc.pipeline.watch.Watch`.

stderr has one line per finding raised or cleared.  SIGTERM or SIGINT end the watch
cleanly -- its normal end: the recording is flushed and closed, the final status
written, and the exit code is 0 (an interruption of ``analyze`` exits 130 because it
leaves nothing; here everything heard is kept).
"""

from __future__ import annotations

import json
import signal
import time
from pathlib import Path
from types import FrameType

import typer

from dracc.cli.app import app, err
from dracc.cli.options import option_values


@app.command("watch")
def watch(
    sources: list[str] = typer.Argument(
        ..., help="udp://HOST:PORT, tcp://HOST:PORT, file:PATH or a growing file."
    ),
    record: Path | None = typer.Option(None, help="Record what is heard in daily files here."),
    status: Path | None = typer.Option(None, help="Rewrite this JSON status (dracc.watch/1)."),
    status_every: str = typer.Option("2s", help="How often the status is rewritten."),
    stale: str = typer.Option("10s", help="A source silent this long raises 'stale'."),
    duration: str | None = typer.Option(None, help="Stop after this long (default: never)."),
) -> None:
    """Listen to live NMEA sources (listening only): record every line with its receive
    time, count and time each source, raise and clear findings; until SIGTERM/SIGINT."""
    from dracc.core.atomic import write_text
    from dracc.core.durations import parse_duration_s
    from dracc.ingest.live import Recorder, open_source
    from dracc.pipeline.watch import Watch

    with option_values():
        every_s = parse_duration_s(status_every, "--status-every", "2s or 0.5s")
        stale_s = parse_duration_s(stale, "--stale", "10s or 1min")
        run_s = parse_duration_s(duration, "--duration", "1h or 30s") if duration else None
    opened = []
    try:
        for spec in sources:
            opened.append(open_source(spec))
    except BaseException:
        for s in opened:
            s.close()
        raise
    loop = Watch(opened, Recorder(record) if record else None, stale_s=stale_s)
    stop: list[int] = []

    def on_signal(signum: int, frame: FrameType | None) -> None:
        stop.append(signum)

    previous = {s: signal.signal(s, on_signal) for s in (signal.SIGTERM, signal.SIGINT)}

    def write_status() -> None:
        if status is not None:
            write_text(status, json.dumps(loop.status(), indent=1) + "\n")

    try:
        start = next_status = time.monotonic()
        while not stop and (run_s is None or time.monotonic() - start < run_s):
            for f in loop.step(0.1):
                err.print(
                    f"{f['cleared_utc'] or f['raised_utc']} {f['check']} {f['event']}: "
                    f"{f['message']}",
                    markup=False,
                    highlight=False,
                )
            if time.monotonic() >= next_status:
                write_status()
                next_status = time.monotonic() + every_s
    finally:
        loop.close()
        write_status()
        for signum, handler in previous.items():
            signal.signal(signum, handler)
