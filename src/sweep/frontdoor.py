"""`python3 run.py sweep [snakemake args...]`: Snakemake as a user meets it.

* results per config: the sweep's folder is `results/<name>/` (`sweep.grid.sweep_name`); the
  whole Snakemake output of the run is appended to `results/<name>/logs/sweep.log`;
* one progress line (scenes done / total, scenes/s, ETA, Snakemake jobs) instead of Snakemake's
  and the jobs' own output; per-scene lines stay in the chunk logs;
* the numba kernels are compiled (or loaded from their cache) once, here, before any job, with
  a message when a compilation is due;
* Ctrl-C (SIGINT) and SIGTERM stop the run and print one line: what was kept and the exact
  command that resumes it. Snakemake runs in its own session, so the terminal's Ctrl-C reaches
  this process only; it is passed on as one SIGINT to Snakemake's process group (Snakemake and
  its jobs), whose output (tracebacks of the interrupted jobs and kernels included) goes to the
  log; every process of that group is gone before this one exits, so nothing prints afterwards;
* `-j2` is added only when neither the arguments nor a `--profile` set `jobs`/`cores`, and
  `--rerun-incomplete` always (a chunk job is idempotent and writes atomically), so the resume
  command is the command that was interrupted.

Options that only inform or maintain (`-n`, `--unlock`, `--lint`, `--list...`, `--help`, ...)
run Snakemake with its own output, as does `--verbose`/`--debug`.
"""
from __future__ import annotations

import collections
import contextlib
import io as _stdio
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

RESUME_PREFIX = "python3 run.py sweep"
DEFAULT_JOBS = "2"
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
EXPECTED_COMPILE_S = "up to 90 s"  # measured: 21 s alone, ~50 s on a loaded 2-core machine
SIGNAL_GRACE_S = 60.0            # after the forwarded SIGINT, before SIGKILL


# ------------------------------------------------------------------------------------- arguments

def parsed_args(argv: list[str]):
    """Snakemake's own parse of `argv` (profile defaults applied), or None if it rejects it."""
    from snakemake.cli import parse_args

    with contextlib.redirect_stderr(_stdio.StringIO()), contextlib.redirect_stdout(_stdio.StringIO()):
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


def locations(argv: list[str]) -> tuple[Path, Path]:
    """(working directory, config file whose name names the results folder) of a run."""
    args = parsed_args(argv)
    workdir = Path(args.directory).resolve() if args is not None and args.directory else Path.cwd()
    if args is not None and args.configfile:
        return workdir, Path(args.configfile[-1]).absolute()
    from . import grid

    return workdir, workdir / grid.DEFAULT_CONFIG


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


def warm_numba(say) -> None:
    """Compile (or load) the kernels once in this process, so the jobs find them cached."""
    import copy

    from . import batch
    from .scene import DEFAULTS

    cold = numba_cache_cold()
    if cold:
        say("numba: compiling the integrator's kernels (the kernel sources changed or were never "
            f"compiled); this happens once after a change of src/sweep/core and takes {EXPECTED_COMPILE_S} ...")
    t0 = time.monotonic()
    batch.warm_up(copy.deepcopy(DEFAULTS))
    prune_numba_caches()
    if cold:
        say(f"numba: kernels compiled and cached in {time.monotonic() - t0:.0f} s")


# ------------------------------------------------------------------------------------- progress

def _clock(seconds: float) -> str:
    s = int(round(seconds))
    return f"{s // 3600}:{s % 3600 // 60:02d}:{s % 60:02d}" if s >= 3600 else f"{s // 60}:{s % 60:02d}"


class Progress:
    """Scenes done / total from the run's plan (written by the workflow when it is parsed), the
    chunk files and the chunk logs; steps from Snakemake's output."""

    def __init__(self, results: Path, t_start: float):
        self.results = results
        self.t_start = t_start          # time.time() when the run started
        self.plan: dict[str, int] | None = None
        self.total = 0
        self.kept_at_start = 0
        self.first_seen: tuple[float, int] | None = None   # (time, done) when scenes started to come in
        self.last_seen: tuple[float, int] | None = None    # (time, done) at the latest increase
        self.finished: set[str] = set()
        self.steps: tuple[int, int] | None = None

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

    def chunks_present(self) -> set[str]:
        return {cid for cid in (self.plan or {}) if (self.results / "chunks" / f"{cid}.nc").is_file()}

    def chunks_kept(self, workdir: Path) -> set[str]:
        """Chunk files a resumed run keeps: present, and not marked incomplete by Snakemake (a
        job that was stopped after writing its file but before Snakemake recorded it)."""
        marked = incomplete_outputs(workdir)
        return {cid for cid in self.chunks_present()
                if (self.results / "chunks" / f"{cid}.nc").resolve() not in marked}

    def done(self) -> int | None:
        if self.plan is None:
            self._load_plan()
            if self.plan is None:
                return None
            self.finished = self.chunks_present()
            self.kept_at_start = sum(self.plan[c] for c in self.finished)
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

    def line(self, name: str, now: float) -> str:
        done = self.done()
        elapsed = now - self.t_start
        parts = [f"sweep {name}:"]
        if done is None:
            parts.append("preparing (validating the config, planning chunks)")
        else:
            pct = 100.0 * done / self.total if self.total else 100.0
            parts.append(f"{done}/{self.total} scenes ({pct:.0f}%)")
            if done > self.kept_at_start and self.first_seen is None:
                self.first_seen = (now, done)
            if self.last_seen is None or done > self.last_seen[1]:
                self.last_seen = (now, done)
            first, last = self.first_seen, self.last_seen
            if first is not None and last[0] > first[0] and last[1] > first[1]:
                # over the scenes seen so far; frozen once they are all done (gather, figures)
                rate = (last[1] - first[1]) / (last[0] - first[0])
                parts.append(f"{rate:.2f} scenes/s")
                if done < self.total:
                    parts.append(f"ETA {_clock((self.total - done) / rate)}")
            if self.steps:
                parts.append(f"jobs {self.steps[0]}/{self.steps[1]}")
        parts.append(_clock(elapsed))
        return parts[0] + " " + " | ".join(parts[1:])


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


