"""The hybrid integrator: one scene, DOP853 steps of the current smooth mode, located events.

`run` (numba, no allocation) steps the current contact state, scans the accepted step for events,
locates the earliest on the dense output, restarts there with the new discrete state (keeping the
step size) and records what the scene asked for. Every discrete decision is taken in
event_dispatch.apply_event from the state at the located event; the step size, rtol and atol only decide
where the steps fall. `integrate` (Python) allocates the buffers and names the outputs.
"""
from __future__ import annotations

import math
from collections import namedtuple

import numpy as np

from .. import outcomes as oc
from .constants import EPS, ROLL, SLAVED
from .contact import (cone_violated, confirm_slaved, consistent_signs, eval_rhs, mode_energy, mode_energy_at, set_slip,
                      spin_sticks, start_slip)
from .controller import accepted_step_factor, step_factor
from .dop853 import ERR_EXPONENT, N_DENSE, dense_eval, error_norm, initial_step, rk_step
from .event_dispatch import apply_event, event_values
from .event_ids import EVENTS, EV_AGAINST1, EV_LEVEL, N_DYN_EVENTS
from .event_rules import count_transition
from .events import (C_MOMENT, D_RATES, D_SIDE, D_SIGN, D_SLIP, E_CLASS, E_COMPONENT, E_DIP, E_HOLDS, E_RESTART, R_SPIN,
                     R_SURFACE)
from .frequency import FQ_COLS, FQ_LEVEL0, finish_levels, freq_start
from .jit import kernel
from .layout import (CS_MODE, CS_NU, CS_SIDE, CS_SIG, CS_STUCK, F_APPROACH, F_DIMPACT, F_E0, F_EEND, F_HLAST,
                     F_SLIDETIME, F_TEND, F_THALT, F_THALT_ERR, F_TIMPACT, I_EVENTS, I_FLAT, I_IMPACTS, I_OUTCOME,
                     I_OVERFLOW, I_PEAKS, I_REJECTED, I_SLIDE_REJECTED, I_SLIDE_STEPS, I_STEPS, I_STICK, I_TRAJ,
                     I_TRANS, LEVEL_COLS, L_PENDING, N_CS, N_FSTATS, N_ISTATS, N_KROWS, N_TRACK, N_WCOLS, N_WORK,
                     PEAK_COLS, Point, Record, RunConsts, SAMPLE_COLS, S_ATOL, S_HMAX, S_KIN, S_MAXSTEPS, S_PEAKS,
                     S_RTOL, S_TMAX, Segment, Span, System, TRAJ_COLS, T_CUT, T_DEEP_E, T_DIMPACT_HALT, T_DIP_END,
                     T_END_IMPACTS, T_END_STICK, T_END_TRANS, T_H_AFTER, T_NEXT_LEVEL, T_NEXT_SAMPLE, T_PENDING,
                     T_PHI_B, T_RATES_NEW, T_RATES_OLD, T_T_AFTER, W_AUX, W_AUXBUF, W_AUXNEW, W_DELTA, W_DYBUF,
                     W_ESCALE, W_F, W_FNEW, W_GNEW, W_GOLD, W_RATENEW, W_RATEOLD, W_YBUF, W_YNEW, W_YSEG, Work)
from .model import (N_AUX, N_CORE, N_FULL, N_PARAMS, N_THETA, P_G, P_H, P_UTOL, X_COSA, X_NU, X_OK, X_PHI, X_SINA,
                    Y_ALPHA, Y_DK1, Y_DK2, Y_DK3, Y_DSLIDE, Y_THETA, Y_U1, Y_U2, Y_W1, Y_W2, Y_W3,
                    energy_increment_trig, energy_rate_trig)
from .roots import (brent_min, event_rates, event_value_at, hermite_dip, hermite_peak, locate, location_tol,
                    reads_forces, sign_slopes, slip_closest_approach, span_state)
from .tableau import N_STAGES
from .tracking import (deep_levels, deep_pending, dense_wanted, halt_flat, record_levels, record_sample, record_samples,
                       record_traj, start_deep_levels, step_dense, track_frequency)

# A step may not raise the energy by more than ENERGY_GUARD * rtol * E(0): the true energy never
# increases, so such a step is an instability the error estimate did not see; it is rejected.
ENERGY_GUARD = 10.0
# A step's energy balance, E + dissipated, may move by at most BALANCE_FACTOR * rtol times what the
# step dissipates plus its share h / tau_max of E(0). Summed over a scene that is at most
# 2 BALANCE_FACTOR rtol E(0) (nothing dissipates more than E(0)): the budget closes to 1e-9 E(0) at
# the default rtol 1e-10 (the componentwise error norm alone lets through a bias of the
# 8th-order step in the energy, one sign over 1e5 steps). The balance is taken on the step's
# increment before rounding, in difference form (model.energy_increment), so its own round-off,
# BALANCE_ROUNDOFF times its scale, is relative to the change; what the rounding of the state adds
# is a random walk, ~sqrt(steps) EPS G (docs/model.md, 'Energy and the dissipation budget').
BALANCE_FACTOR = 4.0
# The increment's own round-off: its stages are summed with weights whose magnitudes add to ~12.4
# (dop853's b), so each component carries up to ~12 EPS of itself, and the change that many EPS of
# the scale of energy_increment (measured: up to 5 EPS); a floor that round-off could exceed would
# reject every shorter step alike (both scale with the step), so it is set well above.
BALANCE_ROUNDOFF = 32.0 * EPS
STATE_BALANCE_ROUNDOFF = 4.0 * EPS
# The right-hand side's own round-off in the energy direction (power_defect: what dE/dtau plus the
# dissipated power leaves of 0 at a step's ends) enters the increment as h times a weighted sum of
# its values at the stages; the floor takes DEFECT_FACTOR times the larger end value. Near flat the
# gyroscopic terms (tan(alpha) ~ 1e6) carry it far above the energy's own round-off, and it scales
# with h like a step's dissipation, so without it every shorter step failed alike (slides at
# beta ~ 1e-6 ended in step_size_underflow at rtol 1e-12, 1e-13: docs/model.md, 'Energy and the
# dissipation budget').
DEFECT_FACTOR = 16.0

