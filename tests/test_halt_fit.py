"""The halt-time fit (sweep.diagnostics.halt_time) and what its error bar means, on level times of
known approach laws (no integration)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from sweep import diagnostics

LEVELS = np.array([1e-1, 1e-2, 1e-3, 1e-4])
T = 30.0


def level_times(c: float, p: float, a: float, levels=LEVELS) -> np.ndarray:
    """Times at which beta(t) = c (T - t)^p (1 + a (T - t)) reaches each level (bisection)."""
    out = []
    for b in levels:
        lo, hi = T - 1e3, T
        for _ in range(200):
            mid = 0.5 * (lo + hi)
            if c * (T - mid) ** p * (1 + a * (T - mid)) > b:
                lo = mid
            else:
                hi = mid
        out.append(0.5 * (lo + hi))
    return np.array(out)


def test_exact_law_gives_the_halt_and_the_remainder_as_error():
    t = level_times(0.01, 2.0, 0.0)
    fit = diagnostics.halt_time(t, LEVELS)
    assert fit["halt_finite"]
    assert fit["t_halt"] == pytest.approx(T, abs=1e-9)
    assert fit["approach_exponent"] == pytest.approx(2.0, rel=1e-6)
    # the error bar is the part of t_halt that is extrapolated, not located
    assert fit["t_halt_error"] == pytest.approx(fit["t_halt"] - t[-1], rel=1e-12)
    assert fit["t_halt_error"] == pytest.approx(math.sqrt(1e-4 / 0.01), rel=1e-6)


@pytest.mark.parametrize("c, p, a", [(0.01, 2.0, 0.3), (0.01, 2.0, 1.0), (0.003, 2.0, 3.0),
                                     (0.02, 0.5, 0.5), (0.05, 1.0, 2.0)])
def test_error_bar_covers_the_true_error_of_a_law_not_yet_final(c, p, a):
    """A correction (1 + a (T - t)) that matters at the upper levels makes the fit miss T; the
    error bar (the remainder after the last level) is larger than the miss, but not by orders of
    magnitude (0.1-0.22 of it for these laws)."""
    t = level_times(c, p, a)
    fit = diagnostics.halt_time(t, LEVELS)
    miss = abs(fit["t_halt"] - T)
    assert fit["t_halt_error"] == pytest.approx(fit["t_halt"] - t[-1], rel=1e-12)
    assert 0.05 * fit["t_halt_error"] <= miss <= fit["t_halt_error"]


def test_no_finite_halt_without_shrinking_gaps():
    t = np.array([1.0, 2.0, 3.0, 4.0])   # equal gaps per decade: the approach never ends
    fit = diagnostics.halt_time(t, LEVELS)
    assert not fit["halt_finite"] and math.isnan(fit["t_halt"]) and math.isnan(fit["t_halt_error"])
