"""Safety: config files are data; fleet output paths stay inside the output folder; odd
file names work; everything from a log is escaped in the HTML report and never styles
the terminal."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from dracc.cli.main import main
from dracc.core.config import load_config
from dracc.core.errors import ConfigError, ExitCode, FleetError
from dracc.pipeline.fleet import inside, safe_name

REPO = Path(__file__).resolve().parents[1]
SAMPLES = REPO / "sample_logs"
XSS = "<script>alert(1)</script>"
XSS_ESC = "&lt;script&gt;alert(1)&lt;/script&gt;"
RICH = "[red]INS3[/red]"  #: rich console markup, as a source name


def _main(*args) -> int:
    return main([str(a) for a in args])


def _tag_checksum(body: bytes) -> bytes:
    x = 0
    for c in body:
        x ^= c
    return b"%02X" % x


def _rename_tag_source(data: bytes, old: bytes, new: bytes) -> bytes:
    """Rename a TAG block source, fixing each TAG block's checksum."""
    out = []
    for line in data.split(b"\r\n"):
        if line.startswith(b"\\s:" + old + b","):
            tag, _, rest = line[1:].partition(b"\\")
            body = tag[: tag.rfind(b"*")].replace(b"s:" + old, b"s:" + new, 1)
            line = b"\\" + body + b"*" + _tag_checksum(body) + b"\\" + rest
        out.append(line)
    return b"\r\n".join(out)


# ----------------------------------------------------------------- config is data


