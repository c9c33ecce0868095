"""Step acceptance: one step of the current contact state (try_step: DOP853, or in a stiff slide the
linearly implicit extrapolation, stepper_for) with its error norm (error_scale: this state's
per-component scales), the energy-balance checks of a step and of the
kept part of a step cut at an event (balance_error, state_balance_error), and the step counters.
"""
from __future__ import annotations

import math

from .constants import EPS, ROLL, SLIDE
from .contact_rhs import eval_rhs, mode_energy, mode_energy_at
from .dop853 import dense_eval, error_norm, rk_step
from .extrapolation import N_COLUMNS, lie_error_norm, lie_step
from .jit import kernel
from .layout import (CS_MODE, CS_SIDE, CS_STEPPER, I_REJECTED, I_SLIDE_REJECTED, I_SLIDE_STEPS, I_STEPS, STEP_DOP853,
                     STEP_LIE, Point, W_AUX, W_AUXNEW, W_DELTA, W_ESCALE, W_F, W_FNEW, W_YNEW, W_YSEG)
from .model import (N_CORE, P_G, P_H, P_MUD, P_STIFF, P_UTOL, X_COSA, X_PHI, X_SINA, Y_ALPHA, Y_DK1, Y_DK2, Y_DK3, Y_DSLIDE, Y_U1,
                    Y_U2, Y_W1, Y_W2, Y_W3, energy_increment_trig, energy_rate_trig)
from .tableau import N_STAGES



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
# left that decision to the error of the step: whether a near-reversal stuck moved with rtol. The
# region is at least SLIP_NEAR x atol wide: a slide at |u| ~ 20 atol, its direction unresolved by an
# error of atol, let the stepper at its stability bound flip the direction by ~12 degrees at every
# step; that chatter held the friction at its Filippov average about u = 0 for millions of steps,
# never reaching a slip_tol below atol (docs/model.md, 'Where a slip ends'). Only a slide's (SLIDE):
# a slaved slip's direction is not integrated, and its right-hand side carries the noise of its root
# and of its differences along the motion (~5e-5 of the slip acceleration near flat), which a
# tolerance of the slip's round-off failed at every step down to the step floor.
SLIP_NEAR = 100.0


# The slip is the contact point's velocity, a difference of O(|omega|) terms: its round-off, and its
# step's round-off in the error estimate, is ~EPS |omega|. A tolerance below it failed every shorter
# step alike (a random-scene harness run at rtol 1e-13 ended in step_size_underflow that way).
SLIP_ROUNDOFF = 4.0 * EPS


# The extrapolation's Jacobian: the components the right-hand side reads (alpha, omega, the slip: the
# dissipation books and the kinematics are quadratures), the slip's pair among them
LIE_COMPONENTS = (Y_U2 + 1, Y_U1, Y_U2)
# ... and the fewest columns (its order) at which it may stop, where that column has converged
EARLY_COLUMNS = 6


@kernel
def stepper_for(h, y, aux, p, cs):
    """The stepper of a step of size h from y (aux: the right-hand side's there) in the contact
    state cs: STEP_LIE (the linearly implicit extrapolation, extrapolation.py) for a slide where h is
    at least p[P_STIFF] > 0 relaxation times of the slip direction, |u| / (mu_d Phi): there DOP853 is
    held at its stability bound (h mu_d Phi / |u| ~ 1.5-2 on slow slides, docs/model.md 'Slow
    slip'), the extrapolation steps at what accuracy needs; else STEP_DOP853. Which stepper takes a
    step is numerics: both converge to the same motion, and no decision reads it."""
    r = p[P_STIFF]
    if r > 0.0 and cs[CS_MODE] == SLIDE and h * p[P_MUD] * max(aux[X_PHI], 0.0) >= r * math.hypot(y[Y_U1], y[Y_U2]):
        return STEP_LIE
    return STEP_DOP853


