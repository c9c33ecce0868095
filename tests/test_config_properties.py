"""Sweep configs, property-based (issue #5): random valid configs validate and yield a plan;
random invalid ones (one key corrupted) fail naming the key and the allowed range, before any job.

Validation here is `sweep.validation.check_config` / `normalize` (what workflow/rules/common.smk runs
when Snakemake parses the workflow) and `snakemake.utils.validate` against the same schema. No
integration is run, except in the last tests, which call `snakemake -n` on a copy of the
workflow and check that it stops with a readable message before any job.
"""
from __future__ import annotations

import copy
import math
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from sweep import chunking, fields, grid, validation
from conftest import copy_workflow
from sweep.errors import ConfigError
from sweep.scene import load_scene

ROOT = Path(__file__).resolve().parents[1]
SCHEMA_PATH = validation.SCHEMA_PATH
SCHEMA = validation.load_schema(SCHEMA_PATH)
HALF_PI = math.pi / 2
FINITE = dict(allow_nan=False, allow_infinity=False)
HSETTINGS = dict(deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])


def base() -> dict:
    """config/tiny.yaml: valid, every key set."""
    return yaml.safe_load((ROOT / "config" / "tiny.yaml").read_text())


# ------------------------------------------------------------------------------- valid configs

def _axis(elements, max_size=3):
    return st.lists(elements, min_size=1, max_size=max_size, unique=True)


@st.composite
def valid_configs(draw, levels_max: float = HALF_PI, ordinary_disk: bool = False):
    """A config inside every documented range; optional sections and keys are left out at
    random (then the schema's defaults apply)."""
    if ordinary_disk:  # sizes at which the core's floating-point set-up cannot underflow
        radius = draw(st.floats(1e-3, 10.0, **FINITE))
    else:
        radius = draw(st.floats(1e-6, 10.0, **FINITE))
    cfg: dict = {}
    disk = {}
    if draw(st.booleans()):
        disk["radius"] = radius
    else:
        radius = SCHEMA["properties"]["disk"]["properties"]["radius"]["default"]
    if "radius" in disk or draw(st.booleans()):  # the default thickness may exceed 4 * radius
        disk["thickness"] = draw(st.floats(0.0, 1.0, exclude_min=True, **FINITE)) * 4 * radius
        if disk["thickness"] <= 0:
            disk["thickness"] = radius
    if draw(st.booleans()):
        disk["mass"] = draw(st.floats(1e-3 if ordinary_disk else 1e-9, 1e4, **FINITE))
    if draw(st.booleans()):
        disk["shape"] = draw(st.sampled_from(["solid", "shell"]))
    if disk or draw(st.booleans()):
        cfg["disk"] = disk
    if draw(st.booleans()):
        cfg["gravity"] = draw(st.floats(0.1 if ordinary_disk else 1e-3, 1000.0, **FINITE))
    mu_s = draw(st.floats(0.0, 10.0, exclude_min=True, **FINITE))
    if draw(st.booleans()):
        cfg["mu_s"] = mu_s
    else:
        mu_s = SCHEMA["properties"]["mu_s"]["default"]
    kmax = min(radius, 1.0)
    # within BETA_FACE (1e-6 rad) of flat the disk starts lying flat: the core's scene checks refuse it
    nonzero_alpha = st.floats(-HALF_PI + 1e-6, HALF_PI - 1e-6, exclude_min=True, exclude_max=True,
                              **FINITE).filter(lambda a: a != 0)
    cfg["grid"] = {
        "mu_d": draw(_axis(st.floats(0.0, mu_s, **FINITE))),
        "k1": draw(_axis(st.floats(0.0, kmax, **FINITE))),
        "k2": draw(_axis(st.floats(0.0, kmax, **FINITE), 2)),
        "k3": draw(_axis(st.floats(0.0, kmax, **FINITE), 2)),
        "alpha0": draw(_axis(nonzero_alpha)),
        "omega0": draw(_axis(st.one_of(st.floats(0.0, 1e4, exclude_min=True, **FINITE),
                                       st.integers(1, 10_000)))),
    }
    if draw(st.booleans()):
        cfg["levels"] = draw(_axis(st.floats(1e-7, levels_max, exclude_max=True, **FINITE), 4))
    elif levels_max < 0.1:
        cfg["levels"] = [levels_max / 2]
    solver = {}
    if draw(st.booleans()):
        solver["method"] = draw(st.sampled_from(["adaptive", "fixed"]))
        if solver["method"] == "fixed" or draw(st.booleans()):
            solver["dt"] = draw(st.floats(0.0, 1.0, exclude_min=True, **FINITE))
    if draw(st.booleans()):
        solver["rtol"] = draw(st.floats(1e-14, 1e-2, **FINITE))
    if draw(st.booleans()):
        solver["atol"] = draw(st.floats(1e-16, 1e-2, **FINITE))
    if draw(st.booleans()):
        solver["slip_tol"] = draw(st.floats(0.0, 1e-2, exclude_min=True, **FINITE))
    if draw(st.booleans()):
        solver["spin_tol"] = draw(st.floats(0.0, 1e-2, **FINITE))
    if draw(st.booleans()):
        solver["slave_tol"] = draw(st.floats(0.0, 0.1, **FINITE))
    if solver or draw(st.booleans()):
        cfg["solver"] = solver
    stop = {}
    if draw(st.booleans()):
        stop["t_max"] = draw(st.floats(0.0, 1e5, exclude_min=True, **FINITE))
    if draw(st.booleans()):
        stop["max_steps"] = draw(st.integers(1, 10**9))
    if stop or draw(st.booleans()):
        cfg["stop"] = stop
    if draw(st.booleans()):
        cfg["chunk_size"] = draw(st.integers(1, 100_000))
    if draw(st.booleans()):
        cfg["outputs"] = {"notebooks": draw(st.lists(st.sampled_from(grid.NOTEBOOKS), unique=True))}
    return cfg


