"""Water-column points: in-column returns georeferenced like bottoms and classed 64.

A detector may report, per pulse, one return from inside the water column between the surface
and the bottom (``DetectedReturns.has_column``: a scattering layer, fish, a turbidity front).
Its geometry is that of a bottom return that came back earlier, so it goes through the very
same refraction (:func:`pipeline.process.refraction.seabed_points`: entry on the fitted
surface, Snell with the phase index, in-water range at the group speed) on a copy of the
returns whose bottom is the column return; the classification rules are the bottom's, ending in
:data:`~pipeline.process.classify.WATER_COLUMN` (64) instead of 40.

Return numbering: LAS numbers the returns of a pulse in time order, so in a pulse with a column
return the surface is 1, the column return 2 and the bottom (or no-bottom-found-at point) 3 of
3 (:func:`number_returns`); pulses without one keep their numbering.

Examples
--------
The survey run appends the points after the surface and bottom points::

    processed = add_water_column_points(processed, returns, refraction_settings, classify)
"""

from __future__ import annotations

import dataclasses

import numpy as np

from pipeline.process.classify import ClassifySettings, classify_points
from pipeline.process.refraction import ProcessedPoints, RefractionSettings, seabed_points
from pipeline.process.returns import DetectedReturns, Points, ReturnKind
from pipeline.process.surface_fit import WaterSurface

__all__ = ["water_column_points", "number_returns", "add_water_column_points"]

#: Time order of the returns of one pulse, by point kind (derived surface points are not
#: returns and keep their own numbering).
_TIME_RANK = {ReturnKind.SURFACE: 1, ReturnKind.WATER_COLUMN: 2, ReturnKind.BOTTOM: 3}


def water_column_points(
    returns: DetectedReturns,
    surface: WaterSurface,
    refraction_settings: RefractionSettings | None = None,
    classify_settings: ClassifySettings | None = None,
) -> Points:
    """Classified points of the in-column returns, one per pulse that has one.

    Parameters
    ----------
    returns : DetectedReturns
        Measured navigation and detections; ``has_column`` marks the in-column returns.
    surface : WaterSurface
        The fitted water surface of the same pulses.
    refraction_settings : RefractionSettings, optional
    classify_settings : ClassifySettings, optional

    Returns
    -------
    Points
        ``kind = WATER_COLUMN``, classified (64, or noise/unclassified by the bottom rules),
        numbered as :func:`seabed_points` numbers a bottom (see :func:`number_returns`).
    """
    probe = dataclasses.replace(
        returns,
        has_bottom=returns.has_column,
        t_bottom_s=returns.t_column_s,
        bottom_confidence=returns.column_confidence,
        bottom_amplitude=returns.column_amplitude,
        t_bottom_sigma_s=None,  # a detector's bottom timing sigma is not the column's
        has_column=None,
        t_column_s=None,
        column_confidence=None,
        column_amplitude=None,
    )
    pts = seabed_points(probe, surface, refraction_settings)
    pts = pts.replace(kind=np.full(len(pts), ReturnKind.WATER_COLUMN, dtype=np.uint8))
    return classify_points(pts, classify_settings)


def number_returns(points: Points) -> Points:
    """LAS return numbers in time order for the pulses that have a water-column point.

    Parameters
    ----------
    points : Points
        Surface, water-column and bottom points (any order; other kinds are left alone).

    Returns
    -------
    Points
        A copy where, in each pulse with a ``WATER_COLUMN`` point, the surface, column and
        bottom points are numbered 1, 2, 3 in that order (``number_of_returns`` = how many of
        them the pulse has); every other point keeps its numbering.
    """
    kind = points.kind
    rank = np.zeros(len(points), dtype=np.int64)
    for k, r in _TIME_RANK.items():
        rank[kind == k] = r
    pulses = np.unique(points.pulse_id[kind == ReturnKind.WATER_COLUMN])
    sel = np.flatnonzero(np.isin(points.pulse_id, pulses) & (rank > 0))
    if sel.size == 0:
        return points
    order = sel[np.lexsort((rank[sel], points.pulse_id[sel]))]
    pid = points.pulse_id[order]
    first = np.flatnonzero(np.r_[True, pid[1:] != pid[:-1]])
    group = np.repeat(np.arange(first.size), np.diff(np.r_[first, pid.size]))
    number = points.return_number.copy()
    total = points.number_of_returns.copy()
    number[order] = np.arange(order.size) - first[group] + 1
    total[order] = np.diff(np.r_[first, pid.size])[group]
    return points.replace(return_number=number, number_of_returns=total)


def add_water_column_points(
    processed: ProcessedPoints,
    returns: DetectedReturns,
    refraction_settings: RefractionSettings | None = None,
    classify_settings: ClassifySettings | None = None,
) -> ProcessedPoints:
    """``processed`` with the water-column points appended and the returns renumbered.

    Parameters
    ----------
    processed : ProcessedPoints
        From :func:`pipeline.process.refraction.georeference` (surface fit and points).
    returns : DetectedReturns
        The returns ``processed`` was made from.
    refraction_settings : RefractionSettings, optional
    classify_settings : ClassifySettings, optional

    Returns
    -------
    ProcessedPoints
        The same object when no pulse has a column return (outputs unchanged).
    """
    if not np.any(returns.has_column):
        return processed
    col = water_column_points(returns, processed.surface, refraction_settings, classify_settings)
    points = number_returns(Points.concatenate([processed.points, col]))
    return dataclasses.replace(processed, points=points)
