"""The core's kernels called one by one (src/sweep/core): step, error norm, dense output, event
location, interior dips, Phi maxima, slaved slip directions. Each against an independent evaluation.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from sweep import outcomes as oc
from sweep.core import constants as CN
from sweep.core import contact_rhs as CR
from sweep.core import dop853 as D
from sweep.core import event_dispatch as ED
from sweep.core import event_ids as ID
from sweep.core import event_rules as ER
from sweep.core import events as EV
from sweep.core import integrate as I
from sweep.core import layout as L
from sweep.core import model as M
from sweep.core import moments as MO
from sweep.core import roots as R
from sweep.core import slip as SL
from sweep.core import tableau as T
from sweep.scene import load_scene


@pytest.fixture(scope="module")
def setup():
    sc = load_scene("config/scenes/kessler2002.yaml")
    p = sc.params.copy()
    p[M.P_UTOL] = 1e-9 * sc.chi / 0.03755
    y = np.zeros(M.N_FULL)
    y[M.Y_ALPHA] = 1.0
    y[M.Y_W1] = 0.05
    y[M.Y_W2] = -0.1
    y[M.Y_W3] = -1.0
    cs = np.zeros(L.N_CS)
    cs[L.CS_SIDE] = 1.0
    cs[L.CS_SIG:L.CS_SIG + 3] = [1.0, -1.0, 1.0]
    return p, y, cs


def _sys(p, cs, n, wk, ist):
    return L.System(p, cs, n, wk, ist)


def _work():
    return np.zeros((L.N_WORK, L.N_WCOLS)), np.zeros(L.N_ISTATS, np.int64)


def _ev_sys(p, cs):
    """The system an event function reads (its parameters and contact state), with fresh buffers."""
    wk, ist = _work()
    return _sys(p, cs, M.N_CORE, wk, ist)


def _consts(rtol=1e-10, atol=1e-12, t_max=100.0, max_steps=10**9, e0=1.0, n=M.N_CORE):
    """The run's constants (layout.RunConsts) with the given values, no levels, no samples."""
    return L.RunConsts(n, rtol, atol, math.inf, t_max, max_steps, False, e0, np.zeros(0), np.zeros(0))


def _step(t, y, f, h, sys, K, y_new, f_new=None):
    """dop853.rk_step with the contact right-hand side from (t, y, f) over h into y_new (its
    derivative into f_new if given), in the system sys (layout.System)."""
    f_new = np.zeros(M.N_FULL) if f_new is None else f_new
    D.rk_step(CR.eval_rhs, t, h, (L.Point(y, f, np.zeros(M.N_AUX)), L.Point(y_new, f_new, np.zeros(M.N_AUX))), sys,
              K)


def _f(t, y, p, cs, n=M.N_CORE):
    dy = np.zeros(M.N_FULL)
    aux = np.zeros(M.N_AUX)
    contact = M.Contact(CN.ROLL, int(cs[L.CS_SIDE]), cs[L.CS_SIG:L.CS_SIG + 3], cs[L.CS_STUCK:L.CS_STUCK + 3], 1.0, 0.0)
    M.rhs(y, p, contact, n, dy, aux)
    return dy[:n].copy(), aux


def test_rk_step_is_the_tableau_applied_to_the_model(setup):
    p, y, cs = setup
    n, h = M.N_CORE, 0.05
    wk, ist = _work()
    K = np.zeros((T.N_STAGES_EXTENDED, M.N_FULL))
    f = np.zeros(M.N_FULL)
    f[:n] = _f(0.0, y, p, cs)[0]
    y_new = np.zeros(M.N_FULL)
    _step(0.0, y, f, h, _sys(p, cs, n, wk, ist), K, y_new)
    # plain numpy DOP853 with the published tableau
    k = np.zeros((T.N_STAGES, n))
    for s in range(T.N_STAGES):
        ys = y.copy()
        ys[:n] = y[:n] + h * (T.A[s, :s] @ k[:s])
        k[s] = _f(T.C[s] * h, ys, p, cs)[0]
    ref = y[:n] + h * (T.B[:T.N_STAGES] @ k)
    assert np.max(np.abs(y_new[:n] - ref)) < 1e-15
    assert ist[L.I_RHS] == T.N_STAGES      # 11 stages + f(t + h, y_new); stage 0 is the given f


@pytest.mark.parametrize("side", [1.0, -1.0], ids=["own_rim", "past_the_edge"])
def test_energy_balance_residual_is_the_local_error_of_the_step(setup, side):
    """The step's energy-balance residual Delta(E + dissipated) is zero for the exact flow, so it
    is the 8th-order step's own local error in that direction: halving h divides it by at least
    ~2^9 (a model whose energy did not match its right-hand side would give a residual ~ h). Also with the contact kept on the rim past alpha = 0 (side -1 at
    alpha 1), which a step overshooting the rim-edge event integrates."""
    from sweep.core import accept as A
    p, y, cs0 = setup
    cs = cs0.copy()
    cs[L.CS_SIDE] = side
    n = M.N_CORE
    g = _f(0.0, y, p, cs)[1][M.X_G1:M.X_G3 + 1]
    cs[L.CS_SIG:L.CS_SIG + 3] = np.sign(g)       # consistent signs: the moments dissipate
    res = []
    for h in (0.6, 0.3, 0.4, 0.2):
        wk, ist = _work()
        K = np.zeros((T.N_STAGES_EXTENDED, M.N_FULL))
        f = np.zeros(M.N_FULL)
        aux = np.zeros(M.N_AUX)
        CR.eval_rhs(0.0, y, _sys(p, cs, n, wk, ist), f, aux)
        y_new = np.zeros(M.N_FULL)
        _step(0.0, y, f, h, _sys(p, cs, n, wk, ist), K, y_new)
        e_cur, e_new = CR.mode_energy(y, p, cs), CR.mode_energy(y_new, p, cs)
        delta = wk[L.W_DELTA, :n]
        assert np.array_equal(y_new[:n], y[:n] + delta)      # the increment the step added
        assert np.sum(y_new[M.Y_DSLIDE:M.Y_DK3 + 1]) > 1e-6 * e_cur        # it dissipates
        res.append(abs((e_new + np.sum(y_new[M.Y_DSLIDE:M.Y_DK3 + 1])) - e_cur))
        # the residual from the increment in difference form is the same to round-off
        change, _ = M.energy_increment(y, wk[L.W_DELTA], p, side, False)
        inc_res = abs(change + np.sum(delta[M.Y_DSLIDE:M.Y_DK3 + 1]))
        assert abs(inc_res - res[-1]) < 1e-15 * e_cur, (inc_res, res[-1])
        # balance_error is that residual over its allowance, which grows with h and the dissipation
        ratio = A.balance_error(L.Point(y, f, aux), wk[L.W_DELTA], h, 0.0, _sys(p, cs, n, wk, ist),
                                _consts(1e-10, e0=e_cur, t_max=100.0))
        allowed = A.BALANCE_FACTOR * 1e-10 * (np.sum(delta[M.Y_DSLIDE:M.Y_DK3 + 1]) + e_cur * h / 100.0)
        assert inc_res / ratio >= allowed
    assert res[0] / res[1] > 256.0 and res[2] / res[3] > 256.0, res
    assert res[3] > 1e-14, res         # far above round-off (~1e-16)