@pytest.mark.slow
@settings(max_examples=200, **HSETTINGS)
@given(valid_configs())
def test_valid_config_validates_and_yields_a_plan(cfg):
    from snakemake.utils import validate

    filled = validation.check_config(cfg, SCHEMA)
    theirs = copy.deepcopy(cfg)
    validate(theirs, str(SCHEMA_PATH))  # Snakemake's own validation accepts it and fills the same defaults
    assert theirs == filled
    settings_ = grid.normalize(cfg, SCHEMA, check_scenes=False)
    # Bounded work: every scene of every valid config has a finite time limit and step budget.
    assert 0 < settings_["stop"]["t_max"] <= 1e5 and 1 <= settings_["stop"]["max_steps"] <= 10**9
    plan = chunking.plan_chunks(settings_)
    points = [p for c in plan.values() for p in c.points]
    assert len(points) == len(set(points)) == math.prod(grid.grid_shape(settings_))
    cap = 2 * settings_["chunk_size"]
    assert all(1 <= len(c.points) <= cap for c in plan.values())
    sc = grid.scene(settings_, points[0])
    assert sc["stop"]["t_max"] == settings_["stop"]["t_max"] and sc["stop"]["max_steps"] == settings_["stop"]["max_steps"]


@settings(max_examples=40, **HSETTINGS)
@given(valid_configs())
def test_core_checks_raise_only_readable_config_errors(cfg):
    # The physics core's own scene checks (run by normalize) either accept a schema-valid config
    # or reject it with a SweepConfigError naming a key, never with another exception.
    try:
        grid.normalize(cfg, SCHEMA)
    except validation.SweepConfigError as err:
        for line in str(err).splitlines():   # one line per field: `key = value is invalid: ... allowed ...`
            assert re.match(r"^[\w.\[\], ]+ (= .+ is invalid: |is missing: )", line) and "allowed" in line, line


@settings(max_examples=40, **HSETTINGS)
@given(valid_configs(levels_max=0.3, ordinary_disk=True))
def test_ordinary_valid_configs_pass_the_core_checks(cfg):
    # Levels below 0.3 rad lie under the largest steady-motion inclination of every disk shape
    # the schema allows (thickness <= 4 radius gives ~0.31 rad at worst).
    grid.normalize(cfg, SCHEMA)


