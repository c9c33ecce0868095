#!/usr/bin/env python3
"""Slow slip near the edge of the friction cone (mu_d -> mu_s): cost against content, this tree
against a base commit side by side (docs/model.md, 'Slow slip').

    .venv/bin/python benchmarks/slow_slip.py [--base 746a2c3] [--random 30] [--seed 20261150]
        [--parts paper,accuracy,k3,random,mechanism] [--scene SEED:INDEX]

Parts (each prints one table; this tree and the base run in two worker processes, the base
extracted with `git archive` into a temporary directory with its own numba cache):

* paper: the paper's disk (config/scenes/kessler2002.yaml) at mu_d 0.3, 0.49, 0.499, 0.5 (mu_s 0.5),
  each kernel at its defaults and this tree again at each --slave-tols:
  accepted steps (rejected), right-hand sides, located events, roll<->slip transitions, slip
  fraction, CPU; and the steps at mu_d = mu_s over those at 0.3.
* accuracy: the same disk at mu_d = mu_s, its level times and t_halt at the default settings
  against the converged answer (this tree at rtol 1e-12 with slave_tol 1e-6: the direction
  integrated wherever its relaxation time times the motion's rate exceeds 1e-6), and the change
  under alpha0 + 1e-10 rad (the sensitivity of the dynamics, to tell it from the numerical error).
* k3: the same scene with k3 = 0 (halts, or runs into step_limit).
* random: random harness scenes (benchmarks/convergence.py's draw, levels 0.1 .. 0.001 rad,
  t_max 300 s) with mu_d / mu_s drawn in [0.97, 1], and the same scenes at mu_d = 0.9 mu_s:
  outcomes that are failures, and the total steps of the near-edge set over the 0.9 set.
* mechanism: where the steps of the mu_d = mu_s scene (or of the harness scene --scene SEED:INDEX)
  go, by contact state (ROLL, SLIDE, SLAVED)
  and slip speed |u| (m/s): steps, simulated time, mean step, and for SLIDE the median of
  h mu_d Phi / |u| (dimensionless): a constant there means the step is held at the stability
  bound of the explicit method by the direction's relaxation rate ~ mu_d Phi / |u|. Then the
  sliding steps by why they are not slaved (the first hand-over condition their start state fails).
* bands: tries per unit of content (precession cycles + transitions, stick phases, impacts) of the
  convergence harness's scenes (--bands of the main draw, a fifth as many near the edge) at rtol
  1e-10, by mu_d / mu_s band: median, p99, max and the median against that of mu_d / mu_s < 0.9.
* sweep: the default sweep's scenes (config/config.yaml: this tree's grid, mu_d = mu_s included, on
  this kernel; the base's grid on the base kernel), each run once, CPU summed: what the sweep's
  integration costs (the sweep also reruns each scene for its error bars, alike on both sides).
"""
from __future__ import annotations

import argparse
import copy
import json
import math
import subprocess
import sys
import tarfile
import tempfile
from pathlib import Path

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[1]
HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
import convergence as cv  # noqa: E402

FAILURES = ("step_size_underflow", "step_limit", "numerical_error")
# solver keys newer than the bases this benchmark is run against (part sweep leaves them out there)
SOLVER_KEYS_SINCE = ("stiff_ratio",)


def extract(commit: str, into: Path) -> Path:
    """src/ of `commit` into `into` (git archive); returns its src directory."""
    tar = into / "src.tar"
    subprocess.run(["git", "-C", str(ROOT), "archive", "--format=tar", "-o", str(tar), commit, "src"], check=True)
    with tarfile.open(tar) as t:
        t.extractall(into, filter="data")
    return into / "src"
MUDS = (0.3, 0.49, 0.499, 0.5)
U_BANDS = (0.0, 1e-9, 1e-7, 1e-5, 1e-3, 1e-1, math.inf)   # m/s