@pytest.mark.parametrize("alpha", [0.02, 0.9, 1.5478, -1.5706])
def test_energy_increment_is_exact_to_the_round_off_of_the_change(setup, alpha):
    """model.energy_increment against E(y + d) - E(y) in extended precision: its error is within
    BALANCE_ROUNDOFF of its own scale (relative to the change), while the difference of two float64
    energies errs by ~EPS E, 10..10^4 times more (measured; the error that hid a step's truncation
    in the budget)."""
    from sweep.core import accept as A
    p, _, _ = setup
    ld = np.longdouble
    if np.finfo(ld).eps > 1e-18:
        pytest.skip("no extended precision on this platform")
    rng = np.random.default_rng(11)
    side = math.copysign(1.0, alpha)

    def energy(yv, slip):
        a = yv[M.Y_ALPHA]
        h = ld(side * p[M.P_H])
        c, s = np.cos(a), np.sin(a)
        e, f = c + h * s, h * c - s
        u1, u2 = (yv[M.Y_U1], yv[M.Y_U2]) if slip else (ld(0), ld(0))
        vx, vy, vz = u1 + yv[M.Y_W2] - h * yv[M.Y_W3], u2 - e * yv[M.Y_W1], f * yv[M.Y_W1]
        kin = (vx * vx + vy * vy + vz * vz) / 2 + ld(p[M.P_A]) * (yv[M.Y_W1] ** 2 + yv[M.Y_W3] ** 2) / 2 \
            + ld(p[M.P_C]) * yv[M.Y_W2] ** 2 / 2
        return kin + ld(p[M.P_G]) * (e - abs(h))

    for slip in (False, True):
        for step in (1e-2, 1e-5):
            y = np.zeros(M.N_FULL)
            y[M.Y_ALPHA] = alpha
            y[M.Y_W1:M.Y_W3 + 1] = rng.normal(size=3) * 0.3
            y[M.Y_U1:M.Y_U2 + 1] = rng.normal(size=2) * 0.01
            d = np.zeros(M.N_FULL)
            d[:M.Y_U2 + 1] = rng.normal(size=M.Y_U2 + 1) * step
            change, scale = M.energy_increment(y, d, p, side, slip)
            yl, dl = y.astype(ld), d.astype(ld)
            e_new, e_old = energy(yl + dl, slip), energy(yl, slip)
            exact = e_new - e_old
            ref_err = 4 * np.finfo(ld).eps * (abs(e_new) + abs(e_old))   # the reference's own round-off
            assert abs(ld(change) - exact) <= A.BALANCE_ROUNDOFF * scale + ref_err, (slip, step, change, exact)
            naive = M.energy_with_slip(y + d, p, side, *((y + d)[M.Y_U1:M.Y_U2 + 1] if slip else (0.0, 0.0))) \
                - M.energy_with_slip(y, p, side, *(y[M.Y_U1:M.Y_U2 + 1] if slip else (0.0, 0.0)))
            assert abs(ld(change) - exact) <= abs(ld(naive) - exact) + 4 * np.finfo(float).eps * scale + ref_err


@pytest.mark.parametrize("mode", [CN.ROLL, CN.SLIDE])
def test_energy_rate_is_the_gradient_of_the_energy_and_the_power_defect_is_round_off(setup, mode):
    """model.energy_rate(y, v) is dE/dtau along v: against a central difference of
    energy_with_slip along random v (the gradient written independently of the energy's own
    formula would differ at O(1)). Along the right-hand side it is minus the dissipated power, so
    integrate.power_defect is round-off of the power's terms, also near flat (beta = 1e-6), where
    the gyroscopic terms (tan(alpha) ~ 1e6) make those terms, and the defect, large against the
    dissipated power: balance_error's floor measures the defect instead of assuming it small."""
    from sweep.core import accept as A
    p, _, cs0 = setup
    rng = np.random.default_rng(5)
    slip = mode == CN.SLIDE
    defects_far, defects_flat = [], []
    for trial in range(200):
        beta = 1e-6 if trial % 4 == 0 else rng.uniform(0.05, 1.5)
        side = float(rng.choice([-1.0, 1.0]))
        y = np.zeros(M.N_FULL)
        y[M.Y_ALPHA] = side * (math.pi / 2 - beta)
        y[M.Y_W1:M.Y_W3 + 1] = rng.normal(size=3) * [0.3, 1.0, 0.3]
        if slip:
            y[M.Y_U1:M.Y_U2 + 1] = rng.normal(size=2) * 0.1
        v = rng.normal(size=M.N_FULL)
        step = 1e-4 * min(1.0, beta)      # O(step^2) truncation of the difference, its round-off below
        e_plus = M.energy_with_slip(y + step * v, p, side, *((y + step * v)[M.Y_U1:M.Y_U2 + 1] if slip else (0.0, 0.0)))
        e_minus = M.energy_with_slip(y - step * v, p, side, *((y - step * v)[M.Y_U1:M.Y_U2 + 1] if slip else (0.0, 0.0)))
        rate = M.energy_rate(y, v, p, side, slip)
        assert rate == pytest.approx((e_plus - e_minus) / (2 * step), rel=1e-6, abs=1e-14 * (1 + abs(e_plus)) / step)
        cs = cs0.copy()
        cs[L.CS_MODE] = mode
        cs[L.CS_SIDE] = side
        dy = np.zeros(M.N_FULL)
        aux = np.zeros(M.N_AUX)
        contact = M.Contact(mode, int(side), cs[L.CS_SIG:L.CS_SIG + 3], cs[L.CS_STUCK:L.CS_STUCK + 3], 1.0, 0.0)
        M.rhs(y, p, contact, M.N_CORE, dy, aux)
        if aux[M.X_OK] != 1.0:
            continue
        # the power's terms: the rates of the energy's parts and the dissipated powers
        terms = (abs(p[M.P_G] * dy[M.Y_ALPHA]) + np.sum(np.abs(dy[M.Y_DSLIDE:M.Y_DK3 + 1]))
                 + p[M.P_A] * (abs(y[M.Y_W1] * dy[M.Y_W1]) + abs(y[M.Y_W3] * dy[M.Y_W3]))
                 + p[M.P_C] * abs(y[M.Y_W2] * dy[M.Y_W2]) + np.sum(np.abs(dy[M.Y_W1:M.Y_U2 + 1])) ** 2)
        (defects_flat if beta == 1e-6 else defects_far).append(A.power_defect(y, dy, aux, p, cs) / terms)
    assert len(defects_far) > 100 and len(defects_flat) > 30
    assert max(defects_far) < 1e-12, max(defects_far)
    assert np.median(defects_far) < 1e-14
    assert max(defects_flat) < 1e-12


def test_energy_kernels_from_the_rhs_trig_are_the_plain_ones_to_the_bit(setup):
    """The step control and the events read sin/cos of alpha from the right-hand side's aux
    (X_SINA, X_COSA) instead of evaluating them again: aux holds math.sin/math.cos of y's alpha in
    every mode (SLAVED's last model call is at y), and energy_from_trig, mode_energy_at,
    energy_rate_trig and energy_increment_trig return exactly what energy_with_slip, mode_energy,
    energy_rate and energy_increment return, so trajectories do not change by a bit."""
    p, _, cs0 = setup
    rng = np.random.default_rng(11)
    wk, ist = _work()
    for trial in range(60):
        mode = (CN.ROLL, CN.SLIDE, CN.SLAVED)[trial % 3]
        y = np.zeros(M.N_FULL)
        side = float(rng.choice([-1.0, 1.0]))
        y[M.Y_ALPHA] = side * (rng.uniform(1e-3, 1.5) if trial % 5 else math.pi / 2 - 1e-6)
        y[M.Y_W1:M.Y_W3 + 1] = rng.normal(size=3) * [0.3, 1.0, 0.3]
        if mode != CN.ROLL:
            y[M.Y_U1:M.Y_U2 + 1] = rng.normal(size=2) * (1e-9 if mode == CN.SLAVED else 0.1)
        cs = cs0.copy()
        cs[L.CS_MODE], cs[L.CS_SIDE] = mode, side
        cs[L.CS_NU] = math.atan2(y[M.Y_U2], y[M.Y_U1])
        dy, aux = np.zeros(M.N_FULL), np.zeros(M.N_AUX)
        CR.eval_rhs(0.0, y, _sys(p, cs, M.N_CORE, wk, ist), dy, aux)
        assert aux[M.X_SINA] == math.sin(y[M.Y_ALPHA]) and aux[M.X_COSA] == math.cos(y[M.Y_ALPHA])
        slip = mode != CN.ROLL
        assert CR.mode_energy_at(y, aux, p, cs) == CR.mode_energy(y, p, cs)
        v = rng.normal(size=M.N_FULL) * 1e-3
        assert (M.energy_rate_trig(y, v, p, side, slip, (aux[M.X_SINA], aux[M.X_COSA]))
                == M.energy_rate(y, v, p, side, slip))
        assert (M.energy_increment_trig(y, v, p, side, slip, (aux[M.X_SINA], aux[M.X_COSA]))
                == M.energy_increment(y, v, p, side, slip))


def test_error_norm_is_hairers_dop853_norm_in_the_callers_scales():
    """dop853.error_norm knows no state: Hairer's norm over the first n components, each in units
    of the scale the caller gives it."""
    rng = np.random.default_rng(3)
    n = 7
    K = rng.normal(size=(T.N_STAGES_EXTENDED, M.N_FULL))
    sc = 10.0 ** rng.uniform(-12, -6, size=M.N_FULL)
    h = 0.01
    e5 = np.sum(((T.E5 @ K[:13, :n]) / sc[:n]) ** 2)
    e3 = np.sum(((T.E3 @ K[:13, :n]) / sc[:n]) ** 2)
    ref = h * e5 / math.sqrt((e5 + 0.01 * e3) * n)
    assert D.error_norm(K, h, sc, n) == pytest.approx(ref, rel=1e-12)
    sc2 = sc.copy()
    sc2[n:] = np.nan           # components past n are not read
    assert D.error_norm(K, h, sc2, n) == D.error_norm(K, h, sc, n)
    sc2[n - 1] *= 2.0          # ... component n - 1 is
    assert D.error_norm(K, h, sc2, n) < D.error_norm(K, h, sc, n)
    assert D.error_norm(np.zeros_like(K), h, sc, n) == 0.0


