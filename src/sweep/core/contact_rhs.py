"""The contact's right-hand side per contact state (constants.ROLL, SLIDE, SLAVED), and the slip speeds
that bound the modes. The kernels take the system they evaluate as one group, `sys` (layout.System:
parameters, contact state, state size, work buffer, counters); slip_tol is p[P_UTOL].

Modes (docs/model.md, 'Modes, signs and sticking'):
  ROLL    no slip; friction is what rolling needs, inside the static cone |F| <= mu_s Phi.
  SLIDE   friction -mu_d Phi u/|u| (eq. 4.7), the slip integrated in Cartesian form.
  SLAVED  a slow slip, |u| <= the slaving speed u_s (slave_speed: slave_tol mu_d Phi / (1 + |theta'|)): its direction
          is not integrated but solved at every evaluation as the slow manifold of the direction
          dynamics (the direction rate, ~ mu_d Phi / u, is the stiff mode of the sliding equations
          at u -> 0): the quasi-static direction nu*, where the slip acceleration is parallel to the
          slip, plus the lag behind it, first order in the relaxation time (slaved_slip). Entered at a slip onset (u = 0) and from SLIDE where
          |u| falls to u_s onto the attracting quasi-static direction, if there is one (slip.try_slave);
          it hands over to SLIDE where u grows past SLAVE_EXIT u_s or the direction folds away, and
          ends in ROLL where u.s returns to 0 (located events; the velocity is continuous).
"""
from __future__ import annotations

import math

from .constants import BELOW, EPS, ROLL, SLAVED, SLIDE
from .jit import kernel
from .layout import (CS_FLOOR, CS_MODE, CS_NU, CS_SIDE, CS_SIG, CS_SLAVE_OFF, CS_STUCK, I_RHS, Eval, System, W_AUXDRIFT,
                     W_AUXFLOW, W_AUXSLOPE, W_DYDRIFT, W_DYFLOW, W_DYSLOPE, W_PFRICTION, W_YDRIFT, W_YFLOW, W_YSLIP)
from .model import (Contact, N_PARAMS, P_A, P_MUD, P_SLAVE, P_UTOL, X_COSA, X_DCROSS, X_LAG, X_NU, X_OK, X_PHI, X_SINA,
                    X_SLAVE_ERR, Y_ALPHA, Y_U1, Y_U2, Y_W3, energy_from_trig, rhs)



# The slip direction is slaved at least where its relaxation time |u|/(mu_d Phi) is below SLAVE_FLOOR
# (units of chi), whatever slave_tol: near flat the motion's rate 1 + |theta'| grows without bound
# and slave_tol / rate alone left creeping slips to be integrated down to slip_tol, ~1/|u| steps
# each (a harness scene ran into step_limit at slip_tol 1e-13 m/s). The slaved direction's error
# there is second order in SLAVE_FLOOR (docs/model.md, 'Slow slip').
SLAVE_FLOOR = 1e-7


# A slaved slip returns to SLIDE only where it has grown to SLAVE_EXIT times the slaving speed: the
# two modes' boundaries differ, so a slip near the slaving speed cannot switch at every step. The
# slaved direction's error grows as the square of the relaxation time (docs/model.md, 'Slow slip'):
# at 4 times the slaving speed slips that never left SLAVED carried 30 times the error of those at 2.
SLAVE_EXIT = 2.0


# ... and in the floor's region (SLAVE_FLOOR) where it has grown to FLOOR_EXIT times its speed, as
# before slave_tol existed: exiting there at twice the speed cost 29 % more steps in the paper's
# disk at mu_d = mu_s
FLOOR_EXIT = 4.0


# A passage by u = 0 is resolved in time where it takes at least this many ulps of tau (slip_floor).
SLIP_RESOLUTION = 256.0


# Secant iterations of the slaved direction: converged when the angle update is below DIR_TOL rad.
DIR_TOL = 1e-14


