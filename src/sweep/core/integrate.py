"""The hybrid integrator: one scene, DOP853 steps of the current smooth mode, located events.

`run` (numba, no allocation) steps the current contact state (accept.try_step), scans the accepted step for events (scan.first_event),
locates the earliest on the dense output, restarts there with the new discrete state (keeping the
step size) and records what the scene asked for. Every discrete decision is taken in
event_dispatch.apply_event from the state at the located event; the step size, rtol and atol only decide
where the steps fall. `integrate` (Python) allocates the buffers and names the outputs.
"""
from __future__ import annotations

import math
from collections import namedtuple

import numpy as np

from .. import outcomes as oc
from .accept import norm_size, retract_step, segment_end, try_step
from .constants import EPS, ROLL, SLAVED
from .contact_rhs import eval_rhs, mode_energy, mode_energy_at
from .controller import accepted_step_factor, step_factor
from .dop853 import ERR_EXPONENT, N_DENSE, dense_eval, initial_step
from .event_dispatch import apply_event, event_values
from .event_ids import EV_LEVEL, N_DYN_EVENTS
from .event_rules import count_transition
from .frequency import FQ_COLS, FQ_LEVEL0, finish_levels, freq_start
from .jit import kernel
from .layout import (CS_MODE, CS_NU, CS_SIDE, CS_SIG, CS_STUCK, EA_DIMPACT, EA_H_AFTER, EA_T_AFTER, EN_IMPACTS,
                     EN_STICK, EN_TRANS, EndState, F_APPROACH, F_DIMPACT, F_E0, F_EEND, F_HLAST, F_SLIDETIME, F_TEND,
                     F_THALT, F_THALT_ERR, F_TIMPACT, I_EVENTS, I_FLAT, I_IMPACTS, I_OUTCOME, I_OVERFLOW, I_PEAKS,
                     I_REJECTED, I_STEPS, I_STICK, I_TRAJ, I_TRANS, LEVEL_COLS, L_PENDING, N_CS, N_EA, N_EN, N_FSTATS,
                     N_FT, N_ISTATS, N_KROWS, N_PH, N_SC, N_TF, N_TK, N_WCOLS, N_WORK, PEAK_COLS, Record, Run,
                     RunConsts, SAMPLE_COLS, S_ATOL, S_HMAX, S_KIN, S_MAXSTEPS, S_PEAKS, S_RTOL, S_TMAX, ScanState,
                     Segment, Span, System, TK_LEVEL, TRAJ_COLS, TrackState, Tracking, W_AUX, W_AUXBUF, W_AUXNEW,
                     W_DYBUF, W_F, W_FNEW, W_GNEW, W_GOLD, W_YBUF, W_YNEW, W_YSEG, Work)
from .model import N_AUX, N_CORE, N_FULL, N_PARAMS, N_THETA, X_NU, X_OK, X_PHI, Y_ALPHA, Y_THETA, Y_U1, Y_U2
from .moments import consistent_signs
from .roots import location_tol
from .scan import carry_rates, first_event, start_scan
from .slip import cone_violated, confirm_slaved, set_slip, start_slip
from .tracking import (deep_levels, deep_pending, dense_wanted, end_deep_levels, halt_flat, pending, record_levels,
                       record_samples, record_traj, start_deep_levels, start_tracking, step_dense, track_frequency)


KernelOutput = namedtuple("KernelOutput", "istats fstats levels samples trajectory peaks y_end")


@kernel
def failure_outcome(ok):
    """Outcome for a right-hand side that failed: the model's Painleve flag (-1) or a slaved
    direction that did not converge (0)."""
    return oc.PAINLEVE if ok < 0.0 else oc.NUMERICAL_ERROR


