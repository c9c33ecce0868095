"""The rounds of an adaptive map: which nodes to compute next (sweep.lattice, sweep.surplus).

Round 0 computes the coarse sub-lattice; round k refines the cells of round k - 1 that
sweep.surplus.cell_states flags (outcome boundaries and failures first, then the largest errors),
within the node budget. The map's own surpluses test only the cells it chose to refine, the hard
ones, so a map large enough for it also computes a hold-out in its last round (`holdout_size`): a
random sample of the nodes it would reconstruct, left out of the reconstruction, whose errors
calibrate the bars of the reconstructed nodes directly (sweep.reconstruct.holdout_bars). The sample
is stratified (`holdout_strata`): the nodes the finished map will reconstruct are known when the
last round is planned, and so is each one's error scale for the first driving output
(sweep.interpolation), which splits them into quiet and loud; the quiet stratum, where the map's
median bar lies, gets QUIET_TESTS of the tests, so its bar rests on more of them.

Everything is a function of the set of computed nodes and their values, so the same config
computes the same nodes (determinism: ties are broken by node index), and a round can be planned
again after an interruption with the same answer.
"""
from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field

import numpy as np

from .interpolation import estimate
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


# The hold-out's strata (`holdout_strata`): the nodes the finished map reconstructs that have a
# value of the first driving output are split at the QUIET_SHARE quantile of its error scale
# (sweep.interpolation.error_scale) into quiet and loud; those without one are a stratum of their
# own, sampled in proportion to its size. Of the rest of the hold-out the quiet stratum gets
# QUIET_TESTS. The map's median bar is a quiet node's when QUIET_SHARE > 1/2, so its bar decides
# the median: on issue #52's plane, 3/4 of the tests there instead of their proportional 55 %
# bring the median bar's spread over draws of the hold-out from 3.8-6.7 % to 3.6-5.2 % (10-90 %
# of 300 draws; benchmarks/adaptive_map.py --draws), the loud bin's bar resting on ~25 tests.
QUIET_SHARE = 0.55
QUIET_TESTS = 0.75
STRATUM_NONE, STRATUM_QUIET, STRATUM_LOUD = 0, 1, 2


@dataclass
class Plan:
    """The nodes of a round (lexicographic), and what the round found: cells flagged per reason,
    refined, left for the budget, rough; `holdout`: the nodes of the last round's hold-out
    (among `nodes`; holdout_size); `strata`: where there is one, per lattice node (flat) the
    hold-out stratum of each node the finished map reconstructs (holdout_strata), -1 elsewhere."""
    round: int
    nodes: np.ndarray
    flagged: dict[str, int]
    refined: int
    skipped: int
    rough: int
    holdout: np.ndarray = field(default_factory=lambda: np.zeros((0, 2), np.int64))
    strata: np.ndarray | None = None


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
    strata = None
    if n_hold and k == lat.rounds:
        # a stratified sample of the nodes the map will reconstruct (fixed seed)
        strata = holdout_strata(lat, f, st, taken, surs[st.outputs[0]])
        hold = _draw(strata, n_hold)
        taken[hold] = True
    as_nodes = (lambda idx: np.array(np.unravel_index(idx, lat.shape)).T.astype(np.int64).reshape(-1, lat.ndim))
    flagged = {"outcome": int(cs["disagree"].sum()), "failed": int(cs["failed"].sum()),
               "error": int(((err > 1.0) & ~cs["rough"]).sum())}
    return Plan(k, as_nodes(np.nonzero(taken)[0]), flagged, refined, skipped, int((cs["rough"] & ~by_outcome).sum()),
                as_nodes(hold), strata)


