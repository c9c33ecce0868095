"""Linearly implicit Euler extrapolation: the stiff-stable stepper of slow slides.

A slide's slip direction relaxes at the rate ~ mu_d Phi / |u|, which at slow slips is far faster
than the motion (docs/model.md, 'Slow slip'); DOP853 must step within its stability bound of that
rate. This stepper treats the dynamics linearly implicitly and steps at what the motion's accuracy
needs. It knows no physics: the caller gives the right-hand side, `rhs(t, y, sys, dy, aux)` as
dop853's, the number m <= N_JAC of leading components it reads (the others are quadratures, whose
Jacobian columns are 0), and a pair of those components (c1, c2) whose difference steps scale
with their joint magnitude (the slip, where the friction's direction turns with u / |u|).

The step of size h from y (f = rhs(t, y)): for each n_j of SEQUENCE, n_j sub-steps of
h_j = h / n_j of the linearly implicit Euler method

    (I - h_j J) (Y_{i+1} - Y_i) = h_j f(t + i h_j, Y_i),      Y_0 = y,

J the Jacobian at the step start (forward differences over the m leading components), then
Aitken-Neville extrapolation of the increments T_{j,1} = Y_{n_j} - y in h_j (the method has an
asymptotic expansion in powers of h_j, Hairer & Wanner (1996), IV.9):

    T_{j,q+1} = T_{j,q} + (T_{j,q} - T_{j-1,q}) / (n_j / n_{j-q} - 1).

y_new = y + T_{k,k} (k = N_COLUMNS = 8), or T_{j,j} of the first column j >= the caller's `first`
whose estimate has converged (its error then of order j: fewer right-hand sides where the step is
short for order 8). The error estimate is T_{k,k} - T_{k-1,k-1}, the error of the order-7 diagonal
entry (as dop853's estimator: the same step-size exponent): on the slow slides
of the paper's disk at mu_d = mu_s the true local error of the steps so controlled is 0.32 / 3.2 /
7.1 times the tolerance (median, p99, max; dop853 0.09 / 2.3 / 4.9), where T_{k,k} - T_{k,k-1}
let it reach 2.5 / 25 / 77 (docs/model.md, 'Slow slip').

The dense output (lie_dense) is the quintic Hermite interpolant of the step's ends and of its
midpoint, computed by the same extrapolation over h / 2, with the derivatives there, written as
dop853's coefficients (its continuous extension's nested form, the highest two rows 0), so the
scan, the levels and the recorders read it as they read dop853's. It recomputes the Jacobian from
the step's start (the same, bit for bit), so a step keeps only K[R_F0] and K[R_FNEW] for it, which
the rows dop853's stages are kept in for a previous step's dense output hold.

Rows of the stage buffer K: R_F0 f at the step start, R_P.. the extrapolation's diagonal, R_D the
sub-step increment, R_FS a sub-step's f, R_LOW T_{k-1,k-1}, R_FNEW f at the step end, R_MID the
midpoint's increment. The work buffer's rows W_JAC hold the Jacobian's columns, W_LU the factored
I - h_j J of the m leading components (row r: its row r, and in column N_JAC the pivot).
"""
from __future__ import annotations

import math

import numpy as np

from .jit import kernel
from .layout import W_AUXTMP, W_DELTA, W_JAC, W_LU, W_YTMP

SEQUENCE = np.array([1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0])
N_COLUMNS = 8
N_JAC = 6   # rows W_JAC, W_LU: the most leading components the Jacobian takes

R_F0, R_P = 0, 1                             # R_P .. R_P + N_COLUMNS - 1
R_D = R_P + N_COLUMNS                        # 9
R_FS, R_LOW, R_FNEW, R_MID = 10, 11, 12, 13

