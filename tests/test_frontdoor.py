"""The front door as a user meets it: `python3 run.py sweep` (sweep.frontdoor).

Results per config (results/<name>/), one progress line, Ctrl-C/SIGTERM ending the run with one
line naming what was kept and the resume command, first-run messages, YAML numbers like 1e-10,
one message per invalid value, and `-j2` never overriding a profile's `jobs`.
"""
from __future__ import annotations

import importlib.util
import json
import os
import re
import shlex
import shutil
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
import xarray as xr
import yaml

import sweep
from sweep import axes, chunking, configfiles, frontdoor, grid, progress, runlock, snakemake_args, validation, warmup
from sweep.scene import load_scene
from conftest import copy_workflow

ROOT = Path(__file__).resolve().parents[1]
SCHEMA = validation.load_schema()
TIMEOUT_S = 600


def load_run_py():
    spec = importlib.util.spec_from_file_location("run_py", ROOT / "run.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


# ------------------------------------------------------------------------------- arguments

def test_sweep_keeps_the_profiles_job_limit():
    slurm = str(ROOT / "workflow" / "profiles" / "slurm")
    profile_jobs = yaml.safe_load((Path(slurm) / "config.yaml").read_text())["jobs"]
    argv = snakemake_args.snakemake_argv(["--profile", slurm], progress=True)
    assert "-j" not in argv and "-j2" not in argv
    # Snakemake's own parse of the command `run.py sweep --profile ...` runs
    assert snakemake_args.parsed_args(argv).jobs == profile_jobs == 100
    # without a profile: two local jobs; an explicit -j wins over both
    assert snakemake_args.parsed_args(snakemake_args.snakemake_argv([], progress=True)).jobs == 2
    assert snakemake_args.parsed_args(snakemake_args.snakemake_argv(["--profile", slurm, "-j", "7"], True)).jobs == 7
    assert snakemake_args.parsed_args(snakemake_args.snakemake_argv(["--cores", "3"], True)).cores == 3
    # a run resumes what an interrupted run left: --rerun-incomplete is always there
    assert "--rerun-incomplete" in snakemake_args.snakemake_argv([], progress=True)


def test_informational_options_show_snakemake_itself():
    assert snakemake_args.is_raw(["-n"]) and snakemake_args.is_raw(["--unlock", "--configfile", "x.yaml"])
    assert snakemake_args.is_raw(["--dry-run"]) and not snakemake_args.is_raw(["--configfile", "config/tiny.yaml"])


# ------------------------------------------------------------------------------- results per config

def test_results_folder_is_named_by_the_config(tmp_path):
    assert configfiles.sweep_name(ROOT / "config" / "config.yaml") == "default"
    assert configfiles.sweep_name(ROOT / "config" / "tiny.yaml") == "tiny"
    (tmp_path / "my_sweep.yaml").write_text("grid: {mu_d: [0.2]}\n")
    assert configfiles.sweep_name(tmp_path / "my_sweep.yaml") == "my_sweep"   # no name: the file's stem
    (tmp_path / "bad.yaml").write_text("name: ../elsewhere\n")
    with pytest.raises(validation.SweepConfigError, match=r"^bad.yaml: name = '\.\./elsewhere' is invalid: allowed "):
        configfiles.sweep_name(tmp_path / "bad.yaml", "bad.yaml")
    # the front door's run: Snakemake's working directory, the config files in Snakemake's order
    argv, given = snakemake_args.absolute_paths(["--configfile", "my_sweep.yaml", "--directory", "."], tmp_path)
    args = snakemake_args.parsed_args(argv)
    wd, files, overrides = snakemake_args.config_files(args, given, tmp_path)
    assert wd == tmp_path and overrides is None
    assert files == [(tmp_path / "config" / "config.yaml", "config/config.yaml"),
                     (tmp_path / "my_sweep.yaml", "my_sweep.yaml")]


EXPONENTS = """\
# written as people write numbers: YAML 1.1 reads 1e-8 as a string, the sweep reads a number
grid:
  mu_d: [0.2]
  k1: [3.755e-6]
  k2: [3e-5]
  k3: [6e-4]
  alpha0: [1.0]
  omega0: [14.457]
levels: [3e-1, 1e-1, 3e-2, 1e-2]
solver: {method: adaptive, rtol: 1e-8, atol: 1e-10}
stop: {t_max: 30.0, max_steps: 2e5}
chunk_size: 1
outputs: {notebooks: []}
"""


@pytest.mark.slow
def test_dry_run_of_a_config_without_name_plans_its_own_folder_and_reads_1e_minus_8(tmp_path):
    wd = copy_workflow(tmp_path / "wf")
    (wd / "config" / "exponents.yaml").write_text(EXPONENTS)
    p = subprocess.run([sys.executable, "-m", "snakemake", "-n", "-j1", "--snakefile", str(wd / "Snakefile"),
                        "--directory", str(wd), "--configfile", "config/exponents.yaml"],
                       cwd=wd, capture_output=True, text=True, timeout=TIMEOUT_S)
    out = p.stdout + p.stderr
    assert p.returncode == 0, out[-3000:]
    assert "results/exponents/chunks/" in out and "results/exponents/cube.nc" in out
    assert "results/default/" not in out and not re.search(r"results/(chunks|cube)", out)


def test_one_rule_for_numbers_in_configs_and_scene_files(tmp_path):
    """1e-8 is a number (YAML 1.2, though YAML 1.1, hence Snakemake's loader, reads a string);
    '1e-8' in quotes is text, rejected where a number is expected, in a sweep config as in a
    scene file, with the same message."""
    (tmp_path / "exponents.yaml").write_text(EXPONENTS)
    assert yaml.safe_load(EXPONENTS)["solver"]["rtol"] == "1e-8"    # YAML 1.1
    s = grid.load_sweep([(tmp_path / "exponents.yaml", "exponents.yaml")]).settings
    assert s["solver"]["rtol"] == 1e-8 and s["levels"] == [0.3, 0.1, 0.03, 0.01]
    assert s["grid"]["k2"] == [3e-5] and s["stop"]["max_steps"] == 200000
    scene = tmp_path / "scene.yaml"
    scene.write_text("solver: {rtol: 1e-8, atol: 1E-10}\nstop: {levels: [1e-1, 1e-2], max_steps: 2e5}\n")
    sc = load_scene(scene).config
    assert sc["solver"]["rtol"] == 1e-8 and sc["solver"]["atol"] == 1e-10
    assert sc["stop"]["levels"] == [0.1, 0.01] and sc["stop"]["max_steps"] == 200000
    # quoted: the same complaint from both
    (tmp_path / "quoted.yaml").write_text(EXPONENTS.replace("rtol: 1e-8", "rtol: '1e-8'"))
    with pytest.raises(validation.SweepConfigError) as err:
        grid.load_sweep([(tmp_path / "quoted.yaml", "quoted.yaml")])
    (line,) = str(err.value).splitlines()
    scene.write_text("solver: {rtol: '1e-8'}\n")
    with pytest.raises(sweep.ConfigError) as err2:
        load_scene(scene)
    hint = "solver.rtol = '1e-8' is invalid: a number in quotes is text: remove the quotes; allowed"
    assert line.startswith(f"quoted.yaml: {hint}") and str(err2.value).startswith(f"{scene}: {hint}")


@pytest.mark.parametrize("section, key, value", [("disk", "radius", -0.03), ("disk", "radius", "big"),
                                                  (None, "mu_s", -1.0)])
def test_one_invalid_value_gives_one_message(section, key, value):
    cfg = yaml.safe_load((ROOT / "config" / "tiny.yaml").read_text())
    (cfg[section] if section else cfg)[key] = value
    with pytest.raises(validation.SweepConfigError) as err:
        grid.normalize(cfg, SCHEMA)
    lines = str(err.value).splitlines()
    assert len(lines) == 1, str(err.value)
    assert lines[0].startswith(f"{section + '.' if section else ''}{key} = ") and "allowed" in lines[0]


# ------------------------------------------------------------------------------- first-run messages

def test_first_run_says_what_it_installs():
    run_py = load_run_py()
    lock = (ROOT / "requirements.lock").read_text()
    msg = run_py.install_message(lock, fresh=True)
    n = len(re.findall(r"^[A-Za-z0-9_.-]+==", lock, flags=re.M))
    assert f"the {n} pinned packages" in msg and "1-2 min" in msg
    for name in ("numpy", "numba", "snakemake", "xarray"):
        assert re.search(rf"{name} \d", msg), (name, msg)


def test_cold_numba_cache_is_detected_and_old_caches_pruned(tmp_path):
    cache = tmp_path / "__pycache__" / "numba-0123456789abcdef"
    cache.mkdir(parents=True)
    assert warmup.numba_cache_cold(cache)                            # never compiled
    (cache / "contact_rhs.eval_rhs-150.py311.nbi").write_bytes(b"")
    assert warmup.numba_cache_cold(cache)                            # the main loop is not there yet
    (cache / "integrate.run-400.py311.nbi").write_bytes(b"")
    assert not warmup.numba_cache_cold(cache)                        # cached
    old = tmp_path / "__pycache__" / "numba-fedcba9876543210"
    old.mkdir()
    (old / "integrate.run-390.py311.nbi").write_bytes(b"")
    other = tmp_path / "__pycache__" / "model.cpython-311.pyc"
    other.write_bytes(b"")
    assert warmup.prune_numba_caches(cache) == [old]
    assert cache.is_dir() and not old.exists() and other.exists()


def test_numba_cache_is_keyed_by_every_kernel_source(tmp_path):
    """numba invalidates a cached function only when its own file changes, and the cached code of a
    caller contains its callees from other files (integrate.run holds model.rhs): the kernels'
    cache folder and source stamp are the digest of all kernel sources, so an edit of any one of
    them (here: a copy of the package with model.py changed) selects a new, empty folder."""
    from sweep.core import jit

    pkg = tmp_path / "sweep"
    shutil.copytree(Path(sweep.__file__).parent, pkg, ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
    paths = [pkg / p.relative_to(jit.PACKAGE) for p in jit.KERNEL_SOURCES]
    assert jit.sources_digest(paths, pkg) == jit.DIGEST
    model = pkg / "core" / "model.py"
    model.write_text(model.read_text() + "\n# edited\n")
    assert jit.sources_digest(paths, pkg) != jit.DIGEST
    assert {p.name for p in jit.KERNEL_SOURCES} >= {"model.py", "contact_rhs.py", "event_rules.py", "event_dispatch.py", "integrate.py", "outcomes.py"}
    assert jit.DIGEST[:16] in jit.cache_dir().name
    # the kernels are located there, with the digest as their stamp
    from sweep.core import integrate
    locator = integrate.run._cache._impl.locator
    assert isinstance(locator, jit.CoreCacheLocator)
    assert locator.get_source_stamp() == jit.DIGEST and locator.get_cache_path() == str(jit.cache_dir())


# ------------------------------------------------------------------------------- a real run, interrupted

@pytest.fixture(scope="module")
def src(tmp_path_factory) -> Path:
    """A snapshot of the `sweep` package with its numba cache (as in test_faults), so that edits
    of the live source during the test do not change chunk ids mid-run."""
    dest = tmp_path_factory.mktemp("src")
    shutil.copytree(Path(sweep.__file__).parent, dest / "sweep", copy_function=shutil.copy2,
                    ignore=shutil.ignore_patterns("*.pyc"))
    return dest


class Run:
    """`python3 run.py sweep ARGS` started as a terminal starts it: in its own process group
    (the terminal's foreground group, which a Ctrl-C signals as a whole)."""

    def __init__(self, argv: list[str], src: Path):
        env = dict(os.environ, PYTHONPATH=str(src))
        self.proc = subprocess.Popen([sys.executable, str(ROOT / "run.py"), "sweep", *argv], env=env,
                                     stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                     stdin=subprocess.DEVNULL, start_new_session=True)
        self.chunks: list[bytes] = []
        self.eof = threading.Event()
        self.reader = threading.Thread(target=self._read, daemon=True)
        self.reader.start()

    def _read(self):
        for data in iter(lambda: self.proc.stdout.read1(65536), b""):
            self.chunks.append(data)
        self.eof.set()

    def finish(self, timeout: float = TIMEOUT_S) -> tuple[int, str]:
        """Exit status and console text; asserts that nothing can print after the exit: the
        console (the pipe) is closed by every process, and the process group is empty."""
        code = self.proc.wait(timeout=timeout)
        assert self.eof.wait(10), "a process still holds the console after run.py exited"
        with pytest.raises(ProcessLookupError):
            os.killpg(self.proc.pid, 0)
        return code, b"".join(self.chunks).decode(errors="replace")


def wait_for(condition, timeout: float = TIMEOUT_S, proc=None) -> None:
    deadline = time.monotonic() + timeout
    while not condition():
        assert proc is None or proc.poll() is None, "the run ended before the interruption"
        assert time.monotonic() < deadline, "timed out"
        time.sleep(0.05)


def assert_clean_console(out: str) -> None:
    assert "Traceback" not in out and "Error" not in out and "KeyboardInterrupt" not in out, out
    assert "outcome=" not in out, out               # per-scene lines stay in the chunk logs
    assert "localrule" not in out and "without encryption" not in out, out


def test_an_interrupted_run_releases_only_the_lock_it_wrote(tmp_path):
    """Snakemake's lock files (.snakemake/locks/<n>.<type>.lock) written since the run started
    are removed after an interruption, older ones (another run's) kept; with none left the
    folder goes too, as Snakemake's own unlock leaves it."""
    locks = tmp_path / ".snakemake" / "locks"
    locks.mkdir(parents=True)
    started = time.time()
    older = locks / "0.output.lock"
    older.write_text("results/other/cube.nc\n")
    os.utime(older, (started - 30.0, started - 30.0))
    ours = [locks / "1.input.lock", locks / "1.output.lock"]
    for lock in ours:
        lock.write_text("results/tiny/cube.nc\n")
    assert runlock.release_own_locks(tmp_path, started - 1.0) == ours
    assert sorted(locks.iterdir()) == [older]
    assert runlock.release_own_locks(tmp_path, started - 60.0) == [older]
    assert not locks.exists()
    assert runlock.release_own_locks(tmp_path, started) == []     # nothing there: nothing to do


@pytest.mark.slow
def test_ctrl_c_and_sigterm_then_resume(tmp_path, src):
    wd = copy_workflow(tmp_path / "wf")
    cfg = yaml.safe_load((ROOT / "config" / "tiny.yaml").read_text())
    cfg["chunk_size"] = 1            # 8 one-scene jobs: room to interrupt between them
    (wd / "config" / "tiny.yaml").write_text(yaml.safe_dump(cfg))
    argv = ["--snakefile", str(wd / "Snakefile"), "--directory", str(wd), "--configfile", str(wd / "config" / "tiny.yaml")]
    results = wd / "results" / "tiny"
    plan = chunking.plan_chunks(grid.normalize(cfg, SCHEMA))
    n_chunks = len(plan)
    present = lambda: sorted(p.stem for p in (results / "chunks").glob("*.nc"))  # noqa: E731
    # chunk files not marked incomplete (a job stopped after writing its file but before
    # Snakemake recorded it is computed again on resume)
    recorded = lambda: [c for c in present() if (results / "chunks" / f"{c}.nc").resolve()  # noqa: E731
                        not in progress.incomplete_outputs(wd)]

    # 1. Ctrl-C (SIGINT to the terminal's foreground group) once some, not all, chunks exist
    run = Run(argv, src)
    wait_for(lambda: len(present()) < n_chunks - 2 and recorded(), proc=run.proc)
    os.killpg(run.proc.pid, signal.SIGINT)
    code, out = run.finish()
    assert code == 130, out
    assert_clean_console(out)
    last = out.rstrip("\n").splitlines()[-1]
    m = re.fullmatch(r"sweep tiny: interrupted \(SIGINT\) after \d+:\d\d; kept (\d+) of (\d+) scenes "
                     r"\((\d+) of (\d+) chunk files\) in (\S+)/chunks/; resume with: (.+)", last)
    assert m, out
    kept = recorded()
    assert kept and int(m.group(1)) == len(kept) and int(m.group(3)) == len(kept) and int(m.group(4)) == n_chunks
    assert m.group(5) == str(results)
    resume = shlex.split(m.group(6))
    # run.py named as the user named it (here: its absolute path), then the same arguments
    assert resume[:3] == ["python3", str(ROOT / "run.py"), "sweep"] and resume[3:] == argv, \
        (results / "logs" / "sweep.log").read_text()[-6000:]
    assert not (wd / ".snakemake" / "locks").exists()
    mtimes = {c: (results / "chunks" / f"{c}.nc").stat().st_mtime_ns for c in kept}

    # 2. the resume command, stopped by SIGTERM (to run.py alone, as `kill` or a scheduler
    #    would) once the cube exists, i.e. during the figures
    run = Run(resume[3:], src)
    wait_for(lambda: (results / "cube.nc").exists(), proc=run.proc)
    os.kill(run.proc.pid, signal.SIGTERM)
    code, out = run.finish()
    assert code == 143, out
    assert_clean_console(out)
    last = out.rstrip("\n").splitlines()[-1]
    assert re.match(rf"sweep tiny: interrupted \(SIGTERM\) .*; kept 8 of 8 scenes \({n_chunks} of {n_chunks} "
                    rf"chunk files\) .*; resume with: python3 {ROOT / 'run.py'} sweep ", last), out

    # 3. the same command again finishes: figures made, nothing kept recomputed
    run = Run(resume[3:], src)
    code, out = run.finish()
    assert code == 0, out
    assert_clean_console(out)
    assert re.search(r"^sweep tiny: done in \d+:\d\d: 8 scenes \(0 computed now\)", out, flags=re.M), out
    for c, t in mtimes.items():
        assert (results / "chunks" / f"{c}.nc").stat().st_mtime_ns == t, c
    for nb in cfg["outputs"]["notebooks"]:
        assert (results / "figures" / f"{nb}.png").read_bytes()[:4] == b"\x89PNG"
    assert "sweep.log" in out and (results / "logs" / "sweep.log").stat().st_size > 0
    assert not (wd / "results" / "cube.nc").exists() and not (wd / "results" / "chunks").exists()
    # the resumed cube holds what the scenes give when run one by one (by the same snapshot)
    settings = grid.normalize(cfg, SCHEMA)
    points = [p for chunk in plan.values() for p in chunk.points]
    script = ("import json, sys, sweep; from sweep import grid; s = json.loads(sys.argv[1]); "
              "print(json.dumps([(r['t_end'], r['n_steps'], [lv['t'] for lv in r['levels']]) for r in "
              "(sweep.simulate(grid.scene(s, tuple(p))).summary for p in json.loads(sys.argv[2]))]))")
    one_by_one = subprocess.run([sys.executable, "-c", script, chunking.canonical_json(settings),
                                 chunking.canonical_json([list(p) for p in points])],
                                env=dict(os.environ, PYTHONPATH=str(src)), capture_output=True, text=True,
                                check=True, timeout=TIMEOUT_S).stdout
    with xr.open_dataset(results / "cube.nc") as cube:
        for point, (t_end, n_steps, t_levels) in zip(points, json.loads(one_by_one)):
            at = cube.sel(dict(zip(axes.AXES, point)))
            assert float(at.t_end) == t_end and int(at.n_steps) == n_steps, point
            np.testing.assert_array_equal(at.t_level.values, np.array(t_levels, dtype=float))

    # 4. and once more: nothing to do
    code, out = Run(resume[3:], src).finish()
    assert code == 0 and "nothing to do" in out, out


# ------------------------------------------------------------------------------- from another directory (issue #43)

def run_py(*args: str, cwd: Path, timeout: float = TIMEOUT_S) -> subprocess.CompletedProcess:
    """`python3 <project>/run.py ARGS` as a user starts it from `cwd`."""
    return subprocess.run([sys.executable, str(ROOT / "run.py"), *args], cwd=cwd, capture_output=True,
                          text=True, timeout=timeout, stdin=subprocess.DEVNULL)


def test_scene_paths_are_taken_from_the_users_directory(tmp_path):
    cfg = yaml.safe_load((ROOT / "config" / "scenes" / "kessler2002.yaml").read_text())
    cfg["stop"]["levels"] = [0.3]
    (tmp_path / "short.yaml").write_text(yaml.safe_dump(cfg))
    p = run_py("scene", "short.yaml", "--audio", "out.wav", "--json", cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    assert json.loads(p.stdout)["outcome"] == "halted"
    assert re.search(r"^wrote out\.wav \(", p.stderr, flags=re.M), p.stderr   # as given ...
    assert (tmp_path / "out.wav").read_bytes()[:4] == b"RIFF"                  # ... and where the user is
    assert not (ROOT / "out.wav").exists()
    p = run_py("scene", "nowhere/missing.yaml", cwd=tmp_path)
    assert p.returncode == 2 and p.stderr.startswith("error: nowhere/missing.yaml: no such file;"), p.stderr


@pytest.mark.slow
def test_a_dry_run_from_another_directory_finds_the_project_and_the_users_config(tmp_path):
    """Without --directory: the project's Snakefile and config/config.yaml, the user's file."""
    (tmp_path / "mytiny.yaml").write_text((ROOT / "config" / "tiny.yaml").read_text().replace("name: tiny", "name: mytiny"))
    p = run_py("sweep", "--configfile", "mytiny.yaml", "-n", cwd=tmp_path)
    out = p.stdout + p.stderr
    assert p.returncode == 0, out
    assert "results/mytiny/cube.nc" in out and "Traceback" not in out
    assert not (ROOT / "results" / "mytiny").exists()          # a dry run writes nothing


def test_a_missing_sweep_config_is_named_as_given(tmp_path):
    """(The fast tier's run of the tiny grid, below, reads its config relative to the user's
    directory too.)"""
    p = run_py("sweep", "--configfile", "missing.yaml", "-n", cwd=tmp_path)
    assert p.returncode == 2 and p.stdout == "", p.stdout
    assert p.stderr == ("error: missing.yaml: no such file; allowed a YAML mapping of sweep config keys "
                        "(grid, levels, solver, ...: docs/pipeline.md)\n")


BAD_CONFIGS = {
    # file text -> the lines the user sees (after "error: <file>: ")
    "typo.yaml": ("name: typo\nchunk_sise: 3\n", [
        "chunk_sise = 3 is invalid: no such key; allowed keys: chunk_size, disk, gravity, grid, "
        "levels, mu_s, name, outputs, refine, solver, stop"]),
    "quoted.yaml": ("name: quoted\nsolver: {rtol: '1e-10'}\nmu_s: 0.25\n", [
        "solver.rtol = '1e-10' is invalid: a number in quotes is text: remove the quotes; allowed [1e-14, 1e-2] "
        "(relative error tolerance of the adaptive method, dimensionless)",
        "grid.mu_d[2] = 0.3 is invalid: exceeds mu_s = 0.25; allowed [0, mu_s] = [0, 0.25] (with mu_d > mu_s the "
        "slip onset is inconsistent)",
        "grid.mu_d[3] = 0.4 is invalid: exceeds mu_s = 0.25; allowed [0, mu_s] = [0, 0.25] (with mu_d > mu_s the "
        "slip onset is inconsistent)",
        "grid.mu_d[4] = 0.5 is invalid: exceeds mu_s = 0.25; allowed [0, mu_s] = [0, 0.25] (with mu_d > mu_s the "
        "slip onset is inconsistent)"]),
    "empty.yaml": ("# nothing yet\n", [
        "the file is empty; allowed a YAML mapping of sweep config keys (grid, levels, solver, ...: docs/pipeline.md)"]),
    "list.yaml": ("- 1\n- 2\n", [
        "its top level is a list, not a mapping of keys; allowed a YAML mapping of sweep config keys "
        "(grid, levels, solver, ...: docs/pipeline.md)"]),
}


@pytest.mark.parametrize("name, extra", [(name, []) for name in sorted(BAD_CONFIGS)]
                         + [pytest.param("typo.yaml", ["-n"], marks=pytest.mark.slow)])
def test_invalid_config_gives_one_line_per_field_naming_the_file_and_creates_nothing(tmp_path, name, extra):
    """Before Snakemake starts: exit status 2, one line per invalid field on stderr naming the file
    as the user gave it (a key merged from config/config.yaml names that file), nothing created
    under results/ (nor Snakemake's .snakemake/), in a copy of the workflow; a dry run too."""
    wd = copy_workflow(tmp_path / "wf")
    text, lines = BAD_CONFIGS[name]
    (tmp_path / name).write_text(text)
    p = run_py("sweep", "--directory", "wf", "--configfile", name, *extra, cwd=tmp_path, timeout=120)
    assert p.returncode == 2, p.stdout + p.stderr
    assert p.stdout == ""
    # grid.mu_d comes from config/config.yaml, merged under the user's file
    want = [f"error: {'wf/config/config.yaml' if 'grid.mu_d' in line else name}: {line}" for line in lines]
    assert p.stderr.splitlines() == want
    assert not (wd / "results").exists() and not (wd / ".snakemake").exists()


def test_a_config_error_reads_alike_from_the_workflow(tmp_path):
    """Snakemake run directly (no front door) stops at parse time with the same lines, under
    one header, before any job."""
    wd = copy_workflow(tmp_path / "wf")
    (wd / "config" / "typo.yaml").write_text(BAD_CONFIGS["typo.yaml"][0])
    p = subprocess.run([sys.executable, "-m", "snakemake", "-n", "--configfile", "config/typo.yaml"], cwd=wd,
                       capture_output=True, text=True, timeout=TIMEOUT_S)
    out = p.stdout + p.stderr
    assert p.returncode != 0 and "invalid sweep configuration:" in out
    assert f"{wd / 'config' / 'typo.yaml'}: {BAD_CONFIGS['typo.yaml'][1][0]}" in out, out
    assert not (wd / "results").exists()


# ------------------------------------------------------------------------------- progress (issue #43)

SNAKEMAKE_LINES = """\
Building DAG of jobs...
Job stats:
job               count
--------------  -------
simulate_chunk        4
gather                1
notebook              4
all                   1
total                10

[Fri Nov 27 13:23:45 2026]
localrule simulate_chunk:
    output: results/tiny/chunks/48475ec4dcaccf60.nc
    jobid: 4
1 of 10 steps (10%) done
"""


def test_progress_names_its_phase_and_its_eta_covers_gather_and_figures(tmp_path):
    results = tmp_path / "results" / "tiny"
    (results / "chunks").mkdir(parents=True)
    t0 = time.time()
    plan = {"a" * 16: 3, "b" * 16: 1}
    (results / "plan.json").write_text(json.dumps({"name": "tiny", "scenes": 4, "chunks": plan}))
    p = progress.Progress(results, t0 - 1, jobs=2, t_origin=t0 - 100)
    for line in SNAKEMAKE_LINES.splitlines(True):
        p.feed(line, now=t0)
    assert p.counts == {"simulate_chunk": 4, "gather": 1, "notebook": 4, "all": 1}
    assert p.running == {"4": ("simulate_chunk", t0)}
    line = p.line("tiny", t0)
    assert line.startswith("sweep tiny: scenes 0/4 (0%) | ") and line.endswith(" | jobs 1/10 | 1:40"), line
    # scenes come in at 1 scene / 10 s: ETA = 2 scenes left at that rate + gather + 4 notebooks 2 at a time
    (results / "logs" / "chunks").mkdir(parents=True)
    log = results / "logs" / "chunks" / f"{'a' * 16}.log"
    log.write_text(f"x INFO chunk {'a' * 16}: 1/3 ...\n")
    p.line("tiny", t0 + 10)
    log.write_text(f"x INFO chunk {'a' * 16}: 2/3 ...\n")
    line = p.line("tiny", t0 + 20)
    # (before a chunk job has finished: a lower bound, the jobs' start-up and writing left out)
    eta = 2 * 10 + progress.GATHER_S + 2 * progress.GATHER_S_PER_CHUNK + 4 * progress.NOTEBOOK_S / 2
    assert f"0.10 scenes/s | ETA at least {progress.clock(eta)}" in line, line
    # every scene done: the gather runs, then the figures; a finished job's time replaces the estimate
    for cid in plan:
        (results / "chunks" / f"{cid}.nc").write_bytes(b"")
    p.feed("Finished jobid: 4 (Rule: simulate_chunk)\n", now=t0 + 30)
    p.feed("localrule gather:\n", now=t0 + 30)
    p.feed("    jobid: 1\n", now=t0 + 30)
    line = p.line("tiny", t0 + 31)
    assert line.startswith("sweep tiny: gather (4 scenes into cube.nc) | ETA "), line
    p.feed("Finished jobid: 1 (Rule: gather)\n", now=t0 + 33)
    for jid in ("6", "8"):
        p.feed("localrule notebook:\n", now=t0 + 33)
        p.feed(f"    jobid: {jid}\n", now=t0 + 33)
    p.feed("Finished jobid: 6 (Rule: notebook)\n", now=t0 + 41)
    line = p.line("tiny", t0 + 41)
    # 3 notebooks left at the 8 s the first took, 2 at a time: (max(8 - 8, 1) + 8 + 8) / 2
    assert line.startswith("sweep tiny: figures 1/4 | ETA 0:08 | "), line


def test_the_eta_is_a_lower_bound_until_a_chunk_job_has_finished(tmp_path):
    """Before a chunk job has finished, the scenes' rate has not met a job's start-up and writing
    out: the line says `ETA at least`; after, the plain ETA at the rate seen so far."""
    results = tmp_path / "results" / "s"
    (results / "chunks").mkdir(parents=True)
    (results / "logs" / "chunks").mkdir(parents=True)
    t0 = time.time()
    plan = {c * 16: 4 for c in "abcd"}          # 16 scenes in 4 chunks of 4
    (results / "plan.json").write_text(json.dumps({"name": "s", "scenes": 16, "chunks": plan}))
    p = progress.Progress(results, t0 - 1, jobs=2, t_origin=t0)
    for line in ("Job stats:", "job count", "simulate_chunk 4", "gather 1", "notebook 4", "total 9", ""):
        p.feed(line + "\n", now=t0)
    for jid in ("1", "2"):
        p.feed("localrule simulate_chunk:\n", now=t0)
        p.feed(f"    jobid: {jid}\n", now=t0)
    log = results / "logs" / "chunks" / f"{'a' * 16}.log"
    log.write_text(f"x INFO chunk {'a' * 16}: 1/4 ...\n")
    p.line("s", t0 + 6)
    log.write_text(f"x INFO chunk {'a' * 16}: 4/4 ...\n")
    line = p.line("s", t0 + 9)             # 3 scenes in 3 s: 12 left, 12 s at least
    after = progress.GATHER_S + 4 * progress.GATHER_S_PER_CHUNK + 4 * progress.NOTEBOOK_S / 2
    assert f"| ETA at least {progress.clock(12 + after)} |" in line, line
    (results / "chunks" / f"{'a' * 16}.nc").write_bytes(b"")
    p.feed("Finished jobid: 1 (Rule: simulate_chunk)\n", now=t0 + 14)
    line = p.line("s", t0 + 14)
    assert f"| ETA {progress.clock(12 + after)} |" in line, line


def test_adaptive_progress_shows_rounds_and_one_line_per_finished_round(tmp_path):
    results = tmp_path / "results" / "amap"
    rounds = results / "rounds"
    (rounds / "map-a").mkdir(parents=True)
    t0 = time.time()
    info = {"maps": {"map-a": "mu_d 0.3"}, "rounds": 2, "lattice": 81, "budget": 36, "rounds_dir": str(rounds)}
    (results / "plan.json").write_text(json.dumps({"name": "amap", "scenes": 36, "chunks": {}, "adaptive": info}))
    p = progress.Progress(results, t0 - 1, jobs=2, t_origin=t0 - 5)
    assert p.line("amap", t0).startswith("sweep amap: rounds 0 scenes computed (budget 36), 3 of 3 map rounds to go")
    assert p.round_lines() == []
    (rounds / "map-a" / "round0.json").write_text(json.dumps({"computed": 9, "line": "round 0 line"}))
    assert p.line("amap", t0 + 1).startswith("sweep amap: rounds 9 scenes computed (budget 36), 2 of 3 map rounds")
    assert p.round_lines() == ["round 0 line"] and p.round_lines() == []   # each round once
    for k, n in ((1, 25), (2, 33)):
        (rounds / "map-a" / f"round{k}.json").write_text(json.dumps({"computed": n, "line": f"round {k} line"}))
    assert p.round_lines() == ["round 1 line", "round 2 line"]
    for text in ("Job stats:\n", "job  count\n", "refine_round  3\n", "gather  1\n", "total  4\n",
                 "localrule gather:\n", "    jobid: 1\n"):
        p.feed(text, now=t0 + 3)
    assert p.line("amap", t0 + 3).startswith("sweep amap: gather (33 scenes into cube.nc)")


def test_compile_shows_a_ticking_elapsed_time_and_the_estimate(monkeypatch, capsys):
    """A cold numba cache: the line saying why and how long it usually takes, the ticking
    elapsed time while it compiles, then how long it took (here a stand-in that takes 2.3 s)."""
    from sweep import batch

    monkeypatch.setattr(warmup, "numba_cache_cold", lambda cache=None: True)
    monkeypatch.setattr(warmup, "prune_numba_caches", lambda cache=None: [])
    monkeypatch.setattr(batch, "warm_up", lambda scene, simulate=None: time.sleep(2.3))
    took = warmup.warm_numba(progress.StatusLine(sys.stdout, every_tty=0.0, every_log=0.0, heartbeat=0.9),
                             label="sweep tiny: compile")
    out = capsys.readouterr().out.splitlines()
    assert took >= 2.3              # the time it measured covers the stand-in's
    assert out[0] == warmup.COMPILE_LINE and warmup.COMPILE_ESTIMATE in out[0]
    ticks = [line for line in out if line.startswith("sweep tiny: compile | ")]
    assert ticks[:3] == ["sweep tiny: compile | 0:00", "sweep tiny: compile | 0:01", "sweep tiny: compile | 0:02"]
    assert re.fullmatch(r"numba: kernels compiled and cached in 0:0[23]", out[-1]), out


def test_setup_prints_one_line_per_step_and_logs_pip(tmp_path, monkeypatch, capsys):
    run_py_module = load_run_py()
    monkeypatch.setattr(run_py_module, "SETUP_LOG", tmp_path / "setup.log")
    noisy = [sys.executable, "-c", "import sys; print('WARNING: Location ... is ignored\\n' * 50); "
             "print('stderr noise', file=sys.stderr)"]
    with open(tmp_path / "setup.log", "a") as log:
        run_py_module._step("run.py: set-up 2/3: installing ...", noisy, log)
    assert capsys.readouterr().out == "run.py: set-up 2/3: installing ... done in 0:00\n"
    text = (tmp_path / "setup.log").read_text()
    assert text.count("WARNING: Location ... is ignored\n") == 50 and "stderr noise" in text
    failing = [sys.executable, "-c", "print('ERROR: no matching distribution for numpy==0'); raise SystemExit(1)"]
    with open(tmp_path / "setup.log", "a") as log, pytest.raises(subprocess.CalledProcessError):
        run_py_module._step("run.py: set-up 3/3: installing this package ...", failing, log)
    out = capsys.readouterr().out
    assert out.startswith("run.py: set-up 3/3: installing this package ... failed after 0:00; the end of ")
    assert "ERROR: no matching distribution" in out   # the cause is shown, from the log


# ------------------------------------------------------------------------------- the tiny grid, end to end

def test_tiny_sweep_through_the_front_door(tmp_path):
    """The fast tier's end-to-end run: config/tiny.yaml through `python3 run.py sweep` in a copy
    of the workflow (numba kernels cached), from the directory above it: progress lines naming
    their phase, the closing line with paths as seen from there, a CF cube whose every missing
    frequency or fit has its reason, and the four figures."""
    from sweep import reasons

    wd = copy_workflow(tmp_path / "wf")
    # the tiny grid in 2 jobs instead of 4 (each job starts Python and loads the kernels: ~4-8 s)
    tiny = (wd / "config" / "tiny.yaml").read_text()
    (wd / "config" / "tiny.yaml").write_text(tiny.replace("chunk_size: 3", "chunk_size: 5"))
    p = run_py("sweep", "--directory", "wf", "--configfile", "wf/config/tiny.yaml", cwd=tmp_path)
    out = p.stdout + p.stderr
    assert p.returncode == 0, out
    assert_clean_console(out)
    lines = out.rstrip("\n").splitlines()
    assert re.fullmatch(r"sweep tiny: done in \d+:\d\d: 8 scenes \(8 computed now\); wf/results/tiny/cube\.nc, "
                        r"wf/results/tiny/figures/; Snakemake's output: wf/results/tiny/logs/sweep\.log", lines[-1]), out
    for line in lines[:-1]:
        assert re.match(r"sweep tiny: (plan|scenes|gather|figures) ", line), line
    with xr.open_dataset(wd / "results" / "tiny" / "cube.nc") as cube:
        assert cube.attrs["sweep_name"] == "tiny"
        for name, var in cube.variables.items():
            assert var.attrs.get("units") and var.attrs.get("long_name"), name
        for flag, (explained, codes, _) in reasons.FLAGS.items():
            assert set(np.unique(cube[flag].values)) <= set(codes), flag
            for name in explained:
                np.testing.assert_array_equal(cube[flag].values == reasons.VALUE, np.isfinite(cube[name].values),
                                              err_msg=name)
    for nb in grid.NOTEBOOKS:
        assert (wd / "results" / "tiny" / "figures" / f"{nb}.png").read_bytes()[:4] == b"\x89PNG"


# Imported at start-up by every Python process given its folder on PYTHONPATH (the front door,
# Snakemake and its jobs alike): where SWEEP_TEST_FAIL_CHUNKS is set, sweep.batch.run_chunk_job,
# what a chunk job runs, raises.
FAILING_JOBS = """
import importlib.util, os, sys

class _FailChunkJobs:
    def find_spec(self, name, path=None, target=None):
        if name != "sweep.batch" or not os.environ.get("SWEEP_TEST_FAIL_CHUNKS"):
            return None
        sys.meta_path.remove(self)
        spec = importlib.util.find_spec(name)
        run = spec.loader.exec_module

        def exec_module(module):
            run(module)

            def fail(**kw):
                raise RuntimeError("injected failure of chunk job " + kw["expected_id"])
            module.run_chunk_job = fail
        spec.loader.exec_module = exec_module
        return spec

sys.meta_path.insert(0, _FailChunkJobs())
"""


def test_a_failing_job_fails_the_sweep_with_its_cause_and_the_log(tmp_path):
    """A chunk job that raises: `python3 run.py sweep` exits with Snakemake's non-zero status,
    shows the end of Snakemake's output (the failing rule and the job's exception) and closes with
    one line naming that status and the full log; no cube is written."""
    wd = copy_workflow(tmp_path / "wf")
    hook = tmp_path / "hook"
    hook.mkdir()
    (hook / "sitecustomize.py").write_text(FAILING_JOBS)
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(hook)] + [p for p in [os.environ.get("PYTHONPATH")] if p]),
               SWEEP_TEST_FAIL_CHUNKS="1")
    p = subprocess.run([sys.executable, str(ROOT / "run.py"), "sweep", "--directory", "wf", "--configfile",
                        "wf/config/tiny.yaml", "-j1"], cwd=tmp_path, capture_output=True, text=True,
                       timeout=TIMEOUT_S, stdin=subprocess.DEVNULL, env=env)
    out = p.stdout + p.stderr
    assert p.returncode == 1, (p.returncode, out)
    lines = out.rstrip("\n").splitlines()
    assert re.fullmatch(r"sweep tiny: failed \(Snakemake exit status 1\) after \d+:\d\d; "
                        r"full output: wf/results/tiny/logs/sweep\.log", lines[-1]), out
    assert "simulate_chunk" in out, out
    log = (wd / "results" / "tiny" / "logs" / "sweep.log").read_text()
    assert "injected failure of chunk job " in out + log, out
    assert not (wd / "results" / "tiny" / "cube.nc").exists()


