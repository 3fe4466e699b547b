"""grid.nc (CF-1.8, read by xarray) and grid.tif (COG, read by rasterio) on a hand-built grid.

Truths are written here: the cell means of hand-placed depths and a hand-built per-cell
uncertainty; the CF and COG requirements are the conventions' own words.
"""

import numpy as np
import pyproj
import pytest
import rasterio

from pipeline.outputs.raster import write_grid_tif
from pipeline.process.grid import grid_points
from pipeline.uncertainty.cell_uncertainty import CellUncertainty

xr = pytest.importorskip("xarray")
pytest.importorskip("netCDF4")

ORIGIN = (400_000.0, 5_000_000.0, 0.0)
RES = 2.0


def hand_grid():
    """A 3 x 4 grid (2 m cells over x 0..8, y 0..6): three filled cells, the rest empty."""
    # cell (row 0, col 0): x 0-2, y 4-6: depths 4, 6 -> mean 5, spread sqrt(2)
    # cell (row 1, col 2): x 4-6, y 2-4: depth 10 alone
    # cell (row 2, col 3): x 6-8, y 0-2: depths 20, 21, 22 -> mean 21, spread 1
    x = [0.5, 1.5, 5.0, 7.0, 7.2, 7.4]
    y = [5.0, 5.5, 3.0, 1.0, 1.2, 1.4]
    d = [4.0, 6.0, 10.0, 20.0, 21.0, 22.0]
    g = grid_points(
        x, y, d, resolution_m=RES, bounds_m=(0.0, 8.0, 0.0, 6.0), origin_m=ORIGIN, crs=32632
    )
    assert g.shape == (3, 4)
    return g


def hand_cells(shape):
    nan = np.full(shape, np.nan)
    tvu, thu = nan.copy(), nan.copy()
    order = np.full(shape, -1, np.int8)
    count = np.zeros(shape, np.int64)
    for (r, c), v, h, o, n in (
        ((0, 0), 0.25, 0.8, 1, 2),
        ((1, 2), 0.5, 1.2, 2, 1),
        ((2, 3), 1.5, 3.0, 4, 3),
    ):
        tvu[r, c], thu[r, c], order[r, c], count[r, c] = v, h, o, n
    return CellUncertainty(
        sigma_v_m=tvu / 1.96,
        sigma_h_m=thu / 2.45,
        tvu95_m=tvu,
        thu95_m=thu,
        count=count,
        n_posterior=np.zeros(shape, np.int64),
        order=order,
    )


EXPECTED_DEPTH = np.array(
    [[5.0, np.nan, np.nan, np.nan], [np.nan, np.nan, 10.0, np.nan], [np.nan] * 3 + [21.0]]
)


def test_grid_nc_is_cf_and_holds_the_cells(tmp_path):
    from pipeline.outputs.netcdf import write_grid_nc

    g, cells = hand_grid(), hand_cells((3, 4))
    path = write_grid_nc(tmp_path / "grid.nc", g, cells)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["grid.nc"]
    with xr.open_dataset(path) as ds:
        assert ds.attrs["Conventions"] == "CF-1.8"
        # grid mapping: CF name, WKT for CF readers and for GDAL
        gm = ds["crs"].attrs
        assert gm["grid_mapping_name"] == "transverse_mercator"
        assert pyproj.CRS.from_wkt(gm["crs_wkt"]) == pyproj.CRS.from_epsg(32632)
        assert pyproj.CRS.from_wkt(gm["spatial_ref"]) == pyproj.CRS.from_epsg(32632)
        # coordinates: cell centres in world metres
        assert ds.x.attrs["standard_name"] == "projection_x_coordinate"
        assert ds.y.attrs["standard_name"] == "projection_y_coordinate"
        assert ds.x.attrs["units"] == ds.y.attrs["units"] == "m"
        np.testing.assert_allclose(ds.x.values, ORIGIN[0] + np.array([1.0, 3.0, 5.0, 7.0]))
        np.testing.assert_allclose(ds.y.values, ORIGIN[1] + np.array([5.0, 3.0, 1.0]))
        dep = ds["depth"]
        assert dep.attrs["standard_name"] == "sea_floor_depth_below_sea_surface"
        assert dep.attrs["units"] == "m" and dep.attrs["positive"] == "down"
        for name in ("depth", "tvu95", "thu95", "iho_order", "count", "spread"):
            assert ds[name].attrs["grid_mapping"] == "crs", name
            assert ds[name].dims == ("y", "x")
        np.testing.assert_allclose(dep.values, EXPECTED_DEPTH, rtol=1e-6)
        np.testing.assert_allclose(ds["tvu95"].values, cells.tvu95_m, rtol=1e-6)
        np.testing.assert_allclose(ds["thu95"].values, cells.thu95_m, rtol=1e-6)
        assert ds["tvu95"].attrs["units"] == ds["thu95"].attrs["units"] == "m"
        order = ds["iho_order"]
        np.testing.assert_array_equal(order.attrs["flag_values"], [0, 1, 2, 3, 4])
        meanings = order.attrs["flag_meanings"].split()
        assert len(meanings) == 5 and meanings[1] == "order_special"
        assert meanings[-1] == "no_order_met"
        np.testing.assert_array_equal(
            np.nan_to_num(order.values, nan=-1), [[1, -1, -1, -1], [-1, -1, 2, -1], [-1] * 3 + [4]]
        )
        np.testing.assert_array_equal(
            ds["count"].values, [[2, 0, 0, 0], [0, 0, 1, 0], [0, 0, 0, 3]]
        )
        spread = ds["spread"].values
        assert spread[0, 0] == pytest.approx(np.sqrt(2.0), rel=1e-6)
        assert spread[2, 3] == pytest.approx(1.0, rel=1e-6)
        assert ds["spread"].attrs["units"] == "m"


