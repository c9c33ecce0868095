"""Sweep configuration: validation, normalisation and the split of the grid into chunks.

A sweep is the Cartesian product of six axes (see `AXES`), every point one scene integrated by
`sweep.simulate`. The grid is cut into *chunks*, one Snakemake job each, whose identity is the
SHA-256 of the canonical JSON of their content (the point values, every setting that changes a
scene's result, and a fingerprint of the physics core's source). So a chunk file is reused
exactly when its scenes would be recomputed identically, whatever the position of its points
in the axes.

Chunk layout (see docs/pipeline.md, "How reruns work"):

* A chunk never mixes values of the *outer* axes (mu_d, k1, k2, k3): adding a value to one of
  these axes, anywhere in it, adds whole new chunks and leaves every existing one untouched.
* For one outer point, the *inner* points (alpha0, omega0), in row-major order of the sorted
  axes, are cut by content-defined chunking: a chunk ends after the inner point p when
  ``H(p) % chunk_size == 0`` (H: a hash of p's values only) or when it has reached
  ``2 * chunk_size`` points. Inserting a value into alpha0 or omega0 therefore changes only the
  chunks around the new points (until the next content-defined cut), instead of shifting every
  later chunk as a positional split would.

Units: SI throughout (m, kg, s, rad, rad/s); friction coefficients are dimensionless.
"""
from __future__ import annotations

import copy
import hashlib
import itertools
import json
import math
import re
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .core.jit import kernel_sources, sources_digest

AXES = ("mu_d", "k1", "k2", "k3", "alpha0", "omega0")
OUTER_AXES = AXES[:4]
INNER_AXES = AXES[4:]
AXIS_UNITS = {"mu_d": "1", "k1": "m", "k2": "m", "k3": "m", "alpha0": "rad", "omega0": "rad s-1"}
AXIS_LONG_NAMES = {
    "mu_d": "dynamic friction coefficient",
    "k1": "rolling resistance length k1 (moment k1 |N|)",
    "k2": "pivoting resistance length k2 (moment k2 |N|)",
    "k3": "rolling resistance length k3 (moment k3 |N|)",
    "alpha0": "initial angle alpha",
    "omega0": "initial spin rate about -e3",
}

# Bump when the chunk file layout or the meaning of its variables changes: every chunk's
# identity includes it, so old chunk files are then recomputed instead of being gathered.
CHUNK_FORMAT = 2     # 2: error bars of the counts and slip_fraction (CHANGELOG.md, 2026-11-26)

# Length of the hex chunk id: 16 hex digits = 64 bits, so a collision among even 10^6 chunks
# has probability ~ n^2 / 2^65 < 3e-8.
CHUNK_ID_HEX = 16

# The config schema ships as package data (sweep/schema/config.schema.yaml, see pyproject.toml),
# so an installed (non-editable) package finds it too; the Snakemake workflow validates against
# this same file (workflow/rules/common.smk).
SCHEMA_RESOURCE = ("schema", "config.schema.yaml")


def schema_path() -> Path:
    """Filesystem path of the packaged config schema (for tools that want a path, e.g.
    snakemake.utils.validate). The package is installed as files, never zipped, so the
    importlib.resources traversable is a real path."""
    from importlib.resources import files

    return Path(str(files(__package__).joinpath(*SCHEMA_RESOURCE)))


SCHEMA_PATH = schema_path()

NOTEBOOKS = ("halt_time", "frequency_ramps", "roll_slip", "cost")


class SweepConfigError(ValueError):
    """The sweep configuration is invalid; the message names every offending key."""


# --------------------------------------------------------------------------------------------
# canonical JSON and hashing
# --------------------------------------------------------------------------------------------

def canonical_json(obj: Any) -> str:
    """Canonical JSON text: sorted keys, no whitespace, floats in Python's shortest repr.

    NaN and infinities are refused (they have no JSON form and never belong in a valid config).
    """
    return json.dumps(obj, sort_keys=True, separators=(",", ":"), allow_nan=False)


def sha256_hex(text: str) -> str:
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


# --------------------------------------------------------------------------------------------
# validation
# --------------------------------------------------------------------------------------------

