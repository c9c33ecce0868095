"""Analogues of the paper's Figs 3-6 for one scene (matplotlib, Agg backend)."""
from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from .core import model  # noqa: E402
from .simulate import SimulationResult  # noqa: E402


def _save(fig, path: Path, paths: list[Path]) -> None:
    """Write one figure (120 dpi), record its path, and free it."""
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    paths.append(path)


def normal_force_frequency(peaks_tau: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The paper's f_hat = 2/T, T spanning three consecutive peaks of Phi (footnote 3).

    Returns (tau at the third peak, f_hat) for every run of three consecutive located peaks.
    """
    tp = np.asarray(peaks_tau, dtype=float)
    if tp.size < 3:
        return np.empty(0), np.empty(0)
    return tp[2:], 2.0 / (tp[2:] - tp[:-2])


def paper_figures(result: SimulationResult, outdir) -> list[Path]:
    """Write fig3 (alpha, energy), fig4 (Phi, f_hat), fig5 (centre path), fig6 (dtheta/dtau)."""
    tr = result.trajectory
    if tr is None:
        raise ValueError("paper_figures needs a result computed with trajectory=True")
    out = Path(outdir)
    out.mkdir(parents=True, exist_ok=True)
    chi = result.scene.chi
    R = result.scene.config["disk"]["radius"]
    tau = tr["tau"]
    escale = result.scene.energy_scale
    paths = []

    E = tr["energy"] / escale          # dimensionless, as the paper's Fig. 3(b)

    fig, ax = plt.subplots(2, 1, figsize=(7, 6), sharex=True)
    ax[0].plot(tau, tr["alpha"], lw=0.6)
    ax[0].axhline(np.pi / 2, color="k", ls=":", lw=0.8)
    ax[0].set_ylabel(r"$\alpha$ (rad)")
    ax[1].plot(tau, E, lw=0.8)
    sl = tr["mode"] == model.SLIDE
    ax[1].plot(tau[sl], E[sl], ".", ms=1.5, color="C3", label="sliding")
    ax[1].set_ylabel(r"$\hat E$ (energy / ($mR^2/\chi^2$))")
    ax[1].set_xlabel(r"$\tau = t/\chi$")
    ax[1].legend(loc="upper right")
    fig.suptitle(f"Fig. 3 analogue: inclination and energy (chi = {chi:.6g} s, E(0) = {E[0] * escale:.4g} J)")
    _save(fig, out / "fig3_alpha_energy.png", paths)

    fig, ax = plt.subplots(2, 1, figsize=(7, 6), sharex=True)
    ok = np.isfinite(tr["phi"])
    ax[0].plot(tau[ok], tr["phi"][ok], lw=0.4)
    ax[0].set_ylabel(r"$\Phi = \chi^2 N/(mR)$")
    pk = result.peaks[:, 0] / chi if result.peaks is not None and result.peaks.size else np.empty(0)
    tf, fh = normal_force_frequency(pk)
    ax[1].plot(tf, fh, ".", ms=2)
    ax[1].set_ylabel(r"$\hat f = 2/T$")
    ax[1].set_yscale("log")
    ax[1].set_xlabel(r"$\tau$")
    sec = ax[1].secondary_yaxis("right", functions=(lambda f: f / chi, lambda hz: hz * chi))
    sec.set_ylabel("Hz")
    fig.suptitle("Fig. 4 analogue: normal force and its frequency")
    _save(fig, out / "fig4_normal_force.png", paths)

    fig, ax = plt.subplots(figsize=(6, 6))
    ax.plot(tr["x"] / R, tr["y"] / R, lw=0.4)
    ax.set_aspect("equal")
    ax.set_xlabel(r"$\hat x = x/R$")
    ax.set_ylabel(r"$\hat y = y/R$")
    ax.set_title("Fig. 5 analogue: path of the centre of mass")
    _save(fig, out / "fig5_centre_path.png", paths)

    fig, ax = plt.subplots(figsize=(7, 4))
    thd = tr["omega"][:, 2] * chi / np.cos(tr["alpha"])
    ax.plot(tau, thd, lw=0.5)
    ax.set_xlabel(r"$\tau$")
    ax.set_ylabel(r"$d\theta/d\tau = \hat\omega_3 \sec\alpha$")
    ax.set_title("Fig. 6 analogue: precession rate")
    _save(fig, out / "fig6_precession.png", paths)
    return paths
