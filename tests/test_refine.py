"""sweep.refine: the lattice, the surpluses, the rounds' plans and the reconstruction with its
error bars, on synthetic maps whose truth is known (no scenes are integrated here)."""
from __future__ import annotations

import numpy as np
import pytest

from sweep import axes, errorbars, grid, interpolation, outcomes, reconstruct, refine, surplus, validation
from sweep import lattice as sweep_lattice


def lattice(points=33, start=5):
    return sweep_lattice.make_lattice({"x": {"from": 0.0, "to": 1.0, "points": points},
                                       "y": {"from": 0.0, "to": 1.0, "points": points}}, start)


def xy(lat):
    x, y = np.meshgrid(lat.values[0], lat.values[1], indexing="ij")
    return x.ravel(), y.ravel()


def synthetic(lat, seed=1):
    """A map with the three things the refinement must tell apart: a smooth positive output
    (log-interpolated), an outcome boundary along a curve (no value beyond it), and a rough
    patch (a factor exp(0.3 N(0, 1)) per node) at x > 0.6, y < 0.5."""
    x, y = xy(lat)
    oc = np.where(y > 0.7 + 0.1 * np.sin(4 * x), outcomes.CONTACT_LOST, outcomes.HALTED)
    val = np.exp(1.0 + 2.0 * x + np.sin(3.0 * y))
    rough = (x > 0.6) & (y < 0.5)
    val = val * np.where(rough, np.exp(0.3 * np.random.default_rng(seed).standard_normal(val.shape)), 1.0)
    return oc, np.where(oc == outcomes.HALTED, val, np.nan), rough


def run_rounds(lat, oc, val, share=0.25, tol=0.01):
    f = sweep_lattice.Fields.empty(lat, {"t": 1}, {"t": True})
    st = sweep_lattice.Settings(("t",), tol, int(share * lat.size))
    plans = []
    for k in range(lat.rounds + 1):
        p = refine.plan_round(lat, f, st, k)
        idx = sweep_lattice.flat_index(lat, p.nodes)
        f.set(lat, p.nodes, k, oc[idx], {"t": val[idx]})
        plans.append(p)
    return f, st, plans


def test_lattice_sizes_and_values():
    assert [n for n in range(2, 70) if sweep_lattice.is_lattice_size(n)] == [3, 5, 9, 17, 33, 65]
    v = sweep_lattice.axis_values(2.0, 200.0, 65, "log")
    assert v[0] == 2.0 and v[-1] == 200.0 and v[32] == pytest.approx(20.0, rel=1e-12)
    np.testing.assert_allclose(np.diff(np.log(v)), np.log(100.0) / 64, rtol=1e-9)
    lat = sweep_lattice.make_lattice({"a": {"from": 0.0, "to": 1.0, "points": 65},
                                      "b": {"from": 0.0, "to": 1.0, "points": 33}}, 9)
    # R = log2(32) - log2(8) = 2 rounds after round 0; round 0 has 9 points on b, 17 on a
    assert lat.rounds == 2 and len(lat.round0_nodes()) == 17 * 9
    assert lat.stride(0) == 4 and lat.stride(lat.rounds) == 1


def test_surplus_of_a_quadratic_is_its_second_difference():
    # f = i^2 along axis 0 (index units): a node halfway along an edge of stride 2s is predicted
    # as the mean of its neighbours, ((i - s)^2 + (i + s)^2) / 2 = i^2 + s^2, so |surplus| = s^2;
    # a bilinear function has none.
    lat = lattice(17, 3)                    # strides 8 (round 0), 4, 2, 1
    i, j = np.unravel_index(np.arange(lat.size), lat.shape)
    f = sweep_lattice.Fields.empty(lat, {"q": 1, "b": 1}, {"q": False, "b": False})
    nodes = np.stack([i, j], axis=1)
    f.set(lat, nodes, 0, np.zeros(lat.size, int), {"q": i.astype(float) ** 2, "b": (1.0 + i) * (2.0 + 3 * j)})
    sq = surplus.surpluses(lat, f, "q")[:, 0].reshape(lat.shape)
    rounds = sweep_lattice.node_round(lat, nodes).reshape(lat.shape)
    for k in range(1, lat.rounds + 1):
        on_edge = (rounds == k) & (np.arange(17)[:, None] % lat.stride(k - 1) != 0) & (
            np.arange(17)[None, :] % lat.stride(k - 1) == 0)
        np.testing.assert_allclose(sq[on_edge], lat.stride(k) ** 2)
    assert sq[4, 0] == 16.0 and sq[12, 8] == 16.0           # round 0's odd nodes: s = 4 against stride 8
    assert np.nanmax(surplus.surpluses(lat, f, "b")[:, 0][rounds.ravel() >= 0]) == pytest.approx(0.0, abs=1e-9)


