"""Verify sweep.core.model against an independent world-frame Newton-Euler formulation.

The reference (tests/reference/newton_euler.py) works in SI units with random m, R, g and a
random body orientation (theta, psi), solves accelerations and contact reactions as one linear
system, and only then converts to the model's dimensionless reduced variables. Agreement is
required to RTOL relative, each difference scaled by 1 + |reference value|.

Tolerances (RTOL = 1e-12). Over 128 000 valid states (8 seeds x 16 mode/stuck combinations)
every derivative, the normal and friction forces, energy, physical velocity and omega.a_i agreed
to <= 1.8e-13 (typically a few 1e-15), so RTOL keeps a margin of ~5.
The effective sign sigma_i of a stuck moment component is a ratio mu_i / (k_i Phi) whose
numerator is a sum of terms of size S ~ 1 + |omega|^2 (1 + |tan alpha|) + Phi; its plain
relative error reached 6.5e-12 at Phi = 3.4e-5 (sigma = 3.5e4) although the moment itself agreed
to ~1e-13 of S. It is therefore compared relative to 1 + |sigma| + S/(k_i Phi) (sigma_error;
worst seen 1.6e-13); the plain relative error is reported as sig*_plain. The power identity is
compared relative to 1 + the sum of the magnitudes of the individual power terms, which cancel.
steady_rolling_w3sq is compared with the reference's zero of d(omega_1)/dtau, whose own error is
amplified near the pole of omega_3^2 by the condition number used there.

Run ``.venv/bin/python -m tests.test_model_equations`` for a table of the maximal errors.
"""
from __future__ import annotations

import math
import time

import numpy as np
import pytest

from tests.reference import newton_euler as ne

from sweep.core import constants as CN
from sweep.core import model as M
from sweep.core import layout as L
from sweep.core.impulse import project_velocity, stop_axis_rate

RTOL = 1e-12
N_VALID = 1000          # valid (den > 0, Phi > 0) states per mode / stuck combination
MAX_SKIP_FRACTION = 0.15
STUCK_SETS = [(), (0,), (1,), (2,), (1, 2), (0, 1), (0, 2), (0, 1, 2)]

DY_NAMES = ["dalpha", "dw1", "dw2", "dw3", "du1", "du2", "P_slide", "P_k1", "P_k2", "P_k3",
            "dtheta", "dpsi", "dx", "dy"]
AUX_NAMES = ["Phi", "F1", "F2", "sig1", "sig2", "sig3", "g1", "g2", "g3"]


# ----------------------------------------------------------------------------------------------
# random cases
# ----------------------------------------------------------------------------------------------
def random_disk(rng, stuckset=()):
    kshape = float(rng.choice([1.0, 2.0]))
    m = 10 ** rng.uniform(-1, 1)
    R = 10 ** rng.uniform(-2, 0)
    g = rng.uniform(1.0, 20.0)
    h = rng.uniform(0.0, 0.5)
    L = 2.0 * h * R
    k = []
    for i in range(3):
        if i in stuckset:
            k.append(rng.uniform(0.005, 0.3) * R)
        else:
            k.append(0.0 if rng.random() < 0.25 else rng.uniform(0.0, 0.3) * R)
    mud = 0.0 if rng.random() < 0.1 else rng.uniform(0.0, 1.0)
    disk = ne.Disk(m, R, L, g, kshape, tuple(k), mud)
    p, chi = M.make_params(kshape, R, L, g, 1.0, mud, (k[0], k[1], k[2]))
    return disk, p, chi


def random_alpha(rng, lo=0.02, hi=1.55):
    return rng.uniform(lo, hi) * rng.choice([-1.0, 1.0])


def random_state(rng, rolling, alpha):
    """Dimensionless state with kinematics (theta random); psi returned separately."""
    y = np.zeros(M.N_FULL)
    y[M.Y_ALPHA] = alpha
    y[M.Y_W1:M.Y_W3 + 1] = rng.normal(0.0, 1.0, 3) * 10 ** rng.uniform(-1.3, 0.2)
    if not rolling:
        y[M.Y_U1:M.Y_U2 + 1] = rng.normal(0.0, 1.0, 2) * 10 ** rng.uniform(-2, 0.3)
    y[M.Y_THETA] = rng.uniform(-math.pi, math.pi)
    y[M.Y_PSI] = rng.uniform(-math.pi, math.pi)
    return y


def _rel(a, b):
    return np.abs(np.asarray(a) - np.asarray(b)) / (1.0 + np.abs(np.asarray(b)))