@kernel
def try_step(t, h, consts, work, sys):
    """One step of size h (DOP853, or the extrapolation where stepper_for says, the choice kept in
    cs[CS_STEPPER] for its dense output) from work.y, f = wk[W_F] (wk[W_AUX]: the right-hand side's aux
    there) into wk[W_YNEW], wk[W_FNEW], wk[W_AUXNEW], in the system sys (layout.System); returns
    its error norm (inf for a step with a non-finite stage or end state, or one that raises the
    energy by more than ENERGY_GUARD rtol e0), at least its energy-balance error (balance_error;
    consts: layout.RunConsts), and counts it.

    Every stage is checked, also those whose tableau weight in y_new or the error estimate is zero
    (stages 1-4, and f_new): a right-hand side that failed there (a slaved direction that lost its
    root returns NaN) makes the step fail, so steps shrink until the event that ends the mode is
    located; accepted, its NaN f_new would poison every later step."""
    y, p, cs, wk, K = work.y, sys.p, sys.cs, sys.wk, work.K
    rtol, atol, n = consts.rtol, consts.atol, consts.n
    f = wk[W_F]
    y_new = wk[W_YNEW]
    aux = wk[W_AUX]
    aux_new = wk[W_AUXNEW]
    e_cur = mode_energy_at(y, aux, p, cs)
    start = Point(y, f, aux)
    stepper = stepper_for(h, y, aux, p, cs)
    cs[CS_STEPPER] = stepper
    nc = norm_size(n)
    columns = N_COLUMNS
    if stepper == STEP_LIE:
        # (the tolerances at the step start, for the extrapolation's convergence test)
        error_scale(y, y, nc, (rtol, atol, slip_atol(y, y, p, cs[CS_MODE], rtol, atol)), wk[W_ESCALE])
        columns = lie_step(eval_rhs, (t, h, wk[W_ESCALE], EARLY_COLUMNS, nc),
                           (start, Point(y_new, wk[W_FNEW], aux_new)), sys, K, LIE_COMPONENTS)
    else:
        rk_step(eval_rhs, t, h, (start, Point(y_new, wk[W_FNEW], aux_new)), sys, K)
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
        error_scale(y, y_new, nc, (rtol, atol, slip_atol(y, y_new, p, cs[CS_MODE], rtol, atol)), wk[W_ESCALE])
        # (an extrapolation that stopped at column j < 8 has an error of order j: as a norm for
        # dop853's exponent -1/8, err^(8/j), so the next step grows as that order asks)
        step_err = (lie_error_norm(K, wk[W_ESCALE], nc) ** (N_COLUMNS / columns) if stepper == STEP_LIE
                    else error_norm(K, h, wk[W_ESCALE], nc))
        err = max(step_err, balance_error(start, wk[W_DELTA], h, defect, sys, consts))
    tally_step(cs, sys.istats, err <= 1.0, 1)
    return err


@kernel
def power_defect(y, dy, aux, p, cs):
    """|dE/dtau + dissipated power| of the evaluated right-hand side dy, aux at y: 0 for the exact
    flow, so what is left is the right-hand side's own round-off in the energy direction."""
    rate = energy_rate_trig(y, dy, p, cs[CS_SIDE], cs[CS_MODE] != ROLL, (aux[X_SINA], aux[X_COSA]))
    return abs(rate + dy[Y_DSLIDE] + dy[Y_DK1] + dy[Y_DK2] + dy[Y_DK3])


@kernel
def balance_error(start, d, h, defect, sys, consts):
    """The energy-balance residual |Delta(E + dissipated)| of a step's increment d (before rounding:
    wk[W_DELTA]) from start (layout.Point: y and the right-hand side's aux there) over h, in the
    system sys (its parameters and contact state), over what it may be (see BALANCE_FACTOR);
    accepted if <= 1. defect: power_defect at the step's ends (the larger); of the run's constants
    (layout.RunConsts) e0 = |E(0)| > 0, t_max (tau) and rtol."""
    y, aux, p, cs = start.y, start.aux, sys.p, sys.cs
    change, scale = energy_increment_trig(y, d, p, cs[CS_SIDE], cs[CS_MODE] != ROLL, (aux[X_SINA], aux[X_COSA]))
    dissipated = d[Y_DSLIDE] + d[Y_DK1] + d[Y_DK2] + d[Y_DK3]
    allowed = (BALANCE_FACTOR * consts.rtol * (max(dissipated, 0.0) + consts.e0 * h / consts.t_max)
               + BALANCE_ROUNDOFF * (scale + abs(d[Y_DSLIDE]) + abs(d[Y_DK1]) + abs(d[Y_DK2]) + abs(d[Y_DK3]))
               + DEFECT_FACTOR * abs(h) * defect)
    return abs(change + dissipated) / allowed


