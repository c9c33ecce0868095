"""Chunk files, their verification, the cube and the batch runner, on synthetic summaries.

No integration is run: summaries are generated from the point values by `fake_summary`, so
every value in a file can be traced back to its grid point.
"""
from __future__ import annotations

import hashlib
import json
import math
import os
import random
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import xarray as xr
import yaml

from sweep import (atomic, axes, batch, cf, chunkfiles, chunking, figures, gather, grid, notebooks, numerical_error, outcomes,
                   outputs, validation, verify)

ROOT = Path(__file__).resolve().parents[1]
SCHEMA = validation.load_schema()


def settings_for(**grid_axes) -> dict:
    cfg = yaml.safe_load((ROOT / "config" / "tiny.yaml").read_text())
    cfg["grid"].update({k: list(v) for k, v in grid_axes.items()})
    return grid.normalize(cfg, SCHEMA, check_scenes=False)


def fake_summary(point, levels) -> dict:
    """A summary whose every value is a distinct function of the point (SI units as in the contract)."""
    mu_d, k1, k2, k3, a0, w0 = point
    code = outcomes.HALTED if a0 < 1.0 else outcomes.T_MAX
    base = 1000 * mu_d + 1e4 * k3 + a0 + 0.01 * w0
    return {
        "outcome": outcomes.NAMES[code], "outcome_code": code, "t_end": base + 1, "t_halt": base + 2,
        "t_halt_error": 1e-3 * base, "halt_finite": code == outcomes.HALTED, "approach_exponent": 0.5 + mu_d,
        "ramp_exponent": math.nan if code else 1.0 + k3, "ramp_exponent_error": math.nan if code else 0.01 * a0,
        "levels": [{"inclination": lv, "t": base + j, "precession_hz": w0 / (j + 1), "ringing_hz": 0.8 * w0 / (j + 1),
                    "precession_hz_error": 1e-3 * w0, "precession_window": 0.0, "precession_cycles": 8.0,
                    "ringing_ratio": 0.8 + 0.01 * j,
                    "normal_force_hz": math.nan if j == 0 else 2 * w0 * j} for j, lv in enumerate(levels)],
        "slip_fraction": mu_d / 2, "n_transitions": int(w0), "n_stick": int(10 * a0), "n_impacts": 0,
        "energy_initial": w0 ** 2, "energy_final": 0.1 * w0,
        "dissipation": {"sliding": mu_d, "k1": k1, "k2": k2, "k3": k3, "impact": 0.0},
        "n_steps": int(base), "n_rejected": int(base) // 7, "n_rhs": 12 * int(base), "n_events": 3,
        "wall_time": 0.001 * base,
    }


def write_all(settings, d: Path, summarise=fake_summary) -> list[Path]:
    paths = []
    for cid, c in chunking.plan_chunks(settings).items():
        sums = [summarise(p, settings["levels"]) for p in c.points]
        paths.append(chunkfiles.write_chunk(c, sums, d / f"{cid}.nc"))
    return paths


@pytest.fixture
def tiny():
    return settings_for(mu_d=[0.1, 0.3], k3=[1e-4, 3e-4, 5e-4], alpha0=[0.6, 1.2], omega0=[10.0, 20.0, 30.0])


# ------------------------------------------------------------------------------- chunk files

def test_chunk_round_trip(tmp_path, tiny):
    chunk = next(iter(chunking.plan_chunks(tiny).values()))
    sums = [fake_summary(p, tiny["levels"]) for p in chunk.points]
    sums[0] = outputs.empty_summary(len(tiny["levels"]))  # a scene that raised
    path = chunkfiles.write_chunk(chunk, sums, tmp_path / f"{chunk.id}.nc")
    assert verify.verify_chunk(path, chunk) is None
    with xr.open_dataset(path) as ds:
        assert ds.sizes == {"point": len(chunk.points), "level": len(tiny["levels"])}
        for i, a in enumerate(axes.AXES):
            np.testing.assert_array_equal(ds[a].values, [p[i] for p in chunk.points])
        for var in outputs.VARIABLES:
            got = ds[var.name].values
            for j, s in enumerate(sums):
                want = chunkfiles.value_of(var, s)
                want = np.array(np.nan if want is None else want, dtype=float)
                np.testing.assert_array_equal(np.asarray(got[j], dtype=float), want, err_msg=var.name)
        assert ds.outcome.values[0] == outcomes.NUMERICAL_ERROR
        assert ds.attrs["sweep_chunk_id"] == chunk.id


def test_summary_levels_must_match_the_level_coordinate(tiny):
    chunk = next(iter(chunking.plan_chunks(tiny).values()))
    sums = [fake_summary(p, list(reversed(tiny["levels"]))) for p in chunk.points]
    with pytest.raises(ValueError, match="do not match"):
        chunkfiles.chunk_dataset(chunk, sums)


def test_every_variable_and_coordinate_has_cf_attributes(tmp_path, tiny):
    paths = write_all(tiny, tmp_path)
    gather.gather(paths, tiny, tmp_path / "cube.nc")
    for path in [paths[0], tmp_path / "cube.nc"]:
        with xr.open_dataset(path) as ds:
            assert ds.attrs["Conventions"] == "CF-1.10"
            for name in ds.variables:
                assert ds[name].attrs.get("units"), (path.name, name)
                assert ds[name].attrs.get("long_name"), (path.name, name)
            assert list(ds.outcome.attrs["flag_values"]) == outcomes.FLAG_VALUES
            assert ds.outcome.attrs["flag_meanings"] == outcomes.FLAG_MEANINGS


