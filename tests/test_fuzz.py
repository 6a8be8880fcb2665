"""Fuzzing the NMEA ingest: a seeded mutation fuzzer over real and simulated lines, and
hypothesis properties.

Invariants checked on every mutated log (``check_mutated``):

1. no exception other than :class:`~dracc.core.errors.DraccError` (zero tracebacks);
2. every rejected line is counted under a known reason (``nmea.REASONS``), and every
   non-blank line that gave no record and carries no ZDA is counted at least once, as
   rejected or as ignored (a valid sentence dracc does not use);
3. differential: every untouched line gives the same records as in the clean log (same
   values; same time and source where the line carries its own time: TAG ``c:`` or a
   timestamp prefix), at the same line number as the clean log's line counted with the
   line ends of the mutated log.

A mutated log has its own line ends: CR LF, LF, a lone CR, CR CR LF, or a mix of them
(line by line), and ends with one or without (a cut file).

The same machinery drives ``benchmarks/fuzz_long.py`` (the long run before a release).
"""

from __future__ import annotations

import bisect
import math
import os
import random
import re
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from dracc.core.config import IngestConfig
from dracc.frames import KIND_COLUMNS
from dracc.ingest.nmea import REASONS, parse_buffer, read_nmea
from dracc.ingest.tagblock import parse_numbers
from dracc.ingest.timebase import ASSUMED_DATE_NOTE

REPO = Path(__file__).resolve().parents[1]
SAMPLES = REPO / "sample_logs"
REAL = Path(os.environ.get("DRACC_REAL_DATA", REPO.parent / "shared" / "data" / "real"))

#: corpus: (file, per-line time?) -- lines carrying their own time give exact differential times
CORPUS_FILES = (
    (SAMPLES / "voyage_tag.nmea", True),
    (SAMPLES / "voyage_prefix.nmea", True),
    (REAL / "VDRplayer" / "Hakefjord.txt", False),
    (REAL / "gpsd" / "bundg_zeus_9.log", False),
    (REAL / "openrvdas" / "NBP1406_gyr1-2014-08-01", True),
    (REAL / "openrvdas" / "NBP1406_seap-2014-08-01", True),
    (REAL / "anemomind" / "Irene" / "2014" / "20140611" / "NMEA0048.TXT", False),
    (REAL / "signalk-server" / "plaka.log", False),
)
WINDOW = 100  #: lines per fuzzed log

#: a line end as dracc reads it: CR CR LF, CR LF, LF or a lone CR (leftmost, longest first)
LINE_END = re.compile(rb"\r\r\n|\r\n|\n|\r")
#: the line ends a mutated log is written with ("mixed": one drawn per line)
LINE_ENDS = {"crlf": b"\r\n", "lf": b"\n", "cr": b"\r", "crcrlf": b"\r\r\n"}


def line_starts(data: bytes) -> list[int]:
    """Offsets where the lines of ``data`` start (a final line end starts no line)."""
    out = [0] + [m.end() for m in LINE_END.finditer(data)]
    if out[-1] == len(data) and len(out) > 1:
        out.pop()
    return out if data else []


def split_lines(data: bytes) -> list[bytes]:
    """The lines of ``data`` without their line ends, as dracc counts them."""
    out, at = [], 0
    for m in LINE_END.finditer(data):
        out.append(data[at : m.start()])
        at = m.end()
    if at < len(data):
        out.append(data[at:])
    return out


def load_corpus(max_lines: int = 6000) -> list[tuple[list[bytes], bool]]:
    """(lines without terminators, per-line time) for each corpus file present."""
    out = []
    for path, timed in CORPUS_FILES:
        if path.exists():
            lines = split_lines(path.read_bytes())[:max_lines]
            out.append(([ln for ln in lines if ln.strip()], timed))
    return out


# ------------------------------------------------------------------------ mutations


def _checksum(body: bytes) -> bytes:
    x = 0
    for c in body:
        x ^= c
    return b"%02X" % x


def _sentence_span(line: bytes) -> tuple[int, int] | None:
    """[start of '$'/'!', index of '*') of the sentence in a line, if any."""
    s = max(line.find(b"$"), -1)
    if s < 0:
        s = line.find(b"!")
    if s < 0:
        return None
    e = line.find(b"*", s)
    return (s, e) if e > s else None


def _set_field(line: bytes, k: int, value: bytes) -> bytes | None:
    """Replace data field ``k`` (1-based) of the sentence and fix the checksum."""
    sp = _sentence_span(line)
    if sp is None:
        return None
    s, e = sp
    fields = line[s + 1 : e].split(b",")
    if k >= len(fields):
        return None
    fields[k] = value
    body = b",".join(fields)
    return line[: s + 1] + body + b"*" + _checksum(body) + line[e + 3 :]


