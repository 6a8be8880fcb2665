"""Source keys, their summary (:class:`SourceInfo`) and role assignment.

Source keys come from the readers: the TAG ``s:`` value, an MCAP topic, a CSV source
column, or the NMEA talker ID; a talker whose position sentences come with two or more
different numbers of decimals of minutes (two receivers behind one talker) is split
into ``<talker>/<n>dp`` keys (see :func:`dracc.ingest.nmea.reader._fingerprint`).

Role assignment (:func:`assign_roles`), in this order:

1. the configuration mapping ``[ingest.sources]``; a key there may be a source key or
   a talker ID (then every source with that talker gets the role);
2. names: a source key naming its unit (``INS1``..``INS3``, ``GYRO``/``HDG``/
   ``COMPASS``/``HEADING``, ``LOG``/``SPEEDLOG``/``STW``, ``GNSS``/``GPS``), case-insensitive,
   as a whole key or the last component of a topic; only if one source has that name;
3. content, only where unambiguous: gnss from the first of these tiers that has a
   candidate -- talker families (GP/GN/GA/GL/GB ...), NMEA 2000 devices sending
   positions (PGN129029/129025) and no heading (PGN127250), then those sending both (a
   satellite compass, an integrated navigation system), own-ship AIS (``VDO``);
   exactly three INS-type sources (talkers IN, II, IR, keys containing 'INS', or
   senders of an INS's own PASHR/PSXN) with positions -> ins1..3 in sorted order;
   the only source with heading sentences (HDT/HDG/HDM/THS, PGN127250; never rate of
   turn alone, ROT/PGN127251) and no positions -> compass (where there is none, the only
   instrument bus with heading sentences); a
   source of fixes without log sentences (an INS, a GNSS compass) is never made the
   compass by content, a sender of PASHR/PSXN only where no other heading source is a
   candidate (the Seapath's PSXN beside its GP fixes: openrvdas/NBP1406_seap);
   the only source with VHW/VBW/PGN128259 -> log (a GNSS's PGN128259, speed over
   ground only, gives way to a log's).  An instrument bus (e.g. 'II' with HDG + VHW)
   may be compass and log.
4. Where several sources could fill the compass, log or gnss role (by content, or named
   alike), the role stays free here and the candidates are handed back: one is chosen
   by evidence from the data (:mod:`dracc.ingest.role_evidence`), the others kept as
   witnesses -- two instruments are never merged into one series.  Otherwise a note
   names what is unassigned; :class:`AmbiguousSourceError` is for the caller that
   requires a role (``require_role``).
"""

from __future__ import annotations

import re
from collections import Counter
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from contextvars import ContextVar
from typing import cast

import numpy as np
import pandas as pd

from dracc.core.errors import AmbiguousSourceError, ConfigError, OptionError
from dracc.core.vocabulary import INS_ROLES, ROLES
from dracc.frames import SourceInfo

GNSS_FAMILY = ("GP", "GN", "GA", "GL", "GB", "GI", "GQ", "BD")
INS_TALKERS = ("IN", "II", "IR")
#: NMEA 2000 messages are sentences ``PGN<n>`` (:mod:`dracc.ingest.n2k`)
N2K_HEADING = {"PGN127250"}
#: rate of turn (ROT, PGN127251) is never a heading: a device sending only it is no compass
RATE_SENTENCES = {"ROT", "PGN127251"}
N2K_LOG = {"PGN128259", "PGN128275"}
N2K_POSITION = {"PGN129029", "PGN129025"}
#: proprietary sentences of INS (attitude and true heading: NovAtel/Trimble, Seapath)
INS_SENTENCES = {"PASHR", "PSXN"}
HEADING_SENTENCES = {"HDT", "HDG", "HDM", "THS"} | INS_SENTENCES | N2K_HEADING
LOG_SENTENCES = {"VHW", "VBW", "VLW"} | N2K_LOG
#: own-ship AIS (``!AIVDO``) positions come from the transponder's own receiver
AIS_POSITION = {"VDO"}
POSITION_SENTENCES = {"GGA", "GLL", "RMC", "GNS"} | N2K_POSITION | AIS_POSITION

