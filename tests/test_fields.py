"""The registry of inputs (sweep.fields) is the one place a sweepable input is declared: the sweep
schema, scene defaults and checks, the grid's axes and the cube's coordinates all follow it."""
import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from sweep import axes, fields, figures, scene, validation

SRC = Path(__file__).resolve().parents[1] / "src"

# a new sweepable input, as a maintainer would add it: one entry in sweep/fields.py's FIELDS
DUMMY_ENTRY = '''    Field("contact.crr", Range(0.0, 0.5, "rolling-resistance coefficient c_rr, dimensionless"), 0.0,
          axis=Axis("crr", "1", "rolling resistance coefficient c_rr", "rolling resistance c_rr", outer=True,
                    default=(0.0,))),
'''

CHECKS = r'''
import json, sys
import yaml
from sweep import axes, cf, chunking, figures, grid, scene, validation
from sweep.errors import ConfigError

out = {}
schema = validation.load_schema()
out["grid_prop"] = schema["properties"]["grid"]["properties"]["crr"]
out["grid_desc"] = schema["properties"]["grid"]["description"]
out["refine_axes"] = sorted(schema["properties"]["refine"]["properties"]["axes"]["properties"])
out["default"] = scene.DEFAULTS["contact"]["crr"]
try:
    scene.load_scene({"contact": {"crr": 0.7}})
except ConfigError as err:
    out["scene_error"] = str(err)
tiny = yaml.safe_load(open(sys.argv[1]))
try:
    grid.normalize(dict(tiny, grid=dict(tiny["grid"], crr=[0.1, 0.9])), schema)
except validation.SweepConfigError as err:
    out["sweep_error"] = str(err)
settings = grid.normalize(tiny, schema)      # a config without the new axis: its default
out["axes"] = [axes.AXES, axes.OUTER_AXES, axes.INNER_AXES]
out["settings_crr"] = settings["grid"]["crr"]
chunk = next(iter(chunking.plan_chunks(settings).values()))
out["point"] = chunk.points[0]
out["scene_crr"] = grid.scene(settings, chunk.points[0])["contact"]["crr"]
out["coord"] = cf.cube_coords(settings)["crr"][2]
out["label"] = figures.AXIS_LABELS["crr"]
print(json.dumps(out))
'''


def test_the_axes_come_from_the_registry():
    assert axes.AXES == ("mu_d", "k1", "k2", "k3", "alpha0", "omega0")
    assert axes.OUTER_AXES == ("mu_d", "k1", "k2", "k3") and axes.INNER_AXES == ("alpha0", "omega0")
    assert axes.AXIS_UNITS == {"mu_d": "1", "k1": "m", "k2": "m", "k3": "m", "alpha0": "rad", "omega0": "rad s-1"}
    assert set(figures.AXIS_LABELS) == set(axes.AXES) | {"level"}
    assert {a: fields.SWEEP_KEYS[f"grid.{a}"] for a in axes.AXES} == {
        "mu_d": "contact.mu_d", "k1": "contact.k1", "k2": "contact.k2", "k3": "contact.k3",
        "alpha0": "initial.alpha", "omega0": "initial.spin"}


def test_scene_defaults_are_valid_and_every_scene_field_has_one():
    sc = scene.load_scene({})
    assert sc.config == scene.DEFAULTS | {"stop": dict(scene.DEFAULTS["stop"],
                                                      levels=sorted(scene.DEFAULTS["stop"]["levels"], reverse=True))}
    for f in fields.FIELDS:
        assert f.scene == (f.default is not None), f.path
        assert (f.range is not None) == (f.kind in ("number", "vector", "levels")), f.path