WORKER = r"""
import json, math, sys, time
import numpy as np
from sweep.scene import load_scene
from sweep.simulate import run_kernel, simulate
from sweep.core import model
BANDS = json.loads(sys.argv[1])


def why_sliding(sc, tr):
    # the sliding steps (SLIDE: the direction integrated) by the first of the hand-over's tests
    # (slip.try_slave, settle_onto) that the step's start state fails, and where it passes them
    # all, whether it is above the slaving speed (contact_rhs.slave_speed): {reason: [steps, time
    # (s)]}, and the median over the steps with an attracting direction of its relaxation rate
    # (rad - c') over the slaving speed's proxy for it, mu_d Phi; None for a kernel without the
    # slaved slip's second order
    try:
        from sweep.core import constants as CN, contact_rhs as CR, layout as L, slip as SL
        CR.second_order_applies
    except (ImportError, AttributeError):
        return None
    p = np.array(sc.params)
    stol = p[model.P_SLAVE]
    tau = tr[:, 0]
    out = {}
    ratios = []
    for k in np.nonzero(tr[1:, 2 + model.N_FULL] == CN.SLIDE)[0]:
        y = tr[k, 1:1 + model.N_FULL].copy()
        cs = np.zeros(L.N_CS)
        cs[L.CS_MODE], cs[L.CS_SIDE] = CN.SLIDE, (1.0 if y[model.Y_ALPHA] >= 0.0 else -1.0)
        cs[L.CS_SIG:L.CS_SIG + 3] = np.where(np.array(model.moment_axes_rates(y)) >= 0.0, 1.0, -1.0)
        system = L.System(p, cs, model.N_CORE, np.zeros((L.N_WORK, L.N_WCOLS)), np.zeros(L.N_ISTATS, np.int64))
        dy, aux = np.zeros(model.N_FULL), np.zeros(model.N_AUX)
        CR.eval_rhs(tau[k], y, system, dy, aux)
        u = math.hypot(y[model.Y_U1], y[model.Y_U2])
        root = SL.attracting_direction(math.atan2(y[model.Y_U2], y[model.Y_U1]), u, tau[k], y, system)
        if not math.isfinite(root):
            why = "no attracting direction (a spiral or a jam)"
        else:
            ev = L.Eval(tau[k], y, system, np.zeros(model.N_FULL), np.zeros(model.N_AUX))
            cross0, rad0 = CR.slip_rates(root, u, ev, np.zeros(model.N_FULL))
            lag, dcross, err = CR.root_lag(root, u, ev)
            ratios.append((rad0 - dcross) / (p[model.P_MUD] * aux[model.X_PHI]))
            if not CR.second_order_applies(lag, err, p):
                why = "first-order measure > 2 slave_tol (the series does not hold)"
            else:
                lag, err = CR.second_order(root, lag, dcross, err, ev)
                turn = math.atan2(y[model.Y_U2], y[model.Y_U1]) - (root + lag)
                turn = abs(math.atan2(math.sin(turn), math.cos(turn)))
                if err > stol:
                    why = "err in (slave_tol, 2 slave_tol]"
                elif turn > stol * stol:
                    why = "direction > slave_tol^2 rad from the manifold (not settled)"
                elif u > CR.slave_speed(y, aux, p):
                    why = "passes the tests, above the slaving speed"
                else:
                    why = "passes the tests, below the slaving speed (refused earlier in the slide)"
        row = out.setdefault(why, [0, 0.0])
        row[0] += 1
        row[1] += float((tau[k + 1] - tau[k]) * sc.chi)
    return {"reasons": out, "relax_over_proxy": float(np.median(ratios)) if ratios else math.nan}


for line in sys.stdin:
    job = json.loads(line)
    cfg = job["cfg"]
    t0 = time.process_time()
    if job.get("mechanism"):
        cfg.setdefault("outputs", {})["kinematics"] = True
        sc = load_scene(cfg)
        out = run_kernel(sc, None, 4_000_000)
        tr = out.trajectory
        chi, R = sc.chi, cfg["disk"]["radius"]
        tau = tr[:, 0]
        h = np.diff(tau)
        u = np.hypot(tr[1:, 1 + model.Y_U1], tr[1:, 1 + model.Y_U2]) * R / chi
        mode = tr[1:, 2 + model.N_FULL]
        phi = tr[1:, 1 + model.N_FULL]
        uhat = np.hypot(tr[1:, 1 + model.Y_U1], tr[1:, 1 + model.Y_U2])
        rows = []
        for m in (0, 1, 2):
            for lo, hi in zip(BANDS[:-1], BANDS[1:]):
                sel = (mode == m) & (u >= lo) & (u < (hi if hi is not None else math.inf))
                if not sel.any():
                    continue
                ok = sel & np.isfinite(phi)   # (a row at an event carries no normal force)
                stab = float(np.median(h[ok] * sc.params[model.P_MUD] * phi[ok] / np.maximum(uhat[ok], 1e-300))) if ok.any() else math.nan
                rows.append([m, lo, hi, int(sel.sum()), float(h[sel].sum() * chi), float(h[sel].mean() * chi), stab])
        print(json.dumps({"rows": rows, "why": why_sliding(sc, tr), "cpu": time.process_time() - t0}), flush=True)
        continue
    if job.get("anatomy"):
        from sweep.core import layout as L
        from sweep import outcomes
        sc = load_scene(cfg)
        tau = np.array(job["anatomy"], dtype=float)
        out = run_kernel(sc, tau[tau * sc.chi < cfg["stop"]["t_max"]])
        ist = out.istats
        print(json.dumps({"outcome": outcomes.NAMES[int(ist[L.I_OUTCOME])],
                          "tries": int(ist[L.I_STEPS] + ist[L.I_REJECTED]),
                          "cycles": abs(float(out.y_end[model.Y_THETA])) / (2.0 * math.pi),
                          "events": int(ist[L.I_TRANS] + ist[L.I_STICK] + ist[L.I_IMPACTS]),
                          "cpu": time.process_time() - t0}), flush=True)
        continue
    try:
        s = simulate(cfg).summary
        out = {k: s[k] for k in ("outcome", "t_end", "t_halt", "t_halt_error", "n_steps", "n_rejected", "n_rhs",
                                 "n_events", "n_transitions", "n_stick", "slip_fraction")}
        out["levels"] = [lv["t"] for lv in s["levels"]]
    except Exception as exc:
        out = {"error": f"{type(exc).__name__}: {exc}"}
    out["cpu"] = time.process_time() - t0
    print(json.dumps(out), flush=True)
"""


