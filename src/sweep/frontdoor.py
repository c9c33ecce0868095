"""`python3 run.py sweep [snakemake args...]`: Snakemake as a user meets it.

* paths on the command line (`--configfile`, `--snakefile`, `--directory`, a `--profile` folder)
  are taken relative to the directory the user stands in, and messages show them as given;
  Snakemake itself runs in the project root (where the Snakefile is) unless `--directory` says
  otherwise, so results go to `<project>/results/<name>/` from wherever it is started;
* the config is read and validated before Snakemake starts, by the code the workflow runs
  (`sweep.grid.load_sweep`): an invalid config gives one line per invalid field, naming its file,
  and exit status 2, and nothing is created under results/;
* results per config: the sweep's folder is `results/<name>/` (`sweep.grid.sweep_name`); the
  whole Snakemake output of the run is appended to `results/<name>/logs/sweep.log`;
* one progress line naming its phase (compile, plan, scenes, gather, figures) with scenes done /
  total, scenes/s, an ETA that covers the phases still to come, Snakemake's jobs and the elapsed
  time, instead of Snakemake's and the jobs' own output; per-scene lines stay in the chunk logs;
* the numba kernels are compiled (or loaded from their cache) once, here, before any job; a
  compilation shows its ticking elapsed time and the estimate COMPILE_ESTIMATE;
* Ctrl-C (SIGINT) and SIGTERM stop the run and print one line: what was kept and the exact
  command that resumes it. Snakemake runs in its own session, so the terminal's Ctrl-C reaches
  this process only; it is passed on as one SIGINT to Snakemake's process group (Snakemake and
  its jobs), whose output (tracebacks of the interrupted jobs and kernels included) goes to the
  log; every process of that group is gone before this one exits, so nothing prints afterwards;
* `-j2` is added only when neither the arguments nor a `--profile` set `jobs`/`cores`, and
  `--rerun-incomplete` always (a chunk job is idempotent and writes atomically), so the resume
  command is the command that was interrupted.

* one run per config at a time: a run holds `results/<name>/.running` (its pid, start time and
  command); a second run of the same config (or its `--unlock`) is refused in one line naming
  the first, with exit status 2, before anything is touched; a lock whose process is gone is
  taken over.

`-h`/`--help` prints the front door's own help (HELP); `--help-snakemake` Snakemake's. Options
that only inform or maintain (`-n`, `--unlock`, `--lint`, `--list...`, ...) run Snakemake with
its own output, as does `--verbose`/`--debug` (after the same validation).
"""
from __future__ import annotations

import collections
import contextlib
import io as _stdio
import json
import math
import os
import re
import shlex
import shutil
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Mapping
from pathlib import Path

from . import grid

# the project root: the Snakefile, config/, workflow/ (src/sweep/frontdoor.py -> ../..)
PROJECT_ROOT = Path(__file__).resolve().parents[2]
DEFAULT_JOBS = "2"
# options whose values are paths (taken relative to the user's directory): how many values
PATH_OPTIONS = {"--configfile": "+", "--configfiles": "+", "--snakefile": 1, "-s": 1, "--directory": 1,
                "-d": 1, "--profile": 1}