_NAME_RULES = [
    (re.compile(r"^(?:.*[/_.-])?ins[_-]?([123])$", re.I), None),
    (re.compile(r"^(?:.*[/_.-])?(gyro|compass|hdg|heading)$", re.I), "compass"),
    (re.compile(r"^(?:.*[/_.-])?(log|speedlog|stw)$", re.I), "log"),
    (re.compile(r"^(?:.*[/_.-])?(gnss|gps)$", re.I), "gnss"),
]


#: sentences that give rows of several kinds from one line (RMC: position and ground;
#: AIS VDO: position, ground, heading): kind -> the types whose rows of that kind are not
#: counted as sentences (their position row is)
COUNTED_IN_POSITION = {"ground": ("RMC", "VDO"), "heading": ("VDO",)}


def summarize(
    frames: dict[str, pd.DataFrame], file: str, into: dict[str, SourceInfo] | None = None
) -> dict[str, SourceInfo]:
    """Add per-source counts of ``frames`` (kind -> canonical frame) to ``into``.

    Records are counted once per frame row; a sentence giving rows of several kinds (an
    RMC: a position and a ground row) is counted once, in its position row
    (:data:`COUNTED_IN_POSITION`).  The reference for
    :func:`dracc.ingest.summarize_frames`, which counts the same on categorical codes.
    """
    out = {} if into is None else into
    for kind, df in frames.items():
        if df is None or len(df) == 0:
            continue
        src = df["source"].astype(str).to_numpy()
        sent = df["sentence"].astype(str).to_numpy()
        talk = df["talker"].astype(str).to_numpy()
        t = df["time_ns"].to_numpy()
        codes, uniq = pd.factorize(src)
        for i, key in enumerate(uniq):
            sel = codes == i
            info = out.setdefault(key, SourceInfo(key=key))
            count_sent = sel & ~np.isin(sent, COUNTED_IN_POSITION.get(kind, ()))
            if count_sent.any():
                u, c = np.unique(sent[count_sent], return_counts=True)
                info.sentences.update(dict(zip(u.tolist(), c.tolist(), strict=True)))
                u, c = np.unique(talk[count_sent], return_counts=True)
                info.talkers.update(
                    {k: v for k, v in zip(u.tolist(), c.tolist(), strict=True) if k}
                )
            info.records += int(sel.sum())
            ts = t[sel]
            lo, hi = int(ts.min()), int(ts.max())
            info.first_ns = lo if info.first_ns is None else min(info.first_ns, lo)
            info.last_ns = hi if info.last_ns is None else max(info.last_ns, hi)
            info.files.add(file)
    return out


#: mapping keys that must match a source (``--role KEY=ROLE`` on the command line: a key
#: that matches nothing is a bad option value there, exit 2, while a fleet's
#: [ingest.sources] may name units a given log lacks)
_MUST_MATCH: ContextVar[frozenset[str]] = ContextVar(
    "dracc_role_keys_must_match", default=frozenset()
)


@contextmanager
def keys_must_match(keys: Iterable[str]) -> Iterator[None]:
    """Within the block, :func:`assign_roles` raises :class:`OptionError` (exit 2, a bad
    ``--role`` value) for a mapping key in ``keys`` that matches no source (naming the
    keys that exist)."""
    token = _MUST_MATCH.set(frozenset(keys))
    try:
        yield
    finally:
        _MUST_MATCH.reset(token)


def _talker(info: SourceInfo) -> str | None:
    """The dominant talker of a source, if any."""
    if not info.talkers:
        return None
    return info.talkers.most_common(1)[0][0]