def load_schema(path: str | Path | None = None) -> dict:
    """The config JSON schema (YAML file), by default the packaged sweep/schema/config.schema.yaml
    (read with importlib.resources)."""
    import yaml

    if path is None:
        from importlib.resources import files

        return yaml.safe_load(files(__package__).joinpath(*SCHEMA_RESOURCE).read_text(encoding="utf-8"))
    with open(path, encoding="utf-8") as fh:
        return yaml.safe_load(fh)


def _key(path: Iterator[Any] | list[Any]) -> str:
    out = ""
    for part in path:
        out += f"[{part}]" if isinstance(part, int) else (f".{part}" if out else str(part))
    return out or "<config>"


def _subschema(schema: dict, path: list[Any]) -> dict:
    """The schema node describing the config value at `path` (array indices -> items)."""
    node = schema
    for part in path:
        if isinstance(part, int):
            node = node.get("items", {})
        else:
            node = node.get("properties", {}).get(part, {})
    return node


def _walk(obj: Any, path: list[Any]) -> Iterator[tuple[list[Any], Any]]:
    yield path, obj
    if isinstance(obj, Mapping):
        for k, v in obj.items():
            yield from _walk(v, path + [k])
    elif isinstance(obj, list):
        for i, v in enumerate(obj):
            yield from _walk(v, path + [i])


def fill_defaults(config: Mapping, schema: dict) -> dict:
    """A deep copy of `config` with the schema's defaults filled in (same rule as
    snakemake.utils.validate: an absent property with a `default` gets it, recursively)."""
    def fill(value: Any, node: dict) -> Any:
        if isinstance(value, Mapping):
            out = dict(value)
            for name, sub in node.get("properties", {}).items():
                if name not in out and "default" in sub:
                    out[name] = copy.deepcopy(sub["default"])
                if name in out:
                    out[name] = fill(out[name], sub)
            return out
        if isinstance(value, list):
            return [fill(v, node.get("items", {})) for v in value]
        return value

    return fill(config, schema)


# `execution` (where chunks ran: cpu, or cuda on a GPU) went with the GPU path: a config that still
# has it is refused with the reason, not as an unknown key.
EXECUTION_REMOVED = ("the GPU path was removed on 2026-11-27 (it ran slower than the CPU: CHANGELOG.md); "
                     "delete the `execution` section: chunks run on CPU cores, on a cluster with "
                     "--profile workflow/profiles/slurm")


def removed_key_errors(config: Mapping) -> list[str]:
    """A one-line message naming the field where the config still has the `execution` section."""
    if "execution" not in config:
        return []
    section = config["execution"]
    if isinstance(section, Mapping) and "device" in section:
        return [f"config key `execution.device`: {section['device']!r} is no longer accepted: {EXECUTION_REMOVED}"]
    return [f"config key `execution`: no longer accepted: {EXECUTION_REMOVED}"]


def schema_errors(config: Mapping, schema: dict) -> list[str]:
    """Readable messages for every JSON-schema violation and every non-finite number."""
    import jsonschema

    messages: list[str] = removed_key_errors(config)
    config = {k: v for k, v in config.items() if k != "execution"}
    for path, value in _walk(config, []):
        if isinstance(value, float) and not math.isfinite(value):
            # an axis item has no description of its own: its axis states the allowed range
            desc = (_subschema(schema, path).get("description")
                    or (_subschema(schema, path[:-1]).get("description", "") if path and isinstance(path[-1], int)
                        else ""))
            messages.append(f"config key `{_key(path)}`: {value!r} is not a finite number"
                            + (f" ({desc})" if desc else ""))
    validator = jsonschema.Draft202012Validator(schema)
    for err in sorted(validator.iter_errors(config), key=lambda e: [str(p) for p in e.absolute_path]):
        path = list(err.absolute_path)
        value = err.instance
        if isinstance(value, float) and not math.isfinite(value):
            continue  # already reported above, with a clearer message
        if err.validator == "additionalProperties":
            node = _subschema(schema, path)
            unknown = sorted(set(value) - set(node.get("properties", {})))
            allowed = ", ".join(sorted(node.get("properties", {})))
            messages.append(f"config key `{_key(path)}`: unknown key(s) {', '.join(map(repr, unknown))}; "
                            f"allowed keys: {allowed}")
            continue
        if err.validator == "required":
            messages.append(f"config key `{_key(path)}`: {err.message}")
            continue
        node = _subschema(schema, path)
        desc = node.get("description") or _subschema(schema, path[:-1]).get("description", "")
        msg = f"config key `{_key(path)}`: {err.message}"
        if err.validator == "minItems" and not value:
            msg = f"config key `{_key(path)}`: the axis is empty; give at least one value"
        elif err.validator == "uniqueItems":
            seen, dups = set(), []
            for v in value:
                if v in seen:
                    dups.append(v)
                seen.add(v)
            msg = f"config key `{_key(path)}`: duplicate value(s) {dups}; each value may appear once"
        if isinstance(value, str) and err.validator == "type":
            try:
                float(value)
                msg += " (a number in quotes is a string: remove the quotes)"
            except ValueError:
                pass
        if desc:
            msg += f" [{desc}]"
        messages.append(msg)
    return messages