# ------------------------------------------------------------------------------- invalid configs

# The ranges the validation must enforce: the one table (sweep.fields.RANGES) that scene files
# and the sweep schema share, and whose every row docs/pipeline.md states (test_grid checks that).
def _bounds(key: str) -> tuple:
    r = fields.RANGES[fields.SWEEP_KEYS[key]]
    return r.lo, r.hi, r.lo_open, r.hi_open


# Scalar keys: (path, lower bound, upper bound, lower open, upper open, integer)
SCALARS = [(tuple(key.split(".")), *_bounds(key), fields.RANGES[fields.SWEEP_KEYS[key]].integer)
           for key in ("disk.radius", "disk.mass", "gravity", "mu_s", "solver.rtol", "solver.atol", "solver.dt",
                       "solver.slip_tol", "solver.spin_tol", "solver.slave_tol", "stop.t_max", "stop.max_steps")]
SCALARS.append((("chunk_size",), 1, 100_000, False, False, True))
# Axis items: (axis, lower, upper, lower open, upper open), absolute bounds (mu_d <= mu_s and
# k_i <= radius are the cross-field cases below)
ITEMS = [(key.split(".")[-1], *_bounds(key)) for key in
         ("grid.mu_d", "grid.k1", "grid.k2", "grid.k3", "grid.alpha0", "grid.omega0", "levels")]
SECTIONS = ["disk", "solver", "stop", "outputs", "grid"]
WRONG_TYPES = st.one_of(
    st.text(max_size=8), st.booleans(), st.none(),
    st.lists(st.integers(), max_size=2),
    st.dictionaries(st.sampled_from(["a", "b"]), st.integers(), max_size=1),
    st.sampled_from(["12", "0.5", "1e-3"]),  # numbers in quotes: text, in configs as in scene files
)


def _set(cfg: dict, path: tuple, value) -> None:
    node = cfg
    for part in path[:-1]:
        node = node.setdefault(part, {}) if isinstance(part, str) else node[part]
    node[path[-1]] = value


def _axis_path(axis: str) -> tuple:
    return ("levels",) if axis == "levels" else ("grid", axis)


def _key(path: tuple) -> str:
    return "".join(f"[{p}]" if isinstance(p, int) else (f".{p}" if i else p) for i, p in enumerate(path))


def _outside(draw, lo, hi, lo_open, hi_open, integer: bool):
    """A number outside [lo, hi] (or on an open bound)."""
    choices = []
    if integer:
        choices += [st.integers(max_value=int(lo) - 1).map(int), st.integers(min_value=int(hi) + 1)]
    else:
        span = max(abs(hi - lo), 1.0)
        choices += [st.floats(hi, hi + 10 * span, exclude_min=not hi_open, **FINITE).filter(lambda v: v > hi or hi_open),
                    st.floats(lo - 10 * span, lo, exclude_max=not lo_open, **FINITE).filter(lambda v: v < lo or lo_open)]
        choices.append(st.just(hi * (1 + 1e-12) if hi > 0 else hi + 1e-12))
        if hi_open:
            choices.append(st.just(hi))
        if lo_open:
            choices.append(st.just(lo))
    return draw(st.one_of(*choices))