def sigma_error(sig_model, sig_ref, k, phi, y, p, rolling):
    """Error of the effective sign of a stuck moment component, relative to what is resolvable.

    sigma_i = mu_i / (k_i Phi), where the moment magnitude mu_i (dimensionless) is the sum of
    terms of size S = 1 + (|omega|^2 + |u| |omega|) (1 + |tan alpha|) + Phi (1 + mu_d)
    (gravity, gyroscopic and rate-of-frame terms, friction). In floating point mu_i is known to
    ~eps S absolutely, so sigma_i to ~eps S / (k_i Phi): when Phi or k_i is small, sigma_i is large
    and only its leading digits are meaningful (observed: relative error 6.5e-12 at Phi = 3.4e-5,
    sigma = 3.5e4, while the moment agreed to 5e-14 of S). The error is therefore scaled by
    1 + |sigma| + S / (k_i Phi).
    """
    w = y[M.Y_W1:M.Y_W3 + 1]
    wn2 = float(w @ w)
    un = 0.0 if rolling else math.hypot(y[M.Y_U1], y[M.Y_U2])
    S = 1.0 + (wn2 + un * math.sqrt(wn2)) * (1.0 + abs(math.tan(y[M.Y_ALPHA]))) \
        + abs(phi) * (1.0 + p[M.P_MUD])
    return abs(sig_model - sig_ref) / (1.0 + abs(sig_ref) + S / (k * abs(phi)))


def reference_rhs(disk, y, side, rolling, sig, stuck, n0):
    ws = ne.from_reduced(disk, y, side, rolling, y[M.Y_THETA], y[M.Y_PSI])
    n_dir = None
    if not rolling and y[M.Y_U1] == 0.0 and y[M.Y_U2] == 0.0:
        n_dir = n0[0] * ws.A[:, 0] + n0[1] * ws.A[:, 1]
    sol = ne.solve(disk, ws, rolling, sig, stuck, n_dir)
    der = ne.derivatives(disk, ws, sol)
    dy, aux = ne.reduced_outputs(disk, ws, sol, der)
    return ws, sol, der, dy, aux, n_dir


