"""Roots and maxima on the dense output of one accepted step (numba kernels).

Events are roots of g_k (g > 0 before the event). Roots are bracketed on the accepted step and
refined with Brent's method on the 7th-order dense output until the bracket is no wider than
4 ulp of tau (location_tol); the restart point is the right end of the
bracket, where the event has certainly happened, so a restart can never re-detect the crossing.
The maxima of the normal force Phi are found by Brent's method on the same dense output.
"""
from __future__ import annotations

import math

from .constants import EPS
from .contact_rhs import eval_rhs
from .dop853 import dense_eval
from .event_dispatch import event_value, event_values, state_event_value
from .event_ids import EVENTS, N_EVENTS
from .events import E_FORCES
from .jit import kernel
from .layout import W_AUXBUF, W_DYBUF, W_GBUF, W_YBUF
from .model import X_PHI, Y_U1, Y_U2, sign_rate

# Events are located to 4 ulp of tau, where the bracket cannot shrink further, with this floor near
# tau = 0. The restart point is the bracket's right end, so each event restarts up to the tolerance
# past its root: a one-sided error that no rtol removes.
EVENT_TOL_TAU = 1e-15
# Step (tau) of the forward difference that gives the rate of an event function without a closed form.
RATE_STEP = 1e-7


@kernel
def sign_slopes(i, sig, start, end, h):
    """End slopes, per unit of the step from start to end (layout.Point: y and its derivative f) of
    length h, of sig * omega.a_i: exact, from the state and its derivative (no RHS evaluation); for
    the sign and spin events' Hermite checks."""
    return sig * sign_rate(i, start.y, start.f) * h, sig * sign_rate(i, end.y, end.f) * h


@kernel
def _hermite(x, g0, d0, g1, d1):
    h00 = (1.0 + 2.0 * x) * (1.0 - x) ** 2
    h10 = x * (1.0 - x) ** 2
    h01 = x * x * (3.0 - 2.0 * x)
    h11 = x * x * (x - 1.0)
    return h00 * g0 + h10 * d0 + h01 * g1 + h11 * d1


@kernel
def _hermite_extremum(g0, d0, g1, d1, sgn):
    """x in (0, 1) of the interior extremum of the cubic Hermite interpolant (values g0, g1 and
    derivatives d0, d1 per unit x at the step ends) with the smallest sgn * H (sgn = 1: lowest
    minimum, -1: highest maximum), found exactly from the quadratic H'; -1 if there is none."""
    # H'(x) = a x^2 + b x + c
    a = 6.0 * (g0 - g1) + 3.0 * (d0 + d1)
    b = -6.0 * (g0 - g1) - 4.0 * d0 - 2.0 * d1
    c = d0
    best = -1.0
    vbest = 0.0
    if a == 0.0:
        if b != 0.0:
            x = -c / b
            if 0.0 < x < 1.0:
                best = x
        return best
    disc = b * b - 4.0 * a * c
    if disc < 0.0:
        return -1.0
    # the cancellation-free pair of roots: q / a and c / q (a may be tiny against b)
    q = -0.5 * (b + math.copysign(math.sqrt(disc), b))
    for i in range(2):
        if q == 0.0:
            break
        x = q / a if i == 0 else c / q
        if 0.0 < x < 1.0:
            v = sgn * _hermite(x, g0, d0, g1, d1)
            if best < 0.0 or v < vbest:
                best = x
                vbest = v
    return best


@kernel
def hermite_dip(g0, d0, g1, d1):
    """Where in (0, 1) the cubic Hermite interpolant of g (values g0, g1 > 0 and derivatives d0, d1
    per unit x at the step ends) has an interior minimum: that x, else -1. The caller checks g on
    the step's dense output there: the cubic's own error can hide a shallow dip below 0 (a grazing
    double crossing), so its value at the minimum decides nothing."""
    return _hermite_extremum(g0, d0, g1, d1, 1.0)


@kernel
def _hermite_slope(x, g0, d0, g1, d1):
    """d/dx of the cubic Hermite interpolant (_hermite)."""
    return (6.0 * x * x - 6.0 * x) * (g0 - g1) + (3.0 * x * x - 4.0 * x + 1.0) * d0 + (3.0 * x * x - 2.0 * x) * d1


