"""Convergence over the parameter space (issue #8): a fixed-seed subset of the random-scene harness
(benchmarks/convergence.py) and the reproducers that once switched branch with the tolerance.

Numerical error is what changes with rtol; sensitivity is what a 1e-10 rad change of alpha0 does.
Well-conditioned quantities (sensitivity < 1e-8 relative) must agree between rtol 1e-10 and 1e-12
to 1e-6, with the same event sequence.
"""
from __future__ import annotations

import copy
import math
import sys
from pathlib import Path

import numpy as np
import pytest

import sweep
from sweep.scene import DEFAULTS

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import convergence as harness  # noqa: E402

N_SCENES = 30
SEED = 7


def _subset():
    rng = np.random.default_rng(SEED)
    scenes = [harness._valid_levels(harness.draw_scene(rng)) for _ in range(N_SCENES)]
    for sc in scenes:
        sc["stop"]["t_max"] = 60.0      # keeps the suite short; the harness runs to 300 s
    return scenes


@pytest.fixture(scope="module")
def runs():
    out = []
    for cfg in _subset():
        default = harness._one_run(cfg, 1e-10)
        tight = harness._one_run(cfg, 1e-12)
        pert = harness._one_run(cfg, 1e-12, 1e-10 * math.copysign(1.0, cfg["initial"]["alpha"]))
        out.append((cfg, default, tight, pert))
    return out


@pytest.mark.slow
def test_random_scenes_end_physically_without_failures(runs):
    for cfg, *rs in runs:
        for r in rs:
            assert "exception" not in r, (cfg, r)
            assert not r["nan_in_summary"], cfg
            assert r["outcome"] != "step_size_underflow", cfg
            assert r["outcome"] != "numerical_error", cfg
            assert r["outcome"] != "step_limit", cfg
            # what is left plus what was dissipated is what there was: each step's balance is held
            # to 4 rtol of what it dissipates plus its share of E0 (core.integrate.BALANCE_FACTOR),
            # at most 8 rtol E0 = 8e-10 E0 in all at rtol 1e-10, plus round-off
            assert r["budget"] < 1e-9, (cfg, r["budget"])


@pytest.mark.slow
def test_well_conditioned_quantities_converge_with_the_same_events(runs):
    n_wc = n_ok = 0
    bad = []
    for cfg, default, tight, pert in runs:
        if pert["events"] == tight["events"]:   # a discrete sequence that the dynamics do not change
            assert default["events"] == tight["events"], (cfg, default["events"], tight["events"])
        for k, v in tight["q"].items():
            if v is None or not math.isfinite(v):
                continue
            if not harness._rel(pert["q"][k], v) < harness.WELL_CONDITIONED:
                continue
            n_wc += 1
            err = harness._rel(default["q"][k], v)
            if err <= harness.AGREE:
                n_ok += 1
            else:
                bad.append((k, err, cfg))
    print(f"\nwell-conditioned quantities within {harness.AGREE:g}: {n_ok}/{n_wc}")
    assert n_wc >= 60
    assert not bad, bad[:3]


def _reproducer_1(rtol):
    cfg = {"disk": {"radius": 0.009949042587459808, "thickness": 0.00014859458124330668,
                    "mass": 0.34225959698231734, "shape": "solid"},
           "contact": {"mu_s": 1.111739276303773, "mu_d": 0.056486485412309155, "k1": 7.479156886316974e-08,
                       "k2": 1.417391173403711e-05, "k3": 1.6787014706282867e-08},
           "gravity": 9.81,
           "initial": {"alpha": 0.27668410699108603, "omega": [0, 0, -4.732216567790502], "slip": [0, 0]},
           "stop": {"levels": [1e-7], "t_max": 5.0}, "solver": {"rtol": rtol, "atol": rtol * 1e-2}}
    chi = math.sqrt(1.25 * cfg["disk"]["radius"] / 9.81)
    return float(sweep.simulate(cfg, sample_times=[50.0 * chi]).samples["alpha"][0])


def _reproducer_2(rtol):
    cfg = copy.deepcopy(DEFAULTS)
    chi = math.sqrt(1.25 * 0.03755 / 9.81)
    cfg["initial"]["omega"] = [0.0, 0.0, -0.5 / chi]
    cfg["stop"] = {"levels": [1e-7], "t_max": 101.0 * chi}
    cfg["solver"] = {"rtol": rtol, "atol": rtol * 1e-2}
    return float(sweep.simulate(cfg, sample_times=[100.0 * chi]).samples["alpha"][0])


