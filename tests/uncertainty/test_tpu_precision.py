"""The TPU's timing terms when the detector gives per-return sigmas that the timing does not
reach: the scatter of successive soundings raises them, never lowers them. Truth is analytic:
flat water at z = 0 over a flat seabed 12 m deep (:func:`tests.uncertainty.test_tpu.survey`),
with bottom-time noise of a known sigma added here."""

import dataclasses

import numpy as np
import pytest

from pipeline.process.refraction import seabed_points
from pipeline.uncertainty.tpu import (
    pair_scatter,
    point_tpu,
    timing_from_scatter,
)
from pipeline.uncertainty.tpu_settings import DEPTH, Z
from pipeline.uncertainty.tpu_window import (
    WINDOW_TERM,
    cell_relief_sigma_m,
    cell_window_sigma_m,
    window_footprint_sigma_m,
    with_random_term,
)
from tests.uncertainty.test_tpu import RST, survey

TRUE_DEPTH_M = 12.0


def _noisy(sigma_b_s, detector_b_s, seed=7):
    ret, surf = survey(n_side=36, seed=seed)
    n = len(ret)
    rng = np.random.default_rng(seed)
    ret = dataclasses.replace(
        ret,
        t_bottom_s=ret.t_bottom_s + rng.normal(0.0, sigma_b_s, n),
        # survey() puts 0.1 ns of noise on the surface times; the detector knows that one
        t_surface_sigma_s=np.full(n, 1e-10),
        t_bottom_sigma_s=np.full(n, detector_b_s),
    )
    pts = seabed_points(ret, surf, RST)
    scatter = pair_scatter(pts.xyz_m[:, :2], pts.depth_m, order=ret.pulse_id)
    return ret, surf, pts, scatter


def test_scatter_raises_a_detector_sigma_the_timing_does_not_reach():
    """The detector claims 0.02 ns on the bottom, the times scatter by 0.4 ns (~4.4 cm of
    depth): the TPU intervals must hold the true depth at their nominal rates."""
    ret, surf, pts, scatter = _noisy(4e-10, 2e-11)
    err = pts.depth_m - TRUE_DEPTH_M
    own = point_tpu(ret, surf, RST)
    z_own = np.abs(err) / own.sigma_depth_m
    assert np.mean(z_own <= 1.96) < 0.5  # the detector's sigma alone: far too small
    raised = timing_from_scatter(ret, surf, RST, depth_scatter_m=scatter, raise_only=True)
    tpu = point_tpu(raised, surf, RST)
    z = np.abs(err) / tpu.sigma_depth_m
    # 1296 points: the coverage is known to ~1.3 % (68 %) and ~0.6 % (95 %), the scatter
    # estimate (64 pairs each) to ~9 %
    assert 0.62 <= np.mean(z <= 1.0) <= 0.75
    assert 0.92 <= np.mean(z <= 1.96) <= 0.975


