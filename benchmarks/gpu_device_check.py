#!/usr/bin/env python3
"""GPU figures of the batch path within a short lease of a GPU machine: compile and reference here,
only the runs there.

    # here (no GPU): the kernel, compiled for the GPU's compute capability (~20 min of one core) ...
    .venv/bin/python benchmarks/cuda_compile_offline.py --cc 9.0 --save-kernel gpucheck/kernel_sm90.pkl.xz
    # ... and the scenes with their one-core CPU summaries (the reference)
    .venv/bin/python benchmarks/gpu_device_check.py prepare --dir gpucheck --n 100000 --n-ref 1000
    # two commits' CPU kernels on the same scenes (each `prepare` run from its own tree):
    .venv/bin/python benchmarks/gpu_device_check.py compare OLD/scenes.pkl.xz NEW/scenes.pkl.xz
    # there (python3 with numba-cuda; no compilation, no schema package needed):
    python3 benchmarks/gpu_device_check.py run --dir gpucheck --budget-s 420 --out $OUT

The scenes are gpu_throughput.py's: the default grid's ranges, random inside them (seed 0). `run`
installs the prebuilt kernel (sweep.gpu.install_prebuilt), runs the n-ref reference scenes on the GPU
and compares every summary with the CPU's (outcomes and event counts exactly, each physical float
at 1e-9, 1e-6 and 1e-3 relative; the summaries go to OUT/gpu_summaries.pkl.xz), then, where time is
left, one scene per thread on one block of every multiprocessor, and last, while time is left, the reference scenes on all CPU cores
of that machine (numba compiles the CPU kernels first; the compile is timed apart). It prints scenes/s,
the launch (threads, registers, local memory) and writes everything to OUT/gpu_check.json.
"""
from __future__ import annotations

import argparse
import json
import lzma
import os
import pickle
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))
sys.path.insert(0, str(ROOT / "benchmarks"))

from sweep.ensemble import RUN_STATISTICS  # noqa: E402  (sweep imports no numba-cuda)
T_START = time.perf_counter()


def prepare(args) -> int:
    from gpu_throughput import scenes

    import sweep

    d = Path(args.dir)
    d.mkdir(parents=True, exist_ok=True)
    sc = scenes(args.n, args.seed)
    sweep.simulate_batch(sc[:1], device="cpu", workers=1)   # compile or load the CPU kernels first
    t0 = time.perf_counter()
    ref = sweep.simulate_batch(sc[:args.n_ref], device="cpu", workers=args.workers)
    dt = time.perf_counter() - t0
    with lzma.open(d / "scenes.pkl.xz", "wb") as f:
        pickle.dump({"seed": args.seed, "scenes": sc, "n_ref": args.n_ref, "reference": ref,
                     "reference_seconds": dt, "reference_workers": args.workers}, f)
    walls = np.array([s["wall_time"] for s in ref])
    print(f"{args.n} scenes (seed {args.seed}); reference: {args.n_ref} scenes on {args.workers} CPU thread(s) in "
          f"{dt:.1f} s; per scene median {np.median(walls):.3f} s, mean {walls.mean():.3f} s, max {walls.max():.2f} s")
    return 0


def compare(args) -> int:
    """Two `prepare` records of the same scenes (e.g. two commits' CPU kernels): how many reference
    summaries are identical (run statistics aside), which keys differ, the cost ratio, and per level
    how many reached levels have no precession value."""
    import collections
    import math

    from sweep.ensemble import summaries_equal

    recs = []
    for path in (args.a, args.b):
        with lzma.open(path, "rb") as f:
            recs.append(pickle.load(f))
    ref_a, ref_b = recs[0]["reference"], recs[1]["reference"]
    if recs[0]["seed"] != recs[1]["seed"] or len(ref_a) != len(ref_b):
        raise SystemExit("compare: the two records hold different scenes (seed or n-ref differ)")
    keys: collections.Counter = collections.Counter()
    same = 0
    for x, y in zip(ref_a, ref_b):
        bad = summaries_equal(x, y, rtol=0.0, run_statistics=False)
        same += not bad
        keys.update({b.split(":")[0] for b in bad})
    print(f"{len(ref_a)} scenes: {same} summaries identical (rtol 0, run statistics aside)")
    print("keys that differ (scenes):", dict(keys.most_common(20)))
    for stat in ("n_rhs", "n_steps"):
        ta, tb = sum(r[stat] for r in ref_a), sum(r[stat] for r in ref_b)
        print(f"{stat}: {ta} -> {tb} ({tb / ta:.4f})")

    def reached_without_precession(ref, lv):
        return sum(1 for r in ref if lv < len(r["levels"]) and math.isfinite(r["levels"][lv]["t"])
                   and math.isnan(r["levels"][lv]["precession_hz"]))

    for lv in range(max(len(r["levels"]) for r in ref_a)):
        print(f"level {lv}: reached with precession NaN: {reached_without_precession(ref_a, lv)} -> "
              f"{reached_without_precession(ref_b, lv)}")
    return 0