# Forward-difference step of a Jacobian column, relative to the component's magnitude (at least 1;
# the pair's, their joint magnitude): the method keeps its order for any matrix, so the differences
# need only resolve the stiff couplings
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
def jacobian(rhs, t, start, sys, comps):
    """The Jacobian's columns of the comps = (m, c1, c2) leading components at (t, start.y) (start:
    layout.Point, f = rhs there) by forward differences, into wk[W_JAC + c]."""
    y, f = start.y, start.f
    n, wk = sys.n, sys.wk
    m, c1, c2 = comps
    ytmp = wk[W_YTMP]
    pair = math.hypot(y[c1], y[c2])
    for c in range(m):
        for i in range(n):
            ytmp[i] = y[i]
        size = pair if (c == c1 or c == c2) else max(abs(y[c]), 1.0)
        ytmp[c] = y[c] + JAC_STEP * max(size, 1e-300)
        d = ytmp[c] - y[c]
        col = wk[W_JAC + c]
        rhs(t, ytmp, sys, col, wk[W_AUXTMP])
        for i in range(n):
            col[i] = (col[i] - f[i]) / d


@kernel
def factor(hs, m, wk):
    """LU factors (partial pivoting) of I - hs J over the m leading components into wk[W_LU..]."""
    for r in range(m):
        row = wk[W_LU + r]
        for c in range(m):
            row[c] = (1.0 if r == c else 0.0) - hs * wk[W_JAC + c, r]
    for c in range(m):
        piv = c
        for r in range(c + 1, m):
            if abs(wk[W_LU + r, c]) > abs(wk[W_LU + piv, c]):
                piv = r
        wk[W_LU + c, N_JAC] = piv
        if piv != c:
            for q in range(m):
                a = wk[W_LU + c, q]
                wk[W_LU + c, q] = wk[W_LU + piv, q]
                wk[W_LU + piv, q] = a
        for r in range(c + 1, m):
            l = wk[W_LU + r, c] / wk[W_LU + c, c]
            wk[W_LU + r, c] = l
            for q in range(c + 1, m):
                wk[W_LU + r, q] -= l * wk[W_LU + c, q]


@kernel
def solve_into(b, hs, m, n, wk, x):
    """x += the solution of (I - hs J) x' = b (factor's factors; J's columns beyond m are 0): the
    m leading components from the factors, the others b_i + hs sum_c J_ic x'_c."""
    lu = wk[W_LU:W_LU + N_JAC]
    z = wk[W_LU:W_LU + N_JAC, N_JAC + 1]       # (the m leading components of x', in place)
    for c in range(m):
        z[c] = b[c]
    for c in range(m):
        piv = int(lu[c, N_JAC])
        if piv != c:
            a = z[c]
            z[c] = z[piv]
            z[piv] = a
        for r in range(c + 1, m):
            z[r] -= lu[r, c] * z[c]
    for c in range(m - 1, -1, -1):
        v = z[c]
        for q in range(c + 1, m):
            v -= lu[c, q] * z[q]
        z[c] = v / lu[c, c]
    for i in range(n):
        if i < m:
            x[i] += z[i]
        else:
            v = b[i]
            for c in range(m):
                v += hs * wk[W_JAC + c, i] * z[c]
            x[i] += v