def test_heights_scatter_sets_the_timing_where_depths_read_a_sea():
    """Depths read below a sea that differs between soundings 1.5 m apart (short waves of
    3-6 m, added to the depths and to their truth alike: relief, no error) scatter more than
    their errors, and the rise ``a h²`` removes only part of it: the TPU from the depths'
    scatter is too wide. The seabed heights carry no sea: their scatter sets the timing
    through its height derivatives, and the depth intervals hold the truth at their rates
    (the same bounds as above). The errors are the analytic 12 m seabed's."""
    ret, surf, pts, _ = _noisy(4e-10, 2e-11)
    err = pts.depth_m - TRUE_DEPTH_M
    xy = pts.xyz_m[:, :2]
    wave_m, angle = np.array([0.06, 0.05, 0.04]), np.radians([10.0, 70.0, 135.0])
    k = 2.0 * np.pi / np.array([3.3, 4.1, 5.7])
    along = xy[:, :1] * np.cos(angle) + xy[:, 1:] * np.sin(angle)
    sea = np.sum(wave_m * np.sin(k * along + [0.3, 1.1, 2.0]), axis=1)

    def coverage(values, column):
        scatter = pair_scatter(xy, values, order=ret.pulse_id)
        raised = timing_from_scatter(
            ret, surf, RST, depth_scatter_m=scatter, raise_only=True, scatter_column=column
        )
        z = np.abs(err) / point_tpu(raised, surf, RST).sigma_depth_m
        return np.mean(z <= 1.0), np.mean(z <= 1.96)

    from_depths = coverage(pts.depth_m + sea, DEPTH)
    assert from_depths[0] > 0.8  # the sea read as timing noise
    from_heights = coverage(-pts.xyz_m[:, 2], Z)
    assert 0.62 <= from_heights[0] <= 0.75
    assert 0.92 <= from_heights[1] <= 0.975
    # without the sea the two agree (here a height moves as its depth for every term)
    plain = coverage(pts.depth_m, DEPTH)
    assert abs(plain[0] - from_heights[0]) < 0.04
    with pytest.raises(ValueError, match="scatter_column"):
        timing_from_scatter(ret, surf, RST, depth_scatter_m=err, scatter_column=1)


def test_a_detector_sigma_above_the_scatter_is_kept():
    ret, surf, _, scatter = _noisy(1e-11, 2e-9)
    out = timing_from_scatter(ret, surf, RST, depth_scatter_m=scatter, raise_only=True)
    np.testing.assert_array_equal(out.t_bottom_sigma_s, ret.t_bottom_sigma_s)
    np.testing.assert_array_equal(out.t_surface_sigma_s, ret.t_surface_sigma_s)
    # without raise_only the scatter replaces them (the photon-counting path)
    set_ = timing_from_scatter(ret, surf, RST, depth_scatter_m=scatter)
    assert np.median(set_.t_bottom_sigma_s) < 0.5 * 2e-9


def test_photon_window_spread_over_a_slope_is_the_uniform_rms():
    """Shots evenly spread along x over a window of length L above a plane of gradient g share
    one depth (the window's, at its centre): each misses its own by g (x - x_mean), whose rms
    over the window is g L / sqrt(12) (a uniform distribution)."""
    n_win, per, length_m, g = 40, 200, 1.5, 0.2
    x = np.concatenate([w * 3.0 + np.linspace(0, length_m, per) for w in range(n_win)])
    y = np.zeros_like(x)
    group = np.repeat(np.arange(n_win), per)
    grad = np.tile([g, 0.0], (x.size, 1))
    sigma = window_footprint_sigma_m(np.column_stack([x, y]), group, grad)
    # per-shot spacing L / (per - 1): the discrete rms is g L sqrt((per + 1) / (12 (per - 1)))
    expected = g * length_m * np.sqrt((per + 1) / (12.0 * (per - 1)))
    np.testing.assert_allclose(sigma, expected, rtol=1e-9)
    # the shots' errors, window depth minus each shot's true depth, are held at their rates
    centre = np.repeat(x.reshape(n_win, per).mean(axis=1), per)
    err = g * (centre - x)
    z = np.abs(err) / sigma
    assert np.mean(z <= 1.0) == pytest.approx(1 / np.sqrt(3), abs=0.01)  # uniform: 57.7 %
    assert np.all(z <= np.sqrt(3) + 1e-9)


