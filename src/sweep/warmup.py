"""The numba kernels compiled (or loaded from their cache) once, before any job: whether the cache
is cold, a compilation shown with its ticking elapsed time and the estimate COMPILE_ESTIMATE, and
the cache folders of earlier kernel sources pruned.
"""
from __future__ import annotations

import shutil
import sys
import time
from pathlib import Path

from .progress import StatusLine, clock, ticking


# The kernels' compilation (docs/pipeline.md, "Running"): measured on 2-core machines shared with
# other work: 75 s to 213 s on a fresh clone.
COMPILE_ESTIMATE = "usually 1-4 min on a 2-core machine, by how busy it is"


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
        with ticking(status, lambda s: f"{label} | {clock(s)}"):
            batch.warm_up(copy.deepcopy(DEFAULTS))
    else:
        batch.warm_up(copy.deepcopy(DEFAULTS))
    prune_numba_caches()
    if cold:
        took = time.monotonic() - t0
        status.say(f"numba: kernels compiled and cached in {clock(took)}")
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
