"""Recorders that read an accepted step's dense output: halt levels, samples, Phi maxima, trajectory.

They never change the trajectory. Their state between steps is layout.TrackState (work.trk.track:
at, flags, phi, fit; written here only);
the rows they write have the columns layout.L_* (levels), SA_* (samples), TR_* (trajectory) and
PK_* (maxima of Phi). The step they read comes as a layout.Span (its dense output, from work.y, and
the system it ran in).
"""
from __future__ import annotations

import math

from .accept import LIE_COMPONENTS
from .contact_rhs import eval_rhs, mode_energy
from .dop853 import N_DENSE, dense_coeffs, dense_eval
from .event_ids import EV_LEVEL
from .extrapolation import lie_dense
from .fits import halt_from_three
from .frequency import (Q_CAND_PHI, Q_CAND_T, Q_CAND_TH, lattice_due, lattice_step, open_level, peak_candidate,
                        peak_confirmed)
from .jit import kernel
from .layout import (Bracket, CS_MODE, CS_STEPPER, STEP_LIE, FT_B, FT_DEEP_B, FT_DEEP_E, FT_T, F_APPROACH, F_NFMAX, F_TEND, F_THALT,
                     F_THALT_ERR, I_LEVELS, I_OVERFLOW, I_PEAKS, I_TRAJ, K_PREV, L_ALPHA, L_FHAT, L_PENDING, L_TAU,
                     N_CS, PH_A, PH_B, PH_HPREV, PH_TA, PH_TB, PH_TPREV, PK_PHI, PK_TAU, PK_THETA, Peak, SA_ENERGY,
                     SA_MODE, SA_PHI, SA_Y, Span, System, TF_PREV_DENSE, TF_PREV_OK, TF_RING, TK_FHAT_PENDING, TK_LEVEL,
                     TK_NPK, TK_SAMPLE, TR_MODE, TR_PHI, TR_TAU, TR_Y, W_AUXBUF, W_CSPREV, W_DYBUF, W_YBUF, W_YPREV)
from .model import X_PHI, Y_ALPHA, Y_THETA, steady_rolling_energy
from .roots import brent_max_phi, locate, phi_on_dense
from .tableau import N_STAGES

# Minimum prominence of a located maximum of Phi over its bracket ends, relative to Phi.
PEAK_PROMINENCE = 1e-6
# Phi is read this fraction of the shorter bracketing segment either side of their common end to
# tell which segment holds the maximum (peak_sides); a rise or fall counts only beyond
# PEAK_SIDE_TOL x Phi, far above the round-off of Phi on a dense output (~1e-14 Phi).
PEAK_SIDE_GAP = 1e-4
PEAK_SIDE_TOL = 1e-12


@kernel
def dense_wanted(seg, at_end, consts, trk, fq):
    """Whether a recorder reads the dense output of the kept part seg (layout.Segment) of a step (the
    tests they make): a level crossed (while running, or one the halt fit waits for after the halt),
    a sample due, a new point of the precession lattice, a bracketed Phi maximum. at_end = (e_seg,
    theta_seg, phi_c): the energy (mode_energy), theta and Phi at the segment end; consts:
    layout.RunConsts."""
    e_seg, theta_seg, phi_c = at_end
    level_e, sample_tau = consts.level_e, consts.sample_tau
    L = trk.at[TK_LEVEL]
    if seg.running and L < level_e.shape[0] and e_seg - level_e[L] <= 0.0:
        return True
    if not seg.running and deep_pending(trk) and e_seg - trk.fit[FT_DEEP_E] <= 0.0:
        return True
    j = trk.at[TK_SAMPLE]
    if j < sample_tau.shape[0] and sample_tau[j] <= seg.end:
        return True
    return consts.peaks_on and (lattice_due(theta_seg, fq) or peak_bracketed(phi_c, trk))


