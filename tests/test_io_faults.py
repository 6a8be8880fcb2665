"""Issue 33: every I/O fault is one line with its exit code (6, ``OutputError``), never an
internal error (exit 5), for every command that writes: a full disk (ENOSPC, injected at
the fsync every output goes through), a read-only folder (chmod 0o500; as root, where a
mode does not stop a write, EROFS injected at ``open``/``mkdir``), a file where a folder
is to go and a folder where a file is to go.  Nothing partial is left and an earlier
output is kept; the audit's reports appear together or not at all; ``watch --record``
goes on listening when the disk fills, says so once and never cuts a line.
"""

from __future__ import annotations

import errno
import json
import os
from collections.abc import Callable
from pathlib import Path

import pytest
from conftest import SPARSE_RATES

import dracc.cli.audit_cmd as audit_cmd
from dracc.cli.main import main
from dracc.core.errors import ExitCode
from dracc.ingest.live import record as record_mod
from dracc.ingest.live.base import LiveSource
from dracc.ingest.live.record import Recorder
from dracc.pipeline.watch import Watch

NIGHT = "2026-11-18"
EARLIER = "an earlier output"


def _run(capsys, *args: object) -> tuple[int, str, str]:
    code = main([str(a) for a in args])
    cap = capsys.readouterr()
    return code, cap.out, cap.err


@pytest.fixture(scope="module")
def ship(tmp_path_factory) -> dict[str, Path]:
    """A simulated 20 min (low rates) in a vessel folder, and a state database holding its
    night (for ``audit history``)."""
    root = tmp_path_factory.mktemp("ship")
    logs = root / "logs"
    argv = ["simulate", "--out", logs, "--hours", "0.3", "--seed", "5", "--name", f"nav-{NIGHT}"]
    assert main([str(a) for a in [*argv, "--start", f"{NIGHT}T00:00:00Z", *SPARSE_RATES]]) == 0
    for extra in ("truth.csv", "errors.csv", "params.json"):
        (logs / extra).unlink()
    log, db = logs / f"nav-{NIGHT}.nmea", root / "state.sqlite"
    assert main(["audit", str(log), "--date", NIGHT, "--db", str(db)]) in (0, 1)
    return {"log": log, "logs": logs, "db": db}


# ------------------------------------------------------------------ the faults


def _under(path: object, folder: Path) -> bool:
    where = Path(os.path.abspath(os.fsdecode(path)))  # type: ignore[arg-type]
    return where == folder or folder in where.parents


def disk_full(monkeypatch, folder: Path) -> None:
    """Every file under ``folder`` fails its fsync with ENOSPC (a disk that fills while
    the output is written: a delayed allocation tells at fsync, a write at once)."""
    real = os.fsync

    def fsync(fd: int) -> None:
        try:
            where = os.readlink(f"/proc/self/fd/{fd}")
        except OSError:
            where = ""
        if where and _under(where, folder):
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        real(fd)

    monkeypatch.setattr(os, "fsync", fsync)


def read_only(monkeypatch, folder: Path, request) -> None:
    """``folder`` refuses new files and folders: mode 0o500, or (as root, whom a mode
    does not stop) EROFS from ``open`` for writing and ``mkdir`` under it."""
    if os.geteuid() != 0:
        folder.chmod(0o500)
        request.addfinalizer(lambda: folder.chmod(0o700))
        return
    real_open, real_mkdir = os.open, os.mkdir
    writing = os.O_WRONLY | os.O_RDWR | os.O_CREAT

    def refuse(path: object) -> OSError:
        return OSError(errno.EROFS, os.strerror(errno.EROFS), os.fsdecode(path))  # type: ignore[arg-type]

    def open_(path, flags, mode=0o777, *, dir_fd=None):
        if flags & writing and _under(path, folder):
            raise refuse(path)
        return real_open(path, flags, mode, dir_fd=dir_fd)

    def mkdir(path, mode=0o777, *, dir_fd=None):
        if _under(path, folder):  # as the kernel: an existing name first
            if os.path.lexists(path):
                raise FileExistsError(errno.EEXIST, os.strerror(errno.EEXIST), path)
            raise refuse(path)
        return real_mkdir(path, mode, dir_fd=dir_fd)

    monkeypatch.setattr(os, "open", open_)
    monkeypatch.setattr(os, "mkdir", mkdir)


