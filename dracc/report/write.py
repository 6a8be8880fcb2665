"""Writing an analysis's reports: the terminal summary or the JSON on stdout, then the JSON,
HTML, table and export (GPX, KML, GeoJSON, MCAP) files, all renamed into place together; a
write error becomes one line."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING

from rich.console import Console

from dracc.core import atomic
from dracc.core.errors import DraccError, OutputError
from dracc.report.output import STDOUT, json_text

if TYPE_CHECKING:  # the pipeline loads when the command runs, not when the CLI starts
    from dracc.pipeline.results import Analysis


@contextmanager
def writing(target: object) -> Iterator[None]:
    """OSError while writing ``target`` -> one line naming it: an
    :class:`~dracc.core.errors.OutputError` (exit 6) for what the disk or the folder
    refused (:func:`dracc.core.atomic.output_error`), else a :class:`DraccError`; a closed
    stdout pipe passes."""
    try:
        yield
    except BrokenPipeError:
        raise  # stdout closed by the reader (e.g. `| head`): not an error of ours
    except OSError as e:
        fault = atomic.output_error(target, e)
        if fault is not None:
            raise fault from e
        detail = f"{e.filename}: {e.strerror}" if e.filename and e.strerror else str(e)
        raise DraccError(f"cannot write {target}: {detail}") from e


def write_reports(
    result: Analysis,
    console: Console,
    json_path: str | None,
    html_path: Path | None,
    out_dir: Path | None,
    *,
    gpx_path: Path | None = None,
    kml_path: Path | None = None,
    geojson_path: Path | None = None,
    mcap_path: Path | None = None,
) -> list[str]:
    """The terminal summary on ``console`` (or the JSON there, for ``json_path`` '-'), then
    the report files: each written in full to a temporary file and all renamed together at
    the end (:func:`dracc.core.atomic.together`), so that an interrupt while the plots are
    drawn leaves every earlier report as it was, not a new JSON beside an old HTML.  The
    exports join the set: GPX, KML and GeoJSON (:mod:`dracc.report.exports`) and the MCAP
    for Foxglove (:func:`dracc.report.mcap_export.write_mcap_export`).

    Returns the lines that say what was written (``wrote report.json``)."""
    from dracc.report import html as html_report
    from dracc.report import json_report, tables, terminal

    said = []
    with writing("the reports"), atomic.together():
        if json_path == STDOUT:
            console.file.write(json_text(json_report.to_dict(result), ascii_only=True))
            console.file.flush()
        else:
            terminal.print_summary(result, console)
            if json_path:
                with writing(json_path):
                    json_report.write_json(result, json_path)
                said.append(f"wrote {json_path}")
        if html_path is not None:
            with writing(html_path):
                html_report.write_html(result, html_path)
            said.append(f"wrote {html_path}")
        if out_dir is not None:
            with writing(out_dir):
                written = tables.write_tables(result, out_dir)
            said.append(
                f"wrote {len(written)} tables to {out_dir}"
                if written
                else f"no tables to write to {out_dir} (no DR and no deviation statistics)"
            )
        for path, write in _exports(gpx_path, kml_path, geojson_path, mcap_path):
            with writing(path):
                write(result, path)
            said.append(f"wrote {path}")
    return said


def _exports(
    gpx: Path | None, kml: Path | None, geojson: Path | None, mcap: Path | None
) -> list[tuple[Path, Callable[[Analysis, Path], None]]]:
    """(path, writer) of each export asked for, its module loaded only then."""
    todo: list[tuple[Path, Callable[[Analysis, Path], None]]] = []
    if gpx is not None or kml is not None or geojson is not None:
        from dracc.report import exports

        for path, fn in (
            (gpx, exports.write_gpx),
            (kml, exports.write_kml),
            (geojson, exports.write_geojson),
        ):
            if path is not None:
                todo.append((path, fn))
    if mcap is not None:
        from dracc.report.mcap_export import write_mcap_export

        todo.append((mcap, write_mcap_export))
    return todo


class StatusFile:
    """A document rewritten now and then (``watch --status``), atomically.  The first
    write that fails is an :class:`~dracc.core.errors.OutputError` (the command stops
    before it listens); a later one (the disk filled up) stops nothing: :meth:`write`
    returns one line saying so, once, and the next rewrite tries again."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.written = 0
        self.fault: str | None = None

    def write(self, text: str) -> str | None:
        """Write ``text``; return a line to say when writing fails or works again."""
        try:
            atomic.write_text(self.path, text)
        except OutputError as e:
            if not self.written:
                raise
            said, self.fault = self.fault, str(e)
            return None if said else f"{e}; still listening, tried again at the next rewrite"
        self.written += 1
        if self.fault is None:
            return None
        self.fault = None
        return f"{self.path} written again"
