"""The cluster path for real: the tiny sweep through a live one-node SLURM cluster.

A module-scoped fixture starts munge, slurmctld and slurmd on localhost as this user
(tests/cluster/slurm_cluster.py) and stops them afterwards. The runs use the README's cluster
command, `python3 run.py sweep --profile workflow/profiles/slurm`, plus the overlay
tests/cluster/profile (job status via squeue, small resources) and `--cores <node cpus>`.

Where the SLURM and munge binaries are missing the tests are skipped, saying how to enable them
(apt-get install munge slurmctld slurmd slurm-client, as .ci/run does); with CI=true they fail.
"""
from __future__ import annotations

import math
import os
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml

import sweep
from sweep import chunking, grid, validation
from conftest import copy_workflow

sys.path.insert(0, str(Path(__file__).resolve().parent / "cluster"))
import slurm_cluster  # noqa: E402

from test_faults import cube_content  # noqa: E402  (cube variables and attributes, wall_time left out)

pytestmark = pytest.mark.slow

ROOT = Path(__file__).resolve().parents[1]
SCHEMA = validation.load_schema()
PROFILE = ROOT / "workflow" / "profiles" / "slurm"
OVERLAY = ROOT / "tests" / "cluster" / "profile"
TIMEOUT_S = 600
IN_CI = os.environ.get("CI", "").strip().lower() in {"1", "true", "yes"}


@pytest.fixture(scope="module")
def cluster(tmp_path_factory):
    missing = slurm_cluster.missing_binaries()
    if missing:
        msg = (f"live SLURM tests need {', '.join(missing)}: install them with `apt-get install munge "
               "slurmctld slurmd slurm-client` (what .ci/run does) to run tests/test_slurm.py")
        if IN_CI:
            pytest.fail("CI=true but " + msg)
        pytest.skip(msg)
    c = slurm_cluster.Cluster(tmp_path_factory.mktemp("slurm"))
    try:
        c.start()
    except RuntimeError as exc:
        c.stop()
        pytest.fail(f"the one-node SLURM cluster did not start: {exc}")
    yield c
    c.stop()


@pytest.fixture(scope="module")
def src(tmp_path_factory) -> Path:
    """The `sweep` package as of now, its numba cache filled, for every run of this module."""
    dest = tmp_path_factory.mktemp("src")
    shutil.copytree(Path(sweep.__file__).parent, dest / "sweep", copy_function=shutil.copy2,
                    ignore=shutil.ignore_patterns("*.pyc"))
    subprocess.run([sys.executable, "-c", "import copy, sweep; from sweep.batch import warm_up; "
                    "from sweep.scene import DEFAULTS; warm_up(copy.deepcopy(DEFAULTS))"],
                   env=dict(os.environ, PYTHONPATH=str(dest)), check=True, timeout=TIMEOUT_S)
    return dest


def tiny() -> dict:
    cfg = yaml.safe_load((ROOT / "config" / "tiny.yaml").read_text())
    cfg["outputs"]["notebooks"] = []   # the figures are tested locally (test_pipeline.py)
    return cfg


def workdir(tmp_path: Path) -> Path:
    wd = copy_workflow(tmp_path / "wf")
    (wd / "config" / "tiny.yaml").write_text(yaml.safe_dump(tiny()))
    return wd


def cluster_sweep(wd: Path, cluster, src: Path) -> subprocess.Popen:
    """The README's cluster command for the test cluster, started in the background."""
    cmd = [sys.executable, str(ROOT / "run.py"), "sweep", "--profile", str(PROFILE), "--workflow-profile",
           str(OVERLAY), "--cores", str(cluster.cpus), "--snakefile", str(wd / "Snakefile"),
           "--directory", str(wd), "--configfile", str(wd / "config" / "tiny.yaml")]
    return subprocess.Popen(cmd, env=dict(cluster.env, PYTHONPATH=str(src)), stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True, start_new_session=True)


def finish(proc: subprocess.Popen, wd: Path) -> str:
    try:
        out, _ = proc.communicate(timeout=TIMEOUT_S)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, 9)
    log = (wd / "results" / "tiny" / "logs" / "sweep.log").read_text(errors="replace")
    assert proc.returncode == 0, out + "\n--- sweep.log\n" + log[-6000:]
    return log


def jobs_of(cluster, log: str) -> list[dict[str, str]]:
    """This run's SLURM jobs (all states) as squeue lists them: job name = the run's id."""
    run_ids = set(re.findall(r"SLURM run ID: (\S+)", log))
    assert run_ids, log[-3000:]
    out = cluster.run("squeue", "--states=all", "--noheader", "-o", "%i|%T|%j|%C|%k").stdout
    rows = [dict(zip(("id", "state", "name", "cpus", "comment"), line.split("|"))) for line in out.splitlines()]
    return [r for r in rows if r["name"] in run_ids]


