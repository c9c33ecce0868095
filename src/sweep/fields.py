"""The allowed range of every number a user gives, in one table: scene files (sweep.scene) check
their values against it, and the sweep config's schema (sweep.grid.load_schema) takes its bounds
and the 'allowed' part of its descriptions from it, so a scene and a sweep accept the same values
and say so in the same words.

A field is named by its scene-file path (`disk.radius`, `contact.mu_d`, `initial.omega`); the
sweep keys that feed it (`grid.mu_d` items, `levels` items, ...) are in SWEEP_KEYS. SI units.
A bound may be another field's value times a factor (mu_d <= mu_s, k_i <= radius): the absolute
bound applies on its own, the relative one where the other field is known and valid.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from .errors import ConfigError

HALF_PI = 0.5 * math.pi


def number_text(x: float) -> str:
    """A bound as the messages print it: 0.5, 10, 1000, 1e-2, 1e4, 1e-7 (powers of ten and small
    or large values in e-notation without padding)."""
    if x == 0.0 or 0.1 <= abs(x) < 1e4:
        return f"{x:g}"
    mantissa, exp = f"{x:.12e}".split("e")
    mantissa = mantissa.rstrip("0").rstrip(".")
    return f"{mantissa}e{int(exp)}"


@dataclass(frozen=True)
class Relative:
    """An upper bound that is another field's value times `factor`, printed as `label`
    (e.g. 4*radius); `why` says what goes wrong beyond it, where that is not obvious."""

    field: str
    factor: float
    label: str
    why: str = ""


@dataclass(frozen=True)
class Range:
    """The allowed values of one number: [lo, hi] (open ends as flagged), optionally below a
    Relative bound, optionally excluding one value, optionally integers; `meaning` (with its unit
    and a note) is what the field is, for the messages."""

    lo: float
    hi: float
    meaning: str
    unit: str = ""
    lo_open: bool = False
    hi_open: bool = False
    integer: bool = False
    relative: Relative | None = None
    excluded: float | None = None
    lo_text: str = ""
    hi_text: str = ""
    note: str = ""

    def _lower(self) -> str:
        """The range's opening: `[0`, `(-pi/2`."""
        return f"{'(' if self.lo_open else '['}{self.lo_text or number_text(self.lo)}"

    def text(self) -> str:
        """The range as the messages print it: `[1e-14, 1e-2]`, `(0, 4*radius]`, `(-pi/2, pi/2), not 0`."""
        hi = self.relative.label if self.relative else (self.hi_text or number_text(self.hi))
        text = f"{self._lower()}, {hi}{')' if self.hi_open else ']'}"
        if self.integer:
            text = "integer " + text
        if self.excluded is not None:
            text += f", not {number_text(self.excluded)}"
        return text

    def describe(self) -> str:
        """`meaning in unit, note` for the messages' parentheses."""
        text = f"{self.meaning} in {self.unit}" if self.unit else self.meaning
        return f"{text}, {self.note}" if self.note else text

    def allowed(self) -> str:
        """What a message says is allowed: `[1e-14, 1e-2] (relative error tolerance ...)`."""
        return f"{self.text()} ({self.describe()})"

    def schema_bounds(self) -> dict:
        """The JSON-schema keywords of the absolute bounds."""
        out = {"exclusiveMinimum" if self.lo_open else "minimum": self.lo,
               "exclusiveMaximum" if self.hi_open else "maximum": self.hi}
        return {k: (int(v) if self.integer else v) for k, v in out.items()}

    def problem(self, v) -> str | None:
        """What is wrong with v under the absolute bounds, '' for a plain range violation, None
        where v is allowed (a number, finite, inside, not excluded)."""
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            return "" if isinstance(v, str) else "not a number"
        if not math.isfinite(v):
            return "not a finite number"
        if self.integer and not float(v).is_integer():
            return "not an integer"
        if v < self.lo or v > self.hi or (self.lo_open and v == self.lo) or (self.hi_open and v == self.hi):
            return ""
        if self.excluded is not None and v == self.excluded:
            return f"{number_text(self.excluded)} is not allowed"
        return None

    def relative_error(self, field: str, v: float, other: float) -> ConfigError | None:
        """The error where v exceeds the relative bound, `other` being the other field's value."""
        r = self.relative
        if r is None or v <= r.factor * other:
            return None
        bound = r.factor * other
        why = f" ({r.why})" if r.why else ""
        unit = f" {self.unit}" if self.unit else ""
        lower = self._lower()
        return ConfigError(field, v, f"{lower}, {r.label}] = {lower}, {bound!r}]{unit}{why}",
                           problem=f"exceeds {r.label} = {bound!r}{unit}")


