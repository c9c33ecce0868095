#!/usr/bin/env python3
"""Where the numba compile time goes before the first scene (issue #42, part 3: the measurement).

    .venv/bin/python benchmarks/compile_time.py              # cold + warm, tiny scene (~2-4 min on 2 cores)
    .venv/bin/python benchmarks/compile_time.py --top 25     # more dispatchers in the table
    .venv/bin/python benchmarks/compile_time.py --json out.json
    .venv/bin/python benchmarks/compile_time.py --opt 2 1   # also cold compiles at NUMBA_OPT 2, 1 (~2 min each)
    .venv/bin/python benchmarks/compile_time.py --against 378a4e3 --pairs 3   # side by side (~10 min)

Each measurement runs in a fresh Python process (the numba cache is per process and per disk folder):

* **cold**: NUMBA_CACHE_DIR set to an empty temporary folder, so every kernel compiles (the
  project's cache, src/sweep/core/__pycache__/numba-<digest>/, is neither read nor touched; core.jit
  honours NUMBA_CACHE_DIR). The process times `import sweep`, then the first `sweep.simulate` of a
  tiny scene (the defaults with t_max = 0.01 s: what `python3 run.py sweep` compiles before its first
  job, warmup.warm_numba -> batch.warm_up -> sweep.simulate), then the first
  `sweep.simulate_batch([scene], workers=1)` (its entry point core.ensemble.solve_index is another
  top-level kernel: what it adds), then a second simulate (in-process, warm).
* **warm**: the same in a new process over the cache the cold run filled: the cost of loading the
  compiled kernels, which every process that runs scenes pays once (each Snakemake job of a sweep is
  one such process).

Before the runs it prints the core's call graph from the source (`static_call_graph`): the number
of @kernel functions, the inline="always" ones and their call sites, the separate kernels with a
single call site, how deep the separate libraries nest below the entry points, and the kernels
linked into the most other libraries (numba links a callee's LLVM module into each caller's library
and optimises and compiles the whole linked module again there).

`--against COMMIT` runs only the side-by-side: cold compiles of this checkout and of COMMIT (a
temporary git worktree), alternated --pairs times, each in a fresh process with an empty cache
(the compile times of a shared machine drift by up to 1.5x within an hour, so only alternated runs
compare); their first simulate's and first simulate_batch's thread CPU, and the ratios at the
minima and the medians.

Each process then times the paper's case (to the 1e-3 level, thread CPU, minimum of 3 runs), so that
`--opt` levels (NUMBA_OPT for the whole compilation) show compile time against the code's speed.

During each phase a listener on numba's event API (`numba.core.event`) records every
"numba:compile" (one dispatcher's compilation for one signature), "numba:run_pass" (one compiler
pass of one function: type inference, lowering, ...) and "numba:llvm_lock" (the time spent inside
LLVM: IR parsing, optimisation passes, machine-code generation, linking). The events nest (a callee
compiles while its caller is being typed; LLVM runs inside the lowering pass), so each interval's
*exclusive* time is its duration minus its children's. All event times are the compiling thread's
CPU time (time.thread_time: what other processes on a shared machine take does not count; numba
compiles in one thread). Reported per phase: wall and CPU time; the time in compile events (top
level, inclusive); LLVM (all llvm_lock time, and how much of it inside the lowering pass); typing
(exclusive time of the type-inference pass: without the callees' compilations it triggers);
lowering, Python side (the lowering pass less the LLVM time inside it); the other passes; the CPU
time outside any compile event (cache writes, loading, Python); and the dispatchers by exclusive
time (their own typing, lowering and LLVM, not their callees' compilations), with the number of
signatures compiled. The cold first simulate's LLVM time is also split by what it does (timed
around numba's code-library methods): function passes, the module passes on each library's final
module (its functions and a linked copy of all its callees'), and machine code; with the number of
function bodies the module passes saw against the distinct functions among them.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent

CHILD = r'''
import json, sys, time, threading
T0 = time.perf_counter()
from numba.core import event as ev
CLOCK = time.thread_time      # CPU time of the compiling thread: robust on a shared machine

class Recorder(ev.Listener):
    """Nested intervals of compile / pass / LLVM events, per thread. Each interval's exclusive time
    (duration less its children's) goes to its pass (or to LLVM) and to the dispatcher whose
    compilation it belongs to (the nearest compile event on the stack)."""
    def __init__(self):
        self.stack = {}
        self.reset()
    def reset(self):
        self.by_disp = {}       # qualname -> [own (exclusive) time, top-level inclusive, signatures, own LLVM time]
        self.by_pass = {}       # pass name -> exclusive time (LLVM and nested compilations excluded)
        self.llvm = 0.0
        self.llvm_in = {}       # pass name (or 'compile' / 'outside') -> LLVM time inside it
        self.top_compile = 0.0
        self.n_compile = 0
    def _name(self, event):
        d = event.data or {}
        if event.kind == "numba:compile":
            disp = d.get("dispatcher")
            f = getattr(disp, "py_func", None)
            return f"{f.__module__}.{f.__qualname__}" if f is not None else str(disp)
        if event.kind == "numba:run_pass":
            return d.get("name", "?").split(" [")[0]
        return "llvm"
    def on_start(self, event):
        st = self.stack.setdefault(threading.get_ident(), [])
        st.append([event.kind, self._name(event), CLOCK(), 0.0])
    def on_end(self, event):
        st = self.stack.get(threading.get_ident())
        if not st:
            return
        kind, name, t0, child = st.pop()
        dur = CLOCK() - t0
        excl = dur - child
        if st:
            st[-1][3] += dur
        owner = name if kind == "numba:compile" else next(
            (f[1] for f in reversed(st) if f[0] == "numba:compile"), None)
        if owner is not None:
            e = self.by_disp.setdefault(owner, [0.0, 0.0, 0, 0.0])
            e[0] += excl
            if kind == "numba:llvm_lock" and not any(f[0] == "numba:llvm_lock" for f in st):
                e[3] += dur
        if kind == "numba:compile":
            e[2] += 1
            self.n_compile += 1
            if not any(f[0] == "numba:compile" for f in st):
                self.top_compile += dur
                e[1] += dur
        elif kind == "numba:run_pass":
            self.by_pass[name] = self.by_pass.get(name, 0.0) + excl
        elif not any(f[0] == "numba:llvm_lock" for f in st):
            self.llvm += dur
            where = next((f[1] for f in reversed(st) if f[0] == "numba:run_pass"), None)
            if where is None:
                where = "compile" if any(f[0] == "numba:compile" for f in st) else "outside"
            self.llvm_in[where] = self.llvm_in.get(where, 0.0) + dur


rec = Recorder()
for kind in ("numba:compile", "numba:run_pass", "numba:llvm_lock"):
    ev.register(kind, rec)

# The LLVM time by what it does, timed around numba's code-library methods (numba.core.codegen):
# function passes on each new function; the module passes on a library's final module, which holds
# its own functions and a linked copy of every callee library's (so a callee is optimised again in
# each library above it); machine code for that whole module. Also how many function bodies those
# module passes saw, against the distinct functions among them.
from numba.core import codegen as _cg
SPLIT = {"function_passes_s": 0.0, "module_passes_s": 0.0, "machine_code_s": 0.0, "libraries": 0,
         "bodies_optimised": 0, "distinct": set()}
def _timed(key, fn):
    def wrapper(self, *a, **k):
        t = CLOCK()
        try:
            return fn(self, *a, **k)
        finally:
            SPLIT[key] += CLOCK() - t
    return wrapper
_final = _cg.CPUCodeLibrary._optimize_final_module
def _optimize_final_module(self):
    names = [f.name for f in self._final_module.functions if not f.is_declaration]
    SPLIT["libraries"] += 1
    SPLIT["bodies_optimised"] += len(names)
    SPLIT["distinct"].update(names)
    return _final(self)
_cg.CPUCodeLibrary._optimize_functions = _timed("function_passes_s", _cg.CPUCodeLibrary._optimize_functions)
_cg.CPUCodeLibrary._optimize_final_module = _timed("module_passes_s", _optimize_final_module)
_cg.JITCodeLibrary._finalize_specific = _timed("machine_code_s", _cg.JITCodeLibrary._finalize_specific)
def split_reset():
    for k in SPLIT:
        SPLIT[k] = set() if k == "distinct" else type(SPLIT[k])()

out = {}
t = time.perf_counter()
import sweep
out["import_s"] = time.perf_counter() - t
out["import_cpu_s"] = time.process_time()
out["python_start_to_import_s"] = time.perf_counter() - T0

SCENE = {"stop": {"t_max": 0.01}}
PAPER = sys.argv[1]

def phase(name, fn):
    rec.reset()
    split_reset()
    t, c = time.perf_counter(), time.thread_time()
    fn()
    wall, cpu = time.perf_counter() - t, time.thread_time() - c
    out[name] = {"wall_s": wall, "cpu_s": cpu, "compile_s": rec.top_compile, "n_compiled": rec.n_compile, "llvm_s": rec.llvm,
                 "llvm_in": rec.llvm_in, "passes": rec.by_pass,
                 "dispatchers": {k: {"exclusive_s": v[0], "inclusive_s": v[1], "signatures": v[2], "llvm_s": v[3]}
                                 for k, v in rec.by_disp.items()},
                 "llvm_split": {k: (len(v) if k == "distinct" else v) for k, v in SPLIT.items()}}

def batch():
    import inspect
    kw = {"workers": 1}
    if "device" in inspect.signature(sweep.simulate_batch).parameters:
        kw["device"] = "cpu"
    sweep.simulate_batch([SCENE], **kw)

phase("simulate", lambda: sweep.simulate(SCENE))
phase("simulate_batch", batch)
phase("second_simulate", lambda: sweep.simulate(SCENE))
# what the compiled code then costs: the paper's case to the 1e-3 level, minimum thread CPU of 3 runs
import yaml, copy
cfg = yaml.safe_load(open(PAPER))
cfg.setdefault("stop", {})["levels"] = [1e-1, 1e-2, 1e-3]
best = 1e9
for _ in range(3):
    c = time.thread_time()
    sweep.simulate(copy.deepcopy(cfg))
    best = min(best, time.thread_time() - c)
out["paper_case_cpu_s"] = best
from sweep.core import jit
out["cache_dir"] = str(jit.cache_dir())
import numba
out["numba_opt"] = numba.config.OPT
print("RESULT " + json.dumps(out), flush=True)
'''


def static_call_graph(core: Path = ROOT / "src" / "sweep" / "core") -> dict:
    """The core's @kernel functions and their call sites, from the source (ast): how many there are,
    how many are inline="always" (numba inlines them into each caller's IR: typed and lowered once
    per call site), how many separate ones have a single call site, the depth of the nesting of
    separate libraries below each entry point, and the kernels whose code is linked into the most
    other libraries (numba links a callee's LLVM module into every caller's library and optimises
    and compiles the linked module again there, at every level)."""
    import ast
    import collections
    import functools

    kernels, bodies = {}, {}
    for f in sorted(core.glob("*.py")):
        for node in ast.parse(f.read_text()).body:
            if not isinstance(node, ast.FunctionDef):
                continue
            inline = None
            for d in node.decorator_list:
                if isinstance(d, ast.Name) and d.id == "kernel":
                    inline = False
                elif isinstance(d, ast.Call) and getattr(d.func, "id", None) == "kernel":
                    inline = any(k.arg == "inline" and getattr(k.value, "value", None) == "always" for k in d.keywords)
            if inline is not None:
                kernels[node.name] = inline
                bodies[node.name] = node
    calls = collections.defaultdict(list)
    for name, node in bodies.items():
        for sub in ast.walk(node):
            if isinstance(sub, ast.Call):
                fn = sub.func
                callee = fn.id if isinstance(fn, ast.Name) else (fn.attr if isinstance(fn, ast.Attribute) else None)
                if callee in kernels and callee != name:
                    calls[callee].append(name)
    graph = collections.defaultdict(set)
    for callee, callers in calls.items():
        for c in callers:
            graph[c].add(callee)

    @functools.lru_cache(None)
    def depth(n):
        subs = [depth(c) for c in graph[n]]
        return (max(subs) if subs else 0) + (0 if kernels[n] else 1)

    @functools.lru_cache(None)
    def ancestors(n):
        out = set()
        for c in calls[n]:
            out.add(c)
            out |= ancestors(c)
        return frozenset(out)

    linked = sorted(((sum(1 for a in ancestors(k) if not kernels[a]), k) for k in kernels if not kernels[k]),
                    reverse=True)
    entries = [k for k in kernels if not calls[k]]
    return {"kernels": len(kernels), "inline_always": sum(kernels.values()),
            "inline_call_sites": {k: len(calls[k]) for k in kernels if kernels[k]},
            "single_call_site": sum(1 for k in kernels if not kernels[k] and len(calls[k]) == 1),
            "entries": entries, "depth": {k: depth(k) for k in ("run", "solve_index") if k in kernels},
            "most_linked": linked[:8]}


def run_child(cache_dir: str, opt: int | None = None, src: Path = ROOT / "src") -> dict:
    import resource
    env = dict(os.environ, NUMBA_CACHE_DIR=cache_dir, PYTHONPATH=str(src))
    if opt is not None:
        env["NUMBA_OPT"] = str(opt)
    r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    p = subprocess.run([sys.executable, "-c", CHILD, str(ROOT / "config" / "scenes" / "kessler2002.yaml")], env=env,
                       capture_output=True, text=True, cwd=ROOT)
    total = time.perf_counter() - t0
    r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (r1.ru_utime - r0.ru_utime) + (r1.ru_stime - r0.ru_stime)
    if p.returncode != 0:
        raise SystemExit(f"child failed ({p.returncode}):\n{p.stderr[-4000:]}")
    line = next(ln for ln in p.stdout.splitlines() if ln.startswith("RESULT "))
    res = json.loads(line[len("RESULT "):])
    res["process_s"] = total
    res["process_cpu_s"] = cpu
    return res


def cache_size(path: str) -> tuple[int, int]:
    files = [f for f in Path(path).rglob("*") if f.is_file()]
    return len(files), sum(f.stat().st_size for f in files)


def load() -> str:
    return "load average %.2f %.2f %.2f" % os.getloadavg()


def phase_lines(name: str, ph: dict) -> list[str]:
    passes = ph["passes"]
    typing = passes.get("nopython_type_inference", 0.0)
    lowering = passes.get("native_lowering", 0.0)      # exclusive: the LLVM time inside it is apart
    llvm_low = ph["llvm_in"].get("native_lowering", 0.0)
    other = sum(v for k, v in passes.items() if k not in ("nopython_type_inference", "native_lowering"))
    llvm_other = ph["llvm_s"] - llvm_low
    return [
        f"| {name} | {ph['wall_s']:.2f} | {ph['cpu_s']:.2f} | {ph['compile_s']:.2f} | {ph['n_compiled']} | {ph['llvm_s']:.2f} "
        f"({llvm_low:.2f} in lowering, {llvm_other:.2f} elsewhere) | {typing:.2f} | {lowering:.2f} | "
        f"{other:.2f} | {max(ph['cpu_s'] - ph['compile_s'], 0.0):.2f} |"]


def side_by_side(commit: str, pairs: int) -> int:
    """Cold compiles of this checkout and of `commit` (a temporary git worktree), alternated, `pairs`
    times, each in a fresh process with an empty cache: the first simulate's and the first
    simulate_batch's thread CPU, and their ratios at the minima and the medians."""
    import shutil
    import statistics
    wt = Path(tempfile.mkdtemp(prefix="sweep-compile-base-")) / "wt"
    subprocess.run(["git", "worktree", "add", "--detach", str(wt), commit], cwd=ROOT, check=True,
                   capture_output=True, text=True)
    runs = {"current": [], commit: []}
    try:
        for i in range(pairs):
            for name, src in (("current", ROOT / "src"), (commit, wt / "src")):
                tmp = tempfile.mkdtemp(prefix="sweep-compile-time-")
                try:
                    r = run_child(tmp, src=src)
                finally:
                    shutil.rmtree(tmp, ignore_errors=True)
                runs[name].append((r["simulate"]["cpu_s"], r["simulate_batch"]["cpu_s"], r["simulate"]["n_compiled"]))
                print(f"pair {i + 1}: {name}: first simulate {r['simulate']['cpu_s']:.1f} s CPU "
                      f"({r['simulate']['n_compiled']} signatures), first simulate_batch "
                      f"{r['simulate_batch']['cpu_s']:.1f} s ({load()})", flush=True)
    finally:
        subprocess.run(["git", "worktree", "remove", "--force", str(wt)], cwd=ROOT, capture_output=True)
        subprocess.run(["git", "worktree", "prune"], cwd=ROOT, capture_output=True)
        shutil.rmtree(wt.parent, ignore_errors=True)
    print("\n| checkout | first simulate CPU (s), each pair | min | median | first simulate_batch CPU (s) | signatures |")
    print("|---|---|---|---|---|---|")
    for name, rr in runs.items():
        sim = [x[0] for x in rr]
        print(f"| {name} | {' / '.join(f'{v:.1f}' for v in sim)} | {min(sim):.1f} | {statistics.median(sim):.1f} | "
              f"{' / '.join(f'{x[1]:.1f}' for x in rr)} | {rr[0][2]} |")
    cur = [x[0] for x in runs["current"]]
    base = [x[0] for x in runs[commit]]
    print(f"\ncurrent / {commit}: {min(cur) / min(base):.3f} at the minima, "
          f"{statistics.median(cur) / statistics.median(base):.3f} at the medians, pairwise "
          + ", ".join(f"{c / b:.3f}" for c, b in zip(cur, base)))
    return 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--top", type=int, default=15, help="dispatchers listed (by exclusive compile time)")
    ap.add_argument("--json", default=str(HERE / "out" / "compile_time.json"))
    ap.add_argument("--opt", type=int, nargs="*", default=[],
                    help="also cold-compile with these NUMBA_OPT levels (0-3; default 3) in fresh processes and "
                         "report compile CPU against the paper case's CPU time")
    ap.add_argument("--against", metavar="COMMIT", default=None,
                    help="only the side-by-side: cold compiles of this checkout and COMMIT alternated (--pairs)")
    ap.add_argument("--pairs", type=int, default=3)
    a = ap.parse_args(argv)
    print(f"# compile_time: {os.cpu_count()} CPUs, python {sys.version.split()[0]}; {load()}\n", flush=True)
    if a.against:
        return side_by_side(a.against, a.pairs)
    st = static_call_graph()
    print(f"the core's call graph (source): {st['kernels']} @kernel functions, {st['inline_always']} of them "
          f"inline=\"always\" (call sites: {st['inline_call_sites']}); {st['single_call_site']} separate kernels "
          f"with a single call site; entry points / called from Python only: {', '.join(st['entries'])}; "
          f"nesting of separate libraries below the entry points: {st['depth']}; the kernels linked into the "
          f"most other libraries (count, name): {st['most_linked']}\n", flush=True)
    tmp = tempfile.mkdtemp(prefix="sweep-compile-time-")
    try:
        cold = run_child(tmp)
        print(f"cold run done ({load()})", flush=True)
        files, size = cache_size(tmp)
        warm = run_child(tmp)
        print(f"warm run done ({load()})\n", flush=True)
    finally:
        import shutil
        shutil.rmtree(tmp, ignore_errors=True)

    print(f"cold process: import sweep {cold['import_s']:.2f} s; whole process {cold['process_s']:.1f} s wall, "
          f"{cold['process_cpu_s']:.1f} s CPU; cache written: {files} files, {size / 1e6:.1f} MB")
    print(f"warm process (what each Snakemake job of a sweep pays once, before its first scene): import sweep "
          f"{warm['import_s']:.2f} s; whole process (start, imports, cache loads, three tiny runs) "
          f"{warm['process_s']:.2f} s wall, {warm['process_cpu_s']:.2f} s CPU\n")
    head = ("| phase | wall (s) | CPU (s) | in compile events (s) | signatures compiled | LLVM (s) | typing (s) | "
            "lowering, Python side (s) | other passes (s) | outside compile (s) |")
    lines = [head, "|---|---|---|---|---|---|---|---|---|---|"]
    for run, r in (("cold", cold), ("warm", warm)):
        for ph in ("simulate", "simulate_batch", "second_simulate"):
            lines += phase_lines(f"{run}: first {ph}" if ph != "second_simulate" else f"{run}: second simulate", r[ph])
    print("\n".join(lines))

    sp = cold["simulate"]["llvm_split"]
    print(f"\ncold, first simulate, LLVM by what it does: function passes {sp['function_passes_s']:.1f} s, module "
          f"passes on the {sp['libraries']} libraries' final modules {sp['module_passes_s']:.1f} s, machine code "
          f"{sp['machine_code_s']:.1f} s; the module passes saw {sp['bodies_optimised']} function bodies, "
          f"{sp['distinct']} distinct ({sp['bodies_optimised'] / max(sp['distinct'], 1):.1f} times each on average: "
          f"a callee's code is linked into every library above it and optimised and compiled again there)")
    for ph in ("simulate", "simulate_batch"):
        d = cold[ph]["dispatchers"]
        tot = sum(v["exclusive_s"] for v in d.values())
        print(f"\ncold, first {ph}: {len(d)} dispatchers, {tot:.1f} s exclusive in all; the top {a.top}:\n")
        print("| dispatcher | exclusive (s) | of it LLVM (s) | share | inclusive, top level (s) | signatures |")
        print("|---|---|---|---|---|---|")
        for k, v in sorted(d.items(), key=lambda kv: -kv[1]["exclusive_s"])[:a.top]:
            print(f"| {k} | {v['exclusive_s']:.2f} | {v['llvm_s']:.2f} | {100 * v['exclusive_s'] / tot:.1f} % | "
                  f"{v['inclusive_s']:.2f} | {v['signatures']} |")
        passes = cold[ph]["passes"]
        ptot = sum(passes.values())
        print(f"\ncold, first {ph}: compiler passes by exclusive time (without the LLVM time and the callees' "
              f"compilations inside them; LLVM in all: {cold[ph]['llvm_s']:.1f} s):\n")
        print("| pass | exclusive (s) | share |")
        print("|---|---|---|")
        for k, v in sorted(passes.items(), key=lambda kv: -kv[1])[:10]:
            print(f"| {k} | {v:.2f} | {100 * v / ptot:.1f} % |")
    opts = {}
    for level in a.opt:
        tmp2 = tempfile.mkdtemp(prefix=f"sweep-compile-opt{level}-")
        try:
            opts[level] = run_child(tmp2, level)
        finally:
            import shutil
            shutil.rmtree(tmp2, ignore_errors=True)
        print(f"NUMBA_OPT={level} cold run done ({load()})", flush=True)
    print("\nLLVM optimisation level: cold compile of the first simulate against the paper case's cost "
          "(to the 1e-3 level, min thread CPU of 3 runs):\n")
    print("| NUMBA_OPT | first simulate CPU (s) | of it LLVM (s) | first simulate_batch CPU (s) | paper case CPU (ms) |")
    print("|---|---|---|---|---|")
    for level, r in [(cold["numba_opt"], cold)] + list(opts.items()):
        print(f"| {level} | {r['simulate']['cpu_s']:.1f} | {r['simulate']['llvm_s']:.1f} | "
              f"{r['simulate_batch']['cpu_s']:.1f} | {1e3 * r['paper_case_cpu_s']:.1f} |")
    res = {"static": st, "cold": cold, "warm": warm, "opt": opts, "cache_files": files, "cache_bytes": size, "load_end": load()}
    Path(a.json).parent.mkdir(parents=True, exist_ok=True)
    Path(a.json).write_text(json.dumps(res, indent=1))
    print(f"\n({load()}); written: {a.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
