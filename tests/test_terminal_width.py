"""Terminal output that never breaks a number or a name (issue 18).

Every command's terminal text (``analyze``, ``inspect``, ``fleet``, ``audit history``) at
80 and 200 columns, on a terminal (a rich console forced to be one) and on a pipe,
against golden files in ``tests/golden/terminal/``; then the properties behind them: on
a pipe nothing is squeezed (no ellipsis, every source key and figure whole, the same
words at 80 as at 200 columns), on a narrow terminal no line is wider than the terminal
and a note names the columns left out.  Regenerate the golden files with
``DRACC_UPDATE_GOLDEN=1 python -m pytest tests/test_terminal_width.py``.
"""

from __future__ import annotations

import io
import os
import re
import shutil
from collections import Counter
from pathlib import Path

import pytest
from conftest import REPO, SAMPLES
from rich.console import Console

from dracc.core.config import load_config
from dracc.ingest.inspect import inspect_logs
from dracc.pipeline.analysis import analyse
from dracc.pipeline.audit import open_state
from dracc.pipeline.clock_stage import source_clocks
from dracc.pipeline.fleet import discover, run_fleet
from dracc.report import audit_json, json_report, rows, terminal
from dracc.report.audit_text import print_history
from dracc.report.inspect_report import render_inspection, with_clocks
from dracc.report.textout import Layout, fit, table, wrap

GOLDEN = Path(__file__).parent / "golden" / "terminal"
#: the sample log, named relative to the repository (the summary shows the path as given)
LOG = Path("sample_logs") / "voyage_tag.nmea"
WIDTHS = (80, 200)
COMMANDS = ("analyze", "inspect", "fleet", "audit_history")

pytestmark = pytest.mark.skipif(not (SAMPLES / "voyage_tag.nmea").exists(), reason="no samples")


@pytest.fixture(scope="module")
def made(tmp_path_factory):
    """One analysis, one inspection, one fleet run of two vessels and one audited night:
    the documents every rendering below lays out."""
    cwd = os.getcwd()
    os.chdir(REPO)
    try:
        cfg = load_config(None)
        a = analyse([LOG], cfg)
        rep = inspect_logs([LOG], cfg.ingest)
        clocks = source_clocks([LOG], cfg)
        rep = with_clocks(rep, clocks)
    finally:
        os.chdir(cwd)
    root = tmp_path_factory.mktemp("term")
    for vessel, name in (("Aurora", "voyage_tag.nmea"), ("Borealis", "voyage_prefix.nmea")):
        (root / "fleet" / vessel).mkdir(parents=True)
        shutil.copy(SAMPLES / name, root / "fleet" / vessel / name)
    tasks = discover([root / "fleet" / "Aurora", root / "fleet" / "Borealis"])
    fleet = run_fleet(tasks, cfg, root / "fleet-report", workers=2)
    assert not fleet.failures, fleet.failures
    from dracc.cli.main import main

    db = root / "state.sqlite"
    code = main(["audit", str(SAMPLES / "voyage_tag.nmea"), "--db", str(db), "--vessel", "Aurora"])
    assert code in (0, 1)
    with open_state(cfg, db) as store:
        history = audit_json.history_document(store, None, None, None)
    return {
        "analysis": a,
        "inspection": rep,
        "clocks": clocks,
        "fleet": fleet,
        "history": history,
    }


def _printer(made, command):
    return {
        "analyze": lambda c: terminal.print_summary(made["analysis"], c),
        "inspect": lambda c: render_inspection(made["inspection"], c, made["clocks"]),
        "fleet": lambda c: terminal.print_fleet(made["fleet"], c),
        "audit_history": lambda c: print_history(made["history"], c),
    }[command]


def render(made, command, width, tty, monkeypatch) -> tuple[str, str]:
    """(the text, the raw output with its escape sequences) of ``command`` printed on a
    console of ``width`` columns: a terminal (``tty``) or a pipe with ``COLUMNS=width``."""
    monkeypatch.setenv("COLUMNS", str(width))
    buf = io.StringIO()
    console = Console(
        file=buf,
        width=width,
        force_terminal=tty,
        color_system="standard" if tty else None,
        record=True,
        soft_wrap=True,
        emoji=False,
        highlight=False,
    )
    _printer(made, command)(console)
    return console.export_text(styles=False), buf.getvalue()


def _golden_name(command, width, tty):
    return f"{command}_{'tty' if tty else 'pipe'}_{width}.txt"


@pytest.mark.parametrize("tty", [False, True], ids=["pipe", "tty"])
@pytest.mark.parametrize("width", WIDTHS)
@pytest.mark.parametrize("command", COMMANDS)
def test_golden(made, command, width, tty, monkeypatch):
    text, _ = render(made, command, width, tty, monkeypatch)
    path = GOLDEN / _golden_name(command, width, tty)
    if os.environ.get("DRACC_UPDATE_GOLDEN"):
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text, encoding="utf-8")
    assert text == path.read_text(encoding="utf-8")
    # stable: nothing of this run (its temporary folder, an absolute path) is in the text
    assert str(REPO) not in text and "/tmp" not in text and "pytest-" not in text


