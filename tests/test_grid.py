"""Sweep config validation and the chunk plan (sweep.grid); no integration is run here."""
from __future__ import annotations

import copy
import itertools
import math
import re
from pathlib import Path

import pytest
import yaml
from hypothesis import assume, given, settings as hsettings, strategies as st

from sweep import axes, chunking, grid, validation

ROOT = Path(__file__).resolve().parents[1]
SCHEMA = validation.load_schema()


def load(name: str) -> dict:
    return yaml.safe_load((ROOT / "config" / name).read_text())


def small(**grid_axes) -> dict:
    """A valid config with a small grid; keyword arguments replace axes."""
    cfg = load("tiny.yaml")
    cfg["grid"].update({k: list(v) for k, v in grid_axes.items()})
    return cfg


def norm(cfg: dict) -> dict:
    # the core's per-scene checks are exercised separately; skipping them keeps these fast
    return grid.normalize(cfg, SCHEMA, check_scenes=False)


# ------------------------------------------------------------------------------- validation

@pytest.mark.parametrize("name", ["config.yaml", "tiny.yaml", "million.yaml"])
def test_shipped_configs_are_valid(name):
    settings = grid.normalize(load(name), SCHEMA)
    cfg = load(name)
    for a in axes.AXES:
        assert settings["grid"][a] == sorted(float(v) for v in cfg["grid"][a])


def test_defaults_match_snakemake_validate():
    from snakemake.utils import validate

    cfg = {"grid": load("tiny.yaml")["grid"]}
    ours = validation.fill_defaults(cfg, SCHEMA)
    theirs = copy.deepcopy(cfg)
    validate(theirs, str(validation.SCHEMA_PATH))
    assert ours == theirs
    # every default the schema declares is filled in (`name` has none: it defaults to the
    # config file's stem, see sweep.configfiles.sweep_name; `refine`, an adaptive map, is there only if given)
    assert set(ours) == set(SCHEMA["properties"]) - {"name", "refine"}


def _bad(mutate) -> str:
    cfg = load("tiny.yaml")
    mutate(cfg)
    with pytest.raises(validation.SweepConfigError) as exc:
        grid.normalize(cfg, SCHEMA)
    return str(exc.value)


@pytest.mark.parametrize("mutate, fragments", [
    (lambda c: c["grid"].__setitem__("mu_d", [0.2, -0.1]), ["grid.mu_d[1] = -0.1 is invalid", "allowed [0, mu_s]"]),
    (lambda c: c["grid"].__setitem__("k3", ["big"]), ["grid.k3[0] = 'big' is invalid: not a number"]),
    # one rule for numbers everywhere: a number in quotes is text, here as in scene files
    (lambda c: c["solver"].__setitem__("rtol", "1e-1"), ["solver.rtol = '1e-1'", "remove the quotes", "[1e-14, 1e-2]"]),
    (lambda c: c["solver"].__setitem__("rtol", "0.001"), ["solver.rtol = '0.001'", "remove the quotes"]),
    (lambda c: c.__setitem__("colour", "red"), ["colour = 'red' is invalid: no such key", "allowed keys"]),
    (lambda c: c["disk"].__setitem__("diameter", 0.07), ["disk.diameter = 0.07", "no such key", "allowed keys"]),
    (lambda c: c["grid"].__setitem__("omega0", []), ["grid.omega0 = []", "empty"]),
    (lambda c: c["grid"].__setitem__("alpha0", [0.9, 1.1, 0.9]), ["grid.alpha0 = ", "duplicate", "0.9"]),
    (lambda c: c.__setitem__("levels", [0.3, 1.6]), ["levels[1] = 1.6", "[1e-7, pi/2)"]),
    (lambda c: c.__setitem__("levels", [0.0, 0.1]), ["levels[0] = 0.0", "[1e-7, pi/2)"]),
    (lambda c: c["grid"].__setitem__("alpha0", [1.6]), ["grid.alpha0[0] = 1.6", "(-pi/2, pi/2)"]),
    (lambda c: c["grid"].__setitem__("alpha0", [0.0, 0.5]), ["grid.alpha0[0] = 0.0", "0 is not allowed"]),
    (lambda c: c["grid"].__setitem__("mu_d", [0.2, 0.6]), ["grid.mu_d[1] = 0.6", "exceeds mu_s", "[0, mu_s]"]),
    (lambda c: c["grid"].__setitem__("k1", [float("nan")]), ["grid.k1[0] = nan", "not a finite number"]),
    (lambda c: c.__setitem__("gravity", float("inf")), ["gravity = inf", "not a finite number", "[1e-3, 1000]"]),
    (lambda c: c["solver"].__setitem__("method", "fixed"), ["solver.dt is missing", "required"]),
    (lambda c: c["solver"].__setitem__("method", "rk4"), ["solver.method = 'rk4'", "adaptive | fixed"]),
    (lambda c: c["stop"].__setitem__("max_steps", 10.5), ["stop.max_steps = 10.5", "integer"]),
    (lambda c: c.__setitem__("chunk_size", 0), ["chunk_size = 0", "[1, 100000]"]),
    (lambda c: c["grid"].__setitem__("k3", [0.05]), ["grid.k3[0] = 0.05", "exceeds radius = 0.03755 m", "[0, radius] = [0, 0.03755] m"]),
    (lambda c: c["outputs"].__setitem__("notebooks", ["maps"]), ["outputs.notebooks[0] = 'maps'", "halt_time"]),
    (lambda c: c["grid"].pop("k2"), ["grid.k2 is missing", "required"]),
    (lambda c: c.__setitem__("solver", 3), ["solver = 3 is invalid: not a mapping", "rtol"]),
])
def test_bad_configs_name_the_key_and_range(mutate, fragments):
    msg = _bad(mutate)
    for frag in fragments:
        assert frag in msg, (frag, msg)


