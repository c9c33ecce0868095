"""The rules of the hybrid system's events, one place for each: every event's row of properties (the
columns of events.py), its event function g_k (value: from the right-hand side's aux at the state;
state_value: from the state alone, where the row does not read the forces) and its discrete update,
registered together (a Rule row of RULES). An event k has g_k > 0 before it; it happens where g_k first reaches 0.

The ids (event_ids.py) and the dispatch over them (event_dispatch.py: event_values, event_value,
state_event_value, apply_event) are GENERATED from RULES by event_codegen.py: `python -m
sweep.core.event_codegen` rewrites both, and tests/test_events.py checks that the checked-in files
are the generator's text. Adding an event is one Rule row here plus its value and update functions,
then that command. The generator refuses a table that a dispatch could not serve
(event_codegen.check_rules): an event function without a value, a row of the state alone without
its state value, an update missing or of a class with no update protocol; the generated dispatches
raise for an id outside the table.

The order of the rows is the order of the ids: the events of the dynamics first (scanned on every
step, in this order: the first of two at one time wins), then the levels' event (recorded, no
restart; event functions end there, N_EVENTS), then the ids that are updates only.

How an update is applied follows its class (E_CLASS, apply_event; event_codegen.PROTOCOLS):
  C_MOMENT        update(i, t, y, sys) -> (own, held): a moment component's update; then settle_event
  C_SLIP          update(t, y, sys) -> the outcome that ends the scene, or -1; then settle_event
  C_CONTACT_LOST, C_FACE, C_SIDE
                  update(t, y, sys, fstats) -> the outcome, or -1 (nothing settles after it)
  C_LEVEL         none: recorded by the level tracker
A value is value(i, t, y, aux, sys, lev) and a state value state_value(i, t, y, sys, lev): i is the
row's moment component (-1: none), lev the next level's energy (NaN: none); +inf where the event is
not active in the contact state sys.cs.
"""
from __future__ import annotations

import math
from collections import namedtuple

from .. import outcomes as oc
from .constants import AT_FLOOR, HANDOVER_ARMED, HANDOVER_OFF, ROLL, SLAVED, SLIDE, SLOW_OFF
from .contact_rhs import (FLOOR_EXIT, SLAVE_EXIT, SLAVE_FLOOR, eval_rhs, exit_speed, mode_energy, mode_energy_at,
                          slave_speed, slip_floor)
from .events import (C_CONTACT_LOST, C_FACE, C_LEVEL, C_MOMENT, C_SIDE, C_SLIP, D_NONE, D_RATES, D_SIDE, D_SIGN, D_SLIP,
                     R_NONE, R_SPIN, R_SURFACE)
from .impulse import project_velocity, stop_axis_rate
from .jit import kernel
from .layout import (CS_MODE, CS_SIDE, CS_SIG, CS_SLAVE_OFF, CS_STUCK, F_DIMPACT, F_TIMPACT, I_IMPACTS, I_STICK,
                     I_TRANS, W_AUXTMP, W_DYTMP, W_SCRATCH)
from .model import (P_K1, P_K2, P_K3, P_MUD, P_MUS, P_SLAVE, P_UTOL, P_WTOL, X_DCROSS, X_F1, X_F2, X_G1, X_LAG, X_NU,
                    X_PHI, X_SIG1, X_SLAVE_ERR, Y_ALPHA, Y_DK1, Y_DSLIDE, Y_U1, Y_U2, Y_W1, Y_W2, Y_W3,
                    moment_axes_rates)
from .moments import (consistent_signs, decision_rhs, needed_sigma, release_moved, settle_signs, spin_sticks,
                      stick_or_flip)
from .slip import cone_violated, set_slip, slow_slide, start_slip, try_slave

