"""Plain text for the terminal, a pipe or a file: fixed-width tables and wrapped notes.

Every command's terminal tables go through :func:`table` and its long lines through
:func:`wrap`, so that no output ever splits a name or a number, cuts one to an ellipsis
or squeezes a header:

- a table is laid out at its natural width: each column as wide as its widest cell,
  two spaces between columns, numbers right-aligned, no trailing spaces;
- not a terminal (a pipe, a file, mail): always every column, however wide;
- a terminal narrower than the table: the columns of lowest priority (the highest
  ``priorities`` number; 0 is never dropped) are left out, one at a time, until the
  table fits, and one note line names them; a table that does not fit even then is
  printed whole (the terminal folds the long lines, dracc never does);
- notes and messages are wrapped on spaces only (never on a hyphen, never inside a
  word): at the terminal's width, or, not on a terminal, at ``$COLUMNS`` or
  :data:`PIPE_WIDTH`.

:func:`layout` says which case a rich console is; :func:`print_lines` prints the laid-out
text (bold headings on a terminal, nothing but the text on a pipe).  Every cell and
line is passed through :func:`dracc.core.safetext.printable`: a log's control characters
are shown as escapes, never sent to the terminal, and nothing is read as rich markup.
"""

from __future__ import annotations

import os
import re
import textwrap
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass

from rich.cells import cell_len
from rich.console import Console
from rich.text import Text

from dracc.core.safetext import printable

#: where the output is not a terminal and ``$COLUMNS`` is not set: notes wrap at this width
PIPE_WIDTH = 100
#: the narrowest width anything is laid out for
MIN_WIDTH = 20
#: spaces between two columns of a table
GAP = 2


@dataclass(frozen=True)
class Layout:
    """How text is laid out: ``width`` for wrapping (and, on a terminal, for tables),
    ``tty``: a terminal (tables may leave columns out to fit ``width``)."""

    width: int = PIPE_WIDTH
    tty: bool = False


def pipe_width(environ: Mapping[str, str] | None = None) -> int:
    """The wrapping width where the output is not a terminal: ``$COLUMNS`` when it is a
    positive number, else :data:`PIPE_WIDTH`."""
    columns = (os.environ if environ is None else environ).get("COLUMNS", "")
    return max(int(columns), MIN_WIDTH) if columns.isdigit() and int(columns) > 0 else PIPE_WIDTH


def layout(console: Console) -> Layout:
    """The layout for printing on ``console``: its width on a terminal; a pipe or a
    file has no width (tables at their natural width, notes at :func:`pipe_width`)."""
    if console.is_terminal:
        return Layout(max(console.width, MIN_WIDTH), True)
    return Layout(pipe_width(), False)


def width_of(text: str) -> int:
    """The number of terminal cells ``text`` takes (a CJK character takes two)."""
    return cell_len(text)


def _cell_lines(value: object) -> list[str]:
    """A cell's lines: its text split at line breaks, control characters escaped."""
    return [printable(part) for part in str(value).split("\n")] or [""]


def _pad(text: str, width: int, right: bool) -> str:
    fill = " " * (width - width_of(text))
    return fill + text if right else text + fill


@dataclass(frozen=True)
class Fitted:
    """A table laid out: its ``lines`` (the header first) and the ``hidden`` columns."""

    lines: list[str]
    hidden: list[str]

    def text(self) -> str:
        return "\n".join(self.lines)


