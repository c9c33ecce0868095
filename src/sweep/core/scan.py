"""The event scan of an accepted step: the earliest event on it (first_event), each event bracketed as
its row says (events.py: E_DIP, E_RESTART, E_HOLDS), located on the step's dense output
(roots.locate).
"""
from __future__ import annotations

import math

from .event_ids import EVENTS, EV_AGAINST1, N_DYN_EVENTS
from .events import (C_MOMENT, D_RATES, D_SIDE, D_SIGN, D_SLIP, E_CLASS, E_COMPONENT, E_DIP, E_HOLDS, E_RESTART, R_SPIN,
                     R_SURFACE)
from .jit import kernel
from .layout import (CS_SIDE, CS_SIG, SC_RATES_NEW, SC_RATES_OLD, W_AUX, W_AUXNEW, W_F, W_FNEW, W_GNEW, W_GOLD,
                     W_RATENEW, W_RATEOLD, W_YBUF, W_YNEW, Bracket, Hermite, Point)
from .model import Y_W1
from .moments import spin_sticks
from .roots import (brent_min, event_rates, event_value_at, hermite_dip, hermite_peak, locate, reads_forces,
                    sign_slopes, slip_closest_approach, span_state)
from .tracking import step_dense



# A dip whose dense-output value at the cubic Hermite minimum is below DIP_REFINE times the lower end
# value is searched for its true minimum (roots.brent_min) before it is ruled out.
DIP_REFINE = 0.1


@kernel
def first_event(span, lev, work):
    """Earliest event on the accepted step span (layout.Span: [t, t + h] from work.y; its end state,
    derivatives and event values in wk: W_YNEW, W_F, W_FNEW, W_GOLD, W_GNEW; lev: the next level's
    energy): (k, restart time, dense output made?).

    An event function that is positive at both ends can still cross zero twice inside the step
    (dip_bracket); one that starts on its surface can leave it and come back (surface_bracket,
    spin_bracket). The rates at the step end are kept for the next step's start
    (work.trk.scan: layout.ScanState), so a step costs one RHS evaluation for them.
    """
    t, h = span.t0, span.h
    wk, scan = span.sys.wk, work.trk.scan
    g_old = wk[W_GOLD]
    g_new = wk[W_GNEW]
    have_dense = False
    scan.rates[SC_RATES_NEW] = False
    scan.dip_end[0] = -1.0
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
            ra, rb = locate(k, Bracket(ta, ga, tb, gb), span, lev)
            if (rb < first_t or first_k < 0) and (EVENTS[k, E_HOLDS] == 0
                                                  or spin_holds(EVENTS[k, E_COMPONENT], rb, span)):
                first_k = k_event
                first_t = rb
                scan.dip_end[0] = dip_end
    return first_k, first_t, have_dense


@kernel(inline="always")
def step_start(y, wk):
    """The accepted step's start (layout.Point): y (work.y), its derivative wk[W_F] and aux wk[W_AUX]."""
    return Point(y, wk[W_F], wk[W_AUX])


@kernel(inline="always")
def step_end(wk):
    """The accepted step's end (layout.Point): wk[W_YNEW], wk[W_FNEW], wk[W_AUXNEW]."""
    return Point(wk[W_YNEW], wk[W_FNEW], wk[W_AUXNEW])


@kernel
def lift_off(k, span, ends, lev):
    """On the step span (layout.Span: [t, t + h] from its y0, dense output built) that starts on
    event k's surface (g0 <= 0, just after a discrete update put the state there) and ends with
    g1 <= 0: a time where g_k > 0 and its value, to bracket a return to the surface within the step;
    (-1, 0) if there is none. ends (layout.Hermite): g0, g1 and the exact end derivatives d0, d1 of
    g_k per unit of the step. Starts at
    the peak of the cubic Hermite interpolant of g_k; where g_k leaves the surface upwards (d0 > 0)
    it halves towards t, where g_k ~ g0 + d0 x > 0. lev: the next level's energy.
    """
    t, h = span.t0, span.h
    g0, d0, g1, d1 = ends
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
def dense_built(have_dense, span, work):
    """The accepted step's dense output in F[0:7] (the step span, layout.Span, from work.y to
    wk[W_YNEW]), built once per step: returns True."""
    if not have_dense:
        step_dense(span, span.sys.wk[W_YNEW], work.K)
    return True


