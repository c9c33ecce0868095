"""The contact as a hybrid system: right-hand side per contact state, event functions, and the
discrete updates at events. Every decision here reads the state and physical parameters only
(slip_tol is p[P_UTOL], spin_tol p[P_WTOL]). The kernels take the system they evaluate as one
group, `sys` (layout.System: parameters, contact state, state size, work buffer, counters).

Modes (docs/model.md, 'Modes, signs and sticking'):
  ROLL    no slip; friction is what rolling needs, inside the static cone |F| <= mu_s Phi.
  SLIDE   friction -mu_d Phi u/|u| (eq. 4.7), the slip integrated in Cartesian form.
  SLAVED  a slow slip, |u| <= the slaving speed u_s (slave_speed: slave_tol mu_d Phi / (1 + |theta'|)): its direction
          is not integrated but solved at every evaluation as the slow manifold of the direction
          dynamics (the direction rate, ~ mu_d Phi / u, is the stiff mode of the sliding equations
          at u -> 0): the quasi-static direction nu*, where the slip acceleration is parallel to the
          slip, plus the lag behind it, first order in the relaxation time (slaved_slip). Entered at a slip onset (u = 0) and from SLIDE where
          |u| falls to u_s onto the attracting quasi-static direction, if there is one (try_slave);
          it hands over to SLIDE where u grows past SLAVE_EXIT u_s or the direction folds away, and
          ends in ROLL where u.s returns to 0 (located events; the velocity is continuous).
A SLIDE not handed over (a slip spiralling into u = 0, or passing by it) meets its fate where |u|
falls to slip_tol (slip_fate, slow_slide; docs/model.md, 'Where a slip ends'): where its direction
dynamics carry it to u = 0 along nu* it settles onto nu* and ends as a slaved slip at u.s = 0 (a
located event); a slip that spirals out slides on; otherwise it is followed below slip_tol, its
fate read again 16 times slower, until it settles, or, at the round-off floor, it ends or passes
through u = 0 by an impulse of O(floor). No decision, and no event before it, depends on slip_tol.
Moment components (eq. 3.3, Filippov): a free component sticks where omega.a_i reaches 0, or where
it slows to spin_tol and its motion goes on to rest, if the moment can hold it there
(spin_sticks; |sigma needed| < 1); a stuck one is released where |sigma needed| reaches 1.
"""
from __future__ import annotations

import math

from .. import outcomes as oc
from .events import (C_CONTACT_LOST, C_FACE, C_MOMENT, C_SIDE, C_SLIP, E_CLASS, E_COMPONENT, E_FORCES, EV_AGAINST1, EV_AGAINST3, EV_CONE, EV_CONTACT,
                     EV_FACE, EV_LEVEL, EV_SIDE, EV_SIGN1, EV_SIGN3, EV_SLAVE, EV_SLAVE_LOST, EV_SLIP_FAST, EV_SLIP_SLOW,
                     EV_SLIP_STOP, EV_SPIN1, EV_SPIN3, EV_UNSTICK1, EV_UNSTICK3, EVENTS, N_EVENTS)
from .constants import AT_FLOOR, BELOW, EPS, HANDOVER_ARMED, HANDOVER_OFF, ROLL, SLAVED, SLIDE, SLOW_OFF
from .impulse import project_velocity, stop_axis_rate
from .jit import kernel
from .layout import (CS_FLOOR, CS_MODE, CS_NU, CS_SLAVE_OFF, CS_SIDE, CS_SIG, CS_STUCK, W_AUXTMP,
                     W_AUXDRIFT, W_AUXFLOW, W_AUXSLOPE, W_DYDRIFT, W_DYFLOW, W_YDRIFT, W_DYSLOPE, W_DYTMP, W_GBUF, W_YFLOW, W_PFRICTION, W_SCRATCH, W_YSLIP, I_RHS, I_STICK, I_TRANS, I_IMPACTS, F_DIMPACT, F_TIMPACT,
                     System)
from .model import (N_PARAMS, P_A, P_SLAVE, P_K1, P_K2, P_K3, P_MUD, P_MUS, P_UTOL, P_WTOL, Y_DK1, X_COSA, X_DCROSS, X_F1, X_F2, X_G1, X_OK, X_PHI, X_SIG1, X_SINA, X_LAG, X_NU, X_SLAVE_ERR, Y_ALPHA,
                    Y_DSLIDE, Y_U1, Y_U2, Y_W1, Y_W2, Y_W3, Contact, energy_from_trig, moment_axes_rates, rhs, sign_rate)

# Inclination (rad) at which the face is taken to touch the table: the disk lies flat. The far rim
# is then 1e-6 R above the table (38 nm for the paper's disk), below any real table's flatness. A disk
# that slaps down reaches it with a normal force ~1e5 m g (tests/test_stress.py 'tiny spin'); closer
# to flat the rigid single-contact model has no physical content left.
BETA_FACE = 1e-6
# Two rim-edge impacts closer than ZENO_DTAU (tau) end the scene as line contact.
ZENO_DTAU = 1e-6
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
# a slide followed BELOW slip_tol (constants.BELOW) has its fate read again BELOW_STEP times slower
# each time
BELOW_STEP = 16.0
# settle_onto's answers
SETTLED, AGAINST, INACCURATE = 0, 1, 2
# tau: the differences of d/dtau(omega.a_i) along the motion for its second and third derivatives
# (spin_rest_time): truncation O(SPIN_DIFF^2) and O(SPIN_DIFF), round-off EPS |g1| / SPIN_DIFF^2.
SPIN_DIFF = 1e-3
# A passage by u = 0 is resolved in time where it takes at least this many ulps of tau (slip_floor).
SLIP_RESOLUTION = 256.0
# Secant iterations of the slaved direction: converged when the angle update is below DIR_TOL rad.
DIR_TOL = 1e-14
# ... or when cross is at its round-off floor: |cross| <= DIR_NOISE |slip acceleration|. Near a fold
# (d cross/d nu small) the secant can stall there, two iterates giving the same rounded cross, before
# its angle update gets below DIR_TOL: the root is then found to machine precision, not lost.
DIR_NOISE = 64.0 * EPS
DCROSS_DNU = 1e-7   # rad: forward-difference step of d cross/d nu
# tau: central-difference step of d cross/d tau along the motion at a fixed direction (the lag):
# truncation O(FLOW_DTAU^2) relative, round-off ~EPS |a_P| / FLOW_DTAU; the second order differences
# the lag again over DRIFT_DTAU, which takes that round-off times 1 / DRIFT_DTAU
FLOW_DTAU = 1e-5
# tau x (1 + |theta'|): the step along the slaved motion over which the first-order manifold's
# direction is differenced (second_order_lag): truncation O(DRIFT_DTAU) relative in a second-order
# term, round-off ~DIR_TOL (1 + |theta'|) / DRIFT_DTAU
DRIFT_DTAU = 1e-5
DIR_MAXSTEP = 0.25  # rad: largest secant update of the slaved direction
DIR_MAXIT = 30
# attracting_direction's answer where the slip direction is carried into the Painleve singularity
JAMMED = math.inf


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
    return _mode_energy_trig(y, p, cs, math.sin(y[Y_ALPHA]), math.cos(y[Y_ALPHA]))


