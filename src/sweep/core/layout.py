"""Named slots of the plain arrays that the kernels pass around (no Python objects in a kernel).

Contact state `cs` (float64, N_CS): the discrete state of the hybrid system.
    CS_MODE    constants.ROLL, SLIDE (slip faster than slip_tol, friction along -u/|u|) or SLAVED (slip
               at most the slaving speed, its direction slaved to the quasi-static one; docs/model.md)
    CS_SIDE    +1/-1: which rim edge carries the contact (sign of alpha)
    CS_SIG     3 slots: sign of omega.a_i used in the moment M_f (eq. 3.3)
    CS_STUCK   3 slots: 1 where omega.a_i is held at 0 by the dry-friction moment (Filippov)
    CS_NU      slip direction angle on (a1, a2) (rad): the slaved friction direction
    CS_SLAVE_OFF  a slide's hand-over to SLAVED: constants.HANDOVER_ARMED, HANDOVER_OFF, SLOW_OFF,
                  BELOW or AT_FLOOR (constants.py says what each means)
    CS_FLOOR   the slip speed (u_hat) at which a slide followed BELOW meets its fate again
    CS_STEPPER the stepper of the contact state's current step (numerics, not physics: no event or
               rule reads it): STEP_DOP853 or STEP_LIE (accept.stepper_for; its dense output is
               that stepper's: tracking.step_dense)
Work buffer `wk` (float64, N_WORK x N_FULL): rows used as vectors; `K` (N_KROWS x N_FULL) holds the
RK stages of this step (rows 0..15) and of the previous step (rows K_PREV.., kept while its dense
output was not built), `F` (14 x N_FULL) the dense-output coefficients of this step (rows 0..6) and
of the previous step (rows 7..13, for Phi maxima that straddle a step end). A step builds its
dense output (3 more stages) only where something reads it: an event, a level, a sample, a point of
the precession lattice, a Phi maximum.
"""
from __future__ import annotations

from collections import namedtuple

from .event_ids import N_EVENTS
from .model import N_AUX, N_FULL
from .tableau import N_STAGES_EXTENDED

# --- contact state ----------------------------------------------------------------------------
CS_MODE = 0
CS_SIDE = 1
CS_SIG = 2       # 2, 3, 4
CS_STUCK = 5     # 5, 6, 7
CS_NU = 8
CS_SLAVE_OFF = 9  # 1 after a failed SLIDE -> SLAVED hand-over, until the slip is fast again
CS_FLOOR = 10
CS_STEPPER = 11
N_CS = 12
STEP_DOP853, STEP_LIE = 0.0, 1.0

# --- work-buffer rows ---------------------------------------------------------------------------
W_Y = 0          # state at the step start
W_F = 1          # its derivative
W_YNEW = 2       # state at the step end
W_FNEW = 3
W_YTMP = 4       # stage state / trial state
W_DYTMP = 5
W_YBUF = 6       # dense-output evaluations
W_DYBUF = 7
W_YSLIP = 8      # state with the slaved slip vector (SLAVED mode right-hand side)
W_AUX = 9        # aux of the step start
W_AUXNEW = 10
W_AUXTMP = 11
W_AUXBUF = 12
W_GOLD = 13      # event values at the step start
W_GNEW = 14      # at the step end
W_GBUF = 15      # at a dense-output point
W_YPREV = 16     # state at the previous step's start (its dense output is F[7:14])
W_CSPREV = 17    # contact state of the previous step
W_SCRATCH = 18   # 7 rows: the plastic impulse's normal equations (impulse.py)
W_YSEG = 25      # state at the end of the current segment (step end or event)
W_PFRICTION = 26  # SLAVED: the parameters with the friction direction held at the slaved one
W_DYSLOPE = 27    # SLAVED: right-hand side beside the slaved direction (d cross/d nu)
W_AUXSLOPE = 28
W_RATEOLD = 29    # d g_k/d tau at the step start (forward difference; roots.event_rates)
W_RATENEW = 30    # ... at the step end
W_DELTA = 31      # the step's (or kept segment's) increment y_new - y before rounding (energy balance)
W_YFLOW = 32      # SLAVED: the state a short way along the motion (the slip direction's lag)
W_DYFLOW = 33
W_AUXFLOW = 34
W_ESCALE = 35     # the error norm's per-component scales of this step (accept.error_scale)
W_YDRIFT = 36     # SLAVED: the state a short way along the slaved motion (the slow manifold's drift)
W_DYDRIFT = 37
W_AUXDRIFT = 38
W_JAC = 39       # 6 rows: the extrapolation's Jacobian columns (core.extrapolation; row c: d f/d y_c)
W_LU = 45        # 6 rows: its linear system I - h_j J, LU-factored (row r: the matrix's row r, its pivot after)
N_WORK = 51
N_WCOLS = max(N_FULL, N_AUX, N_EVENTS)   # columns of the work buffer: a state, an aux or every event's value

