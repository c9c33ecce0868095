"""The Kessler-O'Reilly (2002) rigid-disk model in dimensionless form: numba kernels.

Units (paper eq. 4.4-4.6): lengths in R, mass in m, time tau = t/chi with
chi = sqrt((k^2+4)/4 * R/g); angular velocities omega_hat = chi*omega; slip velocities
u_hat = chi*u/R; normal force Phi = chi^2 N/(m R); friction force chi^2 F/(m R); energy
chi^2 E/(m R^2). In these units gravity is G = (k^2+4)/4.

Frames (paper eq. 2.1): E fixed; a = E turned by theta about E3; e = a turned by alpha about a1.
e2 is the symmetry axis, e3 lies in the disk plane and points from the contact point towards the
centre side, e1 = a1 is horizontal. Contact point P is at -H e2 - R e3 from the centre,
H = (L/2) side, side = sign(alpha).

All kernels take plain arrays/scalars. See docs/model.md for the derivation; every equation here
is checked in tests/test_model_equations.py against a world-frame Newton-Euler formulation.
"""
from __future__ import annotations

import math
from collections import namedtuple

import numpy as np

from .constants import SLIDE
from .jit import kernel

# --- state vector layout -------------------------------------------------------------------
Y_ALPHA, Y_W1, Y_W2, Y_W3, Y_U1, Y_U2 = 0, 1, 2, 3, 4, 5
Y_DSLIDE, Y_DK1, Y_DK2, Y_DK3 = 6, 7, 8, 9            # dissipated energy per mechanism
Y_THETA, Y_PSI, Y_X, Y_Y = 10, 11, 12, 13              # kinematics, integrated only on request
N_CORE = 10   # always integrated, and the only components in the error control
N_THETA = 11  # with theta (for the mean precession rate between normal-force maxima)
N_FULL = 14   # with all kinematics

# --- parameter vector layout ---------------------------------------------------------------
P_G, P_H, P_A, P_C, P_K1, P_K2, P_K3, P_MUS, P_MUD = 0, 1, 2, 3, 4, 5, 6, 7, 8
# slip_tol (u_hat = chi u/R): the slip speed at which a slow slide meets its fate and below which a
# slip is slaved (core.contact), and at or below which the model's friction direction is the given
# one (Contact.n0x, n0y) rather than u/|u|; 0 in the pure model, solver.slip_tol chi/R in a scene
# (docs/model.md).
P_UTOL = 9
# Rate |omega.a_i| (dimensionless, solver.spin_tol chi) at or below which a free moment component
# that slows down sticks, when the moment can hold it (docs/model.md); 0: only at omega.a_i = 0.
P_WTOL = 10
# Relaxation time of the slip direction (units of chi; solver.slave_tol) below which a slow slip's
# direction is slaved: solved as the slow manifold of the direction dynamics to first order in that
# time instead of integrated (core.contact, docs/model.md 'Slow slip'). A numerical knob: the
# results converge to those of the integrated direction as it goes to 0.
P_SLAVE = 11
# A slide's step is taken by the linearly implicit extrapolation (core.extrapolation) where it spans
# at least this many relaxation times of the slip direction, |u| / (mu_d Phi) (solver.stiff_ratio);
# 0: by DOP853 everywhere, as in the pure model. A numerical choice: both steppers converge to the
# same motion (core.accept.stepper_for).
P_STIFF = 12
N_PARAMS = 13

# --- auxiliary outputs of the right-hand side ----------------------------------------------
X_PHI, X_F1, X_F2, X_SIG1, X_SIG2, X_SIG3, X_G1, X_G2, X_G3, X_OK = 0, 1, 2, 3, 4, 5, 6, 7, 8, 9
X_DCROSS = 10   # SLAVED only (contact_rhs.eval_rhs): d cross/d nu at the slaved direction (< 0: attracting)
# sin(alpha), cos(alpha) of the state the right-hand side was evaluated at: the energy kernels of
# the step control and the events read them (*_trig) instead of evaluating the pair again
X_SINA, X_COSA = 11, 12
X_NU = 13       # SLAVED only (contact_rhs.eval_rhs): the quasi-static slip direction at this state (rad)
X_LAG = 14      # SLAVED only: the slip direction's lag behind it (rad); the friction acts along X_NU + X_LAG
X_SLAVE_ERR = 15  # SLAVED only: how far the slaved direction is from exact (contact_rhs.slaved_slip; inf: invalid)
N_AUX = 16


