"""Post-processing of a scene's located events: halt time, its error, and the ramp exponent.

Halt time. Near the end the energy-equivalent inclination follows beta ~ c (t_halt - t)^p. The
three unknowns (c, t_halt, p) are fixed by the last three level times; t_halt solves

    ln((x - t1)/(x - t2)) / ln((x - t2)/(x - t3)) = ln(b1/b2) / ln(b2/b3),   x > t3,

which has a root if and only if the gaps between level times shrink faster than the levels do
(for decade levels: t3 - t2 < t2 - t1); that is the finite-time criterion. For geometric levels it
is Aitken's delta-squared extrapolation. The error estimate is the change of t_halt when the fit
uses the previous three levels instead (or, where that fit has no root, the remainder t_halt - t3).

Ramp exponent n of the precession frequency, Omega ~ (t_halt - t)^(-n): least squares of
ln Omega_i against ln(t_halt - t_i) over the reached levels with a precession frequency (the mean
over whole precession cycles, docs/model.md); its error is the standard error of the slope (NaN
with only two levels).
"""
from __future__ import annotations

import math

import numpy as np


def _halt_from_three(t: np.ndarray, b: np.ndarray) -> tuple[float, float]:
    """(t_halt, p) from three level times t (increasing) and inclinations b (decreasing), or NaNs."""
    t1, t2, t3 = (float(x) for x in t)
    b1, b2, b3 = (float(x) for x in b)
    d1, d2 = t2 - t1, t3 - t2
    if not (d1 > 0.0 and d2 > 0.0):
        return math.nan, math.nan
    rho = math.log(b1 / b2) / math.log(b2 / b3)
    if d1 / d2 <= rho:       # the root x runs off to infinity: no finite halt
        return math.nan, math.nan

    def F(x):
        return math.log((x - t1) / (x - t2)) / math.log((x - t2) / (x - t3)) - rho

    lo = t3 + 1e-12 * max(1.0, abs(t3))
    hi = t3 + d2
    while F(hi) < 0.0:
        hi = t3 + 2.0 * (hi - t3)
        if hi - t3 > 1e12 * d2:
            return math.nan, math.nan
    # F increases from -rho at x = t3+ to d1/d2 - rho > 0 at infinity; bisection to round-off
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if mid <= lo or mid >= hi:
            break
        if F(mid) < 0.0:
            lo = mid
        else:
            hi = mid
    x = 0.5 * (lo + hi)
    p = math.log(b2 / b3) / math.log((x - t2) / (x - t3))
    return x, p


def halt_time(level_t: np.ndarray, levels: np.ndarray) -> dict:
    """Fit the final approach law over the last reached levels (times in any unit, levels in rad).

    Returns t_halt, t_halt_error (the change against the previous three levels, else the
    extrapolated remainder t_halt - t_last), approach exponent
    p (beta ~ (t_halt - t)^p), and halt_finite (False where the gaps do not shrink fast enough).
    """
    ok = np.isfinite(level_t)
    t = np.asarray(level_t)[ok]
    b = np.asarray(levels)[ok]
    res = {"t_halt": math.nan, "t_halt_error": math.nan, "approach_exponent": math.nan, "halt_finite": False}
    if t.size < 3:
        return res
    th, p = _halt_from_three(t[-3:], b[-3:])
    if not math.isfinite(th):
        return res
    res.update(t_halt=th, approach_exponent=p, halt_finite=True)
    # Without a finite fit on the previous three levels (fewer than four reached, or the approach
    # was not yet in its final law there), the extrapolated remainder t_halt - t_last itself is the
    # error bar: the halt lies after the last reached level, at most about that far from t_halt.
    res["t_halt_error"] = th - float(t[-1])
    if t.size >= 4:
        th2, _ = _halt_from_three(t[-4:-1], b[-4:-1])
        if math.isfinite(th2):
            res["t_halt_error"] = abs(th - th2)
    return res


def ramp_exponent(level_t: np.ndarray, precession: np.ndarray, t_halt: float) -> float:
    """n in Omega ~ (t_halt - t)^(-n), least squares over levels with finite values; NaN if < 2."""
    return ramp_fit(level_t, precession, t_halt)[0]


def ramp_fit(level_t: np.ndarray, precession: np.ndarray, t_halt: float) -> tuple[float, float]:
    """(n, standard error of n): n in Omega ~ (t_halt - t)^(-n) by least squares of ln Omega
    against ln(t_halt - t) over the levels with finite values; NaN if fewer than 2 (error: 3)."""
    if not math.isfinite(t_halt):
        return math.nan, math.nan
    lt = np.asarray(level_t, dtype=float)
    om = np.abs(np.asarray(precession, dtype=float))
    ok = np.isfinite(lt) & np.isfinite(om) & (om > 0) & (lt < t_halt)
    k = int(ok.sum())
    if k < 2:
        return math.nan, math.nan
    x = np.log(t_halt - lt[ok])
    yv = np.log(om[ok])
    xm = x - x.mean()
    sxx = float(np.dot(xm, xm))
    if not sxx > 0.0:
        return math.nan, math.nan
    slope = float(np.dot(xm, yv - yv.mean())) / sxx
    err = math.nan
    if k > 2:
        res = yv - yv.mean() - slope * xm
        err = math.sqrt(float(np.dot(res, res)) / (k - 2) / sxx)
    return -slope, err
