"""A sweep's grid: the validated config in canonical form (`normalize`, `load_sweep`) and the scene
of each of its points.

A sweep is the Cartesian product of the axes of the registry of inputs (sweep.fields;
sweep.axes.AXES), every point one scene integrated by `sweep.simulate` (`scene`). The config is read
by sweep.configfiles and validated by sweep.validation; the grid is cut into chunks by
sweep.chunking.

Units: SI throughout (m, kg, s, rad, rad/s); friction coefficients are dimensionless.
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

from . import fields
from .axes import AXES, AXIS_DEFAULTS
from .configfiles import read_config, sweep_name
from .errors import ConfigError
from .validation import SweepConfigError, check_config, load_schema


NOTEBOOKS = ("halt_time", "frequency_ramps", "roll_slip", "cost")


# the notebooks of an adaptive map (a refine: section) only
ADAPTIVE_NOTEBOOKS = ("adaptive_map",)


def normalize(config: Mapping, schema: dict | None = None, check_scenes: bool = True) -> dict:
    """The validated config in canonical form.

    Defaults filled; axis values sorted ascending (the cube's coordinate order); levels sorted
    decreasing (the order in which the disk reaches them, as `sweep.simulate` reports them);
    every real number a float (so 1 and 1.0 hash alike); the solver settings completed with
    the physics core's defaults (`sweep.scene.DEFAULTS["solver"]`, e.g. slip_tol), so a change
    of those defaults changes every chunk's identity. With `check_scenes`, representative
    scenes are validated by the core too (see `check_scenes`).
    """
    from . import scene as _scene

    cfg = check_config(config, schema)
    disk = cfg["disk"]
    solver = dict(_scene.DEFAULTS["solver"])
    solver.update(cfg["solver"])
    solver = {k: (v if isinstance(v, str) else float(v)) for k, v in solver.items()}
    settings = {
        "disk": {"radius": float(disk["radius"]), "thickness": float(disk["thickness"]),
                 "mass": float(disk["mass"]), "shape": disk["shape"]},
        "gravity": float(cfg["gravity"]),
        "mu_s": float(cfg["mu_s"]),
        "grid": {a: (refine_axis(cfg["refine"]["axes"][a]) if a in cfg.get("refine", {}).get("axes", {})
                     else sorted(float(v) for v in cfg["grid"].get(a, AXIS_DEFAULTS.get(a)))) for a in AXES},
        "levels": sorted((float(v) for v in cfg["levels"]), reverse=True),
        "solver": solver,
        "stop": {"t_max": float(cfg["stop"]["t_max"]), "max_steps": int(cfg["stop"]["max_steps"])},
        "chunk_size": int(cfg["chunk_size"]),
        "outputs": {"notebooks": list(cfg["outputs"]["notebooks"]),
                    "error_estimate": bool(cfg["outputs"]["error_estimate"])},
    }
    if "refine" in cfg:
        ref = cfg["refine"]
        settings["refine"] = {
            "axes": {a: {"from": float(ref["axes"][a]["from"]), "to": float(ref["axes"][a]["to"]),
                         "points": int(ref["axes"][a]["points"]), "spacing": ref["axes"][a].get("spacing", "linear")}
                     for a in AXES if a in ref["axes"]},
            "max_share": float(ref["max_share"]), "start_points": int(ref["start_points"]),
            "tolerance": float(ref["tolerance"]), "outputs": list(ref["outputs"]),
        }
    if check_scenes:
        check_scenes_valid(settings)
    return settings


def refine_axis(spec: Mapping) -> list[float]:
    """The values of a lattice axis of refine.axes (sweep.lattice.axis_values)."""
    from . import lattice as _lattice

    return [float(v) for v in _lattice.axis_values(float(spec["from"]), float(spec["to"]), int(spec["points"]),
                                                   spec.get("spacing", "linear"))]


def is_adaptive(settings: Mapping) -> bool:
    """Whether a normalised config is an adaptive map (a `refine:` section)."""
    return "refine" in settings


@dataclass(frozen=True)
class Sweep:
    """A sweep as read and validated: its name (results/<name>/), the config with the schema's
    defaults filled, and the normalised settings (`normalize`)."""
    name: str
    config: dict
    settings: dict


def load_sweep(files: Sequence[tuple[str | Path, str]], overrides: Mapping | None = None,
               schema: dict | None = None, check_scenes: bool = True) -> Sweep:
    """The sweep whose config files are `files` ((path, name to show) in Snakemake's order:
    config/config.yaml, then each --configfile) with Snakemake's --config `overrides`. Raises
    SweepConfigError, every message naming its file, before any work. What `python3 run.py
    sweep` checks before Snakemake starts and the workflow when Snakemake parses it
    (workflow/rules/common.smk): the same code."""
    schema = schema if schema is not None else load_schema()
    src = read_config(files, overrides)
    name = sweep_name(*files[-1])
    try:
        return Sweep(name, check_config(src.config, schema), normalize(src.config, schema, check_scenes))
    except SweepConfigError as err:
        raise src.name_errors(err) from None


def check_scenes_valid(settings: Mapping) -> None:
    """Validate representative scenes with the physics core's own checks (sweep.scene).

    Every value of every axis is tried once (with the first value of the other axes), so each
    single-value rule of the core (e.g. k_i <= radius, levels below the largest inclination for
    which the disk's steady motion exists) is checked for every configured value, in
    sum(len(axis)) scene validations (~ms each) instead of one per grid point.
    """
    from . import scene as _scene

    first = {a: settings["grid"][a][0] for a in AXES}
    errors: dict[str, ConfigError] = {}
    for a in AXES:
        for v in settings["grid"][a]:
            point = dict(first, **{a: v})
            try:
                _scene.load_scene(scene(settings, point))
            except ConfigError as err:
                base = err.field.split("[")[0]
                key = fields.SWEEP_KEY_OF.get(base, err.field)
                if key.startswith("grid."):   # the axis value this scene had
                    axis = key.split(".")[1]
                    key = f"{key}[{settings['grid'][axis].index(point[axis])}]"
                errors.setdefault(key, ConfigError(key, err.value, err.allowed,
                                                   problem="rejected by the physics-core scene checks"))
            except (ArithmeticError, ValueError) as err:
                # Values inside every documented range can still be numerically degenerate for
                # the core's set-up (e.g. a subnormal radius: chi^2 = R/g underflows to 0). Stop
                # here with a message rather than a traceback at parse time or a failed job; the
                # disk and gravity are shared by every scene, so one message says it.
                errors.setdefault("disk", ConfigError(
                    "disk", settings["disk"], "values in the documented ranges that are not numerically "
                    f"degenerate (e.g. not a subnormal radius), with gravity {settings['gravity']!r}",
                    problem=f"the physics core cannot set up a scene with it ({type(err).__name__}: {err})"))
    if errors:
        raise SweepConfigError(list(errors.values()))


def grid_shape(settings: Mapping) -> tuple[int, ...]:
    return tuple(len(settings["grid"][a]) for a in AXES)


def scene(settings: Mapping, point: Mapping[str, float] | tuple[float, ...]) -> dict:
    """The `sweep.simulate` scene dict (SI units) of one grid point.

    The fixed part of the start is rolling: slip = [0, 0] m/s, theta = psi = 0; each axis sets its
    field (omega0: omega = [0, 0, -omega0] rad/s).
    """
    p = dict(zip(AXES, point)) if not isinstance(point, Mapping) else dict(point)
    sc = {
        "disk": dict(settings["disk"]),
        "contact": {"mu_s": settings["mu_s"]},
        "gravity": settings["gravity"],
        "initial": {"slip": [0.0, 0.0], "theta": 0.0, "psi": 0.0},
        "stop": {"levels": list(settings["levels"]), "t_max": settings["stop"]["t_max"],
                 "max_steps": settings["stop"]["max_steps"]},
        "solver": dict(settings["solver"]),
    }
    for a in fields.AXES:
        field = fields.axis_field(a.name)
        value = p[a.name] if a.to_scene is None else a.to_scene(p[a.name])
        fields.set_path(sc, a.sets or field.path, value)
    return sc


def grid_index(settings: Mapping) -> dict[str, dict[float, int]]:
    """Per axis: value -> position in the (sorted) cube axis."""
    return {a: {v: i for i, v in enumerate(settings["grid"][a])} for a in AXES}
