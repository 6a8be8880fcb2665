"""The sensor-fault stage: faults found in the raw records (:mod:`dracc.math.faults`),
always reported, their records left out of what follows only on request."""

from __future__ import annotations

from dracc.core.config import Config
from dracc.frames import Voyage
from dracc.math.faults import SensorFault, detect_faults, exclude_faults


def sensor_faults(
    voyage: Voyage, cfg: Config, notes: list[str]
) -> tuple[tuple[SensorFault, ...], Voyage]:
    """Sensor faults in the raw records (dracc.math.faults); their records are left out of
    what follows only where ``[faults] exclude = true`` (the tracks keep the raw figures)."""
    faults = tuple(detect_faults(voyage, cfg.faults))
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
