"""netCDF input/output of the sweep: chunk files, their verification, the gathered cube.

Chunk files (`results/<name>/chunks/<id>.nc`) hold one row per scene along the dimension `point`
(coordinates mu_d, k1, k2, k3, alpha0, omega0 per point) and the dimension `level`. Their global
attribute `sweep_checksum` is a SHA-256 over every variable's values, so a truncated or damaged
file is detected before it is gathered. The cube (`results/<name>/cube.nc`) has the dimensions
(mu_d, k1, k2, k3, alpha0, omega0[, level]) and CF-1.10 metadata.

Every file is written atomically: to a temporary name in the target directory, fsync'ed, then
os.replace'd over the target, so a reader never sees a partial file under the final name.
"""
from __future__ import annotations

import datetime as _dt
import hashlib
import json
import logging
import math
import os
import shutil
import subprocess
import tempfile
import uuid
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from . import fields
from . import grid as _grid
from . import outcomes, reasons
from . import outputs as _outputs

log = logging.getLogger("sweep.io")

INT_FILL = -1          # _FillValue of the count variables: counts are >= 0, so -1 is never data
COMPLEVEL = 4          # zlib level: the summary data compress ~3x by level 4; higher levels gain <5%
# Target elements per netCDF chunk of the cube: 2^15 float64 = 256 KiB, so several chunks fit in
# the default 1 MiB HDF5 chunk cache and a 1-D read along any axis touches few chunks.
CUBE_CHUNK_ELEMENTS = 2 ** 15


# the cube's variables: generated from the output registry (sweep.outputs)
Var = _outputs.Var
VARIABLES = _outputs.VARIABLES
VARIABLE_NAMES = tuple(v.name for v in VARIABLES)
LEVEL_ATTRS = {"units": "rad", "long_name": "inclination level"}

# ---- error bars (outputs.error_estimate): every scene is rerun with the tolerances of
# sweep.grid.error_reference; each variable marked numerical_error=True gets <name>_numerical_error.
ERROR_SUFFIX = "_numerical_error"
# Reference outcomes that mean the rerun could not get where the main run got (not a physical end):
# a value the main run has but such a rerun lacks has an unknown error (NaN), not an infinite one.
REFERENCE_FAILURES = frozenset({outcomes.STEP_LIMIT, outcomes.STEP_SIZE_UNDERFLOW, outcomes.NUMERICAL_ERROR,
                                outcomes.NOT_RUN})


def _error_var(var: Var) -> Var:
    key = var.name + ERROR_SUFFIX
    return Var(key, "float", var.units,
               f"{var.long_name}: absolute difference to a rerun at rtol/100 (numerical error estimate; "
               "NaN where there is no value or the rerun failed, inf where only this run has a value)",
               (lambda d: d[key]), per_level=var.per_level)


ERROR_VARIABLES: tuple[Var, ...] = tuple(_error_var(v) for v in VARIABLES if v.numerical_error) + (
    Var("reference_outcome", "outcome", "1",
        "outcome of the rerun at rtol/100 that gives the *_numerical_error variables (see flag_meanings)",
        lambda s: s["reference_outcome"]),
)


def variables(error_estimate: bool = False) -> tuple[Var, ...]:
    """The variables of a chunk file / the cube: VARIABLES, plus ERROR_VARIABLES with error bars."""
    return VARIABLES + (ERROR_VARIABLES if error_estimate else ())


def _abs_difference(value: Any, ref: Any, ref_failed: bool) -> float:
    a = math.nan if value is None else float(value)
    b = math.nan if ref is None else float(ref)
    if math.isnan(a):
        return math.nan              # no value, no error bar
    if math.isnan(b):
        return math.nan if ref_failed else math.inf   # the tighter run has no such value
    return abs(a - b)


def add_numerical_errors(summary: dict, reference: Mapping | None) -> dict:
    """Add `<name>_numerical_error` (|value - reference value|) to a scene's summary, in place,
    for every variable marked numerical_error, and `reference_outcome`.

    `reference`: the summary of the same scene rerun at tighter tolerances, or None where the
    rerun raised (then every error is NaN and reference_outcome is numerical_error). A value the
    reference lacks has error inf if the rerun ended physically (the value is a numerical
    artefact), NaN if it ended in a numerical failure (step limit, underflow, error). Whole-run
    totals (counts, slip_fraction) get NaN where the rerun failed: its totals stop at its failure.
    """
    ref_code = outcomes.NUMERICAL_ERROR if reference is None else int(reference["outcome_code"])
    failed = reference is None or ref_code in REFERENCE_FAILURES
    summary["reference_outcome"] = ref_code
    for var in VARIABLES:
        if not var.numerical_error:
            continue
        key = var.name + ERROR_SUFFIX
        if var.per_level:
            for j, lv in enumerate(summary["levels"]):
                ref = var.get(reference["levels"][j]) if reference is not None else None
                lv[key] = _abs_difference(var.get(lv), ref, failed)
        elif var.whole_run and failed:
            summary[key] = math.nan    # a rerun that did not end physically has partial totals
        else:
            summary[key] = _abs_difference(var.get(summary), var.get(reference) if reference is not None else None,
                                           failed)
    return summary