# Within SLIP_NEAR x slip_tol of u = 0 the slip components are held to rtol SLIP_NEAR slip_tol rather
# than atol: there the physics decides by |u| against slip_tol (a slip passing by 0 stops if it
# comes within slip_tol, else reverses), and atol (1e-12 by default, ~1e-4 of slip_tol in u_hat)
# left that decision to the error of the step: whether a near-reversal stuck moved with rtol.
SLIP_NEAR = 100.0
# The slip is the contact point's velocity, a difference of O(|omega|) terms: its round-off, and its
# step's round-off in the error estimate, is ~EPS |omega|. A tolerance below it failed every shorter
# step alike (a random-scene harness run at rtol 1e-13 ended in step_size_underflow that way).
SLIP_ROUNDOFF = 4.0 * EPS

# A dip whose dense-output value at the cubic Hermite minimum is below DIP_REFINE times the lower end
# value is searched for its true minimum (roots.brent_min) before it is ruled out.
DIP_REFINE = 0.1

KernelOutput = namedtuple("KernelOutput", "istats fstats levels samples trajectory peaks y_end")


@kernel
def failure_outcome(ok):
    """Outcome for a right-hand side that failed: the model's Painleve flag (-1) or a slaved
    direction that did not converge (0)."""
    return oc.PAINLEVE if ok < 0.0 else oc.NUMERICAL_ERROR


@kernel
def start(y, sys):
    """Initial discrete state of the system sys (layout.System) at y: moment signs, slip mode, and
    slip onset if rolling cannot hold. Returns the outcome that ends the scene at once (set_slip),
    else -1."""
    cs = sys.cs
    cs[CS_SIDE] = 1.0 if y[Y_ALPHA] > 0.0 else -1.0
    for i in range(3):
        cs[CS_SIG + i] = 1.0
        cs[CS_STUCK + i] = 0.0
    rolling = y[Y_U1] == 0.0 and y[Y_U2] == 0.0
    if not rolling:
        code = set_slip(0.0, y, sys)
        if code >= 0:
            return code
    else:
        cs[CS_MODE] = ROLL
    consistent_signs(0.0, y, sys)
    if cs[CS_MODE] == ROLL and cone_violated(0.0, y, sys):
        start_slip(0.0, y, sys)
    # a scene that starts rolling and slips at once has its transition
    count_transition(rolling, cs, sys.istats)
    return -1


@kernel
def lift_off(k, span, g0, d0, g1, d1, lev):
    """On the step span (layout.Span: [t, t + h] from its y0, dense output built) that starts on
    event k's surface (g0 <= 0, just after a discrete update put the state there) and ends with
    g1 <= 0: a time where g_k > 0 and its value, to bracket a return to the surface within the step;
    (-1, 0) if there is none. d0, d1: exact end derivatives of g_k per unit of the step. Starts at
    the peak of the cubic Hermite interpolant of g_k; where g_k leaves the surface upwards (d0 > 0)
    it halves towards t, where g_k ~ g0 + d0 x > 0. lev: the next level's energy.
    """
    t, h = span.t0, span.h
    x = hermite_peak(g0, d0, g1, d1)
    tries = 60 if d0 > 0.0 else 1
    if x <= 0.0:
        if d0 <= 0.0:
            return -1.0, 0.0
        x = 0.5
    for _ in range(tries):
        gm = event_value_at(k, t + x * h, span, lev)
        if gm > 0.0:
            return t + x * h, gm
        x *= 0.5
    return -1.0, 0.0


@kernel
def first_event(span, lev, work):
    """Earliest event on the accepted step span (layout.Span: [t, t + h] from work.y; its end state,
    derivatives and event values in wk: W_YNEW, W_F, W_FNEW, W_GOLD, W_GNEW; lev: the next level's
    energy): (k, restart time, dense output made?).

    An event function that is positive at both ends can still cross zero twice inside the step
    (dip_bracket); one that starts on its surface can leave it and come back (surface_bracket,
    spin_bracket). The rates at the step end are kept for the next step's start
    (trk[T_RATES_OLD]), so a step costs one RHS evaluation for them.
    """
    t, h = span.t0, span.h
    wk, trk = work.wk, work.trk
    g_old = wk[W_GOLD]
    g_new = wk[W_GNEW]
    have_dense = False
    trk[T_RATES_NEW] = 0.0
    trk[T_DIP_END] = -1.0
    first_k = -1
    first_t = t + h
    for k in range(N_DYN_EVENTS):
        k_event = k
        dip_end = -1.0
        ta = -1.0
        ga = 0.0
        tb = 0.0
        gb = 0.0
        if g_old[k] > 0.0 and g_new[k] <= 0.0:
            ta, ga, tb, gb = t, g_old[k], t + h, g_new[k]
        elif EVENTS[k, E_RESTART] == R_SURFACE and g_old[k] <= 0.0 and g_new[k] <= 0.0:
            # the step starts on the surface (alpha = 0 after a side change; a moment component
            # released at an un-stick, omega.a_i = 0 up to its drift while held) and ends on or
            # past it: it left and came back within the step (a rocking bounce), or it never left
            have_dense = dense_built(have_dense, span, work)
            ta, ga, tb, gb, k_event = surface_bracket(k, span, lev, work)
        elif EVENTS[k, E_RESTART] == R_SPIN and g_old[k] <= 0.0 and g_new[k] <= 0.0:
            ta, ga, have_dense = spin_bracket(k, span, lev, work, have_dense)
            tb, gb = t + h, g_new[k]
        elif g_old[k] > 0.0 and g_new[k] > 0.0 and g_old[k] != math.inf and g_new[k] != math.inf:
            tm, gm, have_dense = dip_bracket(k, span, lev, work, have_dense)
            if tm >= 0.0:
                ta, ga, tb, gb = t, g_old[k], tm, gm
                if reads_forces(k):
                    dip_end = tm
        if ta >= 0.0 and ta < first_t:
            have_dense = dense_built(have_dense, span, work)
            ra, rb = locate(k, ta, ga, tb, gb, span, lev)
            if (rb < first_t or first_k < 0) and (EVENTS[k, E_HOLDS] == 0
                                                  or spin_holds(EVENTS[k, E_COMPONENT], rb, span)):
                first_k = k_event
                first_t = rb
                trk[T_DIP_END] = dip_end
    return first_k, first_t, have_dense


@kernel
def dense_built(have_dense, span, work):
    """The accepted step's dense output in F[0:7] (the step span, layout.Span, from work.y to
    wk[W_YNEW]), built once per step: returns True."""
    if not have_dense:
        step_dense(span.t0, span.y0, span.h, work.wk[W_YNEW], span.sys, work.K, span.F)
    return True