@kernel
def start(y, sys):
    """Initial discrete state of the system sys (layout.System) at y: moment signs, slip mode, and
    slip onset if rolling cannot hold. Returns the outcome that ends the scene at once (set_slip),
    else -1."""
    cs = sys.cs
    cs[CS_SIDE] = 1.0 if y[Y_ALPHA] > 0.0 else -1.0
    for i in range(3):
        cs[CS_SIG + i] = 1.0
        cs[CS_STUCK + i] = 0.0
    rolling = y[Y_U1] == 0.0 and y[Y_U2] == 0.0
    if not rolling:
        code = set_slip(0.0, y, sys)
        if code >= 0:
            return code
    else:
        cs[CS_MODE] = ROLL
    consistent_signs(0.0, y, sys)
    if cs[CS_MODE] == ROLL and cone_violated(0.0, y, sys):
        start_slip(0.0, y, sys)
    # a scene that starts rolling and slips at once has its transition
    count_transition(rolling, cs, sys.istats)
    return -1


@kernel
def mark_end(t_end, y_at_end, sys, ends, rec):
    """The scene ended (halted, or reached t_max) at t_end in state y_at_end (of the system sys,
    layout.System): its end state, energy, impact losses and event counts (ends: layout.EndState). The steps
    after a halt only complete the levels' frequency windows and change none of them."""
    istats, fstats, y_end = sys.istats, rec.fstats, rec.y_end
    fstats[F_TEND] = t_end
    for i in range(sys.n):
        y_end[i] = y_at_end[i]
    fstats[F_EEND] = mode_energy(y_end, sys.p, sys.cs)
    ends.after[EA_DIMPACT] = fstats[F_DIMPACT]
    ends.counts[EN_TRANS] = istats[I_TRANS]
    ends.counts[EN_STICK] = istats[I_STICK]
    ends.counts[EN_IMPACTS] = istats[I_IMPACTS]


@kernel
def state_size(settings):
    """Components integrated: the dynamics and the dissipation books (N_CORE), + theta for the
    frequency outputs (N_THETA), + the kinematics (N_FULL)."""
    if settings[S_KIN] > 0.0:
        return N_FULL
    return N_THETA if settings[S_PEAKS] > 0.0 else N_CORE


@kernel
def begin(lev, work, rec, sys):
    """The scene at tau = 0 in the system sys (layout.System): its contact state, f and aux
    (wk[W_F], wk[W_AUX]), E(0), the event values (wk[W_GOLD]; lev: the first level's energy), the
    end's markers. Returns the outcome that ends the scene at once, else -1."""
    y, p, cs, wk = work.y, sys.p, sys.cs, sys.wk
    ends, fstats = work.trk.ends, rec.fstats
    f = wk[W_F]
    aux = wk[W_AUX]
    fstats[F_TIMPACT] = -math.inf
    fstats[F_THALT] = math.nan
    fstats[F_THALT_ERR] = math.nan
    fstats[F_APPROACH] = math.nan
    for i in range(N_EN):
        ends.counts[i] = -1
    ends.after[EA_H_AFTER] = 0.0
    start_code = start(y, sys)
    eval_rhs(0.0, y, sys, f, aux)
    fstats[F_E0] = mode_energy(y, p, cs)
    event_values(0.0, y, aux, sys, lev, wk[W_GOLD])
    outcome = -1
    if aux[X_PHI] <= 0.0:
        outcome = oc.CONTACT_LOST
    if aux[X_OK] != 1.0:
        outcome = failure_outcome(aux[X_OK])
    if start_code >= 0:
        outcome = start_code
    return outcome


@kernel
def record_start(consts, work, rec, sys):
    """What the scene records at tau = 0 (the samples due, the trajectory's first row, Phi for the
    maxima, the precession lattice's origin) and its starting step size (before the ceiling h_max);
    consts: layout.RunConsts."""
    y, p, cs, n, wk = work.y, sys.p, sys.cs, sys.n, sys.wk
    aux = wk[W_AUX]
    start_tracking(y, aux, sys, consts.sample_tau, work.trk.track, rec.samples)
    if rec.traj.shape[0] > 0:
        record_traj(0.0, y, aux[X_PHI], sys, rec.traj)
    start_scan(work.trk.scan)
    if consts.peaks_on:
        freq_start(y[Y_THETA], aux[X_PHI], rec.fq)
    return initial_step(eval_rhs, 0.0, y, wk[W_F], sys, (consts.rtol, consts.atol, norm_size(n)))


