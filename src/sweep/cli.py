"""Command line: `python -m sweep scene FILE.yaml [--json] [--plot DIR] [--trajectory FILE.nc]
[--sample-times t1,t2,...] [--animate FILE.gif|.mp4 [--fps F] [--animation-seconds S]] [--audio FILE.wav]
[--spectrogram FILE.png]`. Invalid input exits with status 2 and a message naming the field."""
from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np

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
            "mode": ("time", tr["mode"], {"units": "1", "long_name": "contact mode", "flag_values": np.array([0, 1], np.int8),
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


def _print_human(s: dict) -> None:
    print(f"outcome          {s['outcome']}  (t_end = {s['t_end']:.6f} s)")
    print(f"t_halt           {s['t_halt']:.6f} s  +- {s['t_halt_error']:.3g} s  (finite: {s['halt_finite']})")
    print(f"ramp exponent    {s['ramp_exponent']:.4f} +- {s['ramp_exponent_error']:.2g}   "
          f"approach exponent {s['approach_exponent']:.4f}")
    print("levels           inclination (rad)   t (s)          precession (Hz), window error   ringing (Hz)      "
          "normal force f_hat (Hz)")
    sides = {-1.0: " (cycle before)", 1.0: " (cycle after)"}
    for lv in s["levels"]:
        prec = f"{lv['precession_hz']:.6g}"
        if lv["precession_hz"] == lv["precession_hz"]:
            prec += f" +- {lv['precession_hz_error']:.2g}" + sides.get(lv["precession_window"], "")
        print(f"                 {lv['inclination']:<18.3g} {lv['t']:<14.6f} {prec:<31} "
              f"{lv['ringing_hz']:<17.6g} {lv['normal_force_hz']:.6g}")
    print(f"max normal-force frequency {s['normal_force_hz_max']:.6g} Hz")
    print(f"slip fraction    {s['slip_fraction']:.4f}   transitions {s['n_transitions']}   stick episodes {s['n_stick']}   impacts {s['n_impacts']}")
    print(f"energy           {s['energy_initial']:.6g} J -> {s['energy_final']:.6g} J")
    d = s["dissipation"]
    print("dissipated (J)   " + "  ".join(f"{k} {v:.6g}" for k, v in d.items()))
    print(f"cost             {s['n_steps']} steps ({s['n_rejected']} rejected), {s['n_rhs']} RHS, {s['n_events']} events, {s['wall_time'] * 1e3:.2f} ms")


def _media(args, res) -> None:
    """--animate, --audio, --spectrogram: each reruns the scene with the samples it needs."""
    import time

    if args.animate:
        from .animate import write_animation
        t0 = time.perf_counter()
        info = write_animation(res.scene, args.animate, fps=args.fps, duration_s=args.animation_seconds)
        print(f"wrote {args.animate} ({info['frames']} frames, {info['duration_s']:g} s at {info['fps']:g} fps, "
              f"{info['bytes'] / 1e6:.2f} MB, {time.perf_counter() - t0:.1f} s)", file=sys.stderr)
    if args.audio or args.spectrogram:
        from . import audio
        t0 = time.perf_counter()
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


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m sweep", description=__doc__)
    sub = ap.add_subparsers(dest="cmd", required=True)
    sp = sub.add_parser("scene", help="simulate one scene from a YAML file (SI units)")
    sp.add_argument("file", help="scene YAML file, e.g. config/scenes/kessler2002.yaml")
    sp.add_argument("--json", action="store_true", help="print one JSON object (NaN -> null)")
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

    from .frontdoor import compile_for_command
    from .scene import load_scene
    from .simulate import simulate

    try:
        times = _times(args.sample_times) if args.sample_times else None
        want_traj = bool(args.plot or args.trajectory)
        if args.animate:   # options checked before any work
            from .animate import check_options, check_path
            check_options(args.fps, args.animation_seconds)
            check_path(args.animate)
        for opt, name, ext in (("--audio", args.audio, ".wav"), ("--spectrogram", args.spectrogram, ".png")):
            if name and not name.lower().endswith(ext):
                raise ConfigError(opt, name, f"a file name ending in {ext}")
        load_scene(args.file)   # a bad scene file says so before any compilation
        compile_for_command()   # a compilation of the kernels shows its progress (on stderr)
        res = simulate(args.file, sample_times=times, trajectory=want_traj)
        _media(args, res)
    except ConfigError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    out = dict(res.summary)
    if res.samples is not None:
        out["samples"] = {k: res.samples[k] for k in ("t", "alpha", "omega", "energy")}
    if args.trajectory:
        write_trajectory(res, args.trajectory)
    if args.plot:
        from .plots import paper_figures
        for p in paper_figures(res, args.plot):
            print(f"wrote {p}", file=sys.stderr)
    if args.json:
        print(json.dumps(_jsonable(out), allow_nan=False))
    else:
        _print_human(res.summary)
        if res.samples is not None:
            print("samples          t (s), alpha (rad), omega (rad/s), energy (J)")
            for i, t in enumerate(res.samples["t"]):
                w = res.samples["omega"][i]
                print(f"                 {t:<10.4g} {res.samples['alpha'][i]:<12.8g} "
                      f"[{w[0]:.6g}, {w[1]:.6g}, {w[2]:.6g}]  {res.samples['energy'][i]:.8g}")
    return 0