@kernel
def surface_bracket(k, span, lev, work):
    """Event k (the side, or a moment sign) on the step span (layout.Span: [t, t + h] from work.y)
    that starts on its surface and ends on or past it (dense output built): a bracket (ta, ga, tb,
    gb) of its return to the surface, and the event to apply there (k, or EV_AGAINST1 + i for a
    component moving against its sign)."""
    t, h = span.t0, span.h
    y, cs, wk = work.y, work.cs, work.wk
    g0 = wk[W_GOLD, k]
    g1 = wk[W_GNEW, k]
    y_new = wk[W_YNEW]
    i = EVENTS[k, E_COMPONENT]
    if EVENTS[k, E_DIP] == D_SIDE:
        # g = side alpha, dg/dtau = side omega_1 (eq. 2.3)
        d0 = cs[CS_SIDE] * y[Y_W1] * h
        d1 = cs[CS_SIDE] * y_new[Y_W1] * h
    else:
        d0, d1 = sign_slopes(i, cs[CS_SIG + i], y, wk[W_F], y_new, wk[W_FNEW], h)
    ta, ga = lift_off(k, span, g0, d0, g1, d1, lev)
    tb, gb = t + h, g1
    k_event = k
    moment = EVENTS[k, E_CLASS] == C_MOMENT
    if ta < 0.0 and moment and g0 < 0.0 and d0 > 0.0:
        # released with omega.a_i on the far side of its new sign (an impulse's residual, below
        # spin_tol) and moving towards it, as its sign says: no event while it rises (however
        # short the step); turned back below the surface inside the step, it moves against its
        # sign from that turning point on
        x_turn = hermite_peak(g0, d0, g1, d1) if d1 <= 0.0 else -1.0
        if x_turn > 0.0:
            ta, tb = t + x_turn * h, t + x_turn * h
            k_event = EV_AGAINST1 + i
    elif ta < 0.0:
        # it never leaves: at once (a moment component moving against its new sign means the
        # un-stick only grazed |sigma| = 1: apply_event sticks it)
        ta, tb = t, t
        if moment:
            k_event = EV_AGAINST1 + i
    return ta, ga, tb, gb, k_event


# spin_bracket and dip_bracket are inlined into first_event, their one caller: they run for every
# active event on every step, and a call passes the step's span and work groups (~100 words).
@kernel(inline="always")
def spin_bracket(k, span, lev, work, have_dense):
    """A free component slower than spin_tol at both ends of the step span (layout.Span: [t, t + h]
    from work.y; e.g. just released at an un-stick) can speed past spin_tol and slow to it again
    within the step: the peak of the Hermite interpolant of g_k (exact end slopes), confirmed on
    the dense output. Returns (the peak's time, g_k there, have_dense); the time is -1 where g_k
    stays below spin_tol."""
    t, h = span.t0, span.h
    y, cs, wk = work.y, work.cs, work.wk
    i = EVENTS[k, E_COMPONENT]
    d0, d1 = sign_slopes(i, cs[CS_SIG + i], y, wk[W_F], wk[W_YNEW], wk[W_FNEW], h)
    peak = hermite_peak(wk[W_GOLD, k], d0, wk[W_GNEW, k], d1)
    if peak > 0.0:
        have_dense = dense_built(have_dense, span, work)
        gm = event_value_at(k, t + peak * h, span, lev)
        if gm > 0.0:
            return t + peak * h, gm, have_dense
    return -1.0, 0.0, have_dense


@kernel(inline="always")
def dip_bracket(k, span, lev, work, have_dense):
    """Event k positive at both ends of the step span (layout.Span: [t, t + h] from work.y) can
    still reach 0 and come back within it: a bounce off alpha = 0, a brief slip demand, a needed
    moment that touches its limit, a dip of the normal force. The cubic Hermite interpolant of g_k
    flags the dip; the dense output confirms it. Returns (the time of the dip's minimum where g_k
    <= 0 there, g_k there, have_dense); the time is -1 where there is no such dip."""
    t, h = span.t0, span.h
    y, cs, wk, trk = work.y, work.cs, work.wk, work.trk
    g0 = wk[W_GOLD, k]
    g1 = wk[W_GNEW, k]
    f = wk[W_F]
    y_new = wk[W_YNEW]
    f_new = wk[W_FNEW]
    how = EVENTS[k, E_DIP]
    if how == D_SIDE:
        # g = side alpha, dg/dtau = side omega_1 (eq. 2.3)
        dip = hermite_dip(g0, cs[CS_SIDE] * y[Y_W1] * h, g1, cs[CS_SIDE] * y_new[Y_W1] * h)
    elif how == D_SIGN:
        # sigma_i omega.a_i (less spin_tol): exact slopes from the state
        i = EVENTS[k, E_COMPONENT]
        d0, d1 = sign_slopes(i, cs[CS_SIG + i], y, f, y_new, f_new, h)
        dip = hermite_dip(g0, d0, g1, d1)
    elif how == D_SLIP:
        # |u| less a speed: a V where the slip passes by u = 0, placed from the slip's own smooth
        # components (a cubic in g, or its difference quotient, can step over it)
        dip = slip_closest_approach(y, f, y_new, f_new, h)
    elif how == D_RATES:
        if trk[T_RATES_OLD] == 0.0:
            event_rates(t, y, f, wk[W_GOLD], wk[W_RATEOLD], lev, span.sys)
            trk[T_RATES_OLD] = 1.0
        if trk[T_RATES_NEW] == 0.0:
            event_rates(t + h, y_new, f_new, wk[W_GNEW], wk[W_RATENEW], lev, span.sys)
            trk[T_RATES_NEW] = 1.0
        dip = hermite_dip(g0, wk[W_RATEOLD, k] * h, g1, wk[W_RATENEW, k] * h)
    else:
        raise ValueError("dip_bracket: an event of the dynamics with no way to bracket a dip (E_DIP)")
    if not dip > 0.0:
        return -1.0, 0.0, have_dense
    have_dense = dense_built(have_dense, span, work)
    tm = t + dip * h
    gm = event_value_at(k, tm, span, lev)
    if 0.0 < gm < DIP_REFINE * min(g0, g1):
        # the cubic's minimum is only near the dense output's: a shallow dip (a grazing double
        # crossing) is decided by the minimum of g_k itself
        tm, gm = brent_min(k, t, t + h, 0.0, span, lev)
    if gm <= 0.0:
        return tm, gm, have_dense
    return -1.0, 0.0, have_dense