@st.composite
def invalid_configs(draw):
    """(config, key that must be named, [fragments that must be on that key's message line]).

    A valid config with exactly one corruption."""
    cfg = base()
    cfg["solver"]["dt"] = 1e-3  # so that solver.dt can be corrupted too (adaptive ignores it)
    kind = draw(st.sampled_from([
        "scalar_range", "item_range", "non_finite", "wrong_type", "section_type", "axis_type",
        "unknown_key", "empty_axis", "duplicate", "alpha0_zero", "mu_d_above_mu_s",
        "k_above_radius", "thickness", "fixed_without_dt", "non_integer"]))
    if kind == "scalar_range":
        path, lo, hi, lo_open, hi_open, integer = draw(st.sampled_from(SCALARS))
        _set(cfg, path, _outside(draw, lo, hi, lo_open, hi_open, integer))
        return cfg, _key(path), ["allowed"]
    if kind == "item_range":
        axis, lo, hi, lo_open, hi_open = draw(st.sampled_from(ITEMS))
        values = cfg[axis] if axis == "levels" else cfg["grid"][axis]
        i = draw(st.integers(0, len(values)))
        bad = _outside(draw, lo, hi, lo_open, hi_open, False)
        values.insert(i, bad)
        if bad in values[:i] + values[i + 1:]:
            return cfg, _key(_axis_path(axis)), ["duplicate"]
        rng = {"alpha0": "(-pi/2, pi/2)", "levels": "[1e-7, pi/2)"}.get(axis, "allowed")
        return cfg, _key(_axis_path(axis) + (i,)), [rng]
    if kind == "non_finite":
        bad = draw(st.sampled_from([math.nan, math.inf, -math.inf]))
        if draw(st.booleans()):
            path = draw(st.sampled_from(SCALARS))[0] + ()
        else:
            axis = draw(st.sampled_from(ITEMS))[0]
            values = cfg[axis] if axis == "levels" else cfg["grid"][axis]
            i = draw(st.integers(0, len(values) - 1))
            path = _axis_path(axis) + (i,)
        _set(cfg, path, bad)
        return cfg, _key(path), ["not a finite number", "allowed"]
    if kind == "wrong_type":
        path = draw(st.sampled_from([s[0] for s in SCALARS] + [("disk", "shape"), ("solver", "method"),
                                                             ("disk", "thickness")]))
        bad = draw(WRONG_TYPES)
        if path in {("disk", "shape"), ("solver", "method")}:
            bad = draw(st.one_of(st.integers(), st.floats(**FINITE), st.text(max_size=8).filter(
                lambda s: s not in {"solid", "shell", "adaptive", "fixed"})))
        _set(cfg, path, bad)
        return cfg, _key(path), ["allowed"]
    if kind == "section_type":
        section = draw(st.sampled_from(SECTIONS))
        cfg[section] = draw(st.one_of(st.integers(), st.text(max_size=5), st.lists(st.integers(), max_size=2)))
        return cfg, section, ["not a mapping", "allowed"]
    if kind == "axis_type":
        axis = draw(st.sampled_from([i[0] for i in ITEMS]))
        value = draw(st.one_of(st.floats(0.1, 1.0, **FINITE), st.text(max_size=5), st.just({"a": 1})))
        _set(cfg, _axis_path(axis), value)
        return cfg, _key(_axis_path(axis)), ["not a list", "allowed"]
    if kind == "unknown_key":
        section = draw(st.sampled_from([None, "disk", "solver", "stop", "outputs", "grid"]))
        node = cfg if section is None else cfg[section]
        name = draw(st.from_regex(r"[a-z][a-z0-9_]{0,11}", fullmatch=True).filter(lambda n: n not in node))
        node[name] = draw(st.one_of(st.integers(), st.text(max_size=3)))
        return cfg, f"{section}.{name}" if section else name, ["no such key", "allowed keys"]
    if kind == "empty_axis":
        axis = draw(st.sampled_from([i[0] for i in ITEMS]))
        _set(cfg, _axis_path(axis), [])
        return cfg, _key(_axis_path(axis)), ["empty", "allowed"]
    if kind == "duplicate":
        axis = draw(st.sampled_from([i[0] for i in ITEMS]))
        values = cfg[axis] if axis == "levels" else cfg["grid"][axis]
        v = draw(st.sampled_from(values))
        values.insert(draw(st.integers(0, len(values))), float(v) if draw(st.booleans()) else v)
        return cfg, _key(_axis_path(axis)), ["duplicate", repr(float(v)), "allowed"]
    if kind == "alpha0_zero":
        values = cfg["grid"]["alpha0"]
        i = draw(st.integers(0, len(values)))
        values.insert(i, draw(st.sampled_from([0, 0.0, -0.0])))
        return cfg, f"grid.alpha0[{i}]", ["0 is not allowed", "(-pi/2, pi/2), not 0"]
    if kind == "mu_d_above_mu_s":
        mu_s = cfg["mu_s"]
        values = cfg["grid"]["mu_d"]
        i = draw(st.integers(0, len(values)))
        values.insert(i, draw(st.floats(mu_s, 10.0, exclude_min=True, **FINITE)))
        return cfg, f"grid.mu_d[{i}]", ["exceeds mu_s", "allowed [0, mu_s]"]
    if kind == "k_above_radius":
        axis = draw(st.sampled_from(["k1", "k2", "k3"]))
        values = cfg["grid"][axis]
        i = draw(st.integers(0, len(values)))
        values.insert(i, draw(st.floats(cfg["disk"]["radius"], 1.0, exclude_min=True, **FINITE)))
        return cfg, f"grid.{axis}[{i}]", ["exceeds radius", "allowed [0, radius]"]
    if kind == "thickness":
        cfg["disk"]["thickness"] = draw(st.floats(4 * cfg["disk"]["radius"], 40.0, exclude_min=True, **FINITE))
        return cfg, "disk.thickness", ["exceeds 4*radius", "allowed (0, 4*radius]"]
    if kind == "fixed_without_dt":
        cfg["solver"] = {"method": "fixed"}
        return cfg, "solver.dt", ["required", "allowed (0, 1]"]
    assert kind == "non_integer"
    path = draw(st.sampled_from([("stop", "max_steps"), ("chunk_size",)]))
    _set(cfg, path, draw(st.floats(1.0, 1000.0, **FINITE).filter(lambda v: not v.is_integer())))
    return cfg, _key(path), ["integer", "allowed"]


