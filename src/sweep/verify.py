"""Verification of chunk files before they are reused or gathered: the checksum over the values
read, the variables present, and the chunk's id, spec, points and levels against the plan; a damaged
file is moved to <chunks>/quarantine/ (with its reason) so that Snakemake computes it again.
"""
from __future__ import annotations

import datetime as _dt
import json
import os
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from . import chunking as _chunking
from .cf import variables
from .chunkfiles import checksum_of


def read_chunk_file(path: str | Path, chunk: _chunking.Chunk | None = None,
                    expect_id: str | None = None) -> tuple[str | None, dict[str, np.ndarray]]:
    """(None, every variable's raw values) if the chunk file is intact (and matches `chunk`), else
    (the reason it is not, {}). One read of the file: the checksum is taken over the values read.
    `expect_id` instead of `chunk`: the file's id attribute and the hash of its spec must both be
    that id (the plan's chunks are named by the hash of their spec, so this is the same check
    without the plan's spec texts at hand)."""
    import netCDF4

    path = Path(path)
    try:
        if path.stat().st_size == 0:
            return "empty file", {}
        with netCDF4.Dataset(path, "r") as nc:
            attrs = {k: nc.getncattr(k) for k in nc.ncattrs()}
            sizes = {k: len(v) for k, v in nc.dimensions.items()}
            nc.set_auto_maskandscale(False)
            arrays = {name: np.asarray(v[...]) for name, v in nc.variables.items()}
        names = set(arrays)
        want = attrs.get("sweep_checksum")
        if want is None:
            return "no sweep_checksum attribute (incomplete write)", {}
        if checksum_of(arrays) != want:
            return "checksum mismatch (damaged data)", {}
        try:
            with_errors = bool(json.loads(attrs.get("sweep_chunk_spec", "{}"))["settings"].get("error_estimate", False))
        except (ValueError, KeyError, TypeError, AttributeError):
            with_errors = False
        missing = [v.name for v in variables(with_errors) if v.name not in names]
        if missing:
            return f"missing variables {missing}", {}
        if chunk is not None:
            if attrs.get("sweep_chunk_id") != chunk.id:
                return f"chunk id {attrs.get('sweep_chunk_id')!r} != expected {chunk.id!r}", {}
            if attrs.get("sweep_chunk_spec") != chunk.spec_json:
                return "chunk spec differs from the expected one", {}
            if sizes.get("point") != len(chunk.points):
                return f"{sizes.get('point')} points, expected {len(chunk.points)}", {}
            if sizes.get("level") != len(chunk.spec["settings"]["levels"]):
                return "wrong number of levels", {}
        elif expect_id is not None:
            if attrs.get("sweep_chunk_id") != expect_id:
                return f"chunk id {attrs.get('sweep_chunk_id')!r} != expected {expect_id!r}", {}
            spec = attrs.get("sweep_chunk_spec", "")
            if _chunking.sha256_hex(spec)[:_chunking.CHUNK_ID_HEX] != expect_id:
                return "chunk spec differs from the expected one", {}
            if sizes.get("point") != len(json.loads(spec)["points"]):
                return f"{sizes.get('point')} points, expected {len(json.loads(spec)['points'])}", {}
    except (OSError, RuntimeError, ValueError, KeyError, IndexError) as exc:  # HDF5 damage surfaces as these
        return f"unreadable ({type(exc).__name__}: {exc})", {}
    return None, arrays


def verify_chunk(path: str | Path, chunk: _chunking.Chunk | None = None) -> str | None:
    """None if the chunk file is intact (and matches `chunk`), else the reason it is not."""
    return read_chunk_file(path, chunk)[0]


def quarantine(path: str | Path, reason: str) -> Path:
    """Move a damaged chunk file to <dir>/quarantine/ (kept for inspection) so it is recomputed."""
    path = Path(path)
    qdir = path.parent / "quarantine"
    qdir.mkdir(parents=True, exist_ok=True)
    stamp = _dt.datetime.now(_dt.timezone.utc).strftime("%Y%m%dT%H%M%S")
    target = qdir / f"{path.name}.{stamp}"
    os.replace(path, target)
    (qdir / f"{target.name}.reason").write_text(reason + "\n", encoding="utf-8")
    return target


VERIFIED_CACHE = ".verified.json"


def check_existing_chunks(chunk_dir: str | Path, chunks: Mapping[str, _chunking.Chunk],
                          act: bool = True) -> dict[str, str]:
    """Verify every existing chunk file of the plan; quarantine damaged ones if `act`.

    Returns {chunk_id: reason} for the damaged files (which Snakemake then sees as missing).
    A file that verified before and whose (size, mtime) has not changed since is not read
    again (cache `<chunk_dir>/.verified.json`), so a Snakemake call over 10^4 chunks costs
    10^4 stat calls, not 10^4 checksums; the gather still verifies every checksum.
    """
    bad: dict[str, str] = {}
    chunk_dir = Path(chunk_dir)
    cache_path = chunk_dir / VERIFIED_CACHE
    try:
        cache = json.loads(cache_path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        cache = {}
    fresh = {}
    for cid, chunk in chunks.items():
        p = chunk_dir / f"{cid}.nc"
        try:
            st = p.stat()
        except FileNotFoundError:
            continue
        stamp = [st.st_size, st.st_mtime_ns]
        if cache.get(cid) == stamp:
            fresh[cid] = stamp
            continue
        reason = verify_chunk(p, chunk)
        if reason is None:
            fresh[cid] = stamp
            continue
        bad[cid] = reason
        if act:
            quarantine(p, reason)
    if fresh != cache and chunk_dir.is_dir():
        tmp = chunk_dir / f".{VERIFIED_CACHE}.tmp-{os.getpid()}"
        tmp.write_text(json.dumps(fresh), encoding="utf-8")
        os.replace(tmp, cache_path)
    return bad
