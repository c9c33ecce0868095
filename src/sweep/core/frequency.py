"""Frequencies at the halt levels (numba kernels; no allocation, no exceptions, fixed-size buffers).

Precession over whole cycles (docs/model.md, 'Frequencies at the levels'). theta is integrated as a
passive quadrature when the frequencies are asked for. Its first-reach times of the lattice
theta0 + j 2 pi/S, j = 1, 2, ... (S = SAMPLES_PER_CYCLE), upwards and downwards, are located on the
dense output (theta reaching a lattice value it never reached before), with Phi there. A ring
buffer per direction keeps the last HALF_CYCLES cycles of them. A level crossed at t_L takes the
direction of the first lattice point reached after t_L; J is the last index reached at or before
t_L, and the window is the lattice indices J - m S ... J + m S: m = HALF_CYCLES whole cycles on
each side, or as many as the scene has before and after the level (the same on both sides); where
one side has none (the level is reached within the first cycle, or the motion ends within one
after it), the whole cycle next to the level on the other side, with the next one for its error
(window_values). Then

    mean dtheta/dtau = d 2 pi (2 m) / (T(J + m S) - T(J - m S)),   d = +1 or -1 (direction),

which cannot collapse: theta has to turn 2m full times inside the window whatever Phi does.

Ringing ratio: the dominant frequency of Phi over the same window, in cycles of Phi per
precession cycle: the Phi samples are uniform in theta (S per cycle); nu is the frequency of the
sinusoid that, with a straight line, fits them best in least squares weighted by a 4-term
Blackman-Harris window (a periodogram without the leakage of the negative frequency: exact for a
tone on a line), searched over nu in [2/(2m), S/2] on a grid of 1/(4 * 2m) and refined by golden
section. The ringing frequency is nu times the precession frequency (simulate.py).

Normal-force maxima (f_hat = 2/T over three consecutive counted maxima, tracking.py): a located
maximum of Phi counts only with hysteresis H = PEAK_HYSTERESIS A, A the amplitude of Phi's swing
(the rise of the last counted maximum above the lowest Phi before it; |Phi(0)| before the first):
it rose H above the lowest Phi since the previous counted maximum, and it is confirmed once Phi
(at a step end) has fallen H below it; of the maxima in between, the highest counts.

Buffer `fq` (float64, (FQ_LEVEL0 + n_levels) x FQ_COLS): row 0 scalars (Q_*), rows 1, 2 the ring
buffers (up, down: times then Phi), row FQ_LEVEL0 + L the window of level L (LW_* head, then the
times and the Phi values at window positions 0 .. WIN_LEN - 1, position HALF_CYCLES S being J).
level_out columns written here (layout.L_*): L_PRECESSION the mean dtheta/dtau (centred window),
L_PREC_SIDE the one-sided one, L_PREC_ERR the window error, L_WINDOW the window's side, L_RINGING
the ringing ratio, L_CYCLES the cycles in the window.
"""
from __future__ import annotations

import math

from .constants import EPS
from .contact_rhs import eval_rhs
from .dop853 import dense_component, dense_eval
from .jit import kernel
from .layout import (L_CYCLES, L_PRECESSION, L_PREC_ERR, L_PREC_SIDE, L_RINGING, L_WINDOW, W_AUXBUF, W_DYBUF, W_YBUF,
                     W_YSEG)
from .model import X_PHI, Y_THETA

