#!/usr/bin/env python3
"""A harness scene's discrete events compared one by one across rtol: where two runs' event
sequences part, and how far apart their event times have drifted by then (docs/performance.md,
'Stop 27': scenes 346 of seed 20261125, 332 and 336 of seed 20261126).

    .venv/bin/python benchmarks/event_sequences.py INDEX [--seed 20261122] [--rtol 1e-10 1e-11 1e-13]

Copies this tree's src/ into a temporary directory and applies
benchmarks/patches/trajectory-counts.diff, which writes the transition and stick-phase counts into
the trajectory's mode column (the trajectories stay the core's bit for bit). Each run records the
state at every step and event; an event's time is that of the row after which a count rises. Every
rtol is compared with the last one given: for transitions and stick phases, the first event whose
time differs by more than --tol (tau) or that one run lacks, the events around it, and the time
difference at six events before it (a linear drift is a periodic motion's phase error; a
geometric growth is an amplifying trajectory). The patched kernels compile into their own numba
cache (about a minute).
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
PATCH = HERE / "patches" / "trajectory-counts.diff"

WORKER = r"""
import sys
import numpy as np
src, bench, seed, index, tol = sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4]), float(sys.argv[5])
rtols = [float(x) for x in sys.argv[6:]]
sys.path.insert(0, src)
sys.path.insert(0, bench)
import convergence as cv
import sweep

runs = {}
for rtol in rtols:
    res = sweep.simulate(cv.harness_scene(seed, index, rtol), trajectory=True)
    s, tr = res.summary, res.trajectory
    code, tau = np.asarray(tr["mode"]), np.asarray(tr["tau"])
    sticks = np.floor(code / 4e6)
    trans = np.floor((code - 4e6 * sticks) / 4)
    runs[rtol] = {"transitions": tau[:-1][np.diff(trans) > 0], "stick phases": tau[:-1][np.diff(sticks) > 0]}
    print(f"rtol {rtol:g}: {s['outcome']} at {s['t_end']:.6g} s, transitions {s['n_transitions']}, "
          f"stick phases {s['n_stick']}, impacts {s['n_impacts']}, rows with a rise: "
          f"{len(runs[rtol]['transitions'])} / {len(runs[rtol]['stick phases'])}")
ref = rtols[-1]
for rtol in rtols[:-1]:
    for kind in ("transitions", "stick phases"):
        a, b = runs[rtol][kind], runs[ref][kind]
        n = min(len(a), len(b))
        d = np.abs(a[:n] - b[:n])
        bad = np.nonzero(d > tol)[0]
        k = int(bad[0]) if len(bad) else n
        if k == n and len(a) == len(b):
            print(f"  {kind}, rtol {rtol:g} against {ref:g}: all {n} agree within {tol:g} tau, max |dt| "
                  f"{d.max() if n else 0.0:.2e}")
            continue
        print(f"  {kind}, rtol {rtol:g} against {ref:g}: they part at event {k} ({len(a)} against {len(b)})")
        for i in range(max(0, k - 3), min(max(len(a), len(b)), k + 3)):
            ta = f"{a[i]:.10f}" if i < len(a) else "-"
            tb = f"{b[i]:.10f}" if i < len(b) else "-"
            print(f"    #{i}: {ta}  {tb}")
        if k > 0:
            picks = np.unique(np.linspace(0, k - 1, 6).astype(int))
            print("    |dt| before: " + ", ".join(f"{d[i]:.1e} at tau {b[i]:.1f}" for i in picks))
"""


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("index", type=int)
    ap.add_argument("--seed", type=int, default=20261122)
    ap.add_argument("--rtol", type=float, nargs="+", default=[1e-10, 1e-11, 1e-13],
                    help="the last one is the reference")
    ap.add_argument("--tol", type=float, default=1e-4, help="event times (tau) further apart part the sequences")
    a = ap.parse_args(argv)
    if a.index < 0 or len(a.rtol) < 2 or not all(0.0 < r < 1.0 for r in a.rtol) or not a.tol > 0.0:
        ap.error("INDEX >= 0, at least two --rtol in (0, 1) and --tol > 0")
    with tempfile.TemporaryDirectory(prefix="events-") as tmp:
        shutil.copytree(ROOT / "src", Path(tmp) / "src", ignore=shutil.ignore_patterns("__pycache__", "*.egg-info"))
        subprocess.run(["git", "apply", str(PATCH)], cwd=tmp, check=True)
        return subprocess.run([sys.executable, "-c", WORKER, str(Path(tmp) / "src"), str(HERE), str(a.seed),
                               str(a.index), repr(a.tol), *map(repr, a.rtol)]).returncode


if __name__ == "__main__":
    sys.exit(main())
