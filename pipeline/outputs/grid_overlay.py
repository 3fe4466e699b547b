"""The sample's posterior cells laid over a blocked survey's grid (:mod:`.grid_tiles`)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from pipeline.process.grid_axes import held_index

__all__ = ["Overlay"]


@dataclass(frozen=True)
class Overlay:
    """Cells laid over the stored ones where posteriors ran: :meth:`GridTiles.layer`'s.

    Attributes
    ----------
    cells : CellUncertainty
        On the whole grid, or on ``rows`` x ``cols`` of it.
    rows, cols : (k,) int64 or None
        The grid's rows and columns ``cells`` holds, increasing (a blocked survey's sample:
        :class:`~pipeline.process.grid.Grid`'s ``rows``, ``cols``); None: all.
    """

    cells: Any
    rows: np.ndarray | None = None
    cols: np.ndarray | None = None

    def window(self, field: str, rows: slice, cols: slice, shape) -> tuple:
        """``(sampled (r, c) bool, values (r, c))`` of ``field`` over window ``rows, cols``.

        ``shape``: the whole grid's ``(ny, nx)``.
        """
        c = self.cells
        if self.rows is None:
            if c.order.shape != tuple(shape):
                raise ValueError(f"`overlay` has shape {c.order.shape}; the grid's {shape}")
            return c.n_posterior[rows, cols] > 0, getattr(c, field)[rows, cols]
        if (
            c.order.shape != (self.rows.size, self.cols.size)
            or (self.rows.size and self.rows[-1] >= shape[0])
            or (self.cols.size and self.cols[-1] >= shape[1])
        ):
            raise ValueError(
                f"`overlay` has shape {c.order.shape} on {self.rows.size} rows and"
                f" {self.cols.size} columns of the grid's {shape}"
            )
        r0, r1, r_step = rows.indices(shape[0])
        k0, k1, k_step = cols.indices(shape[1])
        if r_step != 1 or k_step != 1:
            raise ValueError(f"a window is a block of cells (step 1); got {rows}, {cols}")
        values = getattr(c, field)
        if values.size == 0:  # no cell held
            return np.zeros((r1 - r0, k1 - k0), dtype=bool), np.zeros((r1 - r0, k1 - k0))
        r, r_ok = held_index(np.arange(r0, r1), self.rows)
        k, k_ok = held_index(np.arange(k0, k1), self.cols)
        at = np.ix_(r, k)
        sampled = r_ok[:, None] & k_ok[None, :] & (c.n_posterior[at] > 0)
        return sampled, values[at]