# The discrete configuration the right-hand side (rhs) is evaluated in: mode (ROLL or SLIDE), side
# (+1/-1: sign(alpha), the rim edge in contact), sig (3 signs of omega.a_i used in M_f, eq. 3.3),
# stuck (3 flags: 1 where omega.a_i is held at 0), and (n0x, n0y) the unit slip direction that the
# friction opposes at slip speeds <= p[P_UTOL]. numba passes it as its fields.
Contact = namedtuple("Contact", "mode side sig stuck n0x n0y")


def make_params(k2_shape: float, radius: float, thickness: float, gravity: float,
                mu_s: float, mu_d: float, k) -> tuple[np.ndarray, float]:
    """Dimensionless parameter vector and the time scale chi (s) from SI values.

    k2_shape: k^2 of eq. (2.4): 1 for the solid cylinder, 2 for the thin shell.
    radius, thickness (m); gravity (m/s^2); k = (k1, k2, k3) (m, moment = k_i |N|).
    """
    k1, k2, k3 = k
    h = 0.5 * thickness / radius
    chi = math.sqrt((k2_shape + 4.0) / 4.0 * radius / gravity)
    p = np.empty(N_PARAMS)
    p[P_G] = (k2_shape + 4.0) / 4.0
    p[P_H] = h
    p[P_A] = k2_shape / 4.0 + h * h / 3.0   # transverse inertia / (m R^2), eq. (2.4)
    p[P_C] = k2_shape / 2.0                 # axial inertia / (m R^2)
    p[P_K1] = k1 / radius
    p[P_K2] = k2 / radius
    p[P_K3] = k3 / radius
    p[P_MUS] = mu_s
    p[P_MUD] = mu_d
    p[P_UTOL] = 0.0
    p[P_WTOL] = 0.0
    p[P_SLAVE] = 0.0
    p[P_STIFF] = 0.0
    return p, chi


@kernel
def moment_axes_rates(y):
    """omega.a_i for i = 1, 2, 3 (the arguments of the sign terms of M_f, eq. 3.3)."""
    s = math.sin(y[Y_ALPHA])
    c = math.cos(y[Y_ALPHA])
    w1, w2, w3 = y[Y_W1], y[Y_W2], y[Y_W3]
    return w1, w2 * c - w3 * s, w2 * s + w3 * c


@kernel
def sign_rate(k, y, dy):
    """d/dtau of omega.a_k (k = 0, 1, 2) from the state and its derivative."""
    a = y[Y_ALPHA]
    s = math.sin(a)
    c = math.cos(a)
    w1, w2, w3 = y[Y_W1], y[Y_W2], y[Y_W3]
    if k == 0:
        return dy[Y_W1]
    if k == 1:
        return dy[Y_W2] * c - dy[Y_W3] * s - w1 * (w2 * s + w3 * c)
    return dy[Y_W2] * s + dy[Y_W3] * c + w1 * (w2 * c - w3 * s)


@kernel
def height_above_flat(alpha, h):
    """height_from_trig at the inclination alpha."""
    return height_from_trig(math.sin(alpha), math.cos(alpha), h)


