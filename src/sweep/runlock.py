"""One run per config at a time: the lock `results/<name>/.running` (RUN_LOCK: the run's pid, host,
start time and command, the pid of its Snakemake), taken atomically, taken over when its process
is gone, and the one line that refuses a second run; and the Snakemake locks a stopped run of this
front door left behind.
"""
from __future__ import annotations

import contextlib
import json
import os
import time
from pathlib import Path

from .progress import clock


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
    return (f"sweep {name}: already running since {since} ({clock(max(time.time() - started, 0.0))} ago; "
            f"pid {run.get('pid')} on {run.get('host')}: {run.get('command')}), writing {shown}/; {what}. "
            f"Wait for it, or stop it: kill -INT {run.get('pid')} (or Ctrl-C in its terminal)")
