"""The single-scene command line (`python -m sweep scene ...`)."""
import json
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
