"""One name per concept (issue 32): the water track, the DR over the ground and the
fix-updated EP are named so in every renderer and export, and the names they replaced
appear nowhere a user reads.

Two nets for the retired names: (1) every string literal of the package (ast string
constants, f-string parts included; docstrings left out, where the papers may still be
cited as seeds/00N, and comments, which ast never sees), and (2) what one ``analyze`` of
a shipped sample writes: the terminal text, the HTML (its images left out), GPX, KML,
GeoJSON, the JSON's string values (its keys are a contract and keep their names:
``estimated_position``) and the MCAP's channel names.
"""

from __future__ import annotations

import ast
import html
import json
import re
import types
from collections.abc import Iterator
from pathlib import Path

import pytest
from conftest import REPO, SAMPLES

from dracc.core.errors import ExitCode
from dracc.core.vocabulary import DR_OVER_GROUND, FIX_UPDATED_EP, WATER_TRACK
from dracc.report import terminal
from dracc.report.glossary import GLOSSARY, JSON_KEYS

SAMPLE = SAMPLES / "voyage.mcap"
NAMES = (WATER_TRACK, DR_OVER_GROUND, FIX_UPDATED_EP)

#: the retired names: what each caught, and an example of each from before issue 32
RETIRED: dict[str, tuple[re.Pattern[str], str]] = {
    # both the learned DR and the aided EP were "estimated position"; neither is now
    "estimated position": (re.compile(r"estimated position", re.I), "EP (estimated position)"),
    # "EP" alone named both; the abbreviation stays only in "fix-updated EP"
    "bare EP": (re.compile(r"(?<![Ff]ix-updated )\bEP\b"), "centred on the EP (+)"),
    # the aided EP's old names (the machine keys aided_ep, /dracc/aided_ep stay)
    "aided-DR, aided EP": (re.compile(r"\b[Aa]ided[- ](?:DR|EP)\b"), "Aided-DR estimated position"),
    # the papers' file names: users read the authors (METHODS.md)
    "seeds/00N": (re.compile(r"\bseeds?[/ _]?0\d\d", re.I), "aided-DR EP (seeds/003)"),
    # the water track was also "DR water track" and "DR (water track)"
    "DR water track": (re.compile(r"\bDR \(?water track", re.I), "DR (water track)"),
}

pytestmark = pytest.mark.skipif(not SAMPLE.exists(), reason="sample_logs not generated")


def retired_in(text: str) -> list[str]:
    """'name: matched text' for each retired name found in ``text``."""
    return [
        f"{name}: {m.group(0)!r}" for name, (pat, _) in RETIRED.items() for m in pat.finditer(text)
    ]


def test_the_retired_patterns_catch_the_old_names_and_spare_the_new():
    olds = [
        "aided-DR EP (seeds/003)",
        "Aided-DR estimated position",
        "EP (estimated position)",
        "DR water track",
        "DR (water track)",
        "the aided-DR filter (seeds/003)",
        "(seed 001, K3b-K8)",
        "EP 12:00 2-sigma ellipse",
        "of the aided EP",
    ]
    for name, (pat, example) in RETIRED.items():
        assert pat.search(example), (name, example)
    assert all(retired_in(old) for old in olds), [o for o in olds if not retired_in(o)]
    for ok in (*NAMES, "Fix-updated EP", "fix-updated EP's 2M", "aided_ep", "/dracc/aided_ep"):
        assert not retired_in(ok), ok
    assert all(name == name.strip() and name for name in NAMES) and len(set(NAMES)) == 3


# ------------------------------------------------------------------ the source


def _docstring_ids(tree: ast.AST) -> set[int]:
    """The string constants that are docstrings (modules, classes, functions) or bare
    string statements (attribute docstrings)."""
    ids = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Expr) and isinstance(node.value, ast.Constant):
            ids.add(id(node.value))
    return ids


