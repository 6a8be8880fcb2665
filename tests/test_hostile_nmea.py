"""Hostile and damaged NMEA input (issue 15): memory bounded by a cap and not by the
content, every line end a logger writes, MCAP files damaged in transfer, and reader
workers that never outlive their parent.

The memory and worker tests run ``dracc`` in a subprocess (peak RSS from
``getrusage(RUSAGE_CHILDREN)`` of a small wrapper process, workers found through
``/proc``); the benchmark with 256 MB of NUL bytes is ``benchmarks/`` (the lead's).
"""

from __future__ import annotations

import json
import os
import random
import signal
import subprocess
import sys
import textwrap
import threading
import time
from collections import Counter
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from dracc.core.config import IngestConfig
from dracc.core.errors import ExitCode, IngestError
from dracc.ingest import detect_format, nmea, read_logs
from dracc.ingest.memory import HANDOVER_PREFIX, sweep_handover
from dracc.ingest.nmea import (
    StreamState,
    engine_c,
    engine_numpy,
    iter_nmea_blocks,
    parse_buffer,
    read_nmea,
)
from dracc.ingest.nmea.blocks import block_ranges

REPO = Path(__file__).resolve().parents[1]
SAMPLES = REPO / "sample_logs"
MB = 1024 * 1024


def _sample_lines(name: str = "voyage_tag.nmea") -> list[bytes]:
    return [ln for ln in (SAMPLES / name).read_bytes().split(b"\r\n") if ln]


def _env(**extra: str) -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(REPO)] + [p for p in [env.get("PYTHONPATH")] if p])
    env.update(extra)
    return env


def _dracc() -> list[str]:
    return [sys.executable, "-m", "dracc"]


