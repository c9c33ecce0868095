import copy
import math
import shutil
import sys
from pathlib import Path

import pytest

from sweep.scene import DEFAULTS

# chi of the paper's disk, eq. (4.5): sqrt((k^2+4)/4 R/g) with k^2 = 1, R = 3.755 cm, g = 9.81
CHI_PAPER = math.sqrt(1.25 * 0.03755 / 9.81)


def make_scene(**mods):
    """DEFAULTS (the paper's case) with overrides given as section__key=value."""
    cfg = copy.deepcopy(DEFAULTS)
    for k, v in mods.items():
        sec, key = k.split("__")
        cfg[sec][key] = v
    return cfg


@pytest.fixture
def scene():
    return make_scene


ROOT = Path(__file__).resolve().parents[1]


def copy_workflow(dest: Path) -> Path:
    """Snakefile, workflow/ and config/ copied to `dest` (a temporary working directory), so that
    pipeline tests never touch the real results/."""
    dest.mkdir(parents=True, exist_ok=True)
    shutil.copy2(ROOT / "Snakefile", dest / "Snakefile")
    ignore = shutil.ignore_patterns("__pycache__", "*.pyc", ".ipynb_checkpoints")
    for d in ("workflow", "config"):
        shutil.copytree(ROOT / d, dest / d, ignore=ignore)
    return dest


def scipy_peer():
    """The independent SciPy reference model (its own contact rules and event logic):
    tests.reference.scipy_driver."""
    from tests.reference import scipy_driver
    return scipy_driver


def peer_run(cfg: dict, rtol: float) -> tuple[dict, float]:
    """The SciPy peer's run of scene `cfg` at rtol (atol rtol/100; cfg's other solver settings, e.g.
    slave_tol, kept): its result dict (times in tau) and chi (s), to convert them."""
    from sweep.scene import load_scene

    c = copy.deepcopy(cfg)
    c["solver"] = {**c.get("solver", {}), "rtol": rtol, "atol": rtol * 1e-2}
    sc = load_scene(c)
    return scipy_peer().run_scipy(sc, "DOP853", rtol, rtol * 1e-2), sc.chi
