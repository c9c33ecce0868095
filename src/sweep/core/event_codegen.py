"""The generator of the events' ids (event_ids.py) and dispatch (event_dispatch.py) from the rows of
event_rules.RULES, as tableau.py generates dop853_sums.py: `python -m sweep.core.event_codegen`
writes both; tests/test_events.py checks that the checked-in files are its text.

check_rules refuses a table that a dispatch could not serve; the generated dispatches are straight-
line code over the rows (each id calls its own functions) and raise for an id outside the table.
"""
from __future__ import annotations

from pathlib import Path

from .event_rules import RULES
from .events import C_CONTACT_LOST, C_FACE, C_LEVEL, C_MOMENT, C_SIDE, C_SLIP, D_NONE

# the update protocol of each class of event (apply_event; event_rules' docstring says what each is)
PROTOCOLS = {C_MOMENT: "moment", C_SLIP: "slip", C_CONTACT_LOST: "final", C_FACE: "final", C_SIDE: "final", C_LEVEL: None}
IDS_MODULE = "event_ids.py"
DISPATCH_MODULE = "event_dispatch.py"


def _fn(f) -> str:
    """The name of a kernel (or plain function)."""
    return getattr(f, "py_func", f).__name__


def table_sizes(rules=None) -> tuple[int, int]:
    """(N_DYN_EVENTS, N_EVENTS) of the rows: the leading events of the dynamics (dip searched), and
    the leading event functions (a value)."""
    rules = RULES if rules is None else rules
    n_dyn = next((k for k, r in enumerate(rules) if r.dip == D_NONE), len(rules))
    n_ev = next((k for k, r in enumerate(rules) if r.value is None), len(rules))
    return n_dyn, n_ev


def check_rules(rules=None) -> None:
    """Raise ValueError for a table that a dispatch could not serve (event_rules' docstring lists what each row needs)."""
    rules = RULES if rules is None else rules
    n_dyn, n_ev = table_sizes(rules)
    names = [r.name for r in rules]
    if len(set(names)) != len(names):
        raise ValueError(f"event names repeat: {names}")
    for k, r in enumerate(rules):
        where = f"event {r.name} (id {k})"
        if r.cls not in PROTOCOLS:
            raise ValueError(f"{where}: class {r.cls} has no update protocol (PROTOCOLS)")
        if (r.update is None) != (PROTOCOLS[r.cls] is None):
            raise ValueError(f"{where}: an update is {'missing' if r.update is None else 'given for a class without one'}")
        if (r.value is None) != (k >= n_ev):
            raise ValueError(f"{where}: the event functions (a value) must come first, then the update-only ids")
        if (r.dip != D_NONE) != (k < n_dyn):
            raise ValueError(f"{where}: the events of the dynamics (a dip search) must come first")
        if r.value is not None and (r.state_value is None) != (r.forces != 0):
            raise ValueError(f"{where}: an event of the state alone (forces 0) needs a state value, and only it")
        if r.value is None and r.state_value is not None:
            raise ValueError(f"{where}: a state value without a value")
        if (r.cls == C_MOMENT) != (r.component in (0, 1, 2)):
            raise ValueError(f"{where}: a moment event needs its component (0, 1, 2), and only it")
    if n_ev == n_dyn:
        raise ValueError("no level event after the events of the dynamics")


def ids_source(rules=None) -> str:
    """The source of event_ids.py: the ids EV_<name>, the table's sizes and EVENTS (the columns of
    events.py, one row per id)."""
    rules = RULES if rules is None else rules
    check_rules(rules)
    n_dyn, n_ev = table_sizes(rules)
    out = ['"""The events\' ids and their table, GENERATED from event_rules.py: do not edit; edit its rows and',
           "rerun `python -m sweep.core.event_codegen`.", "",
           "An event's id is the position of its row: the events of the dynamics 0 .. N_DYN_EVENTS - 1 (scanned",
           "on every step), the levels' event (event functions end at N_EVENTS), then the ids that are",
           'updates only (up to N_EVENT_IDS). EVENTS[k]: the columns of events.py (E_CLASS .. E_HOLDS)."""',
           "import numpy as np", ""]
    out += [f"EV_{r.name} = {k}" for k, r in enumerate(rules)]
    out += [f"N_DYN_EVENTS = {n_dyn}", f"N_EVENTS = {n_ev}", f"N_EVENT_IDS = {len(rules)}", "",
            "EVENTS = np.array(["]
    out += [f"    ({r.cls}, {r.forces}, {r.dip}, {r.restart}, {r.component}, {r.holds}),  # EV_{r.name}" for r in rules]
    out += ["], dtype=np.int64)", "EVENTS.setflags(write=False)"]
    return "\n".join(out) + "\n"


