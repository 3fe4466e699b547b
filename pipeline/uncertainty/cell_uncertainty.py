"""Uncertainty of every grid cell from its points' TPU and spread, and its IHO S-44 order.

Estimator
---------
A cell's depth is the mean of its ``n`` points (:mod:`pipeline.process.grid`). Its error is
the mean of the points' errors: the *correlated* part of their TPU (navigation, attitude,
surface fit, water indices: shared by neighbouring points) does not average down, the *random*
part (timing, jitter, waves, footprint) does, by ``1/n``. The random part is taken as the larger
of the TPU's and the points' observed spread (``Grid.spread_m``, ``ddof = 1``), which guards
against an optimistic TPU and includes relief within the cell:

``sigma_v² = mean(sv_corr²) + max(mean(sv_rand²), spread²) / n``
``sigma_h² = mean(sh_corr²) + mean(sh_rand²) / n``

(one point: the TPU alone). The 95 % values and the strictest IHO order follow
:mod:`pipeline.iho` (``1.96 sigma_v``, ``2.45 sigma_h``).

Posterior sampling where it matters
-----------------------------------
:func:`select_posterior_pulses` picks at most ``k_per_cell`` pulses in the cells whose order
is marginal (TVU95 within ``margin`` of an order's allowance) or that hold flagged pulses,
at most ``max_pulses`` in all: the cost is ``n_selected x`` (seconds per pulse of
:mod:`pipeline.uncertainty.posterior`), bounded by ``max_pulses`` whatever the survey size. Their
posterior depth sigma replaces the TPU's waveform timing terms in the cell: the cell's timing
variance is scaled by ``mean(posterior var) / mean(TPU timing var)`` of the sampled pulses.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from pipeline.iho import (
    CLASSIFIED_ORDERS,
    NO_DATA,
    strictest_order,
    thu95_m,
    tvu95_m,
    tvu_allowance_m,
)
from pipeline.process.grid import Grid, grid_cell_index
from pipeline.process.grid_axes import full_shape
from pipeline.uncertainty.tpu import PointTpu

__all__ = [
    "CellUncertainty",
    "cell_index",
    "cell_uncertainty",
    "select_posterior_pulses",
]

#: TPU terms that the waveform posterior measures (the rest are geometry and navigation).
TIMING_TERMS = ("timing_surface", "timing_bottom")


@dataclass(frozen=True)
class CellUncertainty:
    """Per-cell uncertainty, shapes ``(ny, nx)`` like the grid; NaN where empty.

    Attributes
    ----------
    sigma_v_m, sigma_h_m : float64
        One-sigma vertical and per-axis horizontal uncertainty of the cell value.
    tvu95_m, thu95_m : float64
        ``1.96 sigma_v`` and ``2.45 sigma_h``.
    count : int64
        Points in the cell.
    n_posterior : int64
        Of which sampled by the posterior.
    order : int8
        Strictest IHO order met (:func:`pipeline.iho.strictest_order` codes; -1 empty).
    """

    sigma_v_m: np.ndarray
    sigma_h_m: np.ndarray
    tvu95_m: np.ndarray
    thu95_m: np.ndarray
    count: np.ndarray
    n_posterior: np.ndarray
    order: np.ndarray


def cell_index(grid: Grid, x_m: Any, y_m: Any) -> np.ndarray:
    """Flat cell index ``row * nx + col`` of points (the grid's registration); -1 outside.

    For a grid of some rows and columns (:class:`~pipeline.process.grid.Grid`'s ``rows``,
    ``cols``): the cell among those it holds, -1 outside them.
    """
    x, y = np.asarray(x_m, dtype=np.float64), np.asarray(y_m, dtype=np.float64)
    if getattr(grid, "rows", None) is not None:
        cell, inside = grid_cell_index(grid, x, y)
        return np.where(inside, cell, -1)
    w, _, _, n = grid.bounds_m
    r = grid.resolution_m
    ny, nx = grid.shape
    col = np.floor((x - w) / r).astype(np.int64)
    row = np.floor((n - y) / r).astype(np.int64)
    inside = (col >= 0) & (col < nx) & (row >= 0) & (row < ny)
    return np.where(inside, row * nx + col, -1)


def _cell_mean(cell: np.ndarray, values: np.ndarray, size: int) -> tuple[np.ndarray, np.ndarray]:
    ok = cell >= 0
    cnt = np.bincount(cell[ok], minlength=size)
    tot = np.bincount(cell[ok], weights=values[ok], minlength=size)
    return tot / np.maximum(cnt, 1), cnt


def cell_uncertainty(
    grid: Grid,
    tpu: PointTpu,
    *,
    posterior_sigma_v_m: Any = None,
    has_posterior: Any = None,
) -> CellUncertainty:
    """Uncertainty and IHO order of every cell of ``grid`` from the points' TPU.

    Parameters
    ----------
    grid : Grid
        The gridded points (its ``depth_m``, ``spread_m`` and ``count``).
    tpu : PointTpu
        TPU of the same points (``tpu.xyz_m`` places them in the cells).
    posterior_sigma_v_m : (n,) array_like, optional
        Posterior depth sigma of the points that were sampled (any value elsewhere).
    has_posterior : (n,) bool array_like, optional
        Which points were sampled.

    Returns
    -------
    CellUncertainty
    """
    ny, nx = grid.shape
    size = ny * nx
    cell = cell_index(grid, tpu.xyz_m[:, 0], tpu.xyz_m[:, 1])
    corr_v, n = _cell_mean(cell, tpu.sigma_v_correlated_m**2, size)
    rand_v, _ = _cell_mean(cell, tpu.sigma_v_random_m**2, size)
    corr_h, _ = _cell_mean(cell, tpu.sigma_h_correlated_m**2, size)
    rand_h, _ = _cell_mean(cell, tpu.sigma_h_random_m**2, size)
    n_post = np.zeros(size, dtype=np.int64)
    if has_posterior is not None:
        sampled = np.asarray(has_posterior, dtype=bool) & (cell >= 0)
        post = np.asarray(posterior_sigma_v_m, dtype=np.float64)
        timing_v = sum(tpu.terms[k][:, 2] ** 2 for k in TIMING_TERMS)
        ps, n_post = _cell_mean(np.where(sampled, cell, -1), np.where(sampled, post**2, 0.0), size)
        ts, _ = _cell_mean(np.where(sampled, cell, -1), np.where(sampled, timing_v, 0.0), size)
        all_t, _ = _cell_mean(cell, timing_v, size)
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = np.where((n_post > 0) & (ts > 0), ps / np.where(ts > 0, ts, 1.0), 1.0)
        # posterior variance in place of the timing terms (scaled to the whole cell)
        rand_v = np.maximum(rand_v + (ratio - 1.0) * all_t, 0.0)
    spread = np.nan_to_num(grid.spread_m.ravel(), nan=0.0)
    has = n > 0
    nn = np.maximum(n, 1)
    var_v = corr_v + np.maximum(rand_v, spread**2) / nn
    var_h = corr_h + rand_h / nn
    sig_v = np.where(has, np.sqrt(var_v), np.nan).reshape(ny, nx)
    sig_h = np.where(has, np.sqrt(var_h), np.nan).reshape(ny, nx)
    tvu, thu = tvu95_m(sig_v), thu95_m(sig_h)
    order = strictest_order(grid.depth_m, tvu, thu)
    return CellUncertainty(
        sigma_v_m=sig_v,
        sigma_h_m=sig_h,
        tvu95_m=tvu,
        thu95_m=thu,
        count=n.reshape(ny, nx),
        n_posterior=n_post.reshape(ny, nx),
        order=order,
    )


#: Numbers drawn at a time by :func:`uniform_at`.
RANDOM_BLOCK = 1 << 20


def uniform_at(rng: np.random.Generator, n: int, at: np.ndarray) -> np.ndarray:
    """``rng.random(n)[at]``, drawn :data:`RANDOM_BLOCK` at a time: the same numbers, bounded.

    ``at`` ``(k,)`` int64 in ``0 .. n-1``; ``rng`` moves on by ``n`` numbers, as one call.
    """
    at = np.asarray(at, dtype=np.int64)
    out = np.empty(at.size)
    order = np.argsort(at, kind="stable")
    sorted_at = at[order]
    for a in range(0, n, RANDOM_BLOCK):
        u = rng.random(min(RANDOM_BLOCK, n - a))
        lo, hi = np.searchsorted(sorted_at, [a, a + u.size])
        out[order[lo:hi]] = u[sorted_at[lo:hi] - a]
    return out


def _whole_cells(grid: Grid, cells: np.ndarray) -> tuple[int, np.ndarray]:
    """The whole grid's cell count, and its flat index of ``grid``'s ``cells``."""
    if getattr(grid, "rows", None) is None:
        ny, nx = grid.shape
        return ny * nx, cells
    ny, nx = full_shape(grid.bounds_m, grid.resolution_m)
    r, c = np.divmod(cells, grid.cols.size)
    return ny * nx, grid.rows[r] * nx + grid.cols[c]


def select_posterior_pulses(
    grid: Grid,
    cells: CellUncertainty,
    tpu: PointTpu,
    *,
    k_per_cell: int = 2,
    max_pulses: int = 2000,
    margin: float = 0.25,
    flagged: Any = None,
    seed: int = 0,
) -> np.ndarray:
    """Points whose pulses are worth a posterior: a bounded sample in the cells that matter.

    A cell matters when its TVU95 is within ``margin`` (relative) of the allowance of an order
    (the decision could flip) or when it holds a ``flagged`` point (e.g. the detector's
    LOW_SNR or MERGED). At most ``k_per_cell`` points per cell, chosen at random (seeded), and
    at most ``max_pulses`` in all (cells in random order).

    Returns
    -------
    ndarray of int64
        Indices into ``tpu`` (and the points) of the selected points, sorted.
    """
    if k_per_cell < 1 or max_pulses < 0:
        raise ValueError(
            f"`k_per_cell` must be >= 1 and `max_pulses` >= 0; got {k_per_cell}, {max_pulses}"
        )
    rng = np.random.default_rng(seed)
    ny, nx = grid.shape
    cell = cell_index(grid, tpu.xyz_m[:, 0], tpu.xyz_m[:, 1])
    depth = np.nan_to_num(grid.depth_m, nan=0.0)
    tvu = cells.tvu95_m
    marginal = np.zeros((ny, nx), dtype=bool)
    with np.errstate(invalid="ignore"):
        for name in CLASSIFIED_ORDERS:
            allow = tvu_allowance_m(depth, name)
            marginal |= np.abs(tvu - allow) <= margin * allow
    marginal &= (cells.order != NO_DATA) & (cells.count > 0)
    matter = marginal.ravel().copy()
    if flagged is not None:
        fl = np.asarray(flagged, dtype=bool) & (cell >= 0)
        matter[np.unique(cell[fl])] = True
    idx = np.flatnonzero((cell >= 0) & matter[np.maximum(cell, 0)])
    if idx.size == 0 or max_pulses == 0:
        return np.zeros(0, dtype=np.int64)
    # by cell, in random order within the cell; keep the first k of each cell
    order = np.lexsort((rng.random(idx.size), cell[idx]))
    idx, cs = idx[order], cell[idx][order]
    pos = np.arange(idx.size)
    first = np.r_[True, cs[1:] != cs[:-1]]
    rank = pos - np.maximum.accumulate(np.where(first, pos, 0))
    idx, cs = idx[rank < k_per_cell], cs[rank < k_per_cell]
    # cells in random order up to the cap: a number per cell of the whole grid, so that a
    # grid of some of its rows and columns (a blocked survey's sample) picks as it would
    prio = uniform_at(rng, *_whole_cells(grid, cs))
    idx = idx[np.argsort(prio, kind="stable")][:max_pulses]
    return np.sort(idx).astype(np.int64)