@pytest.mark.parametrize("reproducer", [_reproducer_1, _reproducer_2])
def test_issue_reproducers_converge(reproducer):
    # alpha at tau = 50 (resp. 100) once moved by 0.18 (2.7e-2) rad between tolerances
    a = [reproducer(rt) for rt in (1e-10, 1e-12, 1e-13)]
    assert abs(a[0] - a[2]) < 1e-7, a
    assert abs(a[1] - a[2]) < 1e-9, a


def test_paper_case_with_its_exact_spin_keeps_its_branch():
    # omega_hat(0) = -e3 exactly; at rtol 1e-10 it once took another branch (36 transitions, the
    # 0.01 level at 18.47 s instead of 15.09 s)
    cfg = copy.deepcopy(DEFAULTS)
    cfg["initial"]["omega"] = [0.0, 0.0, -14.456878347621343]
    cfg["outputs"]["normal_force_frequency"] = False
    res = []
    for rt in (1e-10, 1e-13):
        c = copy.deepcopy(cfg)
        c["solver"] = {"rtol": rt, "atol": rt * 1e-2}
        res.append(sweep.simulate(c).summary)
    assert res[0]["n_transitions"] == res[1]["n_transitions"]
    t0 = [lv["t"] for lv in res[0]["levels"]]
    t1 = [lv["t"] for lv in res[1]["levels"]]
    assert abs(t0[0] - t1[0]) < 1e-9 * t1[0]          # 0.1 level: well conditioned
    assert abs(t0[1] - t1[1]) < 1e-5 * t1[1]          # 0.01 level: sensitive (docs/model.md)
    assert abs(res[0]["t_halt"] - res[1]["t_halt"]) < 1e-2


def test_slaved_slip_losing_its_direction_inside_a_step_is_rejected_not_accepted():
    """Harness scene 12 (seed 20261122) at rtol 1e-13: a slaved slip's direction loses its root
    inside a step and the model returns NaN at the last stage (f_new), whose weight in y_new and
    in the error estimate is zero. Accepted, that NaN poisoned every later step (step_size_underflow
    at 5.73 s); rejected, steps shrink onto the located event and the scene halts where rtol 1e-12
    puts it."""
    rng = np.random.default_rng(20261122)   # the harness's default seed
    cfg = [harness.draw_scene(rng) for _ in range(13)][12]
    cfg = harness._valid_levels(cfg)
    halts = {}
    for rtol in (1e-12, 1e-13):
        r = harness._one_run(cfg, rtol)
        assert r["outcome"] == "halted", (rtol, r["outcome"], r["t_end"])
        halts[rtol] = r["q"]["t_halt"]
    assert abs(halts[1e-13] - halts[1e-12]) < 1e-8 * halts[1e-12]


def test_a_needed_moment_touching_its_limit_inside_a_step_unsticks():
    """Harness scene 435 (seed 20261122): a thin shell whose spin component omega.a_3 is held by
    the dry-friction moment; near tau 108.55 the moment it needs touches its limit (|sigma_3|
    reaches 1.004) and falls back, all within one step at rtol 1e-10 (sigma_3 = 0.985 and 0.9997
    at the step ends). The scan once looked for such interior dips only in the sign functions and
    the cone margin: the un-stick was missed at rtol 1e-10 and 1e-13 but not at 1e-11 and 1e-12
    (162, 161, 164, 163 stick phases; t_halt off by 7.8e-6 relative at the default rtol). Every
    event function now gets the interior-dip check, so the event counts agree and t_halt with them."""
    rng = np.random.default_rng(20261122)
    cfg = [harness.draw_scene(rng) for _ in range(436)][435]
    cfg = harness._valid_levels(cfg)
    res = {rtol: harness._one_run(cfg, rtol) for rtol in (1e-10, 1e-12)}
    assert res[1e-10]["events"] == res[1e-12]["events"]
    assert res[1e-10]["outcome"] == res[1e-12]["outcome"] == "halted"
    t0, t1 = res[1e-10]["q"]["t_halt"], res[1e-12]["q"]["t_halt"]
    assert abs(t0 - t1) < 1e-8 * t1


