"""Random-scene convergence harness: does the integrator converge everywhere, in rtol and in each threshold knob?

    python benchmarks/convergence.py [--quick] [--scenes N] [--seed S] [--jobs J] [--tag NAME] [--atol-ratio R]
    python benchmarks/convergence.py --seed S --only I J ... --tag NAME     # some scenes of a seed again

Draws scenes over wide physical ranges (radius 3 mm..30 cm, thickness/radius 0.01..2, solid or
shell, mu_s 0.05..1.6, mu_d/mu_s 0..1, each k_i/R 0 or 1e-6..5e-2, |alpha0| 0.03..1.5 rad with both
signs, omega_hat ~ -e3 of 0.1..10, some with random omega1, omega2 and an initial slip), runs each
at rtol 1e-9 ... 1e-13 (atol = rtol/100), once more with alpha0 + 1e-10 rad at rtol 1e-13, and at
rtol 1e-10 with each threshold knob tightened alone (slip_tol 1e-11 and 1e-13 m/s, spin_tol 1e-9
rad/s), and reports:

* outcomes, exceptions, NaNs, step_size_underflow, step_limit (allowed only past 100 s simulated),
  the dissipation budget |E0 - E_end - sum(dissipated)| / E0 (target <= 1e-9), halted runs
  without a finite t_halt (a scene's whose halt fit needs levels past t_max, shown by a run to
  LONG_T_MAX, is listed apart: its NaN is the budget's, docs/model.md 'Halt time');
* for every quantity (level times, t_halt, alpha at tau = 10, 30, 100, 300, and the scene's end:
  alpha at t_max = 300 s where the run gets there, the time of a located end (contact loss, line
  contact, Painleve)): its numerical error
  (difference to rtol 1e-13) and its sensitivity (change under alpha0 + 1e-10 rad at rtol 1e-13);
  among well-conditioned quantities (sensitivity < 1e-8 relative) the share within 1e-6 of rtol
  1e-13 at the default rtol 1e-10 (target >= 99.5 %), and whether errors shrink with rtol;
* whether the event sequence (roll<->slip transitions, stick phases, impacts) is the same from
  rtol 1e-10 down;
* for each threshold knob: the share of well-conditioned quantities within 1e-6 and 1e-3 of the default
  run's, and the scenes whose event counts differ from the default run's (a knob's run that used up
  the step budget where the default run did not is run again with LONG_MAX_STEPS, and listed);
* cost at the default rtol: median, p90, p99, max of steps and wall time, total CPU time.

Per-scene records go to benchmarks/out/convergence-<tag>.jsonl, the table to stdout and to
benchmarks/out/convergence-<tag>.md. The scene set depends only on --seed and --scenes.
"""
from __future__ import annotations

import argparse
import json
import math
import multiprocessing as mp
import sys
import time
from pathlib import Path

import numpy as np

OUT = Path(__file__).resolve().parent / "out"
RTOLS = [1e-9, 1e-10, 1e-11, 1e-12, 1e-13]
DEFAULT_RTOL = 1e-10
REF_RTOL = 1e-13
LEVELS = [0.1, 0.01, 0.001]
SAMPLE_TAU = [10.0, 30.0, 100.0, 300.0]
T_MAX = 300.0
# a halted scene without a finite t_halt runs once more to this t_max (s): is its halt fit's last
# level past T_MAX (docs/model.md, 'Halt time')?
LONG_T_MAX = 3000.0
# a knob's run that uses up the scene's step budget (stop.max_steps, 5e6 by default) where the
# default run does not runs once more with this budget: a knob tightened towards its limit may cost
# far more steps (slave_tol 1e-4 integrates slow slides at the stability bound), which is the
# budget's NaN, not the knob's answer; such runs are listed apart
LONG_MAX_STEPS = 100_000_000
PERTURB = 1e-10
# atol = ATOL_RATIO * rtol: the product's default (solver rtol 1e-10, atol 1e-12) scaled with rtol
ATOL_RATIO = 1e-2
WELL_CONDITIONED = 1e-8
AGREE = 1e-6
# every value must agree with the default run's to this where a threshold knob is tightened
AGREE_ALL = 1e-3
# the solver's threshold knobs, each tightened alone at the default rtol and compared with the
# default run (slip_tol 1e-9 m/s, spin_tol 1e-7 rad/s, slave_tol 3e-3), and the slides' stepper
# (stiff_ratio 0: DOP853 everywhere, where the default steps slow slides by the extrapolation): the
# answers must not move (docs/model.md, 'Where a slip ends'; 'Sticking at spin_tol'; 'Slow slip')
KNOB_RUNS = [("slip_tol 1e-11", {"slip_tol": 1e-11}), ("slip_tol 1e-13", {"slip_tol": 1e-13}),
             ("spin_tol 1e-9", {"spin_tol": 1e-9}), ("slave_tol 1e-4", {"slave_tol": 1e-4}),
             ("stiff_ratio 0", {"stiff_ratio": 0.0})]