@kernel
def step_after_end(t, h, t_max, trk):
    """The step size after a halt, where the steps only complete the levels' frequency windows
    (precession cycles and Phi maxima after the levels) or reach the levels the halt fit waits for:
    while only windows wait, not past the last step before the end nor past twice the end's tau (a
    steady motion, e.g. rolling at a tilt held by a stuck moment, has no maxima, and its steps would
    grow tenfold each until t overflowed); while the halt fit waits, as the step control has it (the
    motion speeds up towards the halt, and capped steps spent the step budget first); never past
    t_max. Returns -1 where they stop."""
    after, track = trk.ends.after, trk.track
    if after[EA_H_AFTER] == 0.0:
        after[EA_H_AFTER] = h
        after[EA_T_AFTER] = 2.0 * t
    if t_max - t <= 2.0 * EPS * max(abs(t), 1.0) or (t >= after[EA_T_AFTER] and not deep_pending(track)):
        return -1.0
    if deep_pending(track):
        return min(h, t_max - t)
    return min(h, after[EA_H_AFTER], t_max - t)


@kernel
def segment_phi(seg_end, event, sys):
    """Phi at the segment end (the step end's from its last stage; an event's from the dense state),
    in the system sys (layout.System)."""
    wk = sys.wk
    if event:
        eval_rhs(seg_end, wk[W_YSEG], sys, wk[W_DYBUF], wk[W_AUXBUF])
        return wk[W_AUXBUF, X_PHI]
    return wk[W_AUXNEW, X_PHI]


@kernel
def advance(seg, ended, sys, work, fstats):
    """Move the start to the end of the kept part seg (layout.Segment): its state (sys.n components),
    and where no event restarts there the step end's f, aux and event rates; the time spent sliding
    (to the scene's end: ended)."""
    y, cs, n, wk = work.y, sys.cs, sys.n, sys.wk
    event = seg.k >= 0
    if cs[CS_MODE] != ROLL and seg.running:
        fstats[F_SLIDETIME] += (seg.end if not ended else fstats[F_TEND]) - seg.t
    for i in range(n):
        y[i] = wk[W_YSEG, i]
    if not event:
        for i in range(n):
            wk[W_F, i] = wk[W_FNEW, i]
        for i in range(N_AUX):
            wk[W_AUX, i] = wk[W_AUXNEW, i]
    carry_rates(event, work.trk.scan, wk)


@kernel
def restart_after_event(k, t, y, lev, sys, fstats):
    """The discrete update of event k at t (event_dispatch.apply_event) of the system sys (layout.System);
    then the new contact state's slaved direction, right-hand side (wk[W_F], wk[W_AUX]) and event
    values (wk[W_GOLD]; lev: the next level's energy); the roll<->slip transition the update made is
    counted. Returns the outcome that ends the scene here (FACE_CONTACT: the disk lies flat), else -1."""
    p, cs, wk, istats = sys.p, sys.cs, sys.wk, sys.istats
    istats[I_EVENTS] += 1
    rolling = cs[CS_MODE] == ROLL
    code = apply_event(k, t, y, sys, fstats)
    count_transition(rolling, cs, istats)
    if code >= 0:
        return code
    if cs[CS_MODE] == SLAVED:
        # the slaved direction of the contact state the update left, continued across the event
        # (steps that end in events would otherwise leave it behind the moving root)
        code = confirm_slaved(t, y, sys)
        if code >= 0:
            return code
    aux = wk[W_AUX]
    eval_rhs(t, y, sys, wk[W_F], aux)
    if aux[X_OK] != 1.0:
        return failure_outcome(aux[X_OK])
    if aux[X_PHI] <= 0.0:
        # the update (an impact) leaves the disk with no compressive normal force: it leaves the
        # table here (its own event, Phi falling through 0, cannot happen)
        return oc.CONTACT_LOST
    event_values(t, y, aux, sys, lev, wk[W_GOLD])
    return -1


