"""The events' dispatch, GENERATED from event_rules.py: do not edit; edit its rows and functions and
rerun `python -m sweep.core.event_codegen`.

Each id calls the functions its row registers (event_rules.RULES); an id with none raises.
"""
from .event_ids import (
    EV_SIGN1, EV_SIGN2, EV_SIGN3, EV_UNSTICK1, EV_UNSTICK2, EV_UNSTICK3, EV_CONE, EV_SLIP_SLOW,
    EV_SLIP_STOP, EV_SLIP_FAST, EV_SLAVE, EV_CONTACT, EV_SIDE, EV_FACE, EV_SLAVE_LOST, EV_SPIN1,
    EV_SPIN2, EV_SPIN3, EV_LEVEL, EV_AGAINST1, EV_AGAINST2, EV_AGAINST3,
)
from .event_rules import (
    against_update, cone_update, cone_value, contact_update, contact_value, face_state_value,
    face_update, face_value, level_state_value, level_value, side_change, side_state_value,
    side_value, sign_state_value, sign_update, sign_value, slave_lost_update, slave_lost_value,
    slave_update, slave_value, slip_fast_update, slip_fast_value, slip_slow_update,
    slip_slow_value, slip_stop_update, slip_stop_value, spin_state_value, spin_update, spin_value,
    unstick_update, unstick_value, settle_event,
)
from .jit import kernel
from .model import moment_axes_rates


@kernel
def event_values(t, y, aux, sys, lev, g):
    """g[k] for every event function k (inf where not active); aux must belong to y, lev: the next
    level's energy (NaN: none)."""
    g[EV_SIGN1] = sign_value(0, t, y, aux, sys, lev)
    g[EV_SIGN2] = sign_value(1, t, y, aux, sys, lev)
    g[EV_SIGN3] = sign_value(2, t, y, aux, sys, lev)
    g[EV_UNSTICK1] = unstick_value(0, t, y, aux, sys, lev)
    g[EV_UNSTICK2] = unstick_value(1, t, y, aux, sys, lev)
    g[EV_UNSTICK3] = unstick_value(2, t, y, aux, sys, lev)
    g[EV_CONE] = cone_value(-1, t, y, aux, sys, lev)
    g[EV_SLIP_SLOW] = slip_slow_value(-1, t, y, aux, sys, lev)
    g[EV_SLIP_STOP] = slip_stop_value(-1, t, y, aux, sys, lev)
    g[EV_SLIP_FAST] = slip_fast_value(-1, t, y, aux, sys, lev)
    g[EV_SLAVE] = slave_value(-1, t, y, aux, sys, lev)
    g[EV_CONTACT] = contact_value(-1, t, y, aux, sys, lev)
    g[EV_SIDE] = side_value(-1, t, y, aux, sys, lev)
    g[EV_FACE] = face_value(-1, t, y, aux, sys, lev)
    g[EV_SLAVE_LOST] = slave_lost_value(-1, t, y, aux, sys, lev)
    g[EV_SPIN1] = spin_value(0, t, y, aux, sys, lev)
    g[EV_SPIN2] = spin_value(1, t, y, aux, sys, lev)
    g[EV_SPIN3] = spin_value(2, t, y, aux, sys, lev)
    g[EV_LEVEL] = level_value(-1, t, y, aux, sys, lev)


@kernel
def event_value(k, t, y, aux, sys, lev):
    """g_k of event function k (event_values's)."""
    if k == EV_SIGN1:
        return sign_value(0, t, y, aux, sys, lev)
    if k == EV_SIGN2:
        return sign_value(1, t, y, aux, sys, lev)
    if k == EV_SIGN3:
        return sign_value(2, t, y, aux, sys, lev)
    if k == EV_UNSTICK1:
        return unstick_value(0, t, y, aux, sys, lev)
    if k == EV_UNSTICK2:
        return unstick_value(1, t, y, aux, sys, lev)
    if k == EV_UNSTICK3:
        return unstick_value(2, t, y, aux, sys, lev)
    if k == EV_CONE:
        return cone_value(-1, t, y, aux, sys, lev)
    if k == EV_SLIP_SLOW:
        return slip_slow_value(-1, t, y, aux, sys, lev)
    if k == EV_SLIP_STOP:
        return slip_stop_value(-1, t, y, aux, sys, lev)
    if k == EV_SLIP_FAST:
        return slip_fast_value(-1, t, y, aux, sys, lev)
    if k == EV_SLAVE:
        return slave_value(-1, t, y, aux, sys, lev)
    if k == EV_CONTACT:
        return contact_value(-1, t, y, aux, sys, lev)
    if k == EV_SIDE:
        return side_value(-1, t, y, aux, sys, lev)
    if k == EV_FACE:
        return face_value(-1, t, y, aux, sys, lev)
    if k == EV_SLAVE_LOST:
        return slave_lost_value(-1, t, y, aux, sys, lev)
    if k == EV_SPIN1:
        return spin_value(0, t, y, aux, sys, lev)
    if k == EV_SPIN2:
        return spin_value(1, t, y, aux, sys, lev)
    if k == EV_SPIN3:
        return spin_value(2, t, y, aux, sys, lev)
    if k == EV_LEVEL:
        return level_value(-1, t, y, aux, sys, lev)
    raise ValueError("event_value: an id that is no event function")