@kernel
def spin_holds(i, t_event, span):
    """Would free component i stick at its spin event at t_event on span's dense output
    (contact.spin_sticks, the test contact.stick_at_spin_tol makes)? Where it would not, the event
    changes nothing, and the step goes on instead of restarting there (the same trajectory, fewer
    restarts)."""
    sys = span.sys
    span_state(t_event, span)
    return spin_sticks(i, t_event, sys.wk[W_YBUF], sys)


@kernel
def power_defect(y, dy, aux, p, cs):
    """|dE/dtau + dissipated power| of the evaluated right-hand side dy, aux at y: 0 for the exact
    flow, so what is left is the right-hand side's own round-off in the energy direction."""
    rate = energy_rate_trig(y, dy, p, cs[CS_SIDE], cs[CS_MODE] != ROLL, aux[X_SINA], aux[X_COSA])
    return abs(rate + dy[Y_DSLIDE] + dy[Y_DK1] + dy[Y_DK2] + dy[Y_DK3])


@kernel
def balance_error(y, aux, d, h, defect, p, cs, consts):
    """The energy-balance residual |Delta(E + dissipated)| of a step's increment d (before rounding:
    wk[W_DELTA]) from y (aux: the right-hand side's there) over h, over what it may be (see
    BALANCE_FACTOR); accepted if <= 1. defect: power_defect at the step's ends (the larger); of the
    run's constants (layout.RunConsts) e0 = |E(0)| > 0, t_max (tau) and rtol."""
    change, scale = energy_increment_trig(y, d, p, cs[CS_SIDE], cs[CS_MODE] != ROLL, aux[X_SINA], aux[X_COSA])
    dissipated = d[Y_DSLIDE] + d[Y_DK1] + d[Y_DK2] + d[Y_DK3]
    allowed = (BALANCE_FACTOR * consts.rtol * (max(dissipated, 0.0) + consts.e0 * h / consts.t_max)
               + BALANCE_ROUNDOFF * (scale + abs(d[Y_DSLIDE]) + abs(d[Y_DK1]) + abs(d[Y_DK2]) + abs(d[Y_DK3]))
               + DEFECT_FACTOR * abs(h) * defect)
    return abs(change + dissipated) / allowed


@kernel
def state_balance_error(y, y_new, e_cur, e_new, h, p, consts):
    """balance_error of the kept part of a step cut at an event, from the states at its ends (the
    dense output's increment carries the round-off of its coefficients, not of the change).

    The residual's round-off, in units of EPS: E and the dissipated energy; the height's terms
    G cos(alpha) (1 + |h|), which cancel near upright for a thick disk; and the inclination's last
    bit times dE/dalpha ~ G (|sin alpha| + |h| cos(alpha)) + omega_1^2 (1 + |h|), which dominates
    near flat, where E << G. Once per event, this floor adds to the budget at most the events'
    number times it."""
    d_cur = y[Y_DSLIDE] + y[Y_DK1] + y[Y_DK2] + y[Y_DK3]
    d_new = y_new[Y_DSLIDE] + y_new[Y_DK1] + y_new[Y_DK2] + y_new[Y_DK3]
    residual = (e_new + d_new) - (e_cur + d_cur)
    a = abs(y[Y_ALPHA])
    c = abs(math.cos(a))
    habs = p[P_H]
    w1 = y[Y_W1]
    roundoff = (abs(e_cur) + abs(d_cur) + p[P_G] * (c * (1.0 + habs) + a * (abs(math.sin(a)) + habs * c))
                + a * w1 * w1 * (1.0 + habs))
    allowed = (BALANCE_FACTOR * consts.rtol * (max(d_new - d_cur, 0.0) + consts.e0 * h / consts.t_max)
               + STATE_BALANCE_ROUNDOFF * roundoff)
    return abs(residual) / allowed


@kernel
def try_step(t, h, consts, work, sys):
    """One DOP853 step of size h from work.y, f = wk[W_F] (wk[W_AUX]: the right-hand side's aux
    there) into wk[W_YNEW], wk[W_FNEW], wk[W_AUXNEW], in the system sys (layout.System); returns
    its error norm (inf for a step with a non-finite stage or end state, or one that raises the
    energy by more than ENERGY_GUARD rtol e0), at least its energy-balance error (balance_error;
    consts: layout.RunConsts), and counts it.

    Every stage is checked, also those whose tableau weight in y_new or the error estimate is zero
    (stages 1-4, and f_new): a right-hand side that failed there (a slaved direction that lost its
    root returns NaN) makes the step fail, so steps shrink until the event that ends the mode is
    located; accepted, its NaN f_new would poison every later step."""
    y, p, cs, wk, K = work.y, work.p, work.cs, work.wk, work.K
    rtol, atol, n = consts.rtol, consts.atol, consts.n
    f = wk[W_F]
    y_new = wk[W_YNEW]
    aux = wk[W_AUX]
    aux_new = wk[W_AUXNEW]
    e_cur = mode_energy_at(y, aux, p, cs)
    rk_step(eval_rhs, t, h, Point(y, f, aux), Point(y_new, wk[W_FNEW], aux_new), sys, K)
    err = 0.0
    for i in range(n):
        if not math.isfinite(y_new[i]):
            err = math.inf
        for j in range(N_STAGES + 1):
            if not math.isfinite(K[j, i]):
                err = math.inf
    e_new = mode_energy_at(y_new, aux_new, p, cs)
    if err == 0.0 and e_new > e_cur + ENERGY_GUARD * rtol * consts.e0:
        err = math.inf
    if err == 0.0:
        defect = max(power_defect(y, f, aux, p, cs), power_defect(y_new, wk[W_FNEW], aux_new, p, cs))
        nc = norm_size(n)
        error_scale(y, y_new, nc, rtol, atol, slip_atol(y, y_new, p, rtol, atol), wk[W_ESCALE])
        err = max(error_norm(K, h, wk[W_ESCALE], nc), balance_error(y, aux, wk[W_DELTA], h, defect, p, cs, consts))
    tally_step(cs, sys.istats, err <= 1.0, 1)
    return err


@kernel
def norm_size(n):
    """The components 0..norm_size(n) - 1 of a state of size n that the step's error norms run over
    (dop853.error_norm, initial_step): the dynamics and the dissipation books (model.N_CORE). theta,
    psi, x, y (when integrated) are passive quadratures that never feed back into the dynamics;
    leaving them out keeps the step sequence, and so every result, identical whether or not a scene
    asks for them."""
    return min(n, N_CORE)


