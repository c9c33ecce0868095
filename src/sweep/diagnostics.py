"""Post-processing of a scene's located events: halt time, its error, and the ramp exponent.

Halt time. Near the end the energy-equivalent inclination follows beta ~ c (t_halt - t)^p. The
three unknowns (c, t_halt, p) are fixed by the last three level times; t_halt solves

    ln((x - t1)/(x - t2)) / ln((x - t2)/(x - t3)) = ln(b1/b2) / ln(b2/b3),   x > t3,

which has a root if and only if the gaps between level times shrink faster than the levels do
(for decade levels: t3 - t2 < t2 - t1); that is the finite-time criterion. For geometric levels it
is Aitken's delta-squared extrapolation. The error estimate is the change of t_halt when the fit
uses the previous three levels instead (or, where that fit has no root, the remainder t_halt - t3).

Ramp exponent n of the precession frequency, Omega ~ (t_halt - t)^(-n): least squares of
ln Omega_i against ln(t_halt - t_i) over the reached levels.
"""
from __future__ import annotations

import numpy as np

from .core.ensemble import (D_APPROACH, D_HALT_FINITE, D_THALT, D_THALT_ERR, N_DERIVED, halt_fit, halt_from_three,
                            ramp_fit)


def _halt_from_three(t: np.ndarray, b: np.ndarray) -> tuple[float, float]:
    """(t_halt, p) from three level times t (increasing) and inclinations b (decreasing), or NaNs."""
    return halt_from_three(*(float(x) for x in t), *(float(x) for x in b))


def halt_time(level_t: np.ndarray, levels: np.ndarray) -> dict:
    """Fit the final approach law over the last reached levels (times in any unit, levels in rad).

    Returns t_halt, t_halt_error (the change against the previous three levels, else the
    extrapolated remainder t_halt - t_last), approach exponent
    p (beta ~ (t_halt - t)^p), and halt_finite (False where the gaps do not shrink fast enough).
    Without a finite fit on the previous three levels (fewer than four reached, or the approach
    was not yet in its final law there), the extrapolated remainder t_halt - t_last itself is the
    error bar: the halt lies after the last reached level, at most about that far from t_halt.
    The numbers come from the numba kernel `core.ensemble.halt_fit`, which the batch path runs on
    its device.
    """
    lt = np.ascontiguousarray(level_t, dtype=float)
    out = np.empty(N_DERIVED)
    halt_fit(lt, np.ascontiguousarray(levels, dtype=float), lt.shape[0], out)
    return {"t_halt": float(out[D_THALT]), "t_halt_error": float(out[D_THALT_ERR]),
            "approach_exponent": float(out[D_APPROACH]), "halt_finite": bool(out[D_HALT_FINITE])}


def ramp_exponent(level_t: np.ndarray, precession: np.ndarray, t_halt: float) -> float:
    """n in Omega ~ (t_halt - t)^(-n), least squares over levels with finite values; NaN if < 2
    (the numba kernel `core.ensemble.ramp_fit`)."""
    lt = np.ascontiguousarray(level_t, dtype=float)
    return float(ramp_fit(lt, np.ascontiguousarray(precession, dtype=float), lt.shape[0], float(t_halt)))