@kernel
def start_tracking(y, aux, sys, sample_tau, trk, samples):
    """What the recorders take at tau = 0 from the state y (aux: its right-hand side's): the samples
    due then (sample_tau, ascending), and Phi for the maxima (trk: layout.TrackState)."""
    ns = sample_tau.shape[0]
    while trk.at[TK_SAMPLE] < ns and sample_tau[trk.at[TK_SAMPLE]] <= 0.0:
        record_sample(y, aux, sys.p, sys.cs, sys.n, samples[trk.at[TK_SAMPLE]])
        trk.at[TK_SAMPLE] += 1
    trk.phi[PH_B] = aux[X_PHI]


@kernel
def pending(trk):
    """Do a level's frequencies still wait for the motion after it (trk: layout.Tracking): an f_hat
    for maxima, or a precession window for lattice points?"""
    return trk.track.at[TK_FHAT_PENDING] + trk.windows[0] > 0


@kernel
def peak_bracketed(phi_c, trk):
    """Phi at the last three segment ends a < b >= c: a maximum lies in the last two segments."""
    return trk.phi[PH_B] > trk.phi[PH_A] and trk.phi[PH_B] >= phi_c and trk.flags[TF_PREV_OK]


@kernel
def step_dense(span, y_new, K):
    """dop853.dense_coeffs for the contact right-hand side (contact_rhs.eval_rhs), or where the
    step was the extrapolation's (span.sys.cs[CS_STEPPER]) extrapolation.lie_dense: the dense output
    (rows row0..row0 + 6 of span.F) of the step span (layout.Span: from y0 at t0 over h, in its
    system) to y_new, from its stages K.
    A kernel of its own: the stepper's kernels are inlined into their callers, and this one
    compiled copy serves every step's dense output (scan.dense_built, previous_dense)."""
    if span.sys.cs[CS_STEPPER] == STEP_LIE:
        lie_dense(eval_rhs, span, y_new, K, LIE_COMPONENTS)
    else:
        dense_coeffs(eval_rhs, span, y_new, K)


@kernel
def previous_dense(sys, work):
    """The previous step's dense output into F[7:14], from its stages kept in K[K_PREV:] (a step
    without an event: it ended in work.y, the current step's start, with f = its last stage), in
    the contact state it ran in (wk[W_CSPREV]); sys: the current step's layout.System."""
    K, F, trk, wk = work.K, work.F, work.trk.track, sys.wk
    if not trk.flags[TF_PREV_DENSE]:
        before = System(sys.p, wk[W_CSPREV, :N_CS], sys.n, wk, sys.istats)
        span = Span(F, N_DENSE, wk[W_YPREV], trk.phi[PH_TPREV], trk.phi[PH_HPREV], before)
        step_dense(span, work.y, K[K_PREV:])
        trk.flags[TF_PREV_DENSE] = True


@kernel
def record_levels(span, seg_end, e_seg, consts, trk, rec):
    """Record the halt levels (consts.level_e: their energies) crossed on [t, seg_end] of the step span
    (layout.Span, from t = span.t0; energy is monotone: one root each); e_seg is the energy
    (mode_energy) at seg_end; with consts.peaks_on the levels' frequencies are tracked.

    Returns the tau of the last level if it was reached in this segment (the scene halts), else -1.
    """
    y, t, h, sys = span.y0, span.t0, span.h, span.sys
    level_e, level_out = consts.level_e, rec.levels
    nl = level_e.shape[0]
    while trk.track.at[TK_LEVEL] < nl:
        L = trk.track.at[TK_LEVEL]
        gl = e_seg - level_e[L]
        if not gl <= 0.0:
            return -1.0
        gl0 = mode_energy(y, sys.p, sys.cs) - level_e[L]
        if gl0 <= 0.0:
            ta = t
            tb = t
        else:
            ta, tb = locate(EV_LEVEL, Bracket(t, gl0, seg_end, gl), span, level_e[L])
        tl = 0.5 * (ta + tb)
        ybuf = sys.wk[W_YBUF]
        dense_eval(span, tl, sys.n, ybuf)
        level_out[L, L_TAU] = tl
        level_out[L, L_ALPHA] = ybuf[Y_ALPHA]
        if consts.peaks_on:
            level_out[L, L_PENDING] = 1.0
            trk.track.at[TK_FHAT_PENDING] += 1
            open_level(L, tl, rec.fq, trk.windows)
        trk.track.at[TK_LEVEL] = L + 1
        sys.istats[I_LEVELS] = L + 1
        if L + 1 == nl:
            return tl
    return -1.0


