"""Adaptive maps on a lattice: which nodes to compute next, and the full map rebuilt from them.

Pure numpy, no I/O (the pipeline's side is sweep.adaptive). A map is a lattice of 2^L_a + 1 points
on each of its d axes (d = 2 or 3), indexed by integer nodes. Round 0 computes the coarse
sub-lattice of stride S = 2^R (R: the number of refinement rounds); round k (1..R) works at stride
s_k = 2^(R - k) and refines some *cells* of round k - 1: a cell is a box of side s_{k-1} whose
2^d corners are computed; refining it computes every node of its sub-lattice of stride s_k (the
3^d - 2^d that are new, fewer where a neighbour already computed the shared ones), which makes
its 2^d children cells. A cell is refined when

* its corners differ in outcome (a boundary of the outcome map runs through it), or one of them
  failed numerically (sweep.outcomes FAILED), or
* its interpolation error estimate, for one of the driving outputs, exceeds the tolerance;

unless its error does not fall as the cells shrink (ROUGH): structure finer than the lattice,
where refining buys nothing, reported as rough.

The error estimate is the hierarchical surplus: a node computed at round k is also predicted by
multilinear interpolation from the corners of the cell of round k - 1 it lies in (log values for
positive times and frequencies); the difference, |surplus|, is what interpolation at the coarser
stride missed there. For a smooth function it falls 4x per halving (second order); a cell's
error, for planning, is the largest surplus at its own corners (`cell_error`). Round 0's nodes
get surpluses too, against the lattice of stride 2S (every other node of round 0).

The reconstructed map's error bars are calibrated on the map itself (`bar_factors`): every node
computed after round 0 is a test of interpolation in the coarser cell it lies in (its surplus is
that interpolation's true error), so the share of tests within factor x indicator fixes the
factor, per class of cell and bin of the indicator (split-conformal prediction). Those tests
come from the cells the map chose to refine, the hard ones, so a map large enough for it also
computes a hold-out in its last round (`holdout_size`): a uniform random sample of the nodes it
would reconstruct, left out of the reconstruction, whose errors calibrate the bars of the
reconstructed nodes directly (`holdout_bars`).

Everything is a function of the set of computed nodes and their values, so the same config
computes the same nodes (determinism: ties are broken by node index), and a round can be planned
again after an interruption with the same answer.
"""
from __future__ import annotations

import itertools
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from . import outcomes

# Outcomes that are a numerical failure, not physics: the cells around them are refined.
FAILED = frozenset({outcomes.STEP_LIMIT, outcomes.STEP_SIZE_UNDERFLOW, outcomes.NUMERICAL_ERROR, outcomes.NOT_RUN})
# The planning estimate of a cell's error: its corners' |surplus| (the error at twice its side)
# times KAPPA: second-order interpolation errs 1/4 of the surplus at most in the limit, KAPPA =
# 1/2 is that with a factor 2 of margin. (The map's error bars are calibrated: bar_factors.)
KAPPA = 0.5
# A cell is rough when its error fell by less than 1/ROUGH_RATIO per halving over the last two
# (its grandparent's error over its own below 1/ROUGH_RATIO^2 = 4); a smooth function's falls 4x
# per halving, 16x over two. One halving is not evidence enough: the ratio of two maxima of a few
# surpluses scatters by 2x in smooth regions too, and a region judged rough at stride 4 on one
# halving errs ~4x less at stride 2 (benchmarks/adaptive_map.py).
ROUGH_RATIO = 0.5
SPACINGS = ("linear", "log")
# A round before the last spends at most this share of the budget left on cells flagged for their
# error (outcome boundaries and failures first, without this cap).
ERROR_SHARE = 0.5
# The share of reconstructed nodes whose error bar should hold (issue #52: >= 90 %), and the
# fewest tests (computed nodes with a surplus) a calibration class needs (bar_factors).
COVERAGE = 0.9
MIN_CALIBRATION = 20
BIN_TESTS = 200
# The hold-out (a random sample of the nodes the finished map would reconstruct, computed in the
# last round as tests of its reconstruction, `holdout_size`): this share of the budget, when that is
# HOLDOUT_MIN nodes at least; drawn with a fixed seed (determinism). The map's own surpluses test
# only the cells it chose to refine, the hard ones (their quietest tenth errs ~5x more than the
# quietest half of the reconstructed nodes on issue #52's plane), so only a sample of the
# reconstructed nodes themselves can show how small the error is where the map is quiet.
HOLDOUT_SHARE = 0.14
HOLDOUT_MIN = 60
HOLDOUT_SEED = 52
# The bars calibrated on the hold-out: the reconstructed nodes split at this quantile of their
# error scale (`Map.scale`) into quiet and loud, each bin's bar its tests' conformal quantile.
QUIET_SHARE = 0.6


