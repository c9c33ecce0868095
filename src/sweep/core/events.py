"""The hybrid system's events, as data: their ids, and one table of per-event properties that the
event scan (integrate.first_event: how a crossing inside a step is bracketed, which events may
start on their surface), the evaluation on a dense output (roots.event_value_at: whether it needs
the right-hand side) and the discrete update (contact.apply_event: which update runs) read.

An event k has a function g_k(state) > 0 before it; it happens where g_k first reaches 0
(contact.event_values computes every active g_k). Adding an event is one id, one row of EVENTS,
its value in contact.event_values and its update in the function its class names.
"""
from __future__ import annotations

import numpy as np

# --- ids ------------------------------------------------------------------------------------------
EV_SIGN1, EV_SIGN2, EV_SIGN3 = 0, 1, 2          # omega.a_i crosses 0 against its moment's sign
EV_UNSTICK1, EV_UNSTICK2, EV_UNSTICK3 = 3, 4, 5  # a stuck component needs more than k_i |N|
EV_CONE = 6        # ROLL: the friction needed leaves the static cone, mu_s Phi - |F| = 0
EV_SLIP_SLOW = 7   # SLIDE: |u| falls to slip_tol (contact.slip_floor) -> its fate (contact.slow_slide)
EV_SLIP_STOP = 8   # SLAVED: u.s reaches 0 -> ROLL
EV_SLIP_FAST = 9   # SLAVED: |u| grows to SLAVE_EXIT x the slaving speed -> SLIDE (and SLIDE re-arms the hand-over)
EV_SLAVE = 10      # SLIDE: |u| falls to the slaving speed -> SLAVED if the direction has relaxed
EV_CONTACT = 11    # Phi = 0: contact lost
EV_SIDE = 12       # alpha = 0: the other rim edge takes the contact
EV_FACE = 13       # pi/2 - |alpha| = BETA_FACE: the face reaches the table
EV_SLAVE_LOST = 14  # SLAVED: the slaved direction stops attracting (d cross/d nu -> 0, a fold) -> SLIDE
EV_SPIN1, EV_SPIN2, EV_SPIN3 = 15, 16, 17  # a free component slows to spin_tol: sticks if it goes to rest and can be held
N_DYN_EVENTS = 18
EV_LEVEL = 18      # energy reaches the next halt level (recorded, no restart)
N_EVENTS = 19
# not event functions: EV_AGAINST1 + i is the sign event of component i found at the restart itself
# (omega.a_i moves against its new moment sign at once: the un-stick only grazed |sigma| = 1)
EV_AGAINST1, EV_AGAINST2, EV_AGAINST3 = 19, 20, 21
N_EVENT_IDS = 22

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

EVENTS = np.zeros((N_EVENT_IDS, N_EVENT_COLS), dtype=np.int64)


def _row(k, cls, forces, dip, restart, component=-1, holds=0):
    EVENTS[k] = (cls, forces, dip, restart, component, holds)


for _i in range(3):
    _row(EV_SIGN1 + _i, C_MOMENT, 0, D_SIGN, R_SURFACE, _i)
    _row(EV_UNSTICK1 + _i, C_MOMENT, 1, D_RATES, R_NONE, _i)
    _row(EV_SPIN1 + _i, C_MOMENT, 0, D_SIGN, R_SPIN, _i, holds=1)
    _row(EV_AGAINST1 + _i, C_MOMENT, 0, D_NONE, R_NONE, _i)
_row(EV_CONE, C_SLIP, 1, D_RATES, R_NONE)
_row(EV_SLIP_SLOW, C_SLIP, 1, D_SLIP, R_NONE)
_row(EV_SLIP_STOP, C_SLIP, 1, D_RATES, R_NONE)
_row(EV_SLIP_FAST, C_SLIP, 1, D_RATES, R_NONE)
_row(EV_SLAVE, C_SLIP, 1, D_SLIP, R_NONE)
_row(EV_CONTACT, C_CONTACT_LOST, 1, D_RATES, R_NONE)
_row(EV_SIDE, C_SIDE, 0, D_SIDE, R_SURFACE)
_row(EV_FACE, C_FACE, 0, D_RATES, R_NONE)
_row(EV_SLAVE_LOST, C_SLIP, 1, D_RATES, R_NONE)
_row(EV_LEVEL, C_LEVEL, 0, D_NONE, R_NONE)
EVENTS.setflags(write=False)
del _i