def left(args) -> float:
    return args.budget_s - (time.perf_counter() - T_START)


def run_gpu(gpu, Batch, scs):
    """(summaries or None where the kernel flagged a peak-ring overflow, launch facts, host seconds).
    simulate_batch(device="cuda") without its CPU rerun of such scenes, which would compile the CPU
    kernels on the device in the middle of the timings."""
    from sweep.core.layout import I_OVERFLOW

    t0 = time.perf_counter()
    batch = Batch(scs)
    t_pack = time.perf_counter() - t0
    info = gpu.run_cuda(batch.order, *batch.inputs, batch.outputs)
    batch.wall[:] = info["gpu_seconds"] / len(scs)
    t0 = time.perf_counter()
    out = [None if batch.ISTATS[j, I_OVERFLOW] != 0 else batch.summary(j) for j in range(len(scs))]
    return out, info, t_pack + time.perf_counter() - t0


RUN_FIELDS = ("wall_time",) + RUN_STATISTICS
COUNT_FIELDS = ("outcome", "n_transitions", "n_stick", "n_impacts")


def physics_values(summary) -> dict:
    """The summary's floats that describe the motion (level entries flattened), run statistics out."""
    out = {}
    for key, value in summary.items():
        if key in RUN_FIELDS or key in COUNT_FIELDS or isinstance(value, (bool, str)):
            continue
        if key == "levels":
            for j, lev in enumerate(value):
                out.update({f"levels[{j}].{k}": float(v) for k, v in lev.items()})
        elif key == "dissipation":
            out.update({f"dissipation.{k}": float(v) for k, v in value.items()})
        elif isinstance(value, float):
            out[key] = value
    return out


def agreement(ref, got) -> dict:
    """GPU against CPU summaries: outcomes and event counts exactly; per physical float, the share
    within 1e-9, 1e-6, 1e-3 relative; the largest differences."""
    cmp = {"n": len(ref), "overflow": sum(g is None for g in got)}
    pairs = [(r, g) for r, g in zip(ref, got) if g is not None]
    for key in COUNT_FIELDS:
        cmp[f"same_{key}"] = sum(r[key] == g[key] for r, g in pairs)
    rel = []
    for r, g in pairs:
        a, b = physics_values(r), physics_values(g)
        for key in a:
            x, y = a[key], b.get(key, float("nan"))
            if np.isnan(x) and np.isnan(y):
                continue
            d = abs(x - y) / max(abs(x), abs(y), 1e-300) if x != y else 0.0
            rel.append((d if np.isfinite(d) else np.inf, key, x, y))
    ds = np.array([d for d, *_ in rel])
    cmp["values"] = len(rel)
    for tol in (1e-9, 1e-6, 1e-3):
        cmp[f"values_within_{tol:g}"] = int((ds <= tol).sum())
    cmp["rel_diff_percentiles_50_90_99_max"] = np.percentile(ds, [50, 90, 99, 100]).tolist() if rel else []
    by_key: dict = {}
    for d, key, *_ in rel:
        k = key.split("].")[-1] if key.startswith("levels") else key
        by_key.setdefault(k, []).append(d)
    cmp["median_rel_diff_by_quantity"] = {k: float(np.median(v)) for k, v in sorted(by_key.items())}
    cmp["largest"] = [f"{key}: {x!r} vs {y!r} ({d:.1e})" for d, key, x, y in sorted(rel, key=lambda t: -t[0])[:8]]
    return cmp


def big_run(gpu, Batch, load_scene, scenes) -> dict:
    """One GPU batch of the scene dicts `scenes`, loaded and run: its big_summary."""
    t0 = time.perf_counter()
    big = [load_scene(s) for s in scenes]
    t_load = time.perf_counter() - t0
    print(f"{len(big)} scenes loaded in {t_load:.1f} s; launching", flush=True)
    got, info, host = run_gpu(gpu, Batch, big)
    out = big_summary(got, info, host + t_load)
    print(f"big batch: {out}", flush=True)
    return out


def big_summary(got, info, host_s) -> dict:
    steps = np.array([g["n_steps"] + g["n_rejected"] for g in got if g is not None], float)
    return {"n": len(got), "gpu_kernel_s": info["gpu_seconds"], "host_s": host_s,
            "scenes_per_s": len(got) / info["gpu_seconds"], "blocks": info["blocks"], "threads": info["threads"],
            "overflow": sum(g is None for g in got),
            "steps_percentiles_0_50_90_99_100": np.percentile(steps, [0, 50, 90, 99, 100]).tolist(),
            "outcomes": {str(k): int(v) for k, v in zip(*np.unique(
                [g["outcome"] for g in got if g is not None], return_counts=True))}}


