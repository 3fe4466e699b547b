"""``grid.nc``: the grid and its per-cell uncertainty as CF-1.8 NetCDF-4 (via xarray).

Variables, on dimensions ``(y, x)`` (row 0 north, as in ``grid.tif``):

* ``x``, ``y``: world coordinates of the cell centres, ``standard_name``
  ``projection_x_coordinate`` / ``projection_y_coordinate``, ``units = "m"``, ``axis``.
* ``crs``: the grid-mapping variable (CF §5.6): pyproj's CF attributes of the horizontal CRS
  (``grid_mapping_name`` and its parameters, ``crs_wkt``) and ``spatial_ref`` (the same WKT,
  what GDAL reads). Every data variable names it in ``grid_mapping``.
* ``depth``: depth of the cell (by default the median of its points, ``Grid.statistic``),
  ``units = "m"``, ``positive = "down"``, ``standard_name =
  "sea_floor_depth_below_sea_surface"``. Why this name: the grid's datum is the survey's mean
  water level (:mod:`pipeline.process.datum`), the water surface averaged over the waves *at
  survey time*, tide included: CF's ``..._below_mean_sea_level`` is a level averaged over the
  tides (and ``..._below_geoid`` / ``..._below_geopotential_datum`` a realised vertical datum),
  neither of which a survey of minutes measures; ``..._below_sea_surface`` is the depth below
  the sea surface at the time of measurement, which is what the datum realises. The datum's
  local z is in the ``datum_water_level_m`` attribute and the ``comment``.
* ``median_depth``: likewise, the cell's median.
* ``tvu95``, ``thu95``: 95 % total vertical / horizontal uncertainty of the cell (m),
  ``iho_order``: strictest IHO S-44 order met (``flag_values`` / ``flag_meanings``), ``count``
  (``standard_name = "sea_floor_depth_below_sea_surface number_of_observations"``), ``spread``
  (standard deviation of the cell's depths, m); ``depth``'s ``ancillary_variables`` names them.

Float variables are float32 with ``_FillValue = -9999`` (empty cells), ``iho_order`` int8 with
``_FillValue = -1`` (the code of an empty cell), ``count`` int32 (0 where empty), each in
zlib-compressed chunks of 256 x 256 cells (:data:`NC_CHUNK`). Written atomically (temporary
file, then rename).
"""

from __future__ import annotations

import shutil
import tempfile
from pathlib import Path

import numpy as np
import pyproj

from pipeline.iho import CLASSIFIED_ORDERS, NO_DATA, NO_ORDER
from pipeline.outputs.atomic import atomic_path
from pipeline.outputs.raster import NODATA, depth_reference, grid_layers
from pipeline.process.grid import Grid, require_whole
from pipeline.uncertainty.cell_uncertainty import CellUncertainty

__all__ = [
    "DEPTH_STANDARD_NAME",
    "ORDER_FLAG_MEANINGS",
    "NC_VARIABLES",
    "nc_variable",
    "grid_dataset",
    "save_grid_nc",
    "write_grid_nc",
]

#: CF standard name of the grid's depth (see the module's docstring for why).
DEPTH_STANDARD_NAME = "sea_floor_depth_below_sea_surface"
#: ``flag_meanings`` of ``iho_order``, for the codes 0 .. NO_ORDER.
ORDER_FLAG_MEANINGS = " ".join(
    [f"order_{name}" for name in CLASSIFIED_ORDERS] + ["no_order_met"]
).replace("order_1a", "order_1a_or_1b")


def _grid_mapping(crs: pyproj.CRS | None) -> dict[str, object]:
    """CF grid-mapping attributes of the horizontal CRS (WKT alone if CF has no mapping)."""
    if crs is None:
        return {}
    wkt = crs.to_wkt()
    try:
        attrs = dict(crs.to_cf())
    except Exception:  # pyproj raises for CRSs CF has no grid mapping for
        attrs = {}
    attrs.setdefault("crs_wkt", wkt)
    attrs["spatial_ref"] = wkt
    return attrs