def run(argv: list[str]) -> int:
    if is_raw(argv):
        cmd = [sys.executable, "-m", "snakemake", *snakemake_argv(argv, progress=False)]
        try:
            return subprocess.run(cmd).returncode
        except KeyboardInterrupt:
            return 130

    from . import grid

    interactive = sys.stdout.isatty()
    resume = " ".join([RESUME_PREFIX, *map(shlex.quote, argv)])
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

    def say(text: str) -> None:
        print(("\r\033[K" if interactive else "") + text, flush=True)

    try:
        workdir, configfile = locations(argv)
        try:
            name = grid.sweep_name(configfile)
        except grid.SweepConfigError as err:
            say(f"sweep: {err}")
            return 2
        results = workdir / "results" / name
        shown = str(results.relative_to(Path.cwd())) if results.is_relative_to(Path.cwd()) else str(results)
        try:
            warm_numba(say)
        except _Stop:
            raise
        except Exception as exc:  # noqa: BLE001 - the jobs will report the same problem in full
            say(f"numba: warm-up failed ({type(exc).__name__}: {exc}); the jobs will try again")
        log_path = results / "logs" / "sweep.log"
        log_path.parent.mkdir(parents=True, exist_ok=True)
        t_start = time.time()
        t_locks = t_start - 1.0      # file times may be rounded down to the second
        cmd = [sys.executable, "-m", "snakemake", *snakemake_argv(argv, progress=True)]
        log = open(log_path, "a", encoding="utf-8")
        log.write(f"=== {time.strftime('%Y-%m-%d %H:%M:%S')} {resume}\n=== {shlex.join(cmd)}\n")
        log.flush()
        proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                stdin=subprocess.DEVNULL, start_new_session=True,
                                text=True, errors="replace", bufsize=1)
        state["proc"] = proc
    except _Stop:
        say(f"sweep: interrupted before the sweep started; nothing was computed. Run again: {resume}")
        return 128 + state["signal"]

    progress = Progress(results, t_start)
    tail: collections.deque[str] = collections.deque(maxlen=60)
    flags = {"nothing": False}

    def read() -> None:
        for text in proc.stdout:
            log.write(text)
            log.flush()   # `tail -f results/<name>/logs/sweep.log` follows the run
            m = STEPS.search(text)
            if m:
                progress.steps = (int(m.group(1)), int(m.group(2)))
            if NOTHING in text:
                flags["nothing"] = True
            if not JOB_LOG_LINE.match(text):
                tail.append(text.rstrip("\n"))
        log.flush()

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    last_line, last_print = "", 0.0
    deadline = None
    while proc.poll() is None:
        time.sleep(0.25)
        if state["signal"] is not None:
            deadline = deadline or time.monotonic() + SIGNAL_GRACE_S
            if time.monotonic() > deadline:
                _killpg(proc.pid, signal.SIGKILL)
            continue
        now = time.time()
        text = progress.line(name, now)
        key = text.rsplit(" | ", 1)[0]
        if interactive:
            if now - last_print >= 0.5:
                print("\r\033[K" + text, end="", flush=True)
                last_print = now
        elif key != last_line and now - last_print >= 10.0:
            print(text, flush=True)
            last_line, last_print = key, now
    _end_group(proc.pid)
    reader.join(timeout=10)
    log.close()
    code = proc.returncode
    elapsed = _clock(time.time() - t_start)

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
        again = f"{RESUME_PREFIX} --unlock{resume[len(RESUME_PREFIX):]} && {resume}" if locked else resume
        what = (f"kept {kept} of {progress.total} scenes ({len(present)} of {len(plan)} chunk files) "
                f"in {shown}/chunks/" if plan else "nothing was computed yet")
        say(f"sweep {name}: interrupted ({signal.Signals(state['signal']).name}) after {elapsed}; "
            f"{what}; resume with: {again}")
        return 128 + state["signal"]
    if code == 0:
        if flags["nothing"]:
            say(f"sweep {name}: nothing to do, {shown}/ is up to date ({shown}/cube.nc, {shown}/figures/)")
        else:
            done = progress.done() or 0
            say(f"sweep {name}: done in {elapsed}: {done} scenes ({done - progress.kept_at_start} computed now); "
                f"{shown}/cube.nc, {shown}/figures/; Snakemake's output: {shown}/logs/sweep.log")
        return 0
    if interactive:
        print("\r\033[K", end="")
    print("\n".join(tail), flush=True)
    say(f"sweep {name}: failed (Snakemake exit status {code}) after {elapsed}; "
        f"full output: {shown}/logs/sweep.log")
    return code


def main() -> None:
    sys.exit(run(sys.argv[1:]))


if __name__ == "__main__":
    main()