def _name_role(key: str) -> str | None:
    for rx, role in _NAME_RULES:
        m = rx.match(key)
        if m:
            return f"ins{m.group(1)}" if role is None else role
    return None


def assign_roles(
    sources: dict[str, SourceInfo],
    mapping: dict[str, str],
    candidates: dict[str, list[str]] | None = None,
) -> list[str]:
    """Assign ``SourceInfo.roles`` in place; return human-readable notes.

    A compass, log or gnss role that several sources could fill by content is left free
    and its candidates put in ``candidates`` (role -> keys): one of them is chosen by
    evidence from the data (:func:`dracc.ingest.role_evidence.choose_roles`), never
    several merged.

    Raises :class:`ConfigError` for a mapping to an unknown role, and
    :class:`AmbiguousSourceError` when the mapping itself gives one role to sources
    that contradict each other (two different mapped keys for ``ins1``, say, where
    both carry data).
    """
    notes: list[str] = []
    for key, role in mapping.items():
        if role not in ROLES:
            raise ConfigError(
                f"[ingest.sources] {key!r} = {role!r}: role must be one of {', '.join(ROLES)}"
            )
    taken: dict[str, list[str]] = {}

    def give(info: SourceInfo, role: str, why: str) -> None:
        if role not in info.roles:
            info.roles.append(role)
            taken.setdefault(role, []).append(info.key)
            notes.append(f"{info.key} -> {role} ({why})")

    # 1. configuration
    used_keys = set()
    for key, role in mapping.items():
        hits = [s for k, s in sources.items() if k == key]
        if not hits:
            hits = [s for s in sources.values() if _talker(s) == key or key in s.talkers]
        if not hits:
            if key in _MUST_MATCH.get():
                known = ", ".join(sorted(sources)) or "none"
                talkers = sorted({t for x in sources.values() for t in x.talkers} - set(sources))
                raise OptionError(
                    f"--role {key}={role}: no source has the key {key!r}; the sources are "
                    f"{known}" + (f" (talkers {', '.join(talkers)})" if talkers else "")
                )
            notes.append(f"[ingest.sources] {key!r} matches no source in the data")
        for s in hits:
            give(s, role, "configuration")
            used_keys.add(s.key)
    for role, keys in taken.items():
        if role in INS_ROLES and len(keys) > 1:
            raise AmbiguousSourceError(
                f"[ingest.sources] role {role} given to several sources: {', '.join(sorted(keys))}"
            )
    free = {k: s for k, s in sources.items() if k not in used_keys}
    # 2. names
    by_name: dict[str, list[SourceInfo]] = {}
    for key, info in free.items():
        named = _name_role(key)
        if named and named not in taken:
            by_name.setdefault(named, []).append(info)
    for role, infos in by_name.items():
        if len(infos) == 1:
            give(infos[0], role, "name")
        elif role in ("compass", "log", "gnss") and candidates is not None:
            candidates[role] = sorted(i.key for i in infos)  # one chosen by evidence
            taken[role] = []
        else:
            notes.append(
                f"{role} role not assigned: several sources are named for it "
                f"({', '.join(sorted(i.key for i in infos))}); map one in [ingest.sources]"
            )
    # several units behind one key (dracc.ingest.interleaved) get a role only by mapping
    free = {k: s for k, s in free.items() if not s.roles and not s.interleaved}
    one_unit = {k: s for k, s in sources.items() if not s.interleaved}

    # 3. content
    def has(info: SourceInfo, sents: set[str]) -> bool:
        return any(info.sentences.get(x, 0) for x in sents)

    if not any(r in taken for r in INS_ROLES):
        ins = [
            s
            for s in free.values()
            if has(s, POSITION_SENTENCES)
            and (
                (_talker(s) in INS_TALKERS and "/" not in s.key)
                or "ins" in s.key.lower()
                or has(s, INS_SENTENCES)
            )
        ]
        if len(ins) == 3:
            for role, s in zip(INS_ROLES, sorted(ins, key=lambda s: s.key), strict=True):
                give(s, role, "three INS-type sources with positions")
        elif ins and len(ins) != 1:
            notes.append(
                f"INS roles not assigned: {len(ins)} INS-type position sources "
                f"({', '.join(sorted(s.key for s in ins))}); map them in [ingest.sources]"
            )
    # GNSS candidates, the first tier that has any: satellite talkers; NMEA 2000 devices
    # sending positions and no heading (a satellite compass sends both); own-ship AIS
    tiers = [
        (
            [s for s in free.values() if (_talker(s) or "") in GNSS_FAMILY],
            lambda s: f"satellite talker {_talker(s)}",
        ),
        (
            [s for s in free.values() if has(s, N2K_POSITION) and not has(s, N2K_HEADING)],
            lambda s: "NMEA 2000 positions without heading",
        ),
        (  # a satellite compass or an integrated navigation system: positions and heading
            [s for s in free.values() if has(s, N2K_POSITION)],
            lambda s: (
                "NMEA 2000 positions (with heading: a satellite compass or navigation system)"
            ),
        ),
        ([s for s in free.values() if has(s, AIS_POSITION)], lambda s: "own-ship AIS (VDO)"),
    ]
    gnss, why_gnss = next(
        (
            ([s for s in t if not s.roles and has(s, POSITION_SENTENCES)], why)
            for t, why in tiers
            if any(not s.roles and has(s, POSITION_SENTENCES) for s in t)
        ),
        ([], tiers[0][1]),
    )
    pending = {} if candidates is None else candidates
    if "gnss" not in taken:
        if len(gnss) == 1:
            give(gnss[0], "gnss", why_gnss(gnss[0]))
        elif len(gnss) > 1:
            pending["gnss"] = sorted(s.key for s in gnss)
    if "compass" not in taken:
        cands = [
            s
            for s in one_unit.values()
            if has(s, HEADING_SENTENCES) and not any(r in INS_ROLES or r == "gnss" for r in s.roles)
        ]
        # what a sentence type can be: a source of fixes (GGA/GLL/RMC/GNS) that gives heading
        # too is an INS or a GNSS compass (a lone IN, a skytraq GN with HDT), not the ship's
        # compass; only an instrument bus (fixes beside speed-log sentences, e.g. II with
        # RMC + HDG + VHW) may still be.  The pipeline takes heading from such a source, and
        # says so, only where no compass exists.
        # an INS's own attitude sentences (PASHR, PSXN) make it an INS, not the compass,
        # where another heading source is a candidate
        cands = [s for s in cands if not has(s, INS_SENTENCES)] or cands
        devices = [s for s in cands if has(s, POSITION_SENTENCES) and not has(s, LOG_SENTENCES)]
        if devices:
            cands = [s for s in cands if s not in devices]
            for s in sorted(devices, key=lambda s: s.key):
                hs = "/".join(x for x in sorted(HEADING_SENTENCES) if s.sentences.get(x))
                ps = "/".join(x for x in sorted(POSITION_SENTENCES) if s.sentences.get(x))
                notes.append(
                    f"{s.key} not given the compass role: it sends fixes ({ps}) as well as "
                    f"heading ({hs}), so it is an INS or a GNSS compass; map it "
                    f"(--role {s.key}=compass) if it is the ship's compass"
                )
        pure = [s for s in cands if not has(s, POSITION_SENTENCES)]  # heading sentences only
        if pure:
            cands = pure
        if len(cands) == 1:
            give(cands[0], "compass", "the only source of heading sentences")
        elif len(cands) > 1:
            pending["compass"] = sorted(s.key for s in cands)
    if "log" not in taken:
        cands = [
            s
            for s in one_unit.values()
            if has(s, {"VHW", "VBW", "PGN128259"})
            and not any(r in INS_ROLES or r == "gnss" for r in s.roles)
        ]
        if len(cands) > 1:  # a GNSS's 128259 (speed over ground only) beside the log's
            cands = [s for s in cands if not has(s, POSITION_SENTENCES)] or cands
        if len(cands) == 1:
            give(cands[0], "log", "the only source of VHW/VBW/PGN128259")
        elif len(cands) > 1:
            pending["log"] = sorted(s.key for s in cands)
    waiting = {k for keys in pending.values() for k in keys}  # chosen or kept as witnesses
    unassigned = [k for k, s in sources.items() if not s.roles and k not in waiting]
    if unassigned:
        notes.append(f"no role: {', '.join(sorted(unassigned))}")
    return notes


