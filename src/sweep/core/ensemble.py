"""The batch path: one scene per worker on fixed-size per-worker buffers, and the summary fits.

`solve_scene` integrates one scene with `integrate.run`, the same kernel `sweep.simulate` calls,
and computes the summary's fitted numbers (halt time and its error, approach and ramp exponents)
with `summary_fits`, which `sweep.simulate` calls too. Every buffer has a size fixed by layout.py
and MAX_LEVELS / PEAK_RING: `solve_index` runs on the buffers each of sweep.ensemble's threads
allocates once (`work_buffers`).

The arrays travel in named groups (namedtuples of arrays, which numba passes as their arrays): the
batch's BatchInputs and BatchOutputs, a worker's SceneInputs and Fits, and the run's layout.Work and
layout.Record.

The only difference to `sweep.simulate` is the peak buffer: a ring of the last PEAK_RING normal-
force maxima (layout.T_PEAK_RING) instead of every maximum, since the summary needs only the last
few. A scene whose look-back outgrows the ring (never seen) flags I_OVERFLOW, and the caller reruns
it with `sweep.simulate`.
"""
from __future__ import annotations

import math
from collections import namedtuple

import numpy as np

from .frequency import FQ_COLS, FQ_LEVEL0
from .halt import halt_from_three
from .integrate import run
from .jit import kernel
from .layout import (F_APPROACH, F_TEND, F_THALT, F_THALT_ERR, I_FLAT, I_OVERFLOW, LEVEL_COLS, N_CS, N_KROWS, N_FSTATS, N_ISTATS, N_SETTINGS, N_TRACK,
                     N_WCOLS, N_WORK, PEAK_COLS, SAMPLE_COLS, T_PEAK_RING, TRAJ_COLS, Record, Work)
from .model import N_FULL, N_PARAMS
from .roots import location_tol
from .dop853 import N_DENSE

# Levels per scene on the batch path (a worker's buffers have a fixed size, allocated once).
MAX_LEVELS = 16
# Rows of the ring of normal-force maxima: the level frequencies look back at most ~3 maxima.
PEAK_RING = 16

# --- the batch's arrays and a worker's buffers, grouped (namedtuples of arrays, as layout.Work) ----
# Inputs, one row per scene: Y0 (N_FULL), P (N_PARAMS), S (N_SETTINGS), LE level energies and LV
# level inclinations (rad) (MAX_LEVELS, the first NL used), CHI the time scale (s).
BatchInputs = namedtuple("BatchInputs", "Y0 P S LE LV NL CHI")
# Outputs, one row per scene: ISTATS, FSTATS, LEV (MAX_LEVELS x LEVEL_COLS), YEND (N_FULL), DER (N_DERIVED).
BatchOutputs = namedtuple("BatchOutputs", "ISTATS FSTATS LEV YEND DER")
# One scene's inputs in a worker: the initial state, parameters, settings, level energies and
# level inclinations (the first nl; a worker's buffers have MAX_LEVELS).
SceneInputs = namedtuple("SceneInputs", "y0 p settings level_e levels")
# What a worker fits after the run: scratch (N_SCRATCH x MAX_LEVELS), derived (N_DERIVED, D_*).
Fits = namedtuple("Fits", "scratch derived")

# --- the summary's fitted numbers (SI: s) ------------------------------------------------------
D_THALT, D_THALT_ERR, D_HALT_FINITE, D_APPROACH, D_RAMP, D_RAMP_ERR = range(6)
N_DERIVED = 6
# rows of the per-scene scratch: level times (s), precession frequencies (Hz)
R_LEVEL_T, R_PREC_HZ = 0, 1
N_SCRATCH = 2
TWO_PI = 2.0 * math.pi


# --- halt time and exponents (diagnostics.py explains the method; halt_from_three: core/halt.py) ----
@kernel
def halt_fit(level_t, levels, nl, out):
    """out[D_THALT, D_THALT_ERR, D_HALT_FINITE, D_APPROACH] from the last reached levels
    (diagnostics.halt_time: the fit on the last three; its error bar is the extrapolated remainder
    t_halt - t_last, the part of t_halt the fit adds)."""
    out[D_THALT] = math.nan
    out[D_THALT_ERR] = math.nan
    out[D_HALT_FINITE] = 0.0
    out[D_APPROACH] = math.nan
    i1 = i2 = i3 = -1   # the last three reached levels, i1 the last
    count = 0
    for i in range(nl):
        if math.isfinite(level_t[i]):
            i3, i2, i1 = i2, i1, i
            count += 1
    if count < 3:
        return
    th, p = halt_from_three(level_t[i3], level_t[i2], level_t[i1], levels[i3], levels[i2], levels[i1])
    if not math.isfinite(th):
        return
    out[D_THALT] = th
    out[D_APPROACH] = p
    out[D_HALT_FINITE] = 1.0
    out[D_THALT_ERR] = th - level_t[i1]


