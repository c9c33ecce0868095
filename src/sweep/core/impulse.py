"""Perfectly plastic contact impulse: the kinetic-energy projection of the velocity (no allocation).

Used where alpha crosses 0 and the other rim edge takes the contact (side change). The physical
velocity (v, omega) of the old contact is projected, in the metric of the kinetic energy
(diag(1, 1, 1, A, C, A) on e-frame components), onto the velocities the new contact allows. This is
Gauss' principle for an impulsive constraint: the energy lost, 1/2 |V - V_new|^2_M >= 0, is returned.

Also used where a moment component sticks at spin_tol (`stop_axis_rate`): the same least change of
the velocity, with omega.a_i stopped and the contact kept.
"""
from __future__ import annotations

import math

from .jit import kernel
from .constants import ROLL
from .layout import CS_MODE, CS_SIDE, CS_STUCK
from .model import P_A, P_C, P_H, Y_ALPHA, Y_U1, Y_U2, Y_W1, Y_W2, Y_W3, physical_velocity

# scratch layout: rows 0..5 hold J (6 x 5) in columns 0..4 and the augmented normal matrix
# (5 x 6) in columns 5..10; row 6 holds the old velocity V (columns 0..5) and the metric (6..11)
_M0, _VROW, _WT = 5, 6, 6


@kernel
def _set_metric(S, p):
    """The kinetic-energy metric on e-frame (v, omega) components, into S's metric slots."""
    W = S[_VROW, _WT:_WT + 6]
    W[0] = 1.0
    W[1] = 1.0
    W[2] = 1.0
    W[3] = p[P_A]
    W[4] = p[P_C]
    W[5] = p[P_A]


@kernel
def _least_change(S, nq):
    """Velocity nearest to V (S[_VROW, 0:6]) in the metric W among the combinations of the columns
    S[0:6, 0:nq]: Gaussian elimination with partial pivoting on the normal equations. The
    coefficients overwrite S[0:nq, _M0 + nq]; returns the energy lost, 1/2 |V - V_new|^2_W."""
    V = S[_VROW]
    W = S[_VROW, _WT:_WT + 6]
    for i in range(nq):
        b = 0.0
        for k in range(6):
            b += S[k, i] * W[k] * V[k]
        S[i, _M0 + nq] = b
        for j in range(nq):
            m = 0.0
            for k in range(6):
                m += S[k, i] * W[k] * S[k, j]
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
        loss += 0.5 * W[k] * (V[k] - vk) ** 2
    return loss


@kernel
def project_velocity(y, p, old, new, S, slip_dir=math.nan):
    """Project y's velocity onto the new contact in place; returns the energy lost.

    old, new: the contact before and after, each (side, slides): the rim edge (+1/-1) and whether
    the contact slides (else it rolls). A new sliding contact has both slip components free, or,
    with slip_dir (rad) given, only the slip along (cos, sin)(slip_dir).
    S: scratch array with at least 7 rows and 12 columns.
    """
    side_old, slip_old = old
    side_new, slip_new = new
    V = S[_VROW]
    physical_velocity(y, p, side_old, 1 if slip_old else 0, V)
    with_slip = slip_new
    h = side_new * p[P_H]
    a = y[Y_ALPHA]
    s = math.sin(a)
    c = math.cos(a)
    along = with_slip and not math.isnan(slip_dir)
    nq = (4 if along else 5) if with_slip else 3
    for k in range(6):
        for j in range(5):
            S[k, j] = 0.0
    _set_metric(S, p)
    # columns: d V / d (w1, w2, w3, u1, u2) for the new contact
    S[0, 1] = 1.0
    S[0, 2] = -h
    S[1, 0] = -1.0
    S[2, 0] = h
    S[3, 0] = 1.0
    S[4, 1] = 1.0
    S[5, 2] = 1.0
    if along:
        cd = math.cos(slip_dir)
        sd = math.sin(slip_dir)
        S[0, 3] = cd
        S[1, 3] = sd * c
        S[2, 3] = -sd * s
    else:
        S[0, 3] = 1.0
        S[1, 4] = c
        S[2, 4] = -s
    loss = _least_change(S, nq)
    y[Y_W1] = S[0, _M0 + nq]
    y[Y_W2] = S[1, _M0 + nq]
    y[Y_W3] = S[2, _M0 + nq]
    if along:
        y[Y_U1] = S[3, _M0 + nq] * math.cos(slip_dir)
        y[Y_U2] = S[3, _M0 + nq] * math.sin(slip_dir)
    elif with_slip:
        y[Y_U1] = S[3, _M0 + nq]
        y[Y_U2] = S[4, _M0 + nq]
    else:
        y[Y_U1] = 0.0
        y[Y_U2] = 0.0
    return loss


@kernel
def stop_axis_rate(y, p, cs, i, S):
    """omega.a_i -> 0 where a moment component sticks at spin_tol (docs/model.md), in place.

    The least change of the velocity in the kinetic-energy metric that keeps the contact (rolling,
    or sliding with both slip components free) with omega.a_i = 0 and every stuck component at
    rest (omega.a_j = 0; they are held there up to round-off): an impulsive contact moment with
    the contact impulse that keeps the contact. The admissible velocities form a linear subspace,
    so the energy drops by exactly the returned loss (second order in omega.a_i). S: >= 7 x 12.
    """
    slides = cs[CS_MODE] != ROLL
    V = S[_VROW]
    physical_velocity(y, p, cs[CS_SIDE], 1 if slides else 0, V)
    h = cs[CS_SIDE] * p[P_H]
    s = math.sin(y[Y_ALPHA])
    c = math.cos(y[Y_ALPHA])
    _set_metric(S, p)
    for k in range(6):
        for j in range(5):
            S[k, j] = 0.0
    nq = 0
    for j in range(3):
        if j != i and cs[CS_STUCK + j] != 1.0:
            # a_1 = e1, a_2 = c e2 - s e3, a_3 = s e2 + c e3 on e-frame components
            a1 = 1.0 if j == 0 else 0.0
            a2 = 0.0 if j == 0 else (c if j == 1 else s)
            a3 = 0.0 if j == 0 else (-s if j == 1 else c)
            S[0, nq] = a2 - h * a3        # d V / d (omega.a_j) on this contact
            S[1, nq] = -a1
            S[2, nq] = h * a1
            S[3, nq] = a1
            S[4, nq] = a2
            S[5, nq] = a3
            nq += 1
    n_rot = nq
    if slides:
        S[0, nq] = 1.0
        S[1, nq + 1] = c
        S[2, nq + 1] = -s
        nq += 2
    loss = _least_change(S, nq)
    r0, r1, r2 = 0.0, 0.0, 0.0        # omega.a_j after the update
    q = 0
    for j in range(3):
        if j != i and cs[CS_STUCK + j] != 1.0:
            if j == 0:
                r0 = S[q, _M0 + nq]
            elif j == 1:
                r1 = S[q, _M0 + nq]
            else:
                r2 = S[q, _M0 + nq]
            q += 1
    y[Y_W1] = r0
    y[Y_W2] = c * r1 + s * r2
    y[Y_W3] = -s * r1 + c * r2
    if slides:
        y[Y_U1] = S[n_rot, _M0 + nq]
        y[Y_U2] = S[n_rot + 1, _M0 + nq]
    return loss