@kernel
def height_from_trig(sin_a, cos_a, h):
    """e - |h|: centre height above its flat-lying value, in R, without cancellation near pi/2.

    e = cos(alpha) + h sin(alpha) (eq. 4.9), h = side |h| the contact rim's offset. With side =
    sign(alpha) this is the physical height, 1 - |sin a| = cos(a)^2 / (1 + |sin a|). Past alpha = 0
    with the side kept (a step that overshoots the rim-edge event) it is the height of the smooth
    continuation the right-hand side integrates, so that E + dissipated stays conserved there.
    """
    c = cos_a
    s = sin_a if h >= 0.0 else -sin_a   # side sin(alpha)
    if s >= 0.0:
        return c - abs(h) * c * c / (1.0 + s)
    return c - abs(h) * (1.0 - s)


@kernel
def energy(y, p, side, mode):
    """Total energy chi^2 E/(m R^2), zero for the disk lying flat at rest (eq. 6.1, corrected).

    1/2 (u1 + w2 - h w3)^2 + 1/2 (u2 - e w1)^2 + 1/2 f^2 w1^2 + 1/2 A (w1^2 + w3^2)
    + 1/2 C w2^2 + G (e - |h|); the slip (u1, u2) counts only when sliding.
    """
    if mode == SLIDE:
        return energy_with_slip(y, p, side, y[Y_U1], y[Y_U2])
    return energy_with_slip(y, p, side, 0.0, 0.0)


@kernel
def centre_velocity(y, u1, u2, h, e, f):
    """Velocity of the centre of mass in chi R/tau, on an orthonormal frame whose first axis is a1:
    (u1 + w2 - h w3, u2 - e w1, f w1), (w1, w2, w3) y's angular velocity, (u1, u2) the contact
    point's slip (eq. 4.9 for e, f); half its square is the translational part of energy()."""
    w1, w2, w3 = y[Y_W1], y[Y_W2], y[Y_W3]
    return u1 + w2 - h * w3, u2 - e * w1, f * w1


@kernel
def slip_of(y, slip):
    """The slip components (u1, u2) of y where slip, else (0, 0)."""
    if slip:
        return y[Y_U1], y[Y_U2]
    return 0.0, 0.0


@kernel
def energy_with_slip(y, p, side, u1, u2):
    """energy() with the slip components on a1, a2 given explicitly."""
    return energy_from_trig(y, p, side, u1, u2, (math.sin(y[Y_ALPHA]), math.cos(y[Y_ALPHA])))


@kernel
def energy_from_trig(y, p, side, u1, u2, trig):
    """energy_with_slip with trig = (s, c), the sine and cosine of y's inclination, given (e.g.
    aux[X_SINA], aux[X_COSA] of the right-hand side at y): the same arithmetic, the same result to
    the last bit."""
    s, c = trig
    h = side * p[P_H]
    e = c + h * s
    f = h * c - s
    w1, w2, w3 = y[Y_W1], y[Y_W2], y[Y_W3]
    vx, vy, vz = centre_velocity(y, u1, u2, h, e, f)
    kin = 0.5 * (vx * vx + vy * vy + vz * vz) + 0.5 * p[P_A] * (w1 * w1 + w3 * w3) + 0.5 * p[P_C] * w2 * w2
    return kin + p[P_G] * height_from_trig(s, c, h)


@kernel
def energy_increment(y, d, p, side, slip):
    """energy_increment_trig with sin, cos of y's inclination evaluated here."""
    return energy_increment_trig(y, d, p, side, slip, (math.sin(y[Y_ALPHA]), math.cos(y[Y_ALPHA])))