RANGES: dict[str, Range] = {
    # lower bounds of the disk keep chi = sqrt(k^2 R / g)-scaled groups normal floating-point
    # numbers (a subnormal radius makes chi^2 underflow to 0); no rigid disk is below them
    "disk.radius": Range(1e-6, 10.0, "disk radius R", "m"),
    "disk.thickness": Range(0.0, 40.0, "disk thickness L", "m", lo_open=True,
                            relative=Relative("disk.radius", 4.0, "4*radius")),
    "disk.mass": Range(1e-9, 1e4, "disk mass m", "kg"),
    "gravity": Range(1e-3, 1e3, "gravitational acceleration g", "m/s^2"),
    # up to 100: a disk that never slides (the no-slip limit of the rolling model)
    "contact.mu_s": Range(0.0, 100.0, "static friction coefficient, dimensionless"),
    # mu_d > mu_s leaves no consistent slip onset (an instant can switch rolling<->sliding forever)
    "contact.mu_d": Range(0.0, 100.0, "dynamic friction coefficient, dimensionless",
                          relative=Relative("contact.mu_s", 1.0, "mu_s",
                                            "with mu_d > mu_s the slip onset is inconsistent")),
    "contact.k1": Range(0.0, 10.0, "rolling-resistance length k1", "m", note="moment k1 |N|",
                        relative=Relative("disk.radius", 1.0, "radius")),
    "contact.k2": Range(0.0, 10.0, "pivoting (drilling) resistance length k2", "m", note="moment k2 |N|",
                        relative=Relative("disk.radius", 1.0, "radius")),
    "contact.k3": Range(0.0, 10.0, "rolling-resistance length k3", "m", note="moment k3 |N|",
                        relative=Relative("disk.radius", 1.0, "radius")),
    "initial.alpha": Range(-HALF_PI, HALF_PI, "initial angle alpha (tilt of the disk plane from the vertical) in rad; "
                           "0 is line contact, +-pi/2 lies flat", lo_open=True, hi_open=True, excluded=0.0,
                           lo_text="-pi/2", hi_text="pi/2"),
    "initial.omega": Range(-1e5, 1e5, "initial angular velocity component on e1, e2, e3", "rad/s"),
    "initial.spin": Range(0.0, 1e5, "initial spin magnitude about -e3 (omega = [0, 0, -omega0])", "rad/s",
                          lo_open=True),
    "initial.slip": Range(-1e3, 1e3, "initial slip velocity component on a1, a2", "m/s"),
    "initial.theta": Range(-1e6, 1e6, "initial precession angle theta", "rad"),
    "initial.psi": Range(-1e6, 1e6, "initial spin angle psi", "rad"),
    # levels below the face inclination (core.contact.BETA_FACE = 1e-6 rad) are crossed when the
    # disk lies flat; 1e-7 keeps their energies normal numbers
    "stop.levels": Range(1e-7, HALF_PI, "inclination level in rad at which times and frequencies are recorded",
                         hi_open=True, hi_text="pi/2"),
    "stop.t_max": Range(0.0, 1e5, "simulated time limit", "s", lo_open=True),
    "stop.max_steps": Range(1, 10**9, "step budget per scene", integer=True),
    # rtol below 1e-14 asks for less than ~50 ulp per step: the error control cannot deliver it
    "solver.rtol": Range(1e-14, 1e-2, "relative error tolerance of the adaptive method, dimensionless"),
    "solver.atol": Range(1e-16, 1e-2, "absolute error tolerance of the adaptive method (dimensionless state)"),
    "solver.dt": Range(0.0, 1.0, "step ceiling of the fixed-step method (required when method is fixed)", "s",
                       lo_open=True),
    "solver.slip_tol": Range(0.0, 1e-2, "slip speed at which a slide meets its fate (it ends where it reaches "
                             "zero slip, else it passes through or spirals out; no decision depends on it: "
                             "docs/model.md)", "m/s", lo_open=True),
    "solver.spin_tol": Range(0.0, 1e-2, "rate |omega.a_i| at which a slowing moment component sticks if its "
                             "motion goes on to rest and the contact moment can hold it (0: only at rest)",
                             "rad/s"),
    "solver.slave_tol": Range(0.0, 0.1, "relaxation time of a slow slip's direction times the rate of the "
                              "motion (dimensionless) below which the direction is solved as its slow manifold "
                              "instead of integrated (0: only below slip_tol; results converge as it goes to 0: "
                              "docs/model.md, 'Slow slip')"),
    # the disk's material, for the sound synthesis only (sweep.audio, sweep.plate)
    "material.E": Range(0.0, 1e13, "Young's modulus", "Pa", lo_open=True),
    "material.density": Range(0.0, 1e5, "density", "kg/m^3", lo_open=True),
    "material.poisson": Range(-1.0, 0.5, "Poisson ratio", lo_open=True, hi_open=True),
    "material.damping": Range(0.0, 1.0, "modal damping ratio (fraction of critical)", lo_open=True, hi_open=True),
}

