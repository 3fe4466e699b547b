"""GeoTIFF DEM read: values at pixel centres, interpolation, CRS and refusals."""

import numpy as np
import pyproj
import pytest
import rasterio
from rasterio.transform import Affine

from terrain import LocalFrame, read_dem

WEST, NORTH, PIX = 650_000.0, 5_420_000.0, 2.0


def _write(path, z, crs="EPSG:32632", nodata=None):
    """Write a north-up GeoTIFF; pixel [r, c] has its corner at (WEST + c PIX, NORTH - r PIX)."""
    profile = {
        "driver": "GTiff",
        "height": z.shape[0],
        "width": z.shape[1],
        "count": 1,
        "dtype": "float64",
        "crs": crs,
        "transform": Affine(PIX, 0.0, WEST, 0.0, -PIX, NORTH),
    }
    if nodata is not None:
        profile["nodata"] = nodata
    with rasterio.open(path, "w", **profile) as ds:
        ds.write(z, 1)


def _centres(rows, cols):
    return WEST + (cols + 0.5) * PIX, NORTH - (rows + 0.5) * PIX


def test_values_at_pixel_centres_and_crs(tmp_path):
    rng = np.random.default_rng(4)
    z = -20.0 + rng.normal(0.0, 1.0, (30, 40))
    path = tmp_path / "dem.tif"
    _write(path, z)
    surf, frame = read_dem(path)
    assert frame.crs.equals(pyproj.CRS.from_epsg(32632))
    rows, cols = np.meshgrid(np.arange(30), np.arange(40), indexing="ij")
    e, n = _centres(rows, cols)
    x, y = frame.to_local(e, n)
    # the interpolating spline passes through every pixel value (prefilter rounding ~1e-13)
    np.testing.assert_allclose(surf.height_m(x, y), z, atol=1e-9)
    e0, n0 = frame.origin_easting_m, frame.origin_northing_m
    expected = (
        WEST + PIX / 2 - e0,
        WEST + 39.5 * PIX - e0,
        NORTH - 29.5 * PIX - n0,
        NORTH - PIX / 2 - n0,
    )
    assert surf.bounds == pytest.approx(expected, abs=1e-9)  # float64 translation rounding


def test_planar_dem_is_interpolated_exactly_with_given_frame(tmp_path):
    rows, cols = np.meshgrid(np.arange(25), np.arange(35), indexing="ij")
    e, n = _centres(rows, cols)
    z = 5.0 - 0.01 * (e - WEST) + 0.02 * (n - NORTH)
    path = tmp_path / "plane.tif"
    _write(path, z)
    frame = LocalFrame(WEST, NORTH, 32632, origin_height_m=1.0)
    surf, used = read_dem(path, frame=frame)
    assert used is frame
    rng = np.random.default_rng(0)
    ep = rng.uniform(WEST + PIX / 2, WEST + 34.5 * PIX, 500)
    nq = rng.uniform(NORTH - 24.5 * PIX, NORTH - PIX / 2, 500)
    truth = 5.0 - 0.01 * (ep - WEST) + 0.02 * (nq - NORTH) - 1.0
    # odd-reflection edges keep a plane to 0.268**16 of a cell's rise (~1e-11 m here)
    np.testing.assert_allclose(surf.height_m(*frame.to_local(ep, nq)), truth, atol=1e-8)
    gx, gy = surf.gradient(*frame.to_local(ep, nq))
    np.testing.assert_allclose(gx, -0.01, atol=1e-8)  # same edge-effect bound on slopes
    np.testing.assert_allclose(gy, 0.02, atol=1e-8)


def test_dem_refusals(tmp_path):
    z = np.zeros((5, 6))
    path = tmp_path / "a.tif"
    _write(path, z)
    with pytest.raises(ValueError, match="differs from the DEM"):
        read_dem(path, frame=LocalFrame(0.0, 0.0, 32633))
    surf, frame = read_dem(path)
    with pytest.raises(ValueError, match="`x_m` must lie within"):
        surf.height_m(1e4, 0.0)
    z[2, 3] = -9999.0
    bad = tmp_path / "nodata.tif"
    _write(bad, z, nodata=-9999.0)
    with pytest.raises(ValueError, match="1 nodata pixels"):
        read_dem(bad)
    with pytest.raises(ValueError, match="`band` must be <= 1"):
        read_dem(path, band=2)
