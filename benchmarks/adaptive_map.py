"""Adaptive maps against the dense lattice and against uniform sampling (issue #52, item 5).

    .venv/bin/python benchmarks/adaptive_map.py [--points 33] [--planes paper,friction] [--jobs 2]
                                               [--max-share 0.25] [--start 5] [--tolerance 0.01]
                                               [--draws 8] [--sensitivity 3]

For each plane (a 2-D map of the pipeline's `refine:` mode; the other axes fixed):

1. the dense lattice, every node computed scene by scene with the pipeline's chunk runner
   (sweep.adaptive.run_chunks, `--jobs` processes), its chunk files cached under
   benchmarks/out/adaptive_map/<plane>-<points>/chunks/ (content-addressed, as the pipeline's: a
   rerun with the same settings computes nothing);
2. the adaptive map (sweep.refine.plan_round / reconstruct, the rounds the pipeline runs), whose
   computed nodes take their values from the dense lattice: the integrator is deterministic, so
   these are the values the pipeline would compute (its last round's hold-out included: those
   nodes count as computed);
3. uniform sampling with at least as many scenes: every second node (stride 2), reconstructed the
   same way (nearest outcome, multilinear in log t_halt; no hold-out, so the surpluses' bars).

Reports, side by side: scenes computed (share of the lattice), outcome wrong (share of the
lattice's nodes), boundary displacement (for every node with a wrong outcome, the Chebyshev
distance in lattice cells to the nearest node that truly has the outcome it was given: mean and
max), t_halt's relative error at the reconstructed nodes that halted in both (median, p95, max;
also where the map is smooth: the issue's criterion, |second difference of log t_halt| < 0.01
along both axes, and the ratio of uniform's median there to the adaptive one's), the share of
those nodes where the error bar holds (|error| <= t_halt_interpolation_error), and the median bar
relative to the value. Then: the lattice-scale noise where smooth (sigma from fourth
differences) and how much larger the fourth differences are where n_transitions changes within
the stencil; the adaptive map's coverage, median bar and outcome errors over `--draws` other draws
of its hold-out (seeds 0..draws-1); with `--sensitivity N`, N smooth and N rough nodes rerun at
tighter knobs (rtol, slip_tol, slave_tol) and with the first axis moved by +-1e-10, and the
smoothest lattice line of each axis rerun at all the tight knobs at once (sigma before/after).

Planes: `paper` is issue #52's plane (mu_d 0.3, the paper's k1, k2, k3; alpha0 0.05..1.5 rad x
omega0 2..200 rad/s log-spaced); `friction` is mu_d 0.05..0.45 x k3 0..8e-4 m at alpha0 1.0 rad,
omega0 20 rad/s; `slow` is alpha0 0.2..1.4 x omega0 4..40 rad/s log at mu_d 0.2 (the paper's k's).
Solver and stop settings: config/config.yaml's (rtol 1e-10, t_max 120 s).
"""
from __future__ import annotations

import argparse
import concurrent.futures
import math
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

from sweep import adaptive, chunking, grid, lattice, outcomes, reconstruct, refine
from sweep import axes as sweep_axes  # noqa: E402

PAPER_K = {"k1": [3.755e-6], "k2": [3.004e-5], "k3": [3.004e-4]}
PLANES = {
    "paper": ({"mu_d": [0.3], **PAPER_K},
              {"alpha0": {"from": 0.05, "to": 1.5}, "omega0": {"from": 2.0, "to": 200.0, "spacing": "log"}}),
    "friction": ({"k1": [3.755e-6], "k2": [3.004e-5], "alpha0": [1.0], "omega0": [20.0]},
                 {"mu_d": {"from": 0.05, "to": 0.45}, "k3": {"from": 0.0, "to": 8.0e-4}}),
    "slow": ({"mu_d": [0.2], **PAPER_K},
             {"alpha0": {"from": 0.2, "to": 1.4}, "omega0": {"from": 4.0, "to": 40.0, "spacing": "log"}}),
}