def test_a_slaved_slip_whose_moment_state_changes_at_the_hand_over_keeps_a_direction():
    """Harness scene 64 (seed 20261122) at rtol 1e-11, atol 1e-14: a slide with omega.a_1 held by the
    dry-friction moment falls to the slaving speed (tau 37.2785) and is handed to its attracting
    quasi-static direction; the plastic impulse of the hand-over moves the held omega.a_1, which
    releases it, and the released component changes the slip dynamics so that the direction found
    before is no root any more. The slaved right-hand side then had no root near the restart and
    every step failed (step_size_underflow at 4.23 s). contact.confirm_slaved now finds the
    direction of the state the update left (or hands the slip to SLIDE)."""
    rng = np.random.default_rng(20261122)
    cfg = [harness.draw_scene(rng) for _ in range(65)][64]
    cfg = harness._valid_levels(cfg)
    low_atol = harness._one_run(cfg, 1e-11, 0.0, 1e-3)
    tight = harness._one_run(cfg, 1e-12)
    assert low_atol["outcome"] == tight["outcome"] == "halted", (low_atol["outcome"], low_atol["t_end"])
    assert abs(low_atol["q"]["t_halt"] - tight["q"]["t_halt"]) < 1e-9 * tight["q"]["t_halt"]


def test_a_released_component_left_past_its_sign_by_an_impulse_is_free_while_it_rises():
    """Seed 20261124, scene 431: at tau 224.3477 a slip ends; the slip-end impulse leaves the held
    omega.a_1 at +3.9e-10 (below spin_tol) and the moment, which can no longer hold it, releases it
    with sign -1: sigma_1 omega.a_1 starts below 0 and rises. A step too short to see it reach 0
    once counted that as 'moving against its new sign at once' and stuck the component: 13 or 286
    stick phases depending on rtol (13, 286, 286, 13 at rtol 1e-9..1e-12). The rate at the restart
    decides now (integrate.first_event), so every rtol takes the same branch."""
    rng = np.random.default_rng(20261124)
    cfg = harness._valid_levels([harness.draw_scene(rng) for _ in range(432)][431])
    res = {rtol: harness._one_run(cfg, rtol) for rtol in (1e-9, 1e-10, 1e-11, 1e-12)}
    assert len({tuple(r["events"]) for r in res.values()}) == 1, {k: r["events"] for k, r in res.items()}
    t12 = res[1e-12]["q"]["t_halt"]
    assert abs(res[1e-10]["q"]["t_halt"] - t12) < 1e-8 * t12


def test_a_shallow_dip_below_spin_tol_is_decided_by_the_dense_outputs_minimum():
    """Harness scene 4 (seed 20261122): after an un-stick at tau 573.62 omega.a_1 swings to 1.6e-4
    and returns, dipping 2e-10 below spin_tol (a stick there starts a micro-stick regime). At rtol
    1e-10 the dense output at the cubic Hermite interpolant's minimum was +1.3e-10, so the dip was
    stepped over: 546 stick phases against 556 at rtol 1e-11..1e-13 (397..439 at 1e-9). A shallow
    dip is now decided by the minimum of the event function on the dense output (roots.brent_min)."""
    rng = np.random.default_rng(20261122)
    cfg = harness._valid_levels([harness.draw_scene(rng) for _ in range(5)][4])
    res = {rtol: harness._one_run(cfg, rtol) for rtol in (1e-9, 1e-10, 1e-12)}
    assert len({tuple(r["events"]) for r in res.values()}) == 1, {k: r["events"] for k, r in res.items()}
    t12 = res[1e-12]["q"]["t_halt"]
    assert abs(res[1e-10]["q"]["t_halt"] - t12) < 1e-8 * t12


def test_an_unstick_only_the_dense_output_shows_is_confirmed_by_the_integrated_state():
    """Harness scene 246 (seed 20261124): at tau 1737.4961541 a slaved slip leaves for SLIDE; at rtol
    1e-10 the fifth step of the stiff transient that follows has the un-stick function of the held
    omega.a_3 at 0.369 at both ends and 0 inside on its dense output (|sigma_3| moves ~700 times the
    friction direction's angle: k3/R 1.2e-3, mu_d 0.81), so the component was released and stuck
    again at once: 70 stick phases against 69 at rtol 1e-11..1e-13. An event of the forces that only
    the dense output shows now stands only where an integrated step to its minimum confirms it."""
    rng = np.random.default_rng(20261124)
    cfg = harness._valid_levels([harness.draw_scene(rng) for _ in range(247)][246])
    res = {rtol: harness._one_run(cfg, rtol) for rtol in (1e-10, 1e-11, 1e-12)}
    assert len({tuple(r["events"]) for r in res.values()}) == 1, {k: r["events"] for k, r in res.items()}
    t12 = res[1e-12]["q"]["t_halt"]
    assert abs(res[1e-10]["q"]["t_halt"] - t12) < 1e-6 * t12


