"""The grid written by tiles (:mod:`pipeline.outputs.grid_tiles`): the in-memory writers' files.

Truth: a random grid and cell uncertainty held whole, with some cells overlaid by a random
"sample" (the blocked run's posterior cells), written by ``write_grid_tif``/``write_grid_nc``.
The tiles get the same cells as blocks' windows in random order, each cut out of a larger
block grid, and must write files of identical contents, whatever the blocks' size.
"""

from __future__ import annotations

import dataclasses
import tracemalloc
from types import SimpleNamespace

import numpy as np
import pytest
import rasterio

from pipeline.outputs.grid_tiles import GridFrame, GridTiles
from pipeline.outputs.netcdf import write_grid_nc
from pipeline.outputs.raster import write_grid_tif
from pipeline.process.grid import Grid
from pipeline.uncertainty.cell_uncertainty import CellUncertainty

netCDF4 = pytest.importorskip("netCDF4")

FRAME = GridFrame.over(
    np.array([-1000.0, 1650.0, -900.0, 2600.0]),
    5.0,
    (430_000.0, 6_120_000.0, 12.5),
    32619,
    -0.25,
    "median",
)  # 700 x 530 cells: windows of 256 that do not divide it


def assert_same_tif(a, b) -> None:
    """Two ``grid.tif`` files of identical contents: values, overviews and metadata."""
    with rasterio.open(a) as r, rasterio.open(b) as s:
        assert r.profile == s.profile
        assert r.crs == s.crs and r.transform == s.transform and r.nodata == s.nodata
        assert r.descriptions == s.descriptions and r.units == s.units
        for ns in (None, "IMAGE_STRUCTURE"):
            assert r.tags(ns=ns) == s.tags(ns=ns), ns
        for i in r.indexes:
            assert r.tags(i) == s.tags(i)
            assert r.overviews(i) == s.overviews(i) and r.overviews(i)
        np.testing.assert_array_equal(r.read(), s.read())
        levels = len(r.overviews(1))
    for k in range(levels):
        with rasterio.open(a, overview_level=k) as r, rasterio.open(b, overview_level=k) as s:
            np.testing.assert_array_equal(r.read(), s.read(), err_msg=f"overview {k}")


def _attrs(x) -> dict:
    return {k: np.asarray(x.getncattr(k)).tolist() for k in x.ncattrs()}


def assert_same_nc(a, b) -> None:
    """Two ``grid.nc`` files of identical contents: variables, attributes, coordinates."""
    with netCDF4.Dataset(a) as r, netCDF4.Dataset(b) as s:
        r.set_auto_mask(False)
        s.set_auto_mask(False)
        assert _attrs(r) == _attrs(s)
        assert {k: len(d) for k, d in r.dimensions.items()} == {
            k: len(d) for k, d in s.dimensions.items()
        }
        assert list(r.variables) == list(s.variables)
        for name, v in r.variables.items():
            w = s.variables[name]
            assert (v.dtype, v.dimensions) == (w.dtype, w.dimensions), name
            assert _attrs(v) == _attrs(w), name
            assert v.chunking() == w.chunking() and v.filters() == w.filters(), name
            np.testing.assert_array_equal(v[...], w[...], err_msg=name)


def random_cells(rng, shape):
    """A random grid over :data:`FRAME` and its cells: empty cells, NaN spreads, every code."""
    has = rng.random(shape) < 0.7
    depth = np.where(has, rng.uniform(0.1, 40.0, shape), np.nan)
    count = np.where(has, rng.integers(1, 60, shape), 0)
    spread = np.where(count >= 2, rng.uniform(0.0, 0.5, shape), np.nan)
    f = FRAME
    grid = Grid(
        depth_m=depth,
        median_depth_m=np.where(has, depth + rng.normal(0, 0.01, shape), np.nan),
        spread_m=spread,
        z_m=-depth,
        count=count.astype(np.int64),
        x_m=f.x_m,
        y_m=f.y_m,
        resolution_m=f.resolution_m,
        bounds_m=f.bounds_m,
        origin_m=f.origin_m,
        crs=f.crs,
        datum_m=f.datum_m,
        statistic=f.statistic,
    )
    tvu = np.where(has, rng.uniform(0.05, 2.0, shape), np.nan)
    thu = np.where(has, rng.uniform(0.2, 5.0, shape), np.nan)
    cells = CellUncertainty(
        sigma_v_m=tvu / 1.96,
        sigma_h_m=thu / 2.45,
        tvu95_m=tvu,
        thu95_m=thu,
        count=count.astype(np.int64),
        n_posterior=np.zeros(shape, np.int64),
        order=np.where(has, rng.integers(0, 5, shape), -1).astype(np.int8),
    )
    return grid, cells