@pytest.mark.parametrize("alpha", [0.3, 1.0, -1.5707, 1.5707963])
def test_error_scale_is_hairers_with_the_inclination_and_slip_rules(alpha):
    """integrate.error_scale: atol + rtol max(|y|, |y_new|), the inclination's magnitude
    min(|alpha|, pi/2 - |alpha|), the slip components' absolute tolerance u_atol."""
    from sweep.core.accept import error_scale
    rng = np.random.default_rng(3)
    n = M.N_CORE
    y = rng.normal(size=M.N_FULL)
    y[M.Y_ALPHA] = alpha
    y_new = y + 1e-3 * rng.normal(size=M.N_FULL)
    y_new[M.Y_ALPHA] = alpha * (1.0 - 1e-8)
    rtol, atol = 1e-8, 1e-10
    mag = np.maximum(np.abs(y[:n]), np.abs(y_new[:n]))
    mag[M.Y_ALPHA] = min(abs(alpha), 0.5 * math.pi - abs(alpha) * (1.0 - 1e-8))
    for u_atol in (atol, 1e-16):     # the slip components' own absolute tolerance
        ref = atol + rtol * mag
        ref[M.Y_U1:M.Y_U2 + 1] = u_atol + rtol * mag[M.Y_U1:M.Y_U2 + 1]
        sc = np.full(M.N_FULL, -1.0)
        error_scale(y, y_new, n, (rtol, atol, u_atol), sc)
        np.testing.assert_allclose(sc[:n], ref, rtol=1e-12)
        assert np.all(sc[n:] == -1.0)


def test_dense_output_interpolates_the_step_at_seventh_order(setup):
    p, y, cs = setup
    n = M.N_CORE
    errs = []
    for h in (0.2, 0.1):
        wk, ist = _work()
        K = np.zeros((T.N_STAGES_EXTENDED, M.N_FULL))
        F = np.zeros((14, M.N_FULL))
        f = np.zeros(M.N_FULL)
        f[:n] = _f(0.0, y, p, cs)[0]
        y_new = np.zeros(M.N_FULL)
        f_new = np.zeros(M.N_FULL)
        _step(0.0, y, f, h, _sys(p, cs, n, wk, ist), K, y_new, f_new)
        span = L.Span(F, 0, y, 0.0, h, _sys(p, cs, n, wk, ist))
        D.dense_coeffs(CR.eval_rhs, span, y_new, K)
        out = np.zeros(M.N_FULL)
        D.dense_eval(span, 0.0, n, out)
        assert np.max(np.abs(out[:n] - y[:n])) < 1e-15
        D.dense_eval(span, h, n, out)
        assert np.max(np.abs(out[:n] - y_new[:n])) < 1e-14
        # midpoint against two half steps
        yh = np.zeros(M.N_FULL)
        _step(0.0, y, f, 0.5 * h, _sys(p, cs, n, wk, ist), K, yh)
        D.dense_eval(span, 0.5 * h, n, out)
        errs.append(np.max(np.abs(out[:n] - yh[:n])))
    assert errs[0] / errs[1] > 2 ** 6.5      # local error of the interpolant ~ h^8


def test_hermite_dip_finds_the_minimum_exactly():
    # g(x) = (x - 0.5)^2 - c is its own Hermite cubic: its minimum is at 0.5 whatever its value (the
    # caller checks the dense output there, since a cubic above 0 may hide a shallow dip)
    for c in (0.01, 1e-12, -1e-12, -0.2):
        g0 = g1 = 0.25 - c
        assert R.hermite_dip(g0, -1.0, g1, 1.0) == pytest.approx(0.5, abs=1e-12)
    # g(x) = (x - 0.3)^2 + 0.1: minimum at 0.3
    assert R.hermite_dip(0.19, -0.6, 0.59, 1.4) == pytest.approx(0.3, abs=1e-12)
    assert R.hermite_dip(1.0, 1.0, 2.0, 1.0) == -1.0          # monotone: no interior minimum


def test_slip_closest_approach_places_the_v_of_a_slip_passing_by_zero():
    """A slip passing by u = 0: u(x) = (x - x0) v + w, w perpendicular to v, is its own Hermite curve.
    |u| - slip_tol has a V at x0 of width ~|w|/|v|, far narrower than the step: the cubic in g
    through the end values and slopes of |u| puts its minimum elsewhere, and the
    closest approach puts it at x0 (seed 20261128 scene 39, docs/performance.md 'Stop 29')."""
    h = 1e-5
    for x0 in (0.5, 0.137, 0.91):
        v = np.array([0.3, -0.4]) / h           # per unit tau: |v h| = 0.5 over the step
        w = np.array([0.4, 0.3]) * 1.5e-9       # miss distance 1.5e-9, perpendicular to v
        y0, y1, f0, f1 = (np.zeros(M.N_FULL) for _ in range(4))
        y0[[M.Y_U1, M.Y_U2]] = -x0 * v * h + w
        y1[[M.Y_U1, M.Y_U2]] = (1 - x0) * v * h + w
        f0[[M.Y_U1, M.Y_U2]] = v
        f1[[M.Y_U1, M.Y_U2]] = v
        x = R.slip_closest_approach(y0, f0, y1, f1, h)
        assert x == pytest.approx(x0, abs=1e-15)
        # the cubic through |u| and its exact end slopes misses the V by far more than its width
        g0, g1 = np.hypot(*y0[[M.Y_U1, M.Y_U2]]), np.hypot(*y1[[M.Y_U1, M.Y_U2]])
        d0 = y0[[M.Y_U1, M.Y_U2]] @ v * h / g0
        d1 = y1[[M.Y_U1, M.Y_U2]] @ v * h / g1
        if x0 != 0.5:
            assert abs(R.hermite_dip(g0, d0, g1, d1) - x0) > 1e-3
    # moving away from 0 at the start, or towards it at the end: no interior minimum of |u|
    y0, y1, f0, f1 = (np.zeros(M.N_FULL) for _ in range(4))
    y0[M.Y_U1], y1[M.Y_U1], f0[M.Y_U1], f1[M.Y_U1] = 1e-6, 2e-6, 0.1, 0.1
    assert R.slip_closest_approach(y0, f0, y1, f1, 1e-5) == -1.0


def _dense_step(p, y, cs, h, n=M.N_CORE, t0=0.0, y_end=None):
    """One DOP853 step from (t0, y) with its dense output: (F, wk, istats); its end state into
    y_end if given."""
    wk, ist = _work()
    K = np.zeros((T.N_STAGES_EXTENDED, M.N_FULL))
    F = np.zeros((14, M.N_FULL))
    f = np.zeros(M.N_FULL)
    f[:n] = _f(t0, y, p, cs)[0]
    y_new, f_new = np.zeros(M.N_FULL), np.zeros(M.N_FULL)
    _step(t0, y, f, h, _sys(p, cs, n, wk, ist), K, y_new, f_new)
    D.dense_coeffs(CR.eval_rhs, L.Span(F, 0, y, t0, h, _sys(p, cs, n, wk, ist)), y_new, K)
    if y_end is not None:
        y_end[:] = y_new
    return F, wk, ist


def test_locate_brackets_a_sign_event_to_the_tolerance(setup):
    p, y, cs = setup
    n, h = M.N_CORE, 0.3
    k = ID.EV_SIGN1        # g = sigma_1 w1 = 0.05 > 0; w1 rises through 0 within the step
    y = y.copy()
    y[M.Y_W1] = -0.05
    cs = cs.copy()
    cs[L.CS_SIG] = -1.0
    F, wk, ist = _dense_step(p, y, cs, h)
    span = L.Span(F, 0, y, 0.0, h, _sys(p, cs, n, wk, ist))
    g0 = R.event_value_at(k, 0.0, span, math.nan)
    g1 = R.event_value_at(k, h, span, math.nan)
    assert g0 > 0.0 >= g1, (g0, g1)
    ta, tb = R.locate(k, L.Bracket(0.0, g0, h, g1), span, math.nan)
    assert tb - ta <= R.location_tol(tb)
    assert R.event_value_at(k, ta, span, math.nan) > 0.0
    assert R.event_value_at(k, tb, span, math.nan) <= 0.0


