"""TPU term of the wave facet a beam refracts through that the fitted surface does not resolve.

The processing refracts each beam through its pulse's fitted local water plane
(:func:`~pipeline.process.refraction.seabed_points`). The sea the pulse met is tilted by the
waves' slope at its entry; where the plane does not follow that slope (a profiler's collinear
surface points hold no across-track slope; a sparse or wide fit smooths the waves away) the
in-water beam leaves in another direction and the sounding lands beside where it is put. By
Snell's law a nadir beam through a facet of slope ``beta`` turns by ``beta (1 - 1/n_w)``,
``L beta (1 - 1/n_w)`` sideways after the in-water path ``L``, and over a seabed of depth
gradient ``g`` the depth read at the measured position is wrong by ``g`` times that (the
vertical change itself is second order near nadir). This term propagates it, per slope axis
``u`` in ``x``, ``y``: ``dB/dbeta_u = L dt/dbeta_u`` (``t`` the in-water direction of
:func:`~pipeline.optics.refract_direction` through the plane's normal with its slope ``u``
moved), the depth ``(p - g) . dB_xy - dB_z`` (``p`` the plane's gradient: the depth is read
below the plane above the point), times the slope sigma ``s_u``.

``s_u`` is measured by the survey, never assumed: the surface returns' height variogram above
each pulse's own plane (:func:`~pipeline.uncertainty.tpu_measured.surface_variogram`) rises
as ``gamma(h) = n + a h²`` at short lags, ``2 a`` the mean-square slope of the sea that the
planes do not follow along the pairs' directions. Isotropic sea: the same along both axes,
``s_u² = 2 a - t_u²``, ``t_u`` the plane's per-axis tilt sigma the ``surface_tilt_*`` terms
already carry (the fit's standard error or the tilt measured over the sounding,
:func:`~pipeline.uncertainty.tpu_neighbours.surface_tilt_sigma`): never a double count. The two
axes are along and across each pulse's flight line (:func:`track_directions`). Across a
profiler's track (a pulse whose plane is flagged ``SURFACE_ILL_CONDITIONED``: its neighbours
are nearly collinear and the ridge keeps it level across) the plane follows no slope at all: it
misses the whole sea's slope there, ``2 a_raw`` (the same variogram's rise with the heights
taken above the survey's global plane, so the along-track slope the planes do follow is back
in; isotropic sea), less the tilt term's share. Before, it got ``2 a``: on suite tuning seed 19
(full-waveform profiler, 3.3 m/s, a 14° seabed sloping across the track) that sized the facet's
slope at 0.021 rad where the sea's across-track slope the planes missed was 0.038 rad. Flat
water: ``a = a_raw = 0``, no term. A user's ``process.tpu.wave_slope_sigma_rad > 0`` wins (its
``wave_slope_*`` terms stand for it and this term is not added).

Slopes shorter than the variogram's shortest lags (capillaries) are not in ``a``: they vary
within the footprint, and their mean over it is small.

The second-order part is a bias, not a spread: every facet lengthens the in-water path read
along the plane's refracted direction by ``L delta² / 2``, so the soundings lie deep on average
by ``L (1 - 1/n_w)² mss / 2`` at nadir, ``mss`` the sea's whole mean-square slope (short waves
included, which ``a`` does not see): 2.0 cm at 12.7 m under a 9.9 m/s sea on suite tuning seed
205, against 2.2 cm predicted (``benchmarks/wave_refraction/RESULTS.md``, photon profilers).
With ``process.wave_facet_correction`` (off by default: over sloping seabeds it worsened the
held-out bias, :mod:`pipeline.process.facet_excess`) refraction takes it off (``mss`` from the
logged wind) and :func:`with_facet_excess` adds what that correction is uncertain by (the
wind's sigma through Cox-Munk's slope: a correlated term, the same wind for the whole survey).
Without it the excess is left on the soundings, and :func:`with_uncorrected_facet_excess`
budgets its whole predicted size as a correlated term (:data:`UNCORRECTED_TERM`): a known
effect left uncorrected enlarges the uncertainty by its size (JCGM 100:2008, the GUM, F.2.4.5).
"""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np

from pipeline.optics import refract_direction
from pipeline.process.facet_excess import (
    apply_facets,
    expected_depth_excess_m,
    facet_wide,
    normal_with_slope,
    track_axes,
)
from pipeline.process.facet_excess import track_directions as _track_directions
from pipeline.process.returns import DetectedReturns, PointFlag
from pipeline.process.surface_fit import WaterSurface
from pipeline.uncertainty.tpu_measured import SurfaceVariogram
from pipeline.uncertainty.tpu_settings import DEPTH, PointTpu, X, Y, Z
from pipeline.uncertainty.tpu_window import with_random_term