def overlaid(cells, sample):
    """``cells`` with ``sample``'s where it has a posterior (the blocked run's delivery)."""
    s = sample.n_posterior > 0
    return dataclasses.replace(
        cells,
        **{
            k.name: np.where(s, getattr(sample, k.name), getattr(cells, k.name))
            for k in dataclasses.fields(cells)
        },
    )


def _cut(a, window, shape, own, rng):
    """``a[window]`` at ``own`` of an array of ``shape``, garbage elsewhere (a block's halo)."""
    out = rng.normal(size=shape).astype(a.dtype)
    out[own] = a[window]
    return out


def fill_by_blocks(tiles, grid, cells, block, rng, skip=()):
    """Put every block of side ``block`` (but ``skip``) in random order, each cut out of a
    larger block grid whose other cells are garbage."""
    ny, nx = grid.shape
    starts = [(r, c) for r in range(0, ny, block) for c in range(0, nx, block)]
    for k in rng.permutation(len(starts)):
        if k in skip:
            continue
        r0, c0 = starts[k]
        r1, c1 = min(r0 + block, ny), min(c0 + block, nx)
        pad = int(rng.integers(0, 7))
        shape = (r1 - r0 + 2 * pad, c1 - c0 + 2 * pad)
        own = (slice(pad, pad + r1 - r0), slice(pad, pad + c1 - c0))

        window = (slice(r0, r1), slice(c0, c1))
        fields = ("depth_m", "median_depth_m", "spread_m", "count")
        g = SimpleNamespace(**{k: _cut(getattr(grid, k), window, shape, own, rng) for k in fields})
        c = SimpleNamespace(
            **{
                k: _cut(getattr(cells, k), window, shape, own, rng)
                for k in ("tvu95_m", "thu95_m", "order")
            }
        )
        tiles.put((slice(r0, r1), slice(c0, c1)), g, c, own)


def emptied(grid, cells, block, skip):
    """``grid, cells`` with the blocks of ``skip`` empty (never processed)."""
    ny, nx = grid.shape
    starts = [(r, c) for r in range(0, ny, block) for c in range(0, nx, block)]
    g = {k: getattr(grid, k).copy() for k in ("depth_m", "median_depth_m", "spread_m", "count")}
    c = {k: getattr(cells, k).copy() for k in ("tvu95_m", "thu95_m", "order")}
    for k in skip:
        r0, c0 = starts[k]
        w = (slice(r0, r0 + block), slice(c0, c0 + block))
        for a in (*g.values(), *c.values()):
            a[w] = {np.dtype(np.int8): -1, np.dtype(np.int64): 0}.get(a.dtype, np.nan)
    return dataclasses.replace(grid, **g), dataclasses.replace(cells, **c)


@pytest.mark.parametrize("block", [61, 256, 1000])
def test_tiles_filled_by_blocks_write_the_in_memory_writers_files(tmp_path, block):
    rng = np.random.default_rng(block)
    grid, cells = random_cells(rng, FRAME.shape)
    sample = dataclasses.replace(
        random_cells(rng, FRAME.shape)[1],
        n_posterior=(rng.random(FRAME.shape) < 0.2).astype(np.int64),
    )
    skip = (1,) if block < 1000 else ()  # a block never processed stays empty
    grid, cells = emptied(grid, cells, block, skip)
    want, got = tmp_path / "memory", tmp_path / "tiles"
    out_cells = overlaid(cells, sample)
    write_grid_tif(want / "grid.tif", grid, out_cells)
    write_grid_nc(want / "grid.nc", grid, out_cells)
    with GridTiles(FRAME, folder=tmp_path) as tiles:
        fill_by_blocks(tiles, grid, cells, block, rng, skip)
        tiles.write_tif(got / "grid.tif", sample)
        tiles.write_nc(got / "grid.nc", sample)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["memory", "tiles"]  # nothing left
    assert_same_tif(want / "grid.tif", got / "grid.tif")
    assert_same_nc(want / "grid.nc", got / "grid.nc")


def test_tiles_without_an_overlay_write_the_blocks_cells(tmp_path):
    rng = np.random.default_rng(3)
    grid, cells = random_cells(rng, FRAME.shape)
    write_grid_tif(tmp_path / "a.tif", grid, cells)
    write_grid_nc(tmp_path / "a.nc", grid, cells)
    with GridTiles(FRAME) as tiles:
        fill_by_blocks(tiles, grid, cells, 300, rng)
        tiles.write_tif(tmp_path / "b.tif")
        tiles.write_nc(tmp_path / "b.nc")
    assert_same_tif(tmp_path / "a.tif", tmp_path / "b.tif")
    assert_same_nc(tmp_path / "a.nc", tmp_path / "b.nc")