@kernel
def error_scale(y, y_new, n, rtol, atol, u_atol, sc):
    """The error norm's scale of each of the components 0..n-1 of a step from y to y_new (dop853's
    error_norm reads them): atol + rtol max(|y_i|, |y_new_i|), as in Hairer's dop853, with two
    rules of this state's. The slip components (Y_U1, Y_U2) take the absolute tolerance u_atol
    (slip_atol) instead of atol. The inclination's error is relative to its distance from the
    nearer of upright and flat, min(|alpha|, pi/2 - |alpha|): near flat the dynamics and the face
    event depend on beta = pi/2 - |alpha| (the face contact lies at beta = 1e-6 rad), which an
    error relative to |alpha| ~ 1.57 would resolve only to rtol * 1.57 (n: norm_size)."""
    for i in range(n):
        mag = max(abs(y[i]), abs(y_new[i]))
        if i == Y_ALPHA:
            mag = min(mag, max(0.5 * math.pi - min(abs(y[i]), abs(y_new[i])), 0.0))
        sc[i] = (u_atol if i == Y_U1 or i == Y_U2 else atol) + rtol * mag


@kernel
def slip_atol(y, y_new, p, rtol, atol):
    """Absolute tolerance of the slip components on a step: atol, but rtol SLIP_NEAR slip_tol where
    the slip is within SLIP_NEAR x slip_tol (p[P_UTOL]) of 0 at either end (see SLIP_NEAR), and not
    below the round-off of the velocities the slip is the difference of (SLIP_ROUNDOFF |omega|)."""
    near = SLIP_NEAR * p[P_UTOL]
    if math.hypot(y[Y_U1], y[Y_U2]) < near or math.hypot(y_new[Y_U1], y_new[Y_U2]) < near:
        w = max(abs(y[Y_W1]), abs(y[Y_W2]), abs(y[Y_W3]), 1.0)
        return min(atol, max(rtol * near, SLIP_ROUNDOFF * w))
    return atol


@kernel
def tally_step(cs, istats, accepted, count):
    """Add count to the accepted or rejected step counters (and to their sliding share)."""
    sliding = cs[CS_MODE] != ROLL
    if accepted:
        istats[I_STEPS] += count
        istats[I_SLIDE_STEPS] += count * sliding
    else:
        istats[I_REJECTED] += count
        istats[I_SLIDE_REJECTED] += count * sliding


@kernel
def mark_end(t_end, y_at_end, sys, trk, rec):
    """The scene ended (halted, or reached t_max) at t_end in state y_at_end (of the system sys,
    layout.System): its end state, energy, impact losses and event counts (trk[T_END_*]). The steps
    after a halt only complete the levels' frequency windows and change none of them."""
    istats, fstats, y_end = sys.istats, rec.fstats, rec.y_end
    fstats[F_TEND] = t_end
    for i in range(sys.n):
        y_end[i] = y_at_end[i]
    fstats[F_EEND] = mode_energy(y_end, sys.p, sys.cs)
    trk[T_DIMPACT_HALT] = fstats[F_DIMPACT]
    trk[T_END_TRANS] = istats[I_TRANS]
    trk[T_END_STICK] = istats[I_STICK]
    trk[T_END_IMPACTS] = istats[I_IMPACTS]


@kernel
def state_size(settings):
    """Components integrated: the dynamics and the dissipation books (N_CORE), + theta for the
    frequency outputs (N_THETA), + the kinematics (N_FULL)."""
    if settings[S_KIN] > 0.0:
        return N_FULL
    return N_THETA if settings[S_PEAKS] > 0.0 else N_CORE


@kernel
def begin(lev, work, rec, sys):
    """The scene at tau = 0 in the system sys (layout.System): its contact state, f and aux
    (wk[W_F], wk[W_AUX]), E(0), the event values (wk[W_GOLD]; lev: the first level's energy), the
    end's markers. Returns the outcome that ends the scene at once, else -1."""
    y, p, cs, wk = work.y, sys.p, sys.cs, sys.wk
    trk, fstats = work.trk, rec.fstats
    f = wk[W_F]
    aux = wk[W_AUX]
    fstats[F_TIMPACT] = -math.inf
    fstats[F_THALT] = math.nan
    fstats[F_THALT_ERR] = math.nan
    fstats[F_APPROACH] = math.nan
    trk[T_DEEP_E] = 0.0
    trk[T_END_TRANS] = -1.0
    trk[T_END_STICK] = -1.0
    trk[T_END_IMPACTS] = -1.0
    trk[T_H_AFTER] = 0.0
    start_code = start(y, sys)
    eval_rhs(0.0, y, sys, f, aux)
    fstats[F_E0] = mode_energy(y, p, cs)
    event_values(0.0, y, aux, sys, lev, wk[W_GOLD])
    outcome = -1
    if aux[X_PHI] <= 0.0:
        outcome = oc.CONTACT_LOST
    if aux[X_OK] != 1.0:
        outcome = failure_outcome(aux[X_OK])
    if start_code >= 0:
        outcome = start_code
    return outcome


@kernel
def record_start(consts, work, rec, sys):
    """What the scene records at tau = 0 (the samples due, the trajectory's first row, Phi for the
    maxima, the precession lattice's origin) and its starting step size (before the ceiling h_max);
    consts: layout.RunConsts."""
    y, p, cs, n, wk = work.y, sys.p, sys.cs, sys.n, sys.wk
    trk = work.trk
    aux = wk[W_AUX]
    sample_tau = consts.sample_tau
    ns = sample_tau.shape[0]
    while int(trk[T_NEXT_SAMPLE]) < ns and sample_tau[int(trk[T_NEXT_SAMPLE])] <= 0.0:
        record_sample(y, aux, p, cs, n, rec.samples[int(trk[T_NEXT_SAMPLE])])
        trk[T_NEXT_SAMPLE] += 1.0
    if rec.traj.shape[0] > 0:
        record_traj(0.0, y, aux[X_PHI], cs, n, rec.traj, sys.istats)
    trk[T_PHI_B] = aux[X_PHI]
    trk[T_RATES_OLD] = 0.0
    if consts.peaks_on:
        freq_start(y[Y_THETA], aux[X_PHI], rec.fq)
    return initial_step(eval_rhs, 0.0, y, wk[W_F], sys, consts.rtol, consts.atol, norm_size(n))


