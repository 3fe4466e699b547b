"""Gridding against a brute-force loop over the cells."""

from types import SimpleNamespace

import numpy as np
import pytest

from pipeline.process.grid import grid_points, grid_seabed, snap_bounds_m
from pipeline.process.returns import Points


def brute_force(x, y, v, bounds, res):
    w, e, s, n = bounds
    nx, ny = round((e - w) / res), round((n - s) / res)
    mean = np.full((ny, nx), np.nan)
    med = np.full((ny, nx), np.nan)
    std = np.full((ny, nx), np.nan)
    cnt = np.zeros((ny, nx), int)
    for row in range(ny):
        for col in range(nx):
            x0, x1 = w + col * res, w + (col + 1) * res
            y1, y0 = n - row * res, n - (row + 1) * res
            sel = (x >= x0) & (x < x1) & (y > y0) & (y <= y1)
            vals = v[sel]
            cnt[row, col] = vals.size
            if vals.size:
                mean[row, col] = vals.mean()
                med[row, col] = np.median(vals)
            if vals.size >= 2:
                std[row, col] = vals.std(ddof=1)
    return mean, med, std, cnt


def test_matches_brute_force():
    rng = np.random.default_rng(0)
    n = 3000
    x = rng.uniform(-7.3, 12.1, n)
    y = rng.uniform(-4.0, 9.7, n)
    v = 10 + 0.1 * x + rng.normal(0, 0.2, n)
    origin = (500_000.0, 5_000_000.0, 0.0)
    g = grid_points(x, y, v, resolution_m=2.0, origin_m=origin, crs=32633)
    mean, med, std, cnt = brute_force(x, y, v, g.bounds_m, 2.0)
    np.testing.assert_array_equal(g.count, cnt)
    assert g.count.sum() == n  # default bounds enclose every point
    # summation order differs from numpy's: agree to a few ulps of ~10 m
    np.testing.assert_allclose(g.mean_depth_m, mean, rtol=0, atol=1e-12)
    np.testing.assert_allclose(g.median_depth_m, med, rtol=0, atol=0)
    np.testing.assert_allclose(g.depth_m, med, rtol=0, atol=0)  # the default statistic
    np.testing.assert_allclose(g.spread_m, std, rtol=0, atol=1e-12)
    np.testing.assert_allclose(g.z_m, -med, rtol=0, atol=1e-12)
    gm = grid_points(x, y, v, resolution_m=2.0, origin_m=origin, statistic="mean")
    np.testing.assert_allclose(gm.depth_m, mean, rtol=0, atol=1e-12)
    np.testing.assert_allclose(gm.z_m, -mean, rtol=0, atol=1e-12)
    # cell centres and world transform
    w, e, s, nn = g.bounds_m
    np.testing.assert_allclose(g.x_m, w + 1.0 + 2.0 * np.arange(g.shape[1]))
    np.testing.assert_allclose(g.y_m, nn - 1.0 - 2.0 * np.arange(g.shape[0]))
    assert g.transform.c == pytest.approx(w + origin[0]) and g.transform.e == -2.0
    assert (w + origin[0]) % 2.0 == 0.0 and (nn + origin[1]) % 2.0 == 0.0
    assert g.crs.to_epsg() == 32633


def test_given_bounds_and_edges():
    # points on the west/north edges are inside, on the east/south edges outside
    x = np.array([0.0, 1.0, 2.0, 0.5, 1.5])
    y = np.array([2.0, 1.0, 1.5, 0.0, 0.5])
    v = np.arange(5.0)
    g = grid_points(x, y, v, resolution_m=1.0, bounds_m=(0, 2, 0, 2))
    # (0, 2) -> row 0, col 0; (1, 1) and (1.5, 0.5) -> row 1, col 1; x = 2 and y = 0 are out
    np.testing.assert_array_equal(g.count, [[1, 0], [0, 2]])
    with pytest.raises(ValueError, match="whole cells"):
        grid_points(x, y, v, resolution_m=1.5, bounds_m=(0, 2, 0, 2))


def test_snap_includes_max_on_a_multiple():
    b = snap_bounds_m(np.array([0.0, 4.0]), np.array([0.0, 4.0]), 2.0)
    np.testing.assert_array_equal(b, [0.0, 6.0, -2.0, 4.0])


def test_grid_seabed_selects_class_40():
    n = 4
    p = Points(
        pulse_id=np.arange(n),
        xyz_m=np.array([[0.5, 0.5, -5.0], [0.5, 0.5, -7.0], [0.5, 0.5, 1.0], [0.5, 0.5, -6.0]]),
        depth_m=np.array([5.0, 7.0, -1.0, 6.0]),
        classification=np.array([40, 40, 2, 7], np.uint8),
        kind=np.full(n, 2, np.uint8),
        flags=np.zeros(n, np.uint16),
        detector_flags=np.zeros(n, np.uint16),
        return_number=np.ones(n, np.uint8),
        number_of_returns=np.ones(n, np.uint8),
        confidence=np.ones(n),
        uncertainty_v_m=np.zeros(n),
        uncertainty_h_m=np.zeros(n),
    )
    g = grid_seabed(p, 1.0)
    assert g.shape == (1, 1) and g.count[0, 0] == 2
    assert g.depth_m[0, 0] == 6.0 and g.spread_m[0, 0] == pytest.approx(np.sqrt(2.0))