# Inclination (rad) at which the face is taken to touch the table: the disk lies flat. The far rim
# is then 1e-6 R above the table (38 nm for the paper's disk), below any real table's flatness. A disk
# that slaps down reaches it with a normal force ~1e5 m g (tests/test_stress.py 'tiny spin'); closer
# to flat the rigid single-contact model has no physical content left.
BETA_FACE = 1e-6
# Two rim-edge impacts closer than ZENO_DTAU (tau) end the scene as line contact.
ZENO_DTAU = 1e-6

# A row of the table: the event's name (its id is EV_<name>), the columns of events.py (E_CLASS ..
# E_HOLDS) and its functions (None where the row has none). RULES.append(Rule(...)) registers it; its
# id is its position.
Rule = namedtuple("Rule", "name cls forces dip restart component holds value state_value update",
                  defaults=(-1, 0, None, None, None))
RULES: list[Rule] = []


# === a moment component: omega.a_i crosses 0 against its moment's sign ===============================
@kernel
def sign_value(i, t, y, aux, sys, lev):
    """sigma_i omega.a_i of a free component (omega.a_i from the right-hand side: the same arithmetic
    as sign_state_value, without a sine)."""
    p, cs = sys.p, sys.cs
    k = (p[P_K1], p[P_K2], p[P_K3])
    if k[i] > 0.0 and cs[CS_STUCK + i] == 0.0:
        return cs[CS_SIG + i] * aux[X_G1 + i]
    return math.inf


@kernel
def sign_state_value(i, t, y, sys, lev):
    """sign_value from the state alone."""
    r1, r2, r3 = moment_axes_rates(y)
    return sys.cs[CS_SIG + i] * (r1 if i == 0 else (r2 if i == 1 else r3))


@kernel
def sign_update(i, t, y, sys):
    """At omega.a_i = 0: the component sticks or its sign flips (stick_or_flip)."""
    stick_or_flip(i, t, y, sys)
    return -1, False


RULES.append(Rule("SIGN1", C_MOMENT, 0, D_SIGN, R_SURFACE, 0, value=sign_value, state_value=sign_state_value, update=sign_update))
RULES.append(Rule("SIGN2", C_MOMENT, 0, D_SIGN, R_SURFACE, 1, value=sign_value, state_value=sign_state_value, update=sign_update))
RULES.append(Rule("SIGN3", C_MOMENT, 0, D_SIGN, R_SURFACE, 2, value=sign_value, state_value=sign_state_value, update=sign_update))


# === a stuck component needs more than k_i |N| ========================================================
@kernel
def unstick_value(i, t, y, aux, sys, lev):
    """1 - |sigma needed| of a stuck component."""
    p, cs = sys.p, sys.cs
    k = (p[P_K1], p[P_K2], p[P_K3])
    if k[i] > 0.0 and cs[CS_STUCK + i] == 1.0:
        return 1.0 - abs(aux[X_SIG1 + i])
    return math.inf


@kernel
def unstick_update(i, t, y, sys):
    """The release of a stuck component, in the direction of the needed moment; it is left on its
    surface (own)."""
    cs, wk = sys.cs, sys.wk
    eval_rhs(t, y, sys, wk[W_DYTMP], wk[W_AUXTMP])
    cs[CS_SIG + i] = 1.0 if wk[W_AUXTMP, X_SIG1 + i] > 0.0 else -1.0
    cs[CS_STUCK + i] = 0.0
    return i, False


RULES.append(Rule("UNSTICK1", C_MOMENT, 1, D_RATES, R_NONE, 0, value=unstick_value, update=unstick_update))
RULES.append(Rule("UNSTICK2", C_MOMENT, 1, D_RATES, R_NONE, 1, value=unstick_value, update=unstick_update))
RULES.append(Rule("UNSTICK3", C_MOMENT, 1, D_RATES, R_NONE, 2, value=unstick_value, update=unstick_update))


# === ROLL: the friction needed leaves the static cone, mu_s Phi - |F| = 0 ============================
@kernel
def cone_value(i, t, y, aux, sys, lev):
    """mu_s Phi - |F| of a rolling contact."""
    p = sys.p
    if sys.cs[CS_MODE] == ROLL:
        return p[P_MUS] * aux[X_PHI] - math.hypot(aux[X_F1], aux[X_F2])
    return math.inf