# --- settings vector: the run's inputs (float64; a scene's row of a batch), read once into RunConsts ---
# rtol, atol; h_max (tau; 0: no ceiling); t_max (tau); the step budget; 1.0: integrate the
# kinematics; 1.0: track the normal force's maxima and the levels' frequencies
S_RTOL, S_ATOL, S_HMAX, S_TMAX, S_MAXSTEPS, S_KIN, S_PEAKS = 0, 1, 2, 3, 4, 5, 6
N_SETTINGS = 7

# --- integer statistics -------------------------------------------------------------------------
I_OUTCOME, I_STEPS, I_REJECTED, I_RHS, I_EVENTS, I_TRANS, I_STICK, I_IMPACTS, I_LEVELS, I_TRAJ, I_PEAKS = range(11)
I_SLIDE_STEPS, I_SLIDE_REJECTED, I_OVERFLOW = 11, 12, 13   # steps while sliding; buffers too small
I_FLAT = 14      # 1: the scene halted by lying flat (face contact)
N_ISTATS = 15

# --- float statistics ---------------------------------------------------------------------------
F_TEND, F_SLIDETIME, F_DIMPACT, F_E0, F_EEND, F_HLAST, F_NFMAX, F_TIMPACT = range(8)
# the halt time (tau), its error and the approach exponent from the levels below the last one, where
# the configured levels give no finite halt (tracking.deep_levels); NaN where not needed or not found
F_THALT, F_THALT_ERR, F_APPROACH = 8, 9, 10
N_FSTATS = 11

# --- the state the loop, the scan and the recorders carry between steps: typed records, each written
# by one module (its owner; integrate.tracking_arrays allocates them zeroed, and clear_tracking
# zeroes them for a batch's next scene). Grouped in Tracking (below).
# ScanState (scan.py): rates (bool, N_SC) SC_RATES_OLD: wk[W_RATEOLD] holds the event rates at the
# current step start (the last step end's); SC_RATES_NEW: this step's scan computed wk[W_RATENEW] (the
# rates at its end); dip_end (float64, 1): the first event found by an interior dip of an event of the
# forces: the time of the dense output's minimum there, where an integrated step confirms it; -1 else.
SC_RATES_OLD, SC_RATES_NEW = 0, 1
N_SC = 2
# EndState (integrate.py): the scene's end (halt or t_max), after which the steps only complete the
# levels' frequency windows and the halt fit. counts (int64, N_EN): the event counts at the end
# (EN_TRANS, EN_STICK, EN_IMPACTS; -1 before it); cut (bool, 1): a numerical guard stopped the steps
# (step budget, step floor), running or after a halt: the windows still open then get no value;
# after (float64, N_EA): EA_DIMPACT the impact dissipation up to the end, EA_H_AFTER the last step
# size before the end (0 before it), EA_T_AFTER twice the end's tau (the steps after it stop there).
EN_TRANS, EN_STICK, EN_IMPACTS = 0, 1, 2
N_EN = 3
EA_DIMPACT, EA_H_AFTER, EA_T_AFTER = 0, 1, 2
N_EA = 3
# TrackState (tracking.py): at (int64, N_TK): TK_LEVEL the next level to cross, TK_SAMPLE the next
# sample, TK_FHAT_PENDING the crossed levels whose f_hat waits for maxima after them, TK_NPK the
# maxima counted; flags (bool, N_TF): TF_PREV_OK a previous segment exists, TF_PREV_DENSE F[7:14]
# holds the previous step's dense output (else K[K_PREV:] its stages), TF_RING the peak buffer is a
# ring of its last rows (set by the buffers' creator: the batch path keeps only the summary); phi
# (float64, N_PH): Phi at the last two segment ends (PH_A, PH_B) and their tau (PH_TA, PH_TB), the
# previous step's start and size (PH_TPREV, PH_HPREV); fit (float64, N_FT): the halt fit's next
# level below the last one (FT_DEEP_E its energy, > 0; 0: none; FT_DEEP_B its inclination, rad) and
# the last three levels crossed, oldest first (FT_T: 3 slots of tau, FT_B: 3 of inclination).
TK_LEVEL, TK_SAMPLE, TK_FHAT_PENDING, TK_NPK = 0, 1, 2, 3
N_TK = 4
TF_PREV_OK, TF_PREV_DENSE, TF_RING = 0, 1, 2
N_TF = 3
PH_A, PH_B, PH_TA, PH_TB, PH_TPREV, PH_HPREV = range(6)
N_PH = 6
FT_DEEP_E, FT_DEEP_B, FT_T, FT_B = 0, 1, 2, 5
N_FT = 8

