"""The vertical datum of the bathymetry grid: the mean water level of the survey.

A point's ``depth_m`` (:class:`~pipeline.process.returns.Points`) is below the *local* fitted
water surface: right for refraction and for the point's own uncertainty, but under a wind sea
that surface follows the crests and troughs, so depths referenced to it carry the wave heights
(a seabed point under a 0.5 m crest reads 0.5 m deeper than one under the mean level). A chart
reduces soundings to one level instead (IHO S-44, 6th ed., §2 "vertical reference"; C-13
Manual on Hydrography, ch. 4, "reduction of soundings"): the grid's depth is
``datum − z`` with a single ``datum`` per survey.

The datum is the user's ``process.datum.water_level_m`` (e.g. a tide-gauge reading reduced to
the local frame) when given; otherwise it is estimated from the survey's measured surface
returns: their mean after a robust gate (``|z − median| ≤ 5 × 1.4826 MAD``, which keeps every
return of a Gaussian sea and drops spray, birds or stray land). The mean, not the median: the
mean water level is a mean, and one wave realisation's heights are skewed (a 10 m/s tile here
had median 0.04 m below its mean). Every surface return counts except ground (class 2): the
local-plane surface fit rejects crests under a steep sea (flagged LAND, class 1, or outliers
7/18; on a 10 m/s sea 4.5 % of the returns, mostly crests), and leaving them out put the datum
0.10 m into the troughs. GNSS height errors common to the surface and seabed returns cancel in
``datum − z``, as they do in the points' ``depth_m``.

A survey whose every surface return with water under it (a later return in its pulse) is
clipped into its column (``CLIPPED_MERGED``: a pulse energy far above the digitiser's range;
fewer than 3 unclipped ones) measured only early bounds of the surface,
each within a sample or two of it (:mod:`pipeline.process.detect_clipped`): the datum is their
gated mean, source ``"clipped_bound"``, at or above the true level.

A survey with no surface return at all (zero photons, an all-ground scene) has nothing that
measured the water level: its datum is ``process.datum.fallback_water_level_m`` (source
``"fallback"``), the level the surface fit also falls back to by default
(``process.surface_fit.fallback_water_level_m``), so whatever was measured stays referenced
to one level and the run completes.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.config import setting
from pipeline.constants import MAD_TO_SIGMA
from pipeline.process.classify import GROUND
from pipeline.process.returns import DetectorFlag, Points, ReturnKind

__all__ = ["DatumSettings", "Datum", "survey_datum", "depth_below_datum_m"]

#: Gate of the surface returns around their median, robust σ (a priori: keeps a Gaussian sea).
GATE_SIGMA = 5.0


@dataclass(frozen=True, kw_only=True)
class DatumSettings:
    """The grid's vertical datum (``[process.datum]``)."""

    water_level_m: float | None = setting(
        None,
        ge=-1000.0,
        le=1000.0,
        doc="mean water level (local z, m) the grid's depths are below, e.g. from a tide "
        "gauge; default: the robust mean of the survey's measured surface returns",
    )
    fallback_water_level_m: float = setting(
        0.0,
        ge=-1000.0,
        le=1000.0,
        doc="datum (local z, m) of a survey with no surface return to estimate one from; "
        "keep it equal to process.surface_fit.fallback_water_level_m",
    )
    min_wet_points: int = setting(
        30,
        ge=0,
        doc="the datum is the mean of the surface returns with water under them (a later "
        "return of their pulse) when at least this many (a calm sea seen off nadir from high "
        "up returns only the seabed on many pulses: suite tuning seed 7201's lone seabed "
        "echoes set the level 2.2 m down); fewer: of every surface return off land; keep it "
        "equal to process.surface_fit.sea_min_wet_pulses",
    )


@dataclass(frozen=True)
class Datum:
    """The datum used: its level (local z, metres), where it came from, and its support.

    Attributes
    ----------
    water_level_m : float
        Local z of the datum.
    source : str
        ``"user"`` (``process.datum.water_level_m``), ``"surface_mean"``, ``"clipped_bound"``
        (every surface return off land clipped into its column: the mean of their early
        bounds, at or above the level) or ``"fallback"``
        (``process.datum.fallback_water_level_m``: no surface return in the survey).
    n_surface_points : int
        Surface returns the estimate used (0 for a user datum).
    """

    water_level_m: float
    source: str
    n_surface_points: int

    def to_dict(self) -> dict:
        """JSON-ready summary."""
        return {
            "water_level_m": self.water_level_m,
            "source": self.source,
            "n_surface_points": self.n_surface_points,
        }


def survey_datum(points: Points, settings: DatumSettings | None = None) -> Datum:
    """The survey's datum: the user's level, else the gated mean of its surface returns.

    Parameters
    ----------
    points : Points
        The classified points of the whole survey; their surface returns off land are used.
    settings : DatumSettings, optional

    Returns
    -------
    Datum
        The user's level; else the surface returns' gated mean; else, when there is no
        surface return, the fallback level.
    """
    s = settings or DatumSettings()
    if s.water_level_m is not None:
        return Datum(float(s.water_level_m), "user", 0)
    # a clipped surface merged with the column is only an early bound of the level
    bound = (points.detector_flags & np.uint16(DetectorFlag.CLIPPED_MERGED)) != 0
    surface = (points.kind == ReturnKind.SURFACE) & (points.classification != GROUND)
    z = points.xyz_m[surface & ~bound, 2]
    source = "surface_mean"
    # water under an unclipped surface return: a later (bottom or column) return of its pulse
    later = np.isin(points.kind, (ReturnKind.BOTTOM, ReturnKind.WATER_COLUMN))
    wet = surface & ~bound & np.isin(points.pulse_id, points.pulse_id[later])
    if np.count_nonzero(wet) >= max(s.min_wet_points, 1):
        # water for certain: a calm sea off nadir from high up returns only the seabed on
        # many pulses, whose lone echoes (half the survey's "surface" returns on suite tuning
        # seed 7201, flat water from 694 m over a 0-5 m shoal) set the level 2.2 m down; the
        # surface returns with light under them sample the sea's crests and troughs alike
        z = points.xyz_m[wet, 2]
    elif np.count_nonzero(wet) < 3 and np.any(surface & bound):
        # every water surface clipped into its column (what else is level is a beach face
        # with nothing under it): the bounds are all that measured the water; the datum is
        # their mean, at or above the level, and says so (as the surface fit's level:
        # pipeline.process.surface_evidence.level_points)
        z, source = points.xyz_m[surface & bound, 2], "clipped_bound"
    if z.size == 0:
        # nothing measured the water level (zero photons, all ground): the fallback, recorded
        # as such in evaluation.json, rather than no outputs at all
        return Datum(float(s.fallback_water_level_m), "fallback", 0)
    med = np.median(z)
    mad_sigma = MAD_TO_SIGMA * np.median(np.abs(z - med))
    # a flat calm sea has MAD 0: then keep what sits at the median (to the mm)
    keep = np.abs(z - med) <= max(GATE_SIGMA * mad_sigma, 1e-3)
    return Datum(float(np.mean(z[keep])), source, int(np.count_nonzero(keep)))


def depth_below_datum_m(z_m: np.ndarray, datum: Datum) -> np.ndarray:
    """Depth (positive down, metres) of elevations ``z_m`` (any shape) below the datum."""
    return datum.water_level_m - np.asarray(z_m, dtype=np.float64)