# ------------------------------------------------------------------ the commands

#: (id, the output's name in the folder, is it a folder, argv given the ship and the output)
COMMANDS: list[tuple[str, str, bool, Callable[[dict, Path], list]]] = [
    ("audit --json", "a.json", False,
     lambda s, o: ["audit", s["log"], "--date", NIGHT, "--db", s["db"], "--json", o]),
    ("audit --summary", "a.txt", False,
     lambda s, o: ["audit", s["log"], "--date", NIGHT, "--db", s["db"], "--summary", o]),
    ("audit --html", "a.html", False,
     lambda s, o: ["audit", s["log"], "--date", NIGHT, "--db", s["db"], "--html", o]),
    ("audit history --html", "h.html", False,
     lambda s, o: ["audit", "history", "--db", s["db"], "--html", o]),
    ("audit history --json", "h.json", False,
     lambda s, o: ["audit", "history", "--db", s["db"], "--json", o]),
    ("fleet --out", "fleet", True,
     lambda s, o: ["fleet", s["logs"], "--out", o, "--workers", "1"]),
    ("simulate --out", "sim", True,
     lambda s, o: ["simulate", "--out", o, "--hours", "0.05", *SPARSE_RATES]),
    ("analyze --json", "r.json", False, lambda s, o: ["analyze", s["log"], "--json", o]),
    ("analyze --html", "r.html", False, lambda s, o: ["analyze", s["log"], "--html", o]),
    ("analyze --out", "tables", True, lambda s, o: ["analyze", s["log"], "--out", o]),
    ("analyze --gpx", "r.gpx", False, lambda s, o: ["analyze", s["log"], "--gpx", o]),
    ("analyze --mcap", "r.mcap", False, lambda s, o: ["analyze", s["log"], "--mcap", o]),
    ("records --out", "r.parquet", False, lambda s, o: ["records", s["log"], "--out", o]),
    ("records --out csv", "r.csv", False, lambda s, o: ["records", s["log"], "--out", o]),
    ("watch --status", "w.json", False,
     lambda s, o: ["watch", s["log"], "--status", o, "--duration", "0.3s", "--no-analysis"]),
    ("watch --record", "rec", True,
     lambda s, o: ["watch", s["log"], "--record", o, "--duration", "0.3s", "--no-analysis"]),
]  # fmt: skip


@pytest.fixture
def cheap_pages(monkeypatch):
    """The pages are rendered as usual but without their plots' cost (seconds each): what
    is tested here is the writing, not the page."""
    monkeypatch.setattr(audit_cmd, "audit_page", lambda outcome, doc: "<p>audit page</p>")
    monkeypatch.setattr(audit_cmd, "history_html", lambda doc: "<p>history page</p>")
    import dracc.report.html as html_report

    monkeypatch.setattr(html_report, "render_html", lambda result: "<p>report</p>")


def _one_line_exit_6(code: int, err: str, name: str) -> None:
    assert code == ExitCode.OUTPUT, err
    assert err.count("\n") == 1 and err.startswith("error: cannot write "), err
    assert name in err and "Traceback" not in err and "internal error" not in err, err


def _no_temporaries(folder: Path) -> None:
    left = [p for p in folder.rglob("*") if p.name.endswith(".part") or p.name.startswith("tmp-")]
    assert not left, left


#: every command and fault; a recording that finds the disk full goes on listening
#: (tests below), it does not stop at the start
FAULTS = [
    pytest.param(c, f, id=f"{c[0]}, {f}")
    for c in COMMANDS
    for f in ("disk full", "read-only")
    if (c[0], f) != ("watch --record", "disk full")
]


