"""End to end: the tiny sweep through Snakemake in a temporary copy of the workflow.

Runs `snakemake` (this interpreter's) with --snakefile/--directory pointing at a copy of
Snakefile, workflow/ and config/ under pytest's tmp dir, so the real results/ is never touched,
and with a snapshot of the `sweep` package (SNAPSHOT, taken once per session) on PYTHONPATH, so
that edits of the live source during the tests neither change chunk ids mid-module nor make a
job recompile the numba kernels.
The tests of this module share that copy and run in file order (each builds on the last run).
"""
from __future__ import annotations

import json
import math
import os
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import xarray as xr
import yaml

import sweep
from sweep import axes, cf, chunkfiles, chunking, grid, numerical_error, outcomes, validation, verify
from sweep import outputs as sweep_outputs
from conftest import copy_workflow

pytestmark = pytest.mark.slow

ROOT = Path(__file__).resolve().parents[1]
SCHEMA = validation.load_schema()
# A Snakemake call here takes ~3 s to parse and, for a run, ~3 s per job on a busy 2-core
# machine; 10 min flags a hang (e.g. a notebook kernel that never starts), not slowness.
TIMEOUT_S = 600




SNAPSHOT: Path | None = None


@pytest.fixture(scope="module", autouse=True)
def snapshot(tmp_path_factory) -> Path:
    """The `sweep` package copied with its numba cache; every run of this module imports it."""
    global SNAPSHOT
    dest = tmp_path_factory.mktemp("src")
    shutil.copytree(Path(sweep.__file__).parent, dest / "sweep", copy_function=shutil.copy2,
                    ignore=shutil.ignore_patterns("*.pyc"))
    SNAPSHOT = dest
    yield dest
    SNAPSHOT = None


def plan_of(settings: dict) -> dict[str, chunking.Chunk]:
    """The chunk plan as the snapshot's Snakemake sees it (ids include its core fingerprint)."""
    saved = chunking.__file__
    chunking.__file__ = str(SNAPSHOT / "sweep" / "chunking.py")
    try:
        return chunking.plan_chunks(settings)
    finally:
        chunking.__file__ = saved


def simulate_in_snapshot(settings: dict, points) -> list[dict]:
    """`sweep.simulate(...).summary` of each point, computed by the snapshot (JSON: NaN -> None)."""
    script = ("import json, math, sys, sweep; from sweep import grid; s = json.loads(sys.argv[1]); "
              "clean = lambda x: {k: clean(v) for k, v in x.items()} if isinstance(x, dict) else "
              "[clean(v) for v in x] if isinstance(x, list) else (None if isinstance(x, float) and "
              "not math.isfinite(x) else x); "
              "print(json.dumps([clean(dict(sweep.simulate(grid.scene(s, tuple(p))).summary)) "
              "for p in json.loads(sys.argv[2])]))")
    out = subprocess.run([sys.executable, "-c", script, chunking.canonical_json(settings),
                          chunking.canonical_json([list(p) for p in points])],
                         env=dict(os.environ, PYTHONPATH=str(SNAPSHOT)), capture_output=True, text=True,
                         timeout=TIMEOUT_S)
    assert out.returncode == 0, out.stderr[-3000:]
    return json.loads(out.stdout)