# The dense lattices' chunk layout (their cache's chunk ids): the tensor sweep's content-defined
# cut of the lattice in lexicographic order, whatever config.yaml's chunk_size.
DENSE_CHUNK_SIZE = 16


def settings_of(plane: str, points: int, start: int, share: float, tol: float) -> dict:
    import yaml

    cfg = yaml.safe_load((ROOT / "config" / "config.yaml").read_text())
    outer, axes = PLANES[plane]
    cfg["name"] = f"bench-{plane}"
    cfg["grid"] = dict(outer)
    cfg["refine"] = {"axes": {a: dict(spec, points=points) for a, spec in axes.items()},
                     "start_points": start, "max_share": share, "tolerance": tol}
    cfg["outputs"] = {"notebooks": []}
    cfg["chunk_size"] = DENSE_CHUNK_SIZE
    return grid.normalize(cfg)


def dense(settings: dict, out: Path, jobs: int) -> adaptive.MapState:
    """Every node of the plane's lattice, computed (or read from the cache)."""
    lat = adaptive.lattice(settings)
    (map_id, outer), = adaptive.maps(settings).items()
    nodes = np.array(np.unravel_index(np.arange(lat.size), lat.shape)).T
    inner = {lat.point(n): n for n in nodes}
    blocks = [np.array([inner[p] for p in b]) for b in chunking.split_inner(list(inner), DENSE_CHUNK_SIZE)]
    chunks = adaptive.chunks_of(settings, outer, lat, blocks)
    t0 = time.perf_counter()
    ran = adaptive.run_chunks(chunks, out / "chunks", jobs)
    print(f"  dense {lat.shape[0]}x{lat.shape[1]}: {len(chunks)} chunks, {ran} computed now "
          f"({time.perf_counter() - t0:.0f} s), the rest from {out / 'chunks'}", flush=True)
    state = adaptive.MapState(settings)
    state.add_chunks([out / "chunks" / f"{c.id}.nc" for c in chunks], 0)
    return state


def subset(lat, truth: adaptive.MapState, computed: np.ndarray, rnd: np.ndarray) -> lattice.Fields:
    f = lattice.Fields.empty(lat, {k: v.shape[1] for k, v in truth.fields.values.items()}, truth.fields.log)
    idx = np.nonzero(computed)[0]
    nodes = np.array(np.unravel_index(idx, lat.shape)).T
    f.set(lat, nodes, 0, truth.fields.outcome[idx], {k: v[idx] for k, v in truth.fields.values.items()})
    f.round[idx] = rnd[idx]
    return f


def adaptive_fields(lat, st, truth: adaptive.MapState) -> lattice.Fields:
    """The rounds the pipeline runs, every computed node's values taken from the dense lattice."""
    f = lattice.Fields.empty(lat, {k: v.shape[1] for k, v in truth.fields.values.items()}, truth.fields.log)
    for k in range(lat.rounds + 1):
        plan = refine.plan_round(lat, f, st, k)
        print(f"    round {k}: {len(plan.nodes)} scenes; cells flagged {plan.flagged}, refined {plan.refined}, "
              f"left for the budget {plan.skipped}, rough {plan.rough}")
        if not len(plan.nodes):
            continue
        idx = lattice.flat_index(lat, plan.nodes)
        f.set(lat, plan.nodes, k, truth.fields.outcome[idx], {n: v[idx] for n, v in truth.fields.values.items()})
    return f


def uniform_fields(lat, truth: adaptive.MapState) -> lattice.Fields:
    nodes = np.array(np.unravel_index(np.arange(lat.size), lat.shape)).T
    on = (nodes % 2 == 0).all(axis=1)
    return subset(lat, truth, on, np.where(on, 0, -1))