@kernel(inline="always")
def extrapolate(rhs, at, y, sys, K, m):
    """The extrapolation over h from y at t (K[R_F0] = f there, wk[W_JAC..] the Jacobian's columns
    of the m leading components), at = (t, h, sc, first, nc): from `first` columns on it stops at
    the first column j whose estimate, the RMS of (T_jj - T_{j-1,j-1}) / sc over the nc leading
    components, is within 1 (the step's error is then that column's, of order j). T_{j,j} (the
    increment) in K[R_P + N_COLUMNS - 1], T_{j-1,j-1} in K[R_LOW]; returns j."""
    t, h, sc, first, nc = at
    n, wk = sys.n, sys.wk
    ytmp = wk[W_YTMP]
    aux = wk[W_AUXTMP]
    d, fs = K[R_D], K[R_FS]
    for j in range(N_COLUMNS):
        nj = SEQUENCE[j]
        hs = h / nj
        factor(hs, m, wk)
        for i in range(n):
            d[i] = 0.0
        for s in range(int(nj)):
            fi = K[R_F0]
            if s > 0:
                for i in range(n):
                    ytmp[i] = y[i] + d[i]
                rhs(t + s * hs, ytmp, sys, fs, aux)
                fi = fs
            # (the right-hand side times hs, in place: fi is not read again)
            for i in range(n):
                ytmp[i] = hs * fi[i]
            solve_into(ytmp, hs, m, n, wk, d)
        for i in range(n):
            cur = d[i]
            for q in range(1, j + 1):
                r = nj / SEQUENCE[j - q]
                prev = K[R_P + q - 1, i]
                if q == j:
                    K[R_LOW, i] = prev
                K[R_P + q - 1, i] = cur
                cur = cur + (cur - prev) / (r - 1.0)
            K[R_P + j, i] = cur
        if j + 1 >= first and j + 1 < N_COLUMNS:
            e = 0.0
            for i in range(nc):
                e += ((K[R_P + j, i] - K[R_LOW, i]) / sc[i]) ** 2
            if e <= nc:
                for i in range(n):
                    K[R_P + N_COLUMNS - 1, i] = K[R_P + j, i]
                return j + 1
    return N_COLUMNS


@kernel(inline="always")
def lie_step(rhs, at, ends, sys, K, comps):
    """One extrapolation step of size h from start at t (at = (t, h, sc, first, nc), as
    extrapolate's: the tolerances sc of the nc leading components, from `first` columns on the
    first converged column ends it; ends = (start, end), each a layout.Point; start: y, f at t):
    end.y, and end.f = K[R_FNEW] = f(t + h, end.y) with its aux end.aux; the increment before
    rounding in sys.wk[W_DELTA]; the error estimate's rows for lie_error_norm. comps = (m, c1, c2):
    the leading components the Jacobian takes, and the pair whose difference steps scale together
    (jacobian). Returns the columns used (the step's order)."""
    t, h = at[0], at[1]
    start, end = ends
    n = sys.n
    y, y_new, f_new = start.y, end.y, end.f
    for i in range(n):
        K[R_F0, i] = start.f[i]
    jacobian(rhs, t, start, sys, comps)
    columns = extrapolate(rhs, at, y, sys, K, comps[0])
    delta = sys.wk[W_DELTA]
    top = K[R_P + N_COLUMNS - 1]
    for i in range(n):
        delta[i] = top[i]
        y_new[i] = y[i] + top[i]
    rhs(t + h, y_new, sys, f_new, end.aux)
    for i in range(n):
        K[R_FNEW, i] = f_new[i]
    return columns


@kernel
def lie_error_norm(K, sc, n):
    """The RMS norm of the error estimate T_{k,k} - T_{k-1,k-1} over the components 0..n-1, each in
    units of sc[i] > 0."""
    e = 0.0
    top = K[R_P + N_COLUMNS - 1]
    for i in range(n):
        e += ((top[i] - K[R_LOW, i]) / sc[i]) ** 2
    return math.sqrt(e / n)


@kernel(inline="always")
def lie_dense(rhs, span, y_new, K, comps):
    """Coefficients F[row0:row0+7] of the step span (layout.Span: from y0 at t0 over h) to y_new
    in dop853's nested form: the quintic Hermite interpolant of y0, f0 = K[R_F0], the midpoint
    (the extrapolation over h / 2 from y0) and its f, y_new and f_new = K[R_FNEW]; 29 right-hand
    sides (comps = (m, c1, c2), as lie_step's). The midpoint's extrapolation takes the Jacobian last
    computed (wk[W_JAC]: this step's, or for a previous step's dense output the step after it): the
    method has its order whatever the matrix, which need only carry the stiff direction, and
    that of two consecutive steps of a slide does."""
    t, y, h, sys, F = span.t0, span.y0, span.h, span.sys, span.F[span.row0:]
    n, wk = sys.n, sys.wk
    extrapolate(rhs, (t, 0.5 * h, K[R_F0], N_COLUMNS, 1), y, sys, K, comps[0])
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