@kernel
def mode_energy_at(y, aux, p, cs):
    """mode_energy(y, p, cs) from the sine and cosine of alpha in aux, the right-hand side's at y."""
    return _mode_energy_trig(y, p, cs, aux[X_SINA], aux[X_COSA])


@kernel
def _mode_energy_trig(y, p, cs, s, c):
    side = int(cs[CS_SIDE])
    u1, u2 = (0.0, 0.0) if cs[CS_MODE] == ROLL else (y[Y_U1], y[Y_U2])
    return energy_from_trig(y, p, side, u1, u2, s, c)


@kernel(inline="always")
def _model(t, y, sys, mode, dy, aux, n0x, n0y):
    """The model's right-hand side in mode ROLL or SLIDE (a constant at each call site, so that LLVM
    specialises the copy), the friction along (n0x, n0y) at slip speeds <= slip_tol; counts the call."""
    cs = sys.cs
    rhs(t, y, sys.p, Contact(mode, int(cs[CS_SIDE]), cs[CS_SIG:CS_SIG + 3], cs[CS_STUCK:CS_STUCK + 3], n0x, n0y),
        sys.n, dy, aux)
    sys.istats[I_RHS] += 1


@kernel
def slide_model(t, y, sys, dy, aux, n0x, n0y):
    """The sliding right-hand side (contact states SLIDE and SLAVED), the friction along (n0x, n0y) at
    slip speeds <= slip_tol: the one compiled copy of the sliding model, which every sliding
    evaluation calls (the rolling one is inlined into eval_rhs, where the steps of a rolling motion
    call it; each inlined copy of the model costs ~3 s of compilation)."""
    _model(t, y, sys, SLIDE, dy, aux, n0x, n0y)


@kernel
def model_call(t, y, sys, dy, aux, n0x, n0y):
    """The model for the contact state sys.cs (SLAVED evaluates as sliding, along (n0x, n0y)), where a
    discrete update reads the right-hand side once (start_slip, set_slip)."""
    if sys.cs[CS_MODE] == ROLL:
        eval_rhs(t, y, sys, dy, aux)
    else:
        slide_model(t, y, sys, dy, aux, n0x, n0y)


@kernel
def slip_rates(nu, u, t, y, sys, dy, aux, ys):
    """(cross, dot) of the slip acceleration with the slip direction s = (cos nu, sin nu), for the
    slip vector u s; the full right-hand side is left in dy, aux."""
    n = sys.n
    c = math.cos(nu)
    s = math.sin(nu)
    for i in range(n):
        ys[i] = y[i]
    ys[Y_U1] = u * c
    ys[Y_U2] = u * s
    slide_model(t, ys, sys, dy, aux, c, s)
    return dy[Y_U2] * c - dy[Y_U1] * s, dy[Y_U1] * c + dy[Y_U2] * s


@kernel
def slaved_direction(nu0, u, t, y, sys, dy, aux, ys):
    """Slip direction near nu0 at which the slip acceleration is parallel to the slip (secant).

    Returns nu; dy, aux hold the right-hand side there. aux[X_OK] = 0 if it does not converge.
    """
    return direction_from(nu0, 0.0, u, t, y, sys, dy, aux, ys)


@kernel
def direction_from(nu0, slope, u, t, y, sys, dy, aux, ys):
    """slaved_direction from nu0, its first update a Newton step with slope (d cross/d nu near the
    root, < 0) where one is known, else from a probe 1e-6 rad away; then the same damped secant."""
    xa = nu0
    ca, da = slip_rates(xa, u, t, y, sys, dy, aux, ys)
    if abs(ca) <= DIR_NOISE * math.hypot(ca, da):
        return xa
    xb = nu0 + 1e-6
    if slope < 0.0:
        xb = nu0 - max(-DIR_MAXSTEP, min(DIR_MAXSTEP, ca / slope))
    cb, db = slip_rates(xb, u, t, y, sys, dy, aux, ys)
    for _ in range(DIR_MAXIT):
        if abs(cb) <= DIR_NOISE * math.hypot(cb, db) or abs(xb - xa) < DIR_TOL:
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
        cb, db = slip_rates(xb, u, t, y, sys, dy, aux, ys)
    if aux[X_OK] > 0.0:
        aux[X_OK] = 0.0   # (a Painleve flag, -1, from the model stays)
    return xb


@kernel
def friction_along(nu, t, y, sys, dy, aux):
    """The sliding right-hand side at the state's own slip vector with the friction along s(nu),
    whatever |u| (the parameters with slip_tol, where the model freezes the friction direction,
    lifted to inf, in wk[W_PFRICTION])."""
    p, wk = sys.p, sys.wk
    pf = wk[W_PFRICTION]
    for i in range(N_PARAMS):
        pf[i] = p[i]
    pf[P_UTOL] = math.inf
    slide_model(t, y, System(pf, sys.cs, sys.n, wk, sys.istats), dy, aux, math.cos(nu), math.sin(nu))


