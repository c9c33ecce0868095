"""Animation of a scene: the disk in an orthographic 3D view, as a GIF (Pillow) or an MP4 (ffmpeg).

Geometry (src/sweep/core/model.py, docs/model.md): E fixed; a = E turned by theta about E3; e = a
turned by alpha about a1, so e1 = a1, e2 = cos(alpha) a2 + sin(alpha) a3 (the symmetry axis),
e3 = -sin(alpha) a2 + cos(alpha) a3; the body is e turned by psi about e2. The contact point is
P = xbar - H e2 - R e3 with H = (L/2) sign(alpha), and the centre's height is
R cos|alpha| + H sin(alpha) (P on the table, z = 0; tested). x, y of the centre come from the
samples (dense output).

Frames are uniform in a time-warped clock: frame k of K shows t_k with t_h - t_k geometric in k, from
t_h to t_h - t_end (t_h = t_halt, or 1.05 t_end when the scene has no halt time beyond t_end),
so the clock slows as the disk flattens and the last second of the motion stays visible. Each frame
shows the disk (faces, rim and side), the contact point, the centre-of-mass path of the last frames
(from dense-output samples between frames), the clock with its speed against real time, the
inclination and the precession frequency (mean rate of theta over the frame interval), and a
caption saying what the marks are (LEGEND).
"""
from __future__ import annotations

import math
import os
import shutil
import subprocess
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .errors import ConfigError

FPS = 20                    # frames per second of animation
DURATION_S = 12.0           # seconds of animation
MAX_DURATION_S = 20.0
MAX_BYTES = 10 * 1024 * 1024
SUBSTEPS = 16               # dense-output samples per frame interval for the centre-of-mass path
TRAIL_FRAMES = 30           # frames of centre-of-mass path shown behind the disk
AZIMUTH = math.radians(20.0)    # camera azimuth (about E3, from E1): looks along the initial tilt axis
ELEVATION = math.radians(20.0)  # camera elevation above the table
WIDTH_PX, HEIGHT_PX, DPI = 480, 400, 80
RIM_COLOR = "#1b2a6b"
FACE_COLOR = "#b8c4da"
SIDE_COLOR = "#7f8fb0"
N_RIM = 96
VIEW_BOTTOM, VIEW_HEIGHT = 0.085, 0.755     # the 3-D view between the caption (below) and the text (above)
LEGEND = ("red dot: contact point with the table (a ring where the disk hides it)\n"
          "orange line: a radius painted on the disk (its spin)   green: path of the centre of mass")


def camera(azimuth: float = AZIMUTH, elevation: float = ELEVATION):
    """Unit vectors (right, up, towards the camera) of the orthographic view, in E coordinates."""
    ca, sa, ce, se = math.cos(azimuth), math.sin(azimuth), math.cos(elevation), math.sin(elevation)
    right = np.array([-sa, ca, 0.0])
    up = np.array([-se * ca, -se * sa, ce])
    toward = np.array([ce * ca, ce * sa, se])
    return right, up, toward


def frames_of(theta, alpha, psi):
    """e1, e2, e3 and the body axes b1, b3 (in the disk plane) in E coordinates; arrays of shape (n, 3)."""
    theta, alpha, psi = (np.atleast_1d(np.asarray(v, float)) for v in (theta, alpha, psi))
    ct, st, ca, sa, cp, sp = np.cos(theta), np.sin(theta), np.cos(alpha), np.sin(alpha), np.cos(psi), np.sin(psi)
    z = np.zeros_like(theta)
    a1 = np.stack([ct, st, z], -1)
    a2 = np.stack([-st, ct, z], -1)
    a3 = np.stack([z, z, z + 1.0], -1)
    e1 = a1
    e2 = ca[:, None] * a2 + sa[:, None] * a3
    e3 = -sa[:, None] * a2 + ca[:, None] * a3
    b1 = cp[:, None] * e1 - sp[:, None] * e3     # e turned by psi about e2
    b3 = sp[:, None] * e1 + cp[:, None] * e3
    return e1, e2, e3, b1, b3


