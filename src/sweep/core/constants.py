"""The names every part of the core shares, in their one home: machine epsilon and the values of
the discrete contact state (layout.py names its slots, cs[CS_MODE] and cs[CS_SLAVE_OFF]).

The contact state is stored as float64 (cs, a plain array); these integer values are stored and
compared exactly (0.0, 1.0, ...). This module imports nothing, so the model, which evaluates its
right-hand side in mode ROLL or SLIDE, can use them below layout.py (which sizes its buffers from
the model's).
"""
from __future__ import annotations

# double precision's unit round-off x 2 (numpy.finfo(float).eps): 2**-52
EPS = 2.220446049250313e-16

# --- contact modes: cs[CS_MODE] ---------------------------------------------------------------------
# ROLL: no slip; SLIDE: friction along -u/|u|, the slip integrated; SLAVED: a slow slip whose direction
# is slaved to the quasi-static one (contact_rhs.py; docs/model.md). The model's right-hand side is
# evaluated in ROLL or SLIDE (SLAVED evaluates as sliding along the slaved direction).
ROLL, SLIDE, SLAVED = 0, 1, 2

# --- a slide's hand-over to SLAVED: cs[CS_SLAVE_OFF] -----------------------------------------------
# HANDOVER_ARMED: handed over where the slip falls to the slaving speed (EV_SLAVE).
# HANDOVER_OFF: off (the slip found no quasi-static direction, or passed it by) until the slip is fast
#   again (EV_SLIP_FAST re-arms it).
# SLOW_OFF: a slide that spirals out from u = 0 slides on below slip_tol; the hand-over and
#   EV_SLIP_SLOW are both off until the slip is fast again (slip.slow_slide).
# BELOW: a slide below slip_tol followed to its fate (an ending slip whose direction has yet to turn to
#   its direction of arrival, one spiralling in, one passing by u = 0); its fate is read again at
#   cs[CS_FLOOR] (slip.slow_slide).
# AT_FLOOR: a slide refused at the slaving speed for its slaved direction's error, followed to the
#   floor's speed SLAVE_FLOOR mu_d Phi, where it is handed over whatever that error (slip.try_slave);
#   or re-armed where it is fast again.
HANDOVER_ARMED, HANDOVER_OFF, SLOW_OFF, BELOW, AT_FLOOR = 0, 1, 2, 3, 4