# The near-edge band: scenes drawn as the others, with mu_d / mu_s in [EDGE_LO, 1] (a quarter of them
# exactly mu_d = mu_s), numbered from EDGE_BASE in a draw of their own (--edge N), so the main
# draw's scenes keep their indices
EDGE_LO = 0.95
EDGE_BASE = 100000
# mu_d / mu_s bands of the cost report (tries per unit of content)
BANDS = ((0.0, 0.9), (0.9, 0.95), (EDGE_LO, 1.0))
DENSITY = 7800.0
# outcomes whose t_end is a located event time (a quantity of the scene's end, like a level time)
LOCATED_ENDS = ("contact_lost", "line_contact", "painleve")
END_KEYS = ("alpha_t_max", "t_end")


def end_quantities(outcome: str, t_end: float, alpha_at_t_max: float) -> dict:
    """Quantities of the scene's end (s, rad; alpha_at_t_max: alpha sampled at the scene's stop.t_max,
    NaN if the run ended before). Where the sample times and levels stop short of the end
    (a long t_max scene, a contact loss), they carry the sensitivity test and the error check to the
    whole run, which the event counts cover."""
    if outcome == "t_max":
        return {"alpha_t_max": float(alpha_at_t_max)}
    if outcome in LOCATED_ENDS:
        return {"t_end": float(t_end)}
    return {}


def draw_scene(rng: np.random.Generator) -> dict:
    """One random scene (SI) over the harness ranges."""
    R = math.exp(rng.uniform(math.log(3e-3), math.log(0.3)))
    L = R * math.exp(rng.uniform(math.log(0.01), math.log(2.0)))
    shell = rng.uniform() < 0.2
    k2shape = 2.0 if shell else 1.0
    g = 9.81
    chi = math.sqrt((k2shape + 4.0) / 4.0 * R / g)
    mu_s = math.exp(rng.uniform(math.log(0.05), math.log(1.6)))
    mu_d = mu_s * rng.uniform()
    ks = []
    for _ in range(3):
        ks.append(0.0 if rng.uniform() < 0.1 else R * math.exp(rng.uniform(math.log(1e-6), math.log(5e-2))))
    alpha = math.exp(rng.uniform(math.log(0.03), math.log(1.5))) * (1.0 if rng.uniform() < 0.5 else -1.0)
    w_hat = math.exp(rng.uniform(math.log(0.1), math.log(10.0)))
    w = [0.0, 0.0, -w_hat]
    if rng.uniform() < 0.25:
        w[0] = rng.normal(0.0, 0.3)
        w[1] = rng.normal(0.0, 0.3)
    slip = [0.0, 0.0]
    if rng.uniform() < 0.2:
        slip = [rng.normal(0.0, 0.1) * R / chi, rng.normal(0.0, 0.1) * R / chi]
    mass = DENSITY * math.pi * R * R * L * (0.1 if shell else 1.0)
    return {
        "disk": {"radius": R, "thickness": L, "mass": mass, "shape": "shell" if shell else "solid"},
        "contact": {"mu_s": mu_s, "mu_d": mu_d, "k1": ks[0], "k2": ks[1], "k3": ks[2]},
        "gravity": g,
        "initial": {"alpha": alpha, "omega": [x / chi for x in w], "slip": slip},
        "stop": {"levels": list(LEVELS), "t_max": T_MAX},
    }


def draw_edge_scene(seed: int, j: int) -> dict:
    """Scene j of the near-edge draw for seed: a harness scene (draw_scene) with mu_d / mu_s in
    [EDGE_LO, 1], exactly 1 for every fourth."""
    rng = np.random.default_rng([seed, EDGE_BASE])
    for _ in range(j + 1):
        cfg = draw_scene(rng)
        ratio = rng.uniform(EDGE_LO, 1.0)
    c = cfg["contact"]
    c["mu_d"] = c["mu_s"] if j % 4 == 0 else c["mu_s"] * ratio
    return cfg


