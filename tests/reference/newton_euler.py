"""Independent world-frame Newton-Euler reference for the Kessler & O'Reilly (2002) disk.

Nothing here is taken from ``sweep.core.model``'s equations: the body is described by a rotation
matrix built from the 3-1-2 Euler angles, the balances of linear and angular momentum are written
with world-frame vectors (inertia tensor I_w = Q I_body Q^T), and all contact reactions (normal
force, friction, the magnitudes of "stuck" dry-friction moment components) are solved together
with the accelerations as ONE small linear system. Everything is in SI units with arbitrary
m, R, g; only the final outputs are made dimensionless (tau = t/chi, omega_hat = chi omega,
u_hat = chi u/R, Phi = chi^2 N/(m R), energy chi^2 E/(m R^2)).

Conventions (paper eq. 2.1): E fixed, a = Rz(theta) E, e = a turned by alpha about a1,
body = e turned by psi about e2. e2 is the symmetry axis, e3 lies in the disk plane, e1 = a1 is
horizontal. The contact point is at r = -H e2 - R e3 from the centre, H = (L/2) sign(alpha)
(sign chosen by the caller as ``side``).

Rolling constraint. The material point at the contact has velocity v_P = v + omega x r(t) where
r(t) = -H e2(t) - R e3(t) is the (moving) geometric contact point. Rolling means v_P(t) = 0 for
all t, so its derivative vanishes:  a + alpha_w x r + omega x dr/dt = 0.  This differs from the
acceleration of the material point, a + alpha_w x r + omega x (omega x r), which is not zero.
dr/dt is obtained by differentiating the rotation matrices with respect to theta and alpha.
Sliding constraint: the vertical component of the same expression is zero (second derivative of
the contact point's height; (omega - Omega_e) x r is horizontal, so v_P.E3 = d(r.E3)/dt + v.E3).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

E3 = np.array([0.0, 0.0, 1.0])


# ----------------------------------------------------------------------------------------------
# kinematics
# ----------------------------------------------------------------------------------------------
def _rz(t):
    c, s = np.cos(t), np.sin(t)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _drz(t):
    c, s = np.cos(t), np.sin(t)
    return np.array([[-s, -c, 0.0], [c, -s, 0.0], [0.0, 0.0, 0.0]])


def _rx(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def _drx(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[0.0, 0.0, 0.0], [0.0, -s, -c], [0.0, c, -s]])


def _ry(p):
    c, s = np.cos(p), np.sin(p)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def _skew(x):
    return np.array([[0.0, -x[2], x[1]], [x[2], 0.0, -x[0]], [-x[1], x[0], 0.0]])


@dataclass
class Disk:
    """SI description of the body and its contact laws."""
    m: float
    R: float
    L: float
    g: float
    kshape: float      # k^2 of eq. (2.4): 1 solid cylinder, 2 thin shell
    k: tuple            # (k1, k2, k3) lengths (m): moment magnitude k_i |N|
    mu_d: float

    @property
    def I1(self):
        return self.m * (self.R ** 2 * self.kshape / 4.0 + self.L ** 2 / 12.0)

    @property
    def I2(self):
        return self.m * self.R ** 2 * self.kshape / 2.0

    @property
    def chi(self):
        return np.sqrt((self.kshape + 4.0) / 4.0 * self.R / self.g)


@dataclass
class WorldState:
    theta: float
    alpha: float
    psi: float
    side: float
    A: np.ndarray        # columns a1, a2, a3
    Ef: np.ndarray       # columns e1, e2, e3
    Q: np.ndarray        # body rotation (columns: body axes)
    dA: np.ndarray       # d/dt of A
    dEf: np.ndarray      # d/dt of Ef
    omega: np.ndarray    # world angular velocity
    v: np.ndarray        # centre velocity
    r: np.ndarray        # contact point relative to centre
    rdot: np.ndarray     # d r / dt (moving contact point)
    vP: np.ndarray       # velocity of the material point at the contact
    Iw: np.ndarray       # world inertia tensor about the centre
    rates: np.ndarray    # (theta_dot, alpha_dot, psi_dot)
    H: float


def euler_rates(omega, A, Ef):
    """Solve omega = theta_dot E3 + alpha_dot e1 + psi_dot e2 for the 3-1-2 angle rates."""
    M = np.column_stack([E3, Ef[:, 0], Ef[:, 1]])
    return np.linalg.solve(M, omega)


def world_state(disk: Disk, alpha, omega_e, vP_a, side, theta=0.0, psi=0.0) -> WorldState:
    """World-frame state from SI reduced quantities.

    omega_e: components of omega on e1, e2, e3 (rad/s); vP_a: components of the contact point's
    velocity on a1, a2 (m/s; zero when rolling). The centre velocity follows from v = v_P - omega x r.
    """
    Rz, Rx = _rz(theta), _rx(alpha)
    A = Rz
    Ef = Rz @ Rx
    Q = Ef @ _ry(psi)
    omega = Ef @ np.asarray(omega_e, float)
    rates = euler_rates(omega, A, Ef)
    thd, ald = rates[0], rates[1]
    dA = _drz(theta) * thd
    dEf = _drz(theta) @ Rx * thd + Rz @ _drx(alpha) * ald
    H = 0.5 * disk.L * side
    r = -H * Ef[:, 1] - disk.R * Ef[:, 2]
    rdot = -H * dEf[:, 1] - disk.R * dEf[:, 2]
    vP = vP_a[0] * A[:, 0] + vP_a[1] * A[:, 1]
    v = vP - np.cross(omega, r)
    Iw = Q @ np.diag([disk.I1, disk.I2, disk.I1]) @ Q.T
    return WorldState(theta, alpha, psi, side, A, Ef, Q, dA, dEf, omega, v, r, rdot, vP, Iw,
                      rates, H)


# ----------------------------------------------------------------------------------------------
# dynamics: one linear system for accelerations and reactions
# ----------------------------------------------------------------------------------------------
def solve(disk: Disk, ws: WorldState, rolling: bool, sigma, stuck, n_dir=None):
    """Accelerations and contact reactions.

    sigma[i]: sign used in M_f for a non-stuck component (M_f = -sum k_i N sigma_i a_i, N > 0
    assumed, which the caller checks). stuck[i]: the moment component on a_i is an unknown
    magnitude mu_i (M_f += -mu_i a_i) fixed by d/dt(omega.a_i) = 0.
    n_dir: unit slip direction (world) used when sliding; default v_P/|v_P|.

    Unknowns: acc (3), alpha_w (3), N, [F1, F2 on a1, a2 if rolling], [mu_i for stuck i].
    """
    m, g = disk.m, disk.g
    A, r, om, Iw = ws.A, ws.r, ws.omega, ws.Iw
    stuck_idx = [i for i in range(3) if stuck[i]]
    nF = 2 if rolling else 0
    n = 7 + nF + len(stuck_idx)
    if not rolling:
        if n_dir is None:
            n_dir = ws.vP / np.linalg.norm(ws.vP)
    M = np.zeros((n, n))
    b = np.zeros(n)
    iN = 6
    # linear momentum: m acc - N E3 - F = -m g E3
    M[0:3, 0:3] = m * np.eye(3)
    M[0:3, iN] = -E3
    if not rolling:
        M[0:3, iN] += disk.mu_d * n_dir          # -F = +mu_d N n
    else:
        M[0:3, 7] = -A[:, 0]
        M[0:3, 8] = -A[:, 1]
    b[0:3] = -m * g * E3
    # angular momentum about the centre: Iw alpha_w - r x (N E3 + F) - M_f = -omega x Iw omega
    M[3:6, 3:6] = Iw
    colN = -np.cross(r, E3)
    if not rolling:
        colN += disk.mu_d * np.cross(r, n_dir)
    for i in range(3):
        if not stuck[i]:
            colN += disk.k[i] * sigma[i] * A[:, i]
    M[3:6, iN] = colN
    if rolling:
        M[3:6, 7] = -np.cross(r, A[:, 0])
        M[3:6, 8] = -np.cross(r, A[:, 1])
    for j, i in enumerate(stuck_idx):
        M[3:6, 7 + nF + j] = A[:, i]
    b[3:6] = -np.cross(om, Iw @ om)
    # contact constraint: acc + alpha_w x r + omega x rdot = 0 (all 3 rows rolling, E3 row sliding)
    row = 7 if not rolling else 9
    if rolling:
        M[6:9, 0:3] = np.eye(3)
        M[6:9, 3:6] = -_skew(r)
        b[6:9] = -np.cross(om, ws.rdot)
        row = 9
    else:
        M[6, 0:3] = E3
        M[6, 3:6] = -(E3 @ _skew(r))
        b[6] = -E3 @ np.cross(om, ws.rdot)
        row = 7
    # stuck components: d/dt(omega . a_i) = alpha_w . a_i + omega . da_i/dt = 0
    for i in stuck_idx:
        M[row, 3:6] = A[:, i]
        b[row] = -om @ ws.dA[:, i]
        row += 1
    # equilibrate rows and columns (the SI unknowns have very different units)
    rs = 1.0 / np.max(np.abs(M), axis=1)
    Ms = M * rs[:, None]
    cs = 1.0 / np.max(np.abs(Ms), axis=0)
    Ms = Ms * cs[None, :]
    x = np.linalg.solve(Ms, b * rs) * cs
    acc, alw, N = x[0:3], x[3:6], x[6]
    if rolling:
        F = x[7] * A[:, 0] + x[8] * A[:, 1]
    else:
        F = -disk.mu_d * N * n_dir
    sig_eff = np.array(sigma, float).copy()
    Mf = np.zeros(3)
    for i in range(3):
        if not stuck[i]:
            Mf -= disk.k[i] * sigma[i] * N * A[:, i]
    for j, i in enumerate(stuck_idx):
        mu = x[7 + nF + j]
        Mf -= mu * A[:, i]
        sig_eff[i] = mu / (disk.k[i] * N) if disk.k[i] * N != 0.0 else np.nan
    return dict(acc=acc, alpha_w=alw, N=N, F=F, Mf=Mf, sigma=sig_eff, cond=np.linalg.cond(Ms))


def derivatives(disk: Disk, ws: WorldState, sol):
    """SI time derivatives of the reduced variables from the world-frame solution.

    d(alpha)/dt, d(omega . e_i)/dt (components on the rotating e-frame), d(v_P . a_beta)/dt,
    theta_dot, psi_dot, and the contact power terms.
    """
    om, acc, alw = ws.omega, sol["acc"], sol["alpha_w"]
    dwe = np.array([alw @ ws.Ef[:, i] + om @ ws.dEf[:, i] for i in range(3)])
    dvP = acc + np.cross(alw, ws.r) + np.cross(om, ws.rdot)
    du = np.array([dvP @ ws.A[:, j] + ws.vP @ ws.dA[:, j] for j in range(2)])
    g = np.array([om @ ws.A[:, i] for i in range(3)])
    # power of each dissipative mechanism (positive when dissipating)
    p_slide = -sol["F"] @ ws.vP
    p_k = np.array([disk.k[i] * sol["N"] * sol["sigma"][i] * g[i] for i in range(3)])
    # dE/dt from the accelerations (d Iw/dt contributes omega.(omega x Iw omega)/2 = 0)
    dEdt = disk.m * ws.v @ acc + om @ ws.Iw @ alw + disk.m * disk.g * ws.v[2]
    return dict(dalpha=ws.rates[1], dwe=dwe, du=du, g=g, thd=ws.rates[0], psid=ws.rates[2],
                p_slide=p_slide, p_k=p_k, dEdt=dEdt, dvP=dvP)


def energy(disk: Disk, ws: WorldState):
    """SI energy: kinetic + m g (z_centre - |H|) (zero for the disk lying flat at rest)."""
    z = -ws.r[2]      # the contact point is on the table, z = 0
    return (0.5 * disk.m * ws.v @ ws.v + 0.5 * ws.omega @ ws.Iw @ ws.omega
            + disk.m * disk.g * (z - abs(ws.H)))


def kinetic(disk: Disk, v, omega, Iw):
    return 0.5 * disk.m * v @ v + 0.5 * omega @ Iw @ omega


def plastic_impulse(disk: Disk, ws_old: WorldState, side_new, rolling_new):
    """Perfectly plastic impulse at the new contact point (world frame).

    m (v+ - v-) = P, Iw (w+ - w-) = r x P; rolling: v+ + w+ x r = 0 (P has 3 components);
    sliding: P = p E3 (no tangential impulse) and (v+ + w+ x r) . E3 = 0.
    Returns v+, w+, the new contact vector r and the kinetic energy lost.
    """
    H = 0.5 * disk.L * side_new
    Ef = ws_old.Ef
    r = -H * Ef[:, 1] - disk.R * Ef[:, 2]
    Iw, m = ws_old.Iw, disk.m
    nP = 3 if rolling_new else 1
    n = 6 + nP
    M = np.zeros((n, n))
    b = np.zeros(n)
    M[0:3, 0:3] = m * np.eye(3)
    M[3:6, 3:6] = Iw
    b[0:3] = m * ws_old.v
    b[3:6] = Iw @ ws_old.omega
    if rolling_new:
        M[0:3, 6:9] = -np.eye(3)
        M[3:6, 6:9] = -_skew(r)
        M[6:9, 0:3] = np.eye(3)
        M[6:9, 3:6] = -_skew(r)
    else:
        M[0:3, 6] = -E3
        M[3:6, 6] = -np.cross(r, E3)
        M[6, 0:3] = E3
        M[6, 3:6] = -(E3 @ _skew(r))
    rs = 1.0 / np.max(np.abs(M), axis=1)
    Ms = M * rs[:, None]
    cs = 1.0 / np.max(np.abs(Ms), axis=0)
    x = np.linalg.solve(Ms * cs[None, :], b * rs) * cs
    vn, wn = x[0:3], x[3:6]
    loss = kinetic(disk, ws_old.v, ws_old.omega, Iw) - kinetic(disk, vn, wn, Iw)
    return vn, wn, r, loss


# ----------------------------------------------------------------------------------------------
# conversion to/from the model's dimensionless reduced variables
# ----------------------------------------------------------------------------------------------
def from_reduced(disk: Disk, y, side, rolling, theta=0.0, psi=0.0) -> WorldState:
    """World state from the model's dimensionless y (alpha, omega_hat 1..3, u_hat 1..2)."""
    chi = disk.chi
    w = np.array([y[1], y[2], y[3]]) / chi
    if rolling:
        u = np.zeros(2)
    else:
        u = np.array([y[4], y[5]]) * disk.R / chi
    return world_state(disk, y[0], w, u, side, theta, psi)


