"""One cause, one finding (issue 32, alarm noise): the failed checks a fault causes are
listed under it (dracc.math.integrity.causes), in the audit and the analysis.

The rule on hand-made evidence (each relation, and what must stay apart), then nights
with three seeded faults -- a GNSS jump out and back, a frozen INS, an INS drop-out --
at random times, sizes and seeds: three findings, each with its consequences, and no
finding blaming the current for the jump.
"""

from __future__ import annotations

import jsonschema
import numpy as np
import pytest
from test_pipeline import voyage_from_sim

from dracc.core.config import Config
from dracc.core.errors import ExitCode
from dracc.math.integrity.causes import Trace, cause_of, failed_with_consequences, trace
from dracc.pipeline.analysis import analyse_voyage
from dracc.pipeline.audit import audit_config, audit_night, evaluate, facts_from_analysis
from dracc.pipeline.state import StateStore
from dracc.report import audit_html, audit_json, json_report, terminal
from dracc.report import html as html_report
from dracc.report.audit_text import format_summary
from dracc.sim import SimParams, simulate
from dracc.sim.faults import parse_fault

T0 = "2026-11-30T02:"


def _t(mmss: str) -> str:
    return f"{T0}{mmss}.000Z"


def _jump(*times_n_e: tuple[str, float, float], source: str = "GNSS") -> Trace:
    return trace(
        "plausibility",
        "jump",
        source,
        [{"time": _t(t), "innovation_north_m": n, "innovation_east_m": e} for t, n, e in times_n_e],
    )


OUT_AND_BACK = _jump(("00:00", 500.0, 400.0), ("10:00", -498.0, -401.0))


def test_contradiction_and_dr_2m_go_under_the_jump_they_name():
    contradiction = trace(
        "validity",
        "contradiction",
        "GNSS",
        [{"what": "jump", "time": _t("00:00")}, {"what": "jump", "time": _t("10:00")}],
    )
    # the filter's outliers while the fix was displaced and while it settled after each jump
    dr_2m = trace(
        "plausibility",
        "dr_2m",
        "GNSS",
        [{"time": _t(t)} for t in ("00:12", "00:48", "01:24", "10:12", "10:48", "12:00")],
    )
    assert cause_of([OUT_AND_BACK, contradiction, dr_2m]) == (None, 0, 0)


def test_what_another_source_or_another_time_shows_stays_a_cause():
    other_source = trace(
        "validity", "contradiction", "INS1", [{"what": "jump", "time": _t("00:00")}]
    )
    later = trace("plausibility", "dr_2m", "GNSS", [{"time": _t("40:00")}])
    wrong_fault = trace(
        "validity", "contradiction", "GNSS", [{"what": "frozen", "time": _t("00:00")}]
    )
    assert cause_of([OUT_AND_BACK, other_source, later, wrong_fault]) == (None, None, None, None)


def test_two_jumps_that_do_not_cancel_bracket_nothing():
    """Two separate displaced fixes, ten minutes apart, in the same direction: the time
    between them is no displacement, so a fix outside the 2M there is its own finding."""
    two = _jump(("00:00", 500.0, 400.0), ("10:00", 480.0, 410.0))
    between = trace("plausibility", "dr_2m", "GNSS", [{"time": _t("05:00")}])
    assert cause_of([two, between]) == (None, None)
    assert cause_of([OUT_AND_BACK, between]) == (None, 0)


def test_velocity_disagreement_reaches_back_two_schuler_periods():
    frozen = trace("plausibility", "frozen", "INS2", [{"start": _t("00:00"), "end": _t("40:00")}])
    run = {"from": "2026-11-30T04:30:00.000Z", "to": "2026-11-30T04:40:00.000Z"}
    velocity = trace("consistency", "velocity", "INS2", [run])
    other_unit = trace("consistency", "velocity", "INS1", [run])
    far = {"from": "2026-11-30T06:00:00.000Z", "to": "2026-11-30T06:10:00.000Z"}
    too_late = trace("consistency", "velocity", "INS2", [far])
    assert cause_of([frozen, velocity, other_unit, too_late]) == (None, 0, None, None)


def test_dr_verdict_goes_under_its_reference_jump_only_when_it_passes_without_it():
    legs = [{"start": _t("00:00"), "end": _t("20:00")}]

    def dr(without: str, source: str = "GNSS") -> Trace:
        ev = {"reference_source": source, "reference_jump_legs": legs}
        return trace(
            "consistency", "dr_inconsistent", None, [{**ev, "verdict_without_them": without}]
        )

    assert cause_of([OUT_AND_BACK, dr("consistent")]) == (None, 0)
    assert cause_of([OUT_AND_BACK, dr("inconsistent")]) == (None, None)
    assert cause_of([OUT_AND_BACK, dr("consistent", "INS1")]) == (None, None)
    assert cause_of([OUT_AND_BACK, trace("consistency", "dr_inconsistent", None)]) == (None, None)