@kernel
def energy_increment_trig(y, d, p, side, slip, trig):
    """E(y + d) - E(y) of energy_with_slip (the slip counted where slip), in difference form.

    d is a step's increment before it is rounded into the state. Evaluated as the difference of two
    energies, the change carries the round-off of E itself: near flat E << G, and alpha's last bit
    alone moves G (e - |h|) by ~EPS G, which hid a step's truncation error in the energy (a slide
    near flat: ~1e-14 E0 per step, summed over 1.4 M steps to 1.5e-9 E0; docs/model.md, 'Energy and
    the dissipation budget'). Here every
    term is (change of q) x (q + change/2), the cosine and sine by their half-angle products, so the
    round-off is relative to the change. Returns (change, scale): scale bounds the change's round-off
    in units of EPS. trig: (s, c), the sine and cosine of y's inclination."""
    s, c = trig
    h = side * p[P_H]
    a = y[Y_ALPHA]
    half = 0.5 * d[Y_ALPHA]
    sh = math.sin(half)
    dc = -2.0 * math.sin(a + half) * sh     # cos(a + da) - cos(a)
    ds = 2.0 * math.cos(a + half) * sh      # sin(a + da) - sin(a)
    e = c + h * s
    f = h * c - s
    de = dc + h * ds
    df = h * dc - ds
    ade = (abs(dc) + abs(h * ds)) * (1.0 + abs(a))   # its round-off scale (the argument a + da/2)
    adf = (abs(h * dc) + abs(ds)) * (1.0 + abs(a))
    w1, w2, w3 = y[Y_W1], y[Y_W2], y[Y_W3]
    d1, d2, d3 = d[Y_W1], d[Y_W2], d[Y_W3]
    u1, u2 = slip_of(y, slip)
    du1, du2 = slip_of(d, slip)
    vx, vy, vz = centre_velocity(y, u1, u2, h, e, f)
    dvx = du1 + d2 - h * d3
    dvy = du2 - (de * (w1 + d1) + e * d1)
    dvz = df * (w1 + d1) + f * d1
    A = p[P_A]
    C = p[P_C]
    G = p[P_G]
    change = (dvx * (vx + 0.5 * dvx) + dvy * (vy + 0.5 * dvy) + dvz * (vz + 0.5 * dvz)
              + A * (d1 * (w1 + 0.5 * d1) + d3 * (w3 + 0.5 * d3)) + C * d2 * (w2 + 0.5 * d2) + G * de)
    scale = ((abs(du1) + abs(d2) + abs(h * d3)) * (abs(vx) + abs(dvx))
             + (abs(du2) + ade * abs(w1 + d1) + abs(e * d1)) * (abs(vy) + abs(dvy))
             + (adf * abs(w1 + d1) + abs(f * d1)) * (abs(vz) + abs(dvz))
             + A * (abs(d1) * (abs(w1) + abs(d1)) + abs(d3) * (abs(w3) + abs(d3)))
             + C * abs(d2) * (abs(w2) + abs(d2)) + G * ade)
    return change, scale


@kernel
def energy_rate(y, dy, p, side, slip):
    """energy_rate_trig with sin, cos of y's inclination evaluated here."""
    return energy_rate_trig(y, dy, p, side, slip, (math.sin(y[Y_ALPHA]), math.cos(y[Y_ALPHA])))


@kernel
def energy_rate_trig(y, dy, p, side, slip, trig):
    """dE/dtau along dy at y: the gradient of energy_with_slip (the slip counted where slip) times dy.

    With dy the right-hand side, energy_rate(y, dy) + dy[Y_DSLIDE] + dy[Y_DK1..3] is exactly 0 for
    the exact flow (the power balance of eq. 6.1); what the evaluated right-hand side leaves of it
    is its round-off in the energy direction, which near flat (tan(alpha) ~ 1e6 in the gyroscopic
    terms) is far above the round-off of the energy's own terms (accept.balance_error).
    Uses de/dalpha = f, df/dalpha = -e (eq. 4.9); trig: (s, c), the sine and cosine of y's
    inclination."""
    s, c = trig
    h = side * p[P_H]
    e = c + h * s
    f = h * c - s
    w1, w2, w3 = y[Y_W1], y[Y_W2], y[Y_W3]
    da, d1, d2, d3 = dy[Y_ALPHA], dy[Y_W1], dy[Y_W2], dy[Y_W3]
    u1, u2 = slip_of(y, slip)
    du1, du2 = slip_of(dy, slip)
    vx, vy, vz = centre_velocity(y, u1, u2, h, e, f)
    dvx = du1 + d2 - h * d3
    dvy = du2 - f * da * w1 - e * d1
    dvz = -e * da * w1 + f * d1
    return (vx * dvx + vy * dvy + vz * dvz + p[P_A] * (w1 * d1 + w3 * d3) + p[P_C] * w2 * d2
            + p[P_G] * f * da)