@kernel
def state_event_value(k, t, y, sys, lev):
    """g_k of an event function of the state alone (E_FORCES 0), from the state y without the
    right-hand side; raises for any other id."""
    if k == EV_SIGN1:
        return sign_state_value(0, t, y, sys, lev)
    if k == EV_SIGN2:
        return sign_state_value(1, t, y, sys, lev)
    if k == EV_SIGN3:
        return sign_state_value(2, t, y, sys, lev)
    if k == EV_SIDE:
        return side_state_value(-1, t, y, sys, lev)
    if k == EV_FACE:
        return face_state_value(-1, t, y, sys, lev)
    if k == EV_SPIN1:
        return spin_state_value(0, t, y, sys, lev)
    if k == EV_SPIN2:
        return spin_state_value(1, t, y, sys, lev)
    if k == EV_SPIN3:
        return spin_state_value(2, t, y, sys, lev)
    if k == EV_LEVEL:
        return level_state_value(-1, t, y, sys, lev)
    raise ValueError("state_event_value: an event id with no value of the state alone")


@kernel
def apply_event(k, t, y, sys, fstats):
    """Discrete update at a located event k (state y at the event, changed in place): the event's own
    update, then, for a moment's or the slip's, what every update owes the state (settle_event,
    from omega.a_i before the update). Returns the outcome code that ends the scene, or -1 to
    continue; raises for an id with no update (the level's). The caller counts the roll<->slip
    transition (count_transition) and re-evaluates the right-hand side and the event functions."""
    g_before = moment_axes_rates(y)
    if k == EV_SIGN1:
        own, held = sign_update(0, t, y, sys)
        if held:
            g_before = moment_axes_rates(y)   # the stop holds the stuck components: they stay stuck
        return settle_event(t, y, sys, g_before, own)
    if k == EV_SIGN2:
        own, held = sign_update(1, t, y, sys)
        if held:
            g_before = moment_axes_rates(y)   # the stop holds the stuck components: they stay stuck
        return settle_event(t, y, sys, g_before, own)
    if k == EV_SIGN3:
        own, held = sign_update(2, t, y, sys)
        if held:
            g_before = moment_axes_rates(y)   # the stop holds the stuck components: they stay stuck
        return settle_event(t, y, sys, g_before, own)
    if k == EV_UNSTICK1:
        own, held = unstick_update(0, t, y, sys)
        if held:
            g_before = moment_axes_rates(y)   # the stop holds the stuck components: they stay stuck
        return settle_event(t, y, sys, g_before, own)
    if k == EV_UNSTICK2:
        own, held = unstick_update(1, t, y, sys)
        if held:
            g_before = moment_axes_rates(y)   # the stop holds the stuck components: they stay stuck
        return settle_event(t, y, sys, g_before, own)
    if k == EV_UNSTICK3:
        own, held = unstick_update(2, t, y, sys)
        if held:
            g_before = moment_axes_rates(y)   # the stop holds the stuck components: they stay stuck
        return settle_event(t, y, sys, g_before, own)
    if k == EV_CONE:
        code = cone_update(t, y, sys)
        if code >= 0:
            return code
        return settle_event(t, y, sys, g_before, -1)
    if k == EV_SLIP_SLOW:
        code = slip_slow_update(t, y, sys)
        if code >= 0:
            return code
        return settle_event(t, y, sys, g_before, -1)
    if k == EV_SLIP_STOP:
        code = slip_stop_update(t, y, sys)
        if code >= 0:
            return code
        return settle_event(t, y, sys, g_before, -1)
    if k == EV_SLIP_FAST:
        code = slip_fast_update(t, y, sys)
        if code >= 0:
            return code
        return settle_event(t, y, sys, g_before, -1)
    if k == EV_SLAVE:
        code = slave_update(t, y, sys)
        if code >= 0:
            return code
        return settle_event(t, y, sys, g_before, -1)
    if k == EV_CONTACT:
        return contact_update(t, y, sys, fstats)
    if k == EV_SIDE:
        return side_change(t, y, sys, fstats)
    if k == EV_FACE:
        return face_update(t, y, sys, fstats)
    if k == EV_SLAVE_LOST:
        code = slave_lost_update(t, y, sys)
        if code >= 0:
            return code
        return settle_event(t, y, sys, g_before, -1)
    if k == EV_SPIN1:
        own, held = spin_update(0, t, y, sys)
        if held:
            g_before = moment_axes_rates(y)   # the stop holds the stuck components: they stay stuck
        return settle_event(t, y, sys, g_before, own)
    if k == EV_SPIN2:
        own, held = spin_update(1, t, y, sys)
        if held:
            g_before = moment_axes_rates(y)   # the stop holds the stuck components: they stay stuck
        return settle_event(t, y, sys, g_before, own)
    if k == EV_SPIN3:
        own, held = spin_update(2, t, y, sys)
        if held:
            g_before = moment_axes_rates(y)   # the stop holds the stuck components: they stay stuck
        return settle_event(t, y, sys, g_before, own)
    if k == EV_AGAINST1:
        own, held = against_update(0, t, y, sys)
        if held:
            g_before = moment_axes_rates(y)   # the stop holds the stuck components: they stay stuck
        return settle_event(t, y, sys, g_before, own)
    if k == EV_AGAINST2:
        own, held = against_update(1, t, y, sys)
        if held:
            g_before = moment_axes_rates(y)   # the stop holds the stuck components: they stay stuck
        return settle_event(t, y, sys, g_before, own)
    if k == EV_AGAINST3:
        own, held = against_update(2, t, y, sys)
        if held:
            g_before = moment_axes_rates(y)   # the stop holds the stuck components: they stay stuck
        return settle_event(t, y, sys, g_before, own)
    raise ValueError("apply_event: an event id with no discrete update")
