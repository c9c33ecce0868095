"""The stepper of slow slides (core.extrapolation): its dense output's form, its order, its stiff
stability, and the paper's disk at mu_d = mu_s stepped by it against DOP853 (docs/model.md, 'Slow
slip')."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import yaml
from numba import njit

import sweep
from sweep.core import dop853, extrapolation as X, layout as L, model as M

ROOT = Path(__file__).resolve().parents[1]


def _paper_edge(**solver):
    cfg = yaml.safe_load((ROOT / "config/scenes/kessler2002.yaml").read_text())
    cfg["contact"]["mu_d"] = cfg["contact"]["mu_s"]
    cfg["solver"] = solver
    return cfg


def test_the_dense_output_coefficients_give_the_quintic_hermite_interpolant():
    """HERMITE5 maps a step's Hermite data (y1 - y0, h f0, ym - y0, h fm, h f1) to coefficients that
    dop853's continuous extension (dense_component, which every search reads) evaluates as the
    quintic through them: a random quintic comes back to round-off."""
    rng = np.random.default_rng(3)
    c = rng.normal(size=6)
    h, t0 = 0.37, 2.0
    y = lambda t: np.polyval(c, (t - t0) / h)                            # noqa: E731
    dy = lambda t: np.polyval(np.polyder(c), (t - t0) / h) / h           # noqa: E731
    data = np.array([y(t0 + h) - y(t0), h * dy(t0), y(t0 + 0.5 * h) - y(t0), h * dy(t0 + 0.5 * h), h * dy(t0 + h)])
    F = np.zeros((2 * dop853.N_DENSE, M.N_FULL))
    F[:5, 0] = X.HERMITE5 @ data
    y0 = np.zeros(M.N_FULL)
    y0[0] = y(t0)
    span = L.Span(F, 0, y0, t0, h, None)
    for x in np.linspace(0.0, 1.0, 13):
        assert abs(dop853.dense_component(span, t0 + x * h, 0) - y(t0 + x * h)) < 1e-13 * (1 + abs(y(t0 + x * h)))


@njit
def _linear(t, y, sys, dy, aux):
    """y0' = lam y0, y1' = lam y1 (lam = p[0]), and y2' = y0, a quadrature (no Jacobian column)."""
    lam = sys.p[0]
    dy[0] = lam * y[0]
    dy[1] = lam * y[1]
    dy[2] = y[0]
    aux[0] = 0.0


def _linear_step(lam, h):
    """One extrapolation step (the kernel's lie_step) of _linear from (1, 0.5, 0) over h."""
    p = np.zeros(M.N_PARAMS)
    p[0] = lam
    system = L.System(p, np.zeros(L.N_CS), 3, np.zeros((L.N_WORK, L.N_WCOLS)), np.zeros(L.N_ISTATS, np.int64))
    y, f, aux = np.zeros(M.N_FULL), np.zeros(M.N_FULL), np.zeros(M.N_AUX)
    y[:2] = 1.0, 0.5
    _linear(0.0, y, system, f, aux)
    end = L.Point(np.zeros(M.N_FULL), np.zeros(M.N_FULL), np.zeros(M.N_AUX))
    at = (0.0, h, np.ones(M.N_FULL), X.N_COLUMNS, 3)    # (all eight columns: no early stop)
    X.lie_step(_linear, at, (L.Point(y, f, aux), end), system, np.zeros((L.N_KROWS, M.N_FULL)), (2, 0, 1))
    return end.y[:3]


def test_the_extrapolation_is_of_high_order_and_damps_a_stiff_mode():
    """lie_step on y' = lam y with its Jacobian over the two leading components (the third a
    quadrature): for lam = -1 the local error falls faster than h^8 when h halves from 0.4 to 0.2
    (order 8 gives h^9 asymptotically; measured 1.0e-10 -> 6.1e-13, a factor 171 = 2^7.4; at
    shorter steps it meets the extrapolation's round-off, ~3e3 ulps of the increment), in the
    quadrature too; for lam = -1e4 over h = 1 (h lam = -1e4, where every explicit method diverges)
    the step damps the mode as the flow does, and the quadrature takes its integral, 1e-4."""
    e = [abs(_linear_step(-1.0, h) - np.array([1.0, 0.5, 1.0 - 1.0]) * math.exp(-h)
             - np.array([0.0, 0.0, 1.0 - math.exp(-h)])) for h in (0.4, 0.2)]
    assert np.all(e[0] / e[1] > 2.0 ** 7), e
    stiff = _linear_step(-1e4, 1.0)
    assert abs(stiff[0]) < 1e-6 and abs(stiff[1]) < 1e-6, stiff
    assert abs(stiff[2] - 1e-4) < 1e-9, stiff


def test_the_slides_of_the_paper_disk_at_the_edge_of_the_cone_take_longer_steps_to_the_same_motion():
    """The paper's disk at mu_d = mu_s to its 0.01 rad level: stepped by the extrapolation where a
    slide's step spans a relaxation time of its direction (the default, stiff_ratio 1) and by DOP853
    everywhere (0), the same transitions and stick phases and level times within 1e-11 relative
    (measured 2e-13 and 1.2e-12, the integration's error at rtol 1e-10), in fewer than 40 % of the
    steps (measured 30 394 against 111 904): the slow slides are stepped at ~5 relaxation times
    instead of DOP853's ~1.5."""
    got = {}
    for ratio in (1.0, 0.0):
        cfg = _paper_edge(stiff_ratio=ratio)
        cfg["stop"] = {"levels": [0.1, 0.01], "t_max": 120.0}
        got[ratio] = sweep.simulate(cfg).summary
    s1, s0 = got[1.0], got[0.0]
    assert s1["outcome"] == s0["outcome"]
    assert (s1["n_transitions"], s1["n_stick"]) == (s0["n_transitions"], s0["n_stick"])
    for a, b in zip(s1["levels"], s0["levels"]):
        assert abs(a["t"] - b["t"]) < 1e-11 * b["t"], (a["t"], b["t"])
    assert s1["n_steps"] < 0.4 * s0["n_steps"], (s1["n_steps"], s0["n_steps"])
