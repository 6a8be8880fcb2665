import os
import stat

import pytest

from dracc.core.atomic import atomic_path, together, write_text


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
    with pytest.raises(KeyboardInterrupt), atomic_path(target) as tmp:
        tmp.write_text("half")
        raise KeyboardInterrupt
    assert target.read_text() == "old"
    assert [p.name for p in tmp_path.iterdir()] == ["report.html"]


def test_files_written_together_appear_together_or_not_at_all(tmp_path):
    a, b = tmp_path / "report.json", tmp_path / "tables" / "t.csv"
    a.write_text("old json")
    with pytest.raises(KeyboardInterrupt), together():
        write_text(a, "new json")
        assert a.read_text() == "old json"  # not yet: the rename waits for the block
        write_text(b, "new table")
        raise KeyboardInterrupt  # e.g. while the HTML's plots are drawn
    assert a.read_text() == "old json" and not b.exists()
    assert not list(tmp_path.rglob("*.part"))
    with together():
        write_text(a, "new json")
        write_text(b, "new table")
    assert a.read_text() == "new json" and b.read_text() == "new table"
    assert not list(tmp_path.rglob("*.part"))


def test_a_write_outside_together_is_renamed_at_once(tmp_path):
    with together():
        pass
    write_text(tmp_path / "x", "1")
    assert (tmp_path / "x").read_text() == "1"


def test_file_set_publishes_a_whole_set_by_one_link(tmp_path):
    import signal

    from dracc.core.atomic import CURRENT, RUNS, deferred_signals, file_set

    out = tmp_path / "out"
    done: list[str] = []
    with file_set(out, done) as stage:
        (stage / "a.csv").write_text("1")
        (stage / "sub").mkdir()
        (stage / "sub" / "b.csv").write_text("1")
    assert len(done) == 1 and os.readlink(out / CURRENT) == os.path.join(RUNS, done[0])
    assert (out / "a.csv").read_text() == "1" and (out / "sub" / "b.csv").read_text() == "1"
    again: list[str] = []
    with pytest.raises(KeyboardInterrupt), file_set(out, again) as stage:
        (stage / "a.csv").write_text("2")
        raise KeyboardInterrupt
    assert again == [] and (out / "a.csv").read_text() == "1"
    assert len(os.listdir(out / RUNS)) == 1  # the staging folder went with the interrupt
    with file_set(out) as stage:  # a set without sub/: its link goes
        (stage / "a.csv").write_text("3")
    assert (out / "a.csv").read_text() == "3" and not os.path.lexists(out / "sub")
    # SIGINT inside a critical section is held until its end, then acted on
    with pytest.raises(KeyboardInterrupt), deferred_signals():
        signal.raise_signal(signal.SIGINT)
        reached = True
    assert reached


def test_a_device_or_fifo_target_is_written_in_place_not_replaced(tmp_path):
    """Regression (issue 15): `--json /dev/null` as root renamed a regular file onto
    /dev/null.  A target that is not a regular file is written as it is."""
    import threading

    fifo = tmp_path / "out.json"
    os.mkfifo(fifo)
    got = []
    reader = threading.Thread(target=lambda: got.append(fifo.read_text()), daemon=True)
    reader.start()
    write_text(fifo, "{}")
    reader.join(30)
    assert got == ["{}"] and stat.S_ISFIFO(os.stat(fifo).st_mode)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.json"]
