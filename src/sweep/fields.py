"""The registry of every input a user gives: one `Field` per scene-file number, choice or switch,
with its allowed range, its scene default, the sweep config key that sets it, and (for a sweep
axis) the axis' name, units, long name and figure label. Everything else is generated from FIELDS:

* scene files (sweep.scene): DEFAULTS, and the checks, in FIELDS' order;
* the sweep config's JSON schema (sweep.validation.load_schema, `config_schema`): bounds, descriptions
  and defaults of the numbers, one property per axis under `grid` and `refine.axes`;
* the sweep axes (sweep.axes.AXES, their chunk layout, units and long names) and a point's scene
  (sweep.grid.scene);
* the cube's coordinates (sweep.cf) and the figures' axis labels (sweep.figures).

So a scene and a sweep accept the same values and say so in the same words, and a new sweepable
input is one Field (with an Axis) here plus its use in the model: a `kernel` slot of the model's
parameter vector (sweep.core.model.P_*), or a use of its scene value.

A field is named by its scene-file path (`disk.radius`, `contact.mu_d`, `initial.omega`). SI units.
A bound may be another field's value times a factor (mu_d <= mu_s, k_i <= radius): the absolute
bound applies on its own, the relative one where the other field is known and valid.
"""
from __future__ import annotations

import copy
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

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




@dataclass(frozen=True)
class Param:
    """Where a field enters the kernel: the slot of the model's parameter vector (the name of a
    sweep.core.model.P_* constant) and how its SI value is made dimensionless there: "1" (as is),
    "length" (/ R), "rate" (* chi), "speed" (* chi / R); R the disk radius, chi the time scale."""

    slot: str
    scale: str = "1"


def _spin_about_minus_e3(omega0: float) -> list[float]:
    """The initial omega of a rolling start spinning at omega0 about -e3."""
    return [0.0, 0.0, -omega0]


@dataclass(frozen=True)
class Axis:
    """A sweep axis: `grid.<name>` (or `refine.axes.<name>`) in the sweep config, the cube's dimension
    and coordinate `<name>`. `outer`: a chunk never mixes its values, so a value added anywhere adds
    whole chunks (docs/pipeline.md, 'How reruns work'); the others are cut by content. `sets`: the
    scene path a point's value sets (default: the field's own), through `to_scene` (default: as is).
    `default`: the values of a config that names none (None: the axis is required)."""

    name: str
    units: str                  # CF units of the coordinate
    long_name: str              # CF long_name of the coordinate
    label: str                  # a figure's axis label: words, symbol, unit
    outer: bool
    sets: str = ""
    to_scene: Callable[[float], Any] | None = None
    default: tuple[float, ...] | None = None


@dataclass(frozen=True)
class Field:
    """One input. `kind`: "number" (checked against `range`), "vector" (`size` numbers, each in
    `range`), "levels" (a non-empty list of distinct numbers in `range`, kept in decreasing order),
    "choice" (one of `choices`), "flag" (true or false). `default`: the scene's default; `scene`
    False for a field that is only a sweep axis' range (initial.spin: omega0). `sweep`: the sweep
    config key that sets it in every scene ("mu_s", "solver.rtol"; an axis: grid.<name>);
    `sweep_default`: the sweep schema gives that key the scene's default. `kernel`: the model
    parameter it sets directly (fields that sweep.core.model.make_params takes have none)."""

    path: str
    range: Range | None = None
    default: Any = None
    kind: str = "number"
    size: int = 0
    choices: tuple[str, ...] = ()
    sweep: str = ""
    sweep_default: bool = False
    axis: Axis | None = None
    kernel: Param | None = None
    scene: bool = True

    @property
    def sweep_key(self) -> str:
        return f"grid.{self.axis.name}" if self.axis else self.sweep