def error_summary(n_levels: int, outcome_code: int = outcomes.NUMERICAL_ERROR, wall_time: float = math.nan) -> dict:
    """A summary dict for a scene that produced no result (NaN everywhere, counts missing):
    sweep.outputs.empty_summary."""
    return _outputs.empty_summary(n_levels, outcome_code, wall_time)


def value_of(var: Var, summary: Mapping):
    """What `var` holds for a scene's `summary`: a scalar, or a list over the levels (a flag is
    derived from the summary by sweep.reasons where the summary does not carry it yet)."""
    if var.kind == "flag" and var.name not in summary and not (
            summary["levels"] and var.name in summary["levels"][0]):
        summary = reasons.add_flags(summary)
    return [var.get(lv) for lv in summary["levels"]] if var.per_level else var.get(summary)


def _column(var: Var, summaries: Sequence[Mapping], n_levels: int) -> np.ndarray:
    if var.per_level:
        raw = [[var.get(s["levels"][j]) for j in range(n_levels)] for s in summaries]
    else:
        raw = [var.get(s) for s in summaries]
    if var.kind == "float":
        return np.array(raw, dtype=np.float64).reshape(len(summaries), *([n_levels] if var.per_level else []))
    if var.kind == "int":
        return np.array([INT_FILL if v is None else int(v) for v in raw], dtype=np.int32)
    if var.kind == "bool":
        return np.array([bool(v) for v in raw], dtype=bool)
    if var.kind == "flag":
        return np.array(raw, dtype=np.int8).reshape(len(summaries), *([n_levels] if var.per_level else []))
    return np.array([int(v) for v in raw], dtype=np.int8)


def _var_attrs(var: Var) -> dict:
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


def _coord_attrs(axis: str) -> dict:
    return {"units": _grid.AXIS_UNITS[axis], "long_name": _grid.AXIS_LONG_NAMES[axis]}


# --------------------------------------------------------------------------------------------
# checksums and atomic writes
# --------------------------------------------------------------------------------------------

def file_checksum(path: str | Path) -> str:
    """SHA-256 over every variable's name, shape and stored values of a netCDF file.

    Values are taken raw (no masking or scaling, so count fills stay -1), as float64 with one
    bit pattern for every NaN, in name order; attributes are not covered.
    """
    import netCDF4

    with netCDF4.Dataset(path, "r") as nc:
        nc.set_auto_maskandscale(False)
        return _checksum_of({name: np.asarray(v[...]) for name, v in nc.variables.items()})


def _fsync_path(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def write_file_atomic(path: str | Path, write: Callable[[Path], None],
                      finish: Callable[[Path], None] | None = None) -> Path:
    """Make the file at `path` atomically: `write(tmp)` writes a temporary file in the same
    directory, `finish(tmp)` may amend it (e.g. add a checksum), then fsync and os.replace; on any
    error the temporary file is removed and `path` is untouched."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.parent / f".{path.name}.tmp-{os.getpid()}-{uuid.uuid4().hex[:8]}"
    try:
        write(tmp)
        if finish is not None:
            finish(tmp)
        _fsync_path(tmp)
        os.replace(tmp, path)
        _fsync_path(path.parent)  # make the rename itself durable
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return path


def write_atomic(ds, path: str | Path, encoding: Mapping | None = None,
                 finish: Callable[[Path], None] | None = None) -> Path:
    """Write the xarray Dataset `ds` to netCDF-4 at `path` atomically (write_file_atomic)."""
    return write_file_atomic(
        path, lambda tmp: ds.to_netcdf(tmp, engine="netcdf4", format="NETCDF4", encoding=dict(encoding or {})),
        finish)


# --------------------------------------------------------------------------------------------
# chunk files
# --------------------------------------------------------------------------------------------

def chunk_content(chunk: _grid.Chunk, summaries: Sequence[Mapping]) -> tuple[dict, dict, dict]:
    """What a chunk file holds, from its scenes' summaries (in chunk point order): (coordinates
    {name: (dims, values, attrs)}, data variables likewise, global attributes)."""
    spec = chunk.spec
    levels = spec["settings"]["levels"]
    if len(summaries) != len(chunk.points):
        raise ValueError(f"chunk {chunk.id}: {len(summaries)} summaries for {len(chunk.points)} points")
    for s in summaries:  # the level columns must line up with the `level` coordinate
        got = [lv["inclination"] for lv in s["levels"]]
        if len(got) != len(levels) or any(g == g and g != w for g, w in zip(got, levels)):
            raise ValueError(f"chunk {chunk.id}: summary levels {got} do not match the configured {levels}")
    pts = np.array(chunk.points, dtype=np.float64).reshape(len(chunk.points), len(_grid.AXES))
    coords = {a: (("point",), pts[:, i], _coord_attrs(a)) for i, a in enumerate(_grid.AXES)}
    coords["level"] = (("level",), np.array(levels, dtype=np.float64), dict(LEVEL_ATTRS))
    summaries = [reasons.add_flags(s) for s in summaries]   # why each missing value is missing
    data = {}
    for var in variables(bool(spec["settings"].get("error_estimate", False))):
        dims = ("point", "level") if var.per_level else ("point",)
        data[var.name] = (dims, _column(var, summaries, len(levels)), _var_attrs(var))
    from . import __version__
    attrs = {"Conventions": "CF-1.10", "title": "Euler's disk sweep chunk",
             "sweep_chunk_id": chunk.id, "sweep_chunk_spec": chunk.spec_json,
             "sweep_chunk_format": _outputs.CHUNK_FORMAT, "sweep_version": __version__}
    return coords, data, attrs


def chunk_dataset(chunk: _grid.Chunk, summaries: Sequence[Mapping]):
    """The xarray Dataset of one chunk from its scenes' summaries (in chunk point order)."""
    import xarray as xr

    coords, data, attrs = chunk_content(chunk, summaries)
    return xr.Dataset(data, coords=coords, attrs=attrs)