def dispatch_source(rules=None) -> str:
    """The source of event_dispatch.py: event_values (every event function at a state), event_value and
    state_event_value (one of them), apply_event (an event's discrete update): straight-line code over
    the rows, each id calling its own functions; an id outside the table raises."""
    rules = RULES if rules is None else rules
    check_rules(rules)
    n_dyn, n_ev = table_sizes(rules)
    fns = sorted({_fn(f) for r in rules for f in (r.value, r.state_value, r.update) if f is not None})
    ids = [f"EV_{r.name}" for r in rules]
    out = ['"""The events\' dispatch, GENERATED from event_rules.py: do not edit; edit its rows and functions and',
           "rerun `python -m sweep.core.event_codegen`.", "",
           "Each id calls the functions its row registers (event_rules.RULES); an id with none raises.",
           '"""', "from .event_ids import ("]
    out += _wrapped(ids, "    ") + [")", "from .event_rules import ("] + _wrapped(fns + ["settle_event"], "    ")
    out += [")", "from .jit import kernel", "from .model import moment_axes_rates", "", "",
            "@kernel", "def event_values(t, y, aux, sys, lev, g):",
            '    """g[k] for every event function k (inf where not active); aux must belong to y, lev: the next',
            "    level's energy (NaN: none).\"\"\""]
    out += [f"    g[EV_{r.name}] = {_fn(r.value)}({r.component}, t, y, aux, sys, lev)" for r in rules[:n_ev]]
    out += ["", "", "@kernel", "def event_value(k, t, y, aux, sys, lev):",
            '    """g_k of event function k (event_values\'s)."""']
    for r in rules[:n_ev]:
        out += [f"    if k == EV_{r.name}:", f"        return {_fn(r.value)}({r.component}, t, y, aux, sys, lev)"]
    out += ['    raise ValueError("event_value: an id that is no event function")']
    out += ["", "", "@kernel", "def state_event_value(k, t, y, sys, lev):",
            '    """g_k of an event function of the state alone (E_FORCES 0), from the state y without the',
            '    right-hand side; raises for any other id."""']
    for r in rules[:n_ev]:
        if r.state_value is not None:
            out += [f"    if k == EV_{r.name}:", f"        return {_fn(r.state_value)}({r.component}, t, y, sys, lev)"]
    out += ['    raise ValueError("state_event_value: an event id with no value of the state alone")']
    out += ["", "", "@kernel", "def apply_event(k, t, y, sys, fstats):",
            '    """Discrete update at a located event k (state y at the event, changed in place): the event\'s own',
            "    update, then, for a moment's or the slip's, what every update owes the state (settle_event,",
            "    from omega.a_i before the update). Returns the outcome code that ends the scene, or -1 to",
            "    continue; raises for an id with no update (the level's). The caller counts the roll<->slip",
            '    transition (count_transition) and re-evaluates the right-hand side and the event functions."""',
            "    g_before = moment_axes_rates(y)"]
    for r in rules:
        proto = PROTOCOLS[r.cls]
        if proto is None:
            continue
        out += [f"    if k == EV_{r.name}:"]
        if proto == "moment":
            out += [f"        own, held = {_fn(r.update)}({r.component}, t, y, sys)",
                    "        if held:",
                    "            g_before = moment_axes_rates(y)   # the stop holds the stuck components: they stay stuck",
                    "        return settle_event(t, y, sys, g_before, own)"]
        elif proto == "slip":
            out += [f"        code = {_fn(r.update)}(t, y, sys)",
                    "        if code >= 0:", "            return code",
                    "        return settle_event(t, y, sys, g_before, -1)"]
        else:
            out += [f"        return {_fn(r.update)}(t, y, sys, fstats)"]
    out += ['    raise ValueError("apply_event: an event id with no discrete update")']
    return "\n".join(out) + "\n"


def _wrapped(names, indent) -> list[str]:
    """Names, comma-separated, in lines of at most 100 characters."""
    lines, cur = [], indent
    for name in names:
        piece = name + ", "
        if len(cur) + len(piece) > 100:
            lines.append(cur.rstrip())
            cur = indent
        cur += piece
    lines.append(cur.rstrip())
    return lines


def write_generated(folder: Path = Path(__file__).parent) -> list[Path]:
    """Write event_ids.py and event_dispatch.py into folder; returns their paths."""
    paths = []
    for name, text in ((IDS_MODULE, ids_source()), (DISPATCH_MODULE, dispatch_source())):
        path = folder / name
        path.write_text(text)
        paths.append(path)
    return paths


if __name__ == "__main__":
    for path in write_generated():
        print(f"written: {path}")
