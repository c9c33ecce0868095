"""Does the SciPy driver (tests/reference/scipy_driver.py) agree with the kernel on the harness scenes?

    python benchmarks/scipy_agreement.py [--scenes N] [--seed S] [--rtol R] [--cap SECONDS] [--tag NAME]
    python benchmarks/scipy_agreement.py --analyse benchmarks/out/scipy-agreement-<tag>.jsonl [--diagnose]

Issue #8, item 3: the SciPy driver, with the same state-only rules written there independently and
simply, must agree with the kernel within 1e-8 on the well-conditioned quantities of >= 100 harness
scenes at rtol 1e-12. A rule that is consistent but wrong in one of the two shows up here.

The scenes are the first N of the convergence harness (benchmarks/convergence.py: its generator,
its seed 20261122 by default, its level filter), taken in order whatever their cost. Each scene runs

* in the kernel (`sweep.simulate`) at rtol, atol = rtol/100 (the harness' scaling of the default);
* in the kernel again with alpha0 + 1e-10 rad (same rtol): the kernel's own sensitivity test;
* in the SciPy driver (DOP853, same rtol and atol), under a time cap per scene (CPU time, so that
  the load of a shared machine does not change which scenes are compared); a scene over the cap
  is counted as 'not compared' and listed.

Quantities: the level times (s), alpha at tau = 10, 30, 100, 300 (while t <= t_max), the scene's end
(alpha at t_max where both runs reach it, the time of a located end: convergence.end_quantities;
since stop 29), the outcome and
the event counts (roll<->slip transitions, stick phases, rim-edge impacts). A value is
well-conditioned where the perturbed kernel run moves it by < 1e-8 relative. An outcome or an event
count is a total over the whole run: it is well-conditioned where the perturbed run leaves it
unchanged *and* every value of the run (t_halt included) is well-conditioned, the harness's 'calm'
scenes (one perturbed run can leave a count of a sensitive scene unchanged by chance). The table
gives the share of well-conditioned quantities on which driver and kernel agree within 1e-8
relative (exactly, for outcomes and counts) and lists every disagreement. Records (one JSON line per scene) go to
benchmarks/out/scipy-agreement-<tag>.jsonl; an interrupted run resumes from that file.
"""
from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent))   # the repository root: the SciPy peer is tests.reference.scipy_driver

import convergence as cv  # noqa: E402  (the harness' scene generator, level filter and kernel run)

OUT = HERE / "out"
WELL = 1e-8     # sensitivity below which a quantity is well-conditioned (relative)
AGREE = 1e-8    # agreement required (relative)


def _driver(cfg: dict, rtol: float, cap: float) -> dict:
    from tests.reference.scipy_driver import run_scipy
    from sweep.scene import load_scene

    c = json.loads(json.dumps(cfg))
    c["solver"] = {"rtol": rtol, "atol": rtol * 1e-2}
    sc = load_scene(c)
    taus = [tau for tau in cv.SAMPLE_TAU if tau * sc.chi < cv.T_MAX]
    t0 = time.process_time()
    try:
        r = run_scipy(sc, "DOP853", rtol, rtol * 1e-2, sample_tau=np.array(taus + [c["stop"]["t_max"] / sc.chi]), max_wall=cap,
                      clock=time.process_time)
    except Exception as exc:  # noqa: BLE001 - reported per scene
        return {"exception": f"{type(exc).__name__}: {exc}"}
    cpu = time.process_time() - t0
    q = {f"t_level_{b:g}": float(tl * sc.chi) for b, tl in zip(sc.levels, r["level_tau"])}
    for tau, a in zip(taus, r["samples"][:-1, 0]):
        q[f"alpha_tau_{tau:g}"] = float(a)
    if not r["timed_out"]:
        q.update(cv.end_quantities(r["outcome"], r["t_end"] * sc.chi, r["samples"][-1, 0]))
    diag = {k: r[k] for k in ("onset_repelling", "unstick_at_restart", "released_by_impulse", "fold_by_failure",
                              "reslaved_after_update")}
    return {"outcome": r["outcome"], "timed_out": bool(r["timed_out"]), "t_end": r["t_end"] * sc.chi, "q": q,
            "events": [r["n_transitions"], r["n_stick"], r["n_impacts"]], "cpu": cpu, "wall": r["wall"],
            "nfev": r["nfev"], "n_segments": r["n_segments"], "diag": diag, "event_kinds": r["event_kinds"]}