@kernel
def carry_step_end(lev, level_pending, y, sys):
    """A step that ended without an event (y now its end state, of the system sys): its end's event values start
    the next step (the level's from the energy, +inf once every level is crossed), and a slaved
    direction is continued to its end."""
    p, cs, wk = sys.p, sys.cs, sys.wk
    for k in range(N_DYN_EVENTS):
        wk[W_GOLD, k] = wk[W_GNEW, k]
    wk[W_GOLD, EV_LEVEL] = mode_energy_at(y, wk[W_AUX], p, cs) - lev if level_pending else math.inf
    if cs[CS_MODE] == SLAVED:
        # the step end's right-hand side continued it there (the root from cs[CS_NU] at y_new)
        cs[CS_NU] = wk[W_AUX, X_NU]


@kernel
def finish(outcome, t, consts, sys, work, rec):
    """The scene's outputs once the loop stops at t: outcome, the event counts, end state and energy at
    its end (kept by mark_end, else the last state), the levels' frequencies."""
    y, p, cs, ends = work.y, sys.p, sys.cs, work.trk.ends
    istats, fstats, y_end = sys.istats, rec.fstats, rec.y_end
    if outcome < 0:
        outcome = oc.STEP_LIMIT
    ended = ends.counts[EN_TRANS] >= 0
    if ended:
        istats[I_TRANS] = ends.counts[EN_TRANS]
        istats[I_STICK] = ends.counts[EN_STICK]
        istats[I_IMPACTS] = ends.counts[EN_IMPACTS]
    if consts.peaks_on:
        # a window cut by a numerical stop has no value; one cut by the motion's end has its largest
        # symmetric part
        cut = ends.cut[0] or outcome == oc.NUMERICAL_ERROR
        finish_levels(rec.fq, rec.levels, cut)
    if ended:
        fstats[F_DIMPACT] = ends.after[EA_DIMPACT]   # the end state and energy were taken at the end
    else:
        fstats[F_TEND] = t
        for i in range(consts.n):
            y_end[i] = y[i]
        fstats[F_EEND] = mode_energy(y_end, p, cs)
    istats[I_OUTCOME] = outcome


@kernel
def next_try(t, h, outcome, consts, work, istats):
    """The size of the next try from t (h: the step control's), or where the loop stops: after the
    scene's end the Phi maxima's steps (step_after_end), the step budget, t_max, the smallest step
    that still moves tau (consts: layout.RunConsts; istats: the step counts). Returns (h, outcome, whether the step ends at t_max,
    whether to stop)."""
    running = outcome < 0
    if not running:
        h = step_after_end(t, h, consts.t_max, work.trk)
        if h < 0.0:
            return h, outcome, False, True
    if istats[I_STEPS] + istats[I_REJECTED] >= consts.max_steps:
        work.trk.ends.cut[0] = True
        return h, oc.STEP_LIMIT if running else outcome, False, True
    at_tmax = running and t + h >= consts.t_max
    if at_tmax:
        h = consts.t_max - t
    # the model is autonomous (no stage reads tau), so a step only has to move tau: the floor is
    # 2 eps tau; 16 eps tau stopped a slip spiralling into slip_tol at tau ~ 5100, which needs
    # steps of ~1e-11 (tests/test_convergence.py)
    if h <= 2.0 * EPS * max(abs(t), 1.0):
        if running:
            outcome = oc.T_MAX if at_tmax else oc.STEP_SIZE_UNDERFLOW
        if outcome != oc.T_MAX:
            work.trk.ends.cut[0] = True
        return h, outcome, at_tmax, True
    return h, outcome, at_tmax, False


