"""A SciPy driver of the same Euler's-disk model: SciPy's own steppers, located events, restarts.

This is what a researcher would write instead of `sweep`'s hybrid integrator (issues #3, #8): the
same equations (`sweep.core.model.rhs`, numba-compiled, or its plain-Python/NumPy `py_func` for the
"plain NumPy" peer) and the same plastic impulse (`sweep.core.impulse.project_velocity`). The
discrete rules are written here again from the physics in docs/model.md, in plain Python and
independently of the kernel's contact modules (only constants are read from the kernel):

* modes ROLL (no slip; the friction that rolling needs, inside the static cone), SLIDE (friction
  -mu_d Phi u/|u|) and SLAVED (a slow slip whose direction is the slow manifold of its direction
  dynamics: the attracting quasi-static direction nu, the root of cross(nu) = 0 (the slip
  acceleration at the slip |u| s(nu) parallel to s(nu), d cross/d nu < 0), plus its lag
  (Disk.lag); the sliding equations are evaluated at the slip vector u itself with the friction
  held on -mu_d Phi s(nu + lag));
* ROLL -> SLAVED where mu_s Phi - |F| reaches 0: the slip starts at u = 0 along a direction in which
  the sliding equations make it grow (a_P parallel to s, a_P.s > 0), attracting, nearest -F/|F|;
* SLAVED -> ROLL where u.s(nu) reaches 0 (plastic impulse removes what is left of the slip);
  SLAVED -> SLIDE where |u| grows to SLAVE_EXIT x the slaving speed u_s = max(slip_tol,
  mu_d Phi max(SLAVE_FLOOR, slave_tol / (1 + |theta'|))), or where the attracting direction ceases to exist (a fold: d cross/d nu
  reaches 0, or no root is left near the last one: the stepper cannot continue and the fold is the
  last accepted point); after a fold the hand-over back to SLAVED is off until |u| grows past
  SLAVE_EXIT x u_s again;
* SLIDE at |u| = slip_tol: its fate from the slip's direction dynamics near u = 0 (the direction
  flow d nu/ds = cross, d ln|u|/ds = rad integrated with the state frozen, Disk.slip_fate): a slip
  that shrinks to u = 0 along nu settles onto nu (the cross slip removed plastically) and ends as a
  slaved slip where u.s(nu) reaches 0; one that spirals out slides on with no slip end until |u| is
  past SLAVE_EXIT x u_s; any other (an ending slip still pointing away from nu, one spiralling in,
  one passing by u = 0) slides on and meets its fate again 16 times slower, down to the round-off
  floor, where an ending slip is ended by the plastic impulse (its loss booked to sliding; ROLL)
  and one that passes by u = 0 (it grows along the direction where the flow settles) goes through
  it: the impulse removes the slip and a slaved slip leaves from u = 0 along that direction, no
  transition; SLIDE ->
  SLAVED where |u| falls to u_s, onto the root of cross that the direction dynamics
  d nu/d tau = cross/|u| carry the slip to (the cross slip removed plastically); none on the whole
  circle, or a slip that the impulse would leave pointing against the root (it is passing by
  u = 0): it stays in SLIDE, the hand-over off until |u| grows past SLAVE_EXIT x u_s again;
* moment signs sigma_i = sign(omega.a_i) with Filippov sticking: at omega.a_i = 0 a component
  sticks if the moment needed to hold it is within k_i Phi (|sigma needed| < 1), else it passes;
  a stuck component leaves where |sigma needed| reaches 1, with that sign; a free component that
  slows to |omega.a_i| = spin_tol (from above) sticks there if its motion, integrated ahead, reaches
  omega.a_i = 0 before it turns back (Disk.reaches_rest) and the moment can hold it there, and the
  rate left is stopped by the least (kinetic-energy) change of the velocity that keeps the contact
  and the stuck components at rest (loss booked to k_i), else it stays free;
* after every discrete update (the driver's 'settle'): a slip at or past 'slipfast' (a slaved slip
  at SLAVE_EXIT x u_s, which a stop at spin_tol can carry there) slides, the hand-over re-armed; a
  slide at or below slip_tol meets its fate; a
  component whose omega.a_i an impulse moved takes the sign of its new omega.a_i (a stuck one is
  released, a finite moment cannot hold it through an impulse, unless the move is within spin_tol;
  a free one left past its switching surface by no more than spin_tol is at rest and gets the stick
  test); a free component at or past its switching surface gets the stick test; a stuck component whose needed moment now exceeds k_i Phi
  (the contact law changed under it) is released with that sign; Phi <= 0 is contact loss; a
  rolling state outside the static cone starts to slip;
* an event function that is <= 0 at a restart (the state sits on that surface: alpha = 0 after
  an impact, omega.a_i = 0 after an un-stick, u.s = 0 at a slip onset) is armed from the surface:
  if the first step ends at or past it, a point inside where it is positive is searched for (a
  return within the step); if there is none it never left and the event happens at once;
* alpha = 0: plastic impact of the other rim edge (loss booked to impact), which releases every
  held component; each free sign is then that of its omega.a_i (an exact 0 gets the stick test)
  and a rolling contact outside the cone slips; line contact if no
  rotation towards the new side is left or two impacts come within ZENO_DTAU; Phi = 0: contact
  lost; pi/2 - |alpha| = BETA_FACE: the disk lies flat, a halt (every level not yet reached gets
  that time); the contact law without a solution (rhs flag -1) ends the scene as `painleve`;
* halt levels by energy (E = E_ss(level)); a level already passed after an impulse is recorded at
  the restart time.
* counts: an update makes a roll<->slip transition where the contact rolls on one side of it and
  slips on the other (a slip that ends and slips again at once within one update counts none); a
  stick phase is counted where a component sticks.
No rule depends on rtol, atol or the step size.

The integration uses SciPy's `OdeSolver` classes (DOP853, RK45, LSODA, Radau, ...) step by step,
as `solve_ivp` does, with the driver's own event scan (sign change at the step ends; inside a step,
for every event function, the minimum of a cubic Hermite interpolant: exact end slopes for the sign,
spin and side functions, the minimum of |u| for the slip speeds, end slopes by differences on the
dense output for the rest, plus 7 interior samples for the cone and un-stick margins) and location
(Illinois regula falsi on the stepper's dense output to a bracket of a few ulp; the restart is at
the bracket's post-event end). A new solver (default initial step) starts at every restart. The slaved direction's root is
continued from the last accepted step end (never from a rejected stage).

Usage:
    from tests.reference.scipy_driver import run_scipy
    res = run_scipy(cfg_dict, method="DOP853", rtol=1e-12, atol=1e-14, sample_tau=np.linspace(0, 100, 101))
"""
from __future__ import annotations

import math
import time
import types

import numpy as np
import scipy.integrate as _si
from scipy.optimize import minimize_scalar as _minimize_scalar
from numba.core.registry import CPUDispatcher

from sweep import outcomes
from sweep.core import contact_rhs as _contact_rhs
from sweep.core import event_rules as _event_rules
from sweep.core import impulse as _impulse
from sweep.core import model
from sweep.core.model import (N_AUX, N_CORE, P_A, P_C, P_H, P_K1, P_K2, P_K3, P_MUD, P_MUS, P_SLAVE, P_UTOL, P_WTOL, X_F1, X_F2,
                              X_G1, X_LAG, X_NU, X_OK, X_PHI, X_SLAVE_ERR, X_SIG1, Y_ALPHA, Y_DK1, Y_DSLIDE, Y_U1, Y_U2, Y_W1, Y_W2, Y_W3)
from sweep.scene import Scene, load_scene
from sweep.simulate import initial_state, level_energies

__all__ = ["run_scipy", "numba_backend", "numpy_backend", "Backend"]

# physical constants of the rules (documented in docs/model.md)
BETA_FACE = _event_rules.BETA_FACE
ZENO_DTAU = _event_rules.ZENO_DTAU
SLAVE_EXIT = _contact_rhs.SLAVE_EXIT
SLAVE_FLOOR = _contact_rhs.SLAVE_FLOOR
FLOOR_EXIT = _contact_rhs.FLOOR_EXIT

ROLL, SLIDE, SLAVED = 0, 1, 2     # driver modes; model.rhs knows ROLL (0) and SLIDE (1)
DIR_TOL = 1e-14                   # convergence of the slaved direction (rad)
CONE_SAMPLES = 7                  # interior points at which a step's cone margin is checked for a dip
ROUNDOFF = 1e-14                  # ... or |cross| below this fraction of the slip acceleration
DIR_JUMP = 0.3                    # rad: a root farther than this from the last one is another root
DCROSS_STEP = 1e-6                # rad: central difference of d cross/d nu (error ~1e-12 relative)
FLOW_STEP = 1e-6                  # tau: central difference of d cross/d tau along the motion (the lag)
EPS = float(np.finfo(float).eps)
DRIFT_STEP = 1e-4                 # tau x (1 + |theta'|): central difference of the first-order manifold (Disk.manifold)

# events in a fixed order (a tie goes to the first)
SIGN = ("sign0", "sign1", "sign2")
UNSTICK = ("unstick0", "unstick1", "unstick2")
SPIN = ("spin0", "spin1", "spin2")
ORDER = (*SIGN, *UNSTICK, "cone", "slipslow", "slipstop", "slipfast", "slave", "contact", "side", "face",
         "slave_lost", *SPIN)
