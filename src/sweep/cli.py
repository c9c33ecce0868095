"""Command line: `python -m sweep scene FILE.yaml [--json] [--plot DIR] [--trajectory FILE.nc]
[--sample-times t1,t2,...] [--animate FILE.gif|.mp4 [--fps F] [--animation-seconds S]] [--audio FILE.wav]
[--spectrogram FILE.png]`.

Exit status: 0 the scene ran to a physical end (its outcome: halted, t_max, contact_lost, ...);
2 invalid input (every invalid field of the scene file and every unusable output path, one line
each, before any work); 3 the integration failed numerically (outcome step_limit,
step_size_underflow or numerical_error: the summary is printed, then the reason on stderr);
1 an output could not be written (after the summary)."""
from __future__ import annotations

import argparse
import contextlib
import json
import math
import sys
from pathlib import Path

import numpy as np

from .core.constants import ROLL, SLIDE
from .errors import ConfigError


def _times(text: str) -> list[float]:
    try:
        return [float(x) for x in text.split(",") if x.strip()]
    except ValueError:
        raise ConfigError("--sample-times", text, "comma-separated times in s, e.g. 0,1.5,3") from None


def _jsonable(obj):
    if isinstance(obj, dict):
        return {k: _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _jsonable(obj.tolist())
    if isinstance(obj, (float, np.floating)):
        x = float(obj)
        return x if math.isfinite(x) else None   # JSON has no NaN: unknown values are null
    if isinstance(obj, np.integer):
        return int(obj)
    return obj


def write_trajectory(result, path) -> None:
    """Trajectory (every accepted step) as CF-style netCDF, written atomically."""
    import os

    import xarray as xr

    from . import __version__

    tr = result.trajectory
    ds = xr.Dataset(
        {
            "alpha": ("time", tr["alpha"], {"units": "rad", "long_name": "tilt of the disk plane from the vertical"}),
            "omega": (("time", "axis"), tr["omega"], {"units": "rad s-1", "long_name": "angular velocity on e1, e2, e3"}),
            "slip": (("time", "tangent"), tr["slip"], {"units": "m s-1", "long_name": "contact point velocity on a1, a2"}),
            "theta": ("time", tr["theta"], {"units": "rad", "long_name": "precession angle (3-1-2 Euler angle 1)"}),
            "psi": ("time", tr["psi"], {"units": "rad", "long_name": "spin angle (3-1-2 Euler angle 3)"}),
            "x": ("time", tr["x"], {"units": "m", "long_name": "centre of mass position on E1"}),
            "y": ("time", tr["y"], {"units": "m", "long_name": "centre of mass position on E2"}),
            "normal_force": ("time", tr["normal_force"], {"units": "N", "long_name": "normal contact force"}),
            "mode": ("time", tr["mode"], {"units": "1", "long_name": "contact mode", "flag_values": np.array([ROLL, SLIDE], np.int8),
                                          "flag_meanings": "rolling sliding"}),
        },
        coords={"time": ("time", tr["t"], {"units": "s", "long_name": "time"}),
                "axis": ("axis", [1, 2, 3], {"units": "1", "long_name": "e-frame axis index"}),
                "tangent": ("tangent", [1, 2], {"units": "1", "long_name": "a-frame tangent axis index"})},
        attrs={"Conventions": "CF-1.10", "title": "Euler's disk trajectory (Kessler & O'Reilly 2002 model)",
               "source": f"sweep {__version__}", "scene": json.dumps(result.scene.config, sort_keys=True),
               "outcome": result.summary["outcome"]},
    )
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp{os.getpid()}")
    enc = {v: {"zlib": True, "complevel": 4} for v in ds.data_vars}
    ds.to_netcdf(tmp, engine="netcdf4", encoding=enc)
    os.replace(tmp, path)


def with_error(x: float, err: float, unit: str = "") -> str:
    """`x +- err` to the digits the error allows: the error to two significant digits, the value
    to the same decimal place (`11.97 +- 0.27`, `764 +- 12`); `x` to six where there is no error."""
    unit = f" {unit}" if unit else ""
    if not math.isfinite(x):
        return f"nan{unit}"
    if not (math.isfinite(err) and err > 0.0):
        return f"{x:.6g}{unit}"
    decimals = max(0, 1 - math.floor(math.log10(err)))
    return f"{x:.{decimals}f} +- {err:.{decimals}f}{unit}"


def _counting(ratio: float) -> str:
    """f_hat's counting at a level, from f_hat / ringing: `x2` (two normal-force maxima per
    oscillation counted), `x1`, or the ratio where it is neither."""
    if not math.isfinite(ratio):
        return ""
    near = round(ratio)
    return f"x{near}" if near in (1, 2) and abs(ratio - near) < 0.15 * near else f"x{ratio:.2g}"


def _print_human(s: dict) -> None:
    print(f"outcome          {s['outcome']}  (t_end = {s['t_end']:.6f} s)")
    if s["lay_flat"]:
        print(f"t_halt           {s['t_halt']:.6f} s  (the disk lay flat then: a located time, not extrapolated, "
              "so no extrapolation error)")
    else:
        print(f"t_halt           {with_error(s['t_halt'], s['t_halt_error'], 's')}  (finite: {s['halt_finite']})")
    print(f"ramp exponent    {with_error(s['ramp_exponent'], s['ramp_exponent_error'])}   "
          f"approach exponent {s['approach_exponent']:.3f}")
    print("levels           inclination (rad)   t (s)          precession (Hz), window error   ringing (Hz)   "
          "normal force f_hat (Hz), x ringing")
    sides = {-1.0: " (cycle before)", 1.0: " (cycle after)"}
    counts = set()
    for lv in s["levels"]:
        if s["lay_flat"] and lv["t"] == s["t_end"]:   # sweep.reasons: level_crossed_lying_flat
            print(f"                 {lv['inclination']:<18.3g} {lv['t']:<14.6f} (the moment the disk lay flat: "
                  "the face impact took this level's energy; no frequencies)")
            continue
        prec = with_error(lv["precession_hz"], lv["precession_hz_error"])
        if lv["precession_hz"] == lv["precession_hz"]:
            prec += sides.get(lv["precession_window"], "")
        count = _counting(lv["normal_force_hz_per_ringing"])
        counts.add(count)
        fhat = f"{lv['normal_force_hz']:.4g}" + (f"  {count}" if count else "")
        print(f"                 {lv['inclination']:<18.3g} {lv['t']:<14.6f} {prec:<31} "
              f"{lv['ringing_hz']:<14.4g} {fhat}")
    if counts - {"", "x1"}:
        print("                 (f_hat = 2/T counts every maximum of the normal force: x2 where the force has two "
              "per oscillation, x1 one; otherwise f_hat / ringing)")
    print(f"max normal-force frequency {s['normal_force_hz_max']:.4g} Hz (the largest f_hat of the run: it counts "
          "maxima as at the levels, x1 or x2)" if s["normal_force_hz_max"] == s["normal_force_hz_max"] else
          "max normal-force frequency nan Hz")
    print(f"slip fraction    {s['slip_fraction']:.4f}   transitions {s['n_transitions']}   stick episodes {s['n_stick']}   impacts {s['n_impacts']}")
    print(f"energy           {s['energy_initial']:.6g} J -> {s['energy_final']:.6g} J")
    d = s["dissipation"]
    print("dissipated (J)   " + "  ".join(f"{k} {v:.6g}" for k, v in d.items()))
    print(f"cost             {s['n_steps']} steps ({s['n_rejected']} rejected), {s['n_rhs']} RHS, {s['n_events']} events, {s['wall_time'] * 1e3:.2f} ms")


def units_map() -> dict:
    """The unit of every value of the JSON output: top-level keys, `levels.<key>`,
    `dissipation.<key>`, `samples.<key>` (UDUNITS strings; "1" dimensionless, "" text)."""
    from .outputs import OUTPUTS

    units = {(f"{o.where}.{o.key}" if o.where else o.key): o.units for o in OUTPUTS}
    units.update({"samples.t": "s", "samples.alpha": "rad", "samples.omega": "rad s-1", "samples.energy": "J"})
    return units


def _media(args, res) -> None:
    """--animate, --audio, --spectrogram: each reruns the scene with the samples it needs."""
    import time

    if args.animate:
        from .animate import write_animation
        t0 = time.perf_counter()
        with ticker(f"scene: writing {args.animate}"):
            info = write_animation(res.scene, args.animate, fps=args.fps, duration_s=args.animation_seconds)
        print(f"wrote {args.animate} ({info['frames']} frames, {info['duration_s']:g} s at {info['fps']:g} fps, "
              f"{info['bytes'] / 1e6:.2f} MB, {time.perf_counter() - t0:.1f} s)", file=sys.stderr)
    if args.audio or args.spectrogram:
        from . import audio
        t0 = time.perf_counter()
        with ticker("scene: synthesising the ringing"):
            res_a, ring = audio.ringing(res.scene)
        modes = ", ".join(f"({m.n},{m.s}) {m.frequency_hz:.0f} Hz" for m in ring.modes)
        if args.audio:
            p = audio.write_wav(args.audio, ring)
            print(f"wrote {p} ({len(ring.signal)} samples, {len(ring.signal) / ring.rate_hz:.3f} s at "
                  f"{ring.rate_hz} Hz, {p.stat().st_size / 1e6:.2f} MB; plate modes {modes}; "
                  f"{time.perf_counter() - t0:.1f} s)", file=sys.stderr)
        if args.spectrogram:
            p = audio.spectrogram_png(res_a, ring, args.spectrogram)
            print(f"wrote {p} ({p.stat().st_size / 1e3:.0f} kB)", file=sys.stderr)


def numerical_failure(summary: dict, source: str) -> str | None:
    """The one-line reason of a scene that the numerics ended (outcomes.NUMERICAL_FAILURES), or
    None for a physical end."""
    from . import outcomes

    code = summary["outcome_code"]
    if code not in outcomes.NUMERICAL_FAILURES:
        return None
    return (f"{source}: the integration failed at t = {summary['t_end']:.6g} s, outcome {summary['outcome']}: "
            f"{outcomes.NUMERICAL_FAILURES[code]}; the summary above is that of the part integrated")


def _writable_folder(opt: str, name: str, folder: Path) -> None:
    """ConfigError unless `folder` exists, is a folder and takes a new file (probed with a
    temporary file, removed at once: permissions, read-only mounts and /proc alike)."""
    import os
    import tempfile

    if not folder.exists():
        raise ConfigError(opt, name, "a path in an existing folder (it is not created)",
                          problem=f"no such folder {str(folder)!r}")
    if not folder.is_dir():
        raise ConfigError(opt, name, "a path in an existing folder", problem=f"{str(folder)!r} is not a folder")
    try:
        fd, probe = tempfile.mkstemp(prefix=".sweep-probe-", dir=folder)
    except OSError as exc:
        raise ConfigError(opt, name, "a path in a folder you can write to",
                          problem=f"cannot write in {str(folder)!r} ({exc.strerror})") from None
    os.close(fd)
    os.unlink(probe)


def check_output_file(opt: str, name: str, ext: tuple[str, ...] = ()) -> None:
    """An output file option: its suffix, not a folder, in an existing writable folder."""
    path = Path(name)
    if ext and path.suffix.lower() not in ext:
        raise ConfigError(opt, name, f"a file name ending in {' or '.join(ext)}")
    if path.is_dir():
        raise ConfigError(opt, name, "a file name", problem="is a folder")
    _writable_folder(opt, name, path.parent)


def check_output_folder(opt: str, name: str) -> None:
    """An output folder option: a folder that exists (and takes files), or a new one in an
    existing writable folder (created when the figures are written)."""
    path = Path(name)
    if path.exists():
        if not path.is_dir():
            raise ConfigError(opt, name, "a folder (one that exists, or a new one in an existing folder)",
                              problem="exists and is not a folder")
        _writable_folder(opt, name, path)
    else:
        _writable_folder(opt, name, path.parent)


def check_outputs(args) -> None:
    """Every option and output path of `scene`, before any work (ConfigError)."""
    if args.animate:
        from .animate import check_options, check_path
        check_options(args.fps, args.animation_seconds)
        check_path(args.animate)
        check_output_file("--animate", args.animate)
    for opt, name, ext in (("--audio", args.audio, (".wav",)), ("--spectrogram", args.spectrogram, (".png",)),
                           ("--trajectory", args.trajectory, ())):
        if name:
            check_output_file(opt, name, ext)
    if args.plot:
        check_output_folder("--plot", args.plot)


# The ticker runs in a process of its own: the integration is one numba call that holds the
# interpreter's lock, so a thread of this process could not print while it runs. It stops when
# told (SIGTERM), on Ctrl-C (which reaches the whole foreground group) and when its parent is gone.
_TICKER = """
import os, signal, sys, time
signal.signal(signal.SIGINT, lambda *a: os._exit(0))
signal.signal(signal.SIGTERM, lambda *a: os._exit(0))
t0, label, after, parent = float(sys.argv[1]), sys.argv[2], float(sys.argv[3]), os.getppid()
tick = t0 + after
while True:
    time.sleep(max(0.0, tick - time.monotonic()))   # on the second of the clock, whatever the start-up took
    if os.getppid() != parent:
        break
    s = int(round(time.monotonic() - t0))
    sys.stderr.write(f"\\r\\033[K{label} | {s // 60}:{s % 60:02d}")
    sys.stderr.flush()
    tick += 1.0
"""


@contextlib.contextmanager
def ticker(label: str, after_s: float = 2.0, stream=None):
    """While the block runs longer than `after_s`, a status line on a terminal (`stream`, default
    stderr, so stdout stays the summary) with the elapsed time, and a last line when it ends."""
    import signal
    import subprocess
    import time

    stream = stream or sys.stderr
    if not stream.isatty():
        yield
        return
    t0 = time.monotonic()
    stream.flush()
    proc = subprocess.Popen([sys.executable, "-S", "-c", _TICKER, repr(t0), label, repr(after_s)],
                            stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=stream)
    try:
        yield
    finally:
        proc.send_signal(signal.SIGTERM)
        proc.wait()
        took = time.monotonic() - t0
        if took >= after_s:
            print(f"\r\033[K{label}: done in {_clock(took)}", file=stream, flush=True)


def _clock(seconds: float) -> str:
    s = int(round(seconds))
    return f"{s // 60}:{s % 60:02d}"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m sweep", description=__doc__)
    sub = ap.add_subparsers(dest="cmd", required=True)
    sp = sub.add_parser("scene", help="simulate one scene from a YAML file (SI units)")
    sp.add_argument("file", help="scene YAML file, e.g. config/scenes/kessler2002.yaml")
    sp.add_argument("--json", action="store_true", help="print one JSON object (NaN -> null; the unit of every value in its 'units')")
    sp.add_argument("--plot", metavar="DIR", help="write the analogues of the paper's Figs 3-6 to DIR")
    sp.add_argument("--trajectory", metavar="FILE.nc", help="write the state at every step to netCDF")
    sp.add_argument("--sample-times", metavar="T1,T2,...", help="report alpha, omega, energy at these times (s)")
    sp.add_argument("--animate", metavar="FILE.gif|.mp4", help="write an animation of the disk (.mp4 needs ffmpeg)")
    sp.add_argument("--fps", type=float, default=20.0, help="animation frames per second (default 20)")
    sp.add_argument("--animation-seconds", type=float, default=12.0,
                    help="animation length in s, at most 20 (default 12)")
    sp.add_argument("--audio", metavar="FILE.wav", help="write the synthesised ringing (44.1 kHz, 16-bit PCM)")
    sp.add_argument("--spectrogram", metavar="FILE.png", help="write the spectrogram of the ringing")
    args = ap.parse_args(argv)

    from .warmup import compile_for_command
    from .scene import check_start, load_scene
    from .simulate import simulate

    try:
        times = _times(args.sample_times) if args.sample_times else None
        want_traj = bool(args.plot or args.trajectory)
        check_outputs(args)   # options and output paths checked before any work, nothing created
        try:   # a bad scene file says so (every field) before any compilation
            check_start(load_scene(args.file))
        except ConfigError as err:
            raise err.with_source(args.file) from None
        compile_for_command()   # a compilation of the kernels shows its progress (on stderr)
        with ticker("scene: integrating"):
            res = simulate(args.file, sample_times=times, trajectory=want_traj)
    except ConfigError as exc:
        for line in exc.lines():
            print(f"error: {line}", file=sys.stderr)
        return 2
    out = dict(res.summary)
    if res.samples is not None:
        out["samples"] = {k: res.samples[k] for k in ("t", "alpha", "omega", "energy")}
    if args.json:
        out["units"] = units_map()
        print(json.dumps(_jsonable(out), allow_nan=False), flush=True)
    else:
        _print_human(res.summary)
        if res.samples is not None:
            print("samples          t (s), alpha (rad), omega (rad/s), energy (J)")
            for i, t in enumerate(res.samples["t"]):
                w = res.samples["omega"][i]
                print(f"                 {t:<10.4g} {res.samples['alpha'][i]:<12.8g} "
                      f"[{w[0]:.6g}, {w[1]:.6g}, {w[2]:.6g}]  {res.samples['energy'][i]:.8g}")
        sys.stdout.flush()
    failed = numerical_failure(res.summary, args.file)
    if failed:   # no media from a run that failed: they would show its failure, not the scene
        print(f"error: {failed}", file=sys.stderr)
        return 3
    try:
        if args.trajectory:
            write_trajectory(res, args.trajectory)
            print(f"wrote {args.trajectory}", file=sys.stderr)
        if args.plot:
            from .plots import paper_figures
            for p in paper_figures(res, args.plot):
                print(f"wrote {p}", file=sys.stderr)
        _media(args, res)
    except OSError as exc:   # the disk filled up, a folder vanished: after the checks, during the writing
        print(f"error: could not write {exc.filename or 'an output'}: {exc.strerror or exc}", file=sys.stderr)
        return 1
    return 0