__all__ = [
    "FACET_TERMS",
    "track_directions",
    "unresolved_slope_sigma_rad",
    "unresolved_slope_cov",
    "facet_jacobian",
    "with_wave_facet",
    "with_facet_excess",
    "with_uncorrected_facet_excess",
    "EXCESS_TERM",
    "UNCORRECTED_TERM",
]

#: The term of the facet excess's own uncertainty (the logged wind's, through Cox-Munk).
EXCESS_TERM = "wave_facet_excess"

#: The term of the facet excess left on the soundings (its whole predicted size).
UNCORRECTED_TERM = "wave_facet_excess_uncorrected"

#: ``facets`` not given: measured (None is an answer: no wave sea).
_MEASURE = object()

#: Names of the two terms (facet slope along and across the pulse's flight line).
FACET_TERMS = ("wave_facet_along", "wave_facet_across")


def track_directions(returns: DetectedReturns) -> np.ndarray:
    """Unit horizontal direction of each pulse's flight line, ``(n, 2)``.

    :func:`pipeline.process.facet_excess.track_directions` of the measured origins.
    """
    return _track_directions(returns.origin_meas_m[:, :2], returns.line_id)


def unresolved_slope_sigma_rad(
    vg: SurfaceVariogram, surface: WaterSurface, tilt_sigma_rad=None, rows=None
) -> np.ndarray:
    """Sigma of the facet slope the planes do not resolve, ``(k, 2)`` (along, across the track).

    Parameters
    ----------
    vg : SurfaceVariogram
        The survey's surface variogram (its ``rise_per_m2`` and ``raw_rise_per_m2``).
    surface : WaterSurface
        The fitted planes of every pulse (which enter water; the fit's tilt sigma; which are
        ill-conditioned, level across their track).
    tilt_sigma_rad : (k,) array_like, optional
        Each row's plane tilt sigma (both axes) that the ``surface_tilt_*`` terms carry; its
        per-axis share ``/ sqrt 2`` is taken off. Default: the fit's ``normal_sigma_rad``.
    rows : (k,) array_like of int, optional
        Pulses (rows of ``surface``) to give; default all.
    """
    rows = np.arange(len(surface)) if rows is None else np.asarray(rows, dtype=np.int64)
    # the slope the planes miss along the pairs, the same along every axis (isotropic sea). The
    # planes' own slope scatter is not added back across the axes they follow: on flat water
    # it is fit noise (suite tuning scene 24: 4e-4 across a Palmer line, where the fit's sigma
    # says 1e-5 and the sea has 2e-5). Across a blind plane the whole sea's slope is missed
    left = 2.0 * max(vg.rise_per_m2, 0.0)
    whole = max(2.0 * max(vg.raw_rise_per_m2, 0.0), left)
    tilt = surface.normal_sigma_rad[rows] if tilt_sigma_rad is None else tilt_sigma_rad
    tilt2 = np.nan_to_num(np.asarray(tilt, dtype=np.float64)) ** 2 / 2.0
    blind = (surface.flags[rows] & np.uint16(PointFlag.SURFACE_ILL_CONDITIONED)) != 0
    var = np.column_stack(
        [np.maximum(left - tilt2, 0.0), np.maximum(np.where(blind, whole, left) - tilt2, 0.0)]
    )
    return np.where(surface.is_water[rows, None], np.sqrt(var), 0.0)


def unresolved_slope_cov(
    vg: SurfaceVariogram, surface: WaterSurface, track_xy, tilt_sigma_rad=None, rows=None
) -> np.ndarray:
    """:func:`unresolved_slope_sigma_rad` as a covariance in x, y, ``(k, 2, 2)``.

    ``track_xy`` (``(k, 2)``): each row's flight-line direction (:func:`track_directions`).
    """
    sig = unresolved_slope_sigma_rad(vg, surface, tilt_sigma_rad, rows)
    u, v = track_axes(track_xy, len(sig))
    return (sig[:, 0, None, None] ** 2) * u[:, :, None] * u[:, None, :] + (
        sig[:, 1, None, None] ** 2
    ) * v[:, :, None] * v[:, None, :]