def smooth_mask(lat, truth: adaptive.MapState) -> np.ndarray:
    """Nodes where log t_halt is smooth: |second difference| < 0.01 along both axes (interior
    nodes whose neighbours halted)."""
    g = np.log(truth.fields.values["t_halt"][:, 0]).reshape(lat.shape)
    ok = np.zeros(lat.shape, bool)
    d0 = np.abs(g[2:, 1:-1] - 2 * g[1:-1, 1:-1] + g[:-2, 1:-1])
    d1 = np.abs(g[1:-1, 2:] - 2 * g[1:-1, 1:-1] + g[1:-1, :-2])
    ok[1:-1, 1:-1] = (d0 < 0.01) & (d1 < 0.01)
    return ok.ravel()


def noise_floor(lat, truth: adaptive.MapState, smooth: np.ndarray) -> float:
    """The lattice-scale noise of log t_halt where the map is smooth: sigma from the fourth
    differences between neighbours along each axis (median |4th difference| / (0.6745 sqrt(70)),
    what independent noise of sigma gives; a smooth function's are far below its second
    differences). Interpolating noisy nodes errs ~sigma at best, whatever the interpolant."""
    g = np.log(truth.fields.values["t_halt"][:, 0]).reshape(lat.shape)
    sm = smooth.reshape(lat.shape)
    d = []
    for a in range(2):
        h = np.moveaxis(g, a, 0)
        m = np.moveaxis(sm, a, 0)[2:-2]
        d4 = h[4:] - 4 * h[3:-1] + 6 * h[2:-2] - 4 * h[1:-3] + h[:-4]
        d.append(np.abs(d4[m & np.isfinite(d4)]))
    d = np.concatenate(d)
    return float(np.median(d) / (0.6745 * math.sqrt(70))) if d.size else math.nan


def staircase(lat, truth: adaptive.MapState, smooth: np.ndarray) -> tuple[float, float, float]:
    """(median |4th difference| of log t_halt where n_transitions is the same at the stencil's 5
    nodes, where it is not, the share of stencils where it is) over the smooth stencils along both
    axes: whether the lattice-scale 'noise' is the steps t_halt takes where a roll/slip transition
    is gained or lost between neighbouring scenes."""
    g = np.log(truth.fields.values["t_halt"][:, 0]).reshape(lat.shape)
    n = truth.raw["n_transitions"].reshape(lat.shape)
    same, other = [], []
    for a in range(2):
        h, nn = np.moveaxis(g, a, 0), np.moveaxis(n, a, 0)
        m = np.moveaxis(smooth.reshape(lat.shape), a, 0)[2:-2]
        d4 = np.abs(h[4:] - 4 * h[3:-1] + 6 * h[2:-2] - 4 * h[1:-3] + h[:-4])
        const = (nn[4:] == nn[2:-2]) & (nn[3:-1] == nn[2:-2]) & (nn[1:-3] == nn[2:-2]) & (nn[:-4] == nn[2:-2])
        ok = m & np.isfinite(d4)
        same.append(d4[ok & const])
        other.append(d4[ok & ~const])
    same, other = np.concatenate(same), np.concatenate(other)
    med = (lambda a: float(np.median(a)) if a.size else math.nan)
    return med(same), med(other), same.size / max(1, same.size + other.size)


