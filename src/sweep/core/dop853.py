"""DOP853 (Dormand & Prince 8(5,3)) step, error norm, dense output and starting step.

The error norm is Hairer's dop853 (Hairer, Norsett & Wanner (1993), II.10: 5th/3rd-order embedded
estimates); the step-size factor that follows from it is the controller's (controller.py, with this
method's ERR_EXPONENT). The stepper knows no state layout: the caller gives the error norm its
per-component scales (atol_i + rtol |y_i| with whatever component rules it has: the integrator's
accept.error_scale) and the number of leading components the norms run over. Nor does it know
the physics: the right-hand side comes in as a kernel argument, `rhs(t, y, sys, dy, aux)` (dy =
d y/d t and its aux at (t, y); the integrator passes contact_rhs.eval_rhs), with `sys` (layout.System)
passed through to it; of sys the stepper reads only the state size n and the work buffer wk (its
rows W_YTMP, W_DYTMP, W_AUXTMP, W_DELTA). The sums over the stages are straight-line code generated
from the tableau (dop853_sums.py, from tableau.py).

The kernels that call rhs (dop853_sums.main_stages and dense_stages, rk_step, dense_coeffs,
initial_step) are inlined into their callers (inline="always"). numba compiles a kernel passed as
a value into a compiled call as the address of its Python object, and a library holding such an
address cannot be cached: without the inlining, integrate.run and every caller of these kernels
compiled afresh in each process (and core.jit's cache locator failed on numba's warning).
Inlined, the argument is only ever the name of the function called, and the callers cache as
before.
"""
from __future__ import annotations

import math

from .jit import kernel
from .dop853_sums import dense_rows, dense_stages, error_sums, increment, main_stages
from .layout import W_AUXTMP, W_DELTA, W_DYTMP, W_YTMP
from .tableau import N_STAGES

ERR_EXPONENT = -1.0 / 8.0   # error estimator of order 7 -> h ~ err^(-1/8) (controller.step_factor)
N_DENSE = 7                 # rows of dense-output coefficients


@kernel(inline="always")
def rk_step(rhs, t, h, ends, sys, K):
    """One DOP853 step of size h from start (ends = (start, end), each a layout.Point; start: y, f
    at t): end.y, and end.f = K[12] = f(t + h, end.y) with its aux end.aux; the increment
    end.y - start.y before rounding in sys.wk[W_DELTA]."""
    start, end = ends
    n = sys.n
    y, f, y_new, f_new = start.y, start.f, end.y, end.f
    for i in range(n):
        K[0, i] = f[i]
    main_stages(rhs, t, y, h, sys, K)
    increment(K, h, y, y_new, sys.wk[W_DELTA], n)
    rhs(t + h, y_new, sys, f_new, end.aux)
    for i in range(n):
        K[N_STAGES, i] = f_new[i]


@kernel
def error_norm(K, h, sc, n):
    """Hairer's dop853 error norm of the step of size h whose stages are K, over the components
    0..n-1, component i measured in units of sc[i] > 0 (its tolerance: the caller's weights)."""
    e5 = 0.0
    e3 = 0.0
    for i in range(n):
        a5, a3 = error_sums(K, i)
        e5 += (a5 / sc[i]) ** 2
        e3 += (a3 / sc[i]) ** 2
    if e5 == 0.0 and e3 == 0.0:
        return 0.0
    den = e5 + 0.01 * e3
    return abs(h) * e5 / math.sqrt(den * n)


@kernel(inline="always")
def dense_coeffs(rhs, span, y_new, K):
    """Coefficients F[row0:row0+7] of the continuous extension of the step span (layout.Span: from y0
    at t0 over h, in the system sys) to y_new, from its stages K[0:13] (K[12] = f(t0 + h, y_new));
    3 extra RHS calls: stages 13..15."""
    t, y, h, sys, F = span.t0, span.y0, span.h, span.sys, span.F[span.row0:]
    n = sys.n
    dense_stages(rhs, t, y, h, sys, K)
    for i in range(n):
        dyv = y_new[i] - y[i]
        F[0, i] = dyv
        F[1, i] = h * K[0, i] - dyv
        F[2, i] = 2.0 * dyv - h * (K[N_STAGES, i] + K[0, i])
    dense_rows(K, h, F, n)


@kernel
def dense_eval(span, t, n, out):
    """7th-order continuous extension of the step span (layout.Span, or any record with its fields
    F, row0, y0, t0, h: coefficients F[row0:row0+7] of the step from y0 at t0 over h) at t in
    [t0, t0 + h], its components 0..n-1 into out."""
    for i in range(n):
        out[i] = dense_component(span, t, i)


@kernel
def dense_component(span, t, i):
    """Component i of the continuous extension at t (dense_eval for one component)."""
    F, row0, y_old, t_old, h = span.F, span.row0, span.y0, span.t0, span.h
    x = (t - t_old) / h
    x1 = 1.0 - x
    v = F[row0 + 6, i]
    v = F[row0 + 5, i] + x * v
    v = F[row0 + 4, i] + x1 * v
    v = F[row0 + 3, i] + x * v
    v = F[row0 + 2, i] + x1 * v
    v = F[row0 + 1, i] + x * v
    v = F[row0, i] + x1 * v
    return y_old[i] + x * v


@kernel(inline="always")
def initial_step(rhs, t, y, f, sys, norm):
    """Starting step size (Hairer & Wanner II.4, 'starting step size') from y, f = rhs at (t, y):
    norm = (rtol, atol, nc), its norms over the components 0..nc-1 (the caller's: those that carry
    the dynamics) with scale atol + rtol |y_i|."""
    rtol, atol, nc = norm
    n, wk = sys.n, sys.wk
    d0 = 0.0
    d1 = 0.0
    for i in range(nc):
        sc = atol + rtol * abs(y[i])
        d0 += (y[i] / sc) ** 2
        d1 += (f[i] / sc) ** 2
    d0 = math.sqrt(d0 / nc)
    d1 = math.sqrt(d1 / nc)
    h0 = 1e-6 if (d0 < 1e-5 or d1 < 1e-5) else 0.01 * d0 / d1
    ytmp = wk[W_YTMP]
    dytmp = wk[W_DYTMP]
    for i in range(n):
        ytmp[i] = y[i] + h0 * f[i]
    rhs(t + h0, ytmp, sys, dytmp, wk[W_AUXTMP])
    d2 = 0.0
    for i in range(nc):
        sc = atol + rtol * abs(y[i])
        d2 += ((dytmp[i] - f[i]) / sc) ** 2
    d2 = math.sqrt(d2 / nc) / h0
    if max(d1, d2) <= 1e-15:
        h1 = max(1e-6, h0 * 1e-3)
    else:
        h1 = (0.01 / max(d1, d2)) ** (1.0 / 8.0)
    return min(100.0 * h0, h1)
