"""LocalFrame: float64 round trips with UTM-sized coordinates, CRS kept."""

import numpy as np
import pyproj
import pytest

from terrain import LocalFrame


def test_round_trip_utm_sized_coordinates():
    frame = LocalFrame(512_345.678, 5_712_345.678, 32633, origin_height_m=-1.5)
    rng = np.random.default_rng(0)
    e = frame.origin_easting_m + rng.uniform(-20_000, 20_000, 10_000)
    n = frame.origin_northing_m + rng.uniform(-20_000, 20_000, 10_000)
    x, y = frame.to_local(e, n)
    assert x.dtype == np.float64 and np.abs(x).max() <= 20_000
    e2, n2 = frame.to_world(x, y)
    # world -> local is exact (Sterbenz) and back is exact too: any error would be an ulp
    # of the northing (9.3e-10 m); the requirement is 1e-9 m
    assert np.abs(e2 - e).max() <= 1e-9 and np.abs(n2 - n).max() <= 1e-9
    xl, yl = rng.uniform(-20_000, 20_000, (2, 10_000))
    x2, y2 = frame.to_local(*frame.to_world(xl, yl))
    # local -> world rounds once to half an ulp of the world value (4.7e-10 m)
    assert np.abs(x2 - xl).max() <= 1e-9 and np.abs(y2 - yl).max() <= 1e-9
    assert float(frame.height_to_world(frame.height_to_local(3.25))) == 3.25


@pytest.mark.parametrize("crs", [32633, "EPSG:32633", pyproj.CRS(32633).to_wkt()])
def test_crs_retained(crs):
    frame = LocalFrame(500_000.0, 5_000_000.0, crs)
    assert isinstance(frame.crs, pyproj.CRS)
    assert frame.crs.equals(pyproj.CRS.from_epsg(32633))


def test_lonlat_round_trip():
    frame = LocalFrame(500_000.0, 5_000_000.0, 32633)
    lon, lat = frame.to_lonlat(0.0, 0.0)
    # central meridian of UTM zone 33 is 15 E; projection round trip to 1e-9 deg
    assert float(lon) == pytest.approx(15.0, abs=1e-9)
    x, y = frame.from_lonlat(lon, lat)
    assert abs(float(x)) < 1e-6 and abs(float(y)) < 1e-6  # projection round trip, ~1e-9 m


def test_bad_crs_and_origin_raise():
    with pytest.raises(ValueError, match="projected CRS"):
        LocalFrame(0.0, 0.0, 4326)
    with pytest.raises(ValueError, match="not a valid CRS"):
        LocalFrame(0.0, 0.0, "no such crs")
    with pytest.raises(ValueError, match="`origin_easting_m` must be finite"):
        LocalFrame(float("inf"), 0.0, 32633)
