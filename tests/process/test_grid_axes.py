"""A grid of some rows and columns (a blocked survey's sample) against the whole grid.

Every consumer of a sample's grid must give, where it has a cell, what the whole grid gives:
the whole grid (gridded over the whole bounds, as before) is the reference throughout.
"""

from types import SimpleNamespace

import numpy as np
import pytest

from pipeline.evaluate import cell_truth
from pipeline.evaluate_features import cube_detection
from pipeline.outputs.grid_overlay import Overlay
from pipeline.outputs.report import map_cells
from pipeline.outputs.report_figures import MAP_CELLS
from pipeline.process.classify import BATHYMETRIC_POINT, SUBMERGED_OBJECT
from pipeline.process.grid import designate_objects
from pipeline.process.grid_axes import MARGIN_CELLS, occupied_axes
from pipeline.survey_tiles import TileLayout, grid_by_tiles
from pipeline.uncertainty import cell_uncertainty as cu

RES = 2.0
BOUNDS = np.array([0.0, 160.0, 0.0, 120.0])  # 80 x 60 cells


def _sample(seed=0, n_blocks=3, per_block=400):
    """Soundings in a few square blocks spread over the bounds (a sample's blocks)."""
    rng = np.random.default_rng(seed)
    xs, ys = [], []
    for _ in range(n_blocks):
        x0, y0 = rng.uniform(4.0, 120.0), rng.uniform(4.0, 90.0)
        xs.append(rng.uniform(x0, x0 + 24.0, per_block))
        ys.append(rng.uniform(y0, y0 + 18.0, per_block))
    x, y = np.concatenate(xs), np.concatenate(ys)
    depth = 5.0 + 0.05 * x + rng.normal(0.0, 0.2, x.size)
    cls = np.full(x.size, BATHYMETRIC_POINT, dtype=np.uint8)
    cls[rng.choice(x.size, 12, replace=False)] = SUBMERGED_OBJECT
    return SimpleNamespace(xyz_m=np.c_[x, y, -depth], depth_m=depth, classification=cls)


def _grids(points, tile_m=40.0):
    layout = TileLayout(BOUNDS, RES, tile_m)
    ps = SimpleNamespace(grid_statistic="median")
    whole = grid_by_tiles(points, layout, (500.0, 900.0, 0.0), None, None, ps)
    axes = occupied_axes(points.xyz_m[:, 0], points.xyz_m[:, 1], BOUNDS, RES)
    part = grid_by_tiles(points, layout, (500.0, 900.0, 0.0), None, None, ps, axes)
    return whole, part


FIELDS = ("depth_m", "median_depth_m", "mean_depth_m", "spread_m", "z_m", "count")


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_sample_grid_holds_the_whole_grids_cells_and_every_sounding(seed):
    pts = _sample(seed)
    whole, part = _grids(pts)
    at = np.ix_(part.rows, part.cols)
    for f in FIELDS:
        np.testing.assert_array_equal(getattr(part, f), getattr(whole, f)[at], err_msg=f)
    np.testing.assert_array_equal(part.x_m, whole.x_m[part.cols])
    np.testing.assert_array_equal(part.y_m, whole.y_m[part.rows])
    # every sounding is in a held cell: the cells left out are empty in the whole grid
    assert part.count.sum() == whole.count.sum() == pts.depth_m.size
    # and the sample's grid is much smaller than the whole one
    assert part.count.size < 0.7 * whole.count.size
    # a held cell's neighbours are the whole grid's (the evaluation's ring reads them)
    rows = np.flatnonzero(whole.count.sum(axis=1))
    for d in range(-MARGIN_CELLS, MARGIN_CELLS + 1):
        assert np.isin(np.clip(rows + d, 0, whole.shape[0] - 1), part.rows).all()
    with pytest.raises(ValueError, match="some rows and columns cannot give an affine transform"):
        _ = part.transform


