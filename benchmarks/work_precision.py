"""Work-precision benchmark: sweep's hybrid integrator vs SciPy solve_ivp on the same model (issue #3).

    python benchmarks/work_precision.py            # full run (~15-30 min on 2 shared cores)
    python benchmarks/work_precision.py --quick    # paper's case only, few tolerances (~11 min)
    python benchmarks/work_precision.py --quick --rtols 1e-6 1e-8 1e-10 --no-compile-probe
    python3 run.py bench [--quick]                 # the same, in the project venv

For each benchmark scene (the paper's case, a slip-heavy case, a near-upright case, a shell):

* reference: sweep adaptive at rtol 1e-13 (atol 1e-15), checked against SciPy DOP853 at the same
  tolerance (the agreement is printed and written to the report);
* error vs wall time for sweep adaptive (rtol 1e-4..1e-12), sweep fixed-step (a range of dt) and
  SciPy RK45, DOP853, LSODA, Radau (rtol 1e-4..1e-12, numba-compiled RHS), plus SciPy DOP853 with the
  plain Python/NumPy RHS (`rhs.py_func`) on the paper's case;
* errors: relative error of the time of the 0.1 rad level (the deepest well-conditioned level for
  all four scenes: a 1e-10 change of alpha(0) moves it by < 1e-8; the 1e-3 level of the paper's case
  is chaotic, tests/test_physics.py), and the max error of alpha at 201 sample times tau in [0, 100];
* time: minimum of several runs after a warm-up run (numba compilation excluded: it is measured
  separately, in subprocesses, with an empty and a warm NUMBA_CACHE_DIR);
* outputs under benchmarks/out/: work_precision.md (tables, matched-error ratios, targets),
  work_precision.json (all points), work_precision.png (log-log plots).

A SciPy combination is skipped when its predicted time (the previous, looser tolerance's time times
the observed growth) exceeds BUDGET_S = 60 s, and any single SciPy run is abandoned after 60 s; after
an abandoned run the tighter tolerances are skipped too, unless no tolerance has finished yet (a peer
can stall at a loose tolerance only). The report lists what was skipped.
"""
from __future__ import annotations

import argparse
import copy
import json
import math
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(ROOT / "src"))
sys.path.insert(0, str(ROOT))   # the SciPy peer: tests.reference.scipy_driver

import sweep  # noqa: E402
from sweep.scene import DEFAULTS, load_scene  # noqa: E402

from tests.reference.scipy_driver import numpy_backend, run_scipy  # noqa: E402

OUT = HERE / "out"
BUDGET_S = 60.0
SAMPLE_TAU = np.linspace(0.0, 100.0, 201)
LEVELS = [0.3, 0.1]          # the error is measured on the 0.1 rad level (index 1)
LEVEL_INDEX = 1
MATCH_ERRORS = [1e-6, 1e-8, 1e-10]

# name -> (description, scene overrides)
SCENES = {
    "paper": ("the paper's case (Kessler & O'Reilly 2002, sec. 7)", {}),
    "slip": ("slip-heavy: mu_s 0.1, mu_d 0.08 (slides ~40% of the time)",
             {"contact": {"mu_s": 0.1, "mu_d": 0.08}}),
    "upright": ("near-upright start: alpha0 0.3 rad, omega3 -30 rad/s",
                {"initial": {"alpha": 0.3, "omega": [0.0, 0.0, -30.0]}}),
    "shell": ("thin shell (k^2 = 2), otherwise the paper's case", {"disk": {"shape": "shell"}}),
}


def scene_cfg(name: str, **solver) -> dict:
    cfg = copy.deepcopy(DEFAULTS)
    for sec, vals in SCENES[name][1].items():
        cfg[sec].update(vals)
    cfg["stop"]["levels"] = list(LEVELS)
    cfg["stop"]["t_max"] = 1000.0
    cfg["outputs"]["normal_force_frequency"] = False
    cfg["outputs"]["kinematics"] = False
    cfg["solver"].update(solver)
    return cfg


