"""A survey's classified points from its detections: measured data and the context only.

Surface fit, refraction correction and classes (:func:`~pipeline.process.refraction.
georeference`), then the no-bottom-found-at points (:func:`no_bottom_points`) and the
water-column points (:func:`~pipeline.process.water_column.add_water_column_points`, only
where the plan runs them).
"""

from __future__ import annotations

import dataclasses
import itertools

import numpy as np
from scipy.spatial import cKDTree

from pipeline.process.classify import (
    BATHYMETRIC_POINT,
    GROUND,
    NO_BOTTOM_FOUND_AT,
    ClassifySettings,
)
from pipeline.process.context import ProcessingContext
from pipeline.process.refraction import ProcessedPoints, georeference, seabed_points
from pipeline.process.return_order import number_all_returns
from pipeline.process.returns import DetectedReturns, PointFlag, Points, ReturnKind
from pipeline.process.survey_wide import SurveyWide

__all__ = ["process_detections", "no_bottom_points", "contradicted_claims"]


def process_detections(
    returns: DetectedReturns,
    ctx: ProcessingContext,
    classify: ClassifySettings,
    *,
    water_column: bool = True,
    wide: SurveyWide | None = None,
    planes_at: np.ndarray | None = None,
    krige_at: np.ndarray | None = None,
) -> ProcessedPoints:
    """Points from the detections, as ``bathy run`` makes them.

    Parameters
    ----------
    returns : DetectedReturns
        The survey's detections and measured navigation, ``(n_pulses,)`` per field.
    ctx : ProcessingContext
        What processing assumes (:func:`pipeline.process.context.processing_context`).
    classify : ClassifySettings
        LAS class rules.
    water_column : bool
        Add the class-64 points of in-column returns (the detector reports them).
    wide : SurveyWide, optional
        The whole survey's survey-wide figures, when ``returns`` are a tile of it
        (:func:`~pipeline.process.survey_wide.survey_wide`); None: measured from ``returns``.
    planes_at, krige_at : (n_pulses,) bool ndarray, optional
        Need ``wide``. The local planes and the kriged sea (of the soundings and of the
        class-45 points) only at those pulses (:func:`~pipeline.process.refraction.
        georeference`; a block's, :mod:`pipeline.survey_block_reach`): a pulse in
        ``krige_at`` whose kriging reads only echoes in ``planes_at`` gets the points of a
        run asking all, the others' are not the survey's. Default: all.

    Returns
    -------
    ProcessedPoints
        The fitted surface, the classified points (surface, bottom, class 45, class 64) and the
        uncorrected bottoms.
    """
    from pipeline.process.water_column import add_water_column_points

    ins = ctx.instrument
    processed = georeference(
        returns,
        surface_settings=ctx.surface_fit,
        refraction_settings=ctx.refraction,
        classify_settings=classify,
        windows=ins.windows,
        wide=wide,
        planes_at=planes_at,
        krige_at=krige_at,
    )
    # the class-45 points join their pulses' echo sequence: number every pulse again (LAS
    # return numbers 1..n in time order, the class-45 point after its surface)
    claims = no_bottom_points(returns, processed, ctx, krige_at=krige_at)
    withheld = contradicted_claims(claims, processed.points, classify)
    points = Points.concatenate([processed.points, claims.select(~withheld)])
    processed = dataclasses.replace(
        processed,
        points=number_all_returns(points),
        claims_withheld=int(withheld.sum()),
        withheld_pulse_id=claims.pulse_id[withheld],
    )
    if water_column:
        processed = add_water_column_points(processed, returns, ctx.refraction, classify)
    return processed