@kernel
def cone_update(t, y, sys):
    """ROLL -> SLAVED at the onset direction (start_slip), the hand-over armed."""
    start_slip(t, y, sys)
    sys.cs[CS_SLAVE_OFF] = HANDOVER_ARMED
    return -1


RULES.append(Rule("CONE", C_SLIP, 1, D_RATES, R_NONE, value=cone_value, update=cone_update))


# === SLIDE: |u| falls to slip_tol (contact_rhs.slip_floor) -> its fate (slip.slow_slide) ================
@kernel
def slip_slow_value(i, t, y, aux, sys, lev):
    """|u| less the slip's floor (slip_floor) of a slide, unless it spirals out (SLOW_OFF)."""
    p, cs = sys.p, sys.cs
    if cs[CS_MODE] == SLIDE and cs[CS_SLAVE_OFF] != SLOW_OFF:
        return math.hypot(y[Y_U1], y[Y_U2]) - slip_floor(t, aux, p, cs)
    return math.inf


@kernel
def slip_slow_update(t, y, sys):
    """The slide's fate (slow_slide)."""
    return slow_slide(t, y, sys)


RULES.append(Rule("SLIP_SLOW", C_SLIP, 1, D_SLIP, R_NONE, value=slip_slow_value, update=slip_slow_update))


# === SLAVED: u.s reaches 0 -> ROLL =====================================================================
@kernel
def slip_stop_value(i, t, y, aux, sys, lev):
    """The slip along the slaved direction at this state (the right-hand side's): reaches 0 where the
    slip ends."""
    if sys.cs[CS_MODE] == SLAVED:
        return y[Y_U1] * math.cos(aux[X_NU] + aux[X_LAG]) + y[Y_U2] * math.sin(aux[X_NU] + aux[X_LAG])
    return math.inf


@kernel
def slip_stop_update(t, y, sys):
    """The slip speed along the slaved direction is 0; what the integration left of the slip (its
    error) is removed by the plastic impulse, so the energy books stay exact."""
    p, cs, wk = sys.p, sys.cs, sys.wk
    side = int(cs[CS_SIDE])
    y[Y_DSLIDE] += project_velocity(y, p, (side, True), (side, False), wk[W_SCRATCH:W_SCRATCH + 7])
    cs[CS_MODE] = ROLL
    return -1


# (a slaved slip that leaves u = 0 starts on this surface, u.s = 0: it may rise and come back within
# its first step, which a scan of sign changes from g > 0 alone missed; the slip then ran on against s)
RULES.append(Rule("SLIP_STOP", C_SLIP, 1, D_RATES, R_SURFACE, value=slip_stop_value, update=slip_stop_update))


# === SLAVED: |u| grows to SLAVE_EXIT x the slaving speed -> SLIDE; a SLIDE whose hand-over is off ======
# === is fast again (the hand-over re-armed) ============================================================
@kernel
def slaved_margin(y, aux, p):
    """EV_SLIP_FAST of a slaved slip: > 0 while the slip is below its exit speed (exit_speed) and
    the slaved direction's error (aux[X_SLAVE_ERR]) below SLAVE_EXIT times slave_tol, or the slip
    below FLOOR_EXIT times the floor's speed SLAVE_FLOOR mu_d Phi; each as a fraction of its
    bound."""
    u = math.hypot(y[Y_U1], y[Y_U2])
    margin = 1.0 - u / exit_speed(y, aux, p)
    if p[P_SLAVE] > 0.0:
        # (within FLOOR_EXIT times the floor's speed the slip stays slaved whatever the error)
        floor = 1.0 - u / (FLOOR_EXIT * SLAVE_FLOOR * p[P_MUD] * max(aux[X_PHI], 0.0))
        margin = min(margin, max(floor, 1.0 - aux[X_SLAVE_ERR] / (SLAVE_EXIT * p[P_SLAVE])))
    return margin


