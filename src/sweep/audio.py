"""The ringing of Euler's disk, synthesised from a simulation (16-bit PCM WAV and a spectrogram).

Model (docs/model.md, "Sound: the disk's flexural modes"):

* Excitation: the table's force on the disk, N(t) E3 at the contact point P (normal force in N from
  the integrator's dense output, evaluated at every audio sample). Its component along the symmetry
  axis e2, F(t) = N(t) E3.e2 = N(t) sin(alpha), bends the disk; the in-plane part excites in-plane
  modes (far above the audio band) and is left out.
* The disk is a free circular plate of the scene's radius and thickness and `material:` (sweep.plate,
  Mindlin theory). Each flexural mode shape (n, s, orientation cos n phi or sin n phi, body-fixed)
  with frequency f_m <= 0.9 x Nyquist is one damped oscillator
  Q'' + 2 zeta w_m Q' + w_m^2 Q = rim_m g(phi_P) F(t) / m_plate, rim_m the mode's rim deflection at
  unit modal mass (= plate mass), g = cos(n phi) or sin(n phi), phi_P = psi - pi/2 the body angle of
  the contact point (it runs round the rim at the spin rate dpsi/dt, about the precession rate).
* Heard signal: the rim's normal velocity at the contact point, sum rim_m g(phi_P) Q'_m (a disk with
  ka = 2 pi f a / c ~ 7 at 10 kHz radiates a pressure ~ rho c v). Each oscillator starts at rest in
  its static deflection under F(0) and is discretised exactly for a force linear between samples
  (first-order hold), so a mode near Nyquist keeps its frequency.
* Normalised to a peak of 0.9 of full scale, 16-bit PCM, mono, written with the stdlib `wave`.
"""
from __future__ import annotations

import math
import os
import wave
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from . import plate
from .errors import ConfigError

RATE_HZ = 44100
PEAK = 0.9                 # normalised peak, fraction of 16-bit full scale
MODE_CAP = 0.9             # modes up to this fraction of the Nyquist frequency


@dataclass
class Ringing:
    """A synthesised sound: `signal` (float, peak PEAK) at `rate_hz` from t = 0 to the scene's end."""

    rate_hz: int
    t: np.ndarray              # s, sample times
    force_n: np.ndarray        # N, bending force N sin(alpha) at the contact point
    signal: np.ndarray         # normalised rim velocity (peak PEAK; 0 if the force never changes)
    velocity_peak_m_s: float   # the rim velocity (m/s) that PEAK stands for
    modes: list                # plate.Mode used
    damping: float             # modal damping ratio


def disk_modes(scene, rate_hz: int = RATE_HZ) -> list:
    """The plate modes of a validated scene's disk heard at rate_hz (f <= MODE_CAP x Nyquist)."""
    d, m = scene.config["disk"], scene.config["material"]
    return plate.plate_modes(d["radius"], d["thickness"], m["E"], m["density"], m["poisson"],
                             f_max_hz=MODE_CAP * 0.5 * rate_hz)


def mode_response(force_n: np.ndarray, rate_hz: float, f_hz: float, zeta: float, gain: float) -> np.ndarray:
    """Velocity Q'(t) of Q'' + 2 zeta w Q' + w^2 Q = gain F(t) (w = 2 pi f_hz), F linear between
    samples (exact first-order-hold discretisation), started at rest in the static deflection
    under F(0)."""
    from scipy import signal

    w = 2.0 * math.pi * f_hz
    A = np.array([[0.0, 1.0], [-w * w, -2.0 * zeta * w]])
    B = np.array([[0.0], [gain]])
    C = np.array([[0.0, 1.0]])
    Ad, Bd, Cd, Dd, _ = signal.cont2discrete((A, B, C, np.zeros((1, 1))), 1.0 / rate_hz, method="foh")
    b, a = signal.ss2tf(Ad, Bd, Cd, Dd)
    # linear: the static deflection under F(0) is a constant state with zero velocity
    return signal.lfilter(b[0], a, force_n - force_n[0])