def draw(seed: int, index: int) -> dict:
    """Scene `index` of the harness for seed: the main draw below EDGE_BASE, the near-edge draw
    from it (its levels not yet filtered)."""
    if index >= EDGE_BASE:
        return draw_edge_scene(seed, index - EDGE_BASE)
    rng = np.random.default_rng(seed)
    return [draw_scene(rng) for _ in range(index + 1)][index]


def _valid_levels(cfg: dict) -> dict:
    """Keep only the levels for which the energy-equivalent inclination is defined for this disk."""
    from sweep.core import model
    from sweep.scene import SHAPES, max_level

    d, c = cfg["disk"], cfg["contact"]
    p, _ = model.make_params(SHAPES[d["shape"]], d["radius"], d["thickness"], cfg["gravity"],
                             c["mu_s"], c["mu_d"], (c["k1"], c["k2"], c["k3"]))
    bmax = max_level(p)
    lv = [b for b in LEVELS if b < bmax]
    cfg["stop"]["levels"] = lv or [0.5 * bmax]
    return cfg


def harness_scene(seed: int, index: int, rtol: float | None = None, t_max: float | None = None) -> dict:
    """Scene `index` of the harness's draw for `seed` (its levels filtered as the harness does),
    with the solver at rtol (atol = ATOL_RATIO rtol) and stop.t_max (s) set where given."""
    cfg = _valid_levels(draw(seed, index))
    if rtol is not None:
        cfg["solver"] = {"rtol": rtol, "atol": rtol * ATOL_RATIO}
    if t_max is not None:
        cfg["stop"]["t_max"] = t_max
    return cfg


def _one_run(cfg: dict, rtol: float, d_alpha: float = 0.0, atol_ratio: float = ATOL_RATIO,
             knobs: dict | None = None) -> dict:
    import sweep

    c = json.loads(json.dumps(cfg))
    c["solver"] = {"rtol": rtol, "atol": rtol * atol_ratio, **(knobs or {})}
    c["initial"]["alpha"] += d_alpha
    chi = math.sqrt((({"solid": 1.0, "shell": 2.0}[c["disk"]["shape"]]) + 4.0) / 4.0
                    * c["disk"]["radius"] / c["gravity"])
    times = [tau * chi for tau in SAMPLE_TAU if tau * chi < T_MAX] + [c["stop"]["t_max"]]
    t0 = time.process_time()
    try:
        r = sweep.simulate(c, sample_times=times)
    except Exception as exc:  # noqa: BLE001 - the harness reports every exception
        return {"rtol": rtol, "exception": f"{type(exc).__name__}: {exc}"}
    cpu = time.process_time() - t0
    s = r.summary
    dis = s["dissipation"]
    budget = abs(s["energy_initial"] - s["energy_final"] - sum(dis.values())) / s["energy_initial"]
    q = {f"t_level_{lv['inclination']:g}": lv["t"] for lv in s["levels"]}
    q["t_halt"] = s["t_halt"]
    q_halt_error = s["t_halt_error"]
    for tau, a in zip(SAMPLE_TAU, r.samples["alpha"][:-1]):
        q[f"alpha_tau_{tau:g}"] = float(a)
    q.update(end_quantities(s["outcome"], s["t_end"], r.samples["alpha"][-1]))
    return {"rtol": rtol, "outcome": s["outcome"], "t_end": s["t_end"], "q": q, "t_halt_error": q_halt_error,
            "lay_flat": s["lay_flat"],
            "events": [s["n_transitions"], s["n_stick"], s["n_impacts"]], "n_steps": s["n_steps"] + s["n_rejected"],
            "cycles": r.precession_cycles, "located": s["n_events"],
            "cpu": cpu, "budget": budget, "nan_in_summary": _has_bad(s)}


def _has_bad(s: dict) -> bool:
    """A NaN/inf where a value must exist: energies, dissipation, counts, t_end."""
    vals = [s["t_end"], s["energy_initial"], s["energy_final"], *s["dissipation"].values()]
    return not all(math.isfinite(v) for v in vals)


