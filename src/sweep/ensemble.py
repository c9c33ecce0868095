"""Many scenes at once: `simulate_batch(scenes, device="cpu"|"cuda") -> [summary, ...]`.

Each summary equals `sweep.simulate(scene).summary` (the batch runs the same numba kernels:
core.ensemble.solve_scene calls core.integrate.run and core.ensemble.summary_fits). Only the summary
is returned: no samples, trajectory or peak list (use `sweep.simulate` for those).

device="cpu": worker threads (all cores by default), each with its own buffers, take the next scene
when theirs ends; the kernel releases the GIL, so the threads run in parallel.
device="cuda": one batch call of the persistent-thread kernel of sweep.gpu (numba-cuda, imported
only here and only then; a machine without a GPU fails at once with the reason).

The kernel outputs per scene (statistics, level records, end state and the fitted halt time and
exponents, all computed on the device) become the SI summary dict in Python (`simulate.summary_from`,
unit scaling only: ~20 us per scene).
"""
from __future__ import annotations

import logging
import math
import os
import threading
import time
from collections.abc import Iterable, Mapping

import numpy as np

from . import outcomes
from .core.ensemble import MAX_LEVELS, N_DERIVED, BatchInputs, BatchOutputs, solve_index, work_buffers
from .core.layout import I_OVERFLOW, LEVEL_COLS, N_FSTATS, N_ISTATS, N_SETTINGS
from .core.model import N_FULL, N_PARAMS
from .errors import ConfigError
from .scene import Scene, load_scene
from .simulate import _settings, initial_state, level_energies, simulate, summary_from

log = logging.getLogger("sweep.ensemble")

DEVICES = ("cpu", "cuda")


def _workers_default() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:   # not on Linux
        return os.cpu_count() or 1


class Batch:
    """The kernel's input and output arrays of a list of validated scenes (one row each)."""

    def __init__(self, scenes: list[Scene]):
        n = len(scenes)
        self.scenes = scenes
        self.Y0 = np.zeros((n, N_FULL))
        self.P = np.zeros((n, N_PARAMS))
        self.S = np.zeros((n, N_SETTINGS))
        self.LE = np.full((n, MAX_LEVELS), np.nan)
        self.LV = np.full((n, MAX_LEVELS), np.nan)
        self.NL = np.zeros(n, np.int64)
        self.CHI = np.zeros(n)
        for i, sc in enumerate(scenes):
            y0, _ = initial_state(sc)
            self.Y0[i, :y0.shape[0]] = y0
            self.P[i] = sc.params
            self.S[i] = _settings(sc)
            le = level_energies(sc)
            self.LE[i, :le.shape[0]] = le
            self.LV[i, :le.shape[0]] = np.asarray(sc.levels, dtype=float)
            self.NL[i] = le.shape[0]
            self.CHI[i] = sc.chi
        # warps of alike scenes: sorted by parameters, then the initial state (costs follow them)
        keys = [self.Y0[:, j] for j in range(N_FULL - 1, -1, -1)] + [self.P[:, j] for j in range(N_PARAMS - 1, -1, -1)]
        self.order = np.lexsort(keys).astype(np.int64) if n else np.zeros(0, np.int64)
        self.ISTATS = np.zeros((n, N_ISTATS), np.int64)
        self.FSTATS = np.zeros((n, N_FSTATS))
        self.LEV = np.full((n, MAX_LEVELS, LEVEL_COLS), np.nan)
        self.YEND = np.zeros((n, N_FULL))
        self.DER = np.full((n, N_DERIVED), np.nan)
        self.wall = np.zeros(n)

    @property
    def inputs(self) -> BatchInputs:
        return BatchInputs(self.Y0, self.P, self.S, self.LE, self.LV, self.NL, self.CHI)

    @property
    def outputs(self) -> BatchOutputs:
        return BatchOutputs(self.ISTATS, self.FSTATS, self.LEV, self.YEND, self.DER)

    def summary(self, i: int) -> dict:
        nl = int(self.NL[i])
        return summary_from(self.scenes[i], self.ISTATS[i], self.FSTATS[i], self.LEV[i, :nl], self.YEND[i],
                            float(self.wall[i]), self.DER[i])


