"""What the TPU measures over a whole survey, so a tile of it can be given the survey's figures.

Most of the TPU is local: a sounding's terms come from its own pulse, its neighbours' soundings
(the seabed gradient within ``gradient_regional_radius_m``, the pair scatter) and the surface
returns near it. A few figures are measured over the whole survey, because a survey has one
sea and one seabed character and a single point would measure nothing
(:func:`~pipeline.uncertainty.survey_uncertainty.survey_uncertainty` names each where it is
made):

* ``relief_slope_sigma``: how far the seabed's local slope departs from the regional one
  (:func:`~pipeline.uncertainty.seabed_gradient.seabed_gradient`'s ``local_sigma``);
* ``scatter_rise_per_m2``: the true rise between paired soundings (of their heights; of
  depths for photon windows), removed from their scatter, and ``scatter_relief_slope_sigma``,
  the relief slope sigma of the gradient the pairs are levelled by
  (:func:`~pipeline.uncertainty.tpu_neighbours.pair_scatter`);
* ``turn_table``: the mean-square turn of a pulse's water plane against the plane over its
  sounding, against their offset (:func:`~pipeline.uncertainty.tpu_neighbours.
  surface_tilt_sigma`);
* ``amplitude_fill``: the amplitude a return without one is weighted as in the timing split
  (:func:`~pipeline.uncertainty.tpu_neighbours.amplitude_fill`);
* ``variogram``: the surface returns' height variogram
  (:func:`~pipeline.uncertainty.tpu_measured.surface_variogram`);
* ``line_ids`` / ``line_axes``: each flight line's direction
  (:func:`~pipeline.uncertainty.tpu_facet.track_directions`);
* ``facets``: processing's facet figures (:class:`~pipeline.process.facet_excess.FacetWide`:
  the lines' directions and the water planes' slope variance) where the echoes show a wave
  sea and the facet excess left on applies
  (:func:`~pipeline.uncertainty.tpu_facet.with_uncorrected_facet_excess`); else None.

A survey's TPU made with its own :class:`TpuSurveyWide` (``SurveyUncertainty.wide``) is the TPU
made without one, bit for bit: the figures are only carried, not changed. A tile (its pulses
within a halo of its edges) given the survey's figures gets the terms its soundings get in
the whole survey (``tests/uncertainty/test_tpu_survey_wide.py``); streaming the survey tile
by tile needs them made from aggregates first, which is the next step (issue 15).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.process.facet_excess import FacetWide, facet_wide
from pipeline.uncertainty.tpu_facet import track_directions
from pipeline.uncertainty.tpu_measured import SurfaceVariogram

__all__ = [
    "TpuSurveyWide",
    "tpu_halo_m",
    "line_table",
    "axes_of_lines",
    "survey_tracks",
    "facet_sea",
]

#: Allowance (m) for the pair scatter's nearest pairs of successive soundings (< 2 m apart
#: each; their ``scatter_neighbours`` nearest lie within metres where soundings are dense):
#: an allowance, not a bound, as the kriging's nearest echoes are in processing.
PAIR_ALLOWANCE_M = 10.0


@dataclass(frozen=True)
class TpuSurveyWide:
    """The survey-wide figures of a TPU (module notes).

    Attributes
    ----------
    relief_slope_sigma : float or None
        Per-axis sigma of the local seabed slope about the regional one; None: no regional
        step.
    scatter_rise_per_m2 : float
        ``a`` of the pair scatter, m² (of height, or of depth for photon windows) per m² of
        lag (0: none told).
    scatter_relief_slope_sigma : float or None
        ``local_sigma`` of the pair scatter's own seabed gradient.
    turn_table : tuple of two (k,) ndarray, or None
        Offsets (m) and the mean-square turn (m²) at each; None: none measured.
    amplitude_fill : (float, float)
        Surface and bottom amplitudes of returns without one.
    variogram : SurfaceVariogram
    line_ids : (n_lines,) int64
    line_axes : (n_lines, 2) float64
        Unit horizontal direction of each line (sign arbitrary).
    facets : FacetWide or None
        The facet figures of the uncorrected facet term (None: no wave sea, or no term).
    """

    relief_slope_sigma: float | None
    scatter_rise_per_m2: float
    scatter_relief_slope_sigma: float | None
    turn_table: tuple[np.ndarray, np.ndarray] | None
    amplitude_fill: tuple[float, float]
    variogram: SurfaceVariogram
    line_ids: np.ndarray
    line_axes: np.ndarray
    facets: FacetWide | None = None
    cell_relief_sigma: float | None = None


def tpu_halo_m(st) -> float:
    """How far from a tile's soundings the TPU's neighbour searches reach (m).

    The seabed gradient's regional plane (its radius, and the diagonal of the cell a sounding
    takes it from), then its local plane's radius, for the TPU's gradient (``st``:
    :class:`~pipeline.uncertainty.tpu_settings.TpuSettings`) and for the pair scatter's own
    (:func:`~pipeline.uncertainty.seabed_gradient.seabed_gradient`'s defaults), plus
    :data:`PAIR_ALLOWANCE_M`, or a wave pool's cell diagonal if larger. A tile with this halo,
    given the survey's :class:`TpuSurveyWide`, gets the survey's TPU (``tests/uncertainty/
    test_tpu_survey_wide.py``).
    """
    from pipeline.uncertainty.seabed_gradient import RADIUS_M, REGIONAL_CELL_M, REGIONAL_RADIUS_M

    regional = max(st.gradient_regional_radius_m, REGIONAL_RADIUS_M)
    local = max(st.gradient_radius_m, RADIUS_M)
    reach = regional + np.sqrt(2.0) * REGIONAL_CELL_M + local + PAIR_ALLOWANCE_M
    # the wave residual's pool: every pulse of a sounding's cell (pipeline.uncertainty.wave_pool)
    return float(max(reach, np.sqrt(2.0) * st.wave_pool_cell_m))


def line_table(line_id: np.ndarray, axes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each line's direction once, from a per-pulse ``(n, 2)`` table of them.

    Returns
    -------
    ids : (n_lines,) ndarray
    axes : (n_lines, 2) ndarray
    """
    ids, first = np.unique(np.asarray(line_id), return_index=True)
    return ids, np.asarray(axes)[first]


def axes_of_lines(wide: TpuSurveyWide, line_id: np.ndarray) -> np.ndarray:
    """The per-pulse ``(n, 2)`` directions of pulses on lines ``line_id`` (of ``wide``'s)."""
    line_id = np.asarray(line_id)
    at = np.searchsorted(wide.line_ids, line_id)
    if np.any(at >= wide.line_ids.size) or np.any(
        wide.line_ids[np.minimum(at, wide.line_ids.size - 1)] != line_id
    ):
        raise ValueError("`line_id` holds lines the survey-wide table does not")
    return wide.line_axes[at]


def survey_tracks(returns, wide: TpuSurveyWide | None):
    """Each pulse's flight-line direction ``(n, 2)``, and the line table it comes from.

    ``wide`` None: measured from ``returns`` (:func:`~pipeline.uncertainty.tpu_facet.
    track_directions`); else the survey's lines (a tile's pulses lie on some of them).

    Returns
    -------
    tracks : (n, 2) ndarray
    line_ids : (n_lines,) ndarray
    line_axes : (n_lines, 2) ndarray
    """
    line_id = np.zeros(len(returns), np.int64) if returns.line_id is None else returns.line_id
    if wide is None:
        tracks = track_directions(returns)
        return (tracks, *line_table(line_id, tracks))
    return axes_of_lines(wide, line_id), wide.line_ids, wide.line_axes


def facet_sea(returns, surface, refr, group, wide: TpuSurveyWide | None):
    """The facet figures of the uncorrected facet term (:class:`FacetWide` or None).

    None where the term does not apply (the correction on, or no logged wind) or the echoes
    show no wave sea. ``wide`` None: measured from ``returns``
    (:func:`~pipeline.process.facet_excess.facet_wide`); else the survey's.
    """
    if not (refr.facet_mss == 0.0 and refr.facet_mss_uncorrected > 0.0):
        return None
    if wide is not None:
        return wide.facets
    return facet_wide(returns, surface, refr.facet_mss_uncorrected, group)