@kernel
def surface_bracket(k, span, lev, work):
    """Event k (the side, a moment sign, or a slaved slip's end) on the step span (layout.Span:
    [t, t + h] from work.y) that starts on its surface and ends on or past it (dense output built):
    a bracket (ta, ga, tb, gb) of its return to the surface, and the event to apply there (k, or
    EV_AGAINST1 + i for a component moving against its sign)."""
    t, h = span.t0, span.h
    y, cs, wk = work.y, span.sys.cs, span.sys.wk
    g0 = wk[W_GOLD, k]
    g1 = wk[W_GNEW, k]
    y_new = wk[W_YNEW]
    i = EVENTS[k, E_COMPONENT]
    if EVENTS[k, E_DIP] == D_SIDE:
        # g = side alpha, dg/dtau = side omega_1 (eq. 2.3)
        d0 = cs[CS_SIDE] * y[Y_W1] * h
        d1 = cs[CS_SIDE] * y_new[Y_W1] * h
    elif EVENTS[k, E_DIP] == D_RATES:
        d0, d1 = rate_slopes(k, span, lev, work)
    else:
        d0, d1 = sign_slopes(i, cs[CS_SIG + i], step_start(y, wk), step_end(wk), h)
    ta, ga = lift_off(k, span, Hermite(g0, d0, g1, d1), lev)
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
    y, cs, wk = work.y, span.sys.cs, span.sys.wk
    i = EVENTS[k, E_COMPONENT]
    d0, d1 = sign_slopes(i, cs[CS_SIG + i], step_start(y, wk), step_end(wk), h)
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
    y, cs, wk = work.y, span.sys.cs, span.sys.wk
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
        d0, d1 = sign_slopes(i, cs[CS_SIG + i], step_start(y, wk), step_end(wk), h)
        dip = hermite_dip(g0, d0, g1, d1)
    elif how == D_SLIP:
        # |u| less a speed: a V where the slip passes by u = 0, placed from the slip's own smooth
        # components (a cubic in g, or its difference quotient, can step over it)
        dip = slip_closest_approach(y, f, y_new, f_new, h)
    elif how == D_RATES:
        d0, d1 = rate_slopes(k, span, lev, work)
        dip = hermite_dip(g0, d0, g1, d1)
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
def rate_slopes(k, span, lev, work):
    """d g_k per unit of the step span (layout.Span: [t, t + h] from work.y) at its two ends, from
    the events' rates (roots.event_rates: one RHS evaluation for all events at each end, the end's
    kept for the next step's start in work.trk.scan)."""
    t, h = span.t0, span.h
    y, wk, scan = work.y, span.sys.wk, work.trk.scan
    if not scan.rates[SC_RATES_OLD]:
        event_rates(t, step_start(y, wk), wk[W_GOLD], wk[W_RATEOLD], lev, span.sys)
        scan.rates[SC_RATES_OLD] = True
    if not scan.rates[SC_RATES_NEW]:
        event_rates(t + h, step_end(wk), wk[W_GNEW], wk[W_RATENEW], lev, span.sys)
        scan.rates[SC_RATES_NEW] = True
    return wk[W_RATEOLD, k] * h, wk[W_RATENEW, k] * h


@kernel
def spin_holds(i, t_event, span):
    """Would free component i stick at its spin event at t_event on span's dense output
    (moments.spin_sticks, the test event_rules.stick_at_spin_tol makes)? Where it would not, the event
    changes nothing, and the step goes on instead of restarting there (the same trajectory, fewer
    restarts)."""
    sys = span.sys
    span_state(t_event, span)
    return spin_sticks(i, t_event, sys.wk[W_YBUF], sys)


@kernel
def start_scan(scan):
    """No event rates are known at the scene's start (scan: layout.ScanState)."""
    scan.rates[SC_RATES_OLD] = False


@kernel
def carry_rates(event, scan, wk):
    """The event rates at the next step's start are this step's end rates (wk[W_RATENEW]), unless an
    event restarts there (event) or this step's scan did not compute them."""
    scan.rates[SC_RATES_OLD] = not event and scan.rates[SC_RATES_NEW]
    if scan.rates[SC_RATES_OLD]:
        for k in range(N_DYN_EVENTS):
            wk[W_RATEOLD, k] = wk[W_RATENEW, k]