#: The data variables of ``grid.nc``: the :func:`~pipeline.outputs.raster.grid_layers` layer
#: each is made of, and its stored type.
NC_VARIABLES = {
    "depth": ("depth_m", np.float32),
    "median_depth": ("median_depth_m", np.float32),
    "tvu95": ("tvu95_m", np.float32),
    "thu95": ("thu95_m", np.float32),
    "iho_order": ("iho_order", np.int8),
    "count": ("count", np.int32),
    "spread": ("spread_m", np.float32),
}
#: Side of the variables' HDF5 chunks (cells): a grid written window by window
#: (:mod:`pipeline.outputs.grid_tiles`) writes each chunk once, whole.
NC_CHUNK = 256


def nc_variable(name: str, layers: dict[str, np.ndarray]) -> np.ndarray:
    """The stored values of data variable ``name`` from ``layers`` (or windows of them).

    NaN stays NaN in the float variables (written as ``_FillValue``); ``iho_order``'s NaN
    becomes ``NO_DATA``.
    """
    layer, dtype = NC_VARIABLES[name]
    a = layers[layer]
    if name == "iho_order":
        a = np.where(np.isfinite(a), a, NO_DATA)
    return a.astype(dtype)


def grid_dataset(frame, variables: dict):
    """``grid.nc`` as an :class:`xarray.Dataset`: attributes, coordinates and ``variables``.

    Parameters
    ----------
    frame : Grid or GridFrame
        The grid's geometry, CRS, datum and statistic (its arrays are not read).
    variables : dict of str to (ny, nx) array
        Each of :data:`NC_VARIABLES`, of its stored type (:func:`nc_variable`); numpy or dask
        arrays (a dask array is written chunk by chunk).
    """
    import xarray as xr  # imported here: only the NetCDF writer needs xarray

    dims = ("y", "x")
    common = {"grid_mapping": "crs"}
    depth_attrs = {
        "standard_name": DEPTH_STANDARD_NAME,
        "units": "m",
        "positive": "down",
        **({} if frame.datum_m is None else {"datum_water_level_m": float(frame.datum_m)}),
        "comment": depth_reference(frame),
        **common,
    }
    attrs = {
        "depth": {
            "long_name": f"{frame.statistic} depth of the cell's bathymetric points",
            "cell_methods": f"area: {frame.statistic}",
            "ancillary_variables": "tvu95 thu95 iho_order count spread",
            **depth_attrs,
        },
        "median_depth": {
            "long_name": "median depth of the cell's bathymetric points",
            "cell_methods": "area: median",
            **depth_attrs,
        },
        "tvu95": {
            "long_name": "total vertical uncertainty of the cell depth, 95 % confidence",
            "units": "m",
            **common,
        },
        "thu95": {
            "long_name": "total horizontal uncertainty of the cell position, 95 % confidence",
            "units": "m",
            **common,
        },
        "iho_order": {
            "long_name": "strictest IHO S-44 (6th ed.) order met by the cell",
            "flag_values": np.arange(NO_ORDER + 1, dtype=np.int8),
            "flag_meanings": ORDER_FLAG_MEANINGS,
            **common,
        },
        "count": {
            "long_name": "bathymetric points in the cell",
            "standard_name": f"{DEPTH_STANDARD_NAME} number_of_observations",
            "units": "1",
            **common,
        },
        "spread": {
            "long_name": "standard deviation of the cell's point depths",
            "cell_methods": "area: standard_deviation",
            "units": "m",
            **common,
        },
    }
    data = {name: (dims, variables[name], attrs[name]) for name in NC_VARIABLES}
    data["crs"] = ((), np.int32(0), _grid_mapping(frame.crs))
    coords = {
        "x": (
            "x",
            frame.x_m + frame.origin_m[0],
            {
                "standard_name": "projection_x_coordinate",
                "long_name": "easting of the cell centre",
                "units": "m",
                "axis": "X",
            },
        ),
        "y": (
            "y",
            frame.y_m + frame.origin_m[1],
            {
                "standard_name": "projection_y_coordinate",
                "long_name": "northing of the cell centre",
                "units": "m",
                "axis": "Y",
            },
        ),
    }
    return xr.Dataset(
        data,
        coords=coords,
        attrs={
            "Conventions": "CF-1.8",
            "title": "Bathymetric lidar grid",
            "source": "bathy pipeline (airborne bathymetric lidar survey)",
            "resolution_m": float(frame.resolution_m),
            "origin_m": np.asarray(frame.origin_m, dtype=np.float64),
            "registration": "cell centres; cells are resolution_m wide",
        },
    )