@kernel
def step_after_end(t, h, t_max, trk):
    """The step size after a halt, where the steps only complete the levels' frequency windows
    (precession cycles and Phi maxima after the levels) or reach the levels the halt fit waits for:
    while only windows wait, not past the last step before the end nor past twice the end's tau (a
    steady motion, e.g. rolling at a tilt held by a stuck moment, has no maxima, and its steps would
    grow tenfold each until t overflowed); while the halt fit waits, as the step control has it (the
    motion speeds up towards the halt, and capped steps spent the step budget first); never past
    t_max. Returns -1 where they stop."""
    if trk[T_H_AFTER] == 0.0:
        trk[T_H_AFTER] = h
        trk[T_T_AFTER] = 2.0 * t
    if t_max - t <= 2.0 * EPS * max(abs(t), 1.0) or (t >= trk[T_T_AFTER] and not deep_pending(trk)):
        return -1.0
    if deep_pending(trk):
        return min(h, t_max - t)
    return min(h, trk[T_H_AFTER], t_max - t)


@kernel
def retract_step(cs, istats):
    """An accepted step rejected after all (its kept part retried shorter)."""
    tally_step(cs, istats, True, -1)
    tally_step(cs, istats, False, 1)


@kernel
def segment_end(span, seg_end, event, check, consts):
    """The state where the kept part [t, seg_end] of the accepted step span (layout.Span: [t, t + h]
    from its y0) ends (wk[W_YSEG]): the step end, or the dense output at an event. Returns its
    energy (mode_energy) and, for an event's segment where `check`, the energy balance error of the
    kept part (held like a step's: > 1 retries the step shorter; consts: layout.RunConsts), else 0."""
    y, t, sys = span.y0, span.t0, span.sys
    p, cs, wk = sys.p, sys.cs, sys.wk
    y_seg = wk[W_YSEG]
    if not event:
        for i in range(sys.n):
            y_seg[i] = wk[W_YNEW, i]
        return mode_energy_at(y_seg, wk[W_AUXNEW], p, cs), 0.0
    dense_eval(span.F, 0, y, t, span.h, seg_end, sys.n, y_seg)
    e_seg = mode_energy(y_seg, p, cs)
    if not check:
        return e_seg, 0.0
    # the kept part ends on the dense output (7th order)
    return e_seg, state_balance_error(y, y_seg, mode_energy_at(y, wk[W_AUX], p, cs), e_seg, seg_end - t, p, consts)


@kernel
def segment_phi(seg_end, event, sys):
    """Phi at the segment end (the step end's from its last stage; an event's from the dense state),
    in the system sys (layout.System)."""
    wk = sys.wk
    if event:
        eval_rhs(seg_end, wk[W_YSEG], sys, wk[W_DYBUF], wk[W_AUXBUF])
        return wk[W_AUXBUF, X_PHI]
    return wk[W_AUXNEW, X_PHI]


@kernel
def advance(seg, ended, n, work, fstats):
    """Move the start to the end of the kept part seg (layout.Segment): its state (n components),
    and where no event restarts there the step end's f, aux and event rates; the time spent sliding
    (to the scene's end: ended)."""
    y, cs, wk, trk = work.y, work.cs, work.wk, work.trk
    event = seg.k >= 0
    if cs[CS_MODE] != ROLL and seg.running:
        fstats[F_SLIDETIME] += (seg.end if not ended else fstats[F_TEND]) - seg.t
    for i in range(n):
        y[i] = wk[W_YSEG, i]
    if not event:
        for i in range(n):
            wk[W_F, i] = wk[W_FNEW, i]
        for i in range(N_AUX):
            wk[W_AUX, i] = wk[W_AUXNEW, i]
    # the event rates at the new start are this step's end rates, unless an event restarts here
    trk[T_RATES_OLD] = 1.0 if not event and trk[T_RATES_NEW] == 1.0 else 0.0
    if trk[T_RATES_OLD] == 1.0:
        for k in range(N_DYN_EVENTS):
            wk[W_RATEOLD, k] = wk[W_RATENEW, k]


@kernel
def restart_after_event(k, t, y, lev, sys, fstats):
    """The discrete update of event k at t (event_dispatch.apply_event) of the system sys (layout.System);
    then the new contact state's slaved direction, right-hand side (wk[W_F], wk[W_AUX]) and event
    values (wk[W_GOLD]; lev: the next level's energy); the roll<->slip transition the update made is
    counted. Returns the outcome that ends the scene here (FACE_CONTACT: the disk lies flat), else -1."""
    p, cs, wk, istats = sys.p, sys.cs, sys.wk, sys.istats
    istats[I_EVENTS] += 1
    rolling = cs[CS_MODE] == ROLL
    code = apply_event(k, t, y, sys, fstats)
    count_transition(rolling, cs, istats)
    if code >= 0:
        return code
    if cs[CS_MODE] == SLAVED:
        # the slaved direction of the contact state the update left, continued across the event
        # (steps that end in events would otherwise leave it behind the moving root)
        code = confirm_slaved(t, y, sys)
        if code >= 0:
            return code
    aux = wk[W_AUX]
    eval_rhs(t, y, sys, wk[W_F], aux)
    if aux[X_OK] != 1.0:
        return failure_outcome(aux[X_OK])
    if aux[X_PHI] <= 0.0:
        # the update (an impact) leaves the disk with no compressive normal force: it leaves the
        # table here (its own event, Phi falling through 0, cannot happen)
        return oc.CONTACT_LOST
    event_values(t, y, aux, sys, lev, wk[W_GOLD])
    return -1


@kernel
def carry_step_end(lev, level_pending, work):
    """A step that ended without an event (work.y now its end state): its end's event values start
    the next step (the level's from the energy, +inf once every level is crossed), and a slaved
    direction is continued to its end."""
    y, p, cs, wk = work.y, work.p, work.cs, work.wk
    for k in range(N_DYN_EVENTS):
        wk[W_GOLD, k] = wk[W_GNEW, k]
    wk[W_GOLD, EV_LEVEL] = mode_energy_at(y, wk[W_AUX], p, cs) - lev if level_pending else math.inf
    if cs[CS_MODE] == SLAVED:
        # the step end's right-hand side continued it there (the root from cs[CS_NU] at y_new)
        cs[CS_NU] = wk[W_AUX, X_NU]