def sensitivity(settings: dict, lat, truth: adaptive.MapState, smooth: np.ndarray, count: int) -> None:
    """Rerun `count` smooth and `count` rough halted nodes (fixed choice) with tighter knobs and
    perturbed starts, and print the largest change of log t_halt of each against the stored value
    and against the node's neighbours: numerical noise or structure of the dynamics?"""
    import copy
    import importlib

    simulate = importlib.import_module("sweep.simulate").simulate
    (_, outer), = adaptive.maps(settings).items()
    g = np.log(truth.fields.values["t_halt"][:, 0])
    gg = g.reshape(lat.shape)
    d2 = np.zeros(lat.shape)
    d2[1:-1, 1:-1] = np.fmax(np.abs(gg[2:, 1:-1] - 2 * gg[1:-1, 1:-1] + gg[:-2, 1:-1]),
                             np.abs(gg[1:-1, 2:] - 2 * gg[1:-1, 1:-1] + gg[1:-1, :-2]))
    halted = np.isfinite(g) & (truth.fields.outcome == outcomes.HALTED)
    rng = np.random.default_rng(5)
    ax0 = lat.axes[0]
    knobs = {"rtol 1e-12": {"solver": {"rtol": 1e-12, "atol": 1e-14}}, "slip_tol 1e-11": {"solver": {"slip_tol": 1e-11}},
             "slave_tol 3e-4": {"solver": {"slave_tol": 3e-4}}, f"{ax0} +1e-10": 1e-10, f"{ax0} -1e-10": -1e-10}
    for kind, pool in (("smooth", halted & smooth), ("rough", halted & (np.nan_to_num(d2.ravel()) > 0.1))):
        worst = {k: 0.0 for k in knobs}
        nb = []
        for i in rng.choice(np.nonzero(pool)[0], min(count, int(pool.sum())), replace=False):
            node = np.unravel_index(i, lat.shape)
            for k, change in knobs.items():
                full = dict(outer, **dict(zip(lat.axes, lat.point(node))))
                if not isinstance(change, dict):
                    full[ax0] += change
                sc = grid.scene(settings, tuple(float(full[a]) for a in sweep_axes.AXES))
                for sec, kv in (change.items() if isinstance(change, dict) else ()):
                    sc = dict(sc, **{sec: dict(copy.deepcopy(sc[sec]), **kv)})
                worst[k] = max(worst[k], abs(math.log(simulate(sc).summary["t_halt"]) - g[i]))
            nb += [abs(gg[node[0] + a, node[1] + b] - g[i]) for a, b in ((1, 0), (-1, 0), (0, 1), (0, -1))
                   if 0 <= node[0] + a < lat.shape[0] and 0 <= node[1] + b < lat.shape[1]]
        print(f"  sensitivity, {count} {kind} nodes: largest |change of log t_halt| "
              + ", ".join(f"{k} {v:.1e}" for k, v in worst.items())
              + f"; between lattice neighbours: median {np.nanmedian(nb):.1e}", flush=True)
    # the lattice-scale noise along the smoothest lattice line of each axis, at all the tight knobs at once
    tight = {k: v for c in knobs.values() if isinstance(c, dict) for k, v in c["solver"].items()}
    sm = (smooth & halted).reshape(lat.shape)
    for a in range(lat.ndim):
        other = int(np.argmax(np.moveaxis(sm, a, 0).sum(axis=0)))
        line = np.nonzero(np.moveaxis(sm, a, 0)[:, other])[0]
        nodes = [tuple(i if b == a else other for b in range(lat.ndim)) for i in range(line.min(), line.max() + 1)]
        pts = [tuple(float(dict(outer, **dict(zip(lat.axes, lat.point(n))))[x]) for x in sweep_axes.AXES) for n in nodes]
        scenes = [dict(sc, solver=dict(sc["solver"], **tight)) for sc in (grid.scene(settings, p) for p in pts)]
        with concurrent.futures.ProcessPoolExecutor(2) as pool:
            got = np.log([r.summary["t_halt"] for r in pool.map(simulate, scenes)])
        base = np.array([gg[n] for n in nodes])
        sig = (lambda h: float(np.nanmedian(np.abs(h[4:] - 4 * h[3:-1] + 6 * h[2:-2] - 4 * h[1:-3] + h[:-4]))
                                / (0.6745 * math.sqrt(70))))
        print(f"  along {lat.axes[a]} ({len(nodes)} nodes at {lat.axes[1 - a]} index {other}): sigma {sig(base):.3e} "
              f"at the config's knobs, {sig(got):.3e} at {tight}; |change of log t_halt| median "
              f"{np.nanmedian(np.abs(got - base)):.1e}, max {np.nanmax(np.abs(got - base)):.1e}", flush=True)


