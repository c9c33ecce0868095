"""A SciPy driver of the same Euler's-disk model: `solve_ivp` with terminal events and a restart loop.

This is what a researcher would write instead of `sweep`'s hybrid integrator (issue #3): the same
equations (`sweep.model.rhs`, numba-compiled, or its plain-Python/NumPy `py_func` for the
"plain NumPy" peer) and the same discrete event logic as `sweep.integrator.integrate`:

* sign switches of omega.a_i with Filippov sticking (`_stick_or_flip`), un-sticking when the
  needed moment exceeds k_i |N|;
* rolling -> sliding when the friction needed leaves the static cone, with the same slip-onset
  direction (`slip_onset_direction`);
* sliding -> rolling when the slip speed falls to slip_tol, through the same plastic projection
  (`project_velocity`), and the same stiction band (a slip slower than max(slip_tol, rtol|omega|)
  sticks as soon as the static cone holds the rolling state: here a continuous event function
  max(|u| - u_stick, |F_roll| - mu_s Phi_roll), located rather than tested at step ends);
* contact loss (Phi = 0), alpha = 0 side change (projection onto the other rim edge, line contact
  if no rotation towards the new side is left), face contact (pi/2 - |alpha| = 1e-8 rad);
* halt levels by energy (non-terminal events, the last one terminal; a level already passed after
  a projection is recorded at the restart time, as the kernel does).

Every terminal event ends a `solve_ivp` call; the discrete state is updated and a new call starts
from the event point (default initial step selection, as a user of solve_ivp would do).

Differences from the kernel that are inherent to solve_ivp (and documented in docs/performance.md):
no Hermite check for a double sign crossing inside one step; SciPy locates events with brentq to
~4 ulp and restarts at the root (the kernel restarts at the right end of a 1e-12 bracket); the
stiction band is an event instead of a step-end test.

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

from sweep import integrator as _integ
from sweep import model, outcomes
from sweep.events import BETA_FACE
from sweep.model import (N_AUX, N_CORE, P_K1, P_MUS, ROLL, SLIDE, X_F1, X_F2, X_OK, X_PHI, X_SIG1,
                         Y_ALPHA, Y_DSLIDE, Y_U1, Y_U2, Y_W1, Y_W2, Y_W3)
from sweep.scene import Scene, load_scene
from sweep.simulate import initial_state, level_energies

__all__ = ["run_scipy", "numba_backend", "numpy_backend", "Backend"]


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
    """rhs, energy, project_velocity, slip_onset_direction, stick_or_flip, consistent_signs."""


_NAMES = dict(rhs=model.rhs, energy=model.energy, project_velocity=model.project_velocity,
              slip_onset_direction=_integ.slip_onset_direction, stick_or_flip=_integ._stick_or_flip,
              consistent_signs=_integ._consistent_signs)


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


def run_scipy(scene, method: str = "DOP853", rtol: float = 1e-10, atol: float | None = None,
              sample_tau=None, backend: Backend | None = None, max_segments: int = 200_000,
              max_wall: float = math.inf) -> dict:
    """Integrate one scene with scipy.integrate.solve_ivp and the kernel's event logic.

    scene: a scene dict/YAML path or a validated `Scene` (its solver section is ignored except
    slip_tol; stop.levels, stop.t_max are used). Times are dimensionless (tau = t/chi).
    Returns a dict: outcome (name), outcome_code, level_tau (array, NaN if not reached),
    level_alpha, sample_tau, samples (n x N_CORE state, NaN after the end), energy_initial/final
    (dimensionless), nfev (solve_ivp RHS calls), njev, nlu, n_rhs_events (RHS calls made by event
    functions and the discrete logic), n_rhs (total), n_segments (solve_ivp calls), n_events,
    n_transitions, n_stick, n_impacts, t_end, wall (s).
    max_wall: give up (outcome 'step_limit') once this much wall time has been used.
    """
    be = backend or numba_backend()
    sc = scene if isinstance(scene, Scene) else load_scene(scene)
    cfg = sc.config
    p = sc.params
    if atol is None:
        atol = rtol * 1e-2
    n = N_CORE
    t_max = cfg["stop"]["t_max"] / sc.chi
    u_tol = cfg["solver"]["slip_tol"] * sc.chi / cfg["disk"]["radius"]
    level_e = level_energies(sc)
    nl = level_e.size
    st = np.zeros(0) if sample_tau is None else np.asarray(sample_tau, dtype=float)
    ns = st.size
    samples = np.full((ns, n), np.nan)
    level_tau = np.full(nl, np.nan)
    level_alpha = np.full(nl, np.nan)

    rhs, energy = be.rhs, be.energy
    w0 = time.perf_counter()
    y0, mode = initial_state(sc)
    y = y0[:n].copy()
    t = 0.0
    side = 1 if y[Y_ALPHA] > 0.0 else -1
    sig = np.ones(3)
    stuck = np.zeros(3, np.int64)
    active = np.zeros(12, np.int64)
    for i, key in enumerate((model.P_K1, model.P_K2, model.P_K3)):
        active[i] = 1 if p[key] > 0.0 else 0
    active[6] = 1
    n0 = [1.0, 0.0]
    counter = np.zeros(1, np.int64)     # RHS calls of the discrete logic (kernels count into it)
    ev_calls = _Counter()               # RHS calls of the event functions
    dy = np.empty(n)
    aux = np.empty(N_AUX)
    stats = dict(n_events=0, n_transitions=0, n_stick=0, n_impacts=0, nfev=0, njev=0, nlu=0,
                 n_segments=0)

    def onset():
        nonlocal mode
        rhs(t, y, p, mode, side, sig, stuck, n0[0], n0[1], n, dy, aux)
        counter[0] += 1
        nu = be.slip_onset_direction(t, y, p, side, sig, stuck, n, aux[X_F1], aux[X_F2], counter)
        mode = SLIDE
        n0[0], n0[1] = math.cos(nu), math.sin(nu)
        y[Y_U1] = 0.0
        y[Y_U2] = 0.0
        stats["n_transitions"] += 1

    def cone_violated():
        rhs(t, y, p, mode, side, sig, stuck, n0[0], n0[1], n, dy, aux)
        counter[0] += 1
        return aux[X_PHI] > 0.0 and p[P_MUS] * aux[X_PHI] < math.hypot(aux[X_F1], aux[X_F2])

    # --- initial discrete state (as integrate()) ---
    stats["n_stick"] += be.consistent_signs(t, y, p, mode, side, sig, stuck, n0[0], n0[1], n, active,
                                            dy, aux, counter)
    if mode == SLIDE:
        un = math.hypot(y[Y_U1], y[Y_U2])
        n0[0], n0[1] = y[Y_U1] / un, y[Y_U2] / un
    if mode == ROLL and cone_violated():
        onset()
    rhs(t, y, p, mode, side, sig, stuck, n0[0], n0[1], n, dy, aux)
    counter[0] += 1
    e0 = energy(y, p, side, mode)
    outcome = -1
    if aux[X_PHI] <= 0.0:
        outcome = outcomes.CONTACT_LOST
    if aux[X_OK] == 0.0:
        outcome = outcomes.NUMERICAL_ERROR
    isamp = 0
    while isamp < ns and st[isamp] <= 0.0:
        samples[isamp] = y
        isamp += 1
    next_level = 0
    zero_len = 0

    while outcome < 0:
        # levels already passed (the energy drops at a projection): recorded at the restart time
        while next_level < nl and energy(y, p, side, mode) <= level_e[next_level]:
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
        smode, sside, ssig, sstuck, sn0x, sn0y = mode, side, sig.copy(), stuck.copy(), n0[0], n0[1]
        fdy = np.empty(n)
        faux = np.empty(N_AUX)

        fcalls = [0]

        def fun(tt, yy):
            fcalls[0] += 1
            if fcalls[0] % 2000 == 0 and time.perf_counter() - w0 > max_wall:
                raise _Timeout   # a single solve_ivp call can grind (e.g. LSODA at rtol 1e-12)
            rhs(tt, yy, p, smode, sside, ssig, sstuck, sn0x, sn0y, n, fdy, faux)
            return fdy.copy()

        cache_t = [None]
        cache_y = np.empty(n)
        eaux = np.empty(N_AUX)
        edy = np.empty(n)

        def aux_at(tt, yy):
            if cache_t[0] != tt or not np.array_equal(cache_y, yy):
                rhs(tt, yy, p, smode, sside, ssig, sstuck, sn0x, sn0y, n, edy, eaux)
                ev_calls.n += 1
                cache_t[0] = tt
                cache_y[:] = yy
            return eaux

        events, kinds = [], []

        t0 = t

        def add(fn, kind, terminal=True):
            # An event function exactly 0 at the restart point (omega.a_i after a sign flip,
            # alpha after a side change) would be 'detected' again at the first step end by
            # solve_ivp (it counts g(t0) = 0 -> g(t1) <= 0 as a crossing) and located at t0:
            # a restart loop that never advances. Treat an exact zero at t0 as 'just after'.
            def g(tt, yy):
                v = fn(tt, yy)
                return v if (v != 0.0 or tt != t0) else 1e-300
            g.terminal = terminal
            g.direction = -1
            events.append(g)
            kinds.append(kind)

        for i in range(3):
            if active[i] != 1:
                continue
            if sstuck[i] == 1:
                add(lambda tt, yy, i=i: 1.0 - abs(aux_at(tt, yy)[X_SIG1 + i]), ("unstick", i))
            elif i == 0:
                add(lambda tt, yy, s=ssig[0]: s * yy[Y_W1], ("sign", 0))
            elif i == 1:
                add(lambda tt, yy, s=ssig[1]: s * (yy[Y_W2] * math.cos(yy[Y_ALPHA]) - yy[Y_W3] * math.sin(yy[Y_ALPHA])),
                    ("sign", 1))
            else:
                add(lambda tt, yy, s=ssig[2]: s * (yy[Y_W2] * math.sin(yy[Y_ALPHA]) + yy[Y_W3] * math.cos(yy[Y_ALPHA])),
                    ("sign", 2))
        if smode == ROLL:
            def cone(tt, yy):
                a = aux_at(tt, yy)
                return p[P_MUS] * a[X_PHI] - math.hypot(a[X_F1], a[X_F2])
            add(cone, ("cone",))
        else:
            add(lambda tt, yy: math.hypot(yy[Y_U1], yy[Y_U2]) - u_tol, ("slipend",))
            # stiction band (integrator.STICTION_FACTOR = 1): only where it is wider than u_tol
            ydum = np.empty(n)
            sdy = np.empty(n)
            saux = np.empty(N_AUX)

            def stiction(tt, yy):
                u_stick = max(u_tol, rtol * math.sqrt(yy[Y_W1] ** 2 + yy[Y_W2] ** 2 + yy[Y_W3] ** 2))
                gu = math.hypot(yy[Y_U1], yy[Y_U2]) - u_stick
                if gu > 0.0:
                    return gu
                ydum[:] = yy
                ydum[Y_U1] = 0.0
                ydum[Y_U2] = 0.0
                rhs(tt, ydum, p, ROLL, sside, ssig, sstuck, sn0x, sn0y, n, sdy, saux)
                ev_calls.n += 1
                return max(gu, math.hypot(saux[X_F1], saux[X_F2]) - p[P_MUS] * saux[X_PHI])
            add(stiction, ("stiction",))
        add(lambda tt, yy: aux_at(tt, yy)[X_PHI], ("contact",))
        add(lambda tt, yy, s=sside: s * yy[Y_ALPHA], ("side",))
        add(lambda tt, yy: (0.5 * math.pi - abs(yy[Y_ALPHA])) - BETA_FACE, ("face",))
        for L in range(next_level, nl):
            add(lambda tt, yy, L=L: energy(yy, p, sside, smode) - level_e[L], ("level", L),
                terminal=(L == nl - 1))

        t_eval = st[isamp:]
        t_eval = t_eval[t_eval <= t_max]
        try:
            sol = solve_ivp(fun, (t, t_max), y, method=method, rtol=rtol, atol=atol, events=events,
                            t_eval=t_eval if t_eval.size else None)
        except _Timeout:
            stats["nfev"] += fcalls[0]
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
            break
        # terminal event: the earliest one
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
        kind = kinds[k]
        check_cone = False
        if kind[0] == "level":
            next_level = nl
            continue
        if kind[0] == "sign":
            stats["n_stick"] += be.stick_or_flip(kind[1], t, y, p, mode, side, sig, stuck, n0[0], n0[1], n,
                                                 dy, aux, counter)
        elif kind[0] == "unstick":
            i = kind[1]
            rhs(t, y, p, mode, side, sig, stuck, n0[0], n0[1], n, dy, aux)
            counter[0] += 1
            sig[i] = 1.0 if aux[X_SIG1 + i] > 0.0 else -1.0
            stuck[i] = 0
        elif kind[0] == "cone":
            onset()
        elif kind[0] in ("slipend", "stiction"):
            y[Y_DSLIDE] += be.project_velocity(y, p, side, SLIDE, side, ROLL)
            mode = ROLL
            stats["n_transitions"] += 1
            check_cone = True
        elif kind[0] in ("contact", "face"):
            outcome = outcomes.CONTACT_LOST if kind[0] == "contact" else outcomes.FACE_CONTACT
            break
        elif kind[0] == "side":
            be.project_velocity(y, p, side, mode, -side, mode)
            side = -side
            stats["n_impacts"] += 1
            y[Y_ALPHA] = 0.0
            stuck[:] = 0
            if y[Y_W1] * side <= 0.0:
                outcome = outcomes.LINE_CONTACT
                break
            stats["n_stick"] += be.consistent_signs(t, y, p, mode, side, sig, stuck, n0[0], n0[1], n, active,
                                                    dy, aux, counter)
            check_cone = mode == ROLL
        if check_cone and cone_violated():
            onset()
        rhs(t, y, p, mode, side, sig, stuck, n0[0], n0[1], n, dy, aux)
        counter[0] += 1
        if aux[X_OK] == 0.0:
            outcome = outcomes.NUMERICAL_ERROR
            break
        if mode == SLIDE:
            un = math.hypot(y[Y_U1], y[Y_U2])
            if un > 0.0:
                n0[0], n0[1] = y[Y_U1] / un, y[Y_U2] / un

    wall = time.perf_counter() - w0
    n_rhs = stats["nfev"] + ev_calls.n + int(counter[0])
    return dict(outcome=outcomes.NAMES[outcome], outcome_code=outcome, level_tau=level_tau,
                level_alpha=level_alpha, sample_tau=st, samples=samples, t_end=t,
                energy_initial=float(e0), energy_final=float(energy(y, p, side, mode)),
                n_rhs_events=ev_calls.n + int(counter[0]), n_rhs=n_rhs, wall=wall, method=method,
                rtol=rtol, atol=atol, backend=be.name, **stats)
