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

from . import fields, yamlio
from .core import model
from .core.constants import ROLL, SLIDE
from .core.event_rules import BETA_FACE
from .errors import ConfigError, raise_all

# every field's default, by section (the registry of inputs, sweep.fields: ranges and reasons there)
DEFAULTS: dict[str, Any] = fields.SCENE_DEFAULTS

SHAPES = {"solid": 1.0, "shell": 2.0}   # k^2 of eq. (2.4)


def _merge(path: str, user, default, errors: list):
    """The user's mapping over the defaults; every unknown key and every section that is not a
    mapping is added to `errors` (the section then takes its defaults, so its fields are not
    reported again)."""
    if isinstance(default, dict):
        if user is None:
            user = {}
        if not isinstance(user, dict):
            errors.append(ConfigError(path or "scene", user, "a mapping"))
            user = {}
        for key in sorted(set(user) - set(default), key=str):
            where = f"{path}.{key}" if path else str(key)
            errors.append(ConfigError(where, user[key], f"keys: {', '.join(sorted(default))}",
                                      problem="no such key"))
        return {k: (_merge(f"{path}.{k}" if path else k, user[k], d, errors) if k in user else copy.deepcopy(d))
                for k, d in default.items()}
    return user   # an explicit null stays null and is rejected by the field's validator


class _Checks:
    """The field checks of one scene, every failure kept (`errors`) so that all are reported at
    once; a failed check gives None, which later checks skip."""

    def __init__(self, errors: list):
        self.errors = errors

    def field(self, field: str, v, name: str | None = None, values: dict | None = None):
        known = None if values is None else {k: x for k, x in values.items() if x is not None}
        try:
            return fields.check(field, v, name, known)
        except ConfigError as err:
            self.errors.append(err)
            return None

    def vector(self, path: str, v, n: int):
        if not isinstance(v, (list, tuple)) or len(v) != n:
            self.errors.append(ConfigError(path, v, f"a list of {n} numbers, each {fields.RANGES[path].allowed()}"))
            return None
        out = [self.field(path, x, f"{path}[{i}]") for i, x in enumerate(v)]
        return None if any(x is None for x in out) else out

    def choice(self, field: str, v, allowed: tuple[str, ...]):
        if not isinstance(v, str) or v not in allowed:
            self.errors.append(ConfigError(field, v, f"one of: {', '.join(allowed)}"))
            return None
        return v


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


# the fields model.make_params reads (the others that reach the kernel name their slot: Field.kernel)
MODEL_INPUTS = ("disk.radius", "disk.thickness", "disk.shape", "gravity", "contact.mu_s", "contact.mu_d",
                "contact.k1", "contact.k2", "contact.k3")

# SI -> the kernel's units (lengths in R, times in chi): Param.scale -> (value, chi, R) -> dimensionless
KERNEL_SCALE = {
    "1": lambda v, chi, R: v,
    "length": lambda v, chi, R: v / R,
    "rate": lambda v, chi, R: v * chi,
    "speed": lambda v, chi, R: v * chi / R,
}


def _check_field(ok: _Checks, f: fields.Field, v, values: dict):
    """The valid value of field f (None where invalid: the error is in ok.errors); `values`: the
    fields checked before it, for its relative bound."""
    if f.kind == "number":
        return ok.field(f.path, v, values=values)
    if f.kind == "vector":
        return ok.vector(f.path, v, f.size)
    if f.kind == "choice":
        return ok.choice(f.path, v, f.choices)
    if f.kind == "flag":
        if not isinstance(v, bool):
            ok.errors.append(ConfigError(f.path, v, "true or false"))
        return v
    if f.kind == "levels":
        if not isinstance(v, (list, tuple)) or not v:
            ok.errors.append(ConfigError(f.path, v, "a non-empty list, each " + f.range.allowed()))
            return None
        lv = [ok.field(f.path, x, f"{f.path}[{i}]") for i, x in enumerate(v)]
        if any(x is None for x in lv):
            return None
        if len(set(lv)) != len(lv):
            ok.errors.append(ConfigError(f.path, lv, "distinct values (a level is listed twice)"))
            return None
        return sorted(lv, reverse=True)
    raise ValueError(f"{f.path}: unknown field kind {f.kind!r}")


