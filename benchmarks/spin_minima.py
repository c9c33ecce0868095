#!/usr/bin/env python3
"""How close a free moment component comes to its stick threshold: the local minima of
|omega.a_i| (rad/s) in a window of a harness scene, read from the dense output at a fine grid of
sample times, for several rtol and spin_tol (docs/performance.md, 'Stop 37').

    .venv/bin/python benchmarks/spin_minima.py INDEX --seed 20261135 --tau 2011.9 2012.7 \
        [--rtol 1e-10 1e-11 1e-13] [--spin-tol 1e-7] [--axis 1] [--points 20001]

A stick phase at spin_tol begins where a free component slows to |omega.a_i| = spin_tol
(contact.stick_at_spin_tol). A run of dips whose minima drift slowly towards spin_tol starts a
stick sequence at the first dip that crosses it; that dip's margin (spin_tol minus its minimum,
against the error of omega.a_i at the run's rtol) decides at which rtol the run sees it. Minima of
exactly 0 are stuck phases. Each minimum is the grid's smallest value at a local minimum, within
the curvature times the grid spacing squared of the dip's true minimum.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent / "src"))

import convergence as cv  # noqa: E402


def moment_axis_rate(alpha, omega, axis):
    """omega.a_i (model.moment_axes_rates) from samples of alpha and omega (rad/s)."""
    w1, w2, w3 = omega[:, 0], omega[:, 1], omega[:, 2]
    if axis == 1:
        return w1
    s, c = np.sin(alpha), np.cos(alpha)
    return w2 * c - w3 * s if axis == 2 else w2 * s + w3 * c


def local_minima(values, ceiling):
    """Indices of the grid's local minima of `values` below `ceiling`."""
    v = values[1:-1]
    inner = (v <= values[:-2]) & (v < values[2:]) & (v < ceiling)
    return np.nonzero(inner)[0] + 1


def main(argv=None) -> int:
    import sweep
    from sweep.scene import load_scene

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("index", type=int)
    ap.add_argument("--seed", type=int, default=20261122)
    ap.add_argument("--tau", type=float, nargs=2, required=True, metavar=("FROM", "TO"),
                    help="the window, in the scene's dimensionless time")
    ap.add_argument("--rtol", type=float, nargs="+", default=[1e-10, 1e-11, 1e-13])
    ap.add_argument("--spin-tol", type=float, nargs="+", default=[None],
                    help="solver.spin_tol (rad/s) to run with; default: the scene's own")
    ap.add_argument("--axis", type=int, choices=(1, 2, 3), default=1)
    ap.add_argument("--points", type=int, default=20001)
    ap.add_argument("--ceiling", type=float, default=1e-5, help="list minima below this (rad/s)")
    ap.add_argument("--show", type=int, default=12, help="minima listed per run")
    a = ap.parse_args(argv)
    tau = np.linspace(a.tau[0], a.tau[1], a.points)
    for spin_tol in a.spin_tol:
        for rtol in a.rtol:
            cfg = cv.harness_scene(a.seed, a.index, rtol)
            if spin_tol is not None:
                cfg["solver"]["spin_tol"] = spin_tol
            scene = load_scene(cfg)
            res = sweep.simulate(scene, sample_times=tau * scene.chi)
            s = res.summary
            rate = np.abs(moment_axis_rate(np.asarray(res.samples["alpha"]), np.asarray(res.samples["omega"]), a.axis))
            idx = local_minima(rate, a.ceiling)
            used = scene.config["solver"]["spin_tol"]
            print(f"rtol {rtol:g}, spin_tol {used:g} rad/s: {s['outcome']}, t_halt {s['t_halt']!r} s, "
                  f"transitions {s['n_transitions']}, stick phases {s['n_stick']}; |omega.a_{a.axis}| "
                  f"{rate.min():.3e}..{rate.max():.3e} rad/s, {len(idx)} minima below {a.ceiling:g}:")
            for j in idx[:a.show]:
                print(f"    {rate[j]:.5e} at tau {tau[j]:.6f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
