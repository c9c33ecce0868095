#!/usr/bin/env python3
"""Front door: set up the environment on first use, then run the sweep or the tests.

    python3 run.py sweep [snakemake args...]   # default sweep -> results/default/{cube.nc,figures/}
    python3 run.py test  [pytest args...]      # the fast tests (~2-3 min on 2 cores)
    python3 run.py test --all [pytest args...] # the whole test suite (what CI runs, ~9-11 min)
                                               # (tests named by path, -k or -m run whatever their tier)
    python3 run.py scene FILE.yaml [...]       # one scene (same as `python -m sweep scene ...`)
    python3 run.py bench [...]                 # work-precision benchmark (benchmarks/work_precision.py)

Needs only Python >= 3.11. The first call creates `.venv/` beside this file and installs the pinned
packages of `requirements.lock` plus this package (editable), one console line per set-up step
(pip's own output goes to `.venv/setup.log`); later calls reuse it and reinstall only when the
lock file changes (its SHA-256 is stamped in `.venv/.lock-sha256`).

Paths on the command line are taken relative to the directory you run it from, wherever run.py
is. `sweep` runs `python -m sweep.frontdoor` (Snakemake with a progress line, results/<name>/ per
config in the project, clean Ctrl-C; see docs/pipeline.md); the other commands run their tool
directly. Each replaces this process (exec), so a Ctrl-C is handled by the tool alone.
"""
from __future__ import annotations

import hashlib
import os
import re
import shlex
import subprocess
import sys
import venv
from pathlib import Path

ROOT = Path(__file__).resolve().parent
VENV = ROOT / ".venv"
LOCK = ROOT / "requirements.lock"
STAMP = VENV / ".lock-sha256"
SETUP_LOG = VENV / "setup.log"
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
    """What the set-up installs, said before the pip run."""
    pins = dict(re.findall(r"^([A-Za-z0-9_.-]+)==(\S+)", lock_text, flags=re.M))
    named = ", ".join(f"{k} {pins[k]}" for k in KEY_PACKAGES if k in pins)
    what = "first run: installing" if fresh else "requirements.lock or pyproject.toml changed: installing"
    return (f"run.py: {what} the {len(pins)} pinned packages of requirements.lock ({named}, ...) "
            f"and this package into {VENV.name}/; about 1-2 min, once (pip's output: {SETUP_LOG.relative_to(ROOT)})")


def _clock(seconds: float) -> str:
    s = int(round(seconds))
    return f"{s // 60}:{s % 60:02d}"


def _step(text: str, cmd: list[str], log) -> None:
    """Run one set-up step, its output appended to `log`; the console gets one line: `text`
    with the ticking elapsed time on a terminal, then `text ... done in T`. A failure raises
    CalledProcessError after the last lines of the log."""
    import threading
    import time

    tty = sys.stdout.isatty()
    t0 = time.monotonic()
    stop = threading.Event()

    def tick():
        while not stop.wait(1.0):
            print(f"\r\033[K{text} {_clock(time.monotonic() - t0)}", end="", flush=True)

    if tty:
        print(f"{text} 0:00", end="", flush=True)
        ticker = threading.Thread(target=tick, daemon=True)
        ticker.start()
    log.write(f"=== {text}\n=== {' '.join(cmd)}\n")
    log.flush()
    try:
        code = subprocess.run(cmd, stdout=log, stderr=subprocess.STDOUT).returncode
    finally:
        stop.set()
    took = _clock(time.monotonic() - t0)
    if code != 0:
        print(("\r\033[K" if tty else "") + f"{text} failed after {took}; the end of {SETUP_LOG}:", flush=True)
        log.flush()
        print("".join(SETUP_LOG.read_text(errors="replace").splitlines(True)[-25:]), end="", flush=True)
        raise subprocess.CalledProcessError(code, cmd)
    print(("\r\033[K" if tty else "") + f"{text} done in {took}", flush=True)


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
        print(f"run.py: set-up 1/3: creating the virtual environment {VENV.name}/ ...", end="", flush=True)
        venv.EnvBuilder(with_pip=True, clear=False).create(VENV)
        print(" done", flush=True)
    print(install_message(LOCK.read_text(), fresh), flush=True)
    pip = [str(PY), "-m", "pip", "install", "--disable-pip-version-check", "--no-input"]
    with open(SETUP_LOG, "a", encoding="utf-8") as log:
        _step(f"run.py: set-up 2/3: installing the pinned packages of {LOCK.name} ...", pip + ["-r", str(LOCK)], log)
        _step("run.py: set-up 3/3: installing this package (editable) ...", pip + ["--no-deps", "-e", str(ROOT)], log)
    STAMP.write_text(want + "\n")
    print(f"run.py: environment ready in {_clock(time.monotonic() - t0)}", flush=True)


def _absolute_paths(args: list[str], cwd: Path) -> list[str]:
    """pytest arguments naming files or folders (or node ids, `path::test`) relative to the
    user's directory, made absolute (pytest runs in the project root)."""
    out = []
    for a in args:
        head = a.split("::", 1)[0]
        if not a.startswith("-") and head and (cwd / head).exists() and not Path(head).is_absolute():
            a = str(cwd / a)
        out.append(a)
    return out


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
    cwd = Path.cwd()
    if cmd == "test":
        # `test`: the fast tier (tests not marked slow); `test --all`: every test (CI: .ci/run);
        # tests named on the command line (paths, node ids, -k, -m) run whatever their tier
        named = any(not a.startswith("-") for a in rest) or any(a.split("=", 1)[0] in ("-k", "-m") for a in rest)
        tier = ["-m", "not slow"] if "--all" not in rest and not named else []
        rest = _absolute_paths([a for a in rest if a != "--all"], cwd)
        args = [str(PY), "-m", "pytest", "-p", "no:cacheprovider", *tier, *rest]
        os.chdir(ROOT)
        # kernels not compiled yet (a fresh clone, a change of src/sweep/core): compile them first,
        # with the notice and the ticking elapsed time, rather than silently inside the first test
        try:
            subprocess.run([str(PY), "-c", "from sweep.warmup import compile_for_command; compile_for_command()"],
                           env=env, check=False)
        except KeyboardInterrupt:
            return 130
    elif cmd == "sweep":
        # -j2 unless the arguments or a --profile set jobs; paths relative to the user's
        # directory; the resume command names run.py as the user did (see sweep.frontdoor)
        env["SWEEP_COMMAND"] = " ".join(["python3", shlex.quote(sys.argv[0])])
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
