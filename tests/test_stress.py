"""Stress grid of hard scenes, and the SciPy driver as a second implementation (issue #3).

Every scene must end with a meaningful outcome code within a modest step budget (max_steps
200000, 300000 for the frictionless slide: the paper's case needs ~2e4), with no NaN/inf in any output (a level's values may be NaN
only if the level was not reached), and the energy must never increase. Scenes that currently
fail would be marked xfail(strict=True) with the reason; the five problems first found here
(docs/performance.md, 'Stress grid') are fixed in the integrator and now pass.

    python -m pytest tests/test_stress.py -s     # prints the table (also written to benchmarks/out/)
"""
from __future__ import annotations

import copy
import math
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import sweep
from sweep.core import model
from sweep.scene import DEFAULTS, load_scene

ROOT = Path(__file__).resolve().parents[1]
MAX_STEPS = 200_000
K = DEFAULTS["contact"]

# name -> (overrides section__key=value, allowed outcomes, why / xfail reason or None)
GRID = {
    "nearly upright, alpha0 0.02": (dict(initial__alpha=0.02), {"line_contact"},
                                    "rocking between the rim edges collapses (Zeno guard): line_contact"),
    "nearly flat, alpha0 1.5": (dict(initial__alpha=1.5), {"halted"},
                                "a disk that reaches flat has halted (lay_flat)"),
    "tiny spin, omega3 -0.1 rad/s": (dict(initial__omega=[0.0, 0.0, -0.1]), {"halted"},
                                     "a disk that reaches flat has halted (lay_flat)"),
    "huge spin, omega3 -1000 rad/s": (dict(initial__omega=[0.0, 0.0, -1000.0]), {"contact_lost"}, None),
    # mu_d 0 slides all the way (72 s, ~6000 events) and dissipates only through the small k_i: each
    # step's energy error is held to its share of 4 rtol E0 over t_max (core.integrate.balance_error),
    # which takes it 178 000 steps + 34 000 rejections (122 000 + 20 000 before the balance was taken
    # exactly on the step's increment, stop 24): its own budget of 300 000
    "frictionless sliding, mu_d 0": (dict(contact__mu_d=0.0, stop__max_steps=300_000), {"halted"},
                                     None),
    "high friction, mu_s = mu_d = 1.5": (dict(contact__mu_s=1.5, contact__mu_d=1.5), {"halted"},
                                         "creeping slips: their direction is slaved below SLAVE_EPS mu_d Phi"),
    "no rolling resistance, k_i 0": (dict(contact__k1=0.0, contact__k2=0.0, contact__k3=0.0), {"t_max"}, None),
    "rolling resistance 10x": (dict(contact__k1=10 * K["k1"], contact__k2=10 * K["k2"], contact__k3=10 * K["k3"]),
                               {"halted"}, None),
    "thin shell": (dict(disk__shape="shell"), {"halted"}, None),
    "initial slip 0.2, 0.1 m/s": (dict(initial__slip=[0.2, 0.1]), {"halted"}, None),
    "loses contact: omega (30, 0, -100)": (dict(initial__omega=[30.0, 0.0, -100.0]), {"contact_lost"}, None),
    "fixed step, dt 1e-3 s": (dict(solver__method="fixed", solver__dt=1e-3), {"halted"},
                              "energy guard halves steps in the stiff slip ends"),
}
# Expected outcomes that are not 'halted': k_i = 0 has no dissipation while rolling (it rolls
# until t_max = 120 s); omega3 = -1000 rad/s and the nutating fast spin lose contact (the normal
# force needed by the rolling constraint becomes negative within ~15 ms).

ROWS: list[dict] = []


def _cfg(mods: dict) -> dict:
    cfg = copy.deepcopy(DEFAULTS)
    cfg["stop"]["max_steps"] = MAX_STEPS
    for k, v in mods.items():
        sec, key = k.split("__")
        cfg[sec][key] = v
    return cfg


def _finite_tree(x, path=""):
    """Paths of non-finite numbers in a summary (nested dicts/lists)."""
    bad = []
    if isinstance(x, dict):
        for k, v in x.items():
            bad += _finite_tree(v, f"{path}.{k}" if path else k)
    elif isinstance(x, (list, tuple)):
        for i, v in enumerate(x):
            bad += _finite_tree(v, f"{path}[{i}]")
    elif isinstance(x, float) and not math.isfinite(x):
        bad.append(path)
    return bad


# fit diagnostics that are NaN by definition when fewer than three levels were reached
FIT_KEYS = {"t_halt", "t_halt_error", "approach_exponent", "ramp_exponent", "ramp_exponent_error"}


@pytest.fixture(scope="module", autouse=True)
def _table():
    yield
    if not ROWS:
        return
    lines = ["| scene | outcome | steps | rejected | events | RHS | t_end (s) | E_final/E_initial | wall (s) |",
             "|---|---|---|---|---|---|---|---|---|"]
    for r in ROWS:
        lines.append(f"| {r['scene']} | {r['outcome']} | {r['steps']} | {r['rejected']} | {r['events']} | {r['rhs']} | "
                     f"{r['t_end']:.4g} | {r['e_ratio']:.3g} | {r['wall']:.2f} |")
    text = "\n".join(lines)
    out = ROOT / "benchmarks" / "out"
    if out.is_dir():
        (out / "stress_table.md").write_text(text + "\n")
    print("\n" + text)


