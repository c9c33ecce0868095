"""The full map of an adaptive run rebuilt from its computed nodes, with error bars.

Every node not computed is interpolated multilinearly in the finest cell holding it (log values
for positive times and frequencies; the outcome and the categorical values from the nearest
corner; sweep.interpolation), with an error bar (absolute, the output's units) calibrated on the
map's surpluses (sweep.errorbars) or, where the map has a hold-out (sweep.refine.holdout_size), on
the hold-out's errors (`holdout_bars`).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .errorbars import MIN_CALIBRATION, MIN_CONFORMAL, bar_factors, cell_class, conformal_quantile
from .interpolation import estimate
from .lattice import Fields, Lattice, Settings
from .refine import QUIET_SHARE, STRATUM_LOUD, STRATUM_QUIET, holdout_design, inclusion_weights
from .surplus import cell_states, surpluses


@dataclass
class Map:
    """The full lattice rebuilt: per node (flat) its outcome, the index of the corner that gave
    its categorical values (itself where computed), each continuous output with its
    interpolation error bar (absolute, the output's units; 0 where computed), and whether its
    cell is rough; `scale`: per continuous output, each reconstructed node's error scale (in its
    interpolation space, sweep.interpolation.error_scale; NaN where computed); `holdout`: the
    hold-out nodes (holdout_mask), or None."""
    outcome: np.ndarray
    source: np.ndarray
    values: dict[str, np.ndarray]
    bars: dict[str, np.ndarray]
    rough: np.ndarray
    cell_level: np.ndarray
    scale: dict[str, np.ndarray] = field(default_factory=dict)
    holdout: np.ndarray | None = None


def relative_to_absolute(x: np.ndarray, bar: np.ndarray | float) -> np.ndarray:
    """The absolute bar (x's units) of a value x whose bar in log space is `bar`: a true value
    within `bar` of log x lies within x expm1(bar) of x, plus a few ulp of x, the rounding of
    |value - x| (a node whose log error equals the bar, as a conformal quantile's own test and
    the nodes tied with it do, stays within it)."""
    return x * np.expm1(bar) + 8.0 * np.finfo(float).eps * np.abs(x)


def reconstruct(lat: Lattice, f: Fields, st: Settings) -> Map:
    """The full map from the computed nodes (see the module's docstring for the bars): the map's
    cells are interpolated without the hold-out nodes, whose errors then calibrate the bars
    (holdout_bars); in the map they are computed nodes like the others."""
    hold, strata = holdout_design(lat, f, st)
    if not hold.any():
        return _interpolate(lat, f, st)
    known = f.subset(~hold)
    m = _interpolate(lat, known, st)
    holdout_bars(f, known, m, hold, strata, st.outputs[0])
    idx = np.nonzero(hold)[0]
    m.outcome[idx] = f.outcome[idx]
    m.source[idx] = idx
    m.rough[idx] = False
    m.cell_level[idx] = -1
    for name, v in f.values.items():
        m.values[name][idx] = v[idx]
        m.bars[name][idx] = np.where(np.isfinite(v[idx]), 0.0, np.nan)
        m.scale[name][idx] = np.nan
    m.holdout = hold
    return m


def holdout_bars(f: Fields, known: Fields, m: Map, hold: np.ndarray, strata: np.ndarray,
                 headline: str) -> None:
    """Replace the bars of `m` (reconstructed from `known`: `f` without the hold-out nodes `hold`)
    by bars calibrated on the hold-out (split-conformal on a sample of the nodes reconstructed, so
    its COVERAGE holds for them). Per output and component the reconstructed nodes with a value
    are split into quiet and loud: for the first driving output (`headline`) by the hold-out's
    strata (sweep.refine.holdout_strata), each stratum's tests a uniform sample of it; for the
    others at the QUIET_SHARE quantile of their own error scale (`m.scale`), each test weighted by
    its stratum's inclusion weight (sweep.refine.inclusion_weights). Each bin's bar (in the
    interpolation space) is the conformal quantile (conformal_quantile) of its tests' |error|, in
    the loud bin at least the bar calibrated on the surpluses (the loud bin mixes rough cells with
    merely steep ones: its constant bar is not allowed to undercut the per-class one). Where a bin
    has fewer than MIN_CALIBRATION tests the two are one bin, calibrated as a loud one, if it has
    MIN_CONFORMAL tests; with fewer the bars calibrated on the surpluses stay."""
    idx = np.nonzero(hold)[0]
    weight = inclusion_weights(strata, hold)[idx]
    for name, v in f.values.items():
        log = known.is_log(name)
        est, scale = m.values[name], m.scale[name]
        with np.errstate(divide="ignore", invalid="ignore"):
            g_true = np.log(v[idx]) if log else v[idx]
            g_est = np.log(est) if log else est
        rec = (m.cell_level >= 0)[:, None] & np.isfinite(est)                 # (n, m): reconstructed, a value
        for c in range(v.shape[1]):
            pop = rec[:, c]
            if not pop.any():
                continue
            if name == headline and c == 0:
                quiet, loud, w = strata == STRATUM_QUIET, strata == STRATUM_LOUD, None
            else:
                sc = np.where(np.isfinite(scale[:, c]), scale[:, c], np.inf)
                cut = np.quantile(sc[pop], QUIET_SHARE, method="inverted_cdf")
                quiet, loud, w = sc <= cut, sc > cut, weight
            err = np.abs(g_true[:, c] - g_est[idx, c])
            ok = np.isfinite(err)
            bins = ((False, quiet), (True, loud))
            if min((ok & b[idx]).sum() for _, b in bins) < MIN_CALIBRATION:
                # too few tests to split: one bin, if it has enough for a conformal quantile
                bins = ((True, quiet | loud),)
                if (ok & bins[0][1][idx]).sum() < MIN_CONFORMAL:
                    continue
            for is_loud, in_bin in bins:
                sel_t = ok & in_bin[idx]
                q = conformal_quantile(err[sel_t], None if w is None else w[sel_t])
                sel = pop & in_bin & ~hold
                bar = relative_to_absolute(est[sel, c], q) if log else np.full(int(sel.sum()), q)
                m.bars[name][sel, c] = np.fmax(bar, m.bars[name][sel, c]) if is_loud else bar


def _interpolate(lat: Lattice, f: Fields, st: Settings) -> Map:
    """The full map from the computed nodes of `f`, bars calibrated on its surpluses."""
    n = lat.size
    outcome = f.outcome.copy()
    source = np.arange(n)
    values = {k: v.copy() for k, v in f.values.items()}
    bars = {k: np.where(np.isfinite(v), 0.0, np.nan) for k, v in f.values.items()}
    rough_node = np.zeros(n, bool)
    cell_level = np.full(n, -1, np.int64)
    miss = np.nonzero(~f.computed)[0]
    scales = {k: np.full(v.shape, np.nan) for k, v in f.values.items()}
    if not miss.size:
        return Map(outcome, source, values, bars, rough_node, cell_level, scales)
    nodes = np.array(np.unravel_index(miss, lat.shape)).T.astype(np.int64)
    surs = {k: surpluses(lat, f, k) for k in f.values}
    driving = {o: surs[o] for o in st.outputs}
    factors = {k: bar_factors(lat, f, st, k, surs[k], driving) for k in f.values}
    e = estimate(lat, f, nodes, surs)
    cell_level[miss] = e.level
    outcome[miss] = e.outcome
    source[miss] = e.near
    for k in np.unique(e.level):
        sel = np.nonzero(e.level == k)[0]
        tgt = miss[sel]
        # the cells' rough flags (by the driving outputs): reported, and a calibration class
        ucells, inv = np.unique(e.lower[sel], axis=0, return_inverse=True)
        inv = inv.ravel()
        cell_rough = cell_states(lat, f, st, int(k), ucells, driving)["rough"]
        rough_node[tgt] = cell_rough[inv]
        for name in f.values:
            est, ind = e.values[name][sel], e.indicator[name][sel]
            g_all = f.transformed(name)
            cls = cell_class(lat, f, st, int(k), ucells, g_all, driving, cell_rough)[inv]    # (n, m)
            # no indicator (no surplus at this level around): the corners' spread
            bar = np.where(np.isfinite(ind), factors[name].bar(cls, ind), e.spread[name][sel])
            scales[name][tgt] = e.scale(name)[sel]
            if f.is_log(name):
                x = np.exp(est)
                absbar = relative_to_absolute(x, bar)
            else:
                x, absbar = est, bar
            values[name][tgt] = x
            bars[name][tgt] = np.where(np.isfinite(x), absbar, np.nan)
    return Map(outcome, source, values, bars, rough_node, cell_level, scales)