@kernel
def _solve2(m11, m12, m21, m22, b1, b2):
    det = m11 * m22 - m12 * m21
    return (m22 * b1 - m12 * b2) / det, (m11 * b2 - m21 * b1) / det


@kernel(inline="always")
def geometry(y, p, side):
    """(h, s, c, t, e, f, thd) at y's inclination alpha: the contact rim's offset h = side |H|/R,
    sin, cos and tan of alpha, the centre's height e = c + h s (eq. 4.9), f = de/dalpha = h c - s,
    and the precession rate dtheta/dtau = w3 sec(alpha) (eq. 2.3)."""
    h = side * p[P_H]
    s = math.sin(y[Y_ALPHA])
    c = math.cos(y[Y_ALPHA])
    return h, s, c, s / c, c + h * s, h * c - s, y[Y_W3] / c


@kernel(inline="always")
def slip_direction(y, p, mode, n0x, n0y):
    """(u1, u2, n1, n2): the slip on a1, a2 and the unit direction n that friction opposes
    (F = -mud Phi n, eq. 4.7); (n0x, n0y) at slip speeds <= p[P_UTOL]; all zero when rolling."""
    if mode != SLIDE:
        return 0.0, 0.0, 0.0, 0.0
    u1 = y[Y_U1]
    u2 = y[Y_U2]
    un = math.hypot(u1, u2)
    if un > p[P_UTOL]:
        return u1, u2, u1 / un, u2 / un
    return u1, u2, n0x, n0y


@kernel(inline="always")
def tilt_balance(y, p, contact, geo, n2):
    """(dw1, Phi, sigma_1, ok): d omega_1/d tau and the normal force from the e1 moment balance and
    the vertical balance, Phi = phi0 + f dw1 (eq. 4.6; rolling: eq. 5.3_2 with Phi kept), in the
    contact's mode with its signs sig (Contact). A stuck omega.a_1 (contact.stuck[0], k1 > 0) is
    held at 0 and its effective sign sigma_1 solved instead. ok = -1 where no acceleration satisfies
    the contact law (a Painleve inconsistency), else 1."""
    mode, sig, stuck = contact.mode, contact.sig, contact.stuck
    G, A, C, k1 = p[P_G], p[P_A], p[P_C], p[P_K1]
    h, s, c, t, e, f, thd = geo
    w1, w2, w3 = y[Y_W1], y[Y_W2], y[Y_W3]
    phi0 = G - e * w1 * w1
    if mode == SLIDE:
        # A dw1 = C w2 w3 - A w3^2 t + Phi (e F2/Phi - f - k1 sig1), F = -mud Phi n
        a1 = A
        r1 = C * w2 * w3 - A * w3 * w3 * t
        q1 = -p[P_MUD] * e * n2 - f
    else:
        a1 = A + 1.0 + h * h
        r1 = C * w2 * w3 - A * w3 * w3 * t + e * thd * (w2 - h * w3) - G * f
        q1 = 0.0
    if stuck[0] == 1 and k1 > 0.0:
        return 0.0, phi0, (r1 + q1 * phi0) / (k1 * phi0), 1.0
    qq = q1 - k1 * sig[0]
    den = a1 - qq * f
    dw1 = (r1 + qq * phi0) / den
    return dw1, phi0 + f * dw1, sig[0], -1.0 if den <= 0.0 else 1.0