@kernel
def halt_flat(t, level_out, trk, level_e):
    """The disk lies flat at t: the levels not yet crossed are crossed now (the face impact
    dissipates what is left); levels recorded without frequencies."""
    nl = level_e.shape[0]
    for L in range(trk.at[TK_LEVEL], nl):
        level_out[L, L_TAU] = t
    trk.at[TK_LEVEL] = nl


@kernel
def record_sample(y, aux, p, cs, n, row):
    """One sample row (layout.SA_*): state, energy, Phi, mode."""
    for i in range(n):
        row[SA_Y + i] = y[i]
    row[SA_ENERGY] = mode_energy(y, p, cs)
    row[SA_PHI] = aux[X_PHI]
    row[SA_MODE] = cs[CS_MODE]


@kernel
def record_samples(span, seg_end, t_stop, sample_tau, trk, samples):
    """Samples with tau in (t, seg_end] (and <= t_stop) from the dense output of the step span
    (layout.Span, from t = span.t0)."""
    sys = span.sys
    p, cs, n, wk = sys.p, sys.cs, sys.n, sys.wk
    ns = sample_tau.shape[0]
    while trk.at[TK_SAMPLE] < ns:
        j = trk.at[TK_SAMPLE]
        ts = sample_tau[j]
        if ts > seg_end or ts > t_stop:
            return
        dense_eval(span, ts, n, wk[W_YBUF])
        eval_rhs(ts, wk[W_YBUF], sys, wk[W_DYBUF], wk[W_AUXBUF])
        record_sample(wk[W_YBUF], wk[W_AUXBUF], p, cs, n, samples[j])
        trk.at[TK_SAMPLE] = j + 1


@kernel
def record_traj(t, y, phi, sys, traj):
    """Append one trajectory row (layout.TR_*: y's sys.n components, the mode of sys.cs; counted in
    sys.istats, which flags an overflow instead of growing the buffer)."""
    cs, n, istats = sys.cs, sys.n, sys.istats
    i = istats[I_TRAJ]
    if i >= traj.shape[0]:
        istats[I_OVERFLOW] |= 1
        return
    traj[i, TR_TAU] = t
    for j in range(n):
        traj[i, TR_Y + j] = y[j]
    traj[i, TR_PHI] = phi
    traj[i, TR_MODE] = cs[CS_MODE]
    istats[I_TRAJ] = i + 1


@kernel
def track_frequency(span, seg, phi_c, have_dense, work, rec):
    """The frequency recorders on the kept part seg (layout.Segment: [t, seg.end]; seg.running: the
    scene has not ended) of the step span (layout.Span, from t = span.t0; its end state in
    wk[W_YSEG], Phi there phi_c; have_dense: its dense output is built): the precession lattice,
    the Phi maxima (the previous step's dense output where a maximum is bracketed), and the window
    of the last two segments kept for the next bracket."""
    seg_end = seg.end
    lattice_step(span, seg_end, work.trk.windows, rec)
    if peak_bracketed(phi_c, work.trk.track):
        previous_dense(span.sys, work)
    track_peaks(span, seg_end, phi_c, seg.running, work, rec)
    shift_peak_window(span, seg_end, phi_c, have_dense, work)


