"""Sweep configuration: validation, normalisation and the split of the grid into chunks.

A sweep is the Cartesian product of the axes of the registry of inputs (sweep.fields; `AXES`
here), every point one scene integrated by
`sweep.simulate`. The grid is cut into *chunks*, one Snakemake job each, whose identity is the
SHA-256 of the canonical JSON of their content (the point values, every setting that changes a
scene's result, and a fingerprint of the physics core's source). So a chunk file is reused
exactly when its scenes would be recomputed identically, whatever the position of its points
in the axes.

Chunk layout (see docs/pipeline.md, "How reruns work"):

* A chunk never mixes values of the *outer* axes (mu_d, k1, k2, k3; `OUTER_AXES`): adding a value to one of
  these axes, anywhere in it, adds whole new chunks and leaves every existing one untouched.
* For one outer point, the *inner* points (alpha0, omega0; `INNER_AXES`), in row-major order of the sorted
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
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .core.jit import kernel_sources, sources_digest
from . import fields
from . import outputs as _outputs
from .errors import MISSING, ConfigError, quoted_number

# the axes, their order, chunk layout, units and long names: the registry of inputs (sweep.fields)
AXES = tuple(a.name for a in fields.AXES)
OUTER_AXES = tuple(a.name for a in fields.AXES if a.outer)
INNER_AXES = tuple(a.name for a in fields.AXES if not a.outer)
AXIS_UNITS = {a.name: a.units for a in fields.AXES}
AXIS_LONG_NAMES = {a.name: a.long_name for a in fields.AXES}
# the values of an axis a config may leave out
AXIS_DEFAULTS = {a.name: list(a.default) for a in fields.AXES if a.default is not None}


# Length of the hex chunk id: 16 hex digits = 64 bits, so a collision among even 10^6 chunks
# has probability ~ n^2 / 2^65 < 3e-8.
CHUNK_ID_HEX = 16

# The config schema ships as package data: its template (sweep/schema/config.template.yaml, see
# pyproject.toml), from which load_schema builds it with the registry of inputs (sweep.fields), and
# the schema so built (config.schema.yaml, written by write_schema, checked against the build by
# tests/test_grid.py) for tools that want a file, e.g. snakemake.utils.validate. The front door and
# the Snakemake workflow validate with load_schema (load_sweep, called by sweep.frontdoor and
# workflow/rules/common.smk).
SCHEMA_TEMPLATE = ("schema", "config.template.yaml")
SCHEMA_RESOURCE = ("schema", "config.schema.yaml")
SCHEMA_HEADER = ("# The sweep config's JSON schema, generated from config.template.yaml and the registry of\n"
                 "# inputs (sweep.fields): do not edit. Regenerate: .venv/bin/python -c 'from sweep import grid; "
                 "grid.write_schema()'\n")


def schema_path() -> Path:
    """Filesystem path of the packaged config schema (for tools that want a path, e.g.
    snakemake.utils.validate). The package is installed as files, never zipped, so the
    importlib.resources traversable is a real path."""
    from importlib.resources import files

    return Path(str(files(__package__).joinpath(*SCHEMA_RESOURCE)))


SCHEMA_PATH = schema_path()

NOTEBOOKS = ("halt_time", "frequency_ramps", "roll_slip", "cost")
# the notebooks of an adaptive map (a refine: section) only
ADAPTIVE_NOTEBOOKS = ("adaptive_map",)


class SweepConfigError(ValueError):
    """The sweep configuration is invalid: `errors`, one ConfigError per invalid field (key,
    value, allowed range; `source`, the file, where known). str(): one line per field."""

    def __init__(self, errors: Sequence[ConfigError]):
        self.errors = list(errors)
        super().__init__("\n".join(e.line() for e in self.errors))


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
    """The config JSON schema: by default built from the packaged template
    (sweep/schema/config.template.yaml, read with importlib.resources) and the registry of inputs
    (fields.config_schema); else the schema file at `path`, its registry markers filled in."""
    import yaml

    if path is None:
        from importlib.resources import files

        text = files(__package__).joinpath(*SCHEMA_TEMPLATE).read_text(encoding="utf-8")
    else:
        text = Path(path).read_text(encoding="utf-8")
    return fields.config_schema(yaml.safe_load(text))


def write_schema(path: str | Path | None = None) -> Path:
    """Write the schema load_schema builds to `path` (default: the packaged config.schema.yaml)."""
    import yaml

    path = Path(path) if path is not None else SCHEMA_PATH
    text = SCHEMA_HEADER + yaml.safe_dump(load_schema(), sort_keys=False, allow_unicode=True, width=120)
    path.write_text(text, encoding="utf-8")
    return path


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


# `execution` (where chunks ran: cpu, or cuda on a GPU) is refused with the reason, not as an unknown key.
EXECUTION_REMOVED = ("the GPU path was removed (it ran slower than the CPU: CHANGELOG.md); "
                     "delete the `execution` section: chunks run on CPU cores, on a cluster with "
                     "--profile workflow/profiles/slurm")


def removed_key_errors(config: Mapping) -> list[ConfigError]:
    """One error naming the field where the config still has the `execution` section."""
    if "execution" not in config:
        return []
    section = config["execution"]
    if isinstance(section, Mapping) and "device" in section:
        return [ConfigError("execution.device", section["device"], "no `execution` section: " + EXECUTION_REMOVED,
                            problem="no longer accepted")]
    return [ConfigError("execution", section, "no `execution` section: " + EXECUTION_REMOVED,
                        problem="no longer accepted")]


def schema_errors(config: Mapping, schema: dict) -> list[ConfigError]:
    """Every JSON-schema violation and every non-finite number, one ConfigError per field (the
    field, the value, what is allowed there: the schema's description)."""
    import jsonschema

    errors: dict[str, ConfigError] = {}

    def add(err: ConfigError) -> None:
        errors.setdefault(err.field, err)   # one message per field: the first problem found

    for err in removed_key_errors(config):
        add(err)
    config = {k: v for k, v in config.items() if k != "execution"}
    for path, value in _walk(config, []):
        if isinstance(value, float) and not math.isfinite(value):
            add(ConfigError(_key(path), value, _allowed(schema, path), problem="not a finite number"))
    validator = jsonschema.Draft202012Validator(schema)
    for err in sorted(validator.iter_errors(config), key=lambda e: [str(p) for p in e.absolute_path]):
        path = list(err.absolute_path)
        value = err.instance
        node = _subschema(schema, path)
        if isinstance(value, float) and not math.isfinite(value):
            continue  # already reported above
        if err.validator == "additionalProperties":
            known = sorted(node.get("properties", {}))
            for k in sorted(set(value) - set(known), key=str):
                add(ConfigError(_key(path + [k]), value[k], f"keys: {', '.join(known)}", problem="no such key"))
        elif err.validator == "required":
            for k in node.get("required", []):
                if isinstance(value, Mapping) and k not in value:
                    add(ConfigError(_key(path + [k]), MISSING, _allowed(schema, path + [k])))
        elif err.validator == "type" and err.validator_value == "object":
            add(ConfigError(_key(path), value, "a mapping of the keys " + ", ".join(sorted(node.get("properties", {}))),
                            problem="not a mapping"))
        elif err.validator == "type" and err.validator_value == "array":
            add(ConfigError(_key(path), value, "a list: " + _allowed(schema, path), problem="not a list"))
        elif err.validator == "type":
            kind = {"integer": "an integer", "number": "a number", "string": "text",
                    "boolean": "true or false"}.get(err.validator_value, err.validator_value)
            add(ConfigError(_key(path), value, _allowed(schema, path),
                            problem=None if quoted_number(value) else f"not {kind}"))
        elif err.validator == "minItems" and not value:
            add(ConfigError(_key(path), value, "at least one value: " + _allowed(schema, path),
                            problem="the list is empty"))
        elif err.validator == "uniqueItems":
            seen, dups = [], []
            for v in value:
                (dups if v in seen else seen).append(v)
            add(ConfigError(_key(path), value, "each value once: " + _allowed(schema, path),
                            problem=f"duplicate value(s) {dups}"))
        else:   # out of range, not one of the choices, not matching the pattern
            add(ConfigError(_key(path), value, _allowed(schema, path)))
    return list(errors.values())


def _allowed(schema: dict, path: list[Any]) -> str:
    """What the schema allows at `path`: its description's 'allowed ...' part, then the rest of
    it in parentheses (an axis item: its axis's description)."""
    desc = _subschema(schema, path).get("description")
    if not desc and path and isinstance(path[-1], int):
        desc = _subschema(schema, path[:-1]).get("description")
    parts = re.split(r";\s*allowed:?\s+", desc or "", maxsplit=1)
    return f"{parts[1]} ({parts[0]})" if len(parts) == 2 else (desc or "see docs/pipeline.md")


def _valid_number(x: Any) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)


