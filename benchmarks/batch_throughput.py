#!/usr/bin/env python3
"""Throughput of the batch path: the same scenes on one CPU core and on all cores.

    .venv/bin/python benchmarks/batch_throughput.py [--n 1000] [--seed 0] [--workers N] [--skip-1core]

The scenes: the default grid's ranges (config/config.yaml: mu_d, k3, alpha0, omega0 uniform in
[min, max] of their axes, k1, k2 and every other setting as configured), random inside them. Prints
scenes/s for `sweep.simulate_batch(scenes, workers=1)` and for `workers=<all cores>`, each one's
ratio to one core and the CPU cores the process got, an idle-machine estimate for the threads, the
spread of the per-scene step counts, and whether every batch's summaries equal the one-core run's
to 1e-9 relative.
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

import sweep  # noqa: E402
from sweep import axes, chunking, grid  # noqa: E402
from sweep.ensemble import summaries_equal  # noqa: E402
from sweep.scene import load_scene  # noqa: E402
from sweep.yamlio import load  # noqa: E402

RANDOM_AXES = ("mu_d", "k3", "alpha0", "omega0")


def scenes(n: int, seed: int) -> list[dict]:
    cfg = load((ROOT / "config" / "config.yaml").read_text())
    settings = grid.normalize(cfg, check_scenes=False)
    g = settings["grid"]
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        point = {a: g[a][0] for a in axes.AXES}
        for a in RANDOM_AXES:
            point[a] = float(rng.uniform(min(g[a]), max(g[a])))
        out.append(grid.scene(chunking.scene_settings(settings), tuple(point[a] for a in axes.AXES)))
    return out


CPU_SECONDS: dict[str, float] = {}


def timed(label: str, fn):
    """(result, wall seconds); the process's CPU seconds (all threads) go to CPU_SECONDS[label]."""
    c0 = time.process_time()
    t0 = time.perf_counter()
    res = fn()
    dt = time.perf_counter() - t0
    CPU_SECONDS[label] = time.process_time() - c0
    return res, dt


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--n", type=int, default=1000, help="scenes (default 1000)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--workers", type=int, default=None, help="threads of the all-cores run (default: all)")
    ap.add_argument("--skip-1core", action="store_true", help="no one-core run (ratios then against all cores)")
    args = ap.parse_args(argv)
    try:
        cores = len(os.sched_getaffinity(0))
    except AttributeError:
        cores = os.cpu_count() or 1
    workers = args.workers or cores
    sc = [load_scene(s) for s in scenes(args.n, args.seed)]
    print(f"{args.n} scenes of the default grid's ranges (seed {args.seed}); {cores} CPU cores here")

    # compile / load the CPU kernels once, outside the timings
    _, dt = timed("warm", lambda: sweep.simulate_batch(sc[:1], workers=1))
    print(f"CPU warm-up (compile or cache load): {dt:.1f} s")

    rows = []
    ref = None
    if not args.skip_1core:
        ref, t1 = timed("cpu, 1 thread", lambda: sweep.simulate_batch(sc, workers=1))
        rows.append(("cpu, 1 thread", t1, ref))
    allc, tn = timed(f"cpu, {workers} threads", lambda: sweep.simulate_batch(sc, workers=workers))
    rows.append((f"cpu, {workers} threads", tn, allc))
    if ref is None:
        ref = allc

    base = rows[0][1]
    # cores used = the process's CPU seconds / wall seconds: on a shared machine the threads get less
    # than a core each, and this column says how much they got
    print(f"\n{'run':<20} {'seconds':>9} {'scenes/s':>10} {'x ' + rows[0][0]:>18} {'cores used':>11}  "
          "summaries equal (1e-9)")
    for label, dt, res in rows:
        same = sum(summaries_equal(r, s, rtol=1e-9) == [] for r, s in zip(ref, res))
        print(f"{label:<20} {dt:9.2f} {len(sc) / dt:10.2f} {base / dt:18.2f} {CPU_SECONDS[label] / dt:11.2f}  "
              f"{same:>10}/{len(sc)}")
    print(f"load average (1, 5, 15 min) at the end: {os.getloadavg()}")
    if not args.skip_1core and workers > 1:
        # what `workers` threads would take on an idle machine: the one-thread run's per-scene times
        # handed out in order to whichever thread is free (as run_cpu does)
        import heapq

        free = [0.0] * workers
        for s in ref:
            heapq.heapreplace(free, free[0] + s["wall_time"])
        ideal = sum(s["wall_time"] for s in ref) / max(free)
        print(f"idle-machine estimate for {workers} threads (one-thread scene times, dynamic hand-out): "
              f"{ideal:.2f}x one thread")
    wall = np.array([s["wall_time"] for s in ref])
    print(f"one-thread scene times (s){' (all-cores run: --skip-1core)' if args.skip_1core else ''}: "
          f"median {np.median(wall):.3f}, mean {wall.mean():.3f}, max {wall.max():.3f}")
    steps = np.array([s["n_steps"] + s["n_rejected"] for s in ref], dtype=float)
    q = np.percentile(steps, [0, 50, 90, 100])
    print(f"\nsteps per scene (accepted + rejected): min {q[0]:.0f}, median {q[1]:.0f}, p90 {q[2]:.0f}, "
          f"max {q[3]:.0f} (max/median {q[3] / q[1]:.1f}); outcomes "
          f"{ {str(k): int(v) for k, v in zip(*np.unique([s['outcome'] for s in ref], return_counts=True))} }")
    return 0


if __name__ == "__main__":
    sys.exit(main())
