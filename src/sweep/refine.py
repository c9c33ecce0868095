"""The rounds of an adaptive map: which nodes to compute next (sweep.lattice, sweep.surplus).

Round 0 computes the coarse sub-lattice; round k refines the cells of round k - 1 that
sweep.surplus.cell_states flags (outcome boundaries and failures first, then the largest errors),
within the node budget. The map's own surpluses test only the cells it chose to refine, the hard
ones, so a map large enough for it also computes a hold-out in its last round (`holdout_size`): a
uniform random sample of the nodes it would reconstruct, left out of the reconstruction, whose
errors calibrate the bars of the reconstructed nodes directly (sweep.reconstruct.holdout_bars).

Everything is a function of the set of computed nodes and their values, so the same config
computes the same nodes (determinism: ties are broken by node index), and a round can be planned
again after an interruption with the same answer.
"""
from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field

import numpy as np

from .lattice import Fields, Lattice, Settings, cells, flat_index
from .surplus import cell_states, surpluses


# A round before the last spends at most this share of the budget left on cells flagged for their
# error (outcome boundaries and failures first, without this cap).
ERROR_SHARE = 0.5


# The hold-out (a random sample of the nodes the finished map would reconstruct, computed in the
# last round as tests of its reconstruction, `holdout_size`): this share of the budget, when that is
# HOLDOUT_MIN nodes at least; drawn with a fixed seed (determinism). The map's own surpluses test
# only the cells it chose to refine, the hard ones (their quietest tenth errs ~5x more than the
# quietest half of the reconstructed nodes on issue #52's plane), so only a sample of the
# reconstructed nodes themselves can show how small the error is where the map is quiet.
HOLDOUT_SHARE = 0.14
HOLDOUT_MIN = 60
HOLDOUT_SEED = 52


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
        idx = flat_index(lat, low[i] + sub)
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
    refining[flat_index(lat, plan.nodes)] = True
    refining[flat_index(lat, plan.holdout)] = False
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
        leaf = ~f.computed[flat_index(lat, low + lat.stride(level) // 2)]
        if not leaf.any():
            continue
        cs = cell_states(lat, f, st, level, low[leaf], surs)
        out += int((cs["rough"] & ~cs["disagree"] & ~cs["failed"]).sum())
    return out
