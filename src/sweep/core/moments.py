"""The dry-friction moment components (eq. 3.3, Filippov): the stick test, the stop at spin_tol, and
the signs made consistent after a discrete update (spin_tol is p[P_WTOL]).

A free component sticks where omega.a_i reaches 0, or where it slows to spin_tol and its motion goes
on to rest, if the moment can hold it there (spin_sticks; |sigma needed| < 1); a stuck one is
released where |sigma needed| reaches 1.
"""
from __future__ import annotations

import math

from .constants import SLAVED
from .contact_rhs import eval_rhs, friction_along, slaved_slip
from .jit import kernel
from .layout import CS_MODE, CS_NU, CS_SIG, CS_STUCK, I_STICK, Eval, W_AUXTMP, W_DYTMP, W_SCRATCH
from .model import (P_K1, P_K2, P_K3, P_WTOL, X_DCROSS, X_G1, X_LAG, X_NU, X_SIG1, X_SLAVE_ERR, Y_U1, Y_U2,
                    moment_axes_rates, sign_rate)



# tau: the differences of d/dtau(omega.a_i) along the motion for its second and third derivatives
# (spin_rest_time): truncation O(SPIN_DIFF^2) and O(SPIN_DIFF), round-off EPS |g1| / SPIN_DIFF^2.
SPIN_DIFF = 1e-3


@kernel
def decision_rhs(i, t, y, sys, dy, aux):
    """The right-hand side on which a discrete decision at an event reads the moments (to dy, aux),
    with component i treated as stuck (i < 0: the contact state as it is; cs is left as it was).

    In a SLAVED slip the friction acts along the slip's direction at this instant: the slaved root
    continued from cs[CS_NU] for the contact state as it is. Where the secant finds no root there,
    the friction opposes the slip vector itself, as in SLIDE (a direction of the state; cs[CS_NU]
    was set at a step end, which the step size places). The root is not solved again for the
    hypothesis: holding omega.a_i changes the slip dynamics, and a root of those (if any:
    confirm_slaved looks for it after the update) is where the direction relaxes to, not where it
    is; a secant that fails there left its last iterate, a direction set by the iteration, to
    decide the stick (docs/model.md, 'The moment a decision reads in a slaved slip')."""
    cs = sys.cs
    slaved = cs[CS_MODE] == SLAVED
    root, lag, dcross, ok, err = cs[CS_NU], 0.0, 0.0, 1.0, 0.0
    if slaved:
        root, lag, dcross, ok, err = slaved_slip(root, Eval(t, y, sys, dy, aux))
        if ok == 0.0:
            root, lag = math.atan2(y[Y_U2], y[Y_U1]), 0.0
    was = cs[CS_STUCK + i] if i >= 0 else 0.0
    if i >= 0:
        cs[CS_STUCK + i] = 1.0
    if slaved:
        friction_along(root + lag, Eval(t, y, sys, dy, aux))
        # the slaved slip's own quantities, as eval_rhs leaves them (the event functions read them)
        aux[X_DCROSS] = dcross
        aux[X_NU] = root
        aux[X_LAG] = lag
        aux[X_SLAVE_ERR] = err
    else:
        eval_rhs(t, y, sys, dy, aux)
    if i >= 0:
        cs[CS_STUCK + i] = was


@kernel
def needed_sigma(i, t, y, sys, dy, aux):
    """sigma_i of the moment that holds omega.a_i where it is (component i treated as stuck; its
    contact state is left as it was; decision_rhs). The right-hand side goes to dy, aux."""
    decision_rhs(i, t, y, sys, dy, aux)
    return aux[X_SIG1 + i]


@kernel
def stick_or_flip(i, t, y, sys):
    """At omega.a_i = 0: stick if the moment can hold it (|sigma needed| <= 1), else flip its sign
    to the one the motion will take."""
    cs, wk, istats = sys.cs, sys.wk, sys.istats
    need = needed_sigma(i, t, y, sys, wk[W_DYTMP], wk[W_AUXTMP])
    if abs(need) < 1.0:
        cs[CS_STUCK + i] = 1.0
        istats[I_STICK] += 1
        return
    cs[CS_STUCK + i] = 0.0
    cs[CS_SIG + i] = 1.0 if need > 0.0 else -1.0