def _fail_midway(monkeypatch):
    def broken(path, *args, **kwargs):
        Path(path).write_bytes(b"\x89HDF\r\n partial")
        raise OSError("disk full")
    monkeypatch.setattr(chunkfiles, "_write_chunk_nc", broken)


def _raw(path):
    import netCDF4

    with netCDF4.Dataset(path, "r") as nc:
        nc.set_auto_maskandscale(False)
        dims = {k: len(v) for k, v in nc.dimensions.items()}
        gattrs = {k: nc.getncattr(k) for k in nc.ncattrs()}
        out = {}
        for name, v in nc.variables.items():
            attrs = {k: v.getncattr(k) for k in v.ncattrs()}
            out[name] = (v.dimensions, v.dtype, {k: np.asarray(a).tolist() for k, a in attrs.items()},
                         np.asarray(v[...]))
    return dims, gattrs, out


def test_chunk_file_is_what_xarray_writes(tmp_path, tiny):
    """write_chunk writes with netCDF4 alone (no xarray import in a chunk job): the file must
    hold what xarray's writer makes of chunk_dataset with the chunk fills."""
    chunk = next(iter(chunking.plan_chunks(tiny).values()))
    sums = [fake_summary(p, tiny["levels"]) for p in chunk.points]
    sums[0] = outputs.empty_summary(len(tiny["levels"]))
    new = chunkfiles.write_chunk(chunk, sums, tmp_path / "new.nc")
    ds = chunkfiles.chunk_dataset(chunk, sums)
    enc = {name: {"_FillValue": chunkfiles._fill_of(name, np.asarray(ds[name].values))} for name in ds.variables}
    ref = atomic.write_atomic(ds, tmp_path / "ref.nc", enc,
                              finish=lambda tmp: _rechecksum(tmp))
    d_new, g_new, v_new = _raw(new)
    d_ref, g_ref, v_ref = _raw(ref)
    assert d_new == d_ref
    assert g_new == g_ref          # the checksum included: the same stored values
    assert sorted(v_new) == sorted(v_ref)
    for name in v_ref:
        dims, dt, attrs, vals = v_new[name]
        assert (dims, dt) == v_ref[name][:2], name
        assert json.dumps(attrs, sort_keys=True, default=str) == json.dumps(v_ref[name][2], sort_keys=True,
                                                                             default=str), name
        np.testing.assert_array_equal(vals, v_ref[name][3], err_msg=name)
    with xr.open_dataset(new) as a, xr.open_dataset(ref) as b:
        xr.testing.assert_identical(a, b)
    assert verify.verify_chunk(new, chunk) is None


def test_atomic_write_leaves_no_partial_file(tmp_path, tiny, monkeypatch):
    chunk = next(iter(chunking.plan_chunks(tiny).values()))
    sums = [fake_summary(p, tiny["levels"]) for p in chunk.points]
    target = tmp_path / f"{chunk.id}.nc"
    chunkfiles.write_chunk(chunk, sums, target)
    before = target.read_bytes()
    _fail_midway(monkeypatch)
    with pytest.raises(OSError, match="disk full"):
        chunkfiles.write_chunk(chunk, sums, target)
    assert target.read_bytes() == before  # the old complete file is untouched
    assert sorted(os.listdir(tmp_path)) == [target.name]  # and no temporary file is left
    fresh = tmp_path / "fresh.nc"
    with pytest.raises(OSError):
        chunkfiles.write_chunk(chunk, sums, fresh)
    assert not fresh.exists()


# ------------------------------------------------------------------------------- damage

