"""The nightly shipboard audit: thresholds, the a priori rule, findings, the state.

``dracc audit`` runs after midnight over the last day's logs, analyses them with
:func:`dracc.pipeline.analysis.analyse`, checks the results against the limits in the
``[audit]`` section of the configuration and keeps the state between nights in SQLite
(:mod:`dracc.pipeline.state`).  The modules, in reading order:

``limits``    the ``[audit]`` settings, the a priori seeds, the vessel name
``rule``      the paper's monitoring rule ``a_{k+1} = max(a_k, m_y,k)`` (:func:`apriori_chain`)
``facts``     what the audit reads from a typed :class:`~dracc.pipeline.results.Analysis`
``findings``  one night's checks (:func:`evaluate`) and the :class:`Finding` they give
``accuracy``  the limiting errors pooled over the accuracy window (several nights)
``logs``      choosing the night's logs safely, and their content hash
``run``       :func:`run_audit`: analyse, check, record the night and the a priori chain

The names below are the package's API, importable from ``dracc.pipeline.audit``.
"""

from __future__ import annotations

from dracc.pipeline.audit.accuracy import PooledChannel, accuracy_findings, pool_channels
from dracc.pipeline.audit.facts import (
    DR_VERDICTS,
    VALID_UNUSED,
    NightFacts,
    dr_verdict_word,
    facts_from_analysis,
    night_of,
)
from dracc.pipeline.audit.findings import (
    AUDIT_CLAUSES,
    DR_FALSE_ALARM,
    Finding,
    evaluate,
    integrity_finding,
    make_finding,
    not_checked,
)
from dracc.pipeline.audit.limits import (
    KEY_CHANNELS,
    UNITS,
    AuditConfig,
    apriori_seeds,
    audit_config,
    settings_sha256,
    vessel_name,
)
from dracc.pipeline.audit.logs import (
    LogChoice,
    choose_logs,
    content_sha256,
    file_sha256,
    input_problem,
    outside_link,
    parse_night,
    select_logs,
    yesterday_utc,
)
from dracc.pipeline.audit.rule import RuleStep, apriori_chain
from dracc.pipeline.audit.run import (
    NO_DATA_SHA256,
    TEST_SLEEP_ENV,
    AuditOutcome,
    analyse_voyage,
    audit_night,
    open_state,
    record_no_data,
    run_audit,
)

__all__ = [
    "AUDIT_CLAUSES",
    "DR_FALSE_ALARM",
    "DR_VERDICTS",
    "KEY_CHANNELS",
    "NO_DATA_SHA256",
    "TEST_SLEEP_ENV",
    "UNITS",
    "VALID_UNUSED",
    "AuditConfig",
    "AuditOutcome",
    "Finding",
    "LogChoice",
    "NightFacts",
    "PooledChannel",
    "RuleStep",
    "accuracy_findings",
    "analyse_voyage",
    "apriori_chain",
    "apriori_seeds",
    "audit_config",
    "audit_night",
    "choose_logs",
    "content_sha256",
    "dr_verdict_word",
    "evaluate",
    "facts_from_analysis",
    "file_sha256",
    "input_problem",
    "integrity_finding",
    "make_finding",
    "night_of",
    "not_checked",
    "open_state",
    "outside_link",
    "parse_night",
    "pool_channels",
    "record_no_data",
    "run_audit",
    "select_logs",
    "settings_sha256",
    "vessel_name",
    "yesterday_utc",
]
