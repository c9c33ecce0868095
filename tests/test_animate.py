"""Animation of a scene (issue 12): geometry against the model's frames, frames, first-frame tilt."""
from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from sweep import animate
from sweep.cli import main
from sweep.errors import ConfigError

PAPER = str(Path(__file__).resolve().parents[1] / "config" / "scenes" / "kessler2002.yaml")
R, L = 0.03755, 0.0128


def test_contact_point_on_the_table_and_centre_height():
    rng = np.random.default_rng(3)
    n = 500
    alpha = rng.uniform(-1.5, 1.5, n)
    alpha[alpha == 0] = 0.1
    theta, psi = rng.uniform(-20, 20, n), rng.uniform(-20, 20, n)
    x, y = rng.uniform(-0.1, 0.1, n), rng.uniform(-0.1, 0.1, n)
    g = animate.disk_geometry(x, y, theta, alpha, psi, R, L)
    P, c = g["contact"], g["centre"]
    assert np.max(np.abs(P[:, 2])) < 1e-15                     # P on the table
    H = 0.5 * L * np.sign(alpha)
    # centre height: the model's e R = R cos(alpha) + H sin(alpha) (docs/model.md), which is
    # R cos|alpha| + (L/2) sin|alpha| on either rim edge (H sin|alpha| would sink an alpha < 0 disk)
    assert np.allclose(c[:, 2], R * np.cos(alpha) + H * np.sin(alpha), atol=1e-15)
    assert np.allclose(c[:, 2], R * np.cos(np.abs(alpha)) + 0.5 * L * np.sin(np.abs(alpha)), atol=1e-15)
    # P is the lowest point of the solid: every rim point of both faces lies on or above the table
    low = np.minimum(g["rim_contact"][..., 2].min(axis=1), g["rim_far"][..., 2].min(axis=1))
    assert np.all(low > -1e-15)
    # and P lies on the contact face's rim (distance R from that face's centre, in its plane)
    face_c = c - H[:, None] * g["e2"]
    d = P - face_c
    assert np.allclose(np.linalg.norm(d, axis=1), R, rtol=1e-13)
    assert np.allclose(np.einsum("ij,ij->i", d, g["e2"]), 0.0, atol=1e-15)
    # e2 (symmetry axis) makes the angle alpha with the vertical's complement: E3.e2 = sin(alpha)
    assert np.allclose(g["e2"][:, 2], np.sin(alpha), atol=1e-15)


def test_frames_right_handed_and_orthonormal():
    e1, e2, e3, b1, b3 = animate.frames_of([0.3, -2.0], [0.7, -0.4], [1.1, 5.0])
    for u, v, w in ((e1, e2, e3), (b1, e2, b3)):
        M = np.stack([u, v, w], axis=1)
        assert np.allclose(np.einsum("nij,nkj->nik", M, M), np.eye(3), atol=1e-14)
        assert np.allclose(np.cross(u, v), w, atol=1e-14)


def test_warped_clock_slows_towards_the_halt():
    t = animate.warped_times(18.95, 19.39, 200)
    assert t[0] == 0.0 and t[-1] == 18.95 and np.all(np.diff(t) > 0)
    dt = np.diff(t)
    assert dt[0] > 20 * dt[-1]              # the clock slows as the disk flattens
    assert np.count_nonzero(t > 17.95) > 0.2 * len(t)   # the last second holds > 20 % of the frames
    # frames uniform in log(t_h - t)
    assert np.allclose(np.diff(np.log(19.39 - t)), np.diff(np.log(19.39 - t))[0], rtol=1e-9)


@pytest.mark.parametrize("fps, secs, field", [(0, 5.0, "--fps"), (-3, 5.0, "--fps"), (float("nan"), 5.0, "--fps"),
                                              (10, 0.0, "--animation-seconds"), (10, 25.0, "--animation-seconds")])
def test_bad_options_rejected_naming_the_option(fps, secs, field):
    with pytest.raises(ConfigError) as exc:
        animate.check_options(fps, secs)
    assert field in str(exc.value)


def test_cli_rejects_fps_before_any_work(capsys, tmp_path):
    out = tmp_path / "d.gif"
    assert main(["scene", PAPER, "--animate", str(out), "--fps", "0"]) == 2
    assert "--fps" in capsys.readouterr().err and not out.exists()
    assert main(["scene", PAPER, "--animate", str(tmp_path / "d.avi")]) == 2
    assert "--animate" in capsys.readouterr().err


def _disk_mask(rgb):
    """Pixels of the disk (face, side and rim colours), tolerant to the GIF palette."""
    cols = [animate.FACE_COLOR, animate.SIDE_COLOR, animate.RIM_COLOR]
    mask = np.zeros(rgb.shape[:2], bool)
    for c in cols:
        ref = np.array([int(c[i:i + 2], 16) for i in (1, 3, 5)])
        mask |= np.abs(rgb.astype(int) - ref).max(axis=2) <= 12
    return mask


def test_gif_has_the_frames_and_the_first_frame_shows_the_initial_tilt(tmp_path):
    fps, secs = 10.0, 1.5
    out = tmp_path / "disk.gif"
    info = animate.write_animation(PAPER, out, fps=fps, duration_s=secs)
    im = Image.open(out)
    assert im.n_frames == info["frames"] == round(fps * secs)
    assert im.size == (animate.WIDTH_PX, animate.HEIGHT_PX)
    assert info["bytes"] == out.stat().st_size <= animate.MAX_BYTES
    im.seek(0)
    rgb = np.asarray(im.convert("RGB"))
    rows = np.nonzero(_disk_mask(rgb).any(axis=1))[0]
    extent_px = rows.max() - rows.min() + 1
    # expected: the projection onto the camera's up vector of a disk tilted by alpha0 at theta = 0,
    # built here from the paper's frame definitions (e1 = E1, e2 = (0, cos a, sin a), e3 = (0, -sin a, cos a))
    a0 = 1.0
    el, az = animate.ELEVATION, animate.AZIMUTH
    up = np.array([-math.sin(el) * math.cos(az), -math.sin(el) * math.sin(az), math.cos(el)])
    e1, e2, e3 = np.array([1.0, 0, 0]), np.array([0, math.cos(a0), math.sin(a0)]), np.array([0, -math.sin(a0), math.cos(a0)])
    extent_m = 2 * R * math.hypot(up @ e1, up @ e3) + L * abs(up @ e2)
    scale = info["scale_px_per_m"]
    assert extent_px == pytest.approx(extent_m * scale, abs=3.0)
    # a disk lying flat would look different: the upright extent at alpha = pi/2 - 1e-4 is far off
    flat = 2 * R * math.hypot(up @ e1, up @ np.array([0, -1.0, 0])) + L * abs(up @ np.array([0, 0, 1.0]))
    assert abs(flat * scale - extent_px) > 10.0


def test_frames_say_what_the_marks_are_and_how_fast_the_clock_runs():
    """A caption names the red dot, the orange line and the green path; the clock says how the
    shown time relates to real time."""
    res, fr = animate.frame_samples(PAPER, 5)
    rnd = animate.Renderer(fr, res.scene.config["disk"]["radius"], fps=10.0)
    try:
        rnd.draw(2)
        texts = [t.get_text() for t in rnd.fig.texts]
        assert animate.LEGEND in texts
        for mark in ("red dot: contact point", "orange line: a radius painted on the disk", "green: path of the centre of mass"):
            assert mark in animate.LEGEND
        clock = rnd.text.get_text().splitlines()[0]
        assert re.fullmatch(r"t = +[\d.]+ s   shown at [\d.e+-]+x real time", clock), clock
    finally:
        rnd.close()
