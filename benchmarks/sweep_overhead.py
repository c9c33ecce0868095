"""The fixed costs of a sweep, this tree against a base commit side by side (issue #52, item 6).

    .venv/bin/python benchmarks/sweep_overhead.py [--parts figures,gather,sweep] [--base 746a2c3]
                                                 [--gather-sizes 200,2000,20000] [--before-max 2000]

The base commit's `src/` is extracted with `git archive` to benchmarks/out/sweep_overhead/base-<commit>/
(so this needs a git clone with that history); every measurement runs in its own process with
PYTHONPATH at one tree's src/, this tree's and the base's alternately.

* figures: the four figure notebooks of the default sweep against one cube (results/tiny/cube.nc,
  made first if missing): the base runs each in its own Jupyter kernel (sweep.io.run_notebook, the
  rule `notebook` there), this tree all in one process (sweep.notebooks.run_notebooks). Wall time of the
  process, imports included.
* gather: config/million.yaml's grid (2e4 chunk files of 41 or 59 scenes) and sub-grids of it
  (its first mu_d value: 2000 files; its first mu_d and k1 values: 200); this tree's gather reads with
  2 processes (the rule's threads), the base's with one (it had no option). The chunk files are synthetic
  (random values in every variable, written from two templates, checksums as the pipeline writes
  them; cached under benchmarks/out/sweep_overhead/chunks/). Wall time and peak memory (max RSS)
  of each gather process; the base only up to --before-max files (its per-file cost, measured,
  gives the rest). Peak memory: the gathering process's VmHWM (its readers are forked from it), and
  the largest max RSS of any process the benchmark ran so far.
* sweep: the warm default sweep (each tree's config/config.yaml, -j2) through Snakemake in a copy
  of each tree's workflow (the numba cache copied over, so neither compiles): wall time, against
  the ideal, the sum of the scenes' integration times / 2 + the gather's and the figures' job
  times; the ratio wall / ideal (target <= 1.5 in the issue).
"""
from __future__ import annotations

import argparse
import json
import os
import re
import resource
import shutil
import subprocess
import sys
import tarfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "benchmarks" / "out" / "sweep_overhead"
PY = sys.executable


def base_tree(commit: str) -> Path:
    dest = OUT / f"base-{commit}"
    if not (dest / "src" / "sweep").is_dir():
        dest.mkdir(parents=True, exist_ok=True)
        tar = OUT / f"base-{commit}.tar"
        subprocess.run(["git", "-C", str(ROOT), "archive", "-o", str(tar), commit], check=True)
        with tarfile.open(tar) as t:
            t.extractall(dest)
        tar.unlink()
    copy_numba_cache(dest)
    return dest


def copy_numba_cache(tree: Path) -> None:
    """The live tree's numba cache into `tree` (same kernel sources: the same cache), the source
    files' times set alike so numba's index accepts it."""
    live = ROOT / "src" / "sweep" / "core"
    dest = tree / "src" / "sweep" / "core"
    for d in (live / "__pycache__").glob("numba-*"):
        if not (dest / "__pycache__" / d.name).exists():
            shutil.copytree(d, dest / "__pycache__" / d.name)
    for f in live.glob("*.py"):
        g = dest / f.name
        if g.exists() and g.read_bytes() == f.read_bytes():
            st = f.stat()
            os.utime(g, ns=(st.st_atime_ns, st.st_mtime_ns))