# In the order scene files are checked (a relative bound's field before the fields it bounds) and
# their sections listed.
FIELDS: list[Field] = [
    # lower bounds of the disk keep chi = sqrt(k^2 R / g)-scaled groups normal floating-point
    # numbers (a subnormal radius makes chi^2 underflow to 0); no rigid disk is below them
    Field("disk.radius", Range(1e-6, 10.0, "disk radius R", "m"), 0.03755, sweep="disk.radius", sweep_default=True),
    Field("disk.mass", Range(1e-9, 1e4, "disk mass m", "kg"), 0.4387, sweep="disk.mass", sweep_default=True),
    Field("disk.thickness", Range(0.0, 40.0, "disk thickness L", "m", lo_open=True,
                                  relative=Relative("disk.radius", 4.0, "4*radius")),
          0.0128, sweep="disk.thickness", sweep_default=True),
    Field("disk.shape", default="solid", kind="choice", choices=("solid", "shell")),
    # up to 100: a disk that never slides (the no-slip limit of the rolling model)
    Field("contact.mu_s", Range(0.0, 100.0, "static friction coefficient, dimensionless"), 0.5,
          sweep="mu_s", sweep_default=True),
    # mu_d > mu_s leaves no consistent slip onset (an instant can switch rolling<->sliding forever)
    Field("contact.mu_d", Range(0.0, 100.0, "dynamic friction coefficient, dimensionless",
                                relative=Relative("contact.mu_s", 1.0, "mu_s",
                                                  "with mu_d > mu_s the slip onset is inconsistent")), 0.3,
          axis=Axis("mu_d", "1", "dynamic friction coefficient", "dynamic friction coefficient μ_d", outer=True)),
    Field("contact.k1", Range(0.0, 10.0, "rolling-resistance length k1", "m", note="moment k1 |N|",
                              relative=Relative("disk.radius", 1.0, "radius")), 3.755e-6,
          axis=Axis("k1", "m", "rolling resistance length k1 (moment k1 |N|)", "rolling resistance k1 (m)", outer=True)),
    Field("contact.k2", Range(0.0, 10.0, "pivoting (drilling) resistance length k2", "m", note="moment k2 |N|",
                              relative=Relative("disk.radius", 1.0, "radius")), 3.004e-5,
          axis=Axis("k2", "m", "pivoting resistance length k2 (moment k2 |N|)", "pivoting resistance k2 (m)",
                    outer=True)),
    Field("contact.k3", Range(0.0, 10.0, "rolling-resistance length k3", "m", note="moment k3 |N|",
                              relative=Relative("disk.radius", 1.0, "radius")), 3.004e-4,
          axis=Axis("k3", "m", "rolling resistance length k3 (moment k3 |N|)", "rolling resistance k3 (m)", outer=True)),
    Field("gravity", Range(1e-3, 1e3, "gravitational acceleration g", "m/s^2"), 9.81, sweep="gravity",
          sweep_default=True),
    Field("initial.alpha", Range(-HALF_PI, HALF_PI, "initial angle alpha (tilt of the disk plane from the vertical) "
                                 "in rad; 0 is line contact, +-pi/2 lies flat", lo_open=True, hi_open=True,
                                 excluded=0.0, lo_text="-pi/2", hi_text="pi/2"), 1.0,
          axis=Axis("alpha0", "rad", "initial angle alpha", "initial tilt α0 (rad)", outer=False)),
    Field("initial.omega", Range(-1e5, 1e5, "initial angular velocity component on e1, e2, e3", "rad/s"),
          [0.0, 0.0, -14.457], kind="vector", size=3),
    Field("initial.slip", Range(-1e3, 1e3, "initial slip velocity component on a1, a2", "m/s"), [0.0, 0.0],
          kind="vector", size=2),
    Field("initial.theta", Range(-1e6, 1e6, "initial precession angle theta", "rad"), 0.0),
    Field("initial.psi", Range(-1e6, 1e6, "initial spin angle psi", "rad"), 0.0),
    # the omega0 axis: a rolling start spinning about -e3 (initial.omega = [0, 0, -omega0])
    Field("initial.spin", Range(0.0, 1e5, "initial spin magnitude about -e3 (omega = [0, 0, -omega0])", "rad/s",
                                lo_open=True), scene=False,
          axis=Axis("omega0", "rad s-1", "initial spin rate about -e3", "initial spin ω0 (rad/s)", outer=False,
                    sets="initial.omega", to_scene=_spin_about_minus_e3)),
    # levels below the face inclination (core.event_rules.BETA_FACE = 1e-6 rad) are crossed when the
    # disk lies flat; 1e-7 keeps their energies normal numbers
    Field("stop.levels", Range(1e-7, HALF_PI, "inclination level in rad at which times and frequencies are recorded",
                               hi_open=True, hi_text="pi/2"), [1.0e-1, 1.0e-2, 1.0e-3, 1.0e-4], kind="levels",
          sweep="levels", sweep_default=True),
    # t_max: the paper's disk halts in ~10 s; real Euler's disks spin for up to ~2 min.
    Field("stop.t_max", Range(0.0, 1e5, "simulated time limit", "s", lo_open=True), 120.0, sweep="stop.t_max",
          sweep_default=True),
    # ~1e4 steps per halt for the paper's case at rtol 1e-10; 5e6 bounds a pathological scene to ~30 s
    # of CPU while letting the densest scenes of the convergence harness's ranges (~250 located events
    # per second, ~4e4 tries per second at rtol 1e-13) run past 100 s
    Field("stop.max_steps", Range(1, 10**9, "step budget per scene", integer=True), 5_000_000,
          sweep="stop.max_steps", sweep_default=True),
    Field("solver.method", default="adaptive", kind="choice", choices=("adaptive", "fixed")),
    # rtol below 1e-14 asks for less than ~50 ulp per step: the error control cannot deliver it.
    # 1e-10: halt times converge to ~1e-9 relative there (docs/performance.md), at a few ms per scene
    Field("solver.rtol", Range(1e-14, 1e-2, "relative error tolerance of the adaptive method, dimensionless"),
          1.0e-10, sweep="solver.rtol", sweep_default=True),
    Field("solver.atol", Range(1e-16, 1e-2, "absolute error tolerance of the adaptive method (dimensionless state)"),
          1.0e-12, sweep="solver.atol", sweep_default=True),
    Field("solver.dt", Range(0.0, 1.0, "step ceiling of the fixed-step method (required when method is fixed)", "s",
                             lo_open=True), 1.0e-3, sweep="solver.dt"),
    # slip_tol and spin_tol decide nothing (docs/model.md, 'Where a slip ends', 'Sticking at spin_tol')
    Field("solver.slip_tol", Range(0.0, 1e-2, "slip speed at which a slide meets its fate (it ends where it reaches "
                                   "zero slip, else it passes through or spirals out; no decision depends on it: "
                                   "docs/model.md)", "m/s", lo_open=True), 1.0e-9,
          sweep="solver.slip_tol", kernel=Param("P_UTOL", "speed")),
    Field("solver.spin_tol", Range(0.0, 1e-2, "rate |omega.a_i| at which a slowing moment component sticks if its "
                                   "motion goes on to rest and the contact moment can hold it (0: only at rest)",
                                   "rad/s"), 1.0e-7,
          sweep="solver.spin_tol", kernel=Param("P_WTOL", "rate")),
    # results converge as slave_tol goes to 0 (docs/model.md, 'Slow slip')
    Field("solver.slave_tol", Range(0.0, 0.1, "relaxation time of a slow slip's direction times the rate of the "
                                    "motion (dimensionless) below which the direction is solved as its slow manifold "
                                    "instead of integrated (0: only where the relaxation time alone is below 1e-7; "
                                    "results converge as it goes to 0: docs/model.md, 'Slow slip')"), 3.0e-3,
          sweep="solver.slave_tol", kernel=Param("P_SLAVE", "1")),
    # which stepper takes a slide's step: both converge to the same motion (docs/model.md, 'Slow slip')
    Field("solver.stiff_ratio", Range(0.0, 1e6, "step size, in relaxation times of a slide's slip direction "
                                      "(|u| / (mu_d N / m)), from which a slide is stepped by the linearly implicit "
                                      "extrapolation instead of DOP853 (0: DOP853 everywhere; a numerical choice: "
                                      "docs/model.md, 'Slow slip')"), 1.0,
          sweep="solver.stiff_ratio", kernel=Param("P_STIFF", "1")),
    Field("outputs.normal_force_frequency", default=True, kind="flag"),
    Field("outputs.kinematics", default=False, kind="flag"),
    # The disk's elastic material, used only by the sound synthesis (sweep.audio, sweep.plate), never by
    # the integrator or the summary. Default: the paper's steel (its footnote); damping 1e-3 is a choice
    # for a disk in contact with a table (free steel rings longer, ~1e-4).
    Field("material.E", Range(0.0, 1e13, "Young's modulus", "Pa", lo_open=True), 1.95e11),
    Field("material.density", Range(0.0, 1e5, "density", "kg/m^3", lo_open=True), 7737.27),
    Field("material.poisson", Range(-1.0, 0.5, "Poisson ratio", lo_open=True, hi_open=True), 0.28),
    Field("material.damping", Range(0.0, 1.0, "modal damping ratio (fraction of critical)", lo_open=True,
                                    hi_open=True), 1.0e-3),
]


