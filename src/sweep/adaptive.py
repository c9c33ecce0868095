"""Adaptive maps in the pipeline: rounds of scenes chosen by sweep.refine, the full-lattice cube,
the map figure.

A config with a `refine:` section is a set of *maps*: every combination of the `grid:` values of
the other axes (the map's *outer point*) gets the lattice of `refine.axes`. Each map runs rounds
0..R (R: sweep.lattice.Lattice.rounds), one Snakemake job per (map, round), chained by their round
files `results/<name>/rounds/<map>/round<k>.json`. A round job plans its nodes from the chunk files
of the earlier rounds (sweep.refine.plan_round, deterministic), cuts them into chunks of equal size
(round_blocks) named by their content as the tensor sweep's (sweep.chunking.chunk_id_of), runs the
chunks that are not on disk yet with the tensor sweep's runner (sweep.batch.run_chunk, one process
per thread, the largest chunks first) and writes its
round file last, atomically. So a killed round resumes from its finished chunks, and a rerun of a
finished map finds every round file and does nothing.

Units: SI, as the rest of the package.
"""
from __future__ import annotations

import concurrent.futures
import itertools
import json
import logging
import math
import multiprocessing
import os
import time
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from . import atomic as _atomic
from . import axes as _axes
from . import cf as _cf
from . import chunking as _chunking
from . import figures as _figures
from . import grid as _grid
from . import lattice as _lattice
from . import outcomes
from . import reconstruct as _reconstruct
from . import refine as _refine
from . import verify as _verify

log = logging.getLogger("sweep.adaptive")

ROUNDS_DIR = "rounds"
# Units of the outputs interpolated in log (positive times and frequencies).
LOG_UNITS = ("s", "Hz")
INTERP_SUFFIX = "_interpolation_error"


# ------------------------------------------------------------------------------------------ maps

def lattice(settings: Mapping) -> _lattice.Lattice:
    ref = settings["refine"]
    return _lattice.make_lattice(ref["axes"], ref["start_points"])


def budget(settings: Mapping, lat: _lattice.Lattice | None = None) -> int:
    """Computed scenes at most per map: floor(max_share x lattice size)."""
    lat = lat or lattice(settings)
    return math.floor(settings["refine"]["max_share"] * lat.size)


def outer_axes(settings: Mapping) -> tuple[str, ...]:
    return tuple(a for a in _axes.AXES if a not in settings["refine"]["axes"])


def maps(settings: Mapping) -> dict[str, dict[str, float]]:
    """Every map of an adaptive config: {map id: its outer point {axis: value}}, in grid order.
    The id is a digest of the outer point and the settings that decide the map's nodes, so a
    changed map never reuses another's round files."""
    outer = outer_axes(settings)
    key = {k: settings[k] for k in ("refine", "disk", "gravity", "mu_s", "levels", "solver", "stop", "chunk_size")}
    out = {}
    for vals in itertools.product(*(settings["grid"][a] for a in outer)):
        point = dict(zip(outer, vals))
        digest = _chunking.sha256_hex(_chunking.canonical_json({"outer": point, "settings": key}))[:12]
        out[f"map-{digest}"] = point
    return out


def map_label(point: Mapping[str, float]) -> str:
    return ", ".join(f"{a} {v:.4g}" for a, v in point.items())


def plan_info(settings: Mapping, results: str | Path) -> dict:
    """What the front door needs of an adaptive run (results/<name>/plan.json `adaptive`): the
    maps and their labels, the rounds, the budget of scenes over all maps."""
    lat = lattice(settings)
    ms = maps(settings)
    return {"maps": {m: map_label(p) for m, p in ms.items()}, "rounds": lat.rounds, "lattice": lat.size,
            "budget": budget(settings, lat) * len(ms), "rounds_dir": str(Path(results) / ROUNDS_DIR)}


def round_path(results: str | Path, map_id: str, k: int) -> Path:
    return Path(results) / ROUNDS_DIR / map_id / f"round{k}.json"


