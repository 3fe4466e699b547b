"""A survey's propagated uncertainty: TPU of its bathymetric points, per cell, IHO orders.

Measured data and the :class:`~pipeline.process.context.ProcessingContext` only: the seabed
gradient under every bottom point (which couples the horizontal errors into the depth compared
at the measured position) is a local plane through the neighbouring bathymetric soundings
(:func:`~pipeline.uncertainty.tpu.seabed_gradient`); the water plane's tilt uncertainty is the
larger of the fit's and the one measured over the soundings
(:func:`~pipeline.uncertainty.tpu.surface_tilt_sigma`). The timing terms are the detector's
per-return sigmas (full waveform: the Cramér–Rao bound of each echo from its own waveform,
:mod:`pipeline.process.detect_precision`), raised where the scatter of successive soundings
shows more (:func:`~pipeline.uncertainty.tpu.pair_scatter`,
:func:`~pipeline.uncertainty.tpu.timing_from_scatter`); without detector sigmas (photon
counting) the scatter sets them.
The surface returns' height variogram (:mod:`pipeline.uncertainty.tpu_measured`) raises the
surface timing sigmas to the ranging error they show and adds the waves between each pulse's
water entry and its sounding that the fitted plane's tilt does not hold; its rise at short
lags, the sea's slope the planes do not follow, sizes the wave facet each beam refracted
through (:mod:`pipeline.uncertainty.tpu_facet`).
A photon-counting window's shots share one detection: they count as one sounding, and each
shot carries the spread of the seabed under the window's shots
(:mod:`pipeline.uncertainty.tpu_window`). Pulses the
TPU cannot propagate are left out, flagged ``NO_TPU`` and counted.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from pipeline import iho
from pipeline.process.classify import BATHYMETRIC_POINT
from pipeline.process.context import ProcessingContext
from pipeline.process.grid import Grid
from pipeline.process.refraction import ProcessedPoints, kriged_sea_change, seabed_xyz_depth
from pipeline.process.returns import DetectedReturns, PointFlag, Points, ReturnKind
from pipeline.uncertainty.cell_uncertainty import CellUncertainty, cell_uncertainty
from pipeline.uncertainty.seabed_gradient import (
    GRADIENT_TERM,
    REGIONAL_CELL_M,
    gradient_sigma_depth_m,
    horizontal_cov,
    plane_gradient,
)
from pipeline.uncertainty.survey_cells import with_posteriors, without_points  # re-exported
from pipeline.uncertainty.tpu import (
    PointTpu,
    pair_scatter,
    point_tpu,
    seabed_gradient,
    surface_tilt_sigma,
    timing_from_scatter,
)
from pipeline.uncertainty.tpu_facet import (
    unresolved_slope_cov,
    with_facet_excess,
    with_uncorrected_facet_excess,
    with_wave_facet,
)
from pipeline.uncertainty.tpu_measured import (
    surface_variogram,
    with_surface_ranging,
    with_wave_entry,
)
from pipeline.uncertainty.tpu_neighbours import amplitude_fill
from pipeline.uncertainty.tpu_settings import DEPTH, Z, take_tpu  # re-exported: take_tpu
from pipeline.uncertainty.tpu_subset import propagated_bottoms
from pipeline.uncertainty.tpu_survey_wide import TpuSurveyWide, facet_sea, survey_tracks
from pipeline.uncertainty.tpu_timing import split_timing_excess
from pipeline.uncertainty.tpu_window import (
    WINDOW_TERM,
    cell_relief_m,
    cell_window_sigma_m,
    window_footprint_sigma_m,
    with_random_term,
)
from pipeline.uncertainty.wave_pool import pooled_wave

__all__ = [
    "SurveyUncertainty",
    "survey_uncertainty",
    "with_tpu",
    "with_held_sea",
    "with_posteriors",
    "take_tpu",
    "without_points",
]


@dataclass(frozen=True)
class SurveyUncertainty:
    """The uncertainty stage's result.

    Attributes
    ----------
    tpu40 : PointTpu
        TPU of the bathymetric points that have one, in the order of ``points40``.
    points40 : Points
        Those points (class 40 bottoms the TPU propagated).
    is40 : (n_points,) bool
        Where ``points40`` sit among all the survey's points.
    no_tpu : (n_points,) bool
        Bathymetric points the TPU left out (they keep the a-priori uncertainty).
    left_out : dict
        ``pulses``, ``bathymetric_points`` and ``by_reason`` of those left out.
    cells : CellUncertainty
        Per grid cell: TVU, THU and the strictest IHO S-44 order met.
    summary : dict
        The order summary (:func:`pipeline.iho.order_summary`), JSON-ready.
    wide : TpuSurveyWide or None
        The survey-wide figures the TPU used (:mod:`pipeline.uncertainty.tpu_survey_wide`).
    """

    tpu40: PointTpu
    points40: Points
    is40: np.ndarray
    no_tpu: np.ndarray
    left_out: dict[str, Any]
    cells: CellUncertainty
    summary: dict[str, Any]
    wide: TpuSurveyWide | None = None


def survey_uncertainty(
    returns: DetectedReturns,
    processed: ProcessedPoints,
    ctx: ProcessingContext,
    grid: Grid,
    wide: TpuSurveyWide | None = None,
    keep: np.ndarray | None = None,
) -> SurveyUncertainty:
    """TPU of the bathymetric points, cell uncertainty and the IHO order met per cell.

    Parameters
    ----------
    returns : DetectedReturns
        The survey's detections, ``(n_pulses,)`` per field.
    processed : ProcessedPoints
        :func:`pipeline.process.survey_points.process_detections` of them.
    ctx : ProcessingContext
        Navigation quality, beam, wavelength and water the processing assumes.
    grid : Grid
        The bathymetry grid the cells belong to.
    wide : TpuSurveyWide, optional
        The survey-wide figures, as measured over the whole survey these pulses are part of
        (:mod:`pipeline.uncertainty.tpu_survey_wide`; a tile's pulses within their halo);
        default: measured from these pulses. What was used is ``SurveyUncertainty.wide``.
    keep : (n_points,) bool, optional
        The points of ``processed`` whose TPU the caller keeps (a block of a survey: those its
        own pulses, own cells and tests need, :mod:`pipeline.survey_blocks`); needs ``wide``.
        Only their pulses are propagated, while the neighbour searches (gradient, pair
        scatter) still read every sounding: each kept point gets the TPU it would get without
        ``keep`` (:mod:`pipeline.uncertainty.tpu_subset`). The other bathymetric points are
        left as if not bathymetric (not in ``points40``, the cells, ``no_tpu`` or
        ``left_out``). Default: every point.
    """
    st, refr, ins = ctx.tpu, ctx.refraction, ctx.instrument
    held = with_held_sea(returns, processed.surface, refr, held_m=processed.sea_change_m)
    processed = dataclasses.replace(processed, surface=held)
    pts = processed.points
    is40 = (pts.classification == BATHYMETRIC_POINT) & (pts.kind == ReturnKind.BOTTOM)
    points40 = pts.select(is40)
    bottom_xy = seabed_xyz_depth(returns, processed.surface, refr)[:, :2]
    xy40, d40 = points40.xyz_m[:, :2], points40.depth_m
    windows = ins.windows  # photon counting: the detector's windows of shots
    group = None if windows is None else windows.of_points(points40.pulse_id, returns)
    # the pulses propagated (`keep`'s, else all) become the only bottoms of `returns`; `q`
    # picks them among the bottom rows (of bottom_xy)
    every_bottom = returns  # the wave pool's soundings: the same whichever are propagated
    returns, q, is40_kept = propagated_bottoms(returns, pts, is40, keep, wide, windows)
    # a scan's cell windows count as one sounding each (their shots share one depth): the
    # gradient's planes reach over neighbouring windows, so their radii and cells are at
    # least 2.5, 5 and 1 cell sides (a profiler's windows, 0.4 m, change nothing)
    cell = 0.0 if windows is None else windows.cell_m
    near = {
        "neighbours": st.gradient_neighbours,
        "radius_m": max(st.gradient_radius_m, 2.5 * cell),
        "regional_radius_m": st.gradient_regional_radius_m
        and max(st.gradient_regional_radius_m, 5.0 * cell),
        "regional_cell_m": max(REGIONAL_CELL_M, cell),
        "prior_slope_deg": st.gradient_prior_slope_deg,
        # a user's relief slope sigma wins; else the survey's (survey-wide: measured over it)
        "local_sigma": st.gradient_local_sigma
        if st.gradient_local_sigma is not None or wide is None
        else wide.relief_slope_sigma,
    }
    # the seabed's own gradient: of its height below a level datum (depths below the sea
    # at each pulse's time carry the waves' slope, which the surface terms hold; on suite
    # tuning seed 109, 9 m/s over a plane, the depths' cells read 0.057 of relief slope)
    grad, grad_cov, relief_sigma = seabed_gradient(
        xy40,
        -points40.xyz_m[:, 2],
        bottom_xy[q],
        group=group,
        return_cov=True,
        return_local_sigma=True,
        **near,
    )
    # the terms compare each sounding, moved, with the true depth below the sea at the moved
    # position, read below the pulse's plane there: their gradient is the depth's below the
    # sea, the seabed's plus the sea's slope (the plane's, what the depth reading follows)
    bottom_rows = np.flatnonzero(returns.has_bottom)
    grad = grad + plane_gradient(processed.surface, bottom_rows)
    # the water surface measured over each sounding against its pulse's plane there: the
    # plane's tilt uncertainty, averaged over the bathymetric points
    # survey-wide: E[T²] against the offset, pooled over the survey's bathymetric points (a
    # survey's table given: only each pulse's offset is read, no pool)
    if wide is not None and wide.turn_table is None:
        tilt, turn_table = np.zeros(bottom_rows.size), None  # the survey measured no turn
    else:
        rows40 = None
        if wide is None:
            bottom_ids = returns.pulse_id[returns.has_bottom]
            by_id = np.argsort(bottom_ids)
            rows40 = by_id[np.searchsorted(bottom_ids[by_id], points40.pulse_id)]
        tilt, turn_table = surface_tilt_sigma(
            returns,
            processed.surface,
            bottom_xy[q],
            pool=rows40,
            turn_table=None if wide is None else wide.turn_table,
            return_table=True,
        )
    # the measured random scatter of successive soundings: what the timing achieved (with the
    # detector's own Cramér–Rao sigmas it can only raise them; without, it sets them). Of
    # seabed heights: a depth is read below the sea over its sounding, whose waves differ
    # between soundings 1-2 m apart as relief the rise a h² removes only in part (tuning seeds
    # 32, 33: 0.049, 0.062 m from depths, 0.045, 0.041 from heights, errors 0.046, 0.044). A
    # photon window's shots share a depth, not a height: windows pair depths.
    # survey-wide: the true rise between paired soundings
    by_height = group is None
    scatter, scatter_figures = pair_scatter(
        xy40,
        -points40.xyz_m[:, 2] if by_height else d40,
        order=points40.pulse_id,
        group=group,
        query_xy_m=bottom_xy[q],
        max_separation_m=st.pair_max_separation_m,
        neighbours=st.scatter_neighbours,
        rise_per_m2=None if wide is None else wide.scatter_rise_per_m2,
        relief_slope_sigma=None if wide is None else wide.scatter_relief_slope_sigma,
        return_figures=True,
    )
    # survey-wide: the amplitude a return without one is weighted as
    fill = amplitude_fill(returns) if wide is None else wide.amplitude_fill
    detector = returns  # the detector's own timing sigmas, before the scatter raises them
    returns, derivatives = timing_from_scatter(
        returns,
        processed.surface,
        refr,
        st,
        depth_scatter_m=scatter,
        seabed_gradient=grad,
        # a return lies in the recorded window: its timing sigma is at most a uniform one's
        max_sigma_s=ins.window_s / math.sqrt(12.0),
        raise_only=returns.t_bottom_sigma_s is not None,
        amplitude_fill=fill,
        scatter_column=Z if by_height else DEPTH,
        return_derivatives=True,  # the TPU below reads them: the same pulses' points
    )
    # the surface as its returns measure it: their height variogram's nugget (the ranging
    # error of a surface point, e.g. a calm-water onset) raises each surface timing sigma
    pulse_group = None if windows is None else windows.of_returns(returns)
    # survey-wide: one sea, its variogram
    vg = (
        wide.variogram
        if wide is not None
        else surface_variogram(
            returns,
            processed.surface,
            max_dt_s=st.surface_pair_max_dt_s,
            min_pairs=st.surface_min_pairs,
            group=pulse_group,
        )
    )
    returns = with_surface_ranging(returns, processed.surface, vg)
    tpu = point_tpu(
        returns,
        processed.surface,
        refr,
        st,
        seabed_gradient=grad,
        surface_tilt_sigma_rad=tilt,
        wave_sigma_m=pooled_wave(every_bottom, processed.surface, vg, st),
        derivatives=derivatives,
    )
    del derivatives
    # what the scatter and the variogram added to the detector's sigmas is not the
    # waveform's: a posterior of the waveform replaces only the detector's share
    tpu = split_timing_excess(tpu, detector, returns)
    # pulses the TPU could not propagate: their points keep the a-priori uncertainty and are
    # left out of the cell uncertainty and the TPU check
    no_tpu = is40_kept & np.isin(pts.pulse_id, tpu.left_out.pulse_id)
    is40 = is40_kept & ~no_tpu
    points40 = pts.select(is40)
    # TPU rows are per pulse with a bottom; keep those of the bathymetric points, same order
    order = np.argsort(tpu.pulse_id)
    pos = order[np.searchsorted(tpu.pulse_id[order], points40.pulse_id)]
    left_out = {
        "pulses": len(tpu.left_out),
        "bathymetric_points": int(np.count_nonzero(no_tpu)),
        "by_reason": tpu.left_out.counts(),
    }
    # every bottom pulse's terms (~380 B a pulse) are not read again: taken term by term (not
    # held beside their copy) and let go before the wave terms below raise the run's peak
    tpu40 = take_tpu(tpu, pos, consume=True)
    del tpu
    # each bathymetric point's row among the bottom pulses (of grad, grad_cov), and the
    # flight-line direction of its pulse
    at40 = np.searchsorted(bottom_rows, tpu40.row)
    # survey-wide: each line's direction, from all its pulses
    tracks, line_ids, line_axes = survey_tracks(returns, wide)
    cell_relief = None
    if group is not None:
        # one window, one detection: the seabed's spread under its shots (with the gradient's
        # uncertainty) and the sea's slope the planes miss (depth only)
        win = windows.of_points(points40.pulse_id, returns)
        xy40w, g40, gc40 = points40.xyz_m[:, :2], grad[at40], grad_cov[at40]
        if windows.cell_m > 0.0:  # a scan's cell, its bottom carried along its slope
            # (process.photon_carry): the relief its plane misses is left (survey-wide); the sea
            # is in the surface terms (a facet slope over 5 m read 0.034 m of flat water on tuning
            # seed 46: err 0.010)
            d40w, z40w, cell = points40.depth_m, points40.xyz_m[:, 2], windows.cell_m
            cell_relief = None if wide is None else wide.cell_relief_sigma
            if cell_relief is None:
                cell_relief = cell_relief_m(xy40w, d40w, z40w, win, cell)
            seabed = spread = cell_window_sigma_m(
                xy40w, d40w, z40w, win, cell, g40, gc40, relief_m=cell_relief
            )
        else:
            sea_cov = unresolved_slope_cov(vg, processed.surface, tracks[tpu40.row], rows=tpu40.row)
            seabed = window_footprint_sigma_m(xy40w, win, g40, gradient_cov=gc40)
            spread = window_footprint_sigma_m(xy40w, win, g40, sea_cov, gc40)
        tpu40 = with_random_term(tpu40, WINDOW_TERM, seabed, spread)
    # the waves between each pulse's water entry and its sounding (the variogram's wave part
    # beyond what the fitted plane's measured tilt already holds)
    surf = processed.surface
    tpu40 = with_wave_entry(tpu40, vg, surf.entry_m[tpu40.row, :2], surf.sea_correlation)
    if st.wave_slope_sigma_rad == 0.0:  # a user's facet slope (wave_slope_* terms) wins
        # the wave facet each beam refracted through that the fitted planes do not follow
        plane_tilt = surf.normal_sigma_rad.copy()  # what the surface_tilt_* terms carried
        plane_tilt[bottom_rows] = np.maximum(plane_tilt[bottom_rows], np.nan_to_num(tilt))
        tpu40 = with_wave_facet(
            tpu40,
            returns.direction_meas,
            surf,
            vg,
            grad[at40],
            refr.phase_index,
            tilt_sigma_rad=plane_tilt,
            track_xy=tracks,
        )
    # what the facet excess taken off by refraction is uncertain by (the logged wind's sigma)
    tpu40 = with_facet_excess(tpu40, returns.direction_meas, surf, refr)
    # or, with the correction off, the excess left on the soundings at its predicted size
    # survey-wide: the wave sea's facet figures (only where the term applies)
    facets = facet_sea(returns, surf, refr, pulse_group, wide)
    tpu40 = with_uncorrected_facet_excess(tpu40, returns, surf, refr, facets=facets)
    # what the sounding's horizontal uncertainty makes of the gradient's own (unmeasured
    # across a profiler's line: the slope prior)
    tpu40 = with_random_term(
        tpu40,
        GRADIENT_TERM,
        np.zeros(len(tpu40)),
        gradient_sigma_depth_m(grad_cov[at40], horizontal_cov(tpu40)),
    )
    cells = cell_uncertainty(grid, tpu40)
    return SurveyUncertainty(
        tpu40=tpu40,
        points40=points40,
        is40=is40,
        no_tpu=no_tpu,
        left_out=left_out,
        cells=cells,
        summary=iho.order_summary(cells.order).to_dict(),
        wide=TpuSurveyWide(
            relief_slope_sigma=relief_sigma,
            scatter_rise_per_m2=scatter_figures["rise_per_m2"],
            scatter_relief_slope_sigma=scatter_figures["relief_slope_sigma"],
            turn_table=turn_table,
            amplitude_fill=fill,
            variogram=vg,
            line_ids=line_ids,
            line_axes=line_axes,
            facets=facets,
            cell_relief_sigma=cell_relief,
        ),
    )


def with_held_sea(returns: DetectedReturns, surface, refraction_settings, *, held_m=None):
    """``surface`` with its kriged sea change from entry to sounding held for the TPU.

    The TPU moves one input at a time and georeferences again
    (:func:`~pipeline.uncertainty.tpu.point_tpu`); kriged again at points moved by
    millimetres, the sea change would jump wherever an echo enters or leaves the nearest ones
    (tens of centimetres of "pointing" or "surface tilt" sensitivity that no input has). Its
    own error is the TPU's sea terms' (``wave_entry``). A surface without a kriged sea is
    returned as it is.

    ``held_m``: the change already kriged for these returns, surface and settings
    (:attr:`~pipeline.process.refraction.ProcessedPoints.sea_change_m`); None: kriged here.
    """
    if surface.sea_field is None or returns.t_emit_s is None:
        return surface  # nothing kriged (kriged_sea_change gives None)
    held = kriged_sea_change(returns, surface, refraction_settings) if held_m is None else held_m
    return surface if held is None else dataclasses.replace(surface, sea_change_m=held)


def with_tpu(points: Points, unc: SurveyUncertainty) -> Points:
    """``points`` whose bathymetric points carry their TPU as the per-point uncertainty.

    ``uncertainty_v_m`` := ``PointTpu.sigma_v_m``, the one-sigma of the point's elevation ``z``
    (the LAS z; what IHO S-44's TVU bounds), and ``uncertainty_h_m`` := ``sigma_h_m``, per
    horizontal axis; the other points keep the a-priori values of
    :mod:`pipeline.process.refraction`. The points the TPU left out get ``PointFlag.NO_TPU``.
    The depth's own sigma (below the measured water surface, smaller) is
    ``PointTpu.sigma_depth_m`` (what the evaluate stage checks).
    """
    v, h = points.uncertainty_v_m.copy(), points.uncertainty_h_m.copy()
    v[unc.is40], h[unc.is40] = unc.tpu40.sigma_v_m, unc.tpu40.sigma_h_m
    flags = points.flags.copy()
    flags[unc.no_tpu] |= np.uint16(PointFlag.NO_TPU)
    return points.replace(uncertainty_v_m=v, uncertainty_h_m=h, flags=flags)