def test_the_default_slave_tol_gives_the_counts_of_its_limit_in_a_micro_stick_scene():
    """Harness scene 246 (seed 20261124) holds omega.a_3 against a moment that moves ~700 times the
    friction direction's angle: its stick phases are decided by the slaved direction's error
    (docs/model.md, 'Slow slip'). The counts are 69 stick phases from slave_tol 3e-3 down to 0
    (slaved only where the relaxation time alone is below 1e-7) and under perturbations of alpha0
    and omega0 up to 1e-7, the default 3e-3 among them; 73-74 from 1e-2 to 3e-2 (values within
    5e-10)."""
    rng = np.random.default_rng(20261124)
    cfg = harness._valid_levels([harness.draw_scene(rng) for _ in range(247)][246])
    res = {st: harness._one_run(cfg, 1e-10, knobs={} if st is None else {"slave_tol": st}) for st in (None, 1e-4, 0.0)}
    default = res.pop(None)
    for st, r in res.items():
        assert r["events"] == default["events"], (st, r["events"], default["events"])
        assert abs(r["q"]["t_halt"] - default["q"]["t_halt"]) < 1e-8 * r["q"]["t_halt"], st


def _counts(cfg, rtol, spin_tol):
    c = copy.deepcopy(cfg)
    c["solver"] = {"rtol": rtol, "atol": rtol * 1e-2, "spin_tol": spin_tol}
    s = sweep.simulate(c).summary
    return (s["n_transitions"], s["n_stick"], s["n_impacts"]), s["levels"][-1]["t"]


def _peer_end(cfg):
    """The SciPy peer's outcome and end time (s) for a harness scene at rtol 1e-12."""
    from tests.reference.scipy_driver import run_scipy
    from sweep.scene import load_scene

    c = copy.deepcopy(cfg)
    c["solver"] = {"rtol": 1e-12, "atol": 1e-14}
    sc = load_scene(c)
    peer = run_scipy(sc, "DOP853", 1e-12, 1e-14)
    return peer["outcome"], peer["t_end"] * sc.chi


@pytest.mark.slow
def test_a_slip_carried_into_the_painleve_singularity_ends_as_painleve_at_every_rtol():
    """Seed 20261125, scene 472 (a 4.6 mm disk, mu_d 1.53): at tau 7.84396 a decaying slip reaches
    the slaving speed, and the direction dynamics carry it not to a root of cross but to the
    direction where the e1 balance's coefficient of Phi falls to 0 (Phi -> inf; beyond it the
    contact law has no solution). The hand-over once projected the slip onto that pole and every
    slaved step failed: step_size_underflow at every rtol. attracting_direction now tells a pole
    from a root by the state past it, and the scene ends as painleve there; the SciPy peer, with the
    rule written independently, ends at the same time."""
    rng = np.random.default_rng(20261125)
    cfg = harness._valid_levels([harness.draw_scene(rng) for _ in range(473)][472])
    res = {rtol: harness._one_run(cfg, rtol) for rtol in (1e-9, 1e-10, 1e-12)}
    assert {r["outcome"] for r in res.values()} == {"painleve"}, {k: r["outcome"] for k, r in res.items()}
    assert len({tuple(r["events"]) for r in res.values()}) == 1
    t12 = res[1e-12]["t_end"]
    assert abs(res[1e-10]["t_end"] - t12) < 1e-9 * t12
    outcome, t_end = _peer_end(cfg)
    assert outcome == "painleve"
    assert abs(t_end - t12) < 1e-9 * t12


def test_a_slip_onset_beside_a_painleve_pole_takes_the_root_at_every_rtol():
    """Seed 20261136, scene 465 (an 11 cm disk, mu_d 1.15, a tumbling start): at tau 0.2194 the
    friction cone is violated, and the cross product of the slip acceleration with the direction
    changes sign at the root near -F/|F| and at two Painleve poles (Phi's coefficient through 0,
    the contact law without a solution between them). At rtol 1e-9 the onset's bisection of a
    pole's bracket evaluated the model on the pole itself, where the coefficient was exactly 0, and
    the run raised ZeroDivisionError. The kernels now divide as NumPy does (inf, no
    exception), and onset_direction tells a pole from a root by the model's flag on its two sides:
    the disk slides from the root and leaves the table at the same time at every rtol, as the SciPy
    peer does."""
    cfg = harness.harness_scene(20261136, 465)
    res = {rtol: harness._one_run(cfg, rtol) for rtol in (1e-9, 1e-10, 1e-12)}
    assert all("exception" not in r for r in res.values()), res
    assert {r["outcome"] for r in res.values()} == {"contact_lost"}
    assert {tuple(r["events"]) for r in res.values()} == {(1, 0, 0)}
    t12 = res[1e-12]["t_end"]
    assert all(abs(r["t_end"] - t12) < 1e-9 * t12 for r in res.values())
    outcome, t_end = _peer_end(cfg)
    assert outcome == "contact_lost"
    assert abs(t_end - t12) < 1e-8 * t12