@kernel
def track_peaks(this, seg_end, phi_c, running, work, rec):
    """Phi at the last three segment ends a < b >= c brackets a maximum: locate it (Brent) on the
    two steps' dense outputs (this one's: the layout.Span this, from t = this.t0); if it stands out
    of its bracket it passes the hysteresis filter (frequency.peak_candidate); Phi at this segment
    end (phi_c) may confirm the candidate, which is then counted and resolves pending levels' f_hat."""
    sys, t = this.sys, this.t0
    wk, F, trk = sys.wk, work.F, work.trk.track
    peaks, istats, fq = rec.peaks, sys.istats, rec.fq
    npk = trk.at[TK_NPK]
    pa = trk.phi[PH_A]
    if peak_bracketed(phi_c, trk):
        before = Span(F, N_DENSE, wk[W_YPREV], trk.phi[PH_TPREV], trk.phi[PH_HPREV],
                      System(sys.p, wk[W_CSPREV, :N_CS], sys.n, wk, istats))
        left, right = peak_sides(seg_end, before, this, trk)
        tp1, pv1 = trk.phi[PH_TB], -math.inf
        tp2, pv2 = t, -math.inf
        if left:
            tp1, pv1 = brent_max_phi(trk.phi[PH_TA], trk.phi[PH_TB], before)
        if right:
            tp2, pv2 = brent_max_phi(t, seg_end, this)
        ybuf = wk[W_YBUF]
        if pv1 >= pv2:
            tpk, pvk = tp1, pv1
            dense_eval(before, tpk, sys.n, ybuf)
        else:
            tpk, pvk = tp2, pv2
            dense_eval(this, tpk, sys.n, ybuf)
        thk = ybuf[Y_THETA]
        # round-off wiggles (e.g. of a creeping slip) have no prominence; real nutation peaks rise
        # ~0.1 Phi above the bracket ends
        genuine = pvk - max(pa, phi_c) > PEAK_PROMINENCE * abs(pvk)
        if genuine:
            peak_candidate(tpk, pvk, thk, fq)
    if peak_confirmed(phi_c, fq):
        if npk >= peaks.shape[0] and not trk.flags[TF_RING]:
            istats[I_OVERFLOW] |= 2
        else:
            if _add_peak(Peak(fq[0, Q_CAND_T], fq[0, Q_CAND_PHI], fq[0, Q_CAND_TH]), npk, running, trk, rec):
                istats[I_OVERFLOW] |= 2   # a ring too short for a level's look-back (never on the CPU path)
            npk += 1
    trk.at[TK_NPK] = npk
    istats[I_PEAKS] = npk


@kernel
def peak_sides(seg_end, before, this, trk):
    """Which of the two segments bracketing a maximum of Phi (the previous one, [PH_TA, PH_TB], and
    [t, seg_end], with PH_TB = t = this.t0) to search: (left, right). Phi at PH_TB is known; read a
    gap past it on each side. Where it rises on one side and falls on the other, the maximum lies on
    the rising side (for a smooth Phi, one within half the gap of PH_TB falls on both sides), and a
    search of the falling side would only creep to PH_TB (Brent's golden steps, ~40 RHS calls) to
    lose the comparison. Otherwise, or where a difference is within PEAK_SIDE_TOL, both are searched.
    before, this: the two steps' dense outputs (layout.Span)."""
    t = this.t0
    gap = PEAK_SIDE_GAP * min(trk.phi[PH_TB] - trk.phi[PH_TA], seg_end - t)
    if not gap > 0.0:
        return True, True
    phi_b = trk.phi[PH_B]
    tol = PEAK_SIDE_TOL * abs(phi_b)
    d_left = phi_on_dense(trk.phi[PH_TB] - gap, before) - phi_b
    d_right = phi_on_dense(t + gap, this) - phi_b
    if d_left > tol and d_right < -tol:
        return True, False
    if d_right > tol and d_left < -tol:
        return False, True
    return True, True


