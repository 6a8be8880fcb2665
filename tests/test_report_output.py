"""--json PATH / --json -: one writer; stdout never carries a raw C1 control character."""

import json

from dracc.report.output import emit_json


def test_stdout_is_ascii_escaped_and_round_trips(capsys):
    doc = {"source": "GP\x9b31m\x85ä", "n": 3, "x": None}
    assert emit_json(doc, "-") is None
    out = capsys.readouterr().out
    assert out.isascii() and "\x9b" not in out and "\x85" not in out
    assert json.loads(out) == doc


def test_a_path_gets_readable_utf8(tmp_path):
    doc = {"vessel": "Ærøskøbing", "values": [1.5, None]}
    target = tmp_path / "doc.json"
    assert emit_json(doc, target) == str(target)
    text = target.read_text(encoding="utf-8")
    assert "Ærøskøbing" in text
    assert json.loads(text) == doc