def fit(
    headers: Sequence[str],
    rows: Iterable[Sequence[object]],
    *,
    right: Sequence[bool] | None = None,
    priorities: Sequence[int] | None = None,
    lay: Layout = Layout(),
    indent: int = 0,
) -> Fitted:
    """The table of ``headers`` and ``rows`` laid out for ``lay`` (see the module
    docstring).  ``right``: per column, right-aligned (numbers); ``priorities``: per
    column, 0 = always shown, higher = left out sooner on a narrow terminal (ties: the
    rightmost first); ``indent``: spaces before every line.  A cell may hold several
    lines (``\\n``); a row is as tall as its tallest cell."""
    n = len(headers)
    right = list(right) if right is not None else [False] * n
    prio = list(priorities) if priorities is not None else [0] * n
    if len(right) != n or len(prio) != n:
        raise ValueError("right and priorities need one entry per column")
    grid = [[_cell_lines(c) for c in row] for row in rows]
    if any(len(row) != n for row in grid):
        raise ValueError(f"every row needs {n} cells")
    head = [_cell_lines(h) for h in headers]
    widths = [
        max(width_of(line) for cell in [head[j], *(row[j] for row in grid)] for line in cell)
        for j in range(n)
    ]
    shown = list(range(n))

    def total() -> int:
        return indent + sum(widths[j] for j in shown) + GAP * max(len(shown) - 1, 0)

    if lay.tty:
        # the lowest priority first; among equals, the rightmost
        dropped: list[int] = []
        for j in sorted((j for j in range(n) if prio[j] > 0), key=lambda j: (-prio[j], -j)):
            if total() <= lay.width:
                break
            shown.remove(j)
            dropped.append(j)
        # a narrow column left out before a wide one may fit again: the most needed first
        for j in reversed(dropped):
            shown.append(j)
            shown.sort()
            if total() > lay.width:
                shown.remove(j)
    lines: list[str] = []
    for cells in [head, *grid]:
        for k in range(max(len(cells[j]) for j in range(n))):
            parts = [
                _pad(cells[j][k] if k < len(cells[j]) else "", widths[j], right[j]) for j in shown
            ]
            lines.append((" " * indent + (" " * GAP).join(parts)).rstrip())
    return Fitted(lines, [str(headers[j]) for j in range(n) if j not in shown])


def hidden_note(hidden: Sequence[str], lay: Layout) -> str:
    """The one line that says which columns a narrow terminal left out ('' for none)."""
    if not hidden:
        return ""
    return wrap(f"({', '.join(hidden)}: not shown at {lay.width} columns)", lay.width, hang=1)


def table(
    headers: Sequence[str],
    rows: Iterable[Sequence[object]],
    *,
    right: Sequence[bool] | None = None,
    priorities: Sequence[int] | None = None,
    lay: Layout = Layout(),
    title: str | None = None,
    indent: int = 0,
) -> str:
    """The table as text: the ``title`` (wrapped) if any, the header, the rows, and the
    note naming the columns a narrow terminal left out (:func:`fit`)."""
    fitted = fit(headers, rows, right=right, priorities=priorities, lay=lay, indent=indent)
    out = [wrap(title, lay.width)] if title else []
    out += fitted.lines
    note = hidden_note(fitted.hidden, lay)
    if note:
        out.append(note)
    return "\n".join(out)


#: a number and its unit ("96.6 %", "6,101 m", "0.55 kn"): one word for the wrapping
_NUMBER_UNIT = re.compile(r"(?<=\d) (?=(?:%|°|kn|km|m|NM|h|min|s|Hz)(?:[\s,;:.)\]]|$))")
_GLUE = "\ue000"  #: a private-use character standing for the space kept (never in text shown)


def wrap(text: object, width: int, *, hang: int | str = 0, indent: str = "") -> str:
    """``text`` wrapped at ``width`` on spaces only: a word (a number, a source key, a
    path, ``2026-03-01``) is never split, nor a number from its unit, a word longer than
    the width stands alone on its line.  Each line of ``text`` is wrapped on its own; its
    continuation lines are indented by ``hang`` (a number of spaces, or the text itself).
    Control characters are escaped (line breaks kept)."""
    cont = hang if isinstance(hang, str) else " " * hang
    out: list[str] = []
    for line in printable(text, keep="\n").split("\n"):
        if width_of(indent + line) <= width or not line.strip():
            out.append((indent + line).rstrip())
            continue
        glued = textwrap.wrap(
            _NUMBER_UNIT.sub(_GLUE, line.replace(_GLUE, " ")),
            width=max(width, MIN_WIDTH),
            initial_indent=indent,
            subsequent_indent=indent + cont,
            break_long_words=False,
            break_on_hyphens=False,
            replace_whitespace=False,
            drop_whitespace=True,
        )
        out += [part.replace(_GLUE, " ") for part in glued]
    return "\n".join(out)


