"""The split of a sweep's grid into chunks, one Snakemake job each, and their identity.

A chunk's identity is the SHA-256 of the canonical JSON of its content (the point values, every
setting that changes a scene's result, and a fingerprint of the physics core's source). So a chunk
file is reused exactly when its scenes would be recomputed identically, whatever the position of
its points in the axes.

Chunk layout (see docs/pipeline.md, "How reruns work"):

* A chunk never mixes values of the *outer* axes (mu_d, k1, k2, k3; sweep.axes.OUTER_AXES): adding a
  value to one of these axes, anywhere in it, adds whole new chunks and leaves every existing one
  untouched.
* For one outer point, the *inner* points (alpha0, omega0; sweep.axes.INNER_AXES), in row-major order
  of the sorted axes, are cut by content-defined chunking: a chunk ends after the inner point p when
  ``H(p) % chunk_size == 0`` (H: a hash of p's values only) or when it has reached
  ``2 * chunk_size`` points. Inserting a value into alpha0 or omega0 therefore changes only the
  chunks around the new points (until the next content-defined cut), instead of shifting every
  later chunk as a positional split would.

Points are tuples in sweep.axes.AXES order, SI units (m, rad, rad/s; friction coefficients
dimensionless).
"""
from __future__ import annotations

import copy
import hashlib
import itertools
import json
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from . import outputs as _outputs
from .axes import AXES, INNER_AXES, OUTER_AXES
from .core.jit import kernel_sources, sources_digest


# Length of the hex chunk id: 16 hex digits = 64 bits, so a collision among even 10^6 chunks
# has probability ~ n^2 / 2^65 < 3e-8.
CHUNK_ID_HEX = 16


def canonical_json(obj: Any) -> str:
    """Canonical JSON text: sorted keys, no whitespace, floats in Python's shortest repr.

    NaN and infinities are refused (they have no JSON form and never belong in a valid config).
    """
    return json.dumps(obj, sort_keys=True, separators=(",", ":"), allow_nan=False)


def sha256_hex(text: str) -> str:
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def scene_settings(settings: Mapping) -> dict:
    """The part of a normalised config that, with the point values, fixes a chunk's content.

    `error_estimate: true` (outputs.error_estimate: each scene is rerun at tighter tolerances and
    the chunk holds the differences) is part of it; it is left out when false, so switching the
    option off reuses the chunks computed without it.
    """
    part = {k: copy.deepcopy(settings[k]) for k in ("disk", "gravity", "mu_s", "levels", "solver", "stop")}
    if settings.get("outputs", {}).get("error_estimate", False):
        part["error_estimate"] = True
    return part


@dataclass(frozen=True)
class Chunk:
    """One job's worth of scenes. `points` are tuples in AXES order (SI units)."""
    id: str
    points: tuple[tuple[float, ...], ...]
    spec_json: str    # canonical JSON of {format, settings, axes, points}: hashed into `id`

    @property
    def spec(self) -> dict:
        return json.loads(self.spec_json)


def _inner_hash(inner: tuple[float, ...]) -> int:
    return int(sha256_hex(canonical_json(list(inner)))[:16], 16)


def split_inner(inner_points: list[tuple[float, ...]], chunk_size: int) -> list[list[tuple[float, ...]]]:
    """Content-defined cut of a sequence of inner points into blocks of 1..2*chunk_size.

    A block ends after p if hash(p) % chunk_size == 0 (expected block length chunk_size) or
    when it holds 2*chunk_size points (the cap bounds a job's size; the layout resynchronises
    at the next content-defined cut, so an insertion changes only nearby blocks).
    """
    blocks: list[list[tuple[float, ...]]] = []
    cur: list[tuple[float, ...]] = []
    for p in inner_points:
        cur.append(p)
        if _inner_hash(p) % chunk_size == 0 or len(cur) >= 2 * chunk_size:
            blocks.append(cur)
            cur = []
    if cur:
        blocks.append(cur)
    return blocks


# What decides a scene's result: the physics core package and the modules that turn a scene file
# into kernel inputs and a summary. Front ends, plots and the pipeline's own modules are not in it
# (chunk files carry CHUNK_FORMAT for those), so editing them does not recompute chunks.
# the modules besides the kernels (core.jit.kernel_sources) whose change gives every chunk a new
# identity: they turn a scene into the kernel's inputs and its outputs into the summary
CHUNK_MODULES = ("fields.py", "scene.py", "simulate.py", "diagnostics.py")


def core_fingerprint() -> str:
    """SHA-256 (core.jit.sources_digest) of the sources a chunk's numbers come from: the kernels'
    and CHUNK_MODULES, so that a change of any gives every chunk a new identity."""
    pkg = Path(__file__).resolve().parent
    return sources_digest(kernel_sources(pkg) + tuple(pkg / m for m in CHUNK_MODULES), root=pkg)


def chunk_id_of(settings_part: Mapping, points: list[tuple[float, ...]],
                core: str | None = None) -> tuple[str, str]:
    """(id, canonical spec JSON) of a chunk; `core` defaults to core_fingerprint()."""
    spec = {"format": _outputs.CHUNK_FORMAT, "core": core if core is not None else core_fingerprint(),
            "settings": settings_part, "axes": list(AXES), "points": [list(p) for p in points]}
    text = canonical_json(spec)
    return sha256_hex(text)[:CHUNK_ID_HEX], text


def plan_chunks(settings: Mapping) -> dict[str, Chunk]:
    """All chunks of a normalised config, keyed by id, in grid order."""
    part = scene_settings(settings)
    core = core_fingerprint()
    g = settings["grid"]
    inner = list(itertools.product(*(g[a] for a in INNER_AXES)))
    blocks = split_inner(inner, settings["chunk_size"])
    chunks: dict[str, Chunk] = {}
    for outer in itertools.product(*(g[a] for a in OUTER_AXES)):
        for block in blocks:
            points = [tuple(outer) + tuple(p) for p in block]
            cid, text = chunk_id_of(part, points, core)
            chunks[cid] = Chunk(cid, tuple(points), text)
    return chunks
