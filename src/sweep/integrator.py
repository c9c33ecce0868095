"""Hybrid integrator: DOP853 (adaptive, or fixed step) with located events and mode switches.

One numba kernel, `integrate`, runs a whole scene: it steps the current smooth mode (rolling or
sliding with a fixed set of moment signs and stuck components), detects every event on the
accepted step, locates the earliest one on the 7th-order dense output, restarts from there with
the new discrete state (keeping the step size), and records the diagnostics the scene asked for.

Step-size control follows Hairer, Norsett & Wanner (1993), II.4 and II.10: the error norm of
dop853 (5th/3rd-order embedded estimates), safety 0.9, factor in [0.2, 10], exponent -1/8.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from . import outcomes as oc
from .events import (EV_CONE, EV_CONTACT, EV_FACE, EV_LEVEL, EV_SIDE, EV_SIGN1, EV_SLIPEND, EV_UNSTICK1,
                     N_DYN_EVENTS, N_EVENTS, brent_max_phi, dense_eval, event_values,
                     hermite_interior_root, locate)
from .model import (N_AUX, N_CORE, N_FULL, N_THETA, P_K1, P_K2, P_K3, P_MUD, P_MUS, P_UFREEZE, ROLL, SLIDE, X_F1, X_F2, X_G1, X_OK,
                    X_PHI, X_SIG1, Y_ALPHA, Y_DSLIDE, Y_THETA, Y_U1, Y_U2, Y_W1, Y_W2, Y_W3, energy,
                    project_velocity, rhs)
from .tableau import A as RK_A, B as RK_B, C as RK_C, D as RK_D, E3 as RK_E3, E5 as RK_E5

SAFETY = 0.9
MIN_FACTOR = 0.2
MAX_FACTOR = 10.0
ERR_EXPONENT = -1.0 / 8.0   # error estimator of order 7 -> h ~ err^(-1/8)
EPS = 2.220446049250313e-16
# A step may not raise the energy by more than ENERGY_GUARD * rtol * E(0): the true energy never
# increases, so such a step is an instability the error estimate did not see (explicit steps in the
# stiff end phase of a slip). Adaptive mode rejects it; fixed-step mode halves it (as it halves any
# step whose error estimate exceeds the scene's rtol/atol).
ENERGY_GUARD = 10.0
# Minimum prominence of a located maximum of Phi over its bracket ends, relative to Phi (see the
# peak tracking in `integrate`).
PEAK_PROMINENCE = 1e-6
# Minimum separation of two Phi maxima, as a fraction of the precession period 2 pi/|dtheta/dtau|.
MIN_PEAK_SEPARATION = 0.01
# Two rim-edge impacts (alpha = 0) closer than ZENO_DTAU in tau: the rocking between the edges has
# collapsed (a Zeno sequence of plastic impacts), the disk stands on its flat edge: line_contact.
ZENO_DTAU = 1e-6
# A step-size collapse within BETA_SOFT_FACE rad of flat ends as face_contact: there the 3-1-2 angles
# are singular (tan alpha > 1e5) and the precession time scale ~ beta/|omega3| reaches round-off.
BETA_SOFT_FACE = 1e-5
# Stiction: a slip slower than max(slip_tol, rtol |omega|) ends as soon as the static friction cone
# holds for the rolling state. Near u = 0 the sliding equations are stiff (slip-direction rate
# ~ mu_d Phi / u), explicit steps shrink like u, and a slip that creeps (required friction close to
# mu_d Phi) would otherwise take millions of steps. rtol |omega| is the velocity error the step-size
# control itself accepts, so a slip below it is not resolved anyway; at tight tolerances the band
# is slip_tol itself and every slip end stays on the located slip_tol event (first-order
# convergence in slip_tol, tests/test_physics.py).
STICTION_FACTOR = 1.0
# A slip below CREEP_MAX_SLIP (u_hat; ~5e-5 m/s for the paper's disk) also sticks (cone permitting)
# when it creeps -- the step is stability-limited (mu_d Phi h > CREEP_STIFF u: the slip-direction
# mode relaxes within a step) and at its current rate it would need more than CREEP_STEPS such steps
# to end -- or when it would end within the next step while it is inside the error band
# HOVER_FACTOR (atol + rtol |omega|) that the step-size control does not resolve (explicit steps
# across u = 0, where the friction direction jumps, make such a slip hover instead of ending). At
# tight tolerances that band lies below slip_tol, and every ordinary slip end stays on the located
# slip_tol event (slip_tol convergence test).
CREEP_MAX_SLIP = 1e-4
CREEP_STIFF = 0.1
CREEP_STEPS = 100.0
HOVER_FACTOR = 10.0

# settings vector layout
S_RTOL, S_ATOL, S_HFIXED, S_TMAX, S_UTOL, S_MAXSTEPS, S_KIN, S_PEAKS, S_EXTRA = 0, 1, 2, 3, 4, 5, 6, 7, 8
N_SETTINGS = 9

# integer statistics layout
I_OUTCOME, I_STEPS, I_REJECTED, I_RHS, I_EVENTS, I_TRANS, I_STICK, I_IMPACTS, I_LEVELS, I_TRAJ, I_PEAKS = range(11)
I_SLIDE_STEPS, I_SLIDE_REJECTED = 11, 12   # cost accounting: steps taken while sliding
N_ISTATS = 13
# float statistics layout
F_TEND, F_SLIDETIME, F_DIMPACT, F_E0, F_EEND, F_HLAST = range(6)
N_FSTATS = 6
# trajectory columns: tau, y[0:N_FULL], Phi, mode
TRAJ_COLS = 2 + N_FULL + 1
# sample columns: y[0:N_FULL], energy, Phi, mode
SAMPLE_COLS = N_FULL + 3


@njit(cache=True)
def _stages(first, last, t, y, h, n, p, mode, side, sig, stuck, n0x, n0y, K, ytmp, dytmp, auxtmp):
    """Evaluate RK stages first..last-1 into K (stage s uses K[0:s] and row s of the tableau)."""
    for s in range(first, last):
        for i in range(n):
            acc = 0.0
            for j in range(s):
                acc += RK_A[s, j] * K[j, i]
            ytmp[i] = y[i] + h * acc
        rhs(t + RK_C[s] * h, ytmp, p, mode, side, sig, stuck, n0x, n0y, n, dytmp, auxtmp)
        for i in range(n):
            K[s, i] = dytmp[i]


@njit(cache=True)
def _rk_step(t, y, f, h, n, p, mode, side, sig, stuck, n0x, n0y, K, y_new, f_new, aux_new, ytmp, dytmp, auxtmp):
    """One DOP853 step: stages 0..11 into K, y_new, and f_new = K[12] = f(t+h, y_new). 12 RHS calls."""
    for i in range(n):
        K[0, i] = f[i]
    _stages(1, 12, t, y, h, n, p, mode, side, sig, stuck, n0x, n0y, K, ytmp, dytmp, auxtmp)
    for i in range(n):
        acc = 0.0
        for j in range(12):
            acc += RK_B[j] * K[j, i]
        y_new[i] = y[i] + h * acc
    rhs(t + h, y_new, p, mode, side, sig, stuck, n0x, n0y, n, f_new, aux_new)
    for i in range(n):
        K[12, i] = f_new[i]


@njit(cache=True)
def _error_norm(K, h, y, y_new, n, rtol, atol):
    """Hairer's dop853 error norm over the dynamic state and the dissipation quadratures only.

    theta, psi, x, y (when integrated) are passive quadratures that never feed back into the
    dynamics; leaving them out keeps the step sequence, and so every result, identical whether or
    not a scene asks for them (tests/test_physics.py).
    """
    n = min(n, N_CORE)
    e5 = 0.0
    e3 = 0.0
    for i in range(n):
        sc = atol + rtol * max(abs(y[i]), abs(y_new[i]))
        a5 = 0.0
        a3 = 0.0
        for j in range(13):
            a5 += RK_E5[j] * K[j, i]
            a3 += RK_E3[j] * K[j, i]
        e5 += (a5 / sc) ** 2
        e3 += (a3 / sc) ** 2
    if e5 == 0.0 and e3 == 0.0:
        return 0.0
    den = e5 + 0.01 * e3
    return abs(h) * e5 / math.sqrt(den * n)


@njit(cache=True)
def _dense_coeffs(t, y, h, y_new, f_new, n, p, mode, side, sig, stuck, n0x, n0y, K, F, ytmp, dytmp, auxtmp):
    """Coefficients of the continuous extension (3 extra RHS calls: stages 13..15)."""
    _stages(13, 16, t, y, h, n, p, mode, side, sig, stuck, n0x, n0y, K, ytmp, dytmp, auxtmp)
    for i in range(n):
        dyv = y_new[i] - y[i]
        F[0, i] = dyv
        F[1, i] = h * K[0, i] - dyv
        F[2, i] = 2.0 * dyv - h * (f_new[i] + K[0, i])
        for r in range(4):
            acc = 0.0
            for j in range(16):
                acc += RK_D[r, j] * K[j, i]
            F[3 + r, i] = h * acc


@njit(cache=True)
def _slip_accel(nu, t, y, p, side, sig, stuck, n, dy, aux):
    rhs(t, y, p, SLIDE, side, sig, stuck, math.cos(nu), math.sin(nu), n, dy, aux)
    c = math.cos(nu)
    s = math.sin(nu)
    return dy[Y_U2] * c - dy[Y_U1] * s, dy[Y_U1] * c + dy[Y_U2] * s


@njit(cache=True)
def slip_onset_direction(t, y, p, side, sig, stuck, n, F1, F2, counter):
    """Slip direction nu at the onset of sliding (u = 0), consistent with the sliding dynamics.

    Sliding starts with zero slip speed; its direction s = (cos nu, sin nu) must be the one along
    which the slip then grows: the slip acceleration a_P(nu) (with friction -mu_d Phi s) must be
    parallel to s with a_P.s > 0. The paper's rule s = -F_f/|F_f| (section 6.2) is exact only when
    the contact's inverse inertia is isotropic; it is the initial guess. The cross product
    a_P(nu) x s is scanned on 64 angles for sign changes with a_P.s > 0, the root nearest the guess
    is refined by bisection to 1e-13 rad, and the guess is kept if no consistent root exists.
    """
    y0 = y.copy()
    y0[Y_U1] = 0.0
    y0[Y_U2] = 0.0
    dy = np.empty(n)
    aux = np.empty(N_AUX)
    guess = math.atan2(-F2, -F1)
    best = guess
    bestd = 1e300
    m = 64
    xa = guess - math.pi
    ca, da = _slip_accel(xa, t, y0, p, side, sig, stuck, n, dy, aux)
    counter[0] += 1
    for j in range(1, m + 1):
        xb = guess - math.pi + 2.0 * math.pi * j / m
        cb, db = _slip_accel(xb, t, y0, p, side, sig, stuck, n, dy, aux)
        counter[0] += 1
        if (ca > 0.0) != (cb > 0.0):
            lo, hi, clo = xa, xb, ca
            for _ in range(60):
                mid = 0.5 * (lo + hi)
                cm, dm = _slip_accel(mid, t, y0, p, side, sig, stuck, n, dy, aux)
                counter[0] += 1
                if (cm > 0.0) == (clo > 0.0):
                    lo, clo = mid, cm
                else:
                    hi = mid
                if hi - lo < 1e-13:
                    break
            root = 0.5 * (lo + hi)
            cr, dr = _slip_accel(root, t, y0, p, side, sig, stuck, n, dy, aux)
            counter[0] += 1
            dist = abs(math.atan2(math.sin(root - guess), math.cos(root - guess)))
            if dr > 0.0 and dist < bestd:
                best = root
                bestd = dist
        xa, ca, da = xb, cb, db
    return best


@njit(cache=True)
def refine_direction(t, y, p, side, sig, stuck, n, nu0, counter):
    """Consistent slip direction near nu0 (a_P parallel to s, a_P.s > 0) by the secant method.

    At most 8 iterations from nu0 and nu0 + 1e-4 rad; converged when the angle update is below
    1e-12 rad. Falls back to nu0 if it does not converge or lands on a decaying direction.
    """
    y0 = y.copy()
    y0[Y_U1] = 0.0
    y0[Y_U2] = 0.0
    dy = np.empty(n)
    aux = np.empty(N_AUX)
    xa = nu0
    ca, da = _slip_accel(xa, t, y0, p, side, sig, stuck, n, dy, aux)
    xb = nu0 + 1e-4
    cb, db = _slip_accel(xb, t, y0, p, side, sig, stuck, n, dy, aux)
    counter[0] += 2
    for _ in range(8):
        if cb == ca:
            break
        xc = xb - cb * (xb - xa) / (cb - ca)
        xa, ca = xb, cb
        xb = xc
        cb, db = _slip_accel(xb, t, y0, p, side, sig, stuck, n, dy, aux)
        counter[0] += 1
        if abs(xb - xa) < 1e-12:
            if db > 0.0:
                return xb
            break
    return nu0


@njit(cache=True)
def _start_slip(t, y, p, side, sig, stuck, n, F1, F2, counter):
    """Roll -> slip: zero slip speed, direction from slip_onset_direction (F: rolling friction).

    Returns the slip direction (n0x, n0y); the caller sets mode = SLIDE and counts the transition.
    """
    nu = slip_onset_direction(t, y, p, side, sig, stuck, n, F1, F2, counter)
    y[Y_U1] = 0.0
    y[Y_U2] = 0.0
    return math.cos(nu), math.sin(nu)


@njit(cache=True)
def _stick_or_flip(i, t, y, p, mode, side, sig, stuck, n0x, n0y, n, dy, aux, counter):
    """At omega.a_i = 0: stick if the moment can hold it (|sigma needed| <= 1), else flip sign.

    Returns 1 when the component sticks. The sign is set to the one the motion will take.
    """
    stuck[i] = 1
    rhs(t, y, p, mode, side, sig, stuck, n0x, n0y, n, dy, aux)
    counter[0] += 1
    need = aux[X_SIG1 + i]
    if abs(need) < 1.0:
        return 1
    stuck[i] = 0
    sig[i] = 1.0 if need > 0.0 else -1.0
    return 0


@njit(cache=True)
def _consistent_signs(t, y, p, mode, side, sig, stuck, n0x, n0y, n, active, dy, aux, counter):
    """Make every non-stuck moment sign agree with omega.a_i; an exact zero gets the stick test."""
    rhs(t, y, p, mode, side, sig, stuck, n0x, n0y, n, dy, aux)
    counter[0] += 1
    nst = 0
    for i in range(3):
        if active[i] == 1 and stuck[i] == 0:
            g = aux[X_G1 + i]
            if g > 0.0:
                sig[i] = 1.0
            elif g < 0.0:
                sig[i] = -1.0
            else:
                nst += _stick_or_flip(i, t, y, p, mode, side, sig, stuck, n0x, n0y, n, dy, aux, counter)
    return nst


@njit(cache=True)
def integrate(y0, p, mode0, settings, level_e, sample_tau, traj_cap):
    """Integrate one scene. Pure arrays in, arrays out.

    y0: initial state (N_FULL); mode0: ROLL or SLIDE; settings: see S_* indices;
    level_e: energies of the halt levels, decreasing; sample_tau: increasing output times;
    traj_cap: initial capacity of the trajectory buffer (0: no trajectory stored).
    Returns istats, fstats, level_out (n_levels x 4: tau, alpha, dtheta/dtau, f_hat; with peak
    tracking dtheta/dtau is the mean over the three-peak window of f_hat, else instantaneous),
    samples (n_samples x N_FULL, plus energy in an extra column), trajectory (rows x TRAJ_COLS),
    peaks (tau, Phi of the located maxima of the normal force; empty unless tracked).
    """
    rtol = settings[S_RTOL]
    atol = settings[S_ATOL]
    h_fixed = settings[S_HFIXED]
    t_max = settings[S_TMAX]
    u_tol = settings[S_UTOL]
    max_steps = int(settings[S_MAXSTEPS])
    track_peaks = settings[S_PEAKS] > 0.0
    # theta is integrated (passively) whenever Phi peaks are tracked: the mean precession rate over
    # the same three-peak window as f_hat is (theta_k - theta_{k-2}) / (t_k - t_{k-2})
    n = N_FULL if settings[S_KIN] > 0.0 else (N_THETA if track_peaks else N_CORE)
    extra_steps = int(settings[S_EXTRA])
    adaptive = h_fixed <= 0.0

    istats = np.zeros(N_ISTATS, np.int64)
    fstats = np.zeros(N_FSTATS)
    nl = level_e.shape[0]
    level_out = np.full((nl, 4), np.nan)
    ns = sample_tau.shape[0]
    samples = np.full((ns, SAMPLE_COLS), np.nan)
    traj = np.empty((max(traj_cap, 1), TRAJ_COLS))
    ntraj = 0
    peaks = np.empty((64 if track_peaks else 1, 3))    # tau, Phi, theta at each located maximum
    npk = 0
    counter = np.zeros(1, np.int64)

    p = p.copy()
    p[P_UFREEZE] = u_tol     # friction direction frozen at slip speeds <= slip_tol (docs/model.md)
    y = y0.copy()
    t = 0.0
    mode = mode0
    side = 1 if y[Y_ALPHA] > 0.0 else -1
    sig = np.ones(3)
    stuck = np.zeros(3, np.int64)
    active = np.zeros(N_EVENTS, np.int64)
    active[0] = 1 if p[P_K1] > 0.0 else 0
    active[1] = 1 if p[P_K2] > 0.0 else 0
    active[2] = 1 if p[P_K3] > 0.0 else 0
    active[EV_CONE] = 1
    n0x = 1.0
    n0y = 0.0

    f = np.empty(n)
    aux = np.empty(N_AUX)
    K = np.zeros((16, n))
    Fd = np.zeros((7, n))
    Fprev = np.zeros((7, n))
    y_new = np.empty(n)
    f_new = np.empty(n)
    aux_new = np.empty(N_AUX)
    ytmp = np.empty(n)
    dytmp = np.empty(n)
    auxtmp = np.empty(N_AUX)
    ybuf = np.empty(n)
    dybuf = np.empty(n)
    auxbuf = np.empty(N_AUX)
    gbuf = np.empty(N_EVENTS)
    g_old = np.empty(N_EVENTS)
    g_new = np.empty(N_EVENTS)
    yprev = np.empty(n)
    y_end = np.zeros(N_FULL)
    end_mode = ROLL
    end_side = 1

    # --- initial discrete state -------------------------------------------------------------
    istats[I_STICK] += _consistent_signs(t, y, p, mode, side, sig, stuck, n0x, n0y, n, active, dytmp, auxtmp, counter)
    if mode == SLIDE:
        un = math.hypot(y[Y_U1], y[Y_U2])
        n0x = y[Y_U1] / un
        n0y = y[Y_U2] / un
    rhs(t, y, p, mode, side, sig, stuck, n0x, n0y, n, f, aux)
    counter[0] += 1
    if mode == ROLL and aux[X_PHI] > 0.0 and p[P_MUS] * aux[X_PHI] < math.hypot(aux[X_F1], aux[X_F2]):
        n0x, n0y = _start_slip(t, y, p, side, sig, stuck, n, aux[X_F1], aux[X_F2], counter)
        mode = SLIDE
        istats[I_TRANS] += 1
        rhs(t, y, p, mode, side, sig, stuck, n0x, n0y, n, f, aux)
        counter[0] += 1
    fstats[F_E0] = energy(y, p, side, mode)
    e_cur = fstats[F_E0]
    e_guard = ENERGY_GUARD * rtol * max(abs(fstats[F_E0]), 1e-300)
    t_last_impact = -np.inf
    next_level = 0
    lev = level_e[0] if nl > 0 else np.nan
    event_values(y, aux, p, mode, side, sig, stuck, u_tol, lev, active, g_old)
    outcome = -1
    if aux[X_PHI] <= 0.0:
        outcome = oc.CONTACT_LOST
    if aux[X_OK] == 0.0:
        outcome = oc.NUMERICAL_ERROR
    isamp = 0
    while isamp < ns and sample_tau[isamp] <= 0.0:
        for i in range(n):
            samples[isamp, i] = y[i]
        samples[isamp, N_FULL] = energy(y, p, side, mode)
        samples[isamp, N_FULL + 1] = aux[X_PHI]
        samples[isamp, N_FULL + 2] = mode
        isamp += 1
    if traj_cap > 0:
        traj[0, 0] = t
        for i in range(n):
            traj[0, 1 + i] = y[i]
        traj[0, 1 + N_FULL] = aux[X_PHI]
        traj[0, 2 + N_FULL] = mode
        ntraj = 1

    # Phi peak tracking: Phi at the last two step ends and the previous step's dense output
    phi_a = np.nan
    phi_b = aux[X_PHI]
    t_a = np.nan
    t_b = 0.0
    prev_ok = False
    tprev = 0.0
    hprev = 0.0
    prev_mode = mode
    prev_side = side
    prev_sig = sig.copy()
    prev_stuck = stuck.copy()
    prev_n0x = n0x
    prev_n0y = n0y
    pending = np.zeros(nl, np.int64)    # levels waiting for the first Phi peak after them
    n_pending = 0
    after_halt = 0

    # --- initial step size (Hairer & Wanner II.4, 'starting step size') ------------------------
    if adaptive:
        nc = min(n, N_CORE)   # as in the error norm: the passive kinematics do not steer the steps
        d0 = 0.0
        d1 = 0.0
        for i in range(nc):
            sc = atol + rtol * abs(y[i])
            d0 += (y[i] / sc) ** 2
            d1 += (f[i] / sc) ** 2
        d0 = math.sqrt(d0 / nc)
        d1 = math.sqrt(d1 / nc)
        h0 = 1e-6 if (d0 < 1e-5 or d1 < 1e-5) else 0.01 * d0 / d1
        for i in range(n):
            ytmp[i] = y[i] + h0 * f[i]
        rhs(t + h0, ytmp, p, mode, side, sig, stuck, n0x, n0y, n, dytmp, auxtmp)
        counter[0] += 1
        d2 = 0.0
        for i in range(nc):
            sc = atol + rtol * abs(y[i])
            d2 += ((dytmp[i] - f[i]) / sc) ** 2
        d2 = math.sqrt(d2 / nc) / h0
        if max(d1, d2) <= 1e-15:
            h1 = max(1e-6, h0 * 1e-3)
        else:
            h1 = (0.01 / max(d1, d2)) ** (1.0 / 8.0)
        h = min(100.0 * h0, h1)
    else:
        h = h_fixed

    # --- main loop ------------------------------------------------------------------------------
    while outcome < 0 or (n_pending > 0 and after_halt < extra_steps):
        running = outcome < 0
        if not running:
            after_halt += 1
        if istats[I_STEPS] + istats[I_REJECTED] >= max_steps:
            if outcome < 0:
                outcome = oc.STEP_LIMIT
            break
        hit_tmax = False
        if outcome < 0 and t + h >= t_max:
            h = t_max - t
            hit_tmax = True
        if h <= 16.0 * EPS * max(abs(t), 1.0):
            if outcome < 0:
                if hit_tmax:
                    outcome = oc.T_MAX
                elif 0.5 * math.pi - abs(y[Y_ALPHA]) < BETA_SOFT_FACE:
                    outcome = oc.FACE_CONTACT
                else:
                    outcome = oc.STEP_SIZE_UNDERFLOW
            break
        e_cur = energy(y, p, side, mode)
        _rk_step(t, y, f, h, n, p, mode, side, sig, stuck, n0x, n0y, K, y_new, f_new, aux_new, ytmp, dytmp, auxtmp)
        counter[0] += 12
        finite = True
        for i in range(n):
            if not math.isfinite(y_new[i]):
                finite = False
        if finite and energy(y_new, p, side, mode) > e_cur + e_guard:
            finite = False      # treated like a non-finite step: rejected (adaptive) or halved (fixed)
        if not adaptive and (not finite or _error_norm(K, h, y, y_new, n, rtol, atol) > 1.0):
            # fixed-step mode never accepts a step that is unstable or less accurate than the
            # scene's rtol/atol (e.g. the stiff end of a slip): it is halved, then grows back to dt
            istats[I_REJECTED] += 1
            if mode == SLIDE:
                istats[I_SLIDE_REJECTED] += 1
            h *= 0.5
            continue
        if adaptive:
            err = _error_norm(K, h, y, y_new, n, rtol, atol) if finite else np.inf
            if not err <= 1.0:
                istats[I_REJECTED] += 1
                if mode == SLIDE:
                    istats[I_SLIDE_REJECTED] += 1
                fac = MIN_FACTOR if not math.isfinite(err) else max(MIN_FACTOR, SAFETY * err ** ERR_EXPONENT)
                h *= fac
                if not finite and h <= 16.0 * EPS * max(abs(t), 1.0):
                    if outcome < 0:
                        outcome = oc.NUMERICAL_ERROR
                    break
                continue
            fac = MAX_FACTOR if err == 0.0 else min(MAX_FACTOR, SAFETY * err ** ERR_EXPONENT)
            h_next = h * fac
        else:
            h_next = min(2.0 * h, h_fixed)   # after halvings, grow back to dt
        istats[I_STEPS] += 1
        if mode == SLIDE:
            istats[I_SLIDE_STEPS] += 1
        if aux_new[X_OK] == 0.0 and outcome < 0:
            outcome = oc.NUMERICAL_ERROR
            break

        # --- events on [t, t + h] ---------------------------------------------------------------
        event_values(y_new, aux_new, p, mode, side, sig, stuck, u_tol, lev, active, g_new)
        t_end = t + h
        have_dense = False
        first_k = -1
        first_t = t_end
        first_ta = t
        for k in range(N_DYN_EVENTS):
            ta = -1.0
            ga = 0.0
            gb = 0.0
            if g_old[k] > 0.0 and g_new[k] <= 0.0:
                ta, ga, tb, gb = t, g_old[k], t_end, g_new[k]
            elif k <= 2 and g_old[k] > 0.0 and g_new[k] > 0.0 and g_old[k] != np.inf:
                x = hermite_interior_root(k, sig[k], y, f, y_new, f_new, g_old[k], g_new[k], h)
                if x > 0.0:
                    if not have_dense:
                        _dense_coeffs(t, y, h, y_new, f_new, n, p, mode, side, sig, stuck, n0x, n0y, K, Fd, ytmp, dytmp, auxtmp)
                        counter[0] += 3
                        have_dense = True
                    # confirm on the dense output: scan for a sign change of g_k
                    prevt = t
                    prevg = g_old[k]
                    for j in range(1, 17):
                        tj = t + h * j / 17.0
                        dense_eval(Fd, y, t, h, tj, n, ybuf)
                        rhs(tj, ybuf, p, mode, side, sig, stuck, n0x, n0y, n, dybuf, auxbuf)
                        counter[0] += 1
                        event_values(ybuf, auxbuf, p, mode, side, sig, stuck, u_tol, lev, active, gbuf)
                        if prevg > 0.0 and gbuf[k] <= 0.0:
                            ta, ga, tb, gb = prevt, prevg, tj, gbuf[k]
                            break
                        prevt = tj
                        prevg = gbuf[k]
            if ta >= 0.0 and ta < first_t:
                if not have_dense:
                    _dense_coeffs(t, y, h, y_new, f_new, n, p, mode, side, sig, stuck, n0x, n0y, K, Fd, ytmp, dytmp, auxtmp)
                    counter[0] += 3
                    have_dense = True
                ra, rb = locate(k, ta, ga, tb, gb, Fd, y, t, h, n, p, mode, side, sig, stuck, n0x, n0y,
                                u_tol, lev, active, ybuf, dybuf, auxbuf, gbuf, counter)
                if rb < first_t or first_k < 0:
                    first_k = k
                    first_t = rb
                    first_ta = ra
        creeping = False
        if first_k < 0 and mode == SLIDE:
            un = math.hypot(y_new[Y_U1], y_new[Y_U2])
            u_stick = max(STICTION_FACTOR * u_tol, rtol * math.sqrt(y_new[Y_W1] ** 2 + y_new[Y_W2] ** 2 + y_new[Y_W3] ** 2))
            # a tiny slip that either creeps (the explicit step at its stability limit,
            # h ~ u/(mu_d Phi), and so slow that ending it would take more than CREEP_STEPS such
            # steps) or would reach zero within one more step at its current rate (the step would
            # cross the discontinuity of u/|u| at u = 0, where explicit steps make it hover)
            udot = abs(y_new[Y_U1] * f_new[Y_U1] + y_new[Y_U2] * f_new[Y_U2]) / max(un, 1e-300)
            slow = p[P_MUD] * aux_new[X_PHI] * h > CREEP_STIFF * un and un > CREEP_STEPS * h * udot
            wn = math.sqrt(y_new[Y_W1] ** 2 + y_new[Y_W2] ** 2 + y_new[Y_W3] ** 2)
            within = un <= h * udot and un < HOVER_FACTOR * (atol + rtol * wn)
            creeping = un < u_stick or (un < CREEP_MAX_SLIP and (slow or within))
        if creeping:
            # the slip speed is negligible and static friction can hold the rolling state -> stick
            # now (detected at the step end; steps are stability-limited, h ~ u, so the time error
            # is ~h, far below the slip-tolerance error itself)
            for i in range(n):
                ytmp[i] = y_new[i]
            ytmp[Y_U1] = 0.0
            ytmp[Y_U2] = 0.0
            rhs(t_end, ytmp, p, ROLL, side, sig, stuck, n0x, n0y, n, dytmp, auxtmp)
            counter[0] += 1
            if p[P_MUS] * auxtmp[X_PHI] >= math.hypot(auxtmp[X_F1], auxtmp[X_F2]):
                first_k = EV_SLIPEND
                first_t = t_end
        seg_end = first_t if first_k >= 0 else t_end
        need_dense = (not have_dense) and (
            track_peaks or (isamp < ns and sample_tau[isamp] <= seg_end)
            or (nl > next_level and g_old[EV_LEVEL] > 0.0 and g_new[EV_LEVEL] <= 0.0)
            or first_k >= 0)
        if need_dense:
            _dense_coeffs(t, y, h, y_new, f_new, n, p, mode, side, sig, stuck, n0x, n0y, K, Fd, ytmp, dytmp, auxtmp)
            counter[0] += 3
            have_dense = True

        # --- halt levels crossed before the segment end (energy is monotone: one root each) -----
        while outcome < 0 and next_level < nl:
            if first_k >= 0:
                dense_eval(Fd, y, t, h, seg_end, n, ybuf)
                gl = energy(ybuf, p, side, mode) - level_e[next_level]
            else:
                gl = energy(y_new, p, side, mode) - level_e[next_level]
            if not (gl <= 0.0):
                break
            gl0 = energy(y, p, side, mode) - level_e[next_level]
            ta, tb = t, seg_end
            if gl0 <= 0.0:
                tb = t
                ta = t
            else:
                ta, tb = locate(EV_LEVEL, t, gl0, seg_end, gl, Fd, y, t, h, n, p, mode, side, sig, stuck,
                                n0x, n0y, u_tol, level_e[next_level], active, ybuf, dybuf, auxbuf, gbuf, counter)
            tl = 0.5 * (ta + tb)
            dense_eval(Fd, y, t, h, tl, n, ybuf)
            level_out[next_level, 0] = tl
            level_out[next_level, 1] = ybuf[Y_ALPHA]
            level_out[next_level, 2] = ybuf[Y_W3] / math.cos(ybuf[Y_ALPHA])
            if track_peaks:
                pending[next_level] = 1
                n_pending += 1
            next_level += 1
            istats[I_LEVELS] = next_level
            if next_level == nl:
                outcome = oc.HALTED
                fstats[F_TEND] = tl
                for i in range(n):
                    y_end[i] = ybuf[i]
                end_mode = mode
                end_side = side
            else:
                lev = level_e[next_level]

        # --- samples in the segment ----------------------------------------------------------
        while isamp < ns and sample_tau[isamp] <= seg_end and (outcome < 0 or sample_tau[isamp] <= fstats[F_TEND]):
            dense_eval(Fd, y, t, h, sample_tau[isamp], n, ybuf)
            rhs(sample_tau[isamp], ybuf, p, mode, side, sig, stuck, n0x, n0y, n, dybuf, auxbuf)
            counter[0] += 1
            for i in range(n):
                samples[isamp, i] = ybuf[i]
            samples[isamp, N_FULL] = energy(ybuf, p, side, mode)
            samples[isamp, N_FULL + 1] = auxbuf[X_PHI]
            samples[isamp, N_FULL + 2] = mode
            isamp += 1

        # --- normal-force peaks: Phi at step ends a < b > c brackets a maximum ------------------
        if track_peaks:
            if first_k >= 0:
                dense_eval(Fd, y, t, h, seg_end, n, ybuf)
                rhs(seg_end, ybuf, p, mode, side, sig, stuck, n0x, n0y, n, dybuf, auxbuf)
                counter[0] += 1
                phi_c = auxbuf[X_PHI]
            else:
                phi_c = aux_new[X_PHI]
            genuine = False
            if phi_b > phi_a and phi_b >= phi_c and prev_ok:
                tp1, pv1 = brent_max_phi(t_a, t_b, Fprev, yprev, tprev, hprev, n, p, prev_mode, prev_side,
                                         prev_sig, prev_stuck, prev_n0x, prev_n0y, ybuf, dybuf, auxbuf, counter)
                tp2, pv2 = brent_max_phi(t, seg_end, Fd, y, t, h, n, p, mode, side, sig, stuck, n0x, n0y,
                                         ybuf, dybuf, auxbuf, counter)
                tpk = tp1 if pv1 >= pv2 else tp2
                pvk = pv1 if pv1 >= pv2 else pv2
                if pv1 >= pv2:
                    dense_eval(Fprev, yprev, tprev, hprev, tpk, n, ybuf)
                else:
                    dense_eval(Fd, y, t, h, tpk, n, ybuf)
                thk = ybuf[Y_THETA]
                # A maximum of Phi must stand out of its bracket: round-off wiggles (e.g. of a
                # creeping slip) have no prominence. Real nutation peaks rise ~0.1 Phi above the
                # bracket ends (two steps away); 1e-6 Phi is far below that. (Maxima at a restart
                # point are kept: Phi peaks where omega_1 = 0, exactly where the k1 sign events are.)
                genuine = pvk - max(phi_a, phi_c) > PEAK_PROMINENCE * abs(pvk)
            if genuine and npk > 0:
                # no physical Phi oscillation is faster than a small fraction of the precession
                # period 2 pi/|theta'|: closer maxima (the sawtooth of a slip creeping at the slip
                # tolerance) are merged into one, the higher
                thd = abs(y[Y_W3] / math.cos(y[Y_ALPHA]))
                if tpk - peaks[npk - 1, 0] < MIN_PEAK_SEPARATION * 2.0 * math.pi / max(thd, 1e-300):
                    if pvk > peaks[npk - 1, 1]:
                        peaks[npk - 1, 0] = tpk
                        peaks[npk - 1, 1] = pvk
                        peaks[npk - 1, 2] = thk
                    genuine = False
            if track_peaks and phi_b > phi_a and phi_b >= phi_c and prev_ok and genuine:
                if npk == peaks.shape[0]:
                    bigger = np.empty((2 * npk, 3))
                    bigger[:npk] = peaks[:npk]
                    peaks = bigger
                peaks[npk, 0] = tpk
                peaks[npk, 1] = pvk
                peaks[npk, 2] = thk
                npk += 1
                # resolve levels that now have a peak after them: f_hat = 2 / (t_k - t_{k-2})
                for L in range(nl):
                    if pending[L] == 1 and tpk > level_out[L, 0]:
                        j = npk - 2
                        while j >= 0 and peaks[j, 0] > level_out[L, 0]:
                            j -= 1
                        if j >= 2:
                            level_out[L, 3] = 2.0 / (peaks[j, 0] - peaks[j - 2, 0])
                            # mean precession rate over the same window (replaces the instantaneous
                            # rate, which the nutation makes jitter by orders of magnitude)
                            level_out[L, 2] = (peaks[j, 2] - peaks[j - 2, 2]) / (peaks[j, 0] - peaks[j - 2, 0])
                        pending[L] = 0
                        n_pending -= 1
            # shift the window; keep this step's dense output for the next bracket
            phi_a, t_a = phi_b, t_b
            phi_b, t_b = phi_c, seg_end
            for r in range(7):
                for i in range(n):
                    Fprev[r, i] = Fd[r, i]
            for i in range(n):
                yprev[i] = y[i]
            tprev = t
            hprev = h
            prev_mode = mode
            prev_side = side
            for i in range(3):
                prev_sig[i] = sig[i]
                prev_stuck[i] = stuck[i]
            prev_n0x = n0x
            prev_n0y = n0y
            prev_ok = True

        # --- advance ------------------------------------------------------------------------
        if mode == SLIDE and running:
            fstats[F_SLIDETIME] += (seg_end if outcome < 0 else fstats[F_TEND]) - t
        if first_k >= 0:
            dense_eval(Fd, y, t, h, seg_end, n, ybuf)
            for i in range(n):
                y[i] = ybuf[i]
            t = seg_end
        else:
            for i in range(n):
                y[i] = y_new[i]
                f[i] = f_new[i]
            t = t_end
        if traj_cap > 0 and outcome < 0:
            if ntraj == traj.shape[0]:
                bigger = np.empty((2 * ntraj, TRAJ_COLS))
                bigger[:ntraj] = traj[:ntraj]
                traj = bigger
            traj[ntraj, 0] = t
            for i in range(n):
                traj[ntraj, 1 + i] = y[i]
            traj[ntraj, 1 + N_FULL] = aux_new[X_PHI] if first_k < 0 else np.nan
            traj[ntraj, 2 + N_FULL] = mode
            ntraj += 1

        if first_k >= 0:
            istats[I_EVENTS] += 1
            k = first_k
            restart_check_cone = False
            if k <= 2:
                istats[I_STICK] += _stick_or_flip(k, t, y, p, mode, side, sig, stuck, n0x, n0y, n, dytmp, auxtmp, counter)
            elif k <= 5:
                i = k - EV_UNSTICK1
                rhs(t, y, p, mode, side, sig, stuck, n0x, n0y, n, dytmp, auxtmp)
                counter[0] += 1
                sig[i] = 1.0 if auxtmp[X_SIG1 + i] > 0.0 else -1.0
                stuck[i] = 0
            elif k == EV_CONE:
                rhs(t, y, p, mode, side, sig, stuck, n0x, n0y, n, dytmp, auxtmp)
                counter[0] += 1
                n0x, n0y = _start_slip(t, y, p, side, sig, stuck, n, auxtmp[X_F1], auxtmp[X_F2], counter)
                mode = SLIDE
                istats[I_TRANS] += 1
            elif k == EV_SLIPEND:
                loss = project_velocity(y, p, side, SLIDE, side, ROLL)
                y[Y_DSLIDE] += loss
                mode = ROLL
                istats[I_TRANS] += 1
                restart_check_cone = True
            elif k == EV_CONTACT or k == EV_FACE:
                if outcome < 0:
                    outcome = oc.CONTACT_LOST if k == EV_CONTACT else oc.FACE_CONTACT
                    fstats[F_TEND] = t
                break
            elif k == EV_SIDE:
                loss = project_velocity(y, p, side, mode, -side, mode)
                fstats[F_DIMPACT] += loss
                side = -side
                istats[I_IMPACTS] += 1
                y[Y_ALPHA] = 0.0
                for i in range(3):
                    stuck[i] = 0
                zeno = t - t_last_impact < ZENO_DTAU
                t_last_impact = t
                if y[Y_W1] * side <= 0.0 or zeno:
                    # the impact left no rotation towards the new side: the disk stands on its
                    # flat edge (line contact, alpha = 0), where this single-contact model ends
                    if outcome < 0:
                        outcome = oc.LINE_CONTACT
                        fstats[F_TEND] = t
                    break
                else:
                    istats[I_STICK] += _consistent_signs(t, y, p, mode, side, sig, stuck, n0x, n0y, n, active, dytmp, auxtmp, counter)
                    restart_check_cone = mode == ROLL
            rhs(t, y, p, mode, side, sig, stuck, n0x, n0y, n, f, aux_new)
            counter[0] += 1
            if restart_check_cone and p[P_MUS] * aux_new[X_PHI] < math.hypot(aux_new[X_F1], aux_new[X_F2]):
                n0x, n0y = _start_slip(t, y, p, side, sig, stuck, n, aux_new[X_F1], aux_new[X_F2], counter)
                mode = SLIDE
                istats[I_TRANS] += 1
                rhs(t, y, p, mode, side, sig, stuck, n0x, n0y, n, f, aux_new)
                counter[0] += 1
            if aux_new[X_OK] == 0.0:
                if outcome < 0:
                    outcome = oc.NUMERICAL_ERROR
                    fstats[F_TEND] = t
                break
            event_values(y, aux_new, p, mode, side, sig, stuck, u_tol, lev, active, g_old)

        else:
            for kk in range(N_EVENTS):
                g_old[kk] = g_new[kk]
            if nl > next_level:
                g_old[EV_LEVEL] = energy(y, p, side, mode) - lev
        if mode == SLIDE and outcome < 0:
            un = math.hypot(y[Y_U1], y[Y_U2])
            if un > u_tol:
                n0x = y[Y_U1] / un
                n0y = y[Y_U2] / un
            else:
                # slip at or below slip_tol: the friction direction is frozen (p[P_UFREEZE]), so keep
                # it the consistent one as the state moves on (cheap secant from the last one)
                nu = refine_direction(t, y, p, side, sig, stuck, n, math.atan2(n0y, n0x), counter)
                n0x = math.cos(nu)
                n0y = math.sin(nu)
                rhs(t, y, p, mode, side, sig, stuck, n0x, n0y, n, f, auxtmp)
                counter[0] += 1
        if hit_tmax and outcome < 0 and first_k < 0:
            outcome = oc.T_MAX
            fstats[F_TEND] = t
        h = h_next

    if outcome < 0:
        outcome = oc.STEP_LIMIT
    if outcome != oc.HALTED:
        fstats[F_TEND] = t
        for i in range(n):
            y_end[i] = y[i]
        end_mode = mode
        end_side = side
    istats[I_OUTCOME] = outcome
    istats[I_RHS] = counter[0]
    istats[I_TRAJ] = ntraj
    istats[I_PEAKS] = npk
    fstats[F_EEND] = energy(y_end, p, end_side, end_mode)
    fstats[F_HLAST] = h
    return istats, fstats, level_out, samples, traj[:ntraj], peaks[:npk], y_end