@kernel
def direction_lag(nu, u, rates, t, y, sys, dy):
    """The lag (rad) of a slow slip's direction behind the quasi-static direction nu, first order
    in the relaxation time: on the slow manifold of d nu/d tau = cross(nu)/u the direction is
    nu* + delta, and with delta = k u (the lag scales with the slip, whose own rate u'/u = rad/u is
    as fast as the direction's) u (nu*' + delta') = c' delta gives delta = u nu*'/(c' - rad)
    (c' = d cross/d nu < 0 where nu attracts, rad = u' the slip's rate along s), with
    nu*' = -(d cross/d tau at fixed nu)/c' (docs/model.md, 'Slow slip'). dy: the right-hand side
    at the slip vector u s(nu) (slip_rates'), rates = (cross, rad, c') there; d cross/d tau by a
    central difference along that motion (its round-off enters the second order's difference of
    the lag, second_order_lag). 0 where nu does not attract that way (c' - rad >= 0)."""
    cross0, rad0, dcross = rates
    den = dcross * (dcross - rad0)
    if not (dcross < 0.0 and dcross - rad0 < 0.0 and u > 0.0):
        return 0.0
    # the step along the motion, short enough that the slip speed stays positive on it both ways
    step = min(FLOW_DTAU, 0.5 * u / abs(rad0)) if rad0 != 0.0 else FLOW_DTAU
    wk = sys.wk
    yf = wk[W_YFLOW]
    for i in range(sys.n):
        yf[i] = y[i] + step * dy[i]
    cross_f, _ = slip_rates(nu, u + step * rad0, t + step, yf, sys, wk[W_DYFLOW], wk[W_AUXFLOW], wk[W_YSLIP])
    for i in range(sys.n):
        yf[i] = y[i] - step * dy[i]
    cross_b, _ = slip_rates(nu, u - step * rad0, t - step, yf, sys, wk[W_DYFLOW], wk[W_AUXFLOW], wk[W_YSLIP])
    return -u * ((cross_f - cross_b) / (2.0 * step)) / den


@kernel
def root_lag(nu, u, t, y, sys, dy, aux):
    """(lag, c', err) of the slow slip at the quasi-static direction nu (slaved_slip's): dy, aux get
    the right-hand side at the slip vector u s(nu)."""
    wk = sys.wk
    cross0, rad0 = slip_rates(nu, u, t, y, sys, dy, aux, wk[W_YSLIP])
    return lag_and_error(nu, u, cross0, t, y, sys, dy, aux)


@kernel
def lag_and_error(nu, u, cross0, t, y, sys, dy, aux):
    """(lag, c', err) at the quasi-static direction nu, dy, aux the right-hand side at the slip vector
    u s(nu) and cross0 its cross: c' = d cross/d nu by a forward difference, the lag
    (direction_lag) and the slaved direction's error measure (slaved_slip)."""
    wk = sys.wk
    rad0 = dy[Y_U1] * math.cos(nu) + dy[Y_U2] * math.sin(nu)
    cross1, _ = slip_rates(nu + DCROSS_DNU, u, t, y, sys, wk[W_DYSLOPE], wk[W_AUXSLOPE], wk[W_YSLIP])
    dcross = (cross1 - cross0) / DCROSS_DNU
    lag = direction_lag(nu, u, (cross0, rad0, dcross), t, y, sys, dy)
    relax = rad0 - dcross
    err = math.inf
    if dcross < 0.0 and relax > 0.0:
        err = u * (1.0 + abs(y[Y_W3] / aux[X_COSA])) / relax + abs(lag)
    return lag, dcross, err


@kernel
def slaved_slip(nu0, t, y, sys, dy, aux):
    """The slow slip's direction at the state: (nu*, lag, c', ok, err). nu* is the quasi-static
    direction continued from nu0 (slaved_direction), the friction acts along nu* + lag
    (direction_lag), c' = d cross/d nu there; ok is slaved_direction's aux[X_OK] (0: no root
    near nu0). err measures how far the first-order slow manifold is from exact: the direction's
    relaxation time |u|/|c' - rad| times the motion's rate 1 + |theta'|, plus the lag itself
    (the neglected terms are of the order of their product and of the lag squared); inf where the
    direction does not relax onto nu* + lag (c' - rad >= 0). dy, aux are left with the
    right-hand side at the slip vector |u| s(nu*)."""
    u = math.hypot(y[Y_U1], y[Y_U2])
    nu = slaved_direction(nu0, u, t, y, sys, dy, aux, sys.wk[W_YSLIP])
    ok = aux[X_OK]
    cross0 = dy[Y_U2] * math.cos(nu) - dy[Y_U1] * math.sin(nu)
    lag, dcross, err = lag_and_error(nu, u, cross0, t, y, sys, dy, aux)
    if not ok > 0.0:
        lag = 0.0
    elif sys.p[P_SLAVE] > 0.0 and abs(lag) * err > EPS:
        lag, err = second_order(nu, lag, dcross, err, t, y, sys, dy, aux)
    return nu, lag, dcross, ok, err


@kernel
def second_order(nu, lag, dcross, err, t, y, sys, dy, aux):
    """(lag, err) of the second-order slow manifold from the first-order one (lag, err:
    lag_and_error's at the quasi-static direction nu): the lag to second order (second_order_lag,
    with the right-hand side along nu + lag in dy, aux), and the error measure raised to the
    series' own: the second-order term d2 over the first, |d2| / (|lag| + |d2|), estimates the
    expansion's parameter (where the manifold moves faster than the motion's rate 1 + |theta'|
    tells, it exceeds the first-order measure), and times |d2| the neglected third order; err
    becomes the larger of the first-order measure and the cube root of that third order, so that
    err <= slave_tol bounds the neglected terms by slave_tol^3 as it bounds the first-order
    manifold's by slave_tol^2 (docs/model.md, 'Slow slip'). Below that product's round-off
    (|lag| err <= EPS) the second order is not computed."""
    friction_along(nu + lag, t, y, sys, dy, aux)
    lag2 = second_order_lag(nu, lag, dcross, t, y, sys, dy, aux)
    d2 = abs(lag2 - lag)
    return lag2, max(err, (d2 * d2 / abs(lag)) ** (1.0 / 3.0))


