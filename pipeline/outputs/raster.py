"""``grid.tif`` (GeoTIFF) and ``grid.nc`` (NetCDF, CF conventions) from a :class:`Grid`.

GeoTIFF: three float32 bands ``depth_m`` (mean depth, positive down), ``spread_m`` (standard
deviation) and ``count``; nodata ``-9999`` where a cell is empty (NaN inside the pipeline;
``count`` is 0 there, never nodata); CRS and world affine transform (cell corners, "Area"
registration); DEFLATE with the floating-point predictor, 256 x 256 tiles. Band names go in the
band descriptions, units in band tags, and the local origin in dataset tags.

NetCDF: written with :class:`scipy.io.netcdf_file` (NetCDF-3 64-bit offset, no xarray or
netCDF4 needed): ``x``/``y`` world coordinates of the cell centres, every grid statistic as a
variable with ``_FillValue``, and a ``crs`` grid-mapping variable holding the WKT.

Both are written atomically (temporary file, then rename).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pyproj
import rasterio
from affine import Affine
from scipy.io import netcdf_file

from pipeline.outputs.atomic import atomic_path
from pipeline.process.grid import Grid

__all__ = ["NODATA", "TIF_BANDS", "GridRaster", "write_grid_tif", "read_grid_tif", "write_grid_nc"]

#: Nodata value of the written files (an impossible depth, exact in float32).
NODATA = -9999.0
#: Band order of ``grid.tif``: (name, unit).
TIF_BANDS = (("depth_m", "m"), ("spread_m", "m"), ("count", "1"))
_TILE = 256


@dataclass(frozen=True)
class GridRaster:
    """What :func:`read_grid_tif` returns: bands by name (NaN where nodata), georeferencing."""

    bands: dict[str, np.ndarray]
    transform: Affine
    crs: pyproj.CRS | None
    nodata: float
    origin_m: np.ndarray
    profile: dict


def _band_data(grid: Grid, name: str) -> np.ndarray:
    a = getattr(grid, name).astype(np.float64)
    return np.where(np.isfinite(a), a, NODATA).astype(np.float32)


def write_grid_tif(path: str | Path, grid: Grid) -> Path:
    """Write ``grid`` as a tiled, DEFLATE-compressed GeoTIFF, atomically; returns ``path``."""
    if grid.crs is None:
        raise ValueError("`grid.crs` is required for a GeoTIFF; grid with `crs=...`")
    path = Path(path)
    ny, nx = grid.shape
    profile = {
        "driver": "GTiff",
        "width": nx,
        "height": ny,
        "count": len(TIF_BANDS),
        "dtype": "float32",
        "crs": rasterio.crs.CRS.from_wkt(grid.crs.to_wkt()),
        "transform": grid.transform,
        "nodata": NODATA,
        "compress": "deflate",
        "predictor": 3,
        "tiled": True,
        "blockxsize": _TILE,
        "blockysize": _TILE,
    }
    with atomic_path(path) as tmp, rasterio.open(tmp, "w", **profile) as dst:
        for i, (name, unit) in enumerate(TIF_BANDS, start=1):
            dst.write(_band_data(grid, name), i)
            dst.set_band_description(i, name)
            dst.update_tags(i, units=unit)
        dst.update_tags(
            origin_easting_m=repr(float(grid.origin_m[0])),
            origin_northing_m=repr(float(grid.origin_m[1])),
            origin_height_m=repr(float(grid.origin_m[2])),
            resolution_m=repr(float(grid.resolution_m)),
            depth=(
                "positive down, below the fitted local water surface"
                if grid.datum_m is None
                else f"positive down, below the datum (mean water level) at local z = "
                f"{grid.datum_m!r} m, height {grid.datum_m + float(grid.origin_m[2])!r} m"
            ),
            datum_water_level_m="" if grid.datum_m is None else repr(float(grid.datum_m)),
            registration="cell-centre (area): transform gives cell corners",
        )
    return path


def read_grid_tif(path: str | Path) -> GridRaster:
    """Read a file written by :func:`write_grid_tif` (nodata back to NaN)."""
    with rasterio.open(path) as src:
        bands = {}
        for i in range(1, src.count + 1):
            name = src.descriptions[i - 1] or f"band{i}"
            a = src.read(i).astype(np.float64)
            bands[name] = np.where(a == src.nodata, np.nan, a)
        tags = src.tags()
        origin = np.array(
            [float(tags.get(k, 0.0)) for k in ("origin_easting_m", "origin_northing_m")]
            + [float(tags.get("origin_height_m", 0.0))]
        )
        crs = pyproj.CRS.from_wkt(src.crs.to_wkt()) if src.crs else None
        return GridRaster(bands, src.transform, crs, src.nodata, origin, dict(src.profile))


def write_grid_nc(path: str | Path, grid: Grid) -> Path:
    """Write every grid statistic to a CF-style NetCDF-3 file, atomically; returns ``path``."""
    path = Path(path)
    ny, nx = grid.shape
    with atomic_path(path) as tmp:
        f = netcdf_file(tmp, "w", version=2)
        try:
            f.Conventions = "CF-1.8"
            f.title = "bathymetric lidar grid"
            f.origin_m = np.asarray(grid.origin_m, dtype=np.float64)
            f.registration = "cell-centre"
            f.createDimension("y", ny)
            f.createDimension("x", nx)
            x = f.createVariable("x", "f8", ("x",))
            x[:] = grid.x_m + grid.origin_m[0]
            x.standard_name, x.units = "projection_x_coordinate", "m"
            y = f.createVariable("y", "f8", ("y",))
            y[:] = grid.y_m + grid.origin_m[1]
            y.standard_name, y.units = "projection_y_coordinate", "m"
            crs = f.createVariable("crs", "i4", ())
            if grid.crs is not None:
                wkt = grid.crs.to_wkt().encode("utf-8")  # NetCDF-3 text is bytes (may hold "°")
                crs.crs_wkt = wkt
                crs.spatial_ref = wkt
            for name, unit in (
                ("depth_m", "m"),
                ("median_depth_m", "m"),
                ("spread_m", "m"),
                ("z_m", "m"),
            ):
                v = f.createVariable(name, "f4", ("y", "x"))
                v._FillValue = np.float32(NODATA)
                v.units = unit
                v.grid_mapping = "crs"
                v[:] = _band_data(grid, name)
            cnt = f.createVariable("count", "i4", ("y", "x"))
            cnt.units = "1"
            cnt.grid_mapping = "crs"
            cnt[:] = grid.count.astype(np.int32)
        finally:
            f.close()
    return path