# ... or when cross is at its round-off floor: |cross| <= DIR_NOISE (1 + |slip acceleration|). cross
# sums terms as large as gravity's (1 in these units) whatever the slip acceleration they leave: at
# mu_d ~ 1e-3 it is ~1e-3 and the iterates jitter by eps/|d cross/d nu| ~ 1e-13 rad about the root,
# never within DIR_TOL of each other. Near a fold (d cross/d nu small) the secant can stall there, two
# iterates giving the same rounded cross, before its angle update gets below DIR_TOL: the root is
# then found to machine precision, not lost.
DIR_NOISE = 64.0 * EPS


DCROSS_DNU = 1e-7   # rad: forward-difference step of d cross/d nu


# tau x (1 + |theta'|): central-difference step of d cross/d tau along the motion at a fixed
# direction (the lag): truncation O(FLOW_DTAU^2) relative, round-off ~EPS |a_P| / FLOW_DTAU; the
# second order differences the lag again over DRIFT_DTAU, which takes that round-off times
# 1 / DRIFT_DTAU
FLOW_DTAU = 1e-5
# tau x (1 + |theta'|): the step along the slaved motion over which the first-order manifold's
# direction is differenced (second_order_lag): truncation O(DRIFT_DTAU) relative in a second-order
# term (smooth: part of the slaved model's error, which slave_tol bounds), round-off ~DIR_TOL
# (1 + |theta'|) / DRIFT_DTAU (noise, which the error control sees). At 1e-5 that noise held a
# near-edge harness scene's slaved steps at rtol 1e-13 to a seventh of the simulated time per step
# of rtol 1e-12 (step_limit at 15 s, against 105 s, in 1e6 tries); at 1e-4 it reaches 97 s.
DRIFT_DTAU = 1e-4


DIR_MAXSTEP = 0.25  # rad: largest secant update of the slaved direction


DIR_MAXIT = 30


@kernel
def slip_roundoff(t, aux, p):
    """The round-off floor of a slip's approach to u = 0 at tau = t (u_hat): the speed that the
    friction's deceleration, at most ~mu_d Phi (1 + 1/A) (aux: the right-hand side's at the state),
    takes off the slip in SLIP_RESOLUTION ulps of tau. A slide that passes or spirals closer to
    u = 0 than that turns its direction within steps below the step-size floor (2 EPS tau)."""
    decel = p[P_MUD] * max(aux[X_PHI], 0.0) * (1.0 + 1.0 / p[P_A])
    return SLIP_RESOLUTION * EPS * max(abs(t), 1.0) * decel


@kernel
def slip_floor(t, aux, p, cs):
    """The slip speed (u_hat) at which a slide meets its fate (EV_SLIP_SLOW, slow_slide): slip_tol
    (cs[CS_FLOOR] for a slide followed BELOW it), or where larger the round-off floor (slip_roundoff), where
    the fate is taken instead, an O(floor) change of the velocity."""
    floor = cs[CS_FLOOR] if cs[CS_SLAVE_OFF] == BELOW else p[P_UTOL]
    return max(floor, slip_roundoff(t, aux, p))


@kernel
def slave_speed(y, aux, p):
    """Slip speed (u_hat) below which the slip direction is slaved: where its relaxation time
    |u|/(mu_d Phi) times the rate of the motion, 1 + |theta'| (the precession rate theta' =
    omega_3 sec alpha, eq. 2.3, in units of 1/chi), is below slave_tol (p[P_SLAVE]), and at least
    where the relaxation time alone is below SLAVE_FLOOR, and at least slip_tol."""
    rate = 1.0 + abs(y[Y_W3] / aux[X_COSA])
    return max(p[P_UTOL], p[P_MUD] * aux[X_PHI] * max(SLAVE_FLOOR, p[P_SLAVE] / rate))


