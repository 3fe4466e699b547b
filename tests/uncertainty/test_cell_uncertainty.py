"""Cell uncertainty: the estimator by hand, its coverage on simulated cells, the posterior
refinement and the bounded choice of pulses to sample."""

import math

import numpy as np
import pytest

from pipeline.iho import NO_DATA
from pipeline.process.grid import grid_points
from pipeline.uncertainty.cell_uncertainty import (
    cell_index,
    cell_uncertainty,
    select_posterior_pulses,
)
from pipeline.uncertainty.tpu import CORRELATED_TERMS, RANDOM_TERMS, PointTpu


def make_tpu(xyz, sv_r, sv_c, sh_r, sh_c, timing_v=None):
    """A PointTpu with given random / correlated sigmas (timing part of the random one)."""
    n = len(xyz)
    full = np.ones(n)
    sv_r, sv_c, sh_r, sh_c = (
        np.broadcast_to(np.asarray(a, float), (n,)) for a in (sv_r, sv_c, sh_r, sh_c)
    )
    timing = np.zeros(n) if timing_v is None else np.broadcast_to(timing_v, (n,))
    terms = {k: np.zeros((n, 3)) for k in RANDOM_TERMS + CORRELATED_TERMS}
    terms["timing_bottom"][:, 2] = timing
    terms["footprint"][:, 2] = np.sqrt(np.maximum(sv_r**2 - timing**2, 0.0))
    return PointTpu(
        row=np.arange(n),
        pulse_id=np.arange(n),
        xyz_m=np.asarray(xyz, float),
        terms=terms,
        sigma_x_m=full,
        sigma_y_m=full,
        sigma_v_m=np.hypot(sv_r, sv_c),
        sigma_h_m=np.hypot(sh_r, sh_c),
        sigma_v_random_m=sv_r,
        sigma_v_correlated_m=sv_c,
        sigma_h_random_m=sh_r,
        sigma_h_correlated_m=sh_c,
    )


def two_cells():
    # cell (0, 0): four points at 10 m; cell (0, 1): one point
    x = np.array([0.5, 1.5, 0.5, 1.5, 2.5])
    y = np.array([0.5, 0.5, 1.5, 1.5, 0.5])
    depth = np.array([10.0, 10.1, 9.9, 10.0, 10.0])
    grid = grid_points(x, y, depth, resolution_m=2.0, bounds_m=(0, 4, 0, 2))
    xyz = np.column_stack([x, y, -depth])
    return grid, xyz


def test_estimator_by_hand():
    grid, xyz = two_cells()
    tpu = make_tpu(xyz, [0.05] * 4 + [0.1], [0.03] * 4 + [0.05], 0.2, 0.1)
    cells = cell_uncertainty(grid, tpu)
    # cell 1: spread sqrt(0.02 / 3) = 0.0816 > 0.05: 0.03² + 0.02 / 3 / 4
    assert cells.sigma_v_m[0, 0] == pytest.approx(math.sqrt(0.0009 + 0.02 / 12), rel=1e-12)
    # cell 2, one point: its TPU
    assert cells.sigma_v_m[0, 1] == pytest.approx(math.hypot(0.1, 0.05), rel=1e-12)
    assert cells.sigma_h_m[0, 0] == pytest.approx(math.sqrt(0.01 + 0.04 / 4), rel=1e-12)
    assert cells.tvu95_m[0, 0] == pytest.approx(1.96 * cells.sigma_v_m[0, 0], rel=1e-3)
    assert cells.thu95_m[0, 0] == pytest.approx(2.4477 * cells.sigma_h_m[0, 0], rel=1e-4)
    # 10 m: TVU95 0.0993 and THU95 0.346 meet exclusive (0.1677, 1 m); 0.219 meets special
    np.testing.assert_array_equal(cells.order, [[0, 1]])
    np.testing.assert_array_equal(cells.count, [[4, 1]])


def test_tpu_dominates_a_tight_cell():
    grid, xyz = two_cells()
    tpu = make_tpu(xyz, 0.5, 0.0, 0.2, 0.1)  # random TPU 0.5 m >> spread 0.08 m
    cells = cell_uncertainty(grid, tpu)
    assert cells.sigma_v_m[0, 0] == pytest.approx(0.5 / 2.0, rel=1e-12)