# options after which nothing is validated: Snakemake answers without reading the workflow
HELP_OPTIONS = {"-h", "--help", "--version", "-v", "--help-snakemake"}
HELP = """usage: python3 run.py sweep [--configfile FILE.yaml] [--config KEY=VALUE ...] [-j N | --profile DIR]
                           [SNAKEMAKE OPTION ...]

Sweep the parameters of Euler's disk: check the config (every invalid field, one line each, exit
status 2, nothing created), compile the numba kernels once, run the scenes in chunks with
Snakemake, gather results/<name>/cube.nc and draw results/<name>/figures/*.png. One progress
line (phase, scenes done/total, scenes/s, ETA, Snakemake's jobs, elapsed time); Snakemake's own
output goes to results/<name>/logs/sweep.log.

options:
  -h, --help            this help
  --configfile FILE     the sweep config (default config/config.yaml; config/tiny.yaml is the
                        8-scene CI grid); results go to results/<name>/, <name> from the file's
                        `name:` or its stem. Every key, unit, range: docs/pipeline.md
  --config KEY=VALUE    override keys of the config (Snakemake's syntax)
  -j N, --cores N       jobs at once (default 2)
  --profile DIR         a Snakemake profile, e.g. workflow/profiles/slurm (a SLURM cluster)
  -n, --dry-run         list the jobs a run would do, without running them (Snakemake's output)
  --unlock              remove the lock of a run that was killed (kill -9, a crash); refused
                        while a run of the same config is running
  --help-snakemake      Snakemake's own help: any of its options can be given here

A rerun computes only what is missing. Ctrl-C stops a run and prints the command that resumes
it. Exit status: 0 done (or nothing to do); 2 an invalid config, or the same config already
running (nothing touched); 128 + the signal after Ctrl-C / SIGTERM; else Snakemake's."""
# Snakemake options after which its own console output is what the user wants
RAW_OPTIONS = {
    "-n", "--dry-run", "--dryrun", "--unlock", "--lint", "-l", "--list", "--list-rules",
    "--list-target-rules", "--lt", "-h", "--help", "--version", "-v", "-S", "--summary",
    "-D", "--detailed-summary", "--dag", "--rulegraph", "--filegraph", "--d3dag",
    "--cleanup-metadata", "--cm", "--list-changes", "--lc", "--list-input-changes", "--li",
    "--list-params-changes", "--lp", "--list-code-changes", "--list-untracked", "--lu",
    "--delete-all-output", "--delete-temp-output", "--archive", "--report", "-t", "--touch",
    "--cleanup-shadow", "--print-compilation", "--generate-unit-tests", "--containerize",
    "--verbose", "--debug", "--debug-dag", "--export-cwl", "--conda-create-envs-only",
}
# per-scene lines of sweep.batch ("<date> INFO chunk <id>: i/n ...") and other job logging:
# kept in the chunk logs and in sweep.log, never shown on the console
JOB_LOG_LINE = re.compile(r"^\d{4}-\d\d-\d\d \d\d:\d\d:\d\d,\d+ (DEBUG|INFO|WARNING) ")
STEPS = re.compile(r"(\d+) of (\d+) steps \(\d+%\) done")
NOTHING = "Nothing to be done"
JOB_START = re.compile(r"^(?:local)?rule (\w+):")
JOB_ID = re.compile(r"^\s+jobid: (\d+)")
JOB_DONE = re.compile(r"^Finished jobid: (\d+) \(Rule: (\w+)\)")
JOB_STATS = re.compile(r"^(\w+)\s+(\d+)$")
# The kernels' compilation (docs/pipeline.md, "Running"): measured on 2-core machines shared with
# other work: 75 s to 213 s on a fresh clone.
COMPILE_ESTIMATE = "usually 1-4 min on a 2-core machine, by how busy it is"
# After the last scene: the gather (opening every chunk file: 0.5 s + 0.4 s per chunk file), then
# the figures job (every notebook in one process: imports, reductions, plots; 9-10 s for the four
# on a busy 2-core machine), measured on a busy 2-core machine; the run's own durations replace
# them as soon as one has finished.
GATHER_S, GATHER_S_PER_CHUNK = 0.5, 0.4
# the rule of the chunk jobs: until one has finished, the scenes' rate leaves out the jobs' start-up
# and writing out (measured: ~10 s per job on a busy 2-core machine against ~4 s of scenes in a
# default chunk), so the ETA it gives is a lower bound and says so
CHUNK_RULE = "simulate_chunk"
NOTEBOOK_S = 9.0
SIGNAL_GRACE_S = 60.0            # after the forwarded SIGINT, before SIGKILL


# ------------------------------------------------------------------------------------- arguments

def parsed_args(argv: list[str], cwd: Path = PROJECT_ROOT):
    """Snakemake's own parse of `argv` (profile defaults applied, a relative profile path found
    from `cwd`, where Snakemake runs), or None if it rejects it."""
    from snakemake.cli import parse_args

    with contextlib.redirect_stderr(_stdio.StringIO()), contextlib.redirect_stdout(_stdio.StringIO()), \
            contextlib.chdir(cwd):
        try:
            return parse_args(list(argv))[1]
        except SystemExit:
            return None


def snakemake_argv(argv: list[str], progress: bool) -> list[str]:
    """The Snakemake arguments for `run.py sweep argv`: `-j2` unless `argv` or its profile set
    jobs/cores; `--rerun-incomplete` for a run (so an interrupted run resumes as it was started)."""
    args = parsed_args(argv)
    extra = []
    if args is not None and args.jobs is None and args.cores is None:
        extra += ["-j", DEFAULT_JOBS]
    if progress and "--rerun-incomplete" not in argv and "--ri" not in argv:
        extra.append("--rerun-incomplete")
    return extra + list(argv)


def is_raw(argv: list[str]) -> bool:
    return any(a.split("=", 1)[0] in RAW_OPTIONS for a in argv)


def absolute_paths(argv: list[str], cwd: Path) -> tuple[list[str], dict[str, str]]:
    """`argv` with the values of PATH_OPTIONS made absolute against `cwd` (a `--profile` only if
    it names a folder or file there; else it is a profile name or a path in the project), and
    {absolute path: the path as the user wrote it}, to name files as given."""
    out: list[str] = []
    given: dict[str, str] = {}

    def absolute(opt: str, value: str) -> str:
        p = Path(value).expanduser()
        if opt == "--profile" and not (cwd / p).exists():
            return value
        full = str(p if p.is_absolute() else cwd / p)
        given.setdefault(full, value)
        return full

    i = 0
    while i < len(argv):
        a = argv[i]
        opt, eq, value = a.partition("=")
        if eq and opt.startswith("--") and opt in PATH_OPTIONS:
            out.append(f"{opt}={absolute(opt, value)}")
        elif a in PATH_OPTIONS:
            out.append(a)
            n = 0
            while i + 1 < len(argv) and not argv[i + 1].startswith("-") and (PATH_OPTIONS[a] == "+" or n < 1):
                i += 1
                n += 1
                out.append(absolute(a, argv[i]))
        else:
            out.append(a)
        i += 1
    return out, given


def shown_path(path: Path, cwd: Path | None = None) -> str:
    """A path as a message shows it: relative to the user's directory if inside it."""
    cwd = cwd or Path.cwd()
    path = Path(path)
    return str(path.relative_to(cwd)) if path.is_absolute() and path.is_relative_to(cwd) else str(path)