def _number(x: Any) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool)


def config_value(config: Mapping, key: str):
    """The value at a dotted key of a config mapping (`disk.radius`), None where it is absent."""
    node = config
    for part in key.split("."):
        if not isinstance(node, Mapping) or part not in node:
            return None
        node = node[part]
    return node


def cross_field_errors(config: Mapping, invalid: set[str] = frozenset()) -> list[ConfigError]:
    """Rules JSON schema cannot express; `config` must have its defaults filled: the relative
    bounds and excluded values of sweep.fields.RANGES (mu_d <= mu_s, k_i <= radius, thickness <=
    4 radius, alpha0 != 0), and dt for the fixed step.

    `invalid`: fields that already failed the schema; a rule that reads one of them is skipped,
    so one bad value is reported once, not again as its consequences (a negative radius is not
    also "k1 exceeds the radius").
    """
    errors = []

    def value_of(key: str):
        return config_value(config, key)

    for key, field in fields.SWEEP_KEYS.items():
        rng = fields.RANGES[field]
        if rng.relative is None and rng.excluded is None:
            continue
        value = value_of(key)
        items = list(enumerate(value)) if isinstance(value, list) else [(None, value)]
        other_key = fields.SWEEP_KEY_OF.get(rng.relative.field) if rng.relative else None
        other = value_of(other_key) if other_key else None
        other_ok = _valid_number(other) and other >= 0 and other_key not in invalid
        for i, v in items:
            name = key if i is None else f"{key}[{i}]"
            if not _number(v) or name in invalid:
                continue
            if other_ok:
                err = rng.relative_error(name, v, other)
                if err is not None:
                    errors.append(err)
                    continue
            if rng.excluded is not None and v == rng.excluded:
                errors.append(ConfigError(name, v, rng.allowed(), problem=rng.problem(v)))
    errors += refine_errors(config, invalid)
    solver = config.get("solver", {})
    if solver.get("method") == "fixed" and "dt" not in solver:
        errors.append(ConfigError("solver.dt", MISSING, fields.RANGES["solver.dt"].allowed(),
                                  problem="required when solver.method is 'fixed'"))
    return errors