@kernel
def exit_speed(y, aux, p):
    """Slip speed (u_hat) past which a slaved slip slides (SLIDE): SLAVE_EXIT times the slaving
    speed of slave_tol, at least FLOOR_EXIT times the floor's (slave_speed)."""
    rate = 1.0 + abs(y[Y_W3] / aux[X_COSA])
    return max(FLOOR_EXIT * p[P_UTOL],
               p[P_MUD] * aux[X_PHI] * max(FLOOR_EXIT * SLAVE_FLOOR, SLAVE_EXIT * p[P_SLAVE] / rate))


@kernel
def mode_energy(y, p, cs):
    """Energy of the state in the contact state cs (eq. 6.1 corrected; the slip counts when sliding)."""
    return _mode_energy_trig(y, p, cs, (math.sin(y[Y_ALPHA]), math.cos(y[Y_ALPHA])))


@kernel
def mode_energy_at(y, aux, p, cs):
    """mode_energy(y, p, cs) from the sine and cosine of alpha in aux, the right-hand side's at y."""
    return _mode_energy_trig(y, p, cs, (aux[X_SINA], aux[X_COSA]))


@kernel
def _mode_energy_trig(y, p, cs, trig):
    side = int(cs[CS_SIDE])
    u1, u2 = (0.0, 0.0) if cs[CS_MODE] == ROLL else (y[Y_U1], y[Y_U2])
    return energy_from_trig(y, p, side, u1, u2, trig)


@kernel(inline="always")
def _model(ev, mode, n0x, n0y):
    """The model's right-hand side (ev: layout.Eval) in mode ROLL or SLIDE (a constant at each call
    site, so that LLVM specialises the copy), the friction along (n0x, n0y) at slip speeds <=
    slip_tol; counts the call."""
    sys = ev.sys
    cs = sys.cs
    rhs(ev.y, sys.p, Contact(mode, int(cs[CS_SIDE]), cs[CS_SIG:CS_SIG + 3], cs[CS_STUCK:CS_STUCK + 3], n0x, n0y),
        sys.n, ev.dy, ev.aux)
    sys.istats[I_RHS] += 1


@kernel
def slide_model(ev, n0x, n0y):
    """The sliding right-hand side (contact states SLIDE and SLAVED; ev: layout.Eval), the friction
    along (n0x, n0y) at slip speeds <= slip_tol: the one compiled copy of the sliding model, which
    every sliding evaluation calls (the rolling one is inlined into eval_rhs, where the steps of a
    rolling motion call it; each inlined copy of the model costs ~3 s of compilation)."""
    _model(ev, SLIDE, n0x, n0y)


@kernel
def model_call(ev, n0x, n0y):
    """The model for the contact state ev.sys.cs (ev: layout.Eval; SLAVED evaluates as sliding, along
    (n0x, n0y)), where a discrete update reads the right-hand side once (start_slip, set_slip)."""
    if ev.sys.cs[CS_MODE] == ROLL:
        eval_rhs(ev.t, ev.y, ev.sys, ev.dy, ev.aux)
    else:
        slide_model(ev, n0x, n0y)


@kernel
def eval_rhs(t, y, sys, dy, aux):
    """d y/d tau and contact quantities (aux) for the contact state cs; counts its model calls. The
    stepper's right-hand side (dop853: rhs(t, y, sys, dy, aux))."""
    cs, n = sys.cs, sys.n
    ev = Eval(t, y, sys, dy, aux)
    mode = cs[CS_MODE]
    if mode == SLAVED:
        nu, lag, dcross, ok, err = slaved_slip(cs[CS_NU], ev)
        # the sliding equations at the slip vector itself with the friction along s(nu + lag): the
        # slip acceleration, the friction power (mu_d Phi s.u) and the energy stay those of one
        # Newton-Euler motion, so the energy books close however far u turns from s
        friction_along(nu + lag, ev)
        aux[X_DCROSS] = dcross
        aux[X_NU] = nu
        aux[X_LAG] = lag
        aux[X_SLAVE_ERR] = err
        if ok < 0.0:
            aux[X_OK] = ok
        elif ok == 0.0:
            # no slaved direction near the last one (it folded away inside this step): a NaN
            # derivative makes the step fail, so steps shrink until EV_SLAVE_LOST is located
            for i in range(n):
                dy[i] = math.nan
    elif mode == SLIDE:
        un = math.hypot(y[Y_U1], y[Y_U2])
        nx = y[Y_U1] / un if un > 0.0 else math.cos(cs[CS_NU])
        ny = y[Y_U2] / un if un > 0.0 else math.sin(cs[CS_NU])
        _model(ev, SLIDE, nx, ny)
    else:
        # (the rolling model inlined: the steps of a rolling motion call it, and a call passes ~50
        # words of arguments)
        _model(ev, ROLL, 1.0, 0.0)