# ----------------------------------------------------------------------------------------------
# right-hand side: all modes and stuck combinations
# ----------------------------------------------------------------------------------------------
def rhs_errors(rolling, stuckset, seed, n_valid=N_VALID):
    """Compare model.rhs with the reference at n_valid random states; return max errors."""
    rng = np.random.default_rng(seed)
    mode = CN.ROLL if rolling else CN.SLIDE
    err = {name: 0.0 for name in DY_NAMES + AUX_NAMES}
    err.update(energy=0.0, physical_velocity=0.0, power_identity=0.0, power_ref=0.0,
               core_vs_full=0.0, theta_psi_invariance=0.0, params=0.0)
    stats = dict(drawn=0, valid=0, skip_den=0, skip_phi=0, ok_flag_mismatch=0, zero_slip=0)
    stuck = np.zeros(3, np.int64)
    stuck[list(stuckset)] = 1
    dy = np.zeros(M.N_FULL)
    dy_core = np.zeros(M.N_FULL)
    aux = np.zeros(M.N_AUX)
    pv = np.zeros(6)
    sig_scaled = [0.0, 0.0, 0.0]
    while stats["valid"] < n_valid:
        stats["drawn"] += 1
        assert stats["drawn"] < 2 * n_valid, "too many inconsistent states"
        disk, p, chi = random_disk(rng, stuckset)
        alpha = random_alpha(rng)
        side = math.copysign(1.0, alpha)
        y = random_state(rng, rolling, alpha)
        nu = rng.uniform(-math.pi, math.pi)
        n0 = (math.cos(nu), math.sin(nu))
        if not rolling and rng.random() < 0.1:
            y[M.Y_U1] = y[M.Y_U2] = 0.0     # slip onset: direction from (n0x, n0y)
            stats["zero_slip"] += 1
        ws0 = ne.from_reduced(disk, y, side, rolling, y[M.Y_THETA], y[M.Y_PSI])
        g = [ws0.omega @ ws0.A[:, i] for i in range(3)]
        if len(stuckset) and rng.random() < 0.5:
            # physically a stuck component has omega.a_i = 0: impose it (keeps the non-zero case
            # in the other half, which exercises the terms that multiply omega.a_i)
            w = ws0.omega.copy()
            for i in stuckset:
                w -= (w @ ws0.A[:, i]) * ws0.A[:, i]
            y[M.Y_W1:M.Y_W3 + 1] = chi * (ws0.Ef.T @ w)
            ws0 = ne.from_reduced(disk, y, side, rolling, y[M.Y_THETA], y[M.Y_PSI])
            g = [ws0.omega @ ws0.A[:, i] for i in range(3)]
        sig = np.array([1.0 if gi > 0 else (-1.0 if gi < 0 else float(rng.choice([-1, 1])))
                        for gi in g])

        M.rhs(y, p, M.Contact(mode, side, sig, stuck, n0[0], n0[1]), M.N_FULL, dy, aux)
        ws, sol, der, dyr, auxr, n_dir = reference_rhs(disk, y, side, rolling, sig, stuck, n0)

        # ok flag: den > 0 <=> the normal force increases with gravity (N is affine in g)
        disk2 = ne.Disk(disk.m, disk.R, disk.L, 2.0 * disk.g, disk.kshape, disk.k, disk.mu_d)
        N2 = ne.solve(disk2, ws, rolling, sig, stuck, n_dir)["N"]
        ok_ref = N2 > sol["N"]
        if ok_ref != (aux[M.X_OK] == 1.0):
            stats["ok_flag_mismatch"] += 1
        if aux[M.X_OK] != 1.0:
            stats["skip_den"] += 1
            continue
        if aux[M.X_PHI] <= 0.0:
            stats["skip_phi"] += 1
            continue
        stats["valid"] += 1

        for j, name in enumerate(DY_NAMES):
            err[name] = max(err[name], _rel(dy[j], dyr[j]))
        for j, name in enumerate(AUX_NAMES):
            err[name] = max(err[name], _rel(aux[j], auxr[j]))
        # a stuck sigma_i is a ratio moment / (k_i Phi): compare it as in sigma_error; the plain
        # relative error is only reported
        for i in stuckset:
            name = f"sig{i + 1}"
            err[name + "_plain"] = max(err.get(name + "_plain", 0.0),
                                       _rel(aux[M.X_SIG1 + i], auxr[3 + i]))
            sig_scaled[i] = max(sig_scaled[i], sigma_error(aux[M.X_SIG1 + i], auxr[3 + i],
                                                           p[M.P_K1 + i], auxr[0], y, p, rolling))
            err[name] = sig_scaled[i]

        # N_CORE call fills the same first 10 derivatives
        dy_core[:] = np.nan
        M.rhs(y, p, M.Contact(mode, side, sig, stuck, n0[0], n0[1]), M.N_CORE, dy_core, aux)
        err["core_vs_full"] = max(err["core_vs_full"],
                                  np.max(np.abs(dy_core[:M.N_CORE] - dy[:M.N_CORE])))

        # energy and physical velocity
        err["energy"] = max(err["energy"], _rel(M.energy(y, p, side, mode), ne.energy_hat(disk, ws)))
        M.physical_velocity(y, p, side, mode, pv)
        ref_pv = np.concatenate([chi / disk.R * (ws.Ef.T @ ws.v), chi * (ws.Ef.T @ ws.omega)])
        err["physical_velocity"] = max(err["physical_velocity"], np.max(_rel(pv, ref_pv)))

        # power identity: dE/dtau (reference energy, reference accelerations) = -sum dy[6:10]
        sc = chi ** 3 / (disk.m * disk.R ** 2)
        terms = [disk.m * ws.v @ sol["acc"], ws.omega @ ws.Iw @ sol["alpha_w"],
                 disk.m * disk.g * ws.v[2]]
        scale = 1.0 + sc * sum(abs(t) for t in terms)
        dEdtau = ne.dEdtau_hat(disk, der)
        err["power_identity"] = max(err["power_identity"],
                                    abs(dEdtau + np.sum(dy[M.Y_DSLIDE:M.Y_DK3 + 1])) / scale)
        err["power_ref"] = max(err["power_ref"],
                               abs(dEdtau + sc * (der["p_slide"] + np.sum(der["p_k"]))) / scale)

        # the reference must not depend on theta and psi (checked on a subset)
        if stats["valid"] % 10 == 0:
            y2 = y.copy()
            y2[M.Y_THETA] = rng.uniform(-math.pi, math.pi)
            y2[M.Y_PSI] = rng.uniform(-math.pi, math.pi)
            _, _, _, dyr2, auxr2, _ = reference_rhs(disk, y2, side, rolling, sig, stuck, n0)
            d = np.concatenate([_rel(dyr2[:M.N_CORE], dyr[:M.N_CORE]), _rel(auxr2[:3], auxr[:3]),
                                _rel(auxr2[6:], auxr[6:]), _rel(dyr2[11], dyr[11])[None]])
            d = np.append(d, [sigma_error(auxr2[3 + i], auxr[3 + i], p[M.P_K1 + i], auxr[0],
                                          y, p, rolling) for i in stuckset])
            err["theta_psi_invariance"] = max(err["theta_psi_invariance"], np.max(d))

        # parameter vector (eq. 2.4, 4.5)
        d = [_rel(chi, disk.chi), _rel(p[M.P_A], disk.I1 / (disk.m * disk.R ** 2)),
             _rel(p[M.P_C], disk.I2 / (disk.m * disk.R ** 2)),
             _rel(p[M.P_G], disk.g * disk.chi ** 2 / disk.R),
             _rel(p[M.P_H], disk.L / (2 * disk.R))]
        d += [_rel(p[M.P_K1 + i], disk.k[i] / disk.R) for i in range(3)]
        err["params"] = max(err["params"], max(d))
    return err, stats


