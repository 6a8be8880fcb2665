"""Voyage simulator with known truth (:func:`simulate`) and its NMEA 0183 writer.

See :mod:`dracc.sim.model` for the truth, the sensor error processes and the written
precision, and :mod:`dracc.sim.nmea_out` for the sentence layouts and line forms.
"""

from .model import (
    DEFAULT_INS,
    GM,
    InsErrorParams,
    SimParams,
    SimVoyage,
    gauss_markov,
    simulate,
    simulate_segments,
)

__all__ = ["GM", "DEFAULT_INS", "InsErrorParams", "SimParams", "SimVoyage", "gauss_markov",
           "simulate", "simulate_segments"]
