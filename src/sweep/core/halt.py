"""The halt time from three level crossings (diagnostics.py explains the method): the fit the
summary makes on the last three levels, and the one the integrator makes on deeper levels after the
halt where those give no finite value (integrate.deep_levels)."""
from __future__ import annotations

import math

from .jit import kernel


@kernel
def _halt_residual(x, t1, t2, t3, rho):
    return math.log((x - t1) / (x - t2)) / math.log((x - t2) / (x - t3)) - rho


@kernel
def halt_from_three(t1, t2, t3, b1, b2, b3):
    """(t_halt, p) from three level times t1 < t2 < t3 and inclinations b1 > b2 > b3, or NaNs."""
    d1 = t2 - t1
    d2 = t3 - t2
    if not (d1 > 0.0 and d2 > 0.0):
        return math.nan, math.nan
    rho = math.log(b1 / b2) / math.log(b2 / b3)
    if d1 / d2 <= rho:       # the root x runs off to infinity: no finite halt
        return math.nan, math.nan
    lo = t3 + 1e-12 * max(1.0, abs(t3))
    hi = t3 + d2
    while _halt_residual(hi, t1, t2, t3, rho) < 0.0:
        hi = t3 + 2.0 * (hi - t3)
        if hi - t3 > 1e12 * d2:
            return math.nan, math.nan
    # the residual increases from -rho at x = t3+ to d1/d2 - rho > 0 at infinity: bisection to round-off
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if mid <= lo or mid >= hi:
            break
        if _halt_residual(mid, t1, t2, t3, rho) < 0.0:
            lo = mid
        else:
            hi = mid
    x = 0.5 * (lo + hi)
    return x, math.log(b2 / b3) / math.log((x - t2) / (x - t3))
