"""Euler's disk (Kessler & O'Reilly 2002): numba hybrid integrator and parameter sweeps."""
from importlib.metadata import PackageNotFoundError, version as _version

try:
    __version__ = _version("sweep")
except PackageNotFoundError:  # running from a source tree without installation
    __version__ = "0.0.0+unknown"

from .errors import ConfigError  # noqa: E402
from .simulate import SimulationResult, simulate  # noqa: E402
from .ensemble import simulate_batch  # noqa: E402

__all__ = ["simulate", "simulate_batch", "SimulationResult", "ConfigError", "__version__"]
