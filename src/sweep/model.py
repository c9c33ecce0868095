"""Public alias of the model equations, which live in sweep.core.model."""
from .core.model import *  # noqa: F401,F403
from .core.model import make_params  # noqa: F401