def _fill_of(name: str, values: np.ndarray):
    """A chunk variable's _FillValue: NaN for floats, INT_FILL for the counts, none otherwise."""
    if values.dtype.kind == "f":
        return np.nan
    if values.dtype.kind == "i" and name in VARIABLE_NAMES and next(v for v in VARIABLES if v.name == name).kind == "int":
        return np.int32(INT_FILL)
    return None


def _write_chunk_nc(tmp: Path, coords: Mapping, data: Mapping, attrs: Mapping) -> dict[str, np.ndarray]:
    """Write a chunk file with netCDF4 alone, as xarray writes chunk_dataset with these fills
    (same dimensions, variables, dtypes, fills, attributes; booleans as int8 with dtype 'bool'),
    so a chunk job need not import xarray and dask (~1 s a process). Returns the raw arrays
    stored ({name: values}, what file_checksum reads back)."""
    import netCDF4

    coord_names = " ".join(sorted(a for a in coords if a != "level"))
    stored = {}
    with netCDF4.Dataset(tmp, "w", format="NETCDF4") as nc:
        nc.createDimension("point", len(coords[_grid.AXES[0]][1]))
        nc.createDimension("level", len(coords["level"][1]))
        for name, (dims, values, vattrs) in list(data.items()) + list(coords.items()):
            values = np.asarray(values)
            vattrs = dict(vattrs)
            if values.dtype == bool:
                values = values.astype(np.int8)
                vattrs["dtype"] = "bool"
            if name in data:
                vattrs["coordinates"] = coord_names
            fill = _fill_of(name, values)
            v = nc.createVariable(name, values.dtype, tuple(dims), fill_value=fill if fill is not None else False)
            v.set_auto_maskandscale(False)
            for k, a in vattrs.items():
                v.setncattr(k, a)
            v[...] = values
            stored[name] = values
        for k, a in attrs.items():
            nc.setncattr(k, a)
        nc.setncattr("sweep_checksum", _checksum_of(stored))
    return stored


def write_chunk(chunk: _grid.Chunk, summaries: Sequence[Mapping], path: str | Path) -> Path:
    """Write a chunk file atomically, with the checksum of its content as `sweep_checksum`."""
    coords, data, attrs = chunk_content(chunk, summaries)
    return write_file_atomic(path, lambda tmp: _write_chunk_nc(tmp, coords, data, attrs))


def _checksum_of(arrays: Mapping[str, np.ndarray]) -> str:
    """file_checksum's digest of raw arrays already read ({name: values})."""
    h = hashlib.sha256()
    for name in sorted(arrays):
        a = np.asarray(arrays[name])
        if a.dtype.kind not in "biuf":
            h.update(name.encode() + repr(a.tolist()).encode())
            continue
        a = a.astype(np.float64)
        a = np.where(np.isnan(a), np.nan, a)
        h.update(name.encode() + repr(a.shape).encode() + np.ascontiguousarray(a).tobytes())
    return h.hexdigest()


def read_chunk_file(path: str | Path, chunk: _grid.Chunk | None = None,
                    expect_id: str | None = None) -> tuple[str | None, dict[str, np.ndarray]]:
    """(None, every variable's raw values) if the chunk file is intact (and matches `chunk`), else
    (the reason it is not, {}). One read of the file: the checksum is taken over the values read.
    `expect_id` instead of `chunk`: the file's id attribute and the hash of its spec must both be
    that id (the plan's chunks are named by the hash of their spec, so this is the same check
    without the plan's spec texts at hand)."""
    import netCDF4

    path = Path(path)
    try:
        if path.stat().st_size == 0:
            return "empty file", {}
        with netCDF4.Dataset(path, "r") as nc:
            attrs = {k: nc.getncattr(k) for k in nc.ncattrs()}
            sizes = {k: len(v) for k, v in nc.dimensions.items()}
            nc.set_auto_maskandscale(False)
            arrays = {name: np.asarray(v[...]) for name, v in nc.variables.items()}
        names = set(arrays)
        want = attrs.get("sweep_checksum")
        if want is None:
            return "no sweep_checksum attribute (incomplete write)", {}
        if _checksum_of(arrays) != want:
            return "checksum mismatch (damaged data)", {}
        try:
            with_errors = bool(json.loads(attrs.get("sweep_chunk_spec", "{}"))["settings"].get("error_estimate", False))
        except (ValueError, KeyError, TypeError, AttributeError):
            with_errors = False
        missing = [v.name for v in variables(with_errors) if v.name not in names]
        if missing:
            return f"missing variables {missing}", {}
        if chunk is not None:
            if attrs.get("sweep_chunk_id") != chunk.id:
                return f"chunk id {attrs.get('sweep_chunk_id')!r} != expected {chunk.id!r}", {}
            if attrs.get("sweep_chunk_spec") != chunk.spec_json:
                return "chunk spec differs from the expected one", {}
            if sizes.get("point") != len(chunk.points):
                return f"{sizes.get('point')} points, expected {len(chunk.points)}", {}
            if sizes.get("level") != len(chunk.spec["settings"]["levels"]):
                return "wrong number of levels", {}
        elif expect_id is not None:
            if attrs.get("sweep_chunk_id") != expect_id:
                return f"chunk id {attrs.get('sweep_chunk_id')!r} != expected {expect_id!r}", {}
            spec = attrs.get("sweep_chunk_spec", "")
            if _grid.sha256_hex(spec)[:_grid.CHUNK_ID_HEX] != expect_id:
                return "chunk spec differs from the expected one", {}
            if sizes.get("point") != len(json.loads(spec)["points"]):
                return f"{sizes.get('point')} points, expected {len(json.loads(spec)['points'])}", {}
    except (OSError, RuntimeError, ValueError, KeyError, IndexError) as exc:  # HDF5 damage surfaces as these
        return f"unreadable ({type(exc).__name__}: {exc})", {}
    return None, arrays