def run_cpu(batch: Batch, workers: int) -> dict:
    """Integrate the batch on `workers` threads (dynamic: the next scene goes to the free thread)."""
    n = len(batch.scenes)
    lock = threading.Lock()
    nxt = [0]
    errors: dict[int, BaseException] = {}

    def worker():
        bufs = work_buffers()
        inputs, outputs = batch.inputs, batch.outputs
        while True:
            with lock:
                k = nxt[0]
                nxt[0] += 1
            if k >= n:
                return
            i = int(batch.order[k])
            t0 = time.perf_counter()
            try:
                solve_index(i, inputs, outputs, bufs)
            except Exception as exc:  # noqa: BLE001  (numba raises e.g. ZeroDivisionError; rerun per scene)
                errors[i] = exc
            batch.wall[i] = time.perf_counter() - t0

    workers = max(1, min(workers, n))
    t0 = time.perf_counter()
    if workers == 1:
        worker()
    else:
        threads = [threading.Thread(target=worker, name=f"sweep-batch-{j}", daemon=True) for j in range(workers)]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
    return {"device": "cpu", "workers": workers, "seconds": time.perf_counter() - t0, "errors": errors}


def _load(scene) -> Scene:
    return scene if isinstance(scene, Scene) else load_scene(scene)


def simulate_batch(scenes: Iterable, device: str = "cpu", workers: int | None = None,
                   stats: dict | None = None) -> list[dict]:
    """Summaries of many scenes, each equal to `sweep.simulate(scene).summary` (wall_time aside).

    scenes: scene files or dicts (validated as by `sweep.simulate`, ConfigError before any work) or
    Scene objects. device: "cpu" (threads; `workers`, default all cores) or "cuda" (one GPU; fails at
    once with CudaUnavailableError where there is none). stats: a dict to receive what the run did
    (device, workers or the launch shape, seconds, registers and local memory per thread on CUDA).

    wall_time of a summary: that scene's integration time on the CPU; on CUDA the batch's GPU time
    divided by the number of scenes. A scene whose kernel run raised (or whose look-back outgrew the
    peak ring, or that has more than MAX_LEVELS levels) is run with `sweep.simulate` instead; if that
    raises too, its summary is outcome numerical_error with NaNs, as in the pipeline.
    """
    if device not in DEVICES:
        raise ConfigError("device", device, "'cpu' or 'cuda'")
    if device == "cuda":
        from . import gpu
        gpu.require_cuda()   # at once, before validating or packing anything
    if workers is not None and (isinstance(workers, bool) or not isinstance(workers, int) or workers < 1):
        raise ConfigError("workers", workers, "an integer >= 1 (CPU threads)")
    scs = [_load(s) for s in scenes]
    if not scs:
        return []
    in_batch = [i for i, sc in enumerate(scs) if len(sc.levels) <= MAX_LEVELS]
    batch = Batch([scs[i] for i in in_batch])
    if device == "cpu":
        info = run_cpu(batch, workers or _workers_default())
    else:
        from . import gpu
        info = dict(gpu.run_cuda(batch.order, *batch.inputs, batch.outputs), device="cuda", errors={})
        info["seconds"] = info["gpu_seconds"]
        batch.wall[:] = info["gpu_seconds"] / max(len(batch.scenes), 1)
    out: list[dict | None] = [None] * len(scs)
    inb = set(in_batch)
    rerun = [i for i in range(len(scs)) if i not in inb]
    for j, i in enumerate(in_batch):
        if j in info["errors"] or batch.ISTATS[j, I_OVERFLOW] != 0:
            rerun.append(i)
        else:
            out[i] = batch.summary(j)
    for i in sorted(rerun):
        out[i] = _simulate_or_error(scs[i])
    if stats is not None:
        stats.update({k: v for k, v in info.items() if k != "errors"})
        stats.update(n=len(scs), batch=len(in_batch), reruns=len(rerun))
    return out


def _simulate_or_error(sc: Scene) -> dict:
    from . import io as _io

    t0 = time.perf_counter()
    try:
        return dict(simulate(sc).summary)
    except Exception:  # noqa: BLE001  (recorded as in the pipeline's batch.run_scene)
        log.exception("scene raised; recorded as numerical_error")
        return _io.error_summary(len(sc.levels), outcomes.NUMERICAL_ERROR, time.perf_counter() - t0)


# what a summary says of the run, not of the disk: any change of the step sequence (another
# device's round-off) moves these, while the motion agrees to the tolerance
RUN_STATISTICS = ("n_steps", "n_rejected", "n_steps_sliding", "n_rejected_sliding", "n_rhs", "n_events")


