"""A SciPy driver of the same Euler's-disk model: `solve_ivp` with terminal events and a restart loop.

This is what a researcher would write instead of `sweep`'s hybrid integrator (issue #3): the same
equations (`sweep.core.model.rhs`, numba-compiled, or its plain-Python/NumPy `py_func` for the
"plain NumPy" peer), the same plastic impulse (`sweep.core.impulse.project_velocity`) and the
discrete rules of `sweep.core.contact`, written out again here (independently, in plain Python;
only constants are read from the kernel's module):

* contact modes ROLL, SLIDE (|u| > slip_tol, friction along -u/|u|) and SLAVED (a slip starting
  from rest or slower than slip_tol: its direction nu is solved at every right-hand-side call as
  the root of cross(nu) = 0 near the previous one, i.e. slip acceleration parallel to the slip, and
  du/dtau = (s.a) s);
* ROLL -> SLAVED where mu_s Phi - |F| reaches 0, in the onset direction (the consistent growing root
  of cross(nu) at u = 0 nearest -F/|F|, 64-angle scan + refinement);
* SLAVED -> SLIDE where |u| grows to SLAVE_EXIT x the slaving speed u_s = max(slip_tol,
  SLAVE_EPS mu_d Phi); SLAVED -> ROLL where u.s(nu) reaches 0 (no impulse);
* SLIDE -> ROLL where |u| falls to slip_tol, by the plastic impulse (its loss added to the sliding
  dissipation); SLIDE -> SLAVED where |u| falls to u_s and an attracting quasi-static direction
  exists (cross slip removed plastically; a slip the impulse would reverse rolls instead);
  (with SLAVE_EPS absent or 0 in the kernel this reduces to: SLAVED -> SLIDE at slip_tol, no
  SLIDE -> SLAVED hand-over);
* after every discrete update a rolling state is checked against the static cone (onset again);
* sign switches of omega.a_i with Filippov sticking (stick if |sigma needed| < 1, else flip),
  un-sticking where |sigma| reaches 1;
* contact loss (Phi = 0); alpha = 0 side change (impulse to the other rim edge; line contact if
  w1 * side <= 0 after it or two impacts within ZENO_DTAU); face (pi/2 - |alpha| = BETA_FACE):
  the disk lies flat, a halt: every remaining level gets the face time (alpha NaN), outcome halted;
* halt levels by energy (non-terminal events, the last one terminal; a level already passed after
  an impulse is recorded at the restart time, as the kernel does).
No rule depends on rtol, atol or the step size.

Every terminal event ends a `solve_ivp` call; the discrete state is updated and a new call starts
from the event point (default initial step selection, as a user of solve_ivp would do).

Differences from the kernel that are inherent to solve_ivp (docs/performance.md): no Hermite
check for a double crossing inside one step; SciPy locates events with brentq to ~4 ulp and
restarts at the root (the kernel restarts at the right end of a 1e-12 bracket); the slaved
direction's seed follows every right-hand-side call (the kernel's follows accepted steps; the
root is the same to ~1e-14 rad).

Usage:
    from scipy_driver import run_scipy
    res = run_scipy(cfg_dict, method="DOP853", rtol=1e-12, atol=1e-14, sample_tau=np.linspace(0, 100, 101))
"""
from __future__ import annotations

import math
import time
import types

import numpy as np
from numba.core.registry import CPUDispatcher
from scipy.integrate import solve_ivp

from sweep import outcomes
from sweep.core import contact as _contact
from sweep.core import impulse as _impulse
from sweep.core import model
from sweep.core.model import (N_AUX, N_CORE, P_K1, P_K2, P_K3, P_MUD, P_MUS, P_UFREEZE, X_F1, X_F2, X_G1,
                              X_OK, X_PHI, X_SIG1, Y_ALPHA, Y_DSLIDE, Y_U1, Y_U2, Y_W1)
from sweep.scene import Scene, load_scene
from sweep.simulate import initial_state, level_energies