@kernel
def second_order_lag(nu, lag, dcross, t, y, sys, dy, aux):
    """The slow manifold's lag behind nu* to second order in the relaxation time. On the manifold
    nu = h(state) the direction dynamics u nu' = cross(nu) read u Dh = cross(h) (D: the rate along
    the motion with the friction along h), exact. The first-order manifold h1 = nu* + lag
    (slaved_slip's) makes the residual second order; here Dh1 is a forward difference of h1 over
    DRIFT_DTAU / (1 + |theta'|) along the motion with the friction along h1 (dy, aux: the
    right-hand side there), and h solves cross(h) = u Dh1 by secant steps from h1 with the slope
    c' = dcross: the neglected terms are third order (docs/model.md, 'Slow slip'). Returns the lag
    h - nu*; the first-order one where the slaved direction is lost along the difference."""
    wk = sys.wk
    n = sys.n
    u = math.hypot(y[Y_U1], y[Y_U2])
    yf, dyf, auxf = wk[W_YDRIFT], wk[W_DYDRIFT], wk[W_AUXDRIFT]
    rad = (y[Y_U1] * dy[Y_U1] + y[Y_U2] * dy[Y_U2]) / u
    step = DRIFT_DTAU / (1.0 + abs(y[Y_W3] / aux[X_COSA]))
    if rad < 0.0:
        step = min(step, 0.5 * u / -rad)
    for i in range(n):
        yf[i] = y[i] + step * dy[i]
    uf = u + step * rad
    # (started where nu* moves to at its first-order rate, lag (c' - rad)/u: the root is then a
    # Newton step away)
    nuf = direction_from(nu + step * lag * (dcross - rad) / u, dcross, uf, t + step, yf, sys, dyf, auxf, wk[W_YSLIP])
    if not auxf[X_OK] > 0.0:
        return lag
    crossf = dyf[Y_U2] * math.cos(nuf) - dyf[Y_U1] * math.sin(nuf)
    lagf, _, _ = lag_and_error(nuf, uf, crossf, t + step, yf, sys, dyf, auxf)
    if lagf == 0.0:
        return lag
    drift = u * ((nuf + lagf) - (nu + lag)) / step
    # one Newton step from h1 with the slope at nu*: the correction d2 is of the order of the lag
    # times the expansion's parameter, and the step's own error, of d2 times the slope's change
    # over lag + d2, is third order
    cross1, _ = slip_rates(nu + lag, u, t, y, sys, wk[W_DYSLOPE], wk[W_AUXSLOPE], wk[W_YSLIP])
    return lag - max(-abs(lag), min(abs(lag), (cross1 - drift) / dcross))


@kernel
def eval_rhs(t, y, sys, dy, aux):
    """d y/d tau and contact quantities (aux) for the contact state cs; counts its model calls."""
    cs, n = sys.cs, sys.n
    mode = cs[CS_MODE]
    if mode == SLAVED:
        nu, lag, dcross, ok, err = slaved_slip(cs[CS_NU], t, y, sys, dy, aux)
        # the sliding equations at the slip vector itself with the friction along s(nu + lag): the
        # slip acceleration, the friction power (mu_d Phi s.u) and the energy stay those of one
        # Newton-Euler motion, so the energy books close however far u turns from s
        friction_along(nu + lag, t, y, sys, dy, aux)
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
        _model(t, y, sys, SLIDE, dy, aux, nx, ny)
    else:
        # (the rolling model inlined: the steps of a rolling motion call it, and a call passes ~50
        # words of arguments)
        _model(t, y, sys, ROLL, dy, aux, 1.0, 0.0)


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
    guess = math.atan2(-F2, -F1)
    best = guess
    bestd = 1e300    # the nearest root with a solution
    best_none = guess
    bestd_none = 1e300   # ... and without one
    m = 64
    xa = guess - math.pi
    ca, _ = slip_rates(xa, 0.0, t, y, sys, dy, aux, ys)
    oka = aux[X_OK]
    for j in range(1, m + 1):
        xb = guess - math.pi + 2.0 * math.pi * j / m
        cb, _ = slip_rates(xb, 0.0, t, y, sys, dy, aux, ys)
        okb = aux[X_OK]
        if (ca > 0.0) != (cb > 0.0):
            lo, hi, clo, oklo, okhi = xa, xb, ca, oka, okb
            for _ in range(60):
                mid = 0.5 * (lo + hi)
                cm, _ = slip_rates(mid, 0.0, t, y, sys, dy, aux, ys)
                if (cm > 0.0) == (clo > 0.0):
                    lo, clo, oklo = mid, cm, aux[X_OK]
                else:
                    hi, okhi = mid, aux[X_OK]
                if hi - lo < 1e-13:
                    break
            root = 0.5 * (lo + hi)
            _, dr = slip_rates(root, 0.0, t, y, sys, dy, aux, ys)
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
    model_call(t, y, sys, wk[W_DYTMP], wk[W_AUXTMP], 1.0, 0.0)
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
        model_call(t, y, sys, wk[W_DYTMP], wk[W_AUXTMP], 1.0, 0.0)
        if un <= slave_speed(y, wk[W_AUXTMP], p):
            return try_slave(t, y, sys)
        return -1
    cs[CS_MODE] = SLAVED
    cs[CS_NU] = slaved_direction(nu, un, t, y, sys, wk[W_DYTMP], wk[W_AUXTMP], wk[W_YSLIP])
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
    ca, da = slip_rates(nu, u, t, y, sys, dy, aux, ys)
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
        cb, db = slip_rates(xb, u, t, y, sys, dy, aux, ys)
        crossed = (cb > 0.0) != (ca > 0.0) or aux[X_OK] < 0.0
        lo, hi = xa, xb
        if not crossed and abs(ca) < c_prev and abs(ca) <= abs(cb):
            # |cross| dips at xa: a root pair may lie between the neighbouring steps
            x_min = dip_crosses(x_prev if c_prev < math.inf else xa, xb, sense, u, t, y, sys)
            if not math.isnan(x_min):
                crossed = True
                lo, hi = (x_prev if c_prev < math.inf else xa), x_min
        if crossed:
            for _ in range(60):
                mid = 0.5 * (lo + hi)
                cm, dm = slip_rates(mid, u, t, y, sys, dy, aux, ys)
                if (cm > 0.0) == (sense > 0.0) and aux[X_OK] >= 0.0:
                    lo = mid
                else:
                    hi = mid
                if abs(hi - lo) < 1e-13:
                    break
            slip_rates(hi, u, t, y, sys, dy, aux, ys)
            if aux[X_OK] < 0.0:
                return JAMMED
            return 0.5 * (lo + hi)
        x_prev, c_prev = xa, abs(ca)
        xa, ca = xb, cb
    return math.nan


