"""Reproducers of the integrator problems found by tests/test_stress.py (printed diagnostics).

    python benchmarks/reproducers.py [name ...]

For each scene: outcome, counts, and where the steps go (trajectory: mode, slip speed, step sizes,
side changes, energy over the last part of the run).
"""
from __future__ import annotations

import copy
import sys

import numpy as np

import sweep
from sweep import model
from sweep.scene import DEFAULTS, load_scene

CASES = {
    "upright_0.02": {"initial": {"alpha": 0.02}},
    "flat_1.5": {"initial": {"alpha": 1.5}},
    "spin_0.1": {"initial": {"omega": [0.0, 0.0, -0.1]}},
    "mu_1.5": {"contact": {"mu_s": 1.5, "mu_d": 1.5}},
    "fixed_1e-3": {"solver": {"method": "fixed", "dt": 1e-3}},
}


def cfg_of(mods, max_steps=200_000):
    cfg = copy.deepcopy(DEFAULTS)
    for sec, vals in mods.items():
        cfg[sec].update(vals)
    cfg["stop"]["max_steps"] = max_steps
    return cfg


def main(names):
    for name in names or CASES:
        sc = load_scene(cfg_of(CASES[name]))
        r = sweep.simulate(sc, trajectory=True)
        s, tr = r.summary, r.trajectory
        print(f"\n== {name}: {CASES[name]}")
        print({k: s[k] for k in ("outcome", "t_end", "n_steps", "n_rejected", "n_rhs", "n_events", "n_transitions",
                                 "n_stick", "n_impacts", "energy_initial", "energy_final", "slip_fraction")})
        t = tr["t"]
        dt = np.diff(t)
        E = tr["energy"]
        rise = np.diff(E)
        i_rise = np.flatnonzero(rise > 1e-9 * E[0])
        if i_rise.size:
            i = i_rise[0]
            print(f"first energy rise > 1e-9 E0 between rows {i},{i + 1}: t = {t[i]:.6f} s, E {E[i]:.6e} -> {E[i + 1]:.6e} J, "
                  f"mode {tr['mode'][i]}->{tr['mode'][i + 1]}, |slip| {np.hypot(*tr['slip'][i]):.3e} m/s, alpha {tr['alpha'][i]:.6f}")
        n = t.size
        for lo, hi in ((0, n // 2), (n // 2, 9 * n // 10), (9 * n // 10, n)):
            sl = slice(lo, hi)
            d = dt[lo:max(hi - 1, lo + 1)]
            print(f"rows {lo:6d}-{hi:6d}: t {t[lo]:.6f}..{t[hi - 1]:.6f} s, sliding {np.mean(tr['mode'][sl]):.2f}, "
                  f"median step {np.median(d) if d.size else np.nan:.2e} s, sign changes of alpha "
                  f"{int(np.sum(np.diff(np.sign(tr['alpha'][sl])) != 0))}, median |slip| "
                  f"{np.median(np.hypot(tr['slip'][sl, 0], tr['slip'][sl, 1])):.2e} m/s, alpha range "
                  f"[{tr['alpha'][sl].min():.3g}, {tr['alpha'][sl].max():.3g}], Phi range "
                  f"[{np.nanmin(tr['phi'][sl]):.3g}, {np.nanmax(tr['phi'][sl]):.3g}]")
        k = max(n - 4, 0)
        for i in range(k, n):
            print(f"  last rows: t {t[i]:.9f} alpha {tr['alpha'][i]:.9f} omega {np.array2string(tr['omega'][i], precision=5)} "
                  f"slip {np.array2string(tr['slip'][i], precision=3)} mode {tr['mode'][i]} phi {tr['phi'][i]:.4g}")


if __name__ == "__main__":
    main(sys.argv[1:])