SAMPLES_PER_CYCLE = 16          # S: lattice points per precession cycle (Nyquist: 8 Phi cycles per precession cycle)
HALF_CYCLES = 4                 # whole precession cycles on each side of the level (8 in the window)
RING = HALF_CYCLES * SAMPLES_PER_CYCLE + 1
WIN_LEN = 2 * HALF_CYCLES * SAMPLES_PER_CYCLE + 1
ONE_SIDED_CHANGE = 0.5           # a one-sided value needs its two cycles' rates within this fraction
PEAK_HYSTERESIS = 0.01          # fraction of Phi's swing a normal-force maximum must rise and fall by
RINGING_MIN_AMPLITUDE = 1e-8    # below this amplitude of Phi's oscillation (relative to Phi) no ringing
ZERO_PAD = 4                    # coarse frequency grid: 1/(ZERO_PAD window length) per cycle
BH = (0.35875, 0.48829, 0.14128, 0.01168)   # 4-term Blackman-Harris window (sidelobes < -92 dB)
LOWEST_BIN = 2.0                # lowest frequency searched, in bins of 1/(window cycles): above the
                                # detrended mean's leakage, below a ringing of 0.25 per cycle in 8 cycles

# row 0 of fq
Q_TH0 = 0          # lattice origin theta(0)
Q_J = 1            # 1, 2: last lattice index reached upwards, downwards
Q_HEAD = 3         # 3, 4: ring position of the last entry
Q_CNT = 5          # 5, 6: entries in the ring
Q_CAND = 7         # 1 while a maximum of Phi waits for its confirming drop
Q_CAND_T = 8
Q_CAND_PHI = 9
Q_CAND_TH = 10
Q_LO = 11          # lowest Phi since the last counted maximum
Q_AMP = 12         # amplitude of Phi's swing: rise of the last counted maximum
Q_CAND_RISE = 13   # rise of the candidate above Q_LO
FQ_LEVEL0 = 3      # first row of the level windows
# head of a level window row
LW_STATE = 0       # 0 not crossed, 1 crossed (waiting for a lattice point after it), 2 collecting, 3 done
LW_TL = 1
LW_DIR = 2         # ring of the window's direction: 0 up, 1 down
LW_MB = 3          # whole cycles available before the level
LW_NF = 4          # lattice points collected after the level
LW_HEAD = 8
FQ_COLS = LW_HEAD + 2 * WIN_LEN


@kernel
def freq_start(theta0, phi0, fq):
    """Lattice origin at theta(0), both rings holding index 0 at tau = 0, no maximum pending."""
    for r in range(fq.shape[0]):
        for c in range(fq.shape[1]):
            fq[r, c] = 0.0
    fq[0, Q_TH0] = theta0
    for r in range(2):
        fq[1 + r, 0] = 0.0
        fq[1 + r, RING] = phi0
        fq[0, Q_CNT + r] = 1.0
    fq[0, Q_LO] = phi0
    fq[0, Q_AMP] = abs(phi0)


@kernel
def open_level(L, tl, fq, windows):
    """Level L was crossed at tl: its window waits for the first lattice point after tl (windows[0]:
    the windows still open)."""
    row = FQ_LEVEL0 + L
    fq[row, LW_STATE] = 1.0
    fq[row, LW_TL] = tl
    windows[0] += 1


@kernel
def theta_crossing(span, ta, tb, target, sgn):
    """A time where sgn (theta - target) turns >= 0 in [ta, tb] (negative at ta, >= 0 at tb), to
    round-off (Illinois regula falsi on the dense output of span, layout.Span)."""
    ga = sgn * (dense_component(span, ta, Y_THETA) - target)
    gb = sgn * (dense_component(span, tb, Y_THETA) - target)
    if not ga < 0.0:
        return ta
    side = 0
    for _ in range(200):
        if tb - ta <= 4.0 * EPS * max(abs(tb), 1.0) or gb == 0.0:
            break
        tm = (ta * gb - tb * ga) / (gb - ga)
        if not (ta < tm < tb):
            tm = 0.5 * (ta + tb)
        gm = sgn * (dense_component(span, tm, Y_THETA) - target)
        if gm < 0.0:
            ta, ga = tm, gm
            if side == -1:
                gb *= 0.5
            side = -1
        else:
            tb, gb = tm, gm
            if side == 1:
                ga *= 0.5
            side = 1
    return tb