def is_lattice_size(n: int) -> bool:
    """Whether n = 2^L + 1 with L >= 1 (3, 5, 9, 17, 33, 65, ...)."""
    return isinstance(n, int) and n >= 3 and ((n - 1) & (n - 2)) == 0


def axis_values(start: float, stop: float, points: int, spacing: str = "linear") -> np.ndarray:
    """The lattice values of one axis: `points` values from `start` to `stop` (SI units),
    evenly spaced or evenly spaced in log (`spacing` 'log'; start, stop > 0)."""
    if spacing == "log":
        v = np.exp(np.linspace(math.log(start), math.log(stop), points))
    else:
        v = np.linspace(start, stop, points)
    v[0], v[-1] = start, stop
    return v


@dataclass(frozen=True)
class Lattice:
    """A map's lattice: axis names, values per axis, and R, the refinement rounds after round 0
    (round k's stride is 2^(R - k) on every axis)."""
    axes: tuple[str, ...]
    values: tuple[np.ndarray, ...] = field(compare=False)
    rounds: int

    @property
    def shape(self) -> tuple[int, ...]:
        return tuple(len(v) for v in self.values)

    @property
    def size(self) -> int:
        return math.prod(self.shape)

    @property
    def ndim(self) -> int:
        return len(self.axes)

    def stride(self, k: int) -> int:
        """Stride (in lattice steps) of round k; k = -1 is the virtual lattice behind round 0's surpluses."""
        return 2 ** (self.rounds - k)

    def round0_nodes(self) -> np.ndarray:
        s = self.stride(0)
        return np.array(list(itertools.product(*(range(0, n, s) for n in self.shape))), dtype=np.int64)

    def point(self, node: Sequence[int]) -> tuple[float, ...]:
        return tuple(float(self.values[a][int(i)]) for a, i in enumerate(node))


def make_lattice(axes: Mapping[str, Mapping], start_points: int) -> Lattice:
    """The lattice of a `refine.axes` mapping ({name: {from, to, points, spacing}}, validated)
    started with `start_points` (2^l + 1) points on its axis with the fewest points."""
    names = tuple(axes)
    values = tuple(axis_values(float(a["from"]), float(a["to"]), int(a["points"]), a.get("spacing", "linear"))
                   for a in axes.values())
    L_min = min(int(a["points"]) - 1 for a in axes.values()).bit_length() - 1
    rounds = L_min - ((start_points - 1).bit_length() - 1)
    return Lattice(names, values, rounds)


def node_round(lat: Lattice, nodes: np.ndarray) -> np.ndarray:
    """The round whose stride first reaches each node (0..R), -1 for the nodes of the virtual
    stride-2S lattice (round 0's nodes that get no surplus)."""
    nodes = np.asarray(nodes, dtype=np.int64).reshape(-1, lat.ndim)
    out = np.full(len(nodes), lat.rounds, dtype=np.int64)
    for k in range(lat.rounds - 1, -2, -1):
        on = (nodes % lat.stride(k) == 0).all(axis=1)
        out[on] = k
    return out


def corner_offsets(d: int) -> np.ndarray:
    """The 2^d corners of a unit box, (2^d, d), in lexicographic order."""
    return np.array(list(itertools.product((0, 1), repeat=d)), dtype=np.int64)