def refine_errors(config: Mapping, invalid: set[str] = frozenset()) -> list[ConfigError]:
    """The checks of an adaptive map (`refine:`) and of the axes JSON schema cannot express: every
    axis under `grid` or `refine.axes`, not both; a lattice axis' `from` < `to`, both inside the
    axis' range (fields.RANGES, relative bounds included), `from` > 0 for log spacing; at least
    one refinement round (start_points below the smallest axis' points); round 0 within the
    budget; the adaptive_map notebook only with refine."""
    from . import refine as _refine

    errors: list[ConfigError] = []
    grid_cfg = config.get("grid") if isinstance(config.get("grid"), Mapping) else {}
    ref = config.get("refine")
    axes = ref.get("axes") if isinstance(ref, Mapping) and isinstance(ref.get("axes"), Mapping) else {}
    for a in AXES:
        key = f"grid.{a}"
        if a in axes and a in grid_cfg:
            errors.append(ConfigError(f"refine.axes.{a}", axes[a], f"each axis once: under grid or refine.axes",
                                      problem=f"{a} is also listed under {key}"))
        elif a not in axes and a not in grid_cfg and a not in AXIS_DEFAULTS and "grid" not in invalid:
            errors.append(ConfigError(key, MISSING, "a list of values: " + fields.RANGES[fields.SWEEP_KEYS[key]].allowed()
                                      + (", or an axis of refine.axes" if ref is not None else "")))
    notebooks = config.get("outputs", {}).get("notebooks", []) if isinstance(config.get("outputs"), Mapping) else []
    if ref is None:
        if isinstance(notebooks, list) and "adaptive_map" in notebooks:
            i = notebooks.index("adaptive_map")
            errors.append(ConfigError(f"outputs.notebooks[{i}]", "adaptive_map",
                                      "halt_time, frequency_ramps, roll_slip, cost (adaptive_map needs a refine: section)",
                                      problem="adaptive_map draws an adaptive map and this config has no refine:"))
        return errors
    if not isinstance(ref, Mapping) or any(k.startswith("refine") for k in invalid):
        return errors

    def value_of(key: str):
        return config_value(config, key)

    ok_axes = {}
    for a, spec in axes.items():
        if not isinstance(spec, Mapping):
            continue
        field_name = fields.SWEEP_KEYS[f"grid.{a}"]
        rng = fields.RANGES[field_name]
        lo, hi = spec.get("from"), spec.get("to")
        bad = False
        for end, v in (("from", lo), ("to", hi)):
            name = f"refine.axes.{a}.{end}"
            if not _number(v) or name in invalid:
                bad = True
                continue
            problem = rng.problem(v)
            if problem is not None:
                errors.append(ConfigError(name, v, rng.allowed(), problem=problem or None))
                bad = True
                continue
            other_key = fields.SWEEP_KEY_OF.get(rng.relative.field) if rng.relative else None
            other = value_of(other_key) if other_key else None
            if other_key and _valid_number(other) and other >= 0 and other_key not in invalid:
                err = rng.relative_error(name, v, other)
                if err is not None:
                    errors.append(err)
                    bad = True
        if bad:
            continue
        if not lo < hi:
            errors.append(ConfigError(f"refine.axes.{a}.to", hi, f"a value above from = {lo!r}",
                                      problem="the axis must run from a lower to a higher value"))
            continue
        if spec.get("spacing", "linear") == "log" and lo <= 0:
            errors.append(ConfigError(f"refine.axes.{a}.from", lo, "> 0 with spacing: log",
                                      problem="a log-spaced axis needs positive values"))
            continue
        if rng.excluded is not None and lo < rng.excluded < hi and spec.get("spacing", "linear") == "linear":
            pts = spec.get("points")
            if isinstance(pts, int) and _refine.is_lattice_size(pts) and rng.excluded in set(
                    _refine.axis_values(float(lo), float(hi), pts).tolist()):
                errors.append(ConfigError(f"refine.axes.{a}", dict(spec), rng.allowed(),
                                          problem=f"a lattice point falls on the excluded value {rng.excluded!r}"))
                continue
        ok_axes[a] = spec
    if len(ok_axes) != len(axes) or not (2 <= len(axes) <= 3):
        return errors
    points = [spec.get("points") for spec in axes.values()]
    start = ref.get("start_points", 9)
    if not all(isinstance(p, int) and _refine.is_lattice_size(p) for p in points) or not isinstance(start, int):
        return errors
    smallest = min(points)
    if not start < smallest:
        errors.append(ConfigError("refine.start_points", start,
                                  f"2^l + 1 below the smallest axis' points ({smallest}): at most {(smallest - 1) // 2 + 1}",
                                  problem="leaves no round to refine in"))
        return errors
    share = ref.get("max_share", 0.25)
    if _valid_number(share) and 0 < share <= 1:
        lat = _refine.make_lattice(axes, start)
        n0 = len(lat.round0_nodes())
        budget = math.floor(share * lat.size)
        if n0 > budget:
            errors.append(ConfigError("refine.max_share", share,
                                      f"at least {n0} / {lat.size} = {n0 / lat.size:.4g} (round 0's {n0} nodes), "
                                      "or fewer start_points",
                                      problem=f"the budget, {budget} scenes, is below round 0's {n0}"))
    return errors


