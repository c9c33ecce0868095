#!/usr/bin/env python3
"""A harness scene's accepted sliding steps binned by the slip direction's relaxation time
|u|/(mu_d Phi) (in tau): how much of a slide-heavy scene's cost a longer slaved range could take
(docs/performance.md, 'Stop 25').

    .venv/bin/python benchmarks/slide_steps.py INDEX [--seed 20261124] [--rtol 1e-10] [--t-max 10]

The scene is the harness's scene INDEX of that seed (benchmarks/convergence.py), run to t_max (s)
with the trajectory recorded at every accepted step.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import convergence as cv  # noqa: E402

BANDS = [0.0, 1e-7, 1e-6, 1e-5, 1e-4, 1e-3, 1e-2, np.inf]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("index", type=int)
    ap.add_argument("--seed", type=int, default=20261124)
    ap.add_argument("--rtol", type=float, default=cv.DEFAULT_RTOL)
    ap.add_argument("--t-max", type=float, default=10.0, help="simulated time (s)")
    a = ap.parse_args(argv)
    if a.index < 0 or a.t_max <= 0.0:
        ap.error("INDEX must be >= 0 and --t-max > 0")
    import sweep

    cfg = cv.harness_scene(a.seed, a.index, a.rtol, a.t_max)
    res = sweep.simulate(cfg, trajectory=True)
    s, tr = res.summary, res.trajectory
    chi = tr["t"][-1] / tr["tau"][-1]
    u_hat = np.hypot(*np.asarray(tr["slip"]).T) * chi / cfg["disk"]["radius"]
    phi = np.asarray(tr["phi"])
    relax = u_hat / (cfg["contact"]["mu_d"] * phi)    # NaN at event rows (Phi not recorded)
    sliding = (np.asarray(tr["mode"]) != 0) & np.isfinite(relax)
    print(f"outcome {s['outcome']} at {s['t_end']:.3f} s: accepted {s['n_steps']} (sliding {s['n_steps_sliding']}), "
          f"rejected {s['n_rejected']} (sliding {s['n_rejected_sliding']}), transitions {s['n_transitions']}")
    print("relaxation time |u|/(mu_d Phi) (tau)   accepted sliding steps")
    for lo, hi in zip(BANDS[:-1], BANDS[1:]):
        print(f"  {lo:8.0e} .. {hi:8.0e}   {int(np.sum(sliding & (relax >= lo) & (relax < hi)))}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
