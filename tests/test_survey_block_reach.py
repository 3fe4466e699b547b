"""How far past a block its pulses' planes and kriged sea are made (issue 15,
``pipeline.survey_block_reach``): the reaches' sums, and the rows they take."""

from __future__ import annotations

import math

import numpy as np

from pipeline.process.context import processing_context
from pipeline.survey_block_reach import processing_reach_m, processing_rows
from pipeline.survey_blocks import block_halo_m
from pipeline.survey_blocks import tests_reach_m as reach_of_tests
from pipeline.uncertainty.tpu_survey_wide import tpu_halo_m
from tests.test_process_tiles import _scene


def test_the_sea_is_kriged_where_the_kept_points_readers_reach_and_planes_one_kriging_further():
    scene = _scene()
    ctx, ps = processing_context(scene), scene.process
    beam = 17.3
    krige, planes = processing_reach_m(ctx, ps, beam)
    kept = beam + reach_of_tests(ps) + ps.grid_resolution_m
    # the TPU's searches from a kept point, then a beam to the soundings' pulses
    assert krige >= kept + tpu_halo_m(ctx.tpu) + beam
    # the wave pool (planes only): a beam to the kept point's pulse, one to its entry, the
    # cell's diagonal, one from a contributor's entry to its pulse
    assert planes >= kept + 3.0 * beam + math.sqrt(2.0) * ctx.tpu.wave_pool_cell_m
    assert planes >= krige + beam + ctx.surface_fit.radius_m
    # inside the loaded halo: processing's own reach past the planes is what is loaded more
    assert planes < block_halo_m(ctx, ps, beam)


def test_rows_within_the_reach_of_the_box_grown_to_its_own_pulses():
    pos = np.array([[0.0, 0.0], [10.0, 5.0], [14.9, 5.0], [15.1, 5.0], [-3.0, 5.0], [5.0, 21.0]])
    own = np.array([False, False, False, False, True, False])
    box = (0.0, 10.0, 0.0, 10.0)
    got = processing_rows(pos, own, box, 5.0)
    # the box grows west to its own pulse at x = -3; the margin is square
    np.testing.assert_array_equal(got, [True, True, True, False, True, False])
    np.testing.assert_array_equal(processing_rows(pos, np.zeros(6, bool), box, 0.0)[:2], True)
