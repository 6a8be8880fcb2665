"""Documentation and behaviour agree: every ``dracc …`` command line of README.md and
docs/**/*.md names a command and options the real CLI has (typer's click command tree,
tests/cli_lines.py), a concrete line parses as the CLI would parse it (values through
their types and checks), a cheap subset runs end to end on the shipped samples, and the
documented exit codes and the example configuration match the code.

Lines are taken from fenced code blocks (a ``\\`` continues a line; a synopsis's
indented ``[…]`` lines continue theirs; a quoted SQL string may span lines) and from
inline code spans that start with ``dracc``.  A *synopsis* (``[--opt X]``, ``A|B``,
``…``) is checked for its command and option names; any other line is parsed whole.
"""

from __future__ import annotations

import re
import shlex
from dataclasses import dataclass
from pathlib import Path

import pytest
from cli_lines import option_names, parse, resolve, root
from conftest import REPO

from dracc.core.errors import ExitCode

DOCS = [REPO / "README.md", *sorted((REPO / "docs").rglob("*.md"))]

#: where a dracc command starts on a line: at its start (after a prompt, `sudo`, a cron
#: schedule and user, `ExecStart=`), after a shell operator, or named by its full path
_START = re.compile(
    r"(?:^|&&|\|\||[;|]|ExecStart=|^(?:[\d*/,-]+\s+){5}(?:[a-z_][\w-]*\s+)?)\s*"
    r"(?:\$\s+|sudo\s+)?(?:/[\w./-]*/)?dracc(?=\s)"
)
#: where it ends: a shell operator, a redirection or a comment outside quotes
_END = re.compile(r"\s(?:\|\||&&|;|\||<|>|2>|#)\s")


@dataclass(frozen=True)
class Line:
    where: str  #: file:line
    text: str  #: from `dracc` to the end of the command
    inline: bool = False  #: from a code span in the prose: a mention, never parsed whole

    @property
    def synopsis(self) -> bool:
        bare = _unquoted(self.text)
        return self.inline or bool(re.search(r"\[|…|\.\.\.|\S\|\S|\\\|", bare))

    def argv(self) -> list[str]:
        return shlex.split(self.text)[1:]


def _unquoted(text: str) -> str:
    """``text`` with its quoted strings emptied (an SQL query, a field with spaces)."""
    return re.sub(r'"[^"]*"|\'[^\']*\'', '""', text)


def _logical_lines(block: str) -> list[tuple[int, str]]:
    """The lines of a code block joined where they continue: a trailing backslash, an
    open double quote, or an indented synopsis line starting with ``[``."""
    out: list[tuple[int, str]] = []
    for n, raw in enumerate(block.split("\n")):
        if out and (
            out[-1][1].endswith("\\")
            or out[-1][1].count('"') % 2
            or (re.match(r"\s+\[", raw) and "dracc" in out[-1][1])
        ):
            out[-1] = (out[-1][0], out[-1][1].rstrip("\\").rstrip() + " " + raw.strip())
        else:
            out.append((n, raw))
    return out


def _commands_in(text: str) -> list[tuple[int, str]]:
    found = []
    for m in _START.finditer(text):
        rest = text[m.end() - len("dracc") :]
        body = _unquoted(rest)
        end = _END.search(body)
        cut = rest[: end.start()] if end else rest
        found.append((m.start(), cut.strip().rstrip("`")))
    return found


def doc_lines() -> list[Line]:
    lines = []
    for path in DOCS:
        text = path.read_text(encoding="utf-8")
        rel = path.relative_to(REPO)
        for m in re.finditer(r"^ *```[^\n]*\n(.*?)^ *```", text, flags=re.S | re.M):
            first = text[: m.start(1)].count("\n") + 1
            for n, logical in _logical_lines(m.group(1)):
                for _, cmd in _commands_in(logical):
                    lines.append(Line(f"{rel}:{first + n}", cmd))
        for m in re.finditer(r"(?<!`)`(dracc [^`]+)`(?!`)", text):  # may wrap a line
            if "\n\n" in m.group(1):
                continue
            n = text[: m.start()].count("\n") + 1
            span = " ".join(m.group(1).replace("\\|", "|").split())
            lines.append(Line(f"{rel}:{n}", span, inline=True))
    return lines