def labelled(label: str, text: object, width: int, column: int = 9) -> str:
    """``label`` padded to ``column`` characters, then ``text`` wrapped with its
    continuation lines under the text (``2M       of the estimated position, ...``)."""
    head = label.ljust(column - 1) + " " if label else " " * column
    return wrap(head + printable(text), width, hang=column)


def bullet(text: object, width: int, mark: str = "- ") -> str:
    """``- text`` wrapped, its continuation lines under the text."""
    return wrap(mark + printable(text), width, hang=len(mark))


def print_lines(console: Console, text: str, *, bold: Iterable[int] = (), style: str = "") -> None:
    """Print laid-out ``text`` on ``console`` as it is (rich wraps and crops nothing):
    the lines numbered in ``bold`` bold on a terminal; no markup, no highlighting."""
    rich_text = Text(text, style=style, end="\n")
    if console.is_terminal:
        starts = [0]
        for line in text.split("\n"):
            starts.append(starts[-1] + len(line) + 1)
        for k in bold:
            if 0 <= k < len(starts) - 1:
                rich_text.stylize("bold", starts[k], starts[k + 1] - 1)
    console.print(rich_text, soft_wrap=True, crop=False, overflow="ignore", highlight=False)


class Page:
    """Lines of text laid out for ``lay`` as they are added (tables by :func:`fit`,
    everything else wrapped by :func:`wrap`), and which of them are bold on a terminal
    (headings, table headers)."""

    def __init__(self, lay: Layout) -> None:
        self.lay = lay
        self.lines: list[str] = []
        self.bold: list[int] = []

    def add(self, text: str, bold: bool = False) -> None:
        """``text`` as it is (already laid out), bold or not."""
        if bold:
            self.bold.append(len(self.lines))
        self.lines += text.split("\n")

    def blank(self) -> None:
        self.lines.append("")

    def heading(self, text: object) -> None:
        first = len(self.lines)
        self.add(wrap(text, self.lay.width))
        self.bold += range(first, len(self.lines))

    def wrapped(self, text: object, hang: int | str = 0) -> None:
        self.add(wrap(text, self.lay.width, hang=hang))

    def table(
        self,
        headers: Sequence[str],
        rows: Iterable[Sequence[object]],
        *,
        right: Sequence[bool] | None = None,
        priorities: Sequence[int] | None = None,
        title: str | None = None,
    ) -> None:
        """A table (:func:`fit`) under its bold ``title``, and the note of the columns a
        narrow terminal left out."""
        if title:
            self.heading(title)
        fitted = fit(headers, rows, right=right, priorities=priorities, lay=self.lay)
        header_lines = max((len(_cell_lines(h)) for h in headers), default=0)
        self.bold += range(len(self.lines), len(self.lines) + header_lines)
        self.lines += fitted.lines
        if fitted.hidden:
            self.add(hidden_note(fitted.hidden, self.lay))

    def text(self) -> str:
        """The page as text, ending in a line break."""
        return "\n".join(self.lines) + "\n"

    def print(self, console: Console) -> None:
        """Print the page on ``console`` (:func:`print_lines`)."""
        print_lines(console, "\n".join(self.lines), bold=self.bold)


def print_table(
    console: Console,
    headers: Sequence[str],
    rows: Iterable[Sequence[object]],
    *,
    right: Sequence[bool] | None = None,
    priorities: Sequence[int] | None = None,
    title: str | None = None,
    indent: int = 0,
) -> None:
    """:func:`table` laid out for ``console`` (:func:`layout`) and printed there, the
    title and the header bold on a terminal."""
    lay = layout(console)
    text = table(
        headers, rows, right=right, priorities=priorities, lay=lay, title=title, indent=indent
    )
    title_lines = len(wrap(title, lay.width).split("\n")) if title else 0
    header_lines = max(len(_cell_lines(h)) for h in headers)
    print_lines(console, text, bold=range(title_lines + header_lines))


__all__ = [
    "GAP",
    "PIPE_WIDTH",
    "Fitted",
    "Layout",
    "Page",
    "bullet",
    "fit",
    "hidden_note",
    "labelled",
    "layout",
    "pipe_width",
    "print_lines",
    "print_table",
    "table",
    "width_of",
    "wrap",
]
