"""Single-scene API: `simulate(scene) -> SimulationResult` (SI units at this boundary)."""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from . import outcomes
from .core import model
from .core.fits import D_APPROACH, D_HALT_FINITE, D_RAMP, D_RAMP_ERR, D_THALT, D_THALT_ERR, N_DERIVED, summary_fits
from .core.integrate import integrate
from .core.layout import (F_DIMPACT, F_E0, F_EEND, F_NFMAX, F_SLIDETIME, F_TEND, I_EVENTS, I_FLAT, I_IMPACTS,
                          I_OUTCOME, I_REJECTED, I_RHS, I_SLIDE_REJECTED, I_SLIDE_STEPS, I_STEPS, I_STICK,
                          I_TRANS, N_SETTINGS, S_ATOL, S_HMAX, S_KIN, S_MAXSTEPS, S_PEAKS, S_RTOL,
                          S_TMAX)
from .errors import ConfigError
from .scene import Scene, load_scene

@dataclass
class SimulationResult:
    """What one scene produced. `summary` is JSON-able (SI units); arrays are numpy.

    samples: dict at the requested sample times (NaN after the scene ended), from the dense output:
    t (s), alpha (rad), omega (n x 3, rad/s on e1, e2, e3), slip (n x 2, m/s on a1, a2), theta, psi
    (rad), x, y (m, centre of mass), normal_force (N), mode (0 rolling, 1 sliding), energy (J). trajectory: dict of arrays at every
    accepted step (t, alpha, omega, slip, theta, psi, x, y, Phi, mode, energy in J) if requested.
    """

    scene: Scene
    summary: dict
    samples: dict | None = None
    trajectory: dict | None = None
    peaks: np.ndarray | None = field(default=None, repr=False)


def initial_state(scene: Scene) -> tuple[np.ndarray, int]:
    """Dimensionless initial state and mode (SLIDE if the initial slip is non-zero; the kernel
    makes a slip at or below slip_tol a slaved one)."""
    cfg = scene.config
    chi, R = scene.chi, cfg["disk"]["radius"]
    y0 = np.zeros(model.N_FULL)
    ini = cfg["initial"]
    y0[model.Y_ALPHA] = ini["alpha"]
    y0[model.Y_W1:model.Y_W3 + 1] = np.asarray(ini["omega"]) * chi
    slip = np.asarray(ini["slip"]) * chi / R
    mode = model.SLIDE if np.any(slip != 0.0) else model.ROLL
    y0[model.Y_U1:model.Y_U2 + 1] = slip
    y0[model.Y_THETA] = ini["theta"]
    y0[model.Y_PSI] = ini["psi"]
    return y0, mode


def _settings(scene: Scene) -> np.ndarray:
    cfg = scene.config
    so, st, out = cfg["solver"], cfg["stop"], cfg["outputs"]
    s = np.zeros(N_SETTINGS)
    s[S_RTOL] = so["rtol"]
    s[S_ATOL] = so["atol"]
    s[S_HMAX] = so["dt"] / scene.chi if so["method"] == "fixed" else 0.0
    s[S_TMAX] = st["t_max"] / scene.chi
    s[S_MAXSTEPS] = st["max_steps"]
    s[S_KIN] = 1.0 if out["kinematics"] else 0.0
    s[S_PEAKS] = 1.0 if out["normal_force_frequency"] else 0.0
    return s


def level_energies(scene: Scene) -> np.ndarray:
    """Dimensionless energies E_ss(beta) of the configured levels (decreasing)."""
    return np.array([model.steady_rolling_energy(b, scene.params) for b in scene.levels])


def run_kernel(scene: Scene, sample_tau: np.ndarray | None = None, traj_cap: int = 0):
    """Call the numba kernel for a validated scene; returns its KernelOutput (named arrays)."""
    y0, _ = initial_state(scene)
    st = np.zeros(0) if sample_tau is None else np.ascontiguousarray(sample_tau, dtype=float)
    return integrate(y0, scene.params, _settings(scene), level_energies(scene), st, traj_cap)