@pytest.fixture(scope="module")
def local_cube(tmp_path_factory, src) -> Path:
    """The tiny sweep run locally (`snakemake -j2`), the reference for the cluster's cube."""
    wd = workdir(tmp_path_factory.mktemp("local"))
    p = subprocess.run([sys.executable, "-m", "snakemake", "-j2", "--snakefile", str(wd / "Snakefile"),
                        "--directory", str(wd), "--configfile", "config/tiny.yaml"], cwd=wd,
                       env=dict(os.environ, PYTHONPATH=str(src)), capture_output=True, text=True, timeout=TIMEOUT_S)
    assert p.returncode == 0, (p.stdout + p.stderr)[-6000:]
    return wd / "results" / "tiny" / "cube.nc"


def plan() -> dict:
    return chunking.plan_chunks(grid.normalize(tiny(), SCHEMA))


def test_tiny_sweep_through_slurm_equals_local_run(tmp_path, cluster, src, local_cube):
    wd = workdir(tmp_path)
    t0 = time.monotonic()
    log = finish(cluster_sweep(wd, cluster, src), wd)
    seconds = time.monotonic() - t0
    jobs = jobs_of(cluster, log)
    n_chunks = len(plan())
    per_group = int(dict(g.split("=") for g in yaml.safe_load((PROFILE / "config.yaml").read_text())
                         ["group-components"])["chunks"])
    groups = [j for j in jobs if j["comment"] == "rule_chunks_simulate_chunk"]
    # the chunk jobs were submitted as grouped SLURM jobs, each sized to fit the node
    assert len(groups) == math.ceil(n_chunks / per_group) and n_chunks > 1, jobs
    assert all(j["state"] == "COMPLETED" and int(j["cpus"]) <= cluster.cpus for j in groups), jobs
    assert [j["state"] for j in jobs if j["comment"] == "rule_gather"] == ["COMPLETED"], jobs
    assert not [j for j in jobs if j["comment"] == "rule_simulate_chunk"], jobs   # none ungrouped
    # every chunk of the plan ran inside the group job (its SLURM log names each chunk's rule run)
    group_log = (wd / ".snakemake" / "slurm_logs" / "group_chunks_simulate_chunk" / f"{groups[0]['id']}.log").read_text()
    assert set(re.findall(r"chunks/([0-9a-f]{16})\.nc", group_log)) >= set(plan()), group_log[-3000:]
    a, b = cube_content(local_cube), cube_content(wd / "results" / "tiny" / "cube.nc")
    assert a.keys() == b.keys() and [k for k in a if a[k] != b[k]] == []
    print(f"{slurm_cluster.slurm_version()}: {len(jobs)} SLURM jobs "
          f"({', '.join(j['id'] + ':' + j['comment'] + ':' + j['state'] + ':' + j['cpus'] + 'cpu' for j in jobs)}); "
          f"run {seconds:.0f} s")


def test_cancelled_slurm_job_is_retried_and_the_cube_is_the_same(tmp_path, cluster, src, local_cube):
    wd = workdir(tmp_path)
    proc = cluster_sweep(wd, cluster, src)
    log_path = wd / "results" / "tiny" / "logs" / "sweep.log"
    deadline = time.monotonic() + TIMEOUT_S
    victim = None
    while victim is None:
        assert proc.poll() is None, proc.stdout.read()
        assert time.monotonic() < deadline, "the group job never ran"
        log = log_path.read_text(errors="replace") if log_path.exists() else ""
        if "SLURM run ID" in log:
            running = [j for j in jobs_of(cluster, log)
                       if j["comment"] == "rule_chunks_simulate_chunk" and j["state"] == "RUNNING"]
            victim = running[0]["id"] if running else None
        time.sleep(0.2)
    cluster.run("scancel", victim)
    log = finish(proc, wd)
    jobs = jobs_of(cluster, log)
    groups = [(j["id"], j["state"]) for j in jobs if j["comment"] == "rule_chunks_simulate_chunk"]
    # the cancelled group job, then its resubmission (the profile's `retries: 1`), which completed
    assert (victim, "CANCELLED") in groups and groups[-1][1] == "COMPLETED" and len(groups) == 2, jobs
    a, b = cube_content(local_cube), cube_content(wd / "results" / "tiny" / "cube.nc")
    assert a.keys() == b.keys() and [k for k in a if a[k] != b[k]] == []
    print(f"scancel {victim}: SLURM jobs {groups}")
