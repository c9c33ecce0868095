"""Frequencies at the levels against the steady relation, before and after issue 9 (side by side).

    python benchmarks/frequency_outliers.py [--set harness|grid|both] [--scenes N] [--seed S]
                                            [--before REV] [--jobs J] [--tag NAME]

Counts the level values that lie outside a factor FACTOR (3) of the steady precession frequency at
the same energy: the level is the energy-equivalent inclination beta, so the steady centre-fixed
rolling motion at beta has the scene's energy there, and its precession frequency is
|omega_3(beta)| / sin(beta) / (2 pi) (model.steady_rolling_w3sq; Omega^2 sin beta = 4 g/R for the
thin disk). The same scenes run twice, each in a fresh interpreter: with the source tree of
--before (default c6daa06, the last commit with the old estimator: the mean dtheta/dt between
three normal-force maxima, exported with `git archive`) and with this checkout's src/. A scene's
settings that a tree does not know (solver.spin_tol, added after c6daa06) are left out of its runs,
which then follow that tree's own rules.

Scene sets: `harness`, the random scenes of benchmarks/convergence.py (its draw_scene and level
rule, seed and count as there, default rtol 1e-10, t_max 300 s); `grid`, the default sweep
(config/config.yaml, 320 scenes). Reported per set and estimator: finite level values, values
outside the factor (all levels, levels <= 1e-2, and levels <= 1e-2 of scenes that halted
(outcome halted, not lying flat), with the scenes; for the normal-force
frequency f_hat (paper's 2/T over three maxima), how many values are not within a factor 3 of
the ringing frequency (after) - the harmonic branches of the map.
Per-scene records go to benchmarks/out/frequency_outliers-<tag>.jsonl, the table to stdout and
benchmarks/out/frequency_outliers-<tag>.md.
"""
from __future__ import annotations

import argparse
import itertools
import json
import math
import os
import subprocess
import sys
import tarfile
import tempfile
import time
from pathlib import Path

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[1]
OUT = Path(__file__).resolve().parent / "out"
FACTOR = 3.0
DEEP = 1e-2
BEFORE = "c6daa06"

WORKER = r"""
import json, math, sys
import sweep
from sweep.scene import DEFAULTS


def known(cfg, ref):
    # the keys this tree's scene format has: an older tree (--before) refuses settings added
    # since (e.g. solver.spin_tol) and runs with its own rules instead
    return {k: (known(v, ref[k]) if isinstance(v, dict) and isinstance(ref.get(k), dict) else v)
            for k, v in cfg.items() if k in ref}


for line in sys.stdin:
    idx, cfg = json.loads(line)
    try:
        s = sweep.simulate(known(cfg, DEFAULTS)).summary
        rec = {"index": idx, "outcome": s["outcome"], "lay_flat": bool(s.get("lay_flat", False)),
               "slip_fraction": s["slip_fraction"],
               "levels": [{k: lv.get(k, math.nan) for k in ("inclination", "t", "precession_hz", "ringing_hz",
                                                             "normal_force_hz")} for lv in s["levels"]]}
    except Exception as exc:
        rec = {"index": idx, "exception": f"{type(exc).__name__}: {exc}"}
    print(json.dumps(rec), flush=True)
"""


def harness_scenes(n: int, seed: int) -> list[dict]:
    sys.path.insert(0, str(ROOT / "benchmarks"))
    import convergence as cv

    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        cfg = cv._valid_levels(cv.draw_scene(rng))
        cfg["solver"] = {"rtol": cv.DEFAULT_RTOL, "atol": cv.DEFAULT_RTOL * 1e-2}
        out.append(cfg)
    return out


def grid_scenes() -> list[dict]:
    from sweep import grid

    settings = grid.normalize(yaml.safe_load((ROOT / "config" / "config.yaml").read_text()), grid.load_schema())
    g = settings["grid"]
    return [grid.scene(settings, p) for p in itertools.product(*(g[a] for a in grid.AXES))]


def steady_hz(cfg: dict, beta: float) -> float:
    from sweep.core import model
    from sweep.scene import load_scene

    sc = load_scene(cfg)
    return math.sqrt(model.steady_rolling_w3sq(beta, sc.params)) / math.sin(beta) / sc.chi / (2 * math.pi)


def export_source(rev: str, dest: Path) -> Path:
    """src/ of a git revision, extracted into dest (no checkout, nothing in this worktree changes)."""
    tar = dest / "src.tar"
    with tar.open("wb") as fh:
        subprocess.run(["git", "-C", str(ROOT), "archive", rev, "src"], stdout=fh, check=True)
    with tarfile.open(tar) as tf:
        tf.extractall(dest, filter="data")
    return dest / "src"