def run_scene(idx: int, cfg: dict, rtol: float, cap: float) -> dict:
    cfg = cv._valid_levels(cfg)
    rec = {"index": idx, "scene": cfg, "rtol": rtol}
    rec["kernel"] = cv._one_run(cfg, rtol)
    rec["perturbed"] = cv._one_run(cfg, rtol, cv.PERTURB * math.copysign(1.0, cfg["initial"]["alpha"]))
    rec["driver"] = _driver(cfg, rtol, cap)
    return rec


def _rel(a, b) -> float:
    """Relative difference of a to b; 0 if neither exists, NaN if only one does."""
    fa = a is not None and math.isfinite(a)
    fb = b is not None and math.isfinite(b)
    if not fa and not fb:
        return 0.0
    if fa != fb:
        return math.nan
    if a == b:
        return 0.0
    return abs(a - b) / max(abs(b), 1e-300)


def compare(rec: dict) -> dict:
    """Per-scene comparison: lists of (quantity, kernel, driver, rel, sensitivity) for the
    well-conditioned ones, plus those left out as ill-conditioned."""
    k, pt, d = rec["kernel"], rec["perturbed"], rec["driver"]
    res = {"index": rec["index"], "compared": False, "why": None, "wc": [], "ill": 0}
    if "exception" in k or "exception" in pt:
        res["why"] = "kernel exception: " + k.get("exception", pt.get("exception", ""))
        return res
    if "exception" in d:
        res["why"] = "driver exception: " + d["exception"]
        return res
    if d["timed_out"]:
        res["why"] = "over the time cap"
        return res
    res["compared"] = True
    keys = sorted(set(k["q"]) | set(d["q"]))
    calm = True   # every value of the run, t_halt included, moves < WELL under the perturbation
    for key in keys:
        vk, vp, vd = k["q"].get(key), pt["q"].get(key), d["q"].get(key)
        sens = _rel(vp, vk)
        calm = calm and sens < WELL
        if key == "t_halt":
            continue   # derived from the level times (diagnostics.halt_time), not a driver output
        if key in cv.END_KEYS and key not in d["q"]:
            continue   # a driver record from before stop 29, or another kind of end (the outcome is compared)
        if not (vk is not None and math.isfinite(vk)) and not (vd is not None and math.isfinite(vd)):
            continue   # neither run has this value (a level not reached, a sample after the end)
        if not sens < WELL:
            res["ill"] += 1
            continue
        res["wc"].append((key, vk, vd, _rel(vd, vk), sens))
    res["calm"] = calm
    if not calm:
        # the outcome and the event counts are totals over the whole run: where any value of the
        # run is sensitive, so is the part of the trajectory that they count, whether or not the
        # one perturbed run happened to change them
        res["ill"] += 1 + len(k["events"])   # the outcome and each count
        return res
    if pt["outcome"] == k["outcome"]:
        res["wc"].append(("outcome", k["outcome"], d["outcome"], 0.0 if d["outcome"] == k["outcome"] else math.nan, 0.0))
    else:
        res["ill"] += 1
    for j, name in enumerate(("n_transitions", "n_stick", "n_impacts")):
        if pt["events"][j] == k["events"][j]:
            res["wc"].append((name, k["events"][j], d["events"][j],
                              0.0 if d["events"][j] == k["events"][j] else math.nan, 0.0))
        else:
            res["ill"] += 1
    return res