def command_prefix() -> str:
    """How the user started the front door, for the resume command: `python3 run.py` as typed
    (run.py passes it in SWEEP_COMMAND), e.g. `python3 ../sweep/run.py` from another directory."""
    return os.environ.get("SWEEP_COMMAND", "python3 run.py")


def config_files(args, given: Mapping[str, str], cwd: Path) -> tuple[Path, list[tuple[Path, str]], dict | None]:
    """(Snakemake's working directory, the config files in Snakemake's order as (path, as the
    user named it), the --config overrides) of a run parsed as `args` (absolute paths)."""
    from snakemake.cli import parse_config

    workdir = Path(args.directory) if args.directory else PROJECT_ROOT
    files: list[tuple[Path, str]] = []
    if not getattr(args, "replace_workflow_config", False):
        default = workdir / grid.DEFAULT_CONFIG
        files.append((default, shown_path(default, cwd)))
    for f in args.configfile or []:
        f = Path(f)
        if all(f != p for p, _ in files):
            files.append((f, given.get(str(f), shown_path(f, cwd))))
    overrides = parse_config(args.config) if args.config else None
    return workdir, files, overrides


# ---------------------------------------------------------------------------------------- numba

def numba_cache_cold(cache: Path | None = None) -> bool:
    """Whether the kernels of this exact source (core.jit.DIGEST) are not yet compiled and cached:
    the main loop's index is missing from their keyed cache folder (core.jit.cache_dir)."""
    from .core import jit

    cache = cache or jit.cache_dir()
    return not any(cache.glob("integrate.run-*.nbi"))


def prune_numba_caches(cache: Path | None = None) -> list[Path]:
    """Remove the cache folders of earlier versions of the kernel sources beside the current one
    (`numba-<digest>` siblings of core.jit.cache_dir(); ~11 MB each). Called before the jobs start,
    by the one process that warms the cache. Returns what it removed."""
    from .core import jit

    cache = cache or jit.cache_dir()
    prefix = cache.name.rsplit("-", 1)[0] + "-"
    gone = []
    if cache.parent.is_dir():
        for old in cache.parent.glob(prefix + "*"):
            if old.is_dir() and old != cache:
                shutil.rmtree(old, ignore_errors=True)
                gone.append(old)
    return gone


class StatusLine:
    """One status line: rewritten in place on a terminal (at most every `every_tty` s), printed as
    a new line elsewhere (a log, CI) when its text (less the clock) changed, at most every
    `every_log` s, and at least every `heartbeat` s."""

    def __init__(self, stream=None, every_tty: float = 0.5, every_log: float = 10.0, heartbeat: float = 60.0):
        self.stream = stream or sys.stdout
        self.tty = self.stream.isatty()
        self.every = every_tty if self.tty else every_log
        self.heartbeat = heartbeat
        self.last_key = None
        self.last_print = -math.inf
        self.lock = threading.Lock()

    def show(self, text: str, force: bool = False) -> None:
        key = text.rsplit(" | ", 1)[0]
        now = time.monotonic()
        with self.lock:
            quiet = now - self.last_print
            if not force and (quiet < self.every or (not self.tty and key == self.last_key and quiet < self.heartbeat)):
                return
            if self.tty:
                print("\r\033[K" + text, end="", file=self.stream, flush=True)
            else:
                print(text, file=self.stream, flush=True)
            self.last_key, self.last_print = key, now

    def say(self, text: str) -> None:
        """A line of its own (clears a status line being rewritten)."""
        with self.lock:
            print(("\r\033[K" if self.tty else "") + text, file=self.stream, flush=True)
            self.last_key, self.last_print = None, -math.inf

    def clear(self) -> None:
        if self.tty:
            with self.lock:
                print("\r\033[K", end="", file=self.stream, flush=True)


@contextlib.contextmanager
def ticking(status: StatusLine, text, period: float = 1.0):
    """While the block runs, show `text(elapsed seconds)` on `status` every `period` s (from a
    thread: the block keeps the main thread, where signals arrive)."""
    t0 = time.monotonic()
    stop = threading.Event()

    def tick():
        while True:
            status.show(text(time.monotonic() - t0))
            if stop.wait(period):
                return

    thread = threading.Thread(target=tick, daemon=True)
    thread.start()
    try:
        yield
    finally:
        stop.set()
        thread.join(timeout=5)


COMPILE_LINE = ("numba: compiling the integrator's kernels (once after a change of src/sweep/core; "
                f"{COMPILE_ESTIMATE})")


def warm_numba(status: StatusLine, label: str = "numba: compiling") -> float | None:
    """Compile (or load) the kernels once in this process, so the jobs find them cached. A
    compilation shows `label` with its ticking elapsed time and the estimate; returns its
    duration (s), None where the cache was warm."""
    import copy

    from . import batch
    from .scene import DEFAULTS

    cold = numba_cache_cold()
    t0 = time.monotonic()
    if cold:
        status.say(COMPILE_LINE)
        with ticking(status, lambda s: f"{label} | {_clock(s)}"):
            batch.warm_up(copy.deepcopy(DEFAULTS))
    else:
        batch.warm_up(copy.deepcopy(DEFAULTS))
    prune_numba_caches()
    if cold:
        took = time.monotonic() - t0
        status.say(f"numba: kernels compiled and cached in {_clock(took)}")
        return took
    return None


