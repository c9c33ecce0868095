#!/usr/bin/env python3
"""CPU cost of the convergence harness's scenes, this kernel against a baseline commit, side by side.

    .venv/bin/python benchmarks/harness_cost.py [--base 679d92b] [--scenes 100] [--rounds 2]

Issue #8's cost targets are relative to the integrator before that issue (679d92b, the default
base): the harness's total CPU time at the default settings (rtol 1e-10) at most half of it, and
p99 <= 20 x the median of the per-scene cost. Timings on a shared machine drift, so both kernels
run in one process each (the base extracted with `git archive` into a temporary directory, its
own numba cache), scene by scene alternately, every scene `--rounds` times in alternating order;
a scene's cost is its smallest CPU time (time.process_time) over the rounds. The scenes are the
harness's (benchmarks/convergence.py, same seed), run as the harness runs them at rtol 1e-10:
levels 0.1, 0.01, 0.001, t_max 300 s, samples of the state at tau = 10, 30, 100, 300.

Prints per-kernel total, median, p90, p99, max, p99/median, and the ratios new/base.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tarfile
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
HERE = Path(__file__).resolve().parent

WORKER = r"""
import json, sys, time
sys.path.insert(0, sys.argv[1])
import convergence as cv
import sweep
for line in sys.stdin:
    cfg = json.loads(line)
    times = cfg.pop("_sample_times")
    t0 = time.process_time()
    try:
        r = sweep.simulate(cfg, sample_times=times)
        s = r.summary
        out = {"cpu": time.process_time() - t0, "steps": s["n_steps"] + s["n_rejected"], "outcome": s["outcome"]}
    except Exception as exc:  # the base may fail where this kernel does not: report, go on
        out = {"cpu": time.process_time() - t0, "error": f"{type(exc).__name__}: {exc}"}
    print(json.dumps(out), flush=True)
"""


def harness_scenes(n: int, seed: int) -> list[dict]:
    sys.path.insert(0, str(HERE))
    import convergence as cv

    rng = np.random.default_rng(seed)
    scenes = []
    for _ in range(n):
        c = cv._valid_levels(cv.draw_scene(rng))
        c["solver"] = {"rtol": cv.DEFAULT_RTOL, "atol": cv.DEFAULT_RTOL * 1e-2}
        chi = ((({"solid": 1.0, "shell": 2.0}[c["disk"]["shape"]]) + 4.0) / 4.0
               * c["disk"]["radius"] / c["gravity"]) ** 0.5
        c["_sample_times"] = [tau * chi for tau in cv.SAMPLE_TAU if tau * chi < cv.T_MAX]
        scenes.append(c)
    return scenes


def extract(commit: str, into: Path) -> Path:
    """src/ of `commit` into `into` (git archive); returns its src directory."""
    tar = into / "src.tar"
    subprocess.run(["git", "-C", str(ROOT), "archive", "--format=tar", "-o", str(tar), commit, "src"], check=True)
    with tarfile.open(tar) as t:
        t.extractall(into, filter="data")
    return into / "src"


def start(src: Path, cache: Path) -> subprocess.Popen:
    env = dict(os.environ, PYTHONPATH=str(src), NUMBA_CACHE_DIR=str(cache))
    return subprocess.Popen([sys.executable, "-c", WORKER, str(HERE)], stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, text=True, env=env)


def ask(worker: subprocess.Popen, scene: dict) -> dict:
    worker.stdin.write(json.dumps(scene) + "\n")
    worker.stdin.flush()
    return json.loads(worker.stdout.readline())


def cpu_model() -> str:
    """The processor's model name (Linux), for the record: the ratio of two kernels depends on it."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    import platform
    return platform.processor() or "unknown"


def stats(cpu: np.ndarray) -> dict:
    med = float(np.median(cpu))
    p99 = float(np.percentile(cpu, 99))
    return {"total": float(cpu.sum()), "median": med, "p90": float(np.percentile(cpu, 90)), "p99": p99,
            "max": float(cpu.max()), "p99/median": p99 / med}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--base", default="679d92b", help="baseline commit (default: before issue #8)")
    ap.add_argument("--scenes", type=int, default=100)
    ap.add_argument("--seed", type=int, default=20261122)
    ap.add_argument("--rounds", type=int, default=2)
    args = ap.parse_args(argv)
    scenes = harness_scenes(args.scenes, args.seed)
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        base_src = extract(args.base, tmp)
        workers = {"base": start(base_src, tmp / "cache-base"), "new": start(ROOT / "src", tmp / "cache-new")}
        for w in workers.values():    # compile both kernels before any timing
            ask(w, scenes[0])
        cpu = {k: np.full((args.rounds, len(scenes)), np.inf) for k in workers}
        notes = {k: {} for k in workers}
        for r in range(args.rounds):
            order = ["base", "new"] if r % 2 == 0 else ["new", "base"]
            for i, sc in enumerate(scenes):
                for k in order:
                    out = ask(workers[k], sc)
                    cpu[k][r, i] = out["cpu"]
                    notes[k][i] = out
            print(f"round {r + 1}/{args.rounds} done", file=sys.stderr, flush=True)
        for w in workers.values():
            w.stdin.close()
            w.wait()
    best = {k: v.min(axis=0) for k, v in cpu.items()}
    s = {k: stats(v) for k, v in best.items()}
    print(f"harness scenes: {len(scenes)} (seed {args.seed}), rtol 1e-10, best of {args.rounds} alternating rounds")
    print(f"cpu: {cpu_model()}, {os.cpu_count()} cores (ratios of the same two commits have moved by 1.45x between "
          "machines: compare ratios measured on one machine)")
    print(f"{'':12s} {'total s':>9s} {'median ms':>10s} {'p90 ms':>9s} {'p99 ms':>9s} {'max ms':>9s} {'p99/median':>10s}")
    for k, name in (("base", f"base {args.base}"), ("new", "this tree")):
        v = s[k]
        print(f"{name:12s} {v['total']:9.2f} {v['median'] * 1e3:10.1f} {v['p90'] * 1e3:9.1f} {v['p99'] * 1e3:9.1f} "
              f"{v['max'] * 1e3:9.1f} {v['p99/median']:10.1f}")
    print(f"total new/base: {s['new']['total'] / s['base']['total']:.3f} (target <= 0.5); "
          f"median new/base: {s['new']['median'] / s['base']['median']:.3f}; "
          f"p99/median new: {s['new']['p99/median']:.1f} (target <= 20)")
    for k in workers:
        bad = {i: o for i, o in notes[k].items() if "error" in o}
        if bad:
            print(f"{k}: {len(bad)} scenes raised: " + "; ".join(f"{i}: {o['error'][:80]}" for i, o in list(bad.items())[:5]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