def test_the_frame_is_the_grid_of_its_bounds():
    from pipeline.process.grid import grid_points

    g = grid_points(
        [1.0],
        [1.0],
        [3.0],
        resolution_m=5.0,
        bounds_m=FRAME.bounds_m,
        origin_m=FRAME.origin_m,
        crs=32619,
    )
    assert g.shape == FRAME.shape and g.transform == FRAME.transform
    np.testing.assert_array_equal(g.x_m, FRAME.x_m)
    np.testing.assert_array_equal(g.y_m, FRAME.y_m)
    assert g.crs == FRAME.crs


def test_filling_a_large_grid_holds_about_one_block(tmp_path):
    # 4000 x 4000 cells by blocks of 200 x 200: the in-memory accumulator held ~13 arrays of
    # the whole area (~1.6 GB here); the tiles hold one block's window at a time
    n, block = 4000, 200
    frame = GridFrame.over(
        np.array([0.0, 5.0 * n, 0.0, 5.0 * n]), 5.0, (0, 0, 0), 32619, 0.0, "median"
    )
    rng = np.random.default_rng(0)
    ones = np.ones((block, block))
    g = SimpleNamespace(
        depth_m=rng.uniform(1, 30, (block, block)),
        median_depth_m=ones,
        spread_m=ones,
        count=np.full((block, block), 3, np.int64),
    )
    c = SimpleNamespace(tvu95_m=ones, thu95_m=ones, order=np.ones((block, block), np.int8))
    one_block_b = sum(a.nbytes for a in (*vars(g).values(), *vars(c).values()))  # 1.9 MB
    tracemalloc.start()
    try:
        with GridTiles(frame, folder=tmp_path) as tiles:
            for r0 in range(0, n, block):
                for c0 in range(0, n, block):
                    w = (slice(r0, r0 + block), slice(c0, c0 + block))
                    tiles.put(w, g, c, (slice(None), slice(None)))
            _, peak = tracemalloc.get_traced_memory()
            # a spot check that the blocks went where they belong
            got = tiles.layer("depth_m", slice(3800, 4000), slice(200, 400))
            np.testing.assert_array_equal(got, g.depth_m.astype(np.float32))
    finally:
        tracemalloc.stop()
    # one layer's copy of a block, the empty cells' strip (1 MiB), and bookkeeping
    assert peak < one_block_b + (2 << 20), peak


@pytest.mark.parametrize("way", ["anonymous", "beside"])
def test_tiles_write_atomically_with_the_umasks_mode(tmp_path, monkeypatch, way):
    import os
    import stat

    from pipeline.outputs import atomic, grid_tiles

    if way == "beside":  # the fallbacks: named files beside the target and for the cells
        monkeypatch.setattr(atomic, "_anonymous_file", lambda folder: None)
        monkeypatch.setattr(grid_tiles, "anonymous_file", lambda folder: None)
    rng = np.random.default_rng(5)
    grid, cells = random_cells(rng, FRAME.shape)
    old = os.umask(0o027)
    try:
        (tmp_path / "tmp").mkdir()
        with GridTiles(FRAME, folder=tmp_path / "tmp") as tiles:
            fill_by_blocks(tiles, grid, cells, 400, rng)
            named = list((tmp_path / "tmp").iterdir())
            assert len(named) == (way == "beside")  # the cells' file has a name only there
            out = tmp_path / "out"
            tiles.write_tif(out / "grid.tif")
            tiles.write_nc(out / "grid.nc")
    finally:
        os.umask(old)
    assert sorted(p.name for p in out.iterdir()) == ["grid.nc", "grid.tif"]  # nothing else
    assert list((tmp_path / "tmp").iterdir()) == []
    for name in ("grid.nc", "grid.tif"):
        assert stat.S_IMODE((out / name).stat().st_mode) == 0o640


def test_the_tiles_netcdf_is_the_same_file_every_time(tmp_path):
    # the same cells written twice: the same bytes (dask stores its variables' chunks in an
    # order its random task keys set, and HDF5 lays the chunks out as they come)
    rng = np.random.default_rng(8)
    grid, cells = random_cells(rng, FRAME.shape)
    sample = dataclasses.replace(
        random_cells(rng, FRAME.shape)[1],
        n_posterior=(rng.random(FRAME.shape) < 0.2).astype(np.int64),
    )
    with GridTiles(FRAME) as tiles:
        fill_by_blocks(tiles, grid, cells, 256, rng)
        for name in ("a.nc", "b.nc", "c.nc"):
            tiles.write_nc(tmp_path / name, sample)
    first = (tmp_path / "a.nc").read_bytes()
    assert (tmp_path / "b.nc").read_bytes() == first
    assert (tmp_path / "c.nc").read_bytes() == first