def verify_chunk(path: str | Path, chunk: _grid.Chunk | None = None) -> str | None:
    """None if the chunk file is intact (and matches `chunk`), else the reason it is not."""
    return read_chunk_file(path, chunk)[0]


def quarantine(path: str | Path, reason: str) -> Path:
    """Move a damaged chunk file to <dir>/quarantine/ (kept for inspection) so it is recomputed."""
    path = Path(path)
    qdir = path.parent / "quarantine"
    qdir.mkdir(parents=True, exist_ok=True)
    stamp = _dt.datetime.now(_dt.timezone.utc).strftime("%Y%m%dT%H%M%S")
    target = qdir / f"{path.name}.{stamp}"
    os.replace(path, target)
    (qdir / f"{target.name}.reason").write_text(reason + "\n", encoding="utf-8")
    return target


VERIFIED_CACHE = ".verified.json"


def check_existing_chunks(chunk_dir: str | Path, chunks: Mapping[str, _grid.Chunk],
                          act: bool = True) -> dict[str, str]:
    """Verify every existing chunk file of the plan; quarantine damaged ones if `act`.

    Returns {chunk_id: reason} for the damaged files (which Snakemake then sees as missing).
    A file that verified before and whose (size, mtime) has not changed since is not read
    again (cache `<chunk_dir>/.verified.json`), so a Snakemake call over 10^4 chunks costs
    10^4 stat calls, not 10^4 checksums; the gather still verifies every checksum.
    """
    bad: dict[str, str] = {}
    chunk_dir = Path(chunk_dir)
    cache_path = chunk_dir / VERIFIED_CACHE
    try:
        cache = json.loads(cache_path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        cache = {}
    fresh = {}
    for cid, chunk in chunks.items():
        p = chunk_dir / f"{cid}.nc"
        try:
            st = p.stat()
        except FileNotFoundError:
            continue
        stamp = [st.st_size, st.st_mtime_ns]
        if cache.get(cid) == stamp:
            fresh[cid] = stamp
            continue
        reason = verify_chunk(p, chunk)
        if reason is None:
            fresh[cid] = stamp
            continue
        bad[cid] = reason
        if act:
            quarantine(p, reason)
    if fresh != cache and chunk_dir.is_dir():
        tmp = chunk_dir / f".{VERIFIED_CACHE}.tmp-{os.getpid()}"
        tmp.write_text(json.dumps(fresh), encoding="utf-8")
        os.replace(tmp, cache_path)
    return bad


# --------------------------------------------------------------------------------------------
# the cube
# --------------------------------------------------------------------------------------------

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
    coords = {a: (a, np.array(settings["grid"][a], dtype=np.float64), _coord_attrs(a)) for a in _grid.AXES}
    coords["level"] = ("level", np.array(settings["levels"], dtype=np.float64), dict(LEVEL_ATTRS))
    return coords


def cube_attrs(settings: Mapping, name: str | None, history: str, repo_path: str | Path | None) -> dict:
    """The cube's global attributes: CF conventions, title, history (`history`, after the time),
    provenance (version, git commit, config and its SHA-256, solver, core fingerprint)."""
    from . import __version__

    config_json = _grid.canonical_json(settings)
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
        "config_sha256": _grid.sha256_hex(config_json),
        "solver": _grid.canonical_json(settings["solver"]),
        "sweep_core_sha256": _grid.core_fingerprint(),
        "stop": _grid.canonical_json(settings["stop"]),
        "created": created,
    }
    if settings.get("outputs", {}).get("error_estimate", False):  # the rerun's settings behind *_numerical_error
        ref = _grid.error_reference(_grid.scene_settings(settings))
        attrs["error_estimate_solver"] = _grid.canonical_json(ref["solver"])
        attrs["error_estimate_stop"] = _grid.canonical_json(ref["stop"])
    return attrs


# The gather writes its memory-mapped arrays back and drops their pages from its memory every
# RELEASE_EVERY chunk files, so its resident memory stays bounded by what that many files touch.
RELEASE_EVERY = 500


def _release(maps) -> None:
    """Flush memory maps to their files and drop their pages from this process's memory."""
    import mmap

    for m in maps:
        m.flush()
        mm = getattr(m, "_mmap", None)
        if mm is not None and hasattr(mm, "madvise"):
            mm.madvise(mmap.MADV_DONTNEED)