def check_config(config: Mapping, schema: dict | None = None) -> dict:
    """Validate a sweep config and return it with defaults filled.

    Raises SweepConfigError listing every problem (one ConfigError per field: key, value,
    allowed range) before any work. Numbers are what the YAML reader made of them: text (a
    number in quotes) where a number is expected is an error (read files with `read_config`).
    """
    schema = schema if schema is not None else load_schema()
    config = copy.deepcopy(dict(config))
    errors = schema_errors(config, schema)
    invalid = {e.field for e in errors}
    try:  # report cross-field problems together with the schema's, where the types allow it
        errors += [e for e in cross_field_errors(fill_defaults(config, schema), invalid) if e.field not in invalid]
    except (TypeError, AttributeError):
        pass  # a mistyped section: the schema errors above already say which
    if errors:
        raise SweepConfigError(errors)
    return fill_defaults(config, schema)


# --------------------------------------------------------------------------------------------
# config files: read, merged as Snakemake merges them, every key's file remembered
# --------------------------------------------------------------------------------------------

DEFAULT_CONFIG = "config/config.yaml"
NAME_PATTERN = r"^[A-Za-z0-9][A-Za-z0-9._-]{0,63}$"
NAME_ALLOWED = ("1-64 characters of letters, digits, '.', '_', '-', not starting with '.', '_' or '-' "
                "(the results folder results/<name>/)")
