"""validity checks: ``invalid_flag`` (the source's own status flags, spells of at least
``spell_min_s``) and ``contradiction`` (records flagged valid that fail plausibility)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from dracc.core.config import IntegrityConfig
from dracc.core.timefmt import iso_utc
from dracc.core.units import NS_PER_S
from dracc.frames import Voyage
from dracc.math.faults import SensorFault
from dracc.math.integrity.helpers import (
    MAX_EVIDENCE,
    by_source,
    role_of,
    runs,
    statistic,
    threshold,
)
from dracc.math.integrity.results import Check

__all__ = ["contradiction_checks", "validity_checks"]


def validity_checks(voyage: Voyage, cfg: IntegrityConfig) -> list[Check]:
    checks = []
    spell_ns = int(cfg.spell_min_s * NS_PER_S)
    parts: dict[str, list[tuple[str, pd.DataFrame, NDArray[np.bool_]]]] = {}
    for key, g in by_source(voyage.frames["position"]):
        parts.setdefault(key, []).append(("position", g, g["quality"].to_numpy() == 0))
    for key, g in by_source(voyage.frames["heading"]):
        parts.setdefault(key, []).append(
            ("heading", g, ~np.isfinite(g["heading_rad"].to_numpy(float)))
        )
    for key, g in by_source(voyage.frames["ground"]):  # VTG mode N, RMC status V: no velocity
        parts.setdefault(key, []).append(
            (
                "ground",
                g,
                ~np.isfinite(g["cog_rad"].to_numpy(float))
                & ~np.isfinite(g["sog_mps"].to_numpy(float)),
            )
        )
    for key in sorted(parts):
        evidence: list[dict[str, Any]] = []
        n_flag, n_all, longest = 0, 0, 0.0
        t_first: int | None = None
        t_last: int | None = None
        for kind, g, bad in parts[key]:
            t = g["time_ns"].to_numpy(np.int64)
            n_all += len(t)
            n_flag += int(bad.sum())
            t_first = t[0] if t_first is None else min(t_first, t[0])
            t_last = t[-1] if t_last is None else max(t_last, t[-1])
            lines = g["line"].to_numpy()
            sent = g["sentence"]
            for a, b in runs(bad):
                dur = (t[b - 1] - t[a]) / NS_PER_S
                longest = max(longest, dur)
                if t[b - 1] - t[a] >= spell_ns and len(evidence) < MAX_EVIDENCE:
                    evidence.append(
                        {
                            "start": iso_utc(unit="ms", time_ns=t[a]),
                            "end": iso_utc(unit="ms", time_ns=t[b - 1]),
                            "duration_s": dur,
                            "records": b - a,
                            "frame": kind,
                            "first_line": int(lines[a]),
                            "sentence": str(sent.iloc[a]),
                        }
                    )
        assert t_first is not None and t_last is not None  # a source has records
        failed = bool(evidence)
        msg = (
            f"{key}: flagged its own data invalid for {longest:.0f} s at the longest "
            f"({n_flag} of {n_all} records; {len(evidence)} spell(s) of {cfg.spell_min_s:g} s or more)"
            if failed
            else f"{key}: {n_flag} of {n_all} records flagged invalid, no spell of "
            f"{cfg.spell_min_s:g} s"
        )
        checks.append(
            Check(
                "validity",
                "invalid_flag",
                key,
                role_of(voyage, key),
                "fail" if failed else "pass",
                statistic("longest_invalid_spell", longest, "s"),
                threshold(
                    cfg.spell_min_s,
                    "s",
                    "a spell of records the source flags "
                    "invalid (GGA quality 0, RMC/GLL status V, GNS/VTG mode N, "
                    "empty heading) at least this long",
                ),
                {"start_ns": int(t_first), "end_ns": int(t_last)},
                0.0,
                msg,
                tuple(evidence),
                detail={"flagged_records": n_flag, "records": n_all},
            )
        )
    return checks


def contradiction_checks(
    voyage: Voyage, checks: Sequence[Check], faults: Sequence[SensorFault]
) -> list[Check]:
    """validity / contradiction: a source flagging as valid what fails plausibility."""
    out = []
    pos = voyage.frames["position"]
    for key in sorted({c.source for c in checks if c.check == "plausibility" and c.source}):
        events = []
        for c in checks:
            if c.source == key and c.name == "jump" and c.status == "fail":
                events += [
                    {"what": "jump", "time": e["time"], "line": e["line"]}
                    for e in c.evidence
                    if e.get("flagged_valid")
                ]
        mask_src = (pos["source"] == key).to_numpy()
        for f in faults:
            if f.source != key or f.kind != "frozen" or not mask_src.any():
                continue
            t = pos["time_ns"].to_numpy(np.int64)[mask_src]
            q = pos["quality"].to_numpy()[mask_src]
            inside = (t >= f.start_ns) & (t <= f.end_ns)
            if (q[inside] > 0).any():
                events.append(
                    {
                        "what": "frozen",
                        "time": iso_utc(unit="ms", time_ns=f.start_ns),
                        "line": f.first_line,
                        "records_flagged_valid": int((q[inside] > 0).sum()),
                    }
                )
        if not events:
            continue
        out.append(
            Check(
                "validity",
                "contradiction",
                key,
                role_of(voyage, key),
                "fail",
                statistic("implausible_records_flagged_valid", len(events), "count"),
                threshold(0, "count", "a record the source flags valid must pass plausibility"),
                {},
                0.0,
                f"{key}: flagged as valid what fails plausibility: "
                + ", ".join(
                    f"{w} x{sum(e['what'] == w for e in events)}"
                    for w in sorted({e["what"] for e in events})
                ),
                tuple(events[:MAX_EVIDENCE]),
            )
        )
    return out
