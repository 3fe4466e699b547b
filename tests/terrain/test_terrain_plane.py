"""Planar seabed: analytic heights and the slope/aspect conventions."""

import math

import numpy as np
import pytest

from terrain import Plane, compose, plane_seabed


def test_height_matches_plane_formula_at_random_points():
    rng = np.random.default_rng(1)
    depth, slope, aspect = 12.5, 0.05, 1.1
    p = plane_seabed(depth, slope_rad=slope, aspect_rad=aspect)
    x, y = rng.uniform(-5e3, 5e3, (2, 1000))
    # independent formula: depth grows by tan(slope) per metre along (sin aspect, cos aspect)
    expected = -(depth + math.tan(slope) * (x * math.sin(aspect) + y * math.cos(aspect)))
    # 1e-9 m: a few float64 roundings of values ~ 1e2 m
    np.testing.assert_allclose(p.height_m(x, y), expected, rtol=0, atol=1e-9)


@pytest.mark.parametrize(
    ("aspect", "deeper_step"),
    [(0.0, (0, 1)), (math.pi / 2, (1, 0)), (math.pi, (0, -1)), (3 * math.pi / 2, (-1, 0))],
)
def test_aspect_is_downslope_azimuth_clockwise_from_north(aspect, deeper_step):
    p = plane_seabed(10.0, gradient=0.1, aspect_rad=aspect)
    z0 = p.height_m(0.0, 0.0)
    z1 = p.height_m(*deeper_step)
    # one metre downslope deepens by the gradient 0.1 m; 1e-12 covers rounding
    assert z1 - z0 == pytest.approx(-0.1, abs=1e-12)
    assert p.downslope_azimuth_rad == pytest.approx(aspect % (2 * math.pi), abs=1e-12)
    assert p.slope_rad == pytest.approx(math.atan(0.1), abs=1e-15)


def test_normal_is_unit_and_tilts_downslope():
    p = plane_seabed(5.0, gradient=0.2, aspect_rad=math.pi / 2)  # deepens eastward
    n = p.normal(np.zeros((3, 4)), np.zeros((3, 4)))
    assert n.shape == (3, 4, 3)
    # unit vectors to rounding
    np.testing.assert_allclose(np.linalg.norm(n, axis=-1), 1.0, atol=1e-15)
    expected = np.array([0.2, 0.0, 1.0]) / math.hypot(0.2, 1.0)
    np.testing.assert_allclose(n[0, 0], expected, atol=1e-15)  # rounding only


def test_flat_and_gradient_forms_agree():
    a = plane_seabed(3.0, slope_rad=math.atan(0.3), aspect_rad=2.0)
    b = plane_seabed(3.0, gradient=0.3, aspect_rad=2.0)
    assert a.dz_dx == pytest.approx(b.dz_dx, abs=1e-15)  # rounding of tan(atan(.))
    assert a.dz_dy == pytest.approx(b.dz_dy, abs=1e-15)
    flat = plane_seabed(7.0)
    assert float(flat.height_m(123.0, -45.0)) == -7.0


def test_composite_adds_heights_and_intersects_bounds():
    a = Plane(1.0, 0.1, 0.0, extent=(0, 10, 0, 20))
    b = Plane(2.0, 0.0, -0.2, extent=(5, 30, -5, 15))
    c = compose(a, b)
    assert c.bounds == (5, 10, 0, 15)
    assert float(c.height_m(6.0, 1.0)) == pytest.approx(3.0 + 0.6 - 0.2, abs=1e-12)  # rounding
    gx, gy = c.gradient(6.0, 1.0)
    assert (float(gx), float(gy)) == (0.1, -0.2)
    assert isinstance(a + b + a, type(c)) and len((a + b + a).parts) == 3
    with pytest.raises(ValueError, match="do not overlap"):
        compose(a, Plane(0.0, extent=(20, 30, 0, 1)))


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"depth_m": float("nan")}, "`depth_m` must be finite"),
        ({"depth_m": 1.0, "slope_rad": -0.1}, "`slope_rad` must be >= 0"),
        ({"depth_m": 1.0, "gradient": -1}, "`gradient` must be >= 0; got -1"),
        ({"depth_m": 1.0, "gradient": 0.1, "slope_rad": 0.1}, "at most one"),
    ],
)
def test_bad_plane_arguments_raise(kwargs, message):
    with pytest.raises(ValueError, match=message):
        plane_seabed(**kwargs)


def test_bad_query_points_raise():
    p = plane_seabed(1.0)
    with pytest.raises(ValueError, match="`x_m` must be finite"):
        p.height_m([0.0, np.inf], [0.0, 0.0])
    with pytest.raises(ValueError, match="broadcast"):
        p.height_m(np.zeros(3), np.zeros(4))