def test_posterior_replaces_the_timing_terms():
    grid, xyz = two_cells()
    # random TPU 0.2 m (above the 0.08 m spread) of which timing 0.16 m
    tpu = make_tpu(xyz, 0.2, 0.0, 0.2, 0.1, timing_v=0.16)
    sampled = np.array([True, False, False, False, False])
    post = np.array([0.04, 0, 0, 0, 0])
    cells = cell_uncertainty(grid, tpu, posterior_sigma_v_m=post, has_posterior=sampled)
    # ratio 0.04² / 0.16² = 0.0625: random variance 0.04 + (0.0625 - 1) 0.0256 = 0.016
    assert cells.sigma_v_m[0, 0] == pytest.approx(math.sqrt(0.016 / 4), rel=1e-12)
    assert cells.n_posterior[0, 0] == 1 and cells.n_posterior[0, 1] == 0
    assert cells.sigma_v_m[0, 1] == pytest.approx(0.2, rel=1e-12)  # untouched


def test_cell_index_is_the_grids_registration():
    rng = np.random.default_rng(0)
    x, y = rng.uniform(-3, 17, 500), rng.uniform(2, 13, 500)
    grid = grid_points(x, y, np.ones(500), resolution_m=2.5)
    c = cell_index(grid, x, y)
    counts = np.bincount(c[c >= 0], minlength=grid.count.size).reshape(grid.shape)
    np.testing.assert_array_equal(counts, grid.count)


def test_cell_sigma_covers_the_cell_error():
    """Cells of 1-8 points, a correlated error per cell and random errors per point: the
    cell mean is off by less than its TVU95 in ~95 % of cells (slightly more: the spread
    term is conservative)."""
    rng = np.random.default_rng(3)
    n_cells = 3000
    counts = rng.integers(1, 9, n_cells)
    cx = np.repeat(np.arange(n_cells), counts)
    n = cx.size
    sv_r = rng.uniform(0.03, 0.15, n_cells)[cx]
    sv_c = rng.uniform(0.0, 0.08, n_cells)[cx]
    err = rng.normal(0.0, 1.0, n_cells)[cx] * sv_c + rng.normal(0.0, 1.0, n) * sv_r
    x = cx + 0.5
    y = np.full(n, 0.5)
    depth = 10.0 + err
    grid = grid_points(x, y, depth, resolution_m=1.0, bounds_m=(0, n_cells, 0, 1))
    tpu = make_tpu(np.column_stack([x, y, -depth]), sv_r, sv_c, 0.1, 0.1)
    cells = cell_uncertainty(grid, tpu)
    cover = np.mean(np.abs(grid.depth_m - 10.0) <= cells.tvu95_m)
    # 3000 cells: +-0.8 % (2 sigma); the max(TPU, spread) rule adds ~1-2 %
    assert 0.94 < cover < 0.985, cover


def test_pulses_for_the_posterior_are_bounded():
    rng = np.random.default_rng(5)
    n = 4000
    x, y = rng.uniform(0, 40, n), rng.uniform(0, 40, n)
    depth = np.full(n, 10.0)
    grid = grid_points(x, y, depth, resolution_m=2.0, bounds_m=(0, 40, 0, 40))
    # half the area (x < 20) sits near the special-order limit: TVU95 ~ 0.26 at 10 m
    sv = np.where(x < 20, 0.135, 0.02)
    tpu = make_tpu(np.column_stack([x, y, -depth]), 0.0, sv, 0.1, 0.1)
    cells = cell_uncertainty(grid, tpu)
    flagged = (x > 38) & (y > 38)
    pick = select_posterior_pulses(
        grid, cells, tpu, k_per_cell=2, max_pulses=150, margin=0.05, flagged=flagged, seed=1
    )
    assert len(pick) == 150  # the cap
    c = cell_index(grid, x[pick], y[pick])
    assert np.max(np.bincount(c)) <= 2
    assert np.all((x[pick] < 20) | flagged[pick])  # only marginal or flagged cells
    again = select_posterior_pulses(
        grid, cells, tpu, k_per_cell=2, max_pulses=150, margin=0.05, flagged=flagged, seed=1
    )
    np.testing.assert_array_equal(pick, again)
    all_of_them = select_posterior_pulses(
        grid, cells, tpu, k_per_cell=1, max_pulses=10**6, margin=0.05, flagged=flagged
    )
    # one per marginal cell (10 x 20) plus the flagged corner cell
    assert len(all_of_them) == 201
    assert np.all(cells.order != NO_DATA)