DIP_CHECKED = {*SIGN, *SPIN, "cone", "side"}   # also checked inside a step (a double crossing)
# ... and, inside a step only, the un-stick margins 1 - |sigma_i| of held components (a needed
# moment that rises past the limit and falls back within one step: a release the kernel, which
# checks every event function inside its steps, makes; harness seed 20261126 scene 34)
DIP_INSIDE = DIP_CHECKED | set(UNSTICK)
# ... and the slip speed against slip_tol and the slaving speed where a slide passes by u = 0 inside
# a step: |u| has a V there, narrower than the step (harness seed 20261128 scene 39)
DIP_INSIDE |= {"slipslow", "slave"}
# ... and every other event function, as the kernel checks them all: the slaved slip's stop
# u.s = 0, its exit to SLIDE and the fold of its direction, the normal force, the face (harness seed
# 20261133 scene 127: a slaved slip that slowed to u.s = 0 at 2.3e-5 tau into a step of 3.9e-3 tau,
# and sped up again along its direction before the step's end, was a slip with no stop here)
DIP_INSIDE |= {"slipstop", "slipfast", "slave_lost", "contact", "face"}
# the events that read the right-hand side (forces, the slaved direction): a dip that only the dense
# output shows stands where the state integrated to its minimum confirms it (kernel: reads_forces)
FORCE_EVENTS = {"cone", *UNSTICK, "slipslow", "slipstop", "slipfast", "slave_lost", "contact"}
STEP_MIN_XATOL = 1e-12   # the minimum of a function over a step: its position to this fraction of the step   # the dip-checked events that read the contact forces


def _axes_rate(i, y, f):
    """d/dtau of omega.a_i from the state and its derivative (kinematics of the a-frame)."""
    s, c = math.sin(y[Y_ALPHA]), math.cos(y[Y_ALPHA])
    w1, w2, w3 = y[Y_W1], y[Y_W2], y[Y_W3]
    if i == 0:
        return f[Y_W1]
    if i == 1:
        return f[Y_W2] * c - f[Y_W3] * s - w1 * (w2 * s + w3 * c)
    return f[Y_W2] * s + f[Y_W3] * c + w1 * (w2 * c - w3 * s)


def _step_minimum(fun, t_old, hstep):
    """(x, fun(t_old + x hstep)) at the minimum of fun over a step, x in [0, 1] (bounded Brent).
    In the step's own coordinate: SciPy's bounded method stops at sqrt(eps) |x| + xatol / 3, which
    in absolute time (|t| ~ 100, a step of 1e-8) is wider than the step itself, so it returned its
    first golden-section point (harness seed 20261128 scene 19: |u| 1.342e-9 there against a
    minimum of 1.250e-9 under slip_tol 1.264e-9)."""
    res = _minimize_scalar(lambda x: fun(t_old + x * hstep), bounds=(0.0, 1.0), method="bounded",
                           options={"xatol": STEP_MIN_XATOL})
    return float(res.x), float(res.fun)


def _hermite_min(g0, d0, g1, d1):
    """x in (0, 1) of the lowest interior minimum of the cubic Hermite interpolant (end values g,
    end slopes d per unit x); None if it has none."""
    a = 3.0 * (d0 + d1) + 6.0 * (g0 - g1)
    b = -6.0 * (g0 - g1) - 4.0 * d0 - 2.0 * d1
    c = d0
    xs = []
    if a == 0.0:
        if b != 0.0:
            xs.append(-c / b)
    else:
        disc = b * b - 4.0 * a * c
        if disc >= 0.0:
            q = -0.5 * (b + math.copysign(math.sqrt(disc), b))
            if q != 0.0:
                xs += [q / a, c / q]
    best = None
    for x in xs:
        if 0.0 < x < 1.0 and 2.0 * a * x + b > 0.0:
            h = ((1 + 2 * x) * (1 - x) ** 2 * g0 + x * (1 - x) ** 2 * d0 + x * x * (3 - 2 * x) * g1
                 + x * x * (x - 1) * d1)
            if best is None or h < best[1]:
                best = (x, h)
    return None if best is None else best[0]

METHODS = {"RK23": _si.RK23, "RK45": _si.RK45, "DOP853": _si.DOP853, "Radau": _si.Radau, "BDF": _si.BDF,
           "LSODA": _si.LSODA}


# --- backends: the compiled kernels, or the same source run as plain Python/NumPy ----------------

def _pure(disp, memo):
    """The plain-Python version of a numba function, with every numba callee replaced likewise."""
    if disp in memo:
        return memo[disp]
    f = disp.py_func
    g = dict(f.__globals__)
    fn = types.FunctionType(f.__code__, g, f.__name__, f.__defaults__, f.__closure__)
    memo[disp] = fn
    for name in f.__code__.co_names:
        v = f.__globals__.get(name)
        if isinstance(v, CPUDispatcher):
            g[name] = _pure(v, memo)
    return fn


class Backend(types.SimpleNamespace):
    """rhs, energy, project_velocity (the model's equations and the plastic impulse)."""


_NAMES = dict(rhs=model.rhs, energy=model.energy, project_velocity=_impulse.project_velocity)


def numba_backend() -> Backend:
    return Backend(name="numba", **_NAMES)


def numpy_backend() -> Backend:
    memo: dict = {}
    return Backend(name="numpy", **{k: _pure(v, memo) for k, v in _NAMES.items()})


# --- the contact and its rules -------------------------------------------------------------------

class _Timeout(Exception):
    pass


class Contact:
    """The discrete contact state."""

    def __init__(self, side):
        self.mode = ROLL
        self.side = side
        self.sig = [1.0, 1.0, 1.0]
        self.stuck = [False, False, False]
        self.nu = 0.0
        self.slave_off = False   # also "below": a slow slide followed below slip_tol (slow_slide)
        self.slow_off = False    # a slide spiralling out from u = 0: no slip end until fast again
        self.floor = 0.0         # the slip speed of its next fate (slave_off "below")

    def copy(self):
        c = Contact(self.side)
        c.mode, c.nu, c.slave_off, c.slow_off = self.mode, self.nu, self.slave_off, self.slow_off
        c.floor = self.floor
        c.sig = list(self.sig)
        c.stuck = list(self.stuck)
        return c

    def sig_arr(self):
        """sigma_i as the model's array (rebuilt only when the signs changed)."""
        key = tuple(self.sig)
        if getattr(self, "_sk", None) != key:
            self._sk, self._sa = key, np.array(key)
        return self._sa

    def stuck_arr(self):
        key = tuple(self.stuck)
        if getattr(self, "_tk", None) != key:
            self._tk, self._ta = key, np.array([1.0 if v else 0.0 for v in key])
        return self._ta


def _axes(y):
    """omega.a_1, omega.a_2, omega.a_3."""
    s, c = math.sin(y[Y_ALPHA]), math.cos(y[Y_ALPHA])
    return y[Y_W1], y[Y_W2] * c - y[Y_W3] * s, y[Y_W2] * s + y[Y_W3] * c


