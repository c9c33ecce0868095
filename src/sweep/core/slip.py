"""The contact's slip: its onset from rolling, the hand-over between SLIDE and SLAVED, and its fate.
Every decision reads the state and physical parameters only (slip_tol is p[P_UTOL]).

A slip starts where rolling leaves the static cone (start_slip, onto the onset direction). A SLIDE
is handed over to SLAVED where |u| falls to the slaving speed onto the attracting quasi-static
direction (try_slave, settle_onto). A SLIDE not handed over (a slip spiralling into u = 0, or
passing by it) meets its fate where |u| falls to slip_tol (slip_fate, slow_slide; docs/model.md,
'Where a slip ends'): where its direction dynamics carry it to u = 0 along nu* it settles onto nu*
and ends as a slaved slip at u.s = 0 (a located event); a slip that spirals out slides on;
otherwise it is followed below slip_tol, its fate read again 16 times slower, until it settles, or,
at the round-off floor, it ends or passes through u = 0 by an impulse of O(floor). No decision, and
no event before it, depends on slip_tol.
"""
from __future__ import annotations

import math

from .. import outcomes as oc
from .constants import AT_FLOOR, BELOW, HANDOVER_ARMED, HANDOVER_OFF, ROLL, SLAVED, SLIDE, SLOW_OFF
from .contact_rhs import (SLAVE_FLOOR, eval_rhs, model_call, root_lag, second_order, second_order_applies, slave_speed,
                          slaved_direction, slip_floor, slip_rates, slip_roundoff)
from .impulse import project_velocity
from .jit import kernel
from .layout import (CS_FLOOR, CS_MODE, CS_NU, CS_SIDE, CS_SLAVE_OFF, Eval, W_AUXSLOPE, W_AUXTMP, W_DYSLOPE, W_DYTMP,
                     W_SCRATCH, W_YSLIP)
from .model import P_MUD, P_MUS, P_SLAVE, P_UTOL, X_F1, X_F2, X_OK, X_PHI, Y_DSLIDE, Y_U1, Y_U2


# a slide followed BELOW slip_tol (constants.BELOW) has its fate read again BELOW_STEP times slower
# each time
BELOW_STEP = 16.0


# settle_onto's answers
SETTLED, AGAINST, INACCURATE = 0, 1, 2


# attracting_direction's answer where the slip direction is carried into the Painleve singularity
JAMMED = math.inf


# What a slide whose speed has fallen to slip_tol does next (slip_fate): it reaches u = 0 and ends,
# it passes by u = 0 and leaves along a direction of growth, it spirals out from u = 0, or the
# direction dynamics carry it into the Painleve singularity.
FATE_ENDS, FATE_PASSES, FATE_SPIRALS_OUT, FATE_JAMMED = 0, 1, 2, 3


# Points on the circle for the slip's change of ln|u| over one turn of a spiral (a periodic
# integrand: the trapezoidal rule converges geometrically).
SPIRAL_POINTS = 64


# Golden-section iterations of dip_crosses: the minimum located to 0.618^48 ~ 1e-10 of its bracket
DIP_ITERATIONS = 48


@kernel
def cone_violated(t, y, sys):
    """Rolling: the friction needed lies outside the static cone |F| <= mu_s Phi."""
    p, wk = sys.p, sys.wk
    eval_rhs(t, y, sys, wk[W_DYTMP], wk[W_AUXTMP])
    aux = wk[W_AUXTMP]
    return aux[X_PHI] > 0.0 and p[P_MUS] * aux[X_PHI] < math.hypot(aux[X_F1], aux[X_F2])


