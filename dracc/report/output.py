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


def json_text(doc: Any, indent: int | None = 1) -> str:
    """Strict JSON text (no NaN literals; callers give JSON types, see core.numbers.jsonable)."""
    return json.dumps(doc, indent=indent, allow_nan=False, ensure_ascii=False) + "\n"


def emit_json(doc: Any, target: str | Path) -> str | None:
    """Write ``doc`` to ``target`` ('-' for stdout); returns the path written, None for stdout."""
    text = json_text(doc)
    if str(target) == STDOUT:
        sys.stdout.write(text)
        sys.stdout.flush()
        return None
    atomic.write_text(target, text)
    return str(target)