def test_photon_window_spread_under_a_random_sea_slope():
    """The same windows on a flat seabed under a sea whose slope along x, random per window
    (the planes follow none of it), is normal with sigma s: each shot's depth misses by
    beta (x - x_mean). Over many windows the rms of that error is the term, s L / sqrt(12);
    drawn here, not restated."""
    rng = np.random.default_rng(6)
    n_win, per, length_m, s = 4000, 50, 0.4, 0.1
    x = np.concatenate([w * 1.0 + np.linspace(0, length_m, per) for w in range(n_win)])
    xy = np.column_stack([x, np.zeros_like(x)])
    group = np.repeat(np.arange(n_win), per)
    cov = np.tile(np.diag([s**2, 0.0]), (x.size, 1, 1))
    sigma = window_footprint_sigma_m(xy, group, np.zeros((x.size, 2)), cov)
    beta = np.repeat(rng.normal(0.0, s, n_win), per)
    centre = np.repeat(x.reshape(n_win, per).mean(axis=1), per)
    err = beta * (x - centre)
    np.testing.assert_allclose(np.sqrt(np.mean(err**2)), np.sqrt(np.mean(sigma**2)), rtol=0.03)
    assert np.mean(np.abs(err) <= 1.96 * sigma) == pytest.approx(0.95, abs=0.02)


def test_cell_window_spread_with_an_uncertain_gradient():
    """Square 10 m cells of a scan over a seabed whose gradient is known only to its
    estimate's covariance G about a mean m: drawn here per cell, the true gradient m + e
    (e ~ N(0, G)) makes each shot's depth miss the cell's by (m + e) . (p - p_mean). The
    term's rms over many cells matches the drawn errors', and 95 % of them lie within
    1.96 of it; without G the term would hold only the mean gradient's part."""
    rng = np.random.default_rng(12)
    n_win, per, side = 3000, 60, 10.0
    xy = np.concatenate([rng.uniform(0.0, side, (per, 2)) + [20.0 * w, 0.0] for w in range(n_win)])
    group = np.repeat(np.arange(n_win), per)
    mean = np.array([0.03, -0.01])
    g_cov = np.array([[0.02**2, 0.0001], [0.0001, 0.05**2]])
    grad = np.tile(mean, (xy.shape[0], 1))
    cov = np.tile(g_cov, (xy.shape[0], 1, 1))
    sigma = window_footprint_sigma_m(xy, group, grad, gradient_cov=cov)
    true_g = np.repeat(rng.multivariate_normal(mean, g_cov, n_win), per, axis=0)
    centre = np.repeat(xy.reshape(n_win, per, 2).mean(axis=1), per, axis=0)
    err = np.sum(true_g * (xy - centre), axis=1)
    np.testing.assert_allclose(np.sqrt(np.mean(err**2)), np.sqrt(np.mean(sigma**2)), rtol=0.03)
    assert np.mean(np.abs(err) <= 1.96 * sigma) == pytest.approx(0.95, abs=0.02)
    exact = window_footprint_sigma_m(xy, group, grad)
    assert np.mean(np.abs(err) <= 1.96 * exact) < 0.8  # ~70 % when written


def test_cell_relief_is_what_windows_miss_their_neighbours_plane_by():
    """Windows on a 12 m grid over a plane sloping 0.16, each raised by its own relief drawn
    N(0, 0.2 m): the windows' misses from their neighbours' planes have the relief's sd (and
    the plane's own error from ~20 neighbours, +2 % or so); a plane without relief gives 0."""
    rng = np.random.default_rng(4)
    gx, gy = np.meshgrid(np.arange(40) * 12.0, np.arange(40) * 12.0)
    c = np.column_stack([gx.ravel(), gy.ravel()])
    per = 30
    xy = np.repeat(c, per, axis=0) + rng.uniform(-6.0, 6.0, (c.shape[0] * per, 2))
    group = np.repeat(np.arange(c.shape[0]), per)
    relief = np.repeat(rng.normal(0.0, 0.2, c.shape[0]), per)
    plane = 0.16 * xy[:, 0] - 0.05 * xy[:, 1]
    assert cell_relief_sigma_m(xy, plane + relief, group, 12.0) == pytest.approx(0.2, rel=0.1)
    assert cell_relief_sigma_m(xy, plane, group, 12.0) < 1e-6