# Golden-section iterations of dip_crosses: the minimum located to 0.618^48 ~ 1e-10 of its bracket
DIP_ITERATIONS = 48


@kernel
def dip_crosses(lo, hi, sense, u, t, y, sys):
    """Where sense x cross has its minimum on [lo, hi] (golden section), if it is <= 0 there or the
    contact law has no solution (a root pair, or the Painleve pole, between two scan steps of
    attracting_direction whose cross has the sign sense): that point, else NaN."""
    wk = sys.wk
    dy, aux, ys = wk[W_DYTMP], wk[W_AUXTMP], wk[W_YSLIP]
    g = 0.5 * (math.sqrt(5.0) - 1.0)
    x1 = hi - g * (hi - lo)
    x2 = lo + g * (hi - lo)
    f1, _ = slip_rates(x1, u, t, y, sys, dy, aux, ys)
    if aux[X_OK] < 0.0 or sense * f1 <= 0.0:
        return x1
    f2, _ = slip_rates(x2, u, t, y, sys, dy, aux, ys)
    if aux[X_OK] < 0.0 or sense * f2 <= 0.0:
        return x2
    for _ in range(DIP_ITERATIONS):
        if sense * f1 < sense * f2:
            hi, x2, f2 = x2, x1, f1
            x1 = hi - g * (hi - lo)
            f1, _ = slip_rates(x1, u, t, y, sys, dy, aux, ys)
            if aux[X_OK] < 0.0 or sense * f1 <= 0.0:
                return x1
        else:
            lo, x1, f1 = x1, x2, f2
            x2 = lo + g * (hi - lo)
            f2, _ = slip_rates(x2, u, t, y, sys, dy, aux, ys)
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
    lag, dcross, err = root_lag(root, u, t, y, sys, wk[W_DYTMP], wk[W_AUXTMP])
    if p[P_SLAVE] > 0.0 and abs(lag) * err > EPS:
        lag, err = second_order(root, lag, dcross, err, t, y, sys, wk[W_DYTMP], wk[W_AUXTMP])
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
    loss = project_velocity(y, p, side, True, side, True, wk[W_SCRATCH:W_SCRATCH + 7], along)
    if y[Y_U1] * math.cos(along) + y[Y_U2] * math.sin(along) > 0.0:
        y[Y_DSLIDE] += loss
        cs[CS_MODE] = SLAVED
        cs[CS_NU] = root
        return SETTLED
    for i in range(n):
        y[i] = saved[i]
    return AGAINST


# What a slide whose speed has fallen to slip_tol does next (slip_fate): it reaches u = 0 and ends,
# it passes by u = 0 and leaves along a direction of growth, it spirals out from u = 0, or the
# direction dynamics carry it into the Painleve singularity.
FATE_ENDS, FATE_PASSES, FATE_SPIRALS_OUT, FATE_JAMMED = 0, 1, 2, 3
# Points on the circle for the slip's change of ln|u| over one turn of a spiral (a periodic
# integrand: the trapezoidal rule converges geometrically).
SPIRAL_POINTS = 64


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
    u = math.hypot(y[Y_U1], y[Y_U2])
    root = attracting_direction(math.atan2(y[Y_U2], y[Y_U1]), u, t, y, sys)
    if root == JAMMED:
        return FATE_JAMMED, math.nan
    if not math.isnan(root):
        _, rad = slip_rates(root, u, t, y, sys, dy, aux, ys)
        if rad > 0.0:
            return FATE_PASSES, root
        return FATE_ENDS, root
    turn = 0.0
    for j in range(SPIRAL_POINTS):
        cross, rad = slip_rates(2.0 * math.pi * j / SPIRAL_POINTS, u, t, y, sys, dy, aux, ys)
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
    y[Y_DSLIDE] += project_velocity(y, p, side, True, side, False, wk[W_SCRATCH:W_SCRATCH + 7])
    y[Y_U1] = 0.0
    y[Y_U2] = 0.0
    cs[CS_MODE] = SLAVED
    cs[CS_NU] = nu
    cs[CS_SLAVE_OFF] = HANDOVER_ARMED
    return -1


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
    nu = slaved_direction(cs[CS_NU], u, t, y, sys, wk[W_DYTMP], wk[W_AUXTMP], wk[W_YSLIP])
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