def run_timed(code: str, src: Path, *args: str) -> tuple[float, float, str]:
    """(wall s, max RSS MiB, stdout) of `python -c code args` with PYTHONPATH=src."""
    env = dict(os.environ, PYTHONPATH=str(src), MPLBACKEND="Agg")
    before = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    t0 = time.perf_counter()
    p = subprocess.run([PY, "-c", code, *args], env=env, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if p.returncode != 0:
        raise RuntimeError(p.stderr[-3000:])
    rss = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    return wall, max(rss, before) / 1024.0, p.stdout


# ------------------------------------------------------------------------------------ figures

FIG_BASE = """
import sys
from pathlib import Path
from sweep import io
out = Path(sys.argv[2])
for nb in ("halt_time", "frequency_ramps", "roll_slip", "cost"):
    io.run_notebook(Path(sys.argv[3]) / f"{nb}.ipynb", sys.argv[1], out / f"{nb}.png", out / f"{nb}.ipynb")
"""
FIG_NEW = """
import sys
from pathlib import Path
from sweep import notebooks
out = Path(sys.argv[2])
nbs = ("halt_time", "frequency_ramps", "roll_slip", "cost")
notebooks.run_notebooks([Path(sys.argv[3]) / f"{nb}.ipynb" for nb in nbs], sys.argv[1],
                        [out / f"{nb}.png" for nb in nbs], [out / f"{nb}.ipynb" for nb in nbs])
"""


def figures(base: Path, rounds: int) -> None:
    cube = ROOT / "results" / "tiny" / "cube.nc"
    if not cube.exists():
        subprocess.run([PY, str(ROOT / "run.py"), "sweep", "--configfile", "config/tiny.yaml"], check=True, cwd=ROOT)
    print(f"figures: 4 notebooks on {cube.relative_to(ROOT)}")
    rows = []
    for r in range(rounds):
        for label, code, tree in (("before (a kernel each)", FIG_BASE, base), ("after (one process)", FIG_NEW, ROOT)):
            out = OUT / "figures" / label.split()[0]
            wall, rss, _ = run_timed(code, tree / "src", str(cube), str(out), str(tree / "workflow" / "notebooks"))
            rows.append((label, wall))
            print(f"  round {r + 1}: {label:24s} {wall:6.2f} s")
    b = min(w for lbl, w in rows if lbl.startswith("before"))
    a = min(w for lbl, w in rows if lbl.startswith("after"))
    print(f"  best of {rounds}: before {b:.2f} s, after {a:.2f} s, ratio after/before {a / b:.2f}")


# ------------------------------------------------------------------------------------- gather

def million_settings(n_files: int):
    import yaml

    from sweep import grid

    cfg = yaml.safe_load((ROOT / "config" / "million.yaml").read_text())
    if n_files <= 2000:
        cfg["grid"]["mu_d"] = cfg["grid"]["mu_d"][:1]
    if n_files <= 200:
        cfg["grid"]["k1"] = cfg["grid"]["k1"][:1]
    cfg["outputs"] = {"notebooks": []}
    return grid.normalize(cfg, check_scenes=False)


def synthetic_chunks(settings: dict) -> list[Path]:
    """The plan's chunk files, written from templates with random values (cached)."""
    import netCDF4
    import numpy as np

    from sweep import axes, chunkfiles, chunking, outcomes, outputs

    plan = chunking.plan_chunks(settings)
    cdir = OUT / "chunks"
    cdir.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(52)
    templates: dict[int, Path] = {}
    raw: dict[int, dict] = {}
    n_levels = len(settings["levels"])
    paths, t0, made = [], time.perf_counter(), 0
    for cid, chunk in plan.items():
        path = cdir / f"{cid}.nc"
        paths.append(path)
        if path.exists():
            continue
        k = len(chunk.points)
        if k not in templates:
            summaries = []
            for _ in range(k):
                s = outputs.empty_summary(n_levels, outcomes.HALTED, float(rng.uniform(0.01, 1)))
                for key, v in list(s.items()):
                    if isinstance(v, float):
                        s[key] = float(rng.uniform(0, 10))
                for lv in s["levels"]:
                    for key in lv:
                        if key != "inclination":
                            lv[key] = float(rng.uniform(0, 10))
                for key in s["dissipation"]:
                    s["dissipation"][key] = float(rng.uniform(0, 1))
                for key in ("n_steps", "n_rejected", "n_rhs", "n_events", "n_transitions", "n_stick", "n_impacts"):
                    if key in s:
                        s[key] = int(rng.integers(0, 10 ** 6))
                summaries.append(s)
            templates[k] = OUT / f"template-{k}.nc"
            chunkfiles.write_chunk(chunk, summaries, templates[k])
        if k not in raw:   # the template's values, read once: a file's checksum is computed, not read back
            with netCDF4.Dataset(templates[k], "r") as nc:
                nc.set_auto_maskandscale(False)
                raw[k] = {name: np.asarray(v[...]) for name, v in nc.variables.items()}
        tmp = path.with_suffix(".tmp")
        shutil.copyfile(templates[k], tmp)
        pts = np.array(chunk.points, dtype=np.float64)
        arrays = dict(raw[k], **{a: pts[:, i] for i, a in enumerate(axes.AXES)})
        with netCDF4.Dataset(tmp, "a") as nc:
            for i, a in enumerate(axes.AXES):
                nc.variables[a][:] = pts[:, i]
            nc.setncattr("sweep_chunk_id", chunk.id)
            nc.setncattr("sweep_chunk_spec", chunk.spec_json)
            nc.setncattr("sweep_checksum", chunkfiles.checksum_of(arrays))
        os.replace(tmp, path)
        made += 1
        if made % 2000 == 0:
            print(f"    wrote {made} synthetic chunk files ({time.perf_counter() - t0:.0f} s)", flush=True)
    return paths


GATHER = """
import json, sys, time
try:                                  # this tree
    from sweep.gather import gather
except ImportError:                   # the base (before the gather had a module of its own)
    from sweep.io import gather
settings = json.loads(open(sys.argv[1]).read())
paths = open(sys.argv[2]).read().split()
t0 = time.perf_counter()
kw = {"workers": int(sys.argv[4])} if sys.argv[4] != "-" else {}
gather(paths, settings, sys.argv[3], **kw)
hwm = [l for l in open("/proc/self/status") if l.startswith("VmHWM")][0].split()[1]
print(int(hwm) / 1024, time.perf_counter() - t0)
"""


def gather(base: Path, sizes: list[int], before_max: int) -> None:
    print("gather: synthetic chunk files of config/million.yaml's grid (41 or 59 scenes each)")
    for n in sizes:
        settings = million_settings(n)
        paths = synthetic_chunks(settings)
        sfile, pfile = OUT / f"settings-{n}.json", OUT / f"paths-{n}.txt"
        sfile.write_text(json.dumps(settings))
        pfile.write_text("\n".join(map(str, paths)))
        res = {}
        for label, tree in (("after", ROOT), ("before", base)):
            if label == "before" and len(paths) > before_max:
                continue
            cube = OUT / f"cube-{label}-{n}.nc"
            wall, rss, out = run_timed(GATHER, tree / "src", str(sfile), str(pfile), str(cube),
                                       "2" if label == "after" else "-")
            hwm, inner = (float(x) for x in out.split()[-2:])
            res[label] = (wall, inner, rss, hwm)
            cube.unlink(missing_ok=True)
        line = f"  {len(paths):6d} files:"
        for label, (wall, inner, rss, hwm) in res.items():
            line += (f" {label} {wall:7.1f} s ({1000 * inner / len(paths):.1f} ms/file in the gather; peak memory "
                     f"{hwm:.0f} MiB in the gathering process, {rss:.0f} MiB in any process so far);")
        if len(res) == 2:
            line += f" ratio after/before {res['after'][0] / res['before'][0]:.2f}"
        print(line, flush=True)


# -------------------------------------------------------------------------------------- sweep

def sweep(base: Path) -> None:
    import xarray as xr

    print("sweep: the warm default sweep (each tree's own config/config.yaml) with -j2")
    for label, tree in (("before", base), ("after", ROOT)):
        wd = OUT / f"sweep-{label}"
        shutil.rmtree(wd, ignore_errors=True)
        wd.mkdir(parents=True)
        shutil.copy2(tree / "Snakefile", wd / "Snakefile")
        for d in ("workflow", "config"):
            shutil.copytree(tree / d, wd / d)
        env = dict(os.environ, PYTHONPATH=str(tree / "src"))
        env["PATH"] = f"{Path(PY).parent}{os.pathsep}{env.get('PATH', '')}"
        t0 = time.perf_counter()
        p = subprocess.run([PY, "-m", "snakemake", "-j2", "--directory", str(wd), "--snakefile", str(wd / "Snakefile")],
                           cwd=wd, env=env, capture_output=True, text=True)
        wall = time.perf_counter() - t0
        if p.returncode != 0:
            raise RuntimeError(p.stdout[-3000:] + p.stderr[-3000:])
        log = p.stdout + p.stderr
        with xr.open_dataset(wd / "results" / "default" / "cube.nc") as c:
            scenes = float(c.wall_time.sum())
        jobs = job_times(log)
        gather_s = sum(jobs.get("gather", []))
        fig_s = sum(jobs.get("notebook", [])) / min(2, max(1, len(jobs.get("notebook", []))))
        ideal = scenes / 2 + gather_s + fig_s
        print(f"  {label:6s}: wall {wall:6.1f} s; scenes' integration {scenes:.1f} s CPU (/2 = {scenes / 2:.1f} s); "
              f"gather {gather_s:.1f} s; figures {fig_s:.1f} s; ideal {ideal:.1f} s; wall/ideal {wall / ideal:.2f}; "
              f"wall/(integration/2) {wall / (scenes / 2):.2f}; chunk jobs {len(jobs.get('simulate_chunk', []))}",
              flush=True)


def job_times(log: str) -> dict[str, list[float]]:
    """Per rule, the durations of its jobs from Snakemake's console (start and 'Finished' stamps)."""
    import datetime as dt

    stamp = None
    start: dict[str, tuple[str, dt.datetime]] = {}
    rule = None
    out: dict[str, list[float]] = {}
    for line in log.splitlines():
        m = re.match(r"^\[(\w{3} \w{3} +\d+ \d\d:\d\d:\d\d \d{4})\]", line)
        if m:
            stamp = dt.datetime.strptime(m.group(1), "%a %b %d %H:%M:%S %Y")
            continue
        m = re.match(r"^(?:local)?rule (\w+):", line)
        if m:
            rule = m.group(1)
            continue
        m = re.match(r"^\s+jobid: (\d+)", line)
        if m and rule:
            start[m.group(1)] = (rule, stamp)
            rule = None
            continue
        m = re.match(r"^Finished jobid: (\d+)", line)
        if m and m.group(1) in start and stamp is not None:
            r, t0 = start.pop(m.group(1))
            out.setdefault(r, []).append((stamp - t0).total_seconds())
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--parts", default="figures,gather,sweep")
    ap.add_argument("--base", default="746a2c3", help="the commit to compare with (before issue #52)")
    ap.add_argument("--gather-sizes", default="200,2000,20000")
    ap.add_argument("--before-max", type=int, default=2000)
    ap.add_argument("--rounds", type=int, default=2, help="alternated rounds of the figures part")
    args = ap.parse_args()
    sys.path.insert(0, str(ROOT / "src"))
    OUT.mkdir(parents=True, exist_ok=True)
    base = base_tree(args.base)
    head = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"], capture_output=True,
                          text=True).stdout.strip()
    print(f"this tree: {head} (+ working tree); base: {args.base}; {os.cpu_count()} CPUs, load {os.getloadavg()[0]:.1f}")
    parts = args.parts.split(",")
    if "figures" in parts:
        figures(base, args.rounds)
    if "gather" in parts:
        gather(base, [int(x) for x in args.gather_sizes.split(",")], args.before_max)
    if "sweep" in parts:
        sweep(base)


if __name__ == "__main__":
    main()