@kernel
def state_balance_error(y, y_new, energies, h, p, consts):
    """balance_error of the kept part of a step cut at an event, from the states at its ends y, y_new
    and their energies (e_cur, e_new) (the dense output's increment carries the round-off of its
    coefficients, not of the change).

    The residual's round-off, in units of EPS: E and the dissipated energy; the height's terms
    G cos(alpha) (1 + |h|), which cancel near upright for a thick disk; and the inclination's last
    bit times dE/dalpha ~ G (|sin alpha| + |h| cos(alpha)) + omega_1^2 (1 + |h|), which dominates
    near flat, where E << G. Once per event, this floor adds to the budget at most the events'
    number times it."""
    e_cur, e_new = energies
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
def norm_size(n):
    """The components 0..norm_size(n) - 1 of a state of size n that the step's error norms run over
    (dop853.error_norm, initial_step): the dynamics and the dissipation books (model.N_CORE). theta,
    psi, x, y (when integrated) are passive quadratures that never feed back into the dynamics;
    leaving them out keeps the step sequence, and so every result, identical whether or not a scene
    asks for them."""
    return min(n, N_CORE)


@kernel
def error_scale(y, y_new, n, tol, sc):
    """The error norm's scale of each of the components 0..n-1 of a step from y to y_new (dop853's
    error_norm reads them) into sc, tol = (rtol, atol, u_atol): atol + rtol max(|y_i|, |y_new_i|), as
    in Hairer's dop853, with two rules of this state's. The slip components (Y_U1, Y_U2) take the
    absolute tolerance u_atol (slip_atol) instead of atol. The inclination's error is relative to its distance from the
    nearer of upright and flat, min(|alpha|, pi/2 - |alpha|): near flat the dynamics and the face
    event depend on beta = pi/2 - |alpha| (the face contact lies at beta = 1e-6 rad), which an
    error relative to |alpha| ~ 1.57 would resolve only to rtol * 1.57 (n: norm_size)."""
    rtol, atol, u_atol = tol
    for i in range(n):
        mag = max(abs(y[i]), abs(y_new[i]))
        if i == Y_ALPHA:
            mag = min(mag, max(0.5 * math.pi - min(abs(y[i]), abs(y_new[i])), 0.0))
        sc[i] = (u_atol if i == Y_U1 or i == Y_U2 else atol) + rtol * mag


@kernel
def slip_atol(y, y_new, p, mode, rtol, atol):
    """Absolute tolerance of the slip components on a step in the contact mode `mode`: atol, but in
    a slide (SLIDE) rtol SLIP_NEAR max(slip_tol, atol) where the slip is within SLIP_NEAR x
    max(slip_tol (p[P_UTOL]), atol) of 0 at either end (see SLIP_NEAR), and not below the
    round-off of the velocities the slip is the difference of (SLIP_ROUNDOFF |omega|)."""
    near = SLIP_NEAR * max(p[P_UTOL], atol)
    if mode == SLIDE and (math.hypot(y[Y_U1], y[Y_U2]) < near or math.hypot(y_new[Y_U1], y_new[Y_U2]) < near):
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
    dense_eval(span, seg_end, sys.n, y_seg)
    e_seg = mode_energy(y_seg, p, cs)
    if not check:
        return e_seg, 0.0
    # the kept part ends on the dense output (7th order)
    return e_seg, state_balance_error(y, y_seg, (mode_energy_at(y, wk[W_AUX], p, cs), e_seg), seg_end - t, p, consts)
