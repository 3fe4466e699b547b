"""Coverage of the requested area: fractions counted by hand."""

import numpy as np

from pipeline.process.coverage import area_coverage


def test_half_the_area_covered():
    # 10 x 10 cells of 1 m; points fill the western half (x < 5), two per cell
    x, y = np.meshgrid(np.arange(0.25, 5.0, 0.5), np.arange(0.5, 10.0, 1.0))
    assert area_coverage(np.column_stack([x.ravel(), y.ravel()]), (0, 10, 0, 10), 1.0) == 0.5


def test_points_outside_the_area_cover_nothing():
    xy = np.array([[-1.0, 5.0], [12.0, 5.0], [5.0, 10.0]])  # ymax is exclusive
    assert area_coverage(xy, (0, 10, 0, 10), 1.0) == 0.0
    assert area_coverage(np.zeros((0, 2)), (0, 10, 0, 10), 1.0) == 0.0


def test_one_line_short_of_the_area_is_a_small_fraction():
    # a 150 m line along y at x = 200 beside a 110 x 150 m area at x 0-110: nothing inside
    xy = np.column_stack([np.full(300, 200.0), np.linspace(0, 149, 300)])
    assert area_coverage(xy, (0, 110, 0, 150), 5.0) == 0.0