def _valid_number(x: Any) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)


def cross_field_errors(config: Mapping, invalid: set[str] = frozenset()) -> list[str]:
    """Rules JSON schema cannot express; `config` must have its defaults filled.

    `invalid`: keys (as `_key` writes them) that already failed the schema; a rule that reads
    one of them is skipped, so one bad value is reported once, not again as its consequences
    (a negative radius is not also "k1 exceeds the radius").
    """
    messages = []
    disk = config.get("disk", {})
    radius = disk.get("radius")
    if _valid_number(radius) and radius > 0 and "disk.radius" not in invalid:
        if _valid_number(disk.get("thickness", 0)) and disk.get("thickness", 0) > 4 * radius:
            messages.append(f"config key `disk.thickness`: {disk['thickness']!r} exceeds 4*radius = "
                            f"{4 * radius!r} m; allowed (0, 4*radius]")
        for k in ("k1", "k2", "k3"):
            for i, v in enumerate(config.get("grid", {}).get(k, [])):
                if isinstance(v, (int, float)) and v > radius:
                    messages.append(f"config key `grid.{k}[{i}]`: {v!r} m exceeds the disk radius "
                                    f"{radius!r} m; allowed [0, radius]")
    mu_s = config.get("mu_s")
    grid = config.get("grid", {})
    if _valid_number(mu_s) and mu_s > 0 and "mu_s" not in invalid:
        for i, mu_d in enumerate(grid.get("mu_d", [])):
            if isinstance(mu_d, (int, float)) and mu_d > mu_s:
                messages.append(f"config key `grid.mu_d[{i}]`: {mu_d!r} exceeds mu_s = {mu_s!r}; "
                                "allowed [0, mu_s] (with mu_d > mu_s the slip onset is inconsistent)")
    for i, a in enumerate(grid.get("alpha0", [])):
        if isinstance(a, (int, float)) and a == 0:
            messages.append(f"config key `grid.alpha0[{i}]`: 0 is not allowed; allowed (-pi/2, 0) or "
                            "(0, pi/2) (alpha = 0 is the degenerate line-contact state of the model)")
    solver = config.get("solver", {})
    if solver.get("method") == "fixed" and "dt" not in solver:
        messages.append("config key `solver.dt`: required when solver.method is 'fixed'; "
                        "allowed (0, 1] s")
    return messages


def check_config(config: Mapping, schema: dict | None = None) -> dict:
    """Validate a sweep config and return it with defaults filled.

    Raises SweepConfigError listing every problem (key, value, allowed range) before any work.
    """
    schema = schema if schema is not None else load_schema()
    config = copy.deepcopy(dict(config))
    coerce_numbers(config, schema)
    messages = schema_errors(config, schema)
    # keys named by the schema's messages: cross-field rules reading them are skipped
    invalid = set(re.findall(r"^config key `([^`]+)`", "\n".join(messages), flags=re.M))
    try:  # report cross-field problems together with the schema's, where the types allow it
        messages += [m for m in cross_field_errors(fill_defaults(config, schema), invalid)
                     if m not in messages and not any(f"`{k}`" in m for k in invalid)]
    except (TypeError, AttributeError):
        pass  # a mistyped section: the schema errors above already say which
    if messages:
        raise SweepConfigError("invalid sweep configuration:\n  " + "\n  ".join(messages))
    return fill_defaults(config, schema)