@kernel
def onset_direction(t, y, sys, F1, F2):
    """Slip direction at the onset of sliding (u = 0), consistent with the sliding that follows.

    The direction s must be one along which the slip then grows: slip acceleration parallel to s
    with a positive component along it. The paper's rule s = -F/|F| (section 6.2) is exact only for
    an isotropic contact inverse inertia; it is the initial guess. The cross product is scanned on 64
    angles for sign changes, each is bisected, and of the roots with a growing slip the one nearest
    the guess is taken among those where the sliding contact law has a solution (the model's flag
    1), else among those where it has none (flag -1 on both sides: the scene ends as `painleve`
    there), else the guess itself. A sign change whose final bracket has flag 1 on one side and -1
    on the other is no root but a pole: across a Painleve boundary (Phi's coefficient through 0,
    model.tilt_balance) the accelerations pass through infinity (a bisection once landed on the
    pole itself: docs/model.md, 'Roll -> slip').
    """
    wk = sys.wk
    dy = wk[W_DYTMP]
    aux = wk[W_AUXTMP]
    ys = wk[W_YSLIP]
    ev = Eval(t, y, sys, dy, aux)
    guess = math.atan2(-F2, -F1)
    best = guess
    bestd = 1e300    # the nearest root with a solution
    best_none = guess
    bestd_none = 1e300   # ... and without one
    m = 64
    xa = guess - math.pi
    ca, _ = slip_rates(xa, 0.0, ev, ys)
    oka = aux[X_OK]
    for j in range(1, m + 1):
        xb = guess - math.pi + 2.0 * math.pi * j / m
        cb, _ = slip_rates(xb, 0.0, ev, ys)
        okb = aux[X_OK]
        if (ca > 0.0) != (cb > 0.0):
            lo, hi, clo, oklo, okhi = xa, xb, ca, oka, okb
            for _ in range(60):
                mid = 0.5 * (lo + hi)
                cm, _ = slip_rates(mid, 0.0, ev, ys)
                if (cm > 0.0) == (clo > 0.0):
                    lo, clo, oklo = mid, cm, aux[X_OK]
                else:
                    hi, okhi = mid, aux[X_OK]
                if hi - lo < 1e-13:
                    break
            root = 0.5 * (lo + hi)
            _, dr = slip_rates(root, 0.0, ev, ys)
            dist = abs(math.atan2(math.sin(root - guess), math.cos(root - guess)))
            if dr > 0.0 and (oklo > 0.0) == (okhi > 0.0):
                if oklo > 0.0 and dist < bestd:
                    best, bestd = root, dist
                elif oklo < 0.0 and dist < bestd_none:
                    best_none, bestd_none = root, dist
        xa, ca, oka = xb, cb, okb
    return best if bestd < 1e300 else best_none


@kernel
def start_slip(t, y, sys):
    """ROLL -> SLAVED at zero slip speed, in the onset direction."""
    cs, wk = sys.cs, sys.wk
    model_call(Eval(t, y, sys, wk[W_DYTMP], wk[W_AUXTMP]), 1.0, 0.0)
    F1 = wk[W_AUXTMP, X_F1]
    F2 = wk[W_AUXTMP, X_F2]
    cs[CS_MODE] = SLAVED
    cs[CS_NU] = onset_direction(t, y, sys, F1, F2)
    y[Y_U1] = 0.0
    y[Y_U2] = 0.0


@kernel
def set_slip(t, y, sys):
    """Contact state for a Cartesian slip vector y[U1:U3]: SLIDE above the slaving speed (or where
    no quasi-static direction is near), else SLAVED with the quasi-static direction nearest the
    slip's own. Returns the outcome that ends the scene (try_slave), else -1."""
    p, cs, wk = sys.p, sys.cs, sys.wk
    un = math.hypot(y[Y_U1], y[Y_U2])
    nu = math.atan2(y[Y_U2], y[Y_U1])
    if un > p[P_UTOL]:
        cs[CS_MODE] = SLIDE
        cs[CS_NU] = nu
        cs[CS_SLAVE_OFF] = HANDOVER_ARMED
        model_call(Eval(t, y, sys, wk[W_DYTMP], wk[W_AUXTMP]), 1.0, 0.0)
        if un <= slave_speed(y, wk[W_AUXTMP], p):
            return try_slave(t, y, sys)
        return -1
    cs[CS_MODE] = SLAVED
    cs[CS_NU] = slaved_direction(nu, un, Eval(t, y, sys, wk[W_DYTMP], wk[W_AUXTMP]), wk[W_YSLIP])
    return -1


