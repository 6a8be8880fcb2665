"""Voyage simulator with known truth (:func:`simulate`) and its NMEA 0183 writer.

See :mod:`dracc.sim.model` for the truth, the sensor error processes and the written
precision, :mod:`dracc.sim.nmea_out` for the sentence layouts and line forms, and
:mod:`dracc.sim.faults` for the seeded sensor faults (``SimParams(faults=...)``).
"""

from dracc.sim.faults import FAULT_KINDS, SimFault, parse_fault, resolve_faults
from dracc.sim.model import (
    DEFAULT_INS,
    GM,
    InsErrorParams,
    SimParams,
    SimVoyage,
    gauss_markov,
    simulate,
    simulate_segments,
)

__all__ = [
    "GM",
    "DEFAULT_INS",
    "FAULT_KINDS",
    "InsErrorParams",
    "SimFault",
    "SimParams",
    "SimVoyage",
    "gauss_markov",
    "parse_fault",
    "resolve_faults",
    "simulate",
    "simulate_segments",
]
