"""The hierarchical surplus of an adaptive map and what it says of a cell (sweep.lattice).

A cell is refined when

* its corners differ in outcome (a boundary of the outcome map runs through it), or one of them
  failed numerically (sweep.outcomes FAILED), or
* its interpolation error estimate, for one of the driving outputs, exceeds the tolerance;

unless its error does not fall as the cells shrink (ROUGH): structure finer than the lattice,
where refining buys nothing, reported as rough.

The error estimate is the hierarchical surplus: a node computed at round k is also predicted by
multilinear interpolation from the corners of the cell of round k - 1 it lies in (log values for
positive times and frequencies); the difference, |surplus|, is what interpolation at the coarser
stride missed there (in the output's interpolation space: its units, or log units). For a smooth
function it falls 4x per halving (second order); a cell's error, for planning, is the largest
surplus at its own corners (`cell_error`). Round 0's nodes get surpluses too, against the lattice
of stride 2S (every other node of round 0).
"""
from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from . import outcomes
from .lattice import Fields, Lattice, Settings, cell_lower, corner_index, flat_index, multilinear, node_round


# Outcomes that are a numerical failure, not physics: the cells around them are refined.
FAILED = frozenset({outcomes.STEP_LIMIT, outcomes.STEP_SIZE_UNDERFLOW, outcomes.NUMERICAL_ERROR, outcomes.NOT_RUN})


# The planning estimate of a cell's error: its corners' |surplus| (the error at twice its side)
# times KAPPA: second-order interpolation errs 1/4 of the surplus at most in the limit, KAPPA =
# 1/2 is that with a factor 2 of margin. (The map's error bars are calibrated: sweep.errorbars.)
KAPPA = 0.5


# A cell is rough when its error fell by less than 1/ROUGH_RATIO per halving over the last two
# (its grandparent's error over its own below 1/ROUGH_RATIO^2 = 4); a smooth function's falls 4x
# per halving, 16x over two. One halving is not evidence enough: the ratio of two maxima of a few
# surpluses scatters by 2x in smooth regions too, and a region judged rough at stride 4 on one
# halving errs ~4x less at stride 2 (benchmarks/adaptive_map.py).
ROUGH_RATIO = 0.5


def surpluses(lat: Lattice, f: Fields, name: str) -> np.ndarray:
    """|surplus| of output `name` at every computed node (size, m), in its interpolation space:
    |value - multilinear prediction from the corners of the next coarser cell holding it|; for a node of
    the virtual stride-2S lattice, the largest |second difference| at stride S along an axis (the
    same quantity for a node halfway along an edge). NaN where there is none: a corner not
    computed, a value missing, or a corner of another outcome (an outcome boundary is not a
    smoothness)."""
    g = f.transformed(name)
    out = np.full(g.shape, np.nan)
    all_nodes = np.array(np.unravel_index(np.arange(lat.size), lat.shape)).T
    rounds = node_round(lat, all_nodes)
    for k in range(0, lat.rounds + 1):
        sel = np.nonzero((rounds == k) & f.computed)[0]
        if not sel.size:
            continue
        nodes = all_nodes[sel]
        s = lat.stride(k - 1)
        lower = cell_lower(lat, nodes, s)
        corners, w = multilinear(lat, nodes, lower, s)
        cidx = flat_index(lat, corners.reshape(-1, lat.ndim)).reshape(corners.shape[:2])
        used = w > 0
        ok = np.where(used, f.computed[cidx] & (f.outcome[cidx] == f.outcome[sel][:, None]), True).all(axis=1)
        gv = g[cidx]                                                  # (n, 2^d, m)
        with np.errstate(invalid="ignore"):
            pred = np.einsum("nc,ncm->nm", w, np.where(used[:, :, None], gv, 0.0))
            bad = np.where(used[:, :, None], ~np.isfinite(gv), False).any(axis=1)
            sur = np.abs(g[sel] - pred)
        sur[bad | ~ok[:, None]] = np.nan
        out[sel] = sur
    # the virtual lattice's nodes: the largest second difference along an axis at stride S
    sel = np.nonzero((rounds == -1) & f.computed)[0]
    s = lat.stride(0)
    for a in range(lat.ndim):
        nodes = all_nodes[sel]
        inside = (nodes[:, a] >= s) & (nodes[:, a] + s < lat.shape[a])
        if not inside.any():
            continue
        i = sel[inside]
        step = np.zeros(lat.ndim, np.int64)
        step[a] = s
        lo, hi = flat_index(lat, nodes[inside] - step), flat_index(lat, nodes[inside] + step)
        ok = f.computed[lo] & f.computed[hi] & (f.outcome[lo] == f.outcome[i]) & (f.outcome[hi] == f.outcome[i])
        with np.errstate(invalid="ignore"):
            sur = np.abs(g[i] - 0.5 * (g[lo] + g[hi]))
        sur[~ok] = np.nan
        out[i] = np.fmax(out[i], sur)
    return out