#: (sentence type, field number, value) making a physically impossible but well-formed line
OUT_OF_RANGE = {
    b"GGA": [(2, b"9500.000"), (4, b"18100.000")],  # latitude 95 deg, longitude 181 deg
    b"RMC": [(3, b"9500.000"), (7, b"-3.0")],  # latitude 95 deg, SOG -3 kn
    b"GLL": [(1, b"9500.000")],
    b"HDT": [(1, b"400.0")],
    b"HDG": [(1, b"400.0")],
    b"THS": [(1, b"400.0")],  # heading 400 deg
    b"VTG": [(5, b"-3.0")],  # SOG -3 kn
    b"VHW": [(5, b"-3.0")],
}


class Mutator:
    """Seeded line mutations; each returns the new lines or None when it does not apply."""

    OPS = (
        "bit_flip",
        "truncate",
        "garbage",
        "nul",
        "wrong_checksum",
        "no_checksum",
        "fuse",
        "huge",
        "long_field",
        "non_ascii",
        "out_of_range",
        "swap_time_order",
        "insert_junk_line",
    )

    def __init__(self, rng: random.Random):
        self.rng = rng

    def bit_flip(self, b: bytes) -> bytes:
        a = bytearray(b)
        for _ in range(self.rng.randint(1, 3)):
            i = self.rng.randrange(len(a))
            a[i] ^= 1 << self.rng.randrange(8)
        return bytes(a).replace(b"\n", b"\x0b")  # a flipped newline would split the line

    def truncate(self, b: bytes) -> bytes:
        return b[: self.rng.randrange(len(b))]

    def garbage(self, b: bytes) -> bytes:
        i = self.rng.randrange(len(b) + 1)
        junk = bytes(
            self.rng.choice([x for x in range(256) if x != 10])
            for _ in range(self.rng.randint(1, 12))
        )
        return b[:i] + junk + b[i:]

    def nul(self, b: bytes) -> bytes:
        i = self.rng.randrange(len(b) + 1)
        return b[:i] + b"\x00" * self.rng.randint(1, 4) + b[i:]

    def wrong_checksum(self, b: bytes) -> bytes | None:
        j = b.rfind(b"*")
        if j < 0 or len(b) < j + 3:
            return None
        good = b[j + 1 : j + 3]
        bad = good
        while bad == good:
            bad = b"%02X" % self.rng.randrange(256)
        return b[: j + 1] + bad + b[j + 3 :]

    def no_checksum(self, b: bytes) -> bytes | None:
        j = b.rfind(b"*")
        return None if j < 0 else b[:j] + b[j + 3 :]

    def huge(self, b: bytes) -> bytes:
        """A long run inside the line: up to 300 kB (beyond ``max_line_bytes``: too_long)."""
        n = self.rng.choice((2_000, 65_000, 70_000, 300_000))
        filler = self.rng.choice((b"0", b"1234567890,", b"A", b"$GPGGA,", b"\x00"))
        i = self.rng.randrange(len(b) + 1)
        return b[:i] + (filler * (n // len(filler) + 1))[:n] + b[i:]

    def long_field(self, b: bytes) -> bytes | None:
        """One field of the sentence replaced by a long run of digits (checksum fixed)."""
        sp = _sentence_span(b)
        if sp is None:
            return None
        nf = b[sp[0] : sp[1]].count(b",")
        if nf < 1:
            return None
        n = self.rng.choice((25, 500, 5_000, 70_000))
        return _set_field(b, self.rng.randint(1, nf), (b"1234567890" * (n // 10 + 1))[:n])

    def non_ascii(self, b: bytes) -> bytes:
        i = self.rng.randrange(len(b) + 1)
        s = self.rng.choice(("é", "°", "€", "😀", "Ω", "\u200b", "\ufeff")).encode()
        if self.rng.random() < 0.3:
            s = bytes([self.rng.randrange(128, 256)])  # a lone Latin-1 byte
        return b[:i] + s + b[i:]

    def out_of_range(self, b: bytes) -> bytes | None:
        sp = _sentence_span(b)
        if sp is None:
            return None
        t = b[sp[0] + 3 : sp[0] + 6]
        if t not in OUT_OF_RANGE:
            return None
        k, v = self.rng.choice(OUT_OF_RANGE[t])
        return _set_field(b, k, v)

    def mutate_line(self, b: bytes) -> bytes | None:
        op = self.rng.choice(
            (
                "bit_flip",
                "truncate",
                "garbage",
                "nul",
                "wrong_checksum",
                "no_checksum",
                "huge",
                "long_field",
                "non_ascii",
                "out_of_range",
            )
        )
        if not b:
            return None
        return getattr(self, op)(b), op


@dataclass
class Mutated:
    data: bytes  #: the mutated log
    #: original line index -> line index in the mutated log, for untouched lines only
    untouched: dict[int, int]
    ops: Counter  #: mutations applied, by name
    n_mutated: int  #: lines touched


def mutate(lines: list[bytes], rng: random.Random, n_mut: int) -> Mutated:
    """Apply ``n_mut`` mutations to a copy of ``lines`` (line-level and structural)."""
    m = Mutator(rng)
    # each entry: (bytes, original index or None for touched/inserted lines)
    cur: list[tuple[bytes, int | None]] = [(b, i) for i, b in enumerate(lines)]
    ops: Counter = Counter()
    touched = 0
    for _ in range(n_mut):
        kind = rng.random()
        k = rng.randrange(len(cur))
        if kind < 0.08 and len(cur) > 1:  # fuse two lines (a lost newline)
            k = min(k, len(cur) - 2)
            cur[k : k + 2] = [(cur[k][0] + cur[k + 1][0], None)]
            ops["fuse"] += 1
            touched += 2
        elif kind < 0.14 and len(cur) > 1:  # times out of order: two lines swap places
            j = rng.randrange(len(cur))
            cur[k], cur[j] = (cur[j][0], None), (cur[k][0], None)
            ops["swap_time_order"] += 1
            touched += 2
        elif kind < 0.18:  # a junk line of its own
            junk = bytes(rng.randrange(256) for _ in range(rng.randint(0, 80))).replace(b"\n", b"")
            cur.insert(k, (junk, None))
            ops["insert_junk_line"] += 1
            touched += 1
        else:
            r = m.mutate_line(cur[k][0])
            if r is None or r[0] is None:
                continue
            cur[k] = (r[0], None)
            ops[r[1]] += 1
            touched += 1
    style = rng.choice(sorted(LINE_ENDS) + ["mixed"])
    seps = [LINE_ENDS[rng.choice(sorted(LINE_ENDS)) if style == "mixed" else style] for _ in cur]
    parts, offsets, at = [], [], 0
    for (b, _), sep in zip(cur, seps, strict=True):
        offsets.append(at)
        parts += [b, sep]
        at += len(b) + len(sep)
    if rng.random() >= 0.5:
        parts.pop()  # the log ends without a line end (a cut file)
    data = b"".join(parts)
    ops[f"line_end_{style}"] += 1
    # an untouched line's number in the mutated log: the lines before it, as dracc counts
    # them (a mutation may add line ends; a lone CR before a CR LF makes an empty line)
    starts = line_starts(data)
    untouched = {
        i: bisect.bisect_right(starts, offsets[j]) - 1
        for j, (_, i) in enumerate(cur)
        if i is not None
    }
    return Mutated(data, untouched, ops, touched)


# ------------------------------------------------------------------------ invariants


def records_by_line(frames) -> dict[str, dict[int, tuple]]:
    """kind -> line -> (time_ns, source, values...) of the records of a FileResult."""
    out: dict[str, dict[int, tuple]] = {}
    for kind, df in frames.items():
        if df is None or df.empty:
            continue
        vals = [df[c].to_numpy() for c in KIND_COLUMNS[kind]]
        t = df["time_ns"].to_numpy(np.int64)
        src = df["source"].astype(str).to_numpy()
        lines = df["line"].to_numpy(np.int64)
        d = out.setdefault(kind, {})
        for r in range(len(df)):
            d[int(lines[r])] = (int(t[r]), str(src[r])) + tuple(_norm(v[r]) for v in vals)
    return out


def _norm(x):
    if isinstance(x, float) and math.isnan(x):
        return "nan"
    if isinstance(x, (np.floating,)):
        return "nan" if np.isnan(x) else float(x)
    return x if not isinstance(x, np.integer) else int(x)


class InvariantError(AssertionError):
    pass


@dataclass
class Outcome:
    rejects: Counter  #: rejected sentences/lines by reason
    lines: int  #: non-blank lines in the mutated log
    silent: int  #: of them, lines that gave no record (each counted in ``rejects``)


def check_mutated(
    clean_lines: list[bytes], timed: bool, mut: Mutated, clean_recs, tmp: Path, cfg: IngestConfig
) -> Outcome:
    """Read the mutated log; raise InvariantError when an invariant breaks; return rejects."""
    p = tmp / "fuzz.nmea"
    p.write_bytes(mut.data)
    res = read_nmea(p, cfg, workers=1)  # a DraccError (e.g. --strict) goes to the caller
    unknown = set(res.rejects.counts) - set(REASONS)
    if unknown:
        raise InvariantError(f"reject reasons not in nmea.REASONS: {unknown}")
    got = records_by_line(res.frames)
    with_record = {ln for d in got.values() for ln in d}
    mlines = split_lines(mut.data)
    silent = [
        i + 1
        for i, ln in enumerate(mlines)
        if ln.strip(b"\r \t")
        and (i + 1) not in with_record
        and b"ZDA," not in ln  # a time only
        and b"PSXN,20," not in ln  # a quality only, of the PSXN,23 that follows
    ]
    # a line gives a record, or is rejected (damaged), or is ignored (valid, unused: GSV, AIS,
    # a comment ...); blank lines are ignored too but are not among the silent ones
    counted = res.rejects.total + sum(res.ignored.values()) - res.ignored.get("blank", 0)
    if len(silent) > counted:
        raise InvariantError(
            f"{len(silent)} non-blank lines gave no record but only "
            f"{counted} rejected or ignored lines were counted (e.g. line {silent[0]})"
        )
    # differential: untouched lines give the same records
    # the log's only date on a mutated line: its times of day go on the assumed date
    lost_date = res.rejects.counts.get("no_date", 0) > clean_recs.get(NO_DATE, 0) or (
        ASSUMED_DATE_NOTE in res.time_events.decisions and not clean_recs[ASSUMED]
    )
    for kind, d in clean_recs.items():
        if kind in (NO_DATE, ASSUMED):
            continue
        g = got.get(kind, {})
        for ln, rec in d.items():
            j = mut.untouched.get(ln - 1)
            if j is None:
                continue
            have = g.get(j + 1)
            if have is None and lost_date and not timed:
                continue  # the log's only date was on a mutated line: counted as no_date
            exact = timed and not lost_date
            want = rec if exact else rec[2:]
            have = have if (have is None or exact) else have[2:]
            if have != want:
                raise InvariantError(
                    f"{kind}: clean line {ln} (mutated line {j + 1}) gave {want}, now {have}"
                )
    nonblank = sum(1 for ln in mlines if ln.strip(b"\r \t"))
    return Outcome(Counter(res.rejects.counts), nonblank, len(silent))


NO_DATE = "_no_date"  #: key of the clean log's no_date reject count beside its records
ASSUMED = "_assumed"  #: key of: the clean log was read on the assumed date


def clean_records(lines: list[bytes], tmp: Path, cfg: IngestConfig):
    p = tmp / "clean.nmea"
    p.write_bytes(b"\r\n".join(lines) + b"\r\n")
    res = read_nmea(p, cfg, workers=1)
    return {
        **records_by_line(res.frames),
        NO_DATE: res.rejects.counts.get("no_date", 0),
        ASSUMED: ASSUMED_DATE_NOTE in res.time_events.decisions,
    }


def fuzz_round(
    corpus, rng: random.Random, tmp: Path, cfg: IngestConfig
) -> tuple[Outcome, int, Counter]:
    """One fuzzed log: a window of a corpus file, 1-8 mutations; (rejects, lines mutated, ops)."""
    lines, timed = corpus[rng.randrange(len(corpus))]
    a = rng.randrange(max(1, len(lines) - WINDOW))
    window = lines[a : a + WINDOW]
    clean = clean_records(window, tmp, cfg)
    mut = mutate(window, rng, rng.randint(1, 8))
    return check_mutated(window, timed, mut, clean, tmp, cfg), mut.n_mutated, mut.ops


# ------------------------------------------------------------------------ tests


@pytest.fixture(scope="module")
def corpus():
    c = load_corpus()
    if not c:
        pytest.skip("no corpus files")
    return c


CFG = IngestConfig(date="2014-08-01")


@pytest.mark.parametrize("seed", range(3))
def test_seeded_mutation_fuzzer(corpus, tmp_path, seed):
    """50 mutated logs per seed (150 in all, ~700 mutated lines), every mutation kind."""
    rng = random.Random(seed)
    rejects: Counter = Counter()
    ops: Counter = Counter()
    for _ in range(50):
        r, _, o = fuzz_round(corpus, rng, tmp_path, CFG)
        rejects.update(r.rejects)
        ops.update(o)
    assert rejects  # the fuzzer does produce rejects (it cannot pass by doing nothing)
    assert {"fuse", "swap_time_order", "insert_junk_line"} <= set(ops)


def test_every_mutation_kind_is_rejected_with_its_reason(tmp_path):
    """One clean RMC line and one mutation of each kind: each gives the expected reason."""
    good = b"$GPRMC,120000,A,5000.000,N,01000.000,E,10.0,90.0,010120,,*" + _checksum(
        b"GPRMC,120000,A,5000.000,N,01000.000,E,10.0,90.0,010120,,"
    )
    m = Mutator(random.Random(0))
    cases = {
        "checksum": m.wrong_checksum(good),
        "binary": good[:20] + b"\x00" + good[20:],
        "truncated": good[:30] + good,  # cut short, then a whole sentence on the same line
        "malformed_field": _set_field(good, 3, b"9500.000"),  # latitude 95 deg
        "not_nmea": b"hello, world",
    }
    cases["binary_non_ascii"] = "Grüße, Käpt'n".encode()
    hdt = b"$HEHDT,400.0,T*" + _checksum(b"HEHDT,400.0,T")
    cases["malformed_field_heading"] = hdt
    for reason, line in cases.items():
        pb = parse_buffer(good + b"\r\n" + line + b"\r\n" + good + b"\r\n")
        want = reason.removesuffix("_heading").removesuffix("_non_ascii")
        assert pb.reject_counts == Counter({want: 1}), (reason, pb.reject_counts)
        assert len(pb.kinds["position"]["line"]) == 2 + (reason == "truncated")
    # a missing checksum is accepted (counted in the stats), as many loggers drop it
    pb = parse_buffer(m.no_checksum(good) + b"\r\n")
    assert len(pb.kinds["position"]["line"]) == 1 and pb.stats["no_checksum"] == 1


def test_huge_line_is_rejected_and_neighbours_survive(tmp_path):
    lines = (SAMPLES / "voyage_tag.nmea").read_bytes().split(b"\r\n")[:50]
    clean = clean_records(lines, tmp_path, IngestConfig())
    huge = lines[:25] + [b"$GPGGA," + b"1234567890," * 200_000] + lines[25:]
    mut = Mutated(
        b"\r\n".join(huge) + b"\r\n",
        {i: (i if i < 25 else i + 1) for i in range(50)},
        Counter(huge=1),
        1,
    )
    rej = check_mutated(lines, True, mut, clean, tmp_path, IngestConfig()).rejects
    assert sum(rej.values()) == 1


def test_regression_nul_in_tag_block_time(tmp_path):
    """Regression (fuzz): a NUL byte inside a TAG block c: field raised ValueError in
    tagblock.parse_numbers; now the line is rejected as bad_tag."""
    lines = (SAMPLES / "voyage_tag.nmea").read_bytes().split(b"\r\n")[:20]
    bad = lines[5].replace(b"c:1", b"c:1\x00\x00", 1)
    assert bad != lines[5]
    pb = parse_buffer(b"\r\n".join(lines[:5] + [bad] + lines[6:]) + b"\r\n")
    assert pb.reject_counts == Counter({"bad_tag": 1})
    assert sum(len(k["line"]) for k in pb.kinds.values()) == 19


def test_regression_tag_time_beyond_int64(tmp_path):
    """Regression (fuzz): a c: time of 20 digits wrapped around int64 silently."""
    body = b"s:INS1,c:99999999999999999999"
    line = b"\\" + body + b"*" + _checksum(body) + b"\\$HEHDT,60.0,T*" + _checksum(b"HEHDT,60.0,T")
    pb = parse_buffer(line + b"\r\n")
    assert pb.reject_counts == Counter({"bad_tag": 1})


def test_times_out_of_order_are_counted(tmp_path):
    lines = (SAMPLES / "voyage_tag.nmea").read_bytes().split(b"\r\n")[:400]
    lines[100:300] = lines[200:300] + lines[100:200]  # a block written late
    p = tmp_path / "late.nmea"
    p.write_bytes(b"\r\n".join(lines) + b"\r\n")
    res = read_nmea(p, IngestConfig(), workers=1)
    assert res.time_events.backsteps >= 1
    assert sum(len(f) for f in res.frames.values()) == 400 - 0  # nothing lost
    t = [f["time_ns"].to_numpy() for f in res.frames.values() if len(f)]
    assert all(np.all(np.diff(x) >= 0) for x in t)  # frames are sorted by time


# ------------------------------------------------------------------------ hypothesis

SETTINGS = settings(
    max_examples=150, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow]
)


@SETTINGS
@given(st.binary(max_size=600))
def test_parse_buffer_never_raises_on_bytes(data):
    pb = parse_buffer(data)
    assert set(pb.reject_counts) <= set(REASONS)
    nonblank = sum(1 for ln in data.split(b"\n") if ln.strip(b"\r"))
    assert pb.n_lines >= nonblank


@SETTINGS
@given(
    st.lists(
        st.sampled_from(
            [
                b"$",
                b"!",
                b"*",
                b",",
                b"\\",
                b":",
                b"\r",
                b"\n",
                b"\x00",
                b"GPGGA",
                b"HEHDT",
                b"s:",
                b"c:",
                b"1",
                b"A",
                b"5",
                b".",
                b"-",
                b"FF",
                b"\xff",
                b"#",
            ]
        ),
        max_size=80,
    )
)
def test_parse_buffer_never_raises_on_nmea_like_tokens(tokens):
    pb = parse_buffer(b"".join(tokens))
    assert set(pb.reject_counts) <= set(REASONS)


@SETTINGS
@given(st.binary(max_size=30))
def test_parse_numbers_agrees_with_python_float(field):
    """A valid field parses to float(field); anything else is NaN and invalid, never raises."""
    buf = np.frombuffer(field + b",", dtype=np.uint8)
    val, _, invalid = parse_numbers(buf, np.array([0]), np.array([len(field)]), width=30)
    text = field.decode("latin-1")
    import re

    ok = re.fullmatch(r"[+-]?(\d+\.?\d*|\.\d+)", text) is not None
    if not field:
        assert np.isnan(val[0]) and not invalid[0]
    elif ok:
        assert not invalid[0] and val[0] == float(text)
    else:
        assert invalid[0] and np.isnan(val[0])


@SETTINGS
@given(
    lat=st.floats(-89.99, 89.99),
    lon=st.floats(-179.99, 179.99),
    hdg=st.floats(0, 359.99),
    sog=st.floats(0, 50),
    junk=st.binary(max_size=40),
)
@example(lat=0.0, lon=0.0, hdg=0.0, sog=0.0, junk=b"\r\x00")  # a CR in the junk: once flaky
def test_valid_lines_survive_any_junk_between_them(lat, lon, hdg, sog, junk):
    """Round trip: RMC + HDT written to their precision read back exactly, whatever junk
    line sits between them.  The junk is one line: its CR and LF are taken out, as a lone
    CR ends a line too (docs/ingest.md, "Line ends")."""
    la, lo = abs(lat), abs(lon)
    lat_f = b"%02d%07.4f" % (int(la), (la - int(la)) * 60)
    lon_f = b"%03d%07.4f" % (int(lo), (lo - int(lo)) * 60)
    body = b"GPRMC,120000,A,%s,%s,%s,%s,%.1f,%.1f,010120,," % (
        lat_f,
        b"N" if lat >= 0 else b"S",
        lon_f,
        b"E" if lon >= 0 else b"W",
        sog,
        hdg,
    )
    if b"60.0000" in lat_f or b"60.0000" in lon_f:
        return  # rounding wrote 60 minutes: not a valid field (the writer's problem)
    rmc = b"$" + body + b"*" + _checksum(body)
    hb = b"HEHDT,%.2f,T" % hdg
    hdt = b"$" + hb + b"*" + _checksum(hb)
    pb = parse_buffer(
        rmc + b"\r\n" + junk.replace(b"\n", b"").replace(b"\r", b"") + b"\r\n" + hdt + b"\r\n"
    )
    pos = pb.kinds["position"]
    assert list(pos["line"]) == [1]
    want_lat = math.radians(int(la) + float(lat_f[2:]) / 60) * (1 if lat >= 0 else -1)
    assert pos["lat_rad"][0] == pytest.approx(want_lat, abs=1e-12)
    hd = pb.kinds["heading"]
    assert list(hd["line"]) == [3]
    assert hd["heading_rad"][0] == pytest.approx(math.radians(float(b"%.2f" % hdg)), abs=1e-12)
    gr = pb.kinds["ground"]
    assert gr["sog_mps"][0] == pytest.approx(float(b"%.1f" % sog) * 1852 / 3600, abs=1e-12)


def test_the_invariant_checks_can_fail(tmp_path):
    """The differential and the reject accounting catch a planted fault."""
    lines = (SAMPLES / "voyage_tag.nmea").read_bytes().split(b"\r\n")[:30]
    clean = clean_records(lines, tmp_path, IngestConfig())
    # a value changed in a line declared untouched
    changed = list(lines)
    changed[7] = changed[7].replace(b",", b",1", 1)
    j = changed[7].rfind(b"$")
    body = changed[7][j + 1 : changed[7].rfind(b"*")]
    changed[7] = changed[7][: j + 1] + body + b"*" + _checksum(body)
    mut = Mutated(b"\r\n".join(changed) + b"\r\n", {i: i for i in range(30)}, Counter(), 0)
    with pytest.raises(InvariantError, match="clean line 8"):
        check_mutated(lines, True, mut, clean, tmp_path, IngestConfig())
    # a line that vanished without a reject: map line 3 onto a blank-free log missing it
    mut = Mutated(
        b"\r\n".join(lines[:3] + lines[4:]) + b"\r\n", {i: i for i in range(30)}, Counter(), 0
    )
    with pytest.raises(InvariantError):
        check_mutated(lines, True, mut, clean, tmp_path, IngestConfig())


def test_regression_one_damaged_prefix_moves_other_records_to_the_logger_time(tmp_path):
    """Regression (long fuzz run): in a log with timestamp prefixes and no date, one line
    whose prefix is unreadable left the block waiting for a date; at the end of the file
    every other record took its prefix (receive) time instead of its time of fix (rule 1)."""
    good = b"2014-08-01T00:00:57.807000Z $GPGGA,000057.69,2200.227509,S,01756.459284,W,1,09,1.2,0.15,M,,M,,*46"
    bad = b"2014-08-01T00:01\x00\x00:08.805000Z $GPGGA,000108.69,2200.249745,S,01756.478464,W,1,10,0.9,1.61,M,,M,,*44"
    p = tmp_path / "prefix.nmea"
    p.write_bytes(good + b"\r\n" + bad + b"\r\n")
    res = read_nmea(p, IngestConfig(), workers=1)
    pos = res.frames["position"]
    assert pos["line"].tolist() == [1, 2]
    # 00:00:57.69, the time of fix; the line without a readable prefix: its time of fix
    # on the day of the log's first receive time, said so
    assert pos["time_ns"].tolist() == [1406851257_690_000_000, 1406851268_690_000_000]
    assert res.rejects.total == 0
    assert any("day of its first receive time" in d for d in res.time_events.decisions)


def test_regression_garbled_prefix_time_far_in_the_future(tmp_path):
    """Regression (fuzz through the whole pipeline): digits inserted into an ISO prefix
    ('...1234567890,12345678' + '2109-03-01T...') left a valid-looking time in 2109; one such
    record stretched the voyage over decades and the daily deviation windows took minutes.
    External times outside 2000-01-01 .. today+1 are now counted as implausible, not used."""
    lines = (SAMPLES / "voyage_prefix.nmea").read_bytes().split(b"\r\n")[:200]
    assert lines[50][:4] == b"2026" and b"HDT" in lines[50]  # an HDT: no time of its own
    bad = b"1234567890,12345678" + b"2109" + lines[50][4:]
    p = tmp_path / "garbled.nmea"
    p.write_bytes(b"\r\n".join(lines[:50] + [bad] + lines[51:]) + b"\r\n")
    res = read_nmea(p, IngestConfig(), workers=1)
    t = np.concatenate([f["time_ns"].to_numpy() for f in res.frames.values() if len(f)])
    assert t.max() - t.min() < 3600 * 10**9
    assert res.time_events.implausible_dates == 1
    assert any("implausible" in n for n in res.notes + res.time_events.decisions)


def test_regression_iso_prefix_with_a_huge_fraction(tmp_path):
    """Regression (fuzz through the whole pipeline, OOM-killed at 24 GB): a timestamp prefix
    whose fraction ran on for 300 000 digits matched the ISO regex and the matches were
    widened to one fixed-width array (<U300023 x 10 159 rows = 11.4 GiB).  A fraction has
    at most 9 digits now; such a prefix is not a time, and its sentence is still read."""
    import pyarrow as pa
    import pyarrow.compute as pc

    from dracc.ingest.tagblock import _ISO_RE

    ok = "2026-03-01T06:00:40.123456789Z "
    long = "2026-03-01T06:00:40." + "0" * 5000 + "Z "
    m = pc.extract_regex(pa.array([ok, long]), _ISO_RE)
    assert m.is_valid().to_pylist() == [True, False]
    line = long.encode() + b"$HEHDT,59.909,T*13"
    res = read_nmea(_write(tmp_path, [line] * 3), IngestConfig(date="2026-03-01"), workers=1)
    # no time anywhere on these lines: counted (no_date), the prefixes noted as ignored
    assert res.rejects.counts == Counter({"no_date": 3})
    assert "3 line prefixes without a recognisable time ignored" in res.notes


def _write(tmp: Path, lines: list[bytes]) -> Path:
    p = tmp / "log.nmea"
    p.write_bytes(b"\r\n".join(lines) + b"\r\n")
    return p


@pytest.mark.parametrize("seed", range(2))
def test_mutated_voyage_through_the_whole_pipeline(tmp_path, seed):
    """A whole simulated voyage with 3 % of its lines mutated: analyse, the JSON (checked
    against its schema), the HTML and the terminal summary, without a traceback; the
    out-of-range SOG the mutations write is flagged as a sensor fault."""
    import jsonschema

    from dracc.core.config import Config
    from dracc.pipeline.analysis import analyse
    from dracc.report import html as html_report
    from dracc.report import json_report, terminal

    rng = random.Random(seed)
    lines = [ln for ln in (SAMPLES / "voyage_tag.nmea").read_bytes().split(b"\r\n") if ln]
    mut = mutate(lines, rng, len(lines) * 3 // 100)
    # and one RMC of the GNSS with SOG -3 kn and a valid checksum
    k = next(i for i, ln in enumerate(lines) if b"GPRMC" in ln)
    neg = _set_field(lines[k], 7, b"-3.0")
    p = tmp_path / "voyage.nmea"
    p.write_bytes(mut.data + b"\r\n" + neg + b"\r\n")
    a = analyse([p], Config())
    doc = json_report.to_dict(a)
    jsonschema.validate(doc, json_report.load_schema())
    assert html_report.render_html(a).rstrip().endswith("</html>")
    assert "Sensor faults" in terminal.render_text(a)
    assert any(
        f["kind"] == "out_of_range" and f["values"].get("min_sog_kn") == -3.0 for f in doc["faults"]
    )
    assert sum(doc["rejected"].values()) > 0


def test_regression_tag_source_with_nul_or_300k_characters(tmp_path):
    """Regression (whole-pipeline fuzz: a MemoryError drawing the track plot): NUL bytes
    and pairs of equal bytes leave a TAG block's XOR checksum unchanged, so a TAG source
    'G\\0\\0\\0YRO' or 'GAAAA…' (300 000 characters) passed and became a source key (and a
    plot legend 300 000 characters wide).  TAG blocks are printable ASCII now and a source
    identification has at most 64 characters; such lines are rejected as bad_tag."""
    lines = (SAMPLES / "voyage_tag.nmea").read_bytes().split(b"\r\n")[:20]
    assert lines[0].startswith(b"\\s:GYRO,")
    nul = lines[0].replace(b"s:GY", b"s:G\x00\x00\x00Y", 1)  # XOR unchanged by NULs
    long = lines[0].replace(b"s:GY", b"s:G" + b"A" * 300_000 + b"Y", 1)  # even count: XOR unchanged
    short_long = lines[0].replace(b"s:GY", b"s:G" + b"A" * 80 + b"Y", 1)  # a row-path TAG block
    under_cap = lines[0].replace(b"s:GY", b"s:G" + b"A" * 60_000 + b"Y", 1)  # within max_line_bytes
    res = read_nmea(
        _write(tmp_path, [nul, long, short_long, under_cap] + lines[1:]), IngestConfig(), workers=1
    )
    # the 300 000 characters are beyond [ingest] max_line_bytes now: too_long, never parsed
    assert res.rejects.counts == Counter({"bad_tag": 3, "too_long": 1})
    keys = {str(k) for f in res.frames.values() if len(f) for k in f["source"].unique()}
    assert keys <= {"GYRO", "MAG", "LOG", "INS1", "INS2", "INS3", "GNSS"}


def test_regression_stray_records_years_away_do_not_make_a_dr_grid_of_years(tmp_path):
    """Regression (whole-pipeline fuzz: MemoryError, 126 million grid points): one heading
    and one speed record dated four years early (a plausible date, so the time base keeps
    them) made the 1 s dead-reckoning grid span four years.  Silences of both heading and
    speed longer than an hour are now left out of the grid, with a note; the track is the
    same elsewhere."""
    from dracc.core.config import Config
    from dracc.pipeline.analysis import analyse

    lines = (SAMPLES / "voyage_prefix.nmea").read_bytes().split(b"\r\n")[:3000]
    hdt = next(ln for ln in lines if b"HEHDT" in ln)
    vhw = next(ln for ln in lines if b"VWVHW" in ln)
    stray = [hdt.replace(b"2026-", b"2022-", 1), vhw.replace(b"2026-", b"2022-", 1)]
    a = analyse([_write(tmp_path, stray + lines)], Config())
    assert a.dead_reckoning is not None
    assert a.dead_reckoning.track.time_ns.size < 4000  # ~50 min at 1 s, not 4 years
    assert any("both silent for 35,0" in n and "2022-03-01" in n for n in a.notes)
    clean = analyse([_write(tmp_path, lines)], Config()).dead_reckoning
    t = clean.epochs.time_ns
    sel = np.isin(a.dead_reckoning.epochs.time_ns, t)
    assert sel.sum() == t.size
    # the same track to a micrometre (the times differ by four years, so their last bits do)
    np.testing.assert_allclose(
        a.dead_reckoning.epochs.lat_rad[sel], clean.epochs.lat_rad, rtol=0, atol=1e-13
    )