@kernel
def slip_closest_approach(y0, f0, y1, f1, h):
    """Where in (0, 1) the slip vector passes closest to u = 0 on the step [y0, y1] of length h
    (derivatives f0, f1): x of a minimum of |U(x)|^2, U the cubic Hermite curve of (u1, u2) with
    the exact end derivatives h f; -1 unless |U| falls at the start and rises at the end.

    |u| less a speed (slip_tol, the slaving speed) has a V-shaped minimum where a slip passes by
    u = 0, as wide as (miss distance) / (slip rate): often far narrower than the step and than
    RATE_STEP, so that neither a cubic in g nor a difference quotient of g sees it (a harness scene
    whose |u| dipped 1e-12 below slip_tol inside a V ~4e-9 tau wide was stepped over at three of
    four rtols: docs/model.md, 'Modes, signs and sticking'). The components are smooth: U'(x).U(x) changes
    sign once across the V, and bisection on it finds the place to 2^-60 of the step."""
    a0x, a0y, a1x, a1y = y0[Y_U1], y0[Y_U2], y1[Y_U1], y1[Y_U2]
    d0x, d0y, d1x, d1y = h * f0[Y_U1], h * f0[Y_U2], h * f1[Y_U1], h * f1[Y_U2]
    if not (a0x * d0x + a0y * d0y < 0.0 and a1x * d1x + a1y * d1y > 0.0):
        return -1.0
    lo = 0.0
    hi = 1.0
    for _ in range(60):
        x = 0.5 * (lo + hi)
        ux = _hermite(x, a0x, d0x, a1x, d1x)
        uy = _hermite(x, a0y, d0y, a1y, d1y)
        if ux * _hermite_slope(x, a0x, d0x, a1x, d1x) + uy * _hermite_slope(x, a0y, d0y, a1y, d1y) < 0.0:
            lo = x
        else:
            hi = x
    return 0.5 * (lo + hi)


@kernel
def hermite_peak(g0, d0, g1, d1):
    """x in (0, 1) of the interpolant's highest interior maximum, else -1 (see _hermite_extremum)."""
    return _hermite_extremum(g0, d0, g1, d1, -1.0)


@kernel
def event_rates(t, at, g_here, rates, lev, sys):
    """d g_k/d tau along the solution at (t, at.y) for every event k (at: layout.Point, its derivative
    at.f; g_here: the values there; lev: the next level's energy) into rates, by a forward
    difference of step RATE_STEP along f: one RHS evaluation for all, in the system sys
    (layout.System). 0 where g_k is inactive (inf)."""
    y, f = at.y, at.f
    wk = sys.wk
    ys = wk[W_YBUF]
    for i in range(sys.n):
        ys[i] = y[i] + RATE_STEP * f[i]
    eval_rhs(t + RATE_STEP, ys, sys, wk[W_DYBUF], wk[W_AUXBUF])
    event_values(t + RATE_STEP, ys, wk[W_AUXBUF], sys, lev, wk[W_GBUF])
    for k in range(N_EVENTS):
        gk = wk[W_GBUF, k]
        if g_here[k] == math.inf or gk == math.inf:
            rates[k] = 0.0
        else:
            rates[k] = (gk - g_here[k]) / RATE_STEP


@kernel
def reads_forces(k):
    """Does event k's function read the right-hand side's aux (event_ids.EVENTS[k, E_FORCES])? The
    others are functions of the state alone: on a step's dense output they cost no right-hand-side
    evaluation (state_event_value)."""
    return EVENTS[k, E_FORCES] != 0


@kernel
def span_state(t, span):
    """The state at time t on the dense output of a step (span: layout.Span), into its wk[W_YBUF]."""
    sys = span.sys
    dense_eval(span, t, sys.n, sys.wk[W_YBUF])


@kernel
def event_value_at(k, t, span, lev):
    """g_k at time t on the dense output of a step (span: layout.Span; lev: the next level's
    energy); one RHS evaluation, in the span's system, for an event that reads the forces, none for
    one of the state alone."""
    sys = span.sys
    wk = sys.wk
    span_state(t, span)
    if not reads_forces(k):
        return state_event_value(k, t, wk[W_YBUF], sys, lev)
    eval_rhs(t, wk[W_YBUF], sys, wk[W_DYBUF], wk[W_AUXBUF])
    return event_value(k, t, wk[W_YBUF], wk[W_AUXBUF], sys, lev)


@kernel
def location_tol(tau):
    """The width (tau) to which locate shrinks an event's bracket at time tau: 4 ulp of tau, at
    least EVENT_TOL_TAU."""
    return max(EVENT_TOL_TAU, 4.0 * EPS * abs(tau))


