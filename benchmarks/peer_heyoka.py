#!/usr/bin/env python3
"""The project's kernel side by side with heyoka (Taylor's method, LLVM JIT) at matched error (issue #42).

    .venv/bin/pip install -r benchmarks/requirements-heyoka.txt     # once (benchmark-only, not in the lock)
    .venv/bin/python benchmarks/peer_heyoka.py                      # everything (~15-25 min on 2 shared cores)
    .venv/bin/python benchmarks/peer_heyoka.py --parts check wp     # only some parts
    .venv/bin/python benchmarks/peer_heyoka.py --quick              # fewer rounds and rungs (a smoke run)

Parts (`--parts`, default all):

* `check`: the closed-form pure-ROLLING equations of the model, derived here with sympy from the
  Newton-Euler balances (unknowns dw1..3, the centre's acceleration on a1, a2, E3, F1, F2, Phi: a
  9x9 linear system, solved by block elimination: the rolling constraint and the linear momentum
  give the acceleration, F and Phi in terms of dw, which leaves a 3x3 (lower block-triangular)
  system from the angular momentum about the centre), checked against the project's
  `sweep.core.model.rhs` in ROLL mode at random states (random disks, k_i, signs sigma_i, both
  rims; evaluated exactly with mpmath, so the difference is rhs's own round-off). Then the scene's
  checks: T is 90 % of its 1e-3-level time, no transition, stick or impact on [0, T], and sign(omega.a2)
  and sign(alpha) constant on [0, T] (heyoka's event detection on the reference run), so the smooth
  closed-form system with sigma2 fixed is the motion the project integrates.
* `wp`: work-precision on the rolling scene (the paper's disk, mu_s = mu_d = 5, k1 = k3 = 0, k2 =
  3.004e-5 m, alpha0 = 1, omega = (0, 0, -14.456878347621343) rad/s, to T = 57.84 s): max abs error of
  alpha, w1, w2, w3 (dimensionless, tau = t/chi, w = chi omega) at T against a reference (heyoka in
  real128, quadruple precision, tol 1e-32, where the heyoka build has it: the PyPI wheel does;
  cross-checked against heyoka in long double, tol 1e-19; both with the parameters as heyoka par[],
  exactly the project's float64 values), vs time. The project: `sweep.simulate(scene,
  sample_times=[T])`, stop.t_max = T, timed around the kernel call only (the run_kernel call that
  simulate's own summary wall_time measures, wrapped: thread CPU time and wall time), at a ladder of
  rtol (atol = rtol/100, the default ratio), in two configurations: 'lean' (one level, 1e-4 rad, not
  reached before T; normal_force_frequency off) and 'default' (the four default levels,
  normal_force_frequency on); simulate integrates the kinematics for the sample, outside the error
  control. heyoka: `taylor_adaptive` (double, high_accuracy=True, the parameters as numbers: the
  form a user would write; it is ~15 % faster than par[]) at a ladder of tolerances, propagate_until
  timed (building the integrator, LLVM JIT, is reported apart). Interleaved: each round runs every
  configuration once; the minimum over --rounds (21) rounds after a warm-up round. The thread CPU
  time is the primary figure (other processes' time slices on the shared machine do not count); the
  wall ratio is printed beside it. Matched-error ratios at 1e-6, 1e-8, 1e-10, 1e-12: log time
  interpolated against log error on each side's lower envelope (the least error reached at that
  cost or less); where a side cannot reach the target, at the least error both reach (marked ~).
  Also the project's step, rejected and RHS counts, heyoka's steps and Taylor order, and the cost
  anatomy of a project step: the right-hand side's own cost (`core.contact.eval_rhs`, ROLL, in a
  jitted loop, as the kernel calls it) times RHS per try against the CPU time per try.
* `batch`: 64 rolling scenes (alpha0 in [0.5, 1.2], omega3 in [-20, -10] rad/s, seed 42; each to
  90 % of its own 1e-3-level time, each checked as above), one thread: the project's
  `sweep.simulate_batch(scenes, device="cpu", workers=1)` (`device` passed only where the signature
  still has it) vs heyoka's scalar loop and heyoka's batch mode (`taylor_adaptive_batch`, SIMD width
  `heyoka.recommended_simd_size()`; scenes in the drawn order and sorted by the scalar run's step
  count), each at a ladder of tolerances; errors against a long-double heyoka reference per scene
  (tol 1e-19; the project's per-scene error from `sweep.simulate` with the same settings, whose step
  count is checked to equal the batch run's). Scenes/s at matched median error (interpolated), from
  the thread CPU time of the whole simulate_batch call (packing and summaries included) and of
  heyoka's loops; minimum over --batch-rounds (11) interleaved rounds.
Prints the tables and writes benchmarks/out/peer_heyoka.md and peer_heyoka.json (benchmarks/out/ is
git-ignored). Reports the machine's load average before and after each part: the machine is shared.
"""
from __future__ import annotations

import argparse
import copy
import inspect
import json
import math
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(ROOT / "src"))
OUT = HERE / "out"

import sweep  # noqa: E402
from sweep.core import model as M  # noqa: E402
from sweep.scene import load_scene  # noqa: E402
from sweep.simulate import initial_state  # noqa: E402

try:
    import heyoka as hy
    import sympy as sp
except ImportError as exc:  # pragma: no cover
    sys.exit(f"peer_heyoka: {exc}; install the benchmark's requirements: "
             ".venv/bin/pip install -r benchmarks/requirements-heyoka.txt")

T_S = 57.84                       # s: 90 % of the rolling scene's 1e-3-level time
W3 = -14.456878347621343          # rad/s: omega_hat3(0) = -1 for the paper's disk
SCENE = {
    "disk": {"radius": 0.03755, "thickness": 0.0128, "mass": 0.4387, "shape": "solid"},
    "contact": {"mu_s": 5.0, "mu_d": 5.0, "k1": 0.0, "k2": 3.004e-5, "k3": 0.0},
    "gravity": 9.81,
    "initial": {"alpha": 1.0, "omega": [0.0, 0.0, W3], "slip": [0.0, 0.0], "theta": 0.0, "psi": 0.0},
}
LEVELS_DEFAULT = [1e-1, 1e-2, 1e-3, 1e-4]
CONFIGS = {   # the project's two configurations of the work-precision table
    "lean": {"stop": {"levels": [1e-4]}, "outputs": {"normal_force_frequency": False}},
    "default": {"stop": {"levels": LEVELS_DEFAULT}, "outputs": {"normal_force_frequency": True}},
}
MATCH = [1e-6, 1e-8, 1e-10, 1e-12]
RTOLS = [1e-5, 1e-6, 1e-7, 1e-8, 1e-9, 1e-10, 1e-11, 1e-12, 1e-13]
HY_TOLS = [1e-5, 1e-6, 1e-7, 1e-8, 1e-9, 1e-10, 1e-11, 1e-12, 1e-13, 1e-14, 1e-15]
BATCH_RTOLS = [1e-9, 1e-10, 1e-11, 1e-12, 1e-13]
BATCH_HY_TOLS = [1e-9, 1e-10, 1e-11, 1e-12, 1e-13]
BATCH_MATCH = [1e-8, 1e-9, 1e-10]
N_BATCH = 64
BATCH_SEED = 42
REF128_TOL = "1e-32"
REFLD_TOL = 1e-19


