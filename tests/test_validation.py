"""Scene validation: property-based tests over random valid and invalid inputs (issue #5, part 1).

Every invalid input must raise ConfigError naming the field and the allowed range before any
integration; every valid input must load into finite kernel parameters.
"""
import copy
import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import sweep
from sweep.errors import ConfigError
from sweep.fields import RANGES
from sweep.scene import DEFAULTS, load_scene

finite = dict(allow_nan=False, allow_infinity=False)


@st.composite
def valid_scenes(draw):
    R = draw(st.floats(0.005, 0.5, **finite))
    mu_s = draw(st.floats(0.0, 2.0, **finite))
    cfg = {
        "disk": {"radius": R, "thickness": draw(st.floats(0.01, 1.0, **finite)) * R,
                 "mass": draw(st.floats(0.01, 10.0, **finite)), "shape": draw(st.sampled_from(["solid", "shell"]))},
        "contact": {"mu_s": mu_s, "mu_d": draw(st.floats(0.0, 1.0, **finite)) * mu_s,
                    "k1": draw(st.floats(0.0, 0.05, **finite)) * R, "k2": draw(st.floats(0.0, 0.05, **finite)) * R,
                    "k3": draw(st.floats(0.0, 0.05, **finite)) * R},
        "gravity": draw(st.floats(0.1, 30.0, **finite)),
        "initial": {"alpha": draw(st.floats(0.05, 1.5, **finite)) * draw(st.sampled_from([-1, 1])),
                    "omega": draw(st.lists(st.floats(-50, 50, **finite), min_size=3, max_size=3))},
        "stop": {"levels": draw(st.lists(st.floats(1e-6, 0.2, **finite), min_size=1, max_size=5, unique=True))},
    }
    return cfg


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(valid_scenes())
def test_valid_scenes_load_with_finite_parameters(cfg):
    sc = load_scene(cfg)
    assert np.all(np.isfinite(sc.params)) and sc.chi > 0
    assert sc.config["stop"]["levels"] == sorted(cfg["stop"]["levels"], reverse=True)
    assert sc.config["solver"] == DEFAULTS["solver"]          # defaults filled in


# (field path, bad value) pairs: out of range, NaN/inf, wrong type
BAD_VALUES = {
    "disk.radius": [0.0, -0.03, 5e-324, 1e-300, float("nan"), float("inf"), "3cm", None.__class__],
    "disk.thickness": [0.0, -1.0, float("nan"), 10.0],
    "disk.mass": [0.0, -1.0, 1e-300, float("inf"), True],
    "disk.shape": ["cube", 1, None],
    "contact.mu_s": [-0.1, float("nan")],
    "contact.mu_d": [-0.1, 0.51, float("inf")],
    "contact.k1": [-1e-6, 1.0, float("nan")],
    "contact.k2": [-1e-6, "x"],
    "contact.k3": [-1e-6, float("inf")],
    "gravity": [0.0, -9.81, 1e-300, float("nan")],
    "initial.alpha": [0.0, math.pi / 2, -math.pi / 2, 2.0, float("nan"), "1"],
    "initial.omega": [[0.0, 0.0], [0.0, 0.0, float("nan")], "spin", [0, 0, 1e9]],
    "initial.slip": [[0.0], [float("inf"), 0.0]],
    "stop.levels": [[], [0.0], [1e-9], [2.0], [0.1, 0.1], [float("nan")], 0.1],
    "stop.t_max": [0.0, -1.0, float("inf")],
    "stop.max_steps": [0, 1.5, -3, "many"],
    "solver.method": ["rk4"],
    "solver.rtol": [0.0, 1e-20, 0.5, float("nan")],
    "solver.atol": [0.0, 1.0],
    "solver.dt": [0.0, -1e-3],
    "solver.slip_tol": [0.0, 1.0],
    "solver.spin_tol": [-1e-9, 1.0, float("nan"), "off"],
    "solver.slave_tol": [-1e-3, 0.5, float("inf"), "1e-3"],
    "outputs.kinematics": ["yes", 1],
}
CASES = [(f, v) for f, vals in BAD_VALUES.items() for v in vals]


def _a_number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _with(field, value):
    cfg = copy.deepcopy(DEFAULTS)
    parts = field.split(".")
    d = cfg
    for p in parts[:-1]:
        d = d[p]
    d[parts[-1]] = value
    return cfg


@pytest.mark.parametrize("field,value", CASES, ids=[f"{f}={v!r}" for f, v in CASES])
def test_each_bad_value_is_rejected_naming_the_field(field, value):
    with pytest.raises(ConfigError) as ei:
        sweep.simulate(_with(field, value))
    msg = str(ei.value)
    assert ei.value.field.startswith(field), (ei.value.field, field)
    assert "allowed" in msg
    if field in RANGES and _a_number(ei.value.value):    # a number (or a list's item) out of its range
        assert RANGES[field].text() in msg, msg


# field -> the fields whose relative bound it is (contact.mu_s -> contact.mu_d; disk.radius -> k_i, thickness)
RELATIVE_TO = {f: {g for g, r in RANGES.items() if r.relative is not None and r.relative.field == f} for f in RANGES}


@settings(max_examples=200, deadline=None)
@given(field=st.sampled_from(sorted(BAD_VALUES)),
       value=st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.text(max_size=3), st.none(),
                       st.booleans(), st.lists(st.floats(), max_size=4)))
def test_random_values_either_load_or_name_the_field(field, value):
    """Any value in any field: either a valid scene, or a ConfigError that names that field (or one
    of its items) and its allowed range; or, where the value is valid but moves another field's
    relative bound (mu_s below the default mu_d, a radius below the default k_i or thickness / 4),
    that field and the bound it now exceeds."""
    try:
        sc = load_scene(_with(field, value))
    except ConfigError as exc:
        msg = str(exc)
        assert "allowed" in msg, msg
        if exc.field == field or exc.field.startswith(field + "["):
            if field in RANGES and _a_number(exc.value):
                assert RANGES[field].text() in msg, msg
        else:
            assert exc.field in RELATIVE_TO.get(field, ()), (exc.field, field, msg)
            assert RANGES[field].problem(value) is None, (field, value)      # the value itself is valid
            assert f"exceeds {RANGES[exc.field].relative.label} = " in msg and RANGES[exc.field].text() in msg, msg
    else:
        assert np.all(np.isfinite(sc.params))


@pytest.mark.parametrize("cfg,field", [
    ({"disk": {"radius": 0.03, "colour": "red"}}, "disk.colour"),
    ({"contakt": {}}, "contakt"),
    ({"stop": {"levels": [0.1], "tmax": 3}}, "stop.tmax"),
    ({"disk": [1, 2]}, "disk"),
])
def test_unknown_keys_and_wrong_structure_are_rejected(cfg, field):
    with pytest.raises(ConfigError) as ei:
        load_scene(cfg)
    assert ei.value.field == field


def test_levels_above_the_steady_motion_range_are_rejected():
    with pytest.raises(ConfigError) as ei:
        load_scene({"stop": {"levels": [1.4]}})
    assert ei.value.field == "stop.levels" and "steady" in str(ei.value)