class _Paged:
    """A memory-mapped array as dask reads it block by block for the write: each block is copied
    out and the map's pages are dropped again (_release), so a block is resident only while it
    is written."""

    def __init__(self, m: np.ndarray, shape: tuple[int, ...]):
        self.m, self.v = m, m.reshape(shape)
        self.shape, self.dtype, self.ndim = self.v.shape, self.v.dtype, self.v.ndim

    def __getitem__(self, key):
        out = np.array(self.v[key])
        _release([self.m])
        return out


def _fill(kind: str):
    return {"float": np.nan, "int": INT_FILL, "bool": False}.get(kind, 0)


def _dtype(kind: str):
    return {"float": np.float64, "int": np.int32, "bool": np.bool_}.get(kind, np.int8)


def _read_job(job: tuple[Path, str | None]) -> tuple[Path, str | None, dict[str, np.ndarray]]:
    path, cid = job
    reason, data = read_chunk_file(path, expect_id=cid)
    return path, reason, data


# chunk files handed to the reading processes at a time (bounds what waits in their queues)
READ_BATCH = 1000


def _read_all(jobs: Sequence[tuple[Path, str | None]], workers: int):
    """_read_job over `jobs`, in order, in `workers` processes (this one where 1)."""
    if workers <= 1 or len(jobs) < 64:
        yield from map(_read_job, jobs)
        return
    import multiprocessing

    with multiprocessing.get_context("fork").Pool(workers) as pool:
        for i in range(0, len(jobs), READ_BATCH):
            yield from pool.imap(_read_job, jobs[i:i + READ_BATCH], chunksize=16)


def gather(chunk_paths: Sequence[str | Path], settings: Mapping, out_path: str | Path,
           repo_path: str | Path | None = None, history: str = "", name: str | None = None,
           workers: int = 1) -> Path:
    """Gather verified chunk files into the cube at `out_path` (atomic write).

    `settings`: the normalised config (sweep.grid.normalize); `name`: the sweep's name (global
    attribute `sweep_name`, shown on the figures). Every grid point must be present exactly
    once; a damaged chunk file raises (after quarantining it) instead of being gathered.

    Each chunk file is read once (netCDF4, its checksum verified over the values read) and its
    values scattered into one memory-mapped array per variable in a temporary folder beside the
    cube, which is then written block by block (dask over the maps, the cube's netCDF chunks): the
    memory used is a few blocks, whatever the number of chunk files or scenes. `workers`
    processes read the chunk files (the rule `gather` gives its threads).
    """
    import dask.array as dsa
    import xarray as xr

    paths = [Path(p) for p in chunk_paths]
    out_path = Path(out_path)
    plan_ids = set(_grid.plan_chunks(settings))   # the ids only: the plan's spec texts are not kept
    axes = _grid.AXES
    shape = _grid.grid_shape(settings)
    n_levels = len(settings["levels"])
    n = math.prod(shape)
    error_estimate = bool(settings.get("outputs", {}).get("error_estimate", False))
    vars_ = variables(error_estimate)
    axis_values = [np.asarray(settings["grid"][a], dtype=np.float64) for a in axes]
    out_path.parent.mkdir(parents=True, exist_ok=True)
    scratch = Path(tempfile.mkdtemp(prefix=".gather-", dir=out_path.parent))
    try:
        maps = {}
        for var in vars_:
            m = np.lib.format.open_memmap(scratch / f"{var.name}.npy", mode="w+", dtype=_dtype(var.kind),
                                          shape=(n, n_levels) if var.per_level else (n,))
            m[...] = _fill(var.kind)
            _release([m])
            maps[var.name] = m
        seen = np.zeros(n, dtype=np.int32)
        n_read = 0
        for p, reason, data in _read_all([(p, p.stem if p.stem in plan_ids else None) for p in paths], workers):
            if reason is not None:
                moved = quarantine(p, reason)
                raise RuntimeError(f"chunk file {p} is damaged ({reason}); moved to {moved}. "
                                   "Run snakemake again to recompute it.")
            pos = np.zeros(len(data[axes[0]]), dtype=np.int64)
            for a, vals in zip(axes, axis_values):  # flat row-major index of every point in the cube
                got = np.asarray(data[a], dtype=np.float64)
                idx = np.minimum(np.searchsorted(vals, got), len(vals) - 1)
                off = vals[idx] != got
                if off.any():
                    raise RuntimeError(f"a chunk holds {a} = {float(got[off][0])!r}, not on the grid axis")
                pos = pos * len(vals) + idx
            np.add.at(seen, pos, 1)
            for var in vars_:
                maps[var.name][pos] = data[var.name].astype(_dtype(var.kind), copy=False)
            n_read += 1
            if n_read % RELEASE_EVERY == 0:
                _release(maps.values())
        if (seen != 1).any():
            raise RuntimeError(f"chunks hold {int(seen.sum())} points with {int((seen > 0).sum())} distinct "
                               f"grid positions; the grid has {n}")
        _release(maps.values())
        csizes = cube_chunksizes(shape + (n_levels,))
        data_vars, encoding = {}, {}
        for var in vars_:
            full_shape = shape + ((n_levels,) if var.per_level else ())
            cs = csizes if var.per_level else csizes[:-1]
            arr = dsa.from_array(_Paged(maps[var.name], full_shape), chunks=cs, lock=False, asarray=False)
            dims = axes + (("level",) if var.per_level else ())
            data_vars[var.name] = (dims, arr, _var_attrs(var))
            encoding[var.name] = variable_encoding(var.kind, cs)
        coords = cube_coords(settings)
        for c in coords:
            encoding[c] = {"_FillValue": None}
        attrs = cube_attrs(settings, name, f"gathered {len(paths)} chunk files ({n} scenes) into this cube"
                           + (f"; {history}" if history else ""), repo_path)
        names = list(data_vars)
        cube = xr.Dataset({names[0]: data_vars[names[0]]}, coords=coords, attrs=attrs)
        log.info("gathering %d chunk files, %d scenes, grid %s x %d levels into %s (netCDF chunks %s)",
                 len(paths), n, dict(zip(axes, shape)), n_levels, out_path, csizes)
        import dask

        def the_others(tmp: Path) -> None:
            # one variable at a time: only its blocks are ever in memory
            for key in names[1:]:
                xr.Dataset({key: data_vars[key]}).to_netcdf(tmp, mode="a", engine="netcdf4",
                                                            encoding={key: encoding[key]})

        with dask.config.set(scheduler="synchronous"):
            out = write_atomic(cube, out_path, {k: v for k, v in encoding.items() if k in coords or k == names[0]},
                               finish=the_others)
        codes, counts = np.unique(maps["outcome"], return_counts=True)
        log.info("wrote %s (%d bytes); outcomes %s", out, out.stat().st_size,
                 {outcomes.NAMES[int(c)]: int(k) for c, k in zip(codes, counts)})
        del cube, data_vars, maps
        return out
    finally:
        shutil.rmtree(scratch, ignore_errors=True)