def _lines_naming(msg: str, key: str) -> list[str]:
    return [line for line in msg.splitlines() if line.startswith((f"{key} = ", f"{key} is missing"))]


@settings(max_examples=400, **HSETTINGS)
@given(invalid_configs())
def test_invalid_config_fails_naming_the_key_and_range(case):
    cfg, key, fragments = case
    with pytest.raises(validation.SweepConfigError) as exc:
        grid.normalize(cfg, SCHEMA, check_scenes=False)
    msg = str(exc.value)
    lines = _lines_naming(msg, key)
    assert lines, (key, msg)
    for frag in fragments:
        assert any(frag in line for line in lines), (key, frag, msg)


def test_level_below_the_core_minimum_names_levels_and_the_range():
    # Levels below 1e-7 rad (a decade under the face-contact inclination BETA_FACE = 1e-6 rad) are
    # rejected by the sweep's own check, in the words a scene file gets.
    cfg = base()
    cfg["levels"] = [0.3, 1e-8]
    with pytest.raises(validation.SweepConfigError) as exc:
        grid.normalize(cfg, SCHEMA)
    lines = _lines_naming(str(exc.value), "levels[1]")
    assert lines and "1e-08" in lines[0] and "allowed [1e-7, pi/2) each" in lines[0], str(exc.value)
    with pytest.raises(ConfigError) as exc:
        load_scene({"stop": {"levels": [0.3, 1e-8]}})
    assert str(exc.value).startswith("stop.levels[1] = 1e-08 is invalid: allowed [1e-7, pi/2) (")


def test_a_subnormal_disk_is_a_config_error_not_a_crash():
    # A subnormal radius would make chi^2 = R/g underflow to 0 in the core's set-up; the range
    # [1e-6, 10] m rejects it before, naming the key and the range.
    cfg = base()
    cfg["disk"].update(radius=5e-324, thickness=5e-324)
    cfg["grid"].update(k1=[0.0], k2=[0.0], k3=[0.0])
    with pytest.raises(validation.SweepConfigError) as exc:
        grid.normalize(cfg, SCHEMA)
    msg = str(exc.value)
    assert "disk.radius = 5e-324 is invalid: allowed [1e-6, 10] (disk radius R in m)" in msg, msg