@kernel
def _next_target(r, fq):
    """theta of the next new lattice point in direction r (0 upwards, 1 downwards), and the sign."""
    sgn = 1.0 - 2.0 * r
    return fq[0, Q_TH0] + sgn * (fq[0, Q_J + r] + 1.0) * (2.0 * math.pi / SAMPLES_PER_CYCLE), sgn


@kernel
def lattice_due(theta_end, fq):
    """Whether a segment ending at theta_end reaches a new lattice point (lattice_step reads the
    dense output only then)."""
    for r in range(2):
        target, sgn = _next_target(r, fq)
        if not sgn * (theta_end - target) < 0.0:   # as _next_crossing decides
            return True
    return False


@kernel
def _next_crossing(r, t_lo, seg_end, theta_end, span, fq):
    """Time of the next new lattice point in direction r on [t_lo, seg_end] of span's dense output
    (layout.Span, this step's: row 0), or inf."""
    target, sgn = _next_target(r, fq)
    if sgn * (theta_end - target) < 0.0:
        return math.inf
    return theta_crossing(span, t_lo, seg_end, target, sgn)


@kernel
def lattice_step(span, seg_end, windows, rec):
    """The new lattice points on the segment [t, seg_end] of the step span (layout.Span: this
    step's dense output, from t = span.t0; its end state in wk[W_YSEG]) in time order: Phi there
    (dense output, the span's contact state), the rings, and the level windows they open, fill or
    complete (windows[0]: the windows still open, layout.Tracking)."""
    sys = span.sys
    wk = sys.wk
    t = span.t0
    fq, level_out = rec.fq, rec.levels
    theta_end = wk[W_YSEG, Y_THETA]
    tu = _next_crossing(0, t, seg_end, theta_end, span, fq)
    td = _next_crossing(1, t, seg_end, theta_end, span, fq)
    while tu < math.inf or td < math.inf:
        r = 0 if tu <= td else 1
        tc = tu if r == 0 else td
        dense_eval(span, tc, sys.n, wk[W_YBUF])
        eval_rhs(tc, wk[W_YBUF], sys, wk[W_DYBUF], wk[W_AUXBUF])
        push_lattice(r, tc, wk[W_AUXBUF, X_PHI], fq, level_out, windows)
        if r == 0:
            tu = _next_crossing(0, tc, seg_end, theta_end, span, fq)
        else:
            td = _next_crossing(1, tc, seg_end, theta_end, span, fq)


