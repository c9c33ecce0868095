"""Linearly implicit Euler extrapolation: the stiff-stable stepper of slow slides (a W-method).

A slide's slip direction relaxes at the rate ~ mu_d Phi / |u|, which at slow slips is far faster
than the motion (docs/model.md, 'Slow slip'); DOP853 must step within its stability bound of that
rate. This stepper treats the stiff part linearly implicitly and steps at what the motion's accuracy
needs. It knows no physics: the caller names the components whose Jacobian columns it takes (the
slip's two, where the stiffness sits) and gives the right-hand side, `rhs(t, y, sys, dy, aux)`,
as dop853's.

The step of size h from y (f = rhs(t, y)): for each n_j of SEQUENCE, n_j sub-steps of
h_j = h / n_j of the linearly implicit Euler method

    (I - h_j W) (Y_{i+1} - Y_i) = h_j f(t + i h_j, Y_i),      Y_0 = y,

W the Jacobian's columns COLUMNS (forward differences at the step start; the other columns 0),
then Aitken-Neville extrapolation of the end increments T_{j,1} = Y_{n_j} - y in h_j (the method
has an asymptotic expansion in powers of h_j for any W, Hairer & Wanner (1996), IV.9):

    T_{j,q+1} = T_{j,q} + (T_{j,q} - T_{j-1,q}) / (n_j / n_{j-q} - 1).

y_new = y + T_{k,k} (order k = 8); the error estimate is T_{k,k} - T_{k,k-1} (order 7, as dop853's
estimator: the same step-size exponent). With W of two columns the solve of (I - h_j W) x = b is a
2 x 2 system for the two components and one multiply-add for the rest.

The dense output (lie_dense) is the quintic Hermite interpolant of the step's ends and of its
midpoint, computed by the same extrapolation over h / 2, with the derivatives there, written as
dop853's coefficients (its continuous extension's nested form, the highest two rows 0), so the
scan, the levels and the recorders read it as they read dop853's.

Rows of the stage buffer K (its first 13 are kept for a previous step's dense output, as
dop853's stages): R_F0 f at the step start, R_W1 and R_W2 the Jacobian columns, R_P.. the
extrapolation's diagonal, R_D the sub-step increment, R_FNEW f at the step end, R_FS a sub-step's f,
R_LOW T_{k,k-1}, R_MID the midpoint's increment.
"""
from __future__ import annotations

import math

import numpy as np

from .jit import kernel
from .layout import W_AUXTMP, W_DELTA, W_YTMP

SEQUENCE = np.array([1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0])
N_COLUMNS = 8

R_F0, R_W1, R_W2, R_P = 0, 1, 2, 3          # R_P .. R_P + N_COLUMNS - 1
R_D = R_P + N_COLUMNS                        # 11
R_FNEW = 12                                  # as dop853's K[N_STAGES]: f at the step end
R_FS, R_LOW, R_MID = 13, 14, 15

# Forward-difference step of a Jacobian column, relative to the named components' magnitude
JAC_STEP = 1e-7


def _hermite5() -> np.ndarray:
    """The map from the quintic Hermite data of a step, (y1 - y0, h f0, ym - y0, h fm, h f1) at x =
    1, 0, 1/2, 1/2, 1, to dop853's first five dense-output coefficients F0..F4 (F5 = F6 = 0): the
    increment y(x) - y0 = x (F0 + x1 (F1 + x (F2 + x1 (F3 + x F4)))), x1 = 1 - x."""
    def basis(x):
        x1 = 1.0 - x
        return np.array([x, x * x1, x * x * x1, x * x * x1 * x1, x ** 3 * x1 * x1])

    def dbasis(x):
        x1 = 1.0 - x
        return np.array([1.0,
                         x1 - x,
                         2 * x * x1 - x * x,
                         2 * x * x1 * x1 - 2 * x * x * x1,
                         3 * x * x * x1 * x1 - 2 * x ** 3 * x1])

    m = np.array([basis(1.0), dbasis(0.0), basis(0.5), dbasis(0.5), dbasis(1.0)])
    return np.linalg.inv(m)


HERMITE5 = _hermite5()


@kernel(inline="always")
def jacobian_columns(rhs, t, start, sys, K, cols):
    """The Jacobian's columns cols = (c1, c2) at (t, start.y) (start: layout.Point, f = rhs there),
    by forward differences of JAC_STEP times |(y_c1, y_c2)|, into K[R_W1], K[R_W2]; K[R_F0] = f."""
    y, f = start.y, start.f
    n, wk = sys.n, sys.wk
    c1, c2 = cols
    ytmp = wk[W_YTMP]
    for i in range(n):
        K[R_F0, i] = f[i]
    size = max(math.hypot(y[c1], y[c2]), 1e-300)
    for r in range(2):
        c = c1 if r == 0 else c2
        row = R_W1 if r == 0 else R_W2
        for i in range(n):
            ytmp[i] = y[i]
        ytmp[c] = y[c] + JAC_STEP * size
        d = ytmp[c] - y[c]
        rhs(t, ytmp, sys, K[row], wk[W_AUXTMP])
        for i in range(n):
            K[row, i] = (K[row, i] - f[i]) / d