def trajectory_energy(traj: np.ndarray, scene: Scene) -> np.ndarray:
    """Dimensionless energy (eq. 6.1, corrected) at every row of the kernel's trajectory buffer."""
    E = np.empty(traj.shape[0])
    for i in range(traj.shape[0]):
        y = traj[i, 1:1 + model.N_FULL]
        side = 1 if y[model.Y_ALPHA] > 0 else -1
        E[i] = model.energy(y, scene.params, side, min(int(traj[i, 2 + model.N_FULL]), 1))
    return E


def _finite_or_nan(x: float) -> float:
    return float(x) if math.isfinite(x) else math.nan


def summary_from(sc: Scene, istats: np.ndarray, fstats: np.ndarray, lev: np.ndarray, y_end: np.ndarray,
                 wall: float, fits: np.ndarray | None = None) -> dict:
    """The JSON-able summary (SI) of a scene from the kernel's outputs: istats, fstats, lev (levels x
    layout.LEVEL_COLS: tau, alpha, mean dtheta/dtau, f_hat, ringing ratio, window cycles), y_end. fits: the scene's `core.fits.summary_fits` (D_*),
    computed here unless the caller has them (the batch path computes them per scene on its device)."""
    chi = sc.chi
    escale = sc.energy_scale
    levels = sc.levels
    level_t = lev[:, 0] * chi
    # frequencies (docs/model.md, 'Frequencies at the levels'): magnitude of the mean dtheta/dt over
    # whole precession cycles around the level / 2 pi; Phi's dominant frequency over the same
    # window (ringing ratio x precession); the paper's f_hat = 2/T over three counted Phi maxima
    prec_hz = np.abs(lev[:, 2]) / chi / (2.0 * math.pi)
    ratio = lev[:, 4]
    ring_hz = ratio * prec_hz
    nf_hz = lev[:, 3] / chi
    code = int(istats[I_OUTCOME])
    lay_flat = bool(istats[I_FLAT])
    if fits is None:
        # the disk that reached the table face-down halted there, located as an event
        fits = np.empty(N_DERIVED)
        summary_fits(level_t, prec_hz, np.asarray(levels, dtype=float), len(levels), lay_flat,
                     np.asarray(fstats, dtype=float), chi, fits)
    t_end = float(fstats[F_TEND]) * chi
    dis = y_end[model.Y_DSLIDE:model.Y_DK3 + 1] * escale
    return {
        "outcome": outcomes.NAMES[code],
        "outcome_code": code,
        "t_end": t_end,
        "t_halt": _finite_or_nan(fits[D_THALT]),
        "t_halt_error": _finite_or_nan(fits[D_THALT_ERR]),
        "lay_flat": lay_flat,
        "halt_finite": bool(fits[D_HALT_FINITE]),
        "approach_exponent": _finite_or_nan(fits[D_APPROACH]),
        "ramp_exponent": _finite_or_nan(fits[D_RAMP]),
        "ramp_exponent_error": _finite_or_nan(fits[D_RAMP_ERR]),
        "levels": [
            {"inclination": float(b), "t": _finite_or_nan(level_t[i]),
             "precession_hz": _finite_or_nan(prec_hz[i]), "ringing_hz": _finite_or_nan(ring_hz[i]),
             "ringing_ratio": _finite_or_nan(ratio[i]), "normal_force_hz": _finite_or_nan(nf_hz[i])}
            for i, b in enumerate(levels)
        ],
        "normal_force_hz_max": float(fstats[F_NFMAX]) / chi if fstats[F_NFMAX] > 0.0 else math.nan,
        "slip_fraction": float(fstats[F_SLIDETIME] / fstats[F_TEND]) if fstats[F_TEND] > 0 else 0.0,
        "n_transitions": int(istats[I_TRANS]),
        "n_stick": int(istats[I_STICK]),
        "n_impacts": int(istats[I_IMPACTS]),
        "energy_initial": float(fstats[F_E0]) * escale,
        "energy_final": float(fstats[F_EEND]) * escale,
        "dissipation": {"sliding": float(dis[0]), "k1": float(dis[1]), "k2": float(dis[2]),
                        "k3": float(dis[3]), "impact": float(fstats[F_DIMPACT]) * escale},
        "n_steps": int(istats[I_STEPS]),
        "n_rejected": int(istats[I_REJECTED]),
        "n_steps_sliding": int(istats[I_SLIDE_STEPS]),
        "n_rejected_sliding": int(istats[I_SLIDE_REJECTED]),
        "n_rhs": int(istats[I_RHS]),
        "n_events": int(istats[I_EVENTS]),
        "wall_time": wall,
    }