@kernel
def spin_rest_time(i, t, y, sys):
    """Free component i slowing through |omega.a_i| = spin_tol: the time s (tau) after t at which its
    motion reaches rest, omega.a_i = 0, NaN where it turns back above 0 instead (docs/model.md,
    'Sticking at spin_tol'). Read from the state: g = sigma_i omega.a_i and its first three
    derivatives along the motion, g1 exact from the right-hand side, g2 and g3 by differences of g1
    at the trajectory points tau +- SPIN_DIFF (second-order Taylor steps of the state); the cubic
    g + g1 s + g2 s^2/2 + g3 s^3/6 reaches 0 before its first minimum, or not (cubic_rest_time).
    Leaves the right-hand side at y and at y +- SPIN_DIFF f in wk[W_SCRATCH:W_SCRATCH + 3] (for
    spin_sticks); uses wk[W_SCRATCH:W_SCRATCH + 6]."""
    cs, n, wk = sys.cs, sys.n, sys.wk
    f0 = wk[W_SCRATCH]
    fp = wk[W_SCRATCH + 1]
    fm = wk[W_SCRATCH + 2]
    ys = wk[W_SCRATCH + 3]
    dys = wk[W_SCRATCH + 4]
    auxs = wk[W_SCRATCH + 5]
    sig = cs[CS_SIG + i]
    d = SPIN_DIFF
    eval_rhs(t, y, sys, f0, auxs)
    g = sig * moment_axes_rates(y)[i]
    g1 = sig * sign_rate(i, y, f0)
    if not g1 < 0.0:
        return math.nan
    for j in range(n):
        ys[j] = y[j] + d * f0[j]
    eval_rhs(t + d, ys, sys, fp, auxs)
    for j in range(n):
        ys[j] = y[j] - d * f0[j]
    eval_rhs(t - d, ys, sys, fm, auxs)
    # the motion at tau +- d to O(d^3): y +- d f + d^2/2 f', f' by the central difference
    for j in range(n):
        ys[j] = y[j] + d * f0[j] + 0.25 * d * (fp[j] - fm[j])
    eval_rhs(t + d, ys, sys, dys, auxs)
    up = sig * sign_rate(i, ys, dys)
    for j in range(n):
        ys[j] = y[j] - d * f0[j] + 0.25 * d * (fp[j] - fm[j])
    eval_rhs(t - d, ys, sys, dys, auxs)
    down = sig * sign_rate(i, ys, dys)
    g2 = (up - down) / (2.0 * d)
    g3 = (up - 2.0 * g1 + down) / (d * d)
    return cubic_rest_time(g, g1, g2, g3)


@kernel
def spin_sticks(i, t, y, sys):
    """Would free component i, slowing through |omega.a_i| = spin_tol at t, stick: does its motion
    reach rest (spin_rest_time: s later), and can the moment hold it there (|sigma needed| < 1 at
    the state at t + s, y + s f + s^2/2 f', the stick test of stick_or_flip where the exact
    Filippov rule makes it)? A hold that is lost between spin_tol and rest is not taken for one."""
    n, wk = sys.n, sys.wk
    s = spin_rest_time(i, t, y, sys)
    if math.isnan(s):
        return False
    f0 = wk[W_SCRATCH]
    fp = wk[W_SCRATCH + 1]
    fm = wk[W_SCRATCH + 2]
    ys = wk[W_SCRATCH + 3]
    c = 0.25 * s * s / SPIN_DIFF
    for j in range(n):
        ys[j] = y[j] + s * f0[j] + c * (fp[j] - fm[j])
    return abs(needed_sigma(i, t + s, ys, sys, wk[W_SCRATCH + 4], wk[W_SCRATCH + 5])) < 1.0


@kernel
def cubic_rest_time(g, g1, g2, g3):
    """The first s > 0 at which c(s) = g + g1 s + g2 s^2/2 + g3 s^3/6, with g > 0 and g1 < 0, reaches
    0 before its first local minimum there (the first root of c'(s) = g1 + g2 s + g3 s^2/2 where
    c'' > 0; without one, c falls for ever), NaN where the minimum lies above 0. c falls on [0, s]:
    bisection."""
    a = 0.5 * g3
    s_min = math.inf
    if a == 0.0:
        if g2 > 0.0:
            s_min = -g1 / g2
    else:
        disc = g2 * g2 - 4.0 * a * g1
        if disc >= 0.0:
            r = math.sqrt(disc)
            # the roots of a s^2 + g2 s + g1, written without cancellation
            q = -0.5 * (g2 + (r if g2 >= 0.0 else -r))
            if q != 0.0:
                for x in (q / a, g1 / q):
                    if 0.0 < x < s_min and g2 + 2.0 * a * x > 0.0:
                        s_min = x
    if s_min < math.inf:
        if g + s_min * (g1 + s_min * (0.5 * g2 + s_min * g3 / 6.0)) > 0.0:
            return math.nan
        hi = s_min
    else:
        hi = -g / g1
        for _ in range(200):
            if g + hi * (g1 + hi * (0.5 * g2 + hi * g3 / 6.0)) <= 0.0:
                break
            hi *= 2.0
    lo = 0.0
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if mid <= lo or mid >= hi:
            break
        if g + mid * (g1 + mid * (0.5 * g2 + mid * g3 / 6.0)) > 0.0:
            lo = mid
        else:
            hi = mid
    return hi


