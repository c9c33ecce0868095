"""Sweep config files: read, merged as Snakemake merges them (config/config.yaml, then each
--configfile, then --config), every key's file remembered so that a message names it
(`ConfigSource`), and the sweep's name, hence its results folder results/<name>/ (`sweep_name`).
"""
from __future__ import annotations

import copy
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .errors import ConfigError
from .validation import SweepConfigError, dotted_key, walk_values


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
        origins[dotted_key(sub)] = label
        if isinstance(v, Mapping) and isinstance(base.get(k), dict):
            _merge_into(base[k], v, label, origins, sub)
            continue
        head = dotted_key(sub)
        for key in [o for o in origins if o.startswith(head + ".") or o.startswith(head + "[")]:
            del origins[key]
        base[k] = copy.deepcopy(dict(v) if isinstance(v, Mapping) else v)
        for sub_path, _ in walk_values(v, sub):
            if isinstance(sub_path[-1], str):
                origins[dotted_key(sub_path)] = label


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