def test_locate_closes_a_force_event_bracket_superlinearly(setup):
    """The friction cone's margin mu_s Phi - |F| (a force event: one RHS per evaluation) falls
    through 0 inside a rolling step. Bisection from the whole step (0.3 tau) to location_tol
    (1e-15 tau here) needs 49 evaluations; Brent's method on this smooth function closes the
    bracket in fewer than half as many (10; the Illinois loop it replaced took 48, as its
    retained end's value was halved on every step). The bracket keeps g > 0 at its left end and
    g <= 0 at its right."""
    p, y, cs = setup
    n, h = M.N_CORE, 0.3
    y = y.copy()
    y[M.Y_W1] = -0.2      # |F|/Phi rises from 0.393 to 0.413 over the step
    p = p.copy()
    p[M.P_MUS] = 0.403
    k = ID.EV_CONE
    F, wk, ist = _dense_step(p, y, cs, h)
    span = L.Span(F, 0, y, 0.0, h, _sys(p, cs, n, wk, ist))
    g0 = R.event_value_at(k, 0.0, span, math.nan)
    g1 = R.event_value_at(k, h, span, math.nan)
    assert g0 > 0.0 >= g1, (g0, g1)
    rhs_before = ist[L.I_RHS]
    ta, tb = R.locate(k, L.Bracket(0.0, g0, h, g1), span, math.nan)
    evaluations = ist[L.I_RHS] - rhs_before
    assert tb - ta <= R.location_tol(tb)
    assert R.event_value_at(k, ta, span, math.nan) > 0.0
    assert R.event_value_at(k, tb, span, math.nan) <= 0.0
    bisections = math.ceil(math.log2(h / R.location_tol(tb)))
    assert evaluations < bisections / 2, (evaluations, bisections)


def test_brent_finds_the_maximum_of_the_normal_force(setup):
    p, y, cs = setup
    n, h = M.N_CORE, 1.5
    F, wk, ist = _dense_step(p, y, cs, h)
    span = L.Span(F, 0, y, 0.0, h, _sys(p, cs, n, wk, ist))
    grid = np.linspace(0.0, h, 2001)
    phi = []
    for t in grid:
        D.dense_eval(span, t, n, wk[L.W_YBUF])
        phi.append(_f(t, wk[L.W_YBUF], p, cs)[1][M.X_PHI])
    i = int(np.argmax(phi))
    assert 0 < i < len(grid) - 1, "the test step must contain an interior maximum of Phi"
    tmax, pmax = R.brent_max_phi(0.0, h, L.Span(F, 0, y, 0.0, h, _sys(p, cs, n, wk, ist)))
    assert abs(tmax - grid[i]) < 2 * (grid[1] - grid[0])
    assert pmax >= max(phi) - 1e-12


def _two_steps(p, y0, cs, t0, t_mid, t_end, n=M.N_CORE):
    """Two DOP853 steps from (t0, y0), [t0, t_mid] and [t_mid, t_end], set up as track_peaks sees
    them: the first one's dense output in F[7:14] with its start in wk[W_YPREV], the second's in
    F[0:7]; returns (F, trk, wk, istats, y_mid), trk the recorders' layout.TrackState."""
    F = np.zeros((14, M.N_FULL))
    trk = I.tracking_arrays().track
    ys = [y0.copy()]
    for k, (ta, tb) in enumerate(((t0, t_mid), (t_mid, t_end))):
        y1 = np.zeros(M.N_FULL)
        Fs, wk, ist = _dense_step(p, ys[-1], cs, tb - ta, n, ta, y1)
        F[D.N_DENSE * (1 - k):D.N_DENSE * (2 - k)] = Fs[0:D.N_DENSE]
        ys.append(y1)
    wk[L.W_YPREV, :M.N_FULL] = ys[0]
    wk[L.W_CSPREV, :L.N_CS] = cs
    trk.phi[L.PH_TA], trk.phi[L.PH_TB], trk.phi[L.PH_TPREV], trk.phi[L.PH_HPREV] = t0, t_mid, t0, t_mid - t0
    trk.phi[L.PH_B] = _f(t_mid, ys[1], p, cs)[1][M.X_PHI]
    return F, trk, wk, ist, ys[1]


def _spans(p, F, trk, wk, ist, y_mid, t_mid, t1, n=M.N_CORE):
    """The two steps of _two_steps, [PH_TPREV, t_mid] and [t_mid, t1], as track_peaks reads them:
    (before, this), both in the contact state stored in wk[W_CSPREV]."""
    cs = wk[L.W_CSPREV, :L.N_CS].copy()
    before = L.Span(F, D.N_DENSE, wk[L.W_YPREV], trk.phi[L.PH_TPREV], trk.phi[L.PH_HPREV],
                    _sys(p, wk[L.W_CSPREV, :L.N_CS], n, wk, ist))
    this = L.Span(F, 0, y_mid, t_mid, t1 - t_mid, _sys(p, cs, n, wk, ist))
    return before, this


def test_peak_sides_picks_the_segment_that_holds_the_maximum_of_the_normal_force(setup):
    """tracking.peak_sides against Phi's maximum on a fine grid of the two steps' dense outputs: a
    common end left of the maximum searches the right segment only, one right of it the left one,
    the maximum itself as the common end both (Phi falls on either side)."""
    from sweep.core import tracking as TR

    p, y, cs = setup
    n = M.N_CORE
    # to tau = 1 in short steps; Phi then has a maximum near tau = 1.2 (a swing of the wobble)
    f, y_new = np.zeros(M.N_FULL), np.zeros(M.N_FULL)
    wk, ist = _work()
    K = np.zeros((T.N_STAGES_EXTENDED, M.N_FULL))
    y0 = y.copy()
    for j in range(100):
        f[:n] = _f(0.01 * j, y0, p, cs)[0]
        _step(0.01 * j, y0, f, 0.01, _sys(p, cs, n, wk, ist), K, y_new)
        y0 = y_new.copy()
    t0, t1 = 1.0, 1.4

    def phi_max(t_mid):
        F, trk, wk, ist, y_mid = _two_steps(p, y0, cs, t0, t_mid, t1)
        grid = np.linspace(t0, t1, 4001)
        before, this = _spans(p, F, trk, wk, ist, y_mid, t_mid, t1)
        phi = [R.phi_on_dense(t, before) if t <= t_mid
               else R.phi_on_dense(t, this) for t in grid]
        i = int(np.argmax(phi))
        assert 0 < i < len(grid) - 1, "the two steps must hold an interior maximum of Phi"
        return grid[i], F, trk, wk, ist, y_mid

    for t_mid in (1.05, 1.1, 1.25, 1.3):
        t_star, F, trk, wk, ist, y_mid = phi_max(t_mid)
        expected = (t_star < t_mid, t_star > t_mid)
        before, this = _spans(p, F, trk, wk, ist, y_mid, t_mid, t1)
        assert TR.peak_sides(t1, before, this, trk) == expected, (t_mid, t_star)
        # the side it keeps is where the search of both segments finds the larger maximum
        _, pv_left = R.brent_max_phi(t0, t_mid, before)
        _, pv_right = R.brent_max_phi(t_mid, t1, this)
        assert (pv_left >= pv_right) == expected[0]
    # the common end at the maximum (located by Brent on the two steps with an end near it)
    t_star, F, trk, wk, ist, y_mid = phi_max(1.1)
    _, this = _spans(p, F, trk, wk, ist, y_mid, 1.1, t1)
    t_exact, _ = R.brent_max_phi(1.1, t1, this)
    F, trk, wk, ist, y_mid = _two_steps(p, y0, cs, t0, t_exact, t1)
    before, this = _spans(p, F, trk, wk, ist, y_mid, t_exact, t1)
    assert TR.peak_sides(t1, before, this, trk) == (True, True)