class Disk:
    """The model's right-hand side per contact state and the discrete rules (plain Python)."""

    def __init__(self, be, p, n, u_tol, stats):
        self.be, self.n, self.u_tol, self.stats = be, n, u_tol, stats
        self.p = np.array(p, dtype=float)
        self.p[P_UTOL] = 0.0              # the pure model: friction along u/|u| for u != 0
        self.pf = self.p.copy()
        self.pf[P_UTOL] = math.inf        # friction along the given direction whatever u
        self.k = (self.p[P_K1], self.p[P_K2], self.p[P_K3])
        self.S = np.zeros((7, 12))
        self.calls = 0
        self.t_impact = -math.inf
        self.log = None

    # -- right-hand sides --

    def model(self, t, y, mode, c, nx, ny, p=None):
        dy = np.empty(self.n)
        aux = np.empty(N_AUX)
        self.be.rhs(y, self.p if p is None else p,
                    model.Contact(ROLL if mode == ROLL else SLIDE, c.side, c.sig_arr(), c.stuck_arr(), nx, ny),
                    self.n, dy, aux)
        self.calls += 1
        return dy, aux

    def cross_dot(self, nu, u, t, y, c):
        """Slip acceleration across and along s(nu) for the slip vector u s(nu)."""
        cs, sn = math.cos(nu), math.sin(nu)
        ys = np.array(y[:self.n], dtype=float)
        ys[Y_U1] = u * cs
        ys[Y_U2] = u * sn
        dy, aux = self.model(t, ys, SLIDE, c, cs, sn)
        return dy[Y_U2] * cs - dy[Y_U1] * sn, dy[Y_U1] * cs + dy[Y_U2] * sn

    def dcross(self, nu, u, t, y, c):
        return (self.cross_dot(nu + DCROSS_STEP, u, t, y, c)[0]
                - self.cross_dot(nu - DCROSS_STEP, u, t, y, c)[0]) / (2.0 * DCROSS_STEP)

    def lag(self, nu, u, t, y, c):
        """The slaved slip's lag (rad) behind the quasi-static direction nu: the slow manifold of
        d nu/d tau = cross(nu)/u with the lag proportional to u (it shrinks and grows with the
        slip, as fast as the direction relaxes): u (nu*' + lag') = c' lag, lag' = lag u'/u, so
        lag = u nu*'/(c' - u') with nu*' = -(d cross/d tau at fixed nu)/c' (the root moves with
        the motion), c' = d cross/d nu, u' = rad; central differences in nu and along the motion
        (docs/model.md, 'Slow slip'). 0 where c' - u' >= 0 or c' >= 0.

        Returns (lag exp(-err^4), err): err = |u| (1 + |theta'|) / (u' - c') + |lag|, how far this
        first order is from exact (inf where the direction does not relax onto the root); the
        damping takes the lag to 0 where the series does not hold (err >> 1, c' - u' -> 0-)."""
        cross0, rad0 = self.cross_dot(nu, u, t, y, c)
        dc = self.dcross(nu, u, t, y, c)
        if not (dc < 0.0 and dc - rad0 < 0.0):
            return 0.0, math.inf
        if u == 0.0:
            return 0.0, 0.0
        cs, sn = math.cos(nu), math.sin(nu)
        ys = np.array(y[:self.n], dtype=float)
        ys[Y_U1], ys[Y_U2] = u * cs, u * sn
        dy, _ = self.model(t, ys, SLIDE, c, cs, sn)
        step = min(FLOW_STEP, 0.5 * u / abs(rad0)) if rad0 != 0.0 else FLOW_STEP   # the slip stays > 0
        up = self.cross_dot(nu, u + step * rad0, t + step, ys + step * dy, c)[0]
        um = self.cross_dot(nu, u - step * rad0, t - step, ys - step * dy, c)[0]
        root_rate = -((up - um) / (2.0 * step)) / dc
        lag = u * root_rate / (dc - rad0)
        err = u * (1.0 + abs(y[Y_W3] / math.cos(y[Y_ALPHA]))) / (rad0 - dc) + abs(lag)
        return lag * math.exp(-err ** 4), err

    def manifold(self, nu, u, t, y, c):
        """(lag, err) of the slow manifold to second order in the relaxation time. The manifold
        h(state) obeys u Dh = cross(h) exactly (D: the rate along the motion, the friction along h).
        The first-order manifold h1 = nu + lag (Disk.lag) is differenced centrally along the motion
        at the slip vector u s(h1) with the friction along h1 (each side's root continued from nu
        and its own first-order lag), and h solves cross(h) = u Dh1 (secant to convergence): the
        residual is third order. err: the first-order measure, or where larger the cube root of the
        third order's estimate d2^2/|lag| (d2 = h - h1) (docs/model.md, 'Slow slip'). The first
        order where slave_tol is 0 or |lag| err is at round-off."""
        lag, err = self.lag(nu, u, t, y, c)
        if not (self.p[P_SLAVE] > 0.0 and math.isfinite(err) and abs(lag) * err > EPS):
            return lag, err
        h1 = nu + lag
        ys = np.array(y[:self.n], dtype=float)
        ys[Y_U1], ys[Y_U2] = u * math.cos(h1), u * math.sin(h1)
        dy, _ = self.model(t, ys, SLIDE, c, math.cos(h1), math.sin(h1))
        rad = dy[Y_U1] * math.cos(h1) + dy[Y_U2] * math.sin(h1)
        step = DRIFT_STEP / (1.0 + abs(y[Y_W3] / math.cos(y[Y_ALPHA])))
        if rad != 0.0:
            step = min(step, 0.5 * u / abs(rad))
        ends = []
        for sgn in (1.0, -1.0):
            z = ys + sgn * step * dy
            uz = math.hypot(z[Y_U1], z[Y_U2])
            root = self.slaved_root(nu, uz, t + sgn * step, z, c)
            if math.isnan(root):
                return lag, err
            lz, ez = self.lag(root, uz, t + sgn * step, z, c)
            if not math.isfinite(ez):
                return lag, err
            ends.append(root + lz)
        drift = u * (ends[0] - ends[1]) / (2.0 * step)
        xa, xb = h1, h1 + 1e-9
        fa = self.cross_dot(xa, u, t, y, c)[0] - drift
        fb = self.cross_dot(xb, u, t, y, c)[0] - drift
        for _ in range(20):
            if fb == fa or abs(xb - xa) < 1e-16:
                break
            xa, fa, xb = xb, fb, xb - fb * (xb - xa) / (fb - fa)
            fb = self.cross_dot(xb, u, t, y, c)[0] - drift
        d2 = xb - h1
        return xb - nu, max(err, (d2 * d2 / abs(lag)) ** (1.0 / 3.0))

    def slaved_root(self, seed, u, t, y, c):
        """The root of cross(nu) continued from seed (secant); NaN if none within DIR_JUMP."""
        xa, xb = seed, seed + 1e-7
        ca, da = self.cross_dot(xa, u, t, y, c)
        if abs(ca) <= ROUNDOFF * math.hypot(ca, da):
            return xa
        cb, db = self.cross_dot(xb, u, t, y, c)
        for _ in range(40):
            # converged: the update is below DIR_TOL, or cross is at its round-off floor (near a fold
            # the iterates can stall there, two of them giving the same rounded value)
            if abs(xb - xa) < DIR_TOL or abs(cb) <= ROUNDOFF * math.hypot(cb, db):
                return xb if abs(xb - seed) <= DIR_JUMP else math.nan
            if cb == ca:
                return math.nan
            dx = -cb * (xb - xa) / (cb - ca)
            dx = max(-0.1, min(0.1, dx))
            xa, ca = xb, cb
            xb = xb + dx
            if abs(xb - seed) > DIR_JUMP:
                return math.nan
            cb, db = self.cross_dot(xb, u, t, y, c)
        return math.nan

    def rhs(self, t, y, c, seed):
        """(dy, aux, nu) for the contact c; SLAVED: nu is the root continued from seed (NaN: none)."""
        if c.mode == SLAVED:
            u = math.hypot(y[Y_U1], y[Y_U2])
            nu = self.slaved_root(seed, u, t, y, c)
            if math.isnan(nu):
                dy = np.full(self.n, math.nan)
                aux = np.full(N_AUX, math.nan)
                aux[X_OK] = 0.0
                return dy, aux, nu
            lag, err = self.manifold(nu, u, t, y, c)
            dy, aux = self.model(t, y, SLIDE, c, math.cos(nu + lag), math.sin(nu + lag), self.pf)
            aux[X_NU], aux[X_LAG], aux[X_SLAVE_ERR] = nu, lag, err
            return dy, aux, nu
        if c.mode == SLIDE:
            un = math.hypot(y[Y_U1], y[Y_U2])
            if un > 0.0:
                dy, aux = self.model(t, y, SLIDE, c, y[Y_U1] / un, y[Y_U2] / un)
            else:
                dy, aux = self.model(t, y, SLIDE, c, math.cos(c.nu), math.sin(c.nu))
            return dy, aux, c.nu
        dy, aux = self.model(t, y, ROLL, c, 1.0, 0.0)
        return dy, aux, c.nu

    def energy(self, y, c):
        return self.be.energy(y, self.p, c.side, ROLL if c.mode == ROLL else SLIDE)

    def slip_roundoff(self, t, phi):
        """The speed that the friction's deceleration bound mu_d Phi (1 + 1/A) takes off in 256 ulps
        of tau: an approach to u = 0 closer than that cannot be stepped through in double precision
        (docs/model.md, 'Where a slip ends')."""
        decel = self.p[P_MUD] * max(phi, 0.0) * (1.0 + 1.0 / self.p[P_A])
        return 256.0 * np.finfo(float).eps * max(abs(t), 1.0) * decel

    def slip_floor(self, t, phi, c):
        """The slip speed at which a slide meets its fate: slip_tol (a slide followed below it: its
        own floor), or the round-off floor where that is larger."""
        return max(c.floor if c.slave_off == "below" else self.u_tol, self.slip_roundoff(t, phi))

    @staticmethod
    def _slip_dir(y, c):
        un = math.hypot(y[Y_U1], y[Y_U2])
        return (y[Y_U1] / un, y[Y_U2] / un) if un > 0.0 else (math.cos(c.nu), math.sin(c.nu))

    def slaved_margin(self, y, aux, err):
        """> 0 while a slaved slip stays slaved: below SLAVE_EXIT x the slaving speed, and its
        direction's error below SLAVE_EXIT x slave_tol or the slip below SLAVE_EXIT x the floor's
        speed SLAVE_FLOOR mu_d Phi."""
        u = math.hypot(y[Y_U1], y[Y_U2])
        margin = 1.0 - u / self.exit_speed(y, aux)
        if self.p[P_SLAVE] > 0.0:
            floor = 1.0 - u / (FLOOR_EXIT * SLAVE_FLOOR * self.p[P_MUD] * max(aux[X_PHI], 0.0))
            margin = min(margin, max(floor, 1.0 - err / (SLAVE_EXIT * self.p[P_SLAVE])))
        return margin

    def exit_speed(self, y, aux):
        """Where a slaved slip slides: SLAVE_EXIT x slave_tol's slaving speed, at least FLOOR_EXIT x
        the floor's."""
        rate = 1.0 + abs(y[Y_W3] / math.cos(y[Y_ALPHA]))
        return max(FLOOR_EXIT * self.u_tol,
                   self.p[P_MUD] * aux[X_PHI] * max(FLOOR_EXIT * SLAVE_FLOOR, SLAVE_EXIT * self.p[P_SLAVE] / rate))

    def slave_speed(self, y, aux):
        """Where the direction is slaved: relaxation time |u|/(mu_d Phi) times the motion's rate
        1 + |theta'| (theta' = omega_3 / cos alpha) below slave_tol; at least slip_tol."""
        rate = 1.0 + abs(y[Y_W3] / math.cos(y[Y_ALPHA]))
        return max(self.u_tol, self.p[P_MUD] * aux[X_PHI] * max(SLAVE_FLOOR, self.p[P_SLAVE] / rate))

    # -- directions --

    def onset_direction(self, t, y, c):
        """Slip onset at u = 0: a direction s with a_P parallel to s and a_P.s > 0 (the slip grows),
        where the sliding law has a solution, attracting (d cross/d nu < 0), nearest -F/|F|; the
        nearest growing root if none attracts; one without a solution (painleve) only if no root
        has one. A sign change of cross with a solution on one side only is the pole at a Painleve
        boundary, not a root."""
        _, aux = self.model(t, y, ROLL, c, 1.0, 0.0)
        guess = math.atan2(-aux[X_F2], -aux[X_F1])
        m = 128
        xs = [guess - math.pi + 2.0 * math.pi * j / m for j in range(m + 1)]
        cr = [self.cross_dot(x, 0.0, t, y, c)[0] for x in xs]
        best = (math.inf, math.inf, math.inf, guess)   # (no solution, not attracting, distance, root)
        for j in range(m):
            if (cr[j] > 0.0) == (cr[j + 1] > 0.0):
                continue
            lo, hi, clo = xs[j], xs[j + 1], cr[j]
            for _ in range(100):
                mid = 0.5 * (lo + hi)
                if not lo < mid < hi or hi - lo < 1e-15:
                    break
                cm = self.cross_dot(mid, 0.0, t, y, c)[0]
                if (cm > 0.0) == (clo > 0.0):
                    lo, clo = mid, cm
                else:
                    hi = mid
            root = 0.5 * (lo + hi)
            none_lo, none_hi = self.no_solution(lo, 0.0, t, y, c), self.no_solution(hi, 0.0, t, y, c)
            if none_lo != none_hi or self.cross_dot(root, 0.0, t, y, c)[1] <= 0.0:
                continue
            repelling = 0 if self.dcross(root, 0.0, t, y, c) < 0.0 else 1
            d = abs(math.atan2(math.sin(root - guess), math.cos(root - guess)))
            best = min(best, (int(none_lo), repelling, d, root))
        if best[1] == 1:
            self.stats["onset_repelling"] += 1
        return best[3]

    def no_solution(self, nu, u, t, y, c):
        """The sliding contact law at slip u s(nu) has no solution (Painleve: Phi's coefficient <= 0)."""
        cs, sn = math.cos(nu), math.sin(nu)
        ys = np.array(y[:self.n], dtype=float)
        ys[Y_U1] = u * cs
        ys[Y_U2] = u * sn
        try:
            return self.model(t, ys, SLIDE, c, cs, sn)[1][X_OK] < 0.0
        except ZeroDivisionError:   # on the singular direction itself (the pure-Python model)
            return True

    def attracting_direction(self, nu, u, t, y, c):
        """The root of cross that d nu/d tau = cross/u carries nu to (NaN: none on the circle; inf:
        what stops it is the Painleve singularity, cross changing sign through a pole of Phi)."""
        if self.no_solution(nu, u, t, y, c):
            return math.inf
        c0 = self.cross_dot(nu, u, t, y, c)[0]
        if c0 == 0.0:
            return nu

        def passed(x):
            return self.no_solution(x, u, t, y, c) or (self.cross_dot(x, u, t, y, c)[0] > 0.0) != (c0 > 0.0)

        sense = 1.0 if c0 > 0.0 else -1.0
        step = (2.0 * math.pi / 128) * sense
        xa, ca, x_prev, c_prev = nu, abs(c0), nu, math.inf
        for j in range(1, 129):
            xb = nu + j * step
            c_b = self.cross_dot(xb, u, t, y, c)[0]
            crossed = self.no_solution(xb, u, t, y, c) or (c_b > 0.0) != (c0 > 0.0)   # passed(xb)
            lo, hi = xa, xb
            cb = abs(c_b)
            if not crossed and ca < c_prev and ca <= cb:
                # |cross| dips at xa: a root pair narrower than a step may hide between its neighbours
                from scipy.optimize import minimize_scalar

                a, b = sorted((x_prev, xb))
                res = minimize_scalar(lambda x: sense * self.cross_dot(x, u, t, y, c)[0], bounds=(a, b),
                                      method="bounded", options={"xatol": 1e-12})
                if res.fun <= 0.0 or self.no_solution(res.x, u, t, y, c):
                    crossed, lo, hi = True, x_prev, res.x
            if crossed:
                for _ in range(100):
                    mid = 0.5 * (lo + hi)
                    if abs(hi - lo) < 1e-15 or mid in (lo, hi):
                        break
                    if passed(mid):
                        hi = mid
                    else:
                        lo = mid
                return math.inf if self.no_solution(hi, u, t, y, c) else 0.5 * (lo + hi)
            x_prev, c_prev, xa, ca = xa, ca, xb, cb
        return math.nan

    # -- discrete rules --

    def to_roll(self, y, c):
        """A slip ends: the plastic contact impulse removes it (loss booked to sliding)."""
        y[Y_DSLIDE] += self.be.project_velocity(y, self.p, (c.side, True), (c.side, False), self.S)
        c.mode = ROLL

    def slip_fate(self, t, y, c):
        """What a slide at |u| = slip_tol does next (docs/model.md, 'Where a slip ends'), found by
        integrating the slip's direction dynamics near u = 0 with the rest of the state frozen:
        in the time s with ds = d tau/|u|, d nu/ds = cross(nu) and d ln|u|/ds = rad(nu) (the slip
        acceleration across and along s(nu) at the slip vector |u| s(nu)). Integrated (SciPy
        DOP853) until nu settles (cross at its round-off) or has turned twice round the circle:
        ("ends", nu) where ln|u| falls at the end (the direction settles on nu where the slip
        shrinks; nan where it spirals inwards), ("passes", nu) where it grows along the settled nu,
        ("spirals_out", nan) where it grows while turning, ("jammed", nan) where the direction runs
        into the Painleve singularity."""
        u = math.hypot(y[Y_U1], y[Y_U2])
        nu0 = math.atan2(y[Y_U2], y[Y_U1])
        if self.no_solution(nu0, u, t, y, c):
            return "jammed", math.nan
        scale = 1.0
        for j in range(16):
            scale = max(scale, math.hypot(*self.cross_dot(2.0 * math.pi * j / 16, u, t, y, c)))
        jammed = []

        def flow(_s, z):
            if self.no_solution(z[0], u, t, y, c):
                jammed.append(z[0])
                return [0.0, 0.0]
            cr, rd = self.cross_dot(z[0], u, t, y, c)
            return [cr, rd]

        def settled(_s, z):
            return abs(self.cross_dot(z[0], u, t, y, c)[0]) - 1e-10 * scale
        settled.terminal = True

        def turned(_s, z):
            return abs(z[0] - nu0) - 4.0 * math.pi
        turned.terminal = True
        if abs(self.cross_dot(nu0, u, t, y, c)[0]) <= 1e-10 * scale:
            sol_nu = nu0
        else:
            sol = _si.solve_ivp(flow, (0.0, 1e4 / scale), [nu0, 0.0], method="DOP853", rtol=1e-10,
                                atol=1e-12, events=(settled, turned))
            if jammed:
                return "jammed", math.nan
            sol_nu = sol.y[0, -1]
            if sol.t_events[1].size:
                # still turning after two turns: the change of ln|u| over one more full turn decides
                def one_turn(_s, z):
                    return abs(z[0] - sol_nu) - 2.0 * math.pi
                one_turn.terminal = True
                turn = _si.solve_ivp(flow, (0.0, 1e4 / scale), [sol_nu, 0.0], method="DOP853", rtol=1e-10,
                                     atol=1e-12, events=(one_turn,))
                return ("spirals_out", math.nan) if turn.y[1, -1] > 0.0 else ("ends", math.nan)
        rad = self.cross_dot(sol_nu, u, t, y, c)[1]
        return ("passes", sol_nu) if rad > 0.0 else ("ends", sol_nu)

    def slow_slide(self, t, y, c):
        """A slide at |u| = slip_tol (or at its own lower floor), by its fate: one that ends along nu
        settles onto nu (the cross slip removed plastically) and ends as a slaved slip where u.s(nu)
        reaches 0; one that spirals out slides on, no slip end until fast again; any other (an
        ending slip still pointing away from nu, one spiralling in, one passing by u = 0) slides on
        and meets its fate again 16 times slower, down to the round-off floor, where an ending slip
        is ended by the plastic impulse (rolling) and a passing one goes through u = 0 (the impulse
        removes the slip and a slaved slip leaves from u = 0 along its direction of growth; no
        transition). Returns outcomes.PAINLEVE where the direction is carried into the singularity,
        else -1."""
        fate, nu = self.slip_fate(t, y, c)
        if self.log is not None:
            self.log.append((t, "slip_fate", fate, nu))
        self.stats["fate_" + fate] = self.stats.get("fate_" + fate, 0) + 1
        if fate == "jammed":
            return outcomes.PAINLEVE
        if fate == "spirals_out":
            c.slow_off = True
            return -1
        if fate == "ends" and math.isfinite(nu) and self.settle_onto(nu, t, y, c) == "settled":
            c.slave_off = False
            return -1
        phi = self.model(t, y, SLIDE, c, *self._slip_dir(y, c))[1][X_PHI]
        floor = min(self.slip_floor(t, phi, c), math.hypot(y[Y_U1], y[Y_U2])) / 16.0
        if floor > self.slip_roundoff(t, phi):
            c.slave_off, c.floor = "below", floor
            return -1
        if fate == "ends":
            self.to_roll(y, c)
            return -1
        y[Y_DSLIDE] += self.be.project_velocity(y, self.p, (c.side, True), (c.side, False), self.S)
        y[Y_U1] = 0.0
        y[Y_U2] = 0.0
        c.mode, c.nu, c.slave_off = SLAVED, nu, False
        return -1

    def start_slip(self, t, y, c):
        c.nu = self.onset_direction(t, y, c)
        c.mode = SLAVED
        c.slave_off = False
        y[Y_U1] = 0.0
        y[Y_U2] = 0.0

    def cone_violated(self, t, y, c):
        _, aux = self.model(t, y, ROLL, c, 1.0, 0.0)
        return aux[X_PHI] > 0.0 and self.p[P_MUS] * aux[X_PHI] < math.hypot(aux[X_F1], aux[X_F2])

    def try_slave(self, t, y, c):
        """Returns outcomes.PAINLEVE where the slip is carried into the Painleve singularity, else -1."""
        u = math.hypot(y[Y_U1], y[Y_U2])
        at_floor = c.slave_off == "floor"   # the floor's hand-over takes the slip whatever its error
        root = self.attracting_direction(math.atan2(y[Y_U2], y[Y_U1]), u, t, y, c)
        if math.isinf(root):
            phi = self.rhs(t, y, c, c.nu)[1][X_PHI]
            if self.p[P_SLAVE] > 0.0 and u > SLAVE_FLOOR * self.p[P_MUD] * phi and not at_floor:
                c.slave_off = "floor"   # decided at the floor's speed, as at slave_tol 0
                return -1
            return outcomes.PAINLEVE
        if math.isnan(root):
            c.slave_off = True
            return -1
        settled = self.settle_onto(root, t, y, c, strict=not at_floor)
        if settled == "against":
            c.slave_off = True    # pointing against it: passing by u = 0, it goes on sliding
        elif settled == "inaccurate":
            c.slave_off = "floor"    # handed over at the floor's speed SLAVE_FLOOR mu_d Phi instead
        return -1

    def settle_onto(self, root, t, y, c, strict=False):
        """SLIDE -> SLAVED at the quasi-static direction root, the slip across the slaved
        direction there (root plus its lag) removed by the plastic impulse, if that leaves the slip
        along it, and, strict (the hand-over at the slaving speed above the floor's), the slaved
        direction's error within slave_tol; else nothing changes. Returns 'settled', 'against' or
        'inaccurate'."""
        saved = y.copy()
        u = math.hypot(y[Y_U1], y[Y_U2])
        lag, err = self.manifold(root, u, t, y, c)
        along = root + lag
        turn = math.atan2(y[Y_U2], y[Y_U1]) - along
        turn = abs(math.atan2(math.sin(turn), math.cos(turn)))
        if strict and self.p[P_SLAVE] > 0.0 and not (err <= self.p[P_SLAVE] and turn <= self.p[P_SLAVE]):
            cs_, sn_ = math.cos(root), math.sin(root)
            ys = np.array(y[:self.n], dtype=float)
            ys[Y_U1], ys[Y_U2] = u * cs_, u * sn_
            phi = self.model(t, ys, SLIDE, c, cs_, sn_)[1][X_PHI]
            if u > SLAVE_FLOOR * self.p[P_MUD] * phi:
                # the first-order slow manifold is no good here, or the direction has yet to
                # relax onto it: it slides on
                return "inaccurate"
        loss = self.be.project_velocity(y, self.p, (c.side, True), (c.side, True), self.S, along)
        if y[Y_U1] * math.cos(along) + y[Y_U2] * math.sin(along) > 0.0:
            y[Y_DSLIDE] += loss
            c.mode = SLAVED
            c.nu = root
            return "settled"
        y[:] = saved
        return "against"

    def set_slip(self, t, y, c):
        """Contact state for a given slip vector (start, or after an impact while slipping)."""
        un = math.hypot(y[Y_U1], y[Y_U2])
        if un > self.u_tol:
            c.mode, c.nu, c.slave_off, c.slow_off = SLIDE, math.atan2(y[Y_U2], y[Y_U1]), False, False
            _, aux = self.model(t, y, SLIDE, c, y[Y_U1] / un, y[Y_U2] / un)
            if un <= self.slave_speed(y, aux):
                return self.try_slave(t, y, c)
            return -1
        root = self.attracting_direction(math.atan2(y[Y_U2], y[Y_U1]), un, t, y, c)
        if math.isinf(root):
            return outcomes.PAINLEVE
        if math.isnan(root):
            c.mode, c.nu, c.slave_off, c.slow_off = SLIDE, math.atan2(y[Y_U2], y[Y_U1]), True, False
        else:
            c.mode, c.nu = SLAVED, root
        return -1

    def needed_sigma(self, i, t, y, c):
        """sigma_i that holds omega.a_i at 0 (component i treated as stuck). A slaved slip's friction
        acts along its direction at this instant: the root for the contact state as it is (where
        there is none, the slip vector's own direction), not one solved with component i held."""
        nu = c.nu
        if c.mode == SLAVED:
            u = math.hypot(y[Y_U1], y[Y_U2])
            root = self.slaved_root(c.nu, u, t, y, c)
            nu = math.atan2(y[Y_U2], y[Y_U1]) if math.isnan(root) else root + self.manifold(root, u, t, y, c)[0]
        was = c.stuck[i]
        c.stuck[i] = True
        if c.mode == SLAVED:
            _, aux = self.model(t, y, SLIDE, c, math.cos(nu), math.sin(nu), self.pf)
        else:
            _, aux, _ = self.rhs(t, y, c, c.nu)
        c.stuck[i] = was
        return aux[X_SIG1 + i]

    def slip_fast(self, t, y, c):
        """Is the slip at or past the 'slipfast' surface (a slaved slip at SLAVE_EXIT x u_s; a slide
        with the hand-over off, fast again)? Phi as a decision reads it (needed_sigma's friction
        direction, no component held)."""
        if not (c.mode == SLAVED or (c.mode == SLIDE and (c.slave_off or c.slow_off))):
            return False
        un = math.hypot(y[Y_U1], y[Y_U2])
        if c.mode == SLAVED:
            root = self.slaved_root(c.nu, un, t, y, c)
            lag, err = (0.0, math.inf) if math.isnan(root) else self.manifold(root, un, t, y, c)
            nu = math.atan2(y[Y_U2], y[Y_U1]) if math.isnan(root) else root + lag
            _, aux = self.model(t, y, SLIDE, c, math.cos(nu), math.sin(nu), self.pf)
            return self.slaved_margin(y, aux, err) <= 0.0
        _, aux, _ = self.rhs(t, y, c, c.nu)
        return self.exit_speed(y, aux) - un <= 0.0

    def stick_test(self, i, t, y, c, force=False):
        """At omega.a_i = 0: stick if the moment can hold it, else pass with the needed sign.
        force: the sign just taken failed at once, the other opposes the motion: stick."""
        need = self.needed_sigma(i, t, y, c)
        if abs(need) < 1.0 or (force and (1.0 if need > 0.0 else -1.0) == c.sig[i]):
            c.stuck[i] = True
            self.stats["n_stick"] += 1
            if self.log is not None:
                self.log.append((t, "stick", i, need))
        else:
            c.stuck[i] = False
            c.sig[i] = 1.0 if need > 0.0 else -1.0

    def reaches_rest(self, i, t, y, c):
        """Does free component i, slowing through |omega.a_i| = spin_tol, go on to rest (omega.a_i = 0)
        rather than turn back above it? Its motion in the contact state c is integrated ahead (SciPy
        DOP853, rtol 1e-12) to whichever comes first: g = sigma_i omega.a_i reaching 0, or g' reaching
        0 (a minimum above 0); not past 8 g/|g'|, by which a motion that keeps falling has reached 0.
        Returns (t, y) at rest, or None."""
        sig = c.sig[i]
        seed = [c.nu]

        def f(tt, yy):
            dy, _, nu = self.rhs(tt, yy, c, seed[0])
            if c.mode == SLAVED and math.isfinite(nu):
                seed[0] = nu
            return dy

        def g(tt, yy):
            return sig * _axes(yy)[i]

        def slope(tt, yy):
            return sig * _axes_rate(i, yy, f(tt, yy))
        g.terminal = True
        g.direction = -1
        slope.terminal = True
        slope.direction = 1
        y0 = np.array(y[:self.n], dtype=float)
        g0, d0 = g(t, y0), slope(t, y0)
        if not d0 < 0.0:
            return None
        sol = _si.solve_ivp(f, (t, t + 8.0 * g0 / -d0), y0, method="DOP853", rtol=1e-12,
                            atol=1e-15, events=(g, slope))
        if sol.t_events[0].size and (not sol.t_events[1].size or sol.t_events[0][0] <= sol.t_events[1][0]):
            y_rest = np.array(y, dtype=float)
            y_rest[:self.n] = sol.y_events[0][0]
            return sol.t_events[0][0], y_rest
        return None

    def spin_stop(self, i, t, y, c):
        """|omega.a_i| has slowed to spin_tol: it sticks if the moment can hold it, and the rate left
        is stopped by the least change of the velocity in the kinetic-energy metric that keeps the
        contact (rolling, or sliding with the slip free) and the stuck components at rest
        (Lagrange multipliers on all of (w1, w2, w3, u1, u2)); the loss is booked to k_i."""
        rest = self.reaches_rest(i, t, y, c)
        if rest is None:
            return False
        need = self.needed_sigma(i, *rest, c)    # where the Filippov rule decides: at rest
        if abs(need) >= 1.0:
            return False
        p, h = self.p, c.side * self.p[P_H]
        sa, ca = math.sin(y[Y_ALPHA]), math.cos(y[Y_ALPHA])
        # V = J q: centre velocity and omega on e1, e2, e3 for q = (w1, w2, w3, u1, u2)
        J = np.array([[0.0, 1.0, -h, 1.0, 0.0], [-1.0, 0.0, 0.0, 0.0, ca], [h, 0.0, 0.0, 0.0, -sa],
                      [1.0, 0.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0, 0.0]])
        M = np.diag([1.0, 1.0, 1.0, p[P_A], p[P_C], p[P_A]])
        axes = np.array([[1.0, 0.0, 0.0], [0.0, ca, -sa], [0.0, sa, ca]])
        q0 = np.array([y[Y_W1], y[Y_W2], y[Y_W3], y[Y_U1], y[Y_U2]])
        if c.mode == ROLL:
            q0[3:] = 0.0
        rows, rhs = [], []
        if c.mode == ROLL:
            rows += [[0.0, 0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 0.0, 1.0]]
            rhs += [0.0, 0.0]
        for j in range(3):
            if j == i or c.stuck[j]:
                rows.append([*axes[j], 0.0, 0.0])
                rhs.append(0.0)
        C = np.array(rows)
        V0 = J @ q0
        A = J.T @ M @ J
        m = C.shape[0]
        kkt = np.block([[A, C.T], [C, np.zeros((m, m))]])
        sol = np.linalg.solve(kkt, np.concatenate([J.T @ M @ V0, rhs]))
        q = sol[:5]
        dv = V0 - J @ q
        saved = y.copy()
        y[Y_W1], y[Y_W2], y[Y_W3] = q[0], q[1], q[2]
        if c.mode != ROLL:
            y[Y_U1], y[Y_U2] = q[3], q[4]
        # the moment must hold it at the state the stop leaves as well (where later decisions read
        # it), in the mode they read it in (a slaved slip that the stop carries past its exit slides)
        c.stuck[i] = True
        mode = c.mode
        if mode == SLAVED and self.slip_fast(t, y, c):
            c.mode = SLIDE
        holds = abs(self.needed_sigma(i, t, y, c)) < 1.0
        c.mode = mode
        if not holds:
            y[:] = saved
            c.stuck[i] = False
            return False
        y[Y_DK1 + i] += 0.5 * float(dv @ M @ dv)
        self.stats["n_stick"] += 1
        if self.log is not None:
            self.log.append((t, "stick_spin", i, need))
        return True

    def settle(self, t, y, c, g_before, leaving=()):
        """After a discrete update: bring the contact state in line with the state (see the module
        docstring). `leaving`: components just released at an un-stick (on their surface, leaving)."""
        if self.slip_fast(t, y, c):
            c.mode, c.slave_off, c.slow_off = SLIDE, False, False
        if c.mode == SLIDE and not c.slow_off and \
                math.hypot(y[Y_U1], y[Y_U2]) <= self.slip_floor(t, self.model(t, y, SLIDE, c, *self._slip_dir(y, c))[1][X_PHI], c):
            code = self.slow_slide(t, y, c)
            if code >= 0:
                return code
        g = _axes(y)
        for i in range(3):
            if self.k[i] > 0.0 and g[i] != g_before[i]:
                if c.stuck[i] and abs(g[i] - g_before[i]) <= self.p[P_WTOL]:
                    continue   # moved within spin_tol: still at rest (docs/model.md)
                if not c.stuck[i] and c.sig[i] * g[i] <= 0.0 and abs(g[i]) <= self.p[P_WTOL]:
                    continue   # left within spin_tol of its surface: at rest, the stick test below
                if c.stuck[i]:
                    self.stats["released_by_impulse"] += 1
                c.stuck[i] = False
                if g[i] != 0.0:
                    c.sig[i] = 1.0 if g[i] > 0.0 else -1.0
                else:
                    self.stick_test(i, t, y, c)
        for _ in range(6):
            changed = False
            for i in range(3):
                if self.k[i] == 0.0 or i in leaving:
                    continue
                if not c.stuck[i] and c.sig[i] * g[i] <= 0.0:
                    before = (c.stuck[i], c.sig[i])
                    self.stick_test(i, t, y, c)
                    if (c.stuck[i], c.sig[i]) != before:
                        changed = True
                        break
                elif c.stuck[i]:
                    need = self.needed_sigma(i, t, y, c)
                    if abs(need) >= 1.0:
                        c.stuck[i] = False
                        c.sig[i] = 1.0 if need > 0.0 else -1.0
                        self.stats["unstick_at_restart"] += 1
                        if self.log is not None:
                            self.log.append((t, "unstick_at_restart", i, need, c.mode))
                        changed = True
                        break
            if not changed and c.mode == ROLL and self.cone_violated(t, y, c):
                self.start_slip(t, y, c)
                changed = True
            if not changed:
                return -1
        return -1

    def consistent_signs(self, t, y, c):
        """After the start or an impact: each free sign is that of its omega.a_i, an exact 0 gets
        the stick test; a rolling contact outside the static cone starts to slip."""
        g = _axes(y)
        for i in range(3):
            if self.k[i] > 0.0:
                if g[i] != 0.0:
                    c.sig[i] = 1.0 if g[i] > 0.0 else -1.0
                else:
                    self.stick_test(i, t, y, c)
        if c.mode == ROLL and self.cone_violated(t, y, c):
            self.start_slip(t, y, c)

    def side_change(self, t, y, c):
        """alpha = 0: plastic impact of the other rim edge. Returns an outcome code or -1."""
        slipping = c.mode != ROLL
        self.stats["impact_loss"] += self.be.project_velocity(y, self.p, (c.side, slipping), (-c.side, slipping),
                                                              self.S)
        c.side = -c.side
        self.stats["n_impacts"] += 1
        y[Y_ALPHA] = 0.0
        c.stuck = [False, False, False]
        zeno = t - self.t_impact < ZENO_DTAU
        self.t_impact = t
        if y[Y_W1] * c.side <= 0.0 or zeno:
            return outcomes.LINE_CONTACT
        if slipping:
            return self.set_slip(t, y, c)
        return -1