def smk_code(wd: Path, *args: str) -> tuple[int, str]:
    """Run snakemake in `wd`; return its exit status and its merged stdout/stderr."""
    env = dict(os.environ, PYTHONPATH=str(SNAPSHOT))
    env["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{env.get('PATH', '')}"
    cmd = [sys.executable, "-m", "snakemake", "--snakefile", str(wd / "Snakefile"), "--directory", str(wd),
           *args]
    p = subprocess.run(cmd, cwd=wd, env=env, capture_output=True, text=True, timeout=TIMEOUT_S)
    return p.returncode, p.stdout + p.stderr


def smk(wd: Path, *args: str, check: bool = True) -> str:
    """Run snakemake in `wd`; return its merged stdout/stderr (raise on a non-zero exit if `check`)."""
    code, out = smk_code(wd, *args)
    if check and code != 0:
        raise AssertionError(f"snakemake {' '.join(args)} in {wd} exited {code}:\n{out[-6000:]}")
    return out


def job_count(output: str, rule: str) -> int:
    """Number of jobs of `rule` in Snakemake's 'Job stats' table (0 if absent)."""
    m = re.search(rf"^{rule}\s+(\d+)\s*$", output, flags=re.M)
    return int(m.group(1)) if m else 0


def write_config(wd: Path, name: str, cfg: dict) -> str:
    (wd / "config" / name).write_text(yaml.safe_dump(cfg))
    return f"config/{name}"


def tiny_config() -> dict:
    return yaml.safe_load((ROOT / "config" / "tiny.yaml").read_text())


def settings_of(cfg: dict) -> dict:
    return grid.normalize(cfg, SCHEMA)


@pytest.fixture(scope="module")
def wd(tmp_path_factory) -> Path:
    return copy_workflow(tmp_path_factory.mktemp("pipeline") / "wf")


@pytest.fixture(scope="module")
def first_run(wd):
    # Fill the numba cache (cache=True) first, as any earlier use of the package does, so the
    # jobs below load the kernels rather than each compile them (~40 s) on a fresh checkout.
    settings = settings_of(tiny_config())
    simulate_in_snapshot(settings, [tuple(settings["grid"][a][0] for a in axes.AXES)])
    t0 = time.perf_counter()
    out = smk(wd, "-j2", "--configfile", "config/tiny.yaml")
    return out, time.perf_counter() - t0


def chunk_mtimes(wd: Path) -> dict[str, int]:
    return {p.stem: p.stat().st_mtime_ns for p in (wd / "results" / "tiny" / "chunks").glob("*.nc")}


# ------------------------------------------------------------------------------- static checks

def test_lint_reports_only_the_software_environment(wd):
    out = smk(wd, "--lint", "--configfile", "config/tiny.yaml", check=False)
    lints = set(re.findall(r"^\s+\* (.+?):?$", out, flags=re.M))
    # The project's software environment is the pinned venv of run.py (requirements.lock), not
    # a per-rule conda env or container; that one lint is expected for each rule, nothing else.
    assert lints <= {"Specify a conda environment or container for each rule."}, out


def test_stored_notebooks_have_no_outputs():
    import nbformat

    for path in (ROOT / "workflow" / "notebooks").glob("*.ipynb"):
        nb = nbformat.read(path, as_version=4)
        for cell in nb.cells:
            if cell.cell_type == "code":
                assert not cell.outputs and cell.execution_count is None, path.name
    assert {p.stem for p in (ROOT / "workflow" / "notebooks").glob("*.ipynb")} == set(grid.NOTEBOOKS
                                                                                    + grid.ADAPTIVE_NOTEBOOKS)


@pytest.mark.parametrize("mutate, fragment", [
    (lambda c: c["grid"].__setitem__("mu_d", [0.2, 0.7]), "config/bad.yaml: grid.mu_d[1] = 0.7 is invalid"),
    (lambda c: c.__setitem__("levels", [0.3, 2.0]), "config/bad.yaml: levels[1] = 2.0 is invalid"),
    (lambda c: c["grid"].__setitem__("alpha0", [0.0]), "config/bad.yaml: grid.alpha0[0] = 0.0 is invalid"),
    (lambda c: c.__setitem__("extra", 1), "config/bad.yaml: extra = 1 is invalid: no such key"),
])
def test_invalid_config_fails_before_any_job(tmp_path, mutate, fragment):
    d = copy_workflow(tmp_path / "wf")
    cfg = tiny_config()
    mutate(cfg)
    code, out = smk_code(d, "-j1", "--configfile", write_config(d, "bad.yaml", cfg))
    assert code != 0, out                       # a failed run, not a message beside a success
    assert fragment in out and "allowed" in out, out
    assert not (d / "results").exists()


# ------------------------------------------------------------------------------- the tiny run

def test_tiny_run_produces_cube_figures_and_progress_logs(wd, first_run):
    out, seconds = first_run
    settings = settings_of(tiny_config())
    plan = plan_of(settings)
    assert job_count(out, "simulate_chunk") == len(plan)
    assert (wd / "results" / "tiny" / "cube.nc").exists()
    for nb in settings["outputs"]["notebooks"]:
        png = wd / "results" / "tiny" / "figures" / f"{nb}.png"
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    for cid in plan:
        log = (wd / "results" / "tiny" / "logs" / "chunks" / f"{cid}.log").read_text()
        assert re.search(r"done: \d+ scenes in [\d.]+ s \([\d.]+ scenes/s\)", log)
        # Each job loads the numba kernels from the cache once (the fixture filled it): ~1 s,
        # against ~40 s for a compilation measured on this 2-core machine; 15 s separates them
        # even on a loaded machine.
        warm = float(re.search(r"warm-up ([\d.]+) s", log).group(1))
        assert warm < 15, (cid, warm)
    print(f"tiny sweep: {len(plan)} chunk jobs, wall time {seconds:.1f} s")


def test_cube_contents(wd, first_run):
    settings = settings_of(tiny_config())
    with xr.open_dataset(wd / "results" / "tiny" / "cube.nc") as cube:
        assert tuple(cube.outcome.dims) == axes.AXES
        assert dict(cube.sizes) == {**{a: len(settings["grid"][a]) for a in axes.AXES},
                                    "level": len(settings["levels"])}
        for a in axes.AXES:
            np.testing.assert_array_equal(cube[a].values, sorted(tiny_config()["grid"][a]))
        np.testing.assert_array_equal(np.sort(cube.level.values), sorted(tiny_config()["levels"]))
        for name in cube.variables:
            assert cube[name].attrs.get("units") and cube[name].attrs.get("long_name"), name
        halted = cube.outcome.values == outcomes.HALTED
        assert halted.any()
        # a halted scene reached every level and has all its energies, counts and costs
        for name in ("t_level", "t_end", "energy_initial", "energy_final", "slip_fraction", "n_steps",
                     "n_rhs", "n_transitions", "dissipation_sliding", "dissipation_k3", "wall_time"):
            v = cube[name].values
            assert np.isfinite(v[halted]).all(), name
        # a finite halt time wherever the fit found one
        fin = cube.halt_finite.values
        assert np.isfinite(cube.t_halt.values[fin]).all()
        assert (cube.t_halt.values[fin] >= cube.t_end.values[fin]).all()
        assert cube.attrs["git_commit"] != ""
        assert cube.attrs["sweep_version"] == sweep.__version__


def test_cube_equals_scenes_run_one_by_one(wd, first_run):
    settings = settings_of(tiny_config())
    with xr.open_dataset(wd / "results" / "tiny" / "cube.nc") as cube:
        points = [p for chunk in plan_of(settings).values() for p in chunk.points]
        for point, s in zip(points, simulate_in_snapshot(settings, points)):
            at = cube.sel(dict(zip(axes.AXES, point)))
            for var in sweep_outputs.VARIABLES:
                if var.name == "wall_time":  # a measurement, not a result
                    continue
                want = chunkfiles.value_of(var, s)
                # same code, same machine, same inputs: the integration is deterministic
                np.testing.assert_array_equal(np.asarray(at[var.name].values, dtype=float),
                                              np.asarray(want, dtype=float), err_msg=f"{var.name} at {point}")


def test_rerun_does_nothing(wd, first_run):
    out = smk(wd, "-j2", "--configfile", "config/tiny.yaml", "--dry-run")
    assert "Nothing to be done" in out, out


def test_executed_notebooks_have_no_errors(wd, first_run):
    import nbformat

    for nb in grid.NOTEBOOKS:
        executed = nbformat.read(wd / "results" / "tiny" / "notebooks" / f"{nb}.ipynb", as_version=4)
        outputs = [o for c in executed.cells if c.cell_type == "code" for o in c.outputs]
        assert not [o for o in outputs if o.output_type == "error"], nb
        assert any("saved" in o.get("text", "") for o in outputs), nb


# ------------------------------------------------------------------------------- reruns

def _extend_and_run(wd, base: dict, name: str, axis: str, value: float) -> dict:
    """Add `value` to `axis` of config `base`, run, and check that exactly the chunks whose
    content changed were computed and every other chunk file was left alone."""
    old_plan = plan_of(settings_of(base))
    cfg = yaml.safe_load(yaml.safe_dump(base))
    cfg["grid"][axis] = cfg["grid"][axis] + [value]
    cfg["outputs"]["notebooks"] = []  # the figures were checked after the first run
    new_plan = plan_of(settings_of(cfg))
    new_ids = set(new_plan) - set(old_plan)
    # precondition, from the plan alone: some chunks are new and some are kept
    assert new_ids and len(new_ids) < len(new_plan)
    before = chunk_mtimes(wd)
    with xr.open_dataset(wd / "results" / "tiny" / "cube.nc") as c:
        old_cube = c.load()
    out = smk(wd, "-j2", "--configfile", write_config(wd, name, cfg))
    assert job_count(out, "simulate_chunk") == len(new_ids), out
    after = chunk_mtimes(wd)
    for cid in set(new_plan) & set(old_plan):
        assert after[cid] == before[cid], cid  # kept chunk files were not rewritten
    with xr.open_dataset(wd / "results" / "tiny" / "cube.nc") as cube:
        assert cube.sizes[axis] == len(cfg["grid"][axis])
        common = cube.sel({axis: old_cube[axis].values})
        for var in ("t_halt", "t_level", "n_steps", "outcome"):
            np.testing.assert_array_equal(common[var].values, old_cube[var].values)
    return cfg


def test_inserted_inner_value_reruns_only_changed_chunks(wd, first_run):
    # alpha0 1.0 goes between the existing 0.9 and 1.1
    _extend_and_run(wd, tiny_config(), "inner.yaml", "alpha0", 1.0)


def test_new_outer_value_reruns_only_new_chunks(wd, first_run):
    # mu_d 0.25 goes between the existing 0.2 and 0.3
    base = yaml.safe_load((wd / "config" / "inner.yaml").read_text())
    _extend_and_run(wd, base, "outer.yaml", "mu_d", 0.25)


def test_damaged_chunk_is_recomputed_not_gathered(wd, first_run):
    # the latest config of this module's scenario (first run -> inner -> outer insertion), or the
    # first run's alone when this test runs by itself (e.g. selected with -k, or on another worker)
    cfg = "config/outer.yaml" if (wd / "config" / "outer.yaml").exists() else "config/tiny.yaml"
    settings = settings_of(yaml.safe_load((wd / cfg).read_text()))
    plan = plan_of(settings)
    victim = wd / "results" / "tiny" / "chunks" / f"{next(iter(plan))}.nc"
    with xr.open_dataset(wd / "results" / "tiny" / "cube.nc") as c:
        before = c.load()
    victim.write_bytes(victim.read_bytes()[:200])  # a truncated copy
    out = smk(wd, "-j2", "--configfile", cfg, "--dry-run")
    assert f"chunk {victim.stem} is damaged" in out and victim.exists()  # dry run: report only
    (wd / "results" / "tiny" / "cube.nc").unlink()
    out = smk(wd, "results/tiny/cube.nc", "-j2", "--configfile", cfg)
    assert "moved to results/tiny/chunks/quarantine/" in out
    assert job_count(out, "simulate_chunk") == 1
    assert verify.verify_chunk(victim, plan[victim.stem]) is None
    assert list((wd / "results" / "tiny" / "chunks" / "quarantine").glob(victim.name + ".*"))
    with xr.open_dataset(wd / "results" / "tiny" / "cube.nc") as after:
        for var in cf.VARIABLE_NAMES:
            if var != "wall_time":
                np.testing.assert_array_equal(after[var].values, before[var].values, err_msg=var)


# ------------------------------------------------------------------------------- error bars

def test_error_estimate_puts_error_bars_in_the_cube(wd, first_run):
    """outputs.error_estimate through Snakemake: the cube's *_numerical_error are the differences
    between the scenes run one by one at the sweep's tolerances and at rtol/100."""
    cfg = tiny_config()
    cfg.update(name="errbars", outputs={"notebooks": [], "error_estimate": True})
    cfg["grid"].update(mu_d=[0.2], alpha0=[0.9, 1.1], omega0=[12.0])
    settings = settings_of(cfg)
    smk(wd, "-j2", "--configfile", write_config(wd, "errbars.yaml", cfg))
    points = [p for chunk in plan_of(settings).values() for p in chunk.points]
    main = simulate_in_snapshot(settings, points)
    ref_settings = numerical_error.error_reference(chunking.scene_settings(settings))
    assert ref_settings["solver"]["rtol"] == settings["solver"]["rtol"] / 100
    ref = simulate_in_snapshot(ref_settings, points)
    nonzero = 0
    with xr.open_dataset(wd / "results" / "errbars" / "cube.nc") as cube:
        assert json.loads(cube.attrs["error_estimate_solver"]) == ref_settings["solver"]
        for point, m, r in zip(points, main, ref):
            want = numerical_error.add_numerical_errors(m, r)
            at = cube.sel(dict(zip(axes.AXES, point)))
            assert int(at.reference_outcome) == r["outcome_code"] == m["outcome_code"] == outcomes.HALTED
            for var in numerical_error.ERROR_VARIABLES:
                w = chunkfiles.value_of(var, want)
                got = np.asarray(at[var.name].values, dtype=float)
                np.testing.assert_array_equal(got, np.asarray(w, dtype=float), err_msg=f"{var.name} at {point}")
                if var.name != "reference_outcome":
                    assert not np.isinf(got).any() and (got[np.isfinite(got)] >= 0).all()
                    nonzero += int((got[np.isfinite(got)] > 0).sum())
            assert np.isfinite(at.t_level_numerical_error.values).all()   # halted: every level
    assert nonzero > 0   # the rerun ran at another tolerance


# ------------------------------------------------------------------------------- cluster profile

def test_slurm_profile_dry_run_batches_chunk_jobs(tmp_path):
    d = copy_workflow(tmp_path / "wf")
    profile = yaml.safe_load((d / "workflow" / "profiles" / "slurm" / "config.yaml").read_text())
    assert profile["executor"] == "slurm"
    group = dict(g.split("=") for g in profile["groups"])["simulate_chunk"]
    per_group = int(dict(g.split("=") for g in profile["group-components"])[group])
    cfg = tiny_config()
    cfg["grid"]["omega0"] = [10.0, 12.0, 14.457, 17.0, 20.0, 25.0]
    cfg["chunk_size"] = 1  # one scene per chunk: many tiny jobs, the case grouping is for
    n_chunks = len(plan_of(settings_of(cfg)))
    assert n_chunks > per_group
    out = smk(d, "--profile", str(d / "workflow" / "profiles" / "slurm"),
              "--configfile", write_config(d, "many.yaml", cfg), "--dry-run")
    assert job_count(out, "simulate_chunk") == n_chunks
    assert out.count(f"Group job {group}") == math.ceil(n_chunks / per_group), out[-3000:]


# ------------------------------------------------------------------------- the adaptive map

def adaptive_config() -> dict:
    return yaml.safe_load((ROOT / "config" / "tiny_adaptive.yaml").read_text())


def cube_values(path: Path) -> dict[str, np.ndarray]:
    with xr.open_dataset(path) as c:
        return {k: c[k].values.copy() for k in c.data_vars}


@pytest.fixture(scope="module")
def adaptive_run(tmp_path_factory, first_run):
    d = copy_workflow(tmp_path_factory.mktemp("adaptive") / "wf")
    out = smk(d, "-j2", "--configfile", "config/tiny_adaptive.yaml")
    return d, out


def test_adaptive_map_rounds_cube_and_figure(adaptive_run):
    from sweep import adaptive

    d, out = adaptive_run
    settings = settings_of(adaptive_config())
    lat = adaptive.lattice(settings)
    assert job_count(out, "refine_round") == lat.rounds + 1 >= 3
    res = d / "results" / "tiny_adaptive"
    (map_id,) = adaptive.maps(settings)
    recs = [json.loads((res / "rounds" / map_id / f"round{k}.json").read_text()) for k in range(lat.rounds + 1)]
    assert [r["round"] for r in recs] == list(range(lat.rounds + 1))
    assert all(r["line"].startswith("sweep tiny_adaptive: map ") for r in recs)
    cube = cube_values(res / "cube.nc")
    n_comp = int(cube["computed"].sum())
    assert n_comp == recs[-1]["computed"] == sum(r["scenes"] for r in recs) <= adaptive.budget(settings)
    assert n_comp < lat.size and recs[1]["scenes"] > 0
    # every node: computed (round >= 0, bars 0) or reconstructed (round -1); every float output has its bar
    rnd, comp = cube["round"].ravel(), cube["computed"].ravel()
    np.testing.assert_array_equal(rnd >= 0, comp == 1)
    for name, v in cube.items():
        if name.endswith("_interpolation_error"):
            base = cube[name[:-len("_interpolation_error")]]
            np.testing.assert_array_equal(np.isnan(v), np.isnan(base), err_msg=name)
            comp_mask = np.broadcast_to((cube["computed"] == 1).reshape(cube["computed"].shape + (1,) * (v.ndim - 6)),
                                        v.shape)
            assert (v[comp_mask & np.isfinite(v)] == 0).all(), name
    with xr.open_dataset(res / "cube.nc") as c:
        assert c.t_halt_interpolation_error.attrs["units"] == "s" and "flag_meanings" in c.computed.attrs
        # the CI map is too small for a hold-out (sweep.refine.holdout_size); the flag says so
        assert "flag_meanings" in c.holdout.attrs and int(c.holdout.sum()) == recs[-1]["holdout"] == 0
        # a computed node holds what the scene gives when run on its own
        sub = c.where(c.computed == 1, drop=True).stack(p=axes.AXES).dropna("p", subset=["t_halt"])
        p = sub.p.values[len(sub.p) // 2]
        (summary,) = simulate_in_snapshot(settings, [tuple(p)])
        assert float(sub.t_halt.sel(p=p)) == pytest.approx(summary["t_halt"], rel=1e-12)
    assert (res / "figures" / "adaptive_map.png").read_bytes()[:4] == b"\x89PNG"
    assert "Nothing to be done" in smk(d, "-j2", "--configfile", "config/tiny_adaptive.yaml", "--dry-run")


def test_adaptive_map_killed_mid_round_resumes_to_the_same_cube(adaptive_run, tmp_path):
    import signal

    d0, _ = adaptive_run
    d = copy_workflow(tmp_path / "wf")
    env = dict(os.environ, PYTHONPATH=str(SNAPSHOT))
    env["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{env.get('PATH', '')}"
    cmd = [sys.executable, "-m", "snakemake", "--snakefile", str(d / "Snakefile"), "--directory", str(d),
           "-j2", "--configfile", "config/tiny_adaptive.yaml"]
    proc = subprocess.Popen(cmd, cwd=d, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            start_new_session=True)
    res = d / "results" / "tiny_adaptive"
    deadline = time.monotonic() + TIMEOUT_S
    # kill -9 (Snakemake and its jobs) once round 1 has written a chunk file but not its round file
    while time.monotonic() < deadline and proc.poll() is None:
        r0 = list(res.glob("rounds/*/round0.json"))
        if r0 and len(list((res / "chunks").glob("*.nc"))) > len(json.loads(r0[0].read_text())["chunks"]):
            break
        time.sleep(0.05)
    assert proc.poll() is None, "the run ended before it could be killed mid-round"
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    assert not list(res.glob("rounds/*/round1.json")) and not (res / "cube.nc").exists()
    kept = {p.name for p in (res / "chunks").glob("*.nc")}
    smk(d, "--unlock", "--configfile", "config/tiny_adaptive.yaml")
    out = smk(d, "-j2", "--rerun-incomplete", "--configfile", "config/tiny_adaptive.yaml")
    assert "refine_round" in out
    # the same nodes and values as the uninterrupted run; the chunks finished before the kill were kept
    a, b = cube_values(d0 / "results" / "tiny_adaptive" / "cube.nc"), cube_values(res / "cube.nc")
    assert a.keys() == b.keys()
    for k in a:
        if k != "wall_time" and not k.startswith("wall_time"):
            np.testing.assert_array_equal(a[k], b[k], err_msg=k)
    assert kept <= {p.name for p in (res / "chunks").glob("*.nc")}
    for p in (res / "chunks").glob("*.nc"):
        if p.name in kept:
            assert (d0 / "results" / "tiny_adaptive" / "chunks" / p.name).exists()


def test_adaptive_map_slurm_dry_run(tmp_path):
    from sweep import adaptive

    d = copy_workflow(tmp_path / "wf")
    out = smk(d, "--profile", str(d / "workflow" / "profiles" / "slurm"),
              "--configfile", "config/tiny_adaptive.yaml", "--dry-run")
    assert job_count(out, "refine_round") == adaptive.lattice(settings_of(adaptive_config())).rounds + 1
    assert job_count(out, "gather") == 1


def test_adaptive_map_recomputes_a_lost_chunk_of_a_finished_round(adaptive_run, tmp_path):
    from sweep import adaptive

    d0, _ = adaptive_run
    d = copy_workflow(tmp_path / "wf")
    shutil.copytree(d0 / "results" / "tiny_adaptive", d / "results" / "tiny_adaptive")
    res = d / "results" / "tiny_adaptive"
    settings = settings_of(adaptive_config())
    (map_id,) = adaptive.maps(settings)
    rounds = sorted((res / "rounds" / map_id).glob("round*.json"))
    before = {p.name: p.read_text() for p in rounds}
    lost = res / "chunks" / f"{json.loads(rounds[0].read_text())['chunks'][0]}.nc"
    lost.unlink()
    # the gather alone (the cube still there: the front door sees the lost file and remakes it)
    out = smk(d, "-j2", "--configfile", "config/tiny_adaptive.yaml")
    assert "of a finished round is missing" in out and "refine_round" not in out
    assert lost.exists()
    assert {p.name: p.read_text() for p in rounds} == before      # no round ran again
    log = (res / "logs" / "gather.log").read_text()
    assert "1 chunk file(s) to compute again" in log
    a, b = cube_values(d0 / "results" / "tiny_adaptive" / "cube.nc"), cube_values(res / "cube.nc")
    for k in a:
        if not k.startswith("wall_time"):
            np.testing.assert_array_equal(a[k], b[k], err_msg=k)
    assert "Nothing to be done" in smk(d, "-j2", "--configfile", "config/tiny_adaptive.yaml", "--dry-run")


def test_last_round_line_reports_the_finished_maps_rough_cells():
    from sweep import adaptive

    rec = {"round": 3, "rounds": 3, "scenes": 10, "computed": 100, "lattice": 400, "share": 0.25,
           "max_share": 0.25, "next": None, "rough_final": 7}
    assert adaptive.round_line("x", "mu_d 0.3", rec).endswith("no round left; rough 7 cells")
    rec["next"] = {"outcome": 1, "failed": 0, "error": 2, "rough": 4}
    assert adaptive.round_line("x", "mu_d 0.3", rec).endswith("rough 4 cells")
    rec["holdout"] = 3
    assert ": 10 scenes, 3 of them the hold-out (100 of 400" in adaptive.round_line("x", "mu_d 0.3", rec)
