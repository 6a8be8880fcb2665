"""Source keys, their summary (:class:`SourceInfo`) and role assignment.

Source keys come from the readers: the TAG ``s:`` value, an MCAP topic, a CSV source
column, or the NMEA talker ID; a talker whose position sentences come with two or more
different numbers of decimals of minutes (two receivers behind one talker) is split
into ``<talker>/<n>dp`` keys (see :func:`dracc.ingest.nmea._fingerprint`).

Role assignment (:func:`assign_roles`), in this order:

1. the configuration mapping ``[ingest.sources]``; a key there may be a source key or
   a talker ID (then every source with that talker gets the role);
2. names: a source key naming its unit (``INS1``..``INS3``, ``GYRO``/``HDG``/
   ``COMPASS``/``HEADING``, ``LOG``/``SPEEDLOG``/``STW``, ``GNSS``/``GPS``), case-insensitive,
   as a whole key or the last component of a topic; only if one source has that name;
3. content, only where unambiguous: talker families (GP/GN/GA/GL/GB -> gnss; exactly
   three INS-type talkers or keys (IN, II, IR, or names containing 'INS') with
   positions -> ins1..3 in sorted order); the only source with heading sentences and
   no positions -> compass (where there is none, the only source with heading sentences
   at all; where there are several, the only one giving true heading, HDT/THS); the only
   source with VHW/VBW -> log.  An instrument bus (e.g. 'II' with HDG + VHW) may be compass and log.
4. Otherwise the role stays free and a note names the candidates; where the data
   clearly need a role that two sources claim, :class:`AmbiguousSourceError` is for
   the caller that requires it (``require_role``).
"""

from __future__ import annotations

import re
from collections import Counter

import numpy as np
import pandas as pd

from ..errors import AmbiguousSourceError, ConfigError
from .frames import INS_ROLES, ROLES, SourceInfo

GNSS_FAMILY = ("GP", "GN", "GA", "GL", "GB", "GI", "GQ", "BD")
INS_TALKERS = ("IN", "II", "IR")
HEADING_SENTENCES = {"HDT", "HDG", "HDM", "THS", "ROT"}
LOG_SENTENCES = {"VHW", "VBW", "VLW"}
POSITION_SENTENCES = {"GGA", "GLL", "RMC", "GNS"}

_NAME_RULES = [
    (re.compile(r"^(?:.*[/_.-])?ins[_-]?([123])$", re.I), None),
    (re.compile(r"^(?:.*[/_.-])?(gyro|compass|hdg|heading)$", re.I), "compass"),
    (re.compile(r"^(?:.*[/_.-])?(log|speedlog|stw)$", re.I), "log"),
    (re.compile(r"^(?:.*[/_.-])?(gnss|gps)$", re.I), "gnss"),
]


