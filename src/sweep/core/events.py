"""The vocabulary of the hybrid system's events: the columns of their table and the values of each
column. The table itself, one row per event with its functions, is event_rules.RULES; its ids and
rows (event_ids.EVENTS) and the dispatch over them are generated from it (event_rules.py says how).

The columns say how the event scan (scan.first_event: how a crossing inside a step is bracketed,
which events may start on their surface), the evaluation on a dense output (roots.event_value_at:
whether it needs the right-hand side) and the discrete update (event_dispatch.apply_event: which
protocol runs) treat an event.
"""
from __future__ import annotations

# --- the classes of update (column E_CLASS): how apply_event applies it (event_rules.PROTOCOLS) ----
C_MOMENT = 0      # a dry-friction moment component flips, sticks or is released (event_rules: sign_update ..)
C_SLIP = 1        # the contact's slip starts, ends or changes mode (event_rules: cone_update ..)
C_CONTACT_LOST = 2  # the scene ends: contact lost
C_FACE = 3        # the scene ends: the disk lies flat (a halt)
C_SIDE = 4        # the other rim edge's impact (event_rules.side_change)
C_LEVEL = 5       # recorded by the level tracker, no discrete update

# --- how a dip inside a step is bracketed (column E_DIP) --------------------------------------------
D_RATES = 0       # cubic Hermite from difference-quotient end slopes (roots.event_rates)
D_SIGN = 1        # cubic Hermite from the exact slopes of sigma_i omega.a_i (roots.sign_slopes)
D_SIDE = 2        # cubic Hermite from the exact slope of side alpha, side omega_1
D_SLIP = 3        # the slip's own closest approach to u = 0 (roots.slip_closest_approach)
D_NONE = 4        # not searched inside a step (the level: the energy is monotone)

# --- how a step that starts on the event's surface is searched (column E_RESTART) --------------------
R_NONE = 0        # an event that starts at or below 0 cannot fire in this step
R_SURFACE = 1     # it may leave its surface and come back within the step (scan.surface_bracket)
R_SPIN = 2        # below spin_tol at both ends: it may rise past it and slow to it again (scan.spin_bracket)

# --- columns ---------------------------------------------------------------------------------------
E_CLASS = 0       # C_*
E_FORCES = 1      # 1: g_k reads the right-hand side's aux (the contact forces, the slaved direction, Phi)
E_DIP = 2         # D_*
E_RESTART = 3     # R_*
E_COMPONENT = 4   # the moment component i (0, 1, 2) of a sign, un-stick, spin or against event, else -1
E_HOLDS = 5       # 1: the event stands only where its update would stick the component (a spin event:
                  # scan.spin_holds), else the step goes on through it
N_EVENT_COLS = 6
