"""The DOP853 tableau: order 8 for the step and order 7 for the continuous extension.

A plain numpy DOP853 step built from sweep.core.tableau integrates the Kepler-like test problem
y'' = -y / |y|^3 (exact: circular orbit) so that a wrong digit in any coefficient shows up as a
lower observed order.
"""
import numpy as np

from sweep.core import tableau as T


def f(t, y):
    r3 = (y[0] ** 2 + y[1] ** 2) ** 1.5
    return np.array([y[2], y[3], -y[0] / r3, -y[1] / r3])


def exact(t):
    return np.array([np.cos(t), np.sin(t), -np.sin(t), np.cos(t)])


def step(t, y, h):
    K = np.zeros((16, y.size))
    K[0] = f(t, y)
    for s in range(1, 12):
        K[s] = f(t + T.C[s] * h, y + h * K[:s].T @ T.A[s, :s])
    y_new = y + h * K[:12].T @ T.B
    K[12] = f(t + h, y_new)
    for s in range(13, 16):
        K[s] = f(t + T.C[s] * h, y + h * K[:s].T @ T.A[s, :s])
    dy = y_new - y
    F = np.empty((7, y.size))
    F[0] = dy
    F[1] = h * K[0] - dy
    F[2] = 2 * dy - h * (K[12] + K[0])
    F[3:] = h * T.D @ K
    return y_new, F


def dense(F, y_old, x):
    v = F[6]
    for i, Fi in enumerate(F[5::-1]):
        v = Fi + (x if i % 2 == 0 else 1 - x) * v
    return y_old + x * v


def test_step_order_is_8_and_dense_order_is_7():
    errs_step, errs_dense = [], []
    hs = [0.4, 0.2, 0.1]
    for h in hs:
        t, y = 0.0, exact(0.0)
        emax_dense = 0.0
        while t < 4.0 - 1e-12:
            y_new, F = step(t, y, h)
            for x in (0.3, 0.7):
                emax_dense = max(emax_dense, np.max(np.abs(dense(F, y, x) - exact(t + x * h))))
            t, y = t + h, y_new
        errs_step.append(np.max(np.abs(y - exact(t))))
        errs_dense.append(emax_dense)
    p_step = np.log2(errs_step[0] / errs_step[1]), np.log2(errs_step[1] / errs_step[2])
    p_dense = np.log2(errs_dense[0] / errs_dense[1]), np.log2(errs_dense[1] / errs_dense[2])
    # global error of an order-8 method: ratio 2^8 per halving (7.5 allows the pre-asymptotic
    # first halving); local error of the 7th-order interpolant dominates the dense error: 2^7.
    assert min(p_step) > 7.5, (errs_step, p_step)
    assert min(p_dense) > 6.5, (errs_dense, p_dense)