# Every mode (ROLL, SLIDE) with every subset of the three moment components stuck: 16 right-hand
# sides. The fast tier (`python3 run.py test`) checks each at N_VALID_FAST states (~0.25 s each),
# the whole suite (`--all`) each at N_VALID more, drawn from other seeds.
N_VALID_FAST = 200
RHS_COMBINATIONS = [(rolling, stuckset) for stuckset in STUCK_SETS for rolling in (True, False)]


def _rhs_id(rolling, stuckset):
    return ("roll" if rolling else "slide") + "-" + ("stuck" + "".join(str(i + 1) for i in stuckset) if stuckset else "free")


RHS_CASES = [pytest.param(rolling, stuckset, N_VALID_FAST, 50000, id=_rhs_id(rolling, stuckset) + "-fast")
             for rolling, stuckset in RHS_COMBINATIONS]
RHS_CASES += [pytest.param(rolling, stuckset, N_VALID, 0, marks=pytest.mark.slow, id=_rhs_id(rolling, stuckset))
              for rolling, stuckset in RHS_COMBINATIONS]


@pytest.mark.parametrize("rolling, stuckset, n_valid, seed_offset", RHS_CASES)
def test_rhs_against_newton_euler(rolling, stuckset, n_valid, seed_offset):
    seed = seed_offset + 1000 + 100 * int(rolling) + sum(1 << i for i in stuckset)
    err, stats = rhs_errors(rolling, stuckset, seed, n_valid)
    skipped = stats["skip_den"] + stats["skip_phi"]
    print(f"\n{'roll' if rolling else 'slide'} stuck={stuckset}: {stats}")
    print("  " + ", ".join(f"{k}={v:.1e}" for k, v in err.items()))
    assert stats["valid"] >= n_valid
    assert skipped / stats["drawn"] < MAX_SKIP_FRACTION
    assert stats["ok_flag_mismatch"] == 0
    bad = {k: v for k, v in err.items() if not k.endswith("_plain") and not v <= RTOL}
    assert not bad, f"disagreement with the Newton-Euler reference: {bad}"


# ----------------------------------------------------------------------------------------------
# the reference's own geometric ingredients
# ----------------------------------------------------------------------------------------------
def test_reference_contact_geometry():
    """Checks of the reference itself, independent of the model.

    r = -H e2 - R e3 is the lowest point of the body (sampled on both rim circles); dr/dt and
    da_i/dt agree with central differences of the angles; omega - Omega_e is along e2 and
    (omega - Omega_e) x r is horizontal (so v_P.E3 = d/dt(height of the contact point)); the
    rolling constraint a + alpha_w x r + omega x dr/dt = 0 is d/dt of v_P = v + omega x r(t) = 0:
    checked by a central difference of v_P along the first-order motion.
    """
    rng = np.random.default_rng(3)
    phis = np.linspace(0.0, 2 * math.pi, 721)
    for _ in range(200):
        disk, p, chi = random_disk(rng)
        alpha = random_alpha(rng)
        side = math.copysign(1.0, alpha)
        rolling = bool(rng.random() < 0.5)
        y = random_state(rng, rolling, alpha)
        ws = ne.from_reduced(disk, y, side, rolling, y[M.Y_THETA], y[M.Y_PSI])
        # lowest point
        e1, e2, e3 = ws.Ef.T
        for face in (-0.5 * disk.L, 0.5 * disk.L):
            rim = (face * e2[:, None] + disk.R * (np.cos(phis) * e1[:, None] + np.sin(phis) * e3[:, None]))
            assert np.min(rim[2]) >= ws.r[2] - 1e-12 * disk.R
        # angle rates: omega = thd E3 + ald e1 + psid e2
        thd, ald, psid = ws.rates
        assert np.allclose(thd * ne.E3 + ald * e1 + psid * e2, ws.omega, rtol=0, atol=1e-12 * np.linalg.norm(ws.omega))
        Om_e = thd * ne.E3 + ald * e1
        assert abs(np.cross(ws.omega - Om_e, ws.r)[2]) <= 1e-12 * disk.R * np.linalg.norm(ws.omega)
        # central differences of r and a_i along (theta, alpha)
        dt = 1e-6 / (1.0 + np.linalg.norm(ws.omega))
        wp = ne.world_state(disk, alpha + dt * ald, ws.Ef.T @ ws.omega, (0.0, 0.0), side,
                            ws.theta + dt * thd, ws.psi + dt * psid)
        wm = ne.world_state(disk, alpha - dt * ald, ws.Ef.T @ ws.omega, (0.0, 0.0), side,
                            ws.theta - dt * thd, ws.psi - dt * psid)
        sc = disk.R * (1.0 + np.linalg.norm(ws.omega))
        assert np.allclose((wp.r - wm.r) / (2 * dt), ws.rdot, rtol=0, atol=1e-7 * sc)
        assert np.allclose((wp.A - wm.A) / (2 * dt), ws.dA, rtol=0, atol=1e-7 * (1 + abs(thd)))
        assert np.allclose((wp.Ef - wm.Ef) / (2 * dt), ws.dEf, rtol=0,
                           atol=1e-7 * (1 + abs(thd) + abs(ald)))
        # d v_P/dt from the solution equals the central difference of v + omega x r(t)
        sig = np.ones(3)
        sol = ne.solve(disk, ws, rolling, sig, np.zeros(3, np.int64))
        der = ne.derivatives(disk, ws, sol)
        vpp = ws.v + dt * sol["acc"] + np.cross(ws.omega + dt * sol["alpha_w"], wp.r)
        vpm = ws.v - dt * sol["acc"] + np.cross(ws.omega - dt * sol["alpha_w"], wm.r)
        asc = np.linalg.norm(sol["acc"]) + disk.R * np.linalg.norm(sol["alpha_w"]) + sc * (1 + np.linalg.norm(ws.omega))
        assert np.allclose((vpp - vpm) / (2 * dt), der["dvP"], rtol=0, atol=1e-6 * asc)
        if rolling:
            assert np.max(np.abs(der["dvP"])) <= 1e-12 * asc
        else:
            assert abs(der["dvP"][2]) <= 1e-12 * asc