def run_all(scenes: list[dict], src: Path, jobs: int) -> list[dict]:
    """Simulate the scenes with the package under src, in `jobs` fresh interpreters."""
    import threading

    env = {**os.environ, "PYTHONPATH": str(src)}
    procs, feeders = [], []
    for j in range(jobs):
        p = subprocess.Popen([sys.executable, "-c", WORKER], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                             text=True, env=env, cwd=str(ROOT))
        text = "".join(json.dumps([i, c]) + "\n" for i, c in enumerate(scenes) if i % jobs == j)

        def feed(p=p, text=text):   # from a thread: a worker's full stdout pipe must not block the input
            p.stdin.write(text)
            p.stdin.close()

        feeders.append(threading.Thread(target=feed, daemon=True))
        feeders[-1].start()
        procs.append(p)
    recs = []
    for p in procs:
        recs += [json.loads(x) for x in p.stdout if x.strip()]
        p.wait()
    for t in feeders:
        t.join()
    recs.sort(key=lambda r: r["index"])
    return recs


def analyse(name: str, scenes: list[dict], runs: dict[str, list[dict]]) -> list[str]:
    lines = [f"## {name}: {len(scenes)} scenes", ""]
    lines.append("| estimator | finite values | outside x3 (all levels) | outside x3 (levels <= 1e-2) "
                 "| outside x3 (<= 1e-2, halted, not flat) | f_hat not within x3 of the ringing |")
    lines.append("|---|---|---|---|---|---|")
    details = []
    for label, recs in runs.items():
        n_fin = n_all = n_deep = n_roll = 0
        n_branch = n_pairs = 0
        out_scenes = []
        for rec in recs:
            if "exception" in rec:
                details.append(f"  {label}: scene {rec['index']} raised {rec['exception']}")
                continue
            cfg = scenes[rec["index"]]
            rolling = rec["outcome"] == "halted" and not rec["lay_flat"]
            for lv in rec["levels"]:
                b, f = lv["inclination"], lv["precession_hz"]
                if f is None or not math.isfinite(f):
                    continue
                n_fin += 1
                fss = steady_hz(cfg, b)
                bad = not (fss / FACTOR <= f <= FACTOR * fss)
                n_all += bad
                if b <= DEEP:
                    n_deep += bad
                    n_roll += bad and rolling
                if bad:
                    out_scenes.append(f"scene {rec['index']} beta {b:g}: {f:.4g} Hz (steady {fss:.4g}; "
                                      f"{rec['outcome']}{', flat' if rec['lay_flat'] else ''}, "
                                      f"slip {rec['slip_fraction']:.3f})")
                fr, fn = lv.get("ringing_hz"), lv.get("normal_force_hz")
                if fr is not None and fn is not None and math.isfinite(fr) and math.isfinite(fn):
                    n_pairs += 1
                    n_branch += not (fr / FACTOR <= fn <= FACTOR * fr)
        branch = f"{n_branch}/{n_pairs}" if n_pairs else "-"
        lines.append(f"| {label} | {n_fin} | {n_all} | {n_deep} | {n_roll} | {branch} |")
        if out_scenes:
            details.append(f"  {label}: " + "; ".join(out_scenes[:40])
                           + (f"; ... {len(out_scenes) - 40} more" if len(out_scenes) > 40 else ""))
    return lines + [""] + (["outliers:"] + details if details else ["outliers: none"]) + [""]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--set", choices=("harness", "grid", "both"), default="both")
    ap.add_argument("--scenes", type=int, default=100, help="harness scenes (default 100)")
    ap.add_argument("--seed", type=int, default=20261122)
    ap.add_argument("--before", default=BEFORE, help="git revision with the old estimator")
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--tag", default=None)
    a = ap.parse_args(argv)
    sys.path.insert(0, str(ROOT / "src"))
    OUT.mkdir(exist_ok=True)
    tag = a.tag or f"{a.set}-n{a.scenes}-seed{a.seed}"
    sets = []
    if a.set in ("harness", "both"):
        sets.append((f"harness (benchmarks/convergence.py scenes, seed {a.seed})", harness_scenes(a.scenes, a.seed)))
    if a.set in ("grid", "both"):
        sets.append(("default grid (config/config.yaml)", grid_scenes()))
    t0 = time.time()
    lines = [f"# frequency outliers: level values outside a factor {FACTOR:g} of the steady precession "
             f"at the same energy (before: {a.before}, after: this checkout)", ""]
    with tempfile.TemporaryDirectory() as tmp, (OUT / f"frequency_outliers-{tag}.jsonl").open("w") as fh:
        old_src = export_source(a.before, Path(tmp))
        for name, scenes in sets:
            runs = {}
            for label, src in ((f"before ({a.before})", old_src), ("after", ROOT / "src")):
                t1 = time.time()
                runs[label] = run_all(scenes, src, a.jobs)
                print(f"  {name}, {label}: {time.time() - t1:.0f} s", file=sys.stderr, flush=True)
                for rec in runs[label]:
                    fh.write(json.dumps({"set": name, "run": label, **rec}) + "\n")
            lines += analyse(name, scenes, runs)
    lines.append(f"wall time: {time.time() - t0:.0f} s (jobs {a.jobs})")
    table = "\n".join(lines)
    print(table)
    (OUT / f"frequency_outliers-{tag}.md").write_text(table + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