def test_slaved_and_attracting_directions_are_roots_of_the_cross_product(setup):
    p, y, cs = setup
    n = M.N_CORE
    wk, ist = _work()
    sl = cs.copy()
    sl[L.CS_MODE] = CN.SLAVED
    u = 1e-9
    dy, aux, ys = np.zeros(M.N_FULL), np.zeros(M.N_AUX), np.zeros(M.N_FULL)
    for nu0 in np.linspace(-3.0, 3.0, 7):
        nu = SL.attracting_direction(nu0, u, 0.0, y, _sys(p, sl, n, wk, ist))
        if math.isnan(nu):
            continue
        c, _ = CR.slip_rates(nu, u, L.Eval(0.0, y, _sys(p, sl, n, wk, ist), dy, aux), ys)
        assert abs(c) < 1e-10
        # attracting: the direction rate cross/u points back to the root from both sides
        cm, _ = CR.slip_rates(nu - 1e-3, u, L.Eval(0.0, y, _sys(p, sl, n, wk, ist), dy, aux), ys)
        cp, _ = CR.slip_rates(nu + 1e-3, u, L.Eval(0.0, y, _sys(p, sl, n, wk, ist), dy, aux), ys)
        assert cm > 0.0 > cp
        nu2 = CR.slaved_direction(nu + 1e-4, u, L.Eval(0.0, y, _sys(p, sl, n, wk, ist), dy, aux), ys)
        assert abs(math.remainder(nu2 - nu, 2 * math.pi)) < 1e-12


def test_onset_direction_takes_a_root_with_a_solution_and_never_a_painleve_pole(setup):
    """Random rolling states with a high mu_d, where the sliding law has no solution on arcs of
    slip directions (Phi's coefficient <= 0, model.tilt_balance): at the arcs' ends the cross
    product changes sign through a pole, not a root. A fine scan classifies the sign changes; the
    onset direction must be a root with a growing slip and a solution whenever one exists, and
    never a pole (the bisection used to close on one in ~3 % of these states: harness seed
    20261136 scene 465)."""
    p0, _, cs0 = setup
    n = M.N_CORE
    wk, ist = _work()
    dy, aux, ys = np.zeros(M.N_FULL), np.zeros(M.N_AUX), np.zeros(M.N_FULL)
    rng = np.random.default_rng(7)
    grid = np.linspace(-math.pi, math.pi, 1441)
    poles_seen = 0
    for _ in range(200):
        p = p0.copy()
        p[M.P_MUD] = rng.uniform(0.6, 1.6)
        p[M.P_MUS] = 1.05 * p[M.P_MUD]
        p[M.P_H] = rng.uniform(0.0, 1.0)
        p[M.P_A] = 0.25 + p[M.P_H] ** 2 / 3.0
        y = np.zeros(M.N_FULL)
        y[M.Y_ALPHA] = rng.uniform(-1.5, 1.5)
        y[M.Y_W1:M.Y_W3 + 1] = rng.normal(0.0, 2.0, 3)
        cs = cs0.copy()
        cs[L.CS_SIDE] = 1.0 if y[M.Y_ALPHA] >= 0.0 else -1.0
        cs[L.CS_SIG:L.CS_SIG + 3] = np.sign(rng.normal(size=3))
        CR.model_call(L.Eval(0.0, y, _sys(p, cs, n, wk, ist), dy, aux), 1.0, 0.0)
        if aux[M.X_OK] != 1.0 or aux[M.X_PHI] <= 0.0:
            continue
        F1, F2 = aux[M.X_F1], aux[M.X_F2]
        guess = math.atan2(-F2, -F1)
        cs[L.CS_MODE] = CN.SLAVED
        sys_ = _sys(p, cs, n, wk, ist)
        scan = np.array([CR.slip_rates(x, 0.0, L.Eval(0.0, y, sys_, dy, aux), ys) + (aux[M.X_OK],) for x in grid])
        flips = np.nonzero((scan[:-1, 0] > 0.0) != (scan[1:, 0] > 0.0))[0]
        consistent = any(scan[j, 2] > 0.0 and scan[j + 1, 2] > 0.0 and scan[j + 1, 1] > 0.0 for j in flips)
        poles_seen += sum(1 for j in flips if scan[j, 2] != scan[j + 1, 2])
        nu = SL.onset_direction(0.0, y, _sys(p, cs, n, wk, ist), F1, F2)
        if nu == guess:
            assert not consistent
            continue
        cr, dr = CR.slip_rates(nu, 0.0, L.Eval(0.0, y, _sys(p, cs, n, wk, ist), dy, aux), ys)
        assert math.isfinite(cr) and abs(cr) <= 1e-9 * max(1.0, abs(dr)) and dr > 0.0   # a root, not a pole
        if consistent:
            assert aux[M.X_OK] == 1.0
    assert poles_seen > 20   # the draw does reach the Painleve arcs


def test_slaved_direction_near_a_fold_converges_at_the_round_off_floor():
    """500-scene harness scene 112 (seed 20261122) at rtol 1e-11, 36.17 s: a slide near flat hands
    over to the slaved direction of a weakly attracting root (d cross/d nu ~ -2e-3, a fold nearby).
    From that root the secant's iterates give cross values at the round-off floor (|cross| ~ 1e-16
    against a slip acceleration of 0.08), two of them equal, before the angle update falls below
    DIR_TOL: the root was declared lost, the right-hand side NaN, and the scene ended as
    step_size_underflow. A root found to machine precision must be accepted from any start near it."""
    y = np.zeros(M.N_FULL)
    y[:10] = [-1.5673133196188795, -0.017820889609631227, 0.07771254845175782, -0.12143037310535122,
              3.8996640035269233e-10, 2.1236463939109588e-09, 0.2996915475916652, 0.00011133469101795674,
              0.049821969536914465, 0.22653401920898733]
    cs = np.array([CN.SLIDE, -1.0, -1.0, -1.0, -1.0, 0.0, 0.0, 0.0, -1.5431398827001483, 0.0])
    p = np.array([1.25, 0.7147500458389359, 0.42028920934225367, 0.5, 5.2941088582301325e-06,
                  0.0003773901681763095, 0.0024557175535302304, 0.06604195186843453, 0.013401783317111789,
                  9.988368229478843e-10, 0.0, 0.0])   # spin_tol 0; slave_tol 0: slaved from the slip_tol
    n, t = M.N_FULL, 283.5429130271587
    wk, ist = _work()
    SL.try_slave(t, y, _sys(p, cs, n, wk, ist))
    assert cs[L.CS_MODE] == CN.SLAVED
    u = math.hypot(y[M.Y_U1], y[M.Y_U2])
    dy, aux, ys = np.zeros(M.N_FULL), np.zeros(M.N_AUX), np.zeros(M.N_FULL)
    root = CR.slaved_direction(cs[L.CS_NU], u, L.Eval(t, y, _sys(p, cs, n, wk, ist), dy, aux), ys)
    assert aux[M.X_OK] == 1.0
    for k in range(-40, 41):
        start = root + k * 4e-16
        nu = CR.slaved_direction(start, u, L.Eval(t, y, _sys(p, cs, n, wk, ist), dy, aux), ys)
        c, d = CR.slip_rates(nu, u, L.Eval(t, y, _sys(p, cs, n, wk, ist), dy, aux), ys)
        assert aux[M.X_OK] == 1.0, (k, nu)
        assert abs(c) <= CR.DIR_NOISE * math.hypot(c, d) and abs(nu - root) < 1e-12, (k, nu, c)
    # and the slaved right-hand side there is finite (it was NaN with X_OK 1 left by the model)
    cs[L.CS_NU] = root
    CR.eval_rhs(t, y, _sys(p, cs, n, wk, ist), dy, aux)
    assert aux[M.X_OK] == 1.0 and np.isfinite(dy[:n]).all() and aux[M.X_DCROSS] < 0.0


def test_hermite_peak_is_the_interpolants_maximum():
    # g(x) = x (1 - x) - 0.1 x: H(0) = 0, H'(0) = 0.9, H(1) = -0.1, H'(1) = -1.1; maximum at x = 0.45
    x = R.hermite_peak(0.0, 0.9, -0.1, -1.1)
    assert x == pytest.approx(0.45, abs=1e-12)
    assert R.hermite_peak(0.0, 1.0, 1.0, 1.0) == -1.0   # a straight line has no interior extremum


@pytest.mark.parametrize("k1", [1e-3, 0.1, 1.0])
@pytest.mark.parametrize("w1", [0.05, -0.05])
def test_settle_signs_releases_a_stuck_component_the_moment_cannot_hold(setup, k1, w1):
    """After a discrete update a stuck component stays stuck iff the moment needed to hold it is
    within the limit (|sigma needed| <= 1); otherwise it is released towards the needed moment
    (its un-stick event, |sigma| rising to 1, cannot happen from above 1). A component the
    Filippov rule holds (`held`) is left alone."""
    p, y, cs0 = setup
    pp = p.copy()
    pp[M.P_K1], pp[M.P_K2], pp[M.P_K3] = k1, 0.0, 0.0
    y1 = y.copy()
    y1[M.Y_W1] = w1
    for held in (-1, 0):
        cs = cs0.copy()
        cs[L.CS_MODE] = CN.ROLL
        cs[L.CS_STUCK] = 1.0
        wk, ist = _work()
        CR.eval_rhs(0.0, y1, _sys(pp, cs, M.N_CORE, wk, ist), wk[L.W_DYTMP], wk[L.W_AUXTMP])
        need = wk[L.W_AUXTMP, M.X_SIG1]
        MO.settle_signs(0.0, y1, _sys(pp, cs, M.N_CORE, wk, ist), held)
        if abs(need) <= 1.0 or held == 0:
            assert cs[L.CS_STUCK] == 1.0
        else:
            assert cs[L.CS_STUCK] == 0.0 and cs[L.CS_SIG] == math.copysign(1.0, need)