@kernel
def record_segment(seg, e_seg, outcome, lev, run):
    """What the kept part of the step (seg: layout.Segment; its end state wk[W_YSEG], energy
    e_seg) holds: the levels it crosses (HALTED at the last, with its end state), the samples, the
    Phi maxima (run: layout.Run, the run's constants, the step's system and the buffers). Returns
    (the outcome, the energy of the next level to cross)."""
    consts, sys, work, rec = run
    y, wk, trk = work.y, sys.wk, work.trk
    level_e = consts.level_e
    event = seg.k >= 0
    phi_c = segment_phi(seg.end, event, sys) if consts.peaks_on else 0.0
    span = Span(work.F, 0, y, seg.t, seg.h, sys)
    have_dense = seg.dense
    if not have_dense and dense_wanted(seg, (e_seg, wk[W_YSEG, Y_THETA], phi_c), consts, trk.track, rec.fq):
        step_dense(span, wk[W_YNEW], work.K)
        have_dense = True
    if seg.running:
        t_halt = record_levels(span, seg.end, e_seg, consts, trk, rec)
        if t_halt >= 0.0:
            outcome = oc.HALTED
            dense_eval(span, t_halt, consts.n, wk[W_YBUF])
            mark_end(t_halt, wk[W_YBUF], sys, trk.ends, rec)
            start_deep_levels(level_e, rec.levels, sys.p, trk.track, rec.fstats)
        elif trk.track.at[TK_LEVEL] < level_e.shape[0]:
            lev = level_e[trk.track.at[TK_LEVEL]]
    elif deep_pending(trk.track):
        deep_levels(span, seg.end, e_seg, trk.track, rec.fstats)
    record_samples(span, seg.end, rec.fstats[F_TEND] if outcome >= 0 else math.inf, consts.sample_tau, trk.track, rec.samples)
    # after the end, only while a level's frequencies wait for the motion (not for the whole deep
    # search of the halt fit: its Phi maxima are past the scene's end)
    if consts.peaks_on and (seg.running or pending(trk)):
        track_frequency(span, seg, phi_c, have_dense, work, rec)
    return outcome, lev


@kernel
def end_segment(seg, outcome, lev, run):
    """Restart at the end of the kept part (seg: layout.Segment): an event's discrete update
    (restart_after_event: an outcome there ends the scene; a disk lying flat has halted), or the
    step end's values carried on (at t_max the scene ends). run: layout.Run (the run's constants,
    the step's system, the buffers). Returns (the outcome, whether the loop stops)."""
    consts, sys, work, rec = run
    y, cs, wk, trk = work.y, sys.cs, sys.wk, work.trk
    istats, fstats = sys.istats, rec.fstats
    level_e = consts.level_e
    event = seg.k >= 0
    advance(seg, outcome >= 0, sys, work, fstats)
    t = seg.end
    if rec.traj.shape[0] > 0 and outcome < 0:
        record_traj(t, y, math.nan if event else wk[W_AUXNEW, X_PHI], sys, rec.traj)
    if not event:
        carry_step_end(lev, trk.track.at[TK_LEVEL] < level_e.shape[0], y, sys)
        if seg.at_tmax and outcome < 0:
            outcome = oc.T_MAX
            mark_end(t, y, sys, trk.ends, rec)
        return outcome, False
    code = restart_after_event(seg.k, t, y, lev, sys, fstats)
    if code < 0:
        return outcome, False
    if seg.running and code == oc.FACE_CONTACT:
        # the disk lies flat: it has halted (docs/model.md, 'Halt')
        halt_flat(t, rec.levels, trk.track, level_e)
        istats[I_FLAT] = 1
        outcome = oc.HALTED
        mark_end(t, y, sys, trk.ends, rec)
    elif seg.running:
        outcome = code
        fstats[F_TEND] = t
    elif code == oc.FACE_CONTACT and deep_pending(trk.track):
        # the halt fit waited for a deeper level, and the disk lies flat first: it halted here
        fstats[F_THALT] = t
        fstats[F_THALT_ERR] = location_tol(t)
        end_deep_levels(trk.track)
    return outcome, True