class Side:
    """One kernel in a worker process: this tree's src/ or a base commit's."""

    def __init__(self, src: Path, cache: Path | None, knows_slave_tol: bool):
        import os
        import subprocess
        env = dict(os.environ, PYTHONPATH=str(src))
        if cache is not None:   # the base's own cache (this tree's is the one its runs use)
            env["NUMBA_CACHE_DIR"] = str(cache)
        bands = [b if math.isfinite(b) else None for b in U_BANDS]
        self.proc = subprocess.Popen([sys.executable, "-c", WORKER, json.dumps(bands)], stdin=subprocess.PIPE,
                                     stdout=subprocess.PIPE, text=True, env=env)
        self.knows_slave_tol = knows_slave_tol

    def run(self, cfg: dict, mechanism: bool = False, anatomy: list | None = None) -> dict:
        cfg = copy.deepcopy(cfg)
        if not self.knows_slave_tol:
            cfg.get("solver", {}).pop("slave_tol", None)
        self.proc.stdin.write(json.dumps({"cfg": cfg, "mechanism": mechanism, "anatomy": anatomy}) + "\n")
        self.proc.stdin.flush()
        return json.loads(self.proc.stdout.readline())

    def close(self):
        self.proc.stdin.close()
        self.proc.wait()


def paper(mu_d: float, **solver) -> dict:
    cfg = yaml.safe_load((ROOT / "config/scenes/kessler2002.yaml").read_text())
    cfg["contact"]["mu_d"] = mu_d
    cfg.setdefault("solver", {}).update(solver)
    return cfg