def _repeats(t: float) -> int:
    return 7 if t < 0.05 else 5 if t < 0.5 else 3 if t < 5.0 else 2 if t < 20.0 else 1


# --- runners: each returns a point dict (time = min over repeats after one warm-up run) ---------

def run_sweep(cfg: dict) -> dict:
    sc = load_scene(cfg)
    st = SAMPLE_TAU * sc.chi
    r = sweep.simulate(sc, sample_times=st)        # warm-up (and the result)
    times = [r.summary["wall_time"]]
    walls = []
    for _ in range(_repeats(times[0])):
        w = time.perf_counter()
        r = sweep.simulate(sc, sample_times=st)
        walls.append(time.perf_counter() - w)
        times.append(r.summary["wall_time"])
    s = r.summary
    return dict(time=min(walls), kernel_time=min(times[1:]), outcome=s["outcome"],
                level_tau=[lv["t"] / sc.chi for lv in s["levels"]], alpha=r.samples["alpha"].tolist(),
                n_rhs=s["n_rhs"], n_steps=s["n_steps"], n_rejected=s["n_rejected"], n_events=s["n_events"])


def run_peer(cfg: dict, method: str, rtol: float, backend=None, first: dict | None = None) -> dict:
    sc = load_scene(cfg)
    kw = dict(sample_tau=SAMPLE_TAU, backend=backend, max_wall=BUDGET_S)
    r = first or run_scipy(sc, method, rtol, rtol * 1e-2, **kw)
    walls = [r["wall"]]
    if r["wall"] < BUDGET_S / 4:
        for _ in range(_repeats(r["wall"]) - 1):
            r = run_scipy(sc, method, rtol, rtol * 1e-2, **kw)
            walls.append(r["wall"])
    return dict(time=min(walls), outcome=r["outcome"], level_tau=r["level_tau"].tolist(),
                alpha=r["samples"][:, 0].tolist(), n_rhs=r["n_rhs"], nfev=r["nfev"], njev=r["njev"],
                n_segments=r["n_segments"], n_events=r["n_events"])


def errors(pt: dict, ref: dict) -> tuple[float, float]:
    lt, lr = pt["level_tau"][LEVEL_INDEX], ref["level_tau"][LEVEL_INDEX]
    lerr = abs(lt - lr) / lr if math.isfinite(lt) else math.inf
    a = np.asarray(pt["alpha"], dtype=float)
    ar = np.asarray(ref["alpha"], dtype=float)
    both = np.isfinite(ar)
    if not np.all(np.isfinite(a[both])):
        return lerr, math.inf
    return lerr, float(np.max(np.abs(a[both] - ar[both])))


def time_at_error(points: list[dict], key: str, target: float) -> float:
    """Wall time at a given error, interpolated in log-log along the (sorted-by-time) curve.

    Uses the cheapest bracket: the first point (by time) whose error is <= target and its
    predecessor; NaN if no point reaches the target or the curve starts below it.
    """
    pts = sorted((p for p in points if p["time"] > 0 and math.isfinite(p[key]) and p[key] > 0),
                 key=lambda p: p["time"])
    for i, p in enumerate(pts):
        if p[key] <= target:
            if i == 0:
                return p["time"] if p[key] == target else math.nan
            q = pts[i - 1]
            if q[key] <= target:
                return p["time"]
            x0, x1 = math.log(q[key]), math.log(p[key])
            y0, y1 = math.log(q["time"]), math.log(p["time"])
            return math.exp(y0 + (math.log(target) - x0) * (y1 - y0) / (x1 - x0))
    return math.nan


def value_at_error(points: list[dict], key: str, target: float, what: str) -> float:
    """Like time_at_error, for another per-point quantity (e.g. n_rhs), interpolated in log-log."""
    pts = sorted((p for p in points if math.isfinite(p[key]) and p[key] > 0), key=lambda p: p[what])
    for i, p in enumerate(pts):
        if p[key] <= target:
            if i == 0:
                return math.nan
            q = pts[i - 1]
            if q[key] <= target:
                return p[what]
            x0, x1 = math.log(q[key]), math.log(p[key])
            y0, y1 = math.log(q[what]), math.log(p[what])
            return math.exp(y0 + (math.log(target) - x0) * (y1 - y0) / (x1 - x0))
    return math.nan


