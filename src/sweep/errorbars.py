"""The error bars of an adaptive map's reconstructed nodes, calibrated on the map itself.

Every node computed after round 0 is a test of interpolation in the coarser cell it lies in (its
surplus, sweep.surplus, is that interpolation's true error), so the share of tests within factor x
indicator fixes the factor, per class of cell and bin of the indicator (split-conformal prediction):
`bar_factors`, applied by `Calibration.bar`. Bars are in the output's interpolation space (its units,
or log units for a log output). The bars calibrated on a hold-out instead are
sweep.reconstruct.holdout_bars.
"""
from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from .lattice import Fields, Lattice, Settings, cell_lower, corner_index, node_round
from .surplus import cell_states


# The share of reconstructed nodes whose error bar should hold (issue #52: >= 90 %), and the
# fewest tests (computed nodes with a surplus) a calibration class needs (bar_factors).
COVERAGE = 0.9
MIN_CALIBRATION = 20
# The fewest tests whose conformal quantile (conformal_quantile) lies within them: the
# ceil((n + 1) COVERAGE)-th smallest of n exists from n = COVERAGE / (1 - COVERAGE) on.
MIN_CONFORMAL = math.ceil(COVERAGE / (1.0 - COVERAGE) - 1e-9)
BIN_TESTS = 200