def test_a_slide_near_flat_is_not_stopped_by_the_round_off_of_its_energy_balance():
    """Seed 20261125, scene 32 (an 8 mm shell, mu_d 0.0068, sliding at beta ~ 1e-6 before it lies
    flat): the gyroscopic terms of the right-hand side (tan(alpha) ~ 1e6) leave a round-off of
    ~1e-11 of the dissipated power in the power balance, which scales with the step like the
    balance itself; with a floor from the energy's own terms only, every shorter step failed the
    balance at rtol 1e-12, 1e-13 (step_size_underflow). The floor includes the measured defect
    (core.integrate.power_defect): the scene halts at every rtol with the same events."""
    rng = np.random.default_rng(20261125)
    cfg = harness._valid_levels([harness.draw_scene(rng) for _ in range(33)][32])
    res = {rtol: harness._one_run(cfg, rtol) for rtol in (1e-10, 1e-12, 1e-13)}
    assert {r["outcome"] for r in res.values()} == {"halted"}, {k: r["outcome"] for k, r in res.items()}
    assert len({tuple(r["events"]) for r in res.values()}) == 1
    t13 = res[1e-13]["q"]["t_halt"]
    assert abs(res[1e-10]["q"]["t_halt"] - t13) < 1e-8 * t13
    assert all(r["budget"] < 1e-9 for r in res.values())


@pytest.mark.slow
def test_a_slip_spiralling_into_slip_tol_late_in_a_scene_is_not_a_step_size_underflow():
    """Seed 20261127, scene 421 (a 14 mm disk, thickness 0.81 R, mu_d 0.93): near flat, at
    t = 216.09 s (tau ~ 5094), a slide's slip spirals into u = 0 and each step covers a fixed share
    of what is left, ~1e-11 in tau at |u| = slip_tol. The step floor was 16 eps tau (1.8e-11 there),
    so every rtol ended as step_size_underflow, decided by how long the scene had run, not by its
    state. The model is autonomous, so the floor is 2 eps tau: the slide ends at slip_tol and the
    scene halts, with the same events at every rtol."""
    cfg = harness.harness_scene(20261127, 421)
    res = {rtol: harness._one_run(cfg, rtol) for rtol in (1e-10, 1e-12)}
    assert {r["outcome"] for r in res.values()} == {"halted"}, {k: r["outcome"] for k, r in res.items()}
    assert len({tuple(r["events"]) for r in res.values()}) == 1
    t12 = res[1e-12]["q"]["t_halt"]
    assert abs(res[1e-10]["q"]["t_halt"] - t12) < 1e-8 * t12
    assert all(r["budget"] < 1e-9 for r in res.values())


@pytest.mark.slow
def test_a_slip_passing_by_zero_within_slip_tol_ends_at_every_rtol():
    """Seed 20261128, scene 39 (a 58 mm disk, mu_s 0.055, near upright): at tau 827.823 a slide's
    slip passes by u = 0 with a miss distance 1e-12 (0.07 %) below slip_tol in the runs at rtol
    1e-10, 1e-11 and 1e-13 alike, so the slide ends there and a new slip starts at once (the cone
    is violated): two transitions. Its V in |u| is ~4e-9 tau wide, narrower than RATE_STEP; the dip
    check took the cubic through |u|'s difference-quotient slopes and stepped over it in those
    three runs (4024 transitions), while the run at 1e-12 passed closer and caught it (4026). The
    dip check now places the V by the slip's own components (roots.slip_closest_approach)."""
    cfg = harness.harness_scene(20261128, 39)   # the whole scene: its t_max sets each step's energy share
    res = {rtol: harness._one_run(cfg, rtol) for rtol in (1e-12, 1e-13)}
    counts = {rtol: tuple(r["events"]) for rtol, r in res.items()}
    assert len(set(counts.values())) == 1, counts