@kernel
def locate(k, bracket, span, lev):
    """Brent's method (inverse quadratic and secant steps inside a shrinking bracket, bisection
    where they would be slow) for g_k on [ta, tb] with g(ta) = ga > 0 >= g(tb) = gb (bracket:
    layout.Bracket), on the dense output of span (layout.Span; lev: the next level's energy).
    Returns the (ta, tb) bracket, no wider than location_tol, g > 0 at ta.

    b is the best point so far and c the bracket's other end (g of the other sign); a step is at
    least half the tolerance, so a bracket that converges from one side closes. A NaN value (a
    right-hand side that failed) counts as past the event. At most 200 evaluations: Brent's method
    needs at most ~2 per bisection's worth of bracket, ~100 from a whole step to 4 ulp.
    """
    a, fa, b, fb = bracket
    c, fc = a, fa
    d = b - a
    e = d
    for _ in range(200):
        if (fb > 0.0) == (fc > 0.0):
            # b and the previous point a now bracket the root
            c, fc = a, fa
            d = b - a
            e = d
        if abs(fc) < abs(fb):
            a, b, c = b, c, b
            fa, fb, fc = fb, fc, fb
        tol = location_tol(max(abs(b), abs(c)))
        half = 0.5 * tol
        xm = 0.5 * (c - b)
        if abs(c - b) <= tol:
            break
        if abs(e) >= half and abs(fa) > abs(fb):
            s = fb / fa
            if a == c:
                p = 2.0 * xm * s
                q = 1.0 - s
            else:
                q = fa / fc
                r = fb / fc
                p = s * (2.0 * xm * q * (q - r) - (b - a) * (r - 1.0))
                q = (q - 1.0) * (r - 1.0) * (s - 1.0)
            if p > 0.0:
                q = -q
            else:
                p = -p
            if 2.0 * p < min(3.0 * xm * q - abs(half * q), abs(e * q)):
                e = d
                d = p / q
            else:
                d = xm
                e = d
        else:
            d = xm
            e = d
        a, fa = b, fb
        b = b + d if abs(d) > half else b + math.copysign(half, xm)
        fb = event_value_at(k, b, span, lev)
        if math.isnan(fb):
            fb = -1.0
    if b < c:
        return b, c
    return c, b


@kernel
def _objective(k, t, span, lev):
    """What brent_min minimises: -Phi for k < 0, else event k's value, on span's dense output."""
    if k >= 0:
        return event_value_at(k, t, span, lev)
    wk = span.sys.wk
    span_state(t, span)
    eval_rhs(t, wk[W_YBUF], span.sys, wk[W_DYBUF], wk[W_AUXBUF])
    return -wk[W_AUXBUF, X_PHI]


@kernel
def brent_min(k, ta, tb, stop_at, span, lev):
    """Time and value of the minimum of _objective(k) on [ta, tb] (span's dense output) by Brent's parabolic/golden-section
    search; it returns at once at a value <= stop_at (a dip below an event surface is found).

    The location of a smooth minimum is determined only to ~sqrt(eps) relative to the bracket
    (the function is flat there), so xtol = 1e-8 * (tb - ta) + 1e-14 is the useful precision.
    """
    cgold = 0.3819660112501051
    a = ta
    b = tb
    x = w = v = a + cgold * (b - a)
    fx = fw = fv = _objective(k, x, span, lev)
    d = 0.0
    e = 0.0
    for _ in range(100):
        xm = 0.5 * (a + b)
        tol1 = 1e-8 * (tb - ta) + 1e-14
        tol2 = 2.0 * tol1
        if fx <= stop_at or abs(x - xm) <= tol2 - 0.5 * (b - a):
            break
        use_golden = True
        if abs(e) > tol1:
            r = (x - w) * (fx - fv)
            q = (x - v) * (fx - fw)
            pp = (x - v) * q - (x - w) * r
            q = 2.0 * (q - r)
            if q > 0.0:
                pp = -pp
            q = abs(q)
            etemp = e
            e = d
            if not (abs(pp) >= abs(0.5 * q * etemp) or pp <= q * (a - x) or pp >= q * (b - x)):
                d = pp / q
                u = x + d
                if u - a < tol2 or b - u < tol2:
                    d = tol1 if xm - x >= 0 else -tol1
                use_golden = False
        if use_golden:
            e = (a - x) if x >= xm else (b - x)
            d = cgold * e
        u = x + d if abs(d) >= tol1 else x + (tol1 if d >= 0 else -tol1)
        fu = _objective(k, u, span, lev)
        if fu <= fx:
            if u >= x:
                a = x
            else:
                b = x
            v, w, x = w, x, u
            fv, fw, fx = fw, fx, fu
        else:
            if u < x:
                a = u
            else:
                b = u
            if fu <= fw or w == x:
                v, w = w, u
                fv, fw = fw, fu
            elif fu <= fv or v == x or v == w:
                v = u
                fv = fu
    return x, fx


@kernel
def phi_on_dense(tau, span):
    """Phi at tau on the dense output of span (layout.Span)."""
    return -_objective(-1, tau, span, math.nan)


@kernel
def brent_max_phi(ta, tb, span):
    """Time of the maximum of Phi on [ta, tb] (span's dense output) and Phi there (brent_min of -Phi)."""
    x, f = brent_min(-1, ta, tb, -math.inf, span, math.nan)
    return x, -f