__all__ = ["run_scipy", "numba_backend", "numpy_backend", "Backend"]

BETA_FACE = _contact.BETA_FACE
ZENO_DTAU = _contact.ZENO_DTAU
SLAVE_EPS = getattr(_contact, "SLAVE_EPS", 0.0)
SLAVE_EXIT = getattr(_contact, "SLAVE_EXIT", 1.0)
ROLL, SLIDE, SLAVED = 0, 1, 2     # driver modes; model.rhs knows ROLL (0) and SLIDE (1)
DIR_TOL = 1e-14                   # secant tolerance of the slaved direction (rad)


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


# --- the driver ----------------------------------------------------------------------------------

class _Timeout(Exception):
    pass


class _Counter:
    __slots__ = ("n",)

    def __init__(self):
        self.n = 0


class _State:
    """The discrete contact state."""

    def __init__(self, side):
        self.mode = ROLL
        self.side = side
        self.sig = np.ones(3)
        self.stuck = np.zeros(3)
        self.nu = 0.0
        self.slave_off = False

    def copy(self):
        c = _State(self.side)
        c.mode, c.nu, c.slave_off = self.mode, self.nu, self.slave_off
        c.sig = self.sig.copy()
        c.stuck = self.stuck.copy()
        return c


class _Physics:
    """Right-hand side per contact state and the discrete rules, in plain Python."""

    def __init__(self, be, p, n, u_tol, counter):
        self.be, self.p, self.n, self.u_tol, self.counter = be, p, n, u_tol, counter
        self.S = np.zeros((7, 12))

    def model(self, t, y, mmode, st, nx, ny):
        dy = np.empty(self.n)
        aux = np.empty(N_AUX)
        self.be.rhs(t, y, self.p, mmode, st.side, st.sig, st.stuck, nx, ny, self.n, dy, aux)
        self.counter.n += 1
        return dy, aux

    def slip_rates(self, nu, u, t, y, st):
        """(cross, dot, dy, aux): slip acceleration against the direction s(nu), slip u s(nu)."""
        c, s = math.cos(nu), math.sin(nu)
        ys = np.array(y[:self.n], dtype=float)
        ys[Y_U1] = u * c
        ys[Y_U2] = u * s
        dy, aux = self.model(t, ys, SLIDE, st, c, s)
        return dy[Y_U2] * c - dy[Y_U1] * s, dy[Y_U1] * c + dy[Y_U2] * s, dy, aux

    def slaved_direction(self, nu0, u, t, y, st):
        """Root of cross(nu) near nu0 (secant); (nu, dy, aux) there, aux[X_OK] = 0 if it fails."""
        xa = nu0
        ca, _, dy, aux = self.slip_rates(xa, u, t, y, st)
        if ca == 0.0:
            return xa, dy, aux
        xb = nu0 + 1e-6
        cb, _, dy, aux = self.slip_rates(xb, u, t, y, st)
        for _ in range(50):
            if cb == 0.0 or abs(xb - xa) < DIR_TOL:
                return xb, dy, aux
            if cb == ca:
                break
            xa, ca, xb = xb, cb, xb - cb * (xb - xa) / (cb - ca)
            cb, _, dy, aux = self.slip_rates(xb, u, t, y, st)
        aux[X_OK] = 0.0
        return xb, dy, aux

    def eval(self, t, y, st, update_nu=False):
        """dy, aux for the contact state st (SLAVED: direction solved, du = (s.a) s)."""
        if st.mode == SLAVED:
            u = math.hypot(y[Y_U1], y[Y_U2])
            nu, dy, aux = self.slaved_direction(st.nu, u, t, y, st)
            c, s = math.cos(nu), math.sin(nu)
            dot = dy[Y_U1] * c + dy[Y_U2] * s
            dy[Y_U1] = dot * c
            dy[Y_U2] = dot * s
            self.last_nu = nu
            if update_nu and aux[X_OK] != 0.0:
                st.nu = nu
            return dy, aux
        if st.mode == SLIDE:
            un = math.hypot(y[Y_U1], y[Y_U2])
            if un > 0.0:
                return self.model(t, y, SLIDE, st, y[Y_U1] / un, y[Y_U2] / un)
            return self.model(t, y, SLIDE, st, math.cos(st.nu), math.sin(st.nu))
        return self.model(t, y, ROLL, st, 1.0, 0.0)

    def slave_speed(self, aux):
        return max(self.u_tol, SLAVE_EPS * self.p[P_MUD] * aux[X_PHI])

    def energy(self, y, st):
        return self.be.energy(y, self.p, st.side, ROLL if st.mode == ROLL else SLIDE)

    # -- discrete rules --

    def cone_violated(self, t, y, st):
        _, aux = self.eval(t, y, st)
        return aux[X_PHI] > 0.0 and self.p[P_MUS] * aux[X_PHI] < math.hypot(aux[X_F1], aux[X_F2])

    def onset_direction(self, t, y, st, F1, F2):
        """The growing root of cross(nu) at u = 0 nearest -F/|F| (the guess if there is none)."""
        guess = math.atan2(-F2, -F1)
        cross = lambda x: self.slip_rates(x, 0.0, t, y, st)[0]  # noqa: E731
        xs = guess - math.pi + 2.0 * math.pi * np.arange(65) / 64
        cs = [cross(x) for x in xs]
        best, bestd = guess, math.inf
        for j in range(64):
            if (cs[j] > 0.0) != (cs[j + 1] > 0.0):
                lo, hi, clo = xs[j], xs[j + 1], cs[j]
                while hi - lo > 1e-14 * max(1.0, abs(lo)):
                    mid = 0.5 * (lo + hi)
                    if mid <= lo or mid >= hi:
                        break
                    cm = cross(mid)
                    if (cm > 0.0) == (clo > 0.0):
                        lo, clo = mid, cm
                    else:
                        hi = mid
                root = 0.5 * (lo + hi)
                _, dot, _, _ = self.slip_rates(root, 0.0, t, y, st)
                d = abs(math.atan2(math.sin(root - guess), math.cos(root - guess)))
                if dot > 0.0 and d < bestd:
                    best, bestd = root, d
        return best

    def start_slip(self, t, y, st, stats):
        _, aux = self.model(t, y, ROLL, st, 1.0, 0.0)
        st.mode = SLAVED
        st.nu = self.onset_direction(t, y, st, aux[X_F1], aux[X_F2])
        y[Y_U1] = 0.0
        y[Y_U2] = 0.0
        stats["n_transitions"] += 1

    def attracting_direction(self, nu, u, t, y, st):
        """First root of cross met following d nu/d tau = cross/u from nu; NaN if none on the circle."""
        c0 = self.slip_rates(nu, u, t, y, st)[0]
        if c0 == 0.0:
            return nu
        step = (2.0 * math.pi / 64) * (1.0 if c0 > 0.0 else -1.0)
        xa = nu
        for j in range(1, 65):
            xb = nu + j * step
            if (self.slip_rates(xb, u, t, y, st)[0] > 0.0) != (c0 > 0.0):
                lo, hi = xa, xb
                for _ in range(200):
                    if abs(hi - lo) <= 1e-14 * max(1.0, abs(lo)):
                        break
                    mid = 0.5 * (lo + hi)
                    if (self.slip_rates(mid, u, t, y, st)[0] > 0.0) == (c0 > 0.0):
                        lo = mid
                    else:
                        hi = mid
                return 0.5 * (lo + hi)
            xa = xb
        return math.nan

    def try_slave(self, t, y, st, stats):
        """SLIDE -> SLAVED onto the attracting direction (cross slip removed plastically)."""
        u = math.hypot(y[Y_U1], y[Y_U2])
        root = self.attracting_direction(math.atan2(y[Y_U2], y[Y_U1]), u, t, y, st)
        if math.isnan(root):
            st.slave_off = True
            return
        saved = y.copy()
        loss = self.be.project_velocity(y, self.p, st.side, True, st.side, True, self.S, root)
        if y[Y_U1] * math.cos(root) + y[Y_U2] * math.sin(root) > 0.0:
            y[Y_DSLIDE] += loss
            st.mode = SLAVED
            st.nu = root
            return
        y[:] = saved
        y[Y_DSLIDE] += self.be.project_velocity(y, self.p, st.side, True, st.side, False, self.S)
        st.mode = ROLL
        stats["n_transitions"] += 1
        if self.cone_violated(t, y, st):
            self.start_slip(t, y, st, stats)

    def set_slip(self, t, y, st, stats):
        un = math.hypot(y[Y_U1], y[Y_U2])
        nu = math.atan2(y[Y_U2], y[Y_U1])
        if un > self.u_tol:
            st.mode, st.nu, st.slave_off = SLIDE, nu, False
            _, aux = self.model(t, y, SLIDE, st, 1.0, 0.0)
            if SLAVE_EPS > 0.0 and un <= self.slave_speed(aux):
                self.try_slave(t, y, st, stats)
            return
        st.mode = SLAVED
        st.nu = self.slaved_direction(nu, un, t, y, st)[0]

    def stick_or_flip(self, i, t, y, st, stats):
        st.stuck[i] = 1.0
        _, aux = self.eval(t, y, st)
        need = aux[X_SIG1 + i]
        if abs(need) < 1.0:
            stats["n_stick"] += 1
            return
        st.stuck[i] = 0.0
        st.sig[i] = 1.0 if need > 0.0 else -1.0

    def consistent_signs(self, t, y, st, active, stats):
        _, aux = self.eval(t, y, st)
        for i in range(3):
            if active[i] and st.stuck[i] == 0.0:
                g = aux[X_G1 + i]
                if g > 0.0:
                    st.sig[i] = 1.0
                elif g < 0.0:
                    st.sig[i] = -1.0
                else:
                    self.stick_or_flip(i, t, y, st, stats)


