"""The sweep axes by name, from the registry of inputs (sweep.fields): their order (the cube's
dimensions and a point's tuple), the outer/inner split of the chunk layout (sweep.chunking), units
(SI: m, rad, rad/s; friction coefficients dimensionless), long names, the values a config may leave
out.
"""
from __future__ import annotations

from . import fields


# the axes, their order, chunk layout, units and long names: the registry of inputs (sweep.fields)
AXES = tuple(a.name for a in fields.AXES)
OUTER_AXES = tuple(a.name for a in fields.AXES if a.outer)
INNER_AXES = tuple(a.name for a in fields.AXES if not a.outer)
AXIS_UNITS = {a.name: a.units for a in fields.AXES}
AXIS_LONG_NAMES = {a.name: a.long_name for a in fields.AXES}
# the values of an axis a config may leave out
AXIS_DEFAULTS = {a.name: list(a.default) for a in fields.AXES if a.default is not None}