def test_rounds_are_deterministic_and_within_budget():
    lat = lattice()
    oc, val, _ = synthetic(lat)
    f1, st, p1 = run_rounds(lat, oc, val)
    f2, _, p2 = run_rounds(lat, oc, val)
    for a, b in zip(p1, p2):
        np.testing.assert_array_equal(a.nodes, b.nodes)
    assert f1.computed.sum() <= st.budget
    assert len(p1[0].nodes) == 25 and all(len(p.nodes) for p in p1)       # every round computes
    # each round's nodes are new, on its own stride, and make the refined cells' sub-lattices
    seen = set()
    for p in p1:
        keys = {tuple(n) for n in p.nodes}
        assert not keys & seen
        seen |= keys
        assert (p.nodes % lat.stride(p.round) == 0).all()


def test_error_bars_hold_and_the_rough_patch_is_recognised():
    lat = sweep_lattice.make_lattice({"x": {"from": 0.0, "to": 1.0, "points": 65},
                                      "y": {"from": 0.0, "to": 1.0, "points": 65}}, 9)
    oc, val, rough = synthetic(lat)
    f, st, plans = run_rounds(lat, oc, val)
    m = reconstruct.reconstruct(lat, f, st)
    rec = ~f.computed
    assert f.computed.sum() <= 0.25 * lat.size
    assert (m.outcome[rec] != oc[rec]).mean() < 0.01
    ok = rec & np.isfinite(val) & np.isfinite(m.values["t"][:, 0])
    err = np.abs(m.values["t"][:, 0] - val)
    # (the bars' coverage over the hold-out's draws: test_holdout_bars_hold_over_draws)
    # the noise patch is reported rough, not refined to the bottom; the smooth part is not rough
    assert m.rough[ok & rough].mean() > 0.9 and m.rough[ok & ~rough].mean() < 0.05
    assert plans[-1].rough > 0
    # (refined to the bottom, round 3 would compute 3/4 of the patch; only its rim is: shared edges)
    assert (f.round[rough] == lat.rounds).mean() < 0.15
    # where it is smooth the map is far better than the tolerance asks, and computed nodes carry no bar
    assert np.median(err[ok & ~rough] / val[ok & ~rough]) < st.tolerance
    assert (m.bars["t"][f.computed & np.isfinite(val), 0] == 0).all()


def test_nodes_go_where_the_map_changes_and_bars_hold():
    # a gentle background with one bump: the rounds spend their nodes on the bump
    lat = lattice()
    x, y = xy(lat)
    bump = np.exp(-60 * ((x - 0.3) ** 2 + (y - 0.6) ** 2))
    val = np.exp(0.5 + 0.3 * x + 0.2 * y ** 2 + 1.5 * bump)
    f, st, _ = run_rounds(lat, np.zeros(lat.size, int), val)
    near = bump > 1e-3          # r < 0.34: the bump and its flanks
    assert f.computed[near].mean() > 3 * f.computed[~near].mean()
    m = reconstruct.reconstruct(lat, f, st)
    rec = ~f.computed
    err = np.abs(m.values["t"][:, 0] - val)
    assert (err[rec] <= m.bars["t"][rec, 0]).mean() >= 0.9
    assert np.median(err[rec & ~near] / val[rec & ~near]) < st.tolerance


def test_failed_corners_and_outcome_boundaries_are_refined_first():
    lat = lattice(17, 3)
    x, y = xy(lat)
    oc = np.where(x > 0.55, outcomes.CONTACT_LOST, outcomes.HALTED)
    oc[(x == 0.0) & (y == 0.5)] = outcomes.NUMERICAL_ERROR        # a node of round 0, in two cells
    val = np.where(oc == outcomes.HALTED, 1.0 + x, np.nan)       # linear: no error to refine for
    f, st, plans = run_rounds(lat, oc, val, share=1.0)
    assert plans[1].flagged["failed"] == 2 and plans[1].flagged["error"] == 0
    # the finest round computes only around the boundary (x = 0.5 .. 0.5625) and the failed node
    last = plans[-1].nodes * (1.0 / 16)
    assert len(last) and all((0.4 <= n[0] <= 0.65) or (n[0] <= 0.125 and abs(n[1] - 0.5) <= 0.125) for n in last)
    m = reconstruct.reconstruct(lat, f, st)
    np.testing.assert_array_equal(m.outcome, oc)