# ------------------------------------------------------------------------------------------ helpers

def load() -> str:
    try:
        return "load average %.2f %.2f %.2f" % os.getloadavg()
    except OSError:
        return "load average n/a"


def say(*a):
    print(*a, flush=True)


def scene_cfg(base: dict | None = None, **over) -> dict:
    """A full scene dict: SCENE (or base) with sections updated from over (dicts merged one level)."""
    cfg = copy.deepcopy(base or SCENE)
    for sec, vals in over.items():
        if isinstance(vals, dict):
            cfg.setdefault(sec, {}).update(vals)
        else:
            cfg[sec] = vals
    return cfg


def env_line() -> str:
    """The machine and versions, with the CPU LLVM compiles for and heyoka's SIMD width: on X2 the same
    tree gave 2.52 and 1.47 at matched error 1e-6 on two days (docs/performance.md, 'Against heyoka'),
    so a ratio is only read beside the machine it came from."""
    import numba
    from numba.core.config import CPU_NAME
    import llvmlite.binding as ll
    cpu = CPU_NAME or ll.get_host_cpu_name()
    return (f"{platform.node()}, {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, LLVM host CPU "
            f"{cpu}, heyoka SIMD lanes {hy.recommended_simd_size()}; python {platform.python_version()}, numba "
            f"{numba.__version__}, heyoka {hy.__version__}, sympy {sp.__version__}; git {git_head()}")


def git_head() -> str:
    try:
        h = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--", "src"], cwd=ROOT, capture_output=True,
                               text=True).stdout.strip()
        return h + (" (src modified)" if dirty else "")
    except OSError:
        return "?"


def envelope_interp(errs, times, target):
    """Time at error `target` from (error, time) points: over the lower envelope (sorted by time,
    the least error reached at that cost or less), log time interpolated linearly in log error.
    NaN outside the range of the envelope's errors."""
    pts = sorted((t, e) for e, t in zip(errs, times) if e > 0 and math.isfinite(e) and math.isfinite(t))
    env = []
    best = math.inf
    for t, e in pts:
        if e < best:
            env.append((t, e))
            best = e
    if not env:
        return math.nan
    le = np.log([e for _, e in env])
    lt = np.log([t for t, _ in env])
    x = math.log(target)
    if x > le[0] or x < le[-1]:
        return math.nan
    for j in range(len(env) - 1):
        if le[j] >= x >= le[j + 1]:
            if le[j] == le[j + 1]:
                return float(math.exp(lt[j]))
            w = (le[j] - x) / (le[j] - le[j + 1])
            return float(math.exp(lt[j] + w * (lt[j + 1] - lt[j])))
    return float(math.exp(lt[0]))


def loglog_interp(xs, ys, x):
    """y at x, log-log linear between the two points of (xs, ys) that bracket x (xs need not be sorted)."""
    pts = sorted(zip(xs, ys))
    for (x0, y0), (x1, y1) in zip(pts, pts[1:]):
        if x0 <= x <= x1:
            if x1 == x0:
                return y0
            w = (math.log(x) - math.log(x0)) / (math.log(x1) - math.log(x0))
            return math.exp(math.log(y0) + w * (math.log(y1) - math.log(y0)))
    return math.nan


def fmt(x, spec=".3g"):
    return "n/a" if x is None or (isinstance(x, float) and not math.isfinite(x)) else format(x, spec)


# ------------------------------------------------------------------------- the rolling equations

