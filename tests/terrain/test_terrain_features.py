"""Seabed features (IHO cubes, wreck, ridge, channel) and the beach/shoreline."""

import math

import numpy as np
import pytest

from terrain import (
    IHO_CUBE_SIDES_M,
    Beach,
    Ridge,
    channel,
    compose,
    cube,
    plane_seabed,
    ridge,
    wreck,
)


@pytest.mark.parametrize("side", IHO_CUBE_SIDES_M)
def test_cube_stands_on_seabed(side):
    seabed = compose(plane_seabed(15.0), cube(10.0, -4.0, side))
    inside = seabed.height_m(10.0 + 0.49 * side, -4.0 - 0.49 * side)
    outside = seabed.height_m(10.0 + 0.51 * side, -4.0)
    assert float(inside) == -15.0 + side and float(outside) == -15.0


def test_wreck_heading_rotates_footprint():
    w = wreck(0.0, 0.0, length_m=40.0, width_m=8.0, height_m=6.0, heading_rad=math.pi / 2)
    # heading east: long axis along x
    assert float(w.height_m(19.0, 0.0)) == 6.0 and float(w.height_m(0.0, 19.0)) == 0.0
    corners = w.footprint_m
    # corners at (+-20, +-4), counter-clockwise (positive shoelace area = 40 * 8); rounding
    area = 0.5 * np.sum(
        corners[:, 0] * np.roll(corners[:, 1], -1) - np.roll(corners[:, 0], -1) * corners[:, 1]
    )
    assert area == pytest.approx(320.0, abs=1e-9)
    np.testing.assert_allclose(np.sort(np.abs(corners), axis=0)[0], [20.0, 4.0], atol=1e-12)


@pytest.mark.parametrize("profile", ["gaussian", "triangular"])
def test_ridge_and_channel_profiles(profile):
    az = math.radians(30)
    r = ridge(5.0, 5.0, az, height_m=2.0, width_m=4.0, profile=profile)
    # across-axis unit vector (azimuth + 90 deg)
    ux, uy = math.cos(az), -math.sin(az)
    d = np.array([0.0, 2.0, -2.0])
    h = r.height_m(5.0 + d * ux, 5.0 + d * uy)
    # crest height and half height at half the FWHM; rounding only
    np.testing.assert_allclose(h, [2.0, 1.0, 1.0], atol=1e-12)
    # along the axis nothing changes (infinite line)
    assert float(r.height_m(5.0 + 100 * math.sin(az), 5.0 + 100 * math.cos(az))) == pytest.approx(
        2.0
    )
    c = channel(0.0, 0.0, 0.0, depth_m=3.0, width_m=10.0, profile=profile)
    assert float(c.height_m(0.0, 50.0)) == pytest.approx(-3.0, abs=1e-12)  # rounding only


def test_feature_gradients_match_finite_differences():
    rng = np.random.default_rng(2)
    x, y = rng.uniform(-10, 10, (2, 500))
    h = 1e-6
    for feat in (
        Ridge(1.0, 2.0, 0.3, 1.5, 3.0, "gaussian", length_m=8.0),
        Beach(
            0.0,
            0.0,
            2.0,
            0.05,
            berm_height_m=1e9,
            dune_height_m=2.0,
            dune_distance_m=5.0,
            dune_width_m=8.0,
        ),
    ):
        gx, gy = feat.gradient(x, y)
        fx = (feat.height_m(x + h, y) - feat.height_m(x - h, y)) / (2 * h)
        fy = (feat.height_m(x, y + h) - feat.height_m(x, y - h)) / (2 * h)
        # central differences with h = 1e-6 m: truncation ~h**2, rounding ~1e-16/1e-6 = 1e-10
        np.testing.assert_allclose(gx, fx, atol=1e-7)
        np.testing.assert_allclose(gy, fy, atol=1e-7)


def test_finite_ridge_has_rounded_ends():
    r = Ridge(0.0, 0.0, 0.0, 1.0, 2.0, "triangular", length_m=10.0)  # along y from -5 to 5
    assert float(r.height_m(0.0, 4.9)) == pytest.approx(1.0)  # on the segment: crest
    assert float(r.height_m(0.0, 6.0)) == pytest.approx(0.5)  # 1 m past the end: half height
    assert float(r.height_m(0.0, 8.0)) == 0.0


def test_beach_shoreline_depth_zero_and_land_above_water():
    beach = Beach(
        100.0,
        50.0,
        seaward_azimuth_rad=math.pi,
        beach_gradient=0.02,
        shoreline_z_m=0.3,
        berm_height_m=2.0,
        dune_height_m=4.0,
        dune_distance_m=150.0,
        dune_width_m=60.0,
    )
    # the shoreline runs east-west through (100, 50); sea to the south
    xs = np.linspace(-1e3, 1e3, 11)
    # depth (water level 0.3 minus seabed) is zero on the line: rounding only
    np.testing.assert_allclose(beach.height_m(xs, 50.0), 0.3, atol=1e-12)
    seaward = beach.height_m(xs, 50.0 - 200.0)
    np.testing.assert_allclose(0.3 - seaward, 0.02 * 200.0, atol=1e-12)  # depth = gradient * s
    land = beach.height_m(100.0, 50.0 + np.array([10.0, 100.0, 150.0, 300.0]))
    # foreshore, berm, dune crest, berm behind the dune
    np.testing.assert_allclose(land, [0.5, 2.3, 6.3, 2.3], atol=1e-12)
    assert np.all(land > 0.3)


def test_feature_argument_errors():
    with pytest.raises(ValueError, match="`side_m` must be > 0; got -1"):
        cube(0, 0, -1)
    with pytest.raises(ValueError, match="`profile` must be one of"):
        Ridge(0, 0, 0, 1, 1, "square")
    with pytest.raises(ValueError, match="`dune_width_m` must be <="):
        Beach(0, 0, 0, 0.1, dune_height_m=1, dune_distance_m=5, dune_width_m=20)