def run_scene(args) -> dict:
    idx, cfg, atol_ratio = args
    cfg = _valid_levels(cfg)
    rec = {"index": idx, "scene": cfg, "runs": [_one_run(cfg, rt, 0.0, atol_ratio) for rt in RTOLS]}
    rec["perturbed"] = _one_run(cfg, REF_RTOL, PERTURB * math.copysign(1.0, cfg["initial"]["alpha"]), atol_ratio)
    rec["knobs"] = {name: _one_run(cfg, DEFAULT_RTOL, 0.0, atol_ratio, knobs) for name, knobs in KNOB_RUNS}
    default = next(r for r in rec["runs"] if r["rtol"] == DEFAULT_RTOL)
    for name, knobs in KNOB_RUNS:
        if rec["knobs"][name].get("outcome") == "step_limit" and default.get("outcome") != "step_limit":
            budget = json.loads(json.dumps(cfg))
            budget["stop"]["max_steps"] = LONG_MAX_STEPS
            rec.setdefault("knob_budget", {})[name] = rec["knobs"][name]["n_steps"]
            rec["knobs"][name] = _one_run(budget, DEFAULT_RTOL, 0.0, atol_ratio, knobs)
    if any(_halt_unfitted(r) for r in _all_runs(rec)):
        # the halt fit's levels below the last may lie past t_max, where no step goes: the same
        # scene with LONG_T_MAX says whether they do (then t_halt is NaN by the scene's budget)
        long = json.loads(json.dumps(cfg))
        long["stop"]["t_max"] = LONG_T_MAX
        rec["long"] = _one_run(long, DEFAULT_RTOL, 0.0, atol_ratio)
    return rec


def _all_runs(rec: dict) -> list[dict]:
    """A scene record's runs: every rtol, the perturbed one and every knob's."""
    return rec["runs"] + [rec["perturbed"]] + list(rec.get("knobs", {}).values())


def _halt_unfitted(r: dict) -> bool:
    """A halted run without a finite t_halt and (unless it lay flat: a located halt) t_halt_error."""
    return r.get("outcome") == "halted" and not (math.isfinite(r["q"].get("t_halt", math.nan))
                                                 and (r.get("lay_flat")
                                                      or math.isfinite(r.get("t_halt_error", math.nan))))


def _halt_past_t_max(rec: dict) -> bool:
    """Does the scene's run to LONG_T_MAX fit its halt on levels crossed after the scene's t_max
    (t_halt - t_halt_error: the last level of the fit)? Then a NaN t_halt is the budget's."""
    r = rec.get("long")
    if r is None or r.get("outcome") != "halted":
        return False
    th, err = r["q"].get("t_halt", math.nan), r.get("t_halt_error", math.nan)
    return math.isfinite(th) and math.isfinite(err) and th - err > rec["scene"]["stop"]["t_max"]


def _rel(a, b) -> float:
    if a is None or b is None or not (math.isfinite(a) and math.isfinite(b)):
        return math.nan if (a is None or b is None or math.isfinite(a) != math.isfinite(b)) else 0.0
    return abs(a - b) / max(abs(b), 1e-300)