def analyse(recs: list[dict], cap: float | None = None) -> str:
    recs = sorted(recs, key=lambda r: r["index"])
    comps = [compare(r) for r in recs]
    lines = []
    n = len(recs)
    done = [c for c in comps if c["compared"]]
    lines.append(f"scenes: {n} (harness indices {recs[0]['index']}..{recs[-1]['index']}), rtol {recs[0]['rtol']:g}, "
                 f"atol rtol/100, DOP853")
    lines.append(f"compared: {len(done)}; not compared: {n - len(done)}"
                 + "".join(f"\n  scene {c['index']}: {c['why']}" for c in comps if not c["compared"]))
    nq = sum(len(c["wc"]) for c in done)
    ok = sum(1 for c in done for q in c["wc"] if q[3] <= AGREE)
    ill = sum(c["ill"] for c in done)
    lines.append(f"well-conditioned quantities: {nq} (ill-conditioned, left out: {ill})")
    lines.append(f"agree within {AGREE:g}: {ok}/{nq} = {100.0 * ok / max(nq, 1):.2f} %")
    by_kind: dict[str, list[int]] = {}
    for c in done:
        for q in c["wc"]:
            kind = q[0].split("_tau_")[0] if q[0].startswith("alpha") else ("t_level" if q[0].startswith("t_level")
                                                                              else q[0])
            s = by_kind.setdefault(kind, [0, 0])
            s[0] += 1
            s[1] += q[3] <= AGREE
    lines.append("  by quantity: " + ", ".join(f"{k} {v[1]}/{v[0]}" for k, v in sorted(by_kind.items())))
    scenes_all = sum(1 for c in done if all(q[3] <= AGREE for q in c["wc"]))
    lines.append(f"scenes with every well-conditioned quantity in agreement: {scenes_all}/{len(done)}")
    rels = np.array([q[3] for c in done for q in c["wc"] if isinstance(q[1], float) and q[3] <= AGREE])
    if rels.size:
        lines.append(f"relative differences of the agreeing values: median {np.median(rels):.1e}, "
                     f"p99 {np.percentile(rels, 99):.1e}, max {rels.max():.1e}")
    bad = [(c["index"], q) for c in done for q in c["wc"] if not q[3] <= AGREE]
    if bad:
        lines.append("disagreements (scene: quantity kernel driver rel):")
        for idx, q in bad:
            kv = f"{q[1]:.12g}" if isinstance(q[1], float) else str(q[1])
            dv = f"{q[2]:.12g}" if isinstance(q[2], float) else str(q[2])
            lines.append(f"  {idx}: {q[0]} {kv} {dv} {q[3]:.2e}")
    diag: dict[str, int] = {}
    for r in recs:
        for key, v in r["driver"].get("diag", {}).items():
            diag[key] = diag.get(key, 0) + (v > 0)
    lines.append("driver rules that fired (scenes): " + ", ".join(f"{k} {v}" for k, v in sorted(diag.items())))
    kc = np.array([r["kernel"].get("cpu", math.nan) for r in recs])
    dc = np.array([r["driver"].get("cpu", math.nan) for r in recs])
    lines.append(f"cpu per scene: kernel median {np.nanmedian(kc):.2f} s (total {np.nansum(kc):.0f} s), "
                 f"driver median {np.nanmedian(dc):.1f} s (total {np.nansum(dc):.0f} s)"
                 + (f", cap {cap:g} s CPU per driver run" if cap else ""))
    return "\n".join(lines)


