"""The core kernels are compiled without numba's reference-counting runtime (core/jit.py): that is
safe only while no kernel allocates and none returns an array. An allocation fails to compile (every
test that runs a scene sees it); this test checks the return types of every kernel the CPU paths
compile, in a fresh process with an empty cache (a warm cache loads the callers' machine code and
never types the kernels they call), and that none was compiled for a literal constant's type."""
from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap

import pytest

from conftest import ROOT

SCRIPT = textwrap.dedent("""
    import importlib, json, pkgutil
    from numba.core import types
    from numba.core.registry import CPUDispatcher
    import sweep, sweep.core
    from conftest import make_scene

    scene = make_scene(stop__t_max=0.5, stop__levels=[0.3])
    sweep.simulate(scene, sample_times=[0.1, 0.2])
    sweep.simulate_batch([scene, make_scene(disk__shape="shell", stop__t_max=0.5)], device="cpu", workers=1)

    def arrays_in(t):
        if isinstance(t, types.Array):
            return True
        return isinstance(t, types.BaseTuple) and any(arrays_in(x) for x in t.types)

    out = {}
    for m in pkgutil.iter_modules(sweep.core.__path__):
        mod = importlib.import_module("sweep.core." + m.name)
        for name, obj in vars(mod).items():
            if isinstance(obj, CPUDispatcher) and obj.py_func.__module__ == mod.__name__:
                out[m.name + "." + name] = {
                    "nrt": obj.targetoptions.get("_nrt"),
                    "error_model": obj.targetoptions.get("error_model"),
                    "inline": obj.targetoptions.get("inline", "never"),
                    "cached": type(obj._cache).__name__ != "NullCache",
                    "kernel": type(obj).__name__,
                    "literal_args": [str(s.args) for s in obj.nopython_signatures
                                     if any(isinstance(a, types.Literal) for a in s.args)],
                    "returns": [str(s.return_type) for s in obj.nopython_signatures],
                    "array_return": any(arrays_in(s.return_type) for s in obj.nopython_signatures),
                }
    print(json.dumps(out))
""")


@pytest.mark.slow
def test_kernels_compile_without_refcounts_and_return_no_arrays(tmp_path):
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "numba-cache"),
               PYTHONPATH=os.pathsep.join([str(ROOT / "src"), str(ROOT / "tests")]))
    r = subprocess.run([sys.executable, "-c", SCRIPT], env=env, capture_output=True, text=True, timeout=900)
    assert r.returncode == 0, r.stderr[-3000:]
    kernels = json.loads(r.stdout.strip().splitlines()[-1])
    # the scan saw the kernels: the hot ones were typed in this process. Those numba inlines
    # (inline="always": model.rhs and its parts, and the stepper's kernels that call the right-hand
    # side they are given, dop853.rk_step and its kin) are typed only as part of their callers, never
    # on their own: what they return is a value inside the caller's compiled function, under its options.
    # NumPy's floating-point semantics: a division by zero gives inf or NaN, which the integrator
    # rejects or reports, never a ZeroDivisionError that loses the scene
    assert {k["error_model"] for k in kernels.values()} == {"numpy"}
    for name in ("contact_rhs.eval_rhs", "accept.try_step", "integrate.run", "ensemble.solve_index"):
        assert kernels[name]["returns"], name
    assert kernels["model.rhs"]["inline"] == "always" and not kernels["model.rhs"]["returns"]
    assert sum(1 for k in kernels.values() if k["returns"]) > 60
    for name, k in kernels.items():
        assert k["nrt"] is False and k["cached"], name
        assert not k["array_return"], (name, k["returns"])
        # a constant argument (slip_rates(x, 0.0, ...)) does not compile a copy of its own (core.jit.Kernel)
        assert k["kernel"] == "Kernel" and not k["literal_args"], (name, k["literal_args"])
