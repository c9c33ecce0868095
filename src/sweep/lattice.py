"""The lattice of an adaptive map, and what is known on it.

Pure numpy, no I/O (the pipeline's side is sweep.adaptive). A map is a lattice of 2^L_a + 1 points
on each of its d axes (d = 2 or 3; values in the axes' SI units, evenly spaced or evenly spaced in
log), indexed by integer nodes. Round 0 computes the coarse sub-lattice of stride S = 2^R (R: the
number of refinement rounds); round k (1..R) works at stride s_k = 2^(R - k) and refines some
*cells* of round k - 1: a cell is a box of side s_{k-1} whose 2^d corners are computed; refining it
computes every node of its sub-lattice of stride s_k (the 3^d - 2^d that are new, fewer where a
neighbour already computed the shared ones), which makes its 2^d children cells.

Here: the lattice (`Lattice`, `make_lattice`), its nodes, rounds and cells, multilinear
interpolation weights in a cell (index space: linear in the axis' spacing), what is known per node
(`Fields`: computed, round, outcome, the continuous outputs) and the refinement settings
(`Settings`). The refinement criteria are in sweep.surplus, the planning of the rounds in
sweep.refine, the error bars' calibration in sweep.errorbars, the full map in sweep.reconstruct.
"""
from __future__ import annotations

import itertools
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np


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


def flat_index(lat: Lattice, nodes: np.ndarray) -> np.ndarray:
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
        idx = flat_index(lat, nodes)
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


def cells(lat: Lattice, computed: np.ndarray) -> dict[int, np.ndarray]:
    """The cells that exist per level: level 0's all; level k + 1's the children of the level-k
    cells whose centre is computed (refined). {level: lower corners (n, d)}, lexicographic."""
    s0 = lat.stride(0)
    out = {0: np.array(list(itertools.product(*(range(0, n - 1, s0) for n in lat.shape))), dtype=np.int64)}
    off = corner_offsets(lat.ndim)
    for k in range(0, lat.rounds):
        low = out[k]
        s = lat.stride(k)
        refined = low[computed[flat_index(lat, low + s // 2)]] if len(low) else low
        kids = (refined[:, None, :] + (s // 2) * off[None, :, :]).reshape(-1, lat.ndim)
        out[k + 1] = np.unique(kids, axis=0) if len(kids) else np.zeros((0, lat.ndim), np.int64)
    return out


def corner_index(lat: Lattice, lower: np.ndarray, s: int) -> np.ndarray:
    corners = lower[:, None, :] + s * corner_offsets(lat.ndim)[None, :, :]
    return flat_index(lat, corners.reshape(-1, lat.ndim)).reshape(len(lower), -1)


@dataclass
class Settings:
    """Refinement settings: the driving outputs, the tolerance (an interpolation error bar the
    map needs: relative for a log output, a share of the output's range over the map otherwise),
    the node budget (computed nodes at most)."""
    outputs: tuple[str, ...]
    tolerance: float
    budget: int


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
            exists = computed[flat_index(lat, pl + s)]
        take = exists & (level < 0)
        level[take] = k
        lower[take] = low[take]
    return level, lower
