#!/usr/bin/env python3
"""Where the harness's step tries and right-hand-side calls go (docs/performance.md, 'Stop 25').

    .venv/bin/python benchmarks/tries_breakdown.py [--scenes 100] [--seed 20261122] [--rtol 1e-10]
                                                   [--patch benchmarks/patches/X.diff ...]

Copies this tree's src/ into a temporary directory, applies benchmarks/patches/count-tries.diff
(counters in spare slots of the kernel's integer statistics; the trajectories stay the core's bit for
bit) and any --patch given, and runs the harness's scenes (benchmarks/convergence.py, same seed) as
the harness does at one rtol. Prints the accepted and rejected tries, the rejections by cause (error
norm; energy balance of the step; balance of the part kept before an event; non-finite stage or
energy guard; dip retried to its minimum) and the right-hand-side calls by where they are made. The
patched kernels compile into their own numba cache (about a minute).
"""
from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
HERE = Path(__file__).resolve().parent
COUNTERS = HERE / "patches" / "count-tries.diff"

WORKER = r"""
import importlib, math, sys
import numpy as np
src, bench, seed, n, rtol = sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4]), float(sys.argv[5])
sys.path.insert(0, src)
sys.path.insert(0, bench)
import convergence as cv
from sweep.scene import load_scene
S = importlib.import_module("sweep.simulate")
rng = np.random.default_rng(seed)
tot = np.zeros(26, np.int64)
for _ in range(n):
    c = cv._valid_levels(cv.draw_scene(rng))
    c["solver"] = {"rtol": rtol, "atol": rtol * cv.ATOL_RATIO}
    chi = math.sqrt((({"solid": 1.0, "shell": 2.0}[c["disk"]["shape"]]) + 4.0) / 4.0
                    * c["disk"]["radius"] / c["gravity"])
    st = np.array([tau for tau in cv.SAMPLE_TAU if tau * chi < cv.T_MAX])
    tot += S.run_kernel(load_scene(c), st).istats
tries = tot[1] + tot[2]
rej = max(tot[2], 1)
print(f"accepted steps {tot[1]}, rejected tries {tot[2]} ({tot[2] / tries:.1%} of {tries}); "
      f"sliding {tot[11]} / {tot[12]} ({tot[12] / max(tot[11] + tot[12], 1):.1%})")
for k, what in [(15, "error norm"), (16, "energy balance of the step (error norm <= 1)"),
                (19, "balance of the part kept before an event"),
                (17, "non-finite stage or energy guard"), (18, "dip retried to its minimum")]:
    print(f"  rejected by {what}: {tot[k]} ({tot[k] / rej:.1%})")
print(f"right-hand sides {tot[3]}, {tot[3] / tries:.2f} per try")
named = 0
for k, what in [(20, "stages (try_step)"), (21, "event scan (first_event)"),
                (22, "dense output for levels, samples, lattice, maxima"), (23, "discrete updates (apply_event)")]:
    named += tot[k]
    print(f"  {what}: {tot[k]} ({tot[k] / tries:.2f} per try, {tot[k] / tot[3]:.1%})")
rest = tot[3] - named
print(f"  the rest (slaved direction at step ends, tracking): {rest} ({rest / tries:.2f} per try, {rest / tot[3]:.1%})")
"""


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scenes", type=int, default=100)
    ap.add_argument("--seed", type=int, default=20261122)
    ap.add_argument("--rtol", type=float, default=1e-10)
    ap.add_argument("--patch", action="append", default=[], help="another patch to apply (repeatable)")
    a = ap.parse_args(argv)
    if a.scenes < 1:
        ap.error("--scenes must be >= 1")
    if not 0.0 < a.rtol < 1.0:
        ap.error("--rtol must lie in (0, 1)")
    with tempfile.TemporaryDirectory(prefix="tries-") as tmp:
        shutil.copytree(ROOT / "src", Path(tmp) / "src", ignore=shutil.ignore_patterns("__pycache__", "*.egg-info"))
        for patch in [COUNTERS, *map(Path, a.patch)]:
            subprocess.run(["git", "apply", str(patch.resolve())], cwd=tmp, check=True)
        return subprocess.run([sys.executable, "-c", WORKER, str(Path(tmp) / "src"), str(HERE), str(a.seed),
                               str(a.scenes), repr(a.rtol)]).returncode


if __name__ == "__main__":
    sys.exit(main())