@pytest.mark.parametrize("w1_after", [-5e-7, -5e-6])
def test_an_impulse_carrying_a_free_component_past_its_surface(setup, w1_after):
    """An impulse that carries a free component (sigma_1 = +1, omega.a_1 = omega_1 = 0.05) past its
    switching surface: by more than spin_tol (1e-6) it spins the other way at a finite rate, and
    its moment takes the new sign, although the moment could hold it (|sigma needed| < 1 there, so
    a stick test would have stuck a spinning component); within spin_tol it is at rest and gets
    the stick test (docs/model.md, 'Restarts on a surface')."""
    p, y, cs0 = setup
    pp = p.copy()
    pp[M.P_K1], pp[M.P_WTOL] = 1.0, 1e-6
    g_before = M.moment_axes_rates(y)
    y1 = y.copy()
    y1[M.Y_W1] = w1_after
    cs = cs0.copy()
    cs[L.CS_MODE] = CN.ROLL
    wk, ist = _work()
    need = MO.needed_sigma(0, 0.0, y1, _sys(pp, cs, M.N_CORE, wk, ist), wk[L.W_DYTMP], wk[L.W_AUXTMP])
    assert abs(need) < 1.0
    MO.release_moved(y1, pp, cs, g_before)
    MO.settle_signs(0.0, y1, _sys(pp, cs, M.N_CORE, wk, ist), -1)
    if abs(w1_after) > pp[M.P_WTOL]:
        assert cs[L.CS_STUCK] == 0.0 and cs[L.CS_SIG] == -1.0
    else:
        assert cs[L.CS_STUCK] == 1.0


def test_settle_signs_tests_every_component_on_its_surface(setup):
    """A stick test that changes nothing (component 1 at omega.a_1 = 0, its moment too weak to hold
    it, already signed the way the motion goes) must not stop the test of another component on or
    past its surface (component 3, signed against its omega.a_3): it gets its stick test. Before,
    the scan took the first such component on every pass and never reached the third."""
    p, y, cs0 = setup
    pp = p.copy()
    pp[M.P_K1], pp[M.P_K2], pp[M.P_K3] = 1e-6, 1e-6, 1e-6
    y1 = y.copy()
    y1[M.Y_W1] = 0.0
    g = M.moment_axes_rates(y1)
    cs = cs0.copy()
    cs[L.CS_MODE] = CN.ROLL
    cs[L.CS_SIG + 1] = math.copysign(1.0, g[1])
    cs[L.CS_SIG + 2] = -math.copysign(1.0, g[2])
    wk, ist = _work()
    need1 = MO.needed_sigma(0, 0.0, y1, _sys(pp, cs, M.N_CORE, wk, ist), wk[L.W_DYTMP], wk[L.W_AUXTMP])
    need3 = MO.needed_sigma(2, 0.0, y1, _sys(pp, cs, M.N_CORE, wk, ist), wk[L.W_DYTMP], wk[L.W_AUXTMP])
    assert abs(need1) > 1.0
    cs[L.CS_SIG] = math.copysign(1.0, need1)
    MO.settle_signs(0.0, y1, _sys(pp, cs, M.N_CORE, wk, ist), -1)
    assert cs[L.CS_STUCK] == 0.0 and cs[L.CS_SIG] == math.copysign(1.0, need1)
    if abs(need3) < 1.0:   # (0.78 here: the moment holds it)
        assert cs[L.CS_STUCK + 2] == 1.0
    else:
        assert cs[L.CS_STUCK + 2] == 0.0 and cs[L.CS_SIG + 2] == math.copysign(1.0, need3) != -math.copysign(1.0, g[2])


def test_event_rates_are_the_slopes_of_the_event_functions_along_the_solution(setup):
    """roots.event_rates (one forward difference for every event) against the exact slopes of the
    sign functions (sign_rate: from the state and its derivative) and of side * alpha (omega_1), and
    against a central difference of step 1e-5 (error O(1e-10)) for the others."""
    p, y, cs = setup
    n = M.N_CORE
    wk, ist = _work()
    f = np.zeros(M.N_FULL)
    aux = np.zeros(M.N_AUX)
    CR.eval_rhs(0.0, y, _sys(p, cs, n, wk, ist), f, aux)
    g = np.zeros(L.N_WCOLS)
    ED.event_values(0.0, y, aux, _ev_sys(p, cs), math.nan, g)
    rates = np.zeros(L.N_WCOLS)
    R.event_rates(0.0, L.Point(y, f, aux), g, rates, math.nan, _sys(p, cs, n, wk, ist))
    for k in range(3):
        exact = cs[L.CS_SIG + k] * R.sign_rate(k, y, f)
        assert rates[ID.EV_SIGN1 + k] == pytest.approx(exact, rel=1e-6, abs=1e-7)
    assert rates[ID.EV_SIDE] == pytest.approx(cs[L.CS_SIDE] * y[M.Y_W1], rel=1e-6, abs=1e-7)

    def g_at(eps):
        ys = y.copy()
        ys[:n] += eps * f[:n]
        dy, ax, gg = np.zeros(M.N_FULL), np.zeros(M.N_AUX), np.zeros(L.N_WCOLS)
        CR.eval_rhs(eps, ys, _sys(p, cs, n, wk, ist), dy, ax)
        ED.event_values(0.0, ys, ax, _ev_sys(p, cs), math.nan, gg)
        return gg

    g_plus, g_minus = g_at(1e-5), g_at(-1e-5)
    for k in (ID.EV_CONE, ID.EV_CONTACT, ID.EV_FACE):
        assert math.isfinite(g[k])
        central = (g_plus[k] - g_minus[k]) / 2e-5
        assert rates[k] == pytest.approx(central, rel=1e-6, abs=1e-7), k
    for k in range(ID.N_DYN_EVENTS):
        if g[k] == math.inf:
            assert rates[k] == 0.0      # inactive in this mode: no slope


@pytest.mark.parametrize("mode", [CN.ROLL, CN.SLIDE, CN.SLAVED])
def test_events_that_do_not_read_forces_are_functions_of_the_state(setup, mode):
    """roots.event_value_at skips the right-hand side for events with not reads_forces(k): their
    value from the state alone (state_event_value) must be, bit for bit, the one event_values gives
    with the right-hand side's contact quantities, over random states, moment signs, stuck
    components and levels; and event_value_at gives it on the dense output with no RHS call."""
    p0, _, _ = setup
    rng = np.random.default_rng(11)
    checked = set()
    for _ in range(200):
        p = p0.copy()
        p[M.P_WTOL] = rng.choice([0.0, 1e-7])
        y = np.zeros(M.N_FULL)
        y[M.Y_ALPHA] = rng.uniform(-1.5, 1.5)
        y[M.Y_W1:M.Y_W3 + 1] = rng.normal(size=3)
        if mode != CN.ROLL:
            y[M.Y_U1:M.Y_U2 + 1] = rng.normal(scale=1e-3, size=2)
        cs = np.zeros(L.N_CS)
        cs[L.CS_MODE] = mode
        cs[L.CS_SIDE] = 1.0 if y[M.Y_ALPHA] > 0.0 else -1.0
        cs[L.CS_SIG:L.CS_SIG + 3] = rng.choice([-1.0, 1.0], size=3)
        cs[L.CS_STUCK:L.CS_STUCK + 3] = rng.choice([0.0, 1.0], size=3)
        cs[L.CS_NU] = rng.uniform(-math.pi, math.pi)
        level = rng.uniform(0.1, 2.0)
        wk, ist = _work()
        dy, aux = np.zeros(M.N_FULL), np.zeros(M.N_AUX)
        CR.eval_rhs(0.0, y, _sys(p, cs, M.N_CORE, wk, ist), dy, aux)
        g_true = np.zeros(L.N_WCOLS)
        ED.event_values(0.0, y, aux, _ev_sys(p, cs), level, g_true)
        for k in range(ID.N_EVENTS):
            if R.reads_forces(k) or g_true[k] == math.inf:
                continue
            checked.add(k)
            assert ED.state_event_value(k, 0.0, y, _ev_sys(p, cs), level) == g_true[k], k
            # on a dense output whose every coefficient is 0, the value at any t is y itself
            rhs_before = ist[L.I_RHS]
            F = np.zeros((14, M.N_FULL))
            span = L.Span(F, 0, y, 0.0, 1.0, _sys(p, cs, M.N_CORE, wk, ist))
            assert R.event_value_at(k, 0.3, span, level) == g_true[k]
            assert ist[L.I_RHS] == rhs_before
    expected = {ID.EV_SIDE, ID.EV_FACE, ID.EV_LEVEL} | (
        {ID.EV_SIGN1, ID.EV_SIGN2, ID.EV_SIGN3, ID.EV_SPIN1, ID.EV_SPIN2, ID.EV_SPIN3} if mode == CN.ROLL
        else set())
    assert expected <= checked