def test_designated_objects_and_cell_uncertainty_match_the_whole_grid():
    pts = _sample(3)
    whole, part = _grids(pts)
    whole, part = (designate_objects(g, pts) for g in (whole, part))
    at = np.ix_(part.rows, part.cols)
    np.testing.assert_array_equal(part.designated, whole.designated[at])
    np.testing.assert_array_equal(part.depth_m, whole.depth_m[at])
    assert whole.designated.sum() == part.designated.sum() > 0
    rng = np.random.default_rng(4)
    n = pts.depth_m.size
    tpu = SimpleNamespace(
        xyz_m=pts.xyz_m,
        sigma_v_correlated_m=rng.uniform(0.05, 0.3, n),
        sigma_v_random_m=rng.uniform(0.05, 0.3, n),
        sigma_h_correlated_m=rng.uniform(0.1, 0.5, n),
        sigma_h_random_m=rng.uniform(0.1, 0.5, n),
        terms={},
    )
    cw, cp = cu.cell_uncertainty(whole, tpu), cu.cell_uncertainty(part, tpu)
    for f in ("sigma_v_m", "sigma_h_m", "tvu95_m", "thu95_m", "count", "order"):
        np.testing.assert_array_equal(getattr(cp, f), getattr(cw, f)[at], err_msg=f)
    # the posterior pulses picked: the same, the cap reached (cells in random order)
    kw = dict(k_per_cell=1, max_pulses=15, margin=10.0, seed=9)
    sel_w = cu.select_posterior_pulses(whole, cw, tpu, **kw)
    sel_p = cu.select_posterior_pulses(part, cp, tpu, **kw)
    assert sel_w.size == 15
    np.testing.assert_array_equal(sel_p, sel_w)


def test_uniform_at_draws_the_numbers_of_one_call(monkeypatch):
    monkeypatch.setattr(cu, "RANDOM_BLOCK", 1000)
    at = np.random.default_rng(1).integers(0, 5500, 300)
    a, b = np.random.default_rng(7), np.random.default_rng(7)
    np.testing.assert_array_equal(cu.uniform_at(a, 5500, at), b.random(5500)[at])
    assert a.random() == b.random()  # both moved on by as many numbers


def test_the_overlay_of_a_sample_grid_lays_the_whole_grids_cells():
    pts = _sample(5)
    whole, part = _grids(pts)
    rng = np.random.default_rng(6)
    ny, nx = whole.shape
    full = SimpleNamespace(
        n_posterior=np.where(rng.random((ny, nx)) < 0.3, 1, 0) * (whole.count > 0),
        tvu95_m=rng.random((ny, nx)),
        order=rng.integers(-1, 4, (ny, nx)).astype(np.int8),
    )
    at = np.ix_(part.rows, part.cols)
    held = SimpleNamespace(**{k: v[at] for k, v in vars(full).items()})
    for rows, cols in ((slice(0, ny), slice(0, nx)), (slice(7, 31), slice(50, 80))):
        for field in ("tvu95_m", "order"):
            sw, vw = Overlay(full).window(field, rows, cols, (ny, nx))
            sp, vp = Overlay(held, part.rows, part.cols).window(field, rows, cols, (ny, nx))
            np.testing.assert_array_equal(sp, sw)
            np.testing.assert_array_equal(vp[sp], vw[sw])
    with pytest.raises(ValueError, match="overlay"):
        Overlay(held, part.rows, part.cols[:-1]).window("order", rows, cols, (ny, nx))
    with pytest.raises(ValueError, match="step 1"):
        Overlay(held, part.rows, part.cols).window("order", slice(0, 4, 2), cols, (ny, nx))


def test_cube_detection_and_cell_truth_read_the_sample_grid_as_the_whole():
    pts = _sample(8)
    whole, part = _grids(pts)
    # cubes at soundings (some cells full, the ring around them too) and one in empty space
    xy = pts.xyz_m[[0, 500, 900], :2]
    cubes = [
        SimpleNamespace(kind="cube", x_m=x, y_m=y, size_m=1.0, heading_deg=0.0) for x, y in xy
    ] + [SimpleNamespace(kind="cube", x_m=159.0, y_m=1.0, size_m=1.0, heading_deg=0.0)]

    def truth(x, y):
        return 5.0 + 0.05 * np.asarray(x) + 0.01 * np.asarray(y)

    a = cube_detection(cubes, pts, truth, whole, truth)
    b = cube_detection(cubes, pts, truth, part, truth)
    assert a == b
    tw, tp = cell_truth(whole, truth), cell_truth(part, truth)
    np.testing.assert_array_equal(tp, tw[np.ix_(part.rows, part.cols)])
    # the truth at the non-empty cells' centres (brute force), NaN in the empty ones
    xx, yy = np.meshgrid(whole.x_m, whole.y_m)
    full = whole.count > 0
    np.testing.assert_array_equal(tw[full], truth(xx[full], yy[full]))
    assert np.isnan(tw[~full]).all()