def compile_for_command(stream=None) -> None:
    """For a command that runs the kernels in its own process (`python3 run.py scene`): where
    they are not compiled yet, compile them first with the notice and the ticking elapsed time
    (on `stream`, default stderr, so a --json output stays clean)."""
    try:
        cold = numba_cache_cold()
    except Exception:  # noqa: BLE001 - a notice, never a reason to fail
        return
    if cold:
        warm_numba(StatusLine(stream or sys.stderr, every_tty=1.0, every_log=30.0, heartbeat=30.0))


# ------------------------------------------------------------------------------------- progress

def _clock(seconds: float) -> str:
    s = int(round(seconds))
    return f"{s // 3600}:{s % 3600 // 60:02d}:{s % 60:02d}" if s >= 3600 else f"{s // 60}:{s % 60:02d}"


class Progress:
    """The run's progress: scenes done / total from the run's plan (written by the workflow when
    it is parsed), the chunk files and the chunk logs; Snakemake's jobs (which rule runs, how
    many of each are planned and finished, how long they took) from its output, fed line by
    line to `feed`. The phase is `plan` until the plan exists, `scenes` until every scene is
    done, then `gather` and `figures` as their jobs run."""

    def __init__(self, results: Path, t_start: float, jobs: int = int(DEFAULT_JOBS), t_origin: float | None = None):
        self.results = results
        self.t_start = t_start          # time.time() when Snakemake started
        self.t_origin = t_origin if t_origin is not None else t_start   # for the elapsed clock
        self.jobs = max(1, jobs)
        self.plan: dict[str, int] | None = None
        self.total = 0
        self.kept_at_start = 0
        self.first_seen: tuple[float, int] | None = None   # (time, done) when scenes started to come in
        self.last_seen: tuple[float, int] | None = None    # (time, done) at the latest increase
        self.finished: set[str] = set()
        self.steps: tuple[int, int] | None = None
        self.counts: dict[str, int] = {}                   # Snakemake's "Job stats": rule -> jobs
        self.running: dict[str, tuple[str, float]] = {}    # jobid -> (rule, start time)
        self.done_jobs: dict[str, list[float]] = collections.defaultdict(list)  # rule -> durations
        self._rule: str | None = None
        self._in_stats = False
        self.adaptive: dict | None = None                  # an adaptive run's plan_info (sweep.adaptive)
        self.shown_rounds: set[str] = set()
        self.rounds_left = 0

    # --- Snakemake's output
    def feed(self, text: str, now: float | None = None) -> None:
        now = time.time() if now is None else now
        line = text.rstrip("\n")
        m = STEPS.search(line)
        if m:
            self.steps = (int(m.group(1)), int(m.group(2)))
        if line.startswith("Job stats:"):
            self._in_stats, self.counts = True, {}
            return
        if self._in_stats:
            m = JOB_STATS.match(line.strip())
            if (m and m.group(1) == "total") or not line.strip():
                self._in_stats = False
            elif m:
                self.counts[m.group(1)] = int(m.group(2))
            return
        m = JOB_START.match(line)
        if m:
            self._rule = m.group(1)
            return
        m = JOB_ID.match(line)
        if m and self._rule is not None:
            self.running[m.group(1)] = (self._rule, now)
            self._rule = None
            return
        m = JOB_DONE.match(line)
        if m:
            rule, t0 = self.running.pop(m.group(1), (m.group(2), None))
            if t0 is not None:
                self.done_jobs[rule].append(now - t0)

    # --- scenes
    def _load_plan(self) -> None:
        path = self.results / "plan.json"
        try:
            if path.stat().st_mtime < self.t_start - 1:
                return
            data = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, ValueError):
            return
        self.plan = {str(k): int(v) for k, v in data["chunks"].items()}
        self.total = int(data["scenes"])
        self.adaptive = data.get("adaptive")

    def chunks_present(self) -> set[str]:
        return {cid for cid in (self.plan or {}) if (self.results / "chunks" / f"{cid}.nc").is_file()}

    def chunks_kept(self, workdir: Path) -> set[str]:
        """Chunk files a resumed run keeps: present, and not marked incomplete by Snakemake (a
        job that was stopped after writing its file but before Snakemake recorded it)."""
        marked = incomplete_outputs(workdir)
        return {cid for cid in self.chunks_present()
                if (self.results / "chunks" / f"{cid}.nc").resolve() not in marked}

    # --- an adaptive map's rounds (sweep.adaptive): round files instead of a chunk plan
    def _rounds(self) -> dict[str, list[dict]]:
        """{map id: the records of its finished rounds, in order} of an adaptive run."""
        out = {}
        for map_id in self.adaptive["maps"]:
            recs = []
            for k in range(int(self.adaptive["rounds"]) + 1):
                try:
                    recs.append(json.loads((Path(self.adaptive["rounds_dir"]) / map_id / f"round{k}.json")
                                           .read_text(encoding="utf-8")))
                except (OSError, ValueError):
                    break
            out[map_id] = recs
        return out

    def round_lines(self) -> list[str]:
        """The progress line of every round that finished during this run and was not shown yet."""
        if self.plan is None or not getattr(self, "adaptive", None):
            return []
        lines = []
        for map_id in self.adaptive["maps"]:
            for k in range(int(self.adaptive["rounds"]) + 1):
                path = Path(self.adaptive["rounds_dir"]) / map_id / f"round{k}.json"
                key = str(path)
                if key in self.shown_rounds:
                    continue
                try:
                    if path.stat().st_mtime < self.t_start - 1:
                        continue
                    lines.append(json.loads(path.read_text(encoding="utf-8"))["line"])
                except (OSError, ValueError, KeyError):
                    break
                self.shown_rounds.add(key)
        return lines

    def done(self) -> int | None:
        if self.plan is None:
            self._load_plan()
            if self.plan is None:
                return None
            self.finished = self.chunks_present()
            self.kept_at_start = sum(self.plan[c] for c in self.finished)
            if getattr(self, "adaptive", None):
                self.kept_at_start = sum(r[-1]["computed"] for r in self._rounds().values() if r)
        if getattr(self, "adaptive", None):
            rounds = self._rounds()
            self.rounds_left = sum(int(self.adaptive["rounds"]) + 1 - len(r) for r in rounds.values())
            return sum(r[-1]["computed"] for r in rounds.values() if r)
        n = 0
        for cid, size in self.plan.items():
            if cid in self.finished or (self.results / "chunks" / f"{cid}.nc").is_file():
                self.finished.add(cid)
                n += size
                continue
            log = self.results / "logs" / "chunks" / f"{cid}.log"
            try:
                if log.stat().st_mtime < self.t_start:
                    continue
                found = re.findall(rf"chunk {cid}: (\d+)/\d+ ", log.read_text(encoding="utf-8", errors="replace"))
            except OSError:
                continue
            if found:
                n += int(found[-1])
        return n

    # --- after the scenes
    def _left(self, rule: str, expected: float, now: float) -> tuple[int, float]:
        """(jobs of `rule` not finished, seconds of work they have left, at `expected` s per job
        or the mean of those finished)."""
        took = self.done_jobs.get(rule)
        per = sum(took) / len(took) if took else expected
        running = [now - t0 for r, t0 in self.running.values() if r == rule]
        n_left = max(self.counts.get(rule, 0) - len(took or ()), len(running))
        work = sum(max(per - e, 1.0) for e in running) + per * max(n_left - len(running), 0)
        return n_left, work

    def phase(self, done: int | None) -> str:
        if done is None:
            return "plan"
        if self.adaptive:
            if self.rounds_left:
                return "rounds"
        elif done < self.total:
            return "scenes"
        rules = {r for r, _ in self.running.values()}
        if "notebook" in rules or ("gather" not in rules and self.counts.get("notebook", 0)
                                   and self.counts.get("gather", 0) <= len(self.done_jobs.get("gather", ()))):
            return "figures"
        return "gather" if self.counts.get("gather", 0) else "finish"

    def eta(self, done: int, now: float) -> tuple[float, bool] | None:
        """(seconds until the run ends, whether that is a lower bound), or None while there is no
        rate yet. The scenes left at the rate seen so far (from the first scene that came in);
        until a chunk job has finished, that rate has not met a job's start-up and writing out
        (~10 s per job on a busy 2-core machine against ~4 s of scenes in a default chunk), so the
        ETA is a lower bound and says so. Then the gather and the figures (GATHER_S +
        GATHER_S_PER_CHUNK per chunk file, NOTEBOOK_S per notebook, or what this run's finished
        ones took; the notebooks `jobs` at a time)."""
        left, bound = 0.0, False
        if self.adaptive and self.rounds_left:
            return None     # an adaptive sweep: a round's size is known only when it starts
        if done < self.total and not self.adaptive:
            first, last = self.first_seen, self.last_seen
            if first is None or not (last[0] > first[0] and last[1] > first[1]):
                return None
            left += (self.total - done) / ((last[1] - first[1]) / (last[0] - first[0]))
            bound = not self.done_jobs.get(CHUNK_RULE)
        left += self._left("gather", GATHER_S + GATHER_S_PER_CHUNK * len(self.plan or ()), now)[1]
        n_nb, work = self._left("notebook", NOTEBOOK_S, now)
        if n_nb:
            left += work / min(self.jobs, n_nb)
        return left, bound

    def line(self, name: str, now: float) -> str:
        done = self.done()
        phase = self.phase(done)
        parts = [f"sweep {name}: {phase}"]
        if done is None:
            parts[0] += " (Snakemake reads the workflow, checks the chunk files, plans the jobs)"
        else:
            pct = 100.0 * done / self.total if self.total else 100.0
            if done > self.kept_at_start and self.first_seen is None:
                self.first_seen = (now, done)
            if self.last_seen is None or done > self.last_seen[1]:
                self.last_seen = (now, done)
            if phase == "rounds":
                parts[0] += (f" {done} scenes computed (budget {self.total}), {self.rounds_left} of "
                             f"{len(self.adaptive['maps']) * (int(self.adaptive['rounds']) + 1)} map rounds to go")
            elif phase == "scenes":
                parts[0] += f" {done}/{self.total} ({pct:.0f}%)"
            elif phase == "gather":
                parts[0] += f" ({done if self.adaptive else self.total} scenes into cube.nc)"
            else:
                n_nb = self.counts.get("notebook", 0)
                parts[0] += f" {min(len(self.done_jobs.get('notebook', ())), n_nb)}/{n_nb}"
            first, last = self.first_seen, self.last_seen
            if phase == "scenes" and first is not None and last[0] > first[0] and last[1] > first[1]:
                parts.append(f"{(last[1] - first[1]) / (last[0] - first[0]):.2f} scenes/s")
            eta = self.eta(done, now)
            if eta is not None:
                parts.append(f"ETA {'at least ' if eta[1] else ''}{_clock(eta[0])}")
            if self.steps:
                parts.append(f"jobs {self.steps[0]}/{self.steps[1]}")
        parts.append(_clock(now - self.t_origin))
        return " | ".join(parts)