# ------------------------------------------------------------------ 1. memory is capped
def _write_with_run(
    path: Path, before: list[bytes], filler: bytes, run_bytes: int, after: list[bytes]
) -> None:
    """``before`` lines, a run of ``filler`` without any line end, then ``after`` lines
    (the first of them right after the run, on its line: a logger restarted after a crash)."""
    chunk = (filler * (MB // len(filler) + 1))[:MB]
    with path.open("wb") as fh:
        fh.write(b"\r\n".join(before) + b"\r\n")
        left = run_bytes
        while left > 0:
            fh.write(chunk[: min(left, MB)])
            left -= MB
        fh.write(b"\r\n".join(after) + b"\r\n")


_PEAK = textwrap.dedent("""
    import resource, subprocess, sys
    r = subprocess.run(sys.argv[1:], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    sys.stderr.write(r.stderr.decode("utf-8", "replace"))
    print(r.returncode, resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss)
""")


def _peak_rss_mb(args: list[str], env: dict[str, str]) -> tuple[int, float, str]:
    """(exit code, peak RSS in MiB of the largest process of the run, stderr) of a command:
    the maximum over the command and the workers it waited for."""
    r = subprocess.run(
        [sys.executable, "-c", _PEAK, *args], capture_output=True, env=env, timeout=600
    )
    code, kb = r.stdout.split()
    return int(code), int(kb) / 1024, r.stderr.decode("utf-8", "replace")


RUN_MB = 64  #: the run of damage in the memory tests (the lead's benchmark: 256 MB)
PEAK_LIMIT_MB = 300  #: before the cap: 2.2 GB for 64 MB of NUL bytes (`dracc inspect`)


def _analyze_damaged(tmp_path: Path, filler: bytes, engine: str = "c"):
    """(analysis JSON, peak RSS MiB, read_nmea of the good lines alone) of a damaged log."""
    lines = _sample_lines()
    before, after = lines[:3000], lines[3000:6000]
    p = tmp_path / "crashed.nmea"
    _write_with_run(p, before, filler, RUN_MB * MB, after)
    assert p.stat().st_size > nmea.PARALLEL_MIN_BYTES  # the two reader workers take part
    out = tmp_path / "a.json"
    code, peak, err = _peak_rss_mb(
        _dracc() + ["analyze", str(p), "--json", str(out)], _env(DRACC_NMEA_ENGINE=engine)
    )
    assert code == ExitCode.OK, err
    assert "Traceback" not in err
    doc = json.loads(out.read_text())
    good = tmp_path / "good.nmea"
    good.write_bytes(b"\r\n".join(before + after) + b"\r\n")
    want = read_nmea(good, IngestConfig(), workers=1)
    return doc, peak, want


@pytest.mark.parametrize("engine", ["c", "numpy"])
def test_long_nul_run_memory_is_bounded(tmp_path, engine):
    """A crashed logger's file: good sentences, 64 MB of NUL bytes without a line end,
    good sentences (the first right after the NUL bytes).  The run is one line too long
    (``too_long``), never held in memory; every good sentence is kept, the one after the
    run too; peak RSS (main process and workers) stays far below the 512 MB cap.
    Before: 23 bytes of memory per byte of the run (2.2 GB here)."""
    doc, peak, want = _analyze_damaged(tmp_path, b"\x00", engine)
    assert doc["rejected"] == {"too_long": 1}
    assert doc["inputs"][0]["records"] == want.records
    assert doc["inputs"][0]["lines"] == want.lines  # the run and the sentence after it: one line
    ex = doc["reject_examples"]["too_long"][0]
    assert ex["line"] == 3001 and set(ex["text"]) == {"\x00"}
    assert peak < PEAK_LIMIT_MB, f"peak RSS {peak:.0f} MiB"


@pytest.mark.parametrize("filler", [b"A", b"$GPGGA,", b"1234567890,"], ids=["A", "gga", "digits"])
def test_long_garbage_run_without_line_ends_memory_is_bounded(tmp_path, filler):
    """The same with 64 MB of printable junk without a line end ('A', '$GPGGA,' repeated:
    before, 9.6 million 'truncated' sentences and 2.3 GB): one ``too_long`` line, whose
    last sentence (with its TAG block) is read."""
    doc, peak, want = _analyze_damaged(tmp_path, filler)
    assert doc["rejected"] == {"too_long": 1}
    assert doc["inputs"][0]["records"] == want.records
    assert peak < PEAK_LIMIT_MB, f"peak RSS {peak:.0f} MiB"


def _same_result(a, b) -> None:
    assert a.lines == b.lines
    assert a.rejects.counts == b.rejects.counts, (a.rejects.counts, b.rejects.counts)
    assert a.rejects.examples == b.rejects.examples
    assert a.ignored == b.ignored
    for kind in set(a.frames) | set(b.frames):
        pd.testing.assert_frame_equal(
            _labels(a.frames[kind]), _labels(b.frames[kind]), check_exact=True
        )


def _labels(df: pd.DataFrame) -> pd.DataFrame:
    """Categorical columns as their labels (the order of categories depends on the blocks)."""
    return df.assign(
        **{
            c: df[c].astype(str).to_numpy(object)
            for c in df.columns
            if isinstance(df[c].dtype, pd.CategoricalDtype)
        }
    )


def _read_blocks(path: Path, cfg: IngestConfig, block_bytes: int):
    """read_nmea's result, through the block streamer with blocks of ``block_bytes``."""
    from dracc.frames import FileResult, concat_blocks

    st = StreamState(str(path))
    blocks = [b.frames for b in iter_nmea_blocks(path, cfg, st, block_bytes=block_bytes, workers=1)]
    return FileResult(
        path=str(path),
        format="nmea",
        frames=concat_blocks(blocks),
        lines=st.lines,
        rejects=st.rejects,
        time_events=st.time_events(),
        notes=st.notes(),
        ignored=st.ignored,
        ignored_examples=st.ignored_examples,
    )


@pytest.mark.parametrize("engine", ["c", "numpy"])
def test_lines_too_long_give_the_same_result_whatever_the_blocks(tmp_path, monkeypatch, engine):
    """Lines longer than ``max_line_bytes`` inside a block (parsed in memory) and across
    block cuts (found by the block splitter, never read whole) give the same records,
    rejects and examples, with either engine; a block is never longer than its size plus
    ``max_line_bytes``."""
    monkeypatch.setattr(engine_c, "ENGINE", engine)
    lines = _sample_lines()[:400]
    tag = lines[7]
    damaged = list(lines)
    damaged[20] = b"\x00" * 5000 + tag  # NUL run, then a sentence with its TAG block
    damaged[50] = b"A" * 3000  # junk, no sentence
    damaged[90] = b"$GPGGA," * 700 + tag  # junk sentence starts, then a good one
    damaged[130] = lines[130] + b"\x00" * 4000  # a good sentence, then a NUL run
    damaged[170] = b"\x00" * 999  # within the cap: one 'binary' line
    sentence = lines[171][lines[171].index(b"\\$") + 1 :]
    damaged[171] = (
        b"\\s:GYRO,c:1," + b"x" * 2000 + b"*00\\" + sentence
    )  # TAG block too long: not read
    p = tmp_path / "d.nmea"
    p.write_bytes(b"\r\n".join(damaged))  # and no final line end
    cfg = IngestConfig(max_line_bytes=1000)
    whole = read_nmea(p, cfg, workers=1)
    assert whole.rejects.counts["too_long"] == 5
    assert whole.rejects.counts["binary"] == 1
    for ln in (21, 91):  # the tails' sentences are read, with their TAG source and time
        assert any(ln in set(df["line"]) for df in whole.frames.values() if len(df))
    assert not any(131 in set(df["line"]) for df in whole.frames.values() if len(df))
    for block_bytes in (256, 999, 4096, 30_000):
        _same_result(_read_blocks(p, cfg, block_bytes), whole)
    # the splitter: blocks bounded although a line holds no line end for 5 000 bytes
    ranges = list(block_ranges(p, 256, max_line_bytes=1000))
    assert max(ln for _, ln, too_long in ranges if not too_long) <= 256 + 1000 + 3
    assert sum(ln for _, ln, _ in ranges) == p.stat().st_size
    assert [too_long for _, _, too_long in ranges].count(True) >= 3


def test_numpy_path_parses_dense_junk_in_pieces(monkeypatch):
    """Dense junk (a sentence start every two bytes, lines of two bytes, NUL bytes with
    lone CRs) and real logs are parsed in pieces of bounded working memory and merged:
    the same block as one parse gives (line numbers, seq, TAG source codes in order of
    first appearance, the first examples), in either engine."""
    from test_fuzz import mutate
    from test_nmeascan import assert_same_block

    rng = random.Random(4)
    tag = _sample_lines()[:3000]
    datas = [
        b"$," * 30_000,
        b"x\n" * 30_000,
        b"\x00\r" * 20_000 + b"$GPHDT,1,T*00\n",
        b"\r\n".join(tag),
        b"\r\n".join(_sample_lines("voyage_prefix.nmea")[:3000]),
        mutate(tag, rng, 300).data,
        mutate(tag, rng, 300).data,
    ]

    def parse(data, engine, budget, chunk):
        monkeypatch.setattr(engine_numpy, "PIECE_BUDGET", budget)
        monkeypatch.setattr(engine_numpy, "NUMPY_CHUNK_BYTES", chunk)
        return parse_buffer(data, engine=engine)

    for data in datas:
        whole = parse(data, "numpy", 1 << 40, 1 << 40)
        for budget, chunk in ((200_000, 1 << 40), (1 << 40, 20_000), (300_000, 50_000)):
            assert_same_block(parse(data, "numpy", budget, chunk), whole)
            assert_same_block(parse(data, "c", budget, chunk), whole)


# ------------------------------------------------------------------ 2. line ends
LINE_ENDS = {"lf": b"\n", "cr": b"\r", "crlf": b"\r\n", "crcrlf": b"\r\r\n"}


@pytest.fixture(scope="module")
def voyage():
    from dracc.sim import SimParams, simulate

    return simulate(SimParams(duration_s=60.0, seed=5))


def _write_form(voyage, path: Path, form: str, newline: bytes) -> Path:
    from dracc.sim.nmea_out import write_nmea

    write_nmea(voyage, path, form=form, newline=newline)
    return path


def _check_like_lf(tmp_path: Path, voyage, newline_of, name: str) -> None:
    """Each form written with LF and with ``newline_of(lf_data)``: the same result (records,
    line numbers, times, sources), no reject, through every engine and block size."""
    for form in ("tag", "prefix", "bare"):
        lf = _write_form(voyage, tmp_path / f"{form}-lf.nmea", form, b"\n")
        other = tmp_path / f"{form}-{name}.nmea"
        other.write_bytes(newline_of(lf.read_bytes()))
        want = read_nmea(lf, IngestConfig(), workers=1)
        assert want.records > 0 and not want.rejects.counts
        for engine in ("c", "numpy"):
            old = engine_c.ENGINE
            engine_c.ENGINE = engine
            try:
                _same_result(read_nmea(other, IngestConfig(), workers=1), want)
                _same_result(_read_blocks(other, IngestConfig(), 16384), want)
            finally:
                engine_c.ENGINE = old


def test_cr_only_line_ends_give_records(tmp_path, voyage):
    """A log with CR-only line ends (old Mac loggers, serial capture tools) gave 0 records
    (every line one 'truncated' sentence); now the same records and line numbers as LF."""
    _check_like_lf(tmp_path, voyage, lambda d: d.replace(b"\n", b"\r"), "cr")


def test_cr_cr_lf_line_ends(tmp_path, voyage):
    """CR CR LF (CR LF through a text-mode conversion) is one line end, not an empty line:
    the same lines and records as LF (before: every sentence rejected)."""
    _check_like_lf(tmp_path, voyage, lambda d: d.replace(b"\n", b"\r\r\n"), "crcrlf")


def test_crlf_line_ends(tmp_path, voyage):
    _check_like_lf(tmp_path, voyage, lambda d: d.replace(b"\n", b"\r\n"), "crlf")


def test_mixed_line_ends(tmp_path, voyage):
    """LF, CR, CR LF and CR CR LF mixed line by line (logs concatenated from several
    recorders): the same as LF."""
    rng = random.Random(3)
    ends = list(LINE_ENDS.values())
    _check_like_lf(
        tmp_path,
        voyage,
        lambda d: b"".join(ln + rng.choice(ends) for ln in d.split(b"\n")[:-1]),
        "mixed",
    )


@pytest.mark.parametrize("name", sorted(LINE_ENDS))
def test_line_ends_cut_at_every_block_boundary(tmp_path, name):
    """A block may be cut anywhere: between CR and LF, between the two CRs of CR CR LF.
    The splitter moves the cut to after the whole line end, so every block size gives
    the same lines as one block."""
    from test_fuzz import line_starts

    lines = _sample_lines()[:40]
    p = tmp_path / "e.nmea"
    data = LINE_ENDS[name].join(lines) + LINE_ENDS[name]
    p.write_bytes(data)
    starts = set(line_starts(data)) | {len(data)}
    for block_bytes in range(40, 110):  # the cut falls at every offset of the lines
        cuts = [off + ln for off, ln, _ in block_ranges(p, block_bytes)]
        assert set(cuts) <= starts, block_bytes
    want = read_nmea(p, IngestConfig(), workers=1)
    assert want.lines == 40 and not want.rejects.counts
    for block_bytes in (41, 58, 67, 83, 97):
        _same_result(_read_blocks(p, IngestConfig(), block_bytes), want)


def test_cr_only_log_through_dracc_inspect(run_cli, tmp_path):
    lines = _sample_lines()[:300]
    p = tmp_path / "mac.nmea"
    p.write_bytes(b"\r".join(lines) + b"\r")
    code, out, err = run_cli("inspect", p, "--json", "-")
    assert code == ExitCode.OK, err
    doc = json.loads(out)
    assert doc["lines"] == 300 and doc["rejected"] == {}
    assert sum(s["records"] for s in doc["sources"].values()) == 300


# ------------------------------------------------------------------ 3. damaged containers
@pytest.fixture(scope="module")
def mcap_bytes(tmp_path_factory) -> bytes:
    """A real MCAP from dracc's own writer (a short simulated voyage)."""
    from dracc.sim import SimParams, simulate
    from dracc.sim.mcap_out import write_mcap

    v = simulate(SimParams(duration_s=120.0, seed=2))
    p = tmp_path_factory.mktemp("mcap") / "v.mcap"
    write_mcap(v.frames, v.roles, p)
    data = p.read_bytes()
    assert data.startswith(b"\x89MCAP0\r\n") and data.count(b"\r") > 1
    return data


def _one_line_error(code: int, err: str, *needles: str) -> None:
    assert code == ExitCode.INPUT, err
    assert "Traceback" not in err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: "), err
    for n in needles:
        assert n in lines[0], lines[0]


def test_mcap_with_stripped_cr_is_named_a_damaged_container(run_cli, tmp_path, mcap_bytes):
    """An MCAP whose CR bytes were stripped in transfer (the magic ``\\x89MCAP0\\r\\n``
    becomes ``\\x89MCAP0\\n``) was read as NMEA text: `dracc inspect` exited 0, and beside a
    good log it was dropped without a word.  Now a one-line error names it and the damage,
    alone or among other files."""
    bad = tmp_path / "recorder.mcap"
    bad.write_bytes(mcap_bytes.replace(b"\r", b""))
    with pytest.raises(
        IngestError,
        match=r"recorder\.mcap.*MCAP file damaged in transfer "
        r"\(CR bytes stripped: was it copied in text mode\?\)",
    ):
        detect_format(bad)
    code, _, err = run_cli("inspect", bad)
    _one_line_error(code, err, "recorder.mcap", "CR bytes stripped")
    good = tmp_path / "good.nmea"
    good.write_bytes(b"\r\n".join(_sample_lines()[:2000]) + b"\r\n")
    for args in (("inspect", good, bad), ("analyze", good, bad), ("analyze", bad, good)):
        code, _, err = run_cli(*args)
        _one_line_error(code, err, "recorder.mcap", "damaged in transfer")
    with pytest.raises(IngestError, match=r"recorder.mcap"):
        read_logs([good, bad], IngestConfig())


@pytest.mark.parametrize(
    "damage,why",
    [
        (lambda d: d.replace(b"\n", b"\r\n"), "LF bytes turned into CR LF"),
        (lambda d: bytes(b & 0x7F for b in d), "0x09, not 0x89"),
        (lambda d: d.decode("latin-1").encode("utf-8"), "re-encoded as UTF-8"),
        (lambda d: d[4096:], "its beginning is missing"),
        (lambda d: d[:200].replace(b"\r", b"") + d[200:], "CR bytes stripped"),
    ],
    ids=["lf-to-crlf", "7-bit", "utf-8", "head-lost", "magic-only"],
)
def test_mcap_damaged_in_other_ways_is_named(run_cli, tmp_path, mcap_bytes, damage, why):
    bad = tmp_path / "rec.mcap"
    bad.write_bytes(damage(mcap_bytes))
    code, _, err = run_cli("inspect", bad)
    _one_line_error(code, err, "rec.mcap", why)


def test_intact_mcap_and_text_that_mentions_mcap_are_not_damaged(tmp_path, mcap_bytes):
    ok = tmp_path / "ok.mcap"
    ok.write_bytes(mcap_bytes)
    assert detect_format(ok) == "mcap"
    txt = tmp_path / "t.nmea"
    txt.write_bytes(
        b"MCAP0,1,2\r\n$GPTXT,01,01,02,MCAP0*00\r\n" + b"\r\n".join(_sample_lines()[:5])
    )
    assert detect_format(txt) == "nmea"


# ------------------------------------------------------------------ 4. orphan workers
def _children(pid: int) -> set[int]:
    out: set[int] = set()
    try:
        for tid in os.listdir(f"/proc/{pid}/task"):
            with open(f"/proc/{pid}/task/{tid}/children") as fh:
                out |= {int(x) for x in fh.read().split()}
    except OSError:
        pass
    return out


def _alive(pid: int) -> bool:
    """Running (a zombie waiting for a reaper that never comes counts as gone)."""
    try:
        with open(f"/proc/{pid}/stat") as fh:
            state = fh.read().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state not in ("Z", "X")


def _assert_gone_with_eof(proc: subprocess.Popen, workers: set[int], timeout: float = 10.0) -> None:
    """After its parent's SIGKILL: the workers end within seconds and the parent's stdout
    and stderr pipes reach EOF (no worker holds them: cron's mail would hang)."""
    eof = {}

    def drain(name, stream):
        stream.read()
        eof[name] = time.monotonic()

    threads = [
        threading.Thread(target=drain, args=(n, s), daemon=True)
        for n, s in (("stdout", proc.stdout), ("stderr", proc.stderr))
    ]
    for t in threads:
        t.start()
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout and any(_alive(w) for w in workers):
        time.sleep(0.05)
    left = [w for w in workers if _alive(w)]
    for w in left:  # do not leave them behind on a failure
        os.kill(w, signal.SIGKILL)
    assert not left, f"reader workers {left} outlived their parent"
    for t in threads:
        t.join(timeout - (time.monotonic() - t0) + 1)
    assert set(eof) == {"stdout", "stderr"}, "a worker still holds the parent's output pipes"


_DRIVER = textwrap.dedent("""
    import sys, time
    from pathlib import Path
    from dracc.core.config import IngestConfig
    from dracc.ingest.nmea import StreamState, iter_nmea_blocks
    p = Path(sys.argv[1])
    it = iter_nmea_blocks(p, IngestConfig(), StreamState(str(p)), workers=2)
    next(it)  # the pool is up: the workers parse the next blocks
    print("ready", flush=True)
    time.sleep(600)
""")


def _big_log(tmp_path: Path, mb: int) -> Path:
    one = (SAMPLES / "voyage_tag.nmea").read_bytes()
    p = tmp_path / "big.nmea"
    with p.open("wb") as fh:
        for _ in range(mb * MB // len(one) + 1):
            fh.write(one)
    return p


def test_reader_workers_die_with_their_parent(tmp_path):
    """A reader killed by SIGKILL while its two workers are alive: the workers die with it
    (PR_SET_PDEATHSIG on Linux, a watchdog elsewhere) and the pipes it shared reach EOF.
    Before: the workers lived on (PPID 1, 115 MB each) holding the pipes."""
    p = _big_log(tmp_path, 12)
    proc = subprocess.Popen(
        [sys.executable, "-c", _DRIVER, str(p)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        env=_env(),
    )
    try:
        assert proc.stdout.readline().strip() == b"ready", proc.stderr.read()
        workers = _children(proc.pid)
        assert len(workers) == 2, workers
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(10)
        _assert_gone_with_eof(proc, workers)
    finally:
        if proc.poll() is None:
            proc.kill()


def test_reader_workers_die_when_dracc_analyze_is_killed(tmp_path):
    """`dracc analyze BIG.nmea` (above PARALLEL_MIN_BYTES: two reader workers) killed by
    SIGKILL during the parallel read: no worker survives, stdout and stderr reach EOF."""
    for mb in (48, 96, 192):  # bigger if the read ended before the workers were seen
        p = _big_log(tmp_path, mb)
        assert p.stat().st_size >= nmea.PARALLEL_MIN_BYTES
        proc = subprocess.Popen(
            _dracc() + ["analyze", str(p), "--json", str(tmp_path / "a.json")],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            env=_env(),
        )
        try:
            workers: set[int] = set()
            while proc.poll() is None and len(workers) < 2:
                workers |= _children(proc.pid)
                time.sleep(0.005)
            if proc.poll() is None:
                os.kill(proc.pid, signal.SIGKILL)
                proc.wait(10)
                _assert_gone_with_eof(proc, workers)
                return
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait(10)
    pytest.fail("the reader workers were never seen alive")


def test_worker_init_sets_the_death_signal_and_silences_the_streams(tmp_path):
    """In a worker: PR_GET_PDEATHSIG is SIGKILL and fds 0-2 are /dev/null."""
    script = textwrap.dedent("""
        import ctypes, os, sys
        from concurrent.futures import ProcessPoolExecutor
        from dracc.ingest.nmea.pool import worker_init

        def probe():
            libc = ctypes.CDLL(None)
            sig = ctypes.c_int(0)
            libc.prctl(2, ctypes.byref(sig), 0, 0, 0)  # PR_GET_PDEATHSIG
            return sig.value, [os.path.realpath(f"/proc/self/fd/{fd}") for fd in (0, 1, 2)]

        with ProcessPoolExecutor(1, initializer=worker_init, initargs=(os.getpid(),)) as ex:
            print(ex.submit(probe).result())
    """)
    if not sys.platform.startswith("linux"):
        pytest.skip("PR_SET_PDEATHSIG is Linux only (the watchdog covers the rest)")
    r = subprocess.run([sys.executable, "-c", script], capture_output=True, env=_env(), timeout=60)
    assert r.returncode == 0, r.stderr
    assert r.stdout.decode().strip() == str((int(signal.SIGKILL), ["/dev/null"] * 3))


def test_handover_folder_of_a_killed_reader_is_removed(tmp_path):
    """SIGKILL leaves the hand-over folder of a reader behind (its name carries the
    reader's process id); the next reader removes it, and never a live reader's."""
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    stale = tmp_path / f"{HANDOVER_PREFIX}{dead.pid}-abc"
    stale.mkdir()
    (stale / "block-3").write_bytes(b"x" * 1000)
    live = tmp_path / f"{HANDOVER_PREFIX}{os.getpid()}-def"
    live.mkdir()
    other = tmp_path / "dracc-ingest-notapid"
    other.mkdir()
    sweep_handover(str(tmp_path))
    assert not stale.exists() and live.exists() and other.exists()


def test_too_long_is_a_documented_reason():
    assert "too_long" in nmea.REASONS
    doc = (REPO / "docs" / "ingest.md").read_text()
    assert "`too_long`" in doc and "max_line_bytes" in doc


def test_strict_fails_on_a_line_too_long(tmp_path):
    p = tmp_path / "s.nmea"
    p.write_bytes(b"\r\n".join(_sample_lines()[:3]) + b"\r\n" + b"\x00" * 70_000 + b"\r\n")
    with pytest.raises(IngestError, match=r"s\.nmea:4: rejected \(line longer than"):
        read_nmea(p, IngestConfig(strict=True), workers=1)
    res = read_nmea(p, IngestConfig(), workers=1)
    assert res.rejects.counts == Counter({"too_long": 1}) and res.lines == 4
    assert np.array_equal(
        np.sort(np.concatenate([df["line"].to_numpy() for df in res.frames.values() if len(df)])),
        [1, 2, 3],
    )


def test_fleet_workers_die_when_dracc_fleet_is_killed(tmp_path):
    """`dracc fleet --workers 2` killed by SIGKILL while its pool works: no fleet worker
    (nor any reader worker of theirs) survives, and stdout/stderr reach EOF."""
    src = _big_log(tmp_path, 48)
    fleet = tmp_path / "fleet"
    for v in ("V1", "V2"):
        (fleet / v).mkdir(parents=True)
        os.link(src, fleet / v / "nav.nmea")
    proc = subprocess.Popen(
        _dracc()
        + [
            "fleet",
            str(fleet / "V1"),
            str(fleet / "V2"),
            "--workers",
            "2",
            "--out",
            str(tmp_path / "out"),
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        env=_env(),
    )
    try:
        workers: set[int] = set()
        deadline = time.monotonic() + 120
        while proc.poll() is None and len(workers) < 2 and time.monotonic() < deadline:
            workers |= _children(proc.pid)
            time.sleep(0.01)
        assert proc.poll() is None and len(workers) >= 2, "the fleet workers were never seen alive"
        time.sleep(0.5)  # let them start their own reader workers
        for w in list(workers):
            workers |= _children(w)
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(10)
        _assert_gone_with_eof(proc, workers)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(10)