@kernel
def ramp_fit(level_t, precession, nl, t_halt):
    """(n, standard error of n), n in Omega ~ (t_halt - t)^(-n): least squares of ln|Omega| on
    ln(t_halt - t) over the levels with finite values before t_halt; NaN if fewer than two (the
    error: fewer than three)."""
    if not math.isfinite(t_halt):
        return math.nan, math.nan
    m = 0
    sx = 0.0
    sy = 0.0
    for i in range(nl):
        om = abs(precession[i])
        if math.isfinite(level_t[i]) and math.isfinite(om) and om > 0.0 and level_t[i] < t_halt:
            m += 1
            sx += math.log(t_halt - level_t[i])
            sy += math.log(om)
    if m < 2:
        return math.nan, math.nan
    mx = sx / m
    my = sy / m
    sxx = 0.0
    sxy = 0.0
    for i in range(nl):
        om = abs(precession[i])
        if math.isfinite(level_t[i]) and math.isfinite(om) and om > 0.0 and level_t[i] < t_halt:
            dx = math.log(t_halt - level_t[i]) - mx
            sxx += dx * dx
            sxy += dx * (math.log(om) - my)
    if not sxx > 0.0:
        return math.nan, math.nan
    slope = sxy / sxx
    if m < 3:
        return -slope, math.nan
    ssr = 0.0
    for i in range(nl):
        om = abs(precession[i])
        if math.isfinite(level_t[i]) and math.isfinite(om) and om > 0.0 and level_t[i] < t_halt:
            r = math.log(om) - my - slope * (math.log(t_halt - level_t[i]) - mx)
            ssr += r * r
    return -slope, math.sqrt(ssr / (m - 2) / sxx)


@kernel
def summary_fits(level_t, prec_hz, levels, nl, lay_flat, fstats, chi, out):
    """The summary's fitted numbers into out (D_*). level_t (s), prec_hz (Hz), levels (rad): the
    first nl entries; fstats: the run's (layout.F_*). A disk that lay flat halted at the located
    event fstats[F_TEND]; where the configured levels give no finite halt, the integrator's fit on
    the levels below them (fstats[F_THALT], tracking.deep_levels) is taken."""
    if lay_flat:
        out[D_THALT] = fstats[F_TEND] * chi
        out[D_THALT_ERR] = location_tol(fstats[F_TEND]) * chi
        out[D_HALT_FINITE] = 1.0
        out[D_APPROACH] = math.nan
    else:
        halt_fit(level_t, levels, nl, out)
        if math.isnan(out[D_THALT]) and not math.isnan(fstats[F_THALT]):
            out[D_THALT] = fstats[F_THALT] * chi
            out[D_THALT_ERR] = fstats[F_THALT_ERR] * chi
            out[D_HALT_FINITE] = 1.0
            out[D_APPROACH] = fstats[F_APPROACH]
    out[D_RAMP], out[D_RAMP_ERR] = ramp_fit(level_t, prec_hz, nl, out[D_THALT])


# --- one scene on fixed buffers -----------------------------------------------------------------
@kernel
def zero_rows(a, rows):
    """a[:rows, :] = 0 (a loop over the rows of a worker's buffer)."""
    for r in range(rows):
        for c in range(a.shape[1]):
            a[r, c] = 0.0


@kernel
def solve_scene(inp, chi, work, rec, fits):
    """Integrate one scene on a worker's buffers, as integrate.integrate does without samples or
    trajectory, then its fits. inp (SceneInputs, nl = inp.level_e.shape[0] levels), chi (s); work
    and rec (layout.Work, layout.Record) have a worker's sizes: rec.levels MAX_LEVELS rows, of
    which the first nl receive the levels (layout.LEVEL_COLS, then pending), rec.fq the frequency
    windows (core.frequency); fits.derived the D_* numbers. Every buffer is reset here."""
    nl = inp.level_e.shape[0]
    for i in range(N_FULL):
        work.y[i] = inp.y0[i]
        rec.y_end[i] = 0.0
    for i in range(N_PARAMS):
        work.p[i] = inp.p[i]
    for i in range(N_CS):
        work.cs[i] = 0.0
    zero_rows(work.wk, work.wk.shape[0])
    zero_rows(work.K, work.K.shape[0])
    zero_rows(work.F, work.F.shape[0])
    zero_rows(rec.peaks, rec.peaks.shape[0])
    zero_rows(rec.fq, FQ_LEVEL0 + nl)
    for i in range(N_TRACK):
        work.trk[i] = 0.0
    work.trk[T_PEAK_RING] = 1.0
    for i in range(N_ISTATS):
        rec.istats[i] = 0
    for i in range(N_FSTATS):
        rec.fstats[i] = 0.0
    lev = rec.levels
    for L in range(nl):
        for c in range(LEVEL_COLS):
            lev[L, c] = math.nan
        lev[L, LEVEL_COLS] = 0.0
    # the scene's own sizes: nl levels, no samples, no trajectory
    run(inp.settings, inp.level_e, fits.scratch[0, :0], work,
        Record(rec.istats, rec.fstats, lev[:nl], rec.samples[:0], rec.traj[:0], rec.peaks, rec.y_end,
               rec.fq[:FQ_LEVEL0 + nl]))
    # the fits on the level times (s) and precession frequencies (Hz), as sweep.simulate forms them
    scratch = fits.scratch
    for L in range(nl):
        scratch[R_LEVEL_T, L] = lev[L, 0] * chi
        scratch[R_PREC_HZ, L] = abs(lev[L, 2]) / chi / TWO_PI
    summary_fits(scratch[R_LEVEL_T], scratch[R_PREC_HZ], inp.levels, nl, rec.istats[I_FLAT] != 0,
                 rec.fstats, chi, fits.derived)


