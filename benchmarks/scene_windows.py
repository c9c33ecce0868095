#!/usr/bin/env python3
"""Where in simulated time a harness scene spends its steps: accepted steps per window of simulated
time, with the inclination's range, the largest |omega| component and the sliding share in each
(docs/performance.md, 'Stop 27': scene 491 of seed 20261122 rolling near flat after ~105 s).

    .venv/bin/python benchmarks/scene_windows.py INDEX [--seed 20261122] [--rtol 1e-10]
        [--t-max 160] [--window 10]

The scene is the harness's scene INDEX of that seed (benchmarks/convergence.py), run to t_max (s)
with the trajectory recorded at every accepted step (and at events).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import convergence as cv  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("index", type=int)
    ap.add_argument("--seed", type=int, default=20261122)
    ap.add_argument("--rtol", type=float, default=cv.DEFAULT_RTOL)
    ap.add_argument("--t-max", type=float, default=160.0, help="simulated time (s)")
    ap.add_argument("--window", type=float, default=10.0, help="window of simulated time (s)")
    a = ap.parse_args(argv)
    if a.index < 0 or a.t_max <= 0.0 or a.window <= 0.0:
        ap.error("INDEX must be >= 0, --t-max and --window > 0")
    import sweep

    cfg = cv.harness_scene(a.seed, a.index, a.rtol, a.t_max)
    res = sweep.simulate(cfg, trajectory=True)
    s, tr = res.summary, res.trajectory
    print(f"outcome {s['outcome']} at {s['t_end']:.3f} s: accepted {s['n_steps']}, rejected {s['n_rejected']}, "
          f"transitions {s['n_transitions']}, stick phases {s['n_stick']}")
    t = np.asarray(tr["t"])
    alpha = np.asarray(tr["alpha"])
    omega = np.abs(np.asarray(tr["omega"]))
    sliding = np.asarray(tr["mode"]) != 0
    print("window (s)      rows   alpha range           max |omega_i| (rad/s)  sliding share")
    for lo in np.arange(0.0, t[-1], a.window):
        m = (t >= lo) & (t < lo + a.window)
        if m.any():
            print(f"{lo:6.0f}..{lo + a.window:<6.0f} {int(m.sum()):7d}   {alpha[m].min():8.5f}..{alpha[m].max():8.5f}   "
                  f"{omega[m].max():10.4g}             {sliding[m].mean():.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
