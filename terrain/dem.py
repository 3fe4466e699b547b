"""A seabed (or land) from the user's own GeoTIFF DEM, read with rasterio.

The raster holds elevations positive up in metres (apply the file's scale/offset tags), one value
per pixel, georeferenced by a north-up affine transform (no rotation) in a projected CRS in metres.
Pixel values are taken at the pixel *centres*; the truth between them is the cubic B-spline
interpolant of :class:`~terrain.gridded.GridSurface` (non-periodic; queries outside the centre
extent raise :class:`ValueError`). The CRS comes from the file. Nodata pixels are refused: fill
them first.
"""

from __future__ import annotations

import os

import numpy as np
import pyproj
import rasterio

from terrain._validate import check_number
from terrain.frame import LocalFrame
from terrain.gridded import GridSurface

__all__ = ["read_dem"]


def read_dem(
    path: str | os.PathLike, *, frame: LocalFrame | None = None, band: int = 1
) -> tuple[GridSurface, LocalFrame]:
    """Read a GeoTIFF DEM into a local-coordinate surface.

    Parameters
    ----------
    path : str or os.PathLike
        GeoTIFF (any GDAL raster) file with elevations in metres, positive up.
    frame : LocalFrame, optional
        Frame to express the surface in; its CRS must equal the file's (no reprojection is done).
        Default: a frame in the file's CRS with its origin at the DEM centre rounded to whole
        metres and ``origin_height_m = 0``.
    band : int
        1-based band index.

    Returns
    -------
    surface : GridSurface
        Non-periodic surface, node ``[j, i]`` at the pixel centres with y increasing (rows are
        flipped from the file's north-up order), heights ``elevation - frame.origin_height_m``.
    frame : LocalFrame
        The frame used.
    """
    band = int(check_number("band", band, ge=1))
    with rasterio.open(path) as ds:
        if band > ds.count:
            raise ValueError(f"`band` must be <= {ds.count} for {os.fspath(path)!r}; got {band}")
        if ds.crs is None:
            raise ValueError(f"`path` {os.fspath(path)!r} has no CRS; georeference it first")
        t = ds.transform
        if t.b != 0.0 or t.d != 0.0:
            raise ValueError(f"`path` {os.fspath(path)!r} has a rotated transform {tuple(t)[:6]}")
        data = ds.read(band, masked=True)
        scale = ds.scales[band - 1] if ds.scales else 1.0
        offset = ds.offsets[band - 1] if ds.offsets else 0.0
        file_crs = pyproj.CRS.from_user_input(ds.crs.to_wkt())
        height, width = ds.height, ds.width
    n_bad = int(np.ma.count_masked(data))
    if n_bad:
        raise ValueError(f"`path` {os.fspath(path)!r} has {n_bad} nodata pixels; fill them first")
    z = np.asarray(data.filled(0), dtype=np.float64) * scale + offset
    if not np.all(np.isfinite(z)):
        raise ValueError(f"`path` {os.fspath(path)!r} has non-finite elevations")
    # pixel centres: x_i = c + (i + 0.5) a, y_j = f + (j + 0.5) e
    x_first, y_first = t.c + 0.5 * t.a, t.f + 0.5 * t.e
    if t.a < 0:
        z, x_first = z[:, ::-1], x_first + (width - 1) * t.a
    if t.e < 0:
        z, y_first = z[::-1, :], y_first + (height - 1) * t.e
    dx, dy = abs(t.a), abs(t.e)
    if frame is None:
        centre_e = x_first + 0.5 * (width - 1) * dx
        centre_n = y_first + 0.5 * (height - 1) * dy
        frame = LocalFrame(float(np.round(centre_e)), float(np.round(centre_n)), file_crs)
    elif not isinstance(frame, LocalFrame):
        raise ValueError(f"`frame` must be a LocalFrame; got {frame!r}")
    elif not frame.crs.equals(file_crs, ignore_axis_order=True):
        raise ValueError(
            f"`frame` CRS {frame.crs.name!r} differs from the DEM's {file_crs.name!r}; "
            "reproject the DEM first"
        )
    x0, y0 = frame.to_local(x_first, y_first)
    surface = GridSurface(float(x0), float(y0), dx, dy, z - frame.origin_height_m)
    return surface, frame