def coerce_numbers(config: Any, schema: dict) -> list[str]:
    """In place: numbers written like `1e-10` (a string to YAML 1.1, which Snakemake's config
    loader follows) become floats wherever the schema expects a number. Returns the keys."""
    from .yamlio import coerce_numbers as _coerce

    def wants_number(path: list) -> bool:
        return _subschema(schema, path).get("type") in ("number", "integer")

    return [_key(p) for p in _coerce(config, wants_number)]


# --------------------------------------------------------------------------------------------
# results per sweep
# --------------------------------------------------------------------------------------------

DEFAULT_CONFIG = "config/config.yaml"
NAME_PATTERN = r"^[A-Za-z0-9][A-Za-z0-9._-]{0,63}$"


def sweep_name(configfile: str | Path) -> str:
    """The name of a sweep, hence its results folder `results/<name>/`: the `name:` set in its
    config file, else the file's stem (`config/my_sweep.yaml` -> `my_sweep`).

    Only the file itself counts, not config/config.yaml merged under it, so that a config file
    without `name:` never writes into the default sweep's folder.
    """
    from .yamlio import load

    path = Path(configfile)
    try:
        data = load(path.read_text(encoding="utf-8")) or {}
    except (OSError, yaml_error()) as exc:
        raise SweepConfigError(f"config file {str(path)!r} cannot be read: {exc}") from None
    name = data.get("name", path.stem) if isinstance(data, Mapping) else path.stem
    if not isinstance(name, str) or not re.match(NAME_PATTERN, name):
        raise SweepConfigError(f"config key `name` in {str(path)!r}: {name!r} is invalid; allowed 1-64 "
                               "characters of letters, digits, '.', '_', '-', not starting with '.', '_' or '-'")
    return name


def yaml_error() -> type[Exception]:
    import yaml

    return yaml.YAMLError


# --------------------------------------------------------------------------------------------
# normalisation
# --------------------------------------------------------------------------------------------

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
        "grid": {a: sorted(float(v) for v in cfg["grid"][a]) for a in AXES},
        "levels": sorted((float(v) for v in cfg["levels"]), reverse=True),
        "solver": solver,
        "stop": {"t_max": float(cfg["stop"]["t_max"]), "max_steps": int(cfg["stop"]["max_steps"])},
        "chunk_size": int(cfg["chunk_size"]),
        "outputs": {"notebooks": list(cfg["outputs"]["notebooks"]),
                    "error_estimate": bool(cfg["outputs"]["error_estimate"])},
    }
    if check_scenes:
        check_scenes_valid(settings)
    return settings


# scene-file field (sweep.scene) -> sweep config key, to name the key the user wrote
_SCENE_FIELD_TO_KEY = {
    "contact.mu_d": "grid.mu_d", "contact.k1": "grid.k1", "contact.k2": "grid.k2",
    "contact.k3": "grid.k3", "initial.alpha": "grid.alpha0", "initial.omega": "grid.omega0",
    "initial.omega[2]": "grid.omega0", "contact.mu_s": "mu_s", "stop.levels": "levels",
}


