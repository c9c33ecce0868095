"""Outcome codes of a scene: why its integration ended.

The integer codes are stored in the netCDF cube (variable `outcome`, CF `flag_values` /
`flag_meanings`) and returned by the numba kernel, so they are fixed: append, never renumber.
"""
from __future__ import annotations

HALTED = 0               # reached the smallest configured inclination level (normal end)
CONTACT_LOST = 1         # normal force Phi fell to zero: the rigid single-contact model ends
STEP_LIMIT = 2           # the step budget was used up before the smallest level
T_MAX = 3                # t_max (s) was reached before the smallest level
LINE_CONTACT = 4         # alpha came to 0 and stayed: the disk stands on its flat edge (model void)
STEP_SIZE_UNDERFLOW = 5  # the error control asked for a step below the round-off floor of tau
NUMERICAL_ERROR = 6      # a NaN/inf appeared, or an exception was raised for this point
NOT_RUN = 7              # reserved for the pipeline: the point was not computed (never written by a finished chunk)
FACE_CONTACT = 8         # not written: a disk that reaches flat (1e-6 rad) has halted (HALTED, summary lay_flat); the code stays reserved
PAINLEVE = 9             # the contact law admits no acceleration (Painleve paradox: a sliding disk with high mu_d
                         # drives the normal-force coefficient to 0): the rigid-body model with Coulomb friction ends

NAMES = {
    HALTED: "halted",
    CONTACT_LOST: "contact_lost",
    STEP_LIMIT: "step_limit",
    T_MAX: "t_max",
    LINE_CONTACT: "line_contact",
    STEP_SIZE_UNDERFLOW: "step_size_underflow",
    NUMERICAL_ERROR: "numerical_error",
    NOT_RUN: "not_run",
    FACE_CONTACT: "face_contact",
    PAINLEVE: "painleve",
}
CODES = {name: code for code, name in NAMES.items()}

# The ends the numerics made, not the physics: the scene's result stops where they stopped it
# (`python3 run.py scene` exits 3 with this reason; a sweep records the code)
NUMERICAL_FAILURES = {
    STEP_LIMIT: "the step budget stop.max_steps was used up before the smallest level (raise it)",
    STEP_SIZE_UNDERFLOW: "the error control asked for a step below the round-off of the time (a state the "
                         "integrator cannot advance from)",
    NUMERICAL_ERROR: "a NaN or infinity appeared in the state, or a slaved slip direction did not converge",
}

FLAG_VALUES = sorted(NAMES)
FLAG_MEANINGS = " ".join(NAMES[c] for c in FLAG_VALUES)