def test_the_registry_names_the_shapes_and_kernel_slots_the_model_has():
    """disk.shape's choices are scene.SHAPES' (their k^2), and every Param names a parameter slot of
    the model that make_params leaves to it (set to 0 there) with a known scale."""
    from sweep.core import model

    shape = next(f for f in fields.FIELDS if f.path == "disk.shape")
    assert shape.choices == tuple(scene.SHAPES)
    made, _ = model.make_params(1.0, 0.03755, 0.0128, 9.81, 0.5, 0.3, (0.0, 0.0, 0.0))
    for f in fields.FIELDS:
        if f.kernel is not None:
            slot = getattr(model, f.kernel.slot)
            assert 0 <= slot < model.N_PARAMS and made[slot] == 0.0, f.path
            assert f.kernel.scale in scene.KERNEL_SCALE, f.path


def test_the_packaged_schema_file_is_the_one_the_registry_builds():
    """config.schema.yaml (for tools that read a file) equals what load_schema builds from the
    template and the registry; regenerate it with validation.write_schema() after a registry change."""
    assert validation.load_schema(validation.SCHEMA_PATH) == validation.load_schema(), \
        "stale schema file: .venv/bin/python -c 'from sweep import validation; validation.write_schema()'"


def test_a_new_sweepable_input_is_one_registry_entry(tmp_path):
    """Add a dummy sweepable input to a copy of the package as one FIELDS entry (nothing else
    edited) and check that it reaches the schema, the scene defaults and checks (its name and
    range in the messages), the sweep's axes, chunks and scenes, and the cube's coordinates."""
    copy = tmp_path / "src"
    shutil.copytree(SRC / "sweep", copy / "sweep", ignore=shutil.ignore_patterns("*.pyc"))
    registry = copy / "sweep" / "fields.py"
    text = registry.read_text()
    anchor = '    Field("gravity", Range('
    assert text.count(anchor) == 1
    registry.write_text(text.replace(anchor, DUMMY_ENTRY + anchor))
    tiny = Path(__file__).resolve().parents[1] / "config" / "tiny.yaml"
    env = {"PYTHONPATH": str(copy), "PATH": "/usr/bin:/bin", "HOME": str(tmp_path)}
    run = subprocess.run([sys.executable, "-c", CHECKS, str(tiny)], capture_output=True, text=True, env=env,
                         cwd=tmp_path, timeout=600)
    assert run.returncode == 0, run.stderr
    out = json.loads(run.stdout.splitlines()[-1])

    allowed = "[0, 0.5] (rolling-resistance coefficient c_rr, dimensionless)"
    assert out["grid_prop"]["items"] == {"type": "number", "minimum": 0.0, "maximum": 0.5}
    assert out["grid_prop"]["description"] == "rolling-resistance coefficient c_rr, dimensionless; allowed [0, 0.5] each"
    assert "the sweep axes: mu_d, k1, k2, k3, crr, alpha0, omega0," in out["grid_desc"]
    assert "crr" in out["refine_axes"]
    assert out["default"] == 0.0
    assert out["scene_error"] == f"contact.crr = 0.7 is invalid: allowed {allowed}"
    assert out["sweep_error"] == "grid.crr[1] = 0.9 is invalid: allowed [0, 0.5] each (rolling-resistance coefficient c_rr, dimensionless)"
    assert out["axes"] == [["mu_d", "k1", "k2", "k3", "crr", "alpha0", "omega0"], ["mu_d", "k1", "k2", "k3", "crr"],
                           ["alpha0", "omega0"]]
    assert out["settings_crr"] == [0.0] and len(out["point"]) == 7 and out["point"][4] == 0.0
    assert out["scene_crr"] == 0.0
    assert out["coord"] == {"units": "1", "long_name": "rolling resistance coefficient c_rr"}
    assert out["label"] == "rolling resistance c_rr"


@pytest.mark.parametrize("axis", axes.AXES)
def test_every_axis_is_documented(axis):
    """docs/pipeline.md lists every config key and every cube coordinate."""
    doc = (Path(__file__).resolve().parents[1] / "docs" / "pipeline.md").read_text()
    assert f"| `grid.{axis}` |" in doc
    coordinate_rows = [line for line in doc.splitlines() if line.startswith("| `") and f"`{axis}`" in line]
    assert any(f"| {axes.AXIS_UNITS[axis]} |" in line for line in coordinate_rows), coordinate_rows