def run(args) -> int:
    np.row_stack = getattr(np, "row_stack", np.vstack)   # numba-cuda 0.30.4 calls it; numpy 2.5 removed it
    out_dir = Path(args.out)
    out_dir.mkdir(parents=True, exist_ok=True)
    res: dict = {"budget_s": args.budget_s}

    def save():
        res["elapsed_s"] = time.perf_counter() - T_START
        (out_dir / "gpu_check.json").write_text(json.dumps(res, indent=1, default=str))

    d = Path(args.dir)
    with lzma.open(d / "scenes.pkl.xz", "rb") as f:
        data = pickle.load(f)
    os.environ.setdefault("SWEEP_CUDA_KERNEL", str(args.kernel or d / "kernel_sm90.pkl.xz"))
    t0 = time.perf_counter()
    from sweep import gpu
    from sweep.ensemble import Batch, summaries_equal
    from sweep.scene import load_scene

    cuda = gpu.require_cuda()
    dev = cuda.get_current_device()
    name = getattr(dev, "name", "numba's CUDA simulator")
    res["device"] = {"name": name.decode() if isinstance(name, bytes) else str(name),
                     "cc": list(dev.compute_capability), "sms": getattr(dev, "MULTIPROCESSOR_COUNT", 1)}
    res["import_s"] = time.perf_counter() - t0
    n_ref = data["n_ref"]
    ref = data["reference"]
    print(f"{res['device']}; import {res['import_s']:.1f} s", flush=True)
    if args.only_big:
        # one batch of the non-reference scenes alone (a second lease, after a first run measured the rest)
        res["big_run"] = big_run(gpu, Batch, load_scene, data["scenes"][n_ref:n_ref + args.only_big])
        save()
        return 0
    t0 = time.perf_counter()
    scs = [load_scene(s) for s in data["scenes"][:n_ref]]
    res["load_scene_ms_per_scene"] = 1e3 * (time.perf_counter() - t0) / n_ref
    print(f"{n_ref} scenes loaded ({res['load_scene_ms_per_scene']:.2f} ms each)", flush=True)
    t0 = time.perf_counter()
    _, info, _ = run_gpu(gpu, Batch, scs[:8])   # installs the prebuilt kernel, loads its module
    res["warm_s"] = time.perf_counter() - t0
    res["launch"] = {k: info[k] for k in ("threads_per_block", "regs_per_thread", "local_mem_per_thread")}
    print(f"warm-up (kernel install + module load + 8 scenes): {res['warm_s']:.1f} s; {res['launch']}", flush=True)
    save()

    # a GPU thread's time per CPU-core second, from the 8 warm-up scenes (each kernel lasts as long
    # as its slowest scene): the reference run is cut to what fits a third of the time left
    cpu_walls = np.array([r["wall_time"] for r in ref])
    slowdown = info["gpu_seconds"] / cpu_walls[:8].max()
    res["warm_gpu_kernel_s"] = info["gpu_seconds"]
    res["gpu_thread_per_cpu_core_s_est"] = slowdown
    fits = np.nonzero(slowdown * np.maximum.accumulate(cpu_walls) <= left(args) * args.ref_share)[0]
    n_ref = min(len(ref), int(max(fits[-1] + 1 if fits.size else 8, 8)))
    ref, scs = ref[:n_ref], scs[:n_ref]
    cpu_walls = cpu_walls[:n_ref]
    print(f"warm-up kernel {info['gpu_seconds']:.2f} s, {slowdown:.1f} GPU-thread s per CPU-core s: "
          f"{n_ref} reference scenes fit", flush=True)
    got, info, host = run_gpu(gpu, Batch, scs)
    with lzma.open(out_dir / "gpu_summaries.pkl.xz", "wb") as f:   # for analysis after the lease
        pickle.dump({"reference": ref, "gpu": got}, f, protocol=4)
    cmp = agreement(ref, got)
    res["reference_run"] = {"gpu_kernel_s": info["gpu_seconds"], "host_s": host, "blocks": info["blocks"],
                            "threads": info["threads"], "scenes_per_s": n_ref / info["gpu_seconds"],
                            "cpu_one_core_scenes_per_s_here": 1.0 / cpu_walls.mean(), "agreement": cmp}
    print(f"reference scenes on the GPU: {info['gpu_seconds']:.1f} s kernel ({n_ref / info['gpu_seconds']:.1f} scenes/s, "
          f"{info['threads']} threads); agreement {cmp}", flush=True)
    save()

    if args.packed:
        # the same scenes, launched as before stop 34's launch_shape: full blocks of THREADS_PER_BLOCK
        # on as few multiprocessors as they fill (side by side with the spread launch above)
        spread_s = info["gpu_seconds"]
        if left(args) > 2.5 * spread_s + 30:
            spread = gpu.launch_shape
            tpb = gpu.THREADS_PER_BLOCK
            gpu.launch_shape = lambda cuda, n, regs: (-(-n // tpb), tpb)
            try:
                got_p, info_p, _ = run_gpu(gpu, Batch, scs)
            finally:
                gpu.launch_shape = spread
            same = sum(a is not None and b is not None and summaries_equal(a, b, rtol=0.0) == []
                       for a, b in zip(got, got_p))
            res["reference_run_packed"] = {"gpu_kernel_s": info_p["gpu_seconds"], "blocks": info_p["blocks"],
                                           "threads_per_block": info_p["threads_per_block"],
                                           "scenes_per_s": n_ref / info_p["gpu_seconds"],
                                           "spread_over_packed_time": spread_s / info_p["gpu_seconds"],
                                           "summaries_identical_to_spread": same}
            print(f"packed launch: {res['reference_run_packed']}", flush=True)
        else:
            res["reference_run_packed"] = f"skipped: {left(args):.0f} s left"
        save()
    else:
        # the big batch: one block of threads on every multiprocessor (the reference run fills few of
        # them), one scene per thread; its kernel lasts about as long as the reference's slowest scenes.
        # (2026-11-26, H100: a full-residency batch, 33792 scenes on 528 blocks, took more than 400 s.)
        sms = res["device"]["sms"]
        rest = data["scenes"][n_ref:]
        n_big = min(len(rest), sms * gpu.THREADS_PER_BLOCK)
        res["big_plan"] = {"n": n_big, "left_s": left(args)}
        if left(args) > 2.5 * info["gpu_seconds"] + 30 and n_big > 0:
            res["big_run"] = big_run(gpu, Batch, load_scene, rest[:n_big])
            save()

    if left(args) > args.cpu_min_s:
        import sweep

        t0 = time.perf_counter()
        sweep.simulate_batch(scs[:1], device="cpu", workers=1)
        res["cpu_compile_s"] = time.perf_counter() - t0
        workers = len(os.sched_getaffinity(0))
        n_cpu = n_ref
        t0 = time.perf_counter()
        cpu = sweep.simulate_batch(scs[:n_cpu], device="cpu", workers=workers)
        dt = time.perf_counter() - t0
        res["cpu_run"] = {"n": n_cpu, "workers": workers, "seconds": dt, "scenes_per_s": n_cpu / dt,
                          "equal_reference_1e-9": sum(summaries_equal(r, c, rtol=1e-9) == [] for r, c in zip(ref, cpu))}
        print(f"CPU compile {res['cpu_compile_s']:.1f} s; {res['cpu_run']}", flush=True)
    else:
        res["cpu_run"] = f"skipped: {left(args):.0f} s left < {args.cpu_min_s} s"
    save()
    print(json.dumps(res, indent=1, default=str))
    return 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="cmd", required=True)
    p = sub.add_parser("prepare")
    p.add_argument("--dir", default="gpucheck")
    p.add_argument("--n", type=int, default=100_000)
    p.add_argument("--n-ref", type=int, default=1000)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--workers", type=int, default=1)
    r = sub.add_parser("run")
    r.add_argument("--dir", default="gpucheck")
    r.add_argument("--kernel", default=None, help="prebuilt kernel (default DIR/kernel_sm90.pkl.xz)")
    r.add_argument("--budget-s", type=float, default=420.0, help="wall seconds this run may take")
    r.add_argument("--cpu-min-s", type=float, default=120.0, help="run the CPU comparison only with this much left")
    r.add_argument("--only-big", type=int, default=0, metavar="N",
                   help="only one GPU batch of N non-reference scenes (no warm-up, reference or CPU run)")
    r.add_argument("--packed", action="store_true",
                   help="instead of the big batch, rerun the reference scenes in full blocks of THREADS_PER_BLOCK "
                        "(the launch before launch_shape spread small batches over every SM): the two side by side")
    r.add_argument("--ref-share", type=float, default=1 / 3,
                   help="share of the time left that the reference run may take (estimated from the warm-up)")
    r.add_argument("--out", default=os.environ.get("OUT", "gpucheck/out"))
    c = sub.add_parser("compare", help="two prepare records of the same scenes, summary by summary")
    c.add_argument("a")
    c.add_argument("b")
    args = ap.parse_args(argv)
    return {"prepare": prepare, "run": run, "compare": compare}[args.cmd](args)


if __name__ == "__main__":
    sys.exit(main())