def string_literals(path: Path) -> Iterator[tuple[int, str]]:
    """(line, text) of every string constant of a module but its docstrings."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    skip = _docstring_ids(tree)
    for node in ast.walk(tree):
        if isinstance(node, ast.Constant) and isinstance(node.value, str) and id(node) not in skip:
            yield node.lineno, node.value


def test_no_string_literal_of_the_package_uses_a_retired_name():
    modules = sorted((REPO / "dracc").rglob("*.py"))
    assert len(modules) > 100 and any(p.name == "terminal.py" for p in modules)
    found = [
        f"{path.relative_to(REPO)}:{line}: {hit}"
        for path in modules
        if retired_in(path.read_text(encoding="utf-8"))  # parse only where the text has one
        for line, text in string_literals(path)
        for hit in retired_in(text)
    ]
    assert not found, "\n".join(found)


def test_the_string_scan_sees_f_strings_and_skips_docstrings(tmp_path):
    mod = tmp_path / "m.py"
    mod.write_text(
        '"""seeds/003: a docstring."""\n'
        "def f(n):\n"
        '    """The aided-DR EP."""\n'
        '    return f"{n} Aided-DR estimated position"\n',
        encoding="utf-8",
    )
    hits = [hit for _, text in string_literals(mod) for hit in retired_in(text)]
    assert hits == ["estimated position: 'estimated position'", "aided-DR, aided EP: 'Aided-DR'"]


def test_the_glossary_has_each_name_and_the_json_keys_that_hold_it():
    assert set(JSON_KEYS) == set(NAMES)
    for name in NAMES:
        meaning, _label = GLOSSARY[name]
        assert all(key in meaning for key in JSON_KEYS[name]), name
    for term, (meaning, _label) in GLOSSARY.items():
        assert not retired_in(term) and not retired_in(meaning), term


# -------------------------------------------------------------- what analyze writes


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """One ``dracc analyze`` of the 3 h sample (a learned DR and a fix-updated EP) with
    every export, restarted hourly (three legs: fewer panels to draw); the terminal text
    rendered from the same Analysis."""
    from dracc.cli.main import main
    from dracc.pipeline import analysis

    out = tmp_path_factory.mktemp("terms")
    files = {k: out / f"r.{k}" for k in ("json", "html", "gpx", "kml", "geojson", "mcap")}
    caught = {}
    real = analysis.analyse

    def keep(*args, **kwargs):
        caught["a"] = real(*args, **kwargs)
        return caught["a"]

    args = ["analyze", str(SAMPLE), "--dr-reset", "1h"]
    args += [a for k, p in files.items() for a in (f"--{k}", str(p))]
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(analysis, "analyse", keep)
        assert main(args) == ExitCode.OK
    a = caught["a"]
    assert a.dead_reckoning.scored_out_of_sample and a.estimated_position is not None
    text = {k: p.read_text(encoding="utf-8") for k, p in files.items() if k != "mcap"}
    text["terminal"] = terminal.render_text(a, 200, False)
    # the HTML as read: tags and images out, entities resolved
    page = re.sub(r"data:[^\"')]*", "", text["html"])
    text["html"] = html.unescape(re.sub(r"<[^>]+>", "\n", page))
    return types.SimpleNamespace(files=files, text=text, doc=json.loads(text.pop("json")))


def _strings(obj) -> Iterator[str]:
    """Every string value of a JSON document (its keys left out)."""
    if isinstance(obj, dict):
        for v in obj.values():
            yield from _strings(v)
    elif isinstance(obj, list):
        for v in obj:
            yield from _strings(v)
    elif isinstance(obj, str):
        yield obj


def _mcap_names(path: Path) -> dict[str, str]:
    """topic -> the channel metadata's name, for the channels that carry one."""
    from mcap.reader import make_reader

    with open(path, "rb") as fh:
        channels = make_reader(fh).get_summary().channels.values()
    return {c.topic: c.metadata["name"] for c in channels if "name" in c.metadata}


def test_no_output_uses_a_retired_name(run):
    found = [f"{kind}: {hit}" for kind, t in run.text.items() for hit in retired_in(t)]
    found += [f"json: {hit}" for s in _strings(run.doc) for hit in retired_in(s)]
    found += [
        f"mcap: {hit}"
        for name in _mcap_names(run.files["mcap"]).values()
        for hit in retired_in(name)
    ]
    assert not found, "\n".join(found)


def test_every_output_names_the_three_positions(run):
    body, _, glossary = run.text["html"].partition("Glossary\n")
    for name in NAMES:
        assert name in glossary, name
        assert name in body or name[0].upper() + name[1:] in body, f"HTML: {name}"
    term = run.text["terminal"]
    assert f"2M       of the {DR_OVER_GROUND}, largest" in term
    assert (
        "\nFix-updated EP\n" in term and f"note: {DR_OVER_GROUND}: the {WATER_TRACK} plus" in term
    )
    gpx = set(re.findall(r"<trk><name>([^<]*)</name>", run.text["gpx"]))
    assert set(NAMES) <= gpx, gpx
    kml = set(re.findall(r"<(?:kml:)?name>([^<]*)</(?:kml:)?name>", run.text["kml"]))
    assert set(NAMES) <= kml, kml
    geo = {f["properties"].get("name") for f in json.loads(run.text["geojson"])["features"]}
    assert set(NAMES) <= geo, geo
    assert _mcap_names(run.files["mcap"]) == {
        "/dracc/dr": WATER_TRACK,
        "/dracc/ep": DR_OVER_GROUND,
        "/dracc/aided_ep": FIX_UPDATED_EP,
    }


def test_the_json_keys_of_the_glossary_hold_the_positions(run):
    """The JSON keys keep their names (a contract with users' scripts), and each the
    glossary maps to a position is in the document."""
    for keys in JSON_KEYS.values():
        for key in keys:
            node = run.doc
            for part in key.split("."):
                name, many = part.removesuffix("[]"), part.endswith("[]")
                node = node[name][0] if many else node[name]
            assert node is not None, key