def variants(sides: dict, slave_tols: list[float]):
    """(label, side, solver settings): each kernel at its defaults, and this tree at each slave_tol."""
    for name, side in sides.items():
        yield name, side, {}
        if name == "this tree":
            for st in slave_tols:
                yield f"this tree, slave_tol {st:g}", side, {"slave_tol": st}


def part_paper(sides: dict, slave_tols: list[float]) -> list[str]:
    lines = ["## The paper's disk as mu_d approaches mu_s = 0.5", "",
             "| kernel | mu_d | steps (rejected) | RHS | located events | transitions | slip fraction | CPU (s) |",
             "|---|---|---|---|---|---|---|---|"]
    for name, side, solver in variants(sides, slave_tols):
        steps = {}
        for mu_d in MUDS:
            r = side.run(paper(mu_d, **solver))
            steps[mu_d] = r["n_steps"]
            lines.append(f"| {name} | {mu_d:g} | {r['n_steps']} ({r['n_rejected']}) | {r['n_rhs']} | {r['n_events']} | "
                         f"{r['n_transitions']} | {r['slip_fraction']:.2f} | {r['cpu']:.2f} |")
        lines.append(f"| {name} | steps at 0.5 / at 0.3 | **{steps[0.5] / steps[0.3]:.2f}x** | | | | | |")
    return lines


def part_accuracy(sides: dict, slave_tols: list[float]) -> list[str]:
    ref = sides["this tree"].run(paper(0.5, rtol=1e-12, atol=1e-14, slave_tol=1e-6))
    pert = copy.deepcopy(paper(0.5, rtol=1e-12, atol=1e-14, slave_tol=1e-6))
    pert["initial"]["alpha"] += 1e-10
    sens = sides["this tree"].run(pert)
    ref_v = ref["levels"] + [ref["t_halt"]]
    lines = ["## Accuracy at mu_d = mu_s (levels 0.1, 0.01, 1e-3, 1e-4 rad, then t_halt)", "",
             f"converged (this tree, rtol 1e-12, slave_tol 1e-6, {ref['n_steps']} steps): "
             + ", ".join(f"{v!r}" for v in ref_v) + " s", "",
             "| run | relative difference to the converged values | largest |", "|---|---|---|"]
    sv = sens["levels"] + [sens["t_halt"]]
    d = [abs(a - b) / b for a, b in zip(sv, ref_v)]
    lines.append(f"| alpha0 + 1e-10 rad (sensitivity) | {' '.join(f'{x:.1e}' for x in d)} | {max(d):.1e} |")
    for name, side, solver in variants(sides, slave_tols):
        r = side.run(paper(0.5, **solver))
        v = r["levels"] + [r["t_halt"]]
        d = [abs(a - b) / b for a, b in zip(v, ref_v)]
        lines.append(f"| {name}, default settings | {' '.join(f'{x:.1e}' for x in d)} | **{max(d):.1e}** |")
    return lines


def part_k3(sides: dict, slave_tols: list[float]) -> list[str]:
    lines = ["## mu_d = mu_s with k3 = 0", "", "| kernel | outcome | t_halt (s) | steps (rejected) | CPU (s) |",
             "|---|---|---|---|---|"]
    for name, side, solver in variants(sides, slave_tols):
        cfg = paper(0.5, **solver)
        cfg["contact"]["k3"] = 0.0
        r = side.run(cfg)
        lines.append(f"| {name} | {r['outcome']} | {r['t_halt']:.4f} ± {r['t_halt_error']:.2g} | "
                     f"{r['n_steps']} ({r['n_rejected']}) | {r['cpu']:.1f} |")
    return lines