def check_scenes_valid(settings: Mapping) -> None:
    """Validate representative scenes with the physics core's own checks (sweep.scene).

    Every value of every axis is tried once (with the first value of the other axes), so each
    single-value rule of the core (e.g. k_i <= radius, levels below the largest inclination for
    which the disk's steady motion exists) is checked for every configured value, in
    sum(len(axis)) scene validations (~ms each) instead of one per grid point.
    """
    from . import scene as _scene
    from .errors import ConfigError

    first = {a: settings["grid"][a][0] for a in AXES}
    messages = []
    for a in AXES:
        for v in settings["grid"][a]:
            point = dict(first, **{a: v})
            try:
                _scene.load_scene(scene(settings, point))
            except ConfigError as err:
                key = _SCENE_FIELD_TO_KEY.get(err.field, err.field)
                if key.startswith("stop.levels["):
                    key = "levels"
                msg = f"config key `{key}`: {err.value!r} is invalid; allowed {err.allowed}"
                if msg not in messages:
                    messages.append(msg)
            except (ArithmeticError, ValueError) as err:
                # Values inside every documented range can still be numerically degenerate for
                # the core's set-up (e.g. a subnormal radius: chi^2 = R/g underflows to 0). Stop
                # here with a message rather than a traceback at parse time or a failed job; the
                # disk and gravity are shared by every scene, so one message says it.
                if not any(m.startswith("config keys `disk`, `gravity`") for m in messages):
                    messages.append(
                        f"config keys `disk`, `gravity`: the physics core cannot set up the scene at "
                        f"{point} ({type(err).__name__}: {err}) with disk {settings['disk']} and "
                        f"gravity {settings['gravity']!r}; allowed: values in the documented ranges "
                        "that are not numerically degenerate (e.g. not a subnormal radius)")
    if messages:
        raise SweepConfigError("invalid sweep configuration (physics-core checks):\n  "
                               + "\n  ".join(messages))


def scene_settings(settings: Mapping) -> dict:
    """The part of a normalised config that, with the point values, fixes a chunk's content.

    `error_estimate: true` (outputs.error_estimate: each scene is rerun at tighter tolerances and
    the chunk holds the differences) is part of it; it is left out when false, so switching the
    option off reuses the chunks computed without it.
    """
    part = {k: copy.deepcopy(settings[k]) for k in ("disk", "gravity", "mu_s", "levels", "solver", "stop")}
    if settings.get("outputs", {}).get("error_estimate", False):
        part["error_estimate"] = True
    return part


# outputs.error_estimate: every scene is rerun with rtol and atol divided by this factor (not below
# the smallest tolerances the core accepts) and the step budget multiplied by ERROR_STEPS_FACTOR
# (DOP853 is 8th order: 100x tighter tolerances cost ~100^(1/8) = 1.8x the steps).
ERROR_TOL_FACTOR = 100.0
ERROR_RTOL_MIN = 1.0e-14
ERROR_ATOL_MIN = 1.0e-16
ERROR_STEPS_FACTOR = 2


def error_reference(settings_part: Mapping) -> dict:
    """The scene settings (as `scene_settings` returns them) of the rerun behind the error bars:
    rtol/100 (>= 1e-14), atol/100 (>= 1e-16), twice the step budget (<= 1e9); the rest alike."""
    ref = copy.deepcopy(dict(settings_part))
    so, stop = dict(ref["solver"]), dict(ref["stop"])
    so["rtol"] = max(float(so["rtol"]) / ERROR_TOL_FACTOR, ERROR_RTOL_MIN)
    so["atol"] = max(float(so["atol"]) / ERROR_TOL_FACTOR, ERROR_ATOL_MIN)
    stop["max_steps"] = min(int(stop["max_steps"]) * ERROR_STEPS_FACTOR, 1_000_000_000)
    ref["solver"], ref["stop"] = so, stop
    return ref


def grid_shape(settings: Mapping) -> tuple[int, ...]:
    return tuple(len(settings["grid"][a]) for a in AXES)


def scene(settings: Mapping, point: Mapping[str, float] | tuple[float, ...]) -> dict:
    """The `sweep.simulate` scene dict (SI units) of one grid point.

    The start is rolling: omega = [0, 0, -omega0] rad/s, slip = [0, 0] m/s, theta = psi = 0.
    """
    p = dict(zip(AXES, point)) if not isinstance(point, Mapping) else dict(point)
    return {
        "disk": dict(settings["disk"]),
        "contact": {"mu_s": settings["mu_s"], "mu_d": p["mu_d"],
                    "k1": p["k1"], "k2": p["k2"], "k3": p["k3"]},
        "gravity": settings["gravity"],
        "initial": {"alpha": p["alpha0"], "omega": [0.0, 0.0, -p["omega0"]],
                    "slip": [0.0, 0.0], "theta": 0.0, "psi": 0.0},
        "stop": {"levels": list(settings["levels"]), "t_max": settings["stop"]["t_max"],
                 "max_steps": settings["stop"]["max_steps"]},
        "solver": dict(settings["solver"]),
    }


