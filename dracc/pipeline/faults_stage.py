"""The sensor-fault stage: faults found in the raw records (:mod:`dracc.math.faults`),
always reported, their records left out of what follows only on request.  A repeated
position or heading no other source could judge is said in a note, never a fault."""

from __future__ import annotations

from dracc.core.config import Config
from dracc.frames import Voyage
from dracc.math.faults import SensorFault, exclude_faults, faults_and_repeats


def sensor_faults(
    voyage: Voyage, cfg: Config, notes: list[str]
) -> tuple[tuple[SensorFault, ...], Voyage]:
    """Sensor faults in the raw records (dracc.math.faults); their records are left out of
    what follows only where ``[faults] exclude = true`` (the tracks keep the raw figures)."""
    found, repeats = faults_and_repeats(voyage, cfg.faults)
    faults = tuple(found)
    unjudged: dict[tuple[str, str], float] = {}
    for r in repeats:
        if r.verdict == "no_witness":
            k = (r.source, "position" if r.kind == "frozen" else "heading")
            unjudged[k] = max(unjudged.get(k, 0.0), r.duration_s)
    for (source, what), longest in sorted(unjudged.items()):
        notes.append(
            f"{source}: {what} repeated bit for bit for {longest / 60:.0f} min at the longest; "
            f"no other source tells whether the ship {'moved' if what == 'position' else 'turned'}"
            ", so it is not called frozen or stuck"
        )
    if faults and cfg.faults.exclude:
        voyage, removed = exclude_faults(voyage, list(faults))
        notes.append(
            f"{len(faults)} sensor fault(s): their records are left out of the statistics "
            "([faults] exclude = true): "
            + ", ".join(f"{n} {kind}" for kind, n in sorted(removed.items()))
        )
    elif faults:
        notes.append(
            f"{len(faults)} sensor fault(s) found and reported; their records are still in the "
            "statistics (set [faults] exclude = true to leave them out)"
        )
    return faults, voyage