def disk_geometry(x, y, theta, alpha, psi, radius_m: float, thickness_m: float) -> dict:
    """Centre (n x 3), contact point P (n x 3), both rim circles (n x N_RIM x 3; 'rim_contact' is
    the face whose edge touches the table) and the body axes, in metres in the E frame."""
    e1, e2, e3, b1, b3 = frames_of(theta, alpha, psi)
    alpha = np.atleast_1d(np.asarray(alpha, float))
    H = 0.5 * thickness_m * np.sign(alpha)
    zc = radius_m * np.cos(np.abs(alpha)) + H * np.sin(alpha)
    centre = np.stack([np.atleast_1d(x), np.atleast_1d(y), zc], -1)
    P = centre - H[:, None] * e2 - radius_m * e3
    phi = np.linspace(0.0, 2.0 * math.pi, N_RIM, endpoint=False)
    ring = radius_m * (np.cos(phi)[None, :, None] * b1[:, None, :] + np.sin(phi)[None, :, None] * b3[:, None, :])
    near = centre - H[:, None] * e2
    far = centre + H[:, None] * e2
    return {"centre": centre, "contact": P, "e2": e2, "b1": b1, "b3": b3, "phi": phi,
            "rim_contact": near[:, None, :] + ring, "rim_far": far[:, None, :] + ring}


def warped_times(t_end_s: float, t_halt_s: float, n_frames: int) -> np.ndarray:
    """n_frames times from 0 to t_end_s, uniform in log(t_h - t) (see the module docstring)."""
    if n_frames < 1:
        raise ConfigError("frames", n_frames, "at least 1 frame")
    t_h = t_halt_s if (math.isfinite(t_halt_s) and t_halt_s > t_end_s * (1.0 + 1e-6)) else 1.05 * t_end_s
    if n_frames == 1 or t_end_s <= 0.0:
        return np.zeros(1) if n_frames == 1 else np.zeros(n_frames)
    s = np.linspace(0.0, 1.0, n_frames)
    t = t_h - t_h ** (1.0 - s) * (t_h - t_end_s) ** s
    t[0], t[-1] = 0.0, t_end_s
    return t


def check_options(fps, duration_s) -> tuple[float, float]:
    """Validate the animation's fps and duration (s); ConfigError naming the option otherwise."""
    for name, v, lo, hi in (("--fps", fps, 0.0, 60.0), ("--animation-seconds", duration_s, 0.0, MAX_DURATION_S)):
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or not lo < v <= hi:
            raise ConfigError(name, v, f"a number in ({lo:g}, {hi:g}]")
    if round(fps * duration_s) < 2:
        raise ConfigError("--fps", fps, f"fps x duration >= 2 frames (duration {duration_s:g} s)")
    return float(fps), float(duration_s)


def check_path(path) -> Path:
    """The animation file name: .gif, or .mp4 where ffmpeg is on PATH."""
    path = Path(path)
    ext = path.suffix.lower()
    if ext not in (".gif", ".mp4"):
        raise ConfigError("--animate", str(path), "a file name ending in .gif or .mp4")
    if ext == ".mp4" and shutil.which("ffmpeg") is None:
        raise ConfigError("--animate", str(path), "a .gif file (ffmpeg, needed for .mp4, is not on PATH)")
    return path


@dataclass
class Frames:
    """Frame times (s) and the states drawn: from `frame_samples`."""

    t: np.ndarray            # frame times (s)
    fine_t: np.ndarray       # sample times incl. SUBSTEPS per frame interval (s)
    fine: dict               # samples at fine_t
    index: np.ndarray        # index of each frame in fine_t
    geometry: dict           # disk_geometry at fine_t
    precession_hz: np.ndarray  # mean precession frequency around each frame (Hz)


