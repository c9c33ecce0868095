"""The batch path (sweep.simulate_batch): the same summaries as sweep.simulate, on the CPU threads and
on the CUDA kernel run by numba's CUDA simulator (NUMBA_ENABLE_CUDASIM=1, no GPU needed)."""
from __future__ import annotations

import json
import math
import os
import re
import subprocess
import sys
import textwrap

import numpy as np
import pytest

import sweep
from sweep import diagnostics
from sweep.core import ensemble as core_ensemble
from sweep.ensemble import summaries_equal

from conftest import ROOT, make_scene

LEVELS = [0.1, 0.03, 0.01, 0.003]
# scenes of ~0.5-1.5 s each that take the kernel through its three kinds of contact history
SCENES = {
    # mu_s = 100: the friction cone always holds the contact, the disk rolls until it lies flat
    "rolling": dict(contact__mu_s=100.0, stop__levels=LEVELS),
    # the paper's disk: rolling <-> sliding transitions
    "roll_slip": dict(stop__levels=LEVELS),
    # the thin shell: moment components stick (Filippov) and are released
    "sticking": dict(disk__shape="shell", stop__levels=LEVELS),
}


@pytest.fixture(scope="module")
def reference():
    """sweep.simulate summaries of SCENES."""
    return {k: sweep.simulate(make_scene(**v)).summary for k, v in SCENES.items()}


def test_scenes_cover_rolling_slip_and_sticking(reference):
    r = reference
    assert r["rolling"]["n_transitions"] == 0 and r["rolling"]["slip_fraction"] == 0.0
    assert r["roll_slip"]["n_transitions"] > 2 and 0.0 < r["roll_slip"]["slip_fraction"] < 1.0
    assert r["sticking"]["n_stick"] > 10
    for s in r.values():
        assert s["outcome"] == "halted" and s["halt_finite"]


@pytest.mark.slow
@pytest.mark.parametrize("workers", [1, 2])
def test_cpu_batch_equals_simulate(reference, workers):
    stats = {}
    got = sweep.simulate_batch([make_scene(**v) for v in SCENES.values()], device="cpu", workers=workers,
                               stats=stats)
    assert stats["reruns"] == 0 and stats["workers"] == workers
    for (name, ref), s in zip(reference.items(), got):
        assert summaries_equal(ref, s, rtol=1e-9) == [], name
        assert s["wall_time"] > 0.0


_SIM_SCRIPT = textwrap.dedent("""
    import json, sys
    sys.path.insert(0, {tests!r})
    from conftest import make_scene
    import sweep
    stats = {{}}
    out = sweep.simulate_batch([make_scene(**v) for v in json.loads(sys.argv[1])], device="cuda", stats=stats)
    print(json.dumps({{"summaries": out, "stats": stats}}))
""")


def test_cuda_kernel_under_simulator_equals_simulate(reference):
    """The CUDA kernel (persistent threads, atomic counter, local arrays, device-side fits) run by
    numba's simulator: 2 threads share the 3 scenes, every summary equals sweep.simulate's."""
    env = dict(os.environ, NUMBA_ENABLE_CUDASIM="1")
    res = subprocess.run([sys.executable, "-c", _SIM_SCRIPT.format(tests=str(ROOT / "tests")),
                          json.dumps(list(SCENES.values()))], env=env, capture_output=True, text=True,
                         cwd=ROOT, timeout=900)
    assert res.returncode == 0, res.stderr[-3000:]
    data = json.loads(res.stdout.strip().splitlines()[-1])
    st = data["stats"]
    assert st["device"] == "cuda" and st["threads"] == 2 and st["reruns"] == 0
    for (name, ref), s in zip(reference.items(), data["summaries"]):
        assert summaries_equal(ref, s, rtol=1e-9) == [], name