def test_config_is_never_executed(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    marker = tmp_path / "pwned"
    py = tmp_path / "evil.toml"
    py.write_text(f"import os\nos.system('touch {marker}')\n")
    with pytest.raises(ConfigError, match="invalid TOML"):
        load_config(py)
    # code inside TOML strings stays a string: here an unknown key and a bad type
    toml = tmp_path / "evil2.toml"
    toml.write_text(
        f"[ingest]\ndate = \"__import__('os').system('touch {marker}')\"\n"
        f"[dead_reckoning]\nmax_gap_s = \"__import__('os')\"\n"
    )
    code = _main("analyze", SAMPLES / "voyage_tag.nmea", "--config", toml)
    assert code == ExitCode.CONFIG or code == ExitCode.INPUT
    assert not marker.exists()


def test_config_string_where_a_number_belongs_is_a_config_error(tmp_path, run_cli):
    toml = tmp_path / "c.toml"
    toml.write_text("[faults]\nmax_speed_kn = \"__import__('os')\"\n")
    code, _, err = run_cli("analyze", SAMPLES / "voyage_tag.nmea", "--config", toml)
    assert code == ExitCode.CONFIG and "[faults] max_speed_kn" in err and "Traceback" not in err


# ----------------------------------------------------------------- fleet output paths


@pytest.mark.parametrize(
    "name",
    [
        "..",
        ".",
        "../../etc",
        "a/../../b",
        "/etc/passwd",
        "..\\..\\x",
        "\x00evil",
        "CON",
        " .. ",
        "~",
        "-rf",
        XSS,
        "Ålesund ☃",
    ],
)
def test_fleet_names_cannot_escape_the_output_folder(tmp_path, name):
    root = tmp_path / "out"
    root.mkdir()
    p = inside(root, "vessels", name)
    assert root.resolve() in p.parents
    assert p.parent == (root / "vessels").resolve()
    assert "/" not in safe_name(name) and "\\" not in safe_name(name)
    assert safe_name(name) not in ("", ".", "..")


def test_inside_refuses_an_escape_it_is_handed(tmp_path, monkeypatch):
    import dracc.pipeline.fleet.tasks as fleet  # inside() looks safe_name up here

    monkeypatch.setattr(fleet, "safe_name", lambda s, max_len=100: s)  # a broken sanitiser
    with pytest.raises(FleetError, match="escape"):
        inside(tmp_path, "..", "..", "etc")


@pytest.mark.slow
def test_fleet_with_hostile_vessel_folders(tmp_path):
    """Vessel folders named '...', '-rf' and an HTML tag: outputs stay under --out and the
    fleet page escapes the names."""
    src = tmp_path / "in"
    log = (SAMPLES / "voyage_tag.nmea").read_bytes()
    names = ["...", "-rf", "<img src=x onerror=alert(1)>"]
    for i, n in enumerate(names):
        (src / n).mkdir(parents=True)
        (src / n / "log.nmea").write_bytes(log + b"\r\n" * (i + 1))
    out = tmp_path / "out"
    code = _main("fleet", *[src / n for n in names], "--workers", "1", "--out", out)
    assert code == 0
    outside = [
        p
        for p in tmp_path.rglob("*")
        if out not in p.parents and p != out and src not in p.parents and p != src
    ]
    assert outside == []
    page = (out / "fleet.html").read_text()
    assert "<img src=x" not in page and "&lt;img src=x onerror=alert(1)&gt;" in page
    summary = json.loads((out / "fleet.json").read_text())
    assert summary["analysed"] == 3


# ----------------------------------------------------------------- odd file names


@pytest.mark.parametrize(
    "name",
    [
        "-odd name.nmea",
        "Ålesund ☃ log.nmea",
        "--json.nmea",
        " leading space.nmea",
        "semi;colon $(echo x).nmea",
    ],
)
def test_odd_file_names(tmp_path, monkeypatch, run_cli, name):
    monkeypatch.chdir(tmp_path)
    lines = (SAMPLES / "voyage_tag.nmea").read_bytes().split(b"\r\n")[:600]
    Path(name).write_bytes(b"\r\n".join(lines) + b"\r\n")
    code, out, err = run_cli("inspect", "--json", "-", "--", name)
    assert code == ExitCode.OK, err
    assert json.loads(out)["inputs"][0]["path"] == name
    code, out, err = run_cli("analyze", "--json", "r.json", "--", name)
    assert code == ExitCode.OK, err
    assert json.loads(Path("r.json").read_text())["inputs"][0]["path"] == name


def test_leading_dash_file_in_a_real_process(tmp_path):
    """`dracc analyze -- -odd name.nmea`, exactly as a user types it."""
    lines = (SAMPLES / "voyage_tag.nmea").read_bytes().split(b"\r\n")[:600]
    (tmp_path / "-odd name.nmea").write_bytes(b"\r\n".join(lines) + b"\r\n")
    r = subprocess.run(
        [sys.executable, "-m", "dracc", "analyze", "--", "-odd name.nmea"],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=120,
        env={**os.environ, "PYTHONIOENCODING": "utf-8"},
    )
    assert r.returncode == 0, r.stderr
    assert "-odd name.nmea" in r.stdout and "Traceback" not in r.stderr


# ----------------------------------------------------------------- escaping


@pytest.fixture(scope="module")
def hostile_report(tmp_path_factory):
    """The sample voyage with INS2's TAG source renamed to a script tag, a rejected line
    holding markup, and a file name with markup; analysed to JSON and HTML."""
    d = tmp_path_factory.mktemp("hostile")
    data = (SAMPLES / "voyage_tag.nmea").read_bytes()
    data = _rename_tag_source(data, b"INS2", XSS.encode())
    data = _rename_tag_source(data, b"INS3", RICH.encode())
    data += b"<b>not a sentence</b> [red]rich markup[/red] " + XSS.encode() + b"\r\n"
    log = d / "voyage <b onclick=x>.nmea"
    log.write_bytes(data)
    html = d / "r.html"
    code = _main(
        "analyze",
        log,
        "--role",
        f"{XSS}=ins2",
        "--role",
        f"{RICH}=ins3",
        "--html",
        html,
        "--json",
        d / "r.json",
    )
    assert code == 0
    return html.read_text(), json.loads((d / "r.json").read_text()), log


def test_html_escapes_every_log_string(hostile_report):
    page, doc, _ = hostile_report
    assert XSS in doc["source_keys"]  # the source really is named so
    assert "<script>alert" not in page and XSS_ESC in page
    assert "<b>not a sentence" not in page and "<b onclick" not in page
    assert "&lt;b onclick=x&gt;" in page  # the file name, escaped
    assert "<script" not in page.lower()  # the report itself runs no script


def test_terminal_does_not_interpret_log_markup(hostile_report, run_cli):
    _, _, log = hostile_report
    code, out, err = run_cli("analyze", log, "--role", f"{XSS}=ins2", "--role", f"{RICH}=ins3")
    assert code == 0, err
    assert XSS in out and RICH in out  # printed literally (rich markup disabled for log text)
    assert "\x1b[" not in out  # no escape sequences reach a pipe
