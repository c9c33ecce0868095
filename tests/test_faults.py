"""Faults and determinism of the sweep pipeline (issue #5).

* A failing point never fails its chunk: one chunk holds scenes that lose contact, exhaust the
  step budget, hit t_max, and make the kernel raise or return NaN; the chunk completes, each
  point carries its outcome code and NaN only where it could not compute, and every other point
  equals the same scene run alone through `sweep.simulate`.
* `kill -9` of a running `snakemake -j2` sweep: no partial chunk file under a final name; the
  documented recovery (`snakemake --unlock`, then `snakemake -j2 --rerun-incomplete`) gives the
  cube of an uninterrupted run, also when a chunk file was truncated after the kill.
* Determinism: the cube is bit-identical (all variables but wall_time; global attributes but
  history and created) across repeated runs, -j1 vs -j2, and two chunk sizes.
* Bounded work: every scene ends within its step budget and time limit.

The Snakemake runs use a copy of the workflow in pytest's tmp dir (as tests/test_pipeline.py)
and a 24-scene grid with loose levels: ~15 s per run on 2 cores, mostly process start-up. They
import a snapshot of the `sweep` package (PYTHONPATH), taken once with its numba cache, so the
runs compared here all use the same physics core even if src/sweep/ is edited meanwhile (a core
change rightly gives every chunk a new id and may change results).
"""
from __future__ import annotations

import dataclasses
import importlib
import os
import re
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import xarray as xr
import yaml

import sweep
from sweep import axes, batch, chunkfiles, chunking, grid, outcomes, outputs, reasons, validation, verify
from conftest import copy_workflow

ROOT = Path(__file__).resolve().parents[1]
SCHEMA_PATH = validation.SCHEMA_PATH
SCHEMA = validation.load_schema(SCHEMA_PATH)
TIMEOUT_S = 600  # a hang, not slowness (a run here takes ~15 s)

# 2 x 1 x 1 x 1 x 3 x 4 = 24 scenes: halted, face-contact and contact-lost (omega0 = 1000 rad/s)
# outcomes, so the cube holds NaNs too. chunk_size 4 -> 4 chunks (5, 7, 5, 7 scenes), 6 -> 2.
FAULT_CONFIG = """
disk: {radius: 0.03755, thickness: 0.0128, mass: 0.4387, shape: solid}
gravity: 9.81
mu_s: 0.5
grid:
  mu_d: [0.2, 0.3]
  k1: [3.755e-6]
  k2: [3.004e-5]
  k3: [6.0e-4]
  alpha0: [0.6, 1.1, 1.4]
  omega0: [12.0, 16.0, 30.0, 1000.0]
levels: [0.3, 0.1, 0.03]
solver: {method: adaptive, rtol: 1.0e-8, atol: 1.0e-10}
stop: {t_max: 10.0, max_steps: 200000}
chunk_size: 4
outputs: {notebooks: []}
"""


def fault_config(**changes) -> dict:
    cfg = yaml.safe_load(FAULT_CONFIG)
    cfg.update(changes)
    return cfg


def settings_of(cfg: dict) -> dict:
    return grid.normalize(cfg, SCHEMA)


# ------------------------------------------------------------------------------- helpers



def smk_cmd(wd: Path, *args: str) -> list[str]:
    return [sys.executable, "-m", "snakemake", "--snakefile", str(wd / "Snakefile"), "--directory", str(wd), *args]