@kernel
def speed_along(y, nu):
    """The slip's speed along s(nu), u.s: the speed of a slaved slip in its direction dynamics
    (the lag is proportional to it). |u| where u lies along s; it passes through 0 where the slip
    ends (u.s = 0) and goes negative past it, so the slaved right-hand side continues there
    without a kink (with |u| it had one, and every step across a slip's end failed until the
    steps had shrunk onto it), and it stays continuous where u turns across s."""
    return y[Y_U1] * math.cos(nu) + y[Y_U2] * math.sin(nu)


@kernel
def slip_rates(nu, u, ev, ys):
    """(cross, dot) of the slip acceleration with the slip direction s = (cos nu, sin nu), for the
    slip vector u s at the state ev.y (ev: layout.Eval; the state with that slip in ys), the
    friction along s. u NaN: the state's own slip along s, u.s (speed_along); u < 0 (a slaved slip
    past its end) is a slip against s. The full right-hand side is left in ev.dy, ev.aux."""
    y, dy = ev.y, ev.dy
    c = math.cos(nu)
    s = math.sin(nu)
    if math.isnan(u):
        u = y[Y_U1] * c + y[Y_U2] * s
    for i in range(ev.sys.n):
        ys[i] = y[i]
    ys[Y_U1] = u * c
    ys[Y_U2] = u * s
    if u < 0.0:
        friction_along(nu, Eval(ev.t, ys, ev.sys, dy, ev.aux))
    else:
        slide_model(Eval(ev.t, ys, ev.sys, dy, ev.aux), c, s)
    return dy[Y_U2] * c - dy[Y_U1] * s, dy[Y_U1] * c + dy[Y_U2] * s


@kernel
def slaved_direction(nu0, u, ev, ys):
    """Slip direction near nu0 at which the slip acceleration is parallel to the slip (secant), at the
    slip speed u (NaN: the state's own slip along each iterate's direction, slip_rates) and the
    state of ev (layout.Eval; ys: slip_rates' scratch).

    Returns nu; ev.dy, ev.aux hold the right-hand side there. ev.aux[X_OK] = 0 if it does not converge.
    """
    return direction_from(nu0, 0.0, u, ev, ys)


@kernel
def direction_from(nu0, slope, u, ev, ys):
    """slaved_direction from nu0, its first update a Newton step with slope (d cross/d nu near the
    root, < 0) where one is known, else from a probe 1e-6 rad away; then the same damped secant."""
    aux = ev.aux
    xa = nu0
    ca, da = slip_rates(xa, u, ev, ys)
    if abs(ca) <= DIR_NOISE * (1.0 + math.hypot(ca, da)):
        return xa
    xb = nu0 + 1e-6
    if slope < 0.0:
        xb = nu0 - max(-DIR_MAXSTEP, min(DIR_MAXSTEP, ca / slope))
    cb, db = slip_rates(xb, u, ev, ys)
    for _ in range(DIR_MAXIT):
        if abs(cb) <= DIR_NOISE * (1.0 + math.hypot(cb, db)) or abs(xb - xa) < DIR_TOL:
            return xb
        if cb == ca:
            break
        # a damped secant: the root moves little between calls, and a flat stretch of cross (a
        # near-fold) must not throw the iterate onto another root
        dx = -cb * (xb - xa) / (cb - ca)
        if abs(dx) < DIR_TOL:
            return xb   # (the next iterate would be within DIR_TOL: xb is the root to that)
        xc = xb + max(-DIR_MAXSTEP, min(DIR_MAXSTEP, dx))
        xa, ca = xb, cb
        xb = xc
        cb, db = slip_rates(xb, u, ev, ys)
    if aux[X_OK] > 0.0:
        aux[X_OK] = 0.0   # (a Painleve flag, -1, from the model stays)
    return xb