class Rolling:
    """The closed-form rolling equations, derived with sympy (see the module docstring).

    Symbols: alpha, w1..w3 (state), G, h, A, C, k1..k3, sigma1..3 (parameters and signs). After
    `__init__`: dw (3 expressions), phi, F1, F2 (expressions in the state, the parameters and dw
    substituted), den (the determinant of the 3x3 system)."""

    def __init__(self):
        t0 = time.perf_counter()
        self.state = sp.symbols("alpha w1 w2 w3", real=True)
        al, w1, w2, w3 = self.state
        self.pars = sp.symbols("G h A C k1 k2 k3", real=True)
        G, h, A, C, k1, k2, k3 = self.pars
        self.sig = sp.symbols("sigma1 sigma2 sigma3", real=True)
        s1, s2, s3 = self.sig
        dw = sp.Matrix(sp.symbols("dw1 dw2 dw3", real=True))
        acc = sp.Matrix(sp.symbols("acc1 acc2 acc3", real=True))   # centre's acceleration on a1, a2, E3
        F1, F2, Phi = sp.symbols("F1 F2 Phi", real=True)
        s, c = sp.sin(al), sp.cos(al)
        Ae = sp.Matrix([[1, 0, 0], [0, c, -s], [0, s, c]])       # row i: a_i (a3 = E3) on e1, e2, e3
        w = sp.Matrix([w1, w2, w3])
        r = sp.Matrix([0, -h, -1])                               # contact point from the centre (e, units R)
        vbar_a = Ae * (-w.cross(r))                              # rolling: v_P = vbar + w x r = 0
        thd = w3 / c                                             # dtheta/dtau (w3 = thd cos alpha)
        # d/dtau of vbar: its a-frame components' rates (alpha' = w1, w' = dw) + thd E3 x vbar
        kin = vbar_a.jacobian([al, w1, w2, w3]) * sp.Matrix([w1, *dw]) + sp.Matrix([0, 0, thd]).cross(vbar_a)
        I = sp.diag(A, C, A)
        Om = sp.Matrix([w1, w3 * sp.tan(al), w3])                # the e-frame's angular velocity
        force_e = Ae.T * sp.Matrix([F1, F2, Phi])                # F1 a1 + F2 a2 + Phi E3 on e
        Mf_e = -Phi * Ae.T * sp.Matrix([k1 * s1, k2 * s2, k3 * s3])   # M_f = -Phi sum k_i sigma_i a_i (eq. 3.3)
        eqs = ([acc[i] - kin[i] for i in range(3)]                          # the rolling constraint
               + [acc[0] - F1, acc[1] - F2, acc[2] - (Phi - G)]               # linear momentum (m = 1)
               + list(I * dw + Om.cross(I * w) - r.cross(force_e) - Mf_e))    # angular momentum, centre
        unknowns = list(dw) + list(acc) + [F1, F2, Phi]
        M9, _ = sp.linear_eq_to_matrix([sp.expand(e) for e in eqs], unknowns)
        self.shape = M9.shape
        # block elimination: rows 0-5 give acc, F1, F2, Phi in terms of dw; rows 6-8 are then 3x3 in dw
        force = {F1: kin[0], F2: kin[1], Phi: kin[2] + G}
        red = [sp.expand(e.subs(force)) for e in eqs[6:]]
        M3, b3 = sp.linear_eq_to_matrix(red, list(dw))
        pyth = {s**2: 1 - c**2}                                  # sin^2 + cos^2 = 1, polynomially
        M3 = M3.applyfunc(lambda e: sp.expand(sp.expand(e).subs(pyth)))
        b3 = b3.applyfunc(lambda e: sp.expand(sp.expand(e).subs(pyth)))
        self.M3, self.b3 = M3, b3
        self.den = sp.factor(M3.det())
        sol = M3.adjugate() * b3
        self.dw = [sp.expand(sol[i]) / self.den for i in range(3)]
        sub = {dw[i]: self.dw[i] for i in range(3)}
        self.phi = force[Phi].subs(sub)
        self.F1 = force[F1].subs(sub)
        self.F2 = force[F2].subs(sub)
        self.seconds = time.perf_counter() - t0

    def numeric(self, what, pars_num: dict):
        """The expressions `what` with parameters/signs substituted from pars_num (symbol name -> number)."""
        subs = {sym: pars_num[sym.name] for sym in (*self.pars, *self.sig) if sym.name in pars_num}
        return [sp.expand(e.subs(subs)) if e != 0 else e for e in what]

    def check_rhs(self, n: int = 2000, seed: int = 4242) -> dict:
        """Differences to model.rhs (ROLL) at n random states, the exact values from the closed form
        in mpmath at 40 digits (so a difference is rhs's own round-off): max_rel per quantity,
        |rhs - exact| / max(|exact|, 1e-3 max(1, |state|^2)); max_normwise, the largest difference of
        the vector (dw1, dw2, dw3), resp. (Phi, F1, F2), over its largest exact component."""
        import mpmath as mp
        mp.mp.dps = 40
        args = (*self.state, *self.pars, *self.sig)
        f = sp.lambdify(args, [*self.dw, self.phi, self.F1, self.F2], modules="mpmath")
        rng = np.random.default_rng(seed)
        names = ["dw1", "dw2", "dw3", "Phi", "F1", "F2"]
        worst = dict.fromkeys(names, 0.0)
        normwise = {"dw": 0.0, "forces": 0.0}
        dy = np.zeros(M.N_FULL)
        aux = np.zeros(M.N_AUX)
        stuck = np.zeros(3, np.int64)
        done = skipped = 0
        while done < n:
            kshape = rng.choice([1.0, 2.0])
            radius = rng.uniform(0.01, 0.1)
            p, _ = M.make_params(kshape, radius, rng.uniform(0.01, 1.0) * radius, 9.81, 5.0, 5.0,
                                 tuple(rng.uniform(0.0, 0.3) * radius for _ in range(3)))
            alpha = rng.uniform(0.02, 1.5) * rng.choice([-1.0, 1.0])
            side = 1.0 if alpha > 0 else -1.0
            y = np.zeros(M.N_FULL)
            y[M.Y_ALPHA] = alpha
            y[M.Y_W1:M.Y_W3 + 1] = rng.normal(0.0, 1.5, 3)
            sig = rng.choice([-1.0, 1.0], 3)
            M.rhs(0.0, y, p, M.Contact(M.ROLL, side, sig, stuck, 0.0, 0.0), M.N_CORE, dy, aux)
            if aux[M.X_OK] != 1.0:
                skipped += 1
                continue
            vals = [mp.mpf(float(v)) for v in (alpha, *y[M.Y_W1:M.Y_W3 + 1])]
            pv = [mp.mpf(float(v)) for v in (p[M.P_G], side * p[M.P_H], p[M.P_A], p[M.P_C], p[M.P_K1], p[M.P_K2],
                                             p[M.P_K3], *sig)]
            ex = np.array([float(v) for v in f(*vals, *pv)])
            got = np.array([dy[M.Y_W1], dy[M.Y_W2], dy[M.Y_W3], aux[M.X_PHI], aux[M.X_F1], aux[M.X_F2]])
            scale = 1e-3 * max(1.0, float(np.max(np.abs(y[:4]))) ** 2)
            for nm, g, e in zip(names, got, ex):
                worst[nm] = max(worst[nm], abs(g - e) / max(abs(e), scale))
            d = np.abs(got - ex)
            normwise["dw"] = max(normwise["dw"], float(np.max(d[:3]) / np.max(np.abs(ex[:3]))))
            normwise["forces"] = max(normwise["forces"], float(np.max(d[3:]) / np.max(np.abs(ex[3:]))))
            done += 1
        return {"states": n, "skipped_painleve": skipped, "max_rel": {k: float(v) for k, v in worst.items()},
                "max_normwise": normwise}

    def heyoka_system(self, sig2: float, values: dict | None = None):
        """[(var, rhs)] for alpha, w1, w2, w3 with k1 = k3 = 0 and sigma2 = sig2 (sigma1, sigma3 then
        do not enter): the 3x3 system's entries converted to heyoka expressions and solved in them,
        by the same block elimination (dw1 from the first row, then the 2x2 for dw2, dw3), which
        shares the subexpressions. Parameters G, h, A, C, k2: heyoka par[0..4] (values None: exact
        in any precision, for the references) or the numbers in `values` (name -> float, folded by
        sympy in double: the form a user would write, used for the timed double-precision runs)."""
        num = {"k1": 0, "k3": 0, "sigma1": 1, "sigma3": 1, "sigma2": int(sig2)}
        G, h, A, C, _, k2, _ = self.pars
        if values is not None:
            num.update({k: sp.Float(float(v), precision=53) for k, v in values.items()})
        Mn = [self.numeric([self.M3[i, j] for j in range(3)], num) for i in range(3)]
        bn = self.numeric(list(self.b3), num)
        al, w1, w2, w3 = self.state
        hv = hy.make_vars("alpha", "w1", "w2", "w3")
        smap = {al: hv[0], w1: hv[1], w2: hv[2], w3: hv[3], G: hy.par[0], h: hy.par[1], A: hy.par[2],
                C: hy.par[3], k2: hy.par[4]}

        def conv(e):
            e = sp.sympify(e)
            return hy.expression(float(e)) if e.is_number else hy.from_sympy(e, smap)

        m = [[conv(Mn[i][j]) for j in range(3)] for i in range(3)]
        b = [conv(x) for x in bn]
        if any(Mn[0][j] != 0 for j in (1, 2)):
            raise ValueError("the first row of the 3x3 system is not triangular")
        dw1 = b[0] / m[0][0]
        r2 = b[1] - m[1][0] * dw1
        r3 = b[2] - m[2][0] * dw1
        det2 = m[1][1] * m[2][2] - m[1][2] * m[2][1]
        dw2 = (m[2][2] * r2 - m[1][2] * r3) / det2
        dw3 = (m[1][1] * r3 - m[2][1] * r2) / det2
        return list(zip(hv, [hv[1], dw1, dw2, dw3]))


def par_values(p: np.ndarray, side: float) -> dict:
    """G, h (side |H|/R), A, C, k2 of the project's parameter vector, by the names of Rolling.pars."""
    return {"G": p[M.P_G], "h": side * p[M.P_H], "A": p[M.P_A], "C": p[M.P_C], "k2": p[M.P_K2]}


def heyoka_pars(p: np.ndarray, side: float, fp=float):
    """par[0..4] = G, h (side |H|/R), A, C, k2 of the project's parameter vector, in fp (exactly)."""
    vals = [p[M.P_G], side * p[M.P_H], p[M.P_A], p[M.P_C], p[M.P_K2]]
    if fp is float:
        return np.array(vals, dtype=float)
    if fp is np.longdouble:
        return np.array(vals, dtype=np.longdouble)
    return np.array([hy.real128(float(v)) for v in vals], dtype=hy.real128)


