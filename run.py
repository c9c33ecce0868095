#!/usr/bin/env python3
"""Front door: set up the environment on first use, then run the sweep or the tests.

    python3 run.py sweep [snakemake args...]   # default sweep -> results/default/{cube.nc,figures/}
    python3 run.py test  [pytest args...]      # the whole test suite (what CI runs)
    python3 run.py scene FILE.yaml [...]       # one scene (same as `python -m sweep scene ...`)
    python3 run.py bench [...]                 # work-precision benchmark (benchmarks/work_precision.py)

Needs only Python >= 3.11. The first call creates `.venv/` beside this file and installs the pinned
packages of `requirements.lock` plus this package (editable); later calls reuse it and reinstall only
when the lock file changes (its SHA-256 is stamped in `.venv/.lock-sha256`).

`sweep` runs `python -m sweep.frontdoor` (Snakemake with a progress line, results/<name>/ per
config, clean Ctrl-C; see docs/pipeline.md); the other commands run their tool directly. Each
replaces this process (exec), so a Ctrl-C is handled by the tool alone.
"""
from __future__ import annotations

import hashlib
import os
import re
import subprocess
import sys
import venv
from pathlib import Path

ROOT = Path(__file__).resolve().parent
VENV = ROOT / ".venv"
LOCK = ROOT / "requirements.lock"
STAMP = VENV / ".lock-sha256"
BIN = VENV / ("Scripts" if os.name == "nt" else "bin")
PY = BIN / "python"


def _lock_hash() -> str:
    h = hashlib.sha256(LOCK.read_bytes())
    h.update((ROOT / "pyproject.toml").read_bytes())
    return h.hexdigest()


# the packages a user would recognise, named in the first-run message
KEY_PACKAGES = ("numpy", "numba", "scipy", "xarray", "netCDF4", "dask", "snakemake", "nbclient",
                "matplotlib", "pytest")


def install_message(lock_text: str, fresh: bool) -> str:
    """What the set-up installs, said before the (silent, ~1-2 min) pip run."""
    pins = dict(re.findall(r"^([A-Za-z0-9_.-]+)==(\S+)", lock_text, flags=re.M))
    named = ", ".join(f"{k} {pins[k]}" for k in KEY_PACKAGES if k in pins)
    what = "first run: installing" if fresh else "requirements.lock or pyproject.toml changed: installing"
    return (f"run.py: {what} the {len(pins)} pinned packages of requirements.lock ({named}, ...) "
            f"and this package into {VENV.name}/; about 1-2 min, once")


def ensure_env() -> None:
    if sys.version_info < (3, 11):
        sys.exit(f"run.py: Python >= 3.11 is required, this is {sys.version.split()[0]}")
    want = _lock_hash()
    if PY.exists() and STAMP.exists() and STAMP.read_text().strip() == want:
        return
    import time

    t0 = time.monotonic()
    fresh = not PY.exists()
    if fresh:
        print(f"run.py: creating the virtual environment {VENV}", flush=True)
        venv.EnvBuilder(with_pip=True, clear=False).create(VENV)
    print(install_message(LOCK.read_text(), fresh), flush=True)
    pip = [str(PY), "-m", "pip", "install", "--disable-pip-version-check", "-q"]
    subprocess.run(pip + ["-r", str(LOCK)], check=True)
    subprocess.run(pip + ["--no-deps", "-e", str(ROOT)], check=True)
    STAMP.write_text(want + "\n")
    print(f"run.py: environment ready in {time.monotonic() - t0:.0f} s", flush=True)


def main(argv: list[str]) -> int:
    if not argv or argv[0] in {"-h", "--help"}:
        print(__doc__)
        return 0
    cmd, rest = argv[0], argv[1:]
    if cmd not in {"test", "sweep", "scene", "bench"}:
        print(f"run.py: unknown command {cmd!r}; use one of: sweep, test, scene, bench", file=sys.stderr)
        return 2
    try:
        ensure_env()
    except KeyboardInterrupt:
        print("\nrun.py: set-up interrupted; run the same command again to finish it", file=sys.stderr)
        return 130
    except subprocess.CalledProcessError as exc:
        print(f"run.py: set-up failed: {' '.join(map(str, exc.cmd))} exited {exc.returncode}; "
              "fix the problem above and run the same command again", file=sys.stderr)
        return 1
    env = dict(os.environ)
    env["PATH"] = f"{BIN}{os.pathsep}{env.get('PATH', '')}"
    if cmd == "test":
        args = [str(PY), "-m", "pytest", "-p", "no:cacheprovider", *rest]
    elif cmd == "sweep":
        # -j2 unless the arguments or a --profile set jobs; see sweep.frontdoor
        args = [str(PY), "-m", "sweep.frontdoor", *rest]
    elif cmd == "scene":
        args = [str(PY), "-m", "sweep", "scene", *rest]
    elif cmd == "bench":
        args = [str(PY), str(ROOT / "benchmarks" / "work_precision.py"), *rest]
    os.chdir(ROOT)
    sys.stdout.flush()
    os.execve(args[0], args, env)   # the tool replaces run.py: its exit status, its signals


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