# --- compile time and cache, measured in fresh processes ------------------------------------------

PROBE = r"""
import time, json
t0 = time.perf_counter()
import sweep
from sweep.scene import DEFAULTS
t1 = time.perf_counter()
r = sweep.simulate(DEFAULTS)
t2 = time.perf_counter()
r = sweep.simulate(DEFAULTS)
t3 = time.perf_counter()
print(json.dumps(dict(imports=t1 - t0, first_call=t2 - t1, total_first=t2 - t0, second_call=t3 - t2,
                      kernel_first=r.summary["wall_time"])))
"""


def compile_probe() -> dict:
    """Cold compile and warm-cache start-up, each in a fresh process.

    The package source is copied to a temporary directory first, so the measurement is not
    confounded by edits of src/ while it runs (an edited file invalidates its numba cache).
    NUMBA_CACHE_DIR points at an empty directory for the cold run and at the same, now filled,
    directory for the warm runs (minimum of two).
    """
    import shutil
    out = {}
    env = dict(os.environ)
    with tempfile.TemporaryDirectory() as d:
        shutil.copytree(ROOT / "src" / "sweep", Path(d) / "pkg" / "sweep",
                        ignore=shutil.ignore_patterns("__pycache__"))
        env["PYTHONPATH"] = str(Path(d) / "pkg")
        env["NUMBA_CACHE_DIR"] = str(Path(d) / "cache")

        def probe():
            res = subprocess.run([sys.executable, "-c", PROBE], env=env, capture_output=True, text=True, cwd=d)
            if res.returncode != 0:
                return {"error": res.stderr[-400:]}
            return json.loads(res.stdout.strip().splitlines()[-1])

        out["cold (empty NUMBA_CACHE_DIR)"] = probe()
        warm = [probe() for _ in range(2)]
        out["warm (filled cache, new process; min of 2)"] = min(
            warm, key=lambda v: v.get("total_first", math.inf))
    return out


def paper_default_time(repeats: int = 15) -> dict:
    """The paper's case at default settings, to the 1e-3 level (levels [0.1, 0.01, 0.001])."""
    cfg = copy.deepcopy(DEFAULTS)
    cfg["stop"]["levels"] = [0.1, 0.01, 0.001]
    out = {}
    for label, peaks in (("default outputs (normal-force frequency on)", True), ("summary only (normal-force frequency off)", False)):
        c = copy.deepcopy(cfg)
        c["outputs"]["normal_force_frequency"] = peaks
        sc = load_scene(c)
        sweep.simulate(sc)
        walls, kern = [], []
        for _ in range(repeats):
            w = time.perf_counter()
            r = sweep.simulate(sc)
            walls.append(time.perf_counter() - w)
            kern.append(r.summary["wall_time"])
        w = time.perf_counter()
        load_scene(c)
        t_load = time.perf_counter() - w
        s = r.summary
        out[label] = dict(simulate_s=min(walls), kernel_s=min(kern), load_scene_s=t_load, n_steps=s["n_steps"],
                          n_rejected=s["n_rejected"], n_rhs=s["n_rhs"], n_events=s["n_events"],
                          outcome=s["outcome"])
    return out


# --- main -----------------------------------------------------------------------------------------

