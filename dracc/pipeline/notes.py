"""The sentences the dead-reckoning section says about itself: how the track was made,
what limits its scoring, and the verdict of the consistency test (METHODS section 2).

Pure text: every figure comes in from :mod:`dracc.pipeline.dr_stage`.
"""

from __future__ import annotations

from dracc.core.config import DeadReckoningConfig
from dracc.core.vocabulary import DR_OVER_GROUND, WATER_TRACK
from dracc.math.deadreckoning import Consistency, DRTrack
from dracc.math.ep import MIN_LEARNED_S, OUTLIER_NIS, EstimatedPosition
from dracc.pipeline.selection import DR_STEP_S


def dr_notes(
    tr: DRTrack,
    cons: Consistency,
    est: EstimatedPosition | None,
    cfg: DeadReckoningConfig,
    fdesc: str,
    reset_s: float,
    n_prior: int,
) -> list[str]:
    """The notes of the DR section: breaks and bridged gaps of ``tr`` (the track), how the
    model was made (learned ``est`` or as configured), and what limits the scoring
    (``cons``: the consistency result; ``n_prior`` epochs of the prior only, not scored)."""
    notes = []
    n_bridged = sum(g.bridged for g in tr.gaps)
    if tr.n_breaks:
        notes.append(
            f"{tr.n_breaks} heading/speed gap(s) longer than {cfg.max_gap_s:g} s broke "
            "the track; it restarted at the next fix"
        )
    if n_bridged:
        notes.append(f"{n_bridged} short heading/speed gap(s) bridged by holding the last value")
    if est is not None:
        notes.append(
            f"{DR_OVER_GROUND}: the {WATER_TRACK} plus the current and the compass and log "
            f"corrections learned from the {fdesc} fixes before each leg's start fix (never later "
            f"ones); scored out of sample: {cons.n_epochs} epochs of legs whose model had learned "
            f"from at least {min(MIN_LEARNED_S, reset_s) / 60:g} min of fixes; {n_prior} epochs "
            "of earlier legs (the prior only) are shown but not scored"
        )
        if est.model.n_outliers:
            notes.append(
                f"{est.model.n_outliers} fix(es) left out of the learning as outliers "
                f"(innovation beyond chi^2_2 = {OUTLIER_NIS:g} for every model)"
            )
    else:
        notes.append(
            f"{WATER_TRACK}, nothing learned: heading and speed held onto a {DR_STEP_S:g} s "
            "grid; error sources as configured (learn = false; Gauss-Markov, see "
            "docs/dead-reckoning.md)"
        )
    if 0 < cons.n_epochs < 10:
        notes.append(
            f"only {cons.n_epochs} epochs scored: for a short log give a shorter "
            "--epoch-interval (e.g. 1min)"
        )
    if 0 < cons.n_legs < 5:
        notes.append(
            f"only {cons.n_legs} leg(s) scored, and each leg is one trial: the test "
            "calls the circles too small only when the reference lies outside them "
            "in most legs or far outside; a shorter --dr-reset gives more legs"
        )
    return notes


def dr_verdict(
    cons: Consistency, learned: bool, dominant: tuple[str, str] | None
) -> tuple[bool | None, str]:
    """(consistent, verdict sentence) of the consistency test ``cons``; None and
    'undetermined' without a scored epoch.  ``dominant``: what the 2M is mostly made of
    (name, [dead_reckoning] key), named where the circles fail."""
    if not cons.n_epochs:
        return None, (
            "undetermined: no epoch of a leg whose model was learned from earlier fixes "
            "has a reference position"
            if learned
            else "undetermined: no reference position at any DR epoch after a fix"
        )
    verdict = (
        f"{cons.verdict}: reference inside 2M at {100 * cons.inside_fraction:.1f} % of "
        f"{cons.n_epochs} epochs in {cons.n_legs} legs (stated: "
        f"{100 * cons.expected_inside_fraction:.1f} %); RMS error/M "
        f"{cons.rms_error_over_m:.2f} (1 expected); NEES {cons.nees_statistic:.1f} "
        f"(chi^2 {cons.nees_lower:.1f}-{cons.nees_upper:.1f})"
    )
    if dominant is not None and cons.verdict != "consistent":
        verdict += (
            f"; the circle is dominated by {dominant[0]} (key [dead_reckoning] {dominant[1]})"
        )
    return cons.verdict in ("consistent", "conservative"), verdict