CONFIG_FILE = "a YAML mapping of sweep config keys (grid, levels, solver, ...: docs/pipeline.md)"


@dataclass
class ConfigSource:
    """The sweep config as read from its files: `config` (merged), and for every key path the
    file (as the user named it) that set it last, so that a message can name the file."""
    config: dict
    origins: dict[str, str]
    last: str                 # the file given last (its name: is the sweep's name)

    def source_of(self, field: str) -> str:
        """The file that set `field` (or the nearest enclosing key), else the last file."""
        key = field
        while key:
            if key in self.origins:
                return self.origins[key]
            m = re.match(r"^(.*?)(\.[^.\[\]]+|\[\d+\])$", key)
            key = m.group(1) if m else ""
        return self.last

    def name_errors(self, err: SweepConfigError) -> SweepConfigError:
        for e in err.errors:
            e.with_source(self.source_of(e.field))
        return SweepConfigError(err.errors)


def _merge_into(base: dict, new: Mapping, label: str, origins: dict[str, str], path: list[Any]) -> None:
    """Snakemake's update_config: nested mappings merge key by key, anything else replaces; every
    key path set (leaves and the mappings holding them) is recorded in `origins` as `label`'s."""
    for k, v in new.items():
        sub = path + [k]
        origins[_key(sub)] = label
        if isinstance(v, Mapping) and isinstance(base.get(k), dict):
            _merge_into(base[k], v, label, origins, sub)
            continue
        head = _key(sub)
        for key in [o for o in origins if o.startswith(head + ".") or o.startswith(head + "[")]:
            del origins[key]
        base[k] = copy.deepcopy(dict(v) if isinstance(v, Mapping) else v)
        for sub_path, _ in _walk(v, sub):
            if isinstance(sub_path[-1], str):
                origins[_key(sub_path)] = label


