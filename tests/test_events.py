"""The events as data: event_rules.RULES is the one table, its ids (event_ids.py) and dispatch
(event_dispatch.py) are generated from it, and neither the generator nor a dispatch has a default."""
from __future__ import annotations

import filecmp
import json
import math
import shutil
import subprocess
import sys
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


# a new event, as a maintainer would add it: one row and its functions in event_rules.py, then the
# generator. A timer of the state alone (tau reaches TAU_TIMER) that ends the scene as the face's update does (a halt at the event).
TIMER_RULE = '''
# === a timer: tau reaches 5 ============================================================================
@kernel
def timer_state_value(i, t, y, sys, lev):
    """5 - tau."""
    return 5.0 - t


@kernel
def timer_value(i, t, y, aux, sys, lev):
    """timer_state_value."""
    return timer_state_value(i, t, y, sys, lev)


@kernel
def timer_update(t, y, sys, fstats):
    """The scene ends."""
    return oc.FACE_CONTACT


RULES.append(Rule("TIMER", C_FACE, 0, D_RATES, R_NONE, value=timer_value, state_value=timer_state_value,
                  update=timer_update))

'''

TIMER_CHECKS = r'''
import json, math, sys
import numpy as np
import yaml
import sweep
from sweep.core import event_dispatch as ED, event_ids as ID, layout as L, model as M
cfg = yaml.safe_load(open(sys.argv[1]))
cfg["stop"]["t_max"] = 1.0
r = sweep.simulate(cfg)
sys_ = L.System(np.zeros(M.N_PARAMS), np.zeros(L.N_CS), M.N_CORE, np.zeros((L.N_WORK, L.N_WCOLS)),
                np.zeros(L.N_ISTATS, np.int64))
y, aux, g = np.zeros(M.N_FULL), np.zeros(M.N_AUX), np.zeros(ID.N_EVENTS)
ED.event_values(3.0, y, aux, sys_, math.nan, g)
print(json.dumps({"ids": {k: getattr(ID, k) for k in dir(ID) if k.startswith("EV_")},
                  "sizes": [ID.N_DYN_EVENTS, ID.N_EVENTS, ID.N_EVENT_IDS],
                  "value": ED.event_value(ID.EV_TIMER, 3.0, y, aux, sys_, math.nan),
                  "state_value": ED.state_event_value(ID.EV_TIMER, 3.0, y, sys_, math.nan),
                  "values": g[ID.EV_TIMER],
                  "outcome": r.summary["outcome"], "lay_flat": r.summary["lay_flat"], "t_end": r.summary["t_end"], "chi": r.scene.chi}))
'''


def test_a_new_event_is_one_row_and_its_functions(tmp_path):
    """Add an event to a copy of the package as one Rule row with its value, state value and update
    in event_rules.py, run the generator, and nothing else: the ids follow (the new id where its row
    is, the level's and the update-only ids one later), every dispatch calls the new functions, and a
    scene (the paper's, kernels run as Python) ends at the event, located at tau = 5."""
    src = Path(ER.__file__).resolve().parents[2]
    copy = tmp_path / "src"
    shutil.copytree(src / "sweep", copy / "sweep", ignore=shutil.ignore_patterns("__pycache__"))
    rules_py = copy / "sweep" / "core" / "event_rules.py"
    text = rules_py.read_text()
    anchor = "# === SLAVED: the slaved direction stops attracting"
    assert text.count(anchor) == 1
    rules_py.write_text(text.replace(anchor, TIMER_RULE.lstrip("\n") + anchor))
    env = {"PYTHONPATH": str(copy), "PATH": "/usr/bin:/bin", "HOME": str(tmp_path), "NUMBA_DISABLE_JIT": "1"}
    gen = subprocess.run([sys.executable, "-m", "sweep.core.event_codegen"], capture_output=True, text=True,
                         env=env, cwd=tmp_path, timeout=300)
    assert gen.returncode == 0, gen.stderr
    changed = sorted(p.relative_to(copy / "sweep").as_posix() for p in (copy / "sweep").rglob("*.py")
                     if not filecmp.cmp(p, src / "sweep" / p.relative_to(copy / "sweep"), shallow=False))
    assert changed == ["core/event_dispatch.py", "core/event_ids.py", "core/event_rules.py"], changed

    paper = Path(__file__).resolve().parents[1] / "config" / "scenes" / "kessler2002.yaml"
    run = subprocess.run([sys.executable, "-c", TIMER_CHECKS, str(paper)], capture_output=True, text=True,
                         env=env, cwd=tmp_path, timeout=600)
    assert run.returncode == 0, run.stderr
    out = json.loads(run.stdout.splitlines()[-1])
    face = ID.EV_FACE
    want = {f"EV_{r.name}": k + (k > face) for k, r in enumerate(ER.RULES)}
    want["EV_TIMER"] = face + 1
    assert out["ids"] == want
    assert out["sizes"] == [ID.N_DYN_EVENTS + 1, ID.N_EVENTS + 1, ID.N_EVENT_IDS + 1]
    assert out["value"] == out["state_value"] == out["values"] == 2.0
    assert out["outcome"] == "halted" and out["lay_flat"] is True     # the face's update: a halt at the event
    assert out["t_end"] == pytest.approx(5.0 * out["chi"], rel=1e-12)