def log(msg: str) -> None:
    print(msg, flush=True)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="paper's case only, rtol 1e-4..1e-10 in steps of 100x")
    ap.add_argument("--scenes", nargs="*", default=None, help="subset of: " + ", ".join(SCENES))
    ap.add_argument("--rtols", nargs="+", type=float, default=None,
                    help="relative tolerances of every solver (default: 1e-4..1e-10 in steps of 100x with "
                         "--quick, else 1e-4..1e-12)")
    ap.add_argument("--no-compile-probe", action="store_true")
    args = ap.parse_args(argv)
    OUT.mkdir(exist_ok=True)
    quick = args.quick
    scenes = args.scenes or (["paper"] if quick else list(SCENES))
    rtols = args.rtols or ([1e-4, 1e-6, 1e-8, 1e-10] if quick else [10.0 ** -k for k in range(4, 13)])
    methods = ["RK45", "DOP853", "LSODA", "Radau"]
    dts_tau = [0.2, 0.1, 0.05, 0.025] if quick else [0.4, 0.2, 0.1, 0.05, 0.025, 0.0125]
    report = dict(platform=platform.platform(), python=sys.version.split()[0], quick=quick,
                  started=time.strftime("%Y-%m-%d %H:%M:%S"), scenes={}, skipped=[])
    t_start = time.perf_counter()

    if not args.no_compile_probe:
        log("compile/cache probe (fresh processes) ...")
        report["compile"] = compile_probe()
        for k, v in report["compile"].items():
            log(f"  {k}: {v}")

    for name in scenes:
        log(f"\n=== scene {name}: {SCENES[name][0]}")
        sc = load_scene(scene_cfg(name))
        entry = dict(description=SCENES[name][0], chi=sc.chi, points=[])
        ref = run_sweep(scene_cfg(name, rtol=1e-13, atol=1e-15))
        chk = run_scipy(sc, "DOP853", 1e-13, 1e-15, sample_tau=SAMPLE_TAU)
        chk_pt = dict(level_tau=chk["level_tau"].tolist(), alpha=chk["samples"][:, 0].tolist())
        le, ae = errors(chk_pt, ref)
        entry["reference"] = dict(solver="sweep adaptive rtol 1e-13 atol 1e-15", outcome=ref["outcome"],
                                  level_tau=ref["level_tau"], check="SciPy DOP853 rtol 1e-13 atol 1e-15",
                                  check_outcome=chk["outcome"], check_level_rel_diff=le,
                                  check_alpha_max_diff=ae, check_wall=chk["wall"])
        log(f"reference {ref['outcome']} levels(tau) {ref['level_tau']}; SciPy DOP853 1e-13: level rel diff "
            f"{le:.2e}, alpha max diff {ae:.2e}")

        def add(solver, setting, pt):
            pt["level_err"], pt["alpha_err"] = errors(pt, ref)
            pt.update(solver=solver, setting=setting)
            pt.pop("alpha")
            entry["points"].append(pt)
            log(f"  {solver:18s} {setting:>10s}  {pt['time'] * 1e3:10.2f} ms  rhs {pt['n_rhs']:8d}  "
                f"level err {pt['level_err']:.2e}  alpha err {pt['alpha_err']:.2e}  {pt['outcome']}")

        for rt in rtols:
            add("sweep adaptive", f"{rt:.0e}", run_sweep(scene_cfg(name, rtol=rt, atol=rt * 1e-2)))
        for dtt in dts_tau:
            add("sweep fixed", f"{dtt:g}", run_sweep(scene_cfg(name, method="fixed", dt=dtt * sc.chi)))
        peers = [(m, None, m) for m in methods]
        if name == "paper":
            peers.append(("DOP853", numpy_backend(), "DOP853 plain NumPy"))
        for method, be, label in peers:
            prev = []
            for rt in rtols:
                if len(prev) >= 1:
                    growth = prev[-1] / prev[-2] if len(prev) >= 2 else 2.0
                    pred = prev[-1] * max(growth, 1.0)
                    if pred > BUDGET_S:
                        msg = f"{name}: SciPy {label} rtol <= {rt:.0e} skipped (predicted {pred:.0f} s > {BUDGET_S:.0f} s)"
                        report["skipped"].append(msg)
                        log("  " + msg)
                        break
                first = run_scipy(sc, method, rt, rt * 1e-2, sample_tau=SAMPLE_TAU, backend=be, max_wall=BUDGET_S)
                if not prev:   # warm-up at the loosest tolerance (numba specializations, imports)
                    first = None
                pt = run_peer(scene_cfg(name), method, rt, backend=be, first=first)
                add("SciPy " + label, f"{rt:.0e}", pt)
                if pt["outcome"] == "step_limit":
                    if prev:   # a tighter tolerance than one that finished: the cost grows from here
                        msg = f"{name}: SciPy {label} rtol {rt:.0e} abandoned after {BUDGET_S:.0f} s; tighter skipped"
                        report["skipped"].append(msg)
                        log("  " + msg)
                        break
                    # no tolerance has finished yet: a loose one can stall where a tighter one does
                    # not (the peers chatter at the contact rules at rtol 1e-4), so go on
                    msg = f"{name}: SciPy {label} rtol {rt:.0e} abandoned after {BUDGET_S:.0f} s; trying the next"
                    report["skipped"].append(msg)
                    log("  " + msg)
                    continue
                prev.append(pt["time"])
        report["scenes"][name] = entry
        _write(report)

    log("\npaper's case at default settings (to the 1e-3 level) ...")
    report["paper_default"] = paper_default_time()
    for k, v in report["paper_default"].items():
        log(f"  {k}: {v}")
    report["elapsed_s"] = time.perf_counter() - t_start
    _write(report)
    log(f"\nwrote {OUT / 'work_precision.md'}, .json, .png  ({report['elapsed_s']:.0f} s)")
    return 0


