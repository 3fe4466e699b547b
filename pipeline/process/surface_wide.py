"""The survey-wide part of the water-surface fit: the water level, the sea's sigma, dry or wet.

:func:`~pipeline.process.surface_fit.fit_water_surface` decides most things per pulse from its
neighbours (the local planes within ``radius_m`` and ``time_window_s``, the land support within
``land_radius_m``), but a few of its inputs are figures of the whole survey
(:class:`SurfaceWide`): the global water plane (the histogram mode of the surface heights and
the band fit around it), the sea's sigma (the not-surface band below the level, and the land
seeds' height above it), whether clipped surface bounds set the level (no unclipped return
shows water), whether the survey saw no water at all, and whether it has fewer than three
surface returns. Measured once over the whole survey (:func:`surface_wide`) and handed to the
fit of any subset of its pulses (a spatial tile and its halo), they make that subset's fit the
one the whole survey's fit gives its pulses, as far as its neighbour searches stay inside it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.optics import SPEED_OF_LIGHT_M_S
from pipeline.process.returns import DetectedReturns
from pipeline.process.surface_evidence import clipped_into_column, level_points, no_water_seen
from pipeline.process.surface_land import global_plane, sea_sigma_m, where_certain

__all__ = ["SurfaceInputs", "SurfaceWide", "surface_inputs", "surface_points_m", "surface_wide"]


@dataclass(frozen=True)
class SurfaceWide:
    """The water-surface fit's survey-wide figures.

    Attributes
    ----------
    global_plane : (3,) float64
        ``(z0_m, dz_dx, dz_dy)`` of the global water plane.
    global_sigma_m : float
        Its band fit's residual standard deviation.
    bounds_set_level : bool
        Clipped surface bounds join the level points (no unclipped return shows water:
        :func:`~pipeline.process.surface_evidence.level_points`).
    no_water : bool
        No evidence of water anywhere: every return is land
        (:func:`~pipeline.process.surface_evidence.no_water_seen`).
    land_sigma_m : float
        The sea's sigma measured from the level points' heights (the land seeds' height,
        :func:`~pipeline.process.surface_land.land_surface_points`).
    below_m : float
        Depth below the level where the not-surface band starts
        (``max(below_margin_m, below_sea_sigmas * sigma_sea)``).
    few_surface_returns : bool
        Fewer than 3 timed surface returns in the survey: every water pulse is flagged as on
        the global plane.
    """

    global_plane: np.ndarray
    global_sigma_m: float
    bounds_set_level: bool
    no_water: bool
    land_sigma_m: float
    below_m: float
    few_surface_returns: bool


@dataclass(frozen=True)
class SurfaceInputs:
    """Per-pulse points the surface fit starts from, ``(n,)`` or ``(n, 3)`` each.

    ``ps``, ``pb``, ``pc``: the surface, bottom and in-column returns' straight (air) points;
    ``bound``: surface returns clipped into the column; ``has_s``: surface returns that time
    the surface; ``wet``: a bottom ``level_min_depth_m`` under the surface return.
    """

    ps: np.ndarray
    pb: np.ndarray
    pc: np.ndarray
    bound: np.ndarray
    has_s: np.ndarray
    wet: np.ndarray


def surface_points_m(returns: DetectedReturns, air_index: float) -> np.ndarray:
    """Surface-return points ``origin + direction * c t_s / (2 n_air)``; (n, 3), 0 where none."""
    r = SPEED_OF_LIGHT_M_S * returns.t_surface_s / (2.0 * air_index)
    p = returns.origin_meas_m + returns.direction_meas * r[:, None]
    return np.where(returns.has_surface[:, None], p, 0.0)


def surface_inputs(returns: DetectedReturns, st) -> SurfaceInputs:
    """The straight (air) points of every return and which surface returns time the surface."""
    o, d = returns.origin_meas_m, returns.direction_meas
    c = SPEED_OF_LIGHT_M_S
    ps = surface_points_m(returns, st.air_index)
    # a surface return clipped into the column's plateau is only an early bound of the
    # surface (pipeline.process.detect_clipped): not a timing reference of the fit; it sets
    # the level only when nothing else shows water (pipeline.process.surface_evidence)
    bound = clipped_into_column(returns)
    has_s = returns.has_surface & ~bound
    pb = o + d * (c * returns.t_bottom_s / (2.0 * st.air_index))[:, None]
    pc = o + d * (c * returns.t_column_s / (2.0 * st.air_index))[:, None]
    wet = returns.has_bottom & (ps[:, 2] - pb[:, 2] > st.level_min_depth_m)
    return SurfaceInputs(ps, pb, pc, bound, has_s, wet)


def surface_wide(returns: DetectedReturns, st, inputs: SurfaceInputs | None = None) -> SurfaceWide:
    """Measure the surface fit's survey-wide figures from every pulse of a survey.

    Parameters
    ----------
    returns : DetectedReturns
        The whole survey, ``(n_pulses,)`` per field.
    st : SurfaceFitSettings
    inputs : SurfaceInputs, optional
        :func:`surface_inputs` of the same returns, if already made.
    """
    p = inputs or surface_inputs(returns, st)
    ps, has_s, bound = p.ps, p.has_s, p.bound
    lvl, lvl_wet = level_points(has_s, bound, p.wet)
    level_m = float(np.median(ps[lvl, 2])) if lvl.any() else np.nan
    no_water = no_water_seen(returns, p.wet, ps[:, 2] - p.pc[:, 2], level_m, st)
    if lvl.sum() >= 3:
        gplane, gsigma = global_plane(ps[lvl], st, lvl_wet[lvl])
    else:
        level = st.water_level_hint_m
        gplane = np.array([st.fallback_water_level_m if level is None else level, 0.0, 0.0])
        gsigma = 0.0
    z0, gx, gy = gplane
    res_s = np.where(lvl, ps[:, 2] - (z0 + gx * ps[:, 0] + gy * ps[:, 1]), 0.0)
    # the sea is measured where water is certain: on the surface returns with a bottom well
    # under them, when there are enough. A calm sea seen off nadir from high up returns no
    # surface echo on many pulses, only the seabed through it; within the band those echoes
    # read as a rough sea (0.38 m on suite tuning seed 7201, flat water, 694 m, a 0-5 m shoal),
    # whose troughs then took them in as surface points (the planes sank to the seabed: 300
    # soundings 1-1.8 m short)
    sea_pts = where_certain(lvl, lvl_wet, st)
    land_sigma = sea_sigma_m(res_s[sea_pts], st) if sea_pts.any() else 0.0
    # a trough is water: the band below the level widens with the measured sea, as the land
    # margin above it does (a 2.5 m Hs sea has troughs 1.5 m down; a fixed 1 m band dropped
    # them, the pulses fell back to the mean plane and went 1-2 m deep)
    below = st.below_margin_m
    sea_s = where_certain(has_s, lvl_wet, st)
    if sea_s.any():
        below = max(below, st.below_sea_sigmas * sea_sigma_m(res_s[sea_s], st))
    return SurfaceWide(
        global_plane=gplane,
        global_sigma_m=float(gsigma),
        bounds_set_level=bool(np.any(lvl & ~has_s)),
        no_water=bool(no_water),
        land_sigma_m=float(land_sigma),
        below_m=float(below),
        few_surface_returns=bool(has_s.sum() < 3),
    )
