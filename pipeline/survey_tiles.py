"""Square spatial tiles of a survey: their layout, halo, the chunks they need, grids by tile.

Layout
------
Tiles of ``run.tile_m`` (:func:`snap_tile_m`: rounded to a whole number of grid cells, at least
one) tile the grid's bounds from its north-west corner, so **every grid cell lies in exactly
one tile**: a cell's statistics (sums, counts and its median) are computed from that tile's
points alone (:class:`GridAccumulator`) and are the same whatever the tile size. A tile
``(i, j)`` (row ``i`` from the north) covers the cells ``[i k, (i + 1) k)`` by ``[j k,
(j + 1) k)``, ``k = tile_m / resolution_m``; its edges are half-open as the grid's are, and
points outside the grid are assigned to the nearest edge tile.

What runs by tile
-----------------
The grid (:func:`grid_by_tiles`, a cell's points by their own position) and ``points.laz``
(:func:`write_points_by_tiles`, a pulse's points by the pulse's position, so each pulse is
numbered whole). Processing (surface fit, refraction, classes, TPU, class 43) runs on the
whole survey in ``bathy run``, or, for a survey too large to hold, block by block: blocks are
tiles of this layout's kind (:mod:`pipeline.survey_blocks`), loaded with their halo by
:func:`chunks_meeting`, given the survey-wide figures of a sample of blocks.

Halo
----
A tile's neighbour searches reach :func:`halo_m` past its edges: the largest of the
surface fit's neighbour and land radii, the TPU's reach (its regional and local seabed planes
and the pair scatter's allowance, :func:`~pipeline.uncertainty.tpu_survey_wide.tpu_halo_m`)
and the class-43 neighbour radius (the settings that set those searches, not a constant);
processing's own reach along each beam is :func:`pipeline.process_tiles.processing_halo_m`
(a tile loader takes the larger). A tile loads
the stored chunks whose bounding box meets the tile grown by the halo
(:func:`chunks_meeting`).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from pipeline.detection_store import pulse_position_m
from pipeline.process.grid import (
    Grid,
    cell_index,
    cell_statistics,
    grid_from_statistics,
    seabed_values,
)
from pipeline.process.grid_axes import held_index

__all__ = [
    "snap_tile_m",
    "halo_m",
    "TileLayout",
    "chunks_meeting",
    "GridAccumulator",
    "tile_layout",
    "grid_by_tiles",
    "points_tile_order",
    "returns_position_m",
    "write_points_by_tiles",
]


def snap_tile_m(tile_m: float | None, resolution_m: float, extent_m: float) -> float:
    """``tile_m`` as a whole number (>= 1) of grid cells; None: one tile over ``extent_m``."""
    r = float(resolution_m)
    if tile_m is None:
        return max(1, math.ceil(extent_m / r)) * r
    return max(1, round(float(tile_m) / r)) * r


def halo_m(ctx, objects) -> float:
    """How far past a tile's edges its neighbour searches reach (m).

    Parameters
    ----------
    ctx : ProcessingContext
        Its surface-fit and TPU settings.
    objects : ObjectSettings
        The class-43 search (``process.objects``).
    """
    from pipeline.uncertainty.tpu_survey_wide import tpu_halo_m

    sf = ctx.surface_fit
    # the TPU's reach holds its gradient radius and pair separation (tpu_halo_m)
    return float(max(sf.radius_m, sf.land_radius_m, tpu_halo_m(ctx.tpu), objects.radius_m))


@dataclass(frozen=True)
class TileLayout:
    """Tiles over a grid's bounds.

    Attributes
    ----------
    bounds_m : (4,) float
        The grid's ``(W, E, S, N)`` cell edges, local frame.
    resolution_m : float
        Grid cell size.
    tile_m : float
        Tile side, a whole number of cells (:func:`snap_tile_m`).
    """

    bounds_m: np.ndarray
    resolution_m: float
    tile_m: float

    @property
    def cells_per_tile(self) -> int:
        """Grid cells along a tile's side."""
        return int(round(self.tile_m / self.resolution_m))

    @property
    def grid_shape(self) -> tuple[int, int]:
        """``(ny, nx)`` cells."""
        w, e, s, n = self.bounds_m
        r = self.resolution_m
        return int(round((n - s) / r)), int(round((e - w) / r))

    @property
    def shape(self) -> tuple[int, int]:
        """``(rows, cols)`` of tiles."""
        ny, nx = self.grid_shape
        k = self.cells_per_tile
        return -(-ny // k), -(-nx // k)

    @property
    def n_tiles(self) -> int:
        """Tiles in all."""
        return self.shape[0] * self.shape[1]

    def tile_of_xy(self, x_m: np.ndarray, y_m: np.ndarray) -> np.ndarray:
        """Tile number of each position, ``(n,)`` int64 (outside the grid: the nearest)."""
        w, _, _, n = self.bounds_m
        ny, nx = self.grid_shape
        col = np.clip(np.floor((np.asarray(x_m) - w) / self.resolution_m), 0, nx - 1)
        row = np.clip(np.floor((n - np.asarray(y_m)) / self.resolution_m), 0, ny - 1)
        k = self.cells_per_tile
        return (row.astype(np.int64) // k) * self.shape[1] + col.astype(np.int64) // k

    def box_m(self, t: int) -> np.ndarray:
        """Local ``(xmin, xmax, ymin, ymax)`` of tile ``t`` (clipped to the grid)."""
        w, e, s, n = self.bounds_m
        i, j = divmod(int(t), self.shape[1])
        return np.array(
            [
                w + j * self.tile_m,
                min(e, w + (j + 1) * self.tile_m),
                max(s, n - (i + 1) * self.tile_m),
                n - i * self.tile_m,
            ]
        )


def chunks_meeting(chunks, box_m: np.ndarray, halo: float) -> list[int]:
    """Stored chunks whose box meets ``box_m`` grown by ``halo`` on every side.

    ``chunks``: :class:`~pipeline.detection_store.ChunkSummary` of each stored chunk.
    """
    x0, x1, y0, y1 = box_m[0] - halo, box_m[1] + halo, box_m[2] - halo, box_m[3] + halo
    return [
        c.index
        for c in chunks
        if c.bbox_m is not None
        and c.bbox_m[0] <= x1
        and c.bbox_m[1] >= x0
        and c.bbox_m[2] <= y1
        and c.bbox_m[3] >= y0
    ]


class GridAccumulator:
    """A grid filled tile by tile: each tile brings every point of its own cells.

    Memory: the grid's arrays (a few per cell), never the points. Because a cell lies in one
    tile (:class:`TileLayout`), its sums, counts and median are those of all its points, so
    the grid is the one :func:`~pipeline.process.grid.grid_points` makes of all points at once
    (the points of a cell must come in the same order for the sums to match to the bit: pulse
    order, as the processing makes them).

    ``axes``: ``(rows, cols)``, only these rows and columns of the layout's grid are held
    (:mod:`pipeline.process.grid_axes`); points in the others are ignored.
    """

    def __init__(self, layout: TileLayout, origin_m, crs, statistic: str, axes=None) -> None:
        self.layout, self.axes = layout, axes
        self.origin_m, self.crs, self.statistic = origin_m, crs, statistic
        ny, nx = layout.grid_shape
        size = nx * ny if axes is None else axes[0].size * axes[1].size
        self.stats = {k: np.zeros(size) for k in ("mean", "zmean", "spread", "median", "zmedian")}
        self.stats["count"] = np.zeros(size, dtype=np.int64)

    def add(self, x_m: np.ndarray, y_m: np.ndarray, depth_m: np.ndarray, z_m: np.ndarray, tile):
        """Grid the points of tile ``tile`` (those whose cell is in it; others are ignored)."""
        lay = self.layout
        cell, inside = cell_index(x_m, y_m, lay.bounds_m, lay.resolution_m)
        ny, nx = lay.grid_shape
        k = lay.cells_per_tile
        row, col = np.divmod(cell, nx)
        mine = inside & ((row // k) * lay.shape[1] + col // k == tile)
        if self.axes is not None:
            r, r_ok = held_index(row, self.axes[0])
            c, c_ok = held_index(col, self.axes[1])
            cell, mine = r * self.axes[1].size + c, mine & r_ok & c_ok
        if not mine.any():
            return
        cells, local = np.unique(cell[mine], return_inverse=True)
        if np.any(self.stats["count"][cells] > 0):
            raise ValueError("a cell was gridded by two tiles")
        st = cell_statistics(local, depth_m[mine], z_m[mine], len(cells))
        for name, a in st.items():
            self.stats[name][cells] = a

    def grid(self) -> Grid:
        """The accumulated grid."""
        lay = self.layout
        return grid_from_statistics(
            self.stats,
            lay.bounds_m,
            lay.resolution_m,
            self.origin_m,
            self.crs,
            self.statistic,
            self.axes,
        )


def tile_layout(scene, bounds_m: np.ndarray) -> TileLayout:
    """The scene's tiles over the grid ``bounds_m`` (``run.tile_m``; None: one tile)."""
    r = scene.process.grid_resolution_m
    w, e, s, n = bounds_m
    return TileLayout(bounds_m, r, snap_tile_m(scene.run.tile_m, r, max(e - w, n - s)))


def grid_by_tiles(points, layout: TileLayout, origin_m, crs, datum_m, ps, axes=None) -> Grid:
    """:func:`~pipeline.process.grid.grid_seabed` of ``points``, accumulated tile by tile.

    ``ps``: the process settings (grid statistic). The same grid for any tile size.
    ``axes``: ``(rows, cols)``, the grid holds only these (:class:`GridAccumulator`).
    """
    xyz, depth = seabed_values(points, datum_m=datum_m)
    acc = GridAccumulator(layout, origin_m, crs, ps.grid_statistic, axes)
    tiles = layout.tile_of_xy(xyz[:, 0], xyz[:, 1])
    for t in np.unique(tiles):
        sel = tiles == t  # keeps the points' order (pulse order): the cells' sums match
        acc.add(xyz[sel, 0], xyz[sel, 1], depth[sel], xyz[sel, 2], int(t))
    grid = acc.grid()
    return grid if datum_m is None else dataclasses.replace(grid, datum_m=float(datum_m))


def returns_position_m(returns, air_index: float) -> np.ndarray:
    """:func:`~pipeline.detection_store.pulse_position_m` of ``DetectedReturns``, ``(n, 2)``."""
    return pulse_position_m(
        {
            "origin_meas_m": returns.origin_meas_m,
            "direction_meas": returns.direction_meas,
            "has_surface": returns.has_surface,
            "t_surface_s": returns.t_surface_s,
            "has_bottom": returns.has_bottom,
            "t_bottom_s": returns.t_bottom_s,
            **{
                k: getattr(returns, k)
                for k in ("has_column", "t_column_s")
                if returns.has_column is not None
            },
        },
        air_index,
    )


def points_tile_order(
    points, returns, layout: TileLayout, air_index: float
) -> tuple[np.ndarray, np.ndarray]:
    """The order :func:`write_points_by_tiles` writes ``points`` in, and where tiles start.

    A pulse's points go with the tile of its position (:func:`~pipeline.detection_store.
    pulse_position_m`), so every pulse is numbered whole; tile by tile, each tile's points in
    their own order (a stable sort by tile).

    Returns
    -------
    order : (n_points,) int64
    starts : (n_tiles_used + 1,) int64
        ``order[starts[i]:starts[i + 1]]`` are the points of the ``i``-th tile written.
    """
    pos = returns_position_m(returns, air_index)
    pulse_tile = layout.tile_of_xy(pos[:, 0], pos[:, 1])
    by_id = np.argsort(returns.pulse_id)
    row = by_id[np.searchsorted(returns.pulse_id[by_id], points.pulse_id)]
    tiles = pulse_tile[row]
    order = np.argsort(tiles, kind="stable")
    ts = tiles[order]
    starts = np.flatnonzero(np.r_[True, ts[1:] != ts[:-1], True]) if ts.size else np.zeros(1)
    return order, starts.astype(np.int64)


def write_points_by_tiles(path, points, returns, layout: TileLayout, ctx, origin_m, crs):
    """``points.laz`` appended tile by tile (:class:`~pipeline.outputs.las.LazTileWriter`).

    Returns
    -------
    path : Path
    order : (n_points,) int64
        The written order (:func:`points_tile_order`; the views write their points in it).
    """
    from pipeline.outputs.las import LazTileWriter, las_header

    ins = ctx.instrument
    order, starts = points_tile_order(points, returns, layout, ins.air_index)
    header = las_header(points.classification, points.amplitude is not None, crs, origin_m)
    with LazTileWriter(path, header, ins.amplitude_full_scale) as w:
        for i in range(starts.size - 1):
            w.write(points.select(order[starts[i] : starts[i + 1]]), returns)
    return path, order