# sweep config key (an axis or list: its items) -> the field it sets in every scene
SWEEP_KEYS: dict[str, str] = {
    "disk.radius": "disk.radius", "disk.thickness": "disk.thickness", "disk.mass": "disk.mass",
    "gravity": "gravity", "mu_s": "contact.mu_s",
    "grid.mu_d": "contact.mu_d", "grid.k1": "contact.k1", "grid.k2": "contact.k2", "grid.k3": "contact.k3",
    "grid.alpha0": "initial.alpha", "grid.omega0": "initial.spin", "levels": "stop.levels",
    "solver.rtol": "solver.rtol", "solver.atol": "solver.atol", "solver.dt": "solver.dt",
    "solver.slip_tol": "solver.slip_tol", "solver.spin_tol": "solver.spin_tol",
    "solver.slave_tol": "solver.slave_tol", "stop.t_max": "stop.t_max", "stop.max_steps": "stop.max_steps",
}
# the sweep key of a scene field, to name in a message what the user wrote
SWEEP_KEY_OF = {field: key for key, field in SWEEP_KEYS.items()}
SWEEP_KEY_OF["initial.omega"] = "grid.omega0"


def check(field: str, v, name: str | None = None, values: dict | None = None) -> float:
    """v as a float (int for an integer field) if `field`'s range allows it, else ConfigError
    naming `name` (default: the field; an item: `stop.levels[2]`). `values`: the fields a relative
    bound reads (already valid)."""
    rng = RANGES[field]
    name = name or field
    problem = rng.problem(v)
    if problem is not None:
        raise ConfigError(name, v, rng.allowed(), problem=problem or None)
    if rng.relative is not None and values is not None and rng.relative.field in values:
        err = rng.relative_error(name, float(v), values[rng.relative.field])
        if err is not None:
            raise err
    return int(v) if rng.integer else float(v)


def apply_to_schema(schema: dict) -> dict:
    """The config schema with the bounds and the description (meaning, unit, 'allowed ...') of
    every node marked `x-range: <field>` (a number, or a list whose items are that field) filled
    from RANGES."""
    def walk(node):
        if isinstance(node, dict):
            field = node.pop("x-range", None)
            if field is not None:
                rng = RANGES[field]
                target = node["items"] if node.get("type") == "array" else node
                target.update(rng.schema_bounds())
                each = " each" if node.get("type") == "array" else ""
                node["description"] = f"{rng.describe()}; allowed {rng.text()}{each}"
            for v in node.values():
                walk(v)
        elif isinstance(node, list):
            for v in node:
                walk(v)
        return schema
    return walk(schema)