def facet_jacobian(
    direction: np.ndarray,
    normal: np.ndarray,
    entry_m: np.ndarray,
    point_m: np.ndarray,
    seabed_gradient: np.ndarray,
    n_air: float,
    n_water: float,
    track_xy: np.ndarray | None = None,
) -> np.ndarray:
    """Change of each sounding per unit facet slope, ``(n, 2, 4)``: axis, (x, y, z, depth).

    The axes are along and across ``track_xy`` (default x, y).

    The range is unchanged; the in-water direction turns (Snell's law through the plane's
    normal with one slope component moved; central differences). Depth: below the plane above
    the moved point, compared at the measured position (``(p - g) . dB_xy - dB_z``).

    Parameters
    ----------
    direction : (n, 3)
        Measured beam directions (unit).
    normal : (n, 3)
        The fitted planes' upward normals.
    entry_m, point_m : (n, 3)
        Where the beam entered the water; the sounding.
    seabed_gradient : (n, 2)
        Depth gradient of the seabed under the soundings.
    n_air, n_water : float
        Phase indices.
    track_xy : (n, 2), optional
        Unit horizontal direction of the first axis (the second is 90° to its left).
    """
    n = len(direction)
    axes = track_axes(track_xy, n)
    length = np.linalg.norm(point_m - entry_m, axis=1)
    nz = np.where(np.abs(normal[:, 2]) > 1e-12, normal[:, 2], 1e-12)
    plane_grad = -normal[:, :2] / nz[:, None]
    out = np.zeros((n, 2, 4))
    h = 1e-4
    for axis in (0, 1):
        v = axes[axis]
        t_p, _ = refract_direction(direction, normal_with_slope(normal, v, h), n_air, n_water)
        t_m, _ = refract_direction(direction, normal_with_slope(normal, v, -h), n_air, n_water)
        db = length[:, None] * (t_p - t_m) / (2.0 * h)
        out[:, axis, :3] = db
        out[:, axis, DEPTH] = np.sum((plane_grad - seabed_gradient) * db[:, :2], axis=1) - db[:, 2]
    return out


def _with_random_rows(tpu: PointTpu, rows: dict[str, np.ndarray]) -> PointTpu:
    """``tpu`` with more random terms ``(n, 4)`` (x, y, z, depth), totals in quadrature."""
    add = {k: 0.0 for k in ("x", "y", "z", "d")}
    for v in rows.values():
        add["x"] = add["x"] + v[:, X] ** 2
        add["y"] = add["y"] + v[:, Y] ** 2
        add["z"] = add["z"] + v[:, Z] ** 2
        add["d"] = add["d"] + v[:, DEPTH] ** 2
    h2 = (add["x"] + add["y"]) / 2.0

    def up(a, b):
        return None if a is None else np.sqrt(a**2 + b)

    return dataclasses.replace(
        tpu,
        terms={**tpu.terms, **rows},
        sigma_x_m=up(tpu.sigma_x_m, add["x"]),
        sigma_y_m=up(tpu.sigma_y_m, add["y"]),
        sigma_h_m=up(tpu.sigma_h_m, h2),
        sigma_h_random_m=up(tpu.sigma_h_random_m, h2),
        sigma_v_m=up(tpu.sigma_v_m, add["z"]),
        sigma_v_random_m=up(tpu.sigma_v_random_m, add["z"]),
        sigma_depth_m=up(tpu.sigma_depth_m, add["d"]),
        sigma_depth_random_m=up(tpu.sigma_depth_random_m, add["d"]),
    )


def with_wave_facet(
    tpu: PointTpu,
    returns_direction: np.ndarray,
    surface: WaterSurface,
    vg: SurfaceVariogram,
    seabed_gradient: np.ndarray,
    n_water: float,
    tilt_sigma_rad=None,
    track_xy=None,
) -> PointTpu:
    """``tpu`` with the two random :data:`FACET_TERMS` (module notes).

    Parameters
    ----------
    tpu : PointTpu
        Rows ``tpu.row`` are pulses (rows of ``surface`` and ``returns_direction``).
    returns_direction : (n_pulses, 3)
        ``DetectedReturns.direction_meas`` of every pulse.
    surface : WaterSurface
    vg : SurfaceVariogram
    seabed_gradient : (len(tpu), 2)
        Depth gradient under each row's sounding.
    n_water : float
        The processing's phase index of water.
    tilt_sigma_rad : (n_pulses,) array_like, optional
        The plane tilt sigma each pulse's ``surface_tilt_*`` terms used (default: the fit's).
    track_xy : (n_pulses, 2) array_like, optional
        Each pulse's flight-line direction (:func:`track_directions`); default x.
    """
    r = np.asarray(tpu.row, dtype=np.int64)
    tilt = None if tilt_sigma_rad is None else np.asarray(tilt_sigma_rad, dtype=np.float64)[r]
    sig = unresolved_slope_sigma_rad(vg, surface, tilt, rows=r)  # (k, 2)
    jac = facet_jacobian(
        returns_direction[r],
        surface.normal[r],
        surface.entry_m[r],
        tpu.xyz_m,
        np.asarray(seabed_gradient, dtype=np.float64).reshape(-1, 2),
        surface.air_index,
        n_water,
        None if track_xy is None else np.asarray(track_xy, dtype=np.float64)[r],
    )
    rows = {name: jac[:, a, :] * sig[:, a : a + 1] for a, name in enumerate(FACET_TERMS)}
    # a row without water has no facet (sigma 0) and may have no entry or plane: no term
    ok = np.all([np.isfinite(v).all(axis=1) for v in rows.values()], axis=0)
    if np.any(~ok & np.any(sig > 0.0, axis=1)):  # never a silent NaN: said, and no term there
        warnings.warn(
            f"wave facet term not finite for {int(np.sum(~ok & np.any(sig > 0, axis=1)))} "
            "soundings with water; left at 0",
            RuntimeWarning,
            stacklevel=2,
        )
    rows = {k: np.where(ok[:, None], v, 0.0) for k, v in rows.items()}
    return _with_random_rows(tpu, rows)


