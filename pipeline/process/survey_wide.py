"""What processing measures from the whole survey, apart from what each pulse's neighbours give.

Processing a spatial tile (and the halo its neighbour searches reach into) gives the tile's
pulses the points the whole survey's processing gives them only if the few figures processing
measures over the *whole* survey are the survey's, not the tile's. They are gathered here
(:class:`SurveyWide`), measured once (:func:`survey_wide`, from every pulse, exactly as
:func:`~pipeline.process.refraction.georeference` measures them) and handed to the processing
of each tile (``georeference(..., wide=...)``):

========================  =====================================================================
figure                    measured from
========================  =====================================================================
global water plane        the histogram mode of the surface heights, the band fit around it
                          (:func:`~pipeline.process.surface_land.global_plane`)
sea sigmas                the surface heights about that plane (the land seeds' height, the
                          not-surface band below the level; :func:`~pipeline.process.
                          surface_land.sea_sigma_m`)
dry / wet, bounds         whether any pulse saw under its surface return, whether clipped
                          bounds set the level (:mod:`pipeline.process.surface_evidence`)
sea correlation           the regression of pairs of echoes in time order, per lag
                          (:func:`~pipeline.process.sea_correlation.sea_correlation`)
sea covariance            the same pairs' heights above the global plane, fitted exponential
                          (:func:`~pipeline.process.sea_kriging.sea_covariance`)
facets (wave sea)         the echoes' structure function, the planes' slope variance, each
                          line's axis (:func:`~pipeline.process.facet_excess.facet_wide`)
========================  =====================================================================

Everything else is local: each pulse's plane from the echoes within ``radius_m`` (``sqrt 2``
times that in ``(x, y, v t)``), the land candidates' support within ``land_radius_m`` of
candidates decided within ``land_radius_m``, the kriging from the ``kriging_neighbours``
nearest echoes in ``(x, y, v t)``; refraction and classes per pulse. Two local searches have no
fixed reach: the land regions linked within ``land_link_m`` (a region can run across the whole
survey) and the kriging's nearest echoes (as far as the echoes are sparse):
:mod:`pipeline.process_tiles` states what that means for tiles.
"""

from __future__ import annotations

from dataclasses import dataclass

from pipeline.process.facet_excess import FacetWide, facet_wide
from pipeline.process.photon_windows import PhotonWindows
from pipeline.process.refraction_settings import RefractionSettings
from pipeline.process.sea_correlation import SeaCorrelation, sea_correlation
from pipeline.process.sea_kriging import SeaCovariance, survey_sea_covariance
from pipeline.process.surface_fit import fit_water_surface
from pipeline.process.surface_settings import SurfaceFitSettings
from pipeline.process.surface_wide import SurfaceWide, surface_wide

__all__ = ["SeaWide", "SurveyWide", "sea_wide", "survey_wide"]


@dataclass(frozen=True)
class SeaWide:
    """The survey's sea figures, measured from its echoes and their fitted planes.

    Attributes
    ----------
    correlation : SeaCorrelation
        ``rho`` and ``gamma`` against lag.
    covariance : SeaCovariance or None
        The kriging's covariance; None: the sea is not kriged.
    facets : FacetWide or None
        The facet correction's figures; None: no correction.
    """

    correlation: SeaCorrelation
    covariance: SeaCovariance | None
    facets: FacetWide | None


@dataclass(frozen=True)
class SurveyWide:
    """Everything processing measures from the whole survey (module notes).

    Attributes
    ----------
    surface : SurfaceWide
        The surface fit's water level, sea sigmas and dry/wet decisions.
    sea : SeaWide
        The sea's correlation, covariance and facets.
    """

    surface: SurfaceWide
    sea: SeaWide


def sea_wide(
    returns,
    surface,
    surface_settings: SurfaceFitSettings | None,
    refraction_settings: RefractionSettings | None,
    group=None,
) -> SeaWide:
    """The sea's survey-wide figures from every pulse and its fitted surface.

    ``group``: pulses sharing one detection (photon windows): their sea is not kriged.
    """
    st = surface_settings or SurfaceFitSettings()
    corr = sea_correlation(returns, surface, max_dt_s=surface.time_window_s, group=group)
    cov = None
    if group is None and st.time_window_s is not None and st.kriging_neighbours >= 1:
        cov = survey_sea_covariance(returns, surface, st.kriging_window_s)
    mss = (refraction_settings or RefractionSettings()).facet_mss
    return SeaWide(corr, cov, facet_wide(returns, surface, mss, group))


def survey_wide(
    returns,
    *,
    surface_settings: SurfaceFitSettings | None = None,
    refraction_settings: RefractionSettings | None = None,
    windows: PhotonWindows | None = None,
) -> SurveyWide:
    """Measure :class:`SurveyWide` from every pulse of a survey (``georeference``'s arguments).

    Holds the whole survey (the surface fit of every pulse): what streaming must still replace
    by aggregates of tiles.
    """
    st = surface_settings or SurfaceFitSettings()
    level = surface_wide(returns, st)
    group = None if windows is None else windows.of_returns(returns)
    surface = fit_water_surface(returns, st, level, group)
    return SurveyWide(level, sea_wide(returns, surface, st, refraction_settings, group))
