"""Where a JSON document goes: ``--json PATH`` writes it atomically to PATH, ``--json -``
prints it on stdout.  Every command's ``--json`` means this (``dracc.cli.options.JsonOut``).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

from dracc.core import atomic

STDOUT = "-"


def json_text(doc: Any, indent: int | None = 1, ascii_only: bool = False) -> str:
    """Strict JSON text (no NaN literals; callers give JSON types, see core.numbers.jsonable).

    ``ascii_only`` escapes every non-ASCII character (``\\u0085``): what goes to a terminal
    then holds no C1 control character a log's text could smuggle in."""
    return json.dumps(doc, indent=indent, allow_nan=False, ensure_ascii=ascii_only) + "\n"


def emit_json(doc: Any, target: str | Path) -> str | None:
    """Write ``doc`` to ``target`` ('-' for stdout, ASCII-escaped); returns the path written,
    None for stdout."""
    if str(target) == STDOUT:
        sys.stdout.write(json_text(doc, ascii_only=True))
        sys.stdout.flush()
        return None
    atomic.write_text(target, json_text(doc))
    return str(target)
