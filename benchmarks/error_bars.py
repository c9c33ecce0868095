"""Error bars of the cube (issue #8, items 1 and 6): what t_halt_error and the error estimate mean.

    python benchmarks/error_bars.py [--every K] [--config config/config.yaml]

Takes every K-th point (default 8) of a sweep config's grid and runs each scene three times:

1. as the sweep does (its levels, its tolerances): t_halt, t_halt_error, the level times;
2. as `outputs.error_estimate` reruns it (sweep.grid.error_reference: rtol/100, atol/100):
   t_halt_numerical_error, t_level_numerical_error, the count and slip_fraction errors, and the
   cost of the rerun (n_rhs, wall time);
3. with the levels extended by 1e-5 and 1e-6 rad: the halt placed 100x closer to the singularity
   (or located: a disk that reaches flat has halted there), the reference for t_halt of run 1.

For scenes halted in run 1 by the fit (not lying flat) it reports the true extrapolation error
|t_halt(1) - t_halt(3)| against t_halt_error = t_halt - t_last (the extrapolated remainder) and
against the former estimate (the change of the fit on the previous three levels), and, for every
scene, the numerical errors and the cost factor of the error estimate.
"""
from __future__ import annotations

import argparse
import itertools
import math
import sys
import time

import numpy as np
import yaml

from sweep import diagnostics, grid
import sweep.simulate  # noqa: F401  (the module; `sweep.simulate` is the function)

simulate = sys.modules["sweep.simulate"].simulate


def q(a, ps=(0, 50, 90, 100)) -> str:
    a = np.asarray([x for x in a if math.isfinite(x)])
    return "n/a" if a.size == 0 else " / ".join(f"{np.percentile(a, p):.3g}" for p in ps)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--every", type=int, default=8)
    ap.add_argument("--config", default="config/config.yaml")
    args = ap.parse_args()
    cfg = yaml.safe_load(open(args.config, encoding="utf-8"))
    settings = grid.normalize(cfg, check_scenes=False)
    ref_settings = grid.error_reference(grid.scene_settings(settings))
    ext = dict(settings, levels=list(settings["levels"]) + [1e-5, 1e-6])
    pts = list(itertools.product(*(settings["grid"][a] for a in grid.AXES)))[::args.every]
    simulate(grid.scene(settings, pts[0]))   # warm-up (numba cache)
    rows = []
    for p in pts:
        t0 = time.perf_counter()
        s1 = simulate(grid.scene(settings, p)).summary
        w1 = time.perf_counter() - t0
        t0 = time.perf_counter()
        s2 = simulate(grid.scene(ref_settings, p)).summary
        w2 = time.perf_counter() - t0
        s3 = simulate(grid.scene(ext, p)).summary
        lt = np.array([lv["t"] for lv in s1["levels"]])
        lv = np.array(settings["levels"])
        old = math.nan
        if np.isfinite(lt).sum() >= 4 and math.isfinite(s1["t_halt"]) and not s1["lay_flat"]:
            th2, _ = diagnostics._halt_from_three(lt[-4:-1], lv[-4:-1])
            old = abs(s1["t_halt"] - th2)
        lt2 = np.array([x["t"] for x in s2["levels"]])
        rows.append(dict(p=p, o1=s1["outcome"], o2=s2["outcome"], flat=s1["lay_flat"], th=s1["t_halt"],
                         err=s1["t_halt_error"], old=old, true=abs(s1["t_halt"] - s3["t_halt"]),
                         num=abs(s1["t_halt"] - s2["t_halt"]),
                         num_lt=float(np.nanmax(np.abs(lt - lt2))) if np.isfinite(lt - lt2).any() else math.nan,
                         cost=s2["n_rhs"] / s1["n_rhs"], wall=w2 / w1, w1=w1, w2=w2,
                         counts=[abs(s1[k] - s2[k]) for k in ("n_transitions", "n_stick", "n_impacts")],
                         slip=abs(s1["slip_fraction"] - s2["slip_fraction"])))
        r = rows[-1]
        print(f"{dict(zip(grid.AXES, p))} {r['o1']}/{r['o2']} flat={r['flat']} t_halt={r['th']:.6g} "
              f"t_halt_error={r['err']:.3g} former={r['old']:.3g} true={r['true']:.3g} "
              f"numerical={r['num']:.3g} level times numerical={r['num_lt']:.3g} rerun cost x{r['cost']:.2f}",
              flush=True)
    fit = [r for r in rows if r["o1"] == "halted" and not r["flat"] and math.isfinite(r["true"])]
    print(f"\n{len(rows)} scenes (every {args.every}th of {args.config}); {len(fit)} halted by the fit "
          "(not lying flat). Quantiles min / median / p90 / max:")
    print(f"  true error / t_halt_error (remainder)   {q([r['true'] / r['err'] for r in fit])}; "
          f"above 1 in {sum(r['true'] > r['err'] for r in fit)} of {len(fit)}")
    fo = [r for r in fit if math.isfinite(r["old"])]
    print(f"  true error / former estimate            {q([r['true'] / r['old'] for r in fo])}; "
          f"above 1 in {sum(r['true'] > r['old'] for r in fo)} of {len(fo)}")
    print(f"  t_halt_error (s)                        {q([r['err'] for r in fit])}")
    print(f"  t_halt_numerical_error (s), all halted  {q([r['num'] for r in rows if r['o1'] == 'halted'])}")
    print(f"  max level-time numerical error (s)      {q([r['num_lt'] for r in rows])}")
    print(f"  rerun cost (RHS evaluations, x main)    {q([r['cost'] for r in rows])}")
    tot1, tot2 = sum(r["w1"] for r in rows), sum(r["w2"] for r in rows)
    print(f"  total wall: main {tot1:.1f} s, rerun {tot2:.1f} s: error_estimate costs x{(tot1 + tot2) / tot1:.2f}")
    print(f"  outcome of the rerun differs in {sum(r['o1'] != r['o2'] for r in rows)} of {len(rows)}")
    same = [r for r in rows if r["o1"] == r["o2"]]
    moved = [r for r in same if any(r["counts"])]
    print(f"  event counts (transitions, sticks, impacts) moved by the rerun in {len(moved)} of {len(same)} "
          f"scenes with the same outcome" + (": " + "; ".join(f"{dict(zip(grid.AXES, r['p']))} {r['counts']}"
                                                               for r in moved[:6]) if moved else ""))
    print(f"  slip_fraction numerical error           {q([r['slip'] for r in same])}")


if __name__ == "__main__":
    main()