# ----------------------------------------------------------------------------------------- run

def incomplete_outputs(workdir: Path) -> set[Path]:
    """Outputs Snakemake marked incomplete (.snakemake/incomplete/<base64 of the path>): they are
    computed again by the next run (--rerun-incomplete)."""
    import base64

    out = set()
    for marker in (workdir / ".snakemake" / "incomplete").glob("*"):
        try:
            out.add((workdir / base64.urlsafe_b64decode(marker.name).decode()).resolve())
        except ValueError:  # a long path split into '@' folders: not a chunk file
            continue
    return out


def release_own_locks(workdir: Path, since: float) -> list[Path]:
    """Remove the lock files (.snakemake/locks/<n>.<input|output>.lock) written at or after `since`
    (seconds since the epoch), i.e. by the run this front door started and has seen end, and the
    lock folder if that leaves it empty, as Snakemake's own unlock does; older locks (another
    run's) are kept. Returns the removed files.

    Snakemake normally releases its lock when a Ctrl-C stops it, but not always: a CI run found
    the lock still there after one Ctrl-C, and a SIGKILL (a second Ctrl-C, or the grace period
    run out) always leaves it. The resume command stays the interrupted command either way."""
    locks = workdir / ".snakemake" / "locks"
    removed = []
    for lock in sorted(locks.glob("*.lock")):
        with contextlib.suppress(FileNotFoundError):
            if lock.stat().st_mtime >= since:
                lock.unlink()
                removed.append(lock)
    with contextlib.suppress(OSError):
        locks.rmdir()
    return removed


