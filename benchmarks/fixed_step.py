"""Fixed-step mode (a step ceiling dt): convergence on the paper's case and on harness scenes.

    python benchmarks/fixed_step.py [--scenes N]

`solver.method: fixed` is the adaptive DOP853 with its steps capped at `solver.dt` (docs/model.md):
it must converge to the adaptive result as rtol -> 0 with the same events, for every dt. Prints
(1) the paper's case: alpha at tau = 100 and the 0.1-level time for dt = 0.2 .. 0.0125 tau at
rtol 1e-10 and 1e-12, against the adaptive run at rtol 1e-13; (2) N harness scenes (seed 11): the
largest relative difference of the well-conditioned quantities between fixed (dt = 1e-3 s) and
adaptive at rtol 1e-12, and whether the event counts agree.
"""
from __future__ import annotations

import argparse
import copy
import math
import sys
import time
from pathlib import Path

import numpy as np

import sweep
from sweep.scene import DEFAULTS

sys.path.insert(0, str(Path(__file__).resolve().parent))
import convergence as harness  # noqa: E402

CHI = math.sqrt(1.25 * 0.03755 / 9.81)


def paper(method: str, rtol: float, dt_tau: float = 0.0):
    cfg = copy.deepcopy(DEFAULTS)
    cfg["stop"]["levels"] = [0.3, 0.1]
    cfg["outputs"]["normal_force_frequency"] = False
    cfg["solver"] = {"method": method, "rtol": rtol, "atol": rtol * 1e-2, "dt": dt_tau * CHI if dt_tau else 1e-3}
    t0 = time.perf_counter()
    r = sweep.simulate(cfg, sample_times=[100.0 * CHI])
    return r.samples["alpha"][0], r.summary["levels"][1]["t"], r.summary, time.perf_counter() - t0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--scenes", type=int, default=20)
    a = ap.parse_args(argv)
    a_ref, t_ref, s_ref, _ = paper("adaptive", 1e-13)
    print("paper's case, fixed-step (step ceiling dt) against adaptive rtol 1e-13:")
    print("| dt (tau) | rtol | alpha(tau=100) error | 0.1-level time error (rel) | steps | transitions | wall (s) |")
    print("|---|---|---|---|---|---|---|")
    for dt in (0.2, 0.1, 0.05, 0.025, 0.0125):
        for rtol in (1e-10, 1e-12):
            al, tl, s, w = paper("fixed", rtol, dt)
            print(f"| {dt} | {rtol:g} | {abs(al - a_ref):.1e} | {abs(tl - t_ref) / t_ref:.1e} | {s['n_steps']} | "
                  f"{s['n_transitions']} (ref {s_ref['n_transitions']}) | {w:.2f} |")
    rng = np.random.default_rng(11)
    worst = 0.0
    same = 0
    n = 0
    for _ in range(a.scenes):
        cfg = harness._valid_levels(harness.draw_scene(rng))
        cfg["stop"]["t_max"] = 60.0
        ad = harness._one_run(cfg, 1e-12)
        r = _fixed_run(cfg, 1e-12, 1e-3)
        if "q" not in ad or r is None:
            continue
        n += 1
        same += ad["events"] == r["events"]
        for k, v in ad["q"].items():
            if v is not None and math.isfinite(v) and r["q"].get(k) is not None and math.isfinite(r["q"][k]):
                worst = max(worst, abs(r["q"][k] - v) / max(abs(v), 1e-300))
    print(f"\nharness scenes (seed 11, t_max 60 s): {n}; fixed dt = 1e-3 s vs adaptive at rtol 1e-12: "
          f"largest relative difference {worst:.1e}; same event counts in {same}/{n}")
    return 0


def _fixed_run(cfg, rtol, dt):
    c = copy.deepcopy(cfg)
    c["solver"] = {"method": "fixed", "rtol": rtol, "atol": rtol * 1e-2, "dt": dt}
    chi = math.sqrt(({"solid": 1.0, "shell": 2.0}[c["disk"]["shape"]] + 4.0) / 4.0 * c["disk"]["radius"] / c["gravity"])
    times = [tau * chi for tau in harness.SAMPLE_TAU if tau * chi < c["stop"]["t_max"]]
    try:
        r = sweep.simulate(c, sample_times=times)
    except Exception:  # noqa: BLE001
        return None
    s = r.summary
    q = {f"t_level_{lv['inclination']:g}": lv["t"] for lv in s["levels"]}
    q["t_halt"] = s["t_halt"]
    for tau, al in zip(harness.SAMPLE_TAU, r.samples["alpha"]):
        q[f"alpha_tau_{tau:g}"] = float(al)
    return {"q": q, "events": [s["n_transitions"], s["n_stick"], s["n_impacts"]]}


if __name__ == "__main__":
    sys.exit(main())
