"""Scene files: parse, validate (before any work) and convert SI inputs to the kernel's units.

A scene is one simulation: one disk, one set of contact parameters, one initial state. YAML in SI:

    disk:    {radius: 0.03755, thickness: 0.0128, mass: 0.4387, shape: solid}   # m, m, kg
    contact: {mu_s: 0.5, mu_d: 0.3, k1: 3.755e-6, k2: 3.004e-5, k3: 3.004e-4}  # -, -, m, m, m
    gravity: 9.81                                                             # m/s^2
    initial: {alpha: 1.0, omega: [0.0, 0.0, -14.457], slip: [0.0, 0.0], theta: 0.0, psi: 0.0}
    stop:    {levels: [1.0e-1, 1.0e-2, 1.0e-3, 1.0e-4], t_max: 120.0, max_steps: 5000000}
    solver:  {method: adaptive, rtol: 1.0e-10, atol: 1.0e-12}
    outputs: {normal_force_frequency: true, kinematics: false}
    material: {E: 1.95e11, density: 7737.27, poisson: 0.28, damping: 1.0e-3}  # Pa, kg/m^3, -, -

alpha (rad) is the tilt of the disk plane from the vertical; omega (rad/s) on e1, e2, e3; slip (m/s)
is the contact-point velocity on a1, a2 (non-zero: the scene starts sliding); theta, psi (rad).
"""
from __future__ import annotations

import copy
import functools
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from . import yamlio
from .core import model
from .errors import ConfigError

DEFAULTS: dict[str, Any] = {
    "disk": {"radius": 0.03755, "thickness": 0.0128, "mass": 0.4387, "shape": "solid"},
    "contact": {"mu_s": 0.5, "mu_d": 0.3, "k1": 3.755e-6, "k2": 3.004e-5, "k3": 3.004e-4},
    "gravity": 9.81,
    "initial": {"alpha": 1.0, "omega": [0.0, 0.0, -14.457], "slip": [0.0, 0.0], "theta": 0.0, "psi": 0.0},
    # t_max: the paper's disk halts in ~10 s; real Euler's disks spin for up to ~2 min.
    # max_steps: ~1e4 steps per halt for the paper's case at rtol 1e-10; 5e6 bounds a pathological
    # scene to ~30 s of CPU while letting the densest scenes of the convergence harness's ranges
    # (~250 located events per second, ~4e4 tries per second at rtol 1e-13) run past 100 s.
    "stop": {"levels": [1.0e-1, 1.0e-2, 1.0e-3, 1.0e-4], "t_max": 120.0, "max_steps": 5_000_000},
    # rtol 1e-10: halt times converge to ~1e-9 relative there (docs/performance.md, 'Error bars'), at a cost of a
    # few ms per scene; slip_tol: slip speed (m/s) at which a slide meets its fate; spin_tol: rate
    # (rad/s) of a moment component at which it sticks if it goes on to rest and the moment can hold
    # it; neither decides what happens (docs/model.md, 'Where a slip ends', 'Sticking at spin_tol').
    "solver": {"method": "adaptive", "rtol": 1.0e-10, "atol": 1.0e-12, "dt": 1.0e-3, "slip_tol": 1.0e-9,
               "spin_tol": 1.0e-7},
    "outputs": {"normal_force_frequency": True, "kinematics": False},
    # The disk's elastic material, used only by the sound synthesis (sweep.audio, sweep.plate), never by
    # the integrator or the summary: E (Pa), density (kg/m^3), poisson (-), damping (modal damping
    # ratio, fraction of critical). Default: the paper's steel (its footnote); damping 1e-3 is a
    # choice for a disk in contact with a table (free steel rings longer, ~1e-4).
    "material": {"E": 1.95e11, "density": 7737.27, "poisson": 0.28, "damping": 1.0e-3},
}

SHAPES = {"solid": 1.0, "shell": 2.0}   # k^2 of eq. (2.4)
HALF_PI = 0.5 * math.pi


def _num(path: str, v, lo: float, hi: float, lo_open=False, hi_open=False, allowed: str | None = None) -> float:
    rng = f"{'(' if lo_open else '['}{lo:g}, {hi:g}{')' if hi_open else ']'}"
    allowed = allowed or f"a finite number in {rng}"
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise ConfigError(path, v, allowed)
    v = float(v)
    if not math.isfinite(v):
        raise ConfigError(path, v, allowed)
    if v < lo or v > hi or (lo_open and v == lo) or (hi_open and v == hi):
        raise ConfigError(path, v, allowed)
    return v