@kernel
def finish(outcome, t, h, consts, work, rec):
    """The scene's outputs once the loop stops: outcome, the event counts, end state and energy at
    its end (kept by mark_end, else the last state), the levels' frequencies."""
    y, p, cs, trk = work.y, work.p, work.cs, work.trk
    istats, fstats, y_end = rec.istats, rec.fstats, rec.y_end
    if outcome < 0:
        outcome = oc.STEP_LIMIT
    ended = trk[T_END_TRANS] >= 0.0
    if ended:
        istats[I_TRANS] = int(trk[T_END_TRANS])
        istats[I_STICK] = int(trk[T_END_STICK])
        istats[I_IMPACTS] = int(trk[T_END_IMPACTS])
    if consts.peaks_on:
        # a window cut by a numerical stop has no value; one cut by the motion's end has its largest
        # symmetric part
        cut = trk[T_CUT] != 0.0 or outcome == oc.NUMERICAL_ERROR
        finish_levels(rec.fq, rec.levels, cut)
    if ended:
        fstats[F_DIMPACT] = trk[T_DIMPACT_HALT]   # the end state and energy were taken at the end
    else:
        fstats[F_TEND] = t
        for i in range(consts.n):
            y_end[i] = y[i]
        fstats[F_EEND] = mode_energy(y_end, p, cs)
    istats[I_OUTCOME] = outcome
    fstats[F_HLAST] = h


@kernel
def next_try(t, h, outcome, consts, work, rec):
    """The size of the next try from t (h: the step control's), or where the loop stops: after the
    scene's end the Phi maxima's steps (step_after_end), the step budget, t_max, the smallest step
    that still moves tau (consts: layout.RunConsts). Returns (h, outcome, whether the step ends at t_max,
    whether to stop)."""
    running = outcome < 0
    if not running:
        h = step_after_end(t, h, consts.t_max, work.trk)
        if h < 0.0:
            return h, outcome, False, True
    if rec.istats[I_STEPS] + rec.istats[I_REJECTED] >= consts.max_steps:
        work.trk[T_CUT] = 1.0
        return h, oc.STEP_LIMIT if running else outcome, False, True
    at_tmax = running and t + h >= consts.t_max
    if at_tmax:
        h = consts.t_max - t
    # the model is autonomous (no stage reads tau), so a step only has to move tau: the floor is
    # 2 eps tau; 16 eps tau stopped a slip spiralling into slip_tol at tau ~ 5100, which needs
    # steps of ~1e-11 (tests/test_convergence.py)
    if h <= 2.0 * EPS * max(abs(t), 1.0):
        if running:
            outcome = oc.T_MAX if at_tmax else oc.STEP_SIZE_UNDERFLOW
        if outcome != oc.T_MAX:
            work.trk[T_CUT] = 1.0
        return h, outcome, at_tmax, True
    return h, outcome, at_tmax, False


@kernel
def record_segment(seg, e_seg, outcome, lev, consts, work, rec, sys):
    """What the kept part of the step (seg: layout.Segment; its end state wk[W_YSEG], energy
    e_seg) holds: the levels it crosses (HALTED at the last, with its end state), the samples, the
    Phi maxima (consts: layout.RunConsts; sys: the step's layout.System). Returns (the outcome, the energy of
    the next level to cross)."""
    y, wk, trk = work.y, work.wk, work.trk
    level_e = consts.level_e
    event = seg.k >= 0
    phi_c = segment_phi(seg.end, event, sys) if consts.peaks_on else 0.0
    span = Span(work.F, 0, y, seg.t, seg.h, sys)
    have_dense = seg.dense
    if not have_dense and dense_wanted(seg, e_seg, wk[W_YSEG, Y_THETA], phi_c, consts, trk, rec.fq):
        step_dense(seg.t, y, seg.h, wk[W_YNEW], sys, work.K, work.F)
        have_dense = True
    if seg.running:
        t_halt = record_levels(span, seg.end, e_seg, consts, trk, rec)
        if t_halt >= 0.0:
            outcome = oc.HALTED
            dense_eval(work.F, 0, y, seg.t, seg.h, t_halt, consts.n, wk[W_YBUF])
            mark_end(t_halt, wk[W_YBUF], sys, trk, rec)
            start_deep_levels(level_e, rec.levels, work.p, trk, rec.fstats)
        elif int(trk[T_NEXT_LEVEL]) < level_e.shape[0]:
            lev = level_e[int(trk[T_NEXT_LEVEL])]
    elif deep_pending(trk):
        deep_levels(span, seg.end, e_seg, trk, rec.fstats)
    record_samples(span, seg.end, rec.fstats[F_TEND] if outcome >= 0 else math.inf, consts.sample_tau, trk, rec.samples)
    # after the end, only while a level's frequencies wait for the motion (not for the whole deep
    # search of the halt fit: its Phi maxima are past the scene's end)
    if consts.peaks_on and (seg.running or trk[T_PENDING] > 0.0):
        track_frequency(span, seg.end, phi_c, have_dense, seg.running, work, rec)
    return outcome, lev


@kernel
def end_segment(seg, outcome, lev, consts, work, rec, sys):
    """Restart at the end of the kept part (seg: layout.Segment): an event's discrete update
    (restart_after_event: an outcome there ends the scene; a disk lying flat has halted), or the
    step end's values carried on (at t_max the scene ends). consts: layout.RunConsts; sys: the step's
    layout.System. Returns (the outcome, whether the loop stops)."""
    y, cs, wk, trk = work.y, work.cs, work.wk, work.trk
    istats, fstats = rec.istats, rec.fstats
    level_e = consts.level_e
    event = seg.k >= 0
    advance(seg, outcome >= 0, consts.n, work, fstats)
    t = seg.end
    if rec.traj.shape[0] > 0 and outcome < 0:
        record_traj(t, y, math.nan if event else wk[W_AUXNEW, X_PHI], cs, consts.n, rec.traj, istats)
    if not event:
        carry_step_end(lev, int(trk[T_NEXT_LEVEL]) < level_e.shape[0], work)
        if seg.at_tmax and outcome < 0:
            outcome = oc.T_MAX
            mark_end(t, y, sys, trk, rec)
        return outcome, False
    code = restart_after_event(seg.k, t, y, lev, sys, fstats)
    if code < 0:
        return outcome, False
    if seg.running and code == oc.FACE_CONTACT:
        # the disk lies flat: it has halted (docs/model.md, 'Halt')
        halt_flat(t, rec.levels, trk, level_e)
        istats[I_FLAT] = 1
        outcome = oc.HALTED
        mark_end(t, y, sys, trk, rec)
    elif seg.running:
        outcome = code
        fstats[F_TEND] = t
    elif code == oc.FACE_CONTACT and deep_pending(trk):
        # the halt fit waited for a deeper level, and the disk lies flat first: it halted here
        fstats[F_THALT] = t
        fstats[F_THALT_ERR] = location_tol(t)
        trk[T_DEEP_E] = 0.0
    return outcome, True


