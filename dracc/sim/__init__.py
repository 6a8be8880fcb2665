"""Voyage simulator with known truth (:func:`simulate`) and its NMEA 0183 writer.

See :mod:`dracc.sim.model` for :func:`simulate` and its glossary, :mod:`dracc.sim.params`
for the parameters, :mod:`dracc.sim.truth` for the true track, :mod:`dracc.sim.processes`
for the sensor error processes, :mod:`dracc.sim.readings` for the written precision and the
canonical frames, :mod:`dracc.sim.nmea_out` for the sentence layouts and line forms, and
:mod:`dracc.sim.faults` for the seeded sensor and time faults (``SimParams(faults=...)``);
the sources' clocks are ``SimParams(phases_s=..., latency_s=...)`` or
:func:`dracc.sim.params.random_clocks`, their truth ``SimVoyage.clocks``.
"""

from dracc.sim.faults import (
    FAULT_KINDS,
    TIME_FAULT_KINDS,
    SimFault,
    parse_fault,
    resolve_faults,
)
from dracc.sim.model import SimVoyage, simulate, simulate_segments
from dracc.sim.params import DEFAULT_INS, GM, InsErrorParams, SimParams, random_clocks
from dracc.sim.processes import gauss_markov

__all__ = [
    "DEFAULT_INS",
    "FAULT_KINDS",
    "GM",
    "TIME_FAULT_KINDS",
    "InsErrorParams",
    "SimFault",
    "SimParams",
    "SimVoyage",
    "gauss_markov",
    "parse_fault",
    "random_clocks",
    "resolve_faults",
    "simulate",
    "simulate_segments",
]