# --- the driver ----------------------------------------------------------------------------------

def _locate(g, a, ga, b, gb):
    """Illinois regula falsi: a bracket [a, b] with g(a) > 0 >= g(b) of a few ulp; returns (a, b)."""
    side = 0
    while b - a > 4.0 * np.spacing(max(abs(a), abs(b), 1e-300)):
        x = (a * gb - b * ga) / (gb - ga) if gb != ga else 0.5 * (a + b)
        if not a < x < b:
            x = 0.5 * (a + b)
            if not a < x < b:
                break
        gx = g(x)
        if gx > 0.0:
            a, ga = x, gx
            if side == 1:
                gb *= 0.5
            side = 1
        else:
            b, gb = x, gx
            if side == -1:
                ga *= 0.5
            side = -1
    return a, b


def run_scipy(scene, method: str = "DOP853", rtol: float = 1e-10, atol: float | None = None,
              sample_tau=None, backend: Backend | None = None, max_segments: int = 200_000,
              max_wall: float = math.inf, log: list | None = None, clock=time.perf_counter) -> dict:
    """Integrate one scene with a SciPy stepper and the contact rules written above.

    scene: a scene dict/YAML path or a validated `Scene` (its solver section is ignored except
    slip_tol; stop.levels, stop.t_max are used). Times are dimensionless (tau = t/chi).
    Returns a dict: outcome (name), outcome_code, level_tau (array, NaN if not reached),
    level_alpha, sample_tau, samples (n x N_CORE state, NaN after the end), energy_initial/final
    (dimensionless), nfev (stepper RHS calls), njev, nlu, n_rhs (model calls in all; a slaved
    right-hand side is several), n_rhs_events (those not made by the stepper), n_segments
    (restarts), n_events, n_transitions, n_stick, n_impacts, t_end, wall (s), timed_out, and
    diagnostics (counts of rules the kernel may not have: onset_repelling, unstick_at_restart,
    released_by_impulse, fold_by_failure, reslaved_after_update; events by kind).
    max_wall: give up (outcome 'step_limit', timed_out True) once this much time is used, measured
    by `clock` (wall time by default; time.process_time for CPU time).
    """
    be = backend or numba_backend()
    sc = scene if isinstance(scene, Scene) else load_scene(scene)
    cfg = sc.config
    if atol is None:
        atol = rtol * 1e-2
    solver_cls = METHODS[method]
    n = N_CORE
    t_max = cfg["stop"]["t_max"] / sc.chi
    u_tol = cfg["solver"]["slip_tol"] * sc.chi / cfg["disk"]["radius"]
    w_tol = cfg["solver"]["spin_tol"] * sc.chi
    level_e = level_energies(sc)
    nl = level_e.size
    smp = np.zeros(0) if sample_tau is None else np.asarray(sample_tau, dtype=float)
    ns = smp.size
    samples = np.full((ns, n), np.nan)
    level_tau = np.full(nl, np.nan)
    level_alpha = np.full(nl, np.nan)
    stats = dict(n_events=0, n_transitions=0, n_stick=0, n_impacts=0, nfev=0, njev=0, nlu=0, n_segments=0,
                 onset_repelling=0, unstick_at_restart=0, released_by_impulse=0, fold_by_failure=0,
                 reslaved_after_update=0,
                 impact_loss=0.0)
    kinds: dict[str, int] = {}
    w0 = clock()
    disk = Disk(be, sc.params, n, u_tol, stats)
    disk.log = log
    p = disk.p
    k_on = [disk.k[i] > 0.0 for i in range(3)]

    y0, _ = initial_state(sc)
    y = np.array(y0[:n], dtype=float)
    t = 0.0
    c = Contact(1 if y[Y_ALPHA] > 0.0 else -1)
    start_code = -1
    if y[Y_U1] != 0.0 or y[Y_U2] != 0.0:
        start_code = disk.set_slip(t, y, c)
    disk.consistent_signs(t, y, c)
    _count_transition(y0[Y_U1] == 0.0 and y0[Y_U2] == 0.0, c, stats)
    e0 = disk.energy(y, c)
    outcome = start_code
    t_end = 0.0
    isamp = 0
    while isamp < ns and smp[isamp] <= 0.0:
        samples[isamp] = y
        isamp += 1
    next_level = 0
    zero_len = 0
    t_last_restart = -1.0

    def finish(code, tt):
        nonlocal outcome, t_end
        outcome, t_end = code, tt

    while outcome < 0:
        # --- restart at (t, y) with the contact c ------------------------------------------------
        _, aux, nu = disk.rhs(t, y, c, c.nu)
        if c.mode == SLAVED:
            if math.isnan(nu):
                # the update (a moment component stuck, released or flipped) changed the slip
                # dynamics and the direction continued from before is no root: the attracting root
                # the direction dynamics carry it to (docs/model.md, 'a slaved slip gets the slaved
                # direction of the contact state the update left')
                root = disk.attracting_direction(c.nu, math.hypot(y[Y_U1], y[Y_U2]), t, y, c)
                if math.isinf(root):
                    finish(outcomes.PAINLEVE, t)
                    break
                if not math.isnan(root):
                    c.nu = root
                    stats["reslaved_after_update"] += 1
                    continue
                # none on the circle: the slip spirals, its direction follows its own dynamics
                c.mode, c.slave_off, c.slow_off = SLIDE, True, False
                stats["fold_by_failure"] += 1
                continue
            c.nu = nu
        if aux[X_OK] < 0.0:
            finish(outcomes.PAINLEVE, t)
            break
        if aux[X_PHI] <= 0.0:
            finish(outcomes.CONTACT_LOST, t)
            break
        while next_level < nl and disk.energy(y, c) <= level_e[next_level]:
            level_tau[next_level] = t
            level_alpha[next_level] = y[Y_ALPHA]
            next_level += 1
        if next_level == nl:
            finish(outcomes.HALTED, t)
            break
        if stats["n_segments"] >= max_segments or clock() - w0 > max_wall:
            stats["timed_out"] = True
            finish(outcomes.STEP_LIMIT, t)
            break
        zero_len = zero_len + 1 if t == t_last_restart else 0
        t_last_restart = t
        if zero_len > 200:
            finish(outcomes.NUMERICAL_ERROR, t)   # discrete updates that never let time advance
            break
        stats["n_segments"] += 1

        seg = c.copy()
        seed = [seg.nu]
        cache = {}

        def info(tt, yy):
            """(aux, nu, dcross) at a point of this segment (cached per time)."""
            hit = cache.get(tt)
            if hit is not None:
                return hit
            _, a, nu_ = disk.rhs(tt, yy, seg, seed[0])
            dc = math.nan
            if seg.mode == SLAVED and not math.isnan(nu_):
                dc = disk.dcross(nu_, math.hypot(yy[Y_U1], yy[Y_U2]), tt, yy, seg)
            r = (a, nu_, dc)
            if len(cache) > 64:
                cache.clear()
            cache[tt] = r
            return r

        active = []
        for i in range(3):
            if k_on[i]:
                active.append(UNSTICK[i] if seg.stuck[i] else SIGN[i])
                if not seg.stuck[i] and w_tol > 0.0:
                    active.append(SPIN[i])
        if not (seg.mode == SLIDE and seg.slow_off):
            active.append({ROLL: "cone", SLIDE: "slipslow", SLAVED: "slipstop"}[seg.mode])
        if seg.mode == SLAVED:
            active += ["slipfast", "slave_lost"]
        if seg.mode == SLIDE and (not seg.slave_off or seg.slave_off == "floor"):
            active.append("slave")
        if seg.mode == SLIDE and (seg.slave_off or seg.slow_off):
            active.append("slipfast")      # fast again: the hand-over is re-armed
        active += ["contact", "side", "face"]
        active.sort(key=ORDER.index)

        def gval(kind, tt, yy):
            a, nu_, dc = info(tt, yy)
            if kind[:4] == "sign":
                i = int(kind[4])
                return seg.sig[i] * a[X_G1 + i]
            if kind[:4] == "spin":
                i = int(kind[4])
                return seg.sig[i] * a[X_G1 + i] - w_tol
            if kind[:7] == "unstick":
                return 1.0 - abs(a[X_SIG1 + int(kind[7])])
            if kind == "cone":
                return p[P_MUS] * a[X_PHI] - math.hypot(a[X_F1], a[X_F2])
            if kind == "slipslow":
                return math.hypot(yy[Y_U1], yy[Y_U2]) - disk.slip_floor(tt, a[X_PHI], seg)
            if kind == "slave":
                if seg.slave_off == "floor":
                    return math.hypot(yy[Y_U1], yy[Y_U2]) - max(disk.u_tol, SLAVE_FLOOR * p[P_MUD] * a[X_PHI])
                return math.hypot(yy[Y_U1], yy[Y_U2]) - disk.slave_speed(yy, a)
            if kind == "slipstop":
                along = nu_ + a[X_LAG]
                return yy[Y_U1] * math.cos(along) + yy[Y_U2] * math.sin(along)
            if kind == "slipfast":
                if seg.mode != SLAVED:
                    return disk.exit_speed(yy, a) - math.hypot(yy[Y_U1], yy[Y_U2])
                # a slaved slip leaves where it is fast, or where its slaved direction's error is large
                return disk.slaved_margin(yy, a, a[X_SLAVE_ERR])
            if kind == "slave_lost":
                return -dc
            if kind == "contact":
                return a[X_PHI]
            if kind == "side":
                return seg.side * yy[Y_ALPHA]
            if kind == "face":
                return (0.5 * math.pi - abs(yy[Y_ALPHA])) - BETA_FACE
            raise KeyError(kind)

        g0 = {k: gval(k, t, y) for k in active}
        # a spin event below spin_tol at the restart is armed once the rate exceeds spin_tol
        shift = {k: (-v if v <= 0.0 and k not in SPIN else 0.0) for k, v in g0.items()}
        on_surface = {k for k, v in g0.items() if v <= 0.0 and k not in SPIN}
        at_once = [k for k in on_surface if k not in DIP_CHECKED and k not in ("slipstop", "side")
                   and k[:4] != "sign"]
        if at_once:
            # on a surface that a restart cannot leave (e.g. a fold at the restart): happens now
            kind = min(at_once, key=ORDER.index)
            code = _apply(kind, t, y, c, disk, stats, kinds, [], True)
            if code >= 0:
                if code == outcomes.HALTED:
                    level_tau[next_level:] = t
                    next_level = nl
                finish(code, t)
            continue
        g_old = {k: g0[k] + shift[k] for k in active}

        calls = [0]

        def fun(tt, yy):
            calls[0] += 1
            if calls[0] % 2000 == 0 and clock() - w0 > max_wall:
                raise _Timeout
            return disk.rhs(tt, yy, seg, seed[0])[0]

        solver = solver_cls(fun, t, y, t_max, rtol=rtol, atol=atol)
        first_step = True
        f_old = np.array(solver.f) if hasattr(solver, "f") else disk.rhs(t, y, seg, seed[0])[0]
        ev = None
        try:
            while ev is None and outcome < 0:
                msg = solver.step()
                if solver.status == "failed":
                    if seg.mode == SLAVED:
                        # the attracting direction ceased to exist (a fold): the stepper cannot
                        # pass it; hand over to SLIDE at the last accepted point
                        t, y = solver.t, np.array(solver.y)
                        info_nu = info(t, y)[1]
                        c.nu = info_nu if not math.isnan(info_nu) else seed[0]
                        c.mode, c.slave_off, c.slow_off = SLIDE, True, False
                        stats["fold_by_failure"] += 1
                        stats["n_events"] += 1
                        ev = ("fold", t)
                        break
                    finish(outcomes.STEP_SIZE_UNDERFLOW if "step size" in str(msg) else outcomes.NUMERICAL_ERROR,
                           solver.t)
                    t = solver.t
                    break
                t_old, t_new = solver.t_old, solver.t
                y_new = np.array(solver.y)
                f_new = np.array(solver.f) if hasattr(solver, "f") else disk.rhs(t_new, y_new, seg, seed[0])[0]
                cache.clear()   # a time maps to one state within one step's dense output
                a_new, nu_new, _ = info(t_new, y_new)
                if a_new[X_OK] < 0.0:
                    finish(outcomes.PAINLEVE, t_old)
                    t = t_old
                    break
                if seg.mode == SLAVED and not math.isnan(nu_new):
                    seed[0] = nu_new
                dense_box = []

                def dense(tt):
                    if not dense_box:
                        dense_box.append(solver.dense_output())
                    return dense_box[0](tt)

                def gd(kind, tt):
                    return gval(kind, tt, dense(tt)) + shift[kind]

                g_new = {k: gval(k, t_new, y_new) + shift[k] for k in active}
                best = None   # (restart time, order, kind, at once)
                for k in active:
                    br = None
                    if g_old[k] > 0.0 and g_new[k] <= 0.0:
                        br = (t_old, g_old[k], t_new, g_new[k])
                    elif first_step and k in on_surface and g_new[k] <= 0.0:
                        # armed from the surface: a return within the first step, or it never left
                        x = 0.5
                        for _ in range(60):
                            tm = t_old + x * (t_new - t_old)
                            gm = gd(k, tm)
                            if gm > 0.0:
                                br = (tm, gm, t_new, g_new[k])
                                break
                            x *= 0.5
                        if br is None:
                            cand = (t_old, ORDER.index(k), k, True)
                            best = cand if best is None or cand[:2] < best[:2] else best
                            continue
                    elif k in SPIN and g_old[k] <= 0.0 and g_new[k] <= 0.0:
                        # below spin_tol at both ends: a rise past it and back within the step, by
                        # the maximum of the cubic Hermite interpolant, confirmed on the dense output
                        i, hstep = int(k[4]), t_new - t_old
                        x = _hermite_min(-g_old[k], -seg.sig[i] * _axes_rate(i, y, f_old) * hstep, -g_new[k],
                                         -seg.sig[i] * _axes_rate(i, y_new, f_new) * hstep)
                        if x is not None:
                            tm = t_old + x * hstep
                            gm = gd(k, tm)
                            if gm > 0.0:
                                br = (tm, gm, t_new, g_new[k])
                    elif k in DIP_INSIDE and g_old[k] > 0.0 and g_new[k] > 0.0:
                        # a double crossing inside the step: the signs and side by the minimum of
                        # the cubic Hermite interpolant (exact end slopes), the cone and un-stick below;
                        # confirmed on the dense output
                        hstep = t_new - t_old
                        if k == "side":
                            x = _hermite_min(g_old[k], seg.side * y[Y_W1] * hstep, g_new[k],
                                             seg.side * y_new[Y_W1] * hstep)
                            xs = [] if x is None else [x]
                        elif k[:4] in ("sign", "spin"):
                            i = int(k[4])
                            x = _hermite_min(g_old[k], seg.sig[i] * _axes_rate(i, y, f_old) * hstep, g_new[k],
                                             seg.sig[i] * _axes_rate(i, y_new, f_new) * hstep)
                            xs = [] if x is None else [x]
                        elif k in ("slipslow", "slave"):
                            # |u| falls at the start and rises at the end: its minimum on the dense output
                            xs = []
                            if (y[Y_U1] * f_old[Y_U1] + y[Y_U2] * f_old[Y_U2] < 0.0
                                    and y_new[Y_U1] * f_new[Y_U1] + y_new[Y_U2] * f_new[Y_U2] > 0.0):
                                xm, _ = _step_minimum(lambda tt: float(np.hypot(*np.asarray(dense(tt))[[Y_U1, Y_U2]])),
                                                      t_old, hstep)
                                xs = [xm]
                        else:
                            # the others have no exact slope: their Hermite minimum with end slopes by differences
                            # on the dense output, and for the cone and un-stick margins CONE_SAMPLES interior points
                            dt = 1e-6 * hstep
                            d0 = (gd(k, t_old + dt) - g_old[k]) / dt * hstep
                            d1 = (g_new[k] - gd(k, t_new - dt)) / dt * hstep
                            x = _hermite_min(g_old[k], d0, g_new[k], d1)
                            inner = CONE_SAMPLES if k == "cone" or k in UNSTICK else 0
                            xs = sorted([j / (inner + 1) for j in range(1, inner + 1)]
                                        + ([] if x is None else [x]))
                        # the first candidate at or below 0 brackets the dip
                        g_low = math.inf
                        for xj in xs:
                            tm = t_old + xj * hstep
                            gm = gd(k, tm)
                            g_low = min(g_low, gm)
                            if gm <= 0.0:
                                br = (t_old, g_old[k], tm, gm)
                                break
                        if br is None and g_low < 0.1 * min(g_old[k], g_new[k]):
                            # a shallow dip: decided by the minimum of g on the dense output
                            xm, gm = _step_minimum(lambda tt, k=k: gd(k, tt), t_old, hstep)
                            if gm <= 0.0:
                                br = (t_old, g_old[k], t_old + xm * hstep, gm)
                        if br is not None and k in FORCE_EVENTS:
                            # a dip of an event of the forces that only the dense output shows
                            # stands where the state integrated to its minimum confirms it
                            sub = solver_cls(fun, t_old, y, br[2], rtol=rtol, atol=atol)
                            while sub.status == "running":
                                sub.step()
                            cache.pop(br[2], None)   # info() caches per time: the dense state's
                            g_int = gval(k, br[2], np.array(sub.y)) + shift[k]
                            cache.pop(br[2], None)
                            if not g_int <= 0.0:
                                br = None
                    if br is not None:
                        _, tb = _locate(lambda tt, k=k: gd(k, tt), *br)
                        cand = (tb, ORDER.index(k), k, False)
                        best = cand if best is None or cand[:2] < best[:2] else best
                t_seg = best[0] if best is not None else t_new
                y_seg = np.array(dense(t_seg)) if best is not None else y_new
                # halt levels on [t_old, t_seg] (the energy never increases: one root each)
                while next_level < nl:
                    e_end = disk.energy(y_seg, seg) - level_e[next_level]
                    if e_end > 0.0:
                        break
                    e_start = disk.energy(np.array(dense(t_old)), seg) - level_e[next_level]
                    if e_start <= 0.0:
                        tl = t_old
                    else:
                        la, lb = _locate(lambda tt: disk.energy(dense(tt), seg) - level_e[next_level],
                                         t_old, e_start, t_seg, e_end)
                        tl = 0.5 * (la + lb)
                    level_tau[next_level] = tl
                    level_alpha[next_level] = dense(tl)[Y_ALPHA]
                    next_level += 1
                    if next_level == nl:
                        finish(outcomes.HALTED, tl)
                t_stop = t_end if outcome >= 0 else t_seg
                while isamp < ns and smp[isamp] <= t_stop:
                    if smp[isamp] > t_old:
                        samples[isamp] = dense(smp[isamp])
                    isamp += 1
                if outcome >= 0:
                    break
                if best is not None:
                    ev = best
                    t, y = t_seg, y_seg
                    break
                g_old = g_new
                f_old = f_new
                first_step = False
                t, y = t_new, y_new
                if solver.status == "finished":
                    finish(outcomes.T_MAX, t_new)
                    break
        except _Timeout:
            stats["timed_out"] = True
            finish(outcomes.STEP_LIMIT, t)
        stats["nfev"] += solver.nfev
        stats["njev"] += solver.njev
        stats["nlu"] += solver.nlu
        if outcome >= 0 or ev is None or ev[0] == "fold":
            continue
        # --- the discrete update at the event -----------------------------------------------------
        _, kind, now = ev[0], ev[2], ev[3]
        a_ev, nu_ev, _ = info(t, y)
        if seg.mode == SLAVED and not math.isnan(nu_ev):
            c.nu = nu_ev
        code = _apply(kind, t, y, c, disk, stats, kinds, [], now)
        if code >= 0:
            if code == outcomes.HALTED:
                level_tau[next_level:] = t
                next_level = nl
            finish(code, t)

    wall = clock() - w0
    n_rhs = disk.calls
    return dict(outcome=outcomes.NAMES[outcome], outcome_code=outcome, level_tau=level_tau,
                level_alpha=level_alpha, sample_tau=smp, samples=samples, t_end=t_end,
                energy_initial=float(e0), energy_final=float(disk.energy(y, c)),
                n_rhs_events=n_rhs - stats["nfev"], n_rhs=n_rhs, wall=wall, method=method,
                rtol=rtol, atol=atol, backend=be.name, timed_out=stats.pop("timed_out", False),
                event_kinds=kinds, **stats)


