"""Integrate one chunk of the sweep in one process and write its chunk file.

The numba kernels are compiled with cache=True; a process loads (or, the first time on a
machine, compiles) them once, in `warm_up`, and then integrates every scene of the chunk, so no
scene pays for compilation and every scene's `wall_time` measures integration only.
"""
from __future__ import annotations

import collections
import json
import logging
import math
import time
import traceback
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path

from . import axes as _axes
from . import chunkfiles as _chunkfiles
from . import chunking as _chunking
from . import grid as _grid
from . import numerical_error as _numerical_error
from . import outcomes
from . import outputs as _outputs

log = logging.getLogger("sweep.batch")

# The warm-up integrates the chunk's first scene for this many steps: enough to pass through
# every kernel that a normal step uses (right-hand side, error control, event checks), far too
# few (~ms) to matter for the chunk's run time.
WARM_UP_STEPS = 50

_warmed_up = False


def simulate_function() -> Callable:
    """`sweep.simulate` (the function, also when `sweep.simulate` resolves to the module)."""
    import sweep

    fn = getattr(sweep, "simulate", None)
    if fn is None or not callable(fn):
        from . import simulate as module  # the module of the same name
        fn = module.simulate
    return fn


def warm_up(scene: Mapping, simulate: Callable | None = None) -> float:
    """Load/compile the numba kernels once per process with a short run of `scene`.

    Returns the time it took in s (0.0 if this process was already warm).
    """
    global _warmed_up
    if _warmed_up:
        return 0.0
    simulate = simulate or simulate_function()
    short = dict(scene)
    short["stop"] = dict(scene["stop"], max_steps=WARM_UP_STEPS)
    t0 = time.perf_counter()
    try:
        simulate(short)
    except Exception:  # the real run of the same scene records the error; warm-up only compiles
        log.debug("warm-up scene raised:\n%s", traceback.format_exc())
    _warmed_up = True
    return time.perf_counter() - t0


def _summary_or_none(scene: Mapping, simulate: Callable, what: str) -> dict | None:
    try:
        return dict(simulate(scene).summary)
    except Exception:
        log.error("%s of scene %s raised; recorded as numerical_error:\n%s",
                  what, _chunking.canonical_json(scene), traceback.format_exc())
        return None


def run_scene(scene: Mapping, n_levels: int, simulate: Callable | None = None,
              reference_scene: Mapping | None = None) -> dict:
    """The summary of one scene; an exception becomes outcome NUMERICAL_ERROR with NaNs.

    `reference_scene`: the same scene with the tolerances of the error bars' rerun (settings from
    `sweep.numerical_error.error_reference`); when given, it is run too and the summary gets
    `<name>_numerical_error` and `reference_outcome` (`sweep.numerical_error.add_numerical_errors`).
    A failed rerun leaves the main result as it is: its errors are NaN and reference_outcome says why.
    """
    simulate = simulate or simulate_function()
    t0 = time.perf_counter()
    summary = _summary_or_none(scene, simulate, "run")
    if summary is None:
        summary = _outputs.empty_summary(n_levels, outcomes.NUMERICAL_ERROR, time.perf_counter() - t0)
    if reference_scene is not None:
        reference = _summary_or_none(reference_scene, simulate, "error-estimate rerun")
        _numerical_error.add_numerical_errors(summary, reference)
    return summary


def chunk_from_spec(spec_json: str) -> _chunking.Chunk:
    """Rebuild a Chunk from its canonical spec JSON (the id is the spec's hash)."""
    spec = json.loads(spec_json)
    if _chunking.canonical_json(spec) != spec_json:
        raise ValueError("chunk spec is not in canonical JSON form")
    cid = _chunking.sha256_hex(spec_json)[:_chunking.CHUNK_ID_HEX]
    return _chunking.Chunk(cid, tuple(tuple(p) for p in spec["points"]), spec_json)


def run_chunk(chunk: _chunking.Chunk, out_path: str | Path, simulate: Callable | None = None) -> dict:
    """Integrate every scene of `chunk`, write the chunk file atomically, return run statistics.

    Logs one line per scene and a closing line with the rate in scenes/s.
    """
    simulate = simulate or simulate_function()
    spec = chunk.spec
    settings = spec["settings"]
    n_levels = len(settings["levels"])
    scenes = [_grid.scene(settings, p) for p in chunk.points]
    refs = ([_grid.scene(_numerical_error.error_reference(settings), p) for p in chunk.points]
            if settings.get("error_estimate", False) else [None] * len(scenes))
    t_warm = warm_up(scenes[0], simulate)
    log.info("chunk %s: %d scenes; warm-up %.2f s", chunk.id, len(scenes), t_warm)
    t0 = time.perf_counter()
    summaries, counts = [], collections.Counter()
    for i, (sc, ref) in enumerate(zip(scenes, refs), 1):
        s = run_scene(sc, n_levels, simulate, ref)
        summaries.append(s)
        counts[s["outcome"]] += 1
        elapsed = time.perf_counter() - t0
        log.info("chunk %s: %d/%d %s outcome=%s t_halt=%s s n_steps=%s wall=%.3f s (%.2f scenes/s)",
                 chunk.id, i, len(scenes), dict(zip(_axes.AXES, chunk.points[i - 1])), s["outcome"],
                 f"{s['t_halt']:.6g}" if isinstance(s["t_halt"], float) and math.isfinite(s["t_halt"]) else "nan",
                 s["n_steps"], s["wall_time"],
                 i / elapsed if elapsed > 0 else math.inf)
    elapsed = time.perf_counter() - t0
    _chunkfiles.write_chunk(chunk, summaries, out_path)
    rate = len(scenes) / elapsed if elapsed > 0 else math.inf
    log.info("chunk %s done: %d scenes in %.2f s (%.2f scenes/s); outcomes %s",
             chunk.id, len(scenes), elapsed, rate, dict(counts))
    return {"id": chunk.id, "n": len(scenes), "seconds": elapsed, "scenes_per_s": rate,
            "warm_up_s": t_warm, "outcomes": dict(counts)}


def setup_logging(log_path: str | Path | None = None) -> None:
    """Log INFO lines to stderr and, if given, to `log_path` (Snakemake's rule log)."""
    handlers: list[logging.Handler] = [logging.StreamHandler()]
    if log_path:
        Path(log_path).parent.mkdir(parents=True, exist_ok=True)
        handlers.append(logging.FileHandler(log_path, mode="w", encoding="utf-8"))
    logging.basicConfig(level=logging.INFO, handlers=handlers, force=True,
                        format="%(asctime)s %(levelname)s %(message)s")


def run_chunk_job(spec_json: str, expected_id: str, out_path: str | Path,
                  log_path: str | Path | None = None) -> dict:
    """Entry point of the Snakemake job `simulate_chunk` (workflow/scripts/simulate_chunk.py)."""
    setup_logging(log_path)
    chunk = chunk_from_spec(spec_json)
    if chunk.id != expected_id:
        raise ValueError(f"chunk spec hashes to {chunk.id}, but the job is for {expected_id}")
    return run_chunk(chunk, out_path)


def scenes_of(settings: Mapping, points: Sequence[Sequence[float]]) -> list[dict]:
    """Scene dicts of grid points (AXES order), e.g. to re-run points one by one."""
    return [_grid.scene(settings, tuple(p)) for p in points]