def test_a_stick_test_in_a_slaved_slip_reads_the_moment_along_the_slips_direction():
    """Seed 20261128, scene 70: at tau 101.71254987 the slide hands over to SLAVED, and its impulse
    carries a just-released omega.a_3 across 0 by 2.0e-9 (within spin_tol, 2.6e-9: at rest), so
    it gets the stick test. With component 3 held the slaved slip has no root near its direction;
    the test solved for one, and its failed secant's last iterate decided (held, 52 stick phases
    at every rtol) while the SciPy peer read NaN there and passed (51). Both now read the moment
    with the friction along the slip's direction at that instant (contact.decision_rhs): the
    peer's count, 51, at rtol 1e-12 and 1e-13 (benchmarks/scipy_agreement.py)."""
    cfg = harness._valid_levels(harness.harness_scene(20261128, 70))
    res = {rtol: harness._one_run(cfg, rtol) for rtol in (1e-10, 1e-12)}
    assert {r["outcome"] for r in res.values()} == {"halted"}, {k: r["outcome"] for k, r in res.items()}
    assert res[1e-10]["events"] == res[1e-12]["events"], {k: r["events"] for k, r in res.items()}


@pytest.mark.slow
@pytest.mark.parametrize("seed, index", [(20261128, 70), (20261124, 246)])
def test_the_peer_counts_the_stick_phases_alike(seed, index):
    """The SciPy peer, its contact rules written independently, at rtol 1e-12 on the harness scenes
    above whose stick phases hinge on a slaved slip's moment (scene 70) and on the slaved
    direction's error (scene 246, ~70 s of the peer): the kernel's outcome and event counts at
    the same rtol."""
    from conftest import peer_run

    cfg = harness._valid_levels(harness.harness_scene(seed, index))
    kernel = harness._one_run(cfg, 1e-12)
    peer, _ = peer_run(cfg, 1e-12)
    assert peer["outcome"] == kernel["outcome"] == "halted"
    assert [peer["n_transitions"], peer["n_stick"], peer["n_impacts"]] == kernel["events"], kernel["events"]


FOIL_DISK = {
    "disk": {"radius": 0.0038524343923773373, "thickness": 5.94764667844619e-05, "mass": 0.5348422771521737,
             "shape": "solid"},
    "contact": {"mu_s": 0.1906100239171969, "mu_d": 0.1561480687266237, "k1": 0.0, "k2": 0.0,
                "k3": 7.287012338344757e-05},
    "gravity": 9.81,
    "initial": {"alpha": 1.09546964534463, "omega": [0.0, 0.0, -41.13889073568484], "slip": [0.0, 0.0],
                "theta": 0.0, "psi": 0.0},
    "stop": {"levels": [0.1, 0.01, 0.001], "t_max": 300.0},
}


def test_a_slaved_slip_carried_past_its_exit_by_a_stop_at_spin_tol_slides():
    """Issue 50's foil disk (R 3.85 mm, L/R 0.015, mu_d 0.156, k3/R 0.019): at tau 325.8975982 a
    slaved slip (|u_hat| 2.279e-8) has omega.a_3 slow to spin_tol, and the stop that holds it moves
    the slip to 2.3056e-8, past its exit from SLAVED (SLAVE_EXIT u_s = 2.3005e-8). EV_SLIP_FAST,
    g going from > 0 to <= 0, could not happen any more: the slip stayed slaved, its friction held
    on the quasi-static direction, while it grew to 1.1e-2 (1.9 mm/s), until the slaved direction
    was lost and every step failed: step_size_underflow at t = 7.230984 s at every rtol (613
    transitions, 584 stick phases). The update now hands such a slip to SLIDE
    (contact.settle_event): the disk slaps down onto its face at t = 8.3996035479 s, the same at
    every rtol and with slip_tol and spin_tol 100x smaller. (The stick phases: 788 at the default
    spin_tol, 787 below it, where omega.a_3 reaches rest only after the slip has left SLAVED.) The
    runs slave the direction only below the floor (slave_tol 0), where this hand-over happened; at
    the default slave_tol the halt time stays within the issue's 1e-7 of that limit."""
    runs = {}
    for name, solver in (("default", {}), ("rtol 1e-12", {"rtol": 1e-12, "atol": 1e-14}),
                         ("knobs", {"slip_tol": 1e-11, "spin_tol": 1e-9})):
        cfg = copy.deepcopy(FOIL_DISK)
        cfg["solver"] = {**solver, "slave_tol": 0.0}
        runs[name] = sweep.simulate(cfg).summary
    default_tol = sweep.simulate(copy.deepcopy(FOIL_DISK)).summary
    assert default_tol["outcome"] == "halted" and default_tol["lay_flat"]
    assert abs(default_tol["t_halt"] - runs["rtol 1e-12"]["t_halt"]) < 1e-7 * runs["rtol 1e-12"]["t_halt"]
    for name, s in runs.items():
        assert s["outcome"] == "halted" and s["lay_flat"], (name, s["outcome"], s["t_end"])
        budget = abs(s["energy_initial"] - s["energy_final"] - sum(s["dissipation"].values()))
        assert budget < 1e-9 * s["energy_initial"], name
        assert s["n_transitions"] == runs["default"]["n_transitions"], name
    assert runs["rtol 1e-12"]["n_stick"] == runs["default"]["n_stick"]
    t_ref = runs["rtol 1e-12"]["t_halt"]
    assert all(abs(s["t_halt"] - t_ref) < 1e-9 * t_ref for s in runs.values()), {k: s["t_halt"] for k, s in runs.items()}