@kernel
def friction_along(nu, ev):
    """The sliding right-hand side (ev: layout.Eval) at the state's own slip vector with the friction
    along s(nu), whatever |u| (the parameters with slip_tol, where the model freezes the friction
    direction, lifted to inf, in wk[W_PFRICTION])."""
    sys = ev.sys
    p, wk = sys.p, sys.wk
    pf = wk[W_PFRICTION]
    for i in range(N_PARAMS):
        pf[i] = p[i]
    pf[P_UTOL] = math.inf
    friction = System(pf, sys.cs, sys.n, wk, sys.istats)
    slide_model(Eval(ev.t, ev.y, friction, ev.dy, ev.aux), math.cos(nu), math.sin(nu))


@kernel
def direction_lag(nu, u, rates, ev):
    """The lag (rad) of a slow slip's direction behind the quasi-static direction nu, first order
    in the relaxation time: on the slow manifold of d nu/d tau = cross(nu)/u the direction is
    nu* + delta, and with delta = k u (the lag scales with the slip, whose own rate u'/u = rad/u is
    as fast as the direction's) u (nu*' + delta') = c' delta gives delta = u nu*'/(c' - rad)
    (c' = d cross/d nu < 0 where nu attracts, rad = u' the slip's rate along s), with
    nu*' = -(d cross/d tau at fixed nu)/c' (docs/model.md, 'Slow slip'). ev.dy: the right-hand side
    at the slip vector u s(nu) (slip_rates'), rates = (cross, rad, c') there; d cross/d tau by a
    central difference along that motion (its round-off enters the second order's difference of
    the lag, second_order_lag). 0 where nu does not attract that way (c' - rad >= 0)."""
    t, y, sys, dy = ev.t, ev.y, ev.sys, ev.dy
    cross0, rad0, dcross = rates
    den = dcross * (dcross - rad0)
    if not (dcross < 0.0 and dcross - rad0 < 0.0 and u != 0.0):
        return 0.0
    # the step along the motion, short enough that the slip speed keeps its sign on it both ways
    # (over FLOW_DTAU / (1 + |theta'|), the motion's rate: near flat theta' grows without bound)
    step = FLOW_DTAU / (1.0 + abs(y[Y_W3] / math.cos(y[Y_ALPHA])))
    if rad0 != 0.0:
        step = min(step, 0.5 * abs(u) / abs(rad0))
    wk = sys.wk
    yf = wk[W_YFLOW]
    for i in range(sys.n):
        yf[i] = y[i] + step * dy[i]
    cross_f, _ = slip_rates(nu, u + step * rad0, Eval(t + step, yf, sys, wk[W_DYFLOW], wk[W_AUXFLOW]), wk[W_YSLIP])
    for i in range(sys.n):
        yf[i] = y[i] - step * dy[i]
    cross_b, _ = slip_rates(nu, u - step * rad0, Eval(t - step, yf, sys, wk[W_DYFLOW], wk[W_AUXFLOW]), wk[W_YSLIP])
    return -u * ((cross_f - cross_b) / (2.0 * step)) / den


@kernel
def root_lag(nu, u, ev):
    """(lag, c', err) of the slow slip at the quasi-static direction nu (slaved_slip's), at the state
    of ev (layout.Eval): ev.dy, ev.aux get the right-hand side at the slip vector u s(nu)."""
    cross0, rad0 = slip_rates(nu, u, ev, ev.sys.wk[W_YSLIP])
    return lag_and_error(nu, u, cross0, ev)


