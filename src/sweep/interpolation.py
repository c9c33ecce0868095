"""What a node of an adaptive map that is not computed gets from the finest cell holding it.

Pure numpy (sweep.lattice). A node not computed lies in the finest cell that exists around it
(`sweep.lattice.leaf_of`). Its outcome is that of the cell's nearest corner (largest multilinear
weight; ties: the first corner in lexicographic order); each continuous output is interpolated
multilinearly in its interpolation space (log for positive times and frequencies) from the corners
with that outcome and a value, and has none where the nearest corner has none. Beside the
estimate, each node gets an *error scale* in the same space (`error_scale`): what its error is
expected to grow with, known before the node is (or is not) computed. sweep.refine draws the
hold-out by it, sweep.reconstruct splits the nodes into quiet and loud by it; one function serves
both, so the two agree node for node.
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from .errorbars import bar_indicator
from .lattice import Fields, Lattice, flat_index, leaf_of, multilinear


# The error scale of a node: its cell's bar_indicator (the surpluses at the cell's level around
# it: the map's curvature there, what multilinear interpolation errs by) plus SPREAD_WEIGHT times
# the spread of the corner values it is interpolated from (a bound on the error of a monotone
# output between its corners; mostly the map's gradient, not its error). Measured on issue #52's
# plane (benchmarks/adaptive_map.py): the 55 % of reconstructed halted nodes with the smallest
# scale err <= 3.5 % (90 % quantile of log t_halt's error) with weight 0.25, 3.7 % with 0.1,
# 3.9 % with 1 and 4.5 % with 0 (indicator alone); on the mu_d x k3 plane, where every weight
# gives < 1 %, 0.75 % with 0.25.
SPREAD_WEIGHT = 0.25


def error_scale(spread: np.ndarray, indicator: np.ndarray) -> np.ndarray:
    """indicator + SPREAD_WEIGHT x spread (either missing counts as 0; NaN where both are)."""
    both = ~np.isfinite(spread) & ~np.isfinite(indicator)
    return np.where(both, np.nan, np.nan_to_num(indicator) + SPREAD_WEIGHT * np.nan_to_num(spread))


@dataclass
class Estimate:
    """Per node asked for (n of them): the level and lower corner of its cell, the nearest corner
    (flat index) and its outcome; per continuous output (n, m) the estimate, the spread of the
    corner values used and the cell's bar_indicator, all in the output's interpolation space."""
    level: np.ndarray
    lower: np.ndarray
    near: np.ndarray
    outcome: np.ndarray
    values: dict[str, np.ndarray]
    spread: dict[str, np.ndarray]
    indicator: dict[str, np.ndarray]

    def scale(self, name: str) -> np.ndarray:
        return error_scale(self.spread[name], self.indicator[name])


def estimate(lat: Lattice, f: Fields, nodes: np.ndarray, surs: Mapping[str, np.ndarray],
             names: tuple[str, ...] | None = None) -> Estimate:
    """The estimate of `nodes` ((n, d), none computed in `f`) from the computed nodes of `f`:
    `surs` are the surpluses (sweep.surplus.surpluses) of the outputs `names` (default: all)."""
    names = tuple(f.values) if names is None else names
    n = len(nodes)
    level, lower = leaf_of(lat, f.computed, nodes)
    nc = 2 ** lat.ndim
    corners = np.zeros((n, nc), np.int64)
    weights = np.zeros((n, nc))
    ind = {k: np.full((n, f.values[k].shape[1]), np.nan) for k in names}
    for k in np.unique(level):
        sel = np.nonzero(level == k)[0]
        c, w = multilinear(lat, nodes[sel], lower[sel], lat.stride(int(k)))
        corners[sel] = flat_index(lat, c.reshape(-1, lat.ndim)).reshape(c.shape[:2])
        weights[sel] = w
        ucells, inv = np.unique(lower[sel], axis=0, return_inverse=True)
        for name in names:
            ind[name][sel] = bar_indicator(lat, int(k), ucells, surs[name])[inv.ravel()]
    near = corners[np.arange(n), np.argmax(weights, axis=1)] if n else np.zeros(0, np.int64)
    outcome = f.outcome[near]
    same = (weights > 0) & (f.outcome[corners] == outcome[:, None])
    values, spread = {}, {}
    for name in names:
        g_all = f.transformed(name)
        gv = g_all[corners]                                             # (n, 2^d, m)
        ok = same[:, :, None] & np.isfinite(gv)
        wv = np.where(ok, weights[:, :, None], 0.0)
        wsum = wv.sum(axis=1)
        with np.errstate(invalid="ignore", divide="ignore"):
            est = np.einsum("ncm,ncm->nm", wv, np.where(ok, gv, 0.0)) / wsum
        est[(wsum <= 0) | ~np.isfinite(g_all[near])] = np.nan
        lo = np.where(ok, gv, np.inf).min(axis=1)
        hi = np.where(ok, gv, -np.inf).max(axis=1)
        values[name] = est
        spread[name] = np.where(np.isfinite(lo) & np.isfinite(hi), hi - lo, np.nan)
    return Estimate(level, lower, near, outcome, values, spread, ind)
