"""Writing an analysis's reports: the terminal summary or the JSON on stdout, then the JSON,
HTML and table files, all renamed into place together; a write error becomes one line."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING

from rich.console import Console

from dracc.core import atomic
from dracc.core.errors import DraccError
from dracc.report.output import STDOUT, json_text

if TYPE_CHECKING:  # the pipeline loads when the command runs, not when the CLI starts
    from dracc.pipeline.results import Analysis


@contextmanager
def writing(target: object) -> Iterator[None]:
    """OSError while writing ``target`` -> one line naming it (a closed stdout pipe passes)."""
    try:
        yield
    except BrokenPipeError:
        raise  # stdout closed by the reader (e.g. `| head`): not an error of ours
    except OSError as e:
        detail = f"{e.filename}: {e.strerror}" if e.filename and e.strerror else str(e)
        raise DraccError(f"cannot write {target}: {detail}") from e


def write_reports(
    result: Analysis,
    console: Console,
    json_path: str | None,
    html_path: Path | None,
    out_dir: Path | None,
) -> list[str]:
    """The terminal summary on ``console`` (or the JSON there, for ``json_path`` '-'), then
    the report files: each written in full to a temporary file and all renamed together at
    the end (:func:`dracc.core.atomic.together`), so that an interrupt while the plots are
    drawn leaves every earlier report as it was, not a new JSON beside an old HTML.

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
    return said