@kernel
def slip_fast_value(i, t, y, aux, sys, lev):
    """A slaved slip's margin to its exit (slaved_margin); a slide whose hand-over is off or was
    refused (AT_FLOOR): its exit speed less |u|, where the hand-over re-arms."""
    p, cs = sys.p, sys.cs
    mode = cs[CS_MODE]
    if mode == SLAVED:
        return slaved_margin(y, aux, p)
    if mode == SLIDE and cs[CS_SLAVE_OFF] != HANDOVER_ARMED:
        # the hand-over is off (no quasi-static direction to settle on, or the slip passed it
        # by) until the slip is fast again: SLAVE_EXIT times the slaving speed, as a slaved
        # slip's exit; a slip that reverses and later decays is handed over then
        return exit_speed(y, aux, p) - math.hypot(y[Y_U1], y[Y_U2])
    return math.inf


@kernel
def slip_fast_update(t, y, sys):
    """The slip slides (SLIDE), the hand-over re-armed."""
    cs = sys.cs
    cs[CS_MODE] = SLIDE
    cs[CS_SLAVE_OFF] = HANDOVER_ARMED
    return -1


RULES.append(Rule("SLIP_FAST", C_SLIP, 1, D_RATES, R_NONE, value=slip_fast_value, update=slip_fast_update))


# === SLIDE: |u| falls to the slaving speed -> SLAVED if the direction has relaxed ======================
@kernel
def slave_value(i, t, y, aux, sys, lev):
    """|u| less the slaving speed of a slide whose hand-over is armed; one refused for its slaved
    direction's error (AT_FLOOR) is handed over at the floor's speed."""
    p, cs = sys.p, sys.cs
    if cs[CS_MODE] != SLIDE:
        return math.inf
    if cs[CS_SLAVE_OFF] == HANDOVER_ARMED:
        return math.hypot(y[Y_U1], y[Y_U2]) - slave_speed(y, aux, p)
    if cs[CS_SLAVE_OFF] == AT_FLOOR:
        return math.hypot(y[Y_U1], y[Y_U2]) - max(p[P_UTOL], SLAVE_FLOOR * p[P_MUD] * aux[X_PHI])
    return math.inf


@kernel
def slave_update(t, y, sys):
    """SLIDE -> SLAVED onto the attracting quasi-static direction (try_slave)."""
    return try_slave(t, y, sys)


RULES.append(Rule("SLAVE", C_SLIP, 1, D_SLIP, R_NONE, value=slave_value, update=slave_update))


# === Phi = 0: contact lost ===============================================================================
@kernel
def contact_value(i, t, y, aux, sys, lev):
    """The normal force Phi."""
    return aux[X_PHI]


@kernel
def contact_update(t, y, sys, fstats):
    """The scene ends: the disk leaves the table."""
    return oc.CONTACT_LOST


RULES.append(Rule("CONTACT", C_CONTACT_LOST, 1, D_RATES, R_NONE, value=contact_value, update=contact_update))


# === alpha = 0: the other rim edge takes the contact =====================================================
@kernel
def side_state_value(i, t, y, sys, lev):
    """side alpha."""
    return sys.cs[CS_SIDE] * y[Y_ALPHA]


@kernel
def side_value(i, t, y, aux, sys, lev):
    """side_state_value."""
    return side_state_value(i, t, y, sys, lev)