@kernel(inline="always")
def spin_balance(y, p, contact, geo, phi, n1):
    """(dw2, dw3, sigma_2, sigma_3) from the e2, e3 moment balances, M [dw2, dw3] = b - Phi [kb2,
    kb3] (eq. 4.8; rolling: eq. 5.3 with the constraint's force), in the contact's mode with its
    signs (Contact); held_spin_rates where a stuck omega.a_2 or omega.a_3 (k > 0) is held at 0."""
    mode, sig, stuck = contact.mode, contact.sig, contact.stuck
    A, C, k2, k3, mud = p[P_A], p[P_C], p[P_K2], p[P_K3], p[P_MUD]
    h, s, c, t, e, f, thd = geo
    w1, w2, w3 = y[Y_W1], y[Y_W2], y[Y_W3]
    if mode == SLIDE:
        m = (C, 0.0, 0.0, A)
        b = (mud * phi * n1, -C * w1 * w2 + A * w1 * w3 * t - h * mud * phi * n1)
    else:
        m = (C + 1.0, -h, -h, A + h * h)
        b = (-e * w1 * thd, -C * w1 * w2 + A * w1 * w3 * t + h * e * w1 * thd)
    if (stuck[1] == 1 and k2 > 0.0) or (stuck[2] == 1 and k3 > 0.0):
        return held_spin_rates(y, p, contact, geo, phi, (m, b))
    sig2 = sig[1]
    sig3 = sig[2]
    kb2 = k2 * sig2 * c + k3 * sig3 * s
    kb3 = k3 * sig3 * c - k2 * sig2 * s
    dw2, dw3 = _solve2(m[0], m[1], m[2], m[3], b[0] - phi * kb2, b[1] - phi * kb3)
    return dw2, dw3, sig2, sig3


@kernel(inline="always")
def held_spin_rates(y, p, contact, geo, phi, balance):
    """spin_balance's (dw2, dw3, sigma_2, sigma_3) with omega.a_2 and/or omega.a_3 held at 0 by the
    dry-friction moment (contact.stuck, k > 0: Filippov sliding); balance = (m, b), m = (m11, m12, m21,
    m22) and b = (b2, b3) its system without the moment. The rates are dw = W0 + sig2 W2 + sig3 W3, and
    each held sigma is solved from d/dtau(w2 c - w3 s) = dw2 c - dw3 s - w1 (w2 s + w3 c) = 0,
    respectively d/dtau(w2 s + w3 c) = dw2 s + dw3 c + w1 (w2 c - w3 s) = 0."""
    sig, stuck = contact.sig, contact.stuck
    m, b = balance
    k2, k3 = p[P_K2], p[P_K3]
    s, c = geo[1], geo[2]
    w1, w2, w3 = y[Y_W1], y[Y_W2], y[Y_W3]
    m11, m12, m21, m22 = m
    sig2 = sig[1]
    sig3 = sig[2]
    st2 = stuck[1] == 1 and k2 > 0.0
    st3 = stuck[2] == 1 and k3 > 0.0
    x0, y0 = _solve2(m11, m12, m21, m22, b[0], b[1])
    x2, y2 = _solve2(m11, m12, m21, m22, -phi * k2 * c, phi * k2 * s)
    x3, y3 = _solve2(m11, m12, m21, m22, -phi * k3 * s, -phi * k3 * c)
    r2 = w1 * (w2 * s + w3 * c)
    r3 = -w1 * (w2 * c - w3 * s)
    if st2 and st3:
        sig2, sig3 = _solve2(x2 * c - y2 * s, x3 * c - y3 * s, x2 * s + y2 * c, x3 * s + y3 * c,
                             r2 - (x0 * c - y0 * s), r3 - (x0 * s + y0 * c))
    elif st2:
        sig2 = (r2 - (x0 * c - y0 * s) - sig3 * (x3 * c - y3 * s)) / (x2 * c - y2 * s)
    else:
        sig3 = (r3 - (x0 * s + y0 * c) - sig2 * (x2 * s + y2 * c)) / (x3 * s + y3 * c)
    return x0 + sig2 * x2 + sig3 * x3, y0 + sig2 * y2 + sig3 * y3, sig2, sig3