def _words(text: str) -> Counter:
    return Counter(text.split())


@pytest.mark.parametrize("command", COMMANDS)
def test_pipe_at_80_columns_splits_nothing(made, command, monkeypatch):
    """Piped at 80 columns: no ellipsis, no line wrapped inside a word (the words are
    those of 200 columns, only the line breaks differ), tables as wide as they need."""
    narrow, raw = render(made, command, 80, False, monkeypatch)
    wide, _ = render(made, command, 200, False, monkeypatch)
    assert "…" not in narrow and "\x1b[" not in raw  # no escape sequence reaches a pipe
    assert _words(narrow) == _words(wide)
    assert all(line == line.rstrip() for line in narrow.splitlines())


def test_pipe_at_80_columns_keeps_every_source_key_and_figure(made, monkeypatch):
    a = made["analysis"]
    text, _ = render(made, "analyze", 80, False, monkeypatch)
    lines = text.splitlines()
    doc = json_report.to_dict(a)
    # each source of the JSON: its key, role and record count on one line of the table
    for key, s in doc["source_keys"].items():
        role = "+".join(s["roles"]) or "(none)"
        assert any(ln.split()[:3] == [key, role, f"{s['records']:,}"] for ln in lines), key
    # each figure of the per-unit table on its unit's line, whole
    for _, unit in rows.unit_rows(a.deviation):
        for r in unit or ():
            line = next(ln for ln in lines if ln.split()[:3] == [r.unit, *r.channel_text.split()])
            for cell in (r.n, r.m_u, r.m_y, r.kurtosis, r.ref_rms, r.k_star):
                assert f" {cell}" in line, (cell, line)
    # the header row has every column, none split over two lines
    head = next(ln for ln in lines if ln.startswith("unit "))
    assert re.split(r"\s{2,}", head) == [
        "unit", "channel", "n", "m_u", "m_y", "excess kurt.", "limit 95 %", "a priori",
        "verdict", "hat σ", "ref RMS", "k*",
    ]  # fmt: skip
    assert f"{doc['lines']:,} lines" in text
    # the notes wrap at 80 on spaces: every line of prose fits (tables may be wider)
    prose = [ln for ln in lines if ln.startswith(("note: ", "      ", "- ", "  "))]
    assert prose and max(len(ln) for ln in prose) <= 80


@pytest.mark.parametrize("command", COMMANDS)
def test_narrow_terminal_leaves_columns_out_and_says_which(made, command, monkeypatch):
    text, raw = render(made, command, 80, True, monkeypatch)
    assert "…" not in text
    assert max(len(ln) for ln in text.splitlines()) <= 80
    wide, _ = render(made, command, 200, True, monkeypatch)
    assert "not shown at" not in wide
    notes = re.findall(r"^\((.*): not shown at 80 columns\)$", text, re.M)
    if command != "audit_history":  # its tables fit 80 columns
        assert notes
    for note in notes:
        for name in note.split(", "):  # a column left out is not in the narrow header
            assert name in wide
    assert "\x1b[1m" in raw  # the headings and table headers are bold on a terminal


def test_cli_pipe_is_the_golden_pipe(run_cli, monkeypatch):
    """Through the CLI's own consoles (dracc.cli.app) on a pipe: the same text."""
    monkeypatch.chdir(REPO)
    monkeypatch.setenv("COLUMNS", "80")
    code, out, _ = run_cli("analyze", LOG)
    assert code == 0
    assert out == (GOLDEN / "analyze_pipe_80.txt").read_text(encoding="utf-8")
    code, out, _ = run_cli("inspect", LOG)
    assert code == 0
    assert out == (GOLDEN / "inspect_pipe_80.txt").read_text(encoding="utf-8")
    monkeypatch.delenv("COLUMNS")  # no width at all: notes at 100, tables whole
    code, out, _ = run_cli(
        "fix", "--range", "54.63,18.73,3000m,10", "--range", "54.59,18.71,2500m,10",
        "--range", "54.60,18.80,4000m,10",
    )  # fmt: skip
    assert code == 0 and "…" not in out and max(len(ln) for ln in out.splitlines()) <= 100
    assert "verdict: the observations disagree" in out


def test_log_text_is_not_an_emoji_or_markup(run_cli, capsys):
    from dracc.cli.app import out

    out.print("vessel :ship: [bold]x[/bold]", markup=False)
    assert capsys.readouterr().out == "vessel :ship: [bold]x[/bold]\n"


# textout itself, against hand-laid-out text


def test_table_natural_width_alignment_and_no_trailing_spaces():
    text = table(("name", "n"), [("GYRO", "2,883"), ("A", "1")], right=(False, True))
    assert text.splitlines() == ["name      n", "GYRO  2,883", "A         1"]