def draws(lat, st, truth: adaptive.MapState, smooth: np.ndarray, seeds: int) -> None:
    """The adaptive map's figures over `seeds` draws of its hold-out (HOLDOUT_SEED 0..seeds-1): how
    much one map's coverage and median bar owe to its draw."""
    import contextlib
    import io

    keep = refine.HOLDOUT_SEED
    rows = []
    try:
        for seed in range(seeds):
            refine.HOLDOUT_SEED = seed
            with contextlib.redirect_stdout(io.StringIO()):
                rows.append(metrics(lat, st, truth, adaptive_fields(lat, st, truth), smooth))
    finally:
        refine.HOLDOUT_SEED = keep
    for key, label, fmt in (("holds", "error bar holds", "{:.1%}"), ("bar_med", "median bar / value", "{:.2%}"),
                            ("outcome_wrong", "outcome wrong", "{:.2%}")):
        v = np.array([r[key] for r in rows])
        print(f"  over {seeds} draws of the hold-out: {label} min {fmt.format(v.min())}, median "
              f"{fmt.format(float(np.median(v)))}, mean {fmt.format(float(np.mean(v)))}, max {fmt.format(v.max())}"
              + (f"; >= 90 % in {int((v >= 0.9).sum())}" if key == "holds" else "")
              + (f"; <= 5 % in {int((v <= 0.05).sum())}" if key == "bar_med" else ""), flush=True)
    # every output's coverage averaged over the draws (what split-conformal promises), the lowest;
    # and the worst of them within one draw (the minimum of ~47 noisy shares)
    mean_cover = {k: float(np.mean([r["cover"][k] for r in rows if k in r["cover"]])) for k in rows[0]["cover"]}
    if mean_cover:
        low = min(mean_cover, key=mean_cover.get)
        worst = np.array([r["cover_min"] for r in rows])
        print(f"  over {seeds} draws of the hold-out: every output's bars hold on average at >= {mean_cover[low]:.1%} "
              f"({low}; >= 90 % for {sum(v >= 0.9 for v in mean_cover.values())} of {len(mean_cover)}); the worst "
              f"output of one draw holds at {worst.min():.1%}-{worst.max():.1%}", flush=True)


def leave_one_out(lat, truth: adaptive.MapState, smooth: np.ndarray) -> dict[str, float]:
    """The best any reconstruction can do where the map is smooth: each smooth node predicted
    from every other node of the dense lattice (leave-one-out), by the mean of its 4 axis
    neighbours and by least-squares quadratics over the 3 x 3 and 5 x 5 windows around it
    without it; {predictor: median relative t_halt error over the smooth nodes}. A map computed
    on a quarter of the lattice knows less than any of these."""
    g = np.log(truth.fields.values["t_halt"][:, 0]).reshape(lat.shape)
    sm = smooth.reshape(lat.shape)
    out = {}
    p = np.full(lat.shape, np.nan)
    p[1:-1, 1:-1] = 0.25 * (g[2:, 1:-1] + g[:-2, 1:-1] + g[1:-1, 2:] + g[1:-1, :-2])
    preds = {"4-neighbour mean": p}
    for r in (1, 2):
        ii, jj = np.meshgrid(np.arange(-r, r + 1), np.arange(-r, r + 1), indexing="ij")
        keep = ~((ii == 0) & (jj == 0))
        x, y = ii[keep].astype(float), jj[keep].astype(float)
        centre = np.linalg.pinv(np.array([np.ones_like(x), x, y, x * x, x * y, y * y]).T)[0]
        win = np.lib.stride_tricks.sliding_window_view(g, (2 * r + 1, 2 * r + 1))[..., keep]
        p = np.full(lat.shape, np.nan)
        p[r:-r, r:-r] = win @ centre
        preds[f"quadratic, {2 * r + 1} x {2 * r + 1}"] = p
    for name, p in preds.items():
        e = np.abs(np.expm1(p - g))
        ok = sm & np.isfinite(e)
        out[name] = float(np.median(e[ok])) if ok.any() else math.nan
    return out