def require_role(sources: dict[str, SourceInfo], role: str) -> str:
    """The one source serving ``role``; AmbiguousSourceError naming the candidates otherwise."""
    keys = [k for k, s in sources.items() if role in s.roles]
    if len(keys) == 1:
        return keys[0]
    if keys:
        raise AmbiguousSourceError(
            f"role {role} is served by several sources: {', '.join(sorted(keys))}; "
            "choose one in [ingest.sources]"
        )
    raise AmbiguousSourceError(
        f"no source has role {role}; sources: {', '.join(sorted(sources)) or 'none'}; "
        "map one in [ingest.sources]"
    )


def sentence_counts(infos: dict[str, SourceInfo]) -> Counter[str]:
    """All sentence counts over sources."""
    c: Counter[str] = Counter()
    for s in infos.values():
        c.update(s.sentences)
    return c


# ------------------------------------------------------------ one key in several files
#: two files' records of one key overlapping in time by more than this are two sources
FILE_OVERLAP_S = 60.0
_SEP = re.compile(r"[_\-. ]")


def file_ids(files: list[str]) -> dict[str, str]:
    """A short, distinct name per file: the file stems without what all of them share at
    the start and the end, cut at a separator (``NBP1406_seap-2014-08-01`` and
    ``NBP1406_gp02-2014-08-01`` -> ``seap``, ``gp02``); the whole stems where that leaves
    nothing or no longer tells the files apart."""
    from os.path import commonprefix
    from pathlib import Path

    stems = {
        f: Path(f).name.rsplit(".", 1)[0] if "." in Path(f).name[1:] else Path(f).name
        for f in files
    }
    names = list(dict.fromkeys(stems.values()))
    ids = dict(stems)
    if len(names) > 1:
        pre = commonprefix(names)  # noqa: RUF071  character prefix of file names, on purpose
        cut = max((m.end() for m in _SEP.finditer(pre)), default=0)
        suf = commonprefix([n[::-1] for n in names])[::-1]  # noqa: RUF071  likewise
        cut_end = min((m.start() for m in _SEP.finditer(suf)), default=len(suf))
        tail = len(suf) - cut_end
        short = {f: s[cut : len(s) - tail if tail else None] for f, s in stems.items()}
        if all(short.values()) and len(set(short.values())) == len(names):
            ids = short
    seen: Counter[str] = Counter()
    out: dict[str, str] = {}
    for f in files:  # the same name in two folders: numbered
        seen[ids[f]] += 1
        out[f] = ids[f] if seen[ids[f]] == 1 else f"{ids[f]}~{seen[ids[f]]}"
    return out


