"""The batch path: one scene per worker on fixed-size per-worker buffers.

`solve_scene` integrates one scene with `integrate.run`, the same kernel `sweep.simulate` calls,
and computes the summary's fitted numbers (halt time and its error, approach and ramp exponents)
with `fits.summary_fits`, which `sweep.simulate` calls too. Every buffer has a size fixed by layout.py
and MAX_LEVELS / PEAK_RING: `solve_index` runs on the buffers each of sweep.ensemble's threads
allocates once (`work_buffers`).

The arrays travel in named groups (namedtuples of arrays, which numba passes as their arrays): the
batch's BatchInputs and BatchOutputs, a worker's SceneInputs and Fits, and the run's layout.System,
layout.Work and layout.Record.

The only difference to `sweep.simulate` is the peak buffer: a ring of the last PEAK_RING normal-
force maxima (layout.TF_RING) instead of every maximum, since the summary needs only the last
few. A scene whose look-back outgrows the ring (never seen) flags I_OVERFLOW, and the caller reruns
it with `sweep.simulate`.
"""
from __future__ import annotations

import math
from collections import namedtuple

import numpy as np

from .fits import N_DERIVED, summary_fits
from .frequency import FQ_LEVEL0
from .integrate import clear_tracking, record_arrays, run, state_size, system_arrays, work_arrays
from .jit import kernel
from .layout import (I_FLAT, I_OVERFLOW, LEVEL_COLS, L_PENDING, L_PRECESSION, L_TAU, N_CS, N_FSTATS, N_ISTATS,
                     N_SETTINGS, Record, System, TF_RING)
from .model import N_FULL, N_PARAMS

# rows of the per-scene scratch: level times (s), precession frequencies (Hz)
R_LEVEL_T, R_PREC_HZ = 0, 1
N_SCRATCH = 2
TWO_PI = 2.0 * math.pi
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

# --- one scene on fixed buffers -----------------------------------------------------------------
@kernel
def zero_rows(a, rows):
    """a[:rows, :] = 0 (a loop over the rows of a worker's buffer)."""
    for r in range(rows):
        for c in range(a.shape[1]):
            a[r, c] = 0.0


# solve_scene and solve_loaded are inlined into solve_index, their one caller: numba links a
# separate kernel's callees (integrate.run and all below it) into its own library and optimises the
# whole again, so each layer between solve_index and run cost ~3 s of LLVM time at the first
# simulate_batch (10 s with them separate, 4 s inlined; benchmarks/compile_time.py).
@kernel(inline="always")
def solve_scene(inp, chi, sys, work, rec, fits):
    """Integrate one scene on a worker's buffers, as integrate.integrate does without samples or
    trajectory, then its fits. inp (SceneInputs, nl = inp.level_e.shape[0] levels), chi (s); sys,
    work and rec (layout.System: its arrays, the state size set here from the settings; layout.Work,
    layout.Record) have a worker's sizes: rec.levels MAX_LEVELS rows, of
    which the first nl receive the levels (layout.LEVEL_COLS, then pending), rec.fq the frequency
    windows (core.frequency); fits.derived the D_* numbers. Every buffer is reset here."""
    nl = inp.level_e.shape[0]
    for i in range(N_FULL):
        work.y[i] = inp.y0[i]
        rec.y_end[i] = 0.0
    for i in range(N_PARAMS):
        sys.p[i] = inp.p[i]
    for i in range(N_CS):
        sys.cs[i] = 0.0
    zero_rows(sys.wk, sys.wk.shape[0])
    zero_rows(work.K, work.K.shape[0])
    zero_rows(work.F, work.F.shape[0])
    zero_rows(rec.peaks, rec.peaks.shape[0])
    zero_rows(rec.fq, FQ_LEVEL0 + nl)
    clear_tracking(work.trk)
    work.trk.track.flags[TF_RING] = True
    for i in range(N_ISTATS):
        sys.istats[i] = 0
    for i in range(N_FSTATS):
        rec.fstats[i] = 0.0
    lev = rec.levels
    for L in range(nl):
        for c in range(LEVEL_COLS):
            lev[L, c] = math.nan
        lev[L, L_PENDING] = 0.0
    # the scene's own sizes: nl levels, no samples, no trajectory
    run(inp.settings, inp.level_e, fits.scratch[0, :0],
        System(sys.p, sys.cs, state_size(inp.settings), sys.wk, sys.istats), work,
        Record(rec.fstats, lev[:nl], rec.samples[:0], rec.traj[:0], rec.peaks, rec.y_end, rec.fq[:FQ_LEVEL0 + nl]))
    # the fits on the level times (s) and precession frequencies (Hz), as sweep.simulate forms them
    scratch = fits.scratch
    for L in range(nl):
        scratch[R_LEVEL_T, L] = lev[L, L_TAU] * chi
        scratch[R_PREC_HZ, L] = abs(lev[L, L_PRECESSION]) / chi / TWO_PI
    summary_fits(scratch[R_LEVEL_T], scratch[R_PREC_HZ], inp.levels, nl, sys.istats[I_FLAT] != 0,
                 rec.fstats, chi, fits.derived)


# --- a worker over the batch ---------------------------------------------------------------------
def work_buffers():
    """One worker's buffers, (SceneInputs, System, Work, Record, Fits), allocated once per thread (the
    System's arrays; each scene's run gets its own state size)."""
    inp = SceneInputs(np.zeros(N_FULL), np.zeros(N_PARAMS), np.zeros(N_SETTINGS), np.zeros(MAX_LEVELS),
                      np.zeros(MAX_LEVELS))
    # no samples, no trajectory: solve_scene runs on none of their rows
    return (inp, system_arrays(N_FULL), work_arrays(), record_arrays(MAX_LEVELS, 0, 0, PEAK_RING),
            Fits(np.zeros((N_SCRATCH, MAX_LEVELS)), np.zeros(N_DERIVED)))


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
def store_outputs(i, nl, istats, rec, fits, batch_out):
    """Copy a worker's results for scene i (nl levels) into the batch's outputs (BatchOutputs)."""
    for j in range(N_ISTATS):
        batch_out.ISTATS[i, j] = istats[j]
    for j in range(N_FSTATS):
        batch_out.FSTATS[i, j] = rec.fstats[j]
    for L in range(nl):
        for c in range(LEVEL_COLS):
            batch_out.LEV[i, L, c] = rec.levels[L, c]
    for j in range(N_FULL):
        batch_out.YEND[i, j] = rec.y_end[j]
    for j in range(N_DERIVED):
        batch_out.DER[i, j] = fits.derived[j]


@kernel(inline="always")
def solve_loaded(nl, chi, buffers):
    """solve_scene on the first nl levels of a worker's loaded inputs (buffers: work_buffers())."""
    inp, sys, work, rec, fits = buffers
    solve_scene(SceneInputs(inp.y0, inp.p, inp.settings, inp.level_e[:nl], inp.levels[:nl]), chi, sys, work, rec, fits)


@kernel(nogil=True)
def solve_index(i, batch_in, batch_out, buffers):
    """Scene i of the batch on one CPU worker's buffers (work_buffers()), from batch_in
    (BatchInputs) into batch_out (BatchOutputs); releases the GIL: threads run in parallel."""
    inp, sys, work, rec, fits = buffers
    nl, chi = load_inputs(i, batch_in, inp)
    solve_loaded(nl, chi, buffers)
    store_outputs(i, nl, sys.istats, rec, fits, batch_out)
    return sys.istats[I_OVERFLOW]
