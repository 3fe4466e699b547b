"""A grid of some rows and columns of a larger one, and where points fall in it (issue 15).

A blocked survey's sample is a few whole blocks spread over the survey
(:mod:`pipeline.survey_blocks`): gridded over the survey's bounds, its grid and its cells'
uncertainty would be dense over the whole area (a million cells and ~100 B each at 100 M
pulses), though only the sample's blocks hold soundings. Its grid holds instead the rows and
the columns that hold a point (:func:`occupied_axes`), each grown by :data:`MARGIN_CELLS`: their
crossings, the same cells with the same figures as the whole grid's, since a cell's figures
are those of its own points. The cells left out are empty in the whole grid too.

Rows count from the north edge, columns from the west edge, as
:func:`~pipeline.process.grid.cell_index` numbers them.
"""

from __future__ import annotations

import numpy as np

__all__ = ["MARGIN_CELLS", "full_shape", "row_col", "occupied_axes", "held_index", "held_cells"]

#: Rows and columns kept on each side of those holding points: what reads a cell's
#: neighbours reads one cell away (the evaluation's ring around a cube's cell,
#: :func:`pipeline.evaluate_features.cube_detection`), so a kept cell's neighbours are the
#: whole grid's.
MARGIN_CELLS = 1


def full_shape(bounds_m, resolution_m: float) -> tuple[int, int]:
    """``(ny, nx)`` cells of the grid of ``bounds_m`` ``(W, E, S, N)``."""
    w, e, s, n = bounds_m
    return int(round((n - s) / resolution_m)), int(round((e - w) / resolution_m))


def row_col(x, y, bounds_m, resolution_m: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Row, column ``(n,)`` int64 of each point in the grid of ``bounds_m``, and whether inside."""
    w, _, _, n = bounds_m
    ny, nx = full_shape(bounds_m, resolution_m)
    col = np.floor((np.asarray(x) - w) / resolution_m).astype(np.int64)
    row = np.floor((n - np.asarray(y)) / resolution_m).astype(np.int64)
    inside = (col >= 0) & (col < nx) & (row >= 0) & (row < ny)
    return row, col, inside


def occupied_axes(
    x, y, bounds_m, resolution_m: float, margin: int = MARGIN_CELLS
) -> tuple[np.ndarray, np.ndarray]:
    """The rows and the columns holding a point, grown by ``margin``, ``(k,)`` int64 increasing.

    Clipped to the grid; points outside it are ignored (as gridding ignores them).
    """
    ny, nx = full_shape(bounds_m, resolution_m)
    row, col, inside = row_col(x, y, bounds_m, resolution_m)

    def grown(idx: np.ndarray, size: int) -> np.ndarray:
        held = np.zeros(size, dtype=bool)
        used = np.unique(idx)
        for d in range(-margin, margin + 1):
            held[np.clip(used + d, 0, size - 1)] = True
        return np.flatnonzero(held).astype(np.int64)

    return grown(row[inside], ny), grown(col[inside], nx)


def held_index(idx: np.ndarray, held: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Where each of ``idx`` sits among the increasing ``held``, and whether it is there."""
    idx = np.asarray(idx, dtype=np.int64)
    if held.size == 0:
        return np.zeros(idx.shape, dtype=np.int64), np.zeros(idx.shape, dtype=bool)
    pos = np.minimum(np.searchsorted(held, idx), held.size - 1)
    return pos, held[pos] == idx


def held_cells(
    x, y, bounds_m, resolution_m: float, rows: np.ndarray, cols: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Flat cell ``row * len(cols) + col`` of each point in the grid of ``rows`` x ``cols``.

    Returns the cells ``(n,)`` int64 and whether each point is in one (inside the grid of
    ``bounds_m``, in a held row and a held column).
    """
    row, col, inside = row_col(x, y, bounds_m, resolution_m)
    r, r_ok = held_index(row, rows)
    c, c_ok = held_index(col, cols)
    return r * cols.size + c, inside & r_ok & c_ok
