#!/usr/bin/env python3
"""One harness scene under chosen tolerances and contact-parameter scalings: its outcome, event
counts, steps, halt time and the harness quantities. For looking into a scene the harness flags.

    .venv/bin/python benchmarks/scene_probe.py INDEX [--seed 20261122] [--rtol 1e-10]
        [--atol-ratio 1e-2 ...] [--param-scale 1.0 ...]

Every combination of --atol-ratio (atol = ratio x rtol) and --param-scale (mu_s, mu_d, k1, k2, k3
multiplied by it: a persistent perturbation of the dynamics, unlike the harness's alpha0 + 1e-10)
is run once; the scene is the harness's scene INDEX of that seed (benchmarks/convergence.py).
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import convergence as cv  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("index", type=int)
    ap.add_argument("--seed", type=int, default=20261122)
    ap.add_argument("--rtol", type=float, default=cv.DEFAULT_RTOL)
    ap.add_argument("--atol-ratio", type=float, nargs="+", default=[cv.ATOL_RATIO])
    ap.add_argument("--param-scale", type=float, nargs="+", default=[1.0])
    a = ap.parse_args(argv)
    scene = cv.harness_scene(a.seed, a.index)
    print("atol_ratio param_scale outcome [transitions, stick phases, impacts] steps t_halt_s budget")
    for ratio in a.atol_ratio:
        for scale in a.param_scale:
            cfg = json.loads(json.dumps(scene))
            for key in ("mu_s", "mu_d", "k1", "k2", "k3"):
                cfg["contact"][key] *= scale
            r = cv._one_run(cfg, a.rtol, 0.0, ratio)
            if "exception" in r:
                print(ratio, scale, r["exception"], flush=True)
                continue
            print(f"{ratio:g} {scale!r} {r['outcome']} {r['events']} {r['n_steps']} {r['q']['t_halt']!r} "
                  f"{r['budget']:.2e}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