def _params():
    for name, (mods, ok, why) in GRID.items():
        marks = [pytest.mark.xfail(strict=True, reason=why)] if why and why.startswith("XFAIL") else []
        yield pytest.param(name, mods, ok, id=name.split(",")[0].replace(" ", "_"), marks=marks)


@pytest.mark.parametrize("name, mods, allowed", list(_params()))
def test_stress_scene(name, mods, allowed):
    cfg = _cfg(mods)
    sc = load_scene(cfg)
    w = time.perf_counter()
    r = sweep.simulate(sc, sample_times=np.linspace(0.0, cfg["stop"]["t_max"], 241))
    wall = time.perf_counter() - w
    s = r.summary
    ROWS.append(dict(scene=name, outcome=s["outcome"], steps=s["n_steps"], rejected=s["n_rejected"],
                     events=s["n_events"], rhs=s["n_rhs"], t_end=s["t_end"],
                     e_ratio=s["energy_final"] / s["energy_initial"], wall=wall))
    assert s["outcome"] != "step_limit", f"{name}: step budget {cfg['stop']['max_steps']} used up at t = {s['t_end']:.4g} s"
    assert s["outcome"] in allowed, (name, s["outcome"])
    # no NaN/inf in any output, except the values of levels that were not reached and the halt-time
    # fit that needs three reached levels
    levels = s["levels"]
    reached = [math.isfinite(lv["t"]) for lv in levels]
    assert reached == sorted(reached, reverse=True), "levels must be reached in order"
    skip = FIT_KEYS | {"levels"}
    if r.peaks is not None and len(r.peaks) < 3:
        skip = skip | {"normal_force_hz_max"}     # needs three normal-force peaks
    bad = _finite_tree({k: v for k, v in s.items() if k not in skip})
    for i, lv in enumerate(levels):
        # levels crossed by the face impact of a disk that lay flat have no frequencies
        if reached[i] and not (s["lay_flat"] and lv["t"] == s["t_end"]):
            bad += [f"levels[{i}].{k}" for k, v in lv.items() if not math.isfinite(v)]
    if s["halt_finite"]:
        fit = ("t_halt",) if s["lay_flat"] else ("t_halt", "t_halt_error", "approach_exponent")
        bad += [k for k in fit if not math.isfinite(s[k])]
        if s["lay_flat"]:   # a located halt: no extrapolation error (not the location tolerance)
            assert math.isnan(s["t_halt_error"]), s["t_halt_error"]
    assert not bad, f"non-finite outputs: {bad}"
    t = r.samples["t"]
    live = t <= s["t_end"]
    for key in ("alpha", "omega", "energy"):
        assert np.all(np.isfinite(r.samples[key][live])), key
    # the energy never increases: overall, and between samples (up to the local error ~rtol E)
    e0 = s["energy_initial"]
    assert s["energy_final"] <= e0 * (1.0 + 1e-9), (s["energy_final"], e0)
    E = r.samples["energy"][live]
    assert np.all(np.diff(E) <= 1e-8 * e0), float(np.max(np.diff(E)))
    assert s["n_steps"] + s["n_rejected"] <= cfg["stop"]["max_steps"]


# --- the SciPy driver as a second implementation ------------------------------------------------

@pytest.mark.slow
def test_scipy_driver_agrees_with_sweep_on_the_paper_case():
    """SciPy DOP853 (rtol 1e-12) with the same model and event logic reproduces sweep (rtol 1e-12).

    Only well-conditioned quantities: the 0.3 and 0.1 rad level times and alpha at tau <= 100
    (deeper levels are dynamically sensitive, tests/test_physics.py).
    """
    from tests.reference.scipy_driver import run_scipy

    cfg = _cfg({})
    cfg["stop"]["levels"] = [0.3, 0.1]
    cfg["solver"].update(rtol=1e-12, atol=1e-14)
    cfg["outputs"]["normal_force_frequency"] = False
    sc = load_scene(cfg)
    tau = np.linspace(0.0, 100.0, 101)
    ours = sweep.simulate(sc, sample_times=tau * sc.chi)
    peer = run_scipy(sc, "DOP853", 1e-12, 1e-14, sample_tau=tau)
    assert ours.summary["outcome"] == peer["outcome"] == "halted"
    t_ours = np.array([lv["t"] for lv in ours.summary["levels"]]) / sc.chi
    rel = np.abs(peer["level_tau"] - t_ours) / t_ours
    da = np.max(np.abs(peer["samples"][:, model.Y_ALPHA] - ours.samples["alpha"]))
    print("level-time relative differences", rel, "max alpha difference", da)
    assert np.all(rel < 1e-8), rel
    assert da < 1e-8, da
    assert peer["n_transitions"] == ours.summary["n_transitions"]


if __name__ == "__main__":
    sys.exit(pytest.main([__file__, "-s", "-q", "-p", "no:cacheprovider"]))