def _int(path: str, v, lo: int, hi: int) -> int:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not float(v).is_integer():
        raise ConfigError(path, v, f"an integer in [{lo}, {hi}]")
    v = int(v)
    if v < lo or v > hi:
        raise ConfigError(path, v, f"an integer in [{lo}, {hi}]")
    return v


def _merge(path: str, user, default):
    if isinstance(default, dict):
        if user is None:
            user = {}
        if not isinstance(user, dict):
            raise ConfigError(path or "scene", user, "a mapping")
        unknown = sorted(set(user) - set(default), key=str)
        if unknown:
            where = f"{path}.{unknown[0]}" if path else str(unknown[0])
            raise ConfigError(where, user[unknown[0]], f"keys: {', '.join(sorted(default))}",
                              problem="no such key")
        return {k: (_merge(f"{path}.{k}" if path else k, user[k], d) if k in user else copy.deepcopy(d))
                for k, d in default.items()}
    return user   # an explicit null stays null and is rejected by the field's validator


def _vector(path: str, v, n: int, bound: float) -> list[float]:
    if not isinstance(v, (list, tuple)) or len(v) != n:
        raise ConfigError(path, v, f"a list of {n} finite numbers")
    return [_num(f"{path}[{i}]", x, -bound, bound) for i, x in enumerate(v)]


@dataclass(frozen=True)
class Scene:
    """A validated scene in SI units, with the kernel's dimensionless parameters."""

    config: dict              # the validated config with defaults filled (SI)
    params: np.ndarray        # model parameter vector (dimensionless)
    chi: float                # time scale (s), eq. (4.5)
    energy_scale: float       # J per dimensionless energy unit: m R^2 / chi^2

    @property
    def levels(self) -> np.ndarray:
        return np.asarray(self.config["stop"]["levels"], dtype=float)


def max_level(params: np.ndarray) -> float:
    """Largest inclination (rad) for which the energy-equivalent inclination is defined.

    The steady centre-fixed rolling motion exists for beta below the root of C h cos(a) = A sin(a)
    (and above the root of f = 0), and its energy must increase with beta; found on a grid with
    1e-4 rad spacing, which is far finer than the spacing of any sensible level set.
    """
    # it depends on G, h, A, C only (the disk and gravity): memoized, since a sweep shares them
    return _max_level(*(float(params[i]) for i in (model.P_G, model.P_H, model.P_A, model.P_C)))


@functools.lru_cache(maxsize=1024)
def _max_level(g: float, h: float, a: float, c: float) -> float:
    p = np.zeros(model.N_PARAMS)
    p[model.P_G], p[model.P_H], p[model.P_A], p[model.P_C] = g, h, a, c
    return float(model.steady_rolling_max_level(p, 1e-4))


SCENE_FILE = f"a YAML mapping of the sections {', '.join(DEFAULTS)} (e.g. config/scenes/kessler2002.yaml)"


def load_scene(src) -> Scene:
    """Parse and validate a scene (path to a YAML file, or dict). Raises ConfigError; for a file,
    the error names it as given (`source`)."""
    if isinstance(src, (str, Path)):
        try:
            return _validate(yamlio.load_file(src, SCENE_FILE))
        except ConfigError as err:
            raise err.with_source(str(src)) from None
    if isinstance(src, dict):
        return _validate(src)
    raise ConfigError("scene", type(src).__name__, "a path to a YAML file or a dict")


