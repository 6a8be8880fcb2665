"""The INS deviation stage (METHODS section 4): each unit's deviation from the mean of
the units, with GNSS as the reference where present (:mod:`dracc.math.deviation`)."""

from __future__ import annotations

from dracc.core.config import Config
from dracc.core.vocabulary import INS_ROLES
from dracc.frames import Voyage
from dracc.math.deviation import DeviationResult, analyse_deviations, unit_series_from_voyage


def deviation(
    voyage: Voyage, cfg: Config, missing: list[str]
) -> tuple[DeviationResult | None, str | None]:
    """INS deviations from the mean (dracc.math.deviation), with GNSS as the reference where present."""
    present = [r for r in INS_ROLES if voyage.role_sources(r)]
    if len(present) < 2:
        found = f"only one INS unit ({present[0]}) found" if present else "no INS unit found"
        missing.append(
            f"no INS triple: {found}; the deviation statistics need at least "
            "two units (three for the paper's factors); map sources to ins1..ins3 with "
            "--role KEY=ROLE if they are there under another name"
        )
        return None, None
    units = {r: unit_series_from_voyage(voyage, r) for r in present}
    ref_role = "gnss" if voyage.role_sources("gnss") else None
    reference = unit_series_from_voyage(voyage, ref_role) if ref_role else None
    if reference is not None and reference.lat_rad.size == 0:
        reference, ref_role = None, None
    result = analyse_deviations(units, cfg.deviation, reference)
    if len(present) == 2:
        missing.append(
            f"no INS triple: only two units ({', '.join(present)}); statistics use "
            "the first-approximation factor sqrt(2) and no three-cornered hat"
        )
    if ref_role is None:
        missing.append(
            "no reference (GNSS) for the INS: the true error RMS and k* (Table 1) are not computed"
        )
    return result, ref_role
