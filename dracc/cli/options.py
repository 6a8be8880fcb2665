"""Option types every command shares, so that an option means one thing everywhere."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

#: ``--json PATH``: the command's JSON document to PATH (atomic), or ``-`` for stdout
#: (written by :func:`dracc.report.output.emit_json`).
JsonOut = Annotated[
    str | None,
    typer.Option(
        "--json",
        metavar="PATH",
        help="Write the JSON document to PATH, or '-' for stdout.",
    ),
]

#: ``--html PATH``: one self-contained offline HTML page
HtmlOut = Annotated[
    Path | None,
    typer.Option("--html", metavar="PATH", help="Write one self-contained offline HTML page."),
]