def _later_axis_wins(merged: dict, data: Mapping, origins: dict[str, str]) -> None:
    """An axis is a grid list or a lattice of refine.axes: where a file sets it one way, the way an
    earlier file set it is dropped (an adaptive overlay over config/config.yaml's grid, or a grid
    list over an earlier refine:). Both in the same file stays an error (refine_errors)."""
    new_ref = data.get("refine", {}).get("axes", {}) if isinstance(data.get("refine"), Mapping) else {}
    new_grid = data.get("grid", {}) if isinstance(data.get("grid"), Mapping) else {}
    grid_ = merged.get("grid") if isinstance(merged.get("grid"), dict) else {}
    ref = merged.get("refine") if isinstance(merged.get("refine"), dict) else {}
    axes = ref.get("axes") if isinstance(ref.get("axes"), dict) else {}
    for a in list(new_ref) if isinstance(new_ref, Mapping) else []:
        if a in grid_ and a not in new_grid:
            del grid_[a]
            for key in [o for o in origins if o == f"grid.{a}" or o.startswith(f"grid.{a}[")]:
                del origins[key]
    for a in list(new_grid):
        if a in axes and a not in (new_ref if isinstance(new_ref, Mapping) else {}):
            del axes[a]
            for key in [o for o in origins if o.startswith(f"refine.axes.{a}")]:
                del origins[key]
    if ref and not axes and "axes" in ref:
        del merged["refine"]


def read_config(files: Sequence[tuple[str | Path, str]], overrides: Mapping | None = None) -> ConfigSource:
    """Read sweep config files, in order, each given as (path, the name to show for it), and merge
    them as Snakemake does (a later file's keys over an earlier's; nested mappings key by key),
    then `overrides` (Snakemake's --config, shown as '--config'). Numbers are read as YAML 1.2
    reads them (`sweep.yamlio`: 1e-10 is a number, '1e-10' in quotes is text), the same rule as
    scene files. A file that is missing, empty, not YAML or not a mapping raises SweepConfigError
    naming it."""
    from .yamlio import load_file

    merged: dict = {}
    origins: dict[str, str] = {}
    last = ""
    for path, label in files:
        try:
            data = load_file(path, CONFIG_FILE)
        except ConfigError as err:
            raise SweepConfigError([err.with_source(label)]) from None
        _merge_into(merged, data, label, origins, [])
        _later_axis_wins(merged, data, origins)
        last = label
    if overrides:
        _merge_into(merged, overrides, "--config", origins, [])
    return ConfigSource(merged, origins, last)


def sweep_name(configfile: str | Path, label: str | None = None) -> str:
    """The name of a sweep, hence its results folder `results/<name>/`: the `name:` set in its
    config file, else the file's stem (`config/my_sweep.yaml` -> `my_sweep`).

    Only the file itself counts, not config/config.yaml merged under it, so that a config file
    without `name:` never writes into the default sweep's folder. SweepConfigError (naming the
    file as `label`, default the path) if the file cannot be read or the name is invalid.
    """
    from .yamlio import load_file

    path = Path(configfile)
    label = label or str(configfile)
    try:
        data = load_file(path, CONFIG_FILE)
    except ConfigError as err:
        raise SweepConfigError([err.with_source(label)]) from None
    name = data.get("name", path.stem)
    if not isinstance(name, str) or not re.match(NAME_PATTERN, name):
        where = "name" if "name" in data else "name (the file's stem, no name: given)"
        raise SweepConfigError([ConfigError(where, name, NAME_ALLOWED, source=label)])
    return name


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
    """The values of a lattice axis of refine.axes (sweep.refine.axis_values)."""
    from . import refine as _refine

    return [float(v) for v in _refine.axis_values(float(spec["from"]), float(spec["to"]), int(spec["points"]),
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
CHUNK_MODULES = ("fields.py", "scene.py", "simulate.py", "diagnostics.py")


def core_fingerprint() -> str:
    """SHA-256 (core.jit.sources_digest) of the sources a chunk's numbers come from: the kernels'
    and CHUNK_MODULES, so that a change of any gives every chunk a new identity."""
    pkg = Path(__file__).resolve().parent
    return sources_digest(kernel_sources(pkg) + tuple(pkg / m for m in CHUNK_MODULES), root=pkg)


def chunk_id_of(settings_part: Mapping, points: list[tuple[float, ...]],
                core: str | None = None) -> tuple[str, str]:
    """(id, canonical spec JSON) of a chunk; `core` defaults to core_fingerprint()."""
    spec = {"format": _outputs.CHUNK_FORMAT, "core": core if core is not None else core_fingerprint(),
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