@pytest.mark.parametrize("key", sorted(fields.SWEEP_KEYS))
def test_a_scene_and_a_sweep_reject_a_value_alike(key):
    """The value just outside a field's range is rejected by a scene file and by a sweep config,
    with the same range and meaning in the message (one table, sweep.fields)."""
    field = fields.SWEEP_KEYS[key]
    rng = fields.RANGES[field]
    bad = rng.hi * 2 + 1 if not rng.integer else int(rng.hi) + 1
    scene_cfg: dict = {}
    section, _, name = field.rpartition(".")
    value = bad
    if field == "initial.spin":     # the sweep's omega0 is the scene's -omega[2]
        section, name, value = "initial", "omega", [0.0, 0.0, -bad]
    elif field == "stop.levels":
        value = [bad]
    if section:
        scene_cfg[section] = {name: value}
    else:
        scene_cfg[name] = value
    with pytest.raises(ConfigError) as exc:
        load_scene(scene_cfg)
    scene_line = str(exc.value)
    cfg = base()
    path = key.split(".")
    if key.startswith("grid.") or key == "levels":
        _set(cfg, tuple(path), [bad])
    else:
        _set(cfg, tuple(path), bad)
    with pytest.raises(validation.SweepConfigError) as exc:
        grid.normalize(cfg, SCHEMA, check_scenes=False)
    sweep_lines = str(exc.value).splitlines()
    want = f"{rng.text()}"
    assert any(want in line and f"({rng.describe()})" in line for line in sweep_lines), (key, sweep_lines)
    if field != "initial.spin":
        assert want in scene_line and f"({rng.describe()})" in scene_line, scene_line


# ------------------------------------------------------------------------------- end to end (snakemake -n)



def snakemake(wd: Path, *args: str) -> subprocess.CompletedProcess:
    env = dict(os.environ)
    env["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{env.get('PATH', '')}"
    cmd = [sys.executable, "-m", "snakemake", "--snakefile", str(wd / "Snakefile"), "--directory", str(wd), *args]
    return subprocess.run(cmd, cwd=wd, env=env, capture_output=True, text=True, timeout=300)


E2E_BAD = {
    # YAML text as a user would write it: one file with many mistakes, all reported at once
    "many": ("""
disk: {radius: 0.03755, thickness: 0.0128, mass: .nan, shape: solid}
mu_s: 0.5
gravity: "9.81"
grid:
  mu_d: [0.2, 0.7]
  k1: [3.755e-6]
  k2: []
  k3: [6.0e-4, 6.0e-4]
  alpha0: [0.0, 0.9]
  omega0: [12.0, .inf]
levels: [0.3, 1e-2, 2.0]
solver: {method: adaptive, tol: 1.0e-8}
stop: {t_max: 1.0e+6, max_steps: 2000000}
""", ["config/bad.yaml: disk.mass = nan", "config/bad.yaml: grid.mu_d[1] = 0.7", "config/bad.yaml: grid.k2 = []",
      "config/bad.yaml: grid.k3 = [0.0006, 0.0006]", "config/bad.yaml: grid.alpha0[0] = 0.0",
      "config/bad.yaml: grid.omega0[1] = inf", "config/bad.yaml: levels[2] = 2.0",
      "config/bad.yaml: gravity = '9.81' is invalid: a number in quotes is text: remove the quotes",
      "config/bad.yaml: solver.tol = 1e-08 is invalid: no such key", "config/bad.yaml: stop.t_max = 1000000.0"]),
    # a rule only the physics core knows: a level above this disk's steady-motion range
    "core": ("""
levels: [1.5, 0.1]
""", ["config/bad.yaml: levels = 1.5 is invalid", "physics-core", "allowed"]),
}


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(E2E_BAD))
def test_dry_run_with_bad_config_fails_readably_before_any_job(tmp_path, name):
    text, fragments = E2E_BAD[name]
    wd = copy_workflow(tmp_path / "wf")
    cfg = base()
    cfg.update(yaml.safe_load(text))
    (wd / "config" / "bad.yaml").write_text(text if name == "many" else yaml.safe_dump(cfg))
    p = snakemake(wd, "-n", "-j2", "--configfile", "config/bad.yaml")
    out = p.stdout + p.stderr
    assert p.returncode != 0, out
    assert "invalid sweep configuration" in out, out
    for frag in fragments:
        assert frag in out, (frag, out)
    assert "Traceback" not in out, out  # a message, not a crash
    assert "simulate_chunk" not in out and not (wd / "results").exists(), out