@kernel
def attracting_direction(nu, u, t, y, sys):
    """The quasi-static slip direction that the direction dynamics d nu/d tau = cross(nu)/u carry nu
    to: followed from nu in the direction of sign(cross) to the first sign change (64 steps on the
    circle; where |cross| has a local minimum among the steps, its minimum between the neighbouring
    steps is found (dip_crosses), so a pair of roots closer than a step is not stepped over), then
    bisected to 1e-13 rad. NaN if cross keeps its sign on the whole circle (the slip spirals into
    u = 0); JAMMED (inf) if what stops it is not a root of cross but the Painleve
    singularity, where the e1 balance's coefficient of Phi falls to 0 and Phi grows without bound
    (cross changes sign through a pole; beyond it the contact law has no solution)."""
    wk = sys.wk
    dy = wk[W_DYTMP]
    aux = wk[W_AUXTMP]
    ys = wk[W_YSLIP]
    ev = Eval(t, y, sys, dy, aux)
    ca, da = slip_rates(nu, u, ev, ys)
    if aux[X_OK] < 0.0:
        return JAMMED
    if ca == 0.0:
        return nu
    sense = 1.0 if ca > 0.0 else -1.0
    step = (2.0 * math.pi / 64) * sense
    x_prev, c_prev = nu, math.inf     # the step before xa (none before nu)
    xa = nu
    for j in range(1, 65):
        xb = nu + j * step
        cb, db = slip_rates(xb, u, ev, ys)
        crossed = (cb > 0.0) != (ca > 0.0) or aux[X_OK] < 0.0
        lo, hi = xa, xb
        if not crossed and abs(ca) < c_prev and abs(ca) <= abs(cb):
            # |cross| dips at xa: a root pair may lie between the neighbouring steps
            x_min = dip_crosses(x_prev if c_prev < math.inf else xa, xb, sense, u, ev)
            if not math.isnan(x_min):
                crossed = True
                lo, hi = (x_prev if c_prev < math.inf else xa), x_min
        if crossed:
            for _ in range(60):
                mid = 0.5 * (lo + hi)
                cm, dm = slip_rates(mid, u, ev, ys)
                if (cm > 0.0) == (sense > 0.0) and aux[X_OK] >= 0.0:
                    lo = mid
                else:
                    hi = mid
                if abs(hi - lo) < 1e-13:
                    break
            slip_rates(hi, u, ev, ys)
            if aux[X_OK] < 0.0:
                return JAMMED
            return 0.5 * (lo + hi)
        x_prev, c_prev = xa, abs(ca)
        xa, ca = xb, cb
    return math.nan


@kernel
def dip_crosses(lo, hi, sense, u, ev):
    """Where sense x cross has its minimum on [lo, hi] (golden section), if it is <= 0 there or the
    contact law has no solution (a root pair, or the Painleve pole, between two scan steps of
    attracting_direction whose cross has the sign sense): that point, else NaN. ev (layout.Eval):
    the state the trial slips of speed u are evaluated at, and where they leave the right-hand side."""
    aux, ys = ev.aux, ev.sys.wk[W_YSLIP]
    g = 0.5 * (math.sqrt(5.0) - 1.0)
    x1 = hi - g * (hi - lo)
    x2 = lo + g * (hi - lo)
    f1, _ = slip_rates(x1, u, ev, ys)
    if aux[X_OK] < 0.0 or sense * f1 <= 0.0:
        return x1
    f2, _ = slip_rates(x2, u, ev, ys)
    if aux[X_OK] < 0.0 or sense * f2 <= 0.0:
        return x2
    for _ in range(DIP_ITERATIONS):
        if sense * f1 < sense * f2:
            hi, x2, f2 = x2, x1, f1
            x1 = hi - g * (hi - lo)
            f1, _ = slip_rates(x1, u, ev, ys)
            if aux[X_OK] < 0.0 or sense * f1 <= 0.0:
                return x1
        else:
            lo, x1, f1 = x1, x2, f2
            x2 = lo + g * (hi - lo)
            f2, _ = slip_rates(x2, u, ev, ys)
            if aux[X_OK] < 0.0 or sense * f2 <= 0.0:
                return x2
    return math.nan