TIF_EXPECTED = (
    ("depth_m", "m"),
    ("tvu95_m", "m"),
    ("thu95_m", "m"),
    ("iho_order", "1"),
    ("count", "1"),
    ("spread_m", "m"),
)


def test_grid_tif_is_a_cog_with_every_band_described(tmp_path):
    g, cells = hand_grid(), hand_cells((3, 4))
    path = write_grid_tif(tmp_path / "grid.tif", g, cells)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["grid.tif"]
    with rasterio.open(path) as src:
        assert src.tags(ns="IMAGE_STRUCTURE").get("LAYOUT") == "COG"
        assert src.count == len(TIF_EXPECTED)
        for i in range(1, src.count + 1):
            assert src.overviews(i), f"band {i} has no overview"
        assert src.descriptions == tuple(n for n, _ in TIF_EXPECTED)
        assert src.units == tuple(u for _, u in TIF_EXPECTED)
        assert src.nodata == -9999.0
        assert pyproj.CRS.from_wkt(src.crs.to_wkt()) == pyproj.CRS.from_epsg(32632)
        assert tuple(src.transform)[:6] == (RES, 0.0, ORIGIN[0], 0.0, -RES, ORIGIN[1] + 6.0)
        band = {n: src.read(i + 1, masked=True) for i, (n, _) in enumerate(TIF_EXPECTED)}
    np.testing.assert_allclose(band["depth_m"].filled(np.nan), EXPECTED_DEPTH, rtol=1e-6)
    np.testing.assert_allclose(band["tvu95_m"].filled(np.nan), cells.tvu95_m, rtol=1e-6)
    np.testing.assert_allclose(band["thu95_m"].filled(np.nan), cells.thu95_m, rtol=1e-6)
    np.testing.assert_array_equal(
        band["iho_order"].filled(-1), [[1, -1, -1, -1], [-1, -1, 2, -1], [-1] * 3 + [4]]
    )
    np.testing.assert_array_equal(
        band["count"].filled(-1), [[2, 0, 0, 0], [0, 0, 1, 0], [0, 0, 0, 3]]
    )


def test_grid_tif_of_a_large_grid_has_overviews_down_to_one_tile(tmp_path):
    # 1000 x 700 cells: halvings until 256 fits: 1000 -> 500 -> 250: two levels
    n = 1000
    g = grid_points(
        np.linspace(0.5, n - 0.5, n),
        np.linspace(0.5, 699.5, n),
        np.full(n, 3.0),
        resolution_m=1.0,
        bounds_m=(0.0, float(n), 0.0, 700.0),
        origin_m=ORIGIN,
        crs=32632,
    )
    with rasterio.open(write_grid_tif(tmp_path / "grid.tif", g)) as src:
        assert src.overviews(1) == [2, 4]
        assert src.tags(ns="IMAGE_STRUCTURE").get("LAYOUT") == "COG"
        assert src.block_shapes[0] == (256, 256)
