"""The front door's progress line: one status line (rewritten in place on a terminal, a new line in
a log), and the run's progress (`Progress`: phase, scenes done / total, scenes/s, an ETA in seconds
over the phases still to come, Snakemake's jobs) from the run's plan, its chunk files and logs, and
Snakemake's output.
"""
from __future__ import annotations

import collections
import contextlib
import json
import math
import re
import sys
import threading
import time
from pathlib import Path

from .snakemake_args import DEFAULT_JOBS


STEPS = re.compile(r"(\d+) of (\d+) steps \(\d+%\) done")
JOB_START = re.compile(r"^(?:local)?rule (\w+):")
JOB_ID = re.compile(r"^\s+jobid: (\d+)")
JOB_DONE = re.compile(r"^Finished jobid: (\d+) \(Rule: (\w+)\)")
JOB_STATS = re.compile(r"^(\w+)\s+(\d+)$")


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


def clock(seconds: float) -> str:
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
                parts.append(f"ETA {'at least ' if eta[1] else ''}{clock(eta[0])}")
            if self.steps:
                parts.append(f"jobs {self.steps[0]}/{self.steps[1]}")
        parts.append(clock(now - self.t_origin))
        return " | ".join(parts)


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
