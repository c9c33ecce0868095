"""What the figure notebooks draw with: the cube opened lazily and reduced over the axes not shown,
the figure's caption, panel titles that fit, and cell maps with the axes named by parameter and unit
(AXIS_LABELS).
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from . import axes as _axes
from . import fields


# axis labels of the figures: words, symbol, unit (the sweep axes': sweep.fields)
AXIS_LABELS = {**{a.name: a.label for a in fields.AXES}, "level": "inclination level β (rad)"}


def open_cube(path: str | Path):
    """Open the cube lazily (dask arrays with the on-disk chunking)."""
    import xarray as xr

    return xr.open_dataset(path, engine="netcdf4", chunks={})


def reduce_to(da, keep: Sequence[str], how: str = "median"):
    """Reduce a cube variable over every dimension not in `keep` (NaN-skipping), computed.

    `how`: "median" | "mean" | "max" | "min". Returns an in-memory DataArray with dims `keep`.
    """
    others = [d for d in da.dims if d not in keep]
    if others:
        da = da.chunk({d: -1 for d in others}) if hasattr(da.data, "dask") else da
        da = getattr(da, how)(dim=others, skipna=True)
    return da.transpose(*keep).compute()


def figure_caption(ds, reduced: str = "median over the axes not shown") -> str:
    """What a figure of the cube `ds` shows, for its top line: the sweep's name, its number of
    scenes and the grid (values per axis), and how the maps reduce the other axes."""
    shape = " × ".join(f"{a} {ds.sizes[a]}" for a in _axes.AXES if a in ds.sizes)
    n = math.prod(ds.sizes[a] for a in _axes.AXES if a in ds.sizes)
    name = ds.attrs.get("sweep_name", "?")
    return f"sweep '{name}': {n} scenes ({shape})" + (f"; {reduced}" if reduced else "")


def panel_title(ax, text: str) -> None:
    """Set a panel's title, wrapped to lines that fit over the panel (its width less the room of a
    colour bar beside it), so the titles of side-by-side panels neither overlap nor get cut."""
    import textwrap

    from matplotlib.font_manager import FontProperties

    import matplotlib as mpl

    size = FontProperties(size=mpl.rcParams["axes.titlesize"]).get_size_in_points()
    width_pt = ax.get_position().width * ax.figure.get_figwidth() * 72.0
    # 0.45 em: a mean character of DejaVu Sans; 0.8: the room a colour bar and the labels take
    chars = max(16, int(0.8 * width_pt / (0.45 * size)))
    ax.set_title("\n".join(textwrap.wrap(text, chars)))


def _text_colour(rgba) -> str:
    """Black on light cells, white on dark ones (relative luminance of the cell colour)."""
    r, g, b = rgba[:3]
    return "k" if 0.2126 * r + 0.7152 * g + 0.0722 * b > 0.45 else "w"


def plot_map(ax, da, label: str, log: bool = False, annotate_max_cells: int = 64,
             vmin: float | None = None, vmax: float | None = None):
    """Draw a 2-D DataArray (dims (y, x)) as a cell map on a matplotlib Axes.

    Cells sit at index positions with the coordinate values as tick labels, so axes of length
    1, unevenly spaced or logarithmic values all display; NaN cells are grey. `vmin`, `vmax`
    fix the colour scale (a fraction: 0 and 1). Grids with at most `annotate_max_cells` cells
    (64: the numbers stay legible) get their values written in, black on light cells and white
    on dark ones. Axis labels name the parameter and its unit (AXIS_LABELS).
    """
    import matplotlib as mpl
    import matplotlib.colors as mcolors

    ydim, xdim = da.dims
    z = np.asarray(da.values, dtype=float)
    finite = z[np.isfinite(z)]
    if log and finite.size and (finite > 0).all():
        norm = mcolors.LogNorm(vmin=vmin or finite.min(), vmax=vmax or max(finite.max(), finite.min() * (1 + 1e-12)))
    else:
        norm = mcolors.Normalize(vmin=vmin, vmax=vmax)
    cmap = mpl.colormaps["viridis"].with_extremes(bad="0.85")
    ny, nx = z.shape
    mesh = ax.pcolormesh(np.arange(nx + 1) - 0.5, np.arange(ny + 1) - 0.5, np.ma.masked_invalid(z),
                         cmap=cmap, norm=norm, shading="flat")
    ax.set_xticks(range(nx), [f"{v:.3g}" for v in da[xdim].values], rotation=45 if nx > 6 else 0)
    ax.set_yticks(range(ny), [f"{v:.3g}" for v in da[ydim].values])
    ax.set_xlabel(AXIS_LABELS.get(xdim, xdim))
    ax.set_ylabel(AXIS_LABELS.get(ydim, ydim))
    if nx * ny <= annotate_max_cells:
        for (j, i), v in np.ndenumerate(z):
            colour = "k" if not np.isfinite(v) else _text_colour(cmap(mesh.norm(v)))
            ax.text(i, j, "NaN" if not np.isfinite(v) else f"{v:.3g}", ha="center", va="center",
                    fontsize=7, color=colour)
    ax.figure.colorbar(mesh, ax=ax, label=label)
    return mesh
