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


def test_the_generated_sums_are_the_generators_text():
    """dop853_sums.py is what tableau.sums_source() writes: an edit of the tableau or the generator
    without `python src/sweep/core/tableau.py` fails here."""
    from pathlib import Path
    path = Path(T.__file__).with_name(T.SUMS_MODULE)
    assert path.read_text() == T.sums_source()


def _loop_sum(coefs, cols, K, i):
    """The sum as a loop from 0.0 over the tableau's nonzero coefficients in stage order."""
    acc = 0.0
    for j in cols:
        if coefs[j] != 0.0:
            acc += float(coefs[j]) * float(K[j, i])
    return acc


def test_the_generated_sums_add_the_same_terms_in_the_same_order():
    """increment, error_sums, dense_rows and main_stages/dense_stages (through a jitted linear
    right-hand side) against loops over the tableau in plain Python: equal to the last bit."""
    import numba
    from sweep.core import dop853_sums as S
    from sweep.core import layout as L

    rng = np.random.default_rng(7)
    n = 14
    K = rng.standard_normal((32, n))
    h = 0.0371
    y = rng.standard_normal(n)
    y_new, delta = np.zeros(n), np.zeros(n)
    S.increment(K, h, y, y_new, delta, n)
    for i in range(n):
        d = h * _loop_sum(T.B, T.B_COLS, K, i)
        assert delta[i] == d and y_new[i] == y[i] + d
        a5, a3 = S.error_sums(K, i)
        assert a5 == _loop_sum(T.E5, T.E_COLS, K, i) and a3 == _loop_sum(T.E3, T.E_COLS, K, i)
    F = np.zeros((7, n))
    S.dense_rows(K, h, F, n)
    for r in range(4):
        for i in range(n):
            assert F[3 + r, i] == h * _loop_sum(T.D[r], T.D_COLS, K, i)

    M = rng.standard_normal((n, n)) * 0.3

    @numba.njit
    def linear(t, ys, sys, dy, aux):
        for i in range(sys.n):
            acc = 0.0
            for j in range(sys.n):
                acc += M[i, j] * ys[j]
            dy[i] = acc + t

    @numba.njit
    def both(y, h, K, wk):
        sys = L.System(np.zeros(1), np.zeros(1), n, wk, np.zeros(1, np.int64))
        S.main_stages(linear, 0.5, y, h, sys, K)
        S.dense_stages(linear, 0.5, y, h, sys, K)

    K2 = np.zeros((16, n))
    K2[0] = M @ y + 0.5
    K2[12] = rng.standard_normal(n)
    K1 = K2.copy()
    both(y, h, K2, np.zeros((L.N_WORK, L.N_WCOLS)))
    for s in list(range(1, 12)) + list(range(13, 16)):
        ytmp = np.array([y[i] + h * _loop_sum(T.A[s], range(s), K1, i) for i in range(n)])
        for i in range(n):   # the right-hand side's own sum, in the jitted loop's order
            acc = 0.0
            for j in range(n):
                acc += float(M[i, j]) * ytmp[j]
            K1[s, i] = acc + (0.5 + float(T.C[s]) * h)
    assert np.array_equal(K1, K2)