@pytest.mark.parametrize("rolling", [True, False], ids=["roll", "slide"])
def test_energy_balance_holds_past_the_rim_edge_with_the_side_kept(rolling):
    """A step that overshoots alpha = 0 integrates the contact on the same rim past it (the
    rim-edge event is located afterwards on the dense output). The mode's energy there must be the
    energy of that smooth continuation, so that dE/dtau + sum(dissipated rates) = 0 holds on both
    sides of alpha = 0 (the integrator's energy-balance test rejects every step that crosses
    otherwise). Central differences along the right-hand side, alpha within 0.05 of 0."""
    rng = np.random.default_rng(11)
    dy = np.zeros(M.N_FULL)
    aux = np.zeros(M.N_AUX)
    mode = CN.ROLL if rolling else CN.SLIDE
    worst = 0.0
    n_valid = 0
    for _ in range(400):
        disk, p, chi = random_disk(rng)
        alpha = random_alpha(rng, 1e-4, 0.05)
        side = -math.copysign(1.0, alpha)      # past the edge, on the rim it came from
        y = random_state(rng, rolling, alpha)
        sig = np.array([float(rng.choice([-1.0, 1.0])) for _ in range(3)])
        M.rhs(y, p, M.Contact(mode, side, sig, np.zeros(3, np.int64), 1.0, 0.0), M.N_FULL, dy, aux)
        if aux[M.X_OK] != 1.0 or p[M.P_H] < 0.01:
            continue
        n_valid += 1
        eps = 1e-6 / (1.0 + np.max(np.abs(dy[:6])))
        e_plus = M.energy(y + eps * dy, p, side, mode)
        e_minus = M.energy(y - eps * dy, p, side, mode)
        rate = (e_plus - e_minus) / (2.0 * eps)
        power = np.sum(dy[M.Y_DSLIDE:M.Y_DK3 + 1])
        # the potential's rate alone, the term that a height with |sin(alpha)| gets wrong here
        scale = 1.0 + abs(p[M.P_G] * p[M.P_H] * math.cos(alpha) * y[M.Y_W1]) + abs(power)
        worst = max(worst, abs(rate + power) / scale)
        # at alpha = 0 the two rims are at the same height (the kinetic energies differ: the
        # reduced velocities are taken at different contact points), and on its own rim's side
        # the height is the physical one, cos(alpha) + |h| |sin(alpha)| - |h|
        assert M.height_above_flat(0.0, p[M.P_H]) == M.height_above_flat(0.0, -p[M.P_H])
        a = abs(alpha)
        assert M.height_above_flat(-alpha, side * p[M.P_H]) == pytest.approx(
            math.cos(a) + p[M.P_H] * math.sin(a) - p[M.P_H], rel=1e-13, abs=1e-15)
    assert n_valid > 200
    assert worst < 1e-6, worst


# ----------------------------------------------------------------------------------------------
# plastic projection
# ----------------------------------------------------------------------------------------------
def _ke_dist2(disk, Iw, v1, w1, v2, w2):
    dv, dw = v1 - v2, w1 - w2
    return disk.m * dv @ dv + dw @ Iw @ dw