def _validate(raw) -> Scene:
    cfg = _merge("", raw, DEFAULTS)

    d = cfg["disk"]
    # lower bounds keep chi, the energy scale m R^2/chi^2 and every dimensionless group normal
    # floating-point numbers (a subnormal radius divided by zero); no rigid disk is below them
    d["radius"] = _num("disk.radius", d["radius"], 1e-6, 10.0)
    d["thickness"] = _num("disk.thickness", d["thickness"], 0.0, 4.0 * d["radius"], lo_open=True,
                          allowed=f"a finite number in (0, 4*radius] = (0, {4 * d['radius']:g}] m")
    d["mass"] = _num("disk.mass", d["mass"], 1e-9, 1e4)
    if not isinstance(d["shape"], str) or d["shape"] not in SHAPES:
        raise ConfigError("disk.shape", d["shape"], "one of: solid, shell")
    c = cfg["contact"]
    c["mu_s"] = _num("contact.mu_s", c["mu_s"], 0.0, 100.0)
    # mu_d > mu_s leaves no consistent slip onset (an instant can switch rolling<->sliding forever)
    c["mu_d"] = _num("contact.mu_d", c["mu_d"], 0.0, c["mu_s"],
                     allowed=f"a finite number in [0, mu_s] = [0, {c['mu_s']:g}] (mu_d > mu_s has no consistent slip onset)")
    for k in ("k1", "k2", "k3"):
        c[k] = _num(f"contact.{k}", c[k], 0.0, d["radius"],
                    allowed=f"a finite length in [0, radius] = [0, {d['radius']:g}] m")
    cfg["gravity"] = _num("gravity", cfg["gravity"], 1e-3, 1e3)
    ini = cfg["initial"]
    a = _num("initial.alpha", ini["alpha"], -HALF_PI, HALF_PI, lo_open=True, hi_open=True,
             allowed="a number in (-pi/2, pi/2), not 0 (alpha = 0 is line contact, +-pi/2 lies flat)")
    if a == 0.0:
        raise ConfigError("initial.alpha", a, "a number in (-pi/2, pi/2), not 0 (alpha = 0 is line contact, +-pi/2 lies flat)")
    ini["alpha"] = a
    ini["omega"] = _vector("initial.omega", ini["omega"], 3, 1e5)
    ini["slip"] = _vector("initial.slip", ini["slip"], 2, 1e3)
    ini["theta"] = _num("initial.theta", ini["theta"], -1e6, 1e6)
    ini["psi"] = _num("initial.psi", ini["psi"], -1e6, 1e6)
    st = cfg["stop"]
    lv = st["levels"]
    if not isinstance(lv, (list, tuple)) or not lv:
        raise ConfigError("stop.levels", lv, "a non-empty list of inclinations in (0, pi/2) rad")
    # levels below the face inclination (core.contact.BETA_FACE = 1e-6 rad) are crossed when the disk lies flat
    lv = [_num(f"stop.levels[{i}]", x, 1e-7, HALF_PI, hi_open=True,
               allowed="an inclination in [1e-7, pi/2) rad") for i, x in enumerate(lv)]
    if len(set(lv)) != len(lv):
        raise ConfigError("stop.levels", lv, "distinct values (a level is listed twice)")
    st["levels"] = sorted(lv, reverse=True)
    st["t_max"] = _num("stop.t_max", st["t_max"], 0.0, 1e5, lo_open=True)
    st["max_steps"] = _int("stop.max_steps", st["max_steps"], 1, 10**9)
    so = cfg["solver"]
    if not isinstance(so["method"], str) or so["method"] not in ("adaptive", "fixed"):
        raise ConfigError("solver.method", so["method"], "one of: adaptive, fixed")
    # rtol below 1e-14 asks for less than ~50 ulp per step: the error control cannot deliver it
    so["rtol"] = _num("solver.rtol", so["rtol"], 1e-14, 1e-2)
    so["atol"] = _num("solver.atol", so["atol"], 1e-16, 1e-2)
    so["dt"] = _num("solver.dt", so["dt"], 0.0, 10.0, lo_open=True)
    so["slip_tol"] = _num("solver.slip_tol", so["slip_tol"], 0.0, 1e-2, lo_open=True)
    so["spin_tol"] = _num("solver.spin_tol", so["spin_tol"], 0.0, 1e-2)
    out = cfg["outputs"]
    for k in out:
        if not isinstance(out[k], bool):
            raise ConfigError(f"outputs.{k}", out[k], "true or false")
    mat = cfg["material"]   # sound synthesis only: not passed to the kernel
    mat["E"] = _num("material.E", mat["E"], 0.0, 1e13, lo_open=True, allowed="a Young's modulus in (0, 1e13] Pa")
    mat["density"] = _num("material.density", mat["density"], 0.0, 1e5, lo_open=True,
                          allowed="a density in (0, 1e5] kg/m^3")
    mat["poisson"] = _num("material.poisson", mat["poisson"], -1.0, 0.5, lo_open=True, hi_open=True,
                          allowed="a Poisson ratio in (-1, 0.5)")
    mat["damping"] = _num("material.damping", mat["damping"], 0.0, 1.0, lo_open=True, hi_open=True,
                          allowed="a modal damping ratio in (0, 1)")

    params, chi = model.make_params(SHAPES[d["shape"]], d["radius"], d["thickness"], cfg["gravity"],
                                    c["mu_s"], c["mu_d"], (c["k1"], c["k2"], c["k3"]))
    params[model.P_UTOL] = so["slip_tol"] * chi / d["radius"]
    params[model.P_WTOL] = so["spin_tol"] * chi
    bmax = max_level(params)
    if st["levels"][0] > bmax:
        raise ConfigError("stop.levels", st["levels"][0],
                          f"inclinations in (0, {bmax:.4f}) rad for this disk (the energy-equivalent "
                          "inclination is defined only where steady centre-fixed rolling exists)")
    energy_scale = d["mass"] * d["radius"] ** 2 / chi**2
    return Scene(config=cfg, params=params, chi=chi, energy_scale=energy_scale)
