"""Atomic file writes: a temporary name in the target's folder, fsync'ed, then os.replace'd over
the target, so a reader never sees a partial file under the final name (a chunk file, the cube,
a plan or a round file).
"""
from __future__ import annotations

import os
import uuid
from collections.abc import Callable, Mapping
from pathlib import Path


def _fsync_path(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def write_file_atomic(path: str | Path, write: Callable[[Path], None],
                      finish: Callable[[Path], None] | None = None) -> Path:
    """Make the file at `path` atomically: `write(tmp)` writes a temporary file in the same
    directory, `finish(tmp)` may amend it (e.g. add a checksum), then fsync and os.replace; on any
    error the temporary file is removed and `path` is untouched."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.parent / f".{path.name}.tmp-{os.getpid()}-{uuid.uuid4().hex[:8]}"
    try:
        write(tmp)
        if finish is not None:
            finish(tmp)
        _fsync_path(tmp)
        os.replace(tmp, path)
        _fsync_path(path.parent)  # make the rename itself durable
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return path


def write_atomic(ds, path: str | Path, encoding: Mapping | None = None,
                 finish: Callable[[Path], None] | None = None) -> Path:
    """Write the xarray Dataset `ds` to netCDF-4 at `path` atomically (write_file_atomic)."""
    return write_file_atomic(
        path, lambda tmp: ds.to_netcdf(tmp, engine="netcdf4", format="NETCDF4", encoding=dict(encoding or {})),
        finish)


def write_text_atomic(path: str | Path, text: str) -> Path:
    """Write a text file atomically (a temporary name in its folder, then os.replace)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.parent / f".{path.name}.tmp-{os.getpid()}-{uuid.uuid4().hex[:8]}"
    try:
        tmp.write_text(text, encoding="utf-8")
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return path
