"""Many scenes at once on the CPU's cores: `simulate_batch(scenes) -> [summary, ...]`.

Each summary equals `sweep.simulate(scene).summary` (the batch runs the same numba kernels:
core.ensemble.solve_scene calls core.integrate.run and core.fits.summary_fits). Only the summary
is returned: no samples, trajectory or peak list (use `sweep.simulate` for those).

Worker threads (all cores by default), each with its own buffers, take the next scene when theirs
ends; the kernel releases the GIL, so the threads run in parallel. The kernel outputs per scene
(statistics, level records, end state and the fitted halt time and exponents) become the SI summary
dict in Python (`simulate.summary_from`, unit scaling only: ~20 us per scene).

There is no GPU path: one (device="cuda", numba-cuda) ran 18.4 scenes/s on an H200 host against
70.1 on the same machine's 16 CPU cores (CHANGELOG.md).
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
from .core.ensemble import MAX_LEVELS, BatchInputs, BatchOutputs, solve_index, work_buffers
from .core.fits import N_DERIVED
from .core.layout import I_OVERFLOW, LEVEL_COLS, N_FSTATS, N_ISTATS, N_SETTINGS
from .core.model import N_FULL, N_PARAMS
from .errors import ConfigError
from .scene import Scene, load_scene
from .simulate import _settings, initial_state, level_energies, simulate, summary_from

log = logging.getLogger("sweep.ensemble")

# the only device: the GPU path was removed (module docstring); "cuda" gets a ConfigError saying so
DEVICES = ("cpu",)


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
                i = nxt[0]
                nxt[0] += 1
            if i >= n:
                return
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
    return {"workers": workers, "seconds": time.perf_counter() - t0, "errors": errors}


def _load(scene) -> Scene:
    return scene if isinstance(scene, Scene) else load_scene(scene)


def simulate_batch(scenes: Iterable, device: str = "cpu", workers: int | None = None,
                   stats: dict | None = None) -> list[dict]:
    """Summaries of many scenes, each equal to `sweep.simulate(scene).summary` (wall_time aside).

    scenes: scene files or dicts (validated as by `sweep.simulate`, ConfigError before any work) or
    Scene objects. device: "cpu", the only one (a ConfigError for any other, "cuda" included: the GPU
    path was removed). workers: CPU threads, default all cores. stats: a dict to receive what the run
    did (workers, seconds, n, batch, reruns).

    wall_time of a summary: that scene's integration time on its thread. A scene whose kernel run
    raised (or whose look-back outgrew the peak ring, or that has more than MAX_LEVELS levels) is run
    with `sweep.simulate` instead; if that raises too, its summary is outcome numerical_error with
    NaNs, as in the pipeline.
    """
    if device not in DEVICES:
        raise ConfigError("device", device, "'cpu' (the GPU path, device='cuda', was removed: "
                          "it ran slower than the CPU; see CHANGELOG.md)")
    if workers is not None and (isinstance(workers, bool) or not isinstance(workers, int) or workers < 1):
        raise ConfigError("workers", workers, "an integer >= 1 (CPU threads)")
    scs = [_load(s) for s in scenes]
    if not scs:
        return []
    in_batch = [i for i, sc in enumerate(scs) if len(sc.levels) <= MAX_LEVELS]
    batch = Batch([scs[i] for i in in_batch])
    info = run_cpu(batch, workers or _workers_default())
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
    from . import outputs as _outputs

    t0 = time.perf_counter()
    try:
        return dict(simulate(sc).summary)
    except Exception:  # noqa: BLE001  (recorded as in the pipeline's batch.run_scene)
        log.exception("scene raised; recorded as numerical_error")
        return _outputs.empty_summary(len(sc.levels), outcomes.NUMERICAL_ERROR, time.perf_counter() - t0)


def summaries_equal(a: Mapping, b: Mapping, rtol: float = 1e-9) -> list[str]:
    """Keys where two summaries differ beyond rtol (relative; NaN equals NaN; wall_time ignored)."""
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
        if k != "wall_time":
            cmp(a[k], b[k], k)
    return bad

