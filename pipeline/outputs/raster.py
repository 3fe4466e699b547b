"""``grid.tif``: a Cloud Optimized GeoTIFF of the grid and its per-cell uncertainty.

Layout
------
Six float32 bands, in this order (:data:`TIF_BANDS`): ``depth_m`` (cell depth, by default the
median of its points; positive down, below the survey's datum), ``tvu95_m`` and ``thu95_m``
(the cell's 95 % total vertical and horizontal uncertainty,
:mod:`pipeline.uncertainty.cell_uncertainty`), ``iho_order`` (strictest IHO S-44 order met,
the codes of :func:`pipeline.iho.strictest_order`: 0 exclusive, 1 special, 2 order 1a/1b,
3 order 2, 4 none), ``count`` (points per cell) and ``spread_m``
(standard deviation of the cell's depths). Every band has its name as band description and
its unit as band unit (GDAL ``SetUnitType``: ``m``, or ``1`` for codes and counts). Nodata is
``-9999`` where a cell has no value (NaN inside the pipeline; ``count`` is 0 there, never
nodata); written without ``cells`` the three uncertainty bands are nodata throughout.

Cloud Optimized: the file is made by GDAL's COG driver (a GeoTIFF built in memory, then
copied), so it has 256 x 256 DEFLATE tiles with the floating-point predictor, overviews
(at least one level, halving down to one tile; NEAREST resampling, so every overview value is
a real cell value and the order codes and counts stay valid), the IFDs ahead of the data, and
``LAYOUT=COG`` in the ``IMAGE_STRUCTURE`` metadata. CRS and world affine transform (cell
corners, "Area" registration); the local origin and the depth's datum in dataset tags.
Written atomically (temporary file, then rename).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pyproj
import rasterio
import rasterio.shutil
from affine import Affine
from rasterio.io import MemoryFile

from pipeline.outputs.atomic import atomic_path
from pipeline.process.grid import Grid
from pipeline.uncertainty.cell_uncertainty import CellUncertainty

__all__ = [
    "NODATA",
    "TIF_BANDS",
    "GridRaster",
    "grid_layers",
    "tif_profile",
    "describe_tif",
    "tif_band",
    "copy_as_cog",
    "write_grid_tif",
    "read_grid_tif",
    "depth_reference",
]

#: Nodata value of the written files (an impossible depth, exact in float32).
NODATA = -9999.0
#: Band order of ``grid.tif``: (name, unit).
TIF_BANDS = (
    ("depth_m", "m"),
    ("tvu95_m", "m"),
    ("thu95_m", "m"),
    ("iho_order", "1"),
    ("count", "1"),
    ("spread_m", "m"),
)
_TILE = 256


@dataclass(frozen=True)
class GridRaster:
    """What :func:`read_grid_tif` returns: bands by name (NaN where nodata), georeferencing."""

    bands: dict[str, np.ndarray]
    units: dict[str, str]
    transform: Affine
    crs: pyproj.CRS | None
    nodata: float
    origin_m: np.ndarray
    profile: dict


def grid_layers(grid: Grid, cells: CellUncertainty | None) -> dict[str, np.ndarray]:
    """Every written layer as float64 ``(ny, nx)``, NaN where a cell has no value.

    The bands of :data:`TIF_BANDS` and ``median_depth_m`` (``grid.nc``'s). ``iho_order`` is
    NaN where the cell is empty (code -1); without ``cells`` the uncertainty layers are NaN
    throughout.
    """
    nan = np.full(grid.shape, np.nan)
    out = {
        "depth_m": grid.depth_m.astype(np.float64),
        "median_depth_m": grid.median_depth_m.astype(np.float64),
        "count": grid.count.astype(np.float64),
        "spread_m": grid.spread_m.astype(np.float64),
        "tvu95_m": nan,
        "thu95_m": nan,
        "iho_order": nan,
    }
    if cells is not None:
        if cells.order.shape != grid.shape:
            raise ValueError(f"`cells` has shape {cells.order.shape}; the grid {grid.shape}")
        order = cells.order.astype(np.float64)
        out["tvu95_m"] = cells.tvu95_m.astype(np.float64)
        out["thu95_m"] = cells.thu95_m.astype(np.float64)
        out["iho_order"] = np.where(order < 0, np.nan, order)
    return out


def depth_reference(grid: Grid) -> str:
    """In words, what the grid's depths are below."""
    if grid.datum_m is None:
        return "positive down, below the fitted local water surface"
    return (
        f"positive down, below the survey's mean water level (datum) at local z = "
        f"{grid.datum_m!r} m, height {grid.datum_m + float(grid.origin_m[2])!r} m in the "
        "scene's local vertical frame"
    )


def _overview_count(shape: tuple[int, int]) -> int:
    """Halvings until the larger side fits one tile, and at least one (a COG has overviews)."""
    return max(1, math.ceil(math.log2(max(max(shape) / _TILE, 1.0))))


def tif_profile(frame) -> dict:
    """The rasterio profile of ``grid.tif``'s GeoTIFF before the COG copy.

    ``frame``: a :class:`~pipeline.process.grid.Grid` or anything with its ``shape``,
    ``crs`` and ``transform`` (:class:`~pipeline.outputs.grid_tiles.GridFrame`).
    """
    if frame.crs is None:
        raise ValueError("`grid.crs` is required for a GeoTIFF; grid with `crs=...`")
    ny, nx = frame.shape
    return {
        "driver": "GTiff",
        "width": nx,
        "height": ny,
        "count": len(TIF_BANDS),
        "dtype": "float32",
        "crs": rasterio.crs.CRS.from_wkt(frame.crs.to_wkt()),
        "transform": frame.transform,
        "nodata": NODATA,
    }


def describe_tif(dst, frame) -> None:
    """Set the band descriptions, units and dataset tags of ``grid.tif`` on ``dst`` (open)."""
    for i, (name, unit) in enumerate(TIF_BANDS, start=1):
        dst.set_band_description(i, name)
        dst.set_band_unit(i, unit)
    dst.update_tags(
        origin_easting_m=repr(float(frame.origin_m[0])),
        origin_northing_m=repr(float(frame.origin_m[1])),
        origin_height_m=repr(float(frame.origin_m[2])),
        resolution_m=repr(float(frame.resolution_m)),
        depth=depth_reference(frame),
        datum_water_level_m="" if frame.datum_m is None else repr(float(frame.datum_m)),
        iho_order="0 exclusive, 1 special, 2 order 1a/1b, 3 order 2, 4 none met",
        tvu95_m="95 % total vertical uncertainty of the cell depth",
        thu95_m="95 % total horizontal uncertainty of the cell position",
        registration="cell-centre (area): transform gives cell corners",
    )


def tif_band(layer: np.ndarray) -> np.ndarray:
    """A layer of :func:`grid_layers` (or a window of it) as its band's float32 values."""
    return np.where(np.isfinite(layer), layer, NODATA).astype(np.float32)


def copy_as_cog(src, dest: str, shape: tuple[int, int]) -> None:
    """GDAL's COG copy of the open dataset ``src`` to ``dest`` (the creation options above)."""
    rasterio.shutil.copy(
        src,
        dest,
        driver="COG",
        compress="DEFLATE",
        predictor=3,
        blocksize=_TILE,
        overview_resampling="NEAREST",
        overview_count=_overview_count(shape),
    )


def write_grid_tif(path: str | Path, grid: Grid, cells: CellUncertainty | None = None) -> Path:
    """Write ``grid`` (and its cell uncertainty) as a Cloud Optimized GeoTIFF, atomically.

    Parameters
    ----------
    path : str or Path
        Output file.
    grid : Grid
        The bathymetry grid; its ``crs`` is required.
    cells : CellUncertainty, optional
        Per-cell TVU, THU and IHO order of ``grid`` (``SurveyUncertainty.cells``).

    Returns
    -------
    Path
        ``path``.
    """
    profile = tif_profile(grid)
    path = Path(path)
    layers = grid_layers(grid, cells)
    with MemoryFile() as mem:
        with mem.open(**profile) as dst:
            for i, (name, _) in enumerate(TIF_BANDS, start=1):
                dst.write(tif_band(layers[name]), i)
            describe_tif(dst, grid)
        # the COG driver writes side files next to its target (overviews): it writes into
        # GDAL's memory filesystem, and the finished bytes go to disk atomically
        with mem.open() as src, MemoryFile() as cog:
            copy_as_cog(src, cog.name, grid.shape)
            cog.seek(0)
            data = cog.read()
        with atomic_path(path) as tmp:
            tmp.write_bytes(data)
    return path


def read_grid_tif(path: str | Path) -> GridRaster:
    """Read a file written by :func:`write_grid_tif` (nodata back to NaN)."""
    with rasterio.open(path) as src:
        bands, units = {}, {}
        for i in range(1, src.count + 1):
            name = src.descriptions[i - 1] or f"band{i}"
            a = src.read(i).astype(np.float64)
            bands[name] = np.where(a == src.nodata, np.nan, a)
            units[name] = src.units[i - 1] or ""
        tags = src.tags()
        origin = np.array(
            [float(tags.get(k, 0.0)) for k in ("origin_easting_m", "origin_northing_m")]
            + [float(tags.get("origin_height_m", 0.0))]
        )
        crs = pyproj.CRS.from_wkt(src.crs.to_wkt()) if src.crs else None
        return GridRaster(bands, units, src.transform, crs, src.nodata, origin, dict(src.profile))
