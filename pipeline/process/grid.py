"""Seabed points onto a regular grid: per-cell robust depth (median), mean, spread and count.

Registration
------------
Cell-centre (pixel, "area") registration: ``bounds_m = (W, E, S, N)`` are the outer cell
*edges* in the local frame, the cell ``(row, col)`` covers ``[W + col r, W + (col + 1) r)``
by ``(N - (row + 1) r, N - row r]``, and its value is given at its centre. Row 0 is the
northern row (GeoTIFF order). Points outside the bounds, or on the east/south outer edges, are
left out. Default bounds snap the points' extent outwards to multiples of the resolution in
*world* coordinates (local + origin), so grids of different runs share cell edges.

Statistics per cell: the cell depth ``depth_m`` (by default the median of the cell's points,
``statistic="median"``), the mean and the median depth, spread (sample standard deviation,
``ddof=1``; NaN where fewer than 2 points), count, and the elevation ``z_m`` by the same
statistic as ``depth_m``. Empty cells hold NaN (written as nodata by
:mod:`pipeline.outputs.raster`).

Why the median: a per-cell mean takes every outlier (a water-column or noise return that
passed classification, a photon-counting false bottom) at full weight, so one 30 m blunder
among ten soundings moves the cell by 3 m. The median's breakdown point is 50 %: the cell
holds while fewer than half its points are outliers (the simplest of the robust cell
estimators; CUBE, Calder & Mayer 2003, "Automatic processing of high-rate, high-density
multibeam echosounder data", G3 4(6), tracks several depth hypotheses per node instead).

Why the median is not the whole story: it also erases a real shoal smaller than a cell (an IHO
cube's soundings are a minority of its cell). The hydrographic answer is the *designated
sounding* (Smith, Alexander & Armstrong 2002, "The navigation surface: a multipurpose
bathymetric database", Int. Hydrogr. Rev. 3(2); NOAA HSSD: a feature's grid node carries its
least depth): :func:`designate_objects` sets the cells that hold submerged-object soundings
(class 43, :mod:`pipeline.process.objects`) to the least depth among them, so a feature that
processing found survives in the grid while outliers of the class-40 soundings still meet the
median.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import pyproj
from affine import Affine

from pipeline.process.classify import BATHYMETRIC_POINT, SUBMERGED_OBJECT
from pipeline.process.grid_axes import full_shape, held_cells, row_col
from pipeline.process.returns import Points

__all__ = [
    "Grid",
    "GRID_STATISTICS",
    "cell_centres_m",
    "cell_index",
    "cell_statistics",
    "designate_objects",
    "grid_cell_index",
    "grid_from_statistics",
    "grid_points",
    "grid_seabed",
    "require_whole",
    "seabed_values",
    "snap_bounds_m",
]

#: statistics a cell's depth can take (:func:`grid_points`)
GRID_STATISTICS = ("median", "mean")


@dataclass(frozen=True)
class Grid:
    """A regular grid of seabed statistics in the local frame, with its CRS and origin.

    Attributes
    ----------
    depth_m, median_depth_m, mean_depth_m, spread_m, z_m : (ny, nx) float64
        Cell depth (by ``statistic``), median depth, mean depth, depth standard deviation and
        elevation (by ``statistic``); NaN where empty (and ``spread_m`` where fewer than 2
        points).
    count : (ny, nx) int64
        Points per cell.
    x_m : (nx,) float64
        Local x of the cell centres, increasing (east).
    y_m : (ny,) float64
        Local y of the cell centres, decreasing (row 0 is north).
    resolution_m : float
        Cell size.
    bounds_m : (4,) float64
        ``(W, E, S, N)`` cell edges in the local frame.
    origin_m : (3,) float64
        World coordinates ``(easting, northing, height)`` of the local origin.
    crs : pyproj.CRS or None
        Horizontal CRS of the world coordinates.
    datum_m : float or None
        Local z of the water level the depths are below (:mod:`pipeline.process.datum`); None:
        the depths are the points' own ``depth_m`` (below the local fitted surface).
    statistic : str
        What ``depth_m`` and ``z_m`` are per cell: ``"median"`` or ``"mean"``.
    designated : (ny, nx) bool or None
        Cells whose ``depth_m`` and ``z_m`` are a designated sounding, the least depth of the
        submerged objects in them (:func:`designate_objects`); None: none designated.
    rows, cols : (ny,), (nx,) int64 or None
        The rows and columns of the grid of ``bounds_m`` this grid holds, increasing
        (:mod:`pipeline.process.grid_axes`: a blocked survey's sample); ``x_m`` and ``y_m``
        are theirs. None: every one (the grid of the whole bounds). A grid of some rows and
        columns has no affine transform and is never written to a file.
    """

    depth_m: np.ndarray
    median_depth_m: np.ndarray
    spread_m: np.ndarray
    z_m: np.ndarray
    count: np.ndarray
    x_m: np.ndarray
    y_m: np.ndarray
    resolution_m: float
    bounds_m: np.ndarray
    origin_m: np.ndarray
    crs: pyproj.CRS | None
    datum_m: float | None = None
    mean_depth_m: np.ndarray | None = None
    statistic: str = "median"
    designated: np.ndarray | None = None
    rows: np.ndarray | None = None
    cols: np.ndarray | None = None

    @property
    def shape(self) -> tuple[int, int]:
        """``(ny, nx)``."""
        return self.depth_m.shape

    @property
    def local_transform(self) -> Affine:
        """Affine from (col, row) of cell corners to local (x, y)."""
        require_whole(self)
        w, _, _, n = self.bounds_m
        return Affine(self.resolution_m, 0.0, w, 0.0, -self.resolution_m, n)

    @property
    def transform(self) -> Affine:
        """Affine from (col, row) of cell corners to world (easting, northing)."""
        require_whole(self)
        w, _, _, n = self.bounds_m
        e0, n0 = self.origin_m[0], self.origin_m[1]
        return Affine(self.resolution_m, 0.0, w + e0, 0.0, -self.resolution_m, n + n0)


def require_whole(grid, what: str = "an affine transform") -> None:
    """Refuse a grid of some rows and columns ``what`` needs the whole grid for.

    Raises
    ------
    ValueError
        ``grid`` holds some rows and columns only (:class:`Grid`'s ``rows``, ``cols``).
    """
    if getattr(grid, "rows", None) is not None or getattr(grid, "cols", None) is not None:
        raise ValueError(f"a grid of some rows and columns cannot give {what}")


def snap_bounds_m(
    x_m: np.ndarray, y_m: np.ndarray, resolution_m: float, origin_m: Sequence[float] = (0, 0, 0)
) -> np.ndarray:
    """Bounds ``(W, E, S, N)`` enclosing the points, snapped outwards in world coordinates.

    The east and north edges are one cell past the last multiple at or below the maximum, so
    a point exactly on a multiple still falls inside (the grid is half-open on the east/south).
    """
    e0, n0 = float(origin_m[0]), float(origin_m[1])
    r = resolution_m
    w = np.floor((np.min(x_m) + e0) / r) * r - e0
    e = (np.floor((np.max(x_m) + e0) / r) + 1.0) * r - e0
    s = (np.ceil((np.min(y_m) + n0) / r) - 1.0) * r - n0
    n = np.ceil((np.max(y_m) + n0) / r) * r - n0
    return np.array([w, e, s, n], dtype=np.float64)


def grid_points(
    x_m: Any,
    y_m: Any,
    depth_m: Any,
    z_m: Any = None,
    *,
    resolution_m: float,
    bounds_m: Sequence[float] | None = None,
    origin_m: Sequence[float] = (0.0, 0.0, 0.0),
    crs: Any = None,
    statistic: str = "median",
) -> Grid:
    """Grid points by cell: median, mean, spread and count of ``depth_m``; ``z_m`` likewise.

    Parameters
    ----------
    x_m, y_m, depth_m : array_like, (n,)
        Local coordinates and depths of the points.
    z_m : array_like, (n,), optional
        Elevations (default ``-depth_m``).
    resolution_m : float
        Cell size (> 0).
    bounds_m : (W, E, S, N), optional
        Cell edges in the local frame; whole multiples of ``resolution_m`` apart. Default:
        :func:`snap_bounds_m` of the points.
    origin_m : (easting, northing, height)
        World coordinates of the local origin, carried along for the writers.
    crs : optional
        Anything ``pyproj.CRS.from_user_input`` accepts; carried along.
    statistic : {"median", "mean"}
        The cell's ``depth_m`` and ``z_m``: the median (robust to outliers, the default) or
        the mean of its points.

    Returns
    -------
    Grid
    """
    if statistic not in GRID_STATISTICS:
        raise ValueError(f"`statistic` must be one of {GRID_STATISTICS}; got {statistic!r}")
    x, y, v = (np.asarray(a, dtype=np.float64).ravel() for a in (x_m, y_m, depth_m))
    z = -v if z_m is None else np.asarray(z_m, dtype=np.float64).ravel()
    if not (x.shape == y.shape == v.shape == z.shape):
        raise ValueError("`x_m`, `y_m`, `depth_m` and `z_m` must have the same length")
    if not all(np.all(np.isfinite(a)) for a in (x, y, v, z)):
        raise ValueError("point coordinates and values must be finite")
    r = float(resolution_m)
    if not (np.isfinite(r) and r > 0):
        raise ValueError(f"`resolution_m` must be finite and > 0; got {resolution_m!r}")
    origin = np.asarray(origin_m, dtype=np.float64)
    if origin.shape != (3,):
        raise ValueError(f"`origin_m` must be (easting, northing, height); got {origin_m!r}")
    if bounds_m is None:
        if x.size == 0:
            raise ValueError("no points to grid: give `bounds_m`")
        bounds = snap_bounds_m(x, y, r, origin)
    else:
        bounds = np.asarray(bounds_m, dtype=np.float64)
    w, e, s, n = bounds
    nx_f, ny_f = (e - w) / r, (n - s) / r
    nx, ny = int(round(nx_f)), int(round(ny_f))
    if nx < 1 or ny < 1 or abs(nx_f - nx) > 1e-6 or abs(ny_f - ny) > 1e-6:
        raise ValueError(
            f"`bounds_m` {tuple(bounds)} must span whole cells of {r} m (W < E, S < N)"
        )

    cell, inside = cell_index(x, y, bounds, r)
    st = cell_statistics(cell[inside], v[inside], z[inside], nx * ny)

    return grid_from_statistics(st, bounds, r, origin, crs, statistic)


def cell_centres_m(bounds_m, resolution_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Local ``x_m (nx,)`` (east) and ``y_m (ny,)`` (south from row 0) of the cell centres."""
    w, e, s, n = bounds_m
    r = resolution_m
    nx, ny = int(round((e - w) / r)), int(round((n - s) / r))
    return w + (np.arange(nx) + 0.5) * r, n - (np.arange(ny) + 0.5) * r


def grid_from_statistics(
    st: dict,
    bounds_m: np.ndarray,
    resolution_m: float,
    origin_m,
    crs,
    statistic: str,
    axes: tuple[np.ndarray, np.ndarray] | None = None,
) -> Grid:
    """The :class:`Grid` of :func:`cell_statistics` over every cell of ``bounds_m``.

    ``axes``: ``(rows, cols)``, the grid holds only these (:class:`Grid`'s ``rows, cols``);
    ``st`` is then over their ``rows.size * cols.size`` cells.
    """
    r = resolution_m
    x_m, y_m = cell_centres_m(bounds_m, r)
    if axes is not None:
        x_m, y_m = x_m[axes[1]], y_m[axes[0]]
    nx, ny = x_m.size, y_m.size

    def shaped(a, ok):
        return np.where(ok, a, np.nan).reshape(ny, nx)

    count, has = st["count"], st["count"] > 0
    robust = statistic == "median"
    return Grid(
        depth_m=shaped(st["median"] if robust else st["mean"], has),
        median_depth_m=shaped(st["median"], has),
        mean_depth_m=shaped(st["mean"], has),
        statistic=statistic,
        spread_m=shaped(st["spread"], count >= 2),
        z_m=shaped(st["zmedian"] if robust else st["zmean"], has),
        count=count.reshape(ny, nx).astype(np.int64),
        x_m=x_m,
        y_m=y_m,
        resolution_m=r,
        bounds_m=np.asarray(bounds_m, dtype=np.float64),
        origin_m=np.asarray(origin_m, dtype=np.float64),
        crs=None if crs is None else pyproj.CRS.from_user_input(crs),
        rows=None if axes is None else np.asarray(axes[0], dtype=np.int64),
        cols=None if axes is None else np.asarray(axes[1], dtype=np.int64),
    )


def grid_cell_index(grid: Grid, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Flat cell of each point in ``grid`` (``row * nx + col`` of its arrays) and if inside.

    For a grid of some rows and columns, inside means in a cell it holds.
    """
    if getattr(grid, "rows", None) is None:
        return cell_index(x, y, grid.bounds_m, grid.resolution_m)
    return held_cells(x, y, grid.bounds_m, grid.resolution_m, grid.rows, grid.cols)


def cell_index(
    x: np.ndarray, y: np.ndarray, bounds_m: np.ndarray, resolution_m: float
) -> tuple[np.ndarray, np.ndarray]:
    """Flat cell ``row * nx + col`` of each point, ``(n,)`` int64, and whether it is inside."""
    row, col, inside = row_col(x, y, bounds_m, resolution_m)
    return row * full_shape(bounds_m, resolution_m)[1] + col, inside


def cell_statistics(cell: np.ndarray, v: np.ndarray, z: np.ndarray, size: int) -> dict:
    """Per-cell count, mean, spread and median of ``v`` (and mean, median of ``z``), ``(size,)``.

    ``cell`` in ``0 .. size-1``; cells without a point hold the fallback values of
    :func:`grid_points` (masked there). A cell's figures depend only on its own points (and
    their order, for the sums): gridding tile by tile gives the same cells.
    """
    count = np.bincount(cell, minlength=size)
    cnt = np.where(count > 0, count, 1)
    mean = np.bincount(cell, weights=v, minlength=size) / cnt
    zmean = np.bincount(cell, weights=z, minlength=size) / cnt
    ss = np.bincount(cell, weights=(v - mean[cell]) ** 2, minlength=size)
    start = np.concatenate([[0], np.cumsum(count)[:-1]])
    return {
        "count": count,
        "mean": mean,
        "zmean": zmean,
        "spread": np.sqrt(ss / np.maximum(count - 1, 1)),
        "median": _cell_median(v, cell, start, cnt, mean),
        "zmedian": _cell_median(z, cell, start, cnt, zmean),
    }


def _cell_median(v, cell, start, cnt, fallback):
    """Per-cell median of ``v`` (cells sorted by ``cell``); ``fallback`` where no point."""
    if not len(v):
        return fallback
    vs = v[np.lexsort((v, cell))]
    last = len(vs) - 1
    lo = vs[np.minimum(start + (cnt - 1) // 2, last)]
    hi = vs[np.minimum(start + cnt // 2, last)]
    return 0.5 * (lo + hi)


def grid_seabed(
    points: Points,
    resolution_m: float,
    *,
    bounds_m: Sequence[float] | None = None,
    origin_m: Sequence[float] = (0.0, 0.0, 0.0),
    crs: Any = None,
    classes: Sequence[int] = (BATHYMETRIC_POINT, SUBMERGED_OBJECT),
    datum_m: float | None = None,
    statistic: str = "median",
) -> Grid:
    """Grid the points of ``classes`` (default 40 and 43, the seabed soundings).

    By :func:`grid_points`.

    With ``datum_m`` (local z of the survey's mean water level, :mod:`pipeline.process.datum`)
    the gridded depth is ``datum_m − z``: one reference for the whole grid. Without it, the
    points' own ``depth_m`` (below the local fitted surface, which under waves carries the
    wave heights).
    """
    xyz, depth = seabed_values(points, classes, datum_m)
    grid = grid_points(
        xyz[:, 0],
        xyz[:, 1],
        depth,
        xyz[:, 2],
        resolution_m=resolution_m,
        bounds_m=bounds_m,
        origin_m=origin_m,
        crs=crs,
        statistic=statistic,
    )
    return grid if datum_m is None else dataclasses.replace(grid, datum_m=float(datum_m))


def seabed_values(
    points: Points,
    classes: Sequence[int] = (BATHYMETRIC_POINT, SUBMERGED_OBJECT),
    datum_m: float | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """``(xyz_m (m, 3), depth_m (m,))`` of the points of ``classes``, as gridded.

    As :func:`grid_seabed` grids them: depth below ``datum_m``, else the points' own.
    """
    keep = np.isin(points.classification, np.asarray(classes, dtype=np.uint8))
    xyz = points.xyz_m[keep]
    depth = points.depth_m[keep] if datum_m is None else float(datum_m) - xyz[:, 2]
    return xyz, depth


def designate_objects(grid: Grid, points: Points, datum_m: float | None = None) -> Grid:
    """Cells holding submerged-object soundings (class 43) take the least depth among them.

    Designated soundings (module docstring): ``depth_m`` (and ``z_m``) of such a cell become
    the shoalest class-43 point's depth (its highest elevation), and ``designated`` marks the
    cell; ``median_depth_m``, ``mean_depth_m``, ``spread_m`` and ``count`` keep every
    sounding's statistics.

    Parameters
    ----------
    grid : Grid
    points : Points
        Classified points (``xyz_m``, ``depth_m``, ``classification``).
    datum_m : float, optional
        As :func:`grid_seabed`: depths below this local z; default the points' ``depth_m``.

    Returns
    -------
    Grid
        ``grid`` itself when no class-43 point falls in it.
    """
    obj = points.classification == SUBMERGED_OBJECT
    xyz = points.xyz_m[obj]
    ny, nx = grid.shape
    cell, inside = grid_cell_index(grid, xyz[:, 0], xyz[:, 1])
    if not inside.any():
        return grid
    z = xyz[inside, 2]
    depth = points.depth_m[obj][inside] if datum_m is None else float(datum_m) - z
    cell = cell[inside]
    shoal = np.full(nx * ny, np.inf)
    np.minimum.at(shoal, cell, depth)
    high = np.full(nx * ny, -np.inf)
    np.maximum.at(high, cell, z)
    has = np.isfinite(shoal).reshape(ny, nx)
    return dataclasses.replace(
        grid,
        depth_m=np.where(has, shoal.reshape(ny, nx), grid.depth_m),
        z_m=np.where(has, high.reshape(ny, nx), grid.z_m),
        designated=has,
    )