def test_core_checks_reach_the_config_key():
    # The core rejects levels above the largest inclination at which this disk's steady
    # motion exists; the sweep reports it under the config key `levels`, before any job.
    from sweep import scene as core_scene

    cfg = load("tiny.yaml")
    settings = norm(cfg)
    sc = core_scene.load_scene(grid.scene(settings, tuple(settings["grid"][a][0] for a in axes.AXES)))
    too_high = core_scene.max_level(sc.params) + 0.1
    assert too_high < math.pi / 2  # inside the schema's range, so only the core can reject it
    cfg["levels"] = [too_high, 0.1]
    msg = _bad(lambda c: c.update(levels=cfg["levels"]))
    assert msg.startswith("levels = ") and "physics-core" in msg


@pytest.mark.parametrize("section, field", [({"device": "cuda", "chunk_size": 100000}, "execution.device"),
                                            ({"device": "cpu"}, "execution.device"),
                                            ({"chunk_size": 10}, "execution")])
def test_the_removed_execution_section_is_refused_in_one_line_naming_the_field(section, field):
    """The GPU path and its `execution` section were removed: a config that still has one gets one
    line naming the field and saying why and what to do, not an 'unknown key' or a traceback."""
    msg = _bad(lambda c: c.__setitem__("execution", section))
    lines = msg.splitlines()
    assert len(lines) == 1, msg
    assert lines[0].startswith(f"{field} = ") and "no longer accepted" in msg, msg
    assert "GPU path was removed" in msg and "delete the `execution` section" in msg, msg
    if "device" in section:
        assert repr(section["device"]) in msg


def test_all_problems_reported_together():
    msg = _bad(lambda c: (c["grid"].__setitem__("k1", [-1.0]), c.__setitem__("gravity", -1.0)))
    lines = msg.splitlines()   # one line per invalid field
    assert len(lines) == 2 and any(x.startswith("grid.k1[0] = -1.0 is invalid") for x in lines), msg
    assert any(x.startswith("gravity = -1.0 is invalid") for x in lines), msg


# ------------------------------------------------------------------------------- scenes

def test_scene_of_a_point_is_a_rolling_start_accepted_by_the_core():
    from sweep import scene as core_scene

    settings = norm(load("tiny.yaml"))
    point = tuple(settings["grid"][a][-1] for a in axes.AXES)
    sc = grid.scene(settings, point)
    assert sc["initial"]["omega"] == [0.0, 0.0, -point[5]]
    assert sc["initial"]["slip"] == [0.0, 0.0]
    assert sc["initial"]["alpha"] == point[4]
    assert [sc["contact"][k] for k in ("mu_d", "k1", "k2", "k3")] == list(point[:4])
    loaded = core_scene.load_scene(sc)
    assert loaded.config["stop"]["levels"] == settings["levels"]  # same (decreasing) order