LINES = doc_lines()
#: words after `dracc` that are prose or output, not a command (`dracc audit: FAILED …`)
_NOT_COMMANDS = re.compile(r"dracc (?:audit|fleet):")


def _is_command(line: Line) -> bool:
    return not _NOT_COMMANDS.match(line.text)


def _option_tokens(text: str) -> list[str]:
    return re.findall(r"(?<![\w=/.-])(--?[A-Za-z][\w-]*)", _unquoted(text))


def test_the_walk_finds_the_documented_commands():
    """The walk is not vacuous: every command of the CLI is documented on some line, and
    the lines this test was written against are among them."""
    commands = {resolve(ln.argv() if not ln.synopsis else ln.text.split()[1:2]).path[:1]
                for ln in LINES if _is_command(ln)}  # fmt: skip
    assert {("inspect",), ("analyze",), ("fix",), ("audit",), ("fleet",), ("records",),
            ("watch",), ("simulate",)} <= commands  # fmt: skip
    texts = [ln.text for ln in LINES]
    assert any(t.startswith("dracc audit /var/log/nmea --pattern '*.nmea'") for t in texts)
    assert any(t.startswith("dracc watch udp://0.0.0.0:60001 /dev/ttyUSB0") for t in texts)
    assert any(t.startswith('dracc fleet query "SELECT vessel, max(m_y)') for t in texts)
    assert len(LINES) > 80


def test_the_checks_can_fail():
    """A misspelt command or option, and a value the CLI refuses, are caught."""
    check = test_every_documented_command_and_option_exists
    with pytest.raises(pytest.fail.Exception, match="no such command"):
        check(Line("x", "dracc analyse LOG"))
    with pytest.raises(AssertionError, match=r"has no \['--jsn'\]"):
        check(Line("x", "dracc audit DIR [--jsn F]"))
    with pytest.raises(pytest.fail.Exception, match="expected a date YYYY-MM-DD"):
        check(Line("x", "dracc audit D --date 2026-13-01"))
    assert Line("x", "dracc audit DIR --json F", inline=True).synopsis


@pytest.mark.parametrize("line", [ln for ln in LINES if _is_command(ln)], ids=lambda ln: ln.where)
def test_every_documented_command_and_option_exists(line):
    words = [w for w in _unquoted(line.text).split()[1:] if w[0] not in "[…" and w != "..."]
    try:
        r = resolve(line.argv() if not line.synopsis else words)
    except KeyError as e:
        pytest.fail(f"{line.where}: {line.text!r}: {e}")
    known = option_names(r.command)
    unknown = [o for o in _option_tokens(line.text) if o not in known]
    assert not unknown, f"{line.where}: dracc {' '.join(r.path)} has no {unknown}"
    if not line.synopsis:
        try:
            parse(line.argv())
        except Exception as e:  # the CLI's own refusal, said as the CLI says it
            pytest.fail(f"{line.where}: {line.text!r}: {type(e).__name__}: {e}")


def test_every_option_of_the_cli_is_documented():
    """Each command's options all appear on its documented lines (a synopsis or an example)."""
    documented: dict[tuple[str, ...], set[str]] = {}
    for line in LINES:
        if not _is_command(line):
            continue
        words = [w for w in _unquoted(line.text).split()[1:] if w[0] not in "[…" and w != "..."]
        r = resolve(line.argv() if not line.synopsis else words)
        documented.setdefault(r.path, set()).update(_option_tokens(line.text))
    top = root()
    missing = {}
    for name, cmd in top.commands.items():
        for sub, c in (getattr(cmd, "commands", None) or {None: cmd}).items():
            path = (name,) if sub is None else (name, sub)
            shown = documented.get(path, set())
            undocumented = [
                p.opts[0]
                for p in c.params
                if p.param_type_name == "option" and not {*p.opts, *p.secondary_opts} & shown
            ]  # --analysis/--no-analysis: either spelling documents it
            if undocumented:
                missing[" ".join(path)] = undocumented
    assert not missing, f"options no documented command line shows: {missing}"