@kernel
def try_slave(t, y, sys):
    """SLIDE -> SLAVED onto the attracting quasi-static direction of the slip; where there is none
    (a spiralling slip), or where the slip points against it (a slip passing by u = 0), it stays in
    SLIDE, and this hand-over is off until the slip is fast again (EV_SLIP_FAST re-arms it).
    Returns the outcome that ends the scene (PAINLEVE where the direction dynamics carry the slip
    into the Painleve singularity: see attracting_direction; above the floor's speed with slave_tol
    > 0 that is decided at the floor's, AT_FLOOR), else -1."""
    p, cs, wk = sys.p, sys.cs, sys.wk
    u = math.hypot(y[Y_U1], y[Y_U2])
    # the hand-over at the floor's speed (a slide refused above it) takes the slip whatever the
    # slaved direction's error there
    at_floor = cs[CS_SLAVE_OFF] == AT_FLOOR
    root = attracting_direction(math.atan2(y[Y_U2], y[Y_U1]), u, t, y, sys)
    if root == JAMMED:
        # (the normal force at the state, in scratch rows: attracting_direction's are left as they are)
        eval_rhs(t, y, sys, wk[W_DYSLOPE], wk[W_AUXSLOPE])
        if p[P_SLAVE] > 0.0 and not at_floor and u > SLAVE_FLOOR * p[P_MUD] * wk[W_AUXSLOPE, X_PHI]:
            # decided where the direction's relaxation is as fast as at slave_tol 0: at the floor
            cs[CS_SLAVE_OFF] = AT_FLOOR
            return -1
        return oc.PAINLEVE
    if math.isnan(root):
        cs[CS_SLAVE_OFF] = HANDOVER_OFF
        return -1
    # where the slip points against the direction, it is not settling onto it but passing by u = 0
    # (its direction turning towards a root along which it grows): it goes on sliding, as the
    # sliding equations carry it, past u = 0 or to slip_tol (docs/model.md)
    settled = settle_onto(root, t, y, sys, not at_floor)
    if settled == AGAINST:
        cs[CS_SLAVE_OFF] = HANDOVER_OFF
    elif settled == INACCURATE:
        cs[CS_SLAVE_OFF] = AT_FLOOR
    return -1


@kernel
def settle_onto(root, t, y, sys, strict):
    """SLIDE -> SLAVED at the quasi-static direction root: the slip component across the slow
    manifold's direction there (root plus the lag, root_lag) is removed by a plastic impulse
    (O(u^2) loss), if that leaves the slip along it and, strict (the hand-over at the slaving
    speed above the floor's), the slaved direction's error there is within slave_tol (slaved_slip)
    and the slip's own direction within slave_tol rad of it (relaxed onto it); else the state is
    left as it was. Returns SETTLED, AGAINST or INACCURATE."""
    p, cs, n, wk = sys.p, sys.cs, sys.n, sys.wk
    side = int(cs[CS_SIDE])
    u = math.hypot(y[Y_U1], y[Y_U2])
    ev = Eval(t, y, sys, wk[W_DYTMP], wk[W_AUXTMP])
    lag, dcross, err = root_lag(root, u, ev)
    if second_order_applies(lag, err, p):
        lag, err = second_order(root, lag, dcross, err, ev)
    along = root + lag
    if strict and p[P_SLAVE] > 0.0 and u > SLAVE_FLOOR * p[P_MUD] * wk[W_AUXTMP, X_PHI]:
        # the slow manifold is no good approximation here, or the slip's direction has yet to
        # relax onto it (the impulse would cut its transient short, an error first order in the
        # relaxation time): the slip slides on
        turn = math.atan2(y[Y_U2], y[Y_U1]) - along
        turn = abs(math.atan2(math.sin(turn), math.cos(turn)))
        if not (err <= p[P_SLAVE] and turn <= p[P_SLAVE] * p[P_SLAVE]):
            return INACCURATE
    saved = wk[W_YSLIP]
    for i in range(n):
        saved[i] = y[i]
    loss = project_velocity(y, p, (side, True), (side, True), wk[W_SCRATCH:W_SCRATCH + 7], along)
    if y[Y_U1] * math.cos(along) + y[Y_U2] * math.sin(along) > 0.0:
        y[Y_DSLIDE] += loss
        cs[CS_MODE] = SLAVED
        cs[CS_NU] = root
        return SETTLED
    for i in range(n):
        y[i] = saved[i]
    return AGAINST


