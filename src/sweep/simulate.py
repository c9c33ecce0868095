"""Single-scene API: `simulate(scene) -> SimulationResult` (SI units at this boundary)."""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from . import outputs
from .core import model
from .core.fits import N_DERIVED, summary_fits
from .core.integrate import integrate
from .core.constants import SLIDE
from .core.layout import (I_FLAT, L_PRECESSION, L_TAU, N_SETTINGS, S_ATOL, S_HMAX, S_KIN, S_MAXSTEPS, S_PEAKS, S_RTOL, S_TMAX,
                          SA_ENERGY, SA_MODE, SA_PHI, TR_MODE, TR_PHI, TR_TAU, TR_Y)
from .errors import ConfigError
from .scene import Scene, initial_state, load_scene  # noqa: F401 - initial_state: its API home stays here too


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
    # |theta(t_end)| / 2 pi, the precession cycles of the contact line over the run (theta, eq. 2.1,
    # is integrated for the frequency outputs, samples or a trajectory; NaN where it is not)
    precession_cycles: float = math.nan


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
        y = traj[i, TR_Y:TR_Y + model.N_FULL]
        side = 1 if y[model.Y_ALPHA] > 0 else -1
        E[i] = model.energy(y, scene.params, side, min(int(traj[i, TR_MODE]), SLIDE))   # SLAVED: sliding
    return E


def summary_from(sc: Scene, istats: np.ndarray, fstats: np.ndarray, lev: np.ndarray, y_end: np.ndarray,
                 wall: float, fits: np.ndarray | None = None) -> dict:
    """The JSON-able summary (SI) of a scene from the kernel's outputs (sweep.outputs.OUTPUTS says
    what it holds): istats, fstats, lev (levels x layout.LEVEL_COLS), y_end. fits: the scene's
    `core.fits.summary_fits` (D_*), computed here unless the caller has them (the batch path
    computes them per scene in its worker)."""
    if fits is None:
        chi = sc.chi
        # the level times (s) and precession frequencies (Hz) the fits read: the centred windows'
        # only (a one-sided value, the summary's where there is no centred one, is not fitted)
        level_t = lev[:, L_TAU] * chi
        prec_hz = np.abs(lev[:, L_PRECESSION]) / chi / (2.0 * math.pi)
        fits = np.empty(N_DERIVED)
        summary_fits(level_t, prec_hz, np.asarray(sc.levels, dtype=float), len(sc.levels), bool(istats[I_FLAT]),
                     np.asarray(fstats, dtype=float), chi, fits)
    return outputs.summary(outputs.Source(sc, istats, fstats, lev, y_end, fits, wall))


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
            "normal_force": samp[:, SA_PHI] * sc.config["disk"]["mass"] * R / chi**2,
            "mode": np.minimum(samp[:, SA_MODE], float(SLIDE)),   # SLIDE: sliding (also the slaved slip)
            "energy": samp[:, SA_ENERGY] * escale,
        }
    tr = None
    if trajectory:
        R = sc.config["disk"]["radius"]
        tr = {
            "t": traj[:, TR_TAU] * chi,
            "alpha": traj[:, TR_Y + model.Y_ALPHA].copy(),
            "omega": traj[:, TR_Y + model.Y_W1:TR_Y + model.Y_W3 + 1] / chi,
            "slip": traj[:, TR_Y + model.Y_U1:TR_Y + model.Y_U2 + 1] * R / chi,
            "theta": traj[:, TR_Y + model.Y_THETA].copy(),
            "psi": traj[:, TR_Y + model.Y_PSI].copy(),
            "x": traj[:, TR_Y + model.Y_X] * R,
            "y": traj[:, TR_Y + model.Y_Y] * R,
            "normal_force": traj[:, TR_PHI] * sc.config["disk"]["mass"] * R / chi**2,
            "phi": traj[:, TR_PHI].copy(),
            "mode": np.minimum(traj[:, TR_MODE], SLIDE).astype(np.int8),   # SLIDE: sliding (also the slaved slip)
            "tau": traj[:, TR_TAU].copy(),
            "energy": trajectory_energy(traj, sc) * escale,
        }
    out_cfg = sc.config["outputs"]
    theta_on = out_cfg["kinematics"] or out_cfg["normal_force_frequency"]
    cycles = abs(float(y_end[model.Y_THETA])) / (2.0 * math.pi) if theta_on else math.nan
    return SimulationResult(scene=sc, summary=summary, samples=samples, trajectory=tr, peaks=peaks[:, :2] * [chi, 1.0],
                            precession_cycles=cycles)