def test_cell_depth_robust_to_outliers():
    """An analytic sloping seabed, 0.05 m noise, and 20 % of the points replaced by blunders
    (false bottoms 2-30 m off, both ways). The cell depth must stay on the plane: within
    0.1 m of the plane at the cell centre in every cell with >= 8 points (the median of a
    cell with fewer than half outliers lies inside the good points' range), and its elevation
    likewise. A per-cell mean moves by ~20 % of the blunders' size."""
    rng = np.random.default_rng(11)
    n = 12000
    x, y = rng.uniform(0, 40, n), rng.uniform(0, 40, n)

    def plane_depth(x, y):
        return 6.0 + 0.1 * x - 0.05 * y  # analytic truth: depth (m) below the datum

    d = plane_depth(x, y) + rng.normal(0.0, 0.05, n)
    bad = rng.random(n) < 0.2
    d[bad] += rng.choice([-1.0, 1.0], bad.sum()) * rng.uniform(2.0, 30.0, bad.sum())
    g = grid_points(x, y, d, resolution_m=4.0, bounds_m=(0, 40, 0, 40))
    xx, yy = np.meshgrid(g.x_m, g.y_m)
    full = g.count >= 8
    assert full.sum() == 100
    # half a cell of slope (0.1 x 2 m) separates a point's truth from the centre's at most;
    # the median's error here is the noise and the slope's spread, well under 0.1 m
    err = g.depth_m - plane_depth(xx, yy)
    assert np.max(np.abs(err[full])) < 0.1
    np.testing.assert_allclose(g.z_m[full], -g.depth_m[full], atol=1e-12)
    # the mean is not: the same cells are off by metres
    assert np.max(np.abs(g.mean_depth_m - plane_depth(xx, yy))[full]) > 0.5


def _seabed_with_a_cube():
    """A flat seabed 5 m deep sounded on a 0.25 m lattice, a 1 m cube (top 4 m) at (5, 5).

    2 m cells: the cube's 16 soundings are a quarter of the 64 in its cell (4..6 x 4..6), so
    the median gives the seabed there; its soundings are class 43, one class-40 blunder 2 m
    shoal sits in the cell (0..2 x 0..2).
    """
    g = np.arange(0.125, 10.0, 0.25)
    x, y = (a.ravel() for a in np.meshgrid(g, g))
    on = (np.abs(x - 5.0) <= 0.5) & (np.abs(y - 5.0) <= 0.5)
    depth = np.where(on, 4.0, 5.0)
    depth[np.flatnonzero((x < 2) & (y < 2))[0]] = 3.0
    cls = np.where(on, 43, 40).astype(np.uint8)
    return SimpleNamespace(xyz_m=np.c_[x, y, -depth], depth_m=depth, classification=cls)


def test_designated_objects_keep_a_cube_the_median_erases():
    from pipeline.process.grid import designate_objects

    pts = _seabed_with_a_cube()
    grid = grid_seabed(pts, 2.0, bounds_m=(0, 10, 0, 10))
    assert np.all(grid.depth_m == 5.0)  # the median: no cube, no blunder
    des = designate_objects(grid, pts)
    row, col = 2, 2  # the cell y in (4, 6], x in [4, 6) holds the whole cube
    assert des.depth_m[row, col] == 4.0 and des.z_m[row, col] == -4.0
    others = np.ones(grid.shape, bool)
    others[row, col] = False
    assert np.all(des.depth_m[others] == 5.0)  # the class-40 blunder still meets the median
    assert des.median_depth_m[row, col] == 5.0 and des.count[row, col] == 64
    # below a datum 0.5 m above the points' reference: depths 0.5 m more
    below = grid_seabed(pts, 2.0, bounds_m=(0, 10, 0, 10), datum_m=0.5)
    des_d = designate_objects(below, pts, 0.5)
    assert des_d.depth_m[row, col] == 4.5
    # the evaluation's grid criterion (the cell stands above its neighbours by s/2) now holds
    from pipeline.evaluate_features import cube_detection

    cube = SimpleNamespace(kind="cube", x_m=5.0, y_m=5.0, size_m=1.0, heading_deg=0.0)
    flat = lambda x, y: np.full(np.shape(x), 5.0)  # noqa: E731
    assert not cube_detection((cube,), pts, flat, grid)[0]["grid_shows"]
    assert cube_detection((cube,), pts, flat, des)[0]["grid_shows"]


def test_a_designated_cell_is_scored_against_the_least_true_depth_in_it():
    from pipeline.evaluate import grid_errors_m
    from pipeline.evaluate_features import grid_elevation_errors_m
    from pipeline.process.grid import designate_objects

    pts = _seabed_with_a_cube()

    def depth(x, y):  # the analytic seabed: 5 m, the cube's top 4 m
        return np.where((np.abs(x - 5.0) <= 0.5) & (np.abs(y - 5.0) <= 0.5), 4.0, 5.0)

    des = designate_objects(grid_seabed(pts, 2.0, bounds_m=(0, 10, 0, 10)), pts)
    assert des.designated.sum() == 1 and des.designated[2, 2]
    err, _ = grid_errors_m(des, truth_depth_m=depth)
    # the cell (4..6)^2 states the cube's least depth, 4 m, and so is the truth's least depth;
    # at its centre the truth is the top too, so test a cube off the centre below
    assert err[2, 2] == 0.0 and np.all(err[~des.designated] == 0.0)

    def off_centre(x, y):  # the same cell, the cube moved to (4.5, 5.5): centre (5, 5) off it
        return np.where((np.abs(x - 4.2) <= 0.25) & (np.abs(y - 5.7) <= 0.25), 4.0, 5.0)

    err, _ = grid_errors_m(des, truth_depth_m=off_centre)
    assert err[2, 2] == 0.0  # not -1 m: the cell's least true depth is the cube's top
    elev = grid_elevation_errors_m(des, lambda x, y: -off_centre(x, y))
    assert np.all(elev == 0.0)
