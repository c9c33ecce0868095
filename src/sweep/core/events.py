"""The hybrid system's events, as data: their ids, and one table of per-event properties that the
event scan (integrate.first_event: how a crossing inside a step is bracketed, which events may
start on their surface), the evaluation on a dense output (roots.event_value_at: whether it needs
the right-hand side) and the discrete update (contact.apply_event: which update runs) read.

An event k has a function g_k(state) > 0 before it; it happens where g_k first reaches 0
(contact.event_values computes every active g_k). An event's id is the position of its row in the
table (`_event` appends it), so the ids follow from the order of the rows below: the events of the
dynamics first (0 .. N_DYN_EVENTS - 1, scanned on every step, in this order), then the levels' event
(recorded, no restart; event functions end at N_EVENTS), then the ids that are updates only. Adding
an event is one row here, its value in contact.event_values (and in contact.state_event_value where
it does not read the forces) and its update in the function its class names; an id that a dispatch
does not know raises (tests/test_kernels.py enumerates every id against both).
"""
from __future__ import annotations

import numpy as np

# --- the classes of update (column E_CLASS): what contact.apply_event does --------------------------
C_MOMENT = 0      # a dry-friction moment component flips, sticks or is released (contact.moment_event)
C_SLIP = 1        # the contact's slip starts, ends or changes mode (contact.slip_event)
C_CONTACT_LOST = 2  # the scene ends: contact lost
C_FACE = 3        # the scene ends: the disk lies flat (a halt)
C_SIDE = 4        # the other rim edge's impact (contact.side_change)
C_LEVEL = 5       # recorded by the level tracker, no discrete update

# --- how a dip inside a step is bracketed (column E_DIP) --------------------------------------------
D_RATES = 0       # cubic Hermite from difference-quotient end slopes (roots.event_rates)
D_SIGN = 1        # cubic Hermite from the exact slopes of sigma_i omega.a_i (roots.sign_slopes)
D_SIDE = 2        # cubic Hermite from the exact slope of side alpha, side omega_1
D_SLIP = 3        # the slip's own closest approach to u = 0 (roots.slip_closest_approach)
D_NONE = 4        # not searched inside a step (the level: the energy is monotone)

# --- how a step that starts on the event's surface is searched (column E_RESTART) --------------------
R_NONE = 0        # an event that starts at or below 0 cannot fire in this step
R_SURFACE = 1     # it may leave its surface and come back within the step (integrate.surface_bracket)
R_SPIN = 2        # below spin_tol at both ends: it may rise past it and slow to it again (integrate.spin_bracket)

# --- columns ---------------------------------------------------------------------------------------
E_CLASS = 0       # C_*
E_FORCES = 1      # 1: g_k reads the right-hand side's aux (the contact forces, the slaved direction, Phi)
E_DIP = 2         # D_*
E_RESTART = 3     # R_*
E_COMPONENT = 4   # the moment component i (0, 1, 2) of a sign, un-stick, spin or against event, else -1
E_HOLDS = 5       # 1: the event stands only where its update would stick the component (a spin event:
                  # integrate.spin_holds), else the step goes on through it
N_EVENT_COLS = 6

_ROWS = []


def _event(cls, forces, dip, restart, component=-1, holds=0):
    """Append an event's row to the table (columns E_*); returns its id, the row's position."""
    _ROWS.append((cls, forces, dip, restart, component, holds))
    return len(_ROWS) - 1


# --- the table: one row per id, in the order of the ids --------------------------------------------
# the events of the dynamics (scanned on every step, in this order: the first of two at one time wins)
EV_SIGN1 = _event(C_MOMENT, 0, D_SIGN, R_SURFACE, 0)   # omega.a_i crosses 0 against its moment's sign
EV_SIGN2 = _event(C_MOMENT, 0, D_SIGN, R_SURFACE, 1)
EV_SIGN3 = _event(C_MOMENT, 0, D_SIGN, R_SURFACE, 2)
EV_UNSTICK1 = _event(C_MOMENT, 1, D_RATES, R_NONE, 0)  # a stuck component needs more than k_i |N|
EV_UNSTICK2 = _event(C_MOMENT, 1, D_RATES, R_NONE, 1)
EV_UNSTICK3 = _event(C_MOMENT, 1, D_RATES, R_NONE, 2)
EV_CONE = _event(C_SLIP, 1, D_RATES, R_NONE)       # ROLL: the friction needed leaves the static cone, mu_s Phi - |F| = 0
EV_SLIP_SLOW = _event(C_SLIP, 1, D_SLIP, R_NONE)   # SLIDE: |u| falls to slip_tol (contact.slip_floor) -> its fate (contact.slow_slide)
EV_SLIP_STOP = _event(C_SLIP, 1, D_RATES, R_NONE)  # SLAVED: u.s reaches 0 -> ROLL
EV_SLIP_FAST = _event(C_SLIP, 1, D_RATES, R_NONE)  # SLAVED: |u| grows to SLAVE_EXIT x the slaving speed -> SLIDE (and SLIDE re-arms the hand-over)
EV_SLAVE = _event(C_SLIP, 1, D_SLIP, R_NONE)       # SLIDE: |u| falls to the slaving speed -> SLAVED if the direction has relaxed
EV_CONTACT = _event(C_CONTACT_LOST, 1, D_RATES, R_NONE)  # Phi = 0: contact lost
EV_SIDE = _event(C_SIDE, 0, D_SIDE, R_SURFACE)     # alpha = 0: the other rim edge takes the contact
EV_FACE = _event(C_FACE, 0, D_RATES, R_NONE)       # pi/2 - |alpha| = BETA_FACE: the face reaches the table
EV_SLAVE_LOST = _event(C_SLIP, 1, D_RATES, R_NONE)  # SLAVED: the slaved direction stops attracting (d cross/d nu -> 0, a fold) -> SLIDE
# a free component slows to spin_tol: sticks if it goes to rest and can be held (the event stands
# only where it would stick: E_HOLDS)
EV_SPIN1 = _event(C_MOMENT, 0, D_SIGN, R_SPIN, 0, holds=1)
EV_SPIN2 = _event(C_MOMENT, 0, D_SIGN, R_SPIN, 1, holds=1)
EV_SPIN3 = _event(C_MOMENT, 0, D_SIGN, R_SPIN, 2, holds=1)
N_DYN_EVENTS = len(_ROWS)
# the energy reaches the next halt level (recorded by the level tracker, no restart)
EV_LEVEL = _event(C_LEVEL, 0, D_NONE, R_NONE)
N_EVENTS = len(_ROWS)      # the event functions g_k: columns of the work buffer's W_G* rows
# not event functions: EV_AGAINST1 + i is the sign event of component i found at the restart itself
# (omega.a_i moves against its new moment sign at once: the un-stick only grazed |sigma| = 1)
EV_AGAINST1 = _event(C_MOMENT, 0, D_NONE, R_NONE, 0)
EV_AGAINST2 = _event(C_MOMENT, 0, D_NONE, R_NONE, 1)
EV_AGAINST3 = _event(C_MOMENT, 0, D_NONE, R_NONE, 2)
N_EVENT_IDS = len(_ROWS)

EVENTS = np.array(_ROWS, dtype=np.int64)
EVENTS.setflags(write=False)