# ----------------------------------------------------------------- end to end, cheap


def _fenced(path: Path, lang: str) -> list[str]:
    text = path.read_text(encoding="utf-8")
    return re.findall(rf"^```{lang}\n(.*?)^```", text, flags=re.S | re.M)


def test_the_fix_examples_run_as_written(run_cli, tmp_path, monkeypatch):
    """docs/fix.md's command lines, its observation file written out from its own TOML
    block; the free-gyro example gives the figures the page states."""
    import json

    (obs,) = [b for b in _fenced(REPO / "docs" / "fix.md", "toml") if "[[fix]]" in b][:1]
    (tmp_path / "obs.toml").write_text(obs)
    monkeypatch.chdir(tmp_path)
    fixes = [ln for ln in LINES if ln.where.startswith("docs/fix.md") and not ln.synopsis]
    assert len(fixes) == 4
    for line in fixes:
        code, out, err = run_cli(*line.argv())
        assert code == ExitCode.OK, f"{line.where}: {err}"
        if "--json -" in line.text:
            assert json.loads(out)["schema"] == "dracc.fix/1"
        if "--gyro-vector" in line.text:
            page = (REPO / "docs" / "fix.md").read_text(encoding="utf-8")
            stated = re.search(r"gives (\S+) (\S+), DOP ([\d.]+), FDOP \(37\) ([\d.]+)", page)
            assert stated, "docs/fix.md states the free-gyro example's figures"
            for figure in stated.groups():
                assert figure in out, (figure, out)


def test_the_documented_fault_specs_are_accepted():
    """Every `--fault` of the docs parses; with the line's --hours and --seed, resolves."""
    from dracc.sim.faults import parse_fault, resolve_faults

    seen = 0
    for line in LINES:
        if not line.text.startswith("dracc simulate") or "--fault" not in line.text:
            continue
        specs = re.findall(r"--fault[ =]([^\s\[…]+)", line.text)
        parsed = [parse_fault(s) for s in specs if not re.fullmatch(r"[A-Z\[\]:@+=]+", s)]
        seen += len(parsed)
        if not line.synopsis:
            values = parse(line.argv())
            resolve_faults(parsed, values["hours"] * 3600.0, values["seed"], labels=specs)
    assert seen >= 8


def test_the_example_configuration_states_the_defaults():
    """docs/dracc.example.toml: every live setting equals its default (loading it changes
    nothing), and every key of every section is in it, live or commented."""
    import dataclasses

    from dracc.core.config import Config, load_config
    from dracc.pipeline.audit.limits import AuditConfig, audit_config
    from dracc.pipeline.fleet.ranking import RankingConfig, ranking_config
    from dracc.pipeline.fleet.tasks import FleetConfig, fleet_config

    path = REPO / "docs" / "dracc.example.toml"
    example, default = load_config(path), Config()
    for section in ("ingest", "deviation", "faults", "integrity", "reference"):
        assert getattr(example, section) == getattr(default, section), section
    dr, dr0 = example.dead_reckoning, default.dead_reckoning
    for f in dataclasses.fields(dr):  # the error sources' sigmas are written rounded
        a, b = getattr(dr, f.name), getattr(dr0, f.name)
        if hasattr(a, "sigma"):
            assert (a.sigma, a.tau_s) == (pytest.approx(b.sigma, rel=2e-3), b.tau_s), f.name
        else:
            assert a == b, f.name
    assert audit_config(example) == audit_config(default) == AuditConfig()
    assert fleet_config(example) == FleetConfig()
    assert ranking_config(example) == RankingConfig()
    assert example.extra.get("vessel", {}) == {}

    text = path.read_text(encoding="utf-8")
    keys_here = set(re.findall(r"^#? ?([a-z_]+) *=", text, flags=re.M))
    sections = set(re.findall(r"^#? ?\[{1,2}([a-z_.A-Z]+)\]{1,2}", text, flags=re.M))
    keys_here |= {s.rsplit(".", 1)[-1] for s in sections}  # [audit.limits]: the key limits
    tables = {
        "ingest": Config().ingest, "dead_reckoning": dr0, "deviation": default.deviation,
        "faults": default.faults, "integrity": default.integrity, "audit": AuditConfig(),
        "fleet": FleetConfig(), "fleet.ranking": RankingConfig(),
    }  # fmt: skip
    missing = {
        f"[{name}] {f.name}"
        for name, obj in tables.items()
        for f in dataclasses.fields(obj)
        if f.name not in keys_here and f.name not in ("apriori", "sources", "deviation_table")
    }
    assert not missing, f"keys the example does not show: {sorted(missing)}"
    assert {"name", "latency_s"} <= keys_here  # [vessel] name, [sources.KEY] latency_s
    assert {"ingest.sources", "deviation.apriori", "audit.limits", "reference"} <= sections


