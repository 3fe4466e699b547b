"""Seabed points: refraction at the fitted water surface and the in-water range at group speed.

Geometry per pulse with a bottom return (measured origin ``o``, unit direction ``d``)
---------------------------------------------------------------------------------
* The pulse's local water plane (upward normal ``N``) meets the beam at ``r_e``
  (:func:`pipeline.process.surface_fit.fit_water_surface`); its own (non-outlier) surface
  return lies on the beam at ``r_s = c t_s / (2 n_air)``.
* Entry point ``E = o + d r_in``, ``r_in = r_e + w (r_s - r_e)``: the height the pulse met is
  the plane plus the part ``w`` of its own echo's offset from the plane that is sea, not ranging
  noise (``WaterSurface.own_weight``, :func:`pipeline.process.surface_land.own_echo_weight`:
  ``1 - (ranging sigma / fit scatter)²``; 1 where the detector gives no timing sigma; 0
  without an own return). In waves the plane cannot follow (the fit scatters more than the
  echoes range) the pulse enters at its own echo; on a calm sea whose echoes scatter by
  their ranging noise alone it enters on the plane, and the noise of its own echo stays out.
  This is the least-squares estimate of the height met from two measurements of it (the
  plane, the echo) whose errors are the wave and the ranging noise.
* Refracted direction ``t`` by the vector form of Snell's law with the water's *phase* index
  (:func:`pipeline.optics.refract_direction`, air index from the surface fit), at the local
  plane's normal.
* In-water one-way path along ``t`` at the *group* speed ``c / n_g``, timed from the entry:
  ``L = (c t_b / 2 - n_air r_in) / n_g`` (``c (t_b - t_s) / (2 n_g)`` at ``w = 1``). Pulses
  without an own surface return are flagged ``SURFACE_INTERPOLATED``.
* ``L`` less the forward-scattering range bias the bottom echo carries
  (:mod:`pipeline.process.scatter_bias`, when ``forward_scatter`` is set).
* Seabed point ``B = E + t L``; with ``facet_mss`` > 0 (``process.wave_facet_correction``,
  off by default) raised by the mean excess of the in-water paths through the wave facets the
  plane does not follow (second order: :mod:`pipeline.process.facet_excess`; where the
  survey's echoes show a wave sea). Over the flat twin of suite tuning seed 502 (20° Palmer,
  9.8 m/s, 12 m) the seabed's median error was +3.4 mm; under the waves −9.0 mm, predicted
  −13.0 mm; corrected +3.4 mm. On held-out seeds 4, 5 and 7 (seabeds of 7.5-17.5°) the waves
  raised the soundings instead, and the correction made their bias worse: off by default.
  ``depth_m`` is the height of the sea above ``B`` minus ``B_z``
  (vertical, positive down), the sea above ``B`` being the local water plane's level at ``E``
  (carried to ``B`` by the global plane's tilt), plus the share ``gamma(Delta)`` of the local
  plane's own rise from ``E`` to ``B`` that the survey's echo pairs show comes true there
  (:mod:`pipeline.process.sea_correlation`: over a moving wind sea the plane's tilt is mostly
  fit noise and ``gamma`` falls to 0 within a few metres; under a long swell it stays ~1; on
  the 5 m/s wave scene of issue 13 carrying the whole tilt made the sea above ``B`` err by
  0.21 m, more than the sea's own 0.145 m), plus ``rho(Delta) w s_E``: the part of the sea
  met at ``E`` above the plane (``w s_E``, vertical) still there ``Delta = |B - E|`` away,
  ``rho`` the correlation of the sea's heights above the plane at that lag measured from the
  survey's surface returns (:mod:`pipeline.process.sea_correlation`; simple kriging from one
  observation). Before ``gamma`` (the whole tilt carried), on the
  suite's tuning wave scenes (point RMSE, m; plane alone / echo alone / measured ``rho``):
  seed 33, 1.1 m under 10.9 m/s: 0.077 / 0.056 / 0.053; seed 36, 6.7 m under 10.7 m/s:
  0.104 / 0.116 / 0.096; seed 57, 17.5 m under 10.1 m/s: 0.248 / 0.258 / 0.247.

The *uncorrected* point (``correct_refraction=False``, flagged ``NOT_REFRACTED``) is the
straight beam at the speed of light in air for the whole range: ``o + d c t_b / (2 n_air)``.
Land pulses are always computed that way (no water to cross), flagged ``LAND``.

Uncertainty (a-priori, first order, one sigma; independent terms added in quadrature)
-------------------------------------------------------------------------------------
navigation position (``position_sigma_h_m``, ``position_sigma_v_m``); pointing
(``pointing_sigma_deg``) over the air and water paths; the entry's range (the surface return's
timing by ``w``, the fitted height by ``1 - w``), which moves the entry along the beam and the
path's length by ``n_air / n_g`` as much the other way; the surface tilt (a tilt error ``dN``
turns the refracted ray by ``dN (1 - n_air/n_w)``); the bottom's timing (the detector's
sigmas, else ``timing_sigma_s``) and the group index (``group_index_sigma``) along the
in-water path.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from pipeline.optics import SPEED_OF_LIGHT_M_S, refract_direction
from pipeline.process.classify import ClassifySettings, classify_points
from pipeline.process.facet_excess import apply_facets, expected_depth_excess_m
from pipeline.process.photon_windows import PhotonWindows
from pipeline.process.refraction_settings import RefractionSettings
from pipeline.process.returns import DetectedReturns, PointFlag, Points, ReturnKind
from pipeline.process.scatter_bias import range_bias_m
from pipeline.process.sea_kriging import sea_field
from pipeline.process.surface_fit import SurfaceFitSettings, WaterSurface, fit_water_surface
from pipeline.process.surface_points import returns_numbering, timing_sigma, water_surface_points
from pipeline.process.survey_wide import SurveyWide, sea_wide

__all__ = [
    "RefractionSettings",
    "ProcessedPoints",
    "seabed_points",
    "seabed_xyz_depth",
    "kriged_sea_change",
    "water_surface_points",
    "georeference",
]

_C = SPEED_OF_LIGHT_M_S


@dataclass(frozen=True)
class ProcessedPoints:
    """Everything :func:`georeference` makes.

    Attributes
    ----------
    surface : WaterSurface
        The fitted water surface per pulse.
    points : Points
        Classified points: surface returns, then bottom returns (refraction corrected), then
        (if asked) derived water-surface points.
    uncorrected : Points
        Classified bottom returns without refraction correction, for comparison.
    sea_change_m : (n_pulses,) ndarray or None
        The kriged sea change the bottom points' depths used (:func:`kriged_sea_change` of the
        same returns, surface and settings, made once: the TPU holds it); None where the sea
        is not kriged.
    claims_withheld : int
        Class-45 claims not made: a nearby class-40 sounding lies shallower
        (:func:`pipeline.process.survey_points.contradicted_claims`).
    wide : SurveyWide or None
        The survey-wide figures the surface fit and the sea used (measured from these
        returns, or handed in).
    withheld_pulse_id : (claims_withheld,) int64 or None
        The pulses of those claims.
    """

    surface: WaterSurface
    points: Points
    uncorrected: Points
    sea_change_m: np.ndarray | None = None
    claims_withheld: int = 0
    wide: SurveyWide | None = None
    withheld_pulse_id: np.ndarray | None = None


def seabed_points(
    returns: DetectedReturns,
    surface: WaterSurface,
    settings: RefractionSettings | None = None,
    *,
    correct_refraction: bool = True,
    krige_at: np.ndarray | None = None,
) -> Points:
    """Georeference the bottom returns of every pulse that has one.

    Parameters
    ----------
    returns : DetectedReturns
        Measured navigation and detected return times.
    surface : WaterSurface
        The fitted water surface of the same pulses.
    settings : RefractionSettings, optional
        Defaults if omitted.
    correct_refraction : bool
        False gives the uncorrected points (straight beam, speed of light in air).
    krige_at : (n_pulses,) bool ndarray, optional
        Krige the sea only above these pulses' soundings (a block's, whose points are read:
        :mod:`pipeline.survey_block_reach`); the others read the plane. Each sounding is
        kriged on its own, so those asked get the figures of a run asking all. Default: all.

    Returns
    -------
    Points
        One point per pulse with a bottom return, ``kind = BOTTOM``, unclassified (1).

    Notes
    -----
    Where ``surface.sea_change_m`` is given (:func:`kriged_sea_change`, NaN: the plane's
    reading), the sea's change from each entry to above its sounding is used as given, not
    kriged again: the TPU holds it while it moves one input at a time (its error is the TPU's
    own sea term; kriged again at points moved by millimetres, it would jump wherever an echo
    enters or leaves the nearest ones).
    """
    return _seabed_points(returns, surface, settings, correct_refraction, krige_at=krige_at)[0]


def seabed_xyz_depth(
    returns: DetectedReturns, surface: WaterSurface, settings: RefractionSettings | None = None
) -> np.ndarray:
    """:func:`seabed_points`' ``x, y, z, depth`` (m), ``(n_bottom, 4)``, and nothing else.

    The TPU's repeated passes: no a-priori sigmas, flags or numbering are made. Raises
    ValueError where one is not finite, as :func:`seabed_points` does.
    """
    return _seabed_points(returns, surface, settings, True, xyz_depth_only=True)[0]


def kriged_sea_change(
    returns: DetectedReturns, surface: WaterSurface, settings: RefractionSettings | None = None
) -> np.ndarray | None:
    """The kriged change of the sea from each pulse's water entry to above its sounding.

    Returns
    -------
    (n_pulses,) ndarray or None
        Metres, NaN where the depth reads the plane (no bottom, no echo near, not refracted);
        None where the survey's sea is not kriged (``surface.sea_field`` None).
    """
    unfrozen = dataclasses.replace(surface, sea_change_m=None)
    return _seabed_points(returns, unfrozen, settings, True)[1]


def _seabed_points(
    returns, surface, settings, correct_refraction, *, xyz_depth_only=False, krige_at=None
):
    """:func:`seabed_points` (or :func:`seabed_xyz_depth`'s array) and its sea change."""
    st = settings or RefractionSettings()
    if len(surface) != len(returns):
        raise ValueError(f"`surface` has {len(surface)} pulses; `returns` has {len(returns)}")
    na, nw, ng = surface.air_index, st.phase_index, st.group_index
    idx = np.flatnonzero(returns.has_bottom)
    o, d = returns.origin_meas_m[idx], returns.direction_meas[idx]
    tb, ts = returns.t_bottom_s[idx], returns.t_surface_s[idx]
    flags = surface.flags[idx].copy()
    water = surface.is_water[idx]
    r_straight = _C * tb / (2.0 * na)
    straight = o + d * r_straight[:, None]

    entry, nrm, r_e = surface.entry_m[idx], surface.normal[idx], surface.range_to_entry_m[idx]
    own = returns.has_surface[idx] & ((flags & PointFlag.SURFACE_OUTLIER) == 0)
    cos_i = np.abs(np.sum(d * nrm, axis=1))
    r_s = _C * ts / (2.0 * na)
    tb_range = _C * tb / 2.0  # the bottom's air-equivalent range, times n_air
    if surface.own_shift_m is not None:  # a photon window's heights carried to its shot
        shift = surface.own_shift_m[idx]
        r_s = r_s + shift
        # its one bottom height too: where the sea stands higher over the shot than at the
        # window's centre, the shot's path runs as much longer in water as shorter in air
        tb_range = tb_range - (ng - na) * shift
    # where the pulse met the water: between the fitted plane and its own echo, by how much of
    # the echo's offset from the plane is wave rather than ranging noise (module docstring)
    weight = np.ones(len(idx)) if surface.own_weight is None else surface.own_weight[idx]
    weight = np.where(own & water & (r_s > 0.0), weight, 0.0)
    r_in = r_e + weight * (r_s - r_e)
    if correct_refraction:
        length = (tb_range - na * r_in) / ng
        flags[water & ~own] |= np.uint16(PointFlag.SURFACE_INTERPOLATED)
        above = water & (length <= 0.0)
        flags[above] |= np.uint16(PointFlag.ABOVE_SURFACE)
        refr = water & ~above
        entry = np.where(refr[:, None], o + d * r_in[:, None], entry)
        t_dir = d.copy()
        if refr.any():
            t_dir[refr], _ = refract_direction(d[refr], nrm[refr], na, nw)
        length = np.where(refr, length, 0.0)
        # the forward-scattering delay makes the detected bottom late (process/scatter_bias.py)
        length = length - range_bias_m(st.forward_scatter, length, r_in, na, nw, ng)
        xyz = np.where(refr[:, None], entry + t_dir * length[:, None], straight)
        if surface.facet_slope_var is not None:
            # the in-water path through the facets the plane does not follow reads deep on
            # average (second order; pipeline.process.facet_excess): raise the sounding
            fv = np.where(refr[:, None], surface.facet_slope_var[idx], 0.0)
            track = None if surface.track_xy is None else surface.track_xy[idx]
            xyz[:, 2] += expected_depth_excess_m(
                d, nrm, length, na, nw, fv, track, st.facet_decay_per_m
            )
    else:
        refr = np.zeros(len(idx), dtype=bool)
        t_dir, length = d, np.zeros(len(idx))
        flags |= np.uint16(PointFlag.NOT_REFRACTED)
        xyz = straight

    # depth below the sea above the point: the local plane's level where the pulse met the
    # sea (its tilt not extrapolated, WaterSurface.level_z_m), plus the part of the sea the
    # pulse met at its entry (w s_E) that is still there Delta away (sea_correlation)
    met = np.where(refr[:, None], o + d * r_in[:, None], xyz)  # where the pulse met the sea
    level = surface.level_z_m(idx, met[:, :2], xyz[:, :2])
    rise = surface.surface_z_m(idx, xyz[:, 0], xyz[:, 1]) - level  # the plane's own tilt
    corr = surface.sea_correlation
    delta = np.hypot(xyz[:, 0] - met[:, 0], xyz[:, 1] - met[:, 1])
    share = np.ones(len(idx)) if corr is None else corr.tilt_at(delta)
    depth = level + share * rise - xyz[:, 2]
    if correct_refraction and corr is not None:
        sea = np.where(refr, d[:, 2] * (r_in - r_e), 0.0)  # w s_E, vertical
        depth = depth + corr.at(delta) * sea
    field = surface.sea_field
    change = None
    sea_change_m = surface.sea_change_m
    if correct_refraction and sea_change_m is not None:
        change = np.full(len(returns), np.nan)
        r = np.flatnonzero(refr & np.isfinite(sea_change_m[idx]))
        depth[r] = met[r, 2] + sea_change_m[idx[r]] - xyz[r, 2]
    elif correct_refraction and field is not None and returns.t_emit_s is not None:
        # the sea's change from where the pulse met it to above the point, at the pulse's
        # time, kriged from the echoes around each (pipeline.process.sea_kriging), added to the
        # entry's own height: the point hangs below the entry by the in-water path, so an error
        # of the entry's height (the surface echo's range) moves both and cancels in the depth,
        # as in the plane's reading. The kriged height above the point alone would carry it
        # whole, and the kriging's own error at both points (0.078 m sd on suite tuning seed
        # 33, an oscillating scan over a 10.9 m/s sea, where the entry's echo is right to
        # 0.013 m): their difference errs by 0.038 m. The plane's reading stays where no echo
        # is near.
        change = np.full(len(returns), np.nan)
        r = np.flatnonzero(refr if krige_at is None else refr & np.asarray(krige_at)[idx])
        t_r = np.asarray(returns.t_emit_s)[idx[r]]
        at_b, _, used = field.predict(xyz[r, :2], t_r)
        at_e, _, _ = field.predict(met[r, :2], t_r)
        sea_change = (
            surface.global_z_m(xyz[r, 0], xyz[r, 1])
            + at_b
            - surface.global_z_m(met[r, 0], met[r, 1])
            - at_e
        )
        r, sea_change = r[used > 0], sea_change[used > 0]
        depth[r] = met[r, 2] + sea_change - xyz[r, 2]
        change[idx[r]] = sea_change
    if xyz_depth_only:
        xyzd = np.column_stack([xyz, depth])
        if not np.all(np.isfinite(xyzd)):  # as Points would
            raise ValueError("seabed points and depths must be finite (no NaN: use the masks)")
        return xyzd, change

    # a-priori uncertainty, first order
    sig_tb = timing_sigma(returns, idx, "bottom", st.timing_sigma_s)
    sig_ts = timing_sigma(returns, idx, "surface", st.timing_sigma_s)
    point = np.radians(st.pointing_sigma_deg)
    sin_i = np.linalg.norm(np.cross(d, nrm), axis=1)
    sin_w = np.linalg.norm(np.cross(t_dir, nrm), axis=1)
    cos_w = np.sqrt(np.maximum(1.0 - sin_w**2, 0.0))
    r_air = np.where(refr, r_in, r_straight)
    var_v = st.position_sigma_v_m**2 + (r_air * sin_i * point) ** 2
    var_h = st.position_sigma_h_m**2 + (r_air * point) ** 2
    # the bottom time and the group index along the (refracted or straight) path
    sig_len = np.where(refr, _C * sig_tb / (2.0 * ng), _C * sig_tb / (2.0 * na))
    sig_len = np.hypot(sig_len, length * st.group_index_sigma / ng)
    cos_path, sin_path = np.where(refr, cos_w, cos_i), np.where(refr, sin_w, sin_i)
    var_v += (sig_len * cos_path) ** 2
    var_h += (sig_len * sin_path) ** 2
    # the entry's range (the echo's timing and the fitted height, by their weights) moves the
    # entry along the beam and shortens the in-water path by n_air / n_g as much
    hs = surface.height_sigma_m[idx] / np.maximum(cos_i, 1e-3)
    sig_in = np.where(refr, np.hypot(weight * _C * sig_ts / (2.0 * na), (1.0 - weight) * hs), 0.0)
    move = d - (na / ng) * t_dir
    var_v += (sig_in * move[:, 2]) ** 2
    var_h += sig_in**2 * (move[:, 0] ** 2 + move[:, 1] ** 2)
    # in-water: pointing and surface tilt
    turn = surface.normal_sigma_rad[idx] * (1.0 - na / nw)
    var_v += (length * sin_w * np.hypot(point, turn)) ** 2
    var_h += (length * np.hypot(point, turn) * cos_w) ** 2

    number, n_ret = returns_numbering(returns, idx, bottom=True)
    amp = None if returns.bottom_amplitude is None else returns.bottom_amplitude[idx]
    points = Points(
        pulse_id=returns.pulse_id[idx],
        xyz_m=xyz,
        depth_m=depth,
        classification=np.ones(len(idx), dtype=np.uint8),
        kind=np.full(len(idx), ReturnKind.BOTTOM, dtype=np.uint8),
        flags=flags,
        detector_flags=returns.flags[idx],
        return_number=number,
        number_of_returns=n_ret,
        confidence=returns.bottom_confidence[idx],
        uncertainty_v_m=np.sqrt(var_v),
        uncertainty_h_m=np.sqrt(var_h),
        amplitude=amp,
    )
    return points, change


def georeference(
    returns: DetectedReturns,
    *,
    surface_settings: SurfaceFitSettings | None = None,
    refraction_settings: RefractionSettings | None = None,
    classify_settings: ClassifySettings | None = None,
    include_derived_surface: bool = False,
    windows: PhotonWindows | None = None,
    wide: SurveyWide | None = None,
    planes_at: np.ndarray | None = None,
    krige_at: np.ndarray | None = None,
) -> ProcessedPoints:
    """Detected returns to classified points: surface fit, refraction, classification.

    Returns
    -------
    ProcessedPoints
        The fitted surface, the classified points (surface returns, refraction-corrected
        bottom returns, optional derived surface points) and the classified uncorrected bottom
        points.

    ``windows``: photon counting, how the shots were accumulated (a window's shots share one
    detection: the sea correlation does not pair them). ``wide``: the survey-wide figures
    (:func:`~pipeline.process.survey_wide.survey_wide` of the whole survey) to use instead of
    measuring them from ``returns`` (a tile of the survey and its halo). ``planes_at``,
    ``krige_at`` (``(n_pulses,)`` bool, need ``wide``): the local planes and the kriged sea
    only at those pulses (:func:`fit_water_surface`, :func:`seabed_points`; a block's,
    :mod:`pipeline.survey_block_reach`): the other pulses' points are not the survey's.
    """
    if (planes_at is not None or krige_at is not None) and wide is None:
        raise ValueError("`planes_at` and `krige_at` need the survey-wide figures (`wide`)")
    st = surface_settings or SurfaceFitSettings()
    group = None if windows is None else windows.of_returns(returns)
    wide_s = None if wide is None else wide.surface
    surface = fit_water_surface(returns, st, wide_s, group, planes_at=planes_at)
    sea = sea_wide(returns, surface, st, refraction_settings, group) if wide is None else wide.sea
    field = None
    if sea.covariance is not None:  # photon windows: one detection each, never kriged
        field = sea_field(
            returns,
            surface,
            neighbours=st.kriging_neighbours,
            window_s=st.kriging_window_s,
            speed_m_s=st.radius_m / st.time_window_s,
            covariance=sea.covariance,
        )
    surface = dataclasses.replace(surface, sea_correlation=sea.correlation, sea_field=field)
    mss = (refraction_settings or RefractionSettings()).facet_mss
    surface = apply_facets(returns, surface, mss, sea.facets)
    bottom, sea_change = _seabed_points(
        returns, surface, refraction_settings, True, krige_at=krige_at
    )
    parts = [water_surface_points(returns, surface, refraction_settings), bottom]
    if include_derived_surface:
        parts.append(water_surface_points(returns, surface, refraction_settings, derived=True))
    points = classify_points(Points.concatenate(parts), classify_settings)
    raw = seabed_points(returns, surface, refraction_settings, correct_refraction=False)
    return ProcessedPoints(
        surface,
        points,
        classify_points(raw, classify_settings),
        sea_change,
        # the survey-wide figures used (measured here, or handed in for a tile): a survey's
        # sample hands them to its blocks (pipeline.survey_blocks)
        wide=SurveyWide(surface.wide, sea),
    )