def test_an_isolated_cell_window_keeps_its_spread_under_the_slope():
    """A 10 x 10 grid of 12 m cells and one cell 200 m away, over a slope of 0.1 along x:
    the grid's windows (carried by the detector, with neighbours) get the relief term (0
    here: a plane), the isolated one the rms of 0.1 x its shots' offsets, 0.1 x 12 / sqrt 12
    for shots spread evenly across it."""
    rng = np.random.default_rng(2)
    gx, gy = np.meshgrid(np.arange(10) * 12.0, np.arange(10) * 12.0)
    c = np.vstack([np.column_stack([gx.ravel(), gy.ravel()]), [[400.0, 0.0]]])
    per = 400
    xy = np.repeat(c, per, axis=0) + np.column_stack(
        [np.tile(np.linspace(-6.0, 6.0, per), c.shape[0]), rng.uniform(-6.0, 6.0, c.shape[0] * per)]
    )
    group = np.repeat(np.arange(c.shape[0]), per)  # keys of one slab (slab_of: 0)
    depth = 5.0 + 0.1 * xy[:, 0]
    grad = np.tile([0.1, 0.0], (xy.shape[0], 1))
    no_cov = np.zeros((xy.shape[0], 2, 2))
    sigma = cell_window_sigma_m(xy, depth, -depth, group, 12.0, grad, no_cov)
    assert np.all(sigma[:-per] < 1e-6)
    spread = 0.1 * np.std(np.linspace(-6.0, 6.0, per))
    np.testing.assert_allclose(sigma[-per:], spread, rtol=1e-9)
    assert spread == pytest.approx(0.1 * 12.0 / np.sqrt(12.0), rel=0.01)


def test_a_random_term_adds_in_quadrature():
    ret, surf = survey(n_side=4)
    tpu = point_tpu(ret, surf, RST)
    extra = np.linspace(0.01, 0.1, len(tpu))
    out = with_random_term(tpu, WINDOW_TERM, extra, 2 * extra)
    np.testing.assert_allclose(out.sigma_v_m, np.hypot(tpu.sigma_v_m, extra))
    np.testing.assert_allclose(out.sigma_depth_m, np.hypot(tpu.sigma_depth_m, 2 * extra))
    np.testing.assert_allclose(
        out.sigma_depth_random_m, np.hypot(tpu.sigma_depth_random_m, 2 * extra)
    )
    np.testing.assert_array_equal(out.sigma_depth_correlated_m, tpu.sigma_depth_correlated_m)
    np.testing.assert_array_equal(out.sigma_h_m, tpu.sigma_h_m)
    assert out.terms[WINDOW_TERM].shape == (len(tpu), 4)


def test_neighbour_searches_in_blocks_give_the_same_figures(monkeypatch):
    import pipeline.uncertainty.pair_scatter as ps
    import pipeline.uncertainty.tpu_neighbours as tn
    from pipeline.process.surface_fit import fit_water_surface
    from tests.uncertainty.test_tpu import FIT

    ret, surf, pts, scatter = _noisy(3e-10, 1e-10)
    # a time per pulse, so that the surface over each sounding is searched within the window
    ret = dataclasses.replace(ret, t_emit_s=ret.pulse_id * 5e-3)
    surf = fit_water_surface(ret, FIT)
    assert surf.time_window_s is not None
    over = tn.surface_over_sounding(ret, surf, pts.xyz_m[:, :2])
    monkeypatch.setattr(tn, "_QUERY_BLOCK", 37)  # blocks cut anywhere
    monkeypatch.setattr(ps, "_QUERY_BLOCK", 37)
    assert len(ret) > 20 * 37
    np.testing.assert_array_equal(
        pair_scatter(pts.xyz_m[:, :2], pts.depth_m, order=ret.pulse_id), scatter
    )
    for a, b in zip(tn.surface_over_sounding(ret, surf, pts.xyz_m[:, :2]), over, strict=True):
        np.testing.assert_array_equal(a, b)