# ------------------------------------------------------------------ one run per config (issue 51)

def test_a_second_run_of_a_running_config_is_refused_in_one_line(tmp_path, capsys):
    """While a run of a config holds results/<name>/.running (a live process), a second run of
    the same config, or its --unlock, says which run and since when, exits 2 and touches
    nothing; a lock whose process is gone is taken over and released at the end."""
    wd = copy_workflow(tmp_path / "wf")
    results = wd / "results" / "tiny"
    argv = ["--directory", str(wd), "--configfile", str(wd / "config" / "tiny.yaml")]
    holder = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        results.mkdir(parents=True)
        lock = {"pid": holder.pid, "host": __import__("socket").gethostname(), "started": time.time() - 75,
                "command": "python3 run.py sweep --configfile config/tiny.yaml",
                "process_start": runlock._process_start(holder.pid)}
        (results / runlock.RUN_LOCK).write_text(json.dumps(lock))
        for extra in ([], ["--unlock"]):
            assert frontdoor.run(argv + extra) == 2
            err = capsys.readouterr().err
            assert err.count("\n") == 1 and err.startswith("sweep tiny: already running since "), err
            assert re.search(rf"\(1:[12]\d ago; pid {holder.pid} on ", err) and "python3 run.py sweep --configfile config/tiny.yaml" in err
            assert ("--unlock now would let two runs write the same files: not done" in err) == bool(extra)
            assert sorted(p.name for p in results.iterdir()) == [runlock.RUN_LOCK]
        assert not (wd / ".snakemake").exists()
    finally:
        holder.kill()
        holder.wait()
    # its process gone: the lock is stale, taken over by this process and released by it
    assert runlock.running_run(results) is None
    assert runlock.take_run_lock(results, "python3 run.py sweep") is None
    assert json.loads((results / runlock.RUN_LOCK).read_text())["pid"] == os.getpid()
    assert runlock.running_run(results)["command"] == "python3 run.py sweep"
    runlock.release_run_lock(results)
    assert not (results / runlock.RUN_LOCK).exists()


def test_help_is_the_front_doors_own(capsys):
    assert frontdoor.run(["--help"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("usage: python3 run.py sweep ") and "--help-snakemake" in out and "__main__" not in out