def _contact_states():
    """A contact state of every kind: each mode x each hand-over state x no or all components stuck."""
    for mode in (CN.ROLL, CN.SLIDE, CN.SLAVED):
        for handover in (CN.HANDOVER_ARMED, CN.HANDOVER_OFF, CN.SLOW_OFF, CN.BELOW, CN.AT_FLOOR):
            for stuck in (0.0, 1.0):
                yield mode, handover, stuck


def test_the_event_ids_are_the_rows_of_one_table():
    """events.py: ids 0 .. N_EVENT_IDS - 1, each a row of EVENTS with a known class, a moment
    component exactly for the moment events, a dip rule exactly for the events of the dynamics; the
    dynamic events first, the level's event right after them (integrate.carry_step_end and
    first_event rely on it), the update-only ids last."""
    ids = {v: k for k, v in vars(ID).items() if k.startswith("EV_")}
    assert sorted(ids) == list(range(ID.N_EVENT_IDS)) == list(range(ID.EVENTS.shape[0]))
    assert ID.N_DYN_EVENTS == ID.EV_LEVEL < ID.N_EVENTS == ID.EV_LEVEL + 1 <= ID.EV_AGAINST1
    classes = {EV.C_MOMENT, EV.C_SLIP, EV.C_CONTACT_LOST, EV.C_FACE, EV.C_SIDE, EV.C_LEVEL}
    for k in range(ID.N_EVENT_IDS):
        cls = ID.EVENTS[k, EV.E_CLASS]
        assert cls in classes, ids[k]
        assert (ID.EVENTS[k, EV.E_COMPONENT] in (0, 1, 2)) == (cls == EV.C_MOMENT), ids[k]
    assert [k for k in range(ID.N_EVENT_IDS) if ID.EVENTS[k, EV.E_CLASS] == EV.C_LEVEL] == [ID.EV_LEVEL]
    # every event of the dynamics has a way to bracket a dip inside a step (integrate.dip_bracket
    # raises for any other) and a restart rule; the others are never scanned
    for k in range(ID.N_EVENT_IDS):
        dip = ID.EVENTS[k, EV.E_DIP]
        assert (dip in (EV.D_RATES, EV.D_SIGN, EV.D_SIDE, EV.D_SLIP)) == (k < ID.N_DYN_EVENTS), ids[k]
        assert ID.EVENTS[k, EV.E_RESTART] in (EV.R_NONE, EV.R_SURFACE, EV.R_SPIN), ids[k]
        assert dip != EV.D_SIGN or ID.EVENTS[k, EV.E_COMPONENT] in (0, 1, 2), ids[k]


def test_every_event_has_its_value_and_its_update(setup):
    """Every event id against the dispatches, none of which has a default: each event function
    (k < N_EVENTS) is computed by event_values in some contact state, and one of the state alone
    (not reads_forces) by state_event_value, which raises for an id without one; every id but the
    level's runs its discrete update in apply_event, which raises for the level (no update) and an
    unknown class."""
    p0, y0, _ = setup
    p = p0.copy()
    p[M.P_WTOL] = 1e-7
    assert min(p[M.P_K1], p[M.P_K2], p[M.P_K3]) > 0.0
    y = y0.copy()
    y[M.Y_U1], y[M.Y_U2] = 1e-4, -2e-4
    active = set()
    for mode, handover, stuck in _contact_states():
        cs = np.zeros(L.N_CS)
        cs[L.CS_MODE], cs[L.CS_SLAVE_OFF], cs[L.CS_FLOOR] = mode, handover, 1e-12
        cs[L.CS_SIDE] = 1.0
        cs[L.CS_SIG:L.CS_SIG + 3] = [1.0, -1.0, 1.0]
        cs[L.CS_STUCK:L.CS_STUCK + 3] = stuck
        wk, ist = _work()
        dy, aux = np.zeros(M.N_FULL), np.zeros(M.N_AUX)
        CR.eval_rhs(0.0, y, _sys(p, cs, M.N_CORE, wk, ist), dy, aux)
        g = np.zeros(L.N_WCOLS)
        ED.event_values(0.0, y, aux, _ev_sys(p, cs), 0.5, g)
        active |= {k for k in range(ID.N_EVENTS) if g[k] != math.inf}
        for k in range(ID.N_EVENTS):
            if not R.reads_forces(k) and g[k] != math.inf:
                assert ED.state_event_value(k, 0.0, y, _ev_sys(p, cs), 0.5) == g[k], k
    assert active == set(range(ID.N_EVENTS))
    cs = np.zeros(L.N_CS)
    cs[L.CS_SIDE] = 1.0
    for k in range(ID.N_EVENT_IDS):
        if not R.reads_forces(k) and ID.EVENTS[k, EV.E_DIP] == EV.D_NONE and k != ID.EV_LEVEL:
            with pytest.raises(ValueError, match="no value of the state alone"):
                ED.state_event_value(k, 0.0, y, _ev_sys(p, cs), 0.5)      # EV_AGAINST*: not event functions
    for k in range(ID.N_EVENT_IDS):
        for mode in (CN.ROLL, CN.SLIDE, CN.SLAVED):
            cs = np.zeros(L.N_CS)
            cs[L.CS_MODE] = mode
            cs[L.CS_SIDE] = 1.0
            cs[L.CS_SIG:L.CS_SIG + 3] = [1.0, -1.0, 1.0]
            wk, ist = _work()
            yk = y.copy()
            sys = _sys(p, cs, M.N_CORE, wk, ist)
            if k == ID.EV_LEVEL:
                with pytest.raises(ValueError, match="no discrete update"):
                    ED.apply_event(k, 0.0, yk, sys, np.zeros(L.N_FSTATS))
            else:
                code = ED.apply_event(k, 0.0, yk, sys, np.zeros(L.N_FSTATS))
                assert code == -1 or code in oc.NAMES, (k, mode, code)


def test_a_slaved_slips_end_reads_the_slaved_direction_at_the_state(setup):
    """EV_SLIP_STOP, u.s(nu) = 0, reads nu at the state where it is evaluated: the slaved direction
    that the right-hand side finds there (aux[X_NU] + aux[X_LAG]), not the direction stored in cs[CS_NU], which
    the kernel sets at a step end (where the step size puts it). Stored directions on either side
    of the root give the same value, u.s at the root."""
    p, y0, cs0 = setup
    n = M.N_CORE
    wk, ist = _work()
    sl = cs0.copy()
    sl[L.CS_MODE] = CN.SLAVED
    u = 1e-9
    root = SL.attracting_direction(0.3, u, 0.0, y0, _sys(p, sl, n, wk, ist))
    assert math.isfinite(root)
    # the slip vector a little off the root (its component across s is what the impulse removes)
    y = y0.copy()
    y[M.Y_U1], y[M.Y_U2] = u * math.cos(root + 0.2), u * math.sin(root + 0.2)
    values = []
    for stored in (root - 0.02, root + 0.02):
        cs = sl.copy()
        cs[L.CS_NU] = stored
        dy, aux, g = np.zeros(M.N_FULL), np.zeros(M.N_AUX), np.zeros(L.N_WCOLS)
        CR.eval_rhs(0.0, y, _sys(p, cs, n, wk, ist), dy, aux)
        assert aux[M.X_OK] == 1.0
        ED.event_values(0.0, y, aux, _ev_sys(p, cs), math.nan, g)
        values.append(g[ID.EV_SLIP_STOP])
        # the stored direction would have given another value
        assert abs(y[M.Y_U1] * math.cos(stored) + y[M.Y_U2] * math.sin(stored) - g[ID.EV_SLIP_STOP]) > 1e-3 * u
    sl[L.CS_NU] = root
    nu, lag, _, ok, _ = CR.slaved_slip(root, L.Eval(0.0, y, _sys(p, sl, n, wk, ist), np.zeros(M.N_FULL), np.zeros(M.N_AUX)))
    assert ok == 1.0
    # the slip along the friction's direction: the quasi-static one plus its lag (docs/model.md, 'Slow slip')
    expected = y[M.Y_U1] * math.cos(nu + lag) + y[M.Y_U2] * math.sin(nu + lag)
    assert values[0] == pytest.approx(expected, rel=1e-12, abs=1e-24)
    assert values[1] == pytest.approx(expected, rel=1e-12, abs=1e-24)