def open_cube(path: str | Path):
    """Open the cube lazily (dask arrays with the on-disk chunking)."""
    import xarray as xr

    return xr.open_dataset(path, engine="netcdf4", chunks={})


def reduce_to(da, keep: Sequence[str], how: str = "median"):
    """Reduce a cube variable over every dimension not in `keep` (NaN-skipping), computed.

    `how`: "median" | "mean" | "max" | "min". Returns an in-memory DataArray with dims `keep`.
    """
    others = [d for d in da.dims if d not in keep]
    if others:
        da = da.chunk({d: -1 for d in others}) if hasattr(da.data, "dask") else da
        da = getattr(da, how)(dim=others, skipna=True)
    return da.transpose(*keep).compute()


# --------------------------------------------------------------------------------------------
# notebooks
# --------------------------------------------------------------------------------------------

# A notebook cell that runs longer than this is stuck: the figure notebooks reduce the cube
# with dask and plot a handful of panels, which takes seconds even for 10^6 scenes.
NOTEBOOK_CELL_TIMEOUT_S = 600
# The longest folder for the kernel's Unix sockets (a socket path, folder + "/kernel-NNNNN", has
# at most 107 bytes on Linux).
UNIX_SOCKET_DIR_MAX = 90


def _write_notebook(nb, path: str | Path) -> None:
    """Write an executed notebook atomically."""
    import nbformat

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.parent / f".{path.name}.tmp-{os.getpid()}"
    nbformat.write(nb, str(tmp))
    os.replace(tmp, path)


def run_notebook(notebook: str | Path, cube: str | Path, figure: str | Path,
                 executed: str | Path | None = None, log_path: str | Path | None = None) -> Path:
    """Execute a figure notebook with nbclient; it reads the cube and saves `figure` (PNG).

    The paths reach the kernel as the environment variables SWEEP_CUBE and SWEEP_FIGURE
    (absolute). The executed notebook, with its outputs, is written to `executed`.
    """
    import nbclient
    import nbformat
    from traitlets.config import Config

    figure = Path(figure).resolve()
    figure.parent.mkdir(parents=True, exist_ok=True)
    figure.unlink(missing_ok=True)
    env_keys = {"SWEEP_CUBE": str(Path(cube).resolve()), "SWEEP_FIGURE": str(figure),
                "MPLBACKEND": "Agg"}
    saved = {k: os.environ.get(k) for k in env_keys}
    os.environ.update(env_keys)  # the kernel inherits this process's environment
    # The kernel talks to this process over Unix sockets in a folder of its own, not over TCP: a
    # TCP port is picked free and then bound by the kernel, and two notebooks starting at once
    # (snakemake -j2) could pick the same one ("Address already in use", the kernel dies and the
    # figure job fails).
    # a socket's path has at most ~107 bytes; a cluster's TMPDIR can be deep ("sweep-kernel-" and
    # mkdtemp's suffix add 22)
    deep = len(tempfile.gettempdir()) + 22 > UNIX_SOCKET_DIR_MAX
    sockets = tempfile.mkdtemp(prefix="sweep-kernel-", dir="/tmp" if deep else None)
    config = Config()
    config.KernelManager.transport = "ipc"
    config.KernelManager.ip = os.path.join(sockets, "kernel")
    try:
        nb = nbformat.read(str(notebook), as_version=4)
        # log level ERROR: no start-up warnings from the kernel
        client = nbclient.NotebookClient(nb, timeout=NOTEBOOK_CELL_TIMEOUT_S, kernel_name="python3",
                                         resources={"metadata": {"path": str(Path.cwd())}},
                                         extra_arguments=["--log-level=ERROR"], config=config)
        client.execute()
    finally:
        shutil.rmtree(sockets, ignore_errors=True)
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
    if executed is not None:
        _write_notebook(nb, executed)
    if not figure.exists():
        raise RuntimeError(f"notebook {notebook} ran but did not write {figure}")
    if log_path is not None:
        Path(log_path).parent.mkdir(parents=True, exist_ok=True)
        Path(log_path).write_text(f"executed {notebook} -> {figure}\n", encoding="utf-8")
    return figure