@kernel
def run(settings, level_e, sample_tau, sys, work, rec):
    """Integrate one scene (the initial state in work.y, its parameters in sys.p) into sys.istats
    and rec (layout.System, its n the settings' state_size; layout.Work, layout.Record: the
    buffers' shapes): step, scan the accepted step for the earliest event, record the kept part,
    restart at its end. settings (layout.S_*), level_e the levels' energies (dimensionless),
    sample_tau the sample times (tau), ascending: read once here into the run's constants
    (layout.RunConsts), with E(0) from begin."""
    if sys.n != state_size(settings):
        raise ValueError("run: the system's state size is not the settings' (state_size)")
    cs, wk, trk, istats = sys.cs, sys.wk, work.trk, sys.istats
    lev = level_e[0] if level_e.shape[0] > 0 else math.nan
    outcome = begin(lev, work, rec, sys)
    h_max = settings[S_HMAX] if settings[S_HMAX] > 0.0 else math.inf
    consts = RunConsts(sys.n, settings[S_RTOL], settings[S_ATOL], h_max, settings[S_TMAX], int(settings[S_MAXSTEPS]),
                       settings[S_PEAKS] > 0.0, max(abs(rec.fstats[F_E0]), 1e-300), level_e, sample_tau)
    run = Run(consts, sys, work, rec)
    h = min(record_start(consts, work, rec, sys), consts.h_max)
    t = 0.0
    after_reject = False
    # after a halt (the last level: the disk still moves) the steps go on while a level's frequencies
    # wait for the motion after it, or the halt fit for a deeper level: until they are complete, the
    # motion ends (an event's outcome, twice the end's tau), or a guard stops. Every other end (t_max, contact lost, ...) ends the
    # motion the scene simulates: nothing is integrated past it.
    while outcome < 0 or (outcome == oc.HALTED and (pending(trk) or deep_pending(trk.track))):
        running = outcome < 0
        h, outcome, at_tmax, stop = next_try(t, h, outcome, consts, work, istats)
        if stop:
            break
        err = try_step(t, h, consts, work, sys)
        if not err <= 1.0:
            h *= step_factor(err, ERR_EXPONENT)
            after_reject = True
            continue
        h_next = min(h * accepted_step_factor(err, ERR_EXPONENT, after_reject), consts.h_max)
        after_reject = False
        if wk[W_AUXNEW, X_OK] != 1.0 and running:
            outcome = failure_outcome(wk[W_AUXNEW, X_OK])
            break
        # the earliest event on the step: the kept part ends there
        event_values(t + h, wk[W_YNEW], wk[W_AUXNEW], sys, lev, wk[W_GNEW])
        span = Span(work.F, 0, work.y, t, h, sys)
        first_k, seg_end, have_dense = first_event(span, lev, work)
        event = first_k >= 0
        if event and running and t < trk.scan.dip_end[0] < t + h:
            # an event of the forces that only the dense output shows (both step ends on the safe
            # side): its value inside the step carries the interpolant's error, amplified where a
            # held moment's balance reads the slip direction; the dip stands only if the integrated
            # state at its minimum confirms it, so the step is retried to end there
            retract_step(cs, istats)
            h = trk.scan.dip_end[0] - t
            after_reject = True
            continue
        if not event:
            # a step cut to end at t_max ends there exactly: t + (t_max - t) can round 1 ulp short,
            # and a sample asked for at t_max would then be lost
            seg_end = consts.t_max if at_tmax else t + h
        e_seg, seg_err = segment_end(span, seg_end, event, running, consts)
        if seg_err > 1.0:
            retract_step(cs, istats)
            h *= step_factor(seg_err, ERR_EXPONENT)
            after_reject = True
            continue
        seg = Segment(t, h, seg_end, first_k, have_dense, running, at_tmax)
        outcome, lev = record_segment(seg, e_seg, outcome, lev, run)
        outcome, stop = end_segment(seg, outcome, lev, run)
        t = seg_end
        if stop:
            break
        h = h_next
    rec.fstats[F_HLAST] = h
    finish(outcome, t, consts, sys, work, rec)


