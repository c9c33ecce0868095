"""Cost of optional outputs (issue #3, item 5): summary-only scene vs full output, paper's case.

    python benchmarks/output_cost.py
Summary only: outputs.normal_force_frequency false, kinematics false, no trajectory.
Full: both true and trajectory=True. Levels to 1e-3 (the default scene's first three), min of 21 interleaved runs.
"""
import copy
import time

import sweep
from sweep.scene import DEFAULTS, load_scene


CASES = (("summary only", False, False, False), ("normal-force frequency only", True, False, False),
         ("kinematics only", False, True, False), ("full (both + trajectory)", True, True, True))
scenes = []
for label, nff, kin, traj in CASES:
    cfg = copy.deepcopy(DEFAULTS)
    cfg["stop"]["levels"] = [0.1, 0.01, 0.001]
    cfg["outputs"].update(normal_force_frequency=nff, kinematics=kin)
    sc = load_scene(cfg)
    sweep.simulate(sc, trajectory=traj)      # warm-up
    scenes.append((label, sc, traj))
# interleaved repeats (the machine is shared: drifts in load hit every variant alike); minimum
ws = {c[0]: [] for c in CASES}
ks = {c[0]: [] for c in CASES}
last = {}
for _ in range(21):
    for label, sc, traj in scenes:
        w = time.perf_counter()
        r = sweep.simulate(sc, trajectory=traj)
        ws[label].append(time.perf_counter() - w)
        ks[label].append(r.summary["wall_time"])
        last[label] = r.summary
rows = [(c[0], min(ws[c[0]]), min(ks[c[0]]), last[c[0]]) for c in CASES]
base = rows[0][1]
print("| outputs | simulate (ms) | kernel (ms) | vs summary only | steps | rejected | RHS evals |")
print("|---|---|---|---|---|---|---|")
for label, w, k, s in rows:
    print(f"| {label} | {w * 1e3:.1f} | {k * 1e3:.1f} | {w / base:.2f}x | {s['n_steps']} | {s['n_rejected']} | {s['n_rhs']} |")
