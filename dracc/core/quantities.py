"""Named quantities with their unit in the name: the vocabulary of CSV and MCAP/JSON logs
and of ``[ingest] quantities`` in the configuration.

A quantity name is a base name and a unit suffix (``lat_deg``, ``stw_kn``, ``sog_mps``,
``total_water_nmi``); the suffix says how to reach the canonical unit, so a column in
knots is never read as metres per second.  The table of base names, kinds and accepted
suffixes is in :mod:`dracc.ingest.csv_quantities`, which reads columns with it.
"""

from __future__ import annotations

from dataclasses import dataclass

from dracc.core.units import DEG_RAD, KMH_MPS, KN_MPS, NMI_M

#: boolean fields: name -> the reference their ``true`` means
BOOLEAN_FIELDS = {
    "is_true": "T",
    "true_heading": "T",
    "is_true_heading": "T",
    "is_magnetic": "M",
    "magnetic_heading": "M",
}

_ANGLE = {"deg": DEG_RAD, "rad": 1.0}
_SPEED = {"kn": KN_MPS, "mps": 1.0, "kmh": KMH_MPS}
_LENGTH = {"m": 1.0, "nmi": NMI_M}
_RATE = {"radps": 1.0, "degps": DEG_RAD, "degpmin": DEG_RAD / 60.0}

#: base name -> (kind, canonical column, unit suffix -> factor to the canonical unit)
_BASES: dict[str, tuple[str, str, dict[str, float]]] = {
    "lat": ("position", "lat_rad", _ANGLE),
    "lon": ("position", "lon_rad", _ANGLE),
    "alt": ("position", "alt_m", {"m": 1.0}),
    "heading": ("heading", "heading_rad", _ANGLE),
    "deviation": ("heading", "deviation_rad", _ANGLE),
    "variation": ("heading", "variation_rad", _ANGLE),
    "cog": ("ground", "cog_rad", _ANGLE),
    "sog": ("ground", "sog_mps", _SPEED),
    "stw": ("water", "stw_mps", _SPEED),
    "stw_transverse": ("water", "stw_transverse_mps", _SPEED),
    "sog_long": ("water", "sog_long_mps", _SPEED),
    "sog_transverse": ("water", "sog_transverse_mps", _SPEED),
    "total_water": ("distance", "total_water_m", _LENGTH),
    "trip_water": ("distance", "trip_water_m", _LENGTH),
    "rot": ("rot", "rot_radps", _RATE),
}


@dataclass(frozen=True)
class Quantity:
    """One named quantity: where it goes and the factor from its unit to the canonical one."""

    name: str  #: e.g. 'stw_kn'
    kind: str  #: canonical frame kind, e.g. 'water'
    column: str  #: canonical column, e.g. 'stw_mps'
    factor: float  #: canonical = value * factor (e.g. 1852/3600 for knots)


def _build_table() -> dict[str, Quantity]:
    table: dict[str, Quantity] = {}
    for base, (kind, column, units) in _BASES.items():
        for unit, factor in units.items():
            name = f"{base}_{unit}"
            table[name] = Quantity(name, kind, column, factor)
    for name, kind in (("quality", "position"), ("hdop", "position"), ("reference", "heading")):
        table[name] = Quantity(name, kind, name, 1.0)
    for name in BOOLEAN_FIELDS:  # 'is_true' etc.: a boolean that gives the reference
        table[name] = Quantity(name, "heading", "reference", 1.0)
    return table


#: every quantity name dracc understands, e.g. QUANTITIES['stw_kn'].factor == 1852/3600
QUANTITIES: dict[str, Quantity] = _build_table()

#: the quantity names whose values are a heading reference (text or boolean), not numbers
REF_QUANTITIES = frozenset(n for n, q in QUANTITIES.items() if q.column == "reference")
