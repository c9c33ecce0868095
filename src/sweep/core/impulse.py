"""Perfectly plastic contact impulse: the kinetic-energy projection of the velocity (no allocation).

Used where alpha crosses 0 and the other rim edge takes the contact (side change). The physical
velocity (v, omega) of the old contact is projected, in the metric of the kinetic energy
(diag(1, 1, 1, A, C, A) on e-frame components), onto the velocities the new contact allows. This is
Gauss' principle for an impulsive constraint: the energy lost, 1/2 |V - V_new|^2_M >= 0, is returned.
"""
from __future__ import annotations

import math

from numba import njit

from .model import P_A, P_C, P_H, Y_ALPHA, Y_U1, Y_U2, Y_W1, Y_W2, Y_W3

# columns of the scratch rows: J (6 x 5) in 0..4, augmented normal matrix (5 x 6) in 5..10,
# velocity V in 11, metric weights in 12
_J0, _M0, _V, _WT = 0, 5, 11, 12


@njit(cache=True)
def _velocity(y, h, with_slip, out, col):
    """Physical velocity: centre velocity and angular velocity on e1, e2, e3 (reduced state)."""
    a = y[Y_ALPHA]
    s = math.sin(a)
    c = math.cos(a)
    w1, w2, w3 = y[Y_W1], y[Y_W2], y[Y_W3]
    u1 = y[Y_U1] if with_slip else 0.0
    u2 = y[Y_U2] if with_slip else 0.0
    # v = v_P - omega x r, r = -h e2 - e3; v_P = u1 a1 + u2 a2, a2 = c e2 - s e3
    out[0, col] = u1 + w2 - h * w3
    out[1, col] = u2 * c - w1
    out[2, col] = -u2 * s + h * w1
    out[3, col] = w1
    out[4, col] = w2
    out[5, col] = w3


@njit(cache=True)
def project_velocity(y, p, side_old, side_new, with_slip, S):
    """Project y's velocity onto the contact on `side_new` in place; returns the energy lost.

    with_slip: the contact slides (slip components u1, u2 are free), else it rolls (u = 0).
    S: scratch array with at least 6 rows and 13 columns.
    """
    _velocity(y, side_old * p[P_H], with_slip, S, _V)
    h = side_new * p[P_H]
    a = y[Y_ALPHA]
    s = math.sin(a)
    c = math.cos(a)
    nq = 5 if with_slip else 3
    for k in range(6):
        for j in range(5):
            S[k, _J0 + j] = 0.0
    S[0, _WT] = 1.0
    S[1, _WT] = 1.0
    S[2, _WT] = 1.0
    S[3, _WT] = p[P_A]
    S[4, _WT] = p[P_C]
    S[5, _WT] = p[P_A]
    # columns: d V / d (w1, w2, w3, u1, u2) for the new contact
    S[0, 1] = 1.0
    S[0, 2] = -h
    S[1, 0] = -1.0
    S[2, 0] = h
    S[3, 0] = 1.0
    S[4, 1] = 1.0
    S[5, 2] = 1.0
    S[0, 3] = 1.0
    S[1, 4] = c
    S[2, 4] = -s
    for i in range(nq):
        b = 0.0
        for k in range(6):
            b += S[k, i] * S[k, _WT] * S[k, _V]
        S[i, _M0 + nq] = b
        for j in range(nq):
            m = 0.0
            for k in range(6):
                m += S[k, i] * S[k, _WT] * S[k, j]
            S[i, _M0 + j] = m
    # Gaussian elimination with partial pivoting on the nq x (nq + 1) augmented system
    for col in range(nq):
        piv = col
        for r in range(col + 1, nq):
            if abs(S[r, _M0 + col]) > abs(S[piv, _M0 + col]):
                piv = r
        if piv != col:
            for j in range(nq + 1):
                tmp = S[col, _M0 + j]
                S[col, _M0 + j] = S[piv, _M0 + j]
                S[piv, _M0 + j] = tmp
        for r in range(col + 1, nq):
            fac = S[r, _M0 + col] / S[col, _M0 + col]
            for j in range(col, nq + 1):
                S[r, _M0 + j] -= fac * S[col, _M0 + j]
    for col in range(nq - 1, -1, -1):
        acc = S[col, _M0 + nq]
        for j in range(col + 1, nq):
            acc -= S[col, _M0 + j] * S[j, _M0 + nq]
        S[col, _M0 + nq] = acc / S[col, _M0 + col]   # solution overwrites the right-hand side
    loss = 0.0
    for k in range(6):
        vk = 0.0
        for j in range(nq):
            vk += S[k, j] * S[j, _M0 + nq]
        loss += 0.5 * S[k, _WT] * (S[k, _V] - vk) ** 2
    y[Y_W1] = S[0, _M0 + nq]
    y[Y_W2] = S[1, _M0 + nq]
    y[Y_W3] = S[2, _M0 + nq]
    if with_slip:
        y[Y_U1] = S[3, _M0 + nq]
        y[Y_U2] = S[4, _M0 + nq]
    else:
        y[Y_U1] = 0.0
        y[Y_U2] = 0.0
    return loss