def random_scenes(n: int, seed: int) -> list[tuple[dict, dict]]:
    """(near-edge, 0.9 mu_s) pairs of harness scenes, mu_d / mu_s in [0.97, 1] for the first."""
    rng = np.random.default_rng([seed, 97])
    pairs = []
    for _ in range(n):
        cfg = cv._valid_levels(cv.draw_scene(rng))
        edge = copy.deepcopy(cfg)
        edge["contact"]["mu_d"] = cfg["contact"]["mu_s"] * rng.uniform(0.97, 1.0)
        low = copy.deepcopy(cfg)
        low["contact"]["mu_d"] = 0.9 * cfg["contact"]["mu_s"]
        pairs.append((edge, low))
    return pairs


def part_random(sides: dict, n: int, seed: int) -> list[str]:
    pairs = random_scenes(n, seed)
    lines = [f"## {n} random harness scenes (seed {seed}) with mu_d / mu_s in [0.97, 1], and the same at 0.9", "",
             "| kernel | failures near the edge | failures at 0.9 | steps near the edge | steps at 0.9 | ratio | CPU near the edge (s) |",
             "|---|---|---|---|---|---|---|"]
    for name, side in sides.items():
        fail_e, fail_l, st_e, st_l, cpu_e = [], [], 0, 0, 0.0
        for i, (edge, low) in enumerate(pairs):
            re, rl = side.run(edge), side.run(low)
            if "error" in re or re["outcome"] in FAILURES:
                fail_e.append(f"{i}:{re.get('outcome', re.get('error'))}")
            if "error" in rl or rl["outcome"] in FAILURES:
                fail_l.append(f"{i}:{rl.get('outcome', rl.get('error'))}")
            st_e += re.get("n_steps", 0) + re.get("n_rejected", 0)
            st_l += rl.get("n_steps", 0) + rl.get("n_rejected", 0)
            cpu_e += re["cpu"]
        lines.append(f"| {name} | {len(fail_e)} {fail_e[:4]} | {len(fail_l)} {fail_l[:4]} | {st_e} | {st_l} | "
                     f"**{st_e / max(st_l, 1):.2f}** | {cpu_e:.1f} |")
    lines.append("")
    lines.append("(steps: accepted + rejected)")
    return lines


def grid_scenes(config_text: str) -> list[dict]:
    """Every scene of a sweep config's tensor grid (sweep.grid), its solver settings as the sweep's."""
    import itertools

    from sweep import grid
    from sweep import axes as sweep_axes

    with tempfile.NamedTemporaryFile("w", suffix=".yaml", delete=False) as fh:
        fh.write(config_text)
    sw = grid.load_sweep([(fh.name, "config")])
    Path(fh.name).unlink()
    axes = [sw.settings["grid"][a] for a in sweep_axes.AXES]
    return [grid.scene(sw.settings, point) for point in itertools.product(*axes)]


def part_sweep(sides: dict, base: str | None) -> list[str]:
    """The default sweep's scenes: this tree's config/config.yaml (mu_d = mu_s included) on this
    kernel against the base's config on the base kernel, one run of each scene, alternating."""
    import subprocess
    this = grid_scenes((ROOT / "config/config.yaml").read_text())
    lines = ["## The default sweep's scenes (one run each, CPU summed)", "",
             "| kernel | config | scenes | steps + rejected | CPU (s) | failures |", "|---|---|---|---|---|---|"]
    runs = {"this tree": ("config/config.yaml of this tree", this)}
    if base:
        text = subprocess.run(["git", "-C", str(ROOT), "show", f"{base}:config/config.yaml"], check=True,
                              capture_output=True, text=True).stdout
        # (this tree's sweep settings fill in its solver keys; a base older than a key rejects it, so
        # the keys this tree added since are left out: each kernel at its own defaults)
        base_scenes = grid_scenes(text)
        for cfg in base_scenes:
            for key in SOLVER_KEYS_SINCE:
                cfg.get("solver", {}).pop(key, None)
        runs[f"base {base}"] = (f"config/config.yaml of {base}", base_scenes)
    totals = {}
    for name, (label, scenes) in runs.items():
        steps, cpu, fails = 0, 0.0, 0
        for cfg in scenes:
            r = sides[name].run(cfg)
            steps += r.get("n_steps", 0) + r.get("n_rejected", 0)
            cpu += r["cpu"]
            fails += "error" in r or r["outcome"] in FAILURES
        totals[name] = cpu
        lines.append(f"| {name} | {label} | {len(scenes)} | {steps} | {cpu:.1f} | {fails} |")
    if base:
        lines.append(f"| this tree / base | | | | **{totals['this tree'] / totals[f'base {base}']:.2f}x** | |")
    return lines


