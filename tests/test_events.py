"""The events as data: event_rules.RULES is the one table, its ids (event_ids.py) and dispatch
(event_dispatch.py) are generated from it, and neither the generator nor a dispatch has a default."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from sweep.core import event_codegen as EC
from sweep.core import event_dispatch as ED
from sweep.core import event_ids as ID
from sweep.core import event_rules as ER
from sweep.core import events as EV
from sweep.core import layout as L
from sweep.core import model as M


def test_the_generated_ids_and_dispatch_are_the_generators_text():
    """event_ids.py and event_dispatch.py are what event_codegen writes: a row or a function added to
    event_rules.py without `python -m sweep.core.event_codegen` fails here."""
    folder = Path(ER.__file__).parent
    assert (folder / EC.IDS_MODULE).read_text() == EC.ids_source()
    assert (folder / EC.DISPATCH_MODULE).read_text() == EC.dispatch_source()


def test_the_ids_are_the_rows_of_the_rules():
    """EV_<name> is its row's position; EVENTS holds the row's columns (events.E_*)."""
    assert ID.N_EVENT_IDS == len(ER.RULES) == ID.EVENTS.shape[0]
    assert ID.EVENTS.shape[1] == EV.N_EVENT_COLS
    for k, r in enumerate(ER.RULES):
        assert getattr(ID, f"EV_{r.name}") == k
        assert tuple(ID.EVENTS[k]) == (r.cls, r.forces, r.dip, r.restart, r.component, r.holds)
    assert EC.table_sizes() == (ID.N_DYN_EVENTS, ID.N_EVENTS)


def _kernel(name):
    """A stand-in function (only its name is read by the generator)."""
    def fn():
        return None
    fn.__name__ = name
    return fn


def _rules_with(k, **change):
    rules = list(ER.RULES)
    rules[k] = rules[k]._replace(**change)
    return rules


@pytest.mark.parametrize("change, message", [
    ((ID.EV_CONE, {"update": None}), "update is missing"),
    ((ID.EV_LEVEL, {"update": _kernel("level_update")}), "class without one"),
    ((ID.EV_SIDE, {"cls": 99}), "no update protocol"),
    ((ID.EV_FACE, {"state_value": None}), "needs a state value"),
    ((ID.EV_CONE, {"state_value": _kernel("cone_state_value")}), "needs a state value"),
    ((ID.EV_AGAINST2, {"value": _kernel("against_value")}), "event functions .* must come first"),
    ((ID.EV_SIGN1, {"value": None, "state_value": None}), "event functions .* must come first"),
    ((ID.EV_SPIN1, {"dip": EV.D_NONE}), "events of the dynamics"),
    ((ID.EV_CONE, {"component": 1}), "component"),
    ((ID.EV_SIGN2, {"name": "SIGN1"}), "names repeat"),
])
def test_the_generator_refuses_a_table_a_dispatch_could_not_serve(change, message):
    """check_rules (run by both generators) raises for each way a row could leave an id without its
    value or update, or put it where the scan or the table's sizes do not expect it."""
    k, fields = change
    rules = _rules_with(k, **fields)
    with pytest.raises(ValueError, match=message):
        EC.ids_source(rules)
    with pytest.raises(ValueError, match=message):
        EC.dispatch_source(rules)


def test_an_id_outside_the_table_raises_in_every_dispatch():
    """No dispatch has a fall-through default: an id beyond the table (or negative) raises."""
    p = np.zeros(M.N_PARAMS)
    cs = np.zeros(L.N_CS)
    sys = L.System(p, cs, M.N_CORE, np.zeros((L.N_WORK, L.N_WCOLS)), np.zeros(L.N_ISTATS, np.int64))
    y, aux = np.zeros(M.N_FULL), np.zeros(M.N_AUX)
    for k in (-1, ID.N_EVENTS, ID.N_EVENT_IDS):
        with pytest.raises(ValueError, match="no event function"):
            ED.event_value(k, 0.0, y, aux, sys, math.nan)
    for k in (-1, ID.N_EVENT_IDS):
        with pytest.raises(ValueError, match="no value of the state alone"):
            ED.state_event_value(k, 0.0, y, sys, math.nan)
        with pytest.raises(ValueError, match="no discrete update"):
            ED.apply_event(k, 0.0, y, sys, np.zeros(L.N_FSTATS))