def g2_expr(hv):
    """omega.a2 = w2 cos(alpha) - w3 sin(alpha) as a heyoka expression."""
    return hv[2] * hy.cos(hv[0]) - hv[3] * hy.sin(hv[0])


def make_reference(system, y4, pars, tau_end, fp: str, events: bool = True):
    """heyoka reference run from y4 (float64 values, converted exactly) to tau_end: fp 'real128'
    (tol 1e-32) or 'longdouble' (tol 1e-19). Returns (state as float64, crossings of omega.a2 and
    alpha counted by heyoka's event detection, steps, order, seconds)."""
    hv = [v for v, _ in system]
    crossings = {"omega.a2": 0, "alpha": 0}

    def cb(name):
        def f(ta, t, d_sgn):
            crossings[name] += 1
        return f

    if fp == "real128":
        ftype, tol = hy.real128, hy.real128(REF128_TOL)
        st = np.array([hy.real128(float(v)) for v in y4], dtype=hy.real128)
        tend = hy.real128(float(tau_end))
    else:
        ftype, tol = np.longdouble, np.longdouble(REFLD_TOL)
        st = np.array(y4, dtype=np.longdouble)
        tend = np.longdouble(tau_end)
    kw = {}
    if events:
        kw["nt_events"] = [hy.nt_event(g2_expr(hv), cb("omega.a2"), fp_type=ftype),
                           hy.nt_event(hv[0], cb("alpha"), fp_type=ftype)]
    t0 = time.perf_counter()
    if pars is not None:
        kw["pars"] = pars
    ta = hy.taylor_adaptive(system, st, tol=tol, fp_type=ftype, compact_mode=True, **kw)
    res = ta.propagate_until(tend)
    secs = time.perf_counter() - t0
    if res[0] != hy.taylor_outcome.time_limit:
        raise RuntimeError(f"reference run ended with {res[0]}")
    return np.array([float(v) for v in ta.state]), crossings, int(res[3]), int(ta.order), secs


# ----------------------------------------------------------------------------------- the project

def project_scene(cfg_over: dict, rtol: float, t_max: float, base: dict | None = None, kinematics=True):
    cfg = scene_cfg(base, **copy.deepcopy(cfg_over))
    cfg["stop"] = dict(cfg.get("stop", {}), t_max=t_max)
    cfg["solver"] = {"rtol": rtol, "atol": rtol * 1e-2}
    cfg["outputs"] = dict(cfg.get("outputs", {}), kinematics=kinematics)
    return load_scene(cfg)


class KernelClock:
    """Times the kernel call inside `sweep.simulate`: wraps the module's run_kernel (the call that
    simulate's own summary wall_time measures) and records its wall and thread-CPU time. The CPU
    time is the robust one on a shared machine (time slices given to other processes do not count)."""

    def __init__(self):
        import importlib
        self.mod = importlib.import_module("sweep.simulate")
        self.inner = getattr(self.mod, "run_kernel", None)
        self.last = (math.nan, math.nan)
        if self.inner is not None:
            def timed(*args, **kw):
                c0, w0 = time.thread_time(), time.perf_counter()
                out = self.inner(*args, **kw)
                self.last = (time.perf_counter() - w0, time.thread_time() - c0)
                return out
            self.mod.run_kernel = timed

    def run(self, sc, t_s: float):
        """(wall, cpu, state4 at t_s (dimensionless), summary) of sweep.simulate with a sample at t_s.
        Where simulate no longer calls run_kernel, the whole call is timed."""
        self.last = (math.nan, math.nan)
        c0, w0 = time.thread_time(), time.perf_counter()
        r = sweep.simulate(sc, sample_times=[t_s])
        call = (time.perf_counter() - w0, time.thread_time() - c0)
        wall, cpu = self.last if math.isfinite(self.last[0]) else call
        y = np.array([r.samples["alpha"][0], *(r.samples["omega"][0] * sc.chi)])
        return wall, cpu, y, r.summary


CLOCK: KernelClock | None = None


def project_run(sc, t_s: float):
    global CLOCK
    if CLOCK is None:
        CLOCK = KernelClock()
    return CLOCK.run(sc, t_s)


def timed(fn, *args):
    """(wall, cpu, fn(*args)) with the thread's CPU time."""
    c0, w0 = time.thread_time(), time.perf_counter()
    out = fn(*args)
    return time.perf_counter() - w0, time.thread_time() - c0, out


def level_time(base: dict, level: float = 1e-3) -> tuple[float, dict]:
    """The 1e-3-level time (s) at default settings (levels down to 1e-3, t_max 1000 s) and the summary."""
    cfg = scene_cfg(base, stop={"levels": [1e-1, 1e-2, level], "t_max": 1000.0})
    s = sweep.simulate(cfg).summary
    return s["levels"][-1]["t"], s


_RHS_LOOP = None


def rhs_loop():
    """A jitted loop of `core.contact.eval_rhs` (the contact-state dispatch around model.rhs, and the
    RHS count) whose mode and size are run-time values and that feeds a bit of the result back (so
    nothing is hoisted or folded); compiled once per process."""
    global _RHS_LOOP
    if _RHS_LOOP is None:
        from numba import njit

        from sweep.core import contact

        @njit(cache=False, error_model="numpy")
        def loop(y, sys, n, dy, aux):
            acc = 0.0
            for i in range(n):
                contact.eval_rhs(0.0, y, sys, dy, aux)
                y[1] += 1e-300 * dy[1]
                acc += dy[3]
            return acc

        _RHS_LOOP = loop
    return _RHS_LOOP


def rhs_call_ns(p, y, mode: int, nstate: int, n: int = 1_000_000, repeat: int = 7) -> float:
    """Thread-CPU ns per right-hand side as the kernel calls it, in contact mode `mode` (side +1,
    sigma (1, 1, 1)) with `nstate` components: the minimum of `repeat` loops of n calls."""
    from sweep.core import layout

    loop = rhs_loop()
    cs = np.zeros(layout.N_CS)
    cs[layout.CS_MODE] = mode
    cs[layout.CS_SIDE] = 1.0
    cs[layout.CS_SIG:layout.CS_SIG + 3] = 1.0
    yy = y.copy()
    dy = np.zeros(M.N_FULL)
    aux = np.zeros(M.N_AUX)
    sys_ = layout.System(p, cs, nstate, np.zeros((layout.N_WORK, layout.N_WCOLS)),
                         np.zeros(layout.N_ISTATS, np.int64))
    loop(yy, sys_, 1000, dy, aux)
    best = math.inf
    for _ in range(repeat):
        c0 = time.thread_time()
        loop(yy, sys_, n, dy, aux)
        best = min(best, time.thread_time() - c0)
    return best / n * 1e9


def rhs_cost_ns(p, y, n: int = 1_000_000) -> dict:
    """ns per right-hand side in ROLL with N_CORE and N_FULL components (rhs_call_ns)."""
    from sweep.core import layout

    return {name: rhs_call_ns(p, y, layout.ROLL, nstate, n)
            for nstate, name in ((M.N_CORE, "core"), (M.N_FULL, "full"))}


# ---------------------------------------------------------------------------------------- parts