@pytest.mark.parametrize(("cmd", "fault"), FAULTS)
def test_a_write_fault_is_one_line_exit_6(
    capsys, monkeypatch, request, tmp_path, ship, cheap_pages, cmd, fault
):
    _, name, is_folder, argv = cmd
    folder = tmp_path / "out"
    folder.mkdir()
    target = folder / name
    if not is_folder and not name.startswith("a."):  # the audit replaces them (see below)
        target.write_text(EARLIER)
    if fault == "disk full":
        disk_full(monkeypatch, folder)
    else:
        read_only(monkeypatch, folder, request)
    code, _, err = _run(capsys, *argv(ship, target))
    monkeypatch.undo()
    folder.chmod(0o700)
    _one_line_exit_6(code, err, str(folder))
    reason = "disk full" if fault == "disk full" else "read-only file system"
    assert reason in err or "permission denied" in err, err
    if not is_folder and not name.startswith("a."):
        assert target.read_text() == EARLIER  # the earlier output is kept
    _no_temporaries(folder)


@pytest.mark.parametrize(
    "cmd",
    [c for c in COMMANDS if c[0] in ("audit --json", "analyze --out", "simulate --out",
                                     "records --out", "watch --status", "watch --record",
                                     "fleet --out", "audit history --html")],
    ids=lambda c: c[0],
)  # fmt: skip
def test_a_file_in_the_way_of_a_folder(capsys, tmp_path, ship, cheap_pages, cmd):
    _, name, _, argv = cmd
    blocker = tmp_path / "blocker"
    blocker.write_text("a file, not a folder")
    code, _, err = _run(capsys, *argv(ship, blocker / "x" / name))
    _one_line_exit_6(code, err, f"{blocker} is a file, not a folder")
    assert blocker.read_text() == "a file, not a folder"


@pytest.mark.parametrize(
    "cmd",
    [c for c in COMMANDS if c[0] in ("audit --summary", "analyze --json", "records --out",
                                     "watch --status", "audit history --html")],
    ids=lambda c: c[0],
)  # fmt: skip
def test_a_folder_in_the_way_of_a_file(capsys, tmp_path, ship, cheap_pages, cmd):
    _, name, _, argv = cmd
    (tmp_path / name / "inside").mkdir(parents=True)
    code, _, err = _run(capsys, *argv(ship, tmp_path / name))
    _one_line_exit_6(code, err, "it is a folder, not a file")
    assert (tmp_path / name / "inside").is_dir()


def test_an_output_folder_that_is_a_file(capsys, tmp_path, ship):
    (tmp_path / "sim").write_text(EARLIER)
    code, _, err = _run(capsys, "simulate", "--out", tmp_path / "sim", "--hours", "0.05")
    _one_line_exit_6(code, err, f"{tmp_path / 'sim'} is a file, not a folder")


# ------------------------------------------------------------------ the audit's report set


def test_full_disk_leaves_no_json_without_its_html_and_summary(
    capsys, monkeypatch, tmp_path, ship, cheap_pages
):
    """The disk fills while the page is written: tonight's verdict may not appear in
    a.json beside last night's page; the three say the failure (or are gone)."""
    paths = {n: tmp_path / f"a.{n}" for n in ("json", "html", "txt")}
    for p in paths.values():
        p.write_text("last night: 8 findings")
    real = os.fsync

    def fsync(fd: int) -> None:
        if os.readlink(f"/proc/self/fd/{fd}").startswith(str(tmp_path / ".a.html.")):
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        real(fd)

    monkeypatch.setattr(os, "fsync", fsync)
    code, _, err = _run(
        capsys, "audit", ship["log"], "--date", NIGHT, "--db", tmp_path / "s.sqlite",
        "--json", paths["json"], "--html", paths["html"], "--summary", paths["txt"],
    )  # fmt: skip
    _one_line_exit_6(code, err, f"{paths['html']}: no space left on the device (disk full)")
    doc = json.loads(paths["json"].read_text())
    assert (doc["status"], doc["exit_code"], doc["error"]["kind"]) == ("failed", 6, "output error")
    assert paths["txt"].read_text().startswith("dracc audit: FAILED, exit 6 (output error)")
    assert not paths["html"].exists()  # its failure page could not be written either: removed
    _no_temporaries(tmp_path)


# ------------------------------------------------------------------ watch --record


def _lines(n: int, k0: int = 0) -> list[bytes]:
    return [b"$GPHDT,%d.5,T*00" % (k0 + k) for k in range(n)]


