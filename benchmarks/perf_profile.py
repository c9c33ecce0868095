#!/usr/bin/env python3
"""Profile of the jitted core by function, with Linux `perf` (where the CPU time of a scene goes).

    .venv/bin/python benchmarks/perf_profile.py [--seed 20261122] [--index 27 36 9 13 22] [--top 30]
    .venv/bin/python benchmarks/perf_profile.py --rolling 1e-10 [--repeat 40]   # issue #42's rolling scene
    .venv/bin/python benchmarks/perf_profile.py --paper [--repeat 40]           # the paper's case

numba's machine code has no symbols that perf can read, so this compiles the core afresh (into a
temporary NUMBA_CACHE_DIR: code loaded from the cache keeps no LLVM module to name it), writes
/tmp/perf-<pid>.map with the address range of every compiled function (perf's convention for JIT
code), and records the given harness scenes (benchmarks/convergence.py, rtol 1e-10, as the harness
runs them) with `perf record` attached to this process after a warm-up scene. It prints the
functions by their share of the samples (libm's sin/cos and hypot appear under their own names).
With --rolling RTOL it records instead the pure-rolling scene of benchmarks/peer_heyoka.py (the paper's
disk, mu 5, k1 = k3 = 0, to T = 57.84 s; its 'lean' configuration: one level, no normal-force
frequency; a sample at T, so the kinematics are integrated), --repeat times: where a rolling step's
time goes (the right-hand side, contact.eval_rhs with model.rhs inlined, against the machinery).
Needs `perf` and permission to record this process (perf_event_paranoid <= 2 for one's own
processes). With --paper, the paper's case (config/scenes/kessler2002.yaml at the default settings,
the issue #42 comparison's third figure). Compiling takes a few minutes.
"""
from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent


def write_perf_map() -> int:
    """/tmp/perf-<pid>.map for every function of every compiled sweep kernel; returns the count."""
    import numba

    addrs = {}
    for mod in list(sys.modules.values()):
        if not getattr(mod, "__name__", "").startswith("sweep"):
            continue
        for v in vars(mod).values():
            if not isinstance(v, numba.core.dispatcher.Dispatcher):
                continue
            for cres in v.overloads.values():
                lib = cres.library
                module = getattr(lib, "_final_module", None)
                if module is None:
                    continue
                for fn in module.functions:
                    if fn.is_declaration:
                        continue
                    a = lib._codegen._engine.get_function_address(fn.name)
                    if a:
                        addrs[a] = fn.name
    items = sorted(addrs.items())
    with open(f"/tmp/perf-{os.getpid()}.map", "w") as fo:
        for k, (a, name) in enumerate(items):
            size = min(items[k + 1][0] - a if k + 1 < len(items) else 4096, 1 << 20)
            fo.write(f"{a:x} {size:x} {name}\n")
    return len(items)


def short_name(symbol: str) -> str:
    """sweep.core.model.rhs from numba's mangled name _ZN5sweep4core5model3rhsB3v10...; others as given."""
    if not symbol.startswith("_ZN"):
        return symbol
    rest, parts = symbol[3:], []
    while rest[:1].isdigit():
        digits = re.match(r"\d+", rest).group(0)
        n = int(digits)
        parts.append(rest[len(digits):len(digits) + n])
        rest = rest[len(digits) + n:]
    return ".".join(parts) or symbol


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seed", type=int, default=20261122)
    ap.add_argument("--index", type=int, nargs="+", default=[27, 36, 9, 13, 22])
    ap.add_argument("--top", type=int, default=30)
    ap.add_argument("--rolling", type=float, default=None, metavar="RTOL",
                    help="profile the peer_heyoka rolling scene at this rtol instead of harness scenes")
    ap.add_argument("--paper", action="store_true",
                    help="the paper's case (config/scenes/kessler2002.yaml, default settings), --repeat times")
    ap.add_argument("--repeat", type=int, default=40, help="runs of the rolling scene (--rolling) or the paper's case (--paper)")
    a = ap.parse_args(argv)
    if os.environ.get("_PERF_PROFILE_CHILD") != "1":
        tmp = tempfile.mkdtemp(prefix="perf-profile-")
        env = dict(os.environ, NUMBA_CACHE_DIR=tmp, _PERF_PROFILE_CHILD="1")
        return subprocess.call([sys.executable, __file__, *(argv if argv is not None else sys.argv[1:])], env=env)

    sys.path.insert(0, str(HERE))
    sys.path.insert(0, str(HERE.parent / "src"))
    import numpy as np
    import convergence as cv

    if a.rolling is not None:
        import sweep
        W3 = -14.456878347621343
        T = 57.84
        rolling = {"contact": {"mu_s": 5.0, "mu_d": 5.0, "k1": 0.0, "k2": 3.004e-5, "k3": 0.0},
                   "initial": {"alpha": 1.0, "omega": [0.0, 0.0, W3]},
                   "stop": {"levels": [1e-4], "t_max": T}, "solver": {"rtol": a.rolling, "atol": a.rolling * 1e-2},
                   "outputs": {"normal_force_frequency": False}}

        def run(i):
            return sweep.simulate(rolling, sample_times=[T])
        a.index = list(range(a.repeat))
    elif a.paper:
        import sweep
        from sweep.scene import load_scene
        paper = load_scene(HERE.parent / "config" / "scenes" / "kessler2002.yaml")

        def run(i):
            return sweep.simulate(paper)
        a.index = list(range(a.repeat))
    else:
        rng = np.random.default_rng(a.seed)
        scenes = [cv._valid_levels(cv.draw_scene(rng)) for _ in range(max(a.index) + 1)]

        def run(i):
            return cv._one_run(scenes[i], cv.DEFAULT_RTOL)   # as the harness runs it at the default rtol

    run(a.index[0])      # compiles everything
    n_fn = write_perf_map()
    data = Path(os.environ["NUMBA_CACHE_DIR"]) / "perf.data"
    rec = subprocess.Popen(["perf", "record", "-F", "2000", "-o", str(data), "-p", str(os.getpid())],
                           stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    time.sleep(1.0)
    t0 = time.process_time()
    for i in a.index:
        run(i)
    cpu = time.process_time() - t0
    rec.send_signal(2)
    rec.wait()
    rep = subprocess.run(["perf", "report", "-i", str(data), "--no-children", "--sort", "symbol", "--stdio"],
                         capture_output=True, text=True).stdout
    what = (f"rolling scene at rtol {a.rolling:g}, {a.repeat} runs" if a.rolling is not None
            else f"the paper's case, {a.repeat} runs" if a.paper else f"seed {a.seed}, scenes {a.index}")
    print(f"{what}: {cpu:.1f} s CPU recorded; {n_fn} jitted functions mapped\n")
    print("| share | function |")
    print("|---|---|")
    shown = 0
    for line in rep.splitlines():
        m = re.match(r"\s*([\d.]+)%\s+\[\.\]\s+(\S+)", line)
        if m and shown < a.top:
            print(f"| {m.group(1)} % | {short_name(m.group(2))} |")
            shown += 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
