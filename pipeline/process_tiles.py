"""Processing by spatial tiles: each tile with the halo its neighbour searches reach into.

Processing (:func:`~pipeline.process.survey_points.process_detections`: surface fit, sea
kriging, refraction, classes, class-45 points, return numbers) is run on one tile of the
survey at a time (:func:`process_by_tiles`): the pulses whose position
(:func:`~pipeline.detection_store.pulse_position_m`) lies in the tile grown by a halo, with
the survey-wide figures of the whole survey handed in
(:class:`~pipeline.process.survey_wide.SurveyWide`); only the points of the pulses whose
position lies in the tile itself are kept. Those points are the whole survey's points of those
pulses, to the bit, as long as every neighbour search made for a tile's pulse stays inside
the halo.

Halo (:func:`processing_halo_m`)
--------------------------------
Measured from a pulse's position, processing looks

* along its own beam (:func:`beam_reach_m`): its water entry on the fitted plane (a pulse
  without a surface echo sits at its bottom, the entry is above it), its sounding and its
  class-45 point, which the sea is kriged at;
* from there, for neighbours: the local plane's ``k_neighbours`` within ``radius_m``
  (``sqrt 2 radius_m`` in ``(x, y, v t)`` with a time window, the bound of its k-d tree
  query); and the kriging's ``kriging_neighbours`` nearest echoes in ``(x, y, v t)``
  (``kriging_reach_m``);
* and a neighbour is used as its own processing made it: an echo is a water-surface point if
  its pulse is water and not an outlier of its own plane (another ``sqrt 2 radius_m``), and
  water if it is not land, decided from land candidates within ``land_radius_m`` whose
  candidacy is decided within ``land_radius_m`` of them (``2 land_radius_m``).

* a class-45 claim is tested against the class-40 soundings within ``no_bottom_radius_m`` of
  it (:func:`~pipeline.process.survey_points.contradicted_claims`), each made as its own
  pulse's processing made it: another beam reach, that radius and that pulse's own reach.

So ``halo = beam reach + kriging reach + sqrt 2 radius_m + 2 land_radius_m`` (a pulse's own
reach), plus ``beam reach`` and the larger of ``no_bottom_radius_m`` and
``no_bottom_land_radius_m`` where the class-45 test runs.

Not bounded by a setting
------------------------
* The kriging's nearest echoes: ``kriging_neighbours`` nearest in ``(x, y, v t)``, as far as
  the echoes are sparse (a gap in the glint, the edge of the swath). ``kriging_reach_m``
  (default the surface fit's ``radius_m``: where the echoes are dense enough to fit planes,
  the 12 nearest lie within it) is an allowance, not a bound: a sounding whose nearest echoes
  lie farther is kriged from others in its tile than in the whole survey.
* The land regions: land candidates linked within ``land_link_m`` form regions, and a region is
  land if it holds a seed or is wider than ``land_extent_sigmas`` sea sigmas; a region can run
  across the whole survey (a shoreline), so a tile sees only the part within its halo. A region
  cut by the halo may lose its seed, or its width, in the tile: its candidates near the tile
  then read as water.
* The beam reach is a measured maximum over the survey's pulses (a streamed aggregate), not a
  setting; the local plane's entry is allowed the sea's band around the global plane.
"""

from __future__ import annotations

import numpy as np

from pipeline.optics import SPEED_OF_LIGHT_M_S
from pipeline.process.classify import ClassifySettings
from pipeline.process.returns import Points
from pipeline.process.survey_points import process_detections
from pipeline.survey_tiles import TileLayout, returns_position_m

__all__ = ["beam_reach_m", "processing_halo_m", "tile_rows", "process_by_tiles"]


def beam_reach_m(returns, ctx, wide) -> float:
    """Farthest horizontal distance from a pulse's position to where processing uses its beam.

    Per pulse with a return, ``|d_xy|`` times the largest range difference between its
    position's return (surface, else bottom, else column) and its other returns, its class-45
    point (the detection limit, else the window's end) and its entry on the global water
    plane, plus the horizontal run of the beam across the sea's band around that plane (the
    local plane lies within it). A maximum: streamed chunk by chunk, it is the same.

    Parameters
    ----------
    returns : DetectedReturns
        ``(n_pulses,)`` per field.
    ctx : ProcessingContext
        The instrument's window and the surface-fit settings.
    wide : SurveyWide
        The survey's global plane and sea band.

    Returns
    -------
    float
        Metres (0 without returns).
    """
    st, ins = ctx.surface_fit, ctx.instrument
    o, d = returns.origin_meas_m, returns.direction_meas
    to_range = SPEED_OF_LIGHT_M_S / (2.0 * st.air_index)
    has_c = np.zeros(len(returns), bool) if returns.has_column is None else returns.has_column
    t_c = np.zeros(len(returns)) if returns.t_column_s is None else returns.t_column_s
    t_pos = np.where(returns.has_surface, returns.t_surface_s, 0.0)
    t_pos = np.where((t_pos == 0.0) & returns.has_bottom, returns.t_bottom_s, t_pos)
    t_pos = np.where((t_pos == 0.0) & has_c, t_c, t_pos)
    seen = t_pos > 0.0
    if not seen.any():
        return 0.0
    r_pos = to_range * t_pos
    # the class-45 point (pipeline.process.survey_points.no_bottom_points)
    none = returns.has_surface & ~returns.has_bottom
    t_end = returns.t_surface_s + (ins.window_s - ins.pre_trigger_s)
    if returns.t_no_bottom_s is not None:
        none &= returns.t_no_bottom_s > 0.0
        t_end = returns.t_no_bottom_s
    ranges = [
        np.where(returns.has_surface, to_range * returns.t_surface_s, r_pos),
        np.where(returns.has_bottom, to_range * returns.t_bottom_s, r_pos),
        np.where(has_c, to_range * t_c, r_pos),
        np.where(none, to_range * t_end, r_pos),
    ]
    z0, gx, gy = wide.surface.global_plane
    down = d[:, 2] - gx * d[:, 0] - gy * d[:, 1]
    r_g = (z0 + gx * o[:, 0] + gy * o[:, 1] - o[:, 2]) / np.where(down < 0.0, down, -1.0)
    ranges.append(np.where(down < 0.0, r_g, r_pos))
    along = np.max(np.abs(np.stack(ranges) - r_pos), axis=0)
    horiz = np.hypot(d[:, 0], d[:, 1])
    sw = wide.surface
    band_m = sw.below_m + max(st.land_margin_m, st.land_sea_sigmas * sw.land_sigma_m)
    tan = horiz / np.maximum(np.abs(d[:, 2]), 1e-6)
    return float(np.max((horiz * along + tan * band_m)[seen]))


