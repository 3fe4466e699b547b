"""Feature detection and the grid as seabed elevation, against analytic truths."""

import math
from types import SimpleNamespace

import numpy as np

from pipeline.evaluate_features import (
    cube_detection,
    feature_summary,
    features_report,
    grid_elevation_errors_m,
)
from pipeline.process.grid import grid_points

# a 2 m cube at (10, 10) turned 45 degrees on a flat seabed 5 m deep: its top 3 m deep
CUBE = SimpleNamespace(kind="cube", x_m=10.0, y_m=10.0, size_m=2.0, heading_deg=45.0)
RIDGE = SimpleNamespace(kind="ridge", x_m=0.0, y_m=0.0, size_m=1.0, heading_deg=0.0)


def truth_depth(x, y):
    c, s = math.cos(math.pi / 4), math.sin(math.pi / 4)
    along = (x - 10.0) * s + (y - 10.0) * c
    across = (x - 10.0) * c - (y - 10.0) * s
    return np.where((np.abs(along) <= 1.0) & (np.abs(across) <= 1.0), 3.0, 5.0)


def points(xy, depth, cls):
    xy, depth = np.asarray(xy, float), np.asarray(depth, float)
    return SimpleNamespace(
        xyz_m=np.c_[xy, -depth], depth_m=depth, classification=np.asarray(cls, dtype=np.uint8)
    )


def test_points_on_the_top_inside_the_rotated_footprint_detect_a_cube():
    xy = [
        [10.5, 10.0],  # inside, 0.9 m below the top: nearer the top than the seabed (s/2 = 1)
        [10.9, 10.9],  # inside the unrotated square, outside the turned one (along 1.27 m)
        [10.0, 10.5],  # inside, at the seabed's depth: the cube missed
        [10.0, 9.5],  # inside, on the top, but class 1 (not a sounding)
        [10.0, 9.7],  # inside, on the top, class 43
    ]
    pts = points(xy, [3.9, 3.0, 5.0, 3.0, 3.05], [40, 40, 40, 1, 43])
    (c,) = cube_detection((CUBE, RIDGE), pts, truth_depth)
    assert c["top_depth_m"] == 3.0 and c["base_depth_m"] == 5.0
    assert c["points_in_footprint"] == 3 and c["points_on_top"] == 2
    assert c["object_points"] == 1 and c["detected"] and not c["grid_shows"]
    # the footprint grown by 1 m on each side is 4 m x 4 m: 4 soundings (class 1 not counted)
    assert c["density_per_m2"] == 4 / 16
    # soundings that measured the seabed around it (1.1 m or more below the top) do not
    pts = points(xy, [4.1, 3.0, 5.0, 3.0, 4.5], [40, 40, 40, 1, 40])
    (c,) = cube_detection((CUBE,), pts, truth_depth)
    assert c["points_on_top"] == 0 and not c["detected"] and c["object_points"] == 0


def test_a_grid_cell_shallower_than_its_neighbours_shows_a_cube():
    # 1 m cells; soundings of the analytic seabed at every cell's centre, a 2 m unrotated cube
    cube = SimpleNamespace(kind="cube", x_m=10.5, y_m=10.5, size_m=2.0, heading_deg=0.0)
    x, y = np.meshgrid(np.arange(5.5, 16, 1.0), np.arange(5.5, 16, 1.0))
    x, y = x.ravel(), y.ravel()
    depth = np.where((np.abs(x - 10.5) <= 1.0) & (np.abs(y - 10.5) <= 1.0), 3.0, 5.0)
    grid = grid_points(x, y, depth, resolution_m=1.0, bounds_m=(5, 16, 5, 16))
    pts = points(np.c_[x, y], depth + 1.5, np.full(x.size, 40))  # soundings all off the top
    (c,) = cube_detection((cube,), pts, lambda x, y: np.full(np.shape(x), 5.0), grid)
    # the 3x3 cells of the cube's top are 3 m deep; the centre cell's 8 neighbours too: no
    # step there; a 2 m cube on 1 m cells fills the ring, so only a cube near one cell shows
    assert c["grid_cell_depth_m"] == 3.0 and not c["grid_shows"]
    small = SimpleNamespace(kind="cube", x_m=10.5, y_m=10.5, size_m=1.0, heading_deg=0.0)
    depth1 = np.where((np.abs(x - 10.5) <= 0.5) & (np.abs(y - 10.5) <= 0.5), 4.0, 5.0)
    grid1 = grid_points(x, y, depth1, resolution_m=1.0, bounds_m=(5, 16, 5, 16))
    (c1,) = cube_detection((small,), pts, lambda x, y: np.full(np.shape(x), 5.0), grid1)
    assert c1["grid_cell_depth_m"] == 4.0 and c1["grid_around_depth_m"] == 5.0
    assert c1["grid_shows"] and c1["detected"] and c1["points_on_top"] == 0


def test_summary_counts_class_43_away_from_cubes():
    pts = points([[10.0, 10.0], [30.0, 30.0], [10.0, 11.9]], [3.0, 4.0, 5.0], [43, 43, 43])
    cubes = cube_detection((CUBE,), pts, truth_depth)
    s = feature_summary(cubes, pts, (CUBE,))
    assert s["cubes_by_size"]["2"] == {"n": 1, "detected": 1, "points": 1, "grid": 0, "class43": 1}
    # (10, 11.9) is 1.34 m along the turned cube's axis: inside its footprint grown by 1 m
    assert s["object_points"] == 3 and s["object_points_elsewhere"] == 1


def test_grid_elevation_against_an_analytic_seabed():
    rng = np.random.default_rng(2)
    x, y = rng.uniform(0, 20, 4000), rng.uniform(0, 20, 4000)

    def seabed_z(x, y):
        return -6.0 - 0.1 * x + 0.05 * y

    z = seabed_z(x, y) + rng.normal(0, 0.02, x.size)
    grid = grid_points(x, y, -z, z, resolution_m=2.0, bounds_m=(0, 20, 0, 20))
    err = grid_elevation_errors_m(grid, seabed_z)
    assert err.size == 100 and np.max(np.abs(err)) < 0.1
    # a grid lifted by 0.3 m is 0.3 m above the seabed everywhere
    lifted = grid_points(x, y, -z - 0.3, z + 0.3, resolution_m=2.0, bounds_m=(0, 20, 0, 20))
    np.testing.assert_allclose(grid_elevation_errors_m(lifted, seabed_z) - err, 0.3, atol=1e-9)
    scene = SimpleNamespace(seabed=SimpleNamespace(features=(CUBE,)))
    pts = points(np.c_[x, y], -z, np.full(x.size, 40))
    rep = features_report(scene, pts, truth_depth, grid, truth_depth, seabed_z)
    assert rep["grid_elevation"]["n"] == 100
    assert rep["features"]["cubes"][0]["size_m"] == 2.0
