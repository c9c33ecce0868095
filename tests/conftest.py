import copy
import math

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
