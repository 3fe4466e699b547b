"""After the TPU: submerged objects (class 43), then rejected soundings (class 7), then the grid.

The order matters: the objects are found first so that the rejection rules never test a point
standing on a cube (:mod:`pipeline.process.seabed_outliers`), and the grid is made again
without the rejected points before the objects' least depths are put in their cells
(:func:`pipeline.process.grid.designate_objects`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import numpy as np

from pipeline.process.grid import Grid, designate_objects
from pipeline.process.objects import classify_objects_fit
from pipeline.process.seabed_outliers import REJECTED, reject_seabed_outliers
from pipeline.uncertainty.survey_uncertainty import without_points

__all__ = ["objects_and_rejections"]


def objects_and_rejections(
    processed,
    unc,
    grid: Grid,
    make_grid: Callable,
    ps,
    water_level_m,
    surface_range_m=None,
    tested=None,
):
    """Classify objects, reject gross errors, and bring the grid and the cells up to date.

    Parameters
    ----------
    processed : ProcessedSurvey
        Points with their TPU (:func:`~pipeline.uncertainty.survey_uncertainty.with_tpu`).
    unc : SurveyUncertainty
        The survey's TPU (points and cells).
    grid : Grid
        The grid of ``processed.points``.
    make_grid : callable
        ``make_grid(points) -> Grid`` on the survey's bounds, datum and statistic.
    ps : ProcessSettings
        ``objects``, ``outliers`` and ``grid_object_least_depth`` are read.
    water_level_m : float
        The grid's datum (elevation of the water level).
    surface_range_m : (float, float), optional
        The survey's class-41 height range, when ``processed`` is a block of it
        (:func:`~pipeline.process.seabed_outliers.water_surface_range_m`).
    tested : (n_points,) bool, optional
        The points the class-43 and far-below tests are made at (default: all); every
        point is still a reference point of the tested ones' planes. A block of a survey
        passes the points whose TPU it propagated (``process_survey``'s ``tpu_keep``): its
        kept points and those whose class their rejection test reads (below).

    Returns
    -------
    processed, unc, grid
        Updated; the grid and the cells leave the rejected points out.
    n_objects : int
        Class-43 points.
    rejected : dict of str to int
        Rejected points per rule.
    """
    # class 43: seabed points standing above the local seabed by k sigma of their TPU. Its
    # test reads the point's own TPU and its neighbours' positions only; the rejection test
    # of a kept point reads which neighbours within `tests_reach_m` are still class 40 (their
    # class-43 test and TVU rule: their own TPU). That chain ends there, so the points whose
    # TPU a block propagates (`tpu_points`: the kept ones and those within that reach of
    # them) are the ones both tests need at (pipeline.survey_blocks)
    pts, n_obj, fitted = classify_objects_fit(processed.points, ps.objects, tested)
    # gross errors: class 7, withheld; the grid and the cells again without them (the far-below
    # test reads the objects' planes where it tests the same points)
    pts, rejected = reject_seabed_outliers(
        pts, ps.outliers, ps.objects, surface_range_m, tested, fitted
    )
    del fitted  # (~58 B a sounding, not read again)
    processed = dataclasses.replace(processed, points=pts)
    if sum(rejected.values()):
        grid = make_grid(processed.points)
        kept = (pts.flags[unc.is40] & np.uint16(REJECTED)) == 0
        unc = without_points(unc, kept, grid)
    if ps.grid_object_least_depth:
        # the object's least depth in its cell: the median would erase a cube (grid.py)
        grid = designate_objects(grid, pts, water_level_m)
    return processed, unc, grid, n_obj, rejected