# --- report ---------------------------------------------------------------------------------------

def _fmt(x, f="{:.2e}"):
    return "-" if x is None or (isinstance(x, float) and not math.isfinite(x)) else f.format(x)


def _ratios(entry: dict) -> list[dict]:
    pts = entry["points"]
    ours = [p for p in pts if p["solver"] == "sweep adaptive"]
    rows = []
    for solver in sorted({p["solver"] for p in pts if p["solver"].startswith("SciPy")}):
        peer = [p for p in pts if p["solver"] == solver]
        for key in ("alpha_err", "level_err"):
            for tgt in MATCH_ERRORS:
                to, tp = time_at_error(ours, key, tgt), time_at_error(peer, key, tgt)
                ro, rp = value_at_error(ours, key, tgt, "n_rhs"), value_at_error(peer, key, tgt, "n_rhs")
                rows.append(dict(peer=solver, error=key, target=tgt, t_ours=to, t_peer=tp,
                                 ratio=tp / to if to > 0 else math.nan, rhs_ours=ro, rhs_peer=rp,
                                 rhs_ratio=ro / rp if rp > 0 else math.nan))
    return rows


def _write(report: dict) -> None:
    (OUT / "work_precision.json").write_text(json.dumps(report, indent=1, default=float))
    lines = [f"# Work-precision benchmark ({'quick' if report['quick'] else 'full'})", "",
             f"{report['started']}, {report['platform']}, Python {report['python']}. Times: minimum of "
             "repeated runs after a warm-up (compilation excluded), wall-clock of `sweep.simulate(Scene)` "
             "resp. of the SciPy driver. Errors against the reference (sweep rtol 1e-13): relative error of "
             f"the {LEVELS[LEVEL_INDEX]} rad level time; max |alpha error| at 201 samples tau in [0, 100].", ""]
    if "compile" in report:
        lines += ["## Compilation and cache (fresh processes)", "", "| cache | imports (s) | first simulate (s) | "
                  "imports + first (s) | second simulate (s) |", "|---|---|---|---|---|"]
        for k, v in report["compile"].items():
            if "error" in v:
                lines.append(f"| {k} | error: {v['error'][:80]} | | | |")
            else:
                lines.append(f"| {k} | {v['imports']:.2f} | {v['first_call']:.3f} | {v['total_first']:.2f} | "
                             f"{v['second_call']:.4f} |")
        lines.append("")
    for name, e in report["scenes"].items():
        r = e["reference"]
        lines += [f"## {name}: {e['description']}", "",
                  f"Reference ({r['solver']}): {r['outcome']}, level times tau = {r['level_tau']}. "
                  f"Check ({r['check']}): {r['check_outcome']}, level-time relative difference "
                  f"{r['check_level_rel_diff']:.1e}, max alpha difference {r['check_alpha_max_diff']:.1e}.", "",
                  "| solver | rtol / dt (tau) | time (ms) | RHS evals | level err | alpha err | outcome |",
                  "|---|---|---|---|---|---|---|"]
        for p in e["points"]:
            lines.append(f"| {p['solver']} | {p['setting']} | {p['time'] * 1e3:.2f} | {p['n_rhs']} | "
                         f"{_fmt(p['level_err'])} | {_fmt(p['alpha_err'])} | {p['outcome']} |")
        lines += ["", "Time ratio SciPy / sweep adaptive at matched error (log-log interpolation), and RHS "
                  "evaluations (ours / peer):", "",
                  "| peer | error | target | sweep (ms) | peer (ms) | time ratio | RHS ours | RHS peer | RHS ratio |",
                  "|---|---|---|---|---|---|---|---|---|"]
        for row in _ratios(e):
            lines.append(f"| {row['peer']} | {row['error']} | {row['target']:.0e} | {_fmt(row['t_ours'] * 1e3, '{:.2f}')} | "
                         f"{_fmt(row['t_peer'] * 1e3, '{:.1f}')} | {_fmt(row['ratio'], '{:.0f}')} | "
                         f"{_fmt(row['rhs_ours'], '{:.0f}')} | {_fmt(row['rhs_peer'], '{:.0f}')} | "
                         f"{_fmt(row['rhs_ratio'], '{:.2f}')} |")
        lines.append("")
    if report["skipped"]:
        lines += ["## Skipped", ""] + [f"- {s}" for s in report["skipped"]] + [""]
    if "paper_default" in report:
        lines += ["## The paper's case at default settings, to the 1e-3 level", "",
                  "| outputs | simulate(Scene) (ms) | kernel (ms) | load_scene (ms) | steps | rejected | RHS | events |",
                  "|---|---|---|---|---|---|---|---|"]
        for k, v in report["paper_default"].items():
            lines.append(f"| {k} | {v['simulate_s'] * 1e3:.1f} | {v['kernel_s'] * 1e3:.1f} | {v['load_scene_s'] * 1e3:.1f} | "
                         f"{v['n_steps']} | {v['n_rejected']} | {v['n_rhs']} | {v['n_events']} |")
        lines.append("")
    (OUT / "work_precision.md").write_text("\n".join(lines))
    _plot(report)