def run_scipy(scene, method: str = "DOP853", rtol: float = 1e-10, atol: float | None = None,
              sample_tau=None, backend: Backend | None = None, max_segments: int = 200_000,
              max_wall: float = math.inf) -> dict:
    """Integrate one scene with scipy.integrate.solve_ivp and the contact rules written above.

    scene: a scene dict/YAML path or a validated `Scene` (its solver section is ignored except
    slip_tol; stop.levels, stop.t_max are used). Times are dimensionless (tau = t/chi).
    Returns a dict: outcome (name), outcome_code, level_tau (array, NaN if not reached),
    level_alpha, sample_tau, samples (n x N_CORE state, NaN after the end), energy_initial/final
    (dimensionless), nfev (solve_ivp RHS calls), njev, nlu, n_rhs_events (model calls made by event
    functions and the discrete logic), n_rhs (model calls in all; a slaved right-hand side is several),
    n_segments (solve_ivp calls), n_events, n_transitions, n_stick, n_impacts, t_end, wall (s).
    max_wall: give up (outcome 'step_limit') once this much wall time has been used.
    """
    be = backend or numba_backend()
    sc = scene if isinstance(scene, Scene) else load_scene(scene)
    cfg = sc.config
    if atol is None:
        atol = rtol * 1e-2
    n = N_CORE
    t_max = cfg["stop"]["t_max"] / sc.chi
    u_tol = cfg["solver"]["slip_tol"] * sc.chi / cfg["disk"]["radius"]
    p = np.array(sc.params, dtype=float)
    p[P_UFREEZE] = u_tol          # as the kernel: below slip_tol the slip direction is given
    level_e = level_energies(sc)
    nl = level_e.size
    smp = np.zeros(0) if sample_tau is None else np.asarray(sample_tau, dtype=float)
    ns = smp.size
    samples = np.full((ns, n), np.nan)
    level_tau = np.full(nl, np.nan)
    level_alpha = np.full(nl, np.nan)

    w0 = time.perf_counter()
    fcount = _Counter()               # model calls inside solve_ivp's fun
    ecount = _Counter()               # model calls of the event functions and the discrete logic
    ph = _Physics(be, p, n, u_tol, ecount)
    ph_f = _Physics(be, p, n, u_tol, fcount)
    stats = dict(n_events=0, n_transitions=0, n_stick=0, n_impacts=0, nfev=0, njev=0, nlu=0,
                 n_segments=0)
    active = [p[P_K1] > 0.0, p[P_K2] > 0.0, p[P_K3] > 0.0]

    y0, _ = initial_state(sc)
    y = np.array(y0[:n], dtype=float)
    t = 0.0
    st = _State(1 if y[Y_ALPHA] > 0.0 else -1)
    # --- initial discrete state (as the kernel's start) ---
    if y[Y_U1] != 0.0 or y[Y_U2] != 0.0:
        ph.set_slip(t, y, st, stats)
    ph.consistent_signs(t, y, st, active, stats)
    if st.mode == ROLL and ph.cone_violated(t, y, st):
        ph.start_slip(t, y, st, stats)
    _, aux = ph.eval(t, y, st)
    e0 = ph.energy(y, st)
    outcome = -1
    if aux[X_PHI] <= 0.0:
        outcome = outcomes.CONTACT_LOST
    if aux[X_OK] == 0.0:
        outcome = outcomes.NUMERICAL_ERROR
    isamp = 0
    while isamp < ns and smp[isamp] <= 0.0:
        samples[isamp] = y
        isamp += 1
    next_level = 0
    zero_len = 0
    t_impact = -math.inf

    while outcome < 0:
        # levels already passed (the energy drops at an impulse): recorded at the restart time
        while next_level < nl and ph.energy(y, st) <= level_e[next_level]:
            level_tau[next_level] = t
            level_alpha[next_level] = y[Y_ALPHA]
            next_level += 1
        if next_level == nl:
            outcome = outcomes.HALTED
            break
        if stats["n_segments"] >= max_segments or time.perf_counter() - w0 > max_wall:
            outcome = outcomes.STEP_LIMIT
            break

        # --- one smooth segment: fixed discrete state -----------------------------------------
        sst = st.copy()               # its slaved-direction seed follows the right-hand side
        calls = [0]

        def fun(tt, yy):
            calls[0] += 1
            if calls[0] % 2000 == 0 and time.perf_counter() - w0 > max_wall:
                raise _Timeout   # a single solve_ivp call can grind (e.g. LSODA at rtol 1e-12)
            return ph_f.eval(tt, yy, sst, update_nu=True)[0]

        cache_t = [None]
        cache_y = np.empty(n)
        cache_aux = [None]
        cache_nu = [sst.nu]

        def aux_at(tt, yy):
            # event functions must be functions of (t, y) alone: a slaved direction is solved here
            # from the seed, not read from the seed (which the right-hand side moves)
            if cache_t[0] != tt or not np.array_equal(cache_y, yy):
                cache_aux[0] = ph.eval(tt, yy, sst)[1]
                cache_nu[0] = ph.last_nu if sst.mode == SLAVED else sst.nu
                cache_t[0] = tt
                cache_y[:] = yy
            return cache_aux[0]

        def nu_at(tt, yy):
            aux_at(tt, yy)
            return cache_nu[0]

        events, kinds = [], []
        t0 = t

        def add(fn, kind, terminal=True):
            g0 = fn(t0, y)
            # An event function exactly 0 at the restart point (omega.a_i after a sign flip,
            # alpha after a side change, u.s at a slip onset) would be 'detected' again at the first
            # step end by solve_ivp (it counts g(t0) = 0 -> g(t1) <= 0 as a crossing) and located
            # at t0: a restart loop that never advances. Treat an exact zero at t0 as 'just after'
            # (the kernel likewise needs g > 0 at a step's start).
            # The value at t0 is the one of the restart state (the dense output there may differ by
            # rounding, enough to flip the sign of an exact zero).
            def g(tt, yy):
                if tt == t0:
                    return g0 if g0 != 0.0 else 1e-300
                return fn(tt, yy)
            g.terminal = terminal
            g.direction = -1
            events.append(g)
            kinds.append(kind)

        # in the kernel's event order (a tie goes to the first)
        for i in range(3):
            if active[i] and sst.stuck[i] == 0.0:
                add(lambda tt, yy, i=i, s=sst.sig[i]: s * aux_at(tt, yy)[X_G1 + i], ("sign", i))
        for i in range(3):
            if active[i] and sst.stuck[i] == 1.0:
                add(lambda tt, yy, i=i: 1.0 - abs(aux_at(tt, yy)[X_SIG1 + i]), ("unstick", i))
        if sst.mode == ROLL:
            def cone(tt, yy):
                a = aux_at(tt, yy)
                return p[P_MUS] * a[X_PHI] - math.hypot(a[X_F1], a[X_F2])
            add(cone, ("cone",))
        elif sst.mode == SLIDE:
            add(lambda tt, yy: math.hypot(yy[Y_U1], yy[Y_U2]) - u_tol, ("slipslow",))
        else:
            add(lambda tt, yy: yy[Y_U1] * math.cos(nu_at(tt, yy)) + yy[Y_U2] * math.sin(nu_at(tt, yy)),
                ("slipstop",))
            add(lambda tt, yy: SLAVE_EXIT * ph.slave_speed(aux_at(tt, yy)) - math.hypot(yy[Y_U1], yy[Y_U2]),
                ("slipfast",))
        if sst.mode == SLIDE and SLAVE_EPS > 0.0 and not sst.slave_off:
            add(lambda tt, yy: math.hypot(yy[Y_U1], yy[Y_U2]) - ph.slave_speed(aux_at(tt, yy)), ("slave",))
        add(lambda tt, yy: aux_at(tt, yy)[X_PHI], ("contact",))
        add(lambda tt, yy, s=sst.side: s * yy[Y_ALPHA], ("side",))
        add(lambda tt, yy: (0.5 * math.pi - abs(yy[Y_ALPHA])) - BETA_FACE, ("face",))
        for L in range(next_level, nl):
            add(lambda tt, yy, L=L: ph.energy(yy, sst) - level_e[L], ("level", L), terminal=(L == nl - 1))

        t_eval = smp[isamp:]
        t_eval = t_eval[t_eval <= t_max]
        try:
            sol = solve_ivp(fun, (t, t_max), y, method=method, rtol=rtol, atol=atol, events=events,
                            t_eval=t_eval if t_eval.size else None)
        except _Timeout:
            stats["nfev"] += calls[0]
            outcome = outcomes.STEP_LIMIT
            break
        stats["n_segments"] += 1
        stats["nfev"] += sol.nfev
        stats["njev"] += sol.njev
        stats["nlu"] += sol.nlu
        if t_eval.size:
            m = len(sol.t)
            if m:
                samples[isamp:isamp + m] = np.asarray(sol.y).T
                isamp += m
        # non-terminal level crossings inside the segment
        t_stop = min((te[0] for te, ev in zip(sol.t_events, events) if ev.terminal and te.size),
                     default=math.inf)
        for j, kind in enumerate(kinds):
            if kind[0] == "level" and sol.t_events[j].size and sol.t_events[j][0] <= t_stop:
                L = kind[1]
                level_tau[L] = sol.t_events[j][0]
                level_alpha[L] = sol.y_events[j][0][Y_ALPHA]
                next_level = max(next_level, L + 1)
        if sol.status == -1:
            outcome = outcomes.STEP_SIZE_UNDERFLOW if "step size" in sol.message else outcomes.NUMERICAL_ERROR
            t = float(sol.t[-1]) if len(sol.t) else t
            break
        if sol.status == 0:
            outcome = outcomes.T_MAX
            t = t_max
            y = np.array(sol.y[:, -1], dtype=float) if len(sol.t) else y
            break
        # terminal event: the earliest one (a tie goes to the first in the kernel's order)
        k = min((j for j, ev in enumerate(events) if ev.terminal and sol.t_events[j].size),
                key=lambda j: sol.t_events[j][0])
        t_new = float(sol.t_events[k][0])
        zero_len = zero_len + 1 if t_new <= t else 0
        if zero_len > 1000:
            outcome = outcomes.STEP_SIZE_UNDERFLOW
            break
        t = t_new
        y = np.array(sol.y_events[k][0], dtype=float)
        stats["n_events"] += 1
        st.nu = sst.nu
        kind = kinds[k]
        if kind[0] == "level":
            next_level = nl
            continue
        if kind[0] == "sign":
            ph.stick_or_flip(kind[1], t, y, st, stats)
        elif kind[0] == "unstick":
            i = kind[1]
            _, a = ph.eval(t, y, st)
            st.sig[i] = 1.0 if a[X_SIG1 + i] > 0.0 else -1.0
            st.stuck[i] = 0.0
        elif kind[0] == "cone":
            ph.start_slip(t, y, st, stats)
            st.slave_off = False
        elif kind[0] == "slipslow":
            # the slip ends at slip_tol by a plastic contact impulse (its energy goes to sliding)
            y[Y_DSLIDE] += be.project_velocity(y, p, st.side, True, st.side, False, ph.S)
            st.mode = ROLL
            stats["n_transitions"] += 1
        elif kind[0] == "slipstop":
            y[Y_U1] = 0.0
            y[Y_U2] = 0.0
            st.mode = ROLL
            stats["n_transitions"] += 1
        elif kind[0] == "slipfast":
            st.mode = SLIDE
            st.slave_off = False
        elif kind[0] == "slave":
            ph.try_slave(t, y, st, stats)
        elif kind[0] == "contact":
            outcome = outcomes.CONTACT_LOST
            break
        elif kind[0] == "face":
            # the disk lies flat: a halt; the levels not yet crossed are crossed now
            level_tau[next_level:] = t
            next_level = nl
            outcome = outcomes.HALTED
            break
        elif kind[0] == "side":
            mode_old = st.mode
            be.project_velocity(y, p, st.side, mode_old != ROLL, -st.side, mode_old != ROLL, ph.S)
            st.side = -st.side
            stats["n_impacts"] += 1
            y[Y_ALPHA] = 0.0
            st.stuck[:] = 0.0
            zeno = t - t_impact < ZENO_DTAU
            t_impact = t
            if y[Y_W1] * st.side <= 0.0 or zeno:
                outcome = outcomes.LINE_CONTACT
                break
            if mode_old != ROLL:
                ph.set_slip(t, y, st, stats)
            ph.consistent_signs(t, y, st, active, stats)
            if mode_old == ROLL and ph.cone_violated(t, y, st):
                ph.start_slip(t, y, st, stats)
        if kind[0] != "side" and st.mode == ROLL and ph.cone_violated(t, y, st):
            ph.start_slip(t, y, st, stats)
        _, a = ph.eval(t, y, st)
        if a[X_OK] == 0.0:
            outcome = outcomes.NUMERICAL_ERROR
            break

    wall = time.perf_counter() - w0
    n_rhs = fcount.n + ecount.n
    return dict(outcome=outcomes.NAMES[outcome], outcome_code=outcome, level_tau=level_tau,
                level_alpha=level_alpha, sample_tau=smp, samples=samples, t_end=t,
                energy_initial=float(e0), energy_final=float(ph.energy(y, st)),
                n_rhs_events=ecount.n, n_rhs=n_rhs, wall=wall, method=method,
                rtol=rtol, atol=atol, backend=be.name, **stats)
