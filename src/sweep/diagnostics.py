"""Post-processing of a scene's located events: halt time, its error, and the ramp exponent.

Halt time. Near the end the energy-equivalent inclination follows beta ~ c (t_halt - t)^p. The
three unknowns (c, t_halt, p) are fixed by the last three level times; t_halt solves

    ln((x - t1)/(x - t2)) / ln((x - t2)/(x - t3)) = ln(b1/b2) / ln(b2/b3),   x > t3,

which has a root if and only if the gaps between level times shrink faster than the levels do
(for decade levels: t3 - t2 < t2 - t1); that is the finite-time criterion. For geometric levels it
is Aitken's delta-squared extrapolation. Its error estimate is the extrapolated remainder
t_halt - t3: the level times are located on the trajectory (to the integration's accuracy), the
remainder is what the fit adds, and the halt cannot come before t3. Against the halt with levels
extended to 1e-6 rad, on every 8th point of the default grid, the true miss is 0.0007-0.94 of this
remainder, never more (CHANGELOG.md, 'Error bars'); the change against the fit on the previous three
levels is no error estimate (that triple reaches back to 0.1 rad, where the final law does not hold
yet). The numerical error of t_halt is a separate quantity: t_halt_numerical_error
(outputs.error_estimate).

Ramp exponent n of the precession frequency, Omega ~ (t_halt - t)^(-n): least squares of
ln Omega_i against ln(t_halt - t_i) over the reached levels with a precession frequency (the mean
over whole precession cycles, docs/model.md); its error is the standard error of the slope (NaN
with only two levels).
"""
from __future__ import annotations

import numpy as np

from .core.fits import (D_APPROACH, D_HALT_FINITE, D_THALT, D_THALT_ERR, N_DERIVED, halt_fit, halt_from_three)
from .core.fits import ramp_fit as _ramp_fit


def _halt_from_three(t: np.ndarray, b: np.ndarray) -> tuple[float, float]:
    """(t_halt, p) from three level times t (increasing) and inclinations b (decreasing), or NaNs."""
    return halt_from_three(*(float(x) for x in t), *(float(x) for x in b))


def halt_time(level_t: np.ndarray, levels: np.ndarray) -> dict:
    """Fit the final approach law over the last reached levels (times in any unit, levels in rad).

    Returns t_halt, t_halt_error (the extrapolated remainder t_halt - t_last, see the module
    docstring), approach exponent
    p (beta ~ (t_halt - t)^p), and halt_finite (False where the gaps do not shrink fast enough).
    The numbers come from the numba kernel `core.fits.halt_fit`, which the batch path runs on
    its device.
    """
    lt = np.ascontiguousarray(level_t, dtype=float)
    out = np.empty(N_DERIVED)
    halt_fit(lt, np.ascontiguousarray(levels, dtype=float), lt.shape[0], out)
    return {"t_halt": float(out[D_THALT]), "t_halt_error": float(out[D_THALT_ERR]),
            "approach_exponent": float(out[D_APPROACH]), "halt_finite": bool(out[D_HALT_FINITE])}


def ramp_exponent(level_t: np.ndarray, precession: np.ndarray, t_halt: float) -> float:
    """n in Omega ~ (t_halt - t)^(-n), least squares over levels with finite values; NaN if < 2."""
    return ramp_fit(level_t, precession, t_halt)[0]


def ramp_fit(level_t: np.ndarray, precession: np.ndarray, t_halt: float) -> tuple[float, float]:
    """(n, standard error of n): n in Omega ~ (t_halt - t)^(-n) by least squares of ln Omega
    against ln(t_halt - t) over the levels with finite values; NaN if fewer than 2 (error: 3).
    The numba kernel `core.fits.ramp_fit`, which the batch path runs on its device."""
    lt = np.ascontiguousarray(level_t, dtype=float)
    n, err = _ramp_fit(lt, np.ascontiguousarray(precession, dtype=float), lt.shape[0], float(t_halt))
    return float(n), float(err)