def part_check(ctx: dict, res: dict) -> None:
    rol = ctx["rolling"]
    say(f"\n## Rolling equations (sympy, {rol.shape[0]}x{rol.shape[1]} system by block elimination, "
        f"{rol.seconds:.1f} s)\n")
    say(f"determinant of the 3x3 system: {rol.den}")
    chk = rol.check_rhs(n=ctx["n_check"])
    res["rhs_check"] = chk
    say(f"against sweep.core.model.rhs (ROLL) at {chk['states']} random states (random disks, k_i, signs, "
        f"both rims; {chk['skipped_painleve']} Painleve states skipped): max relative difference "
        + ", ".join(f"{k} {v:.1e}" for k, v in chk["max_rel"].items())
        + "; normwise: (dw1, dw2, dw3) {dw:.1e}, (Phi, F1, F2) {forces:.1e}".format(**chk["max_normwise"]))
    # the scene's own checks
    t3, s3 = level_time(SCENE)
    res["scene_check"] = {"t_level_1e-3": t3, "T": T_S, "T_over_t3": T_S / t3,
                          "transitions_to_level": s3["n_transitions"]}
    s = sweep.simulate(project_scene(CONFIGS["default"], 1e-10, T_S, kinematics=False)).summary
    res["scene_check"].update({"transitions": s["n_transitions"], "stick": s["n_stick"],
                               "impacts": s["n_impacts"], "slip_fraction": s["slip_fraction"]})
    say(f"\nscene: 1e-3-level time {t3:.4f} s (default settings), T = {T_S} s = {100 * T_S / t3:.2f} % of it; "
        f"on [0, T]: {s['n_transitions']} transitions, {s['n_stick']} stick phases, {s['n_impacts']} impacts, "
        f"slip fraction {s['slip_fraction']}")
    ok = s["n_transitions"] == 0 and s["n_stick"] == 0 and s["n_impacts"] == 0 and s["slip_fraction"] == 0.0
    if not ok:
        raise SystemExit("the scene does not roll throughout [0, T]: the comparison does not apply")


def reference(ctx: dict, res: dict) -> np.ndarray:
    """The scene's reference state at T (real128 where heyoka has it, cross-checked in long double)."""
    if "ref" in ctx:
        return ctx["ref"]
    sysm, y4, tau = ctx["system"], ctx["y4"], ctx["tau"]
    p, side = ctx["scene"].params, ctx["side"]
    ld, cr_ld, st_ld, or_ld, t_ld = make_reference(sysm, y4, heyoka_pars(p, side, np.longdouble), tau, "longdouble")
    info = {"longdouble": {"tol": REFLD_TOL, "steps": st_ld, "order": or_ld, "seconds": t_ld, "crossings": cr_ld}}
    ref, kind = ld, "heyoka long double, tol 1e-19"
    if getattr(hy, "_with_real128", False) and not ctx.get("no_real128"):
        q, cr_q, st_q, or_q, t_q = make_reference(sysm, y4, heyoka_pars(p, side, hy.real128), tau, "real128")
        info["real128"] = {"tol": float(REF128_TOL), "steps": st_q, "order": or_q, "seconds": t_q, "crossings": cr_q}
        info["longdouble_vs_real128"] = float(np.max(np.abs(ld - q)))
        ref, kind = q, "heyoka real128, tol 1e-32"
    info["kind"] = kind
    info["crossings"] = cr_ld
    res["reference"] = info
    say(f"\nreference: {kind}; " + "; ".join(
        f"{k}: {v['steps']} steps, order {v['order']}, {v['seconds']:.1f} s" for k, v in info.items()
        if isinstance(v, dict) and "steps" in v)
        + (f"; long double vs real128: {info['longdouble_vs_real128']:.1e}" if "longdouble_vs_real128" in info else ""))
    say(f"sign changes on [0, T] (heyoka events): omega.a2 {cr_ld['omega.a2']}, alpha {cr_ld['alpha']} "
        f"(sigma2 = {ctx['sig2']:+.0f}, side = {ctx['side']:+.0f} throughout)")
    if cr_ld["omega.a2"] or cr_ld["alpha"]:
        raise SystemExit("omega.a2 or alpha changes sign on [0, T]: the fixed-sign closed form does not apply")
    ctx["ref"] = ref
    return ref


def matched_rows(sides: dict, targets, n_scale=None):
    """Matched-error comparison. sides: name -> list of points {err, wall, cpu, ...}; per target
    error (or, where a side cannot reach it, the least error both reach: marked approx), each side's
    time interpolated on its lower envelope, for the CPU and the wall clock."""
    floor = max(min(p["err"] for p in pts) for pts in sides.values())
    out = []
    for target in targets:
        eff, approx = (target, False) if target >= floor else (floor, True)
        row = {"target": target, "error": eff, "approx": approx}
        for name, pts in sides.items():
            for clk in ("cpu", "wall"):
                row[(name, clk)] = envelope_interp([p["err"] for p in pts], [p[clk] for p in pts], eff * (1 + 1e-12))
        out.append(row)
    return out