# ------------------------------------------------------------------------------- chunking

def _all_points(settings):
    return set(itertools.product(*(settings["grid"][a] for a in axes.AXES)))


@pytest.mark.parametrize("chunk_size", [1, 2, 3, 7])
def test_plan_covers_grid_once_without_mixing_outer_values(chunk_size):
    cfg = small(mu_d=[0.1, 0.3], k3=[1e-4, 2e-4, 3e-4], alpha0=[0.5, 0.7, 0.9, 1.1], omega0=[5.0, 10.0, 15.0])
    cfg["chunk_size"] = chunk_size
    settings = norm(cfg)
    plan = chunking.plan_chunks(settings)
    pts = [p for c in plan.values() for p in c.points]
    assert len(pts) == len(set(pts)) == len(_all_points(settings))
    assert set(pts) == _all_points(settings)
    for c in plan.values():
        assert 1 <= len(c.points) <= 2 * chunk_size
        assert len({p[:4] for p in c.points}) == 1
        assert c.id == chunking.sha256_hex(c.spec_json)[:chunking.CHUNK_ID_HEX]


def test_chunk_ids_follow_values_not_spelling_or_order():
    a = small(alpha0=[0.9, 1.1], omega0=[14.457])
    b = small(alpha0=[1.1, 0.9], omega0=[14.457])
    b["grid"]["k1"] = [3.755e-6]
    b["gravity"] = 9.81
    c = copy.deepcopy(a)
    c["grid"]["omega0"] = [14.457]
    c["stop"]["t_max"] = 30  # int spelling of 30.0
    assert chunking.plan_chunks(norm(a)).keys() == chunking.plan_chunks(norm(b)).keys() == chunking.plan_chunks(norm(c)).keys()


@pytest.mark.parametrize("change", [
    lambda c: c["solver"].__setitem__("rtol", 1.0e-9),
    lambda c: c["stop"].__setitem__("t_max", 31.0),
    lambda c: c.__setitem__("levels", [0.3, 0.1, 0.03]),
    lambda c: c["disk"].__setitem__("mass", 0.5),
    lambda c: c.__setitem__("mu_s", 0.45),
])
def test_changing_a_setting_changes_every_chunk(change):
    cfg = load("tiny.yaml")
    old = chunking.plan_chunks(norm(cfg))
    change(cfg)
    new = chunking.plan_chunks(norm(cfg))
    assert len(new) == len(old) and not set(new) & set(old)


def test_changing_the_physics_core_changes_every_chunk(monkeypatch):
    cfg = load("tiny.yaml")
    old = chunking.plan_chunks(norm(cfg))
    assert all(json_core(c) == chunking.core_fingerprint() for c in old.values())
    monkeypatch.setattr(chunking, "core_fingerprint", lambda: "0" * 64)
    new = chunking.plan_chunks(norm(cfg))
    assert len(new) == len(old) and not set(new) & set(old)


def json_core(chunk) -> str:
    return chunk.spec["core"]


def test_core_fingerprint_covers_physics_not_pipeline(tmp_path, monkeypatch):
    import shutil

    src = Path(chunking.__file__).parent
    pkg = tmp_path / "sweep"
    shutil.copytree(src, pkg, ignore=shutil.ignore_patterns("__pycache__"))
    monkeypatch.setattr(chunking, "__file__", str(pkg / "chunking.py"))
    base = chunking.core_fingerprint()
    assert base == chunking.core_fingerprint()
    (pkg / "gather.py").write_text((pkg / "gather.py").read_text() + "\n# pipeline edit\n")
    assert chunking.core_fingerprint() == base
    (pkg / "plots.py").write_text((pkg / "plots.py").read_text() + "\n# figure edit\n")
    assert chunking.core_fingerprint() == base
    (pkg / "core" / "contact_rhs.py").write_text((pkg / "core" / "contact_rhs.py").read_text() + "\n# physics edit\n")
    assert chunking.core_fingerprint() != base


def test_output_choice_does_not_change_chunks():
    cfg = load("tiny.yaml")
    old = chunking.plan_chunks(norm(cfg))
    cfg["outputs"]["notebooks"] = ["cost"]
    assert chunking.plan_chunks(norm(cfg)).keys() == old.keys()