@kernel
def push_lattice(r, tc, phi, fq, level_out, windows):
    """Lattice point J + 1 of direction r reached at tc with Phi = phi: open the windows of levels
    crossed before tc (their past from the ring), append it to the open windows of direction r,
    complete those that have as many cycles after the level as before, then store it in the ring."""
    S = SAMPLES_PER_CYCLE
    mid = HALF_CYCLES * S
    cnt = int(fq[0, Q_CNT + r])
    head = int(fq[0, Q_HEAD + r])
    for L in range(fq.shape[0] - FQ_LEVEL0):
        row = FQ_LEVEL0 + L
        if fq[row, LW_STATE] == 1.0 and tc > fq[row, LW_TL]:
            mb = min(HALF_CYCLES, (cnt - 1) // S)
            fq[row, LW_DIR] = r
            fq[row, LW_MB] = mb
            fq[row, LW_NF] = 0.0
            for k in range(mb * S + 1):
                src = (head - k) % RING
                fq[row, LW_HEAD + mid - k] = fq[1 + r, src]
                fq[row, LW_HEAD + WIN_LEN + mid - k] = fq[1 + r, RING + src]
            # no whole cycle before the level: the window collects HALF_CYCLES after it (one-sided)
            fq[row, LW_STATE] = 2.0
        if fq[row, LW_STATE] == 2.0 and fq[row, LW_DIR] == r:
            nf = int(fq[row, LW_NF]) + 1
            fq[row, LW_HEAD + mid + nf] = tc
            fq[row, LW_HEAD + WIN_LEN + mid + nf] = phi
            fq[row, LW_NF] = nf
            mb = int(fq[row, LW_MB])
            if nf == (mb if mb > 0 else HALF_CYCLES) * S:
                window_values(L, mb, nf // S, fq, level_out)
                windows[0] -= 1
    head = (head + 1) % RING
    fq[1 + r, head] = tc
    fq[1 + r, RING + head] = phi
    fq[0, Q_HEAD + r] = head
    fq[0, Q_CNT + r] = min(cnt + 1, RING)
    fq[0, Q_J + r] += 1.0


@kernel
def cycle_rate(fq, row, a, b):
    """Mean dtheta/dtau between the window positions a < b of level row `row` (whole cycles apart)."""
    sgn = 1.0 - 2.0 * fq[row, LW_DIR]
    dt = fq[row, LW_HEAD + b] - fq[row, LW_HEAD + a]
    return sgn * 2.0 * math.pi * (b - a) / SAMPLES_PER_CYCLE / dt if dt > 0.0 else math.nan


@kernel
def window_values(L, mb, ma, fq, level_out):
    """The precession rate and ringing ratio of level L from the whole cycles around it: mb before
    and ma after it in its window (docs/model.md, 'Frequencies at the levels').

    Centred (m = min(mb, ma) >= 1): the mean dtheta/dtau and the ringing ratio over m whole cycles
    on each side; its window error, the bias of the mean over a window centred in theta, which
    grows as the window's length squared, is its difference from the mean over the two cycles next
    to the level times m^2/(m^2 - 1) (m >= 2), or half the difference of those two cycles' own
    means, a first-order bound (m = 1). One-sided (whole cycles on one side only, at
    least two: the level is reached within the first precession cycle, or the motion ends within
    one after it): the mean over the whole cycle next to the level, its window error the
    difference from the next cycle's mean (the change of the rate over one cycle, where the level
    lies half a cycle from the first's centre), if that is below ONE_SIDED_CHANGE of it; no ringing
    ratio (its tone fit needs the centred window). Fewer: no value."""
    row = FQ_LEVEL0 + L
    S = SAMPLES_PER_CYCLE
    mid = HALF_CYCLES * S
    m = min(mb, ma)
    if m >= 1:
        i0 = mid - m * S
        i1 = mid + m * S
        rate = cycle_rate(fq, row, i0, i1)
        level_out[L, L_PRECESSION] = rate
        if m >= 2:
            # the window's bias grows as its length squared: Richardson's estimate of the 2m-cycle
            # mean's from its difference to the 2-cycle one
            level_out[L, L_PREC_ERR] = abs(rate - cycle_rate(fq, row, mid - S, mid + S)) * m * m / (m * m - 1.0)
        else:
            level_out[L, L_PREC_ERR] = 0.5 * abs(cycle_rate(fq, row, mid, mid + S) - cycle_rate(fq, row, mid - S, mid))
        level_out[L, L_RINGING] = ringing_ratio(fq[row], LW_HEAD + WIN_LEN + i0, LW_HEAD + WIN_LEN + i1, S)
        level_out[L, L_CYCLES] = 2.0 * m
        level_out[L, L_WINDOW] = 0.0
    elif max(mb, ma) >= 2:
        side = 1.0 if ma >= 2 else -1.0
        if side > 0.0:
            near = cycle_rate(fq, row, mid, mid + S)
            far = cycle_rate(fq, row, mid + S, mid + 2 * S)
        else:
            near = cycle_rate(fq, row, mid - S, mid)
            far = cycle_rate(fq, row, mid - 2 * S, mid - S)
        # a rate that changes by half or more from one cycle to the next (theta turning back, an
        # impact) has no frequency at the level
        if abs(near - far) < ONE_SIDED_CHANGE * abs(near):
            level_out[L, L_PREC_SIDE] = near
            level_out[L, L_PREC_ERR] = abs(near - far)
            level_out[L, L_CYCLES] = 1.0
            level_out[L, L_WINDOW] = side
    fq[row, LW_STATE] = 3.0


@kernel
def finish_levels(fq, level_out, cut):
    """At the end of the scene: windows still open get what their whole cycles give
    (window_values: the largest centred window, else one side's) where the motion ended there
    (t_max, an event's outcome, twice a halt's tau), no value where a numerical guard stopped the
    steps (cut: step budget, step floor, a NaN state)."""
    for L in range(fq.shape[0] - FQ_LEVEL0):
        row = FQ_LEVEL0 + L
        if fq[row, LW_STATE] == 2.0 and not cut:
            window_values(L, int(fq[row, LW_MB]), int(fq[row, LW_NF]) // SAMPLES_PER_CYCLE, fq, level_out)
        fq[row, LW_STATE] = 3.0


@kernel
def _tone_fit(v, i0, i1, S, nu, e2s):
    """Weighted least squares of the detrended samples v[i0..i1] (already weighted-orthogonal to
    1 and k, weights: Blackman-Harris) on cos and sin of 2 pi nu k/S, with those two also
    projected off 1 and k. Returns (explained weighted sum of squares, amplitude). e2s: 1/sqrt of
    the weighted sum of (k - kbar)^2; the weights sum to 1 (normalised here)."""
    N = i1 - i0 + 1
    c = math.cos(2.0 * math.pi * nu / S)
    s = math.sin(2.0 * math.pi * nu / S)
    zr = 1.0
    zi = 0.0
    km = 0.5 * (N - 1)
    wsum = 0.0
    scc = 0.0
    sss = 0.0
    scs = 0.0
    sc1 = 0.0
    ss1 = 0.0
    sc2 = 0.0
    ss2 = 0.0
    pc = 0.0
    ps = 0.0
    for k in range(N):
        w = _bh(k, N)
        wsum += w
        e2 = (k - km) * e2s
        scc += w * zr * zr
        sss += w * zi * zi
        scs += w * zr * zi
        sc1 += w * zr
        ss1 += w * zi
        sc2 += w * zr * e2
        ss2 += w * zi * e2
        pc += w * v[i0 + k] * zr
        ps += w * v[i0 + k] * zi
        zr, zi = zr * c - zi * s, zr * s + zi * c
    # Gram matrix of cos, sin after removing their projections on 1 and k (orthonormal:
    # 1/sqrt(wsum) and e2 scaled so that sum w e2^2 = 1, by the symmetric weights about km)
    g11 = scc - sc1 * sc1 / wsum - sc2 * sc2
    g22 = sss - ss1 * ss1 / wsum - ss2 * ss2
    g12 = scs - sc1 * ss1 / wsum - sc2 * ss2
    det = g11 * g22 - g12 * g12
    if not det > 1e-14 * (g11 * g22):
        return 0.0, 0.0
    a = (g22 * pc - g12 * ps) / det
    b = (g11 * ps - g12 * pc) / det
    return a * pc + b * ps, math.sqrt(a * a + b * b)


@kernel
def _bh(k, N):
    """4-term Blackman-Harris window at sample k of N."""
    x = 2.0 * math.pi * k / (N - 1)
    return BH[0] - BH[1] * math.cos(x) + BH[2] * math.cos(2.0 * x) - BH[3] * math.cos(3.0 * x)


@kernel
def ringing_ratio(v, i0, i1, S):
    """Dominant frequency of the samples v[i0..i1] (uniform, S per cycle) in cycles per cycle: the
    frequency of the sinusoid that, with a straight line, fits them best by least squares weighted
    with a Blackman-Harris window (exact for a tone on a line: no leakage of its negative
    frequency). NaN where its amplitude is below RINGING_MIN_AMPLITUDE of the samples' mean.
    Overwrites v[i0..i1] with the samples less their weighted straight line."""
    N = i1 - i0 + 1
    if N < 5:
        return math.nan
    km = 0.5 * (N - 1)
    sw = 0.0
    swv = 0.0
    swkk = 0.0
    swkv = 0.0
    for k in range(N):
        w = _bh(k, N)
        sw += w
        swv += w * v[i0 + k]
        swkk += w * (k - km) * (k - km)
        swkv += w * (k - km) * v[i0 + k]
    mean = swv / sw
    slope = swkv / swkk
    for k in range(N):
        v[i0 + k] = v[i0 + k] - mean - slope * (k - km)
    e2s = 1.0 / math.sqrt(swkk)
    cycles = (N - 1) / S
    nu_lo = LOWEST_BIN / cycles
    nu_hi = 0.5 * S
    dnu = 1.0 / (ZERO_PAD * cycles)
    best = -1.0
    nu_best = nu_lo
    nu = nu_lo
    while nu <= nu_hi:
        pw, _ = _tone_fit(v, i0, i1, S, nu, e2s)
        if pw > best:
            best = pw
            nu_best = nu
        nu += dnu
    # golden section on [nu_best - dnu, nu_best + dnu]
    g = 0.3819660112501051
    a = max(nu_best - dnu, nu_lo)
    b = min(nu_best + dnu, nu_hi)
    x1 = a + g * (b - a)
    x2 = b - g * (b - a)
    f1, _ = _tone_fit(v, i0, i1, S, x1, e2s)
    f2, _ = _tone_fit(v, i0, i1, S, x2, e2s)
    for _ in range(100):
        if b - a <= 1e-13 * b:
            break
        if f1 >= f2:
            b = x2
            x2 = x1
            f2 = f1
            x1 = a + g * (b - a)
            f1, _ = _tone_fit(v, i0, i1, S, x1, e2s)
        else:
            a = x1
            x1 = x2
            f1 = f2
            x2 = b - g * (b - a)
            f2, _ = _tone_fit(v, i0, i1, S, x2, e2s)
    nu_star = 0.5 * (a + b)
    _, amp = _tone_fit(v, i0, i1, S, nu_star, e2s)
    if not amp > RINGING_MIN_AMPLITUDE * abs(mean):
        return math.nan
    return nu_star


@kernel
def peak_candidate(tpk, pvk, thk, fq):
    """A located maximum of Phi: it becomes the candidate if it rose PEAK_HYSTERESIS A above the
    lowest Phi since the last counted maximum, or replaces a lower candidate."""
    rise = pvk - fq[0, Q_LO]
    if fq[0, Q_CAND] > 0.0:
        if pvk <= fq[0, Q_CAND_PHI]:
            return
    elif not rise >= PEAK_HYSTERESIS * fq[0, Q_AMP]:
        return
    fq[0, Q_CAND] = 1.0
    fq[0, Q_CAND_T] = tpk
    fq[0, Q_CAND_PHI] = pvk
    fq[0, Q_CAND_TH] = thk
    fq[0, Q_CAND_RISE] = rise


@kernel
def peak_confirmed(phi_c, fq):
    """Phi at a step end: True if it confirms the candidate maximum (a fall of PEAK_HYSTERESIS A
    below it; its rise becomes A); otherwise it lowers the running minimum."""
    if fq[0, Q_CAND] > 0.0:
        if fq[0, Q_CAND_PHI] - phi_c >= PEAK_HYSTERESIS * fq[0, Q_AMP]:
            fq[0, Q_CAND] = 0.0
            fq[0, Q_AMP] = fq[0, Q_CAND_RISE]
            fq[0, Q_LO] = phi_c
            return True
        return False
    fq[0, Q_LO] = min(fq[0, Q_LO], phi_c)
    return False