@kernel
def _add_peak(peak, npk, running, trk, rec):
    """Count maximum npk of Phi (peak: layout.Peak, its tau, value and theta) into rec.peaks
    (layout.PK_*), the largest f_hat seen (rec.fstats[F_NFMAX]; running: the scene has not ended) and
    the f_hat of the levels waiting for it (rec.levels). Returns True where a level's look-back
    outgrows a ring buffer."""
    tpk, pvk, thk = peak
    level_out, peaks, fstats = rec.levels, rec.peaks, rec.fstats
    short = False
    cap = peaks.shape[0]   # row of peak j: j, or j % cap where the buffer is a ring (flags[TF_RING])
    peaks[npk % cap, PK_TAU] = tpk
    peaks[npk % cap, PK_PHI] = pvk
    peaks[npk % cap, PK_THETA] = thk
    if npk >= 2 and (running or tpk <= fstats[F_TEND]):
        fstats[F_NFMAX] = max(fstats[F_NFMAX], 2.0 / (tpk - peaks[(npk - 2) % cap, PK_TAU]))
    # resolve levels that now have a counted maximum after them: f_hat = 2 / (t_k - t_{k-2}) over
    # the last three counted maxima at or before the level
    for L in range(level_out.shape[0]):
        if level_out[L, L_PENDING] == 1.0 and tpk > level_out[L, L_TAU]:
            j = npk - 1
            while j >= 0 and j > npk - cap and peaks[j % cap, PK_TAU] > level_out[L, L_TAU]:
                j -= 1
            if j >= 2:
                if j - 2 <= npk - cap:
                    short = True
                else:
                    level_out[L, L_FHAT] = 2.0 / (peaks[j % cap, PK_TAU] - peaks[(j - 2) % cap, PK_TAU])
            level_out[L, L_PENDING] = 0.0
            trk.at[TK_FHAT_PENDING] -= 1
    return short


@kernel
def shift_peak_window(span, seg_end, phi_c, have_dense, work):
    """Keep this segment's Phi (phi_c at seg_end), contact state and dense output (or, where it was
    not built, the stages it is built from: previous_dense) of the step span (layout.Span, from
    work.y) for the next bracket."""
    y, cs, K, F, trk = work.y, span.sys.cs, work.K, work.F, work.trk.track
    n, wk = span.sys.n, span.sys.wk
    trk.phi[PH_A] = trk.phi[PH_B]
    trk.phi[PH_TA] = trk.phi[PH_TB]
    trk.phi[PH_B] = phi_c
    trk.phi[PH_TB] = seg_end
    if have_dense:
        for r in range(N_DENSE):
            for i in range(n):
                F[N_DENSE + r, i] = F[r, i]
        trk.flags[TF_PREV_DENSE] = True
    else:
        for r in range(N_STAGES + 1):
            for i in range(n):
                K[K_PREV + r, i] = K[r, i]
        trk.flags[TF_PREV_DENSE] = False
    for i in range(n):
        wk[W_YPREV, i] = y[i]
    for i in range(N_CS):
        wk[W_CSPREV, i] = cs[i]
    trk.phi[PH_TPREV] = span.t0
    trk.phi[PH_HPREV] = span.h
    trk.flags[TF_PREV_OK] = True


# Each level the halt fit waits for after the last one lies this factor below the one before (decades,
# as the default levels).
DEEP_FACTOR = 10.0


@kernel
def level_inclination(e, p):
    """The inclination beta (rad) of the steady rolling motion of energy e (E_ss^-1, model.
    steady_rolling_energy, which increases from 0 at beta = 0 up to the largest valid level),
    by bisection to round-off."""
    lo = 0.0
    hi = 1e-3
    while steady_rolling_energy(hi, p) < e and hi < 0.5 * math.pi:
        hi = min(2.0 * hi, 0.5 * math.pi)
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if mid <= lo or mid >= hi:
            break
        if steady_rolling_energy(mid, p) < e:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


