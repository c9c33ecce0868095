"""Flexural modes of a free circular plate: the elastic disk whose ringing `audio.py` synthesises.

Two theories, both exact solutions (Bessel functions) of their equations for a free edge:

* **Kirchhoff** (classical thin plate): w = [J_n(lam r/a) + C I_n(lam r/a)] cos(n phi); the free edge
  (radial moment M_r = 0 and Kirchhoff's effective shear V_r = 0 at r = a) gives the eigenvalues
  lam^2(n, s, nu) of Leissa, *Vibration of Plates* (NASA SP-160, 1969, sec. 2.1.4), and
  f = lam^2 / (2 pi a^2) sqrt(D / (rho h)), D = E h^3 / (12 (1 - nu^2)). Valid for h/a << 1
  (h/a <~ 0.05 within ~1 % for the lowest modes).
* **Mindlin** (shear deformation and rotary inertia, shear coefficient kappa^2 = pi^2/12):
  w = A1 Z_n(d1 r) + A2 Z_n(d2 r), rotations from these and a potential H = A3 Z_n(d3 r) sin(n phi)
  (Deresiewicz & Mindlin 1955); free edge M_r = M_rphi = Q_r = 0 is a 3 x 3 determinant in omega.
  Used for thick disks (h/a up to ~0.5, within a few % of 3D elasticity for the lowest modes);
  it tends to Kirchhoff as h/a -> 0 (tested).

(n, s): n nodal diameters, s nodal circles. A free plate has rigid-body modes at (0, 0) and (1, 0);
the first flexural modes are (2, 0), (0, 1), (3, 0), (1, 1), (4, 0), ...

Mode shapes are normalised to modal mass = plate mass (rho pi a^2 h), so the modal equation of one
orientation is q'' + 2 zeta w q' + w^2 q = (w_rim cos(n phi_c)) F / m_plate with w_rim the
normalised deflection at the rim (`Mode.rim`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

KAPPA2 = math.pi**2 / 12.0   # Mindlin's shear coefficient (matches the thickness-shear cutoff)


@dataclass(frozen=True)
class Mode:
    """One flexural mode (both orientations cos n phi, sin n phi for n >= 1)."""

    n: int                 # nodal diameters
    s: int                 # nodal circles
    frequency_hz: float    # natural frequency (Hz)
    kirchhoff_hz: float    # the thin-plate (Kirchhoff) frequency of the same mode (Hz)
    rim: float             # deflection at the rim per unit modal amplitude, modal mass = plate mass


def _bessel(kind: str, n: int, k: float, r, r_ref: float | None = None):
    """Z, dZ/dr, d2Z/dr2 of Z = J_n(k r) ('J') or I_n(k r) ('I'), k > 0. I_n is scaled by
    exp(-k r_ref) (r_ref defaults to r), so a thick or thin plate's I-waves never overflow; a
    column of a boundary-condition matrix may be scaled freely."""
    from scipy import special

    x = k * r
    if kind == "J":
        z, zp = special.jv(n, x), special.jvp(n, x)
        zpp = -zp / x - (1.0 - n * n / (x * x)) * z
    else:
        sc = np.exp(k * (r - (r if r_ref is None else r_ref)))
        z = special.ive(n, x) * sc
        zp = 0.5 * (special.ive(n - 1, x) + special.ive(n + 1, x)) * sc
        zpp = -zp / x + (1.0 + n * n / (x * x)) * z
    return z, k * zp, k * k * zpp


def _kirchhoff_columns(n: int, lam: float, nu: float):
    """Free-edge conditions at rho = 1 for J_n(lam rho) and I_n(lam rho), a = 1 (2 x 2)."""
    cols = []
    for kind, lap in (("J", -1.0), ("I", 1.0)):
        z, zp, zpp = _bessel(kind, n, lam, 1.0)
        # M_r / (-D): W'' + nu (W'/r - n^2 W/r^2)
        m = zpp + nu * (zp - n * n * z)
        # V_r / (-D): (lap W)' - (1 - nu) n^2 (W'/r^2 - W/r^3), lap Z = -+ lam^2 Z
        v = lap * lam * lam * zp - (1.0 - nu) * n * n * (zp - z)
        cols.append((m, v))
    return np.array(cols).T


def _kirchhoff_det(n: int, lam: float, nu: float) -> float:
    m = _kirchhoff_columns(n, lam, nu)
    scale = np.abs(m).max(axis=0)
    return float(np.linalg.det(m / scale))


def _kirchhoff_det_grid(n: int, lam: np.ndarray, nu: float) -> np.ndarray:
    """The free-edge determinant on a grid of lam (same sign as _kirchhoff_det: positive column scales)."""
    m = _kirchhoff_columns(n, lam, nu)   # (lam, 2 rows, 2 columns)
    return m[:, 0, 0] * m[:, 1, 1] - m[:, 0, 1] * m[:, 1, 0]


def kirchhoff_lambda2(n: int, nu: float, count: int = 3) -> list[float]:
    """Eigenvalues lam^2 = omega a^2 sqrt(rho h / D) of the free Kirchhoff plate with n nodal
    diameters, in increasing order of nodal circles s (s = 0 for n >= 2, s = 1 first for n <= 1):
    sign changes of the free-edge determinant on a grid of lam (step 0.01), refined by Brent."""
    from scipy.optimize import brentq

    lam = np.arange(0.5, 4.0 + 4.0 * count + n, 0.01)
    d = _kirchhoff_det_grid(n, lam, nu)
    out = []
    for i in np.nonzero(np.sign(d[:-1]) * np.sign(d[1:]) < 0)[0]:
        out.append(brentq(lambda x: _kirchhoff_det(n, x, nu), lam[i], lam[i + 1], xtol=1e-14, rtol=1e-14))
        if len(out) == count:
            break
    return [x * x for x in out]


def first_nodal_circles(n: int) -> int:
    return 1 if n <= 1 else 0


def kirchhoff_shape(n: int, lam: float, nu: float):
    """W(rho) = J_n(lam rho) + C I_n(lam rho) on rho in [0, 1] (a callable)."""
    from scipy import special

    m = _kirchhoff_columns(n, lam, nu)
    c = -m[0, 0] / m[0, 1]
    # the I column is scaled by exp(-lam) (see _bessel)
    return lambda rho: special.jv(n, lam * rho) + c * special.ive(n, lam * rho) * np.exp(lam * (rho - 1.0))


# --- Mindlin -----------------------------------------------------------------------------------

def _mindlin_waves(omega: float, E: float, nu: float, rho: float, h: float):
    """The three wave numbers for angular frequency omega: [(kind, k, sigma-1)] for the two
    flexural waves and (kind, k) for the shear potential. kind 'J' if lap Z = -k^2 Z, 'I' if +k^2."""
    G = E / (2.0 * (1.0 + nu))
    D = E * h**3 / (12.0 * (1.0 - nu * nu))
    kGh = KAPPA2 * G * h
    a0 = rho * omega**2 / (KAPPA2 * G)
    rot = rho * h**3 * omega**2 / 12.0
    # D s^2 - (a0 D + rot) s + a0 (rot - kGh) = 0, s = delta^2 (lap w_i = -s_i w_i)
    b = a0 * D + rot
    disc = math.sqrt(b * b - 4.0 * D * a0 * (rot - kGh))
    waves = []
    for s in ((b + disc) / (2.0 * D), (b - disc) / (2.0 * D)):
        sigma_m1 = kGh / (rot - D * s - kGh)   # psi = (sigma - 1) grad w_i
        waves.append(("J" if s > 0 else "I", math.sqrt(abs(s)), sigma_m1))
    s3 = 2.0 * (rot - kGh) / (D * (1.0 - nu))
    return waves, ("J" if s3 > 0 else "I", math.sqrt(abs(s3)))


def _mindlin_matrix(n: int, omega: float, E: float, nu: float, rho: float, h: float, a: float):
    """Rows M_r/D, M_rphi/D, Q_r/(kappa^2 G h) at r = a; columns A1, A2, A3."""
    waves, (k3kind, k3) = _mindlin_waves(omega, E, nu, rho, h)
    r = a
    cols = []
    for kind, k, sm1 in waves:
        z, zp, zpp = _bessel(kind, n, k, r)
        psi_r, dpsi_r = sm1 * zp, sm1 * zpp
        psi_p = -sm1 * n * z / r
        dpsi_p = -sm1 * n * (zp / r - z / (r * r))
        cols.append((dpsi_r + nu / r * (psi_r + n * psi_p),
                     -n * psi_r / r + dpsi_p - psi_p / r,
                     psi_r + zp))
    z, zp, zpp = _bessel(k3kind, n, k3, r)
    psi_r, dpsi_r = n * z / r, n * (zp / r - z / (r * r))
    psi_p, dpsi_p = -zp, -zpp
    cols.append((dpsi_r + nu / r * (psi_r + n * psi_p), -n * psi_r / r + dpsi_p - psi_p / r, psi_r))
    return np.array(cols).T


def _mindlin_det(n, omega, E, nu, rho, h, a) -> float:
    m = _mindlin_matrix(n, omega, E, nu, rho, h, a)
    scale = np.abs(m).max(axis=0)
    scale[scale == 0.0] = 1.0
    m = m / scale
    rs = np.abs(m).max(axis=1)
    rs[rs == 0.0] = 1.0
    return float(np.linalg.det(m / rs[:, None]))


def _mindlin_root(n, omega_guess, E, nu, rho, h, a) -> float:
    """The Mindlin root nearest below the Kirchhoff frequency omega_guess (shear and rotary inertia
    only lower it): first sign change scanning down from 1.02 omega_guess."""
    from scipy.optimize import brentq

    f = lambda w: _mindlin_det(n, w, E, nu, rho, h, a)
    hi = 1.02 * omega_guess
    fhi = f(hi)
    w = hi
    while w > 0.2 * omega_guess:
        lo = w * 0.995
        flo = f(lo)
        if flo * fhi < 0.0:
            return brentq(f, lo, w, xtol=1e-12 * omega_guess, rtol=1e-13)
        w, fhi = lo, flo
    raise RuntimeError(f"no Mindlin root found below the Kirchhoff frequency for n = {n}")


def _mindlin_shape(n, omega, E, nu, rho, h, a):
    """(W, Psi_r, Psi_phi) radial functions of the Mindlin mode (callables on r in (0, a])."""
    m = _mindlin_matrix(n, omega, E, nu, rho, h, a)
    scale = np.abs(m).max(axis=0)
    _, _, vt = np.linalg.svd(m / scale)
    amp = vt[-1] / scale
    waves, (k3kind, k3) = _mindlin_waves(omega, E, nu, rho, h)

    def fields(r):
        W = np.zeros_like(r)
        Pr = np.zeros_like(r)
        Pp = np.zeros_like(r)
        for (kind, k, sm1), A in zip(waves, amp[:2]):
            z, zp, _ = _bessel(kind, n, k, r, a)
            W += A * z
            Pr += A * sm1 * zp
            Pp += -A * sm1 * n * z / r
        z, zp, _ = _bessel(k3kind, n, k3, r, a)
        Pr += amp[2] * n * z / r
        Pp += -amp[2] * zp
        return W, Pr, Pp

    return fields


def plate_modes(radius_m: float, thickness_m: float, E_pa: float, density_kg_m3: float, poisson: float,
                f_max_hz: float, s_max: int = 3, theory: str = "mindlin") -> list[Mode]:
    """Flexural modes of the free circular plate with frequency <= f_max_hz, sorted by frequency.

    theory 'mindlin' (default; for thick disks) or 'kirchhoff' (thin plate). Mindlin frequencies
    lie below Kirchhoff's: a Kirchhoff mode above 2 f_max_hz is not looked at.
    """
    if theory not in ("mindlin", "kirchhoff"):
        raise ValueError(f"theory must be 'mindlin' or 'kirchhoff', not {theory!r}")
    a, h, E, rho, nu = radius_m, thickness_m, E_pa, density_kg_m3, poisson
    D = E * h**3 / (12.0 * (1.0 - nu * nu))
    f_unit = math.sqrt(D / (rho * h)) / (2.0 * math.pi * a * a)   # Hz per unit lam^2
    reach = f_max_hz if theory == "kirchhoff" else 2.0 * f_max_hz
    plate_mass = rho * math.pi * a * a * h
    r = np.linspace(1e-6, 1.0, 4001) * a
    modes = []
    n = 0
    while True:
        s0 = first_nodal_circles(n)
        lam2s = [x for x in kirchhoff_lambda2(n, nu, count=s_max + 1 - s0) if x * f_unit <= reach]
        if not lam2s and n >= 2:
            break   # (n, 0) frequencies increase with n: no higher n reaches f_max either
        last = 0.0
        for i, lam2 in enumerate(lam2s):
            fk = lam2 * f_unit
            if theory == "kirchhoff":
                W = kirchhoff_shape(n, math.sqrt(lam2), nu)(r / a)
                ms = rho * h * np.trapezoid(W * W * r, r)
                f = fk
            else:
                w = _mindlin_root(n, 2.0 * math.pi * fk, E, nu, rho, h, a)
                f = w / (2.0 * math.pi)
                if f <= last * (1.0 + 1e-9):
                    raise RuntimeError(f"Mindlin roots for n = {n} out of order (mode ({n}, {s0 + i}))")
                last = f
                Wf, Pr, Pp = _mindlin_shape(n, w, E, nu, rho, h, a)(r)
                W = Wf
                ms = np.trapezoid((rho * h * W * W + rho * h**3 / 12.0 * (Pr * Pr + Pp * Pp)) * r, r)
            ms *= 2.0 * math.pi if n == 0 else math.pi   # angular integral of cos^2(n phi)
            if f <= f_max_hz:
                rim = abs(float(W[-1])) * math.sqrt(plate_mass / ms)
                modes.append(Mode(n=n, s=s0 + i, frequency_hz=float(f), kirchhoff_hz=float(fk), rim=rim))
        n += 1
    return sorted(modes, key=lambda m: m.frequency_hz)