# --- RK stage buffer ----------------------------------------------------------------------------
K_PREV = N_STAGES_EXTENDED      # first row of the previous step's stages
N_KROWS = 2 * N_STAGES_EXTENDED

# --- output buffers: their columns -------------------------------------------------------------
# a level's row: tau where it is crossed, alpha there, the mean dtheta/dtau over whole precession
# cycles centred on the level, f_hat (2/T over three counted Phi maxima), the ringing ratio (Phi's
# cycles per precession cycle), the whole cycles in the window, the mean dtheta/dtau over the whole
# cycle next to the level where only one side has whole cycles, the window error of the mean
# dtheta/dtau given, the window's side (0 centred, -1 before the level only, +1 after it only; NaN
# none) (core.frequency); in the kernel's buffer L_PENDING is 1 while the level's f_hat waits for a
# maximum
L_TAU, L_ALPHA, L_PRECESSION, L_FHAT, L_RINGING, L_CYCLES, L_PREC_SIDE, L_PREC_ERR, L_WINDOW = range(9)
LEVEL_COLS = 9
L_PENDING = LEVEL_COLS
# a sample's row: the state y[0:N_FULL], its energy, Phi, the mode (cs[CS_MODE])
SA_Y, SA_ENERGY, SA_PHI, SA_MODE = 0, N_FULL, N_FULL + 1, N_FULL + 2
SAMPLE_COLS = N_FULL + 3
# a trajectory row (one per accepted step): tau, the state y[0:N_FULL], Phi, the mode
TR_TAU, TR_Y, TR_PHI, TR_MODE = 0, 1, 1 + N_FULL, 2 + N_FULL
TRAJ_COLS = 3 + N_FULL
# a counted maximum of the normal force: tau, Phi, theta
PK_TAU, PK_PHI, PK_THETA = 0, 1, 2
PEAK_COLS = 3