def cell_lower(lat: Lattice, nodes: np.ndarray, s: int) -> np.ndarray:
    """Lower corner of the cell of side s holding each node (a node on the upper edge of the
    lattice goes to the last cell)."""
    hi = np.array(lat.shape, dtype=np.int64) - 1 - s
    return np.minimum((nodes // s) * s, hi)


def multilinear(lat: Lattice, nodes: np.ndarray, lower: np.ndarray, s: int) -> tuple[np.ndarray, np.ndarray]:
    """(corners (n, 2^d, d), weights (n, 2^d)) of multilinear interpolation at `nodes` in the cells
    of side s with lower corners `lower` (index space: linear in the axis' spacing)."""
    off = corner_offsets(lat.ndim)
    t = (nodes - lower) / s                                        # (n, d) in [0, 1]
    corners = lower[:, None, :] + s * off[None, :, :]
    w = np.prod(np.where(off[None, :, :] == 1, t[:, None, :], 1.0 - t[:, None, :]), axis=2)
    return corners, w


def _flat(lat: Lattice, nodes: np.ndarray) -> np.ndarray:
    return np.ravel_multi_index(tuple(np.asarray(nodes).reshape(-1, lat.ndim).T), lat.shape)


@dataclass
class Fields:
    """What is known of a map: per lattice node (flat index) whether it is computed, its round
    (-1: not computed), its outcome code, and the continuous outputs `values` ({name: array
    (size, m)}, m components: 1, or one per level), each with whether it is interpolated in
    log (`log`: positive times and frequencies)."""
    computed: np.ndarray
    round: np.ndarray
    outcome: np.ndarray
    values: dict[str, np.ndarray]
    log: dict[str, bool]

    @classmethod
    def empty(cls, lat: Lattice, components: Mapping[str, int], log: Mapping[str, bool]) -> "Fields":
        n = lat.size
        return cls(np.zeros(n, bool), np.full(n, -1, np.int64), np.full(n, -1, np.int64),
                   {k: np.full((n, m), np.nan) for k, m in components.items()}, dict(log))

    def set(self, lat: Lattice, nodes: np.ndarray, rnd: int, outcome: np.ndarray, values: Mapping[str, np.ndarray]):
        idx = _flat(lat, nodes)
        if not idx.size:
            return
        self.computed[idx] = True
        self.round[idx] = rnd
        self.outcome[idx] = outcome
        for k, v in values.items():
            self.values[k][idx] = np.asarray(v, dtype=float).reshape(len(idx), -1)

    def subset(self, keep: np.ndarray) -> "Fields":
        """A copy that knows only the computed nodes where `keep` (bool (size,)) is true: what
        was known before those others were computed."""
        keep = keep & self.computed
        return Fields(keep.copy(), np.where(keep, self.round, -1), np.where(keep, self.outcome, -1),
                      {k: np.where(keep[:, None], v, np.nan) for k, v in self.values.items()}, dict(self.log))

    def transformed(self, name: str) -> np.ndarray:
        """The values in the space they are interpolated in: log for a log output whose computed
        values are all positive (where they are finite), else as they are."""
        v = self.values[name]
        if self.log.get(name, False):
            fin = v[np.isfinite(v)]
            if fin.size and (fin > 0).all():
                with np.errstate(divide="ignore", invalid="ignore"):
                    return np.log(v)
        return v

    def is_log(self, name: str) -> bool:
        v = self.values[name]
        fin = v[np.isfinite(v)]
        return bool(self.log.get(name, False) and fin.size and (fin > 0).all())


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
        cidx = _flat(lat, corners.reshape(-1, lat.ndim)).reshape(corners.shape[:2])
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
        lo, hi = _flat(lat, nodes[inside] - step), _flat(lat, nodes[inside] + step)
        ok = f.computed[lo] & f.computed[hi] & (f.outcome[lo] == f.outcome[i]) & (f.outcome[hi] == f.outcome[i])
        with np.errstate(invalid="ignore"):
            sur = np.abs(g[i] - 0.5 * (g[lo] + g[hi]))
        sur[~ok] = np.nan
        out[i] = np.fmax(out[i], sur)
    return out


@dataclass(frozen=True)
class Cell:
    level: int                 # the round that computed its corners
    lower: tuple[int, ...]


def cells(lat: Lattice, computed: np.ndarray) -> dict[int, np.ndarray]:
    """The cells that exist per level: level 0's all; level k + 1's the children of the level-k
    cells whose centre is computed (refined). {level: lower corners (n, d)}, lexicographic."""
    s0 = lat.stride(0)
    out = {0: np.array(list(itertools.product(*(range(0, n - 1, s0) for n in lat.shape))), dtype=np.int64)}
    off = corner_offsets(lat.ndim)
    for k in range(0, lat.rounds):
        low = out[k]
        s = lat.stride(k)
        refined = low[computed[_flat(lat, low + s // 2)]] if len(low) else low
        kids = (refined[:, None, :] + (s // 2) * off[None, :, :]).reshape(-1, lat.ndim)
        out[k + 1] = np.unique(kids, axis=0) if len(kids) else np.zeros((0, lat.ndim), np.int64)
    return out


def _corner_idx(lat: Lattice, lower: np.ndarray, s: int) -> np.ndarray:
    corners = lower[:, None, :] + s * corner_offsets(lat.ndim)[None, :, :]
    return _flat(lat, corners.reshape(-1, lat.ndim)).reshape(len(lower), -1)


def cell_error(lat: Lattice, level: int, lower: np.ndarray, sur: np.ndarray) -> np.ndarray:
    """A cell's error at its level: the largest |surplus| of its corners computed at that level
    (the others are the parent's; at level 0 every corner), per component (n, m); NaN where none
    has one."""
    cidx = _corner_idx(lat, lower, lat.stride(level))
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


@dataclass
class Settings:
    """Refinement settings: the driving outputs, the tolerance (an interpolation error bar the
    map needs: relative for a log output, a share of the output's range over the map otherwise),
    the node budget (computed nodes at most)."""
    outputs: tuple[str, ...]
    tolerance: float
    budget: int


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
    cidx = _corner_idx(lat, lower, lat.stride(level))
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


@dataclass
class Plan:
    """The nodes of a round (lexicographic), and what the round found: cells flagged per reason,
    refined, left for the budget, rough; `holdout`: the nodes of the last round's hold-out
    (among `nodes`; holdout_size)."""
    round: int
    nodes: np.ndarray
    flagged: dict[str, int]
    refined: int
    skipped: int
    rough: int
    holdout: np.ndarray = field(default_factory=lambda: np.zeros((0, 2), np.int64))


def holdout_size(lat: Lattice, st: Settings) -> int:
    """How many nodes the last round computes as a hold-out: HOLDOUT_SHARE of the budget, or none
    where that is fewer than HOLDOUT_MIN (or the map has no round after round 0)."""
    n = math.floor(HOLDOUT_SHARE * st.budget)
    return n if lat.rounds >= 1 and n >= HOLDOUT_MIN else 0


def plan_round(lat: Lattice, f: Fields, st: Settings, k: int) -> Plan:
    """The nodes round k computes, from what rounds < k computed (in `f`)."""
    if k == 0:
        nodes = lat.round0_nodes()
        return Plan(0, nodes, {}, 0, 0, 0)
    level = k - 1
    low = cells(lat, f.computed)[level]
    surs = {name: surpluses(lat, f, name) for name in st.outputs}
    cs = cell_states(lat, f, st, level, low, surs)
    err = np.nan_to_num(cs["error"], nan=0.0)
    by_outcome = cs["disagree"] | cs["failed"]
    by_error = (err > 1.0) & ~cs["rough"]
    want = by_outcome | by_error
    # outcome boundaries and failures first, then the largest errors; ties by position
    order = sorted(np.nonzero(want)[0], key=lambda i: (0 if by_outcome[i] else 1, -err[i], tuple(low[i])))
    # every round leaves room for the last round's hold-out
    n_hold = holdout_size(lat, st)
    left = st.budget - n_hold - int(f.computed.sum())
    # the error's share of what is left: later rounds keep room for the outcome boundaries,
    # which need every round down to stride 1
    error_left = left if k == lat.rounds else math.floor(ERROR_SHARE * left)
    s = lat.stride(level)
    sub = np.array(list(itertools.product((0, 1, 2), repeat=lat.ndim)), dtype=np.int64) * (s // 2)
    taken = np.zeros(lat.size, bool)
    refined = skipped = 0
    for i in order:
        idx = _flat(lat, low[i] + sub)
        new = idx[~f.computed[idx] & ~taken[idx]]
        if len(new) > left or (not by_outcome[i] and len(new) > error_left):
            skipped += 1
            continue
        taken[new] = True
        left -= len(new)
        if not by_outcome[i]:
            error_left -= len(new)
        refined += 1
    hold = np.zeros(0, np.int64)
    if n_hold and k == lat.rounds:
        # a uniform sample of the nodes the map will reconstruct (fixed seed)
        cand = np.nonzero(~f.computed & ~taken)[0]
        pick = np.random.default_rng(HOLDOUT_SEED).choice(len(cand), min(n_hold, len(cand)), replace=False)
        hold = np.sort(cand[pick])
        taken[hold] = True
    as_nodes = (lambda idx: np.array(np.unravel_index(idx, lat.shape)).T.astype(np.int64).reshape(-1, lat.ndim))
    flagged = {"outcome": int(cs["disagree"].sum()), "failed": int(cs["failed"].sum()),
               "error": int(((err > 1.0) & ~cs["rough"]).sum())}
    return Plan(k, as_nodes(np.nonzero(taken)[0]), flagged, refined, skipped, int((cs["rough"] & ~by_outcome).sum()),
                as_nodes(hold))


def holdout_mask(lat: Lattice, f: Fields, st: Settings) -> np.ndarray:
    """The computed nodes that are the last round's hold-out (bool (size,)): the last round is
    planned again from the rounds before it (deterministic), so no file needs to record them;
    every node of the last round that the plan does not refine with is one (so a map computed
    by another plan still gets cells made of refinement nodes only). They are tests of the
    reconstruction, not part of the map's cells."""
    out = np.zeros(lat.size, bool)
    last = f.computed & (f.round == lat.rounds)
    if not holdout_size(lat, st) or not last.any():
        return out
    plan = plan_round(lat, f.subset(f.round < lat.rounds), st, lat.rounds)
    refining = np.zeros(lat.size, bool)
    refining[_flat(lat, plan.nodes)] = True
    refining[_flat(lat, plan.holdout)] = False
    return last & ~refining


def rough_leaves(lat: Lattice, f: Fields, st: Settings) -> int:
    """How many cells of the finished map are rough: leaf cells (not refined) that cell_states
    flags rough and no outcome boundary or failure runs through (the rough regions the map
    reports, what a last round's progress line counts)."""
    out = 0
    f = f.subset(~holdout_mask(lat, f, st))
    surs = {name: surpluses(lat, f, name) for name in st.outputs}
    for level, low in cells(lat, f.computed).items():
        if level >= lat.rounds or not len(low):
            continue
        leaf = ~f.computed[_flat(lat, low + lat.stride(level) // 2)]
        if not leaf.any():
            continue
        cs = cell_states(lat, f, st, level, low[leaf], surs)
        out += int((cs["rough"] & ~cs["disagree"] & ~cs["failed"]).sum())
    return out


# ---------------------------------------------------------------------------------- the full map

@dataclass
class Map:
    """The full lattice rebuilt: per node (flat) its outcome, the index of the corner that gave
    its categorical values (itself where computed), each continuous output with its
    interpolation error bar (absolute, the output's units; 0 where computed), and whether its
    cell is rough; `scale`: per continuous output, each reconstructed node's error scale (in its
    interpolation space: the spread of the corners it is interpolated from plus its cell's
    bar_indicator; NaN where computed); `holdout`: the hold-out nodes (holdout_mask), or None."""
    outcome: np.ndarray
    source: np.ndarray
    values: dict[str, np.ndarray]
    bars: dict[str, np.ndarray]
    rough: np.ndarray
    cell_level: np.ndarray
    scale: dict[str, np.ndarray] = field(default_factory=dict)
    holdout: np.ndarray | None = None


def leaf_of(lat: Lattice, computed: np.ndarray, nodes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(level, lower corner) of the finest existing cell holding each node."""
    level = np.full(len(nodes), -1, np.int64)
    lower = np.zeros_like(nodes)
    for k in range(lat.rounds - 1, -1, -1):
        s = lat.stride(k)
        low = cell_lower(lat, nodes, s)
        if k == 0:
            exists = np.ones(len(nodes), bool)
        else:
            pl = cell_lower(lat, nodes, 2 * s)
            exists = computed[_flat(lat, pl + s)]
        take = exists & (level < 0)
        level[take] = k
        lower[take] = low[take]
    return level, lower


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
    cidx = _corner_idx(lat, lower, lat.stride(level))
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


def _quantile(sample: np.ndarray) -> float:
    """The COVERAGE quantile of a sample with the split-conformal finite-sample correction
    (the ceil((n + 1) COVERAGE)-th smallest)."""
    sample = np.sort(sample)
    return float(sample[min(len(sample) - 1, math.ceil((len(sample) + 1) * COVERAGE) - 1)])


def _binned(ind: np.ndarray, ratio: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(log10 edges, factors) of tests with indicators `ind` and ratios |surplus| / ind: equal-count
    bins of the indicator of BIN_TESTS tests at least, each bin's factor its _quantile."""
    order = np.argsort(ind, kind="stable")
    ind, ratio = ind[order], ratio[order]
    n_bins = max(1, len(ind) // BIN_TESTS)
    cuts = [round(i * len(ind) / n_bins) for i in range(n_bins + 1)]
    factors = np.array([_quantile(ratio[a:b]) for a, b in zip(cuts[:-1], cuts[1:])])
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


def reconstruct(lat: Lattice, f: Fields, st: Settings) -> Map:
    """The full map from the computed nodes (see the module's docstring for the bars): the map's
    cells are interpolated without the hold-out nodes, whose errors then calibrate the bars
    (holdout_bars); in the map they are computed nodes like the others."""
    hold = holdout_mask(lat, f, st)
    if not hold.any():
        return _interpolate(lat, f, st)
    known = f.subset(~hold)
    m = _interpolate(lat, known, st)
    holdout_bars(f, known, m, hold)
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


def holdout_bars(f: Fields, known: Fields, m: Map, hold: np.ndarray) -> None:
    """Replace the bars of `m` (reconstructed from `known`: `f` without the hold-out nodes `hold`) by bars calibrated on the hold-out (split-conformal on a uniform sample of the nodes
    reconstructed, so its COVERAGE holds for them): per output and component, the reconstructed
    nodes with a value split at the QUIET_SHARE quantile of their error scale (`m.scale`) into
    quiet and loud; each bin's bar (in the interpolation space) is the conformal quantile
    (_quantile) of its hold-out tests' |error|, in the loud bin at least the bar calibrated on the
    surpluses (the loud bin mixes rough cells with merely steep ones: its constant bar is not
    allowed to undercut the per-class one). A bin with fewer than MIN_CALIBRATION tests keeps the
    bars calibrated on the surpluses."""
    idx = np.nonzero(hold)[0]
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
            sc = np.where(np.isfinite(scale[:, c]), scale[:, c], np.inf)
            cut = np.quantile(sc[pop], QUIET_SHARE, method="inverted_cdf")
            err = np.abs(g_true[:, c] - g_est[idx, c])
            ok = np.isfinite(err)
            for loud in (False, True):
                in_bin = (sc > cut) if loud else (sc <= cut)
                tests = err[ok & in_bin[idx]]
                if len(tests) < MIN_CALIBRATION:
                    continue
                q = _quantile(tests)
                sel = pop & in_bin & ~hold
                bar = est[sel, c] * np.expm1(q) if log else np.full(int(sel.sum()), q)
                m.bars[name][sel, c] = np.fmax(bar, m.bars[name][sel, c]) if loud else bar


def _interpolate(lat: Lattice, f: Fields, st: Settings) -> Map:
    """The full map from the computed nodes of `f`, bars calibrated on its surpluses."""
    n = lat.size
    all_nodes = np.array(np.unravel_index(np.arange(n), lat.shape)).T.astype(np.int64)
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
    nodes = all_nodes[miss]
    level, lower = leaf_of(lat, f.computed, nodes)
    cell_level[miss] = level
    surs = {k: surpluses(lat, f, k) for k in f.values}
    driving = {o: surs[o] for o in st.outputs}
    factors = {k: bar_factors(lat, f, st, k, surs[k], driving) for k in f.values}
    for k in np.unique(level):
        sel = np.nonzero(level == k)[0]
        s = lat.stride(int(k))
        corners, w = multilinear(lat, nodes[sel], lower[sel], s)
        cidx = _flat(lat, corners.reshape(-1, lat.ndim)).reshape(corners.shape[:2])
        # nearest corner (largest weight; ties: the first in lexicographic order) gives the outcome
        # where the corners disagree, and every categorical value
        near = cidx[np.arange(len(sel)), np.argmax(w, axis=1)]
        oc = f.outcome[cidx]
        used = w > 0
        out = f.outcome[near]
        tgt = miss[sel]
        outcome[tgt] = out
        source[tgt] = near
        # the cells' rough flags (by the driving outputs): reported, and a calibration class
        ucells, inv = np.unique(lower[sel], axis=0, return_inverse=True)
        inv = inv.ravel()
        cell_rough = cell_states(lat, f, st, int(k), ucells, driving)["rough"]
        rough_node[tgt] = cell_rough[inv]
        same = used & (oc == out[:, None])
        for name, g_all in ((nm, f.transformed(nm)) for nm in f.values):
            gv = g_all[cidx]                                            # (n, 2^d, m)
            ok = same[:, :, None] & np.isfinite(gv)
            wv = np.where(ok, w[:, :, None], 0.0)
            wsum = wv.sum(axis=1)
            with np.errstate(invalid="ignore", divide="ignore"):
                est = np.einsum("ncm,ncm->nm", wv, np.where(ok, gv, 0.0)) / wsum
            est[(wsum <= 0) | ~np.isfinite(g_all[near])] = np.nan
            lo = np.where(ok, gv, np.inf).min(axis=1)
            hi = np.where(ok, gv, -np.inf).max(axis=1)
            spread = np.where(np.isfinite(lo) & np.isfinite(hi), hi - lo, np.nan)
            ind = bar_indicator(lat, int(k), ucells, surs[name])[inv]            # (n, m)
            cls = cell_class(lat, f, st, int(k), ucells, g_all, driving, cell_rough)[inv]    # (n, m)
            # no indicator (no surplus at this level around): the corners' spread
            bar = np.where(np.isfinite(ind), factors[name].bar(cls, ind), spread)
            scales[name][tgt] = np.where(np.isfinite(spread) | np.isfinite(ind),
                                         np.nan_to_num(spread) + np.nan_to_num(ind), np.nan)
            if f.is_log(name):
                x = np.exp(est)
                absbar = x * np.expm1(bar)
            else:
                x, absbar = est, bar
            absbar = np.where(np.isfinite(x), absbar, np.nan)
            values[name][tgt] = x
            bars[name][tgt] = absbar
    return Map(outcome, source, values, bars, rough_node, cell_level, scales)


def summarise(lat: Lattice, f: Fields) -> dict:
    """Counts for a progress line: computed nodes and their share of the lattice."""
    n = int(f.computed.sum())
    return {"computed": n, "lattice": lat.size, "share": n / lat.size}
