"""The gather: verified chunk files (sweep.verify) into the cube `results/<name>/cube.nc`, with the
dimensions (mu_d, k1, k2, k3, alpha0, omega0[, level]) and CF-1.10 metadata (sweep.cf), written
atomically (sweep.atomic) and block by block, so its memory stays a few blocks whatever the number
of chunk files or scenes.
"""
from __future__ import annotations

import logging
import math
import shutil
import tempfile
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from . import axes as _axes
from . import chunking as _chunking
from . import grid as _grid
from . import outcomes
from .atomic import write_atomic
from .cf import INT_FILL, cube_attrs, cube_chunksizes, cube_coords, var_attrs, variable_encoding, variables
from .verify import quarantine, read_chunk_file


log = logging.getLogger("sweep.gather")


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
    plan_ids = set(_chunking.plan_chunks(settings))   # the ids only: the plan's spec texts are not kept
    axes = _axes.AXES
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
            data_vars[var.name] = (dims, arr, var_attrs(var))
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