def _damage(path: Path, how: str) -> None:
    data = bytearray(path.read_bytes())
    if how == "truncate":
        path.write_bytes(data[: len(data) // 2])
    elif how == "empty":
        path.write_bytes(b"")
    elif how == "values":  # rewrite one stored value in place, as bit rot would
        import netCDF4
        with netCDF4.Dataset(path, "a") as nc:
            nc["t_halt"][0] = nc["t_halt"][0] + 1.0
    elif how == "no_checksum":
        import netCDF4
        with netCDF4.Dataset(path, "a") as nc:
            nc.delncattr("sweep_checksum")


@pytest.mark.parametrize("how, reason", [
    pytest.param("truncate", "unreadable", marks=pytest.mark.slow), pytest.param("empty", "empty", marks=pytest.mark.slow),
    ("values", "checksum mismatch"), pytest.param("no_checksum", "sweep_checksum", marks=pytest.mark.slow)])
def test_damaged_chunk_is_detected_and_quarantined(tmp_path, tiny, how, reason):
    plan = chunking.plan_chunks(tiny)
    paths = write_all(tiny, tmp_path)
    victim = paths[1]
    _damage(victim, how)
    assert reason in verify.verify_chunk(victim, plan[victim.stem])
    bad = verify.check_existing_chunks(tmp_path, plan, act=False)
    assert list(bad) == [victim.stem] and victim.exists()  # a dry run only reports
    bad = verify.check_existing_chunks(tmp_path, plan, act=True)
    assert list(bad) == [victim.stem] and not victim.exists()
    quarantined = list((tmp_path / "quarantine").glob(victim.name + ".*"))
    assert any(p.suffix != ".reason" for p in quarantined)


def test_chunk_of_another_plan_is_rejected(tmp_path, tiny):
    plan = chunking.plan_chunks(tiny)
    a, b = list(plan.values())[:2]
    path = chunkfiles.write_chunk(a, [fake_summary(p, tiny["levels"]) for p in a.points], tmp_path / f"{b.id}.nc")
    assert "chunk id" in verify.verify_chunk(path, b)


@pytest.mark.slow
def test_gather_refuses_a_damaged_chunk(tmp_path, tiny):
    paths = write_all(tiny, tmp_path)
    _damage(paths[0], "values")
    with pytest.raises(RuntimeError, match="damaged"):
        gather.gather(paths, tiny, tmp_path / "cube.nc")
    assert not (tmp_path / "cube.nc").exists() and not paths[0].exists()


# ------------------------------------------------------------------------------- cube

@pytest.mark.parametrize("shuffle", [False, pytest.param(True, marks=pytest.mark.slow)])
def test_cube_places_every_value_at_its_grid_point(tmp_path, tiny, shuffle):
    paths = write_all(tiny, tmp_path)
    if shuffle:  # the gather must not rely on the order of its inputs
        random.Random(1).shuffle(paths)
    out = gather.gather(paths, tiny, tmp_path / "cube.nc", repo_path=ROOT, history="test")
    with xr.open_dataset(out) as cube:
        assert tuple(cube.outcome.dims) == axes.AXES
        assert tuple(cube.t_level.dims) == axes.AXES + ("level",)
        for a in axes.AXES:
            np.testing.assert_array_equal(cube[a].values, tiny["grid"][a])
        np.testing.assert_array_equal(cube.level.values, tiny["levels"])
        for point in chunking.plan_chunks(tiny)[paths[0].stem].points + chunking.plan_chunks(tiny)[paths[-1].stem].points:
            s = fake_summary(point, tiny["levels"])
            at = cube.sel(dict(zip(axes.AXES, point)))
            for var in outputs.VARIABLES:
                want = chunkfiles.value_of(var, s)
                np.testing.assert_array_equal(np.asarray(at[var.name].values, dtype=float),
                                              np.asarray(want, dtype=float), err_msg=var.name)
        cfg = cube.attrs["config_json"]
        assert json.loads(cfg) == tiny
        assert cube.attrs["config_sha256"] == hashlib.sha256(cfg.encode()).hexdigest()
        assert json.loads(cube.attrs["solver"]) == tiny["solver"]
        for key in ("title", "history", "source", "sweep_version", "git_commit", "created"):
            assert cube.attrs[key]
        enc = cube.t_level.encoding
        assert enc["zlib"] and enc["chunksizes"] == cf.cube_chunksizes(
            tuple(len(tiny["grid"][a]) for a in axes.AXES) + (len(tiny["levels"]),))


@pytest.mark.slow
def test_gather_requires_every_grid_point(tmp_path, tiny):
    paths = write_all(tiny, tmp_path)
    with pytest.raises(RuntimeError, match="grid has"):
        gather.gather(paths[:-1], tiny, tmp_path / "cube.nc")


@pytest.mark.parametrize("shape", [(1,), (3, 1, 1, 5, 7, 2, 4), (200, 1, 1, 300, 20, 20, 4), (2 ** 16,)])
def test_cube_chunksizes(shape):
    c = cf.cube_chunksizes(shape)
    assert len(c) == len(shape)
    assert all(1 <= ci <= max(1, n) for ci, n in zip(c, shape))
    assert math.prod(c) <= max(cf.CUBE_CHUNK_ELEMENTS, 1)
    if math.prod(shape) <= cf.CUBE_CHUNK_ELEMENTS:
        assert c == shape  # small cubes are one chunk
    else:  # balanced: no dimension was halved while a longer one stayed whole
        assert max(c) <= 2 * min(ci for ci, n in zip(c, shape) if ci < n)


def test_git_commit_outside_a_repository(tmp_path):
    assert cf.git_commit(tmp_path) == "unknown"
    assert len(cf.git_commit(ROOT).split("-")[0]) == 40


# ------------------------------------------------------------------------------- batch

class FakeCore:
    """Stands in for sweep.simulate: raises for one point, records warm-up calls."""

    def __init__(self, bad_alpha0: float):
        self.bad_alpha0 = bad_alpha0
        self.calls = []

    def __call__(self, scene):
        self.calls.append(scene)
        if scene["initial"]["alpha"] == self.bad_alpha0:
            raise FloatingPointError("synthetic failure")
        point = (scene["contact"]["mu_d"], scene["contact"]["k1"], scene["contact"]["k2"],
                 scene["contact"]["k3"], scene["initial"]["alpha"], -scene["initial"]["omega"][2])

        class R:
            summary = fake_summary(point, scene["stop"]["levels"])
        return R()


def test_run_chunk_records_exceptions_and_completes(tmp_path, tiny, monkeypatch, caplog):
    monkeypatch.setattr(batch, "_warmed_up", False)
    chunk = max(chunking.plan_chunks(tiny).values(), key=lambda c: len({p[4] for p in c.points}))
    bad = chunk.points[0][4]
    core = FakeCore(bad)
    caplog.set_level("INFO", logger="sweep.batch")
    stats = batch.run_chunk(chunk, tmp_path / f"{chunk.id}.nc", simulate=core)
    assert stats["n"] == len(chunk.points)
    with xr.open_dataset(tmp_path / f"{chunk.id}.nc") as ds:
        is_bad = ds.alpha0.values == bad
        assert (ds.outcome.values[is_bad] == outcomes.NUMERICAL_ERROR).all()
        assert np.isnan(ds.t_halt.values[is_bad]).all() and np.isnan(ds.n_steps.values[is_bad]).all()
        assert (ds.outcome.values[~is_bad] != outcomes.NUMERICAL_ERROR).all()
    # one warm-up call (short step budget) and then one call per scene
    warm = [c for c in core.calls if c["stop"]["max_steps"] == batch.WARM_UP_STEPS]
    assert len(warm) == 1 and len(core.calls) == len(chunk.points) + 1
    assert "scenes/s" in caplog.text and "numerical_error" in caplog.text
    # a second chunk in the same process does not warm up again
    other = next(c for c in chunking.plan_chunks(tiny).values() if c.id != chunk.id)
    core.calls.clear()
    batch.run_chunk(other, tmp_path / f"{other.id}.nc", simulate=core)
    assert len(core.calls) == len(other.points)


def test_chunk_job_checks_its_id(tmp_path, tiny):
    chunk = next(iter(chunking.plan_chunks(tiny).values()))
    assert batch.chunk_from_spec(chunk.spec_json) == chunk
    with pytest.raises(ValueError, match="hashes to"):
        batch.run_chunk_job(chunk.spec_json, "0" * 16, tmp_path / "x.nc")


@pytest.mark.slow
def test_verification_cache_skips_unchanged_files_only(tmp_path, tiny, monkeypatch):
    plan = chunking.plan_chunks(tiny)
    paths = write_all(tiny, tmp_path)
    assert verify.check_existing_chunks(tmp_path, plan) == {}
    calls = []
    real = verify.verify_chunk
    monkeypatch.setattr(verify, "verify_chunk", lambda p, c=None: calls.append(Path(p).stem) or real(p, c))
    assert verify.check_existing_chunks(tmp_path, plan) == {}
    assert calls == []  # every file verified before and unchanged since
    _damage(paths[2], "truncate")  # changes size and mtime
    assert list(verify.check_existing_chunks(tmp_path, plan)) == [paths[2].stem]
    assert calls == [paths[2].stem]


# ------------------------------------------------------------------------------- error bars

def test_every_time_and_frequency_variable_gets_an_error_variable():
    marked = {v.name for v in outputs.VARIABLES if v.numerical_error}
    assert {"t_halt", "t_level", "precession_hz", "ringing_hz", "normal_force_hz",
            "n_transitions", "n_stick", "n_impacts", "slip_fraction"} <= marked
    assert {v.name for v in outputs.VARIABLES if v.whole_run} == {"n_transitions", "n_stick", "n_impacts", "slip_fraction"}
    names = {v.name: v for v in numerical_error.ERROR_VARIABLES}
    for v in outputs.VARIABLES:
        e = names.get(v.name + "_numerical_error")
        assert (e is not None) == v.numerical_error, v.name
        if e is not None:
            assert e.units == v.units and e.per_level == v.per_level and e.kind == "float"
            assert "absolute difference to a rerun at rtol/100" in e.long_name
    assert names["reference_outcome"].kind == "outcome"
    assert cf.variables(False) == outputs.VARIABLES
    assert cf.variables(True) == outputs.VARIABLES + numerical_error.ERROR_VARIABLES


def _perturbed(s: dict, dt: float) -> dict:
    """`s` with every marked time shifted by dt and every frequency scaled by (1 + dt)."""
    out = json.loads(json.dumps(s))   # deep copy (NaN survives json round trip in Python)
    out["t_halt"] += dt
    for lv in out["levels"]:
        lv["t"] += dt
        lv["precession_hz"] *= 1 + dt
        lv["normal_force_hz"] *= 1 + dt
    return out


def test_numerical_errors_are_absolute_differences_with_nan_and_inf_rules(tiny):
    point = (0.1, 3.755e-6, 3.004e-5, 3e-4, 0.6, 20.0)
    levels = tiny["levels"]
    main = fake_summary(point, levels)
    ref = _perturbed(main, 0.25)
    s = numerical_error.add_numerical_errors(json.loads(json.dumps(main)), ref)
    assert s["reference_outcome"] == ref["outcome_code"]
    assert s["t_halt_numerical_error"] == pytest.approx(0.25, abs=1e-12)
    for j, lv in enumerate(s["levels"]):
        assert lv["t_level_numerical_error"] == pytest.approx(0.25, abs=1e-12)
        assert lv["precession_hz_numerical_error"] == pytest.approx(0.25 * main["levels"][j]["precession_hz"])
        if j == 0:   # fake_summary has no normal-force frequency at the first level: no error bar
            assert math.isnan(lv["normal_force_hz_numerical_error"])
        else:
            assert lv["normal_force_hz_numerical_error"] == pytest.approx(0.25 * main["levels"][j]["normal_force_hz"])
    # the main result itself is untouched
    for k in ("t_halt", "outcome_code", "t_end"):
        assert s[k] == main[k]
    # whole-run totals: a count that the rerun changes (a near-tangent crossing decided the other
    # way) gets the difference; equal counts get 0
    assert s["n_stick_numerical_error"] == 0.0 and s["n_impacts_numerical_error"] == 0.0
    ref_c = json.loads(json.dumps(ref))
    ref_c["n_transitions"] += 2
    ref_c["slip_fraction"] += 0.01
    s = numerical_error.add_numerical_errors(json.loads(json.dumps(main)), ref_c)
    assert s["n_transitions_numerical_error"] == 2.0
    assert s["slip_fraction_numerical_error"] == pytest.approx(0.01, abs=1e-12)
    # ... but a rerun cut by a numerical failure has partial totals: no error bar (NaN), while a
    # level it reached before the cut keeps its own
    ref_c["outcome"], ref_c["outcome_code"] = "step_limit", outcomes.STEP_LIMIT
    s = numerical_error.add_numerical_errors(json.loads(json.dumps(main)), ref_c)
    for k in ("n_transitions", "n_stick", "n_impacts", "slip_fraction"):
        assert math.isnan(s[k + "_numerical_error"]), k
    assert s["levels"][0]["t_level_numerical_error"] == pytest.approx(0.25, abs=1e-12)
    # a rerun that ended physically without the last level: that level's value is an artefact (inf)
    ref2 = _perturbed(main, 0.25)
    ref2["levels"][-1]["t"] = math.nan
    ref2["outcome"], ref2["outcome_code"] = "t_max", outcomes.T_MAX
    s = numerical_error.add_numerical_errors(json.loads(json.dumps(main)), ref2)
    assert math.isinf(s["levels"][-1]["t_level_numerical_error"])
    assert s["levels"][0]["t_level_numerical_error"] == pytest.approx(0.25, abs=1e-12)
    # ... the same after a numerical failure of the rerun (step limit): unknown (NaN), not inf
    ref2["outcome"], ref2["outcome_code"] = "step_limit", outcomes.STEP_LIMIT
    s = numerical_error.add_numerical_errors(json.loads(json.dumps(main)), ref2)
    assert math.isnan(s["levels"][-1]["t_level_numerical_error"])
    assert s["reference_outcome"] == outcomes.STEP_LIMIT
    # a rerun that raised: NaN errors, flagged as numerical_error, main result kept
    s = numerical_error.add_numerical_errors(json.loads(json.dumps(main)), None)
    assert s["reference_outcome"] == outcomes.NUMERICAL_ERROR and s["t_halt"] == main["t_halt"]
    assert math.isnan(s["t_halt_numerical_error"])
    assert all(math.isnan(lv[k]) for lv in s["levels"] for k in lv if k.endswith("_numerical_error"))


class TolCore:
    """Stands in for sweep.simulate: results shift with the tolerance (t += 1e6 rtol); the
    tighter rerun of `bad_alpha0` raises."""

    def __init__(self, bad_alpha0: float):
        self.bad_alpha0 = bad_alpha0
        self.rtols = []

    @staticmethod
    def point(scene):
        return (scene["contact"]["mu_d"], scene["contact"]["k1"], scene["contact"]["k2"],
                scene["contact"]["k3"], scene["initial"]["alpha"], -scene["initial"]["omega"][2])

    def __call__(self, scene):
        rtol = scene["solver"]["rtol"]
        self.rtols.append(rtol)
        if scene["initial"]["alpha"] == self.bad_alpha0 and rtol < 1e-9:
            raise FloatingPointError("synthetic failure of the rerun")

        class R:
            summary = _perturbed(fake_summary(self.point(scene), scene["stop"]["levels"]), 1e6 * rtol)
        return R()


def test_error_estimate_chunk_and_cube(tmp_path, tiny, monkeypatch):
    monkeypatch.setattr(batch, "_warmed_up", True)
    cfg = yaml.safe_load((ROOT / "config" / "tiny.yaml").read_text())
    cfg["grid"].update(mu_d=[0.1], k3=[3e-4], alpha0=[0.6, 1.2], omega0=[10.0, 20.0])
    cfg["outputs"]["error_estimate"] = True
    settings = grid.normalize(cfg, SCHEMA, check_scenes=False)
    rtol = settings["solver"]["rtol"]
    plan = chunking.plan_chunks(settings)
    core = TolCore(bad_alpha0=1.2)
    paths = []
    for cid, chunk in plan.items():
        batch.run_chunk(chunk, tmp_path / f"{cid}.nc", simulate=core)
        paths.append(tmp_path / f"{cid}.nc")
        assert verify.verify_chunk(paths[-1], chunk) is None
    assert sorted(set(core.rtols)) == [rtol / 100, rtol]   # every scene once at each tolerance
    assert len(core.rtols) == 2 * sum(len(c.points) for c in plan.values())
    cube_path = gather.gather(paths, settings, tmp_path / "cube.nc")
    dt = 1e6 * (rtol - rtol / 100)
    with xr.open_dataset(cube_path) as cube:
        for v in numerical_error.ERROR_VARIABLES:
            assert cube[v.name].attrs["long_name"] == v.long_name and cube[v.name].attrs["units"]
        assert cube.t_level_numerical_error.attrs["units"] == "s"
        assert cube.precession_hz_numerical_error.attrs["units"] == "Hz"
        ref = json.loads(cube.attrs["error_estimate_solver"])
        assert ref["rtol"] == rtol / 100 and ref["atol"] == settings["solver"]["atol"] / 100
        good = cube.sel(alpha0=0.6)
        np.testing.assert_allclose(good.t_halt_numerical_error.values, dt, rtol=1e-9)
        np.testing.assert_allclose(good.t_level_numerical_error.values, dt, rtol=1e-9)
        assert (good.reference_outcome.values == good.outcome.values).all()
        bad = cube.sel(alpha0=1.2)   # the rerun raised: main result kept, errors NaN, flagged
        assert (bad.reference_outcome.values == outcomes.NUMERICAL_ERROR).all()
        assert (bad.outcome.values != outcomes.NUMERICAL_ERROR).all()
        assert np.isfinite(bad.t_halt.values).all() and np.isnan(bad.t_halt_numerical_error.values).all()
        assert np.isnan(bad.precession_hz_numerical_error.values).all()
    # without the option: no error variables, and the plan is the one of a config without the key
    cfg["outputs"]["error_estimate"] = False
    off = grid.normalize(cfg, SCHEMA, check_scenes=False)
    del cfg["outputs"]["error_estimate"]
    assert chunking.plan_chunks(off).keys() == chunking.plan_chunks(grid.normalize(cfg, SCHEMA, check_scenes=False)).keys()
    assert not set(chunking.plan_chunks(off)) & set(plan)
    other = write_all(off, tmp_path / "off")
    with xr.open_dataset(gather.gather(other, off, tmp_path / "off.nc")) as cube:
        assert not any(n.endswith("_numerical_error") for n in cube.variables)
        assert "reference_outcome" not in cube.variables and "error_estimate_solver" not in cube.attrs


def test_chunk_without_its_error_variables_is_damaged(tmp_path, tiny):
    cfg = yaml.safe_load((ROOT / "config" / "tiny.yaml").read_text())
    cfg["outputs"]["error_estimate"] = True
    settings = grid.normalize(cfg, SCHEMA, check_scenes=False)
    chunk = next(iter(chunking.plan_chunks(settings).values()))
    sums = [numerical_error.add_numerical_errors(fake_summary(p, settings["levels"]), fake_summary(p, settings["levels"]))
            for p in chunk.points]
    path = chunkfiles.write_chunk(chunk, sums, tmp_path / f"{chunk.id}.nc")
    assert verify.verify_chunk(path, chunk) is None
    with xr.open_dataset(path) as ds:
        assert (ds.t_halt_numerical_error.values == 0).all()
        stripped = ds.drop_vars(["t_level_numerical_error"]).load()
    atomic.write_atomic(stripped, path, finish=lambda tmp: _rechecksum(tmp))
    assert "missing variables ['t_level_numerical_error']" in verify.verify_chunk(path, chunk)


def _rechecksum(tmp: Path) -> None:
    import netCDF4

    digest = chunkfiles.file_checksum(tmp)
    with netCDF4.Dataset(tmp, "a") as nc:
        nc.setncattr("sweep_checksum", digest)


# ------------------------------------------------------------------------------- notebooks

@pytest.mark.slow
def test_notebooks_cope_with_length_one_axes_and_nans(tmp_path):
    """Every figure notebook runs on a cube whose axes have 1-2 values and where half the
    scenes failed (NaN everywhere) and one variable is NaN throughout."""
    settings = settings_for(mu_d=[0.2, 0.3], k3=[3e-4], alpha0=[0.9, 1.1], omega0=[14.0])

    def half_failed(point, levels):
        if point[0] == 0.3:
            return outputs.empty_summary(len(levels))
        s = fake_summary(point, levels)
        s["ramp_exponent"] = math.nan
        for lv in s["levels"]:
            lv["normal_force_hz"] = math.nan
        return s

    paths = write_all(settings, tmp_path / "chunks", half_failed)
    cube = gather.gather(paths, settings, tmp_path / "cube.nc")
    for nb in grid.NOTEBOOKS:
        fig = notebooks.run_notebook(ROOT / "workflow" / "notebooks" / f"{nb}.ipynb", cube,
                                     tmp_path / "figures" / f"{nb}.png", tmp_path / "executed" / f"{nb}.ipynb")
        assert fig.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"



def test_a_notebook_kernel_talks_over_unix_sockets_in_a_folder_of_its_own(tmp_path):
    """notebooks.run_notebook starts the kernel with the IPC transport: no TCP port is picked and bound
    later, so two figure jobs starting at once (snakemake -j2) cannot collide on one ("Address
    already in use": the kernel died and the sweep failed). The kernel reads its own connection
    file; the socket folder is gone afterwards, and its path fits a Unix socket's limit."""
    import nbformat

    seen = tmp_path / "connection.json"
    cell = ("import json, os, ipykernel\n"
            "info = json.load(open(ipykernel.get_connection_file()))\n"
            f"open({str(seen)!r}, 'w').write(json.dumps(info))\n"
            "open(os.environ['SWEEP_FIGURE'], 'wb').write(b'\\x89PNG')\n")
    nb = nbformat.v4.new_notebook(cells=[nbformat.v4.new_code_cell(cell)])
    path = tmp_path / "probe.ipynb"
    nbformat.write(nb, str(path))
    fig = notebooks.run_notebook(path, tmp_path / "cube.nc", tmp_path / "probe.png", tmp_path / "probe-run.ipynb")
    assert fig.read_bytes() == b"\x89PNG"
    info = json.loads(seen.read_text())
    folder = Path(info["ip"]).parent
    assert info["transport"] == "ipc", info
    assert folder.name.startswith("sweep-kernel-") and len(str(folder)) <= notebooks.UNIX_SOCKET_DIR_MAX, info
    assert not folder.exists()


def test_figure_helpers_name_the_sweep_fix_fraction_scales_and_keep_numbers_legible(tmp_path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    settings = settings_for(mu_d=[0.2, 0.3], k3=[3e-4], alpha0=[0.9, 1.1], omega0=[14.0])
    cube = gather.gather(write_all(settings, tmp_path / "chunks"), settings, tmp_path / "cube.nc", name="tiny")
    with xr.open_dataset(cube) as ds:
        assert ds.attrs["sweep_name"] == "tiny" and "'tiny'" in ds.attrs["title"]
        assert figures.figure_caption(ds, "") == "sweep 'tiny': 4 scenes (mu_d 2 × k1 1 × k2 1 × k3 1 × alpha0 2 × omega0 1)"
        frac = xr.DataArray([[0.96, 0.98], [1.0, 0.99]], dims=("alpha0", "mu_d"),
                            coords={"alpha0": [0.9, 1.1], "mu_d": [0.2, 0.3]})
        fig, ax = plt.subplots()
        mesh = figures.plot_map(ax, frac, "fraction halted", vmin=0.0, vmax=1.0)
        assert (mesh.norm.vmin, mesh.norm.vmax) == (0.0, 1.0)       # 0.96 is not drawn as the bottom
        assert ax.get_xlabel() == "dynamic friction coefficient μ_d" and ax.get_ylabel() == "initial tilt α0 (rad)"
        # near the top of viridis (yellow) the numbers are black, near the bottom white
        colours = {t.get_text(): t.get_color() for t in ax.texts}
        assert colours["0.96"] == colours["1"] == "k"
        plt.close(fig)
        fig, ax = plt.subplots()
        figures.plot_map(ax, frac * 0 + [[0.0, 0.05], [0.9, 1.0]], "x", vmin=0.0, vmax=1.0)
        assert {t.get_text(): t.get_color() for t in ax.texts}["0"] == "w"
        plt.close(fig)
    for nb in grid.NOTEBOOKS:   # every sweep figure has the caption on its top line
        assert "figures.figure_caption(ds" in (ROOT / "workflow" / "notebooks" / f"{nb}.ipynb").read_text()


def test_the_output_registry_generates_the_summary_its_template_the_cube_and_the_chunk_format():
    """sweep.outputs is the one home of the outputs: every entry is in the summary a scene gives
    and in the template of a scene without a result, under the same keys and layout; every entry
    with a cube name is a cube variable with its units and long name; and the chunk format follows
    the variables, so an output added, removed or changed renames every chunk."""
    import dataclasses

    import sweep
    from conftest import make_scene
    from sweep import outputs

    got = sweep.simulate(make_scene(stop__t_max=0.5, stop__levels=[0.3, 0.2])).summary
    empty = outputs.empty_summary(2)
    for o in outputs.OUTPUTS:
        if o.where == "levels":
            assert all(o.key in lv for lv in got["levels"]) and all(o.key in lv for lv in empty["levels"]), o.key
        elif o.where:
            assert o.key in got[o.where] and o.key in empty[o.where], o.key
        else:
            assert o.key in got and o.key in empty, o.key
    assert set(got) == set(empty) and set(got["levels"][0]) == set(empty["levels"][0])
    cube = {v.name: v for v in outputs.VARIABLES}
    for o in outputs.OUTPUTS:
        if o.cube_name is not None:
            v = cube[o.cube_name]
            assert (v.units, v.long_name, v.per_level) == (o.units, o.long_name, o.per_level), o.key
            want = got["levels"][0][o.key] if o.per_level else (got[o.where][o.key] if o.where else got[o.key])
            have = v.get(got["levels"][0] if o.per_level else got)
            assert have == want or (have != have and want != want), o.key
    extra = outputs.Var("energy_lost_fraction", "float", "1", "share of the initial energy dissipated",
                        lambda s: 1.0 - s["energy_final"] / s["energy_initial"])
    assert outputs.chunk_format(outputs.VARIABLES + (extra,)) != outputs.CHUNK_FORMAT
    renamed = tuple(dataclasses.replace(v, units="ms") if v.name == "t_end" else v for v in outputs.VARIABLES)
    assert outputs.chunk_format(renamed) != outputs.CHUNK_FORMAT
    assert outputs.chunk_format() == outputs.CHUNK_FORMAT


# ------------------------------------------------------------------------------- chunk checks, branch by branch

def _retag(path: Path, chunk) -> None:
    """Give a chunk file `chunk`'s id and spec attributes (its values, and so its checksum, stay)."""
    import netCDF4
    with netCDF4.Dataset(path, "a") as nc:
        nc.setncattr("sweep_chunk_id", chunk.id)
        nc.setncattr("sweep_chunk_spec", chunk.spec_json)


def _other_levels(settings: dict) -> dict:
    """The same grid with one more level: the same points in chunks of other ids and specs."""
    more = json.loads(json.dumps(settings))
    more["levels"] = sorted(set(more["levels"]) | {min(more["levels"]) / 10.0}, reverse=True)
    return more


def test_a_chunk_file_with_the_right_id_but_another_spec_is_rejected(tmp_path, tiny):
    chunk = next(iter(chunking.plan_chunks(tiny).values()))
    path = chunkfiles.write_chunk(chunk, [fake_summary(p, tiny["levels"]) for p in chunk.points], tmp_path / f"{chunk.id}.nc")
    import netCDF4
    with netCDF4.Dataset(path, "a") as nc:
        nc.setncattr("sweep_chunk_spec", chunk.spec_json.replace('"points"', '"points" ', 1))
    assert verify.verify_chunk(path, chunk) == "chunk spec differs from the expected one"
    # without the plan's spec text: the spec attribute must hash to the id
    assert verify.read_chunk_file(path, expect_id=chunk.id)[0] == "chunk spec differs from the expected one"
    _retag(path, chunk)
    assert verify.verify_chunk(path, chunk) is None and verify.read_chunk_file(path, expect_id=chunk.id)[0] is None


def test_a_chunk_file_with_too_few_points_is_rejected(tmp_path, tiny):
    chunk = max(chunking.plan_chunks(tiny).values(), key=lambda c: len(c.points))
    assert len(chunk.points) >= 2
    short = chunking.Chunk(chunk.id, chunk.points[:-1], chunk.spec_json)
    path = chunkfiles.write_chunk(short, [fake_summary(p, tiny["levels"]) for p in short.points], tmp_path / f"{chunk.id}.nc")
    want = f"{len(chunk.points) - 1} points, expected {len(chunk.points)}"
    assert verify.verify_chunk(path, chunk) == want
    assert verify.read_chunk_file(path, expect_id=chunk.id)[0] == want


def test_a_chunk_file_with_another_number_of_levels_is_rejected(tmp_path, tiny):
    chunk = next(iter(chunking.plan_chunks(tiny).values()))
    more = _other_levels(tiny)
    twin = next(c for c in chunking.plan_chunks(more).values() if c.points == chunk.points)
    path = chunkfiles.write_chunk(twin, [fake_summary(p, more["levels"]) for p in twin.points], tmp_path / f"{chunk.id}.nc")
    _retag(path, chunk)
    assert verify.verify_chunk(path, chunk) == "wrong number of levels"


def test_gather_refuses_a_point_off_the_grid_axes(tmp_path, tiny):
    paths = write_all(tiny, tmp_path)
    shifted = settings_for(mu_d=[0.1, 0.3], k3=[1e-4, 3e-4, 5e-4], alpha0=[0.6, 1.2], omega0=[10.0, 20.0, 31.0])
    stray = write_all(shifted, tmp_path / "stray")
    off = next(p for p in stray if any(pt[axes.AXES.index("omega0")] == 31.0
                                       for pt in chunking.plan_chunks(shifted)[p.stem].points))
    with pytest.raises(RuntimeError, match=r"a chunk holds omega0 = 31\.0, not on the grid axis"):
        gather.gather(paths + [off], tiny, tmp_path / "cube.nc")
    assert not (tmp_path / "cube.nc").exists()


def test_gather_refuses_a_point_held_twice(tmp_path, tiny):
    paths = write_all(tiny, tmp_path)
    n = math.prod(len(tiny["grid"][a]) for a in axes.AXES)
    dup = chunking.plan_chunks(tiny)[paths[0].stem]
    copy = tmp_path / "copy" / paths[0].name
    copy.parent.mkdir()
    copy.write_bytes(paths[0].read_bytes())
    with pytest.raises(RuntimeError, match=rf"chunks hold {n + len(dup.points)} points with {n} distinct grid "
                                           rf"positions; the grid has {n}"):
        gather.gather(paths + [copy], tiny, tmp_path / "cube.nc")
    assert not (tmp_path / "cube.nc").exists()


# ------------------------------------------------------------------------------- a new output

# a new per-scene output, as a maintainer would add it: one entry in sweep/outputs.py's OUTPUTS
TRIES_ENTRY = '''    Output("n_tries", "int", "1", "number of integration steps tried (accepted and rejected)",
           lambda s, j: int(s.istats[I_STEPS] + s.istats[I_REJECTED])),
'''

TRIES_CHECKS = r'''
import json, sys
import numpy as np
import xarray as xr
import yaml
import sweep
from sweep import chunkfiles, chunking, gather, grid, validation
cfg = yaml.safe_load(open(sys.argv[2]))
settings = grid.normalize(cfg, validation.load_schema(), check_scenes=False)
paper = yaml.safe_load(open(sys.argv[1]))
paper["stop"].update(t_max=0.3, levels=list(settings["levels"]))
s = sweep.simulate(paper).summary
paths = [chunkfiles.write_chunk(c, [s] * len(c.points), f"{cid}.nc") for cid, c in chunking.plan_chunks(settings).items()]
gather.gather(paths, settings, "cube.nc")
with xr.open_dataset(paths[0]) as ch, xr.open_dataset("cube.nc") as cube:
    v = cube["n_tries"]
    print(json.dumps({"summary": [s["n_tries"], s["n_steps"], s["n_rejected"]],
                      "chunk": sorted(set(ch["n_tries"].values.ravel().tolist())),
                      "cube": sorted(set(v.values.ravel().tolist())), "dims": list(v.dims),
                      "attrs": {k: v.attrs.get(k) for k in ("units", "long_name")},
                      "compressed": bool(v.encoding.get("zlib") or v.encoding.get("compression"))}))
'''


def test_a_new_output_is_one_registry_entry(tmp_path):
    """Add an output to a copy of the package as one OUTPUTS entry (nothing else edited): a scene's
    summary has it (the paper's, kernels run as Python), a chunk file and the gathered cube carry it
    over the grid's dimensions with its units and long name, compressed."""
    src = Path(outputs.__file__).resolve().parents[1]
    copy = tmp_path / "src"
    shutil.copytree(src / "sweep", copy / "sweep", ignore=shutil.ignore_patterns("__pycache__"))
    registry = copy / "sweep" / "outputs.py"
    text = registry.read_text()
    anchor = '    Output("n_steps", "int", "1",'
    assert text.count(anchor) == 1
    registry.write_text(text.replace(anchor, TRIES_ENTRY + anchor))
    env = {"PYTHONPATH": str(copy), "PATH": "/usr/bin:/bin", "HOME": str(tmp_path), "NUMBA_DISABLE_JIT": "1"}
    run = subprocess.run([sys.executable, "-c", TRIES_CHECKS, str(ROOT / "config" / "scenes" / "kessler2002.yaml"),
                          str(ROOT / "config" / "tiny.yaml")], capture_output=True, text=True, env=env, cwd=tmp_path,
                         timeout=600)
    assert run.returncode == 0, run.stderr
    out = json.loads(run.stdout.splitlines()[-1])
    n_tries, n_steps, n_rejected = out["summary"]
    assert n_tries == n_steps + n_rejected and n_steps > 0
    assert out["chunk"] == out["cube"] == [n_tries]
    assert out["dims"] == list(axes.AXES)
    assert out["attrs"] == {"units": "1", "long_name": "number of integration steps tried (accepted and rejected)"}
    assert out["compressed"]