@pytest.mark.slow
def test_the_peer_lays_the_foil_disk_flat_at_the_kernels_time():
    """The SciPy peer, with the contact rules written independently (a restart that leaves an event
    function <= 0 fires that event at once), lays issue 50's foil disk flat at the kernel's time:
    8.399603547969 s against 8.399603547982 s at rtol 1e-12, with the same 880 transitions."""
    cfg = copy.deepcopy(FOIL_DISK)
    cfg["solver"] = {"rtol": 1e-12, "atol": 1e-14}
    s = sweep.simulate(cfg).summary
    outcome, t_end = _peer_end(FOIL_DISK)
    assert outcome == s["outcome"] == "halted"
    assert abs(t_end - s["t_halt"]) < 1e-9 * s["t_halt"], (t_end, s["t_halt"])


def test_the_peers_minimum_over_a_short_step_late_in_a_run_is_the_minimum():
    """The SciPy peer's dip checks minimise over a step in the step's own coordinate: SciPy's
    bounded Brent stops at sqrt(eps) |x| + xatol/3, which in absolute time (tau ~ 124, a step of
    8.8e-9) exceeds the step, and it returned its first golden-section point (seed 20261128 scene
    19: |u| 1.342e-9 there, against a minimum of 1.250e-9 below slip_tol 1.264e-9; the slide's end
    was missed at rtol 1e-11 and 1e-12). A V of |u| with its bottom at 0.63 of the step:"""
    from tests.reference.scipy_driver import _step_minimum

    t_old, hstep = 124.24662130825361, 8.8155e-9
    t_bottom = t_old + 0.63 * hstep
    x, value = _step_minimum(lambda t: 1.25e-9 + 0.13 * abs(t - t_bottom), t_old, hstep)
    assert abs(x - 0.63) < 1e-4 and value < 1.25e-9 + 1e-12, (x, value)


def test_micro_sticks_at_a_moment_limit_are_counted_alike_at_every_rtol():
    """Harness scene 252 (seed 20261122): omega.a_1's needed moment oscillates about its limit, so
    the component unsticks once per period, swings to ~1e-5 and comes back to 0 almost
    tangentially, dipping ~1e-13 below it. With the pure Filippov rule (spin_tol 0) whether a
    return sticks is decided below the integration error: 4573 stick phases at rtol 1e-10, 5427 at
    1e-11..1e-13. Sticking where the rate slows to spin_tol (docs/model.md) makes every such return
    a transversal crossing: the same count at every rtol, and the last level's time within 1e-7
    relative of the pure rule's converged one (first order in spin_tol, 2.4e-8 at 1e-7 rad/s)."""
    rng = np.random.default_rng(20261122)
    cfg = harness._valid_levels([harness.draw_scene(rng) for _ in range(253)][252])
    default_tol = DEFAULTS["solver"]["spin_tol"]
    ev10, t10 = _counts(cfg, 1e-10, default_tol)
    ev12, t12 = _counts(cfg, 1e-12, default_tol)
    assert ev10 == ev12, (ev10, ev12)
    assert abs(t10 - t12) < 1e-9 * t12
    # (the pure rule's count once moved with rtol, 4573 vs 5427; with shallow dips decided by the
    # dense output's minimum, integrate.DIP_REFINE, it gives 5427 at rtol 1e-10 too, but its dips
    # of ~1e-13 lie below the integration error, so that is not asserted)
    _, t_pure = _counts(cfg, 1e-12, 0.0)
    assert abs(t12 - t_pure) < 1e-7 * t_pure