@kernel
def cubic_reaches_zero(g, g1, g2, g3):
    """Does c(s) = g + g1 s + g2 s^2/2 + g3 s^3/6, with g > 0 and g1 < 0, reach 0 at some s > 0 before
    its first local minimum there (cubic_rest_time)?"""
    return not math.isnan(cubic_rest_time(g, g1, g2, g3))


@kernel
def release_moved(y, p, cs, g_before):
    """Moment components whose omega.a_i an impulse has moved. A stuck one moved off its held value
    by more than spin_tol is free: the dry-friction moment is finite and cannot hold it through an
    impulse (sign of the new omega.a_i; an exact 0 is left to settle_signs' stick test). A move
    within spin_tol leaves it at rest, as a free component that slows to spin_tol is taken to stop:
    an impulse that hardly turns it (the O(u^2) one of a slaved hand-over moves it by ~1e-16, its
    round-off) must not release it only to have it stick again at once. A free one carried past its
    switching surface by more than spin_tol spins the other way at a finite rate: its moment takes
    the new sign (a stick test there would hold a spinning component); one left within spin_tol of
    the surface is at rest and gets settle_signs' stick test."""
    g = moment_axes_rates(y)
    for i in range(3):
        if g[i] == g_before[i]:
            continue
        if cs[CS_STUCK + i] == 1.0 and abs(g[i] - g_before[i]) > p[P_WTOL]:
            cs[CS_STUCK + i] = 0.0
            if g[i] != 0.0:
                cs[CS_SIG + i] = 1.0 if g[i] > 0.0 else -1.0
        elif cs[CS_STUCK + i] == 0.0 and cs[CS_SIG + i] * g[i] < 0.0 and abs(g[i]) > p[P_WTOL]:
            cs[CS_SIG + i] = 1.0 if g[i] > 0.0 else -1.0


@kernel
def settle_signs(t, y, sys, own):
    """After a discrete update, every moment component is made consistent with the new state.

    A stuck component whose holding moment now exceeds the limit (|sigma needed| > 1: the update
    changed the dynamics, e.g. rolling resumed after a slip) is released in the direction of the
    needed moment: its un-stick event, |sigma| rising to 1, can no longer happen. A free component
    whose sign function sigma_i (omega.a_i) is <= 0 has reached its switching surface at this same
    event (two components of a spin-free rocking disk pass omega.a_i = 0 together) and gets the
    stick test now, since its own event, g going from > 0 to <= 0, can no longer happen. `own` is
    the component this event put on its surface (-1: none), left to its own rule: held there by
    the Filippov rule, or just released at an un-stick (leaving it: the next step looks for its
    lift-off). Every component is looked at until none changes: a test that changes nothing does
    not stop the others' (three components, so a few passes).
    """
    p, cs, wk = sys.p, sys.cs, sys.wk
    k = (p[P_K1], p[P_K2], p[P_K3])
    for _ in range(6):
        decision_rhs(-1, t, y, sys, wk[W_DYTMP], wk[W_AUXTMP])
        found = -1
        for i in range(3):
            if found < 0 and k[i] > 0.0 and cs[CS_STUCK + i] == 1.0 and i != own \
                    and abs(wk[W_AUXTMP, X_SIG1 + i]) > 1.0:
                found = i
        if found >= 0:
            cs[CS_STUCK + found] = 0.0
            cs[CS_SIG + found] = 1.0 if wk[W_AUXTMP, X_SIG1 + found] > 0.0 else -1.0
            continue
        g = moment_axes_rates(y)
        for i in range(3):
            if found < 0 and k[i] > 0.0 and cs[CS_STUCK + i] == 0.0 and i != own \
                    and cs[CS_SIG + i] * g[i] <= 0.0:
                sig_before = cs[CS_SIG + i]
                stick_or_flip(i, t, y, sys)
                if cs[CS_STUCK + i] == 1.0 or cs[CS_SIG + i] != sig_before:
                    found = i
        if found < 0:
            return


@kernel
def consistent_signs(t, y, sys):
    """Every free moment sign agrees with omega.a_i; an exact zero gets the stick test."""
    p, cs, wk = sys.p, sys.cs, sys.wk
    eval_rhs(t, y, sys, wk[W_DYTMP], wk[W_AUXTMP])
    k = (p[P_K1], p[P_K2], p[P_K3])
    for i in range(3):
        if k[i] > 0.0 and cs[CS_STUCK + i] == 0.0:
            g = wk[W_AUXTMP, X_G1 + i]
            if g > 0.0:
                cs[CS_SIG + i] = 1.0
            elif g < 0.0:
                cs[CS_SIG + i] = -1.0
            else:
                stick_or_flip(i, t, y, sys)