def part_wp(ctx: dict, res: dict) -> None:
    ref = reference(ctx, res)
    y4, tau, rounds = ctx["y4"], ctx["tau"], ctx["rounds"]
    rtols, tols = ctx["rtols"], ctx["hy_tols"]
    say(f"\n## Work-precision, rolling scene to T = {T_S} s (tau = {tau:.6f}); {rounds} interleaved rounds; {load()}\n")
    # the project's scenes (kinematics on, as simulate sets it for samples) and heyoka's integrators
    scenes = {(c, rt): project_scene(CONFIGS[c], rt, T_S) for c in CONFIGS for rt in rtols}
    tas, build = {}, {}
    for tol in tols:
        t0 = time.perf_counter()
        tas[tol] = hy.taylor_adaptive(ctx["system_num"], np.array(y4), tol=tol, high_accuracy=True)
        build[tol] = time.perf_counter() - t0

    def run_hy(tol):
        ta = tas[tol]
        ta.time = 0.0
        ta.state[:] = y4
        wall, cpu, r = timed(ta.propagate_until, tau)
        if r[0] != hy.taylor_outcome.time_limit:
            raise RuntimeError(f"heyoka tol {tol}: {r[0]}")
        return wall, cpu, ta.state.copy(), int(r[3])

    info = {}
    jobs = [("sweep", k) for k in scenes] + [("heyoka", tol) for tol in tols]
    for rnd in range(rounds + 1):           # round 0: warm-up (not counted)
        for kind, key in jobs:
            if kind == "sweep":
                wall, cpu, y, s = project_run(scenes[key], T_S)
                if rnd == 0:
                    info[(kind, key)] = {"err": float(np.max(np.abs(y - ref))), "steps": s["n_steps"],
                                         "rejected": s["n_rejected"], "rhs": s["n_rhs"], "events": s["n_events"],
                                         "transitions": s["n_transitions"]}
            else:
                wall, cpu, y, nsteps = run_hy(key)
                if rnd == 0:
                    info[(kind, key)] = {"err": float(np.max(np.abs(y - ref))), "steps": nsteps,
                                         "order": int(tas[key].order), "build_s": build[key]}
            d = info[(kind, key)]
            if rnd == 1:
                d["wall"], d["cpu"] = wall, cpu
            elif rnd > 1:
                d["wall"], d["cpu"] = min(d["wall"], wall), min(d["cpu"], cpu)

    lines = ["| side | tolerance | error (max abs) | CPU (ms) | wall (ms) | steps | rejected | RHS | CPU us/try | "
             "Taylor order |", "|---|---|---|---|---|---|---|---|---|---|"]
    for c in CONFIGS:
        for rt in rtols:
            d = info[("sweep", (c, rt))]
            lines.append(f"| sweep {c} | rtol {rt:.0e} | {d['err']:.2e} | {1e3 * d['cpu']:.2f} | {1e3 * d['wall']:.2f} | "
                         f"{d['steps']} | {d['rejected']} | {d['rhs']} | {1e6 * d['cpu'] / (d['steps'] + d['rejected']):.2f} | |")
    for tol in tols:
        d = info[("heyoka", tol)]
        lines.append(f"| heyoka | tol {tol:.0e} | {d['err']:.2e} | {1e3 * d['cpu']:.2f} | {1e3 * d['wall']:.2f} | "
                     f"{d['steps']} | | | {1e6 * d['cpu'] / d['steps']:.2f} | {d['order']} |")
    table = "\n".join(lines)
    say(table)
    say(f"\n(heyoka: taylor_adaptive, double, high_accuracy=True, the parameters as numbers; building an "
        f"integrator (LLVM JIT) took {min(build.values()):.2f}-{max(build.values()):.2f} s, not in the times)")

    # matched-error ratios (log time vs log error on each side; counts log-interpolated in the same way)
    hy_pts = [info[("heyoka", t)] for t in tols]
    mlines = ["| error | config | sweep CPU (ms) | heyoka CPU (ms) | sweep / heyoka (CPU) | sweep / heyoka (wall) | "
              "sweep steps (RHS) | heyoka steps (order) |", "|---|---|---|---|---|---|---|---|"]
    matched = []
    for c in CONFIGS:
        sw_pts = [info[("sweep", (c, r))] for r in rtols]
        for row in matched_rows({"sweep": sw_pts, "heyoka": hy_pts}, MATCH):
            ts, th = row[("sweep", "cpu")], row[("heyoka", "cpu")]
            rw = row[("sweep", "wall")] / row[("heyoka", "wall")]
            st = loglog_interp([p["cpu"] for p in sw_pts], [p["steps"] for p in sw_pts], ts)
            rh = loglog_interp([p["cpu"] for p in sw_pts], [p["rhs"] for p in sw_pts], ts)
            hs = loglog_interp([p["cpu"] for p in hy_pts], [p["steps"] for p in hy_pts], th)
            reach = [t for t in tols if info[("heyoka", t)]["err"] <= row["error"] * (1 + 1e-12)]
            order = info[("heyoka", reach[0])]["order"] if reach else None
            lab = f"~{row['error']:.1e}" if row["approx"] else f"{row['error']:.0e}"
            matched.append({"config": c, "target": row["target"], "error": row["error"], "approx": row["approx"],
                            "sweep_cpu": ts, "heyoka_cpu": th, "ratio_cpu": ts / th, "ratio_wall": rw,
                            "sweep_steps": st, "sweep_rhs": rh, "heyoka_steps": hs, "heyoka_order": order})
            mlines.append(f"| {lab} | {c} | {fmt(1e3 * ts, '.2f')} | {fmt(1e3 * th, '.2f')} | {fmt(ts / th, '.2f')} | "
                          f"{fmt(rw, '.2f')} | {fmt(st, '.0f')} ({fmt(rh / 1e3, '.0f')} k) | {fmt(hs, '.0f')} ({order}) |")
    mtable = "\n".join(mlines)
    say("\nmatched-error ratios (time interpolated log-log on each side's lower envelope; '~': the target is "
        "below one side's least error, compared at the least error both reach):\n")
    say(mtable)

    # the cost anatomy of a project step: the right-hand side's own cost against a step's
    y_mid = ctx["scene_y0"].copy()        # a state mid-way (typical values; theta etc. as at the start)
    y_mid[:4] = project_run(project_scene(CONFIGS["lean"], 1e-10, 0.5 * T_S), 0.5 * T_S)[2]
    rc = rhs_cost_ns(ctx["scene"].params, y_mid)
    alines = ["| config | rtol | CPU us per try | RHS per try | RHS CPU per try (us) | RHS share |",
              "|---|---|---|---|---|---|"]
    anat = []
    for c in CONFIGS:
        for rt in rtols:
            d = info[("sweep", (c, rt))]
            tries = d["steps"] + d["rejected"]
            per_try = d["cpu"] / tries * 1e6
            rpt = d["rhs"] / tries
            rcost = rpt * rc["full"] * 1e-3
            anat.append({"config": c, "rtol": rt, "us_per_try": per_try, "rhs_per_try": rpt, "rhs_us_per_try": rcost})
            alines.append(f"| {c} | {rt:.0e} | {per_try:.2f} | {rpt:.1f} | {rcost:.2f} | {100 * rcost / per_try:.0f} % |")
    say(f"\nwhere a project step's time goes: the right-hand side alone (contact.eval_rhs, ROLL, a jitted loop) {rc['core']:.0f} ns with "
        f"N_CORE, {rc['full']:.0f} ns with N_FULL (the kinematics, as in these runs) per call:\n")
    say("\n".join(alines))
    kin = kinematics_cost(rounds)
    if kin:
        say("\nthe passive kinematics that simulate integrates for a sample (lean, run_kernel directly, thread CPU, "
            f"min of {rounds}): " + "; ".join(
                f"rtol {k['rtol']:.0e}: on {1e3 * k['on']:.2f} ms, off {1e3 * k['off']:.2f} ms ({k['on'] / k['off']:.2f}x; "
                f"{k['steps']} steps both, state difference {k['diff']:.0e})" for k in kin))
    hy_us = {t: 1e6 * info[("heyoka", t)]["cpu"] / info[("heyoka", t)]["steps"] for t in tols}
    say("heyoka CPU per step (us): " + ", ".join(f"tol {t:.0e}: {v:.2f}" for t, v in hy_us.items()))
    res["wp"] = {"points": [{"side": k[0], "key": list(k[1]) if isinstance(k[1], tuple) else k[1], **v}
                            for k, v in info.items()],
                 "matched": matched, "rhs_ns": rc, "anatomy": anat, "kinematics": kin, "table": table, "matched_table": mtable,
                 "anatomy_table": "\n".join(alines), "rounds": rounds, "load_after": load()}
    say(f"\n({load()})")


def kinematics_cost(rounds: int, rtols=(1e-8, 1e-10, 1e-12)) -> list[dict]:
    """Kernel CPU time of the lean rolling scene with the passive kinematics on (as simulate runs it
    for samples) and off, through sweep.simulate.run_kernel (skipped where it no longer exists)."""
    import importlib

    from sweep.core.layout import I_STEPS
    sim = importlib.import_module("sweep.simulate")
    if not hasattr(sim, "run_kernel"):
        return []
    out = []
    for rt in rtols:
        got = {}
        for on in (True, False):
            sc = project_scene(CONFIGS["lean"], rt, T_S, kinematics=on)
            tau = np.array([T_S / sc.chi])
            r = sim.run_kernel(sc, tau)
            best = math.inf
            for _ in range(rounds):
                c = time.thread_time()
                r = sim.run_kernel(sc, tau)
                best = min(best, time.thread_time() - c)
            got[on] = (best, int(r.istats[I_STEPS]), np.array(r.samples[0, :4]))
        if got[True][1] != got[False][1]:
            raise RuntimeError("the kinematics changed the steps")
        out.append({"rtol": rt, "on": got[True][0], "off": got[False][0], "steps": got[True][1],
                    "diff": float(np.max(np.abs(got[True][2] - got[False][2])))})
    return out