def _cell_outputs(nbformat, stdout: str, stderr: str, result, figures: list[bytes]) -> list:
    import base64

    outs = []
    if stdout:
        outs.append(nbformat.v4.new_output("stream", name="stdout", text=stdout))
    if stderr:
        outs.append(nbformat.v4.new_output("stream", name="stderr", text=stderr))
    if result is not None:
        outs.append(nbformat.v4.new_output("execute_result", data={"text/plain": repr(result)}))
    for png in figures:
        outs.append(nbformat.v4.new_output("display_data", data={"image/png": base64.b64encode(png).decode("ascii"),
                                                                  "text/plain": "<Figure>"}))
    return outs


def _mtime(path: str) -> int | None:
    try:
        return os.stat(path).st_mtime_ns if path else None
    except OSError:
        return None


def execute_in_process(notebook: str | Path, env: Mapping[str, str]):
    """Execute a notebook's code cells in this process (a fresh namespace, `env` set in
    os.environ meanwhile) and return it with its outputs as Jupyter would store them: each cell's
    stdout and stderr, the value of a last expression, and the figures left open at its end (PNG,
    as the inline backend shows them). A cell that raises gets its error output and the run stops
    with RuntimeError naming the notebook and the cell. No kernel is started: what the notebooks
    import (numpy, xarray, matplotlib, the package) is imported once for all of them."""
    import ast
    import contextlib
    import io as _stdio
    import traceback

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import nbformat

    nb = nbformat.read(str(notebook), as_version=4)
    saved_figure = env.get("SWEEP_FIGURE", "")
    saved = {k: os.environ.get(k) for k in env}
    os.environ.update(env)
    namespace: dict = {"__name__": "__main__"}
    count = 0
    plt.close("all")
    try:
        for cell in nb.cells:
            if cell.cell_type != "code":
                continue
            count += 1
            out, err = _stdio.StringIO(), _stdio.StringIO()
            before = _mtime(saved_figure)
            tree = ast.parse(cell.source)
            last = tree.body.pop() if tree.body and isinstance(tree.body[-1], ast.Expr) else None
            result = None
            try:
                with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
                    exec(compile(tree, f"<{Path(notebook).name} cell {count}>", "exec"), namespace)
                    if last is not None:
                        result = eval(compile(ast.Expression(last.value), f"<{Path(notebook).name} cell {count}>",
                                              "eval"), namespace)
            except Exception as exc:
                cell.outputs = _cell_outputs(nbformat, out.getvalue(), err.getvalue(), None, []) + [
                    nbformat.v4.new_output("error", ename=type(exc).__name__, evalue=str(exc),
                                           traceback=traceback.format_exception(exc))]
                cell.execution_count = count
                raise RuntimeError(f"notebook {notebook}, cell {count} raised {type(exc).__name__}: {exc}") from exc
            pngs = []
            saved_now = _mtime(saved_figure) != before
            for num in plt.get_fignums():
                if saved_now:   # the figure the cell saved: shown as saved, not drawn a second time
                    pngs.append(Path(saved_figure).read_bytes())
                    saved_now = False
                    continue
                buf = _stdio.BytesIO()
                plt.figure(num).savefig(buf, format="png", dpi=72)
                pngs.append(buf.getvalue())
            plt.close("all")
            cell.outputs = _cell_outputs(nbformat, out.getvalue(), err.getvalue(), result, pngs)
            cell.execution_count = count
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
    return nb


def run_notebooks(notebooks: Sequence[str | Path], cube: str | Path, figures: Sequence[str | Path],
                  executed: Sequence[str | Path], log_path: str | Path | None = None) -> list[Path]:
    """Execute figure notebooks against the cube, all in this one process (execute_in_process):
    each saves its figure (`figures`, PNG) and is written with its outputs to `executed`
    (atomically). What the rule `notebook` runs; io.run_notebook runs one in a Jupyter kernel."""
    import time

    lines = []
    done = []
    for notebook, figure, ex in zip(notebooks, figures, executed):
        t0 = time.perf_counter()
        figure = Path(figure).resolve()
        figure.parent.mkdir(parents=True, exist_ok=True)
        figure.unlink(missing_ok=True)
        env = {"SWEEP_CUBE": str(Path(cube).resolve()), "SWEEP_FIGURE": str(figure), "MPLBACKEND": "Agg"}
        nb = execute_in_process(notebook, env)
        _write_notebook(nb, ex)
        if not figure.exists():
            raise RuntimeError(f"notebook {notebook} ran but did not write {figure}")
        lines.append(f"executed {notebook} -> {figure} in {time.perf_counter() - t0:.2f} s")
        done.append(figure)
    if log_path is not None:
        Path(log_path).parent.mkdir(parents=True, exist_ok=True)
        Path(log_path).write_text("\n".join(lines) + "\n", encoding="utf-8")
    return done


