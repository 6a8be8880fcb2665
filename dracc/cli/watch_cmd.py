"""``dracc watch SOURCE...``: listen to live sources (never transmitting), record what was
heard, keep a status document; the loop is :class:`dracc.pipeline.watch.Watch`.

The rolling statistics (:mod:`dracc.pipeline.watch_analysis`) run in one worker process.
When stdout is a TTY the status is drawn live (:mod:`dracc.report.watch_view`); otherwise
stderr has one line per finding raised or cleared (journald, a pipe).  SIGTERM or SIGINT end the watch
cleanly -- its normal end: the recording is flushed and closed, the final status
written, and the exit code is 0 (an interruption of ``analyze`` exits 130 because it
leaves nothing; here everything heard is kept).
"""

from __future__ import annotations

import json
import signal
import sys
import time
from pathlib import Path
from types import FrameType

import typer

from dracc.cli.app import app, err
from dracc.cli.options import ConfigOption, option_values
from dracc.report.watch_view import LiveView, finding_line


@app.command("watch")
def watch(
    sources: list[str] = typer.Argument(
        ..., help="udp://HOST:PORT, tcp://HOST:PORT, /dev/DEVICE or serial://, a growing file."
    ),
    record: Path | None = typer.Option(None, help="Record what is heard in daily files here."),
    status: Path | None = typer.Option(None, help="Rewrite this JSON status (dracc.watch/2)."),
    status_every: str = typer.Option("2s", help="How often the status is rewritten."),
    dropout: str = typer.Option(
        "10s", "--dropout", "--stale", help="A source silent this long raises 'dropout'."
    ),
    duration: str | None = typer.Option(None, help="Stop after this long (default: never)."),
    window: str = typer.Option("1h", help="The DR and integrity statistics are over this span."),
    analyse_every: str = typer.Option("30s", help="How often the window is analysed."),
    window_mb: float = typer.Option(256.0, min=1.0, help="The window holds at most this much."),
    analysis: bool = typer.Option(True, help="--no-analysis: only count, time and record."),
    config: Path | None = ConfigOption,
    baud: int | None = typer.Option(None, min=1, help="Serial: baud (default: spec's or 4800)."),
    join_multicast: bool = typer.Option(False, help="Join udp:// multicast groups (sends IGMP)."),
) -> None:
    """Listen to live NMEA sources (listening only): record every line with its receive
    time, count and time each source, raise and clear findings; until SIGTERM/SIGINT."""
    from dracc.core.config import load_config
    from dracc.core.durations import parse_duration_s
    from dracc.core.numbers import jsonable
    from dracc.ingest.live import Recorder, open_source
    from dracc.pipeline.watch import Watch
    from dracc.pipeline.watch_analysis import LiveAnalyser, worker_pool
    from dracc.report.write import StatusFile

    cfg = load_config(config)
    with option_values():
        every_s = parse_duration_s(status_every, "--status-every", "2s or 0.5s")
        dropout_s = parse_duration_s(dropout, "--dropout", "10s or 1min")
        run_s = parse_duration_s(duration, "--duration", "1h or 30s") if duration else None
        window_s = parse_duration_s(window, "--window", "1h or 6h")
        analyse_s = parse_duration_s(analyse_every, "--analyse-every", "30s or 1min")
    opened = []
    try:
        for spec in sources:
            opened.append(open_source(spec, baud=baud, allow_multicast=join_multicast))
    except BaseException:
        for s in opened:
            s.close()
        raise
    pool = worker_pool() if analysis else None
    analyser = (
        LiveAnalyser(cfg, window_s, analyse_s, int(window_mb * 2**20), pool) if analysis else None
    )
    recorder = Recorder(record) if record else None
    loop = Watch(opened, recorder, dropout_s=dropout_s, analyser=analyser)
    stop: list[int] = []
    view = LiveView() if sys.stdout.isatty() else None

    def on_signal(signum: int, frame: FrameType | None) -> None:
        stop.append(signum)

    previous = {s: signal.signal(s, on_signal) for s in (signal.SIGTERM, signal.SIGINT)}

    status_file = StatusFile(status) if status is not None else None

    def write_status() -> None:
        doc = jsonable(loop.status())
        said = status_file.write(json.dumps(doc, indent=1) + "\n") if status_file else None
        if said is not None:  # a status the disk refuses (full) stops nothing: said once
            err.print(f"warning: {said}", markup=False, highlight=False)
        if view is not None:
            view.show(doc)

    try:
        start = next_status = time.monotonic()
        while not stop and (run_s is None or time.monotonic() - start < run_s):
            for f in loop.step(0.1):
                if view is None:  # else the view shows them
                    err.print(finding_line(f), markup=False, highlight=False)
            if time.monotonic() >= next_status:
                write_status()
                next_status = time.monotonic() + every_s
    finally:
        loop.close()
        if pool is not None:
            pool.shutdown(wait=False, cancel_futures=True)
        if status_file is None or status_file.written:  # else the first write failed
            write_status()
        if view is not None:
            view.stop()
        for signum, handler in previous.items():
            signal.signal(signum, handler)