@pytest.mark.parametrize("axis, value", [("mu_d", 0.25), ("mu_d", 0.05), ("k3", 4.5e-4), ("k1", 1e-6), ("k2", 1e-4)])
def test_new_outer_value_adds_only_new_chunks(axis, value):
    cfg = load("tiny.yaml")
    old = chunking.plan_chunks(norm(cfg))
    cfg["grid"][axis] = cfg["grid"][axis] + [value]
    new = chunking.plan_chunks(norm(cfg))
    assert set(old) <= set(new)
    added = [new[k] for k in set(new) - set(old)]
    idx = axes.AXES.index(axis)
    assert added and all(p[idx] == value for c in added for p in c.points)


def _natural_cuts(inner, chunk_size):
    return {i for i, p in enumerate(inner) if chunking._inner_hash(p) % chunk_size == 0}


@hsettings(max_examples=40, deadline=None)
@given(n_alpha=st.integers(1, 4), n_omega=st.integers(2, 30), chunk_size=st.integers(1, 6),
       axis=st.sampled_from(["alpha0", "omega0"]), where=st.floats(0.0, 1.0))
def test_inner_insertion_keeps_chunks_away_from_it(n_alpha, n_omega, chunk_size, axis, where):
    """Content-defined cut: chunks that end before the first new point, or start after the
    first natural cut following the last new point, survive an insertion into an inner axis."""
    alphas = [0.2 + 0.1 * i for i in range(n_alpha)]
    omegas = [5.0 + 1.0 * i for i in range(n_omega)]
    cfg = small(mu_d=[0.3], k3=[3e-4], alpha0=alphas, omega0=omegas)
    cfg["chunk_size"] = chunk_size
    old_s = norm(cfg)
    old = chunking.plan_chunks(old_s)
    vals = cfg["grid"][axis]
    lo, hi = vals[0] - 0.05, vals[-1] + 0.05
    new_value = round(lo + where * (hi - lo), 6)
    # an existing value is no insertion, and alpha0 must stay a valid initial angle
    assume(new_value not in vals and (axis != "alpha0" or 0 < new_value < 1.5))
    cfg["grid"][axis] = vals + [new_value]
    new_s = norm(cfg)
    new = chunking.plan_chunks(new_s)
    inner = list(itertools.product(*(new_s["grid"][a] for a in axes.INNER_AXES)))
    k = axes.INNER_AXES.index(axis)
    new_pos = [i for i, p in enumerate(inner) if p[k] == new_value]
    first, last = min(new_pos), max(new_pos)
    # the first natural cut at an old point after the last new point: from there on the old
    # and new sequences cut identically
    later_cuts = [i for i in sorted(_natural_cuts(inner, chunk_size)) if i > last]
    resync = later_cuts[0] if later_cuts else len(inner)
    position = {p: i for i, p in enumerate(inner)}
    old_end = max(itertools.product(*(old_s["grid"][a] for a in axes.INNER_AXES)))
    for cid, c in old.items():
        pos = [position[p[4:]] for p in c.points]
        closed = c.points[-1][4:] != old_end  # the old final block was ended by the sequence end only
        if (max(pos) < first and closed) or min(pos) > resync:
            assert cid in new, (pos, first, last, resync)
    # and nothing outside the affected stretch is recomputed needlessly
    for cid, c in new.items():
        if cid not in old:
            pos = [position[p[4:]] for p in c.points]
            assert min(pos) <= resync and max(pos) >= first