@kernel(inline="always")
def contact_rates(y, p, mode, geo, load, dw):
    """(F1, F2, du1, du2): the friction on a1, a2 and the slip's rates, given load = (Phi, n) with
    n = (n1, n2) the slip direction, and dw = (dw1, dw2, dw3). Sliding: F = -mud Phi n and
    eq. 4.7_1,2; rolling: the friction the constraint needs (eq. 5.2_1), and no slip."""
    phi, n = load
    h, s, c, t, e, f, thd = geo
    w1 = y[Y_W1]
    dw1, dw2, dw3 = dw
    q = y[Y_W2] - h * y[Y_W3]      # (centre velocity + slip) . a1 in rolling
    if mode == SLIDE:
        F1 = -p[P_MUD] * phi * n[0]
        F2 = -p[P_MUD] * phi * n[1]
        return (F1, F2, thd * y[Y_U2] + F1 - dw2 + h * dw3 - e * w1 * thd,
                -thd * y[Y_U1] + F2 + e * dw1 - thd * q + f * w1 * w1)
    return dw2 - h * dw3 + e * w1 * thd, -e * dw1 + thd * q - f * w1 * w1, 0.0, 0.0


@kernel(inline="always")
def kinematics_rates(y, geo, u1, u2, nstate, dy):
    """The precession angle's rate dtheta/dtau (eq. 2.3) for nstate > N_CORE; for nstate >
    N_CORE + 1 also the spin angle psi's and the centre's velocity on the table's E1, E2 (eq. 2.5
    solved for the centre's velocity)."""
    h, s, c, t, e, f, thd = geo
    w1, w2, w3 = y[Y_W1], y[Y_W2], y[Y_W3]
    dy[Y_THETA] = thd
    if nstate > N_CORE + 1:
        vx = u1 + (w2 - h * w3)     # centre velocity on a1
        vy = u2 - e * w1            # centre velocity on a2
        ct = math.cos(y[Y_THETA])
        st = math.sin(y[Y_THETA])
        dy[Y_PSI] = w2 - w3 * t
        dy[Y_X] = vx * ct - vy * st
        dy[Y_Y] = vx * st + vy * ct


@kernel(inline="always")
def rhs(y, p, contact, nstate, dy, aux):
    """Time derivatives d y/d tau of the state, and contact quantities in `aux` (the model is
    autonomous: no term reads tau).

    contact (Contact): mode ROLL (eq. 5.3, corrected) or SLIDE (eq. 4.7); side = sign(alpha) = +-1
    selects H; sig[i]: sign of omega.a_i used in M_f (eq. 3.3) for a component that is not stuck;
    stuck[i] = 1: omega.a_i is held at 0 by the dry-friction moment (Filippov sliding), its
    effective sign sigma_i in [-1, 1] solved from d/dtau(omega.a_i) = 0; (n0x, n0y): slip direction
    used while the slip speed is <= p[P_UTOL] (0: only at u = 0).
    nstate: number of state components to fill (N_CORE, N_THETA, or N_FULL with kinematics).
    aux: Phi, F1, F2 (friction on a1, a2), effective sigma_1..3, omega.a_1..3, ok-flag (1; -1 where the
    e1 balance's coefficient of Phi is not positive: a Painleve inconsistency), sin and cos of alpha.
    """
    mode = contact.mode
    geo = geometry(y, p, contact.side)
    s, c = geo[1], geo[2]
    u1, u2, n1, n2 = slip_direction(y, p, mode, contact.n0x, contact.n0y)
    dw1, phi, sig1, ok = tilt_balance(y, p, contact, geo, n2)
    dw2, dw3, sig2, sig3 = spin_balance(y, p, contact, geo, phi, n1)
    F1, F2, du1, du2 = contact_rates(y, p, mode, geo, (phi, (n1, n2)), (dw1, dw2, dw3))
    w1, w2, w3 = y[Y_W1], y[Y_W2], y[Y_W3]
    g2 = w2 * c - w3 * s
    g3 = w2 * s + w3 * c
    dy[Y_ALPHA] = w1
    dy[Y_W1] = dw1
    dy[Y_W2] = dw2
    dy[Y_W3] = dw3
    dy[Y_U1] = du1
    dy[Y_U2] = du2
    # power of each dissipative mechanism (>= 0 when the signs are consistent):
    # -F.v_P = mud Phi |u|;  -M_f.omega = Phi sum k_i sig_i (omega.a_i)
    dy[Y_DSLIDE] = p[P_MUD] * phi * (u1 * n1 + u2 * n2)
    dy[Y_DK1] = p[P_K1] * phi * sig1 * w1
    dy[Y_DK2] = p[P_K2] * phi * sig2 * g2
    dy[Y_DK3] = p[P_K3] * phi * sig3 * g3
    if nstate > N_CORE:
        kinematics_rates(y, geo, u1, u2, nstate, dy)
    aux[X_PHI] = phi
    aux[X_F1] = F1
    aux[X_F2] = F2
    aux[X_SIG1] = sig1
    aux[X_SIG2] = sig2
    aux[X_SIG3] = sig3
    aux[X_G1] = w1
    aux[X_G2] = g2
    aux[X_G3] = g3
    aux[X_OK] = ok
    aux[X_SINA] = s
    aux[X_COSA] = c


