"""A tile of a survey, given the survey's own survey-wide figures, gets the survey's TPU.

The reference is the TPU of the whole survey, computed the usual way (every figure measured
over all its pulses). A tile is the pulses whose water entry lies within a box grown by a halo;
its TPU, given the whole survey's :class:`TpuSurveyWide`, must give the soundings inside the box
the very terms the whole survey gave them: every search the TPU makes is local, and what is
not (the variogram, the pair-scatter rise, the tilt table, ...) comes from the whole survey.
The halo is what the searches reach: the regional seabed plane's radius and cell, the local
plane's radius, and a margin for the pair scatter's nearest pairs.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from pipeline.detection_store import DetectionStore
from pipeline.process.context import processing_context
from pipeline.process.grid import grid_seabed, snap_bounds_m
from pipeline.process.survey_points import process_detections
from pipeline.run_survey import simulate_detections
from pipeline.scene import load_scene
from pipeline.stages import StageClock, plan
from pipeline.suite.generate import ci_draws
from pipeline.suite.scene_file import write_scene
from pipeline.uncertainty.survey_uncertainty import survey_uncertainty
from pipeline.uncertainty.tpu_survey_wide import tpu_halo_m
from pipeline.uncertainty.tpu_terms import _take_surface


@pytest.fixture(scope="module")
def survey(tmp_path_factory):
    # the CI subset's oscillating full-waveform scan over a 5.3 m/s wave sea (258 m swath)
    tmp = tmp_path_factory.mktemp("tpu_wide")
    d = next(d for d in ci_draws() if d.seed == 9002)
    scene = load_scene(write_scene(d, tmp))
    ctx = processing_context(scene)
    with DetectionStore(tmp, ctx.instrument.air_index) as store:
        sim = simulate_detections(scene, plan(scene), ctx, StageClock(), store, log=lambda *a: 0)
    processed = process_detections(sim.returns, ctx, scene.process.classify, water_column=False)
    xmin, xmax, ymin, ymax = sim.extent_m
    bounds = snap_bounds_m(np.array([xmin, xmax]), np.array([ymin, ymax]), 2.0, (0.0, 0.0, 0.0))
    grid = grid_seabed(processed.points, 2.0, bounds_m=bounds)
    return sim.returns, processed, ctx, grid


def _tile(returns, processed, keep):
    """The pulses ``keep`` (bool per pulse) with their surface rows and points."""
    rows = np.flatnonzero(keep)
    pts = processed.points.select(np.isin(processed.points.pulse_id, returns.pulse_id[rows]))
    sea = None if processed.sea_change_m is None else processed.sea_change_m[rows]
    return returns.select(rows), dataclasses.replace(
        processed, surface=_take_surface(processed.surface, rows), points=pts, sea_change_m=sea
    )


def test_the_survey_given_its_own_figures_is_unchanged(survey):
    returns, processed, ctx, grid = survey
    whole = survey_uncertainty(returns, processed, ctx, grid)
    again = survey_uncertainty(returns, processed, ctx, grid, wide=whole.wide)
    np.testing.assert_array_equal(again.tpu40.sigma_depth_m, whole.tpu40.sigma_depth_m)
    for name, term in whole.tpu40.terms.items():
        np.testing.assert_array_equal(again.tpu40.terms[name], term, err_msg=name)


def test_a_tile_given_the_survey_figures_gets_the_survey_tpu(survey):
    returns, processed, ctx, grid = survey
    whole = survey_uncertainty(returns, processed, ctx, grid)
    # the regional plane (its radius and a cell's diagonal), the local plane's radius, and an
    # allowance for the pair scatter's nearest pairs: 77 m at the defaults
    halo = tpu_halo_m(ctx.tpu)
    x = processed.surface.entry_m[:, 0]
    # the swath's western part, and its halo eastwards (the survey ends to the west)
    core = x <= -60.0
    near = x <= -60.0 + halo
    assert core.sum() > 300 and near.sum() < 0.7 * len(returns), (core.sum(), near.sum())
    sub_ret, sub = _tile(returns, processed, near)
    tile = survey_uncertainty(sub_ret, sub, ctx, grid, wide=whole.wide)
    # the box's soundings, matched by pulse
    in_core = np.isin(whole.points40.pulse_id, returns.pulse_id[core])
    ids = whole.points40.pulse_id[in_core]
    at = np.searchsorted(tile.points40.pulse_id, ids)
    assert np.array_equal(tile.points40.pulse_id[at], ids)
    np.testing.assert_allclose(
        tile.tpu40.sigma_depth_m[at], whole.tpu40.sigma_depth_m[in_core], rtol=1e-12, atol=0
    )
    for name, term in whole.tpu40.terms.items():
        np.testing.assert_allclose(
            tile.tpu40.terms[name][at], term[in_core], rtol=1e-12, atol=1e-15, err_msg=name
        )
    # and what the tile would have measured alone differs: the figures matter
    alone = survey_uncertainty(sub_ret, sub, ctx, grid)
    assert alone.wide.scatter_rise_per_m2 != whole.wide.scatter_rise_per_m2 or not np.array_equal(
        alone.wide.turn_table[1], whole.wide.turn_table[1]
    )


def test_blocks_of_rows_on_threads_give_the_whole_survey_tpu(survey, monkeypatch):
    # the TPU's refraction passes in blocks of rows (a prime: blocks cut anywhere), the blocks
    # side by side on threads: every term of every sounding as the survey's rows all at once
    import pipeline.uncertainty.tpu_terms as tpu_terms
    from pipeline.parallel import stage_threads

    returns, processed, ctx, grid = survey
    whole = survey_uncertainty(returns, processed, ctx, grid)
    monkeypatch.setattr(tpu_terms, "TERMS_BLOCK", 397)
    assert len(whole.tpu40.sigma_depth_m) > 10 * 397
    with stage_threads(3):
        blocks = survey_uncertainty(returns, processed, ctx, grid)
    np.testing.assert_array_equal(blocks.tpu40.sigma_depth_m, whole.tpu40.sigma_depth_m)
    assert blocks.tpu40.terms.keys() == whole.tpu40.terms.keys()
    for name, term in whole.tpu40.terms.items():
        np.testing.assert_array_equal(blocks.tpu40.terms[name], term, err_msg=name)


def test_the_kept_points_alone_get_the_survey_tpu_to_the_bit(survey):
    # a block keeps some points' TPU: only their pulses are propagated, while every search
    # (gradient, pair scatter) still reads all the soundings (pipeline.uncertainty.tpu_subset)
    returns, processed, ctx, grid = survey
    whole = survey_uncertainty(returns, processed, ctx, grid)
    keep = processed.points.xyz_m[:, 0] <= -60.0
    part = survey_uncertainty(returns, processed, ctx, grid, wide=whole.wide, keep=keep)
    kept = keep[whole.is40]
    assert 300 < kept.sum() < 0.7 * kept.size, kept.sum()
    np.testing.assert_array_equal(part.is40, whole.is40 & keep)
    np.testing.assert_array_equal(part.points40.pulse_id, whole.points40.pulse_id[kept])
    np.testing.assert_array_equal(part.tpu40.sigma_depth_m, whole.tpu40.sigma_depth_m[kept])
    np.testing.assert_array_equal(part.tpu40.sigma_v_m, whole.tpu40.sigma_v_m[kept])
    assert part.tpu40.terms.keys() == whole.tpu40.terms.keys()
    for name, term in whole.tpu40.terms.items():
        np.testing.assert_array_equal(part.tpu40.terms[name], term[kept], err_msg=name)
    with pytest.raises(ValueError, match="`keep` needs the survey-wide"):
        survey_uncertainty(returns, processed, ctx, grid, keep=keep)


def test_searches_at_some_queries_give_their_rows_of_all(survey):
    # the pair scatter's own gradient made only where the queries' pairs read it, and the
    # regional planes only at the cells the queries take: the same figures to the bit
    from pipeline.process.classify import BATHYMETRIC_POINT
    from pipeline.uncertainty.tpu_neighbours import pair_scatter, seabed_gradient

    _, processed, _, _ = survey
    pts = processed.points
    pts = pts.select(pts.classification == BATHYMETRIC_POINT)
    xy, h = pts.xyz_m[:, :2], -pts.xyz_m[:, 2]
    q = xy[::7] + 0.3
    # the relief figure measured (every cell's plane) against given (the queries' cells)
    g, cov, relief = seabed_gradient(xy, h, q, return_cov=True, return_local_sigma=True)
    g2, cov2 = seabed_gradient(xy, h, q, return_cov=True, local_sigma=relief)
    np.testing.assert_array_equal(g2, g)
    np.testing.assert_array_equal(cov2, cov)
    g_all = seabed_gradient(xy, h, local_sigma=relief)
    _, fig = pair_scatter(xy, h, g_all, order=pts.pulse_id, return_figures=True)
    rise = fig["rise_per_m2"]
    assert rise > 0.0
    ref = pair_scatter(xy, h, g_all, order=pts.pulse_id, query_xy_m=q, rise_per_m2=rise)
    lazy = pair_scatter(
        xy, h, order=pts.pulse_id, query_xy_m=q, rise_per_m2=rise, relief_slope_sigma=relief
    )
    assert np.isfinite(ref).all()
    np.testing.assert_array_equal(lazy, ref)