def frame_samples(scene, n_frames: int) -> tuple[object, Frames]:
    """Simulate (path, dict or Scene) and sample the state at the frame times and between them."""
    from .simulate import simulate

    first = simulate(scene)
    s = first.summary
    t = warped_times(s["t_end"], s["t_halt"], n_frames)
    if n_frames > 1:
        frac = np.arange(SUBSTEPS) / SUBSTEPS
        fine_t = np.concatenate([(t[:-1, None] + frac[None, :] * np.diff(t)[:, None]).ravel(), t[-1:]])
        fine_t = np.maximum.accumulate(fine_t)
        index = np.arange(n_frames) * SUBSTEPS
    else:
        fine_t, index = t.copy(), np.zeros(1, int)
    res = simulate(first.scene, sample_times=fine_t)
    sm = res.samples
    d = res.scene.config["disk"]
    geo = disk_geometry(sm["x"], sm["y"], sm["theta"], sm["alpha"], sm["psi"], d["radius"], d["thickness"])
    th = sm["theta"]
    lo = np.maximum(index - SUBSTEPS // 2, 0)
    hi = np.minimum(index + SUBSTEPS // 2, len(fine_t) - 1)
    dt = fine_t[hi] - fine_t[lo]
    with np.errstate(invalid="ignore", divide="ignore"):
        prec = np.where(dt > 0, np.abs(th[hi] - th[lo]) / np.where(dt > 0, dt, 1.0) / (2.0 * math.pi), np.nan)
    return res, Frames(t=t, fine_t=fine_t, fine=sm, index=index, geometry=geo, precession_hz=prec)


class Renderer:
    """Draws frames on one reused matplotlib figure (Agg) with a fixed metric scale."""

    def __init__(self, frames: Frames, radius_m: float, fps: float = FPS, azimuth: float = AZIMUTH,
                 elevation: float = ELEVATION):
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        from matplotlib.patches import Polygon

        self.fr = frames
        self.fps = fps
        self.right, self.up, self.toward = camera(azimuth, elevation)
        g = frames.geometry
        pts = np.concatenate([g["rim_contact"].reshape(-1, 3), g["rim_far"].reshape(-1, 3)])
        pts = pts[np.all(np.isfinite(pts), axis=1)]
        u, v = pts @ self.right, pts @ self.up
        # table square under the centre-of-mass path, 1.6 R beyond it
        c = g["centre"][np.all(np.isfinite(g["centre"]), axis=1)]
        m = 1.6 * radius_m
        self.table = np.array([[c[:, 0].min() - m, c[:, 1].min() - m, 0.0], [c[:, 0].max() + m, c[:, 1].min() - m, 0.0],
                               [c[:, 0].max() + m, c[:, 1].max() + m, 0.0], [c[:, 0].min() - m, c[:, 1].max() + m, 0.0]])
        u = np.concatenate([u, self.table @ self.right])
        v = np.concatenate([v, self.table @ self.up])
        self.fig = plt.figure(figsize=(WIDTH_PX / DPI, HEIGHT_PX / DPI), dpi=DPI)
        ax = self.fig.add_axes((0.0, VIEW_BOTTOM, 1.0, VIEW_HEIGHT))
        ax.set_axis_off()
        w_px, h_px = WIDTH_PX, VIEW_HEIGHT * HEIGHT_PX
        span_u, span_v = (u.max() - u.min()) * 1.05, (v.max() - v.min()) * 1.05
        self.scale_px_per_m = min(w_px / span_u, h_px / span_v)
        cu, cv = 0.5 * (u.max() + u.min()), 0.5 * (v.max() + v.min())
        hu, hv = 0.5 * w_px / self.scale_px_per_m, 0.5 * h_px / self.scale_px_per_m
        ax.set_xlim(cu - hu, cu + hu)
        ax.set_ylim(cv - hv, cv + hv)
        self.ax = ax
        ax.add_patch(Polygon(self._uv(self.table), closed=True, fc="#efe8dc", ec="#b5a98f", lw=0.8, zorder=0))
        self.side = ax.add_patch(Polygon(np.zeros((3, 2)), closed=True, fc=SIDE_COLOR, ec="none", zorder=2))
        self.face = ax.add_patch(Polygon(np.zeros((3, 2)), closed=True, fc=FACE_COLOR, ec=RIM_COLOR, lw=1.5, zorder=3))
        self.rim_back, = ax.plot([], [], color=RIM_COLOR, lw=1.5, zorder=2.5)
        self.mark, = ax.plot([], [], color="#c07010", lw=2.0, zorder=4)      # a radius painted on the face (spin)
        self.path, = ax.plot([], [], color="#1e9e3c", lw=1.0, zorder=4.5)
        # contact point: filled where it faces the camera, a hollow ring where the disk hides it
        self.contact, = ax.plot([], [], "o", color="#e00000", mfc="#e00000", ms=6, mew=1.5, zorder=5)
        self.text = self.fig.text(0.02, 0.985, "", va="top", ha="left", family="monospace", fontsize=9)
        self.fig.text(0.02, 0.012, LEGEND, va="bottom", ha="left", fontsize=7.5, color="0.15", linespacing=1.3)

    def _uv(self, p):
        return np.stack([p @ self.right, p @ self.up], -1)

    def draw(self, k: int):
        """Draw frame k; returns an RGB uint8 array (HEIGHT_PX x WIDTH_PX x 3)."""
        fr, g = self.fr, self.fr.geometry
        i = fr.index[k]
        rc, rf = g["rim_contact"][i], g["rim_far"][i]
        # visible face: the one whose outward normal points to the camera
        n_far = g["e2"][i] * np.sign(fr.fine["alpha"][i] or 1.0)
        front, back = (rf, rc) if n_far @ self.toward >= 0 else (rc, rf)
        # visible side: rim directions whose outward radial normal faces the camera
        radial = np.cos(g["phi"])[:, None] * g["b1"][i] + np.sin(g["phi"])[:, None] * g["b3"][i]
        vis = radial @ self.toward > 0
        if vis.any():
            start = int(np.argmax(~vis & np.roll(vis, -1))) + 1 if not vis.all() else 0
            order = np.roll(np.arange(len(vis)), -start)
            order = order[vis[order]]
            band = np.concatenate([front[order], back[order][::-1]])
            self.side.set_xy(self._uv(band))
            self.rim_back.set_data(*self._uv(back[order]).T)
        else:
            self.side.set_xy(np.zeros((3, 2)))
            self.rim_back.set_data([], [])
        self.face.set_xy(self._uv(front))
        centre_face = front.mean(axis=0)
        self.mark.set_data(*self._uv(np.stack([centre_face, front[0]])).T)
        j0 = max(0, i - TRAIL_FRAMES * SUBSTEPS)
        self.path.set_data(*self._uv(g["centre"][j0:i + 1]).T)
        self.contact.set_data(*self._uv(g["contact"][i:i + 1]).T)
        p_out = g["contact"][i] - g["centre"][i]          # -H e2 - R e3: seen if its radial part faces us
        seen = (p_out - (p_out @ g["e2"][i]) * g["e2"][i]) @ self.toward > 0.0
        self.contact.set_markerfacecolor("#e00000" if seen else "none")
        a = fr.fine["alpha"][i]
        beta = 0.5 * math.pi - abs(a)
        rate = ""
        if len(fr.t) > 1:   # simulated seconds per second of animation around this frame
            lo, hi = max(k - 1, 0), min(k + 1, len(fr.t) - 1)
            rate = f"   shown at {(fr.t[hi] - fr.t[lo]) / (hi - lo) * self.fps:.3g}x real time"
        self.text.set_text(f"t = {fr.t[k]:9.5f} s{rate}\n"
                           f"tilt alpha = {a:+.5f} rad   beta = pi/2-|alpha| = {beta:.2e} rad\n"
                           f"precession {fr.precession_hz[k]:8.2f} Hz")
        self.fig.canvas.draw()
        buf = np.asarray(self.fig.canvas.buffer_rgba())
        return np.ascontiguousarray(buf[:, :, :3])

    def close(self):
        import matplotlib.pyplot as plt
        plt.close(self.fig)


def write_animation(scene, path, fps: float = FPS, duration_s: float = DURATION_S,
                    max_bytes: int = MAX_BYTES) -> dict:
    """Render a scene to path (.gif with Pillow, .mp4 with ffmpeg). Returns facts about it:
    frames, fps, duration_s, bytes, t_end_s."""
    fps, duration_s = check_options(fps, duration_s)
    path = check_path(path)
    ext = path.suffix.lower()
    ffmpeg = shutil.which("ffmpeg")
    n = int(round(fps * duration_s))
    res, fr = frame_samples(scene, n)
    rnd = Renderer(fr, res.scene.config["disk"]["radius"], fps)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp{os.getpid()}{ext}")
    try:
        if ext == ".gif":
            from PIL import Image

            imgs = [Image.fromarray(rnd.draw(k)).quantize(colors=96, method=Image.Quantize.FASTOCTREE, dither=Image.Dither.NONE)
                    for k in range(n)]
            imgs[0].save(tmp, save_all=True, append_images=imgs[1:], duration=int(round(1000.0 / fps)),
                         loop=0, optimize=False)
        else:
            cmd = [ffmpeg, "-loglevel", "error", "-y", "-f", "rawvideo", "-pix_fmt", "rgb24",
                   "-s", f"{WIDTH_PX}x{HEIGHT_PX}", "-r", f"{fps:g}", "-i", "-", "-pix_fmt", "yuv420p",
                   "-vcodec", "libx264", "-crf", "28", str(tmp)]
            with subprocess.Popen(cmd, stdin=subprocess.PIPE) as proc:
                for k in range(n):
                    proc.stdin.write(rnd.draw(k).tobytes())
                proc.stdin.close()
                if proc.wait() != 0:
                    raise RuntimeError(f"ffmpeg failed writing {path}")
    finally:
        rnd.close()
    size = tmp.stat().st_size
    if size > max_bytes:
        tmp.unlink()
        raise ConfigError("--animate", str(path), f"an animation of at most {max_bytes} bytes: this one is {size} "
                          "bytes; lower --fps or --animation-seconds")
    os.replace(tmp, path)
    return {"frames": n, "fps": fps, "duration_s": n / fps, "bytes": size, "t_end_s": float(fr.t[-1]),
            "scale_px_per_m": rnd.scale_px_per_m}