def _count_transition(rolling_before, c, stats):
    """A roll<->slip transition where the contact rolled before an update and slips after it (or the
    reverse); a slip that ends and, outside the cone, slips again at once within the update never
    rolled and counts none."""
    if rolling_before != (c.mode == ROLL):
        stats["n_transitions"] += 1


def _apply(kind, t, y, c, disk, stats, kinds, leaving_out, now=False):
    """The discrete update for event `kind` at (t, y), with its roll<->slip transition counted
    (_count_transition); returns an outcome code or -1."""
    rolling = c.mode == ROLL
    code = _update(kind, t, y, c, disk, stats, kinds, leaving_out, now)
    _count_transition(rolling, c, stats)
    return code


def _update(kind, t, y, c, disk, stats, kinds, leaving_out, now=False):
    """The discrete update for event `kind` at (t, y); returns an outcome code or -1.
    now: the event happened at the restart itself (the state never left that surface)."""
    stats["n_events"] += 1
    kinds[kind] = kinds.get(kind, 0) + 1
    if disk.log is not None:
        disk.log.append((t, kind, c.mode, tuple(c.stuck), tuple(c.sig)))
    g_before = _axes(y)
    if kind[:4] == "sign":
        disk.stick_test(int(kind[4]), t, y, c, force=now)
    elif kind[:4] == "spin":
        if disk.spin_stop(int(kind[4]), t, y, c):
            g_before = _axes(y)   # the stop keeps the stuck components stuck
    elif kind[:7] == "unstick":
        i = int(kind[7])
        need = disk.needed_sigma(i, t, y, c)
        c.stuck[i] = False
        c.sig[i] = 1.0 if need > 0.0 else -1.0
        leaving_out.append(i)
    elif kind == "cone":
        disk.start_slip(t, y, c)
    elif kind == "slipslow":
        code = disk.slow_slide(t, y, c)
        if code >= 0:
            return code
    elif kind == "slipstop":
        disk.to_roll(y, c)
    elif kind == "slipfast":
        c.mode, c.slave_off, c.slow_off = SLIDE, False, False
    elif kind == "slave":
        code = disk.try_slave(t, y, c)
        if code >= 0:
            return code
    elif kind == "slave_lost":
        c.mode, c.slave_off, c.slow_off = SLIDE, True, False
    elif kind == "contact":
        return outcomes.CONTACT_LOST
    elif kind == "face":
        return outcomes.HALTED
    elif kind == "side":
        # the impact releases every held component; each free sign is then that of its omega.a_i
        # (an exact 0 gets the stick test), and a rolling contact outside the cone slips
        code = disk.side_change(t, y, c)
        if code >= 0:
            return code
        disk.consistent_signs(t, y, c)
        return -1
    return disk.settle(t, y, c, g_before, tuple(leaving_out))
