"""The batch path (sweep.simulate_batch): the same summaries as sweep.simulate, on CPU threads."""
from __future__ import annotations

import math

import numpy as np
import pytest

import sweep
from sweep import diagnostics
from sweep.core import ensemble as core_ensemble
from sweep.ensemble import summaries_equal

from conftest import make_scene

LEVELS = [0.1, 0.03, 0.01, 0.003]
# scenes of ~0.5-1.5 s each that take the kernel through its three kinds of contact history
SCENES = {
    # mu_s = 100: the friction cone always holds the contact, the disk rolls until it lies flat
    "rolling": dict(contact__mu_s=100.0, stop__levels=LEVELS),
    # the paper's disk: rolling <-> sliding transitions
    "roll_slip": dict(stop__levels=LEVELS),
    # the thin shell: moment components stick (Filippov) and are released
    "sticking": dict(disk__shape="shell", stop__levels=LEVELS),
}


@pytest.fixture(scope="module")
def reference():
    """sweep.simulate summaries of SCENES."""
    return {k: sweep.simulate(make_scene(**v)).summary for k, v in SCENES.items()}


def test_scenes_cover_rolling_slip_and_sticking(reference):
    r = reference
    assert r["rolling"]["n_transitions"] == 0 and r["rolling"]["slip_fraction"] == 0.0
    assert r["roll_slip"]["n_transitions"] > 2 and 0.0 < r["roll_slip"]["slip_fraction"] < 1.0
    assert r["sticking"]["n_stick"] > 10
    for s in r.values():
        assert s["outcome"] == "halted" and s["halt_finite"]


@pytest.mark.slow
@pytest.mark.parametrize("workers", [1, 2])
def test_cpu_batch_equals_simulate(reference, workers):
    stats = {}
    got = sweep.simulate_batch([make_scene(**v) for v in SCENES.values()], device="cpu", workers=workers,
                               stats=stats)
    assert stats["reruns"] == 0 and stats["workers"] == workers
    for (name, ref), s in zip(reference.items(), got):
        assert summaries_equal(ref, s, rtol=1e-9) == [], name
        assert s["wall_time"] > 0.0


def test_summaries_equal_reports_every_value_beyond_rtol_and_ignores_wall_time():
    """The comparison the tests above rely on: a difference it did not report would pass them."""
    a = {"outcome": "halted", "t_halt": 19.3836, "n_steps": 1000, "levels": [{"t": 15.0902}], "wall_time": 1.0}
    assert summaries_equal(a, dict(a, wall_time=2.0)) == []
    b = dict(a, t_halt=19.3836 * (1 + 1e-8), levels=[{"t": 15.0902}])
    assert summaries_equal(a, b, rtol=1e-6) == []
    assert summaries_equal(a, b, rtol=1e-9) == ["t_halt: 19.3836 != 19.383600193836"]
    assert summaries_equal(a, dict(a, n_steps=1001)) == ["n_steps: 1000 != 1001"]
    assert summaries_equal(a, dict(a, outcome="t_max")) == ["outcome: 'halted' != 't_max'"]
    assert summaries_equal(a, dict(a, levels=[{"t": 15.1}])) == ["levels[0].t: 15.0902 != 15.1"]


def test_bad_device_and_workers_are_rejected():
    with pytest.raises(sweep.ConfigError, match="device"):
        sweep.simulate_batch([{}], device="tpu")
    # the GPU path was removed: asking for it says so, before any scene is validated or run
    with pytest.raises(sweep.ConfigError, match=r"device = 'cuda' is invalid: allowed 'cpu' \(the GPU path"):
        sweep.simulate_batch([{"disk": {"radius": -1}}], device="cuda")
    assert sweep.simulate_batch([], device="cpu") == []
    with pytest.raises(sweep.ConfigError, match="workers"):
        sweep.simulate_batch([{}], workers=0)
    with pytest.raises(sweep.ConfigError, match="contact.mu_d"):
        sweep.simulate_batch([make_scene(contact__mu_d=0.9)])


def test_empty_batch():
    assert sweep.simulate_batch([]) == []


def test_more_levels_than_the_batch_buffers_fall_back_to_simulate():
    levels = list(np.geomspace(0.3, 0.05, core_ensemble.MAX_LEVELS + 1))
    cfg = make_scene(stop__levels=levels, stop__max_steps=400)
    stats = {}
    [s] = sweep.simulate_batch([cfg], stats=stats)
    assert stats["reruns"] == 1 and stats["batch"] == 0
    assert summaries_equal(sweep.simulate(cfg).summary, s) == []


def test_halt_fit_kernel_matches_closed_forms():
    # beta = c (T - t)^p with T = 10, p = 2, c = 1e-3: the fit on any three levels is exact
    T, p, c = 10.0, 2.0, 1e-3
    levels = np.array([1e-1, 1e-2, 1e-3, 1e-4])
    t = T - (levels / c) ** (1.0 / p)
    fit = diagnostics.halt_time(t, levels)
    assert fit["halt_finite"]
    assert math.isclose(fit["t_halt"], T, rel_tol=1e-12)
    assert math.isclose(fit["approach_exponent"], p, rel_tol=1e-9)
    # its error bar is the extrapolated remainder t_halt - t_last (diagnostics module docstring)
    assert math.isclose(fit["t_halt_error"], T - t[-1], rel_tol=1e-9)
    # Omega = 3 (T - t)^-1.5 exactly: the ramp exponent is 1.5
    om = 3.0 * (T - t) ** -1.5
    assert math.isclose(diagnostics.ramp_exponent(t, om, T), 1.5, rel_tol=1e-12)
    # gaps that do not shrink: no finite halt
    assert not diagnostics.halt_time(np.array([1.0, 2.0, 3.0]), levels[:3])["halt_finite"]
