"""Chunk files (`results/<name>/chunks/<id>.nc`): one row per scene along the dimension `point`
(coordinates mu_d, k1, k2, k3, alpha0, omega0 per point, SI units) and the dimension `level`, CF
metadata from sweep.cf. Their global attribute `sweep_checksum` is a SHA-256 over every variable's
values (`checksum_of`), so a truncated or damaged file is detected before it is gathered
(sweep.verify). Written atomically (sweep.atomic) with netCDF4 alone. Also the run's chunk plan
(`write_plan`, results/<name>/plan.json).
"""
from __future__ import annotations

import hashlib
import json
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from . import axes as _axes
from . import chunking as _chunking
from . import reasons
from .atomic import write_file_atomic, write_text_atomic
from .cf import INT_FILL, LEVEL_ATTRS, VARIABLE_NAMES, coord_attrs, var_attrs, variables
from .outputs import CHUNK_FORMAT, VARIABLES, Var


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


def file_checksum(path: str | Path) -> str:
    """SHA-256 over every variable's name, shape and stored values of a netCDF file.

    Values are taken raw (no masking or scaling, so count fills stay -1), as float64 with one
    bit pattern for every NaN, in name order; attributes are not covered.
    """
    import netCDF4

    with netCDF4.Dataset(path, "r") as nc:
        nc.set_auto_maskandscale(False)
        return checksum_of({name: np.asarray(v[...]) for name, v in nc.variables.items()})


def chunk_content(chunk: _chunking.Chunk, summaries: Sequence[Mapping]) -> tuple[dict, dict, dict]:
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
    pts = np.array(chunk.points, dtype=np.float64).reshape(len(chunk.points), len(_axes.AXES))
    coords = {a: (("point",), pts[:, i], coord_attrs(a)) for i, a in enumerate(_axes.AXES)}
    coords["level"] = (("level",), np.array(levels, dtype=np.float64), dict(LEVEL_ATTRS))
    summaries = [reasons.add_flags(s) for s in summaries]   # why each missing value is missing
    data = {}
    for var in variables(bool(spec["settings"].get("error_estimate", False))):
        dims = ("point", "level") if var.per_level else ("point",)
        data[var.name] = (dims, _column(var, summaries, len(levels)), var_attrs(var))
    from . import __version__
    attrs = {"Conventions": "CF-1.10", "title": "Euler's disk sweep chunk",
             "sweep_chunk_id": chunk.id, "sweep_chunk_spec": chunk.spec_json,
             "sweep_chunk_format": CHUNK_FORMAT, "sweep_version": __version__}
    return coords, data, attrs


def chunk_dataset(chunk: _chunking.Chunk, summaries: Sequence[Mapping]):
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
        nc.createDimension("point", len(coords[_axes.AXES[0]][1]))
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
        nc.setncattr("sweep_checksum", checksum_of(stored))
    return stored


def write_chunk(chunk: _chunking.Chunk, summaries: Sequence[Mapping], path: str | Path) -> Path:
    """Write a chunk file atomically, with the checksum of its content as `sweep_checksum`."""
    coords, data, attrs = chunk_content(chunk, summaries)
    return write_file_atomic(path, lambda tmp: _write_chunk_nc(tmp, coords, data, attrs))


def checksum_of(arrays: Mapping[str, np.ndarray]) -> str:
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


def write_plan(path: str | Path, name: str, chunks: Mapping[str, _chunking.Chunk],
               adaptive: Mapping | None = None) -> Path:
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