def displacement(lat, truth_oc: np.ndarray, got: np.ndarray) -> tuple[float, float]:
    """(mean, max) over nodes with a wrong outcome of the Chebyshev distance (cells) to the
    nearest node whose true outcome is the one given there."""
    wrong = np.nonzero(truth_oc != got)[0]
    if not wrong.size:
        return 0.0, 0.0
    nodes = np.array(np.unravel_index(np.arange(lat.size), lat.shape)).T
    d = []
    for i in wrong:
        cand = nodes[truth_oc == got[i]]
        d.append(np.abs(cand - nodes[i]).max(axis=1).min() if len(cand) else math.inf)
    return float(np.mean(d)), float(np.max(d))


def metrics(lat, st, truth: adaptive.MapState, f: lattice.Fields, smooth: np.ndarray) -> dict:
    m = reconstruct.reconstruct(lat, f, st)
    oc = truth.fields.outcome
    rec = ~f.computed
    t_true = truth.fields.values["t_halt"][:, 0]
    t_got = m.values["t_halt"][:, 0]
    bar = m.bars["t_halt"][:, 0]
    halted = rec & (oc == outcomes.HALTED) & (m.outcome == outcomes.HALTED) & np.isfinite(t_true) & np.isfinite(t_got)
    rel = np.abs(t_got - t_true) / t_true
    holds = np.abs(t_got - t_true) <= bar
    sm = halted & smooth
    mean_d, max_d = displacement(lat, oc, m.outcome)
    # every continuous output's bars, where the outcome is right and both values exist
    cover = {}
    right = rec & (m.outcome == oc)
    for name, v in truth.fields.values.items():
        for c in range(v.shape[1]):
            ok = right & np.isfinite(v[:, c]) & np.isfinite(m.values[name][:, c])
            if ok.sum() >= 100:
                cover[name if v.shape[1] == 1 else f"{name}[{c}]"] = float(
                    (np.abs(m.values[name][ok, c] - v[ok, c]) <= m.bars[name][ok, c]).mean())
    worst = min(cover, key=cover.get) if cover else ""
    q = (lambda a, p: float(np.percentile(a, p)) if a.size else math.nan)
    return {
        "scenes": int(f.computed.sum()), "share": f.computed.mean(),
        "outcome_wrong": float((m.outcome != oc).mean()), "disp_mean": mean_d, "disp_max": max_d,
        "n_halted": int(halted.sum()),
        "err_med": q(rel[halted], 50), "err_p95": q(rel[halted], 95), "err_max": q(rel[halted], 100),
        "holds": float(holds[halted].mean()) if halted.any() else math.nan,
        "bar_med": q((bar / t_got)[halted], 50),
        "n_smooth": int(sm.sum()), "err_med_smooth": q(rel[sm], 50), "err_p95_smooth": q(rel[sm], 95),
        "rough_nodes": int(m.rough.sum()),
        "cover_min": cover.get(worst, math.nan), "cover_worst": worst, "cover": cover,
        "cover_outputs": sum(c >= 0.9 for c in cover.values()), "n_outputs": len(cover),
    }