def test_narrow_terminal_drops_the_lowest_priority_first_then_refits():
    headers = ("key", "a", "bb", "wide column")
    data = [("K", "1", "22", "x" * 11)]
    prio = (0, 1, 2, 2)
    # 3 + 2 + 1 + 2 + 2 + 2 + 11 = 23 columns in all
    assert fit(headers, data, priorities=prio, lay=Layout(23, True)).hidden == []
    assert fit(headers, data, priorities=prio, lay=Layout(200, False)).hidden == []
    assert fit(headers, data, priorities=prio, lay=Layout(10, False)).hidden == []  # a pipe
    # 22: 'wide column' (rightmost of priority 2) goes; 'bb' is kept (3+2+1+2+2 = 10)
    assert fit(headers, data, priorities=prio, lay=Layout(22, True)).hidden == ["wide column"]
    # 9: 'wide column' and 'bb' go, 'a' too (3+2+1 = 6 fits, but 'a' is dropped only if needed)
    f = fit(headers, data, priorities=prio, lay=Layout(9, True))
    assert f.hidden == ["bb", "wide column"] and f.lines == ["key  a", "K    1"]
    # the key never goes, even where it cannot fit
    assert fit(headers, data, priorities=prio, lay=Layout(2, True)).lines[0] == "key"
    text = table(headers, data, priorities=prio, lay=Layout(22, True))
    note = text.splitlines()[2:]  # wrapped at 22, on spaces, continued one space in
    assert note == ["(wide column: not", " shown at 22 columns)"]


def test_cells_of_several_lines_and_wide_characters():
    f = fit(("reason", "examples"), [("checksum", "a.nmea:1 $GP\nb.nmea:2 $HE")])
    assert f.lines == ["reason    examples", "checksum  a.nmea:1 $GP", "          b.nmea:2 $HE"]
    # a CJK character takes two cells: the column is as wide as it shows
    assert fit(("k",), [("船名",), ("ab",)]).lines == ["k", "船名", "ab"]
    assert fit(("k", "v"), [("船名", "1"), ("ab", "2")]).lines == ["k     v", "船名  1", "ab    2"]
    # control characters from a log are escapes, never sent to the terminal
    assert fit(("k",), [("A\x1b[31mB",)]).lines[1] == "A\\x1b[31mB"


def test_wrap_breaks_on_spaces_only():
    text = "course 2026-03-01T06:00:00Z 1,234.5 m gnss:GP-1 " * 3
    out = wrap(text.strip(), 30, hang=2)
    assert out.splitlines()[0].split() == ["course", "2026-03-01T06:00:00Z"]
    assert out.split() == text.split()  # the same words: none split
    assert all(len(ln) <= 30 for ln in out.splitlines())
    assert all(ln.startswith("  ") for ln in out.splitlines()[1:])
    long_key = "/very/long/path/without/any/space/in/it/voyage.nmea"
    assert wrap(f"file {long_key} read", 20).splitlines() == ["file", long_key, "read"]
    assert wrap("short", 20) == "short" and wrap("a\nb", 20) == "a\nb"


def test_wrap_keeps_a_number_with_its_unit():
    text = "first scored leg 100.0 % (stated 96.6 %) the largest 6,101 m at 0.55 kn, 12 s."
    for width in range(20, 80):
        lines = wrap(text, width, hang=2).splitlines()
        assert " ".join(ln.strip() for ln in lines) == text  # the same text, spaces kept
        heads = [ln.strip().split()[0] for ln in lines]
        assert not {"%", "%)", "m", "kn,", "s."} & set(heads), (width, lines)
    # only after a number: "of m" breaks as any two words do
    assert wrap("a long column header of m values", 24).splitlines()[1] == "m values"


def test_audit_summary_wrapped_at_a_width_keeps_its_words_and_table(tmp_path):
    from test_audit_helpers import make_analysis

    from dracc.pipeline.audit import AuditConfig, audit_night, facts_from_analysis
    from dracc.pipeline.state import StateStore
    from dracc.report.audit_text import format_summary

    with StateStore(tmp_path / "s.sqlite") as store:
        outcome = audit_night(
            facts_from_analysis(make_analysis("2026-11-20", containment=0.5, log_scale=None)),
            store=store,
            acfg=AuditConfig(required_sources=("ins1",)),
            seeds={},
            vessel="Aurora",
            night=None,
            content_hash="n",
            settings_hash="s",
        )
    whole, wrapped = format_summary(outcome, 0.95), format_summary(outcome, 0.95, width=60)
    assert max(len(ln) for ln in whole.splitlines()) > 60  # one line per fact by default
    assert whole.split() == wrapped.split()  # the same words, none split
    table_lines = [ln for ln in whole.splitlines() if re.match(r"  (unit|ins\d) ", ln)]
    assert table_lines and all(ln in wrapped.splitlines() for ln in table_lines)
    assert all(len(ln) <= 60 for ln in wrapped.splitlines() if ln not in table_lines)
    finding = "  - [consistency] DR: reference inside 2M at 50.0 % of epochs < 90.0 %"
    assert finding in format_summary(outcome, 0.95, width=80).splitlines()  # 72: fits
    at = wrapped.splitlines().index(finding[:58].rsplit(" ", 1)[0])
    assert wrapped.splitlines()[at + 1].startswith("    ")  # continued under its text