def processing_halo_m(
    ctx,
    beam_reach: float,
    kriging_reach_m: float | None = None,
    classify: ClassifySettings | None = None,
) -> float:
    """How far past a tile's edges processing's searches reach (m; module notes).

    Parameters
    ----------
    ctx : ProcessingContext
        The surface-fit settings.
    beam_reach : float
        :func:`beam_reach_m` of the survey.
    kriging_reach_m : float, optional
        How far the kriging's nearest echoes are allowed to lie (an allowance: module notes);
        default the surface fit's ``radius_m``.
    classify : ClassifySettings, optional
        Its ``no_bottom_radius_m`` and ``no_bottom_land_radius_m`` (default the defaults):
        the class-45 claims' test.
    """
    st = ctx.surface_fit
    fit = st.radius_m * (np.sqrt(2.0) if st.time_window_s is not None else 1.0)
    krige = st.radius_m if kriging_reach_m is None else float(kriging_reach_m)
    own = beam_reach + krige + fit + 2.0 * st.land_radius_m
    # a class-45 claim (on its beam) reads the soundings within the test's radius, each made
    # as its own pulse's processing made it (that pulse's own reach again)
    cl = classify or ClassifySettings()
    r = max(cl.no_bottom_radius_m, cl.no_bottom_land_radius_m)
    return float(own + (beam_reach + r if r > 0.0 else 0.0))


def tile_rows(
    pos_m: np.ndarray, tile: np.ndarray, layout: TileLayout, t: int, halo: float
) -> tuple[np.ndarray, np.ndarray]:
    """The pulse rows tile ``t`` processes, and which of them are its own.

    Parameters
    ----------
    pos_m : (n_pulses, 2)
        Pulse positions.
    tile : (n_pulses,) int64
        Each pulse's tile (:meth:`TileLayout.tile_of_xy`).
    layout : TileLayout
    t : int
    halo : float
        Metres.

    Returns
    -------
    rows : (m,) int64
        Ascending: the pulses within the tile grown by ``halo`` (an edge tile, whose pulses
        include those beyond the grid, grows without end outwards).
    own : (m,) bool
        The pulse is the tile's own.
    """
    x0, x1, y0, y1 = layout.box_m(t)
    w, e, s, n = layout.bounds_m
    x0 = -np.inf if x0 <= w else x0 - halo
    x1 = np.inf if x1 >= e else x1 + halo
    y0 = -np.inf if y0 <= s else y0 - halo
    y1 = np.inf if y1 >= n else y1 + halo
    x, y = pos_m[:, 0], pos_m[:, 1]
    mine = tile == t
    rows = np.flatnonzero(((x >= x0) & (x <= x1) & (y >= y0) & (y <= y1)) | mine)
    return rows, mine[rows]


def process_by_tiles(returns, ctx, classify, layout: TileLayout, halo: float, wide) -> Points:
    """:func:`~pipeline.process.survey_points.process_detections`' points, tile by tile.

    Parameters
    ----------
    returns : DetectedReturns
        The survey, ``(n_pulses,)`` per field (pulse ids unique).
    ctx : ProcessingContext
    classify : ClassifySettings
    layout : TileLayout
        The tiles (:func:`~pipeline.survey_tiles.tile_layout`).
    halo : float
        Metres (:func:`processing_halo_m`).
    wide : SurveyWide
        The whole survey's (:func:`~pipeline.process.survey_wide.survey_wide`).

    Returns
    -------
    Points
        Every pulse's points (no water-column points), ordered by pulse id then return number:
        the whole survey's points in that order wherever the searches stay in the halo
        (module notes).
    """
    pos = returns_position_m(returns, ctx.instrument.air_index)
    tile = layout.tile_of_xy(pos[:, 0], pos[:, 1])
    parts = []
    for t in np.unique(tile):
        rows, own = tile_rows(pos, tile, layout, int(t), halo)
        sub = returns.select(rows)
        points = process_detections(sub, ctx, classify, water_column=False, wide=wide).points
        parts.append(points.select(np.isin(points.pulse_id, sub.pulse_id[own])))
    points = Points.concatenate(parts)
    return points.select(np.lexsort((points.return_number, points.pulse_id)))