def test_inner_insertion_reruns_less_than_a_positional_split():
    omegas = [5.0 + 0.5 * i for i in range(64)]
    cfg = small(mu_d=[0.3], k3=[3e-4], alpha0=[1.0], omega0=omegas)
    cfg["chunk_size"] = 4
    old = chunking.plan_chunks(norm(cfg))
    cfg["grid"]["omega0"] = omegas + [5.0 + 0.5 * 20 + 0.25]   # inserted after the 21st value
    new = chunking.plan_chunks(norm(cfg))
    rerun_points = sum(len(c.points) for k, c in new.items() if k not in old)
    # a positional split into blocks of 4 would rerun every block from the insertion on
    positional = len(omegas) + 1 - (21 // 4) * 4
    assert 1 <= rerun_points < positional


def test_split_inner_caps_block_length():
    inner = [(0.5, float(i)) for i in range(200)]
    for size in (1, 3, 10):
        blocks = chunking.split_inner(inner, size)
        assert [p for b in blocks for p in b] == inner
        assert max(map(len, blocks)) <= 2 * size
        cuts = _natural_cuts(inner, size)
        ends = set(itertools.accumulate(len(b) for b in blocks))
        assert {i + 1 for i in cuts} <= ends  # every natural cut is a block end


# ------------------------------------------------------------------------------- packaging

def test_schema_ships_as_package_data_and_loads_from_an_installed_package(tmp_path):
    """A non-editable install finds the config schema as package data.

    setuptools' `build_py` fills the build directory that a wheel packs as its purelib (the
    venv's setuptools has no `bdist_wheel` without the `wheel` package, so the test stops one step
    before zipping); that directory, put first on sys.path, is the installed package: the schema
    is in its file list and `validation.load_schema()` / `validation.SCHEMA_PATH` find it there."""
    import json
    import shutil
    import subprocess
    import sys

    # build from a copy, so no build/ or *.egg-info lands in the work tree
    src = tmp_path / "src_tree"
    shutil.copytree(ROOT / "src", src / "src",
                    ignore=shutil.ignore_patterns("__pycache__", "*.egg-info", "*.nbi", "*.nbc"))
    shutil.copy(ROOT / "pyproject.toml", src / "pyproject.toml")
    site = tmp_path / "site"
    res = subprocess.run([sys.executable, "-c", "from setuptools import setup; setup()", "-q",
                          "build_py", "--build-lib", str(site)], cwd=src, capture_output=True,
                         text=True, timeout=300)
    assert res.returncode == 0, res.stderr[-3000:]
    files = sorted(p.relative_to(site).as_posix() for p in site.rglob("*") if p.is_file())
    assert "sweep/schema/config.schema.yaml" in files, files
    assert "sweep/validation.py" in files and "sweep/core/integrate.py" in files
    probe = ("import json, sys; sys.path.insert(0, sys.argv[1]); import sweep.validation as g; "
             "print(json.dumps({'file': g.__file__, 'path': str(g.SCHEMA_PATH), "
             "'exists': g.SCHEMA_PATH.is_file(), 'schema': g.load_schema()}))")
    res = subprocess.run([sys.executable, "-c", probe, str(site)], capture_output=True, text=True,
                         timeout=300, cwd=tmp_path)
    assert res.returncode == 0, res.stderr[-3000:]
    got = json.loads(res.stdout.strip().splitlines()[-1])
    assert Path(got["file"]).resolve().is_relative_to(site.resolve())   # the installed copy, not src/
    assert Path(got["path"]).resolve().is_relative_to(site.resolve()) and got["exists"]
    assert got["schema"] == json.loads(json.dumps(SCHEMA))


def test_workflow_validates_against_the_packaged_schema():
    """No second copy of the schema: the workflow validates with sweep.grid.load_sweep (the
    packaged schema), the code the front door runs before Snakemake starts."""
    assert not (ROOT / "workflow" / "schemas").exists()
    smk = (ROOT / "workflow" / "rules" / "common.smk").read_text()
    assert "sweep_grid.load_sweep(" in smk
    assert "grid.load_sweep(" in (ROOT / "src" / "sweep" / "frontdoor.py").read_text()
    assert validation.SCHEMA_PATH.is_file() and validation.SCHEMA_PATH.parent.parent == Path(grid.__file__).parent


def test_the_config_table_in_docs_states_the_ranges_that_are_enforced():
    """docs/pipeline.md's table of config keys gives, for every key with a range, the range of the
    one table the validation reads (sweep.fields.RANGES), in the words the messages use."""
    from sweep import fields

    text = (ROOT / "docs" / "pipeline.md").read_text()
    rows: dict[str, str] = {}
    for m in re.finditer(r"^\| `([\w.]+)` \|(.*)$", text, flags=re.M):
        rows.setdefault(m.group(1), m.group(2))   # the config table comes first
    for key, field in fields.SWEEP_KEYS.items():
        assert key in rows, key
        allowed = rows[key].split("|")[2]
        assert fields.RANGES[field].text() in allowed, (key, allowed, fields.RANGES[field].text())