def cell_error(lat: Lattice, level: int, lower: np.ndarray, sur: np.ndarray) -> np.ndarray:
    """A cell's error at its level: the largest |surplus| of its corners computed at that level
    (the others are the parent's; at level 0 every corner), per component (n, m); NaN where none
    has one."""
    cidx = corner_index(lat, lower, lat.stride(level))
    nodes = np.array(np.unravel_index(cidx.ravel(), lat.shape)).T
    r = node_round(lat, nodes)
    own = ((r == level) | ((level == 0) & (r == -1))).reshape(cidx.shape)
    v = np.where(own[:, :, None], sur[cidx], np.nan)
    with np.errstate(all="ignore"):
        import warnings
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            return np.nanmax(v, axis=1)


def parent_lower(lat: Lattice, level: int, lower: np.ndarray) -> np.ndarray:
    return cell_lower(lat, lower, lat.stride(level - 1))


def _scale(f: Fields, name: str) -> float:
    """What a driving output's error is measured against: 1 for log outputs (relative), the
    range of its values over the map otherwise (1 where it has none)."""
    if f.is_log(name):
        return 1.0
    v = f.values[name][f.computed]
    v = v[np.isfinite(v)]
    rng = float(v.max() - v.min()) if v.size else 0.0
    return rng if rng > 0 else 1.0


def driving_error(lat: Lattice, f: Fields, st: Settings, level: int, lower: np.ndarray,
                  surs: Mapping[str, np.ndarray]) -> np.ndarray:
    """Per cell, the largest error of the driving outputs, in units of their tolerance (NaN: none)."""
    errs = []
    for name in st.outputs:
        e = cell_error(lat, level, lower, surs[name]) / (_scale(f, name) * st.tolerance)
        errs.append(e)
    e = np.concatenate(errs, axis=1) if errs else np.full((len(lower), 1), np.nan)
    import warnings
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        return np.nanmax(e, axis=1)


def cell_states(lat: Lattice, f: Fields, st: Settings, level: int, lower: np.ndarray,
                surs: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
    """For the cells of `level` at `lower`: disagree (corner outcomes differ), failed (a corner
    failed), error (driving error in tolerances, times KAPPA: the bar), ratio (error / the
    parent's, NaN at level 0), rough (level >= 2: over the last two halvings the error fell by
    less than 1/ROUGH_RATIO^2, and the cell would be refined for it)."""
    cidx = corner_index(lat, lower, lat.stride(level))
    oc = f.outcome[cidx]
    disagree = (oc != oc[:, :1]).any(axis=1)
    failed = np.isin(oc, list(FAILED)).any(axis=1)
    e = driving_error(lat, f, st, level, lower, surs)
    ratio = np.full(len(lower), np.nan)
    rough = np.zeros(len(lower), bool)
    if level >= 1:
        pl = parent_lower(lat, level, lower)
        ep = driving_error(lat, f, st, level - 1, pl, surs)
        with np.errstate(all="ignore"):
            ratio = e / ep
        if level >= 2:
            gl = parent_lower(lat, level - 1, pl)
            eg = driving_error(lat, f, st, level - 2, gl, surs)
            with np.errstate(all="ignore"):
                rough |= (e > ROUGH_RATIO ** 2 * eg) & (KAPPA * e > 1.0)
    return {"disagree": disagree, "failed": failed, "error": KAPPA * e, "ratio": ratio, "rough": rough}