@kernel
def side_change(t, y, sys, fstats):
    """alpha = 0: plastic impact of the other rim edge, which releases every held moment component;
    after it each free sign is that of its omega.a_i, an exact 0 gets the stick test
    (consistent_signs), and a rolling contact outside the static cone starts to slip. Ends the scene
    (line contact) when no rotation towards the new side is left, or when two impacts come within
    ZENO_DTAU (the rocking between the edges has collapsed into a Zeno sequence of impacts)."""
    p, cs, wk, istats = sys.p, sys.cs, sys.wk, sys.istats
    mode = cs[CS_MODE]
    side = cs[CS_SIDE]
    loss = project_velocity(y, p, (int(side), mode != ROLL), (int(-side), mode != ROLL), wk[W_SCRATCH:W_SCRATCH + 7])
    fstats[F_DIMPACT] += loss
    cs[CS_SIDE] = -side
    istats[I_IMPACTS] += 1
    y[Y_ALPHA] = 0.0
    for i in range(3):
        cs[CS_STUCK + i] = 0.0
    zeno = t - fstats[F_TIMPACT] < ZENO_DTAU
    fstats[F_TIMPACT] = t
    if y[Y_W1] * cs[CS_SIDE] <= 0.0 or zeno:
        return oc.LINE_CONTACT   # the disk stands on its flat edge
    if mode != ROLL:
        code = set_slip(t, y, sys)
        if code >= 0:
            return code
    consistent_signs(t, y, sys)
    if mode == ROLL and cone_violated(t, y, sys):
        start_slip(t, y, sys)
    return -1


RULES.append(Rule("SIDE", C_SIDE, 0, D_SIDE, R_SURFACE, value=side_value, state_value=side_state_value, update=side_change))


# === pi/2 - |alpha| = BETA_FACE: the face reaches the table ==============================================
@kernel
def face_state_value(i, t, y, sys, lev):
    """pi/2 - |alpha| less BETA_FACE."""
    return (0.5 * math.pi - abs(y[Y_ALPHA])) - BETA_FACE


@kernel
def face_value(i, t, y, aux, sys, lev):
    """face_state_value."""
    return face_state_value(i, t, y, sys, lev)


@kernel
def face_update(t, y, sys, fstats):
    """The scene ends: the disk lies flat (the caller records it as a halt)."""
    return oc.FACE_CONTACT


RULES.append(Rule("FACE", C_FACE, 0, D_RATES, R_NONE, value=face_value, state_value=face_state_value, update=face_update))


# === SLAVED: the slaved direction stops attracting (d cross/d nu -> 0, a fold) -> SLIDE ================
@kernel
def slave_lost_value(i, t, y, aux, sys, lev):
    """-d cross/d nu at the slaved direction (< 0: attracting)."""
    if sys.cs[CS_MODE] == SLAVED:
        return -aux[X_DCROSS]
    return math.inf


@kernel
def slave_lost_update(t, y, sys):
    """The quasi-static direction folds away: the slip direction follows its own dynamics."""
    cs = sys.cs
    cs[CS_MODE] = SLIDE
    cs[CS_SLAVE_OFF] = HANDOVER_OFF
    return -1


RULES.append(Rule("SLAVE_LOST", C_SLIP, 1, D_RATES, R_NONE, value=slave_lost_value, update=slave_lost_update))


# === a free component slows to spin_tol: sticks if it goes to rest and can be held (the event ==========
# === stands only where it would stick: E_HOLDS) =========================================================
@kernel
def spin_value(i, t, y, aux, sys, lev):
    """sigma_i omega.a_i less spin_tol of a free component (where spin_tol > 0)."""
    p, cs = sys.p, sys.cs
    k = (p[P_K1], p[P_K2], p[P_K3])
    if k[i] > 0.0 and cs[CS_STUCK + i] == 0.0 and p[P_WTOL] > 0.0:
        return cs[CS_SIG + i] * aux[X_G1 + i] - p[P_WTOL]
    return math.inf


@kernel
def spin_state_value(i, t, y, sys, lev):
    """spin_value from the state alone."""
    return sign_state_value(i, t, y, sys, lev) - sys.p[P_WTOL]


