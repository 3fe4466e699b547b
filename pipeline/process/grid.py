"""Seabed points onto a regular grid: per-cell mean, median, spread and count.

Registration
------------
Cell-centre (pixel, "area") registration: ``bounds_m = (W, E, S, N)`` are the outer cell
*edges* in the local frame, the cell ``(row, col)`` covers ``[W + col r, W + (col + 1) r)``
by ``(N - (row + 1) r, N - row r]``, and its value is given at its centre. Row 0 is the
northern row (GeoTIFF order). Points outside the bounds, or on the east/south outer edges, are
left out. Default bounds snap the points' extent outwards to multiples of the resolution in
*world* coordinates (local + origin), so grids of different runs share cell edges.

Statistics per cell: mean depth, median depth, spread (sample standard deviation, ``ddof=1``;
NaN where fewer than 2 points), count, and mean elevation ``z_m``. Empty cells hold NaN (written
as nodata by :mod:`pipeline.outputs.raster`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import pyproj
from affine import Affine

from pipeline.process.classify import BATHYMETRIC_POINT
from pipeline.process.returns import Points

__all__ = ["Grid", "grid_points", "grid_seabed", "snap_bounds_m"]


@dataclass(frozen=True)
class Grid:
    """A regular grid of seabed statistics in the local frame, with its CRS and origin.

    Attributes
    ----------
    depth_m, median_depth_m, spread_m, z_m : (ny, nx) float64
        Mean depth, median depth, depth standard deviation and mean elevation; NaN where empty
        (and ``spread_m`` where fewer than 2 points).
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

    @property
    def shape(self) -> tuple[int, int]:
        """``(ny, nx)``."""
        return self.depth_m.shape

    @property
    def local_transform(self) -> Affine:
        """Affine from (col, row) of cell corners to local (x, y)."""
        w, _, _, n = self.bounds_m
        return Affine(self.resolution_m, 0.0, w, 0.0, -self.resolution_m, n)

    @property
    def transform(self) -> Affine:
        """Affine from (col, row) of cell corners to world (easting, northing)."""
        w, _, _, n = self.bounds_m
        e0, n0 = self.origin_m[0], self.origin_m[1]
        return Affine(self.resolution_m, 0.0, w + e0, 0.0, -self.resolution_m, n + n0)


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
) -> Grid:
    """Grid points by cell: mean, median, spread and count of ``depth_m``, mean of ``z_m``.

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

    Returns
    -------
    Grid
    """
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

    col = np.floor((x - w) / r).astype(np.int64)
    row = np.floor((n - y) / r).astype(np.int64)
    inside = (col >= 0) & (col < nx) & (row >= 0) & (row < ny)
    cell = (row * nx + col)[inside]
    v, z = v[inside], z[inside]
    size = nx * ny

    count = np.bincount(cell, minlength=size)
    has = count > 0
    cnt = np.where(has, count, 1)
    mean = np.bincount(cell, weights=v, minlength=size) / cnt
    zmean = np.bincount(cell, weights=z, minlength=size) / cnt
    ss = np.bincount(cell, weights=(v - mean[cell]) ** 2, minlength=size)
    spread = np.sqrt(ss / np.maximum(count - 1, 1))

    order = np.lexsort((v, cell))
    vs = v[order]
    start = np.concatenate([[0], np.cumsum(count)[:-1]])
    lo = vs[np.minimum(start + (cnt - 1) // 2, max(len(vs) - 1, 0))] if len(vs) else mean
    hi = vs[np.minimum(start + cnt // 2, max(len(vs) - 1, 0))] if len(vs) else mean
    median = 0.5 * (lo + hi)

    def shaped(a, ok):
        return np.where(ok, a, np.nan).reshape(ny, nx)

    return Grid(
        depth_m=shaped(mean, has),
        median_depth_m=shaped(median, has),
        spread_m=shaped(spread, count >= 2),
        z_m=shaped(zmean, has),
        count=count.reshape(ny, nx).astype(np.int64),
        x_m=w + (np.arange(nx) + 0.5) * r,
        y_m=n - (np.arange(ny) + 0.5) * r,
        resolution_m=r,
        bounds_m=bounds,
        origin_m=origin,
        crs=None if crs is None else pyproj.CRS.from_user_input(crs),
    )


def grid_seabed(
    points: Points,
    resolution_m: float,
    *,
    bounds_m: Sequence[float] | None = None,
    origin_m: Sequence[float] = (0.0, 0.0, 0.0),
    crs: Any = None,
    classes: Sequence[int] = (BATHYMETRIC_POINT,),
    datum_m: float | None = None,
) -> Grid:
    """Grid the points of ``classes`` (default 40, bathymetric point) by :func:`grid_points`.

    With ``datum_m`` (local z of the survey's mean water level, :mod:`pipeline.process.datum`)
    the gridded depth is ``datum_m − z``: one reference for the whole grid. Without it, the
    points' own ``depth_m`` (below the local fitted surface, which under waves carries the
    wave heights).
    """
    keep = np.isin(points.classification, np.asarray(classes, dtype=np.uint8))
    xyz = points.xyz_m[keep]
    depth = points.depth_m[keep] if datum_m is None else float(datum_m) - xyz[:, 2]
    grid = grid_points(
        xyz[:, 0],
        xyz[:, 1],
        depth,
        xyz[:, 2],
        resolution_m=resolution_m,
        bounds_m=bounds_m,
        origin_m=origin_m,
        crs=crs,
    )
    return grid if datum_m is None else dataclasses.replace(grid, datum_m=float(datum_m))