def save_grid_nc(path: str | Path, ds) -> Path:
    """Write ``grid.nc``'s dataset (:func:`grid_dataset`) as NetCDF-4, atomically."""
    path = Path(path)
    ny, nx = ds["depth"].shape
    chunks = {"chunksizes": (min(ny, NC_CHUNK), min(nx, NC_CHUNK)), "zlib": True, "complevel": 4}
    fill = {"_FillValue": np.float32(NODATA), **chunks}
    encoding = {name: dict(fill) for name in ("depth", "median_depth", "tvu95", "thu95", "spread")}
    encoding["iho_order"] = {"_FillValue": np.int8(NO_DATA), **chunks}
    encoding["count"] = {"_FillValue": None, **chunks}
    encoding["x"] = encoding["y"] = {"_FillValue": None}
    # the HDF5 library under NetCDF-4 opens its file by name, more than once: it writes into a
    # private folder of the system's temporary directory, and the finished bytes go to disk
    # atomically (a run killed meanwhile leaves the output folder clean)
    with tempfile.TemporaryDirectory(prefix="bathy-nc-") as d:
        staged = Path(d) / "grid.nc"
        if any(ds[k].chunks is not None for k in ds.data_vars):
            _to_netcdf_in_order(ds, staged, encoding)
        else:
            ds.to_netcdf(staged, format="NETCDF4", engine="netcdf4", encoding=encoding)
        with atomic_path(path) as tmp, open(staged, "rb") as src, open(tmp, "wb") as dst:
            shutil.copyfileobj(src, dst, 1 << 20)  # by pieces: the file can be large
    return path


def _to_netcdf_in_order(ds, path: Path, encoding: dict) -> None:
    """``ds.to_netcdf`` (NetCDF-4), its dask variables stored one after another, in chunk order.

    One store of every variable runs their chunks in an order that their tasks' keys set, and
    those hold random tokens; HDF5 lays the chunks out as they come, so the same content would
    give other bytes on every run. xarray's ``multifile`` writer (what ``save_mfdataset`` uses)
    hands back the writer with its dask sources still to store: stored here one at a time, a
    variable's chunks go in their own order and the file is the same on every run.
    """
    import dask.array as da

    try:
        from xarray.backends.writers import to_netcdf
    except ImportError:  # xarray before 2025.09 kept it here
        from xarray.backends.api import to_netcdf

    writer, store = to_netcdf(
        ds, path, format="NETCDF4", engine="netcdf4", encoding=encoding, multifile=True
    )
    try:
        for source, target, region in zip(
            writer.sources, writer.targets, writer.regions, strict=True
        ):
            # one thread: a variable's chunks are laid out in their order
            da.store(
                source, target, lock=writer.lock, flush=True, regions=region,
                scheduler="synchronous",
            )  # fmt: skip
    finally:
        store.close()


def write_grid_nc(path: str | Path, grid: Grid, cells: CellUncertainty | None = None) -> Path:
    """Write ``grid`` (and its cell uncertainty) as CF-1.8 NetCDF-4, atomically.

    Parameters
    ----------
    path : str or Path
        Output file.
    grid : Grid
        The bathymetry grid, ``(ny, nx)``.
    cells : CellUncertainty, optional
        Its per-cell TVU, THU and IHO order; without it those variables are all fill values.

    Returns
    -------
    Path
        ``path``.
    """
    require_whole(grid, "a file of its own (its x and y would not be regular)")
    layers = grid_layers(grid, cells)
    return save_grid_nc(path, grid_dataset(grid, {k: nc_variable(k, layers) for k in NC_VARIABLES}))