def simulate(scene, sample_times=None, trajectory: bool = False) -> SimulationResult:
    """Run one scene. `scene`: path to a YAML scene file or a dict of the same structure.

    sample_times: times (s, >= 0, increasing) at which alpha, omega and energy are returned.
    trajectory: also return the state at every accepted step.
    Either request integrates the passive kinematics (theta, psi, x, y); they are left out of the
    error control, so the steps, events and summary are the same as without them.
    Raises ConfigError for invalid input, before any integration.
    """
    sc = scene if isinstance(scene, Scene) else load_scene(scene)
    if (trajectory or sample_times is not None) and not sc.config["outputs"]["kinematics"]:
        cfg = {**sc.config, "outputs": {**sc.config["outputs"], "kinematics": True}}
        sc = load_scene(cfg)
    sample_tau = None
    if sample_times is not None:
        st = np.atleast_1d(np.asarray(sample_times, dtype=float))
        if st.ndim != 1 or not np.all(np.isfinite(st)) or np.any(st < 0) or np.any(np.diff(st) < 0):
            raise ConfigError("sample_times", list(np.atleast_1d(sample_times)),
                              "finite times >= 0 s in increasing order")
        sample_tau = st / sc.chi
    chi = sc.chi
    escale = sc.energy_scale
    t0 = time.perf_counter()
    out = run_kernel(sc, sample_tau, 65536 if trajectory else 0)   # grows (rerun) if too small
    istats, fstats, lev, samp, traj, peaks, y_end = out
    wall = time.perf_counter() - t0

    summary = summary_from(sc, istats, fstats, lev, y_end, wall)
    samples = None
    if sample_tau is not None:
        R = sc.config["disk"]["radius"]
        samples = {
            "t": sample_tau * chi,
            "alpha": samp[:, model.Y_ALPHA].copy(),
            "omega": samp[:, model.Y_W1:model.Y_W3 + 1] / chi,
            "slip": samp[:, model.Y_U1:model.Y_U2 + 1] * R / chi,
            "theta": samp[:, model.Y_THETA].copy(),
            "psi": samp[:, model.Y_PSI].copy(),
            "x": samp[:, model.Y_X] * R,
            "y": samp[:, model.Y_Y] * R,
            "normal_force": samp[:, model.N_FULL + 1] * sc.config["disk"]["mass"] * R / chi**2,
            "mode": np.minimum(samp[:, model.N_FULL + 2], 1.0),   # 1: sliding (also the slaved slip)
            "energy": samp[:, model.N_FULL] * escale,
        }
    tr = None
    if trajectory:
        R = sc.config["disk"]["radius"]
        tr = {
            "t": traj[:, 0] * chi,
            "alpha": traj[:, 1 + model.Y_ALPHA].copy(),
            "omega": traj[:, 1 + model.Y_W1:2 + model.Y_W3] / chi,
            "slip": traj[:, 1 + model.Y_U1:2 + model.Y_U2] * R / chi,
            "theta": traj[:, 1 + model.Y_THETA].copy(),
            "psi": traj[:, 1 + model.Y_PSI].copy(),
            "x": traj[:, 1 + model.Y_X] * R,
            "y": traj[:, 1 + model.Y_Y] * R,
            "normal_force": traj[:, 1 + model.N_FULL] * sc.config["disk"]["mass"] * R / chi**2,
            "phi": traj[:, 1 + model.N_FULL].copy(),
            "mode": np.minimum(traj[:, 2 + model.N_FULL], 1).astype(np.int8),
            "tau": traj[:, 0].copy(),
            "energy": trajectory_energy(traj, sc) * escale,
        }
    return SimulationResult(scene=sc, summary=summary, samples=samples, trajectory=tr, peaks=peaks[:, :2] * [chi, 1.0])
