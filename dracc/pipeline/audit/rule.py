"""The monitoring rule of the a priori RMS, night after night (or log after log).

The rule (INS-deviation paper, conclusions)
-------------------------------------------
"Monitor systematically the RMS values of coordinates and the course using the
deviations of the NP from the average values and compare them with the a priori values
of the RMS.  As a result, the larger value becomes a new a priori one.  In the absence
of a priori values of the RMS, their definition by deviation becomes mandatory."
Per unit and channel::

    a_0     = a priori from the configuration ([deviation.apriori]), or none
    a_{k+1} = max(a_k, m_y,k)        m_y,k = k_ch * m_u,k   (K3b), (K5b)
    a_1     = m_y,0                  when there is no a_0 ("established")

The audit applies it over the stored nights of a vessel, the fleet over a vessel's logs.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass


@dataclass(frozen=True)
class RuleStep:
    """The monitoring rule applied to one night: ``after = max(before, m_y)``."""

    night: str
    m_y: float | None
    before: float | None
    after: float | None
    verdict: str  #: 'established', 'within', 'raised' or 'no data'


def apriori_chain(seed: float | None, nights: Sequence[tuple[str, float | None]]) -> list[RuleStep]:
    """Apply the monitoring rule night after night (paper's conclusions).

    ``nights``: (night, m_y) in time order; ``m_y`` None or NaN where the night gave no
    estimate (the a priori value then carries over unchanged).
    """
    steps = []
    current = seed
    for night, m_y in nights:
        if m_y is None or not math.isfinite(m_y):
            steps.append(RuleStep(night, None, current, current, "no data"))
            continue
        if current is None:
            steps.append(RuleStep(night, m_y, None, m_y, "established"))  # mandatory by deviation
            current = m_y
        elif m_y > current:
            steps.append(
                RuleStep(night, m_y, current, m_y, "raised")
            )  # the larger becomes a priori
            current = m_y
        else:
            steps.append(RuleStep(night, m_y, current, current, "within"))
    return steps
