#!/usr/bin/env python3
"""Front door: set up the environment on first use, then run the sweep or the tests.

    python3 run.py sweep [snakemake args...]   # default sweep -> results/cube.nc + results/figures/
    python3 run.py test  [pytest args...]      # the whole test suite (what CI runs)
    python3 run.py scene FILE.yaml [...]       # one scene (same as `python -m sweep scene ...`)
    python3 run.py bench [...]                 # work-precision benchmark (benchmarks/work_precision.py)

Needs only Python >= 3.11. The first call creates `.venv/` beside this file and installs the pinned
packages of `requirements.lock` plus this package (editable); later calls reuse it and reinstall only
when the lock file changes (its SHA-256 is stamped in `.venv/.lock-sha256`).
"""
from __future__ import annotations

import hashlib
import os
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


def ensure_env() -> None:
    if sys.version_info < (3, 11):
        sys.exit(f"run.py: Python >= 3.11 is required, this is {sys.version.split()[0]}")
    want = _lock_hash()
    if PY.exists() and STAMP.exists() and STAMP.read_text().strip() == want:
        return
    if not PY.exists():
        print(f"run.py: creating virtual environment {VENV}", flush=True)
        venv.EnvBuilder(with_pip=True, clear=False).create(VENV)
    print("run.py: installing pinned dependencies (first run only, ~1-2 min)", flush=True)
    pip = [str(PY), "-m", "pip", "install", "--disable-pip-version-check", "-q"]
    subprocess.run(pip + ["-r", str(LOCK)], check=True)
    subprocess.run(pip + ["--no-deps", "-e", str(ROOT)], check=True)
    STAMP.write_text(want + "\n")


def main(argv: list[str]) -> int:
    if not argv or argv[0] in {"-h", "--help"}:
        print(__doc__)
        return 0
    cmd, rest = argv[0], argv[1:]
    ensure_env()
    env = dict(os.environ)
    env["PATH"] = f"{BIN}{os.pathsep}{env.get('PATH', '')}"
    if cmd == "test":
        args = [str(PY), "-m", "pytest", "-p", "no:cacheprovider", *rest]
    elif cmd == "sweep":
        args = [str(BIN / "snakemake"), "-j2", *rest]
    elif cmd == "scene":
        args = [str(PY), "-m", "sweep", "scene", *rest]
    elif cmd == "bench":
        args = [str(PY), str(ROOT / "benchmarks" / "work_precision.py"), *rest]
    else:
        print(f"run.py: unknown command {cmd!r}; use one of: sweep, test, scene, bench", file=sys.stderr)
        return 2
    return subprocess.run(args, cwd=ROOT, env=env).returncode


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
