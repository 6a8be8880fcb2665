import os
import stat

import pytest

from dracc.atomic import atomic_path, together, write_text


def test_write_is_atomic_and_gets_umask_mode(tmp_path):
    target = tmp_path / "sub" / "report.json"
    write_text(target, "{}")
    assert target.read_text() == "{}"
    umask = os.umask(0)
    os.umask(umask)
    assert stat.S_IMODE(target.stat().st_mode) == 0o666 & ~umask
    assert [p.name for p in target.parent.iterdir()] == ["report.json"]


def test_interrupted_write_leaves_old_file(tmp_path):
    target = tmp_path / "report.html"
    target.write_text("old")
    with pytest.raises(KeyboardInterrupt):
        with atomic_path(target) as tmp:
            tmp.write_text("half")
            raise KeyboardInterrupt
    assert target.read_text() == "old"
    assert [p.name for p in tmp_path.iterdir()] == ["report.html"]


def test_files_written_together_appear_together_or_not_at_all(tmp_path):
    a, b = tmp_path / "report.json", tmp_path / "tables" / "t.csv"
    a.write_text("old json")
    with pytest.raises(KeyboardInterrupt):
        with together():
            write_text(a, "new json")
            assert a.read_text() == "old json"  # not yet: the rename waits for the block
            write_text(b, "new table")
            raise KeyboardInterrupt  # e.g. while the HTML's plots are drawn
    assert a.read_text() == "old json" and not b.exists()
    assert not [p for p in tmp_path.rglob("*.part")]
    with together():
        write_text(a, "new json")
        write_text(b, "new table")
    assert a.read_text() == "new json" and b.read_text() == "new table"
    assert not [p for p in tmp_path.rglob("*.part")]


def test_a_write_outside_together_is_renamed_at_once(tmp_path):
    with together():
        pass
    write_text(tmp_path / "x", "1")
    assert (tmp_path / "x").read_text() == "1"