# ------------------------------------------------------------------- exit codes


def test_the_exit_code_tables_are_the_codes_of_the_cli():
    """README's table lists exactly dracc.core.errors.ExitCode; audit-fleet.md's audit table
    and the audit command's help name only those codes."""
    readme = (REPO / "README.md").read_text(encoding="utf-8")
    section = readme.split("## Exit codes", 1)[1].split("\n## ", 1)[0]
    rows = dict(re.findall(r"^\| (\d+) \| (.+?) \|$", section, flags=re.M))
    assert {int(c) for c in rows} == {int(c) for c in ExitCode}
    for code, words in ((2, "bad option value"), (3, "no usable data"), (4, "configuration")):
        assert words in rows[str(code)], (code, rows[str(code)])
    audit = (REPO / "docs" / "audit-fleet.md").read_text(encoding="utf-8")
    table = audit.split("**Exit codes** (stable", 1)[1].split("\n\n", 2)[1]
    codes = {int(c) for c in re.findall(r"^\| ([\d, ]+) \|", table, flags=re.M) for c in
             re.findall(r"\d+", c)}  # fmt: skip
    assert codes == {int(c) for c in ExitCode}
    help_text = root().commands["audit"].help
    assert {int(c) for c in re.findall(r"\b(\d) [a-z]", help_text)} <= {int(c) for c in ExitCode}


#: (the page, what it says, the command, the exit code it says)
EXITS = [
    ("README.md", "bad option value", ["analyze", "LOG", "--role", "GPS1=gnss"], 2),
    ("docs/ingest.md", "matches no source key or talker is a bad option value (exit 2",
     ["records", "LOG", "--out", "r.csv", "--role", "GPS1=gnss"], 2),
    ("docs/fix.md", "Also: no observations", ["fix"], 2),
    ("docs/fix.md", "or the `--file` does not exist", ["fix", "--file", "missing.toml"], 3),
    ("docs/fix.md", "4 | the `--file` is invalid", ["fix", "--file", "BAD"], 4),
    ("docs/simulate.md", "A bad spec stops the command before anything is written (exit code 2)",
     ["simulate", "--out", "sim", "--fault", "jump:GNSS@2h=670mi"], 2),
    ("README.md", "Another suffix is a usage error (exit 2)", ["records", "LOG", "--out", "x.xlsx"], 2),
    ("README.md", "logs without a single record exit 3", ["records", "JUNK", "--out", "r.csv"], 3),
    ("README.md", "missing file", ["inspect", "missing.nmea"], 3),
    ("README.md", "4 | invalid configuration", ["analyze", "LOG", "--config", "BAD"], 4),
    ("docs/audit-fleet.md", "3 | no logs for the night",
     ["audit", "EMPTY", "--date", "2026-11-20", "--db", "a.sqlite"], 3),
    ("docs/audit-fleet.md", "4 | configuration error: invalid `[audit]`",
     ["audit", "EMPTY", "--db", "a.sqlite", "--config", "BAD"], 4),
    ("docs/audit-fleet.md", "an unknown `--unit`/`--channel`/`--vessel` in `audit history`",
     ["audit", "history", "--db", "a.sqlite", "--unit", "ins9"], 2),
    ("docs/audit-fleet.md", "or no log found (every file skipped)",
     ["fleet", "EMPTY", "--out", "fleet-out"], 3),
    ("docs/audit-fleet.md", "a folder without `tables/`",
     ["fleet", "query", "SELECT 1", "--out", "EMPTY"], 3),
]  # fmt: skip