# --------------------------------------------------------------------------------------------
# what the registry generates
# --------------------------------------------------------------------------------------------

def set_path(tree: dict, path: str, value) -> None:
    """tree[section][key] = value for a dotted path `section.key` (tree[path] for a top-level key)."""
    *sections, key = path.split(".")
    for s in sections:
        tree = tree.setdefault(s, {})
    tree[key] = value


def scene_defaults(fields: list[Field]) -> dict:
    """The scene's defaults as a nested mapping, in the fields' order."""
    out: dict = {}
    for f in fields:
        if f.scene:
            set_path(out, f.path, copy.deepcopy(f.default))
    return out


def axes(fields: list[Field]) -> tuple[Axis, ...]:
    """The sweep axes in the cube's (and a point's) order: the outer ones, then the inner ones."""
    found = [f.axis for f in fields if f.axis]
    return tuple(a for a in found if a.outer) + tuple(a for a in found if not a.outer)


def axis_field(name: str) -> Field:
    """The field of the axis `name`."""
    return next(f for f in FIELDS if f.axis and f.axis.name == name)


RANGES: dict[str, Range] = {f.path: f.range for f in FIELDS if f.range is not None}
# sweep config key (an axis or list: its items) -> the field it sets in every scene
SWEEP_KEYS: dict[str, str] = {f.sweep_key: f.path for f in FIELDS if f.sweep_key}
# the sweep key of a scene field, to name in a message what the user wrote
SWEEP_KEY_OF = {field: key for key, field in SWEEP_KEYS.items()}
SWEEP_KEY_OF.update({f.axis.sets: f.sweep_key for f in FIELDS if f.axis and f.axis.sets})
AXES: tuple[Axis, ...] = axes(FIELDS)
SCENE_DEFAULTS: dict = scene_defaults(FIELDS)
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