def _box_max(lat: Lattice, level: int, lower: np.ndarray, sur: np.ndarray, pad: int) -> np.ndarray:
    """Per cell of `level` (lower corners (n, d)), the largest |surplus| (n, m) of the nodes
    computed at that level (level 0: also the virtual lattice's) in the box of the cell widened
    by `pad` cells on every side (pad 0: its own corners, cell_error); NaN where there is none."""
    s = lat.stride(level)
    nodes = np.array(np.unravel_index(np.arange(lat.size), lat.shape)).T
    r = node_round(lat, nodes)
    own = (r == level) | ((level == 0) & (r == -1))
    m = sur.shape[1]
    v = np.where(own[:, None] & np.isfinite(sur), sur, -np.inf).reshape(lat.shape + (m,))
    sub = v[tuple(slice(None, None, s) for _ in lat.shape)]              # the stride-s sub-lattice
    # sliding max over a window of 2 + 2 pad sub-lattice points per axis, starting pad before the cell
    width = 2 + 2 * pad
    for a in range(lat.ndim):
        padded = np.concatenate([np.full(sub.shape[:a] + (pad,) + sub.shape[a + 1:], -np.inf), sub,
                                 np.full(sub.shape[:a] + (pad,) + sub.shape[a + 1:], -np.inf)], axis=a)
        n_out = sub.shape[a] - 1
        acc = np.full(sub.shape[:a] + (n_out,) + sub.shape[a + 1:], -np.inf)
        for j in range(width):
            acc = np.maximum(acc, np.take(padded, np.arange(j, j + n_out), axis=a))
        sub = acc
    out = sub[tuple((lower // s).T)]                                         # (n, m)
    return np.where(np.isfinite(out), out, np.nan)


def bar_indicator(lat: Lattice, level: int, lower: np.ndarray, sur: np.ndarray) -> np.ndarray:
    """A cell's error indicator (n, m): the geometric mean of the largest |surplus| at its own
    corners and in its neighbourhood (the cell widened by one cell each side), both at its level.
    The surpluses there are errors of interpolation at twice the cell's side; the neighbourhood
    catches roughness that the cell's few corners happen to miss."""
    with np.errstate(invalid="ignore"):
        return np.sqrt(_box_max(lat, level, lower, sur, 0) * _box_max(lat, level, lower, sur, 1))


# Calibration classes of a cell (bar_factors): split by an outcome boundary or a missing value
# (MIXED), rough (ROUGH), neither (SMOOTH).
SMOOTH, ROUGH, MIXED = 0, 1, 2


def cell_class(lat: Lattice, f: Fields, st: Settings, level: int, lower: np.ndarray, g: np.ndarray,
               driving: Mapping[str, np.ndarray], rough: np.ndarray | None = None) -> np.ndarray:
    """Per cell and component of an output (values g (size, m) in their interpolation space), its
    calibration class (n, m): MIXED where its corners differ in outcome or one has no value,
    else ROUGH or SMOOTH by cell_states (or the cells' `rough` flags where given)."""
    cidx = corner_index(lat, lower, lat.stride(level))
    oc = f.outcome[cidx]
    disagree = (oc != oc[:, :1]).any(axis=1)
    missing = ~np.isfinite(g[cidx]).all(axis=1)                                 # (n, m)
    if rough is None:
        rough = cell_states(lat, f, st, level, lower, driving)["rough"]
    base = np.broadcast_to(np.where(rough, ROUGH, SMOOTH)[:, None], missing.shape)
    return np.where(disagree[:, None] | missing, MIXED, base)


@dataclass
class Calibration:
    """Per calibration class and component of an output, the bins of the indicator (log10 edges
    between them), each bin's factor, and the smallest indicator tested: bar = factor(class,
    indicator) x max(indicator, the tests' 1 - COVERAGE quantile of it). Below what was tested
    there is no evidence that the error keeps shrinking with the indicator (an output's noise
    floor, or cells never refined because their error looked small), so none is assumed."""
    edges: dict[tuple[int, int], np.ndarray]
    factors: dict[tuple[int, int], np.ndarray]
    lowest: dict[tuple[int, int], float]

    def bar(self, cls: np.ndarray, ind: np.ndarray) -> np.ndarray:
        """The bars (n, m) of cells of classes `cls` (n, m) with indicators `ind` (n, m)."""
        out = ind.astype(float).copy()
        with np.errstate(divide="ignore", invalid="ignore"):
            lg = np.log10(ind)
        for (k, c), edges in self.edges.items():
            sel = cls[:, c] == k
            if sel.any():
                fac = self.factors[k, c][np.searchsorted(edges, np.nan_to_num(lg[sel, c], nan=-np.inf))]
                out[sel, c] = fac * np.fmax(ind[sel, c], self.lowest[k, c])
        return out


def conformal_quantile(sample: np.ndarray, weights: np.ndarray | None = None) -> float:
    """The COVERAGE quantile of a sample with the split-conformal finite-sample correction: the
    ceil((n + 1) COVERAGE)-th smallest. With `weights` (tests sampled at unequal rates, each
    standing for `weight` nodes), the smallest value at which the weights of the values up to it
    reach COVERAGE of the total plus the largest weight (the node the bar is for, counted at the
    most any test stands for: weighted split-conformal, Tibshirani et al. 2019); equal weights give
    the unweighted rank. The largest value where that is never reached."""
    order = np.argsort(sample, kind="stable")
    sample = np.asarray(sample, float)[order]
    n = len(sample)
    if weights is None or np.all(weights == weights[0]):
        return float(sample[min(n - 1, math.ceil((n + 1) * COVERAGE) - 1)])
    w = np.asarray(weights, float)[order]
    reach = np.cumsum(w) / (w.sum() + w.max())
    return float(sample[min(n - 1, int(np.searchsorted(reach, COVERAGE * (1 - 1e-12))))])


def _binned(ind: np.ndarray, ratio: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(log10 edges, factors) of tests with indicators `ind` and ratios |surplus| / ind: equal-count
    bins of the indicator of BIN_TESTS tests at least, each bin's factor its conformal_quantile."""
    order = np.argsort(ind, kind="stable")
    ind, ratio = ind[order], ratio[order]
    n_bins = max(1, len(ind) // BIN_TESTS)
    cuts = [round(i * len(ind) / n_bins) for i in range(n_bins + 1)]
    factors = np.array([conformal_quantile(ratio[a:b]) for a, b in zip(cuts[:-1], cuts[1:])])
    edges = np.array([0.5 * (np.log10(ind[c - 1]) + np.log10(ind[c])) for c in cuts[1:-1]])
    return edges, factors


def bar_factors(lat: Lattice, f: Fields, st: Settings, name: str, sur: np.ndarray,
                driving: Mapping[str, np.ndarray]) -> Calibration:
    """The factors that turn bar_indicator into an error bar of output `name`, calibrated on the
    map itself (split-conformal): every node computed at round j >= 1 is a test of interpolation
    in the cell of round j - 1 it lies in, whose error is its |surplus|; per calibration class
    (SMOOTH, ROUGH, MIXED) and component, the tests are binned by their cell's indicator (a small
    indicator is often the output's own noise floor, where the error no longer falls with the
    side) and each bin's factor is the COVERAGE quantile of |surplus| / indicator in it. A class
    with fewer than MIN_CALIBRATION tests takes the pooled tests; with fewer in all, factor 1 (the
    bar is then the error at twice the side, a bound where interpolation converges)."""
    nodes = np.array(np.unravel_index(np.arange(lat.size), lat.shape)).T
    r = node_round(lat, nodes)
    g = f.transformed(name)
    inds, errs, classes = [], [], []
    for j in range(1, lat.rounds + 1):
        sel = np.nonzero((r == j) & f.computed)[0]
        if not sel.size:
            continue
        low = cell_lower(lat, nodes[sel], lat.stride(j - 1))
        ucells, inv = np.unique(low, axis=0, return_inverse=True)
        inv = inv.ravel()
        inds.append(bar_indicator(lat, j - 1, ucells, sur)[inv])
        errs.append(sur[sel])
        classes.append(cell_class(lat, f, st, j - 1, ucells, g, driving)[inv])
    m = sur.shape[1]
    cal = Calibration({}, {}, {})
    ind = np.concatenate(inds) if inds else np.zeros((0, m))
    err = np.concatenate(errs) if errs else np.zeros((0, m))
    cl = np.concatenate(classes) if classes else np.zeros((0, m), np.int64)
    for c in range(m):
        ok = np.isfinite(err[:, c]) & np.isfinite(ind[:, c]) & (ind[:, c] > 0)
        for k in (SMOOTH, ROUGH, MIXED):
            sel = ok & (cl[:, c] == k)
            if sel.sum() < MIN_CALIBRATION:
                sel = ok
            if sel.sum() < MIN_CALIBRATION:
                cal.edges[k, c], cal.factors[k, c], cal.lowest[k, c] = np.zeros(0), np.ones(1), 0.0
                continue
            cal.edges[k, c], cal.factors[k, c] = _binned(ind[sel, c], err[sel, c] / ind[sel, c])
            cal.lowest[k, c] = float(np.quantile(ind[sel, c], 1.0 - COVERAGE))
    return cal
