"""The integrity checks' result types: one :class:`Check` per check and source, the
per-source :class:`SourceSummary`, and the night's :class:`IntegrityResult`."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

__all__ = ["CHECK_KINDS", "CLAUSES", "Check", "IntegrityResult", "SourceSummary"]

#: the check families of the audit document (dracc.audit/1 ``findings[].check``)
CHECK_KINDS = (
    "validity",
    "plausibility",
    "latency",
    "availability",
    "consistency",
    "time",
    "accuracy",
    "input",
)
CLAUSES = {
    "validity": "IMO MSC.252(83) 5.3: validity of sensor data (the source's own status flags)",
    "plausibility": "IMO MSC.252(83) 5.3: plausibility (values the ship and sensor can produce)",
    "latency": "IMO MSC.252(83) 5.3: latency and age of the data",
    "availability": "IMO MSC.252(83) 5.1.2: availability of the source",
    "consistency": "IMO MSC.252(83) 5.4: consistency between independent sources",
    "time": "IMO MSC.252(83) 5.3: latency and age of the data -- the time stamps themselves "
    "(the logger clock against the receivers' times of fix)",
}


@dataclass(frozen=True)
class Check:
    """One check of one source over the night."""

    check: str  #: validity | plausibility | latency | availability | consistency | time
    name: str  #: e.g. 'jump', 'invalid_flag', 'dropout', 'velocity'
    source: str | None
    role: str | None
    status: str  #: 'pass', 'fail' or 'not_checked'
    statistic: dict[str, Any]  #: {"name", "value", "unit"}
    threshold: dict[str, Any]  #: {"value", "unit", "rule"}
    window: dict[str, int]  #: {"start_ns", "end_ns"} the records the check looked at
    false_alarm: float  #: probability that a healthy source fails it on one night
    message: str
    evidence: tuple[dict[str, Any], ...] = ()
    why_not: str | None = None  #: for 'not_checked'
    #: further figures (e.g. min_detectable_m)
    detail: dict[str, Any] = field(default_factory=dict)

    @property
    def clause(self) -> str:
        return CLAUSES.get(self.check, "")


@dataclass(frozen=True)
class SourceSummary:
    """Per-source figures behind the checks."""

    source: str
    role: str | None
    records: int
    cadence_s: float | None  #: median interval between records
    availability: float | None  #: fraction of the night without a drop-out
    #: {"n", "p50", "p95", "p99", "max", "min"}, None without receive times
    latency_s: dict[str, float] | None


@dataclass(frozen=True)
class IntegrityResult:
    checks: tuple[Check, ...]
    sources: tuple[SourceSummary, ...]
    start_ns: int
    end_ns: int
    alpha: float  #: false-alarm probability of each statistical check per night

    @property
    def failed(self) -> tuple[Check, ...]:
        return tuple(c for c in self.checks if c.status == "fail")

    @property
    def made(self) -> tuple[Check, ...]:
        """The checks made (passed or failed): the count every report states."""
        return tuple(c for c in self.checks if c.status != "not_checked")

    @property
    def not_checked(self) -> tuple[Check, ...]:
        """The checks that could not be made, each with its ``why_not``."""
        return tuple(c for c in self.checks if c.status == "not_checked")

    @property
    def false_alarm_per_night(self) -> float:
        """Union (Bonferroni) bound of the checks made: P(any healthy check fails)."""
        return float(min(1.0, sum(c.false_alarm for c in self.checks if c.status != "not_checked")))