ROWS = [("scenes computed", "scenes", "{:d}"), ("share of the lattice", "share", "{:.1%}"),
        ("outcome wrong (share of nodes)", "outcome_wrong", "{:.2%}"),
        ("boundary displacement mean (cells)", "disp_mean", "{:.2f}"),
        ("boundary displacement max (cells)", "disp_max", "{:.0f}"),
        ("reconstructed halted nodes", "n_halted", "{:d}"),
        ("t_halt rel. error median", "err_med", "{:.3%}"), ("t_halt rel. error p95", "err_p95", "{:.2%}"),
        ("t_halt rel. error max", "err_max", "{:.1%}"),
        ("error bar holds (share)", "holds", "{:.1%}"), ("median bar / value", "bar_med", "{:.2%}"),
        ("smooth reconstructed halted nodes", "n_smooth", "{:d}"),
        ("t_halt rel. error median, smooth", "err_med_smooth", "{:.4%}"),
        ("t_halt rel. error p95, smooth", "err_p95_smooth", "{:.3%}"),
        ("nodes in rough cells", "rough_nodes", "{:d}"),
        ("outputs whose bars hold at >= 90 %", "cover_outputs", "{:d}"),
        ("outputs with >= 100 nodes to test", "n_outputs", "{:d}"),
        ("bars hold, the worst output", "cover_min", "{:.1%}")]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--points", type=int, default=33, help="lattice points per axis (2^L + 1)")
    ap.add_argument("--planes", default="paper,friction")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--max-share", type=float, default=0.25)
    ap.add_argument("--start", type=int, default=9, help="start_points (round 0's points per axis)")
    ap.add_argument("--tolerance", type=float, default=0.01)
    ap.add_argument("--dense-only", action="store_true", help="compute the dense lattices and stop")
    ap.add_argument("--draws", type=int, default=8, help="draws of the hold-out to report the spread over (0: none)")
    ap.add_argument("--sensitivity", type=int, default=0,
                    help="rerun this many smooth and rough nodes with tighter knobs and perturbed starts")
    args = ap.parse_args()
    for plane in args.planes.split(","):
        settings = settings_of(plane, args.points, args.start, args.max_share, args.tolerance)
        out = ROOT / "benchmarks" / "out" / "adaptive_map" / f"{plane}-{args.points}"
        print(f"plane {plane}: {adaptive.map_label(next(iter(adaptive.maps(settings).values())))}; "
              f"{', '.join(f'{a} {s}' for a, s in settings['refine']['axes'].items())}", flush=True)
        truth = dense(settings, out, args.jobs)
        if args.dense_only:
            continue
        lat = adaptive.lattice(settings)
        st = adaptive.refine_settings(settings, lat)
        counts = {outcomes.NAMES[int(c)]: int(n) for c, n in zip(*np.unique(truth.fields.outcome, return_counts=True))}
        print(f"  dense outcomes: {counts}; start_points {args.start}, max_share {args.max_share}, "
              f"tolerance {args.tolerance}, rounds {lat.rounds + 1}")
        smooth = smooth_mask(lat, truth)
        t0 = time.perf_counter()
        fa = adaptive_fields(lat, st, truth)
        t_plan = time.perf_counter() - t0
        a = metrics(lat, st, truth, fa, smooth)
        u = metrics(lat, st, truth, uniform_fields(lat, truth), smooth)
        print(f"  (planning and reconstruction of the adaptive map: {t_plan:.2f} s)")
        print(f"  {'':38s} {'adaptive':>12s} {'uniform':>12s}")
        for label, key, fmt in ROWS:
            print(f"  {label:38s} {fmt.format(a[key]):>12s} {fmt.format(u[key]):>12s}")
        ratio = u["err_med_smooth"] / a["err_med_smooth"] if a["err_med_smooth"] > 0 else math.inf
        sigma = noise_floor(lat, truth, smooth)
        print(f"  smooth: {int(smooth.sum())} of {lat.size} nodes of the dense lattice (|second difference of log "
              f"t_halt| < 0.01 along both axes); there log t_halt's lattice-scale noise is sigma = {sigma:.3%} "
              f"(fourth differences), uniform's median error {u['err_med_smooth'] / sigma:.1f} sigma")
        print(f"  bars of every continuous output (per level), the worst: adaptive {a['cover_worst']}, "
              f"uniform {u['cover_worst']}")
        print(f"  uniform / adaptive t_halt median error where smooth: {ratio:.1f}x", flush=True)
        loo = leave_one_out(lat, truth, smooth)
        print("  where smooth, each node predicted from all the others (leave-one-out), median error: "
              + ", ".join(f"{k} {v:.3%}" for k, v in loo.items())
              + f"; 4x below uniform would be {u['err_med_smooth'] / 4:.3%}", flush=True)
        same, other, share = staircase(lat, truth, smooth)
        print(f"  smooth stencils with the same n_transitions at all 5 nodes ({share:.0%}): median |4th difference| "
              f"{same:.1e}; where it changes: {other:.1e} ({other / same:.0f}x)", flush=True)
        if args.draws:
            draws(lat, st, truth, smooth, args.draws)
        if args.sensitivity:
            sensitivity(settings, lat, truth, smooth, args.sensitivity)


if __name__ == "__main__":
    main()