def test_an_update_that_leaves_a_slaved_slip_past_its_exit_hands_it_to_slide(setup):
    """contact.settle_event: EV_SLIP_FAST (|u| rising to SLAVE_EXIT times the slaving speed) is a
    crossing from > 0 to <= 0, so a slaved slip that a discrete update leaves at or past it (the
    stop at spin_tol moves the slip by O(spin_tol)) could never leave SLAVED; the update hands it
    to SLIDE, with the hand-over re-armed. Just short of the surface it stays slaved."""
    p, y0, cs0 = setup
    n = M.N_CORE
    wk, ist = _work()
    sl = cs0.copy()
    sl[L.CS_MODE] = CN.SLAVED
    root = SL.attracting_direction(0.3, 1e-9, 0.0, y0, _sys(p, sl, n, wk, ist))
    assert math.isfinite(root)
    sl[L.CS_NU] = root
    # the exit speed at the state (the slaving speed reads Phi, which the slip's size hardly moves)
    y = y0.copy()
    y[M.Y_U1], y[M.Y_U2] = 1e-9 * math.cos(root), 1e-9 * math.sin(root)
    dy, aux = np.zeros(M.N_FULL), np.zeros(M.N_AUX)
    CR.eval_rhs(0.0, y, _sys(p, sl.copy(), n, wk, ist), dy, aux)
    u_exit = CR.exit_speed(y, aux, p)
    for factor, mode in ((1.001, CN.SLIDE), (0.999, CN.SLAVED)):
        y = y0.copy()
        # the slip a little off the slaved direction, as the integrated slip vector is
        y[M.Y_U1], y[M.Y_U2] = factor * u_exit * math.cos(root + 0.01), factor * u_exit * math.sin(root + 0.01)
        cs = sl.copy()
        CR.eval_rhs(0.0, y, _sys(p, cs, n, wk, ist), dy, aux)
        g = np.zeros(L.N_WCOLS)
        ED.event_values(0.0, y, aux, _ev_sys(p, cs), math.nan, g)
        assert (g[ID.EV_SLIP_FAST] <= 0.0) == (mode == CN.SLIDE), (factor, g[ID.EV_SLIP_FAST])
        code = ER.settle_event(0.0, y, _sys(p, cs, n, wk, ist), M.moment_axes_rates(y), -1)
        assert code == -1
        assert cs[L.CS_MODE] == mode, factor
        assert cs[L.CS_SLAVE_OFF] == CN.HANDOVER_ARMED
        assert math.hypot(y[M.Y_U1], y[M.Y_U2]) == pytest.approx(factor * u_exit, rel=1e-15)


def test_an_impulse_releases_a_stuck_component_only_beyond_spin_tol(setup):
    """contact.release_moved: a held omega.a_i moved by an impulse by more than spin_tol is free,
    with the sign of its new rate; a move within spin_tol (the round-off of a tiny impulse) leaves
    it stuck; with spin_tol = 0 any move releases it."""
    p0, y0, _ = setup
    w_tol = 1e-7 * 0.0375   # dimensionless, of the order of the default for a cm-sized disk
    for spin_tol, move, released in ((w_tol, 1e-16, False), (w_tol, 0.5 * w_tol, False),
                                     (w_tol, 2.0 * w_tol, True), (w_tol, -2.0 * w_tol, True),
                                     (0.0, 1e-16, True), (w_tol, 0.0, False)):
        p = p0.copy()
        p[M.P_WTOL] = spin_tol
        y = y0.copy()
        y[M.Y_W1] = 0.0                      # omega.a_1 = omega_1, held at 0
        cs = np.zeros(L.N_CS)
        cs[L.CS_SIDE] = 1.0
        cs[L.CS_SIG:L.CS_SIG + 3] = [-1.0, 1.0, 1.0]
        cs[L.CS_STUCK] = 1.0
        g_before = M.moment_axes_rates(y)
        y[M.Y_W1] += move
        MO.release_moved(y, p, cs, g_before)
        assert (cs[L.CS_STUCK] == 0.0) == released, (spin_tol, move)
        if released and move != 0.0:
            assert cs[L.CS_SIG] == math.copysign(1.0, move)
        assert cs[L.CS_STUCK + 1] == 0.0 and cs[L.CS_STUCK + 2] == 0.0


def test_next_try_clips_at_t_max_and_stops_only_on_budget_floor_or_after_the_end():
    """integrate.next_try: the try's size and the loop's stops, each from its documented rule."""
    from sweep import outcomes as oc
    from sweep.core.constants import EPS
    from sweep.core.integrate import next_try

    consts = _consts(t_max=100.0, max_steps=50)
    wk, istats = _work()
    work = I.work_arrays()

    assert next_try(10.0, 0.5, -1, consts, work, istats) == (0.5, -1, False, False)
    # a try past t_max ends there exactly
    assert next_try(99.75, 0.5, -1, consts, work, istats) == (0.25, -1, True, False)
    # the smallest step that moves tau is 2 eps tau: under it the scene ends, at t_max as T_MAX
    t_near = 100.0 - EPS * 100.0
    h, outcome, at_tmax, stop = next_try(t_near, 0.5, -1, consts, work, istats)
    assert (outcome, at_tmax, stop) == (oc.T_MAX, True, True) and h == 100.0 - t_near
    # (t_max is where the motion ends: the frequency windows still open keep their symmetric part)
    assert not work.trk.ends.cut[0]
    # ... elsewhere as STEP_SIZE_UNDERFLOW (nothing in the model decides by the step size), a
    # numerical stop: the windows still open get no value
    assert next_try(10.0, 1.5 * EPS * 10.0, -1, consts, work, istats)[1:] == (oc.STEP_SIZE_UNDERFLOW, False, True)
    assert work.trk.ends.cut[0]
    I.clear_tracking(work.trk)
    assert next_try(10.0, 2.5 * EPS * 10.0, -1, consts, work, istats)[1:] == (-1, False, False)
    # the step budget counts accepted and rejected tries; it stops the steps after the end too
    istats[L.I_STEPS], istats[L.I_REJECTED] = 30, 20
    assert next_try(10.0, 0.5, -1, consts, work, istats)[1:] == (oc.STEP_LIMIT, False, True)
    assert work.trk.ends.cut[0]
    I.clear_tracking(work.trk)
    assert next_try(10.0, 0.5, oc.HALTED, consts, work, istats)[1:] == (oc.HALTED, False, True)
    assert work.trk.ends.cut[0]
    istats[L.I_STEPS] = 0
    I.clear_tracking(work.trk)
    # after a halt (at tau 40): the steps that complete the frequency windows, no longer than the last one,
    # and none past twice the end's tau, nor past t_max
    after = work.trk.ends.after
    assert next_try(40.0, 0.5, oc.HALTED, consts, work, istats) == (0.5, oc.HALTED, False, False)
    assert after[L.EA_H_AFTER] == 0.5 and after[L.EA_T_AFTER] == 80.0
    assert next_try(60.0, 4.0, oc.HALTED, consts, work, istats) == (0.5, oc.HALTED, False, False)
    assert next_try(99.9, 0.2, oc.HALTED, consts, work, istats) == (-1.0, oc.HALTED, False, True)
    # twice the end's tau is where the motion after it ends, not a numerical stop
    assert not work.trk.ends.cut[0]
    # ... while the halt fit waits for a level below the last one, they go on past it, up to t_max
    work.trk.track.fit[L.FT_DEEP_E] = 1e-3
    assert next_try(90.0, 0.2, oc.HALTED, consts, work, istats) == (0.2, oc.HALTED, False, False)
    assert next_try(99.9, 0.2, oc.HALTED, consts, work, istats)[0] == pytest.approx(0.1)
    assert next_try(100.0, 0.2, oc.HALTED, consts, work, istats) == (-1.0, oc.HALTED, False, True)