@kernel
def lag_and_error(nu, u, cross0, ev):
    """(lag, c', err) at the quasi-static direction nu, ev.dy, ev.aux (layout.Eval) the right-hand
    side at the slip vector u s(nu) and cross0 its cross: c' = d cross/d nu by a forward difference,
    the lag (direction_lag, damped by exp(-err^4)) and the slaved direction's error measure
    (slaved_slip)."""
    y, sys, dy, aux = ev.y, ev.sys, ev.dy, ev.aux
    wk = sys.wk
    rad0 = dy[Y_U1] * math.cos(nu) + dy[Y_U2] * math.sin(nu)
    cross1, _ = slip_rates(nu + DCROSS_DNU, u, Eval(ev.t, y, sys, wk[W_DYSLOPE], wk[W_AUXSLOPE]), wk[W_YSLIP])
    dcross = (cross1 - cross0) / DCROSS_DNU
    lag = direction_lag(nu, u, (cross0, rad0, dcross), ev)
    relax = rad0 - dcross
    err = math.inf
    if dcross < 0.0 and relax > 0.0:
        err = abs(u) * (1.0 + abs(y[Y_W3] / aux[X_COSA])) / relax + abs(lag)
        # as the direction's relaxation falls to the slip's own decay (c' - rad -> 0-) the
        # series' lag grows without bound, and the round-off of c' - rad with it, where the series
        # no longer holds (err >> 1: the slip ends before its direction reaches that lag) and a
        # slip is slaved only at the floor's speed; damped by exp(-err^4) it goes smoothly to 0,
        # the lag where nu does not attract that way, and changes by err^4 where the series holds
        lag *= math.exp(-(err * err) * (err * err))
    return lag, dcross, err


@kernel
def slaved_slip(nu0, ev):
    """The slow slip's direction at the state: (nu*, lag, c', ok, err). nu* is the quasi-static
    direction continued from nu0 (slaved_direction), the friction acts along nu* + lag
    (direction_lag), c' = d cross/d nu there; ok is slaved_direction's aux[X_OK] (0: no root
    near nu0). err measures how far the first-order slow manifold is from exact: the direction's
    relaxation time |u|/|c' - rad| times the motion's rate 1 + |theta'|, plus the lag itself
    (the neglected terms are of the order of their product and of the lag squared); inf where the
    direction does not relax onto nu* + lag (c' - rad >= 0). ev (layout.Eval): the state; its dy,
    aux are left with the right-hand side at the slip vector (u.s) s(nu*). The speed is the slip's
    along s (speed_along), signed: it goes through 0 where the slip ends, so the slaved right-hand
    side has no kink there."""
    y, dy = ev.y, ev.dy
    nu = slaved_direction(nu0, math.nan, ev, ev.sys.wk[W_YSLIP])
    u = speed_along(y, nu)
    ok = ev.aux[X_OK]
    cross0 = dy[Y_U2] * math.cos(nu) - dy[Y_U1] * math.sin(nu)
    lag, dcross, err = lag_and_error(nu, u, cross0, ev)
    if not ok > 0.0:
        lag = 0.0
    elif second_order_applies(lag, err, ev.sys.p):
        lag, err = second_order(nu, lag, dcross, err, ev)
    return nu, lag, dcross, ok, err


@kernel
def second_order_applies(lag, err, p):
    """Whether the slow manifold is taken to second order (second_order) from the first-order lag
    and error measure err: with slave_tol > 0, above the round-off of their product, and where the
    first-order measure is within SLAVE_EXIT slave_tol, the series' region. Beyond it a slip is
    slaved only at the floor's speed (SLAVE_FLOOR: near flat, where the motion's rate 1 + |theta'|
    grows without bound), where the series' terms are not ordered and the second order's difference
    of a difference carries round-off of ~1e-6 of the slip acceleration, which a 1e-13 error
    control cannot step through."""
    return p[P_SLAVE] > 0.0 and abs(lag) * err > EPS and err <= SLAVE_EXIT * p[P_SLAVE]