def _validate(raw) -> Scene:
    errors: list[ConfigError] = []
    cfg = _merge("", raw, DEFAULTS, errors)
    ok = _Checks(errors)
    values: dict[str, Any] = {}     # field -> its valid value, None where invalid
    for f in fields.FIELDS:
        if not f.scene:
            continue
        *section, key = f.path.split(".")
        node = cfg[section[0]] if section else cfg
        node[key] = values[f.path] = _check_field(ok, f, node[key], values)
    d, st, ini = cfg["disk"], cfg["stop"], cfg["initial"]

    # the checks that need the disk's model parameters: where the fields they read are valid
    kernel_fields = [f for f in fields.FIELDS if f.kernel is not None]
    needed = [values[k] for k in MODEL_INPUTS] + [values[f.path] for f in kernel_fields]
    if errors and any(x is None for x in needed):
        raise_all(errors)
    c = cfg["contact"]
    params, chi = model.make_params(SHAPES[d["shape"]], d["radius"], d["thickness"], cfg["gravity"],
                                    c["mu_s"], c["mu_d"], (c["k1"], c["k2"], c["k3"]))
    for f in kernel_fields:
        params[getattr(model, f.kernel.slot)] = KERNEL_SCALE[f.kernel.scale](values[f.path], chi, d["radius"])
    if st["levels"] is not None:
        bmax = max_level(params)
        if st["levels"][0] > bmax:
            errors.append(ConfigError("stop.levels", st["levels"][0],
                                      f"inclinations in (0, {bmax:.4f}) rad for this disk (the energy-equivalent "
                                      "inclination is defined only where steady centre-fixed rolling exists)"))
            st["levels"] = None
    if ini["alpha"] is not None:
        err = flat_start_error(ini["alpha"])
        if err is not None:
            errors.append(err)
            ini["alpha"] = None
    raise_all(errors)
    energy_scale = d["mass"] * d["radius"] ** 2 / chi**2
    return Scene(config=cfg, params=params, chi=chi, energy_scale=energy_scale)


def flat_start_error(alpha: float) -> ConfigError | None:
    """The error for a start that lies flat already: pi/2 - |alpha| at or below the face
    inclination BETA_FACE (1e-6 rad), where the face touches the table (core.event_rules)."""
    beta = 0.5 * math.pi - abs(alpha)
    if beta > BETA_FACE:
        return None
    return ConfigError("initial.alpha", alpha,
                       f"0 < |alpha| < pi/2 - {fields.number_text(BETA_FACE)} = {0.5 * math.pi - BETA_FACE:.7f} rad (at "
                       f"{fields.number_text(BETA_FACE)} rad "
                       "from flat the disk's face reaches the table: the model's halt)",
                       problem=f"the disk starts lying flat (pi/2 - |alpha| = {beta:.3g} rad)")


def initial_state(scene: Scene) -> tuple[np.ndarray, int]:
    """Dimensionless initial state and mode (SLIDE if the initial slip is non-zero; the kernel
    makes a slip at or below slip_tol a slaved one)."""
    cfg = scene.config
    chi, R = scene.chi, cfg["disk"]["radius"]
    y0 = np.zeros(model.N_FULL)
    ini = cfg["initial"]
    y0[model.Y_ALPHA] = ini["alpha"]
    y0[model.Y_W1:model.Y_W3 + 1] = np.asarray(ini["omega"]) * chi
    slip = np.asarray(ini["slip"]) * chi / R
    mode = SLIDE if np.any(slip != 0.0) else ROLL
    y0[model.Y_U1:model.Y_U2 + 1] = slip
    y0[model.Y_THETA] = ini["theta"]
    y0[model.Y_PSI] = ini["psi"]
    return y0, mode


def equivalent_inclination(scene: Scene, energy: float) -> float:
    """The energy-equivalent inclination (rad) of a dimensionless energy: E_ss^-1(energy) on
    (0, max_level], by bisection to 1e-12 relative (E_ss increases there); max_level where the
    energy exceeds E_ss there."""
    lo, hi = 0.0, max_level(scene.params)
    if energy >= model.steady_rolling_energy(hi, scene.params):
        return hi
    while hi - lo > 1e-12 * hi:
        mid = 0.5 * (lo + hi)
        if model.steady_rolling_energy(mid, scene.params) < energy:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


def check_start(scene: Scene) -> Scene:
    """`scene`, or ConfigError where its start's energy is at or below the deepest level's: every
    level would be 'reached' at t = 0 and nothing measured (the energy-equivalent inclination only
    falls). Checked for a scene file (`run.py scene`), not by load_scene: in a sweep, where the
    grid's corners can combine a flat tilt with a slow spin, such a point runs and its level times
    say 0."""
    err = start_below_levels_error(scene)
    if err is not None:
        raise err
    return scene


def start_below_levels_error(scene: Scene) -> ConfigError | None:
    """The error of check_start, None for a start above the deepest level."""
    y0, mode = initial_state(scene)
    side = 1 if y0[model.Y_ALPHA] > 0 else -1
    e0 = model.energy(y0, scene.params, side, mode)
    deepest = float(scene.levels[-1])
    if e0 > model.steady_rolling_energy(deepest, scene.params):
        return None
    beta = equivalent_inclination(scene, e0)
    ini = scene.config["initial"]
    start = {"alpha": ini["alpha"], "omega": ini["omega"], "slip": ini["slip"]}
    return ConfigError("initial", start,
                       f"a start above the deepest level, stop.levels = {deepest!r} rad (more tilt from flat, "
                       "more spin, or a deeper level)",
                       problem=f"its energy-equivalent inclination {beta:.3g} rad is at or below the deepest level "
                       f"{deepest!r} rad: every level would be reached at t = 0")