def test_recorder_keeps_whole_lines_when_the_disk_fills(monkeypatch, tmp_path):
    """A write cut short by a full disk is cut back to its last whole line; the lines
    then heard are counted as lost; writing resumes when the disk has room again."""
    clock = [1_700_000_000 * 10**9]
    rec = Recorder(tmp_path, now_ns=lambda: clock[0], flush_lines=10)
    real = os.pwrite
    full = [False]

    def pwrite(fd: int, data, offset: int) -> int:
        if full[0]:  # half of it goes to the file, then the disk is full
            real(fd, bytes(data[: len(data) // 2]), offset)
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        return real(fd, data, offset)

    monkeypatch.setattr(os, "pwrite", pwrite)
    for ln in _lines(20):
        rec.write(ln, clock[0])
    full[0] = True
    for ln in _lines(25, 20):
        rec.write(ln, clock[0])
    assert rec.fault is not None and "disk full" in rec.fault
    part = rec.current
    assert part is not None and part.read_bytes().endswith(b"\r\n")
    assert part.read_bytes().count(b"\r\n") == 20 and rec.lost == 25
    full[0] = False
    clock[0] += int(record_mod.RETRY_S * 1e9)  # retried after RETRY_S, cleared RETRY_S later
    for step in range(3):
        for ln in _lines(10, 100 + 10 * step):
            rec.write(ln, clock[0])
        clock[0] += int(record_mod.RETRY_S * 1e9 / 2)
    assert rec.fault is None and rec.lost == 25 and rec.lines == 75
    rec.close()
    (done,) = rec.files
    data = done.read_bytes()
    assert data.count(b"\r\n") == 50 and data.endswith(b"\r\n")
    assert all(line.startswith(b"\\c:") for line in data.split(b"\r\n")[:-1])


class _Lines(LiveSource):
    kind = "test"

    def __init__(self) -> None:
        super().__init__("test", 4096, 100)
        self.todo: list[bytes] = []

    def poll(self, timeout_s: float = 0.0) -> list[tuple[int, bytes]]:
        out, self.todo = self.todo, []
        self.lines += len(out)
        return [(self.clock(), ln) for ln in out]

    clock: Callable[[], int] = staticmethod(lambda: 0)  # type: ignore[assignment]


def test_watch_keeps_listening_and_says_so_once(monkeypatch, tmp_path):
    now = [1_700_000_000 * 10**9]
    src = _Lines()
    src.clock = lambda: now[0]  # type: ignore[method-assign]
    rec = Recorder(tmp_path, now_ns=lambda: now[0], flush_lines=5)
    watch = Watch([src], rec, dropout_s=1e6, clock=lambda: now[0])
    monkeypatch.setattr(
        os, "pwrite", lambda *a: (_ for _ in ()).throw(OSError(errno.ENOSPC, "No space"))
    )
    events = []
    for k in range(30):  # 30 s of lines on a full disk
        src.todo = _lines(10, 10 * k)
        events += watch.step(0)
        now[0] += 10**9
    raised = [e for e in events if e["check"] == "recording"]
    assert [(e["event"], e["name"]) for e in raised] == [("raised", "write_failed")]
    assert "disk full" in raised[0]["message"] and "still listening" in raised[0]["message"]
    st = watch.status()
    assert st["received"] == 300 and st["recording_lost"] == 300
    assert [f["evidence"] for f in st["findings"]] == [{"lost_lines": 300}]
    monkeypatch.undo()
    for k in range(30):  # the disk has room again
        src.todo = _lines(10, 1000 + 10 * k)
        events += watch.step(0)
        now[0] += 10**9
    cleared = [e for e in events if e["check"] == "recording" and e["event"] == "cleared"]
    assert len(cleared) == 1 and "recording again; 300 lines" in cleared[0]["message"]
    watch.close()
    assert sum(p.read_bytes().count(b"\r\n") for p in rec.files) == rec.lines - rec.lost > 200


def test_a_read_only_recording_folder_is_found_at_the_start(
    capsys, monkeypatch, request, tmp_path, ship
):
    """The folder exists but takes no file: exit 6 before listening, not a fault at the
    first line heard."""
    folder = tmp_path / "rec"
    folder.mkdir()
    read_only(monkeypatch, folder, request)
    code, _, err = _run(capsys, "watch", ship["log"], "--record", folder, "--duration", "5s")
    monkeypatch.undo()
    _one_line_exit_6(code, err, str(folder))
    assert not list(folder.iterdir())