def _components(settings: Mapping) -> tuple[dict[str, int], dict[str, bool]]:
    """The continuous outputs (float variables of the cube): {name: components (1, or levels)},
    {name: interpolated in log}."""
    n_levels = len(settings["levels"])
    comps, logs = {}, {}
    for var in _cf.variables(bool(settings.get("outputs", {}).get("error_estimate", False))):
        if var.kind == "float":
            comps[var.name] = n_levels if var.per_level else 1
            logs[var.name] = var.units in LOG_UNITS
    return comps, logs


def refine_settings(settings: Mapping, lat: _lattice.Lattice) -> _lattice.Settings:
    ref = settings["refine"]
    return _lattice.Settings(tuple(ref["outputs"]), float(ref["tolerance"]), budget(settings, lat))


# ----------------------------------------------------------------------------------- chunk files

def read_chunk(path: str | Path, names: Sequence[str]) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """(points (n, 6) in AXES order, {name: raw values (n, ...)}) of a chunk file (no masking:
    count fills stay -1, float fills are NaN)."""
    import netCDF4

    with netCDF4.Dataset(path, "r") as nc:
        nc.set_auto_mask(False)
        pts = np.stack([np.asarray(nc.variables[a][:], dtype=np.float64) for a in _axes.AXES], axis=1)
        vals = {n: np.asarray(nc.variables[n][:]) for n in names}
    return pts, vals


def _nodes_of(lat: _lattice.Lattice, pts: np.ndarray) -> np.ndarray:
    """Lattice nodes of chunk points (exact values: the points were made from the lattice)."""
    out = np.zeros((len(pts), lat.ndim), np.int64)
    for i, a in enumerate(lat.axes):
        index = {float(v): j for j, v in enumerate(lat.values[i])}
        col = pts[:, _axes.AXES.index(a)]
        try:
            out[:, i] = [index[float(v)] for v in col]
        except KeyError as exc:
            raise RuntimeError(f"a chunk holds {a} = {exc.args[0]!r}, not on the map's lattice") from None
    return out


class MapState:
    """What is known of one map after some rounds: sweep.lattice.Fields and every variable's raw
    values at the computed nodes (for the categorical ones of the cube)."""

    def __init__(self, settings: Mapping):
        self.settings = settings
        self.lat = lattice(settings)
        comps, logs = _components(settings)
        self.fields = _lattice.Fields.empty(self.lat, comps, logs)
        self.vars = _cf.variables(bool(settings.get("outputs", {}).get("error_estimate", False)))
        self.raw: dict[str, np.ndarray] = {}

    def add_chunks(self, paths: Sequence[str | Path], rnd: int) -> None:
        names = [v.name for v in self.vars]
        for p in paths:
            pts, vals = read_chunk(p, names)
            nodes = _nodes_of(self.lat, pts)
            idx = _lattice.flat_index(self.lat, nodes)
            for name, v in vals.items():
                if name not in self.raw:
                    self.raw[name] = np.zeros((self.lat.size,) + v.shape[1:], dtype=v.dtype)
                self.raw[name][idx] = v
            self.fields.set(self.lat, nodes, rnd, vals["outcome"].astype(np.int64),
                            {k: vals[k] for k in self.fields.values})


# A round's nodes are cut into at least ROUND_CHUNKS chunks of equal size (where that leaves
# ROUND_CHUNK_MIN scenes a chunk), so that its processes share it evenly: a round has one plan, so
# the tensor sweep's content-defined cut (stable under inserted points) buys nothing here, and on
# issue #52's plane it cut round 0's 81 scenes into chunks of 80 and 1, one process doing all.
ROUND_CHUNKS = 8
ROUND_CHUNK_MIN = 8