def synthesize(result, rate_hz: int = RATE_HZ) -> Ringing:
    """Ringing from a SimulationResult whose samples are at uniform times k / rate_hz, k = 0, 1, ..."""
    s = result.samples
    if s is None or len(s["t"]) < 2:
        raise ConfigError("samples", None, f"audio-rate samples (simulate with sample_times = k / {rate_hz})")
    ok = np.isfinite(s["normal_force"])
    n = int(np.count_nonzero(ok))
    t = s["t"][:n]
    force = s["normal_force"][:n] * np.sin(s["alpha"][:n])
    sc = result.scene
    d, mat = sc.config["disk"], sc.config["material"]
    m_plate = mat["density"] * math.pi * d["radius"] ** 2 * d["thickness"]
    modes = disk_modes(sc, rate_hz)
    psi = s["psi"][:n]   # P sits at body angle psi - pi/2 on the rim (e3 = -sin(psi) b1 + cos(psi) b3)
    v = np.zeros(n)
    for md in modes:
        gain = md.rim / m_plate
        if md.n == 0:
            v += md.rim * mode_response(force, rate_hz, md.frequency_hz, mat["damping"], gain)
            continue
        # the pair cos(n phi), sin(n phi): body-fixed shapes, loaded at P and heard at P
        c, si = np.cos(md.n * psi), np.sin(md.n * psi)
        qc = mode_response(force * c, rate_hz, md.frequency_hz, mat["damping"], gain)
        qs = mode_response(force * si, rate_hz, md.frequency_hz, mat["damping"], gain)
        v += md.rim * (qc * c + qs * si)
    peak = float(np.max(np.abs(v))) if n else 0.0
    sig = v * (PEAK / peak) if peak > 0.0 else v
    return Ringing(rate_hz=rate_hz, t=t, force_n=force, signal=sig, velocity_peak_m_s=peak, modes=modes,
                   damping=mat["damping"])


def audio_times(t_end_s: float, rate_hz: int = RATE_HZ) -> np.ndarray:
    """Sample times k / rate_hz covering [0, t_end_s]."""
    return np.arange(int(math.floor(t_end_s * rate_hz)) + 1) / rate_hz


def ringing(scene, rate_hz: int = RATE_HZ):
    """Simulate a scene (path, dict or Scene) and synthesise its ringing. Returns (result, Ringing).
    The scene is run once to find its end, then again with a sample at every audio sample time
    (~1 s for the paper's case: the dense output is evaluated per sample inside the kernel)."""
    from .simulate import simulate

    if not isinstance(rate_hz, int) or isinstance(rate_hz, bool) or not 8000 <= rate_hz <= 192000:
        raise ConfigError("rate_hz", rate_hz, "an integer sample rate in [8000, 192000] Hz")
    first = simulate(scene)
    res = simulate(first.scene, sample_times=audio_times(first.summary["t_end"], rate_hz))
    return res, synthesize(res, rate_hz)


def write_wav(path, ring: Ringing) -> Path:
    """Mono 16-bit PCM WAV at ring.rate_hz (stdlib wave), written atomically."""
    path = Path(path)
    pcm = np.round(np.clip(ring.signal, -1.0, 1.0) * 32767.0).astype("<i2")
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp{os.getpid()}")
    with wave.open(str(tmp), "wb") as w:
        w.setnchannels(1)
        w.setsampwidth(2)
        w.setframerate(ring.rate_hz)
        w.writeframes(pcm.tobytes())
    os.replace(tmp, path)
    return path


# --- frequencies of the simulation, for the spectrogram overlay -------------------------------