@kernel
def slip_fate(t, y, sys):
    """Where a slide goes from a slow slip, decided by the slip's direction dynamics at the state
    (docs/model.md, 'Where a slip ends'): (fate, nu), fate one of FATE_*, nu the root nu* that the
    direction reaches (the one along which a passing slip leaves u = 0, or an ending slip arrives),
    NaN for a spiral.

    Near u = 0 the slip acceleration a_P depends on the slip's direction s(nu) and hardly on its
    size, so along the slide d nu/d ln|u| = cross(nu)/rad(nu) (cross, rad: a_P across and along s).
    The direction therefore moves monotonically, in the sense of sign(cross), to the first root nu*
    of cross (attracting_direction), whatever |u| does on the way, and the slip's fate is the sign
    of rad(nu*): < 0, |u| falls to 0 in finite time along nu* (the slip ends: the model's rolling or
    a new onset follows); > 0, |u| has a minimum on the way and grows along nu* (the slip passes by
    u = 0 and never reaches it). Where cross has no root, the direction turns for ever and
    ln|u| changes by the integral of rad/|cross| over each turn: < 0, the slip spirals into u = 0
    in finite time (it ends); > 0, it spirals out. None of this reads slip_tol: the fate is the same
    from every slower slip of the same slide, to the slip's own O(|u|) change of the state."""
    wk = sys.wk
    dy = wk[W_DYTMP]
    aux = wk[W_AUXTMP]
    ys = wk[W_YSLIP]
    ev = Eval(t, y, sys, dy, aux)
    u = math.hypot(y[Y_U1], y[Y_U2])
    root = attracting_direction(math.atan2(y[Y_U2], y[Y_U1]), u, t, y, sys)
    if root == JAMMED:
        return FATE_JAMMED, math.nan
    if not math.isnan(root):
        _, rad = slip_rates(root, u, ev, ys)
        if rad > 0.0:
            return FATE_PASSES, root
        return FATE_ENDS, root
    turn = 0.0
    for j in range(SPIRAL_POINTS):
        cross, rad = slip_rates(2.0 * math.pi * j / SPIRAL_POINTS, u, ev, ys)
        turn += rad / abs(cross)
    if turn > 0.0:
        return FATE_SPIRALS_OUT, math.nan
    return FATE_ENDS, math.nan