def test_refine_config_errors_name_the_field():
    base = {"grid": {"mu_d": [0.3], "k1": [0.0], "k2": [0.0], "k3": [0.0]},
            "refine": {"axes": {"alpha0": {"from": 0.3, "to": 1.2, "points": 9},
                                "omega0": {"from": 5.0, "to": 50.0, "points": 9, "spacing": "log"}},
                       "start_points": 3, "max_share": 0.5}}
    settings = grid.normalize(base, check_scenes=False)
    assert settings["grid"]["omega0"][0] == 5.0 and settings["grid"]["omega0"][-1] == 50.0
    assert len(settings["grid"]["alpha0"]) == 9 and grid.is_adaptive(settings)

    def fields_of(mutate):
        import copy
        cfg = copy.deepcopy(base)
        mutate(cfg)
        with pytest.raises(validation.SweepConfigError) as exc:
            grid.normalize(cfg, check_scenes=False)
        return {e.field: str(e) for e in exc.value.errors}

    assert "refine.axes.alpha0.points" in fields_of(lambda c: c["refine"]["axes"]["alpha0"].update(points=10))
    assert "refine.axes.alpha0" in fields_of(lambda c: c["grid"].update(alpha0=[1.0]))
    assert "refine.axes.omega0.from" in fields_of(lambda c: c["refine"]["axes"]["omega0"].update({"from": -1.0}))
    assert "refine.axes.omega0.to" in fields_of(lambda c: c["refine"]["axes"]["omega0"].update(to=4.0))
    msg = fields_of(lambda c: c["refine"].update(max_share=0.05))["refine.max_share"]
    assert "round 0's 9" in msg
    assert "refine.start_points" in fields_of(lambda c: c["refine"].update(start_points=9))
    assert "refine.axes" in fields_of(lambda c: c["refine"]["axes"].pop("omega0") and c["grid"].update(omega0=[9.0]))
    assert "grid.alpha0" in fields_of(lambda c: c["refine"]["axes"].pop("alpha0") and c["refine"]["axes"].update(
        mu_d={"from": 0.1, "to": 0.3, "points": 5}) and c["grid"].pop("mu_d"))
    assert "exceeds mu_s" in fields_of(lambda c: c["refine"]["axes"].update(mu_d={"from": 0.1, "to": 0.7, "points": 5})
                                       or c["grid"].pop("mu_d"))["refine.axes.mu_d.to"]
    assert "refine.axes.alpha0" in fields_of(lambda c: c["refine"]["axes"]["alpha0"].update({"from": -0.5, "to": 0.5}))
    assert "refine.tolerance" in fields_of(lambda c: c["refine"].update(tolerance=0.0))
    assert "refine.outputs[0]" in fields_of(lambda c: c["refine"].update(outputs=["n_steps"]))
    tensor = {"grid": {a: [1.0] for a in axes.AXES}, "outputs": {"notebooks": ["adaptive_map"]}}
    with pytest.raises(validation.SweepConfigError, match="outputs.notebooks"):
        grid.normalize(tensor, check_scenes=False)


def test_an_adaptive_overlay_replaces_the_default_grids_axes(tmp_path):
    from pathlib import Path
    root = Path(__file__).resolve().parents[1]
    sweep = grid.load_sweep([(root / "config" / "config.yaml", "config/config.yaml"),
                             (root / "config" / "adaptive.yaml", "config/adaptive.yaml")], check_scenes=False)
    assert sweep.name == "adaptive" and len(sweep.settings["grid"]["alpha0"]) == 65
    assert sweep.settings["grid"]["mu_d"] == [0.3]
    # and a later grid list turns a lattice axis back into a list
    later = tmp_path / "later.yaml"
    later.write_text("grid:\n  alpha0: [1.0]\n  omega0: [10.0]\noutputs:\n  notebooks: [halt_time]\n")
    back = grid.load_sweep([(root / "config" / "adaptive.yaml", "a"), (later, "later")], check_scenes=False)
    assert not grid.is_adaptive(back.settings) and back.settings["grid"]["alpha0"] == [1.0]


