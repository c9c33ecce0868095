"""The single-scene command line (`python -m sweep scene ...`)."""
import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import xarray as xr
import yaml

ROOT = Path(__file__).resolve().parents[1]
PAPER = ROOT / "config" / "scenes" / "kessler2002.yaml"
SUMMARY_KEYS = {"outcome", "t_end", "t_halt", "t_halt_error", "ramp_exponent", "ramp_exponent_error", "levels", "slip_fraction",
                "n_transitions", "n_stick", "energy_initial", "energy_final", "dissipation", "n_steps", "n_rhs"}


def run(*args):
    return subprocess.run([sys.executable, "-m", "sweep", *args], capture_output=True, text=True, cwd=ROOT)


def short_scene(tmp_path, **changes):
    cfg = yaml.safe_load(PAPER.read_text())
    cfg["stop"]["levels"] = [0.3, 0.1]
    for sec, val in changes.items():
        cfg[sec].update(val)
    p = tmp_path / "scene.yaml"
    p.write_text(yaml.safe_dump(cfg))
    return p


def test_json_output_and_samples_match_the_api(tmp_path):
    scene = short_scene(tmp_path)
    proc = run("scene", str(scene), "--json", "--sample-times", "0,0.5,1.25")
    assert proc.returncode == 0, proc.stderr
    out = json.loads(proc.stdout)
    assert SUMMARY_KEYS <= set(out)
    assert set(out["levels"][0]) == {"inclination", "t", "precession_hz", "precession_hz_error", "precession_window",
                                     "precession_cycles", "ringing_hz", "ringing_ratio", "normal_force_hz",
                                     "normal_force_hz_per_ringing"}
    # every value's unit: top level, per level, dissipation, samples
    units = out["units"]
    assert units["t_halt"] == "s" and units["levels.precession_hz"] == "Hz" and units["dissipation.k2"] == "J"
    assert units["samples.omega"] == "rad s-1" and units["outcome"] == ""
    assert {k for k in out if k not in ("levels", "dissipation", "samples", "units")} <= set(units)
    assert {f"levels.{k}" for k in out["levels"][0]} <= set(units)
    assert set(out["dissipation"]) == {"sliding", "k1", "k2", "k3", "impact"}
    s = out["samples"]
    assert s["t"] == [0.0, 0.5, 1.25]
    assert len(s["omega"]) == 3 and len(s["omega"][0]) == 3
    assert s["alpha"][0] == 1.0 and s["energy"][0] == out["energy_initial"]
    import sweep
    r = sweep.simulate(str(scene), sample_times=[0.0, 0.5, 1.25])
    assert np.allclose(s["alpha"], r.samples["alpha"], rtol=0, atol=0)
    assert out["levels"][1]["t"] == r.summary["levels"][1]["t"]


def test_bad_scene_exits_2_naming_the_field(tmp_path):
    scene = short_scene(tmp_path, contact={"mu_d": 0.9})
    proc = run("scene", str(scene), "--json")
    assert proc.returncode == 2
    assert "contact.mu_d" in proc.stderr and "allowed" in proc.stderr
    assert proc.stdout == ""
    proc = run("scene", str(tmp_path / "missing.yaml"))
    assert proc.returncode == 2 and proc.stderr == f"error: {tmp_path / 'missing.yaml'}: no such file; allowed " \
        "a YAML mapping of the sections disk, contact, gravity, initial, stop, solver, outputs, material " \
        "(e.g. config/scenes/kessler2002.yaml)\n"
    proc = run("scene", str(short_scene(tmp_path)), "--sample-times", "1,x")
    assert proc.returncode == 2 and "--sample-times" in proc.stderr


def test_trajectory_and_plots(tmp_path):
    scene = short_scene(tmp_path)
    nc = tmp_path / "traj.nc"
    proc = run("scene", str(scene), "--trajectory", str(nc), "--plot", str(tmp_path / "figs"))
    assert proc.returncode == 0, proc.stderr
    ds = xr.open_dataset(nc)
    for v in ds.variables.values():
        assert "units" in v.attrs and "long_name" in v.attrs, v.name
    assert ds.time.size > 100 and bool(np.all(np.diff(ds.time.values) >= 0))
    assert float(ds.normal_force.min()) > 0
    ds.close()
    figs = sorted(p.name for p in (tmp_path / "figs").glob("*.png"))
    assert figs == ["fig3_alpha_energy.png", "fig4_normal_force.png", "fig5_centre_path.png", "fig6_precession.png"]