@pytest.mark.parametrize("bounds", [BOUNDS, np.array([0.0, 60.0, 0.0, 2400.0 * RES])])
def test_the_reports_maps_show_the_sample_grid_as_the_whole(bounds):
    rng = np.random.default_rng(10)
    x0, x1, y0, y1 = bounds
    x = rng.uniform(x0, x1, 3000)
    y = np.concatenate([rng.uniform(y0, y0 + 60.0, 1500), rng.uniform(y1 - 60.0, y1, 1500)])
    pts = SimpleNamespace(
        xyz_m=np.c_[x, y, -np.full(x.size, 4.0)],
        depth_m=np.full(x.size, 4.0) + rng.normal(0, 0.1, x.size),
        classification=np.full(x.size, BATHYMETRIC_POINT, dtype=np.uint8),
    )
    layout = TileLayout(bounds, RES, 40.0)
    ps = SimpleNamespace(grid_statistic="median")
    whole = grid_by_tiles(pts, layout, (0.0, 0.0, 0.0), None, None, ps)
    axes = occupied_axes(x, y, bounds, RES)
    part = grid_by_tiles(pts, layout, (0.0, 0.0, 0.0), None, None, ps, axes)
    (xw, yw, show_w), (xp, yp, show_p) = map_cells(whole), map_cells(part)
    np.testing.assert_array_equal(xp, xw)
    np.testing.assert_array_equal(yp, yw)
    np.testing.assert_array_equal(xw, whole.x_m)  # the extent: the whole grid's
    np.testing.assert_array_equal(yw, whole.y_m)
    assert max(show_w(whole.count, 0).shape) == min(MAP_CELLS, max(whole.shape))
    np.testing.assert_array_equal(show_p(part.depth_m, np.nan), show_w(whole.depth_m, np.nan))
    np.testing.assert_array_equal(show_p(part.count, 0), show_w(whole.count, 0))


def test_a_sample_with_no_point_in_the_grid_holds_no_cell_and_draws_and_overlays_nothing():
    pts = SimpleNamespace(
        xyz_m=np.array([[500.0, 500.0, -4.0]]),
        depth_m=np.array([4.0]),
        classification=np.array([BATHYMETRIC_POINT], dtype=np.uint8),
    )
    whole, part = _grids(pts)
    assert part.count.shape == (0, 0) and whole.count.sum() == 0
    ny, nx = whole.shape
    x, y, shown = map_cells(part)
    assert np.isnan(shown(part.depth_m, np.nan)).all()
    assert (shown(part.count, 0) == 0).all() and x.size == nx and y.size == ny
    cells = SimpleNamespace(
        n_posterior=np.zeros((0, 0), int), tvu95_m=np.zeros((0, 0)), order=np.zeros((0, 0))
    )
    overlay = Overlay(cells, part.rows, part.cols)
    sampled, _ = overlay.window("tvu95_m", slice(0, 5), slice(None), (ny, nx))
    assert sampled.shape == (5, nx) and not sampled.any()


def test_a_sample_grid_is_never_written_as_a_file_of_its_own(tmp_path):
    from pipeline.outputs.grid_tiles import cell_records
    from pipeline.outputs.netcdf import write_grid_nc

    _, part = _grids(_sample(11))
    with pytest.raises(ValueError, match="some rows and columns"):
        write_grid_nc(tmp_path / "g.nc", part)
    with pytest.raises(ValueError, match="some rows and columns"):
        cell_records(part, None, (slice(0, 2), slice(0, 2)))
    assert not (tmp_path / "g.nc").exists()