def test_a_three_axis_map():
    lat = sweep_lattice.make_lattice({a: {"from": 0.0, "to": 1.0, "points": 17} for a in ("x", "y", "z")}, 5)
    assert lat.rounds == 2 and lat.ndim == 3 and len(lat.round0_nodes()) == 125
    g = np.array(np.unravel_index(np.arange(lat.size), lat.shape)).T / 16.0
    oc = np.where(g[:, 0] + g[:, 1] + g[:, 2] > 1.6, outcomes.CONTACT_LOST, outcomes.HALTED)
    val = np.where(oc == outcomes.HALTED, np.exp(1 + g[:, 0] * g[:, 1] + np.sin(2 * g[:, 2])), np.nan)
    f, st, plans = run_rounds(lat, oc, val, share=0.5)    # a boundary surface needs more than a curve
    assert f.computed.sum() <= st.budget and all(len(p.nodes) for p in plans)
    m = reconstruct.reconstruct(lat, f, st)
    rec = ~f.computed
    assert (m.outcome[rec] != oc[rec]).mean() < 0.01
    ok = rec & np.isfinite(val) & np.isfinite(m.values["t"][:, 0])
    assert (np.abs(m.values["t"][ok, 0] - val[ok]) <= m.bars["t"][ok, 0]).mean() >= 0.9