def summaries_equal(a: Mapping, b: Mapping, rtol: float = 1e-9, run_statistics: bool = True) -> list[str]:
    """Keys where two summaries differ beyond rtol (relative; NaN equals NaN; wall_time ignored;
    the step and evaluation counts of RUN_STATISTICS too where run_statistics is False)."""
    bad: list[str] = []

    def cmp(x, y, key):
        if isinstance(x, Mapping):
            for k in x:
                cmp(x[k], y[k], f"{key}.{k}")
        elif isinstance(x, list):
            for j, (u, v) in enumerate(zip(x, y)):
                cmp(u, v, f"{key}[{j}]")
            if len(x) != len(y):
                bad.append(key)
        elif isinstance(x, float) or isinstance(y, float):
            fx, fy = float(x), float(y)
            if math.isnan(fx) and math.isnan(fy):
                return
            if not (fx == fy or abs(fx - fy) <= rtol * max(abs(fx), abs(fy))):
                bad.append(f"{key}: {fx!r} != {fy!r}")
        elif x != y:
            bad.append(f"{key}: {x!r} != {y!r}")

    for k in a:
        if k != "wall_time" and (run_statistics or k not in RUN_STATISTICS):
            cmp(a[k], b[k], k)
    return bad


def run_chunks_job(specs: list[str], expected_ids: list[str], out_paths: list[str], log_path: str | None = None,
                   device: str = "cuda") -> dict:
    """Entry point of the Snakemake jobs `simulate_cuda_*` (workflow/scripts/simulate_cuda.py): the
    scenes of several chunks in one `simulate_batch` call, then one chunk file each (atomic writes).

    A scene the core refuses is recorded as numerical_error, as `batch.run_chunk` does."""
    from . import batch as _batch
    from . import grid as _grid
    from . import io as _io

    _batch.setup_logging(log_path)
    chunks = [_batch.chunk_from_spec(s) for s in specs]
    for ch, want in zip(chunks, expected_ids):
        if ch.id != want:
            raise ValueError(f"chunk spec hashes to {ch.id}, but the job is for {want}")
    if len(chunks) != len(expected_ids) or len(chunks) != len(out_paths):
        raise ValueError("specs, expected_ids and out_paths must have one entry per chunk")
    summaries: list[dict | None] = []
    loaded: list[Scene] = []
    where: list[int] = []
    refs: list[dict | None] = []   # the error bars' rerun of each summary (outputs.error_estimate)
    for ch in chunks:
        settings = ch.spec["settings"]
        reference = _grid.error_reference(settings) if settings.get("error_estimate", False) else None
        for p in ch.points:
            cfg = _grid.scene(settings, p)
            refs.append(_grid.scene(reference, p) if reference is not None else None)
            try:
                loaded.append(load_scene(cfg))
                where.append(len(summaries))
                summaries.append(None)
            except Exception:  # noqa: BLE001
                log.exception("scene %s refused; recorded as numerical_error", _grid.canonical_json(cfg))
                summaries.append(_io.error_summary(len(settings["levels"]), outcomes.NUMERICAL_ERROR))
    log.info("%d chunks, %d scenes on %s", len(chunks), len(summaries), device)
    stats: dict = {}
    t0 = time.perf_counter()
    for j, s in zip(where, simulate_batch(loaded, device=device, stats=stats)):
        summaries[j] = s
    ref_loaded, ref_where = [], []
    for j, r in enumerate(refs):
        if r is not None:
            try:
                ref_loaded.append(load_scene(r))
                ref_where.append(j)
            except Exception:  # noqa: BLE001
                log.exception("error-estimate rerun %s refused", _grid.canonical_json(r))
                _io.add_numerical_errors(summaries[j], None)
    if ref_loaded:
        for j, r in zip(ref_where, simulate_batch(ref_loaded, device=device)):
            _io.add_numerical_errors(summaries[j], r)
    seconds = time.perf_counter() - t0
    log.info("batch done in %.2f s (%.1f scenes/s): %s", seconds, len(summaries) / max(seconds, 1e-9), stats)
    k = 0
    for ch, path in zip(chunks, out_paths):
        _io.write_chunk(ch, summaries[k:k + len(ch.points)], path)
        k += len(ch.points)
    return dict(stats, seconds=seconds, chunks=len(chunks))