@kernel
def push_fit_level(trk, tau, beta):
    """A level crossed at tau with inclination beta joins the last three (trk.fit[FT_T:], trk.fit[FT_B:])."""
    for j in range(2):
        trk.fit[FT_T + j] = trk.fit[FT_T + j + 1]
        trk.fit[FT_B + j] = trk.fit[FT_B + j + 1]
    trk.fit[FT_T + 2] = tau
    trk.fit[FT_B + 2] = beta


@kernel
def fit_last_three(trk):
    """(t_halt, p) of the halt fit (halt.halt_from_three) on the last three levels crossed, NaNs
    where there are fewer or the fit has no finite root."""
    if math.isnan(trk.fit[FT_T]):
        return math.nan, math.nan
    return halt_from_three(trk.fit[FT_T], trk.fit[FT_T + 1], trk.fit[FT_T + 2],
                           trk.fit[FT_B], trk.fit[FT_B + 1], trk.fit[FT_B + 2])


@kernel
def deep_pending(trk):
    """Is a level below the last one still awaited for the halt fit (its energy, > 0, in trk)?"""
    return trk.fit[FT_DEEP_E] > 0.0


@kernel
def end_deep_levels(trk):
    """The halt fit waits for no deeper level (the disk lies flat first: it halted there)."""
    trk.fit[FT_DEEP_E] = 0.0


@kernel
def next_deep_level(trk, p):
    """The halt fit waits for the level DEEP_FACTOR below the last one crossed."""
    trk.fit[FT_DEEP_B] = trk.fit[FT_B + 2] / DEEP_FACTOR
    trk.fit[FT_DEEP_E] = steady_rolling_energy(trk.fit[FT_DEEP_B], p)


@kernel
def start_deep_levels(level_e, levels, p, trk, fstats):
    """At the halt (the last configured level crossed, levels[:, L_TAU] their tau): the halt fit on the
    last three levels; where it has no finite root (the level times do not yet show the final
    approach, or there are fewer than three levels), the steps after the halt go on to the levels
    below, a decade each (deep_levels), until the fit on the last three has one or the disk lies
    flat (docs/model.md, 'Halt time')."""
    nl = level_e.shape[0]
    for j in range(3):
        trk.fit[FT_T + j] = math.nan
        trk.fit[FT_B + j] = math.nan
    for L in range(max(nl - 3, 0), nl):
        push_fit_level(trk, levels[L, L_TAU], level_inclination(level_e[L], p))
    th, _ = fit_last_three(trk)
    if math.isnan(th):
        next_deep_level(trk, p)


@kernel
def deep_levels(span, seg_end, e_seg, trk, fstats):
    """After the halt, the levels below the last one that the halt fit waits for, crossed on [t,
    seg_end] of the step span (layout.Span, from t = span.t0; dense output built; e_seg: the energy
    at seg_end), located as the configured levels are; where the fit on the last three has a finite
    root, the halt time, its error (the remainder t_halt - t_last) and the approach exponent go to
    fstats (F_THALT, F_THALT_ERR, F_APPROACH), and the search ends."""
    y, t, p, cs = span.y0, span.t0, span.sys.p, span.sys.cs
    while deep_pending(trk) and e_seg - trk.fit[FT_DEEP_E] <= 0.0:
        le = trk.fit[FT_DEEP_E]
        gl0 = mode_energy(y, p, cs) - le
        if gl0 <= 0.0:
            tl = t
        else:
            ta, tb = locate(EV_LEVEL, Bracket(t, gl0, seg_end, e_seg - le), span, le)
            tl = 0.5 * (ta + tb)
        push_fit_level(trk, tl, trk.fit[FT_DEEP_B])
        th, pw = fit_last_three(trk)
        if math.isnan(th):
            next_deep_level(trk, p)
        else:
            fstats[F_THALT] = th
            fstats[F_THALT_ERR] = th - tl
            fstats[F_APPROACH] = pw
            trk.fit[FT_DEEP_E] = 0.0