def normal_force_frequency_track(peaks: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(t, f) of the paper's normal-force frequency f = 2/T, T spanning three consecutive counted
    maxima of N (result.peaks, times in s: located maxima past the 1 % hysteresis, docs/model.md),
    placed at the middle maximum."""
    tp = np.asarray(peaks)[:, 0] if peaks is not None and len(peaks) else np.zeros(0)
    if len(tp) < 3:
        return np.zeros(0), np.zeros(0)
    span = tp[2:] - tp[:-2]
    good = span > 0
    return tp[1:-1][good], 2.0 / span[good]


def precession_track(t: np.ndarray, theta: np.ndarray, window_s: float) -> tuple[np.ndarray, np.ndarray]:
    """(t, f) of the mean precession frequency |d theta/dt| / 2 pi over consecutive windows (the
    instantaneous rate jitters with the nutation; docs/model.md)."""
    ok = np.isfinite(theta)
    t, theta = t[ok], theta[ok]
    if len(t) < 2:
        return np.zeros(0), np.zeros(0)
    edges = np.arange(t[0], t[-1], window_s)
    if len(edges) < 2:
        edges = np.array([t[0], t[-1]])
    th = np.interp(edges, t, theta)
    return 0.5 * (edges[1:] + edges[:-1]), np.abs(np.diff(th)) / np.diff(edges) / (2.0 * math.pi)


def spectrogram_png(result, ring: Ringing, path, nfft: int = 4096) -> Path:
    """Write `spectrogram_figure` as a PNG at `path`."""
    import matplotlib.pyplot as plt

    fig = spectrogram_figure(result, ring, nfft)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    plt.close(fig)
    return path


def spectrogram_figure(result, ring: Ringing, nfft: int = 4096):
    """Spectrogram (dB below the loudest, log frequency, with its colour bar) of the sound with
    the simulation's precession frequency and normal-force frequency overlaid (legend below the
    axes) and the plate modes marked."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from scipy import signal

    f, tt, S = signal.spectrogram(ring.signal, fs=ring.rate_hz, window="hann", nperseg=nfft,
                                  noverlap=nfft * 3 // 4, scaling="spectrum", mode="psd")
    # onto 240 log-spaced bands (10 Hz .. Nyquist): the mean power of the FFT bins in each band,
    # the nearest bin where a band holds none (a small PNG, quick to draw)
    edges = np.geomspace(10.0, 0.5 * ring.rate_hz, 241)
    idx = np.clip(np.searchsorted(f, edges), 0, len(f) - 1)
    rows = []
    for i in range(240):
        lo, hi = idx[i], idx[i + 1]
        rows.append(S[lo:hi].mean(axis=0) if hi > lo else S[min(lo, len(f) - 1)])
    db = 10.0 * np.log10(np.array(rows) + 1e-30)
    vmax = float(db.max())
    fig, ax = plt.subplots(figsize=(8.0, 5.0), dpi=100)
    dt = tt[1] - tt[0] if len(tt) > 1 else ring.t[-1]
    t_edges = np.concatenate([tt - 0.5 * dt, [tt[-1] + 0.5 * dt]])
    mesh = ax.pcolormesh(t_edges, edges, db - vmax, shading="flat", cmap="magma", vmin=-90.0, vmax=0.0,
                         rasterized=True)
    fig.colorbar(mesh, ax=ax, label="power (dB below the loudest)", pad=0.02)
    ax.set_yscale("log")
    ax.set_ylim(10.0, 0.5 * ring.rate_hz)
    ax.set_xlim(0.0, ring.t[-1])
    tp, fp = precession_track(result.samples["t"], result.samples["theta"], nfft / ring.rate_hz)
    ax.plot(tp, fp, color="cyan", lw=1.2, label="precession frequency (simulation)")
    tn, fn = normal_force_frequency_track(result.peaks)
    if len(tn):
        ax.plot(tn, fn, ".", color="lime", ms=1.5, label="normal-force frequency 2/T (simulation)")
    for md in ring.modes:
        ax.axhline(md.frequency_hz, color="white", lw=0.6, ls="--")
        ax.text(0.01 * ring.t[-1], md.frequency_hz * 1.03, f"mode ({md.n},{md.s}) {md.frequency_hz / 1e3:.2f} kHz",
                color="white", fontsize=7)
    ax.set_xlabel("time t (s)")
    ax.set_ylabel("frequency (Hz)")
    ax.set_title("Ringing of the disk: spectrogram of the synthesised sound\n"
                 f"({len(ring.signal) / ring.rate_hz:.2f} s at {ring.rate_hz} Hz; dashed: the plate modes heard)",
                 fontsize=10)
    # below the axes, not over the data
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.14), ncol=2, fontsize=8, frameon=False, markerscale=4)
    fig.tight_layout()
    return fig