def smk_env(src: Path) -> dict:
    """The environment of `python3 run.py sweep` (the venv first on PATH), importing `sweep`
    from the snapshot `src`."""
    env = dict(os.environ)
    env["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{env.get('PATH', '')}"
    env["PYTHONPATH"] = str(src)
    return env


def smk(wd: Path, *args: str, check: bool = True) -> tuple[int, str]:
    src = Path((wd / ".sweep_src").read_text())
    p = subprocess.run(smk_cmd(wd, *args), cwd=wd, env=smk_env(src), capture_output=True, text=True, timeout=TIMEOUT_S)
    out = p.stdout + p.stderr
    if check and p.returncode != 0:
        raise AssertionError(f"snakemake {' '.join(args)} exited {p.returncode}:\n{out[-6000:]}")
    return p.returncode, out


def job_count(output: str, rule: str) -> int:
    m = re.search(rf"^{rule}\s+(\d+)\s*$", output, flags=re.M)
    return int(m.group(1)) if m else 0


def sweep_dir(tmp_path_factory, name: str, cfg: dict, src: Path) -> Path:
    wd = copy_workflow(tmp_path_factory.mktemp(name) / "wf")
    (wd / "config" / "fault.yaml").write_text(yaml.safe_dump(cfg))
    (wd / ".sweep_src").write_text(str(src))  # the package snapshot its runs import
    return wd


def plan_of(cfg: dict, src: Path) -> dict[str, chunking.Chunk]:
    """The chunk plan as the snapshot's Snakemake sees it (chunk ids include the fingerprint
    of the core's source files next to sweep/chunking.py)."""
    saved = chunking.__file__
    chunking.__file__ = str(src / "sweep" / "chunking.py")
    try:
        return chunking.plan_chunks(settings_of(cfg))
    finally:
        chunking.__file__ = saved


def run_sweep(wd: Path, *args: str) -> str:
    """The user's command for this grid: `snakemake -j2 --configfile ...` (= python3 run.py sweep ...)."""
    return smk(wd, *(args or ("-j2",)), "--configfile", "config/fault.yaml")[1]


# Global attributes that record when a cube was made, not what it holds; wall_time is a measurement.
VOLATILE_ATTRS = {"history", "created"}
VOLATILE_VARS = {"wall_time"}


def cube_content(path: Path) -> dict:
    """Everything stored in a netCDF file, raw (no masking or scaling, so fill values and NaN
    bit patterns count), except the volatile attributes and variables."""
    import netCDF4

    out = {}
    with netCDF4.Dataset(path) as nc:
        nc.set_auto_maskandscale(False)
        out["dims"] = {k: len(v) for k, v in nc.dimensions.items()}
        out["attrs"] = {k: nc.getncattr(k) for k in nc.ncattrs() if k not in VOLATILE_ATTRS}
        for name, var in nc.variables.items():
            if name in VOLATILE_VARS:
                continue
            a = np.asarray(var[...])
            out[f"var:{name}"] = (str(a.dtype), var.dimensions, a.shape, a.tobytes(),
                                  repr({k: var.getncattr(k) for k in var.ncattrs()}), repr(var.filters()))
    return out


def assert_same_cube(a: Path, b: Path) -> None:
    ca, cb = cube_content(a), cube_content(b)
    assert ca.keys() == cb.keys()
    diff = [k for k in ca if k != "attrs" and ca[k] != cb[k]]
    assert not diff, f"{a} and {b} differ in {diff}"
    attrs_a, attrs_b = ca["attrs"], cb["attrs"]
    assert attrs_a.keys() == attrs_b.keys()
    for k in attrs_a:
        np.testing.assert_array_equal(attrs_a[k], attrs_b[k], err_msg=f"global attribute {k}")


@pytest.fixture(scope="module", autouse=True)
def warm_numba_cache():
    # Fill the numba cache (cache=True) first, so the chunk jobs load the kernels (~1 s) rather
    # than each compile them (~40 s) on a fresh checkout (as tests/test_pipeline.py does).
    s = settings_of(fault_config())
    sweep.simulate(grid.scene(s, tuple(s["grid"][a][0] for a in axes.AXES)))


# ------------------------------------------------------------------------------- failing points

# (alpha0, omega0) of each injected scene, with what happens to it
LOST = (0.9, 1000.0)        # a natural point: the normal force vanishes at once (contact_lost)
STEPS = (1.1, 12.0)         # stop.max_steps = 20 for this scene only (step_limit)
TMAX = (1.1, 16.0)          # stop.t_max = 0.05 s for this scene only (t_max)
RAISES = (0.6, 12.0)        # the kernel raises FloatingPointError
NAN = (0.6, 16.0)           # the kernel gives up after 30 steps with a NaN state (numerical_error)
OK = [(0.9, 12.0), (1.4, 30.0), (0.6, 30.0)]


def _inner(scene: dict) -> tuple[float, float]:
    return scene["initial"]["alpha"], -scene["initial"]["omega"][2]


def injected_stop(scene: dict) -> dict:
    """The scene as the injected simulate runs it: per-scene step budget and time limit."""
    scene = dict(scene, stop=dict(scene["stop"]))
    if _inner(scene) == STEPS:
        scene["stop"]["max_steps"] = 20
    if _inner(scene) == TMAX:
        scene["stop"]["t_max"] = 0.05
    return scene


@pytest.fixture
def faulty_kernel(monkeypatch):
    """Patch the numba kernel's caller (sweep.simulate.run_kernel) for the RAISES and NAN scenes."""
    from sweep.core import layout

    sim = importlib.import_module("sweep.simulate")
    real = sim.run_kernel

    def kernel(sc, sample_tau=None, traj_cap=0):
        key = (sc.config["initial"]["alpha"], -sc.config["initial"]["omega"][2])
        if key == RAISES:
            raise FloatingPointError("injected kernel failure")
        if key != NAN:
            return real(sc, sample_tau, traj_cap)
        cfg = dict(sc.config, stop=dict(sc.config["stop"], max_steps=30))
        out = real(dataclasses.replace(sc, config=cfg), sample_tau, traj_cap)
        out.istats[layout.I_OUTCOME] = outcomes.NUMERICAL_ERROR   # what the kernel reports on a NaN state
        out.y_end[:] = np.nan
        out.fstats[layout.F_EEND] = np.nan
        return out

    monkeypatch.setattr(sim, "run_kernel", kernel)
    monkeypatch.setattr(batch, "_warmed_up", False)


def test_failing_points_never_fail_their_chunk(tmp_path, faulty_kernel, caplog):
    settings = settings_of(fault_config())
    outer = tuple(settings["grid"][a][0] for a in axes.OUTER_AXES)
    inners = [OK[0], LOST, STEPS, TMAX, RAISES, NAN, OK[1], OK[2]]
    points = [outer + inner for inner in inners]
    cid, spec = chunking.chunk_id_of(chunking.scene_settings(settings), points)
    chunk = chunking.Chunk(cid, tuple(points), spec)
    real_simulate = batch.simulate_function()
    caplog.set_level("INFO", logger="sweep.batch")

    stats = batch.run_chunk(chunk, tmp_path / f"{cid}.nc", simulate=lambda sc: real_simulate(injected_stop(sc)))

    assert stats["n"] == len(points)
    assert verify.verify_chunk(tmp_path / f"{cid}.nc", chunk) is None
    assert "injected kernel failure" in caplog.text  # the traceback is in the chunk's log
    want_outcome = {OK[0]: outcomes.HALTED, LOST: outcomes.CONTACT_LOST, STEPS: outcomes.STEP_LIMIT,
                    TMAX: outcomes.T_MAX, RAISES: outcomes.NUMERICAL_ERROR, NAN: outcomes.NUMERICAL_ERROR}
    with xr.open_dataset(tmp_path / f"{cid}.nc") as ds:
        ds = ds.load()
    for i, inner in enumerate(inners):
        row = ds.isel(point=i)
        assert (float(row.alpha0), float(row.omega0)) == inner
        if inner in want_outcome:
            assert int(row.outcome) == want_outcome[inner], (inner, outcomes.NAMES[int(row.outcome)])
        if inner == RAISES:  # nothing was computed: NaN everywhere, counts missing, flags say why
            for var in outputs.VARIABLES:
                if var.kind == "flag":
                    assert (row[var.name].values == reasons.NO_RESULT).all(), var.name
                elif var.name not in ("outcome", "halt_finite", "wall_time"):
                    assert np.isnan(row[var.name].values).all(), var.name
            assert not bool(row.halt_finite)
            continue
        # every other point: exactly what the same scene gives when run alone (the kernel patch
        # passes it through; NAN is compared with the same patch in place)
        alone = real_simulate(injected_stop(grid.scene(settings, points[i]))).summary
        for var in outputs.VARIABLES:
            if var.name == "wall_time":
                continue
            want = chunkfiles.value_of(var, alone)
            np.testing.assert_array_equal(np.asarray(row[var.name].values, dtype=float),
                                          np.asarray(want, dtype=float), err_msg=f"{var.name} at {inner}")
        # NaN only where the scene could not compute: what it always computes is finite ...
        always = ["t_end", "energy_initial", "slip_fraction", "n_steps", "n_rejected", "n_rhs",
                  "n_events", "n_transitions", "n_stick", "n_impacts"]
        if inner != NAN:
            always += ["energy_final", "dissipation_sliding", "dissipation_k1", "dissipation_k2",
                       "dissipation_k3", "dissipation_impact"]
        for name in always:
            assert np.isfinite(float(row[name])), (inner, name)
        # ... a level time exists exactly for the levels reached before the end ...
        reached = np.isfinite(row.t_level.values)
        assert (row.t_level.values[reached] <= float(row.t_end)).all()
        if int(row.outcome) != outcomes.HALTED:
            assert not reached.all(), inner
            assert np.isnan(float(row.t_halt)) and not bool(row.halt_finite), inner
        else:
            assert reached.all(), inner
    # ... and the injected NaN state shows only in the final energy and the dissipation split
    nan_row = ds.isel(point=inners.index(NAN))
    assert np.isnan(float(nan_row.energy_final)) and np.isnan(float(nan_row.dissipation_sliding))
    assert int(nan_row.n_steps) + int(nan_row.n_rejected) == 30
    # the budget and the time limit bound their scenes
    steps_row = ds.isel(point=inners.index(STEPS))
    assert int(steps_row.n_steps) + int(steps_row.n_rejected) == 20
    assert float(ds.isel(point=inners.index(TMAX)).t_end) == pytest.approx(0.05, rel=1e-9)


KILL_WHILE_WRITING = """
import os, signal, sys
from types import SimpleNamespace
from sweep import atomic, batch, outputs
chunk = batch.chunk_from_spec(sys.argv[1])
n_levels = len(chunk.spec["settings"]["levels"])
real_fsync = atomic._fsync_path
def fsync_then_die(path):
    if ".tmp-" in str(path):  # the temporary file is fully written: die before the rename
        os.kill(os.getpid(), signal.SIGKILL)
    return real_fsync(path)
atomic._fsync_path = fsync_then_die
batch.run_chunk(chunk, sys.argv[2], simulate=lambda sc: SimpleNamespace(summary=outputs.empty_summary(n_levels)))
"""


@pytest.mark.slow
def test_kill_9_while_writing_a_chunk_leaves_no_file_under_its_name(tmp_path, monkeypatch):
    # A deterministic SIGKILL inside the chunk write (after the netCDF data and its checksum, before
    # the fsync and the rename): only a temporary file remains, which no check or gather ever reads.
    settings = settings_of(fault_config())
    chunk = next(iter(chunking.plan_chunks(settings).values()))
    final = tmp_path / f"{chunk.id}.nc"
    p = subprocess.run([sys.executable, "-c", KILL_WHILE_WRITING, chunk.spec_json, str(final)],
                       capture_output=True, text=True, timeout=TIMEOUT_S)
    assert p.returncode == -signal.SIGKILL, p.stderr
    assert not final.exists()
    leftovers = [q.name for q in tmp_path.iterdir()]
    assert len(leftovers) == 1 and re.fullmatch(rf"\.{chunk.id}\.nc\.tmp-\d+-[0-9a-f]{{8}}", leftovers[0]), leftovers
    assert verify.check_existing_chunks(tmp_path, {chunk.id: chunk}) == {}  # nothing under a final name
    monkeypatch.setattr(batch, "_warmed_up", True)  # the fake core below needs no warm-up
    batch.run_chunk(chunk, final, simulate=lambda sc: type("R", (), {"summary": outputs.empty_summary(len(settings["levels"]))}))
    assert verify.verify_chunk(final, chunk) is None


# ------------------------------------------------------------------------------- bounded work

def test_every_scene_has_a_step_budget_and_a_time_limit():
    props = SCHEMA["properties"]["stop"]
    assert props["default"] == {}  # the section is always filled in
    for key, maximum in (("t_max", 1e5), ("max_steps", 10**9)):
        node = props["properties"][key]
        assert node["maximum"] == maximum and "default" in node, key
    cfg = fault_config()
    del cfg["stop"]
    s = settings_of(cfg)
    assert s["stop"] == {"t_max": 120.0, "max_steps": 5_000_000}
    sc = grid.scene(s, tuple(s["grid"][a][0] for a in axes.AXES))
    assert sc["stop"]["t_max"] == 120.0 and sc["stop"]["max_steps"] == 5_000_000


@pytest.mark.parametrize("solver", [{"method": "adaptive", "rtol": 1e-14, "atol": 1e-16},
                                    {"method": "fixed", "dt": 1e-9}])
def test_a_costly_scene_stops_at_its_budget(solver):
    # The tightest tolerances, or a fixed step of 1 ns, would take ~10^10 steps to halt: the
    # budget (steps + rejected steps) ends the scene, with outcome step_limit.
    cfg = fault_config(solver=solver, stop={"t_max": 1e5, "max_steps": 3000})
    s = settings_of(cfg)
    r = sweep.simulate(grid.scene(s, tuple(s["grid"][a][0] for a in axes.AXES))).summary
    assert r["outcome"] == "step_limit" and r["n_steps"] + r["n_rejected"] == 3000


# ------------------------------------------------------------------------------- end to end

@pytest.fixture(scope="module")
def src(tmp_path_factory) -> Path:
    """A snapshot of the `sweep` package with its numba cache, loaded once (or compiled once
    if the cache is stale) so that every chunk job only loads the kernels."""
    dest = tmp_path_factory.mktemp("src")
    shutil.copytree(Path(sweep.__file__).parent, dest / "sweep", copy_function=shutil.copy2,
                    ignore=shutil.ignore_patterns("*.pyc"))
    warm = ("import sweep, yaml; from sweep import axes, grid, validation; "
            f"s = grid.normalize(yaml.safe_load({FAULT_CONFIG!r}), validation.load_schema({str(SCHEMA_PATH)!r})); "
            "sweep.simulate(grid.scene(s, tuple(s['grid'][a][0] for a in axes.AXES)))")
    subprocess.run([sys.executable, "-c", warm], env=smk_env(dest), check=True, timeout=TIMEOUT_S)
    return dest


@pytest.fixture(scope="module")
def reference(tmp_path_factory, src) -> Path:
    """An uninterrupted `snakemake -j2` run of the fault grid; returns its cube."""
    wd = sweep_dir(tmp_path_factory, "reference", fault_config(), src)
    out = run_sweep(wd)
    assert job_count(out, "simulate_chunk") == len(plan_of(fault_config(), src))
    with xr.open_dataset(wd / "results" / "fault" / "cube.nc") as cube:  # the grid's mix of outcomes
        found = set(np.unique(cube.outcome.values).tolist())
        assert {outcomes.HALTED, outcomes.CONTACT_LOST} <= found, found
        assert np.isnan(cube.t_halt.values).any() and np.isfinite(cube.t_level.values).any()
    return wd / "results" / "fault" / "cube.nc"


@pytest.mark.slow
def test_repeated_run_is_bit_identical(tmp_path_factory, src, reference):
    wd = sweep_dir(tmp_path_factory, "repeat", fault_config(), src)
    run_sweep(wd)
    assert_same_cube(reference, wd / "results" / "fault" / "cube.nc")


@pytest.mark.slow
def test_one_job_at_a_time_is_bit_identical(tmp_path_factory, src, reference):
    wd = sweep_dir(tmp_path_factory, "serial", fault_config(), src)
    run_sweep(wd, "-j1")
    assert_same_cube(reference, wd / "results" / "fault" / "cube.nc")


@pytest.mark.slow
def test_other_chunk_size_is_bit_identical_but_for_the_config(tmp_path_factory, src, reference):
    cfg = fault_config(chunk_size=6)
    assert len(plan_of(cfg, src)) != len(plan_of(fault_config(), src))
    wd = sweep_dir(tmp_path_factory, "chunk6", cfg, src)
    run_sweep(wd)
    a, b = cube_content(reference), cube_content(wd / "results" / "fault" / "cube.nc")
    # the config (and so its hash) records the chunk size; every value is the same
    for k in ("config_json", "config_sha256"):
        assert a["attrs"].pop(k) != b["attrs"].pop(k)
    assert a.keys() == b.keys() and [k for k in a if a[k] != b[k]] == []


def _chunk_state(wd: Path) -> tuple[set[str], set[str]]:
    """(chunk ids Snakemake reported finished, chunk ids whose job is running: log, no file)."""
    out = (wd / "snakemake.out").read_text(errors="replace")
    finished_jobs = set(re.findall(r"Finished jobid: (\d+) \(Rule: simulate_chunk\)", out))
    # "rule simulate_chunk: ... output: results/fault/chunks/<id>.nc ... jobid: N"
    ids = dict(re.findall(r"output: results/fault/chunks/([0-9a-f]{16})\.nc.*?jobid: (\d+)", out, flags=re.S))
    finished = {cid for cid, job in ids.items() if job in finished_jobs}
    logs = {p.stem for p in (wd / "results" / "fault" / "logs" / "chunks").glob("*.log")}
    files = {p.stem for p in (wd / "results" / "fault" / "chunks").glob("*.nc")}
    return finished, logs - files


@pytest.mark.slow
def test_kill_9_mid_run_then_documented_recovery(tmp_path_factory, src, reference):
    plan = plan_of(fault_config(), src)
    wd = sweep_dir(tmp_path_factory, "killed", fault_config(), src)
    (wd / "results" / "fault" / "chunks").mkdir(parents=True)
    (wd / "results" / "fault" / "logs" / "chunks").mkdir(parents=True)
    with open(wd / "snakemake.out", "w") as log:
        proc = subprocess.Popen(smk_cmd(wd, "-j2", "--configfile", "config/fault.yaml"), cwd=wd, env=smk_env(src),
                                stdout=log, stderr=subprocess.STDOUT, start_new_session=True)
    try:
        deadline = time.monotonic() + TIMEOUT_S
        while time.monotonic() < deadline and proc.poll() is None:
            finished, running = _chunk_state(wd)
            if finished and running:  # at least one chunk done, and another one mid-run
                break
            time.sleep(0.02)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)  # kill -9 of the whole process group
        proc.wait()
    assert proc.returncode == -signal.SIGKILL, (wd / "snakemake.out").read_text()[-3000:]
    finished, running = _chunk_state(wd)
    assert finished and running
    for _ in range(100):  # every process of the group is gone (no job writes after this)
        try:
            os.killpg(proc.pid, 0)
        except ProcessLookupError:
            break
        time.sleep(0.05)
    else:
        pytest.fail("processes of the killed group survive")

    # Right after the kill: every chunk file under its final name is complete and intact.
    chunk_dir = wd / "results" / "fault" / "chunks"
    present = sorted(chunk_dir.glob("*.nc"))
    assert present and len(present) < len(plan)
    for p in present:
        assert verify.verify_chunk(p, plan[p.stem]) is None, p
    assert not (wd / "results" / "fault" / "cube.nc").exists()
    leftovers = [p.name for p in chunk_dir.iterdir() if p.is_file() and p.suffix != ".nc"
                 and p.name != verify.VERIFIED_CACHE]
    assert all(re.fullmatch(r"\.[0-9a-f]{16}\.nc\.tmp-\d+-[0-9a-f]{8}", n) for n in leftovers), leftovers

    # A chunk file that was complete before the kill is then damaged (a truncated copy).
    victim = chunk_dir / f"{sorted(finished)[0]}.nc"
    kept = {p.stem: p.stat().st_mtime_ns for p in present if p != victim}
    victim.write_bytes(victim.read_bytes()[:300])

    # A plain rerun refuses (Snakemake's lock, or incomplete outputs) and names the remedy.
    code, out = smk(wd, "-j2", "--configfile", "config/fault.yaml", check=False)
    assert code != 0 and ("--unlock" in out or "--rerun-incomplete" in out), out[-3000:]
    # The documented recovery (docs/pipeline.md, "Interrupted runs"):
    #   python3 run.py sweep --unlock; python3 run.py sweep --rerun-incomplete
    smk(wd, "-j2", "--unlock", "--configfile", "config/fault.yaml")
    code, out = smk(wd, "-j2", "--rerun-incomplete", "--configfile", "config/fault.yaml")
    assert not victim.exists() or verify.verify_chunk(victim, plan[victim.stem]) is None
    assert list((chunk_dir / "quarantine").glob(victim.name + ".*")), "truncated chunk not quarantined"
    assert_same_cube(reference, wd / "results" / "fault" / "cube.nc")
    for p in chunk_dir.glob("*.nc"):
        assert verify.verify_chunk(p, plan[p.stem]) is None, p
    # Chunks Snakemake had recorded as finished (and left intact) were reused, not recomputed;
    # the others (running, or written but not yet recorded: --rerun-incomplete) were computed.
    reused = finished - {victim.stem}
    for cid in reused:
        assert (chunk_dir / f"{cid}.nc").stat().st_mtime_ns == kept[cid], cid
    assert job_count(out, "simulate_chunk") == len(plan) - len(reused)
    print(f"kill -9 with {len(finished)} chunk(s) recorded finished, {len(running)} running, "
          f"{len(present)} file(s) present, temporary leftovers {leftovers}; recovery computed "
          f"{job_count(out, 'simulate_chunk')} of {len(plan)} chunks")
