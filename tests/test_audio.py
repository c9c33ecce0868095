"""Sound of the disk (issue 12): plate modes, the WAV, its spectrum, the material block."""
from __future__ import annotations

import math
from pathlib import Path
import wave

import numpy as np
import pytest

from sweep import audio, plate
from sweep.cli import main
from sweep.errors import ConfigError
from sweep.scene import load_scene

PAPER = str(Path(__file__).resolve().parents[1] / "config" / "scenes" / "kessler2002.yaml")
STEEL = dict(E_pa=195e9, density_kg_m3=7737.27, poisson=0.28)


# --- plate theory -----------------------------------------------------------------------------

# Leissa, Vibration of Plates (NASA SP-160, 1969), Table 2.3: free circular plate, nu = 0.33,
# lam^2 for (n nodal diameters, s nodal circles); the table gives 3-4 digits.
LEISSA_033 = {(2, 0): 5.253, (0, 1): 9.084, (3, 0): 12.23, (1, 1): 20.52, (4, 0): 21.6,
              (2, 1): 35.25, (0, 2): 38.55, (3, 1): 52.91, (1, 2): 59.86}


def test_kirchhoff_eigenvalues_match_leissa_table():
    for n in range(5):
        got = plate.kirchhoff_lambda2(n, 0.33, count=3)
        s0 = plate.first_nodal_circles(n)
        for i, lam2 in enumerate(got):
            ref = LEISSA_033.get((n, s0 + i))
            if ref is not None:
                assert lam2 == pytest.approx(ref, rel=5e-3), (n, s0 + i)


def test_mindlin_tends_to_kirchhoff_for_thin_plates_and_lies_below_for_thick():
    dev = {}
    for h_a in (1e-3, 2e-3):
        modes = plate.plate_modes(0.05, 0.05 * h_a, f_max_hz=1.1e5 * h_a, **STEEL)
        assert [(m.n, m.s) for m in modes[:3]] == [(2, 0), (0, 1), (3, 0)]
        dev[h_a] = {(m.n, m.s): 1.0 - m.frequency_hz / m.kirchhoff_hz for m in modes}
    for key, d in dev[1e-3].items():
        assert 0.0 < d < 2e-4, key
        ratio = dev[2e-3][key] / d
        # axisymmetric modes: O((h/a)^2) (shear, rotary inertia); n >= 1: O(h/a) from the free
        # edge's boundary layer (Kirchhoff merges M_rphi = 0 and Q_r = 0 into one condition)
        assert (3.6 < ratio < 4.4) if key[0] == 0 else (1.8 < ratio < 2.3), (key, ratio)
    thick = plate.plate_modes(0.03755, 0.0128, f_max_hz=25000.0, **STEEL)
    for m in thick:
        assert 0.7 < m.frequency_hz / m.kirchhoff_hz < 0.99
    # Kirchhoff frequency from first principles: lam^2/(2 pi a^2) sqrt(D/(rho h))
    a, h = 0.03755, 0.0128
    D = 195e9 * h**3 / (12 * (1 - 0.28**2))
    lam2 = plate.kirchhoff_lambda2(2, 0.28, 1)[0]
    assert thick[0].kirchhoff_hz == pytest.approx(lam2 / (2 * math.pi * a * a) * math.sqrt(D / (7737.27 * h)), rel=1e-12)


def test_paper_disk_modes_in_the_audio_band():
    sc = load_scene(PAPER)
    modes = audio.disk_modes(sc)
    assert [(m.n, m.s) for m in modes] == [(2, 0), (0, 1)]
    assert modes[0].frequency_hz == pytest.approx(10583, rel=2e-3)
    assert modes[1].frequency_hz == pytest.approx(16937, rel=2e-3)
    for m in modes:   # unit modal mass = plate mass: the rim moves more than the mean (|W| rms = 1)
        assert 1.0 < m.rim < 3.0


def test_mode_response_rings_at_its_frequency_and_starts_static():
    """A step of the force rings the oscillator at w sqrt(1 - zeta^2), decaying as exp(-zeta w t),
    with velocity amplitude gain dF / w: the exact discretisation keeps a mode near Nyquist in tune."""
    rate, f0, zeta, gain = 44100, 19000.0, 2e-3, 3.0
    force = np.full(44100, 2.0)
    force[100:] = 2.5
    v = audio.mode_response(force, rate, f0, zeta, gain)
    assert np.max(np.abs(v[:100])) == 0.0     # at rest in the static deflection: no start transient
    t = (np.arange(len(v)) - 99.5) / rate    # from the middle of the one-sample ramp
    seg = slice(200, 4000)
    w0 = 2 * np.pi * f0
    wd = w0 * np.sqrt(1 - zeta**2)
    # least squares on the known model exp(-zeta w0 t) (A cos wd t + B sin wd t)
    basis = np.exp(-zeta * w0 * t[seg])[:, None] * np.stack([np.cos(wd * t[seg]), np.sin(wd * t[seg])], 1)
    coef, *_ = np.linalg.lstsq(basis, v[seg], rcond=None)
    resid = v[seg] - basis @ coef
    assert np.sqrt(np.mean(resid**2)) < 1e-6 * np.max(np.abs(v[seg]))
    # first-order hold: the step is a ramp over one sample, which filters the amplitude by sinc(f0 / rate)
    ramp = np.sinc(f0 / rate)
    assert np.hypot(*coef) == pytest.approx(gain * 0.5 / w0 * ramp, rel=2e-3)


# --- the WAV of the paper's case ----------------------------------------------------------------