def round_blocks(nodes: np.ndarray, chunk_size: int) -> list[np.ndarray]:
    """A round's nodes (lexicographic) cut into consecutive blocks of equal size (+-1): as many as
    chunk_size asks, at least ROUND_CHUNKS where each keeps ROUND_CHUNK_MIN nodes."""
    n = len(nodes)
    if not n:
        return []
    k = max(math.ceil(n / chunk_size), min(ROUND_CHUNKS, n // ROUND_CHUNK_MIN), 1)
    cuts = np.round(np.linspace(0, n, k + 1)).astype(int)
    return [nodes[a:b] for a, b in zip(cuts[:-1], cuts[1:])]


def chunks_of(settings: Mapping, outer: Mapping[str, float], lat: _lattice.Lattice,
              blocks: Sequence[np.ndarray]) -> list[_chunking.Chunk]:
    """One chunk per block of nodes: the points in AXES order, named by their content
    (sweep.chunking.chunk_id_of), as the tensor sweep's."""
    part = _chunking.scene_settings(settings)
    core = _chunking.core_fingerprint()
    chunks = []
    for block in blocks:
        points = []
        for node in block:
            full = dict(outer, **dict(zip(lat.axes, lat.point(node))))
            points.append(tuple(float(full[a]) for a in _axes.AXES))
        cid, text = _chunking.chunk_id_of(part, points, core)
        chunks.append(_chunking.Chunk(cid, tuple(points), text))
    return chunks


def chunks_of_round(settings: Mapping, outer: Mapping[str, float], lat: _lattice.Lattice,
                    nodes: np.ndarray) -> list[_chunking.Chunk]:
    """The chunks of a round's nodes (round_blocks, chunks_of)."""
    return chunks_of(settings, outer, lat, round_blocks(np.asarray(nodes), settings["chunk_size"]))


def _run_one(spec_json: str, out_path: str) -> dict:
    from . import batch

    return batch.run_chunk(batch.chunk_from_spec(spec_json), out_path)


def run_chunks(chunks: Sequence[_chunking.Chunk], chunk_dir: Path, threads: int) -> int:
    """Run the chunks whose file is missing or damaged (quarantined first), `threads` processes
    at a time (each loads the kernels once); returns how many ran."""
    todo = []
    for c in chunks:
        p = chunk_dir / f"{c.id}.nc"
        if p.exists():
            reason = _verify.verify_chunk(p, c)
            if reason is None:
                continue
            _verify.quarantine(p, reason)
            log.warning("chunk %s is damaged (%s): quarantined, recomputed", c.id, reason)
        todo.append(c)
    chunk_dir.mkdir(parents=True, exist_ok=True)
    if threads <= 1 or len(todo) <= 1:
        for c in todo:
            _run_one(c.spec_json, str(chunk_dir / f"{c.id}.nc"))
        return len(todo)
    # the largest chunks first, so the last to finish is a small one
    todo.sort(key=lambda c: -len(c.points))
    ctx = multiprocessing.get_context("fork" if os.name == "posix" else "spawn")
    with concurrent.futures.ProcessPoolExecutor(max_workers=min(threads, len(todo)), mp_context=ctx) as pool:
        futures = [pool.submit(_run_one, c.spec_json, str(chunk_dir / f"{c.id}.nc")) for c in todo]
        for fut in futures:
            fut.result()
    return len(todo)


# ----------------------------------------------------------------------------------- round jobs

def chunk_problem(path: Path, cid: str) -> str | None:
    """Why the chunk file of a finished round cannot be read as it is (missing, damaged, another
    chunk's), or None."""
    if not path.exists():
        return "missing"
    return _verify.read_chunk_file(path, expect_id=cid)[0]


def stale_chunks(settings: Mapping, results: str | Path) -> dict[str, str]:
    """{chunk path: problem} over the chunk files named by the round files on disk: what a
    finished round needs again (the front door's check before Snakemake decides what to run)."""
    out = {}
    rdir = Path(results) / ROUNDS_DIR
    for map_id in maps(settings):
        for rfile in sorted((rdir / map_id).glob("round*.json")):
            try:
                rec = json.loads(rfile.read_text(encoding="utf-8"))
            except (OSError, ValueError):
                continue
            for cid in rec.get("chunks", []):
                p = Path(results) / "chunks" / f"{cid}.nc"
                why = chunk_problem(p, cid)
                if why is not None:
                    out[str(p)] = why
    return out


def load_rounds(settings: Mapping, results: str | Path, map_id: str, upto: int,
                threads: int = 1) -> tuple[MapState, list[dict]]:
    """The map's state after rounds 0..upto-1, from their round files and chunk files. A chunk
    file of a finished round that is missing or damaged is computed again (damaged ones
    quarantined first): the round is planned again from the rounds before it, which gives the
    same chunks (deterministic; checked against the round file), and only those run."""
    results = Path(results)
    state = MapState(settings)
    records = []
    for j in range(upto):
        rec = json.loads(round_path(results, map_id, j).read_text(encoding="utf-8"))
        paths = [results / "chunks" / f"{cid}.nc" for cid in rec["chunks"]]
        bad = {p.name: why for p, cid in zip(paths, rec["chunks"]) if (why := chunk_problem(p, cid)) is not None}
        if bad:
            st = refine_settings(settings, state.lat)
            plan = _refine.plan_round(state.lat, state.fields, st, j)
            chunks = chunks_of_round(settings, maps(settings)[map_id], state.lat, plan.nodes)
            if [c.id for c in chunks] != list(rec["chunks"]):
                raise RuntimeError(f"{round_path(results, map_id, j)} names other chunks than its round plans now "
                                   "(a round file from other settings or code?): delete it and rerun")
            log.warning("map %s round %d: %d chunk file(s) to compute again (%s)", map_id, j, len(bad),
                        ", ".join(f"{n}: {w}" for n, w in sorted(bad.items())))
            run_chunks(chunks, results / "chunks", threads)
        state.add_chunks(paths, j)
        records.append(rec)
    return state, records


def round_line(name: str, label: str, rec: Mapping) -> str:
    """The progress line of a finished round (printed by the front door and the round's log)."""
    nxt = rec.get("next") or {}
    still = (f"still flagged {nxt['outcome']} outcome / {nxt['failed']} failed / {nxt['error']} error cells"
             if nxt else "no round left")
    # after the last round: the rough cells of the finished map
    rough = nxt["rough"] if nxt else rec.get("rough_final", 0)
    hold = f", {rec['holdout']} of them the hold-out" if rec.get("holdout") else ""
    return (f"sweep {name}: map {label}: round {rec['round']}/{rec['rounds']}: {rec['scenes']} scenes{hold} "
            f"({rec['computed']} of {rec['lattice']}, {100 * rec['share']:.1f} %, budget "
            f"{100 * rec['max_share']:.0f} %); {still}; rough {rough} cells")


def run_round(settings: Mapping, map_id: str, k: int, results: str | Path, out_path: str | Path,
              threads: int = 1, name: str = "") -> dict:
    """Snakemake job `refine_round`: plan round k of map `map_id`, run its missing chunks, write
    its round file (atomically, last). Returns the round's record."""
    results = Path(results)
    outer = maps(settings)[map_id]
    state, _ = load_rounds(settings, results, map_id, k, threads)
    lat, st = state.lat, refine_settings(settings, state.lat)
    t0 = time.perf_counter()
    plan = _refine.plan_round(lat, state.fields, st, k)
    chunks = chunks_of_round(settings, outer, lat, plan.nodes)
    ran = run_chunks(chunks, results / "chunks", threads)
    state.add_chunks([results / "chunks" / f"{c.id}.nc" for c in chunks], k)
    nxt = _refine.plan_round(lat, state.fields, st, k + 1) if k < lat.rounds else None
    computed = int(state.fields.computed.sum())
    rec = {
        "round": k, "rounds": lat.rounds, "map": outer, "scenes": int(len(plan.nodes)),
        "holdout": int(len(plan.holdout)), "chunks": [c.id for c in chunks], "chunks_run": ran, "computed": computed, "lattice": lat.size,
        "share": computed / lat.size, "max_share": settings["refine"]["max_share"],
        "planned_from": {"flagged": plan.flagged, "refined": plan.refined, "skipped": plan.skipped,
                         "rough": plan.rough},
        "next": ({**nxt.flagged, "rough": nxt.rough, "skipped": nxt.skipped, "scenes": int(len(nxt.nodes))}
                 if nxt is not None else None),
        "seconds": round(time.perf_counter() - t0, 3),
    }
    if nxt is None:
        rec["rough_final"] = _refine.rough_leaves(lat, state.fields, st)
    rec["line"] = round_line(name, map_label(outer), rec)
    log.info("%s", rec["line"])
    _atomic.write_text_atomic(out_path, json.dumps(rec, indent=1))
    return rec


# ------------------------------------------------------------------------------------ the cube

def interpolation_error_attrs(var) -> dict:
    return {"units": var.units,
            "long_name": f"{var.long_name}: interpolation error bar (absolute; 0 where computed; NaN where "
                         "there is no value; the true value lies within it at >= 90 % of reconstructed nodes, "
                         "docs/pipeline.md 'Adaptive maps')"}


def gather(settings: Mapping, results: str | Path, out_path: str | Path, repo_path: str | Path | None = None,
           name: str | None = None) -> Path:
    """Every map's rounds -> the cube on the full lattice (atomic write): computed nodes with their
    values, the others reconstructed (sweep.reconstruct.reconstruct), with `computed`, `round`, `rough`
    `holdout` and `<X>_interpolation_error` for every continuous output X."""
    import xarray as xr

    results = Path(results)
    shape = _grid.grid_shape(settings)
    n_levels = len(settings["levels"])
    n = math.prod(shape)
    index = _grid.grid_index(settings)
    vars_ = _cf.variables(bool(settings.get("outputs", {}).get("error_estimate", False)))
    comps, _ = _components(settings)
    data = {v.name: None for v in vars_}
    bars = {k: np.full((n, m), np.nan) for k, m in comps.items()}
    computed = np.zeros(n, np.int8)
    rnd = np.full(n, -1, np.int8)
    rough = np.zeros(n, np.int8)
    holdout = np.zeros(n, np.int8)
    n_files = 0
    lat = lattice(settings)
    for map_id, outer in maps(settings).items():
        state, records = load_rounds(settings, results, map_id, lat.rounds + 1)
        n_files += sum(len(r["chunks"]) for r in records)
        m = _reconstruct.reconstruct(lat, state.fields, refine_settings(settings, lat))
        nodes = np.array(np.unravel_index(np.arange(lat.size), lat.shape)).T
        full = [np.full(lat.size, index[a][outer[a]]) if a in outer else nodes[:, lat.axes.index(a)]
                for a in _axes.AXES]
        pos = np.ravel_multi_index(tuple(full), shape)
        for v in vars_:
            raw = state.raw[v.name]
            if data[v.name] is None:
                data[v.name] = np.zeros((n,) + raw.shape[1:], dtype=raw.dtype)
                if v.kind == "float":
                    data[v.name][:] = np.nan
            if v.kind == "float":
                data[v.name][pos] = m.values[v.name].reshape((lat.size,) + raw.shape[1:])
                bars[v.name][pos] = m.bars[v.name]
            elif v.kind == "outcome":
                data[v.name][pos] = m.outcome
            elif v.kind == "bool":
                data[v.name] = data[v.name].astype(bool)
                data[v.name][pos] = raw[m.source].astype(bool)
            else:
                data[v.name][pos] = raw[m.source]
        computed[pos] = state.fields.computed
        rnd[pos] = state.fields.round
        rough[pos] = m.rough
        if m.holdout is not None:
            holdout[pos] = m.holdout
    csizes = _cf.cube_chunksizes(shape + (n_levels,))
    axes = _axes.AXES
    data_vars, encoding = {}, {}
    for v in vars_:
        per = v.per_level
        full_shape = shape + ((n_levels,) if per else ())
        dims = axes + (("level",) if per else ())
        cs = csizes if per else csizes[:-1]
        data_vars[v.name] = (dims, data[v.name].reshape(full_shape), _cf.var_attrs(v))
        encoding[v.name] = _cf.variable_encoding(v.kind, cs)
        if v.kind == "float":
            key = v.name + INTERP_SUFFIX
            data_vars[key] = (dims, bars[v.name].reshape(full_shape), interpolation_error_attrs(v))
            encoding[key] = _cf.variable_encoding("float", cs)
    flag = {"flag_values": np.array([0, 1], np.int8)}
    data_vars["computed"] = (axes, computed.reshape(shape), {
        "units": "1", "long_name": "whether the node's scene was computed (1) or its values reconstructed (0)",
        **flag, "flag_meanings": "reconstructed computed"})
    data_vars["round"] = (axes, rnd.reshape(shape), {
        "units": "1", "long_name": "the refinement round that computed the node (-1: reconstructed)"})
    data_vars["rough"] = (axes, rough.reshape(shape), {
        "units": "1", "long_name": "reconstructed in a rough cell: its error did not fall as the cells shrank "
                                   "(structure finer than the lattice); its error bars are those of the loud nodes", **flag,
        "flag_meanings": "smooth_or_computed rough"})
    data_vars["holdout"] = (axes, holdout.reshape(shape), {
        "units": "1", "long_name": "computed as the last round's hold-out: a random test of the reconstruction "
                                   "that calibrates the error bars, not interpolated from", **flag,
        "flag_meanings": "not_holdout holdout"})
    for key in ("computed", "rough", "holdout"):
        encoding[key] = _cf.variable_encoding("flag", csizes[:-1])
    encoding["round"] = {"dtype": "int8", "_FillValue": None, "zlib": True, "complevel": _cf.COMPLEVEL,
                         "shuffle": True, "chunksizes": csizes[:-1]}
    coords = _cf.cube_coords(settings)
    for c in coords:
        encoding[c] = {"_FillValue": None}
    n_maps = len(maps(settings))
    attrs = _cf.cube_attrs(settings, name, f"adaptive map: {n_maps} map(s) of {lat.size} nodes, "
                           f"{int(computed.sum())} computed in {lat.rounds + 1} rounds ({n_files} chunk files), "
                           "the rest reconstructed", repo_path)
    attrs["sweep_refine"] = _chunking.canonical_json(settings["refine"])
    cube = xr.Dataset(data_vars, coords=coords, attrs=attrs)
    return _atomic.write_atomic(cube, out_path, encoding)


# ----------------------------------------------------------------------------------- the figure

def map_figure(cube_path: str | Path, figure: str | Path, max_maps: int = 4) -> Path:
    """The outcome map and the t_halt map of each map (up to `max_maps`; a 3-axis map: its middle
    slice on the last axis), with the computed nodes drawn over them and the rough cells hatched."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.colors as mcolors
    import matplotlib.pyplot as plt
    import xarray as xr

    with xr.open_dataset(cube_path) as ds:
        ref = json.loads(ds.attrs["sweep_refine"])
        axes = list(ref["axes"])
        xdim, ydim = axes[-1], axes[0]
        outer = [a for a in _axes.AXES if a not in axes]
        combos = list(itertools.product(*(range(ds.sizes[a]) for a in outer)))[:max_maps]
        fig, grid_axes = plt.subplots(len(combos), 2, figsize=(13, 5.2 * len(combos)), squeeze=False,
                                      constrained_layout=True)
        codes = list(outcomes.FLAG_VALUES)
        cmap = matplotlib.colormaps["tab10"].resampled(len(codes))
        for row, combo in zip(grid_axes, combos):
            sel = dict(zip(outer, combo))
            sub = ds.isel(sel)
            if len(axes) == 3:
                sub = sub.isel({axes[1]: sub.sizes[axes[1]] // 2})
            sub = sub.transpose(ydim, xdim, ...)
            x, y = sub[xdim].values, sub[ydim].values
            logx = ref["axes"][xdim].get("spacing") == "log"
            logy = ref["axes"][ydim].get("spacing") == "log"
            oc = sub.outcome.values.astype(float)
            present = [c for c in codes if (oc == c).any()]
            ax = row[0]
            ax.pcolormesh(x, y, oc, cmap=cmap, norm=mcolors.BoundaryNorm(np.arange(len(codes) + 1) - 0.5, len(codes)),
                          shading="nearest")
            handles = [matplotlib.patches.Patch(color=cmap(c), label=outcomes.NAMES[c]) for c in present]
            ax.legend(handles=handles, loc="upper left", fontsize=8, framealpha=0.8)
            ax.set_title(f"outcome ({', '.join(f'{a} {float(ds[a][i]):.4g}' for a, i in sel.items())})", fontsize=9)
            t = sub.t_halt.where(sub.outcome == outcomes.HALTED).values
            ax2 = row[1]
            finite = t[np.isfinite(t) & (t > 0)]
            norm = mcolors.LogNorm(finite.min(), finite.max()) if finite.size else None
            mesh = ax2.pcolormesh(x, y, np.ma.masked_invalid(t), norm=norm, shading="nearest",
                                  cmap=matplotlib.colormaps["viridis"].with_extremes(bad="0.85"))
            fig.colorbar(mesh, ax=ax2, label="halt time t_halt (s), halted scenes")
            bar = sub.t_halt_interpolation_error.where(sub.outcome == outcomes.HALTED).values
            rec = (sub.computed.values == 0) & np.isfinite(t) & (t > 0)
            med = float(np.nanmedian(bar[rec] / t[rec])) if rec.any() else math.nan
            ax2.set_title(f"t_halt; median interpolation error bar {100 * med:.2g} % of the value "
                          f"(reconstructed halted nodes)", fontsize=9)
            yy, xx = np.nonzero(sub.computed.values == 1)
            rough = sub.rough.values == 1
            # a computed node inside a rough region is drawn with it (the flag marks reconstructed nodes)
            near = np.zeros_like(rough)
            near[1:, :] |= rough[:-1, :]
            near[:-1, :] |= rough[1:, :]
            near[:, 1:] |= rough[:, :-1]
            near[:, :-1] |= rough[:, 1:]
            rough = rough | ((sub.computed.values == 1) & near)
            for a in (ax, ax2):
                a.scatter(x[xx], y[yy], s=7, c="k", marker="o", linewidths=0, label="computed")
                if rough.any():
                    a.contourf(x, y, rough.astype(float), levels=[0.5, 1.5], colors="none", hatches=["////"])
                    a.contour(x, y, rough.astype(float), levels=[0.5], colors="r", linewidths=0.8)
                a.set_xscale("log" if logx else "linear")
                a.set_yscale("log" if logy else "linear")
                a.set_xlabel(_figures.AXIS_LABELS.get(xdim, xdim))
                a.set_ylabel(_figures.AXIS_LABELS.get(ydim, ydim))
        n_comp = int(ds.computed.sum())
        n_all = int(ds.computed.size)
        fig.suptitle(f"sweep '{ds.attrs.get('sweep_name', '?')}': adaptive map, {n_comp} of {n_all} nodes computed "
                     f"({100 * n_comp / n_all:.1f} %; black dots); red hatching: rough cells (the error did "
                     "not fall as the cells shrank)", fontsize=10)
    figure = Path(figure)
    figure.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(figure, dpi=110)
    plt.close(fig)
    return figure
