"""How much of the requested survey area the soundings cover."""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["area_cells", "area_coverage"]


def area_cells(
    xy_m: Any, area_m: tuple[float, float, float, float], cell_m: float
) -> tuple[np.ndarray, int]:
    """The ``cell_m`` cells of ``area_m`` = (xmin, xmax, ymin, ymax) that hold a point.

    Returns
    -------
    cells : (k,) int64
        Row-major index of the cell of each point inside the area (repeats kept).
    n_cells : int
        Cells of the area.
    """
    xmin, xmax, ymin, ymax = (float(v) for v in area_m)
    nx = max(1, int(np.ceil((xmax - xmin) / cell_m)))
    ny = max(1, int(np.ceil((ymax - ymin) / cell_m)))
    xy = np.asarray(xy_m, dtype=np.float64).reshape(-1, 2)
    inside = (xy[:, 0] >= xmin) & (xy[:, 0] < xmax) & (xy[:, 1] >= ymin) & (xy[:, 1] < ymax)
    i = np.minimum(((xy[inside, 0] - xmin) / cell_m).astype(np.int64), nx - 1)
    j = np.minimum(((xy[inside, 1] - ymin) / cell_m).astype(np.int64), ny - 1)
    return j * nx + i, nx * ny


def area_coverage(xy_m: Any, area_m: tuple[float, float, float, float], cell_m: float) -> float:
    """Fraction of ``area_m`` = (xmin, xmax, ymin, ymax) whose ``cell_m`` cells hold a point.

    Parameters
    ----------
    xy_m : (n, 2) array_like
        Local positions of the points (any class: a survey covers where it measured).
    area_m : tuple of 4 float
        The area the flight plan was asked to cover.
    cell_m : float
        Cell size (the grid's).

    Returns
    -------
    float
        In [0, 1]; 0 for an empty area or no point in it.
    """
    cells, n_cells = area_cells(xy_m, area_m, cell_m)
    return float(np.unique(cells).size / n_cells)