def no_bottom_points(
    returns: DetectedReturns,
    processed: ProcessedPoints,
    ctx: ProcessingContext,
    krige_at: np.ndarray | None = None,
) -> Points:
    """ASPRS class 45 "no-bottom-found-at" points of the water pulses that have no bottom.

    Each is placed, along the refracted beam, at the pulse's detection limit
    (``returns.t_no_bottom_s``, :mod:`pipeline.process.detection_limit`): the depth down to which
    a bottom of the assumed reflectance would have been detected, so the absence of a bottom is
    established there and no deeper. A full-waveform pulse whose column gave no limit (too weak
    or too short to measure its decay: over land, or a bottom merged with the surface in a metre
    of water) establishes nothing and gets no point. A photon-counting window's limit is the
    lowest height its histogram still shows the water column at
    (:func:`~pipeline.process.detect_photons.detect_photon_events`), not the end of the range
    gate: opaque water establishes nothing below its surface. Detections without limits
    (``t_no_bottom_s`` None) keep the end of the recorded window, ``window_s − pre_trigger_s``
    after the surface echo. ``krige_at`` (``(n_pulses,)`` bool): the sea is kriged above
    those pulses' points only (:func:`~pipeline.process.refraction.seabed_points`).
    """
    ins = ctx.instrument
    none = returns.has_surface & ~returns.has_bottom
    t_end = returns.t_surface_s + (ins.window_s - ins.pre_trigger_s)
    if returns.t_no_bottom_s is not None:
        none &= returns.t_no_bottom_s > 0.0
        t_end = returns.t_no_bottom_s
    probe = dataclasses.replace(
        returns,
        has_bottom=none,
        t_bottom_s=np.where(none, t_end, 0.0),
        bottom_confidence=np.where(none, 1.0, 0.0),
        bottom_amplitude=None,
        t_bottom_sigma_s=None,
        t_no_bottom_s=None,
    )
    pts = seabed_points(probe, processed.surface, ctx.refraction, krige_at=krige_at)
    bad = PointFlag.LAND | PointFlag.GRAZING | PointFlag.ABOVE_SURFACE
    pts = pts.select((pts.flags & np.uint16(bad)) == 0)
    # made by processing, not measured: LAS's synthetic flag; no echo of its own, so amplitude
    # 0 where the detector reports amplitudes (None would drop every point's amplitude when the
    # points are joined)
    return pts.replace(
        classification=np.full(pts.pulse_id.shape, NO_BOTTOM_FOUND_AT, dtype=np.uint8),
        flags=pts.flags | np.uint16(PointFlag.SYNTHETIC),
        amplitude=None if returns.bottom_amplitude is None else np.zeros(len(pts)),
    )


def contradicted_claims(claims: Points, points: Points, classify: ClassifySettings) -> np.ndarray:
    """``(n_claims,)`` bool: class-45 claims a nearby class-40 sounding or ground contradicts.

    A claim states that there is no bottom down to its depth. A class-40 sounding within
    ``classify.no_bottom_radius_m`` (horizontally) that is shallower than the claim by more
    than ``classify.no_bottom_margin_m`` shows a bottom above that depth: the claim is not
    made. Such claims come from bottoms merged with the surface echo over a shoal, or from a
    seabed darker than the one the limit assumes (:mod:`pipeline.process.detection_limit`).
    A class-2 ground point within ``classify.no_bottom_land_radius_m`` is land: the seabed
    rises to it, at its depth (negative, above the water), and contradicts a claim the same way
    (a land echo's tail read as a column gave claims metres deep a few metres from the shore:
    suite tuning seeds 0, 6 and 24, :mod:`pipeline.process.column_level`). All False where the
    radii are 0 or there is no sounding and no ground.
    """
    sea = (points.classification == BATHYMETRIC_POINT) & (points.kind == ReturnKind.BOTTOM)
    land = points.classification == GROUND
    out = np.zeros(len(claims), dtype=bool)
    for rows, r in ((sea, classify.no_bottom_radius_m), (land, classify.no_bottom_land_radius_m)):
        if r > 0.0 and rows.any() and len(claims):
            shallowest = _shallowest_near(
                claims.xyz_m[:, :2], points.xyz_m[rows, :2], points.depth_m[rows], r
            )
            out |= claims.depth_m > shallowest + classify.no_bottom_margin_m
    return out


def _shallowest_near(
    xy: np.ndarray, at_xy: np.ndarray, depth_m: np.ndarray, r: float
) -> np.ndarray:
    """``(n,)``: the least of ``depth_m`` at ``at_xy`` within ``r`` of each ``xy`` (inf: none)."""
    tree = cKDTree(at_xy)
    near = tree.query_ball_point(xy, r, workers=-1)
    counts = np.fromiter(map(len, near), dtype=np.int64, count=len(near))
    out = np.full(len(xy), np.inf)
    has = counts > 0
    if has.any():
        flat = np.fromiter(itertools.chain.from_iterable(near), dtype=np.int64, count=counts.sum())
        starts = np.concatenate([[0], np.cumsum(counts)[:-1]])[has]
        out[has] = np.minimum.reduceat(depth_m[flat], starts)
    return out