def test_paper_figures_are_against_time_in_seconds(tmp_path, monkeypatch):
    """The analogues of the paper's Figs 3, 4 and 6 plot against t (s), with the paper's tau = t/chi
    on the top edge; SI values (J, N, Hz) stand beside the dimensionless ones."""
    import matplotlib.pyplot as plt

    import sweep
    from sweep import plots

    figures = {}

    def keep(fig, path, paths):   # plots._save, keeping the figure for a look
        fig.canvas.draw()
        figures[path.name] = fig
        paths.append(path)

    monkeypatch.setattr(plots, "_save", keep)
    res = sweep.simulate(str(short_scene(tmp_path)), trajectory=True)
    plots.paper_figures(res, tmp_path)
    try:
        def axes(fig):   # with the secondary axes (children of the axes they annotate)
            return [b for a in fig.axes for b in (a, *a.child_axes)]

        for name in ("fig3_alpha_energy.png", "fig4_normal_force.png", "fig6_precession.png"):
            fig = figures[name]
            labels = [a.get_xlabel() for a in axes(fig)] + [a.get_ylabel() for a in axes(fig)]
            assert "time t (s)" in labels, (name, labels)
            assert any("tau = t/\\chi" in lab for lab in labels), (name, labels)
            main_ax = [a for a in fig.axes if a.get_xlabel() == "time t (s)"][0]
            t_end = res.summary["t_end"]
            assert main_ax.get_xlim()[1] == pytest.approx(t_end, rel=0.1)   # seconds, not tau
        assert "energy E (J)" in [a.get_ylabel() for a in axes(figures["fig3_alpha_energy.png"])]
        assert "normal force N (N)" in [a.get_ylabel() for a in axes(figures["fig4_normal_force.png"])]
        assert any("(Hz)" in a.get_ylabel() for a in axes(figures["fig6_precession.png"]))
    finally:
        for fig in figures.values():
            plt.close(fig)


# ------------------------------------------------------------------ issue 51: the first hour, round 3

def test_output_paths_are_checked_before_any_work(tmp_path):
    """An unusable output path: one line naming the option, exit 2, no summary (no work), nothing
    created."""
    scene = short_scene(tmp_path)
    (tmp_path / "afile").write_text("x")
    before = sorted(p.name for p in tmp_path.rglob("*"))
    cases = [("--plot", str(tmp_path / "afile"), "exists and is not a folder"),
             ("--plot", str(tmp_path / "no" / "figs"), "no such folder"),
             ("--audio", str(tmp_path / "no" / "x.wav"), "no such folder"),
             ("--spectrogram", str(tmp_path / "s.wav"), "ending in .png"),
             ("--trajectory", str(tmp_path), "is a folder")]
    for opt, path, problem in cases:
        proc = run("scene", str(scene), opt, path)
        assert proc.returncode == 2, (opt, path, proc.stderr)
        assert proc.stdout == "" and proc.stderr.count("\n") == 1, proc.stderr
        assert proc.stderr.startswith(f"error: {opt} = {path!r} is invalid: ") and problem in proc.stderr, proc.stderr
    assert sorted(p.name for p in tmp_path.rglob("*")) == before


def test_the_summary_comes_before_the_media(tmp_path):
    """The summary is printed (and flushed) before the figures are written, so a figure that
    fails cannot lose it."""
    scene = short_scene(tmp_path)
    proc = subprocess.run([sys.executable, "-m", "sweep", "scene", str(scene), "--plot", str(tmp_path / "figs")],
                          stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, cwd=ROOT)
    assert proc.returncode == 0, proc.stdout
    assert proc.stdout.index("outcome ") < proc.stdout.index("wrote ")


def test_a_numerical_failure_exits_3_with_its_reason(tmp_path):
    scene = short_scene(tmp_path, stop={"max_steps": 10})
    proc = run("scene", str(scene))
    assert proc.returncode == 3, proc.stderr
    assert proc.stdout.startswith("outcome          step_limit")
    assert proc.stderr.startswith(f"error: {scene}: the integration failed at t = ") and "step_limit" in proc.stderr
    assert "stop.max_steps" in proc.stderr and proc.stderr.count("\n") == 1
    proc = run("scene", str(scene), "--json")
    assert proc.returncode == 3 and json.loads(proc.stdout)["outcome"] == "step_limit"


def test_a_start_lying_flat_or_below_the_deepest_level_is_refused(tmp_path):
    """Within round-off of flat (the face on the table) and at or below the deepest level (every
    level 'reached' at t = 0): refused before any work, naming the field."""
    flat = short_scene(tmp_path, initial={"alpha": 1.5707963})
    proc = run("scene", str(flat))
    assert proc.returncode == 2 and proc.stdout == ""
    assert proc.stderr.startswith(f"error: {flat}: initial.alpha = 1.5707963 is invalid: the disk starts lying flat")
    assert "allowed 0 < |alpha| < pi/2 - 1e-6" in proc.stderr
    low = short_scene(tmp_path, initial={"alpha": 1.5, "omega": [0.0, 0.0, 0.0]})
    proc = run("scene", str(low))
    assert proc.returncode == 2 and proc.stdout == ""
    assert proc.stderr.startswith(f"error: {low}: initial = ") and "at or below the deepest level 0.1 rad" in proc.stderr
    # the same start with a deeper level runs
    from sweep.scene import check_start, load_scene
    cfg = yaml.safe_load(low.read_text())
    cfg["stop"]["levels"] = [0.01]
    check_start(load_scene(cfg))