def holdout_strata(lat: Lattice, f: Fields, st: Settings, taken: np.ndarray,
                   sur: np.ndarray) -> np.ndarray:
    """Per lattice node (flat, int8) the hold-out stratum of each node the finished map will
    reconstruct (neither computed in `f`, the rounds before the last, nor `taken` by the last
    round's refinement), -1 elsewhere: STRATUM_NONE where the first driving output gets no value,
    else STRATUM_QUIET or STRATUM_LOUD by its error scale against its QUIET_SHARE quantile over
    them. Those nodes lie in cells of level < R, whose corners and surpluses are all computed
    before the last round, so this is the error scale they have in the finished map. `sur`: the
    first driving output's surpluses in `f` (sweep.surplus.surpluses; the taken nodes have none)."""
    out = np.full(lat.size, -1, np.int8)
    cand = np.nonzero(~f.computed & ~taken)[0]
    if not cand.size:
        return out
    after = Fields(f.computed | taken, f.round, np.where(taken, -1, f.outcome),
                   {k: np.where(taken[:, None], np.nan, v) for k, v in f.values.items()}, dict(f.log))
    name = st.outputs[0]
    nodes = np.array(np.unravel_index(cand, lat.shape)).T.astype(np.int64)
    e = estimate(lat, after, nodes, {name: sur}, (name,))
    has = np.isfinite(e.values[name][:, 0])
    sc = np.where(np.isfinite(e.scale(name)[:, 0]), e.scale(name)[:, 0], np.inf)
    out[cand] = STRATUM_NONE
    if has.any():
        cut = np.quantile(sc[has], QUIET_SHARE, method="inverted_cdf")
        out[cand[has]] = np.where(sc[has] <= cut, STRATUM_QUIET, STRATUM_LOUD)
    return out


def _draw(strata: np.ndarray, n_hold: int) -> np.ndarray:
    """The hold-out (flat indices, sorted): n_hold of the nodes with a stratum, STRATUM_NONE's
    share in proportion to its size, QUIET_TESTS of the rest from STRATUM_QUIET (what a stratum
    lacks goes to the other), each stratum's uniformly at random (seed HOLDOUT_SEED)."""
    members = {s: np.nonzero(strata == s)[0] for s in (STRATUM_NONE, STRATUM_QUIET, STRATUM_LOUD)}
    total = sum(len(v) for v in members.values())
    n_hold = min(n_hold, total)
    n_none = min(len(members[STRATUM_NONE]), round(n_hold * len(members[STRATUM_NONE]) / max(1, total)))
    rest = n_hold - n_none
    n_quiet = min(len(members[STRATUM_QUIET]), round(QUIET_TESTS * rest))
    n_loud = min(len(members[STRATUM_LOUD]), rest - n_quiet)
    n_quiet = min(len(members[STRATUM_QUIET]), rest - n_loud)
    n_none = n_hold - n_quiet - n_loud
    rng = np.random.default_rng(HOLDOUT_SEED)
    picks = [rng.choice(members[s], n, replace=False) for s, n in
             ((STRATUM_NONE, n_none), (STRATUM_QUIET, n_quiet), (STRATUM_LOUD, n_loud))]
    return np.sort(np.concatenate(picks)).astype(np.int64)


def inclusion_weights(strata: np.ndarray, hold: np.ndarray) -> np.ndarray:
    """Per lattice node (flat) the inverse of its stratum's sampling rate, for the hold-out nodes
    (`hold`, bool): the stratum's nodes over its hold-out nodes (NaN elsewhere). A test of stratum
    s stands for N_s / n_s nodes of the map (Horvitz-Thompson)."""
    w = np.full(len(strata), np.nan)
    for s in (STRATUM_NONE, STRATUM_QUIET, STRATUM_LOUD):
        tests = hold & (strata == s)
        if tests.any():
            w[tests] = (strata == s).sum() / tests.sum()
    return w


def holdout_design(lat: Lattice, f: Fields, st: Settings) -> tuple[np.ndarray, np.ndarray | None]:
    """(the computed nodes that are the last round's hold-out (bool (size,)), the strata of the
    nodes the map reconstructs (Plan.strata; None without a hold-out)): the last round is planned
    again from the rounds before it (deterministic), so no file needs to record them; every node
    of the last round that the plan does not refine with is one (so a map computed by another
    plan still gets cells made of refinement nodes only). They are tests of the reconstruction,
    not part of the map's cells."""
    out = np.zeros(lat.size, bool)
    last = f.computed & (f.round == lat.rounds)
    if not holdout_size(lat, st) or not last.any():
        return out, None
    plan = plan_round(lat, f.subset(f.round < lat.rounds), st, lat.rounds)
    refining = np.zeros(lat.size, bool)
    refining[flat_index(lat, plan.nodes)] = True
    refining[flat_index(lat, plan.holdout)] = False
    return last & ~refining, plan.strata


def holdout_mask(lat: Lattice, f: Fields, st: Settings) -> np.ndarray:
    """The computed nodes that are the last round's hold-out (holdout_design)."""
    return holdout_design(lat, f, st)[0]


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