def batch_scenes(n: int, seed: int) -> list[dict]:
    rng = np.random.default_rng(seed)
    a0 = rng.uniform(0.5, 1.2, n)
    w3 = rng.uniform(-20.0, -10.0, n)
    return [scene_cfg(initial={"alpha": float(a), "omega": [0.0, 0.0, float(w)]}) for a, w in zip(a0, w3)]


def simulate_batch_cpu1(scenes, stats):
    """sweep.simulate_batch on one CPU thread, with device="cpu" only where the API still takes it."""
    kw = {"workers": 1, "stats": stats}
    if "device" in inspect.signature(sweep.simulate_batch).parameters:
        kw["device"] = "cpu"
    return sweep.simulate_batch(scenes, **kw)


def part_batch(ctx: dict, res: dict) -> None:
    rounds = ctx["batch_rounds"]
    n = ctx["n_batch"]
    say(f"\n## Batch: {n} rolling scenes (seed {BATCH_SEED}), one thread; {rounds} interleaved rounds; {load()}\n")
    bases = batch_scenes(n, BATCH_SEED)
    rol, system_cache = ctx["rolling"], {}
    T, tau, y4s, refs, pars, syss = [], [], [], [], [], []
    t0 = time.perf_counter()
    for b in bases:
        t3, s3 = level_time(b)
        Ti = 0.9 * t3
        sc = project_scene(CONFIGS["lean"], 1e-10, Ti, base=b, kinematics=False)
        s = sweep.simulate(sc).summary
        if s["n_transitions"] or s["n_stick"] or s["n_impacts"] or s["slip_fraction"]:
            raise SystemExit(f"batch scene {b['initial']} does not roll throughout [0, T]")
        y0, _ = initial_state(sc)
        side = 1.0 if y0[0] > 0 else -1.0
        g2 = y0[M.Y_W2] * math.cos(y0[0]) - y0[M.Y_W3] * math.sin(y0[0])
        sig2 = 1.0 if g2 > 0 else -1.0
        if sig2 not in system_cache:
            system_cache[sig2] = rol.heyoka_system(sig2)
        syss.append(sig2)
        pr = heyoka_pars(sc.params, side)
        r, cr, *_ = make_reference(system_cache[sig2], y0[:4], heyoka_pars(sc.params, side, np.longdouble),
                                   Ti / sc.chi, "longdouble")
        if cr["omega.a2"] or cr["alpha"]:
            raise SystemExit(f"batch scene {b['initial']}: a sign change on [0, T]")
        bscene0, side0 = sc, side
        T.append(Ti)
        tau.append(Ti / sc.chi)
        y4s.append(y0[:4].copy())
        refs.append(r)
        pars.append(pr)
    if len(system_cache) != 1 or any(np.any(p != pars[0]) for p in pars):
        raise SystemExit("batch scenes differ in sigma2, side or parameters: heyoka's batch needs one system")
    system = rol.heyoka_system(syss[0], par_values(bscene0.params, side0))   # the timed runs' form
    say(f"scenes: T from {min(T):.1f} to {max(T):.1f} s; all rolling, no sign change on [0, T] (checked); "
        f"long-double references and checks in {time.perf_counter() - t0:.0f} s")
    y4s = np.array(y4s)
    refs = np.array(refs)
    tau = np.array(tau)

    # the project: errors per scene from simulate (same settings), time from simulate_batch
    bscenes = {rt: [project_scene(CONFIGS["lean"], rt, Ti, base=b, kinematics=False) for b, Ti in zip(bases, T)]
               for rt in ctx["batch_rtols"]}
    perr, psteps = {}, {}
    for rt in bscenes:
        errs, steps = [], []
        for b, Ti in zip(bases, T):
            *_, y, s = project_run(project_scene(CONFIGS["lean"], rt, Ti, base=b), Ti)
            errs.append(y)
            steps.append(s["n_steps"])
        perr[rt] = np.max(np.abs(np.array(errs) - refs), axis=1)
        psteps[rt] = steps

    hy_tols = ctx["batch_hy_tols"]
    tas = {tol: hy.taylor_adaptive(system, y4s[0], tol=tol, high_accuracy=True) for tol in hy_tols}
    lanes = int(hy.recommended_simd_size())
    tbs = {tol: hy.taylor_adaptive_batch(system, np.repeat(y4s[:1].T, lanes, axis=1), tol=tol, high_accuracy=True)
           for tol in hy_tols}

    def run_scalar(tol):
        ta = tas[tol]
        out = np.empty_like(y4s)
        steps = np.zeros(n, np.int64)
        for i in range(n):
            ta.time = 0.0
            ta.state[:] = y4s[i]
            r = ta.propagate_until(tau[i])
            out[i] = ta.state
            steps[i] = r[3]
        return out, steps

    def run_batch(tol, order):
        tb = tbs[tol]
        out = np.empty_like(y4s)
        for g in range(0, n, lanes):
            idx = order[g:g + lanes]
            k = len(idx)
            idx = np.concatenate([idx, np.repeat(idx[-1:], lanes - k)])
            tb.set_time(np.zeros(lanes))
            tb.state[:] = y4s[idx].T
            tb.propagate_until(tau[idx])
            out[idx[:k]] = tb.state[:, :k].T
        return out

    drawn = np.arange(n)
    _, st0 = run_scalar(hy_tols[len(hy_tols) // 2])
    by_cost = np.argsort(st0, kind="stable")
    best: dict = {}
    herr = {}

    def keep(key, wall, cpu, rnd):
        if rnd == 1:
            best[key] = [wall, cpu]
        elif rnd > 1:
            best[key] = [min(best[key][0], wall), min(best[key][1], cpu)]

    for rnd in range(rounds + 1):          # round 0: warm-up and the errors (not timed)
        for rt, scs in bscenes.items():
            stats = {}
            wall, cpu, summ = timed(simulate_batch_cpu1, scs, stats)
            if rnd == 0 and [x["n_steps"] for x in summ] != psteps[rt]:
                raise SystemExit(f"rtol {rt}: simulate_batch and simulate took different steps")
            keep(("sweep", rt), stats.get("seconds", wall), cpu, rnd)
            keep(("sweep call", rt), wall, cpu, rnd)
        for tol in hy_tols:
            wall, cpu, (y, _) = timed(run_scalar, tol)
            if rnd == 0:
                herr[("heyoka scalar", tol)] = np.max(np.abs(y - refs), axis=1)
            keep(("heyoka scalar", tol), wall, cpu, rnd)
            for name, order in (("heyoka batch", drawn), ("heyoka batch sorted", by_cost)):
                wall, cpu, y = timed(run_batch, tol, order)
                if rnd == 0:
                    herr[(name, tol)] = np.max(np.abs(y - refs), axis=1)
                keep((name, tol), wall, cpu, rnd)
    sides = {"sweep": [], "heyoka scalar": [], "heyoka batch": [], "heyoka batch sorted": []}
    lines = ["| side | tolerance | median error | max error | CPU (s) | wall (s) | scenes/s (CPU) | "
             "simulate_batch call wall (s) |", "|---|---|---|---|---|---|---|---|"]
    for side in sides:
        for tol in (ctx["batch_rtols"] if side == "sweep" else hy_tols):
            e = perr[tol] if side == "sweep" else herr[(side, tol)]
            wall, cpu = best[(side, tol)]
            pt = {"tol": tol, "err": float(np.median(e)), "max_err": float(np.max(e)), "wall": wall, "cpu": cpu}
            if side == "sweep":
                pt["call_wall"] = best[("sweep call", tol)][0]
            sides[side].append(pt)
            lines.append(f"| {side} | {tol:.0e} | {pt['err']:.2e} | {pt['max_err']:.2e} | {cpu:.3f} | {wall:.3f} | "
                         f"{n / cpu:.0f} | {fmt(pt.get('call_wall', math.nan), '.3f')} |")
    table = "\n".join(lines)
    say(table)
    say(f"\n(sweep: simulate_batch(workers=1); CPU = the thread's CPU time of the whole call, wall = its own "
        f"kernel loop, stats['seconds']; heyoka: high_accuracy=True, batch mode {lanes} lanes "
        f"(recommended_simd_size); 'sorted': the scenes grouped by the scalar run's step count)")
    mlines = ["| median error | sweep scenes/s | heyoka scalar | heyoka batch | heyoka batch sorted | "
              "sweep / scalar | sweep / batch | sweep / batch sorted |", "|---|---|---|---|---|---|---|---|"]
    matched = []
    for row in matched_rows(sides, ctx["batch_match"]):
        sps = {k: n / row[(k, "cpu")] for k in sides}
        spw = {k: n / row[(k, "wall")] for k in sides}
        matched.append({"target": row["target"], "median_error": row["error"], "approx": row["approx"],
                        "scenes_per_s_cpu": sps, "scenes_per_s_wall": spw})
        lab = f"~{row['error']:.1e}" if row["approx"] else f"{row['error']:.0e}"
        mlines.append(f"| {lab} | {fmt(sps['sweep'], '.0f')} | {fmt(sps['heyoka scalar'], '.0f')} | "
                      f"{fmt(sps['heyoka batch'], '.0f')} | {fmt(sps['heyoka batch sorted'], '.0f')} | "
                      f"{fmt(sps['sweep'] / sps['heyoka scalar'], '.2f')} | {fmt(sps['sweep'] / sps['heyoka batch'], '.2f')} | "
                      f"{fmt(sps['sweep'] / sps['heyoka batch sorted'], '.2f')} |")
    mtable = "\n".join(mlines)
    say("\nscenes/s (CPU) at matched median error (log time interpolated against log median error):\n")
    say(mtable)
    res["batch"] = {"n": n, "seed": BATCH_SEED, "lanes": lanes, "rounds": rounds, "T_range": [min(T), max(T)],
                    "sides": sides, "matched": matched, "table": table, "matched_table": mtable, "load_after": load()}
    say(f"\n({load()})")


# ------------------------------------------------------------------------------------------- main

def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--parts", nargs="+", default=["check", "wp", "batch"], choices=["check", "wp", "batch"])
    ap.add_argument("--rounds", type=int, default=21, help="interleaved timing rounds, work-precision (21)")
    ap.add_argument("--batch-rounds", type=int, default=11, help="interleaved timing rounds, batch (11)")
    ap.add_argument("--quick", action="store_true", help="3 rounds, fewer rungs, 16 batch scenes (a smoke run)")
    ap.add_argument("--no-real128", action="store_true", help="long-double reference even where real128 exists")
    ap.add_argument("--out", default=str(OUT / "peer_heyoka"), help="output stem (.md, .json)")
    a = ap.parse_args(argv)
    ctx = {"rounds": a.rounds, "batch_rounds": a.batch_rounds, "no_real128": a.no_real128, "n_check": 2000,
           "n_batch": N_BATCH, "rtols": RTOLS, "hy_tols": HY_TOLS, "batch_rtols": BATCH_RTOLS, "batch_hy_tols": BATCH_HY_TOLS,
           "batch_match": BATCH_MATCH}
    if a.quick:
        ctx.update(rounds=3, batch_rounds=2, n_check=300, n_batch=16,
                   rtols=RTOLS[::2], hy_tols=HY_TOLS[::2], batch_rtols=BATCH_RTOLS[::2], batch_hy_tols=BATCH_HY_TOLS[::2])
    res: dict = {"env": env_line(), "load_before": load(), "argv": sys.argv[1:]}
    say(f"# peer_heyoka: {res['env']}\n({res['load_before']})")

    # the scene, its state and the heyoka system
    sc = load_scene(scene_cfg())
    y0, mode = initial_state(sc)
    assert mode == M.ROLL
    side = 1.0 if y0[M.Y_ALPHA] > 0 else -1.0
    g2 = y0[M.Y_W2] * math.cos(y0[0]) - y0[M.Y_W3] * math.sin(y0[0])
    rol = Rolling()
    ctx.update(scene=sc, scene_y0=y0, y4=y0[:4].copy(), side=side, sig2=1.0 if g2 > 0 else -1.0,
               tau=T_S / sc.chi, rolling=rol)
    ctx["system"] = rol.heyoka_system(ctx["sig2"])      # exact parameters (par[]): the references
    ctx["system_num"] = rol.heyoka_system(ctx["sig2"], par_values(sc.params, side))   # the timed runs
    sweep.simulate(project_scene(CONFIGS["lean"], 1e-8, 1.0), sample_times=[0.5])   # compile / load
    parts = {"check": part_check, "wp": part_wp, "batch": part_batch}
    for name in ("check", "wp", "batch"):
        if name in a.parts:
            parts[name](ctx, res)
    res["load_end"] = load()
    stem = Path(a.out)
    stem.parent.mkdir(parents=True, exist_ok=True)
    stem.with_suffix(".json").write_text(json.dumps(res, indent=1, default=str))
    md = [f"# peer_heyoka ({time.strftime('%Y-%m-%d %H:%M')})", "", res["env"], "",
          f"command: {' '.join([Path(sys.argv[0]).name, *sys.argv[1:]])}", f"{res['load_before']} (start), "
          f"{res['load_end']} (end)", ""]
    if "rhs_check" in res:
        md += ["## Rolling equations vs model.rhs", "", json.dumps(res["rhs_check"]), "", json.dumps(res["scene_check"]), ""]
    if "reference" in res:
        md += ["## Reference", "", json.dumps(res["reference"], default=str), ""]
    if "wp" in res:
        md += ["## Work-precision", "", res["wp"]["table"], "", "### Matched error", "", res["wp"]["matched_table"], "",
               "### Project step anatomy", "", f"model.rhs: {res['wp']['rhs_ns']}", "", res["wp"]["anatomy_table"], ""]
    if "batch" in res:
        md += ["## Batch", "", res["batch"]["table"], "", res["batch"]["matched_table"], ""]
    stem.with_suffix(".md").write_text("\n".join(md))
    say(f"\nwritten: {stem.with_suffix('.md')}, {stem.with_suffix('.json')}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