@kernel
def slow_slide(t, y, sys):
    """A slide whose speed has reached its floor (slip_floor: slip_tol, or cs[CS_FLOOR] below it;
    EV_SLIP_SLOW, or a discrete update that left it there), by its fate (slip_fate). One that ends
    along a direction nu* settles onto it (settle_onto: the O(u^2) impulse of the hand-over) and
    ends as a slaved slip where u.s(nu*) reaches 0, a located event. Otherwise, an ending slip whose
    direction has yet to turn to nu*, a slip that spirals in, or one that passes by u = 0 is
    followed below: it slides on (BELOW), its fate read again BELOW_STEP times slower, so that the
    events of its last approach to u = 0 happen as in the limit slip_tol -> 0. At the round-off
    floor (slip_roundoff) an ending slip is ended by the plastic contact impulse (end_slip), and a
    passing one goes through u = 0: the same impulse removes what is left of the slip and a slaved
    slip leaves from u = 0 along its direction of growth (no transition: it never rolls). A slip
    that spirals out slides on, and this event is off until the slip is fast again. Neither the
    decisions nor the events before them move with slip_tol; an impulse at the floor changes the
    velocity by O(floor). Returns the outcome that ends the scene (PAINLEVE), else -1."""
    p, cs, wk = sys.p, sys.cs, sys.wk
    fate, nu = slip_fate(t, y, sys)
    if fate == FATE_JAMMED:
        return oc.PAINLEVE
    if fate == FATE_SPIRALS_OUT:
        cs[CS_SLAVE_OFF] = SLOW_OFF
        return -1
    if fate == FATE_ENDS and not math.isnan(nu) and settle_onto(nu, t, y, sys, False) == SETTLED:
        cs[CS_SLAVE_OFF] = HANDOVER_ARMED
        return -1
    eval_rhs(t, y, sys, wk[W_DYTMP], wk[W_AUXTMP])
    floor = min(slip_floor(t, wk[W_AUXTMP], p, cs), math.hypot(y[Y_U1], y[Y_U2])) / BELOW_STEP
    if floor > slip_roundoff(t, wk[W_AUXTMP], p):
        cs[CS_SLAVE_OFF] = BELOW
        cs[CS_FLOOR] = floor
        return -1
    if fate == FATE_ENDS:
        end_slip(y, sys)
        return -1
    side = int(cs[CS_SIDE])
    y[Y_DSLIDE] += project_velocity(y, p, (side, True), (side, False), wk[W_SCRATCH:W_SCRATCH + 7])
    y[Y_U1] = 0.0
    y[Y_U2] = 0.0
    cs[CS_MODE] = SLAVED
    cs[CS_NU] = nu
    cs[CS_SLAVE_OFF] = HANDOVER_ARMED
    return -1


@kernel
def end_slip(y, sys):
    """SLIDE -> ROLL: a plastic contact impulse removes the slip (its energy goes to sliding); for
    a slip that ends at the round-off floor or spirals in (slow_slide)."""
    p, cs, wk = sys.p, sys.cs, sys.wk
    side = int(cs[CS_SIDE])
    y[Y_DSLIDE] += project_velocity(y, p, (side, True), (side, False), wk[W_SCRATCH:W_SCRATCH + 7])
    cs[CS_MODE] = ROLL


@kernel
def confirm_slaved(t, y, sys):
    """SLAVED after a discrete update (integrate.run calls it after every event): the slaved
    direction of the contact state the update left.

    A moment component that the update stuck or released (an impulse moves a held omega.a_i; a
    sign flips) changes the slip dynamics, so the direction found before it (the hand-over's
    attracting root, the onset direction, the continued one) may no longer be a root: it is
    continued for the new state, else the attracting root is looked for from it; where the slip has
    none (it spirals), it is integrated in SLIDE and the hand-over stays off until it is fast
    again. Without this, the slaved right-hand side had no root near the restart and every step
    failed (step_size_underflow). Returns the outcome that ends the scene (PAINLEVE, see
    attracting_direction), else -1.
    """
    cs, wk = sys.cs, sys.wk
    u = math.hypot(y[Y_U1], y[Y_U2])
    nu = slaved_direction(cs[CS_NU], u, Eval(t, y, sys, wk[W_DYTMP], wk[W_AUXTMP]), wk[W_YSLIP])
    if wk[W_AUXTMP, X_OK] != 0.0:
        cs[CS_NU] = nu
        return -1
    root = attracting_direction(cs[CS_NU], u, t, y, sys)
    if root == JAMMED:
        return oc.PAINLEVE
    if math.isnan(root):
        cs[CS_MODE] = SLIDE
        cs[CS_SLAVE_OFF] = HANDOVER_OFF
        return -1
    cs[CS_NU] = root
    return -1