def test_project_velocity():
    rng = np.random.default_rng(7)
    n_per_combo = 150
    worst = dict(state=0.0, loss=0.0, constraint=0.0, energy_drop=0.0, pythagoras=0.0,
                 physical_velocity=0.0)
    count = 0
    for mode_old in (CN.ROLL, CN.SLIDE):
        for mode_new in (CN.ROLL, CN.SLIDE):
            for flip in (False, True):
                for _ in range(n_per_combo):
                    disk, p, chi = random_disk(rng)
                    if rng.random() < 0.3:
                        alpha = random_alpha(rng, 1e-6, 0.02)   # near the edge change
                    else:
                        alpha = random_alpha(rng)
                    side_old = math.copysign(1.0, alpha)
                    side_new = -side_old if flip else side_old
                    y = random_state(rng, mode_old == CN.ROLL, alpha)
                    y0 = y.copy()
                    ws_old = ne.from_reduced(disk, y0, side_old, mode_old == CN.ROLL,
                                             y0[M.Y_THETA], y0[M.Y_PSI])
                    E_old = M.energy(y0, p, side_old, mode_old)
                    loss = project_velocity(y, p, (side_old, mode_old == CN.SLIDE), (side_new, mode_new == CN.SLIDE),
                                            np.zeros((7, 12)))
                    # the impulse leaves the configuration: compare at the height of side_old (the
                    # two rims' heights differ where alpha != 0, i.e. everywhere but at a real edge change)
                    E_new = (M.energy(y, p, side_new, mode_new)
                             + p[M.P_G] * (M.height_above_flat(alpha, side_old * p[M.P_H])
                                           - M.height_above_flat(alpha, side_new * p[M.P_H])))
                    count += 1

                    vn, wn, r, loss_ref = ne.plastic_impulse(disk, ws_old, side_new,
                                                             mode_new == CN.ROLL)
                    sc = chi ** 2 / (disk.m * disk.R ** 2)
                    # the new reduced state from the reference world velocity
                    yr = y0.copy()
                    yr[M.Y_W1:M.Y_W3 + 1] = chi * (ws_old.Ef.T @ wn)
                    vPn = vn + np.cross(wn, r)
                    if mode_new == CN.SLIDE:
                        yr[M.Y_U1] = chi / disk.R * (vPn @ ws_old.A[:, 0])
                        yr[M.Y_U2] = chi / disk.R * (vPn @ ws_old.A[:, 1])
                    else:
                        yr[M.Y_U1] = yr[M.Y_U2] = 0.0
                    worst["state"] = max(worst["state"], np.max(_rel(y[:6], yr[:6])))
                    assert np.all(y[6:] == y0[6:])
                    worst["loss"] = max(worst["loss"], _rel(loss, sc * loss_ref))
                    assert loss >= -1e-14 * (1 + E_old)
                    # energy never increases, and drops by exactly the returned loss
                    assert E_new <= E_old + 1e-13 * (1 + abs(E_old))
                    worst["energy_drop"] = max(worst["energy_drop"],
                                               abs((E_old - E_new) - loss) / (1 + abs(E_old)))
                    # the model's post-impact velocity (its own physical_velocity, rotated to the
                    # world frame) satisfies the new contact constraint at the new contact point
                    pv = np.zeros(6)
                    M.physical_velocity(y, p, side_new, mode_new, pv)
                    v_m = disk.R / chi * (ws_old.Ef @ pv[:3])
                    w_m = ws_old.Ef @ pv[3:] / chi
                    vP = v_m + np.cross(w_m, r)
                    vscale = 1 + chi / disk.R * (np.linalg.norm(ws_old.v)
                                                 + disk.R * np.linalg.norm(ws_old.omega))
                    res = vP if mode_new == CN.ROLL else vP[2:]
                    worst["constraint"] = max(worst["constraint"],
                                              chi / disk.R * np.max(np.abs(res)) / vscale)
                    ref_pv = np.concatenate([chi / disk.R * (ws_old.Ef.T @ vn),
                                             chi * (ws_old.Ef.T @ wn)])
                    worst["physical_velocity"] = max(worst["physical_velocity"],
                                                     np.max(_rel(pv, ref_pv)))
                    ws_new = ne.from_reduced(disk, y, side_new, mode_new == CN.ROLL,
                                             y0[M.Y_THETA], y0[M.Y_PSI])
                    # closest point in the kinetic-energy metric: for any admissible velocity V',
                    # |V - V'|^2 = |V - V+|^2 + |V+ - V'|^2 (so V+ is the unique minimiser)
                    d_plus = _ke_dist2(disk, ws_old.Iw, ws_old.v, ws_old.omega, ws_new.v, ws_new.omega)
                    for _ in range(3):
                        y3 = random_state(rng, mode_new == CN.ROLL, alpha)
                        ws3 = ne.from_reduced(disk, y3, side_new, mode_new == CN.ROLL,
                                              y0[M.Y_THETA], y0[M.Y_PSI])
                        d3 = _ke_dist2(disk, ws_old.Iw, ws_old.v, ws_old.omega, ws3.v, ws3.omega)
                        d23 = _ke_dist2(disk, ws_old.Iw, ws_new.v, ws_new.omega, ws3.v, ws3.omega)
                        assert d3 >= d_plus
                        worst["pythagoras"] = max(worst["pythagoras"],
                                                  abs(d3 - d_plus - d23) * sc / (1 + sc * d3))
    print("\nproject_velocity:", count, "projections;",
          ", ".join(f"{k}={v:.1e}" for k, v in worst.items()))
    assert count >= 1000
    bad = {k: v for k, v in worst.items() if not v <= RTOL}
    assert not bad, bad


