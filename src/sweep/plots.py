"""Analogues of the paper's Figs 3-6 for one scene (matplotlib, Agg backend)."""
from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from .core.constants import SLIDE  # noqa: E402
from .simulate import SimulationResult  # noqa: E402


def _save(fig, path: Path, paths: list[Path]) -> None:
    """Write one figure (120 dpi), record its path, and free it."""
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    paths.append(path)


def normal_force_frequency(peaks_tau: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The paper's f_hat = 2/T, T spanning three consecutive peaks of Phi (footnote 3).

    Returns (time of the third peak, f_hat) for every run of three consecutive located peaks: in
    the peaks' unit of time and its inverse (s and Hz for SimulationResult.peaks).
    """
    tp = np.asarray(peaks_tau, dtype=float)
    if tp.size < 3:
        return np.empty(0), np.empty(0)
    return tp[2:], 2.0 / (tp[2:] - tp[:-2])


def _tau_axis(ax, chi: float) -> None:
    """The paper's dimensionless time tau = t / chi on the top edge of an axes whose x is t (s)."""
    top = ax.secondary_xaxis("top", functions=(lambda t: t / chi, lambda tau: tau * chi))
    top.set_xlabel(rf"$\tau = t/\chi$ (paper's time, $\chi$ = {chi:.4g} s)", fontsize=8)
    top.tick_params(labelsize=8)


def paper_figures(result: SimulationResult, outdir) -> list[Path]:
    """Write fig3 (alpha, energy), fig4 (Phi, f_hat), fig5 (centre path), fig6 (dtheta/dt): the
    analogues of the paper's Figs 3-6, against time t in s (the paper's tau = t/chi on the top
    edge), with SI values on a second axis beside the paper's dimensionless ones."""
    tr = result.trajectory
    if tr is None:
        raise ValueError("paper_figures needs a result computed with trajectory=True")
    out = Path(outdir)
    out.mkdir(parents=True, exist_ok=True)
    chi = result.scene.chi
    R = result.scene.config["disk"]["radius"]
    m = result.scene.config["disk"]["mass"]
    t = tr["t"]
    escale = result.scene.energy_scale
    paths = []

    E = tr["energy"] / escale          # dimensionless, as the paper's Fig. 3(b)

    fig, ax = plt.subplots(2, 1, figsize=(7, 6.4), sharex=True)
    ax[0].plot(t, tr["alpha"], lw=0.6)
    ax[0].axhline(np.pi / 2, color="k", ls=":", lw=0.8, label=r"$\pi/2$: lying flat")
    ax[0].set_ylabel(r"tilt $\alpha$ (rad)")
    ax[0].legend(loc="lower right", fontsize=8)
    _tau_axis(ax[0], chi)
    ax[1].plot(t, E, lw=0.8)
    sl = tr["mode"] == SLIDE
    ax[1].plot(t[sl], E[sl], ".", ms=1.5, color="C3", label="sliding")
    ax[1].set_ylabel(r"energy $\hat E = E/(mR^2/\chi^2)$")
    joules = ax[1].secondary_yaxis("right", functions=(lambda e: e * escale, lambda j: j / escale))
    joules.set_ylabel("energy E (J)")
    ax[1].set_xlabel("time t (s)")
    ax[1].legend(loc="upper right")
    fig.suptitle(f"Fig. 3 analogue: inclination and energy (E(0) = {E[0] * escale:.4g} J)")
    _save(fig, out / "fig3_alpha_energy.png", paths)

    fig, ax = plt.subplots(2, 1, figsize=(7, 6.4), sharex=True)
    ok = np.isfinite(tr["phi"])
    newton = m * R / chi ** 2          # N per unit of Phi
    ax[0].plot(t[ok], tr["phi"][ok], lw=0.4)
    ax[0].set_ylabel(r"normal force $\Phi = \chi^2 N/(mR)$")
    force = ax[0].secondary_yaxis("right", functions=(lambda p: p * newton, lambda n: n / newton))
    force.set_ylabel("normal force N (N)")
    _tau_axis(ax[0], chi)
    pk = result.peaks[:, 0] if result.peaks is not None and result.peaks.size else np.empty(0)
    tf, fh = normal_force_frequency(pk)      # peaks in s: f_hat in Hz
    ax[1].plot(tf, fh, ".", ms=2)
    ax[1].set_ylabel(r"normal-force frequency $\hat f = 2/T$ (Hz)")
    ax[1].set_yscale("log")
    ax[1].set_xlabel("time t (s)")
    fig.suptitle("Fig. 4 analogue: normal force and its frequency")
    _save(fig, out / "fig4_normal_force.png", paths)

    fig, ax = plt.subplots(figsize=(6, 6))
    ax.plot(tr["x"] / R, tr["y"] / R, lw=0.4)
    ax.set_aspect("equal")
    ax.set_xlabel(r"$\hat x = x/R$")
    ax.set_ylabel(r"$\hat y = y/R$")
    ax.set_title(f"Fig. 5 analogue: path of the centre of mass (R = {R * 1e3:.4g} mm)")
    _save(fig, out / "fig5_centre_path.png", paths)

    fig, ax = plt.subplots(figsize=(7, 4.4))
    thd = tr["omega"][:, 2] * chi / np.cos(tr["alpha"])
    ax.plot(t, thd, lw=0.5)
    ax.set_xlabel("time t (s)")
    ax.set_ylabel(r"$d\theta/d\tau = \hat\omega_3 \sec\alpha$")
    hz = ax.secondary_yaxis("right", functions=(lambda r: r / chi / (2 * np.pi), lambda f: f * chi * 2 * np.pi))
    hz.set_ylabel(r"precession rate $(d\theta/dt)/2\pi$ (Hz)")
    _tau_axis(ax, chi)
    ax.set_title("Fig. 6 analogue: precession rate")
    _save(fig, out / "fig6_precession.png", paths)
    return paths