@kernel
def second_order(nu, lag, dcross, err, ev):
    """(lag, err) of the second-order slow manifold from the first-order one (lag, err:
    lag_and_error's at the quasi-static direction nu): the lag to second order (second_order_lag,
    with the right-hand side along nu + lag in ev.dy, ev.aux; ev: layout.Eval), and the error measure raised to the
    series' own: the second-order term d2 over the first, |d2| / |lag|, estimates the expansion's
    parameter (where the manifold moves faster than the motion's rate 1 + |theta'| tells, it
    exceeds the first-order measure), and times |d2| the neglected third order, d2^2 / |lag|; err
    becomes the larger of the first-order measure and the cube root of that third order, so that
    err <= slave_tol bounds the neglected terms by slave_tol^3 as it bounds the first-order
    manifold's by slave_tol^2 (docs/model.md, 'Slow slip'). Below that product's round-off
    (|lag| err <= EPS) the second order is not computed."""
    friction_along(nu + lag, ev)
    lag2 = second_order_lag(nu, lag, dcross, ev)
    d2 = abs(lag2 - lag)
    return lag2, max(err, (d2 * d2 / abs(lag)) ** (1.0 / 3.0))


@kernel
def second_order_lag(nu, lag, dcross, ev):
    """The slow manifold's lag behind nu* to second order in the relaxation time. On the manifold
    nu = h(state) the direction dynamics u nu' = cross(nu) read u Dh = cross(h) (D: the rate along
    the motion with the friction along h), exact. The first-order manifold h1 = nu* + lag
    (slaved_slip's) makes the residual second order; here Dh1 is a forward difference of h1 over
    DRIFT_DTAU / (1 + |theta'|) along the motion with the friction along h1 (ev.dy, ev.aux,
    layout.Eval: the right-hand side there), and h solves cross(h) = u Dh1 by secant steps from h1 with the slope
    c' = dcross: the neglected terms are third order (docs/model.md, 'Slow slip'). Returns the lag
    h - nu*; the first-order one where the slaved direction is lost along the difference."""
    t, y, sys, dy, aux = ev
    wk = sys.wk
    n = sys.n
    u = speed_along(y, nu)
    yf, dyf, auxf = wk[W_YDRIFT], wk[W_DYDRIFT], wk[W_AUXDRIFT]
    rad = speed_along(dy, nu)
    step = DRIFT_DTAU / (1.0 + abs(y[Y_W3] / aux[X_COSA]))
    if rad * u < 0.0:
        step = min(step, 0.5 * abs(u / rad))
    for i in range(n):
        yf[i] = y[i] + step * dy[i]
    # (started where nu* moves to at its first-order rate, lag (c' - rad)/u: the root is then a
    # Newton step away)
    evf = Eval(t + step, yf, sys, dyf, auxf)
    nuf = direction_from(nu + step * lag * (dcross - rad) / u, dcross, math.nan, evf, wk[W_YSLIP])
    if not auxf[X_OK] > 0.0:
        return lag
    crossf = dyf[Y_U2] * math.cos(nuf) - dyf[Y_U1] * math.sin(nuf)
    lagf, _, _ = lag_and_error(nuf, speed_along(yf, nuf), crossf, evf)
    if lagf == 0.0:
        return lag
    drift = u * ((nuf + lagf) - (nu + lag)) / step
    # one Newton step from h1 with the slope at nu*: the correction d2 is of the order of the lag
    # times the expansion's parameter, and the step's own error, of d2 times the slope's change
    # over lag + d2, is third order
    cross1, _ = slip_rates(nu + lag, u, Eval(t, y, sys, wk[W_DYSLOPE], wk[W_AUXSLOPE]), wk[W_YSLIP])
    return lag - max(-abs(lag), min(abs(lag), (cross1 - drift) / dcross))
