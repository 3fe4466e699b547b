"""The grid written by tiles: a blocked survey's ``grid.tif`` and ``grid.nc`` through disk.

A survey processed block by block (:mod:`pipeline.survey_blocks`) hands over each block's own
cells as the block ends. :class:`GridTiles` writes them at once into a raw file of the whole
grid's cells, an unnamed file in the system's temporary directory (``O_TMPFILE``: nothing is
left behind, even by a kill; elsewhere a file in a private folder), and at the end writes
``grid.tif`` and ``grid.nc`` from that file a 256 x 256 window at a time (through named
files in private folders, as :func:`~pipeline.outputs.netcdf.write_grid_nc` does). No array of the
whole area's size is made: memory is bounded by one block's window while filling and by one
window of :data:`TILE` cells (and GDAL's and HDF5's caches, bounded below) while writing.

**Cells on disk.** One record per cell, row-major, in the machine's byte order (a block's
row of cells is one write), holding what :func:`~pipeline.outputs.raster.grid_layers` gives:
``depth_m``, ``median_depth_m``, ``spread_m``, ``tvu95_m``, ``thu95_m``
as float32, ``count`` int64, ``iho_order`` as its int8 code (-1 empty). Float32 loses nothing:
both files store those layers as float32 casts (NaN and the finite values cast alike). Every
cell starts empty (NaN, count 0, code -1: the values of a cell without points), so a block
never processed reads as empty, as in the whole survey's grid.

**The files are the in-memory writers'** (:func:`~pipeline.outputs.raster.write_grid_tif`,
:func:`~pipeline.outputs.netcdf.write_grid_nc`) of the same cells, the same code making their
values and metadata: ``grid.tif`` is GDAL's COG copy (the same options) of a tiled GeoTIFF
written window by window with the same profile, band descriptions, units and tags;
``grid.nc`` is the same dataset with dask arrays whose chunks are the file's 256 x 256 HDF5
chunks, computed one at a time. The sample's posterior cells overlay the blocks' cells
window by window (``overlay``). Both written atomically (temporary file, then rename), with
the mode a plain ``open()`` gives.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pyproj

from pipeline.iho import NO_DATA
from pipeline.outputs.atomic import _anonymous_file as anonymous_file
from pipeline.outputs.atomic import atomic_path
from pipeline.outputs.grid_overlay import Overlay
from pipeline.process.grid import Grid, cell_centres_m, require_whole

__all__ = ["TILE", "GridFrame", "GridTiles", "Overlay", "cell_records"]

#: Side of the windows written (cells): the COG's tiles and ``grid.nc``'s chunks.
TILE = 256
#: Each layer's type on disk and the value of an empty cell.
_LAYERS = {
    "depth_m": (np.float32, np.nan),
    "median_depth_m": (np.float32, np.nan),
    "spread_m": (np.float32, np.nan),
    "count": (np.int64, 0),
    "tvu95_m": (np.float32, np.nan),
    "thu95_m": (np.float32, np.nan),
    "iho_order": (np.int8, NO_DATA),
}
#: A cell's record on disk: its layers, packed (29 bytes).
_CELL = np.dtype([(name, dtype) for name, (dtype, _) in _LAYERS.items()])
#: Where each layer comes from: (``"grid"`` or ``"cells"``, field).
_SOURCES = {
    "depth_m": ("grid", "depth_m"),
    "median_depth_m": ("grid", "median_depth_m"),
    "spread_m": ("grid", "spread_m"),
    "count": ("grid", "count"),
    "tvu95_m": ("cells", "tvu95_m"),
    "thu95_m": ("cells", "thu95_m"),
    "iho_order": ("cells", "order"),
}
#: GDAL's block cache while the GeoTIFF is written and copied (MiB): GDAL's default is 5 %
#: of the machine's memory, which dirty tiles would fill before any is written out.
_GDAL_CACHE_MB = 64
#: HDF5's chunk cache per variable while ``grid.nc`` is written (bytes): NetCDF's default
#: (64 MiB each) would hold up to a whole variable's compressed chunks before writing them.
_HDF5_CACHE_B = 4 << 20


@dataclass(frozen=True)
class GridFrame:
    """A grid's geometry and what its depths mean, without its cells: what the writers read.

    The attributes of :class:`~pipeline.process.grid.Grid` of the same names.

    Attributes
    ----------
    shape : (int, int)
        ``(ny, nx)``.
    x_m : (nx,) float64
    y_m : (ny,) float64
    resolution_m : float
    bounds_m : (4,) float64
    origin_m : (3,) float64
    crs : pyproj.CRS or None
    datum_m : float or None
    statistic : str
    """

    shape: tuple[int, int]
    x_m: np.ndarray
    y_m: np.ndarray
    resolution_m: float
    bounds_m: np.ndarray
    origin_m: np.ndarray
    crs: pyproj.CRS | None
    datum_m: float | None
    statistic: str

    @classmethod
    def over(cls, bounds_m, resolution_m: float, origin_m, crs, datum_m, statistic: str):
        """The frame of the grid of ``bounds_m`` (what :func:`grid_from_statistics` makes)."""
        x_m, y_m = cell_centres_m(bounds_m, resolution_m)
        return cls(
            shape=(y_m.size, x_m.size),
            x_m=x_m,
            y_m=y_m,
            resolution_m=float(resolution_m),
            bounds_m=np.asarray(bounds_m, dtype=np.float64),
            origin_m=np.asarray(origin_m, dtype=np.float64),
            crs=None if crs is None else pyproj.CRS.from_user_input(crs),
            datum_m=None if datum_m is None else float(datum_m),
            statistic=statistic,
        )

    #: world transform of the cell corners, :attr:`Grid.transform`'s (the same attributes)
    transform = Grid.transform


def cell_records(grid, cells, src: tuple[slice, slice]) -> np.ndarray:
    """Cells ``src`` of a block's ``grid`` and ``cells``, as the records :class:`GridTiles` stores.

    A worker that processed the block sends these (29 bytes a cell), not its grid.

    Parameters
    ----------
    grid : Grid
        A block's grid.
    cells : CellUncertainty
        Its cell uncertainty, shaped like ``grid``.
    src : (slice, slice)
        Rows and columns of the block's grid.

    Returns
    -------
    (rows, cols) structured ndarray
    """
    require_whole(grid, "its cells' place in the survey's grid")
    first = getattr(grid, next(iter(_SOURCES.values()))[1])[src]
    out = np.empty(first.shape, dtype=_CELL)
    for name, (where, field) in _SOURCES.items():
        out[name] = getattr(grid if where == "grid" else cells, field)[src]
    return out


class GridTiles:
    """A grid's written layers on disk, filled window by window; writes ``grid.tif``/``.nc``.

    Parameters
    ----------
    frame : GridFrame
        The grid's geometry.
    folder : str or Path, optional
        Where the private folder goes (default: the system's temporary directory).

    Use as a context manager (or call :meth:`close`): the cells' file is removed on exit.
    """

    def __init__(self, frame: GridFrame, folder: str | Path | None = None) -> None:
        self.frame = frame
        self._folder = folder
        # an unnamed file where the system has them: freed by the kernel when the process
        # ends, even killed; else a named one in a private folder, removed by close()
        self._dir = None
        fd = anonymous_file(Path(tempfile.gettempdir() if folder is None else folder))
        if fd is None:
            self._dir = tempfile.TemporaryDirectory(prefix="bathy-grid-", dir=folder)
            path = Path(self._dir.name) / "cells.raw"
            fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_EXCL | os.O_CLOEXEC, 0o600)
        self._fd = fd
        ny, nx = frame.shape
        # every cell empty: written a strip of about 1 MiB at a time
        rows = max(1, (1 << 20) // max(nx * _CELL.itemsize, 1))
        strip = np.empty((min(rows, ny), nx), dtype=_CELL)
        for name, (_, empty) in _LAYERS.items():
            strip[name] = empty
        for r0 in range(0, ny, rows):
            self._pwrite(strip[: min(rows, ny - r0)], r0, 0)

    def __enter__(self) -> GridTiles:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        """Close and remove the cells' file."""
        if self._fd >= 0:
            os.close(self._fd)
            self._fd = -1
        if self._dir is not None:
            self._dir.cleanup()

    def _pwrite(self, a: np.ndarray, r0: int, c0: int) -> None:
        """Write the records ``a`` ``(r, c)`` (C-contiguous) to the cells from ``(r0, c0)``."""
        nx, size = self.frame.shape[1], _CELL.itemsize
        buf = memoryview(a).cast("B")
        if a.shape[1] == nx:  # whole rows lie one after the other
            _write_all(self._fd, buf, r0 * nx * size)
            return
        step = a.shape[1] * size
        for i in range(a.shape[0]):
            _write_all(self._fd, buf[i * step : (i + 1) * step], ((r0 + i) * nx + c0) * size)

    def _pread(self, rows: slice, cols: slice) -> np.ndarray:
        """The records of the cells ``rows, cols``, ``(r, c)``."""
        ny, nx = self.frame.shape
        r0, r1, _ = rows.indices(ny)
        c0, c1, _ = cols.indices(nx)
        size = _CELL.itemsize
        out = np.empty((r1 - r0, c1 - c0), dtype=_CELL)
        buf = memoryview(out).cast("B")
        if c1 - c0 == nx:
            _read_all(self._fd, buf, r0 * nx * size)
            return out
        step = (c1 - c0) * size
        for i in range(r1 - r0):
            _read_all(self._fd, buf[i * step : (i + 1) * step], ((r0 + i) * nx + c0) * size)
        return out

    def put(self, dst: tuple[slice, slice], grid, cells, src: tuple[slice, slice]) -> None:
        """Write cells ``src`` of a block's ``grid`` and ``cells`` to the grid's cells ``dst``.

        Parameters
        ----------
        dst : (slice, slice)
            Rows and columns of this grid (steps of 1, within it).
        grid : Grid
            A block's grid; its fields ``[src]`` have ``dst``'s shape.
        cells : CellUncertainty
            The block's cell uncertainty, shaped like ``grid``.
        src : (slice, slice)
        """
        self.put_records(dst, cell_records(grid, cells, src))

    def put_records(self, dst: tuple[slice, slice], records: np.ndarray) -> None:
        """Write :func:`cell_records` ``(rows, cols)`` to the grid's cells ``dst``."""
        rows, cols = dst
        r0, r1, _ = rows.indices(self.frame.shape[0])
        c0, c1, _ = cols.indices(self.frame.shape[1])
        if records.dtype != _CELL or records.shape != (r1 - r0, c1 - c0):
            raise ValueError(f"records {records.dtype} {records.shape} for cells {dst}")
        self._pwrite(records, r0, c0)

    def layer(self, name: str, rows: slice, cols: slice, overlay=None) -> np.ndarray:
        """A window of layer ``name`` as :func:`~pipeline.outputs.raster.grid_layers` gives it.

        Parameters
        ----------
        name : str
            A key of :func:`~pipeline.outputs.raster.grid_layers`.
        rows, cols : slice
        overlay : Overlay or CellUncertainty, optional
            Cells (of the whole grid, or of some of its rows and columns: :class:`Overlay`)
            whose ``tvu95_m``, ``thu95_m`` and ``order`` replace the stored ones where their
            ``n_posterior > 0`` (the sample's posterior cells).

        Returns
        -------
        (r, c) float64
            NaN where the cell has no value (``iho_order``: code -1).
        """
        a = self._pread(rows, cols)[name]
        if overlay is not None and _SOURCES[name][0] == "cells":
            ov = overlay if isinstance(overlay, Overlay) else Overlay(overlay)
            sampled, values = ov.window(_SOURCES[name][1], rows, cols, self.frame.shape)
            a = np.where(sampled, values, a)
        a = a.astype(np.float64)
        return np.where(a < 0, np.nan, a) if name == "iho_order" else a

    def windows(self):
        """``(rows, cols)`` slices of the :data:`TILE`-cell windows, row by row from the north."""
        ny, nx = self.frame.shape
        for r0 in range(0, ny, TILE):
            for c0 in range(0, nx, TILE):
                yield slice(r0, min(r0 + TILE, ny)), slice(c0, min(c0 + TILE, nx))

    def write_tif(self, path: str | Path, overlay=None) -> Path:
        """Write ``grid.tif`` (:func:`~pipeline.outputs.raster.write_grid_tif`'s), atomically."""
        import rasterio
        from rasterio.windows import Window

        from pipeline.outputs.raster import (
            TIF_BANDS,
            copy_as_cog,
            describe_tif,
            tif_band,
            tif_profile,
        )

        profile = tif_profile(self.frame)
        with (
            tempfile.TemporaryDirectory(prefix="bathy-tif-", dir=self._folder) as d,
            rasterio.Env(GDAL_CACHEMAX=_GDAL_CACHE_MB),
        ):
            source, cog = Path(d) / "source.tif", Path(d) / "grid.tif"
            tiled = {"tiled": True, "blockxsize": TILE, "blockysize": TILE}
            with rasterio.open(source, "w", **profile, **tiled) as dst:
                for rows, cols in self.windows():
                    window = Window.from_slices(rows, cols)
                    for i, (name, _) in enumerate(TIF_BANDS, start=1):
                        band = tif_band(self.layer(name, rows, cols, overlay))
                        dst.write(band, i, window=window)
                describe_tif(dst, self.frame)
            with rasterio.open(source) as src:
                copy_as_cog(src, str(cog), self.frame.shape)
            source.unlink()
            _copy_atomically(cog, Path(path))
        return Path(path)

    def write_nc(self, path: str | Path, overlay=None) -> Path:
        """Write ``grid.nc`` (:func:`~pipeline.outputs.netcdf.write_grid_nc`'s), atomically."""
        import dask
        import dask.array as da
        import netCDF4

        from pipeline.outputs.netcdf import NC_VARIABLES, grid_dataset, save_grid_nc

        ny, nx = self.frame.shape
        chunks = (min(ny, TILE), min(nx, TILE))
        variables = {
            name: da.from_array(
                _NcVariable(self, name, overlay),
                chunks=chunks,
                name=f"bathy-grid-{name}-{id(self):x}",
                lock=False,
                meta=np.empty((0, 0), dtype=NC_VARIABLES[name][1]),
            )
            for name in NC_VARIABLES
        }
        cache = netCDF4.get_chunk_cache()
        netCDF4.set_chunk_cache(_HDF5_CACHE_B)
        try:
            # one chunk at a time: the scheduler's threads would each hold one
            with dask.config.set(scheduler="synchronous"):
                save_grid_nc(path, grid_dataset(self.frame, variables))
        finally:
            netCDF4.set_chunk_cache(*cache)
        return Path(path)


class _NcVariable:
    """A ``grid.nc`` variable read window by window from :class:`GridTiles` (for dask)."""

    def __init__(self, tiles: GridTiles, name: str, overlay) -> None:
        from pipeline.outputs.netcdf import NC_VARIABLES

        self.tiles, self.name, self.overlay = tiles, name, overlay
        self.layer_name, dtype = NC_VARIABLES[name]
        self.dtype, self.shape, self.ndim = np.dtype(dtype), tiles.frame.shape, 2

    def __getitem__(self, key: tuple[slice, slice]) -> np.ndarray:
        from pipeline.outputs.netcdf import nc_variable

        rows, cols = key
        layer = self.tiles.layer(self.layer_name, rows, cols, self.overlay)
        return nc_variable(self.name, {self.layer_name: layer})


def _write_all(fd: int, buf: memoryview, offset: int) -> None:
    """``pwrite`` all of ``buf`` at ``offset`` (a write may be short)."""
    n = os.pwrite(fd, buf, offset)
    while n < buf.nbytes:  # rare: a short write
        buf, offset = buf[n:], offset + n
        n = os.pwrite(fd, buf, offset)


def _read_all(fd: int, buf: memoryview, offset: int) -> None:
    """``preadv`` into all of ``buf`` from ``offset``."""
    n = os.preadv(fd, [buf], offset)
    while n < buf.nbytes:  # rare: a short read
        if n == 0:
            raise OSError(f"a grid layer ended at byte {offset}: its file is short")
        buf, offset = buf[n:], offset + n
        n = os.preadv(fd, [buf], offset)


def _copy_atomically(src: Path, path: Path) -> None:
    """Copy the file ``src`` to ``path`` by pieces, atomically (the umask's mode)."""
    with atomic_path(path) as tmp, open(src, "rb") as f, open(tmp, "wb") as g:
        shutil.copyfileobj(f, g, 1 << 20)