# --- the buffers of one run, grouped ------------------------------------------------------------
# numba passes a namedtuple of arrays as its arrays (no copy, no cost); a kernel takes the group
# and unpacks what it uses.
# Work: what the integrator integrates in: the state y (N_FULL, in place: the initial state in, the
# last state out), the RK stages K (N_KROWS x N_FULL), the dense output F (14 x N_FULL) and the
# state carried between steps trk (Tracking). The parameters, contact state and work buffer are the
# System's (below): each array of a run is in exactly one of System, Work and Record.
Work = namedtuple("Work", "y K F trk")
# Tracking: the state carried between steps, one record per owner (see SC_*, EN_*, TK_* above): scan
# (ScanState, scan.py), ends (EndState, integrate.py), track (TrackState, tracking.py) and windows
# (int64, 1: the levels' precession windows still open, frequency.py).
Tracking = namedtuple("Tracking", "scan ends track windows")
ScanState = namedtuple("ScanState", "rates dip_end")
EndState = namedtuple("EndState", "counts cut after")
TrackState = namedtuple("TrackState", "at flags phi fit")
# Record: what a run writes besides its counts (System.istats): fstats (N_FSTATS), levels (n_levels x
# LEVEL_COLS + 1: the last column L_PENDING), samples (n_samples x SAMPLE_COLS), traj (cap x
# TRAJ_COLS), peaks (cap x PEAK_COLS), y_end (N_FULL) and the frequency windows fq
# (FQ_LEVEL0 + n_levels x FQ_COLS, core.frequency). A buffer of 0 rows switches its recorder off.
Record = namedtuple("Record", "fstats levels samples traj peaks y_end fq")
# RunConsts: the run's constants, read once from the settings (integrate.run): n the state size (the
# components integrated: model.N_CORE, N_THETA or N_FULL), rtol, atol, h_max (tau; inf: no
# ceiling), t_max (tau), max_steps (the step budget, accepted and rejected), peaks_on (the normal
# force's maxima and the levels' frequencies are tracked), e0 (the initial energy's magnitude, the
# scale of the step's energy checks), level_e (the levels' energies, decreasing) and sample_tau
# (the sample times, tau, ascending).
RunConsts = namedtuple("RunConsts", "n rtol atol h_max t_max max_steps peaks_on e0 level_e sample_tau")
# System: what the right-hand side of a contact state reads and where it counts: the parameters p
# (N_PARAMS), the contact state cs (N_CS), the state size n, the work buffer wk (its rows the
# evaluations use as scratch) and istats (N_ISTATS, int64: I_RHS, the steps' and events' counts, the
# outcome). The stepper (dop853) passes it through to the right-hand side it is given and reads only
# n and wk. integrate.system_arrays allocates it; a run's n is its settings' state_size.
System = namedtuple("System", "p cs n wk istats")
# Eval: one evaluation of a right-hand side: at tau t and the state y, in the system sys (System),
# into the rows dy (d y/d tau) and aux (N_AUX). The slaved slip's solvers (contact_rhs) take it as
# the state their trial slips (a direction nu, a speed u) are evaluated at and where they leave the
# last right-hand side.
Eval = namedtuple("Eval", "t y sys dy aux")
# Point: a state y, its derivative f and the right-hand side's aux there (N_AUX): a step's start
# and end (accept.try_step, dop853.rk_step).
Point = namedtuple("Point", "y f aux")
# Span: the dense output that a search on it reads (roots.py): rows row0..row0 + 6 of F (work.F;
# 0: this step's, N_DENSE: the previous step's) hold the coefficients of the step from the state
# y0 (N_FULL) at tau t0 over h, which ran in the system sys (System: its cs the step's contact state).
Span = namedtuple("Span", "F row0 y0 t0 h sys")
# Segment: the kept part of an accepted step, [t, end] of the step [t, t + h] (end < t + h where
# event k, >= 0, ends it; k = -1 where none does), whether the step's dense output is built
# (dense), whether the scene was running when the step began (running: not yet ended, else the
# step only completes frequency windows after a halt), and whether the step ends at t_max (at_tmax).
Segment = namedtuple("Segment", "t h end k dense running at_tmax")
# Bracket: event k's value ga > 0 at tau ta and gb <= 0 at tb > ta (roots.locate shrinks it).
Bracket = namedtuple("Bracket", "ta ga tb gb")
# Hermite: a function's values g0, g1 at the two ends of a step and its slopes d0, d1 there per unit
# of the step (the cubic Hermite interpolant's data: roots.hermite_peak, scan.lift_off).
Hermite = namedtuple("Hermite", "g0 d0 g1 d1")
# Peak: a maximum of the normal force: tau, Phi and theta there (tracking's counted maxima, PK_*).
Peak = namedtuple("Peak", "tau phi theta")
# Run: what a scene's step loop carries from step to step (integrate.run): its constants (RunConsts),
# the system (System) and the buffers it integrates in and writes (Work, Record).
Run = namedtuple("Run", "consts sys work rec")
