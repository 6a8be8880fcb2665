"""Documented ``dracc …`` command lines against the real CLI: typer's click command tree
(``typer.main.get_command``), walked without running a command.

:func:`resolve` finds the command a line names (``dracc audit LOG`` is ``audit run``, as
the CLI's default-subcommand groups read it), :func:`option_names` the options it takes,
and :func:`parse` parses a whole concrete line as the CLI would — every option known, every
value through its type and callback (``--date 2026-13-01`` fails there), the command
itself not run.  Used by tests/test_docs_commands.py and tests/test_systemd_units.py.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache
from typing import Any

import typer.main

#: the subcommand a group runs when the line names none (dracc.cli.audit_cmd._DefaultRun)
DEFAULT_SUBCOMMAND = "run"


@cache
def root() -> Any:
    from dracc.cli.main import app

    return typer.main.get_command(app)


@dataclass(frozen=True)
class Resolved:
    path: tuple[str, ...]  #: e.g. ("audit", "run")
    command: Any  #: the click command
    parents: tuple[Any, ...]  #: the groups above it, root first
    rest: list[str]  #: the arguments after the command's name(s)


def resolve(argv: list[str]) -> Resolved:
    """The command ``dracc ARGV`` names.  Raises KeyError for an unknown command."""
    top = root()
    rest = list(argv)
    while rest and rest[0].startswith("-"):  # root options (--verbose)
        opt = rest.pop(0)
        if opt not in option_names(top):
            raise KeyError(f"dracc {opt}: no such root option")
    if not rest:
        return Resolved((), top, (), rest)
    name = rest.pop(0)
    if name not in top.commands:
        raise KeyError(f"dracc {name}: no such command")
    cmd, path, parents = top.commands[name], [name], [top]
    subs = getattr(cmd, "commands", None)
    if subs:
        sub = rest.pop(0) if rest and rest[0] in subs else DEFAULT_SUBCOMMAND
        parents.append(cmd)
        cmd = subs[sub]
        path.append(sub)
    return Resolved(tuple(path), cmd, tuple(parents), rest)


def option_names(command: Any) -> set[str]:
    """Every option spelling a command takes (``--json``, ``-c``, ``--no-analysis``, help)."""
    names = {"--help", "-h"}
    for p in command.params:
        if getattr(p, "param_type_name", "") == "option":
            names.update(p.opts)
            names.update(p.secondary_opts)
    return names


def parse(argv: list[str]) -> dict[str, Any]:
    """Parse ``dracc ARGV`` as the CLI would, without running it; the command's values.
    Raises the CLI's own errors (a click UsageError, dracc's OptionError) for a line it
    would refuse."""
    r = resolve(argv)
    ctx = None
    for i, group in enumerate(r.parents):
        ctx = group.make_context(
            "dracc" if i == 0 else r.path[i - 1], [], parent=ctx, resilient_parsing=True
        )
    ctx = r.command.make_context(r.path[-1] if r.path else "dracc", list(r.rest), parent=ctx)
    return dict(ctx.params)