@kernel
def physical_velocity(y, p, side, mode, out):
    """Centre velocity (on e1, e2, e3) and angular velocity (on e1, e2, e3) of the reduced state."""
    h = side * p[P_H]
    a = y[Y_ALPHA]
    s = math.sin(a)
    c = math.cos(a)
    w1, w2, w3 = y[Y_W1], y[Y_W2], y[Y_W3]
    u1 = 0.0
    u2 = 0.0
    if mode == SLIDE:
        u1, u2 = y[Y_U1], y[Y_U2]
    # v = v_P - omega x r, r = -h e2 - e3; v_P = u1 a1 + u2 a2, a2 = c e2 - s e3
    out[0] = u1 + w2 - h * w3
    out[1] = u2 * c - w1
    out[2] = -u2 * s + h * w1
    out[3] = w1
    out[4] = w2
    out[5] = w3


@kernel
def steady_rolling_w3sq(beta, p):
    """omega_3^2 of the steady centre-fixed rolling motion at inclination beta = pi/2 - |alpha|.

    From the e1 balance of (5.3) with w1 = 0, w2 = |h| w3 (centre at rest) and no moment:
    w3^2 (C h - A tan alpha) = G f. Negative where no such motion exists.
    """
    h = p[P_H]
    a = 0.5 * math.pi - beta
    s = math.sin(a)
    c = math.cos(a)
    return p[P_G] * (h * c - s) * c / (p[P_C] * h * c - p[P_A] * s)


@kernel
def steady_rolling_energy(beta, p):
    """Energy of the steady centre-fixed rolling motion at inclination beta (dimensionless).

    E_ss = 1/2 (A + C h^2) w3^2 + G (e - |h|); it is ~ G beta (3/2 + C h^2/(2A)) for small beta.
    The energy-equivalent inclination of a state is E_ss^{-1}(E): it is monotone in time because E
    is, so its level crossings do not jitter with the nutation (docs/model.md, 'Halt levels').
    """
    w3sq = steady_rolling_w3sq(beta, p)
    h = p[P_H]
    return 0.5 * (p[P_A] + p[P_C] * h * h) * w3sq + p[P_G] * height_above_flat(0.5 * math.pi - beta, h)


@kernel
def steady_rolling_max_level(p, step):
    """Largest inclination (rad, on a grid of `step`) below which the steady centre-fixed rolling
    motion exists and its energy increases with beta: where the energy-equivalent inclination is
    defined. Scanned upwards from `step`; see scene.max_level."""
    prev = 0.0
    b = step
    while b < 0.5 * math.pi:
        if steady_rolling_w3sq(b, p) <= 0.0:
            return b - step
        e = steady_rolling_energy(b, p)
        if not e > prev:
            return b - step
        prev = e
        b += step
    return b - step