def _night(seed: int) -> tuple[SimParams, dict[str, str]]:
    """One hour with three faults at random times and sizes: the GNSS displaced 40-900 m
    for 2-12 min, an INS frozen 8-15 min, another INS silent 5-10 min."""
    r = np.random.default_rng([32, seed])
    frozen, silent = (str(u) for u in r.permutation(["INS1", "INS2", "INS3"])[:2])
    specs = {
        "GNSS": f"jump:GNSS@{r.uniform(360, 2880):.0f}s+{r.uniform(120, 720):.0f}s"
        f"={r.uniform(40, 900):.0f}m",
        frozen: f"freeze:{frozen}@{r.uniform(360, 2520):.0f}s+{r.uniform(480, 900):.0f}s",
        silent: f"dropout:{silent}@{r.uniform(360, 2880):.0f}s+{r.uniform(300, 600):.0f}s",
    }
    params = SimParams(
        duration_s=3600.0,
        seed=seed,
        compass_hz=1.0,
        aux_hz=0.0,
        speed_kn=float(r.uniform(8.0, 18.0)),
        faults=tuple(parse_fault(s) for s in specs.values()),
    )
    return params, {source: spec.split(":")[0] for source, spec in specs.items()}


@pytest.fixture(scope="module", params=range(4))
def night(request):
    """(the analysis, the seeded faults by source) of one random night."""
    params, seeded = _night(request.param)
    return analyse_voyage(voyage_from_sim(simulate(params)), Config()), seeded


def test_three_faults_give_three_findings_each_with_its_consequences(night, tmp_path):
    a, seeded = night
    facts = facts_from_analysis(a)
    with StateStore(tmp_path / "a.sqlite") as store:
        o = audit_night(
            facts,
            store=store,
            acfg=audit_config(Config()),
            seeds={},
            vessel="Aurora",
            night="2026-03-01",
            content_hash="x",
            settings_hash="y",
        )
    found = o.findings
    kind = {"jump": "jump", "freeze": "frozen", "dropout": "dropout"}
    assert sorted((f.source, f.kind) for f in found) == sorted(
        (source, kind[k]) for source, k in seeded.items()
    ), [(f.source, f.kind, f.message) for f in found]
    assert o.exit_code == ExitCode.FINDINGS
    by_kind = {f.kind: f for f in found}
    under_jump = {(c.kind, c.source) for c in by_kind["jump"].consequences}
    # the receiver flagged the displaced fixes valid; the DR's filter saw them outside its 2M
    assert {("contradiction", "GNSS"), ("dr_2m", "GNSS")} <= under_jump
    assert ("contradiction", by_kind["frozen"].source) in {
        (c.kind, c.source) for c in by_kind["frozen"].consequences
    }
    assert by_kind["dropout"].consequences == ()
    # the DR, where the jump made it fail, is the jump's consequence and blames nothing else
    for said in (*found, *(c for f in found for c in f.consequences)):
        assert "current" not in said.message, said.message
    if a.dead_reckoning is not None and a.dead_reckoning.consistent is False:
        assert ("dr_inconsistent", None) in under_jump
        assert a.dead_reckoning.dominant_source is None
    # the audit's summary, document and page: three findings, the consequences under them
    summary = format_summary(o)
    assert "night 2026-03-01: 3 findings" in summary
    assert summary.count("\n  - [") == 3 and "\n      - consequence: [validity]" in summary
    doc = audit_json.to_dict(o)
    jsonschema.validate(doc, audit_json.load_schema())
    assert [len(f["consequences"]) for f in doc["findings"]] == [len(f.consequences) for f in found]
    page = audit_html.night_html(doc)
    assert page.count("<li>consequence: [") == sum(len(f.consequences) for f in found)


def test_the_analysis_lists_the_same_causes(night):
    a, _ = night
    grouped = failed_with_consequences(a.integrity)
    assert sorted((c.source, c.name) for c, _ in grouped) == sorted(
        (f.source, f.kind)
        for f in evaluate(facts_from_analysis(a), audit_config(Config()))[0]
        if f.kind != "dr_inconsistent"
    )
    text = terminal.render_text(a, width=200)
    assert f"; {len(grouped)} findings" in text and "    consequence: [validity]" in text
    doc = json_report.to_dict(a)
    jsonschema.validate(doc, json_report.load_schema())
    jump = next(
        c for c in doc["integrity"]["checks"] if c["name"] == "jump" and c["status"] == "fail"
    )
    assert {"contradiction", "dr_2m"} <= {c["name"] for c in jump["consequences"]}
    row = html_report._causes_html(a.integrity)  # the report's integrity row (no plots)
    assert row.startswith(f"{len(grouped)} findings") and "consequence: [validity]" in row