class _Stop(Exception):
    pass


def _killpg(pgid: int, sig: int) -> bool:
    """Signal a process group; False if it no longer exists."""
    try:
        os.killpg(pgid, sig)
        return True
    except ProcessLookupError:
        return False
    except PermissionError:
        return True


def _end_group(pgid: int, wait_s: float = 5.0) -> None:
    """Make sure no process of the group survives (e.g. a notebook kernel): SIGTERM, then SIGKILL."""
    if not _killpg(pgid, signal.SIGTERM):
        return
    deadline = time.monotonic() + wait_s
    while time.monotonic() < deadline:
        if not _killpg(pgid, 0):
            return
        time.sleep(0.05)
    _killpg(pgid, signal.SIGKILL)
    for _ in range(100):
        if not _killpg(pgid, 0):
            return
        time.sleep(0.05)


RUN_LOCK = ".running"   # results/<name>/.running: the run of that config in progress (JSON)


def _process_start(pid: int) -> str | None:
    """The start time of process `pid` in clock ticks since boot (/proc/<pid>/stat, field 22), to
    tell a live run from a new process that reuses its pid; None where /proc has no such entry."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    return stat.rsplit(")", 1)[1].split()[19]


def _alive(pid: int, start: str | None) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        pass
    return start is None or _process_start(pid) in (None, start)


def running_run(results: Path) -> dict | None:
    """The run of this config in progress, from its lock `results/RUN_LOCK` ({pid, host, started
    (epoch s), command}), or None: no lock, or a lock whose process is gone on this host."""
    import socket

    try:
        run = json.loads((results / RUN_LOCK).read_text(encoding="utf-8"))
        pid, host = int(run["pid"]), str(run["host"])
    except (OSError, ValueError, KeyError, TypeError):
        return None
    if host == socket.gethostname() and not _alive(pid, run.get("process_start")):
        # the front door is gone (kill -9): its Snakemake, in a session of its own, may run on
        sm = run.get("snakemake_pid")
        if sm is None or not _alive(int(sm), run.get("snakemake_start")):
            return None
        run["pid"], run["command"] = sm, f"Snakemake, left running by: {run.get('command')}"
    return run


def note_snakemake(results: Path, pid: int) -> None:
    """Add the pid of the run's Snakemake to its lock (written atomically), so that the lock
    holds while Snakemake runs even if the front door is killed."""
    path = results / RUN_LOCK
    try:
        run = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return
    if run.get("pid") != os.getpid():
        return
    run.update(snakemake_pid=pid, snakemake_start=_process_start(pid))
    tmp = path.with_name(f"{RUN_LOCK}.tmp{os.getpid()}")
    tmp.write_text(json.dumps(run), encoding="utf-8")
    os.replace(tmp, path)


def take_run_lock(results: Path, command: str) -> dict | None:
    """Make this process the run of `results`' config: write results/RUN_LOCK (atomically, O_EXCL)
    unless a live run holds it. Returns that run (nothing written) or None (the lock is ours; a
    stale one, its process gone, is replaced)."""
    import socket

    mine = {"pid": os.getpid(), "host": socket.gethostname(), "started": time.time(), "command": command,
            "process_start": _process_start(os.getpid())}
    path = results / RUN_LOCK
    for _ in range(3):
        other = running_run(results)
        if other is not None and other.get("pid") != os.getpid():
            return other
        results.mkdir(parents=True, exist_ok=True)
        if other is None:
            with contextlib.suppress(FileNotFoundError):
                path.unlink()   # a stale lock (its process is gone)
        try:
            fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
        except FileExistsError:
            continue            # another run took it between the check and here
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            json.dump(mine, f)
        return None
    return running_run(results) or {"pid": "?", "host": "?", "started": time.time(), "command": "?"}


def release_run_lock(results: Path) -> None:
    """Remove results/RUN_LOCK if this process holds it."""
    run = running_run(results)
    if run is not None and run.get("pid") == os.getpid():
        with contextlib.suppress(FileNotFoundError):
            (results / RUN_LOCK).unlink()


def already_running(name: str, run: dict, shown: str, what: str = "nothing was done") -> str:
    """The one line for a second run of config `name` while `run` (running_run) runs."""
    started = float(run.get("started", 0.0))
    since = time.strftime("%Y-%m-%d %H:%M:%S", time.localtime(started))
    return (f"sweep {name}: already running since {since} ({_clock(max(time.time() - started, 0.0))} ago; "
            f"pid {run.get('pid')} on {run.get('host')}: {run.get('command')}), writing {shown}/; {what}. "
            f"Wait for it, or stop it: kill -INT {run.get('pid')} (or Ctrl-C in its terminal)")


def validate(argv: list[str], cwd: Path) -> tuple[list[str], Path, grid.Sweep | None] | int:
    """The Snakemake arguments (paths made absolute), its working directory and the validated
    sweep of a run; or, for an invalid config, the exit status 2 after one line per invalid
    field on stderr (nothing is created). The sweep is None where Snakemake will answer without
    reading the config (--help, --version) or rejects the arguments itself."""
    sm_argv, given = absolute_paths(argv, cwd)
    args = parsed_args(sm_argv)
    if args is None or any(a in HELP_OPTIONS for a in argv):
        return sm_argv, PROJECT_ROOT, None
    try:
        workdir, files, overrides = config_files(args, given, cwd)
    except ValueError as exc:           # a --config entry Snakemake cannot parse
        print(f"error: --config: {exc}", file=sys.stderr)
        return 2
    try:
        return sm_argv, workdir, grid.load_sweep(files, overrides)
    except grid.SweepConfigError as err:
        for e in err.errors:
            print(f"error: {e.line()}", file=sys.stderr)
        return 2


def run(argv: list[str]) -> int:
    cwd = Path.cwd()
    t_origin = time.time()
    if any(a in ("-h", "--help") for a in argv):
        print(HELP)
        return 0
    if "--help-snakemake" in argv:
        argv = ["--help"]
    checked = validate(argv, cwd)
    if isinstance(checked, int):
        return checked
    sm_argv, workdir, sweep = checked
    resume = " ".join([command_prefix(), "sweep", *map(shlex.quote, argv)])
    if sweep is not None:
        results = workdir / "results" / sweep.name
        other = running_run(results)
        if other is not None and (not is_raw(argv) or "--unlock" in argv):
            what = ("--unlock now would let two runs write the same files: not done" if "--unlock" in argv
                    else "nothing was done")
            print(already_running(sweep.name, other, shown_path(results, cwd), what), file=sys.stderr)
            return 2
    if sweep is None or is_raw(argv):
        cmd = [sys.executable, "-m", "snakemake", *snakemake_argv(sm_argv, progress=False)]
        try:
            return subprocess.run(cmd, cwd=PROJECT_ROOT).returncode
        except KeyboardInterrupt:
            return 130

    name = sweep.name
    results = workdir / "results" / name
    other = take_run_lock(results, resume)
    if other is not None:   # started in the moment since the check above
        print(already_running(name, other, shown_path(results, cwd)), file=sys.stderr)
        return 2
    try:
        return _run(argv, cwd, t_origin, sm_argv, workdir, sweep, resume)
    finally:
        release_run_lock(results)


def _run(argv, cwd, t_origin, sm_argv, workdir, sweep, resume) -> int:
    """A run of a valid sweep that holds its config's lock (run)."""
    name = sweep.name
    status = StatusLine(sys.stdout, heartbeat=30.0)
    state: dict = {"signal": None, "proc": None}

    def on_signal(signum, _frame):
        if state["signal"] is None:
            state["signal"] = signum
            if state["proc"] is None:
                raise _Stop()
            _killpg(state["proc"].pid, signal.SIGINT)   # as a Ctrl-C in Snakemake's own terminal
        elif state["proc"] is not None:
            _killpg(state["proc"].pid, signal.SIGKILL)  # asked twice: stop now

    signal.signal(signal.SIGINT, on_signal)
    signal.signal(signal.SIGTERM, on_signal)

    results = workdir / "results" / name
    shown = shown_path(results, cwd)
    n_scenes = math.prod(grid.grid_shape(sweep.settings))
    if grid.is_adaptive(sweep.settings):   # at most its budget
        from . import adaptive
        n_scenes = adaptive.plan_info(sweep.settings, "")["budget"]
    try:
        try:
            warm_numba(status, label=f"sweep {name}: compile (numba kernels, then {n_scenes} scenes)")
        except _Stop:
            raise
        except Exception as exc:  # noqa: BLE001 - the jobs will report the same problem in full
            status.say(f"numba: warm-up failed ({type(exc).__name__}: {exc}); the jobs will try again")
        log_path = results / "logs" / "sweep.log"
        log_path.parent.mkdir(parents=True, exist_ok=True)
        t_start = time.time()
        t_locks = t_start - 1.0      # file times may be rounded down to the second
        sm_cmd = snakemake_argv(sm_argv, progress=True)
        cmd = [sys.executable, "-m", "snakemake", *sm_cmd]
        log = open(log_path, "a", encoding="utf-8")
        log.write(f"=== {time.strftime('%Y-%m-%d %H:%M:%S')} {resume}\n=== {shlex.join(cmd)}\n")
        log.flush()
        proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                stdin=subprocess.DEVNULL, start_new_session=True, cwd=PROJECT_ROOT,
                                text=True, errors="replace", bufsize=1)
        state["proc"] = proc
        note_snakemake(results, proc.pid)
    except _Stop:
        status.say(f"sweep {name}: interrupted before the sweep started; nothing was computed. Run again: {resume}")
        return 128 + state["signal"]

    args = parsed_args(sm_cmd)
    jobs = (args.jobs or args.cores) if args is not None else None
    progress = Progress(results, t_start, jobs=jobs if isinstance(jobs, int) else int(DEFAULT_JOBS),
                        t_origin=t_origin)
    tail: collections.deque[str] = collections.deque(maxlen=60)
    flags = {"nothing": False}

    def read() -> None:
        for text in proc.stdout:
            log.write(text)
            log.flush()   # `tail -f results/<name>/logs/sweep.log` follows the run
            progress.feed(text)
            if NOTHING in text:
                flags["nothing"] = True
            if not JOB_LOG_LINE.match(text):
                tail.append(text.rstrip("\n"))
        log.flush()

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    deadline = None
    while proc.poll() is None:
        time.sleep(0.25)
        if state["signal"] is not None:
            deadline = deadline or time.monotonic() + SIGNAL_GRACE_S
            if time.monotonic() > deadline:
                _killpg(proc.pid, signal.SIGKILL)
            continue
        status.show(progress.line(name, time.time()))
        for text in progress.round_lines():     # an adaptive map: one line per finished round
            status.say(text)
    for text in progress.round_lines():
        status.say(text)
    _end_group(proc.pid)
    reader.join(timeout=10)
    log.close()
    code = proc.returncode
    elapsed = _clock(time.time() - t_origin)

    if state["signal"] is not None:
        progress.done()
        plan = progress.plan or {}
        present = progress.chunks_kept(workdir)
        kept = sum(plan[c] for c in present)
        released = release_own_locks(workdir, t_locks)
        if released:
            with open(log_path, "a", encoding="utf-8") as note:
                note.write(f"=== sweep: released the lock this run's Snakemake left: "
                           f"{', '.join(p.name for p in released)}\n")
        locked = any((workdir / ".snakemake" / "locks").glob("*"))
        prefix = f"{command_prefix()} sweep"
        again = f"{prefix} --unlock{resume[len(prefix):]} && {resume}" if locked else resume
        what = (f"kept {kept} of {progress.total} scenes ({len(present)} of {len(plan)} chunk files) "
                f"in {shown}/chunks/" if plan else "nothing was computed yet")
        if progress.adaptive:   # rounds: finished ones are kept whole, a stopped one keeps its chunk files
            n_files = len(list((results / "chunks").glob("*.nc")))
            n_rounds = sum(len(r) for r in progress._rounds().values())
            what = (f"kept {n_rounds} finished map rounds ({progress.done() or 0} scenes) and {n_files} chunk files "
                    f"in {shown}/chunks/ (a stopped round reuses its finished chunks)")
        status.say(f"sweep {name}: interrupted ({signal.Signals(state['signal']).name}) after {elapsed}; "
                   f"{what}; resume with: {again}")
        return 128 + state["signal"]
    if code == 0:
        if flags["nothing"]:
            status.say(f"sweep {name}: nothing to do, {shown}/ is up to date ({shown}/cube.nc, {shown}/figures/)")
        else:
            done = progress.done() or 0
            status.say(f"sweep {name}: done in {elapsed}: {done} scenes ({done - progress.kept_at_start} computed "
                       f"now); {shown}/cube.nc, {shown}/figures/; Snakemake's output: {shown}/logs/sweep.log")
        return 0
    if any("LockException" in line for line in tail):
        # a Snakemake not started by this front door (or whose front door was killed before it
        # recorded it) writes the same files
        prefix = f"{command_prefix()} sweep"
        status.say(f"sweep {name}: another Snakemake run holds the lock on {shown_path(workdir, cwd)}/ for the same "
                   f"files (started outside run.py); nothing was computed. If none runs (ps -ef | grep snakemake), "
                   f"remove its lock: {prefix} --unlock{resume[len(prefix):]}")
        return 2
    status.clear()
    print("\n".join(tail), flush=True)
    status.say(f"sweep {name}: failed (Snakemake exit status {code}) after {elapsed}; "
               f"full output: {shown}/logs/sweep.log")
    return code


def main() -> None:
    sys.exit(run(sys.argv[1:]))


if __name__ == "__main__":
    main()