# ----------------------------------------------------------------------------------------------
# steady rolling
# ----------------------------------------------------------------------------------------------
def test_steady_rolling_w3sq():
    rng = np.random.default_rng(11)
    worst_w3sq = 0.0
    worst_w3sq_plain = 0.0
    worst_dw = 0.0
    n_pos = 0
    n = 0
    stuck = np.zeros(3, np.int64)
    sig = np.ones(3)
    while n < 1000:
        kshape = float(rng.choice([1.0, 2.0]))
        R = 10 ** rng.uniform(-2, 0)
        g = rng.uniform(1.0, 20.0)
        h = rng.uniform(0.0, 0.5)
        disk = ne.Disk(10 ** rng.uniform(-1, 1), R, 2 * h * R, g, kshape, (0.0, 0.0, 0.0),
                       rng.uniform(0, 1))
        p, chi = M.make_params(kshape, R, 2 * h * R, g, 1.0, disk.mu_d, (0.0, 0.0, 0.0))
        beta = rng.uniform(0.02, 1.55)
        side = float(rng.choice([-1.0, 1.0]))
        alpha = side * (0.5 * math.pi - beta)
        w3sq = M.steady_rolling_w3sq(beta, p)
        n += 1

        def dw(w3):
            y = np.zeros(M.N_FULL)
            y[M.Y_ALPHA] = alpha
            y[M.Y_W2] = side * h * w3      # centre at rest: omega_2 = h omega_3, h signed
            y[M.Y_W3] = w3
            y[M.Y_THETA] = rng.uniform(-math.pi, math.pi)
            y[M.Y_PSI] = rng.uniform(-math.pi, math.pi)
            ws, sol, der, dyr, auxr, _ = reference_rhs(disk, y, side, True, sig, stuck, (1.0, 0.0))
            assert np.linalg.norm(ws.v) <= 1e-14 * (1 + disk.R * abs(w3 / chi))
            return dyr[M.Y_W1:M.Y_W3 + 1]

        # the reference dw1 is affine in omega_3^2 along the centre-fixed family: solve for its zero
        # Near the pole of w3^2 (C h cos = A sin) d1 - d0 cancels: the reference value carries a
        # relative error ~ eps (|d0| + |d1|) / |d1 - d0|, so the error is divided by that condition
        # number (>= 1).
        d0, d1 = dw(0.0)[0], dw(1.0)[0]
        w3sq_ref = -d0 / (d1 - d0)
        cond = (abs(d0) + abs(d1)) / abs(d1 - d0)
        worst_w3sq = max(worst_w3sq, abs(w3sq - w3sq_ref) / (1 + abs(w3sq_ref)) / max(1.0, cond))
        worst_w3sq_plain = max(worst_w3sq_plain, abs(w3sq - w3sq_ref) / (1 + abs(w3sq_ref)))
        if w3sq > 0:
            n_pos += 1
            for w3 in (math.sqrt(w3sq), -math.sqrt(w3sq)):
                d = dw(w3)
                worst_dw = max(worst_dw, np.max(np.abs(d)) / (1 + w3sq / math.cos(alpha)))
    print(f"\nsteady rolling: {n} states ({n_pos} with w3^2 > 0): w3sq err {worst_w3sq:.1e} "
          f"(not scaled by the condition number: {worst_w3sq_plain:.1e}), "
          f"max |d omega/d tau| {worst_dw:.1e}")
    assert n_pos >= 500
    assert worst_w3sq <= RTOL
    assert worst_dw <= RTOL


if __name__ == "__main__":
    t0 = time.time()
    for rolling in (True, False):
        for st in STUCK_SETS:
            seed = 1000 + 100 * int(rolling) + sum(1 << i for i in st)
            err, stats = rhs_errors(rolling, st, seed)
            print("roll " if rolling else "slide", st, stats)
            print("   ", ", ".join(f"{k}={v:.1e}" for k, v in err.items()))
    print(f"{time.time() - t0:.1f} s")


def _axis_rates(y):
    sa, ca = math.sin(y[M.Y_ALPHA]), math.cos(y[M.Y_ALPHA])
    return np.array([y[M.Y_W1], y[M.Y_W2] * ca - y[M.Y_W3] * sa, y[M.Y_W2] * sa + y[M.Y_W3] * ca])


