"""`python3 run.py sweep [snakemake args...]`: Snakemake as a user meets it.

* paths on the command line (`--configfile`, `--snakefile`, `--directory`, a `--profile` folder)
  are taken relative to the directory the user stands in, and messages show them as given;
  Snakemake itself runs in the project root (where the Snakefile is) unless `--directory` says
  otherwise, so results go to `<project>/results/<name>/` from wherever it is started;
* the config is read and validated before Snakemake starts, by the code the workflow runs
  (`sweep.grid.load_sweep`): an invalid config gives one line per invalid field, naming its file,
  and exit status 2, and nothing is created under results/;
* results per config: the sweep's folder is `results/<name>/` (`sweep.configfiles.sweep_name`); the
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

Here: the run (`run`: validation, the lock, Snakemake in its own session, the closing line and exit
status). Its parts: the command line as Snakemake reads it (sweep.snakemake_args), the numba
warm-up (sweep.warmup), the progress line (sweep.progress) and the run's lock (sweep.runlock).
"""
from __future__ import annotations

import collections
import math
import os
import re
import shlex
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

from . import grid, validation
from .progress import Progress, StatusLine, clock
from .runlock import (already_running, note_snakemake, release_own_locks, release_run_lock, running_run,
                      take_run_lock)
from .snakemake_args import (DEFAULT_JOBS, HELP_OPTIONS, PROJECT_ROOT, absolute_paths, command_prefix, config_files,
                             is_raw, parsed_args, shown_path, snakemake_argv)
from .warmup import warm_numba


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


# per-scene lines of sweep.batch ("<date> INFO chunk <id>: i/n ...") and other job logging:
# kept in the chunk logs and in sweep.log, never shown on the console
JOB_LOG_LINE = re.compile(r"^\d{4}-\d\d-\d\d \d\d:\d\d:\d\d,\d+ (DEBUG|INFO|WARNING) ")
NOTHING = "Nothing to be done"
SIGNAL_GRACE_S = 60.0            # after the forwarded SIGINT, before SIGKILL


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
    except validation.SweepConfigError as err:
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
    elapsed = clock(time.time() - t_origin)

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
