"""The summary's fitted numbers from a scene's level crossings (diagnostics.py explains the
methods): the halt time, its error and the approach exponent from the last three levels
(halt_from_three, halt_fit), the ramp exponent of the precession frequency (ramp_fit), and the
summary's set of them (summary_fits), which sweep.simulate and the batch path both call. The
integrator calls halt_from_three itself after the halt, on levels below the last one, where the
configured levels give no finite halt (tracking.deep_levels)."""
from __future__ import annotations

import math

from .jit import kernel
from .layout import F_APPROACH, F_TEND, F_THALT, F_THALT_ERR
from .roots import location_tol


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


# --- the summary's fitted numbers (SI: s) ------------------------------------------------------
D_THALT, D_THALT_ERR, D_HALT_FINITE, D_APPROACH, D_RAMP, D_RAMP_ERR = range(6)
N_DERIVED = 6


@kernel
def halt_fit(level_t, levels, nl, out):
    """out[D_THALT, D_THALT_ERR, D_HALT_FINITE, D_APPROACH] from the last reached levels
    (diagnostics.halt_time: the fit on the last three; its error bar is the extrapolated remainder
    t_halt - t_last, the part of t_halt the fit adds)."""
    out[D_THALT] = math.nan
    out[D_THALT_ERR] = math.nan
    out[D_HALT_FINITE] = 0.0
    out[D_APPROACH] = math.nan
    i1 = i2 = i3 = -1   # the last three reached levels, i1 the last
    count = 0
    for i in range(nl):
        if math.isfinite(level_t[i]):
            i3, i2, i1 = i2, i1, i
            count += 1
    if count < 3:
        return
    th, p = halt_from_three(level_t[i3], level_t[i2], level_t[i1], levels[i3], levels[i2], levels[i1])
    if not math.isfinite(th):
        return
    out[D_THALT] = th
    out[D_APPROACH] = p
    out[D_HALT_FINITE] = 1.0
    out[D_THALT_ERR] = th - level_t[i1]


@kernel
def ramp_fit(level_t, precession, nl, t_halt):
    """(n, standard error of n), n in Omega ~ (t_halt - t)^(-n): least squares of ln|Omega| on
    ln(t_halt - t) over the levels with finite values before t_halt; NaN if fewer than two (the
    error: fewer than three)."""
    if not math.isfinite(t_halt):
        return math.nan, math.nan
    m = 0
    sx = 0.0
    sy = 0.0
    for i in range(nl):
        om = abs(precession[i])
        if math.isfinite(level_t[i]) and math.isfinite(om) and om > 0.0 and level_t[i] < t_halt:
            m += 1
            sx += math.log(t_halt - level_t[i])
            sy += math.log(om)
    if m < 2:
        return math.nan, math.nan
    mx = sx / m
    my = sy / m
    sxx = 0.0
    sxy = 0.0
    for i in range(nl):
        om = abs(precession[i])
        if math.isfinite(level_t[i]) and math.isfinite(om) and om > 0.0 and level_t[i] < t_halt:
            dx = math.log(t_halt - level_t[i]) - mx
            sxx += dx * dx
            sxy += dx * (math.log(om) - my)
    if not sxx > 0.0:
        return math.nan, math.nan
    slope = sxy / sxx
    if m < 3:
        return -slope, math.nan
    ssr = 0.0
    for i in range(nl):
        om = abs(precession[i])
        if math.isfinite(level_t[i]) and math.isfinite(om) and om > 0.0 and level_t[i] < t_halt:
            r = math.log(om) - my - slope * (math.log(t_halt - level_t[i]) - mx)
            ssr += r * r
    return -slope, math.sqrt(ssr / (m - 2) / sxx)


@kernel
def summary_fits(level_t, prec_hz, levels, nl, lay_flat, fstats, chi, out):
    """The summary's fitted numbers into out (D_*). level_t (s), prec_hz (Hz), levels (rad): the
    first nl entries; fstats: the run's (layout.F_*). A disk that lay flat halted at the located
    event fstats[F_TEND]; where the configured levels give no finite halt, the integrator's fit on
    the levels below them (fstats[F_THALT], tracking.deep_levels) is taken."""
    if lay_flat:
        out[D_THALT] = fstats[F_TEND] * chi
        out[D_THALT_ERR] = location_tol(fstats[F_TEND]) * chi
        out[D_HALT_FINITE] = 1.0
        out[D_APPROACH] = math.nan
    else:
        halt_fit(level_t, levels, nl, out)
        if math.isnan(out[D_THALT]) and not math.isnan(fstats[F_THALT]):
            out[D_THALT] = fstats[F_THALT] * chi
            out[D_THALT_ERR] = fstats[F_THALT_ERR] * chi
            out[D_HALT_FINITE] = 1.0
            out[D_APPROACH] = fstats[F_APPROACH]
    out[D_RAMP], out[D_RAMP_ERR] = ramp_fit(level_t, prec_hz, nl, out[D_THALT])