@kernel
def cone_violated(t, y, sys):
    """Rolling: the friction needed lies outside the static cone |F| <= mu_s Phi."""
    p, wk = sys.p, sys.wk
    eval_rhs(t, y, sys, wk[W_DYTMP], wk[W_AUXTMP])
    aux = wk[W_AUXTMP]
    return aux[X_PHI] > 0.0 and p[P_MUS] * aux[X_PHI] < math.hypot(aux[X_F1], aux[X_F2])


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
        root, lag, dcross, ok, err = slaved_slip(root, t, y, sys, dy, aux)
        if ok == 0.0:
            root, lag = math.atan2(y[Y_U2], y[Y_U1]), 0.0
    was = cs[CS_STUCK + i] if i >= 0 else 0.0
    if i >= 0:
        cs[CS_STUCK + i] = 1.0
    if slaved:
        friction_along(root + lag, t, y, sys, dy, aux)
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
def slip_fast_reached(t, y, sys):
    """Is the slip at or past EV_SLIP_FAST's surface (a slaved slip at SLAVE_EXIT times the slaving
    speed; a slide whose hand-over is off, fast again)? Its event function at the state, with the
    forces that the decisions read (decision_rhs). An impulse of a discrete update (the stop at
    spin_tol moves the slip by O(spin_tol)) can carry the slip there, where the event, g going
    from > 0 to <= 0, can no longer happen (docs/model.md, 'Restarts on a surface')."""
    p, cs, wk = sys.p, sys.cs, sys.wk
    if cs[CS_MODE] == ROLL:
        return False
    decision_rhs(-1, t, y, sys, wk[W_DYTMP], wk[W_AUXTMP])
    event_values(t, y, wk[W_AUXTMP], p, cs, math.nan, wk[W_GBUF])
    return wk[W_GBUF, EV_SLIP_FAST] <= 0.0


@kernel
def holding_sigma(i, t, y, sys, dy, aux):
    """needed_sigma of component i at y in the mode the slip has there after the update: a slaved
    slip at or past its exit (slip_fast_reached) slides (settle_event hands it over), and the
    friction along its own direction, not the quasi-static one, is what the moment must hold
    against. The right-hand side goes to dy, aux; cs is left as it was."""
    cs = sys.cs
    mode = cs[CS_MODE]
    if mode == SLAVED and slip_fast_reached(t, y, sys):
        cs[CS_MODE] = SLIDE
    need = needed_sigma(i, t, y, sys, dy, aux)
    cs[CS_MODE] = mode
    return need


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
def stick_at_spin_tol(i, t, y, sys):
    """A free component has slowed to |omega.a_i| = spin_tol: if it goes on to rest and the moment
    can hold it there (spin_sticks), it sticks, and the rate left is stopped by an impulsive contact
    moment (impulse.stop_axis_rate, its energy booked to k_i), where the moment must hold it as well.
    Else it stays free with its sign (it will cross 0, where the Filippov rule decides, or speed up
    again). Returns whether it stuck."""
    p, cs, wk, istats = sys.p, sys.cs, sys.wk, sys.istats
    if not spin_sticks(i, t, y, sys):
        return False
    w1, w2, w3, u1, u2 = y[Y_W1], y[Y_W2], y[Y_W3], y[Y_U1], y[Y_U2]
    cs[CS_STUCK + i] = 1.0
    loss = stop_axis_rate(y, p, cs, i, wk[W_SCRATCH:W_SCRATCH + 7])
    # the stop changes the velocity (and, sliding, the slip): the moment must hold the component at
    # the state it leaves too, where every later decision (settle_signs) reads it, in the mode it
    # reads it in (a slaved slip that the stop carries past its exit slides); else no stick
    if abs(holding_sigma(i, t, y, sys, wk[W_DYTMP], wk[W_AUXTMP])) < 1.0:
        y[Y_DK1 + i] += loss
        istats[I_STICK] += 1
        return True
    y[Y_W1], y[Y_W2], y[Y_W3], y[Y_U1], y[Y_U2] = w1, w2, w3, u1, u2
    cs[CS_STUCK + i] = 0.0
    return False


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


@kernel
def reads_forces(k):
    """Does event k's function read the right-hand side's aux (events.EVENTS[k, E_FORCES])? The
    others are functions of the state alone: on a step's dense output they cost no right-hand-side
    evaluation (state_event_value)."""
    return EVENTS[k, E_FORCES] != 0


@kernel
def state_event_value(k, t, y, p, cs, lev):
    """g_k of an active event that does not read the forces (not reads_forces(k)); raises for any
    other id."""
    if EV_SIGN1 <= k <= EV_SIGN3 or EV_SPIN1 <= k <= EV_SPIN3:
        i = EVENTS[k, E_COMPONENT]
        r1, r2, r3 = moment_axes_rates(y)
        g = cs[CS_SIG + i] * (r1 if i == 0 else (r2 if i == 1 else r3))
        return g if k <= EV_SIGN3 else g - p[P_WTOL]
    if k == EV_SIDE:
        return cs[CS_SIDE] * y[Y_ALPHA]
    if k == EV_FACE:
        return (0.5 * math.pi - abs(y[Y_ALPHA])) - BETA_FACE
    if k == EV_LEVEL:
        return mode_energy(y, p, cs) - lev
    raise ValueError("state_event_value: an event id with no value of the state alone")