@pytest.mark.slow
def test_spin_tolerance_convergence():
    """The sticking at spin_tol converges to the pure Filippov rule at first order in spin_tol:
    the last level time of harness scene 252 (the micro-stick regime above) at rtol 1e-12 moves by
    1.9e-5, 1.3e-6, 9.4e-8 s for spin_tol 1e-6, 1e-7, 1e-8 rad/s against spin_tol 0."""
    rng = np.random.default_rng(20261122)
    cfg = harness._valid_levels([harness.draw_scene(rng) for _ in range(253)][252])
    t = {st: _counts(cfg, 1e-12, st)[1] for st in (1e-6, 1e-7, 1e-8, 0.0)}
    d = [abs(t[st] - t[0.0]) for st in (1e-6, 1e-7, 1e-8)]
    assert d[0] > d[1] > d[2]
    assert d[0] / d[2] > 30          # two decades of spin_tol: ~100x (first order)
    assert d[2] < 1e-8 * t[0.0]


def test_the_peer_comparison_counts_totals_only_in_calm_scenes():
    """benchmarks/scipy_agreement.py: an event count or outcome is a total over the whole run, so it
    is compared only where every value of the run (t_halt included) moves < 1e-8 under the
    perturbation; a sensitive scene's count that the one perturbed run left alone is left out."""
    import scipy_agreement as sa

    def record(t_halt_perturbed):
        kernel = {"q": {"t_level_0.1": 1.0, "t_halt": 2.0}, "outcome": "halted", "events": [3, 1, 0]}
        perturbed = {"q": {"t_level_0.1": 1.0 + 1e-12, "t_halt": t_halt_perturbed}, "outcome": "halted",
                     "events": [3, 1, 0]}
        driver = {"timed_out": False, "q": {"t_level_0.1": 1.0 + 2e-12}, "outcome": "halted", "events": [4, 1, 0]}
        return {"index": 0, "kernel": kernel, "perturbed": perturbed, "driver": driver}

    calm = sa.compare(record(2.0 + 1e-12))
    assert calm["calm"] and calm["ill"] == 0
    compared = {q[0]: q[3] for q in calm["wc"]}
    assert compared["t_level_0.1"] < 1e-8 and compared["n_stick"] == 0.0 and compared["outcome"] == 0.0
    assert math.isnan(compared["n_transitions"])        # 3 against the driver's 4: a disagreement
    sensitive = sa.compare(record(2.0 * (1 + 1e-5)))
    assert not sensitive["calm"] and sensitive["ill"] == 4
    assert [q[0] for q in sensitive["wc"]] == ["t_level_0.1"]


@pytest.mark.slow
def test_events_restart_at_their_roots_so_many_impacts_add_no_error_that_rtol_leaves():
    """Seed 20261130, scene 8: a disk rocking near upright through 1268 rim impacts and 891 stick
    phases to tau 300, where alpha = -6.381e-4 rad. Each event restarts at the right end of its
    located bracket. With brackets of 1e-12 tau that one-sided offset summed to 4.7e-11 rad: the
    kernel's runs at rtol 1e-12..1e-14 agreed to 3e-12, and the SciPy peer's (located to 4 ulp) to
    2e-12, but the two converged 7e-8 of the value apart. Brackets of 4 ulp (roots.location_tol)
    give the peer's value: the peer at its tightest rtol (SciPy clamps it to 2.2e-14) and the
    kernel at 1e-13 now agree to 3e-13 rad (5e-11 before the change)."""
    from scipy_agreement import _driver

    cfg = harness._valid_levels(harness.harness_scene(20261130, 8))
    kernel = harness._one_run(cfg, 1e-13)
    peer = _driver(cfg, 2.3e-14, 600.0)
    assert kernel["events"] == peer["events"] == [0, 891, 1268], (kernel["events"], peer["events"])
    a_kernel, a_peer = kernel["q"]["alpha_tau_300"], peer["q"]["alpha_tau_300"]
    assert abs(a_kernel - a_peer) <= 1e-8 * abs(a_peer), (a_kernel, a_peer)


def test_a_run_that_reaches_t_max_ends_exactly_there_and_keeps_the_sample_at_t_max():
    """The last step of a run is cut to end at t_max (h = t_max - t), and t + h can round 1 ulp
    short of t_max. Harness seed 20261138 scene 198 (a 9.6 mm shell rolling to t_max 300 s) did so
    at rtol 1e-10: the run ended at 299.99999999999994 s and the sample asked for at 300 s was NaN,
    while rtol 1e-13 had it. The step now ends at t_max itself, at every rtol."""
    for rtol in (1e-10, 1e-13):
        cfg = harness.harness_scene(20261138, 198, rtol)
        r = sweep.simulate(cfg, sample_times=[100.0, cfg["stop"]["t_max"]])
        assert r.summary["outcome"] == "t_max"
        assert r.summary["t_end"] == cfg["stop"]["t_max"], (rtol, r.summary["t_end"])
        assert np.all(np.isfinite(r.samples["alpha"])), (rtol, r.samples["alpha"])