@pytest.fixture(scope="module")
def paper_wav(tmp_path_factory):
    path = tmp_path_factory.mktemp("audio") / "ringing.wav"
    spec = path.with_name("spec.png")
    assert main(["scene", PAPER, "--audio", str(path), "--spectrogram", str(spec)]) == 0
    with wave.open(str(path), "rb") as w:
        params = w.getparams()
        x = np.frombuffer(w.readframes(params.nframes), dtype="<i2").astype(float)
    res, _ = audio.ringing(PAPER)
    return params, x, res, spec


def test_wav_is_valid_pcm_of_the_simulated_length(paper_wav):
    params, x, res, spec = paper_wav
    assert (params.nchannels, params.sampwidth, params.framerate) == (1, 2, 44100)
    assert abs(params.nframes / params.framerate - res.summary["t_end"]) <= 1.0 / params.framerate
    assert np.all(np.isfinite(x))
    peak = np.max(np.abs(x))
    assert peak == pytest.approx(audio.PEAK * 32767, abs=1.0)   # normalised, no clipping
    assert np.count_nonzero(np.abs(x) >= 32767) == 0
    assert spec.stat().st_size > 10_000


def band_power(x, rate, lo, hi):
    from scipy import signal
    f, p = signal.welch(x, rate, nperseg=16384)
    m = (f >= lo) & (f < hi)
    return float(p[m].mean())


def test_energy_concentrates_in_the_listed_modes(paper_wav):
    params, x, res, _ = paper_wav
    rate = params.framerate
    modes = audio.disk_modes(res.scene)
    fm = [m.frequency_hz for m in modes]
    edges = [2000.0] + [0.5 * (a + b) for a, b in zip(fm, fm[1:])] + [0.5 * rate * 0.99]
    for k, f0 in enumerate(fm):
        inside = band_power(x, rate, 0.99 * f0, 1.01 * f0)
        # between modes: the stretches of spectrum away from every mode (2 % margins)
        below = band_power(x, rate, edges[k], 0.98 * f0)
        above = band_power(x, rate, 1.02 * f0, edges[k + 1])
        assert inside > 30.0 * max(below, above), (f0, inside, below, above)


def dominant(x, rate, lo, hi):
    x = x - x.mean()
    sp = np.abs(np.fft.rfft(x * np.hanning(len(x)))) ** 2
    f = np.fft.rfftfreq(len(x), 1.0 / rate)
    m = (f > lo) & (f < hi)
    return f[m][np.argmax(sp[m])]


def test_modulation_rises_with_the_normal_force_frequency(paper_wav):
    """Below the lowest mode the sound carries the excitation's own rhythm: its dominant frequency
    in an early and a late window equals that of N(t) there and rises as N's frequency does."""
    params, x, res, _ = paper_wav
    rate = params.framerate
    N = res.samples["normal_force"]
    f_first = audio.disk_modes(res.scene)[0].frequency_hz
    got = []
    for a, b in ((14.0, 15.0), (18.6, 18.9)):
        i, j = int(a * rate), int(b * rate)
        fs = dominant(x[i:j], rate, 4.0, 0.2 * f_first)
        fn = dominant(N[i:j], rate, 4.0, 0.2 * f_first)
        # the same line (two FFT bins, or 8 %: late, N's frequency chirps within the window)
        assert fs == pytest.approx(fn, abs=max(2.0 * rate / (j - i), 0.08 * fn)), (a, fs, fn)
        got.append(fs)
    assert got[1] > 4.0 * got[0]
    # and the simulation's own level frequencies rise the same way (0.01 -> 1e-4 rad: 75 -> 389 Hz)
    lv = res.summary["levels"]
    assert lv[-1]["normal_force_hz"] > 4.0 * lv[1]["normal_force_hz"]


# --- validation ----------------------------------------------------------------------------------

@pytest.mark.parametrize("field, value", [("E", -1.0e9), ("E", 0.0), ("density", -5.0), ("poisson", 0.5),
                                          ("poisson", -1.0), ("poisson", 0.7), ("damping", 0.0), ("damping", "x")])
def test_bad_material_is_rejected_naming_the_field(field, value):
    with pytest.raises(ConfigError) as exc:
        load_scene({"material": {field: value}})
    assert f"material.{field}" in str(exc.value)


def test_material_does_not_change_the_physics():
    a = load_scene({})
    b = load_scene({"material": {"E": 7.0e10, "density": 2700.0, "poisson": 0.33, "damping": 0.01}})
    assert np.array_equal(a.params, b.params) and a.chi == b.chi


def test_cli_rejects_bad_audio_name_before_work(capsys):
    assert main(["scene", PAPER, "--audio", "ringing.mp3"]) == 2
    assert "--audio" in capsys.readouterr().err


def test_spectrogram_has_a_colour_bar_and_keeps_its_legend_off_the_data(paper_wav):
    import matplotlib.pyplot as plt

    _, _, res, spec = paper_wav
    assert spec.read_bytes()[:4] == b"\x89PNG"
    ring = audio.synthesize(res)
    fig = audio.spectrogram_figure(res, ring)
    try:
        ax, cbar = fig.axes
        assert cbar.get_ylabel() == "power (dB below the loudest)" and cbar.get_ylim() == (-90.0, 0.0)
        assert ax.get_xlabel() == "time t (s)" and ax.get_ylabel() == "frequency (Hz)"
        fig.canvas.draw()
        legend = ax.get_legend().get_window_extent()
        assert legend.y1 <= ax.get_window_extent().y0    # below the axes, not over the spectrogram
    finally:
        plt.close(fig)