def part_bands(sides: dict, n: int, seed: int) -> list[str]:
    """Tries per unit of content (precession cycles + transitions, stick phases, impacts) of the
    convergence harness's scenes at its default settings (rtol 1e-10; n of the main draw and n/5
    of the near-edge band), by mu_d / mu_s band, on each kernel."""
    scenes = [cv._valid_levels(cv.draw(seed, i)) for i in range(n)]
    scenes += [cv._valid_levels(cv.draw(seed, cv.EDGE_BASE + j)) for j in range(n // 5)]
    for c in scenes:
        c["solver"] = {"rtol": cv.DEFAULT_RTOL, "atol": cv.DEFAULT_RTOL * cv.ATOL_RATIO}
    lines = [f"## Tries per unit of content by mu_d / mu_s (harness seed {seed}: {n} scenes + {n // 5} near the edge, "
             "rtol 1e-10)", "", "| kernel | band | scenes | median | p99 | max | median / [0, 0.9)'s | failures | tries |",
             "|---|---|---|---|---|---|---|---|---|"]
    for name, side in sides.items():
        rows = []
        for c in scenes:
            r = side.run(c, anatomy=list(cv.SAMPLE_TAU))
            ratio = c["contact"]["mu_d"] / c["contact"]["mu_s"]
            rows.append((ratio, r["tries"] / max(r["cycles"] + r["events"], 1.0), r["tries"], r["outcome"]))
        base = None
        for lo, hi in cv.BANDS:
            sel = [x for x in rows if lo <= x[0] < hi or x[0] == hi == 1.0]
            if not sel:
                continue
            v = np.array([x[1] for x in sel])
            med = float(np.median(v))
            base = med if base is None else base
            fails = sum(x[3] in FAILURES for x in sel)
            lines.append(f"| {name} | [{lo:g}, {hi:g}{']' if hi == 1.0 else ')'} | {len(sel)} | {med:.1f} | "
                         f"{np.percentile(v, 99):.1f} | {v.max():.1f} | {med / base:.2f} | {fails} | {sum(x[2] for x in sel)} |")
        v = np.array([x[1] for x in rows])
        lines.append(f"| {name} | all | {len(rows)} | {np.median(v):.1f} | {np.percentile(v, 99):.1f} | {v.max():.1f} | "
                     f"p99 / median {np.percentile(v, 99) / np.median(v):.1f} | "
                     f"{sum(x[3] in FAILURES for x in rows)} | {sum(x[2] for x in rows)} |")
    return lines


def part_mechanism(sides: dict, scene: str | None = None) -> list[str]:
    """Where the steps go: the paper's disk at mu_d = mu_s, or the harness scene `scene`
    ("SEED:INDEX", benchmarks/convergence.py's draw, at rtol 1e-10)."""
    names = {0: "ROLL", 1: "SLIDE", 2: "SLAVED"}
    if scene:
        seed, index = (int(x) for x in scene.split(":"))
        cfg = cv.harness_scene(seed, index)
        cfg.setdefault("solver", {})["rtol"] = 1e-10
        title = f"harness scene {index} of seed {seed} (mu_d / mu_s {cfg['contact']['mu_d'] / cfg['contact']['mu_s']:.3f})"
    else:
        cfg, title = paper(0.5), "mu_d = mu_s"
    whys = {}
    lines = [f"## Where the steps go at {title} (default settings)", "",
             "| kernel | contact state | |u| (m/s) | steps | time (s) | mean step (s) | median h mu_d Phi / |u| |",
             "|---|---|---|---|---|---|---|"]
    for name, side in sides.items():
        r = side.run(cfg, mechanism=True)
        for m, lo, hi, k, tt, hm, stab in r["rows"]:
            hi_t = "inf" if hi is None else f"{hi:g}"
            st = f"{stab:.2g}" if m != 0 else "–"
            lines.append(f"| {name} | {names[int(m)]} | [{lo:g}, {hi_t}) | {k} | {tt:.3f} | {hm:.2g} | {st} |")
        whys[name] = r.get("why")
    lines += ["", "Why the sliding steps (SLIDE) are not slaved: the first test of the hand-over "
              "(slip.try_slave) that the step's start state fails, and for those that pass them all, "
              "their speed against the slaving speed (contact_rhs.slave_speed)", "",
              "| kernel | reason | steps | time (s) |", "|---|---|---|---|"]
    for name, why in whys.items():
        if not why:
            continue
        for reason, (k, tt) in sorted(why["reasons"].items(), key=lambda kv: -kv[1][0]):
            lines.append(f"| {name} | {reason} | {k} | {tt:.3f} |")
        lines.append(f"| {name} | median relaxation rate (rad - c') / mu_d Phi (the slaving speed's proxy) "
                     f"| {why['relax_over_proxy']:.2f} | |")
    return lines


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--base", default="746a2c3", help="the commit to compare with (default: before slow slip)")
    ap.add_argument("--random", type=int, default=30, help="random scene pairs in part 'random'")
    ap.add_argument("--seed", type=int, default=20261150)
    ap.add_argument("--scene", default=None, metavar="SEED:INDEX",
                    help="part 'mechanism' on this harness scene instead of the paper's disk")
    ap.add_argument("--parts", default="paper,accuracy,k3,random,mechanism,sweep,bands")
    ap.add_argument("--bands", type=int, default=150, help="harness scenes of the main draw in part 'bands'")
    ap.add_argument("--slave-tols", type=float, nargs="*", default=[1e-4, 1e-3, 3e-3],
                    help="this tree again at these solver.slave_tol in parts paper, accuracy and k3 (the default is 0)")
    a = ap.parse_args(argv)
    parts = a.parts.split(",")
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        sides = {"this tree": Side(ROOT / "src", None, True)}
        if a.base:
            sides[f"base {a.base}"] = Side(extract(a.base, tmp), tmp / "cache-base", False)
        out = []
        try:
            # compile (or load) each kernel before anything is timed: a short run of the paper's disk
            for side in sides.values():
                warm = paper(0.3)
                warm["stop"]["t_max"] = 0.05
                side.run(warm)
            if "paper" in parts:
                out += part_paper(sides, a.slave_tols) + [""]
            if "accuracy" in parts:
                out += part_accuracy(sides, a.slave_tols) + [""]
            if "k3" in parts:
                out += part_k3(sides, a.slave_tols) + [""]
            if "random" in parts:
                out += part_random(sides, a.random, a.seed) + [""]
            if "mechanism" in parts:
                out += part_mechanism(sides, a.scene) + [""]
            if "sweep" in parts:
                out += part_sweep(sides, a.base) + [""]
            if "bands" in parts:
                out += part_bands(sides, a.bands, a.seed) + [""]
        finally:
            for side in sides.values():
                side.close()
    text = "\n".join(out)
    print(text)
    (HERE / "out").mkdir(exist_ok=True)
    (HERE / "out" / "slow_slip.md").write_text(text + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
