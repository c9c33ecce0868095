"""The events' ids and their table, GENERATED from event_rules.py: do not edit; edit its rows and
rerun `python -m sweep.core.event_codegen`.

An event's id is the position of its row: the events of the dynamics 0 .. N_DYN_EVENTS - 1 (scanned
on every step), the levels' event (event functions end at N_EVENTS), then the ids that are
updates only (up to N_EVENT_IDS). EVENTS[k]: the columns of events.py (E_CLASS .. E_HOLDS)."""
import numpy as np

EV_SIGN1 = 0
EV_SIGN2 = 1
EV_SIGN3 = 2
EV_UNSTICK1 = 3
EV_UNSTICK2 = 4
EV_UNSTICK3 = 5
EV_CONE = 6
EV_SLIP_SLOW = 7
EV_SLIP_STOP = 8
EV_SLIP_FAST = 9
EV_SLAVE = 10
EV_CONTACT = 11
EV_SIDE = 12
EV_FACE = 13
EV_SLAVE_LOST = 14
EV_SPIN1 = 15
EV_SPIN2 = 16
EV_SPIN3 = 17
EV_LEVEL = 18
EV_AGAINST1 = 19
EV_AGAINST2 = 20
EV_AGAINST3 = 21
N_DYN_EVENTS = 18
N_EVENTS = 19
N_EVENT_IDS = 22

EVENTS = np.array([
    (0, 0, 1, 1, 0, 0),  # EV_SIGN1
    (0, 0, 1, 1, 1, 0),  # EV_SIGN2
    (0, 0, 1, 1, 2, 0),  # EV_SIGN3
    (0, 1, 0, 0, 0, 0),  # EV_UNSTICK1
    (0, 1, 0, 0, 1, 0),  # EV_UNSTICK2
    (0, 1, 0, 0, 2, 0),  # EV_UNSTICK3
    (1, 1, 0, 0, -1, 0),  # EV_CONE
    (1, 1, 3, 0, -1, 0),  # EV_SLIP_SLOW
    (1, 1, 0, 1, -1, 0),  # EV_SLIP_STOP
    (1, 1, 0, 0, -1, 0),  # EV_SLIP_FAST
    (1, 1, 3, 0, -1, 0),  # EV_SLAVE
    (2, 1, 0, 0, -1, 0),  # EV_CONTACT
    (4, 0, 2, 1, -1, 0),  # EV_SIDE
    (3, 0, 0, 0, -1, 0),  # EV_FACE
    (1, 1, 0, 0, -1, 0),  # EV_SLAVE_LOST
    (0, 0, 1, 2, 0, 1),  # EV_SPIN1
    (0, 0, 1, 2, 1, 1),  # EV_SPIN2
    (0, 0, 1, 2, 2, 1),  # EV_SPIN3
    (5, 0, 4, 0, -1, 0),  # EV_LEVEL
    (0, 0, 4, 0, 0, 0),  # EV_AGAINST1
    (0, 0, 4, 0, 1, 0),  # EV_AGAINST2
    (0, 0, 4, 0, 2, 0),  # EV_AGAINST3
], dtype=np.int64)
EVENTS.setflags(write=False)