@kernel
def run(settings, level_e, sample_tau, work, rec):
    """Integrate one scene (the initial state in work.y, its parameters in work.p) into rec
    (layout.Work, layout.Record: the buffers' shapes): step, scan the accepted step for the
    earliest event, record the kept part, restart at its end. settings (layout.S_*), level_e the
    levels' energies (dimensionless), sample_tau the sample times (tau), ascending: read once here
    into the run's constants (layout.RunConsts), with E(0) from begin."""
    p, cs, wk, trk = work.p, work.cs, work.wk, work.trk
    istats = rec.istats
    sys = System(p, cs, state_size(settings), wk, istats)
    lev = level_e[0] if level_e.shape[0] > 0 else math.nan
    outcome = begin(lev, work, rec, sys)
    h_max = settings[S_HMAX] if settings[S_HMAX] > 0.0 else math.inf
    consts = RunConsts(sys.n, settings[S_RTOL], settings[S_ATOL], h_max, settings[S_TMAX], int(settings[S_MAXSTEPS]),
                       settings[S_PEAKS] > 0.0, max(abs(rec.fstats[F_E0]), 1e-300), level_e, sample_tau)
    h = min(record_start(consts, work, rec, sys), consts.h_max)
    t = 0.0
    after_reject = False
    # after a halt (the last level: the disk still moves) the steps go on while a level's frequencies
    # wait for the motion after it, or the halt fit for a deeper level: until they are complete, the
    # motion ends (an event's outcome, twice the end's tau), or a guard stops. Every other end (t_max, contact lost, ...) ends the
    # motion the scene simulates: nothing is integrated past it.
    while outcome < 0 or (outcome == oc.HALTED and (trk[T_PENDING] > 0.0 or deep_pending(trk))):
        running = outcome < 0
        h, outcome, at_tmax, stop = next_try(t, h, outcome, consts, work, rec)
        if stop:
            break
        err = try_step(t, h, consts, work, sys)
        if not err <= 1.0:
            h *= step_factor(err, ERR_EXPONENT)
            after_reject = True
            continue
        h_next = min(h * accepted_step_factor(err, ERR_EXPONENT, after_reject), consts.h_max)
        after_reject = False
        if wk[W_AUXNEW, X_OK] != 1.0 and running:
            outcome = failure_outcome(wk[W_AUXNEW, X_OK])
            break
        # the earliest event on the step: the kept part ends there
        event_values(t + h, wk[W_YNEW], wk[W_AUXNEW], sys, lev, wk[W_GNEW])
        span = Span(work.F, 0, work.y, t, h, sys)
        first_k, seg_end, have_dense = first_event(span, lev, work)
        event = first_k >= 0
        if event and running and t < trk[T_DIP_END] < t + h:
            # an event of the forces that only the dense output shows (both step ends on the safe
            # side): its value inside the step carries the interpolant's error, amplified where a
            # held moment's balance reads the slip direction; the dip stands only if the integrated
            # state at its minimum confirms it, so the step is retried to end there
            retract_step(cs, istats)
            h = trk[T_DIP_END] - t
            after_reject = True
            continue
        if not event:
            # a step cut to end at t_max ends there exactly: t + (t_max - t) can round 1 ulp short,
            # and a sample asked for at t_max would then be lost
            seg_end = consts.t_max if at_tmax else t + h
        e_seg, seg_err = segment_end(span, seg_end, event, running, consts)
        if seg_err > 1.0:
            retract_step(cs, istats)
            h *= step_factor(seg_err, ERR_EXPONENT)
            after_reject = True
            continue
        seg = Segment(t, h, seg_end, first_k, have_dense, running, at_tmax)
        outcome, lev = record_segment(seg, e_seg, outcome, lev, consts, work, rec, sys)
        outcome, stop = end_segment(seg, outcome, lev, consts, work, rec, sys)
        t = seg_end
        if stop:
            break
        h = h_next
    finish(outcome, t, h, consts, work, rec)


def work_arrays():
    """The buffers a run works in (layout.Work), zeroed: the one place their shapes are written."""
    return Work(np.zeros(N_FULL), np.zeros(N_PARAMS), np.zeros(N_CS), np.zeros((N_WORK, N_WCOLS)),
                np.zeros((N_KROWS, N_FULL)), np.zeros((2 * N_DENSE, N_FULL)), np.zeros(N_TRACK))


def record_arrays(n_levels, n_samples, traj_rows, peak_rows):
    """The buffers a run writes (layout.Record) for n_levels levels and n_samples samples, with room
    for traj_rows trajectory rows and peak_rows maxima of Phi: the levels and samples NaN until
    written (a level's L_PENDING 0), the rest zeroed. The one place their shapes are written."""
    levels = np.full((n_levels, LEVEL_COLS + 1), np.nan)
    levels[:, L_PENDING] = 0.0
    return Record(np.zeros(N_ISTATS, np.int64), np.zeros(N_FSTATS), levels, np.full((n_samples, SAMPLE_COLS), np.nan),
                  np.zeros((traj_rows, TRAJ_COLS)), np.zeros((peak_rows, PEAK_COLS)), np.zeros(N_FULL),
                  np.zeros((FQ_LEVEL0 + n_levels, FQ_COLS)))


def integrate(y0, p, settings, level_e, sample_tau, traj_cap=0, peak_cap=16384):
    """Run one scene (CPU). Allocates the buffers; if the trajectory or peak buffer overflowed, it
    grows it 4x and reruns (the run is deterministic). peak_cap covers ~1.6e4 nutation periods, far
    more than a scene to its halt has, so the rerun is for pathological scenes only. Returns a KernelOutput of arrays:
    istats, fstats (layout.I_*, F_*), levels (n_levels x layout.LEVEL_COLS: the columns layout.L_*),
    samples (layout.SA_*), trajectory (layout.TR_*), peaks (layout.PK_*: the counted maxima),
    y_end (N_FULL)."""
    while True:
        work = work_arrays()
        work.y[:y0.shape[0]] = y0
        work.p[:] = p
        rec = record_arrays(level_e.shape[0], sample_tau.shape[0], traj_cap,
                            peak_cap if settings[S_PEAKS] > 0.0 else 0)
        run(settings, level_e, sample_tau, work, rec)
        istats = rec.istats
        over = istats[I_OVERFLOW]
        if over == 0:
            break
        if over & 1:
            traj_cap = 4 * max(traj_cap, 256)
        if over & 2:
            peak_cap *= 4
    return KernelOutput(istats, rec.fstats, rec.levels[:, :LEVEL_COLS], rec.samples, rec.traj[:istats[I_TRAJ]],
                        rec.peaks[:istats[I_PEAKS]], rec.y_end)