def _plot(report: dict) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    names = list(report["scenes"])
    if not names:
        return
    fig, axes = plt.subplots(len(names), 2, figsize=(11, 3.6 * len(names)), squeeze=False)
    styles = {"sweep adaptive": ("k", "o-"), "sweep fixed": ("0.5", "s--"), "SciPy RK45": ("C0", "^-"),
              "SciPy DOP853": ("C1", "v-"), "SciPy LSODA": ("C2", "d-"), "SciPy Radau": ("C3", "x-"),
              "SciPy DOP853 plain NumPy": ("C4", "v:")}
    for row, name in enumerate(names):
        pts = report["scenes"][name]["points"]
        for col, key in enumerate(("level_err", "alpha_err")):
            ax = axes[row, col]
            for solver, (c, ls) in styles.items():
                sel = [p for p in pts if p["solver"] == solver and math.isfinite(p[key]) and p[key] > 0]
                if sel:
                    ax.loglog([p["time"] for p in sel], [p[key] for p in sel], ls, color=c, label=solver, ms=4)
            ax.set_xlabel("wall time per trajectory (s)")
            ax.set_ylabel("relative error of the 0.1 rad level time" if key == "level_err" else "max |alpha error|, tau <= 100")
            ax.set_title(f"{name}")
            ax.grid(True, which="major", alpha=0.3)
        axes[row, 0].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(OUT / "work_precision.png", dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    sys.exit(main())