def _points_excess_m(tpu: PointTpu, returns_direction, surface: WaterSurface, refr):
    """(n,) the facet excess of each point's in-water path (``surface`` with its facets)."""
    r = np.asarray(tpu.row, dtype=np.int64)
    length = np.linalg.norm(tpu.xyz_m - surface.entry_m[r], axis=1)
    return expected_depth_excess_m(
        returns_direction[r],
        surface.normal[r],
        length,
        surface.air_index,
        refr.phase_index,
        np.where(surface.is_water[r, None], surface.facet_slope_var[r], 0.0),
        None if surface.track_xy is None else surface.track_xy[r],
        refr.facet_decay_per_m,
    )


def with_facet_excess(tpu: PointTpu, returns_direction, surface: WaterSurface, refr) -> PointTpu:
    """``tpu`` with the correlated :data:`EXCESS_TERM`: the facet correction's uncertainty.

    Refraction raised each sounding by the facets' expected excess at the sea's assumed
    mean-square slope (``refr.facet_mss``, :mod:`pipeline.process.facet_excess`). The excess
    is linear in the slope variance, and ``mss`` is uncertain by ``refr.facet_mss_sigma``
    (the logged wind's sigma through Cox-Munk): the depth and elevation by
    ``|excess| * facet_mss_sigma / facet_mss``. No term without facets.

    Parameters
    ----------
    tpu : PointTpu
        Rows ``tpu.row`` are pulses (rows of ``surface``).
    returns_direction : (n_pulses, 3)
        Measured beam directions.
    surface : WaterSurface
        The fitted surface with its ``facet_slope_var`` (None: no facets, ``tpu`` unchanged).
    refr : RefractionSettings
        The processing's refraction settings.
    """
    if surface.facet_slope_var is None or refr.facet_mss <= 0.0:
        return tpu
    excess = _points_excess_m(tpu, returns_direction, surface, refr)
    sigma = np.abs(excess) * (refr.facet_mss_sigma / refr.facet_mss)
    return with_random_term(tpu, EXCESS_TERM, sigma, sigma, correlated=True)


def with_uncorrected_facet_excess(
    tpu: PointTpu,
    returns: DetectedReturns,
    surface: WaterSurface,
    refr,
    group=None,
    *,
    facets=_MEASURE,
) -> PointTpu:
    """``tpu`` with the correlated :data:`UNCORRECTED_TERM`: the facet excess left on.

    With the facet correction off (``refr.facet_mss`` 0) the soundings keep the in-water
    paths' second-order excess through the facets the fitted planes do not follow, deep by
    about ``L (1 - 1/n_w)^2 mss / 2`` at nadir. Where the echoes show a wave sea
    (:func:`~pipeline.process.facet_excess.wave_sea`), its predicted size at the logged
    wind's mean-square slope (``refr.facet_mss_uncorrected``), computed as the correction
    would (:func:`~pipeline.process.facet_excess.expected_depth_excess_m`), is the term's
    sigma in depth and elevation: one sign for the whole survey, so correlated.

    Parameters
    ----------
    tpu : PointTpu
        Rows ``tpu.row`` are pulses (rows of ``returns`` and ``surface``).
    returns : DetectedReturns
    surface : WaterSurface
        The fitted surface (without facets: the correction is off).
    refr : RefractionSettings
    group : (n_pulses,) int, optional
        Pulses sharing one detection (a photon window's shots).
    facets : FacetWide or None, optional
        The survey's facet figures (:func:`~pipeline.process.facet_excess.facet_wide` at
        ``refr.facet_mss_uncorrected``; None: no wave sea), as measured over the whole survey
        (a tile of it is given them, :mod:`pipeline.uncertainty.tpu_survey_wide`); default:
        measured from ``returns``.
    """
    mss = refr.facet_mss_uncorrected
    if refr.facet_mss > 0.0 or mss <= 0.0:
        return tpu
    if facets is _MEASURE:
        facets = facet_wide(returns, surface, mss, group)
    faceted = apply_facets(returns, surface, mss, facets)
    if faceted.facet_slope_var is None:
        return tpu
    sigma = np.abs(_points_excess_m(tpu, returns.direction_meas, faceted, refr))
    return with_random_term(tpu, UNCORRECTED_TERM, sigma, sigma, correlated=True)