@kernel
def event_values(t, y, aux, p, cs, lev, g):
    """g[k] for every event k (inf where not active). `aux` must belong to `y`."""
    for k in range(N_EVENTS):
        g[k] = math.inf
    k = (p[P_K1], p[P_K2], p[P_K3])
    for i in range(3):
        if k[i] > 0.0:
            if cs[CS_STUCK + i] == 1.0:
                g[EV_UNSTICK1 + i] = 1.0 - abs(aux[X_SIG1 + i])
            else:
                # omega.a_i from the RHS: the same arithmetic as state_event_value, without a sine
                g[EV_SIGN1 + i] = cs[CS_SIG + i] * aux[X_G1 + i]
                if p[P_WTOL] > 0.0:
                    g[EV_SPIN1 + i] = g[EV_SIGN1 + i] - p[P_WTOL]
    mode = cs[CS_MODE]
    if mode == ROLL:
        g[EV_CONE] = p[P_MUS] * aux[X_PHI] - math.hypot(aux[X_F1], aux[X_F2])
    elif mode == SLIDE:
        if cs[CS_SLAVE_OFF] != SLOW_OFF:
            g[EV_SLIP_SLOW] = math.hypot(y[Y_U1], y[Y_U2]) - slip_floor(t, aux, p, cs)
        if cs[CS_SLAVE_OFF] == HANDOVER_ARMED:
            g[EV_SLAVE] = math.hypot(y[Y_U1], y[Y_U2]) - slave_speed(y, aux, p)
        elif cs[CS_SLAVE_OFF] == AT_FLOOR:
            # refused for its error at the slaving speed: handed over at the floor's, or re-armed
            # where fast again
            g[EV_SLAVE] = math.hypot(y[Y_U1], y[Y_U2]) - max(p[P_UTOL], SLAVE_FLOOR * p[P_MUD] * aux[X_PHI])
            g[EV_SLIP_FAST] = exit_speed(y, aux, p) - math.hypot(y[Y_U1], y[Y_U2])
        else:
            # the hand-over is off (no quasi-static direction to settle on, or the slip passed it
            # by) until the slip is fast again: SLAVE_EXIT times the slaving speed, as a slaved
            # slip's exit; a slip that reverses and later decays is handed over then
            g[EV_SLIP_FAST] = exit_speed(y, aux, p) - math.hypot(y[Y_U1], y[Y_U2])
    else:
        # the slip along the slaved direction at this state (the RHS's): reaches 0 where the slip ends
        g[EV_SLIP_STOP] = y[Y_U1] * math.cos(aux[X_NU] + aux[X_LAG]) + y[Y_U2] * math.sin(aux[X_NU] + aux[X_LAG])
        g[EV_SLIP_FAST] = slaved_margin(y, aux, p)
        g[EV_SLAVE_LOST] = -aux[X_DCROSS]
    g[EV_CONTACT] = aux[X_PHI]
    g[EV_SIDE] = state_event_value(EV_SIDE, t, y, p, cs, lev)
    g[EV_FACE] = state_event_value(EV_FACE, t, y, p, cs, lev)
    if not math.isnan(lev):
        g[EV_LEVEL] = mode_energy_at(y, aux, p, cs) - lev   # state_event_value's, from aux


@kernel
def slaved_margin(y, aux, p):
    """EV_SLIP_FAST of a slaved slip: > 0 while the slip is below its exit speed (exit_speed) and
    the slaved direction's error (aux[X_SLAVE_ERR]) below SLAVE_EXIT times slave_tol, or the slip
    below FLOOR_EXIT times the floor's speed SLAVE_FLOOR mu_d Phi; each as a fraction of its
    bound."""
    u = math.hypot(y[Y_U1], y[Y_U2])
    margin = 1.0 - u / exit_speed(y, aux, p)
    if p[P_SLAVE] > 0.0:
        # (within FLOOR_EXIT times the floor's speed the slip stays slaved whatever the error)
        floor = 1.0 - u / (FLOOR_EXIT * SLAVE_FLOOR * p[P_MUD] * max(aux[X_PHI], 0.0))
        margin = min(margin, max(floor, 1.0 - aux[X_SLAVE_ERR] / (SLAVE_EXIT * p[P_SLAVE])))
    return margin


@kernel
def end_slip(y, sys):
    """SLIDE -> ROLL: a plastic contact impulse removes the slip (its energy goes to sliding); for
    a slip that ends at the round-off floor or spirals in (slow_slide)."""
    p, cs, wk = sys.p, sys.cs, sys.wk
    side = int(cs[CS_SIDE])
    y[Y_DSLIDE] += project_velocity(y, p, side, True, side, False, wk[W_SCRATCH:W_SCRATCH + 7])
    cs[CS_MODE] = ROLL


@kernel
def moment_event(k, t, y, sys):
    """The update of one dry-friction moment component at its event k: a sign flip or a stick
    (EV_SIGN*), a stick where neither sign holds (EV_AGAINST*), a stick at spin_tol (EV_SPIN*) or a
    release (EV_UNSTICK*). Returns (own, held): own, the component this event put on its surface
    (settle_signs leaves it; -1: none); held, True where a stop at spin_tol holds the stuck
    components, so that the rates after it are those that release_moved compares with."""
    cs, wk, istats = sys.cs, sys.wk, sys.istats
    i = EVENTS[k, E_COMPONENT]
    if EV_SIGN1 <= k <= EV_SIGN3:
        stick_or_flip(i, t, y, sys)
        return -1, False
    if EV_AGAINST1 <= k <= EV_AGAINST3:
        # neither sign holds (the one just set fails at once, the other opposes the motion):
        # the Filippov solution stays on omega.a_i = 0
        sig_failed = cs[CS_SIG + i]
        stick_or_flip(i, t, y, sys)
        if cs[CS_STUCK + i] == 0.0 and cs[CS_SIG + i] == sig_failed:
            cs[CS_STUCK + i] = 1.0
            istats[I_STICK] += 1
            return i, False
        return -1, False
    if EV_SPIN1 <= k <= EV_SPIN3:
        return -1, stick_at_spin_tol(i, t, y, sys)
    if EV_UNSTICK1 <= k <= EV_UNSTICK3:
        eval_rhs(t, y, sys, wk[W_DYTMP], wk[W_AUXTMP])
        cs[CS_SIG + i] = 1.0 if wk[W_AUXTMP, X_SIG1 + i] > 0.0 else -1.0
        cs[CS_STUCK + i] = 0.0
        return i, False
    raise ValueError("moment_event: an event id of class C_MOMENT with no update")


@kernel
def slip_event(k, t, y, sys):
    """The update of the contact's slip at its event k (EV_CONE .. EV_SLAVE, EV_SLAVE_LOST): the
    onset of a slip, its fate below slip_tol or its end along the slaved direction, the hand-over to and from
    the slaved direction. Returns the outcome code that ends the scene, or -1."""
    p, cs, wk = sys.p, sys.cs, sys.wk
    if k == EV_CONE:
        start_slip(t, y, sys)
        cs[CS_SLAVE_OFF] = HANDOVER_ARMED
    elif k == EV_SLIP_SLOW:
        return slow_slide(t, y, sys)
    elif k == EV_SLIP_STOP:
        # the slip speed along the slaved direction is 0; what the integration left of the slip
        # (its error) is removed by the plastic impulse, so the energy books stay exact
        side = int(cs[CS_SIDE])
        y[Y_DSLIDE] += project_velocity(y, p, side, True, side, False, wk[W_SCRATCH:W_SCRATCH + 7])
        cs[CS_MODE] = ROLL
    elif k == EV_SLIP_FAST:
        cs[CS_MODE] = SLIDE
        cs[CS_SLAVE_OFF] = HANDOVER_ARMED
    elif k == EV_SLAVE:
        return try_slave(t, y, sys)
    elif k == EV_SLAVE_LOST:
        # the quasi-static direction folds away: the slip direction follows its own dynamics
        cs[CS_MODE] = SLIDE
        cs[CS_SLAVE_OFF] = HANDOVER_OFF
    else:
        raise ValueError("slip_event: an event id of class C_SLIP with no update")
    return -1