def _span(info: SourceInfo) -> str:
    import datetime as dt

    def hm(ns: int) -> str:
        return dt.datetime.fromtimestamp(ns / 1e9, tz=dt.timezone.utc).strftime("%Y-%m-%d %H:%M:%S")

    return (
        # last_ns is set together with first_ns
        f"{hm(info.first_ns)}-{hm(cast(int, info.last_ns))[11:]}"
        if info.first_ns is not None
        else "no times"
    )


def separate_files(
    per_file: list[tuple[str, dict[str, SourceInfo]]], overlap_s: float = FILE_OVERLAP_S
) -> tuple[dict[str, dict[str, str]], list[str]]:
    """Decide, for every source key that several files carry, whether it is one source.

    A source is its file *and* its key (TAG ``s:``, topic, CSV source or talker): two
    GPS receivers logged to two files both say ``GP``.  Where the files' records of a key
    overlap in time by more than ``overlap_s`` they are two instruments: each file's key
    becomes ``<file id>:<key>`` (:func:`file_ids`).  Where they follow each other in
    time (one recorder's consecutive files) they are one source.  Either way a note says
    so.  Returns ({file: {old key: new key}}, notes); a key found in one file only keeps
    its name, so single-file keys never change.
    """
    by_key: dict[str, list[tuple[str, SourceInfo]]] = {}
    for f, infos in per_file:
        for k, s in infos.items():
            by_key.setdefault(k, []).append((f, s))
    renames: dict[str, dict[str, str]] = {f: {} for f, _ in per_file}
    notes: list[str] = []
    ids = None
    from pathlib import Path

    for key, lst in by_key.items():
        if len(lst) < 2:
            continue
        # (first_ns, last_ns) of the timed summaries: both are set together
        timed = [(s.first_ns, cast(int, s.last_ns)) for _, s in lst if s.first_ns is not None]
        overlap = max(
            (
                min(a_last, b_last) - max(a_first, b_first)
                for i, (a_first, a_last) in enumerate(timed)
                for b_first, b_last in timed[i + 1 :]
            ),
            default=-1,
        )
        where = ", ".join(f"{Path(f).name} {_span(s)}" for f, s in lst)
        if overlap > overlap_s * 1e9:
            if ids is None:
                ids = file_ids([f for f, _ in per_file])
            new = {f: f"{ids[f]}:{key}" for f, _ in lst}
            for f, n in new.items():
                renames[f][key] = n
            notes.append(
                f"{key}: in {len(lst)} files whose times overlap by {overlap / 1e9:.0f} s ({where}): "
                f"{len(lst)} instruments, kept apart as {', '.join(new.values())}"
            )
        else:
            notes.append(
                f"{key}: one source over {len(lst)} files that follow each other in time "
                f"({where}); merged"
            )
    return renames, notes