def _with_axis_rates(y, g):
    """y with omega set from its rates on a1, a2, a3."""
    sa, ca = math.sin(y[M.Y_ALPHA]), math.cos(y[M.Y_ALPHA])
    out = y.copy()
    out[M.Y_W1], out[M.Y_W2], out[M.Y_W3] = g[0], ca * g[1] + sa * g[2], -sa * g[1] + ca * g[2]
    return out


def test_stop_axis_rate_is_the_least_change_that_stops_one_moment_axis():
    """A moment component sticking at spin_tol (impulse.stop_axis_rate): after it omega.a_i = 0,
    every stuck component is at rest (held there up to round-off; here given a small drift), the
    slip stays zero rolling), the energy drops by exactly the returned loss, and the new velocity
    is the closest admissible one in the kinetic-energy metric of the reference Newton-Euler world
    state (Pythagoras against random admissible velocities)."""
    rng = np.random.default_rng(11)
    worst = dict(stopped=0.0, held=0.0, energy_drop=0.0, pythagoras=0.0)
    count = 0
    for rolling in (True, False):
        for i in range(3):
            for stuckset in STUCK_SETS:
                for _ in range(25):
                    disk, p, chi = random_disk(rng)
                    alpha = random_alpha(rng)
                    side = math.copysign(1.0, alpha)
                    y = random_state(rng, rolling, alpha)
                    g0 = _axis_rates(y)
                    g0[i] = rng.normal(0.0, 1e-3)          # a slow component
                    y = _with_axis_rates(y, g0)
                    y0 = y.copy()
                    cs = np.zeros(L.N_CS)
                    cs[L.CS_SIDE] = side
                    cs[L.CS_MODE] = CN.ROLL if rolling else CN.SLIDE
                    for j in stuckset:
                        if j != i:
                            cs[L.CS_STUCK + j] = 1.0
                            g0[j] = rng.normal(0.0, 1e-12)   # a held component's drift
                    y = _with_axis_rates(y, g0)
                    y0 = y.copy()
                    mode = CN.ROLL if rolling else CN.SLIDE
                    E_old = M.energy(y0, p, side, mode)
                    loss = stop_axis_rate(y, p, cs, i, np.zeros((7, 12)))
                    E_new = M.energy(y, p, side, mode)
                    count += 1
                    g1 = _axis_rates(y)
                    scale = 1.0 + np.max(np.abs(g0))
                    worst["stopped"] = max(worst["stopped"], abs(g1[i]) / scale)
                    for j in range(3):
                        if cs[L.CS_STUCK + j] == 1.0:
                            worst["held"] = max(worst["held"], abs(g1[j]) / scale)
                    assert np.all(y[M.Y_ALPHA] == y0[M.Y_ALPHA]) and np.all(y[6:] == y0[6:])
                    assert loss >= 0.0
                    worst["energy_drop"] = max(worst["energy_drop"], abs((E_old - E_new) - loss) / (1 + abs(E_old)))
                    if rolling:
                        assert y[M.Y_U1] == 0.0 and y[M.Y_U2] == 0.0
                    # closest admissible velocity: Pythagoras against random admissible ones
                    ws = ne.from_reduced(disk, y, side, rolling, y0[M.Y_THETA], y0[M.Y_PSI])
                    ws0 = ne.from_reduced(disk, y0, side, rolling, y0[M.Y_THETA], y0[M.Y_PSI])
                    d_plus = _ke_dist2(disk, ws0.Iw, ws0.v, ws0.omega, ws.v, ws.omega)
                    for _ in range(3):
                        y3 = random_state(rng, rolling, alpha)
                        g3 = _axis_rates(y3)
                        g3[i] = 0.0
                        for j in range(3):
                            if cs[L.CS_STUCK + j] == 1.0:
                                g3[j] = 0.0
                        y3 = _with_axis_rates(y3, g3)
                        ws3 = ne.from_reduced(disk, y3, side, rolling, y0[M.Y_THETA], y0[M.Y_PSI])
                        d3 = _ke_dist2(disk, ws0.Iw, ws0.v, ws0.omega, ws3.v, ws3.omega)
                        d23 = _ke_dist2(disk, ws0.Iw, ws.v, ws.omega, ws3.v, ws3.omega)
                        assert d3 >= d_plus * (1 - 1e-12)
                        worst["pythagoras"] = max(worst["pythagoras"], abs(d3 - d_plus - d23) / (d3 + d23 + 1e-300))
    print("\nstop_axis_rate:", count, "stops;", ", ".join(f"{k}={v:.1e}" for k, v in worst.items()))
    assert count >= 1000
    bad = {k: v for k, v in worst.items() if not v <= RTOL}
    assert not bad, bad
