"""The CF-1.10 metadata of the chunk files and the cube: their variables (the output registry,
sweep.outputs, plus the numerical-error variables of sweep.numerical_error), each variable's and
coordinate's attributes (`units`, `long_name`, flags), the cube's netCDF encoding (types, fills,
zlib, chunk shape), coordinates (SI units: the sweep axes, the inclination levels in rad) and global
attributes (provenance: version, git commit, config, solver, core fingerprint).
"""
from __future__ import annotations

import datetime as _dt
import math
import subprocess
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from . import axes as _axes
from . import chunking as _chunking
from . import outcomes, reasons
from .numerical_error import ERROR_VARIABLES, error_reference
from .outputs import VARIABLES, Var


INT_FILL = -1          # _FillValue of the count variables: counts are >= 0, so -1 is never data
COMPLEVEL = 4          # zlib level: the summary data compress ~3x by level 4; higher levels gain <5%
# Target elements per netCDF chunk of the cube: 2^15 float64 = 256 KiB, so several chunks fit in
# the default 1 MiB HDF5 chunk cache and a 1-D read along any axis touches few chunks.
CUBE_CHUNK_ELEMENTS = 2 ** 15

VARIABLE_NAMES = tuple(v.name for v in VARIABLES)
LEVEL_ATTRS = {"units": "rad", "long_name": "inclination level"}


def variables(error_estimate: bool = False) -> tuple[Var, ...]:
    """The variables of a chunk file / the cube: VARIABLES, plus ERROR_VARIABLES with error bars."""
    return VARIABLES + (ERROR_VARIABLES if error_estimate else ())


def var_attrs(var: Var) -> dict:
    """A variable's CF attributes: units and long_name (a flag: its flag values and meanings;
    an outcome: the outcome codes'), and the flag variable that says why a value is missing."""
    if var.kind == "flag":
        return reasons.flag_attrs(var.name)
    attrs = {"units": var.units, "long_name": var.long_name}
    flag = reasons.flag_of(var.name)
    if flag is not None:   # CF: the flag variable that says why a value is missing
        attrs["ancillary_variables"] = flag
    if var.kind == "outcome":
        attrs["flag_values"] = np.array(outcomes.FLAG_VALUES, dtype=np.int8)
        attrs["flag_meanings"] = outcomes.FLAG_MEANINGS
    return attrs


def coord_attrs(axis: str) -> dict:
    """A sweep axis' CF attributes: units and long_name (sweep.axes)."""
    return {"units": _axes.AXIS_UNITS[axis], "long_name": _axes.AXIS_LONG_NAMES[axis]}


def cube_chunksizes(shape: Sequence[int], target: int = CUBE_CHUNK_ELEMENTS) -> tuple[int, ...]:
    """netCDF chunk shape: halve the longest dimension until the chunk holds <= target elements.

    Balanced chunks make a 1-D read along any axis touch about the same number of chunks.
    """
    c = [max(1, int(n)) for n in shape]
    while math.prod(c) > target:
        i = max(range(len(c)), key=lambda k: c[k])
        c[i] = math.ceil(c[i] / 2)
    return tuple(c)


def git_commit(path: str | Path) -> str:
    """HEAD commit of the git repository containing `path` (+ '-dirty' if tracked files
    differ from it), or 'unknown'."""
    try:
        head = subprocess.run(["git", "-C", str(path), "rev-parse", "HEAD"], capture_output=True,
                              text=True, timeout=30, check=True).stdout.strip()
        dirty = subprocess.run(["git", "-C", str(path), "status", "--porcelain", "--untracked-files=no"],
                               capture_output=True, text=True, timeout=30, check=True).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return "unknown"
    return head + ("-dirty" if dirty else "") if head else "unknown"


def variable_encoding(kind: str, chunksizes: Sequence[int]) -> dict:
    """The cube's netCDF encoding of a variable of `kind` (sweep.outputs.Var.kind): int32 with
    fill -1 for counts (decoded with NaN for missing), int8 for outcome codes and flags, float64
    with NaN fill; zlib with shuffle, in `chunksizes`."""
    if kind == "int":
        enc = {"dtype": "int32", "_FillValue": np.int32(INT_FILL)}
    elif kind in ("outcome", "flag"):
        enc = {"dtype": "int8", "_FillValue": None}
    elif kind == "bool":
        enc = {"_FillValue": None}
    else:
        enc = {"dtype": "float64", "_FillValue": np.nan}
    enc.update(zlib=True, complevel=COMPLEVEL, shuffle=True, chunksizes=tuple(chunksizes))
    return enc


def cube_coords(settings: Mapping) -> dict:
    """The cube's coordinates: the six axes (the values of `settings["grid"]`) and `level`."""
    coords = {a: (a, np.array(settings["grid"][a], dtype=np.float64), coord_attrs(a)) for a in _axes.AXES}
    coords["level"] = ("level", np.array(settings["levels"], dtype=np.float64), dict(LEVEL_ATTRS))
    return coords


def cube_attrs(settings: Mapping, name: str | None, history: str, repo_path: str | Path | None) -> dict:
    """The cube's global attributes: CF conventions, title, history (`history`, after the time),
    provenance (version, git commit, config and its SHA-256, solver, core fingerprint)."""
    from . import __version__

    config_json = _chunking.canonical_json(settings)
    created = _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")
    attrs = {
        "Conventions": "CF-1.10",
        "title": "Euler's disk (Kessler & O'Reilly 2002) parameter sweep" + (f" '{name}'" if name else ""),
        "sweep_name": name or "",
        "history": f"{created}: {history}",
        "source": f"sweep {__version__}: rigid-disk model of Kessler & O'Reilly (2002), "
                  "numba hybrid integrator",
        "sweep_version": __version__,
        "git_commit": git_commit(repo_path) if repo_path is not None else "unknown",
        "config_json": config_json,
        "config_sha256": _chunking.sha256_hex(config_json),
        "solver": _chunking.canonical_json(settings["solver"]),
        "sweep_core_sha256": _chunking.core_fingerprint(),
        "stop": _chunking.canonical_json(settings["stop"]),
        "created": created,
    }
    if settings.get("outputs", {}).get("error_estimate", False):  # the rerun's settings behind *_numerical_error
        ref = error_reference(_chunking.scene_settings(settings))
        attrs["error_estimate_solver"] = _chunking.canonical_json(ref["solver"])
        attrs["error_estimate_stop"] = _chunking.canonical_json(ref["stop"])
    return attrs