def merge_infos(
    per_file: list[tuple[str, dict[str, SourceInfo]]], renames: dict[str, dict[str, str]]
) -> dict[str, SourceInfo]:
    """The per-file summaries under their decided keys, merged where a key is shared."""
    out: dict[str, SourceInfo] = {}
    for f, infos in per_file:
        for k, s in infos.items():
            key = renames.get(f, {}).get(k, k)
            m = out.setdefault(key, SourceInfo(key=key))
            m.talkers.update(s.talkers)
            m.sentences.update(s.sentences)
            m.records += s.records
            if s.first_ns is not None:
                assert s.last_ns is not None  # set together with first_ns
                m.first_ns = s.first_ns if m.first_ns is None else min(m.first_ns, s.first_ns)
                m.last_ns = s.last_ns if m.last_ns is None else max(m.last_ns, s.last_ns)
            m.files |= s.files
    return out


def rename_sources(frames: dict[str, pd.DataFrame], mapping: dict[str, str]) -> None:
    """Rename source keys in a file's frames, in place (categoricals keep their codes)."""
    if not mapping:
        return
    for df in frames.values():
        if df is None or "source" not in df:
            continue
        col = df["source"]
        if isinstance(col.dtype, pd.CategoricalDtype):
            cats = [str(c) for c in col.cat.categories]
            new = [mapping.get(c, c) for c in cats]
            if new != cats and len(set(new)) == len(new):
                df["source"] = col.cat.rename_categories(new)
            elif new != cats:
                df["source"] = pd.Categorical(col.astype(str).map(lambda x: mapping.get(x, x)))
        else:
            df["source"] = col.astype(str).map(lambda x: mapping.get(x, x))