def test_cuda_without_gpu_fails_at_once_and_nothing_imports_numba_cuda():
    code = textwrap.dedent("""
        import sys, sweep
        assert "numba.cuda" not in sys.modules           # importing sweep never loads numba-cuda
        sweep.simulate_batch([{}], device="cpu", workers=1)
        assert "numba.cuda" not in sys.modules           # nor does the CPU batch
        from sweep.gpu import CudaUnavailableError
        try:
            sweep.simulate_batch([{"disk": {"radius": -1}}], device="cuda")
        except CudaUnavailableError as exc:
            print("ERR", exc)
        else:
            print("RAN")
    """)
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_ENABLE_CUDASIM"}
    res = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, cwd=ROOT,
                         timeout=600)
    assert res.returncode == 0, res.stderr[-3000:]
    out = res.stdout.strip()
    if out == "RAN":
        pytest.skip("this machine has a GPU: the no-GPU message cannot be checked here")
    # the GPU check comes first (before the invalid scene is even validated), and says what to do
    assert out.startswith("ERR device='cuda'") and "device='cpu'" in out


def test_a_prebuilt_kernel_from_other_sources_or_numba_cuda_is_refused_naming_what_differs(tmp_path):
    """gpu.install_prebuilt checks the stamp of a kernel compiled elsewhere (save_prebuilt) before it
    registers it: the core's and the kernel's source fingerprint, numba-cuda and compute capability."""
    code = textwrap.dedent("""
        import lzma, pickle, sys
        from sweep import gpu
        disp = gpu.kernel()
        cc = tuple(gpu.cuda.get_current_device().compute_capability)
        good = {"format": gpu.PREBUILT_FORMAT, "fingerprint": gpu._core_fingerprint(), "cc": cc,
                "numba_cuda": gpu._numba_cuda_version(), "kernel": None}
        for key, bad in (("fingerprint", "0" * 64), ("numba_cuda", "0.1.0"), ("cc", (1, 0)), ("format", 0)):
            path = sys.argv[1] + "/k_" + key + ".pkl.xz"
            with lzma.open(path, "wb") as f:
                pickle.dump(dict(good, **{key: bad}), f)
            try:
                gpu.install_prebuilt(disp, path)
            except ValueError as exc:
                print(key, "|", exc)
            else:
                print(key, "| ACCEPTED")
        for name, content in (("missing", None), ("garbage", b"not lzma")):
            path = sys.argv[1] + "/" + name + ".pkl.xz"
            if content is not None:
                open(path, "wb").write(content)
            try:
                gpu.install_prebuilt(disp, path)
            except ValueError as exc:
                print(name, "|", exc)
    """)
    env = dict(os.environ, NUMBA_ENABLE_CUDASIM="1")
    res = subprocess.run([sys.executable, "-c", code, str(tmp_path)], env=env, capture_output=True, text=True,
                         cwd=ROOT, timeout=600)
    assert res.returncode == 0, res.stderr[-3000:]
    lines = dict(line.split(" | ", 1) for line in res.stdout.strip().splitlines())
    assert set(lines) == {"fingerprint", "numba_cuda", "cc", "format", "missing", "garbage"}
    for name in ("missing", "garbage"):   # an unreadable file: said so, with the way out
        msg = lines.pop(name)
        assert msg.startswith("SWEEP_CUDA_KERNEL=") and "cannot read a prebuilt kernel" in msg, msg
        assert "--save-kernel" in msg and "unset SWEEP_CUDA_KERNEL" in msg, msg
    for key, msg in lines.items():
        assert msg.startswith("SWEEP_CUDA_KERNEL=") and f"prebuilt kernel's {key} is" in msg, msg
        assert "cuda_compile_offline.py --cc" in msg and "--save-kernel" in msg


def test_the_prebuilt_kernel_stamp_follows_the_kernel_source():
    """An edit of the kernel body (sweep.gpu._build_kernel) or of the core changes the stamp."""
    from sweep import gpu

    base = gpu._core_fingerprint()
    original = gpu._build_kernel
    try:
        def _build_kernel(cuda_module):   # another kernel source
            return None
        gpu._build_kernel = _build_kernel
        assert gpu._core_fingerprint() != base
    finally:
        gpu._build_kernel = original
    assert gpu._core_fingerprint() == base