def test_every_invalid_field_of_a_scene_file_at_once(tmp_path):
    p = tmp_path / "two.yaml"
    p.write_text("contact: {mu_s: 0.5, mu_d: 0.9}\nsolver: {rtol: 1.0}\nstop: {t_mx: 3}\ndisk: {shape: cube}\n")
    proc = run("scene", str(p))
    assert proc.returncode == 2 and proc.stdout == ""
    lines = proc.stderr.splitlines()
    assert len(lines) == 4, proc.stderr
    assert all(line.startswith(f"error: {p}: ") for line in lines)
    assert [line.split(": ")[2].split(" ")[0] for line in lines] == ["stop.t_mx", "disk.shape", "contact.mu_d",
                                                                      "solver.rtol"]
    from sweep.errors import ConfigError, ConfigErrors
    from sweep.scene import load_scene
    with pytest.raises(ConfigErrors) as err:
        load_scene({"disk": {"radius": -1.0}, "gravity": 0.0})
    assert [e.field for e in err.value.errors] == ["disk.radius", "gravity"]
    assert isinstance(err.value, ConfigError) and err.value.field == "disk.radius"   # a ConfigError too
    # a relative bound is checked only against a valid field: one error for the bad radius, not k1's too
    with pytest.raises(ConfigErrors) as err:
        load_scene({"disk": {"radius": -1.0}, "contact": {"k1": 0.5}, "gravity": 0.0})
    assert [e.field for e in err.value.errors] == ["disk.radius", "gravity"]


def test_values_carry_the_digits_their_error_allows():
    from sweep.cli import with_error
    assert with_error(11.972606, 0.272, "s") == "11.97 +- 0.27 s"
    assert with_error(764.3, 12.0, "Hz") == "764 +- 12 Hz"
    assert with_error(1.0421, 0.022) == "1.042 +- 0.022"
    assert with_error(14.8422, float("nan")) == "14.8422"
    assert with_error(float("nan"), 0.1, "s") == "nan s"


def test_a_long_scene_shows_a_ticking_elapsed_time_on_a_terminal():
    """The ticker (a process of its own: the kernel holds the interpreter's lock) shows the elapsed
    time every second after `after_s`, then one closing line; on a pipe it shows nothing."""
    import os
    import pty
    import select
    import time

    from sweep.cli import ticker
    master, slave = pty.openpty()
    with open(slave, "w", closefd=True) as term:
        with ticker("scene: integrating", after_s=1.0, stream=term):
            time.sleep(2.6)     # the GIL held as by the numba kernel would not matter: another process ticks
        text = ""
        while "done in" not in text:   # a terminal hands its bytes over in pieces
            ready, _, _ = select.select([master], [], [], 5.0)
            if not ready:
                break
            text += os.read(master, 65536).decode()
    os.close(master)
    assert "scene: integrating | 0:01" in text and "scene: integrating | 0:02" in text, text
    assert re.search(r"scene: integrating: done in 0:0[345]\s*$", text), text
    r, w = os.pipe()
    with open(w, "w") as pipe:
        with ticker("x", after_s=0.0, stream=pipe):
            time.sleep(0.2)
    assert os.read(r, 100) == b""
    os.close(r)


def test_a_kernel_that_raises_exits_non_zero_with_its_exception_and_prints_no_summary(tmp_path):
    """An exception out of the integrator (here injected: the kernel entry raises
    ZeroDivisionError, as a division on a Painleve pole once did) is not a result: the command
    exits 1 with the exception named on stderr, prints no summary and writes none of the files
    it was asked for, and its elapsed-time ticker (a process of its own) does not keep it alive."""
    scene = short_scene(tmp_path)
    traj = tmp_path / "traj.nc"
    # (the module from sys.modules: the package's attribute `simulate` is the function)
    boom = ("import sys, sweep\n"
            "def integrate(*args):\n"
            "    raise ZeroDivisionError('float division by zero (injected into the kernel)')\n"
            "sys.modules['sweep.simulate'].integrate = integrate\n"
            "from sweep.cli import main\n"
            "sys.exit(main(sys.argv[1:]))\n")
    proc = subprocess.run([sys.executable, "-c", boom, "scene", str(scene), "--json", "--trajectory", str(traj)],
                          capture_output=True, text=True, cwd=ROOT, timeout=300)
    assert proc.returncode == 1, (proc.returncode, proc.stderr[-2000:])
    assert "ZeroDivisionError: float division by zero (injected into the kernel)" in proc.stderr, proc.stderr[-2000:]
    assert proc.stdout == ""
    assert not traj.exists()