def write_plan(path: str | Path, name: str, chunks: Mapping[str, _grid.Chunk], adaptive: Mapping | None = None) -> Path:
    """Write the chunk plan of a run ({name, scenes, chunks: {id: number of scenes}}) as JSON,
    atomically; `sweep.frontdoor` reads it to show scenes done / total. An adaptive map has no
    chunks up front: `adaptive` (sweep.adaptive.plan_info) says where its rounds are, and
    `scenes` is its budget."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    plan = {"name": name, "scenes": sum(len(c.points) for c in chunks.values()),
            "chunks": {cid: len(c.points) for cid, c in chunks.items()}}
    if adaptive is not None:
        plan.update(scenes=int(adaptive["budget"]), adaptive=dict(adaptive))
    return write_text_atomic(path, json.dumps(plan))


def write_text_atomic(path: str | Path, text: str) -> Path:
    """Write a text file atomically (a temporary name in its folder, then os.replace)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.parent / f".{path.name}.tmp-{os.getpid()}-{uuid.uuid4().hex[:8]}"
    try:
        tmp.write_text(text, encoding="utf-8")
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return path


# axis labels of the figures: words, symbol, unit (the sweep axes': sweep.fields)
AXIS_LABELS = {**{a.name: a.label for a in fields.AXES}, "level": "inclination level β (rad)"}


def figure_caption(ds, reduced: str = "median over the axes not shown") -> str:
    """What a figure of the cube `ds` shows, for its top line: the sweep's name, its number of
    scenes and the grid (values per axis), and how the maps reduce the other axes."""
    shape = " × ".join(f"{a} {ds.sizes[a]}" for a in _grid.AXES if a in ds.sizes)
    n = math.prod(ds.sizes[a] for a in _grid.AXES if a in ds.sizes)
    name = ds.attrs.get("sweep_name", "?")
    return f"sweep '{name}': {n} scenes ({shape})" + (f"; {reduced}" if reduced else "")


def panel_title(ax, text: str) -> None:
    """Set a panel's title, wrapped to lines that fit over the panel (its width less the room of a
    colour bar beside it), so the titles of side-by-side panels neither overlap nor get cut."""
    import textwrap

    from matplotlib.font_manager import FontProperties

    import matplotlib as mpl

    size = FontProperties(size=mpl.rcParams["axes.titlesize"]).get_size_in_points()
    width_pt = ax.get_position().width * ax.figure.get_figwidth() * 72.0
    # 0.45 em: a mean character of DejaVu Sans; 0.8: the room a colour bar and the labels take
    chars = max(16, int(0.8 * width_pt / (0.45 * size)))
    ax.set_title("\n".join(textwrap.wrap(text, chars)))


def _text_colour(rgba) -> str:
    """Black on light cells, white on dark ones (relative luminance of the cell colour)."""
    r, g, b = rgba[:3]
    return "k" if 0.2126 * r + 0.7152 * g + 0.0722 * b > 0.45 else "w"


def plot_map(ax, da, label: str, log: bool = False, annotate_max_cells: int = 64,
             vmin: float | None = None, vmax: float | None = None):
    """Draw a 2-D DataArray (dims (y, x)) as a cell map on a matplotlib Axes.

    Cells sit at index positions with the coordinate values as tick labels, so axes of length
    1, unevenly spaced or logarithmic values all display; NaN cells are grey. `vmin`, `vmax`
    fix the colour scale (a fraction: 0 and 1). Grids with at most `annotate_max_cells` cells
    (64: the numbers stay legible) get their values written in, black on light cells and white
    on dark ones. Axis labels name the parameter and its unit (AXIS_LABELS).
    """
    import matplotlib as mpl
    import matplotlib.colors as mcolors

    ydim, xdim = da.dims
    z = np.asarray(da.values, dtype=float)
    finite = z[np.isfinite(z)]
    if log and finite.size and (finite > 0).all():
        norm = mcolors.LogNorm(vmin=vmin or finite.min(), vmax=vmax or max(finite.max(), finite.min() * (1 + 1e-12)))
    else:
        norm = mcolors.Normalize(vmin=vmin, vmax=vmax)
    cmap = mpl.colormaps["viridis"].with_extremes(bad="0.85")
    ny, nx = z.shape
    mesh = ax.pcolormesh(np.arange(nx + 1) - 0.5, np.arange(ny + 1) - 0.5, np.ma.masked_invalid(z),
                         cmap=cmap, norm=norm, shading="flat")
    ax.set_xticks(range(nx), [f"{v:.3g}" for v in da[xdim].values], rotation=45 if nx > 6 else 0)
    ax.set_yticks(range(ny), [f"{v:.3g}" for v in da[ydim].values])
    ax.set_xlabel(AXIS_LABELS.get(xdim, xdim))
    ax.set_ylabel(AXIS_LABELS.get(ydim, ydim))
    if nx * ny <= annotate_max_cells:
        for (j, i), v in np.ndenumerate(z):
            colour = "k" if not np.isfinite(v) else _text_colour(cmap(mesh.norm(v)))
            ax.text(i, j, "NaN" if not np.isfinite(v) else f"{v:.3g}", ha="center", va="center",
                    fontsize=7, color=colour)
    ax.figure.colorbar(mesh, ax=ax, label=label)
    return mesh