def tracking_arrays():
    """The state carried between steps (layout.Tracking), zeroed: its records' one allocation."""
    return Tracking(ScanState(np.zeros(N_SC, np.bool_), np.zeros(1)),
                    EndState(np.zeros(N_EN, np.int64), np.zeros(1, np.bool_), np.zeros(N_EA)),
                    TrackState(np.zeros(N_TK, np.int64), np.zeros(N_TF, np.bool_), np.zeros(N_PH), np.zeros(N_FT)),
                    np.zeros(1, np.int64))


@kernel
def clear_tracking(trk):
    """Zero the state carried between steps (layout.Tracking) for a new scene on the same buffers."""
    for rec in (trk.scan.rates, trk.ends.cut, trk.track.flags):
        for i in range(rec.shape[0]):
            rec[i] = False
    for rec in (trk.scan.dip_end, trk.ends.after, trk.track.phi, trk.track.fit):
        for i in range(rec.shape[0]):
            rec[i] = 0.0
    for rec in (trk.ends.counts, trk.track.at, trk.windows):
        for i in range(rec.shape[0]):
            rec[i] = 0


def system_arrays(n):
    """The system a run evaluates (layout.System) for a state of n components (state_size), zeroed:
    the parameters, contact state, work buffer and counters; the one place their shapes are written."""
    return System(np.zeros(N_PARAMS), np.zeros(N_CS), n, np.zeros((N_WORK, N_WCOLS)), np.zeros(N_ISTATS, np.int64))


def work_arrays():
    """The buffers a run integrates in (layout.Work), zeroed: the one place their shapes are written."""
    return Work(np.zeros(N_FULL), np.zeros((N_KROWS, N_FULL)), np.zeros((2 * N_DENSE, N_FULL)), tracking_arrays())


def record_arrays(n_levels, n_samples, traj_rows, peak_rows):
    """The buffers a run writes (layout.Record) for n_levels levels and n_samples samples, with room
    for traj_rows trajectory rows and peak_rows maxima of Phi: the levels and samples NaN until
    written (a level's L_PENDING 0), the rest zeroed. The one place their shapes are written."""
    levels = np.full((n_levels, LEVEL_COLS + 1), np.nan)
    levels[:, L_PENDING] = 0.0
    return Record(np.zeros(N_FSTATS), levels, np.full((n_samples, SAMPLE_COLS), np.nan),
                  np.zeros((traj_rows, TRAJ_COLS)), np.zeros((peak_rows, PEAK_COLS)), np.zeros(N_FULL),
                  np.zeros((FQ_LEVEL0 + n_levels, FQ_COLS)))


def integrate(y0, p, settings, level_e, sample_tau, traj_cap=0, peak_cap=16384):
    """Run one scene (CPU). Allocates the buffers; if the trajectory or peak buffer overflowed, it
    grows it 4x and reruns (the run is deterministic). peak_cap covers ~1.6e4 nutation periods, far
    more than a scene to its halt has, so the rerun is for pathological scenes only. Returns a KernelOutput of arrays:
    istats, fstats (layout.I_*, F_*), levels (n_levels x layout.LEVEL_COLS: the columns layout.L_*),
    samples (layout.SA_*), trajectory (layout.TR_*), peaks (layout.PK_*: the counted maxima),
    y_end (N_FULL)."""
    while True:
        sys = system_arrays(state_size(settings))
        sys.p[:] = p
        work = work_arrays()
        work.y[:y0.shape[0]] = y0
        rec = record_arrays(level_e.shape[0], sample_tau.shape[0], traj_cap,
                            peak_cap if settings[S_PEAKS] > 0.0 else 0)
        run(settings, level_e, sample_tau, sys, work, rec)
        istats = sys.istats
        over = istats[I_OVERFLOW]
        if over == 0:
            break
        if over & 1:
            traj_cap = 4 * max(traj_cap, 256)
        if over & 2:
            peak_cap *= 4
    return KernelOutput(istats, rec.fstats, rec.levels[:, :LEVEL_COLS], rec.samples, rec.traj[:istats[I_TRAJ]],
                        rec.peaks[:istats[I_PEAKS]], rec.y_end)