# --- a worker over the batch ---------------------------------------------------------------------
def work_buffers():
    """One worker's buffers, (SceneInputs, Work, Record, Fits), allocated once per thread."""
    inp = SceneInputs(np.zeros(N_FULL), np.zeros(N_PARAMS), np.zeros(N_SETTINGS), np.zeros(MAX_LEVELS),
                      np.zeros(MAX_LEVELS))
    work = Work(np.zeros(N_FULL), np.zeros(N_PARAMS), np.zeros(N_CS), np.zeros((N_WORK, N_WCOLS)),
                np.zeros((N_KROWS, N_FULL)), np.zeros((2 * N_DENSE, N_FULL)), np.zeros(N_TRACK))
    rec = Record(np.zeros(N_ISTATS, np.int64), np.zeros(N_FSTATS), np.zeros((MAX_LEVELS, LEVEL_COLS + 1)),
                 np.zeros((1, SAMPLE_COLS)), np.zeros((1, TRAJ_COLS)), np.zeros((PEAK_RING, PEAK_COLS)),
                 np.zeros(N_FULL), np.zeros((FQ_LEVEL0 + MAX_LEVELS, FQ_COLS)))
    return inp, work, rec, Fits(np.zeros((N_SCRATCH, MAX_LEVELS)), np.zeros(N_DERIVED))


@kernel
def load_inputs(i, batch_in, inp):
    """Copy scene i's inputs (BatchInputs) into a worker's SceneInputs (MAX_LEVELS levels);
    returns the scene's (number of levels, chi)."""
    for j in range(N_FULL):
        inp.y0[j] = batch_in.Y0[i, j]
    for j in range(N_PARAMS):
        inp.p[j] = batch_in.P[i, j]
    for j in range(N_SETTINGS):
        inp.settings[j] = batch_in.S[i, j]
    for j in range(MAX_LEVELS):
        inp.level_e[j] = batch_in.LE[i, j]
        inp.levels[j] = batch_in.LV[i, j]
    return batch_in.NL[i], batch_in.CHI[i]


@kernel
def store_outputs(i, nl, rec, fits, batch_out):
    """Copy a worker's results for scene i (nl levels) into the batch's outputs (BatchOutputs)."""
    for j in range(N_ISTATS):
        batch_out.ISTATS[i, j] = rec.istats[j]
    for j in range(N_FSTATS):
        batch_out.FSTATS[i, j] = rec.fstats[j]
    for L in range(nl):
        for c in range(LEVEL_COLS):
            batch_out.LEV[i, L, c] = rec.levels[L, c]
    for j in range(N_FULL):
        batch_out.YEND[i, j] = rec.y_end[j]
    for j in range(N_DERIVED):
        batch_out.DER[i, j] = fits.derived[j]


@kernel
def solve_loaded(inp, nl, chi, work, rec, fits):
    """solve_scene on the first nl levels of a worker's loaded inputs."""
    solve_scene(SceneInputs(inp.y0, inp.p, inp.settings, inp.level_e[:nl], inp.levels[:nl]), chi, work, rec, fits)


@kernel(nogil=True)
def solve_index(i, batch_in, batch_out, buffers):
    """Scene i of the batch on one CPU worker's buffers (work_buffers()), from batch_in
    (BatchInputs) into batch_out (BatchOutputs); releases the GIL: threads run in parallel."""
    inp, work, rec, fits = buffers
    nl, chi = load_inputs(i, batch_in, inp)
    solve_loaded(inp, nl, chi, work, rec, fits)
    store_outputs(i, nl, rec, fits, batch_out)
    return rec.istats[I_OVERFLOW]
