"""A survey's detections to classified, gridded points with their TPU: ``bathy run``'s middle.

:func:`process_survey` runs, on detections held in memory, the stages between the chunk loop
and the outputs, in their order: processing (surface fit, refraction, classes), the
water-column points, the grid, the TPU, the submerged objects and rejected soundings. A whole
survey runs it once (:func:`pipeline.run_survey.run_survey`); a survey too large to hold runs it
on a sample of its blocks and then on each block, with the sample's survey-wide figures handed
in (:mod:`pipeline.survey_blocks`).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

import numpy as np

from pipeline.process.context import ProcessingContext
from pipeline.process.grid import Grid
from pipeline.process.grid_axes import occupied_axes
from pipeline.process.refraction import ProcessedPoints
from pipeline.process.returns import DetectedReturns
from pipeline.stages import Plan, StageClock, trim_heap
from pipeline.survey_tiles import TileLayout, grid_by_tiles

__all__ = ["SurveyFigures", "SurveyProducts", "process_survey"]


@dataclass(frozen=True)
class SurveyFigures:
    """What a block of a survey is handed from its survey (None: measured from the block).

    Attributes
    ----------
    wide : SurveyWide or None
        Processing's survey-wide figures (:mod:`pipeline.process.survey_wide`).
    tpu_wide : TpuSurveyWide or None
        The TPU's (:mod:`pipeline.uncertainty.tpu_survey_wide`).
    datum : Datum or None
        The grid's datum (:func:`~pipeline.process.datum.survey_datum`).
    surface_range_m : (float, float) or None
        The class-41 heights' range the rejection of implausible surfaces tests against.
    """

    wide: Any = None
    tpu_wide: Any = None
    datum: Any = None
    surface_range_m: tuple[float, float] | None = None


@dataclass(frozen=True)
class SurveyProducts:
    """What :func:`process_survey` makes.

    Attributes
    ----------
    processed : ProcessedPoints
        Points with their TPU, objects (class 43) and rejections (class 7).
    unc : SurveyUncertainty
    grid : Grid
        On the layout's bounds (or some of its rows and columns: ``process_survey``'s
        ``held_axes``), the rejected points left out, objects designated.
    datum : Datum
    n_objects : int
    rejected : dict of str to int
    figures : SurveyFigures
        The survey-wide figures used (measured here, or handed in).
    """

    processed: ProcessedPoints
    unc: Any
    grid: Grid
    datum: Any
    n_objects: int
    rejected: dict[str, int]
    figures: SurveyFigures


def process_survey(
    returns: DetectedReturns,
    scene,
    plan: Plan,
    ctx: ProcessingContext,
    layout: TileLayout,
    clock: StageClock,
    log=print,
    figures: SurveyFigures | None = None,
    tpu_keep=None,
    process_at: tuple[np.ndarray, np.ndarray] | None = None,
    held_axes: bool = False,
) -> SurveyProducts:
    """Process, grid and propagate the TPU of ``returns`` (``bathy run``'s stages, in order).

    Parameters
    ----------
    returns : DetectedReturns
        The survey's detections (or a block's, with its halo), ``(n_pulses,)`` per field.
    scene : Scene
    plan : Plan
        Whether the water-column points are made.
    ctx : ProcessingContext
    layout : TileLayout
        The grid's bounds and tiles.
    clock : StageClock
    log : callable
    figures : SurveyFigures, optional
        The survey's figures, for a block of it; default: measured from ``returns``.
    tpu_keep : callable, optional
        ``tpu_keep(points) -> (n_points,) bool``: the points whose TPU the caller keeps (a
        block's, :func:`~pipeline.survey_blocks.tpu_points`; the others' is not propagated,
        so their classes and cells are not the survey's); needs ``figures``. The class-43
        and rejection tests are made at the same points (:mod:`pipeline.survey_cleanup`).
        Default: all.
    process_at : ((n_pulses,) bool, (n_pulses,) bool), optional
        The pulses whose local planes and whose kriged sea are made (a block's,
        :func:`~pipeline.survey_block_reach.processing_rows`: every pulse whose points or
        surface what the block keeps reads); needs ``figures``. Default: all.
    held_axes : bool
        Grid only the rows and columns of the layout's grid that hold a point
        (:func:`~pipeline.process.grid_axes.occupied_axes`, of every processed point): a
        blocked survey's sample, whose blocks are spread over the survey's bounds. Its
        grid and its cells are then bounded by the sample, not the survey's area; where
        they have a cell it is the whole grid's.
    """
    from pipeline.process.datum import survey_datum
    from pipeline.process.seabed_outliers import water_surface_range_m
    from pipeline.process.survey_points import process_detections
    from pipeline.survey_cleanup import objects_and_rejections
    from pipeline.uncertainty.survey_uncertainty import survey_uncertainty, with_tpu
    from pipeline.uncertainty.tpu_facet import UNCORRECTED_TERM

    fig = figures or SurveyFigures()
    ps, fr = scene.process, scene.frame
    origin = (fr.origin_easting_m, fr.origin_northing_m, 0.0)
    with clock.stage("process"):
        planes_at, krige_at = (None, None) if process_at is None else process_at
        processed = process_detections(
            returns,
            ctx,
            ps.classify,
            water_column=False,
            wide=fig.wide,
            planes_at=planes_at,
            krige_at=krige_at,
        )
    if processed.surface.facet_slope_var is not None:
        log(
            f"  wave facets: mean-square slope {ctx.refraction.facet_mss:.4f} (Cox-Munk at the "
            f"logged wind, process.wind_speed_m_s: {ctx.sources['process.wind_speed_m_s']}); "
            "soundings raised by their in-water paths' mean excess"
        )
    elif ctx.refraction.facet_mss > 0.0:
        log("  wave facets: none (the surface echoes show no wave sea)")
    if plan.runs("water_column"):
        from pipeline.process.water_column import add_water_column_points

        with clock.stage("water_column"):
            processed = add_water_column_points(processed, returns, ctx.refraction, ps.classify)
    with clock.stage("grid"):
        # one datum for the grid (the user's water level, else the mean measured surface):
        # depth below the local fitted surface would carry the wave heights into the grid
        datum = fig.datum if fig.datum is not None else survey_datum(processed.points, ps.datum)
        axes = None
        if held_axes:
            # once, of every point: the regridding without the rejected keeps these axes
            xy = processed.points.xyz_m
            axes = occupied_axes(xy[:, 0], xy[:, 1], layout.bounds_m, layout.resolution_m)

        def make_grid(points):
            return grid_by_tiles(points, layout, origin, fr.crs, datum.water_level_m, ps, axes)

        grid = make_grid(processed.points)
    with clock.stage("tpu"):
        keep = None if tpu_keep is None else tpu_keep(processed.points)
        unc = survey_uncertainty(returns, processed, ctx, grid, wide=fig.tpu_wide, keep=keep)
        processed = dataclasses.replace(processed, points=with_tpu(processed.points, unc))
    trim_heap()  # the TPU's temporaries: the class-43 and rejection tests start low
    left_on = unc.tpu40.terms.get(UNCORRECTED_TERM)
    if left_on is not None and left_on.size:
        log(
            "  wave facets (correction off): the excess left on the soundings is in the TPU, "
            f"median {np.median(left_on[:, -1]):.3f} m (process.wave_facet_correction)"
        )
    surface_range = fig.surface_range_m
    if surface_range is None:
        surface_range = water_surface_range_m(processed.points)
    with clock.stage("process"):
        processed, unc, grid, n_obj, rejected = objects_and_rejections(
            processed, unc, grid, make_grid, ps, datum.water_level_m, surface_range, keep
        )
    used = SurveyFigures(processed.wide, unc.wide, datum, surface_range)
    return SurveyProducts(processed, unc, grid, datum, n_obj, rejected, used)