# --------------------------------------------------------------------------------------------
# the sweep config's JSON schema
# --------------------------------------------------------------------------------------------

def config_schema(template: dict) -> dict:
    """The sweep config's JSON schema from its template (src/sweep/schema/config.template.yaml):

    * a node marked `x-range: <field>` (a number, or a list whose items are that field) gets the
      field's bounds and description (meaning, unit, 'allowed ...'); with `x-default: true` also
      the field's scene default;
    * a node marked `x-each-axis: <node>` gets one property per axis (AXES order), each a copy of
      <node> in which `x-range: axis` names that axis' field;
    * `{axes}` in a description becomes the axes' names.
    """
    names = ", ".join(a.name for a in AXES)

    def walk(node):
        if isinstance(node, dict):
            each = node.pop("x-each-axis", None)
            if each is not None:
                node["properties"] = {}
                for a in AXES:
                    prop = copy.deepcopy(each)
                    if prop.get("x-range") == "axis":
                        prop["x-range"] = axis_field(a.name).path
                    node["properties"][a.name] = prop
            field = node.pop("x-range", None)
            with_default = node.pop("x-default", False)
            if field is not None:
                rng = RANGES[field]
                target = node["items"] if node.get("type") == "array" else node
                target.update(rng.schema_bounds())
                each_item = " each" if node.get("type") == "array" else ""
                node["description"] = f"{rng.describe()}; allowed {rng.text()}{each_item}"
                if with_default:
                    node["default"] = copy.deepcopy(next(f.default for f in FIELDS if f.path == field))
            if isinstance(node.get("description"), str):
                node["description"] = node["description"].replace("{axes}", names)
            for v in node.values():
                walk(v)
        elif isinstance(node, list):
            for v in node:
                walk(v)
        return node
    return walk(copy.deepcopy(template))