def reduced_outputs(disk: Disk, ws: WorldState, sol, der):
    """Dimensionless counterparts of model.rhs's dy[0:10], dy[10:14] rates and aux."""
    chi, m, R = disk.chi, disk.m, disk.R
    pw = chi ** 3 / (m * R * R)
    dy = np.empty(14)
    dy[0] = chi * der["dalpha"]
    dy[1:4] = chi ** 2 * der["dwe"]
    dy[4:6] = chi ** 2 / R * der["du"]
    dy[6] = pw * der["p_slide"]
    dy[7:10] = pw * der["p_k"]
    dy[10] = chi * der["thd"]
    dy[11] = chi * der["psid"]
    dy[12:14] = chi / R * ws.v[0:2]          # world-frame centre velocity, lengths in R
    aux = np.empty(9)
    aux[0] = chi ** 2 * sol["N"] / (m * R)
    aux[1] = chi ** 2 * (sol["F"] @ ws.A[:, 0]) / (m * R)
    aux[2] = chi ** 2 * (sol["F"] @ ws.A[:, 1]) / (m * R)
    aux[3:6] = sol["sigma"]
    aux[6:9] = chi * der["g"]
    return dy, aux


def energy_hat(disk: Disk, ws: WorldState):
    return disk.chi ** 2 * energy(disk, ws) / (disk.m * disk.R ** 2)


def dEdtau_hat(disk: Disk, der):
    return disk.chi ** 3 * der["dEdt"] / (disk.m * disk.R ** 2)