# --------------------------------------------------------------------------------------------
# chunking
# --------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class Chunk:
    """One job's worth of scenes. `points` are tuples in AXES order (SI units)."""
    id: str
    points: tuple[tuple[float, ...], ...]
    spec_json: str    # canonical JSON of {format, settings, axes, points}: hashed into `id`

    @property
    def spec(self) -> dict:
        return json.loads(self.spec_json)


def _inner_hash(inner: tuple[float, ...]) -> int:
    return int(sha256_hex(canonical_json(list(inner)))[:16], 16)


def split_inner(inner_points: list[tuple[float, ...]], chunk_size: int) -> list[list[tuple[float, ...]]]:
    """Content-defined cut of a sequence of inner points into blocks of 1..2*chunk_size.

    A block ends after p if hash(p) % chunk_size == 0 (expected block length chunk_size) or
    when it holds 2*chunk_size points (the cap bounds a job's size; the layout resynchronises
    at the next content-defined cut, so an insertion changes only nearby blocks).
    """
    blocks: list[list[tuple[float, ...]]] = []
    cur: list[tuple[float, ...]] = []
    for p in inner_points:
        cur.append(p)
        if _inner_hash(p) % chunk_size == 0 or len(cur) >= 2 * chunk_size:
            blocks.append(cur)
            cur = []
    if cur:
        blocks.append(cur)
    return blocks


# What decides a scene's result: the physics core package and the modules that turn a scene file
# into kernel inputs and a summary. Front ends, plots and the pipeline's own modules are not in it
# (chunk files carry CHUNK_FORMAT for those), so editing them does not recompute chunks.
# the modules besides the kernels (core.jit.kernel_sources) whose change gives every chunk a new
# identity: they turn a scene into the kernel's inputs and its outputs into the summary
CHUNK_MODULES = ("scene.py", "simulate.py", "diagnostics.py")


def core_fingerprint() -> str:
    """SHA-256 (core.jit.sources_digest) of the sources a chunk's numbers come from: the kernels'
    and CHUNK_MODULES, so that a change of any gives every chunk a new identity."""
    pkg = Path(__file__).resolve().parent
    return sources_digest(kernel_sources(pkg) + tuple(pkg / m for m in CHUNK_MODULES), root=pkg)


def chunk_id_of(settings_part: Mapping, points: list[tuple[float, ...]],
                core: str | None = None) -> tuple[str, str]:
    """(id, canonical spec JSON) of a chunk; `core` defaults to core_fingerprint()."""
    spec = {"format": CHUNK_FORMAT, "core": core if core is not None else core_fingerprint(),
            "settings": settings_part, "axes": list(AXES), "points": [list(p) for p in points]}
    text = canonical_json(spec)
    return sha256_hex(text)[:CHUNK_ID_HEX], text


def plan_chunks(settings: Mapping) -> dict[str, Chunk]:
    """All chunks of a normalised config, keyed by id, in grid order."""
    part = scene_settings(settings)
    core = core_fingerprint()
    g = settings["grid"]
    inner = list(itertools.product(*(g[a] for a in INNER_AXES)))
    blocks = split_inner(inner, settings["chunk_size"])
    chunks: dict[str, Chunk] = {}
    for outer in itertools.product(*(g[a] for a in OUTER_AXES)):
        for block in blocks:
            points = [tuple(outer) + tuple(p) for p in block]
            cid, text = chunk_id_of(part, points, core)
            chunks[cid] = Chunk(cid, tuple(points), text)
    return chunks


def grid_index(settings: Mapping) -> dict[str, dict[float, int]]:
    """Per axis: value -> position in the (sorted) cube axis."""
    return {a: {v: i for i, v in enumerate(settings["grid"][a])} for a in AXES}