def analyse(recs: list[dict]) -> str:
    lines = []
    n = len(recs)
    by_rtol = {rt: [next(r for r in rec["runs"] if r["rtol"] == rt) for rec in recs] for rt in RTOLS}
    default = by_rtol[DEFAULT_RTOL]
    outcomes: dict[str, int] = {}
    for r in default:
        outcomes[r.get("outcome", "exception")] = outcomes.get(r.get("outcome", "exception"), 0) + 1
    lines.append(f"scenes: {n}")
    lines.append("outcomes at rtol 1e-10: " + ", ".join(f"{k} {v}" for k, v in sorted(outcomes.items())))
    allruns = [r for rec in recs for r in rec["runs"]] + [rec["perturbed"] for rec in recs]
    exc = [r for r in allruns if "exception" in r]
    lines.append(f"exceptions (all runs): {len(exc)}" + (f"  e.g. {exc[0]['exception']}" if exc else ""))
    nan = sum(1 for r in allruns if r.get("nan_in_summary"))
    lines.append(f"NaN/inf where a value must exist (all runs): {nan}")
    und = [rec["index"] for rec in recs for r in rec["runs"] if r.get("outcome") == "step_size_underflow"]
    lines.append(f"step_size_underflow (all rtols): {len(und)} runs, scenes {sorted(set(und))[:10]}")
    bad_limit = [rec["index"] for rec in recs for r in rec["runs"]
                 if r.get("outcome") == "step_limit" and r["t_end"] <= 100.0]
    lines.append(f"step_limit before 100 s simulated (all rtols): {len(bad_limit)} runs, scenes {sorted(set(bad_limit))[:10]}")
    past = [rec["index"] for rec in recs if _halt_past_t_max(rec)]
    no_halt = [rec["index"] for rec in recs for r in _all_runs(rec) if _halt_unfitted(r) and rec["index"] not in past]
    n_halted = sum(1 for rec in recs for r in _all_runs(rec) if r.get("outcome") == "halted")
    lines.append(f"halted runs without a finite t_halt and (unless lay flat) t_halt_error (all runs): "
                 f"{len(no_halt)} of {n_halted}"
                 + (f", scenes {sorted(set(no_halt))[:10]}" if no_halt else ""))
    for rec in recs:
        if rec["index"] in past:
            r = rec["long"]
            lines.append(f"  scene {rec['index']}: its halt fit's levels lie past t_max "
                         f"{rec['scene']['stop']['t_max']:g} s (t_halt NaN, halt_finite false); to t_max "
                         f"{LONG_T_MAX:g} s: t_halt {r['q']['t_halt']:.6g} +- {r['t_halt_error']:.3g} s")
    budgets = np.array([r["budget"] for r in default if "budget" in r])
    nb = int(np.sum(~(budgets <= 1e-9)))
    lines.append(f"dissipation budget at rtol 1e-10: max {np.nanmax(budgets):.2e} E0, scenes over 1e-9 E0: {nb}")

    # convergence of well-conditioned quantities
    keys = sorted({k for rec in recs for r in rec["runs"] if "q" in r for k in r["q"]})
    n_wc = n_ok = 0
    worst = []
    shrink_total = shrink_ok = 0
    n_q_all = 0
    for rec in recs:
        ref = next(r for r in rec["runs"] if r["rtol"] == REF_RTOL)
        pert = rec["perturbed"]
        if "q" not in ref or "q" not in pert:
            continue
        for k in keys:
            vref = ref["q"].get(k)
            if vref is None or not math.isfinite(vref):
                continue
            n_q_all += 1
            sens = _rel(pert["q"].get(k), vref)
            if not sens < WELL_CONDITIONED:
                continue
            n_wc += 1
            rd = next(r for r in rec["runs"] if r["rtol"] == DEFAULT_RTOL)
            err = _rel(rd.get("q", {}).get(k), vref)
            if err <= AGREE:
                n_ok += 1
            else:
                worst.append((err, rec["index"], k))
            errs = [_rel(r.get("q", {}).get(k), vref) for r in rec["runs"] if r["rtol"] in (1e-10, 1e-11, 1e-12)]
            if all(math.isfinite(e) for e in errs):
                shrink_total += 1
                # shrinking, up to a round-off floor of 1e-12
                if errs[1] <= max(errs[0], 1e-12) * 1.5 and errs[2] <= max(errs[1], 1e-12) * 1.5:
                    shrink_ok += 1
    lines.append(f"quantities: {n_q_all}, well-conditioned (sensitivity < {WELL_CONDITIONED:g}): {n_wc}")
    share = 100.0 * n_ok / max(n_wc, 1)
    lines.append(f"well-conditioned within {AGREE:g} of rtol 1e-13 at rtol 1e-10: {n_ok}/{n_wc} = {share:.2f} %")
    lines.append(f"errors shrinking 1e-10 -> 1e-11 -> 1e-12 (to a 1e-12 floor): {shrink_ok}/{shrink_total}")
    worst.sort(reverse=True)
    if worst:
        lines.append("worst: " + "; ".join(f"scene {i} {k} {e:.2e}" for e, i, k in worst[:8]))
    same = 0
    diff_idx = []
    robust = same_robust = 0
    diff_robust = []
    complete = same_complete = 0
    diff_complete = []
    calm = same_calm = same_calm_ti = 0   # ti: transitions and impacts (the stick phases left out)
    diff_calm = []
    # calm scenes whose counts at each rtol differ from rtol 1e-13's: how the count exceptions scale
    calm_off = {rt: [] for rt in RTOLS if rt != REF_RTOL}
    early = same_early = 0     # the calm class before stop 29: quantities up to tau 300 and the levels only
    diff_early = []
    for rec in recs:
        seqs = [tuple(r["events"]) for r in rec["runs"] if r["rtol"] <= DEFAULT_RTOL and "events" in r]
        ok = len(seqs) == 4 and len(set(seqs)) == 1
        same += ok
        if not ok:
            diff_idx.append(rec["index"])
        # scenes whose event counts a 1e-10 rad change of alpha0 leaves alone (not sensitive)
        if "events" in rec["perturbed"] and seqs and tuple(rec["perturbed"]["events"]) == seqs[-1]:
            robust += 1
            same_robust += ok
            if not ok:
                diff_robust.append(rec["index"])
            # ... of which every run reached a physical end (a run cut at step_limit counts fewer)
            if all(r.get("outcome") != "step_limit" for r in rec["runs"] + [rec["perturbed"]]):
                complete += 1
                same_complete += ok
                if not ok:
                    diff_complete.append(rec["index"])
                # ... of which no quantity moves by WELL_CONDITIONED under the perturbation either: a
                # count that one perturbed run happens to keep can still sit on an amplifying trajectory
                ref = next((r for r in rec["runs"] if r["rtol"] == REF_RTOL), {})
                sens = {k: _rel(rec["perturbed"].get("q", {}).get(k), v) for k, v in ref.get("q", {}).items()
                        if v is not None and math.isfinite(v)}
                if sens and all(x < WELL_CONDITIONED for x in sens.values()):
                    calm += 1
                    same_calm += ok
                    same_calm_ti += len(seqs) == 4 and len({(q[0], q[2]) for q in seqs}) == 1
                    if not ok:
                        diff_calm.append(rec["index"])
                    for r in rec["runs"]:
                        if r["rtol"] in calm_off and tuple(r.get("events", ())) != tuple(ref.get("events", ())):
                            calm_off[r["rtol"]].append(rec["index"])
                early_sens = [x for k, x in sens.items() if k not in END_KEYS]
                if early_sens and all(x < WELL_CONDITIONED for x in early_sens):
                    early += 1
                    same_early += ok
                    if not ok:
                        diff_early.append(rec["index"])
    lines.append(f"same event counts (transitions, sticks, impacts) rtol 1e-10..1e-13: {same}/{n}"
                 + (f"; differ: scenes {diff_idx[:12]}" if diff_idx else ""))
    lines.append(f"  among scenes whose counts do not move under alpha0 + 1e-10: {same_robust}/{robust}"
                 + (f"; differ: scenes {diff_robust[:12]}" if diff_robust else ""))
    lines.append(f"  ... whose runs all end without step_limit: {same_complete}/{complete}"
                 + (f"; differ: scenes {diff_complete[:12]}" if diff_complete else ""))
    lines.append(f"  ... whose quantities all move < {WELL_CONDITIONED:g} under alpha0 + 1e-10: {same_calm}/{calm}"
                 + (f"; differ: scenes {diff_calm[:12]}" if diff_calm else ""))
    lines.append(f"      (their transitions and impacts alone, the stick phases left out: {same_calm_ti}/{calm})")
    lines.append("      (counts unlike rtol 1e-13's, by rtol: " + ", ".join(
        f"{rt:g} {len(v)}/{calm}" + (f" {v[:6]}" if v else "") for rt, v in calm_off.items()) + ")")
    lines.append(f"      (the same without the end quantities {', '.join(END_KEYS)}, i.e. the class before "
                 f"stop 29: {same_early}/{early}" + (f"; differ: scenes {diff_early[:12]}" if diff_early else "") + ")")
    lines.extend(analyse_knobs(recs))
    steps = np.array([r.get("n_steps", 0) for r in default])
    cpu = np.array([r.get("cpu", 0.0) for r in default])
    pct = lambda a, q: float(np.percentile(a, q))  # noqa: E731
    lines.append(f"cost at rtol 1e-10: steps median {pct(steps, 50):.0f}, p90 {pct(steps, 90):.0f}, "
                 f"p99 {pct(steps, 99):.0f}, max {steps.max():.0f}")
    lines.append(f"cpu at rtol 1e-10: median {1e3 * pct(cpu, 50):.1f} ms, p90 {1e3 * pct(cpu, 90):.1f} ms, "
                 f"p99 {1e3 * pct(cpu, 99):.1f} ms, max {1e3 * cpu.max():.1f} ms, total {cpu.sum():.1f} s, "
                 f"p99/median {pct(cpu, 99) / max(pct(cpu, 50), 1e-9):.1f}")
    lines.extend(cost_by_band(recs))
    return "\n".join(lines)