def test_launch_shape_spreads_a_small_batch_over_every_multiprocessor(monkeypatch):
    """A batch smaller than the resident threads gets a block on every SM (an H100 ran 1000 scenes
    on 16 of 132 SMs before); a large one fills the GPU with full blocks; never more threads than
    the registers allow, never fewer than the scenes that fit."""
    from types import SimpleNamespace

    from sweep import gpu

    monkeypatch.setattr(gpu, "simulator_enabled", lambda: False)
    h100 = SimpleNamespace(MULTIPROCESSOR_COUNT=132, MAX_THREADS_PER_MULTIPROCESSOR=2048,
                           MAX_REGISTERS_PER_MULTIPROCESSOR=65536)
    fake = SimpleNamespace(get_current_device=lambda: h100)
    tpb = gpu.THREADS_PER_BLOCK
    resident_blocks = 132 * ((65536 // 255) // tpb)          # 4 blocks of 64 per SM at 255 registers
    assert gpu.launch_shape(fake, 1000, 255) == (132, 8)
    assert gpu.launch_shape(fake, 8, 255) == (8, 1)
    assert gpu.launch_shape(fake, 10**6, 255) == (resident_blocks, tpb)
    for n in (1, 2, 131, 132, 133, 1000, 8447, 8448, 8449, 20000, 33792, 33793, 10**6):
        blocks, threads = gpu.launch_shape(fake, n, 255)
        assert 1 <= threads <= tpb and blocks <= resident_blocks, n
        assert blocks >= min(n, 132), n                       # every SM busy while there are scenes for it
        assert blocks * threads >= min(n, resident_blocks * tpb), n
        assert blocks * threads < n + blocks, n               # no block of idle threads only


def test_summaries_compared_without_the_run_statistics_see_only_the_motion():
    """A GPU's round-off moves steps: summaries_equal(..., run_statistics=False) sets the step and
    evaluation counts aside, and still reports any value of the motion beyond rtol."""
    from sweep.ensemble import RUN_STATISTICS

    a = {"outcome": "halted", "t_halt": 19.3836, "n_transitions": 126, "levels": [{"t": 15.0902}],
         "wall_time": 1.0, **{k: 1000 for k in RUN_STATISTICS}}
    b = dict(a, wall_time=2.0, **{k: 1001 for k in RUN_STATISTICS})
    assert sorted(x.split(":")[0] for x in summaries_equal(a, b)) == sorted(RUN_STATISTICS)
    assert summaries_equal(a, b, run_statistics=False) == []
    c = dict(b, t_halt=19.3836 * (1 + 1e-8), levels=[{"t": 15.0902}])
    assert summaries_equal(a, c, rtol=1e-6, run_statistics=False) == []
    assert summaries_equal(a, c, rtol=1e-9, run_statistics=False) == ["t_halt: 19.3836 != 19.383600193836"]
    d = dict(b, n_transitions=127)   # an event count is the motion's, not the run's
    assert summaries_equal(a, d, run_statistics=False) == ["n_transitions: 126 != 127"]


def test_bad_device_and_workers_are_rejected():
    with pytest.raises(sweep.ConfigError, match="device"):
        sweep.simulate_batch([{}], device="tpu")
    with pytest.raises(sweep.ConfigError, match="workers"):
        sweep.simulate_batch([{}], workers=0)
    with pytest.raises(sweep.ConfigError, match="contact.mu_d"):
        sweep.simulate_batch([make_scene(contact__mu_d=0.9)])


def test_empty_batch():
    assert sweep.simulate_batch([]) == []


def test_more_levels_than_the_batch_buffers_fall_back_to_simulate():
    levels = list(np.geomspace(0.3, 0.05, core_ensemble.MAX_LEVELS + 1))
    cfg = make_scene(stop__levels=levels, stop__max_steps=400)
    stats = {}
    [s] = sweep.simulate_batch([cfg], stats=stats)
    assert stats["reruns"] == 1 and stats["batch"] == 0
    assert summaries_equal(sweep.simulate(cfg).summary, s) == []


def test_halt_fit_kernel_matches_closed_forms():
    # beta = c (T - t)^p with T = 10, p = 2, c = 1e-3: the fit on any three levels is exact
    T, p, c = 10.0, 2.0, 1e-3
    levels = np.array([1e-1, 1e-2, 1e-3, 1e-4])
    t = T - (levels / c) ** (1.0 / p)
    fit = diagnostics.halt_time(t, levels)
    assert fit["halt_finite"]
    assert math.isclose(fit["t_halt"], T, rel_tol=1e-12)
    assert math.isclose(fit["approach_exponent"], p, rel_tol=1e-9)
    # its error bar is the extrapolated remainder t_halt - t_last (diagnostics module docstring)
    assert math.isclose(fit["t_halt_error"], T - t[-1], rel_tol=1e-9)
    # Omega = 3 (T - t)^-1.5 exactly: the ramp exponent is 1.5
    om = 3.0 * (T - t) ** -1.5
    assert math.isclose(diagnostics.ramp_exponent(t, om, T), 1.5, rel_tol=1e-12)
    # gaps that do not shrink: no finite halt
    assert not diagnostics.halt_time(np.array([1.0, 2.0, 3.0]), levels[:3])["halt_finite"]


@pytest.mark.slow
def test_pipeline_on_cuda_gives_the_cpu_cube(tmp_path):
    """The tiny sweep with execution.device cuda (the kernel under numba's simulator, one GPU job per
    batch of chunks, resources gpu=1) gives the cube of the cpu run: every variable to 1e-9."""
    import xarray as xr
    import yaml

    from conftest import copy_workflow

    wd = copy_workflow(tmp_path / "wf")
    cfg = yaml.safe_load((wd / "config" / "tiny.yaml").read_text())
    cubes = {}
    for device in ("cpu", "cuda"):
        name = f"tiny_{device}"
        (wd / "config" / f"{name}.yaml").write_text(yaml.safe_dump(
            dict(cfg, name=name, execution={"device": device, "chunk_size": 5})))
        env = dict(os.environ, NUMBA_ENABLE_CUDASIM="1" if device == "cuda" else "0")
        cmd = [sys.executable, "-m", "snakemake", f"results/{name}/cube.nc", "-j2", "--resources", "gpu=1",
               "--configfile", f"config/{name}.yaml"]
        p = subprocess.run(cmd, cwd=wd, env=env, capture_output=True, text=True, timeout=900)
        assert p.returncode == 0, (p.stdout + p.stderr)[-4000:]
        out = p.stdout + p.stderr
        if device == "cuda":
            # 4 chunks of 1-3 scenes in batches of <= 5 scenes: 2 GPU jobs, no per-chunk job
            assert len(re.findall(r"rule simulate_cuda_[0-9a-f]{16}:", out)) == 2
            assert "rule simulate_chunk:" not in out
        cubes[device] = xr.open_dataset(wd / "results" / name / "cube.nc")
    a, b = cubes["cpu"], cubes["cuda"]
    assert set(a.data_vars) == set(b.data_vars)
    for v in a.data_vars:
        if v == "wall_time":
            continue
        x, y = a[v].values, b[v].values
        if x.dtype.kind == "f":
            assert np.allclose(x, y, rtol=1e-9, atol=0.0, equal_nan=True), v
        else:
            assert (x == y).all(), v


def test_batch_chunks_carry_the_error_bars_of_the_chunk_runner(tmp_path):
    """outputs.error_estimate on the batch path (the GPU jobs' runner, here on the CPU threads):
    every scene is rerun at the error bars' tolerances and the chunk file equals the one the
    per-scene chunk runner writes (every variable but wall_time)."""
    import xarray as xr
    import yaml

    from sweep import batch, ensemble, grid

    cfg = yaml.safe_load((ROOT / "config" / "tiny.yaml").read_text())
    cfg["grid"].update(mu_d=[0.1], k3=[3e-4], alpha0=[0.6], omega0=[10.0, 20.0])
    cfg["outputs"]["error_estimate"] = True
    settings = grid.normalize(cfg, grid.load_schema(), check_scenes=False)
    chunks = list(grid.plan_chunks(settings).values())
    one = [tmp_path / f"one-{c.id}.nc" for c in chunks]
    many = [tmp_path / f"batch-{c.id}.nc" for c in chunks]
    for c, path in zip(chunks, one):
        batch.run_chunk(c, path)
    ensemble.run_chunks_job([c.spec_json for c in chunks], [c.id for c in chunks],
                            [str(p) for p in many], device="cpu")
    for a, b in zip(one, many):
        with xr.open_dataset(a) as da, xr.open_dataset(b) as db:
            assert "t_halt_numerical_error" in db and "reference_outcome" in db
            for v in da.data_vars:
                if v != "wall_time":
                    np.testing.assert_allclose(db[v].values, da[v].values, rtol=1e-9, equal_nan=True)