def test_bars_are_calibrated_on_the_maps_own_surpluses():
    # every node computed at a round >= 1 tests the interpolation of the cell it was refined
    # from; per class and bin of the indicator the factor is the conformal 90 % quantile of
    # |surplus| / indicator: exactly ceil(0.9 (n + 1)) of the bin's n tests lie within it
    lat = sweep_lattice.make_lattice({"x": {"from": 0.0, "to": 1.0, "points": 65},
                                      "y": {"from": 0.0, "to": 1.0, "points": 65}}, 9)
    oc, val, rough = synthetic(lat)
    f, st, _ = run_rounds(lat, oc, val)
    f = f.subset(~refine.holdout_mask(lat, f, st))          # what the surplus calibration sees
    sur = surplus.surpluses(lat, f, "t")
    cal = errorbars.bar_factors(lat, f, st, "t", sur, {"t": sur})
    nodes = np.array(np.unravel_index(np.arange(lat.size), lat.shape)).T
    r = sweep_lattice.node_round(lat, nodes)
    tests = {errorbars.SMOOTH: [], errorbars.ROUGH: [], errorbars.MIXED: []}
    for i in np.nonzero(f.computed & (r >= 1))[0]:
        j = r[i]
        low = sweep_lattice.cell_lower(lat, nodes[i:i + 1], lat.stride(j - 1))
        ind = errorbars.bar_indicator(lat, j - 1, low, sur)[0, 0]
        cls = errorbars.cell_class(lat, f, st, j - 1, low, f.transformed("t"), {"t": sur})[0, 0]
        if np.isfinite(sur[i, 0]) and ind > 0:
            tests[cls].append((ind, sur[i, 0] / ind))
    pooled = sum(tests.values(), [])
    checked = 0
    for cls, t in tests.items():
        t = np.array(t if len(t) >= errorbars.MIN_CALIBRATION else pooled)
        edges, factors = cal.edges[cls, 0], cal.factors[cls, 0]
        assert len(factors) == max(1, len(t) // errorbars.BIN_TESTS) == len(edges) + 1
        b = np.searchsorted(edges, np.log10(t[:, 0]))
        for k, fac in enumerate(factors):
            x = t[b == k, 1]
            assert len(x) >= errorbars.BIN_TESTS or len(factors) == 1
            assert (x <= fac).sum() == min(len(x), int(np.ceil(0.9 * (len(x) + 1))))
            checked += 1
        # below the tested range the bar does not shrink with the indicator
        lo = cal.lowest[cls, 0]
        cl = np.full((2, 1), cls)
        np.testing.assert_array_equal(cal.bar(cl, np.array([[lo / 10], [lo]])), cal.bar(cl, np.array([[lo], [lo]])))
    assert checked >= 3
    m = reconstruct._interpolate(lat, f, st)                      # the bars of the surpluses alone
    ok = ~f.computed & np.isfinite(val) & np.isfinite(m.values["t"][:, 0])
    err = np.abs(m.values["t"][:, 0] - val)
    bar = m.bars["t"][:, 0]
    # honest in the rough patch and outside it, not only over all
    assert (err <= bar)[ok & rough].mean() >= 0.85 and (err <= bar)[ok & ~rough].mean() >= 0.9


def test_rough_leaves_count_the_finished_maps_rough_cells():
    lat = sweep_lattice.make_lattice({"x": {"from": 0.0, "to": 1.0, "points": 65},
                                      "y": {"from": 0.0, "to": 1.0, "points": 65}}, 9)
    oc, val, rough = synthetic(lat)
    f, st, plans = run_rounds(lat, oc, val)
    n = refine.rough_leaves(lat, f, st)
    assert n > 0
    # without the rough patch there is none
    smooth = np.where(rough, np.exp(1.0 + 2.0 * xy(lat)[0] + np.sin(3.0 * xy(lat)[1])), val)
    f2, st2, _ = run_rounds(lat, oc, smooth)
    assert refine.rough_leaves(lat, f2, st2) == 0


def test_the_last_round_computes_a_deterministic_holdout_outside_the_cells(monkeypatch):
    lat = sweep_lattice.make_lattice({"x": {"from": 0.0, "to": 1.0, "points": 65},
                                      "y": {"from": 0.0, "to": 1.0, "points": 65}}, 9)
    oc, val, _ = synthetic(lat)
    f, st, plans = run_rounds(lat, oc, val)
    n_hold = refine.holdout_size(lat, st)
    assert n_hold == int(refine.HOLDOUT_SHARE * st.budget) >= refine.HOLDOUT_MIN
    assert all(len(p.holdout) == 0 for p in plans[:-1]) and len(plans[-1].holdout) == n_hold
    assert f.computed.sum() <= st.budget
    hold = refine.holdout_mask(lat, f, st)                   # planned again: the same nodes
    np.testing.assert_array_equal(np.nonzero(hold)[0], sweep_lattice.flat_index(lat, plans[-1].holdout))
    assert (f.round[hold] == lat.rounds).all()
    # a map whose hold-out another draw made (another seed, another numpy) keeps its own: the
    # last round's nodes that the plan does not refine with
    with monkeypatch.context() as mp:
        mp.setattr(refine, "HOLDOUT_SEED", refine.HOLDOUT_SEED + 1)
        assert not np.array_equal(sweep_lattice.flat_index(lat, refine.plan_round(lat, f.subset(f.round < lat.rounds), st,
                                                                                  lat.rounds).holdout), np.nonzero(hold)[0])
        np.testing.assert_array_equal(refine.holdout_mask(lat, f, st), hold)
    # the hold-out is not part of the map's cells: they are those of the refinement alone
    known = f.subset(~hold)
    refined = set(map(tuple, plans[-1].nodes)) - set(map(tuple, plans[-1].holdout))
    only = f.subset(f.round < lat.rounds)
    only.set(lat, np.array(sorted(refined)), lat.rounds, oc[sweep_lattice.flat_index(lat, np.array(sorted(refined)))],
             {"t": val[sweep_lattice.flat_index(lat, np.array(sorted(refined)))]})
    for k, low in sweep_lattice.cells(lat, only.computed).items():
        np.testing.assert_array_equal(sweep_lattice.cells(lat, known.computed)[k], low)
    # the hold-out is a sample of the nodes the map reconstructs (no computed node, spread over it)
    nodes = plans[-1].holdout
    assert len({tuple(n) for n in nodes}) == n_hold and not only.computed[sweep_lattice.flat_index(lat, nodes)].any()
    assert (nodes[:, 0] < 32).mean() == pytest.approx(0.5, abs=0.15)
    # in the map the hold-out nodes are computed: their values, no bar
    m = reconstruct.reconstruct(lat, f, st)
    np.testing.assert_array_equal(m.holdout, hold)
    fin = hold & np.isfinite(val)
    np.testing.assert_array_equal(m.values["t"][fin, 0], val[fin])
    assert (m.bars["t"][fin, 0] == 0).all() and not m.rough[hold].any()
    # a small map (HOLDOUT_SHARE of its budget below HOLDOUT_MIN) has none: its bars are the surpluses'
    small = sweep_lattice.Settings(("t",), 0.01, int(refine.HOLDOUT_MIN / refine.HOLDOUT_SHARE) - 1)
    assert refine.holdout_size(lat, small) == 0 and not refine.holdout_mask(lat, f, small).any()


def test_holdout_bars_are_the_conformal_quantile_of_its_tests_per_bin():
    lat = sweep_lattice.make_lattice({"x": {"from": 0.0, "to": 1.0, "points": 65},
                                      "y": {"from": 0.0, "to": 1.0, "points": 65}}, 9)
    oc, val, rough = synthetic(lat)
    f, st, _ = run_rounds(lat, oc, val)
    hold = refine.holdout_mask(lat, f, st)
    known = f.subset(~hold)
    m0 = reconstruct._interpolate(lat, known, st)                 # the surpluses' bars, the hold-out reconstructed
    m = reconstruct.reconstruct(lat, f, st)
    est = m0.values["t"][:, 0]
    err = np.abs(np.log(val) - np.log(est))
    scale = np.where(np.isfinite(m0.scale["t"][:, 0]), m0.scale["t"][:, 0], np.inf)
    pop = (m0.cell_level >= 0) & np.isfinite(est)
    cut = np.quantile(scale[pop], reconstruct.QUIET_SHARE, method="inverted_cdf")
    target = pop & ~hold
    for loud in (False, True):
        in_bin = (scale > cut) if loud else (scale <= cut)
        tests = np.sort(err[hold & in_bin & np.isfinite(err)])
        assert len(tests) >= errorbars.MIN_CALIBRATION
        k = int(np.ceil(0.9 * (len(tests) + 1)))
        q = tests[k - 1]                                       # exactly k of the bin's tests within q
        assert (tests <= q).sum() == k
        bar = est[target & in_bin] * np.expm1(q)
        got = m.bars["t"][target & in_bin, 0]
        if loud:   # not below the surpluses' bar
            np.testing.assert_allclose(got, np.fmax(bar, m0.bars["t"][target & in_bin, 0]))
        else:
            np.testing.assert_allclose(got, bar)
    # the quiet nodes are the smooth part, and their bars are far tighter than the surpluses' (which
    # test only the cells the map chose to refine, the hard ones)
    quiet = target & (scale <= cut)
    assert rough[quiet].mean() < 0.05
    assert np.median(m.bars["t"][quiet, 0] / est[quiet]) < 0.5 * np.median(m0.bars["t"][quiet, 0] / est[quiet])


def test_holdout_bars_hold_over_draws(monkeypatch):
    # split-conformal: over the draws of the hold-out the bars hold at >= 90 % of the reconstructed
    # nodes on average (one draw scatters by a few %), in the rough patch and outside it
    lat = sweep_lattice.make_lattice({"x": {"from": 0.0, "to": 1.0, "points": 65},
                                      "y": {"from": 0.0, "to": 1.0, "points": 65}}, 9)
    oc, val, rough = synthetic(lat)
    cover, cover_rough, med = [], [], []
    for seed in range(8):
        monkeypatch.setattr(refine, "HOLDOUT_SEED", seed)
        f, st, _ = run_rounds(lat, oc, val)
        m = reconstruct.reconstruct(lat, f, st)
        ok = ~f.computed & np.isfinite(val) & np.isfinite(m.values["t"][:, 0])
        holds = np.abs(m.values["t"][:, 0] - val) <= m.bars["t"][:, 0]
        cover.append(holds[ok].mean())
        cover_rough.append(holds[ok & rough].mean())
        med.append(np.median(m.bars["t"][ok, 0] / m.values["t"][ok, 0]))
    assert np.mean(cover) >= 0.9 and min(cover) >= 0.85
    assert np.mean(cover_rough) >= 0.9
    assert max(med) < 0.02          # the smooth majority's bars: ~0.4 %, not the noise patch's


def two_output_rounds(lat, seed=52, monkeypatch=None):
    """The synthetic map with a second, linear output `u` (not log) that has its own noise patch
    (x < 0.4, y > 0.2) and exists only where x > 0.1: rounds driven by `t` alone, so `t` is the
    headline whose scale stratifies the hold-out and `u` is calibrated with weights."""
    oc, val, rough = synthetic(lat)
    x, y = xy(lat)
    u_patch = (x < 0.4) & (y > 0.2)
    u = 3.0 * x - 2.0 * y ** 2 + np.where(u_patch, 0.2 * np.random.default_rng(7).standard_normal(lat.size), 0.0)
    u = np.where((oc == outcomes.HALTED) & (x > 0.1), u, np.nan)
    f = sweep_lattice.Fields.empty(lat, {"t": 1, "u": 1}, {"t": True, "u": False})
    st = sweep_lattice.Settings(("t",), 0.01, int(0.25 * lat.size))
    plans = []
    for k in range(lat.rounds + 1):
        p = refine.plan_round(lat, f, st, k)
        idx = sweep_lattice.flat_index(lat, p.nodes)
        f.set(lat, p.nodes, k, oc[idx], {"t": val[idx], "u": u[idx]})
        plans.append(p)
    return f, st, plans, oc, val, u, rough, u_patch


def test_the_holdout_strata_are_the_finished_maps_quiet_and_loud_nodes():
    # the strata drawn from before the last round's values exist are the split the finished map
    # makes of its reconstructed nodes by the headline's error scale
    lat = sweep_lattice.make_lattice({"x": {"from": 0.0, "to": 1.0, "points": 65},
                                      "y": {"from": 0.0, "to": 1.0, "points": 65}}, 9)
    f, st, plans, *_ = two_output_rounds(lat)
    strata = plans[-1].strata
    hold, again = refine.holdout_design(lat, f, st)
    np.testing.assert_array_equal(again, strata)
    m0 = reconstruct._interpolate(lat, f.subset(~hold), st)
    cand = m0.cell_level >= 0                                     # reconstructed, the hold-out included
    np.testing.assert_array_equal(np.nonzero(strata >= 0)[0], np.nonzero(cand)[0])
    has = cand & np.isfinite(m0.values["t"][:, 0])
    sc = m0.scale["t"][:, 0]
    cut = np.quantile(sc[has], refine.QUIET_SHARE, method="inverted_cdf")
    np.testing.assert_array_equal(strata[has], np.where(sc[has] <= cut, refine.STRATUM_QUIET, refine.STRATUM_LOUD))
    assert (strata[cand & ~has] == refine.STRATUM_NONE).all()
    # the scale is the indicator plus a quarter of the corners' spread
    np.testing.assert_allclose(interpolation.error_scale(np.array([0.4, np.nan, 1.0]), np.array([0.1, 0.2, np.nan])),
                               [0.1 + 0.25 * 0.4, 0.2, 0.25])
    assert np.isnan(interpolation.error_scale(np.array([np.nan]), np.array([np.nan]))[0])


def test_the_holdout_is_a_stratified_sample_and_its_weights_undo_it():
    lat = sweep_lattice.make_lattice({"x": {"from": 0.0, "to": 1.0, "points": 65},
                                      "y": {"from": 0.0, "to": 1.0, "points": 65}}, 9)
    f, st, plans, *_ = two_output_rounds(lat)
    strata, hold = plans[-1].strata, np.zeros(lat.size, bool)
    hold[sweep_lattice.flat_index(lat, plans[-1].holdout)] = True
    n = refine.holdout_size(lat, st)
    assert hold.sum() == n and (strata[hold] >= 0).all()
    size = {s: (strata == s).sum() for s in (refine.STRATUM_NONE, refine.STRATUM_QUIET, refine.STRATUM_LOUD)}
    got = {s: (hold & (strata == s)).sum() for s in size}
    assert min(size.values()) > 0
    # the stratum without a value in proportion to its size, 3/4 of the rest quiet
    assert got[refine.STRATUM_NONE] == round(n * size[refine.STRATUM_NONE] / sum(size.values()))
    rest = n - got[refine.STRATUM_NONE]
    assert got[refine.STRATUM_QUIET] == round(refine.QUIET_TESTS * rest)
    assert got[refine.STRATUM_LOUD] == rest - got[refine.STRATUM_QUIET]
    # far from the strata's own shares: quiet is 55 % of the nodes with a value
    assert size[refine.STRATUM_QUIET] / (size[refine.STRATUM_QUIET] + size[refine.STRATUM_LOUD]) == pytest.approx(
        refine.QUIET_SHARE, abs=0.01)
    w = refine.inclusion_weights(strata, hold)
    for s in size:
        np.testing.assert_allclose(w[hold & (strata == s)], size[s] / got[s])
    assert np.isnan(w[~hold]).all()
    # the weights undo the sampling: the weighted share of quiet tests is the stratum's share
    assert w[hold & (strata == refine.STRATUM_QUIET)].sum() == pytest.approx(size[refine.STRATUM_QUIET])


def test_the_weighted_conformal_quantile():
    # equal weights: the split-conformal rank ceil(0.9 (n + 1))
    for n in (9, 10, 19, 20, 57, 100):
        x = np.random.default_rng(n).permutation(np.arange(1.0, n + 1))
        k = int(np.ceil(0.9 * (n + 1)))
        assert errorbars.conformal_quantile(x) == errorbars.conformal_quantile(x, np.full(n, 2.5)) == k
    # 30 values 1..30, the last 10 standing for 2 nodes each: total 40, plus the largest weight 2;
    # 0.9 x 42 = 37.8 is first reached after 20 + 2 x 9 = 38, at 29 (the unweighted rank: 28)
    x = np.arange(1.0, 31.0)
    w = np.where(x > 20, 2.0, 1.0)
    assert errorbars.conformal_quantile(x[::-1], w[::-1]) == 29.0 and errorbars.conformal_quantile(x) == 28.0
    # never reached: the largest
    assert errorbars.conformal_quantile(np.array([1.0, 2.0, 3.0, 4.0]), np.array([1.0, 1.0, 1.0, 7.0])) == 4.0
    assert errorbars.MIN_CONFORMAL == 9 and errorbars.conformal_quantile(np.arange(1.0, 10.0)) == 9.0


def test_every_outputs_bars_hold_over_draws(monkeypatch):
    # the headline `t` is calibrated per stratum, `u` (linear, its own noise patch, a value on
    # part of the map) per bin of its own scale with the strata's weights: over draws each holds
    # at >= 90 % on average in each of its bins (what split-conformal promises: coverage over the
    # nodes of a bin, not over any region one picks afterwards)
    lat = sweep_lattice.make_lattice({"x": {"from": 0.0, "to": 1.0, "points": 65},
                                      "y": {"from": 0.0, "to": 1.0, "points": 65}}, 9)
    cover = {}
    for seed in range(32):
        monkeypatch.setattr(refine, "HOLDOUT_SEED", seed)
        f, st, plans, oc, val, u, rough, u_patch = two_output_rounds(lat)
        m = reconstruct.reconstruct(lat, f, st)
        m0 = reconstruct._interpolate(lat, f.subset(~m.holdout), st)
        for name, truth in (("t", val), ("u", u)):
            ok = ~f.computed & np.isfinite(truth) & np.isfinite(m.values[name][:, 0])
            holds = np.abs(m.values[name][:, 0] - truth) <= m.bars[name][:, 0]
            if name == "t":
                quiet = plans[-1].strata == refine.STRATUM_QUIET
            else:
                pop = (m0.cell_level >= 0) & np.isfinite(m0.values["u"][:, 0])
                sc = m0.scale["u"][:, 0]
                quiet = pop & (sc <= np.quantile(sc[pop], refine.QUIET_SHARE, method="inverted_cdf"))
            for label, sel in (("all", ok), ("quiet", ok & quiet), ("loud", ok & ~quiet)):
                cover.setdefault(f"{name} {label}", []).append(holds[sel].mean())
    for key, c in cover.items():
        assert np.mean(c) >= 0.9, (key, np.mean(c))
        assert min(c) >= 0.75, (key, min(c))


def test_an_output_with_few_tests_gets_one_bin():
    # an output with a value on a small part of the map has too few hold-out tests to split into
    # quiet and loud: one bin, its bar the conformal quantile of all its tests (at least the
    # surpluses' bar), if it has MIN_CONFORMAL of them
    lat = sweep_lattice.make_lattice({"x": {"from": 0.0, "to": 1.0, "points": 65},
                                      "y": {"from": 0.0, "to": 1.0, "points": 65}}, 9)
    f, st, _, oc, val, u, *_ = two_output_rounds(lat)
    x, _ = xy(lat)
    f.values["u"] = np.where((x > 0.8)[:, None], f.values["u"], np.nan)
    hold, _ = refine.holdout_design(lat, f, st)
    known = f.subset(~hold)
    m0 = reconstruct._interpolate(lat, known, st)
    m = reconstruct.reconstruct(lat, f, st)
    err = np.abs(f.values["u"][hold, 0] - m0.values["u"][hold, 0])
    tests = err[np.isfinite(err)]
    assert errorbars.MIN_CONFORMAL <= len(tests) < 2 * errorbars.MIN_CALIBRATION
    sel = (m.cell_level >= 0) & np.isfinite(m.values["u"][:, 0])
    assert sel.sum() > 50
    q = errorbars.conformal_quantile(tests, refine.inclusion_weights(refine.holdout_design(lat, f, st)[1], hold)[hold][np.isfinite(err)])
    np.testing.assert_allclose(m.bars["u"][sel, 0], np.fmax(q, m0.bars["u"][sel, 0]))