@kernel
def apply_event(k, t, y, sys, fstats):
    """Discrete update at a located event k (state y at the event, changed in place): the event's
    own update (moment_event, slip_event, side_change), then what every update owes the state
    (settle_event). The caller counts the roll<->slip transition it makes (count_transition); stick
    phases are counted where a component sticks.

    Returns the outcome code that ends the scene, or -1 to continue. The caller re-evaluates the
    right-hand side and the event functions afterwards. Raises for an event with no discrete update
    (the level's, C_LEVEL) or of a class it does not know.
    """
    g_before = moment_axes_rates(y)
    own = -1   # the component this event puts on its surface (settle_signs)
    cls = EVENTS[k, E_CLASS]
    if cls == C_MOMENT:
        own, held = moment_event(k, t, y, sys)
        if held:
            g_before = moment_axes_rates(y)   # the stop holds the stuck components: they stay stuck
    elif cls == C_CONTACT_LOST:
        return oc.CONTACT_LOST
    elif cls == C_FACE:
        return oc.FACE_CONTACT   # the caller records it as a halt
    elif cls == C_SIDE:
        return side_change(t, y, sys, fstats)
    elif cls == C_SLIP:
        code = slip_event(k, t, y, sys)
        if code >= 0:
            return code
    else:
        raise ValueError("apply_event: an event class with no discrete update")
    return settle_event(t, y, sys, g_before, own)


@kernel
def count_transition(rolling, cs, istats):
    """A roll<->slip transition where the contact rolled before a discrete update (rolling) and
    slips after it (cs), or the reverse. A slide that ends and, its cone violated, slips again at
    once within one update never rolled: it has passed through u = 0, and counts as the passage it
    is, whether its fate was read as an end or as a passage (docs/model.md, 'Where a slip ends')."""
    if rolling != (cs[CS_MODE] == ROLL):
        istats[I_TRANS] += 1


@kernel
def settle_event(t, y, sys, g_before, own):
    """What every discrete update owes the state: a slip that it left at or past EV_SLIP_FAST's
    surface (a slaved slip at SLAVE_EXIT times the slaving speed, or its direction's error measure
    at SLAVE_EXIT times slave_tol: slaved_margin) is fast (slip_event: SLIDE, the hand-over
    re-armed); a slide at or below slip_tol meets its fate (slow_slide); the moment
    components that the update moved are released (release_moved: g_before, omega.a_i before it)
    and every sign made consistent (settle_signs, leaving component own); a rolling state left
    outside the static cone starts to slip. Returns the outcome that ends the scene, else -1."""
    p, cs, wk = sys.p, sys.cs, sys.wk
    if slip_fast_reached(t, y, sys):
        slip_event(EV_SLIP_FAST, t, y, sys)
    if cs[CS_MODE] == SLIDE and cs[CS_SLAVE_OFF] != SLOW_OFF:
        eval_rhs(t, y, sys, wk[W_DYTMP], wk[W_AUXTMP])
        if math.hypot(y[Y_U1], y[Y_U2]) <= slip_floor(t, wk[W_AUXTMP], p, cs):
            # the slip reached its floor within the located event's bracket (a stiff slip decays
            # by orders of magnitude in 1e-11 tau): its own event can no longer happen
            code = slow_slide(t, y, sys)
            if code >= 0:
                return code
    release_moved(y, p, cs, g_before)
    settle_signs(t, y, sys, own)
    # a rolling state must be admissible after every discrete update: a moment sign that flips or
    # sticks changes the friction that rolling needs, and it may jump outside the static cone
    if cs[CS_MODE] == ROLL and cone_violated(t, y, sys):
        start_slip(t, y, sys)
        # the slip changes the moments the stuck components need
        # (a component the Filippov rule held is tested again: the slip changed its dynamics)
        settle_signs(t, y, sys, own if own >= 0 and cs[CS_STUCK + own] == 0.0 else -1)
    return -1


@kernel
def side_change(t, y, sys, fstats):
    """alpha = 0: plastic impact of the other rim edge, which releases every held moment component;
    after it each free sign is that of its omega.a_i, an exact 0 gets the stick test
    (consistent_signs), and a rolling contact outside the static cone starts to slip. Ends the scene
    (line contact) when no rotation towards the new side is left, or when two impacts come within
    ZENO_DTAU (the rocking between the edges has collapsed into a Zeno sequence of impacts)."""
    p, cs, wk, istats = sys.p, sys.cs, sys.wk, sys.istats
    mode = cs[CS_MODE]
    side = cs[CS_SIDE]
    loss = project_velocity(y, p, int(side), mode != ROLL, int(-side), mode != ROLL, wk[W_SCRATCH:W_SCRATCH + 7])
    fstats[F_DIMPACT] += loss
    cs[CS_SIDE] = -side
    istats[I_IMPACTS] += 1
    y[Y_ALPHA] = 0.0
    for i in range(3):
        cs[CS_STUCK + i] = 0.0
    zeno = t - fstats[F_TIMPACT] < ZENO_DTAU
    fstats[F_TIMPACT] = t
    if y[Y_W1] * cs[CS_SIDE] <= 0.0 or zeno:
        return oc.LINE_CONTACT   # the disk stands on its flat edge
    if mode != ROLL:
        code = set_slip(t, y, sys)
        if code >= 0:
            return code
    consistent_signs(t, y, sys)
    if mode == ROLL and cone_violated(t, y, sys):
        start_slip(t, y, sys)
    return -1