def tries_per_content(run: dict) -> float:
    """Tries (accepted + rejected steps) per unit of the motion's content: precession cycles plus
    physical events (roll<->slip transitions, stick phases, rim-edge impacts; at least 1)."""
    content = run.get("cycles", math.nan) + sum(run.get("events", []))
    return run["n_steps"] / max(content, 1.0) if math.isfinite(content) else math.nan


def cost_by_band(recs: list[dict]) -> list[str]:
    """Tries per unit of content at rtol 1e-10 by mu_d / mu_s band (BANDS): scenes, median, p99 and
    the band's median against that of mu_d / mu_s < 0.9; the whole set's p99 / median."""
    def ratio(rec):
        c = rec["scene"]["contact"]
        return c["mu_d"] / c["mu_s"] if c["mu_s"] > 0 else 0.0
    default = [(ratio(rec), next(r for r in rec["runs"] if r["rtol"] == DEFAULT_RTOL)) for rec in recs]
    vals = [(x, tries_per_content(r), r.get("n_steps", 0)) for x, r in default if "n_steps" in r]
    if not vals or not any(math.isfinite(v) for _, v, _ in vals):
        return ["tries per unit of content: not in this record"]
    lines = ["tries per unit of content (precession cycles + transitions, stick phases, impacts) at rtol 1e-10, "
             "by mu_d / mu_s:"]
    base = None
    for lo, hi in BANDS:
        inside = [(v, s) for x, v, s in vals if lo <= x < hi or x == hi == 1.0]
        sel = np.array([v for v, _ in inside if math.isfinite(v)])
        steps = sum(s for _, s in inside)
        if sel.size == 0:
            lines.append(f"  [{lo:g}, {hi:g}{']' if hi == 1.0 else ')'}: no scenes")
            continue
        med = float(np.median(sel))
        base = med if base is None else base
        lines.append(f"  [{lo:g}, {hi:g}{']' if hi == 1.0 else ')'}: {sel.size} scenes, median {med:.1f}, "
                     f"p99 {np.percentile(sel, 99):.1f}, max {sel.max():.1f}, median / that of [0, 0.9) "
                     f"{med / base:.2f}; tries in all {steps}")
    allv = np.array([v for _, v, _ in vals if math.isfinite(v)])
    lines.append(f"  all: {allv.size} scenes, median {np.median(allv):.1f}, p99 {np.percentile(allv, 99):.1f}, "
                 f"p99 / median {np.percentile(allv, 99) / np.median(allv):.1f}")
    return lines