@kernel
def slip_fast_reached(t, y, sys):
    """Is the slip at or past EV_SLIP_FAST's surface (a slaved slip at SLAVE_EXIT times the slaving
    speed; a slide whose hand-over is off, fast again)? Its event function at the state, with the
    forces that the decisions read (decision_rhs). An impulse of a discrete update (the stop at
    spin_tol moves the slip by O(spin_tol)) can carry the slip there, where the event, g going
    from > 0 to <= 0, can no longer happen (docs/model.md, 'Restarts on a surface')."""
    cs, wk = sys.cs, sys.wk
    if cs[CS_MODE] == ROLL:
        return False
    decision_rhs(-1, t, y, sys, wk[W_DYTMP], wk[W_AUXTMP])
    return slip_fast_value(-1, t, y, wk[W_AUXTMP], sys, math.nan) <= 0.0


@kernel
def holding_sigma(i, t, y, sys, dy, aux):
    """needed_sigma of component i at y in the mode the slip has there after the update: a slaved
    slip at or past its exit (slip_fast_reached) slides (settle_event hands it over), and the
    friction along its own direction, not the quasi-static one, is what the moment must hold
    against. The right-hand side goes to dy, aux; cs is left as it was."""
    cs = sys.cs
    mode = cs[CS_MODE]
    if mode == SLAVED and slip_fast_reached(t, y, sys):
        cs[CS_MODE] = SLIDE
    need = needed_sigma(i, t, y, sys, dy, aux)
    cs[CS_MODE] = mode
    return need


@kernel
def stick_at_spin_tol(i, t, y, sys):
    """A free component has slowed to |omega.a_i| = spin_tol: if it goes on to rest and the moment
    can hold it there (spin_sticks), it sticks, and the rate left is stopped by an impulsive contact
    moment (impulse.stop_axis_rate, its energy booked to k_i), where the moment must hold it as well.
    Else it stays free with its sign (it will cross 0, where the Filippov rule decides, or speed up
    again). Returns whether it stuck."""
    p, cs, wk, istats = sys.p, sys.cs, sys.wk, sys.istats
    if not spin_sticks(i, t, y, sys):
        return False
    w1, w2, w3, u1, u2 = y[Y_W1], y[Y_W2], y[Y_W3], y[Y_U1], y[Y_U2]
    cs[CS_STUCK + i] = 1.0
    loss = stop_axis_rate(y, p, cs, i, wk[W_SCRATCH:W_SCRATCH + 7])
    # the stop changes the velocity (and, sliding, the slip): the moment must hold the component at
    # the state it leaves too, where every later decision (settle_signs) reads it, in the mode it
    # reads it in (a slaved slip that the stop carries past its exit slides); else no stick
    if abs(holding_sigma(i, t, y, sys, wk[W_DYTMP], wk[W_AUXTMP])) < 1.0:
        y[Y_DK1 + i] += loss
        istats[I_STICK] += 1
        return True
    y[Y_W1], y[Y_W2], y[Y_W3], y[Y_U1], y[Y_U2] = w1, w2, w3, u1, u2
    cs[CS_STUCK + i] = 0.0
    return False


@kernel
def spin_update(i, t, y, sys):
    """The stop at spin_tol (stick_at_spin_tol); held: it holds the stuck components."""
    return -1, stick_at_spin_tol(i, t, y, sys)


RULES.append(Rule("SPIN1", C_MOMENT, 0, D_SIGN, R_SPIN, 0, holds=1, value=spin_value, state_value=spin_state_value, update=spin_update))
RULES.append(Rule("SPIN2", C_MOMENT, 0, D_SIGN, R_SPIN, 1, holds=1, value=spin_value, state_value=spin_state_value, update=spin_update))
RULES.append(Rule("SPIN3", C_MOMENT, 0, D_SIGN, R_SPIN, 2, holds=1, value=spin_value, state_value=spin_state_value, update=spin_update))


# === the energy reaches the next halt level (recorded by the level tracker, no restart) ================
@kernel
def level_value(i, t, y, aux, sys, lev):
    """E - the next level's energy (level_state_value's, from aux)."""
    if not math.isnan(lev):
        return mode_energy_at(y, aux, sys.p, sys.cs) - lev
    return math.inf