@pytest.mark.parametrize("page, says, argv, code", EXITS, ids=[" ".join(e[2][:2]) for e in EXITS])
def test_documented_exit_codes(run_cli, tmp_path, monkeypatch, page, says, argv, code):
    text = " ".join((REPO / page).read_text(encoding="utf-8").split())
    assert says in text, f"{page} no longer says {says!r}"
    monkeypatch.chdir(tmp_path)
    (tmp_path / "EMPTY").mkdir()
    (tmp_path / "JUNK").write_text("not a log line\n" * 3)
    (tmp_path / "BAD").write_text("[audit]\nthreshold = 3\n[ingest]\nstrict = 'no'\n")
    lines = [
        f"$GPRMC,0000{s:02d},A,5436.000,N,01848.000,E,10.0,090.0,011126,,,A" for s in range(20)
    ]
    (tmp_path / "LOG").write_text("".join(f"{ln}*{_checksum(ln):02X}\n" for ln in lines))
    got, _out, err = run_cli(*argv)
    assert got == code, f"{page}: {says!r}: dracc {' '.join(argv)} exited {got}: {err}"
    assert "Traceback" not in err
    assert not (tmp_path / "sim").exists()  # simulate's bad spec: nothing written


def _checksum(sentence: str) -> int:
    x = 0
    for ch in sentence[1:]:
        x ^= ord(ch)
    return x


def test_the_values_a_synopsis_shows_are_the_defaults():
    """``[--stale 10s]``, ``[--hours 4]``: a literal value in a synopsis is the default, the
    option's own or, for analyze's options that default to the configuration, the
    configuration's."""
    from dracc.core.config import Config
    from dracc.core.durations import parse_duration_s

    dev = Config().deviation
    from_config = {"--interval": dev.interval_s, "--window": dev.window_s}
    checked = 0
    for line in LINES:
        if not line.synopsis or not _is_command(line):
            continue
        words = [w for w in _unquoted(line.text).split()[1:] if w[0] not in "[…" and w != "..."]
        params = {o: p for p in resolve(words).command.params for o in p.opts}
        for opt, value in re.findall(r"\[(--[\w-]+) ([^\]\s|]+)\]", line.text):
            p = params[opt]
            if not re.fullmatch(r"[\d.,:TZ-]+(?:s|min|h)?|[a-z]+", value) or p.multiple:
                continue  # a placeholder (FILE, LAT,LON), not a value
            if p.default is not None:  # the option's type is the default's (float, int, str)
                assert type(p.default)(value) == p.default, (line.where, opt, value)
            elif opt in from_config:
                assert parse_duration_s(value, opt) == from_config[opt], (line.where, opt)
            elif opt == "--probability":
                assert float(value) == dev.probability, line.where
            else:
                continue
            checked += 1
    assert checked >= 30


def test_one_install_layout_across_the_docs():
    """Every page names dracc, its configuration file and its state folder the same way
    (the README's cron line's), so the watch unit, the audit's cron line and its systemd
    units work together as written."""
    pages = [*DOCS, *sorted((REPO / "docs" / "systemd").glob("*.service"))]
    text = "\n".join(p.read_text(encoding="utf-8") for p in pages)
    commands = "|".join(root().commands)
    programs = set(re.findall(rf"(/[\w./-]+/)dracc(?= (?:{commands})\b)", text))
    assert programs == {"/opt/dracc/venv/bin/"}
    assert set(re.findall(r"--config (/\S+)", text)) == {"/etc/dracc.toml"}
    assert set(re.findall(r"--db (/\S+)", text)) == {"/var/lib/dracc/audit.sqlite"}