def summarize(frames: dict[str, pd.DataFrame], file: str,
              into: dict[str, SourceInfo] | None = None) -> dict[str, SourceInfo]:
    """Add per-source counts of ``frames`` (kind -> canonical frame) to ``into``.

    Records are counted once per frame row; an RMC gives a position and a ground row,
    so sentence counts use the position row only for RMC.
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
            count_sent = sel & ~((kind == "ground") & (sent == "RMC"))
            if count_sent.any():
                u, c = np.unique(sent[count_sent], return_counts=True)
                info.sentences.update(dict(zip(u.tolist(), c.tolist(), strict=True)))
                u, c = np.unique(talk[count_sent], return_counts=True)
                info.talkers.update({k: v for k, v in zip(u.tolist(), c.tolist(), strict=True) if k})
            info.records += int(sel.sum())
            ts = t[sel]
            lo, hi = int(ts.min()), int(ts.max())
            info.first_ns = lo if info.first_ns is None else min(info.first_ns, lo)
            info.last_ns = hi if info.last_ns is None else max(info.last_ns, hi)
            info.files.add(file)
    return out


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


def assign_roles(sources: dict[str, SourceInfo], mapping: dict[str, str]) -> list[str]:
    """Assign ``SourceInfo.roles`` in place; return human-readable notes.

    Raises :class:`ConfigError` for a mapping to an unknown role, and
    :class:`AmbiguousSourceError` when the mapping itself gives one role to sources
    that contradict each other (two different mapped keys for ``ins1``, say, where
    both carry data).
    """
    notes: list[str] = []
    for key, role in mapping.items():
        if role not in ROLES:
            raise ConfigError(f"[ingest.sources] {key!r} = {role!r}: role must be one of {', '.join(ROLES)}")
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
            notes.append(f"[ingest.sources] {key!r} matches no source in the data")
        for s in hits:
            give(s, role, "configuration")
            used_keys.add(s.key)
    for role, keys in taken.items():
        if role in INS_ROLES and len(keys) > 1:
            raise AmbiguousSourceError(f"[ingest.sources] role {role} given to several sources: "
                                       f"{', '.join(sorted(keys))}")
    free = {k: s for k, s in sources.items() if k not in used_keys}
    # 2. names
    by_name: dict[str, list[SourceInfo]] = {}
    for key, info in free.items():
        role = _name_role(key)
        if role and role not in taken:
            by_name.setdefault(role, []).append(info)
    for role, infos in by_name.items():
        if len(infos) == 1:
            give(infos[0], role, "name")
        else:
            notes.append(f"{role} role not assigned: several sources are named for it "
                         f"({', '.join(sorted(i.key for i in infos))}); map one in [ingest.sources]")
    free = {k: s for k, s in free.items() if not s.roles}

    # 3. content
    def has(info: SourceInfo, sents: set[str]) -> bool:
        return any(info.sentences.get(x, 0) for x in sents)

    if not any(r in taken for r in INS_ROLES):
        ins = [s for s in free.values()
               if has(s, POSITION_SENTENCES) and ((_talker(s) in INS_TALKERS and "/" not in s.key)
                                                 or "ins" in s.key.lower())]
        if len(ins) == 3:
            for role, s in zip(INS_ROLES, sorted(ins, key=lambda s: s.key), strict=True):
                give(s, role, "three INS-type sources with positions")
        elif ins and len(ins) != 1:
            notes.append(f"INS roles not assigned: {len(ins)} INS-type position sources "
                         f"({', '.join(sorted(s.key for s in ins))}); map them in [ingest.sources]")
    gnss = [s for s in free.values() if not s.roles and has(s, POSITION_SENTENCES)
            and (_talker(s) or "") in GNSS_FAMILY]
    if "gnss" not in taken:
        if len(gnss) == 1:
            give(gnss[0], "gnss", f"satellite talker {_talker(gnss[0])}")
        elif len(gnss) > 1:
            notes.append("gnss role not assigned: several satellite sources "
                         f"({', '.join(sorted(s.key for s in gnss))}); map one in [ingest.sources]")
    if "compass" not in taken:
        cands = [s for s in sources.values() if has(s, HEADING_SENTENCES)
                 and not any(r in INS_ROLES or r == "gnss" for r in s.roles)]
        pure = [s for s in cands if not has(s, POSITION_SENTENCES)]  # heading sentences only
        if pure:
            cands = pure
        true = [s for s in cands if has(s, {"HDT", "THS"})]
        if len(cands) > 1 and len(true) == 1:  # a gyro (true heading) beside magnetic compasses
            give(true[0], "compass", "the only source of true heading (HDT/THS) among "
                 f"{', '.join(sorted(s.key for s in cands))}")
        elif len(cands) == 1:
            give(cands[0], "compass", "the only source of heading sentences")
        elif len(cands) > 1:
            notes.append("compass role not assigned: several heading sources "
                         f"({', '.join(sorted(s.key for s in cands))}); map one in [ingest.sources]")
    if "log" not in taken:
        cands = [s for s in sources.values() if has(s, {"VHW", "VBW"})
                 and not any(r in INS_ROLES or r == "gnss" for r in s.roles)]
        if len(cands) == 1:
            give(cands[0], "log", "the only source of VHW/VBW")
        elif len(cands) > 1:
            notes.append("log role not assigned: several speed-log sources "
                         f"({', '.join(sorted(s.key for s in cands))}); map one in [ingest.sources]")
    unassigned = [k for k, s in sources.items() if not s.roles]
    if unassigned:
        notes.append(f"no role: {', '.join(sorted(unassigned))}")
    return notes


def require_role(sources: dict[str, SourceInfo], role: str) -> str:
    """The one source serving ``role``; AmbiguousSourceError naming the candidates otherwise."""
    keys = [k for k, s in sources.items() if role in s.roles]
    if len(keys) == 1:
        return keys[0]
    if keys:
        raise AmbiguousSourceError(f"role {role} is served by several sources: {', '.join(sorted(keys))}; "
                                   "choose one in [ingest.sources]")
    raise AmbiguousSourceError(f"no source has role {role}; sources: {', '.join(sorted(sources)) or 'none'}; "
                               "map one in [ingest.sources]")


def sentence_counts(infos: dict[str, SourceInfo]) -> Counter:
    """All sentence counts over sources."""
    c: Counter = Counter()
    for s in infos.values():
        c.update(s.sentences)
    return c
