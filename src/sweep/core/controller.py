"""Step-size control apart from the method (as OrdinaryDiffEq.jl separates its controllers from its
algorithms): the factor by which the next step's size follows from an error norm.

The elementary (I) controller of Hairer, Norsett & Wanner (1993), II.4: h_new = h fac with
fac = SAFETY err^exponent, limited to [MIN_FACTOR, MAX_FACTOR]; `exponent` is the method's,
-1/(q + 1) for an error estimator of order q (dop853.ERR_EXPONENT). After a rejected step the
accepted one does not grow (Hairer's DOP853 alike).
"""
from __future__ import annotations

import math

from .jit import kernel

SAFETY = 0.9
MIN_FACTOR = 0.2
MAX_FACTOR = 10.0


@kernel
def step_factor(err, exponent):
    """Step-size factor after an error norm `err` (the step is accepted if err <= 1), for the
    method's exponent (-1/(q + 1))."""
    if err == 0.0:
        return MAX_FACTOR
    if not math.isfinite(err):
        return MIN_FACTOR
    return min(MAX_FACTOR, max(MIN_FACTOR, SAFETY * err ** exponent))


@kernel
def accepted_step_factor(err, exponent, after_reject):
    """Step-size factor after an accepted step (err <= 1); no growth right after a rejection (as
    in Hairer's DOP853): 6 % fewer steps at the median harness scene."""
    fac = step_factor(err, exponent)
    return min(fac, 1.0) if after_reject else fac
