"""grid.tif round trip (grid.nc: test_grid_outputs.py)."""

import numpy as np
import pyproj
import pytest
import rasterio

from pipeline.outputs.raster import NODATA, TIF_BANDS, read_grid_tif, write_grid_tif
from pipeline.process.grid import grid_points

ORIGIN = (500_000.0, 6_200_000.0, 0.0)


def sample_grid():
    rng = np.random.default_rng(1)
    n = 4000
    x = rng.uniform(0, 300, n)
    y = rng.uniform(0, 200, n)
    keep = (x - 150) ** 2 + (y - 100) ** 2 < 90**2  # a disc: empty corners
    x, y = x[keep], y[keep]
    d = 5 + 0.05 * x + rng.normal(0, 0.1, x.size)
    return grid_points(x, y, d, resolution_m=5.0, origin_m=ORIGIN, crs=25832)


def test_tif_round_trip(tmp_path):
    g = sample_grid()
    path = write_grid_tif(tmp_path / "grid.tif", g)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["grid.tif"]
    r = read_grid_tif(path)
    assert list(r.bands) == [name for name, _ in TIF_BANDS]
    assert r.units == dict(TIF_BANDS)
    # no cell uncertainty given: those bands are nodata throughout
    for name in ("tvu95_m", "thu95_m", "iho_order"):
        assert np.isnan(r.bands[name]).all()
    assert r.crs == pyproj.CRS.from_epsg(25832)
    assert r.nodata == NODATA
    assert tuple(r.transform)[:6] == pytest.approx(tuple(g.transform)[:6], abs=0)
    np.testing.assert_array_equal(r.origin_m, ORIGIN)
    # float32 storage: relative rounding 2**-24
    np.testing.assert_allclose(r.bands["depth_m"], g.depth_m, rtol=2**-23, equal_nan=True)
    np.testing.assert_allclose(r.bands["spread_m"], g.spread_m, rtol=2**-23, equal_nan=True)
    np.testing.assert_array_equal(r.bands["count"], g.count)  # exact in float32
    assert np.isnan(r.bands["depth_m"]).sum() == (g.count == 0).sum() > 0
    p = r.profile
    assert p["tiled"] and p["compress"].lower() == "deflate" and p["blockxsize"] == 256
    with rasterio.open(path) as src:
        assert src.tags(ns="IMAGE_STRUCTURE")["LAYOUT"] == "COG"


def test_tif_needs_crs(tmp_path):
    g = grid_points([0.5], [0.5], [3.0], resolution_m=1.0)
    with pytest.raises(ValueError, match="crs"):
        write_grid_tif(tmp_path / "grid.tif", g)
