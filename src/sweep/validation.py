"""Validation of a sweep config: the JSON schema (built from its packaged template and the registry
of inputs, sweep.fields), every violation one ConfigError naming the field, its value and what is
allowed there (`schema_errors`), and the rules a schema cannot express (`cross_field_errors`: relative
bounds such as mu_d <= mu_s, excluded values, an adaptive map's lattice). `check_config` raises
SweepConfigError with all of them before any work. Units: SI throughout.
"""
from __future__ import annotations

import copy
import math
import re
from collections.abc import Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any

from . import fields
from .axes import AXES, AXIS_DEFAULTS
from .errors import MISSING, ConfigError, quoted_number


# The config schema ships as package data: its template (sweep/schema/config.template.yaml, see
# pyproject.toml), from which load_schema builds it with the registry of inputs (sweep.fields), and
# the schema so built (config.schema.yaml, written by write_schema, checked against the build by
# tests/test_grid.py) for tools that want a file, e.g. snakemake.utils.validate. The front door and
# the Snakemake workflow validate with load_schema (sweep.grid.load_sweep, called by sweep.frontdoor and
# workflow/rules/common.smk).
SCHEMA_TEMPLATE = ("schema", "config.template.yaml")
SCHEMA_RESOURCE = ("schema", "config.schema.yaml")
SCHEMA_HEADER = ("# The sweep config's JSON schema, generated from config.template.yaml and the registry of\n"
                 "# inputs (sweep.fields): do not edit. Regenerate: .venv/bin/python -c 'from sweep import validation; "
                 "validation.write_schema()'\n")


def schema_path() -> Path:
    """Filesystem path of the packaged config schema (for tools that want a path, e.g.
    snakemake.utils.validate). The package is installed as files, never zipped, so the
    importlib.resources traversable is a real path."""
    from importlib.resources import files

    return Path(str(files(__package__).joinpath(*SCHEMA_RESOURCE)))


SCHEMA_PATH = schema_path()


class SweepConfigError(ValueError):
    """The sweep configuration is invalid: `errors`, one ConfigError per invalid field (key,
    value, allowed range; `source`, the file, where known). str(): one line per field."""

    def __init__(self, errors: Sequence[ConfigError]):
        self.errors = list(errors)
        super().__init__("\n".join(e.line() for e in self.errors))


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


def dotted_key(path: Iterator[Any] | list[Any]) -> str:
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


def walk_values(obj: Any, path: list[Any]) -> Iterator[tuple[list[Any], Any]]:
    yield path, obj
    if isinstance(obj, Mapping):
        for k, v in obj.items():
            yield from walk_values(v, path + [k])
    elif isinstance(obj, list):
        for i, v in enumerate(obj):
            yield from walk_values(v, path + [i])


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
    for path, value in walk_values(config, []):
        if isinstance(value, float) and not math.isfinite(value):
            add(ConfigError(dotted_key(path), value, _allowed(schema, path), problem="not a finite number"))
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
                add(ConfigError(dotted_key(path + [k]), value[k], f"keys: {', '.join(known)}", problem="no such key"))
        elif err.validator == "required":
            for k in node.get("required", []):
                if isinstance(value, Mapping) and k not in value:
                    add(ConfigError(dotted_key(path + [k]), MISSING, _allowed(schema, path + [k])))
        elif err.validator == "type" and err.validator_value == "object":
            add(ConfigError(dotted_key(path), value,
                            "a mapping of the keys " + ", ".join(sorted(node.get("properties", {}))),
                            problem="not a mapping"))
        elif err.validator == "type" and err.validator_value == "array":
            add(ConfigError(dotted_key(path), value, "a list: " + _allowed(schema, path), problem="not a list"))
        elif err.validator == "type":
            kind = {"integer": "an integer", "number": "a number", "string": "text",
                    "boolean": "true or false"}.get(err.validator_value, err.validator_value)
            add(ConfigError(dotted_key(path), value, _allowed(schema, path),
                            problem=None if quoted_number(value) else f"not {kind}"))
        elif err.validator == "minItems" and not value:
            add(ConfigError(dotted_key(path), value, "at least one value: " + _allowed(schema, path),
                            problem="the list is empty"))
        elif err.validator == "uniqueItems":
            seen, dups = [], []
            for v in value:
                (dups if v in seen else seen).append(v)
            add(ConfigError(dotted_key(path), value, "each value once: " + _allowed(schema, path),
                            problem=f"duplicate value(s) {dups}"))
        else:   # out of range, not one of the choices, not matching the pattern
            add(ConfigError(dotted_key(path), value, _allowed(schema, path)))
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
    from . import lattice as _lattice

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
            if isinstance(pts, int) and _lattice.is_lattice_size(pts) and rng.excluded in set(
                    _lattice.axis_values(float(lo), float(hi), pts).tolist()):
                errors.append(ConfigError(f"refine.axes.{a}", dict(spec), rng.allowed(),
                                          problem=f"a lattice point falls on the excluded value {rng.excluded!r}"))
                continue
        ok_axes[a] = spec
    if len(ok_axes) != len(axes) or not (2 <= len(axes) <= 3):
        return errors
    points = [spec.get("points") for spec in axes.values()]
    start = ref.get("start_points", 9)
    if not all(isinstance(p, int) and _lattice.is_lattice_size(p) for p in points) or not isinstance(start, int):
        return errors
    smallest = min(points)
    if not start < smallest:
        errors.append(ConfigError("refine.start_points", start,
                                  f"2^l + 1 below the smallest axis' points ({smallest}): at most {(smallest - 1) // 2 + 1}",
                                  problem="leaves no round to refine in"))
        return errors
    share = ref.get("max_share", 0.25)
    if _valid_number(share) and 0 < share <= 1:
        lat = _lattice.make_lattice(axes, start)
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