@kernel
def level_state_value(i, t, y, sys, lev):
    """E - the next level's energy."""
    return mode_energy(y, sys.p, sys.cs) - lev


RULES.append(Rule("LEVEL", C_LEVEL, 0, D_NONE, R_NONE, value=level_value, state_value=level_state_value))


# === not event functions: the sign event of component i found at the restart itself (omega.a_i ==========
# === moves against its new moment sign at once: the un-stick only grazed |sigma| = 1) ====================
@kernel
def against_update(i, t, y, sys):
    """Neither sign holds (the one just set fails at once, the other opposes the motion): the
    Filippov solution stays on omega.a_i = 0."""
    cs, istats = sys.cs, sys.istats
    sig_failed = cs[CS_SIG + i]
    stick_or_flip(i, t, y, sys)
    if cs[CS_STUCK + i] == 0.0 and cs[CS_SIG + i] == sig_failed:
        cs[CS_STUCK + i] = 1.0
        istats[I_STICK] += 1
        return i, False
    return -1, False


RULES.append(Rule("AGAINST1", C_MOMENT, 0, D_NONE, R_NONE, 0, update=against_update))
RULES.append(Rule("AGAINST2", C_MOMENT, 0, D_NONE, R_NONE, 1, update=against_update))
RULES.append(Rule("AGAINST3", C_MOMENT, 0, D_NONE, R_NONE, 2, update=against_update))


# === what every update owes the state =====================================================================
@kernel
def settle_event(t, y, sys, g_before, own):
    """What every discrete update owes the state: a slip that it left at or past EV_SLIP_FAST's
    surface (a slaved slip at SLAVE_EXIT times the slaving speed, or its direction's error measure
    at SLAVE_EXIT times slave_tol: slaved_margin) is fast (slip_fast_update: SLIDE, the hand-over
    re-armed); a slide at or below slip_tol meets its fate (slow_slide); the moment
    components that the update moved are released (release_moved: g_before, omega.a_i before it)
    and every sign made consistent (settle_signs, leaving component own); a rolling state left
    outside the static cone starts to slip. Returns the outcome that ends the scene, else -1."""
    p, cs, wk = sys.p, sys.cs, sys.wk
    if slip_fast_reached(t, y, sys):
        slip_fast_update(t, y, sys)
    if cs[CS_MODE] == SLIDE and cs[CS_SLAVE_OFF] != SLOW_OFF:
        eval_rhs(t, y, sys, wk[W_DYTMP], wk[W_AUXTMP])
        if math.hypot(y[Y_U1], y[Y_U2]) <= slip_floor(t, wk[W_AUXTMP], p, cs):
            # the slip reached its floor within the located event's bracket (a stiff slip decays
            # by orders of magnitude in 1e-11 tau): its own event can no longer happen
            code = slow_slide(t, y, sys)
            if code >= 0:
                return code
    release_moved(y, p, cs, g_before)
    settle_signs(t, y, sys, own)
    # a rolling state must be admissible after every discrete update: a moment sign that flips or
    # sticks changes the friction that rolling needs, and it may jump outside the static cone
    if cs[CS_MODE] == ROLL and cone_violated(t, y, sys):
        start_slip(t, y, sys)
        # the slip changes the moments the stuck components need
        # (a component the Filippov rule held is tested again: the slip changed its dynamics)
        settle_signs(t, y, sys, own if own >= 0 and cs[CS_STUCK + own] == 0.0 else -1)
    return -1


@kernel
def count_transition(rolling, cs, istats):
    """A roll<->slip transition where the contact rolled before a discrete update (rolling) and
    slips after it (cs), or the reverse. A slide that ends and, its cone violated, slips again at
    once within one update never rolled: it has passed through u = 0, and counts as the passage it
    is, whether its fate was read as an end or as a passage (docs/model.md, 'Where a slip ends')."""
    if rolling != (cs[CS_MODE] == ROLL):
        istats[I_TRANS] += 1