def analyse_knobs(recs: list[dict]) -> list[str]:
    """Each threshold knob tightened alone (KNOB_RUNS) against the default run: the share of
    well-conditioned values (those a 1e-10 rad change of alpha0 moves by < WELL_CONDITIONED at rtol
    1e-13) within AGREE and AGREE_ALL, the largest difference, and the scenes whose event counts
    (transitions, stick phases, impacts) differ, among all scenes, among those whose counts the
    perturbation leaves alone, and among those whose counts are well-conditioned (the same at every
    rtol and under the perturbation: a count that the integration error or a 1e-10 change of the
    start moves is not one a knob can be held to)."""
    lines = []
    names = [name for name, _ in KNOB_RUNS if all(name in rec.get("knobs", {}) for rec in recs)]
    if not names:
        return ["threshold knobs: not run in this record"]
    lines.append("threshold knobs at rtol 1e-10 against the default (slip_tol 1e-9 m/s, spin_tol 1e-7 rad/s):")
    for rec in recs:
        for name, used in rec.get("knob_budget", {}).items():
            run = rec["knobs"][name]
            lines.append(f"  scene {rec['index']}, {name}: the step budget ran out ({used} tries) where the default "
                         f"run's did not; with max_steps {LONG_MAX_STEPS:.0e}: {run.get('outcome')} in "
                         f"{run.get('n_steps')} tries (compared below)")
    for name in names:
        n_wc = n_ok = n_ok_all = 0
        worst = []
        same = robust = same_robust = settled = same_settled = 0
        diff = []
        diff_settled = []
        for rec in recs:
            ref = next(r for r in rec["runs"] if r["rtol"] == REF_RTOL)
            base = next(r for r in rec["runs"] if r["rtol"] == DEFAULT_RTOL)
            run = rec["knobs"][name]
            pert = rec["perturbed"]
            ok_counts = "events" in run and "events" in base and run["events"] == base["events"]
            same += ok_counts
            if not ok_counts:
                diff.append(rec["index"])
            if "events" in pert and "events" in ref and pert["events"] == ref["events"]:
                robust += 1
                same_robust += ok_counts
                if all(r.get("events") == ref["events"] for r in rec["runs"]):
                    settled += 1
                    same_settled += ok_counts
                    if not ok_counts:
                        diff_settled.append(rec["index"])
            if "q" not in ref or "q" not in pert or "q" not in base:
                continue
            for k, vref in ref["q"].items():
                if vref is None or not math.isfinite(vref) or not _rel(pert["q"].get(k), vref) < WELL_CONDITIONED:
                    continue
                vb = base["q"].get(k)
                if vb is None or not math.isfinite(vb):
                    continue
                n_wc += 1
                d = _rel(run.get("q", {}).get(k), vb)
                n_ok += d <= AGREE
                n_ok_all += d <= AGREE_ALL
                if not d <= AGREE:
                    worst.append((d, rec["index"], k))
        worst.sort(key=lambda w: (-w[0] if math.isfinite(w[0]) else -math.inf))
        lines.append(f"  {name}: well-conditioned within {AGREE:g} of the default {n_ok}/{n_wc} = "
                     f"{100.0 * n_ok / max(n_wc, 1):.2f} %, within {AGREE_ALL:g} {n_ok_all}/{n_wc}, largest miss beyond {AGREE:g} "
                     f"{(worst[0][0] if worst else 0.0):.2e}; same event counts {same}/{len(recs)} scenes "
                     f"({100.0 * same / max(len(recs), 1):.1f} %), among scenes whose counts alpha0 + 1e-10 "
                     f"leaves alone {same_robust}/{robust}" + (f"; counts differ: scenes {diff[:10]}" if diff else ""))
        lines.append(f"    same event counts among scenes whose counts are well-conditioned (every rtol and "
                     f"alpha0 + 1e-10 alike): {same_settled}/{settled} = {100.0 * same_settled / max(settled, 1):.1f} %"
                     + (f"; differ: scenes {diff_settled[:10]}" if diff_settled else ""))
        if worst:
            lines.append("    worst: " + "; ".join(f"scene {i} {k} {e:.2e}" for e, i, k in worst[:6]))
    return lines


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="100 scenes instead of 500")
    ap.add_argument("--scenes", type=int, default=None)
    ap.add_argument("--seed", type=int, default=20261122)
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--tag", default=None)
    ap.add_argument("--atol-ratio", type=float, default=ATOL_RATIO,
                    help=f"atol = this x rtol in every run (default {ATOL_RATIO:g}, the product's default scaled)")
    ap.add_argument("--edge", type=int, default=None,
                    help=f"near-edge scenes (mu_d / mu_s in [{EDGE_LO:g}, 1]) beside the main draw "
                         "(default: a fifth of --scenes)")
    ap.add_argument("--analyse", metavar="JSONL", help="only analyse an existing record file")
    ap.add_argument("--only", type=int, nargs="+", metavar="INDEX",
                    help="run only these scene indices of the seed's draw (e.g. a table's exceptions again)")
    ap.add_argument("--resume", action="store_true",
                    help="keep the scenes already in the tag's record file (same seed and core) and run only the rest")
    a = ap.parse_args(argv)
    OUT.mkdir(exist_ok=True)
    if a.analyse:
        recs = [json.loads(x) for x in Path(a.analyse).read_text().splitlines() if x.strip()]
        print(analyse(recs))
        return 0
    n = a.scenes or (100 if a.quick else 500)
    n_edge = n // 5 if a.edge is None else a.edge
    tag = a.tag or f"n{n}-seed{a.seed}"
    if a.only:
        scenes = [(i, draw(a.seed, i), a.atol_ratio) for i in a.only]
    else:
        rng = np.random.default_rng(a.seed)
        scenes = [(i, draw_scene(rng), a.atol_ratio) for i in range(n)]
        scenes += [(EDGE_BASE + j, draw_edge_scene(a.seed, j), a.atol_ratio) for j in range(n_edge)]
    n = len(scenes)
    path = OUT / f"convergence-{tag}.jsonl"
    t0 = time.time()
    recs = []
    if a.resume and path.exists():
        recs = [json.loads(x) for x in path.read_text().splitlines() if x.strip()]
        done = {r["index"] for r in recs}
        scenes = [sc for sc in scenes if sc[0] not in done]
        print(f"resuming {tag}: {len(done)} scenes on record, {len(scenes)} to run", file=sys.stderr)
    with path.open("a" if a.resume else "w") as fh:
        if a.jobs > 1:
            with mp.get_context("spawn").Pool(a.jobs) as pool:
                it = pool.imap_unordered(run_scene, scenes)
                for rec in it:
                    recs.append(rec)
                    fh.write(json.dumps(rec) + "\n")
                    fh.flush()
        else:
            for sc in scenes:
                rec = run_scene(sc)
                recs.append(rec)
                fh.write(json.dumps(rec) + "\n")
                fh.flush()
                if len(recs) % 10 == 0:
                    print(f"  {len(recs)}/{n} scenes, {time.time() - t0:.0f} s", file=sys.stderr, flush=True)
    recs.sort(key=lambda r: r["index"])
    table = analyse(recs) + f"\nwall time of the harness: {time.time() - t0:.0f} s (jobs {a.jobs})"
    print(table)
    (OUT / f"convergence-{tag}.md").write_text(table + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