def diagnose(recs: list[dict], cap: float) -> str:
    """Each disagreement rerun at rtol/10 on both sides: how far each side's own value moves, and how
    far apart the two are there. It explains nothing away (the table above stands); it says which
    side had not converged at the harness rtol."""
    bad = [(r, q) for r in sorted(recs, key=lambda r: r["index"]) for c in [compare(r)] if c["compared"]
           for q in c["wc"] if not q[3] <= AGREE and isinstance(q[1], float)]
    if not bad:
        return ""
    lines = ["each disagreement at rtol/10 (own move of kernel and peer from rtol to rtol/10; apart at rtol/10):"]
    for rec, (key, vk, vd, rel, _) in bad:
        rt = rec["rtol"] / 10
        k10 = cv._one_run(rec["scene"], rt)["q"].get(key)
        d10 = _driver(rec["scene"], rt, 10 * cap)
        d10v = d10.get("q", {}).get(key) if not d10.get("timed_out") else None
        lines.append(f"  {rec['index']}: {key}: kernel moves {_rel(k10, vk):.1e}, peer moves "
                     f"{_rel(d10v, vd):.1e}; at rtol {rt:g} apart {_rel(d10v, k10):.1e} (at rtol {rec['rtol']:g}: {rel:.1e})")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scenes", type=int, default=120, help="the first N harness scenes (default 120)")
    ap.add_argument("--seed", type=int, default=20261122, help="the harness seed (default: convergence.py's)")
    ap.add_argument("--rtol", type=float, default=1e-12)
    ap.add_argument("--cap", type=float, default=60.0,
                    help="cap on one driver run (s of CPU time: independent of the load of a shared machine)")
    ap.add_argument("--tag", default=None)
    ap.add_argument("--analyse", metavar="JSONL", help="only analyse an existing record file")
    ap.add_argument("--diagnose", action="store_true",
                    help="with --analyse: rerun each disagreement at rtol/10 on both sides (done after every full run)")
    ap.add_argument("--rekernel", metavar="JSONL",
                    help="rerun only the kernel (and its sensitivity run) of an existing record file with the "
                         "current kernel, keep its driver runs; writes <file>-rekernel.jsonl and analyses it")
    a = ap.parse_args(argv)
    OUT.mkdir(exist_ok=True)
    if a.rekernel:
        src = Path(a.rekernel)
        dst = src.with_name(src.stem + "-rekernel.jsonl")
        recs = []
        with dst.open("w") as fh:
            for x in src.read_text().splitlines():
                if not x.strip():
                    continue
                rec = json.loads(x)
                cfg, rt = rec["scene"], rec["rtol"]
                rec["kernel"] = cv._one_run(cfg, rt)
                rec["perturbed"] = cv._one_run(cfg, rt, cv.PERTURB * math.copysign(1.0, cfg["initial"]["alpha"]))
                recs.append(rec)
                fh.write(json.dumps(rec) + "\n")
        print(analyse(recs, a.cap))
        return 0
    if a.analyse:
        recs = [json.loads(x) for x in Path(a.analyse).read_text().splitlines() if x.strip()]
        print(analyse(recs))
        if a.diagnose:
            print(diagnose(recs, a.cap))
        return 0
    tag = a.tag or f"n{a.scenes}-seed{a.seed}-rtol{a.rtol:g}"
    path = OUT / f"scipy-agreement-{tag}.jsonl"
    rng = np.random.default_rng(a.seed)
    scenes = [(i, cv.draw_scene(rng)) for i in range(a.scenes)]   # the harness' draw, in its order
    recs = []
    if path.exists():
        recs = [json.loads(x) for x in path.read_text().splitlines() if x.strip()]
    done = {r["index"] for r in recs}
    t0 = time.time()
    with path.open("a") as fh:
        for i, cfg in scenes:
            if i in done:
                continue
            rec = run_scene(i, cfg, a.rtol, a.cap)
            recs.append(rec)
            fh.write(json.dumps(rec) + "\n")
            fh.flush()
            d = rec["driver"]
            print(f"  scene {i}: kernel {rec['kernel'].get('outcome')} driver {d.get('outcome', d.get('exception'))}"
                  f"{' (cap)' if d.get('timed_out') else ''} {d.get('cpu', 0):.1f} s; {time.time() - t0:.0f} s",
                  file=sys.stderr, flush=True)
    table = analyse(recs, a.cap) + f"\nwall time of this run: {time.time() - t0:.0f} s"
    follow = diagnose(recs, a.cap)
    if follow:
        table += "\n" + follow
    print(table)
    (OUT / f"scipy-agreement-{tag}.md").write_text(table + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