@kernel(inline="always")
def extrapolate(rhs, at, y, sys, K, cols):
    """The extrapolation over h from y at t (at = (t, h); K[R_F0] = f there, K[R_W1], K[R_W2] the
    Jacobian's columns cols): T_{k,k} (the increment) in K[R_P + N_COLUMNS - 1], T_{k,k-1} in
    K[R_LOW]."""
    t, h = at
    n, wk = sys.n, sys.wk
    c1, c2 = cols
    ytmp = wk[W_YTMP]
    aux = wk[W_AUXTMP]
    w1, w2, d, fs = K[R_W1], K[R_W2], K[R_D], K[R_FS]
    for j in range(N_COLUMNS):
        nj = SEQUENCE[j]
        hs = h / nj
        a11 = 1.0 - hs * w1[c1]
        a12 = -hs * w2[c1]
        a21 = -hs * w1[c2]
        a22 = 1.0 - hs * w2[c2]
        det = a11 * a22 - a12 * a21
        for i in range(n):
            d[i] = 0.0
        for s in range(int(nj)):
            fi = K[R_F0]
            if s > 0:
                for i in range(n):
                    ytmp[i] = y[i] + d[i]
                rhs(t + s * hs, ytmp, sys, fs, aux)
                fi = fs
            b1 = hs * fi[c1]
            b2 = hs * fi[c2]
            x1 = (a22 * b1 - a12 * b2) / det
            x2 = (a11 * b2 - a21 * b1) / det
            for i in range(n):
                d[i] += hs * (fi[i] + w1[i] * x1 + w2[i] * x2)
        for i in range(n):
            cur = d[i]
            for q in range(1, j + 1):
                r = nj / SEQUENCE[j - q]
                nxt = cur + (cur - K[R_P + q - 1, i]) / (r - 1.0)
                K[R_P + q - 1, i] = cur
                if q == j:
                    K[R_LOW, i] = cur
                cur = nxt
            K[R_P + j, i] = cur


@kernel(inline="always")
def lie_step(rhs, at, ends, sys, K, cols):
    """One extrapolation step of size h from start at t (at = (t, h); ends = (start, end), each a
    layout.Point; start: y, f at t): end.y, and end.f = K[R_FNEW] = f(t + h, end.y) with its aux end.aux; the increment
    before rounding in sys.wk[W_DELTA]; the error estimate's rows for lie_error_norm. cols: the
    components whose Jacobian columns are taken."""
    t, h = at
    start, end = ends
    n = sys.n
    y, y_new, f_new = start.y, end.y, end.f
    jacobian_columns(rhs, t, start, sys, K, cols)
    extrapolate(rhs, at, y, sys, K, cols)
    delta = sys.wk[W_DELTA]
    top = K[R_P + N_COLUMNS - 1]
    for i in range(n):
        delta[i] = top[i]
        y_new[i] = y[i] + top[i]
    rhs(t + h, y_new, sys, f_new, end.aux)
    for i in range(n):
        K[R_FNEW, i] = f_new[i]


@kernel
def lie_error_norm(K, sc, n):
    """The RMS norm of the error estimate T_{k,k} - T_{k,k-1} over the components 0..n-1, each in
    units of sc[i] > 0."""
    e = 0.0
    top = K[R_P + N_COLUMNS - 1]
    for i in range(n):
        e += ((top[i] - K[R_LOW, i]) / sc[i]) ** 2
    return math.sqrt(e / n)


@kernel(inline="always")
def lie_dense(rhs, span, y_new, K, cols):
    """Coefficients F[row0:row0+7] of the step span (layout.Span: from y0 at t0 over h) to y_new
    in dop853's nested form: the quintic Hermite interpolant of y0, f0 = K[R_F0], the midpoint
    (the extrapolation over h / 2 from y0, with the step's Jacobian columns K[R_W1], K[R_W2]) and
    its f, y_new and f_new = K[R_FNEW]; 36 right-hand sides."""
    t, y, h, sys, F = span.t0, span.y0, span.h, span.sys, span.F[span.row0:]
    n, wk = sys.n, sys.wk
    extrapolate(rhs, (t, 0.5 * h), y, sys, K, cols)
    mid = K[R_MID]
    top = K[R_P + N_COLUMNS - 1]
    ytmp = wk[W_YTMP]
    for i in range(n):
        mid[i] = top[i]
        ytmp[i] = y[i] + top[i]
    rhs(t + 0.5 * h, ytmp, sys, K[R_FS], wk[W_AUXTMP])
    for i in range(n):
        data0 = y_new[i] - y[i]
        data1 = h * K[R_F0, i]
        data2 = mid[i]
        data3 = h * K[R_FS, i]
        data4 = h * K[R_FNEW, i]
        for r in range(5):
            F[r, i] = (HERMITE5[r, 0] * data0 + HERMITE5[r, 1] * data1 + HERMITE5[r, 2] * data2
                       + HERMITE5[r, 3] * data3 + HERMITE5[r, 4] * data4)
        F[5, i] = 0.0
        F[6, i] = 0.0
