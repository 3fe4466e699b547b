"""Expected photoelectrons and time shapes of every return, per pulse and sub-ray, in log space.

The lidar equation of the reference document (Figure 11),
``N = N_L [beta dR] (A/R^2) [T T] [eta G] + N_B``, evaluated along each traced sub-ray
(:class:`~pipeline.simulate.paths.Paths`) and kept as natural logarithms, so that a 100 m deep
floor in turbid water (e^-3000) is as exact as a bright land echo. Common factor of every return:
``ln N_L + ln eta_t + ln eta_r + ln A + ln G(R) + ln w_j - 2 alpha_air R``.

Returns
-------
* **Water surface**: quasi-specular glint of the wave facets in two scales (the traced slope at
  the hit plus the unresolved Cox-Munk facets, in slope space) and Lambertian whitecaps:
  :mod:`pipeline.simulate.glint`.
* **Land** (LAND sub-rays): Lambertian, ``rho cos(t) / pi``, ``rho`` a Table 1 graybody power
  reflectance (desert sand by default), range ``R``.
* **Bottom**: ``T_down T_up T_w^2 (rho_b / pi) cos(t_b)`` times the refracted aperture term
  (:mod:`.geometry`), ``T_w = exp(-∫ k dl)`` with the lidar attenuation ``k`` between ``c`` and
  ``K_d`` set by the receiver's field of view (Gordon 1982, :mod:`pipeline.water_optics`;
  ``returns.lidar_attenuation = "beam"``: ``k = c``, the single-scattering equation).
* **Water column**: ``T_down T_up beta(180) ∫ exp(-2 k l) dOmega_w(l) dl``, ``k`` at the
  field-of-view radius where the sub-ray enters the water (the radius grows by
  ``tan(fov/2) n_a / n_w`` per metre, a few % over a column); ``T_up`` by reciprocity at the
  entry facet (unpolarised T air→water at the same angle pair), because the trace stage only
  gives ``T_up`` for bottom returns. NO_BOTTOM sub-rays scatter until the end of the window.
  ``beta(180)``: the scene's, or from ``c`` through a named phase function
  (:mod:`pipeline.water_optics`).
* **Scattering layer** (optional, ``water.layer_depth_m > 0``): a horizontal slab of thickness
  ``T`` centred ``layer_depth_m`` below the mean water level (``water_surface.level_m``) that adds
  ``beta_L`` to the volume backscatter at 180°. Each wet sub-ray crosses it along its refracted
  ray between the in-water paths ``l1`` (top, or the surface) and ``l2`` (bottom of the slab, or
  the seabed when that comes first: a layer below the seabed gives no echo); its echo is the
  column integral over that segment, ``T_down T_up beta_L ∫_l1^l2 exp(-2 k l) dOmega_w(l) dl``
  (same reciprocity ``T_up``, ``k`` the chunk's median column attenuation), one Gaussian per
  sub-ray. Model choices: the layer's own extinction is neglected (optically thin layer: the
  bottom and column below it are not dimmed), and its echo's time shape is a Gaussian with the
  segment's mean and variance, shifted and widened by the forward-scattering delay.

Time: echoes at ``2 n_air R / c0`` and ``+ 2 n_g L / c0`` (group index in water). Gaussian
widths ``sigma^2 = sigma_pulse^2 + sigma_detector^2``. Forward scattering
(:mod:`pipeline.forward_scatter`, ``returns.forward_scatter = "small_angle"``) splits each bottom
echo into the undelayed pulse and a tail, the pulse convolved with an exponential delay (a column-
shaped component of unbounded width), so the echo is skewed late and its centroid delayed by
the mean two-way excess path ``n_g kappa_1 / c0``. The column of a pulse is one component:
N-weighted mean start, decay rate ``2k + d ln(dOmega_w)/dl`` and duration. The layer echo's
timing and integral: :mod:`pipeline.simulate.layer`.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from pipeline import lidar_equation as le
from pipeline import optics
from pipeline.config import setting
from pipeline.constants import FWHM_TO_SIGMA
from pipeline.forward_scatter import bottom_delay
from pipeline.forward_scatter_mc import water_tables
from pipeline.simulate import paths as P
from pipeline.simulate.geometry import (
    LOG_ZERO,
    column_aggregate,
    log_aperture_factor,
    log_column_integral,
    safe_log,
)
from pipeline.simulate.glint import (
    MIN_MEAN_SQUARE_SLOPE,
    log_surface_backscatter_per_sr,
    surface_mean_square_slope,
)
from pipeline.simulate.layer import LayerEcho, layer_echo
from pipeline.water_optics import scattering_split, water_attenuation

__all__ = [
    "ReturnSettings",
    "ReturnBudget",
    "MIN_MEAN_SQUARE_SLOPE",
    "surface_mean_square_slope",
    "log_surface_backscatter_per_sr",
    "land_power_reflectance",
    "LayerEcho",
    "layer_echo",
    "return_budget",
]

C0 = optics.SPEED_OF_LIGHT_M_S


@dataclass(frozen=True, kw_only=True)
class ReturnSettings:
    """Model choices of the return budget that the scene does not hold elsewhere."""

    land_surface: str = setting(
        "desert_sand",
        choices=tuple(optics.GRAYBODY_AMPLITUDE_PERCENT),
        doc="Table 1 graybody surface of LAND sub-rays",
    )
    land_reflectivity_position: float = setting(
        0.5, ge=0.0, le=1.0, doc="where in Table 1's amplitude range: 0 low end, 1 high end"
    )
    resolved_mean_square_slope: float = setting(
        0.0, ge=0.0, le=1.0, doc="slope variance the water-surface mesh already carries"
    )
    forward_scatter: str = setting(
        "small_angle",
        choices=("small_angle", "none"),
        doc="bottom-echo delay by forward scattering (pipeline.forward_scatter)",
    )
    lidar_attenuation: str = setting(
        "fov",
        choices=("fov", "beam"),
        doc="decay of bottom and column: 'fov' between c and K_d by the field of view "
        "(Gordon 1982), 'beam' c",
    )
    full_overlap_range_m: float = setting(
        0.0, ge=0.0, le=1e5, doc="G(R) = overlap_factor (R / R_full)^2 below this range"
    )


def land_power_reflectance(settings: ReturnSettings) -> float:
    """Power reflectance of the Table 1 land surface at the chosen point of its range."""
    lo, hi = optics.GRAYBODY_AMPLITUDE_PERCENT[settings.land_surface]
    amp = lo + settings.land_reflectivity_position * (hi - lo)
    return float(optics.graybody_power_reflectance(amp))


@dataclass(frozen=True)
class ReturnBudget:
    """Expected photoelectrons (log) and time shapes, shapes ``(n_pulses, n_sub)`` unless stated.

    Attributes
    ----------
    pulse_id : (n_pulses,) int64
    subray_flags : uint8
        The trace flags (:mod:`pipeline.simulate.paths`).
    t0_s : (n_pulses,) float64
        Time of sample 0 (bin centre) after emission; the window is
        ``[t0 - dt/2, t0 + (n_samples - 1/2) dt)``.
    sample_interval_s : float
    n_samples : int
    log_surface, log_land, log_bottom, log_column : float64
        ln expected photoelectrons of each sub-ray's water-surface, land, bottom and column
        return (:data:`~pipeline.simulate.geometry.LOG_ZERO` where there is none).
    t_surface_s, sigma_surface_s : float64
        Centre and Gaussian sigma of the surface or land echo, seconds.
    t_bottom_s, sigma_bottom_s : float64
        Centre and sigma of the bottom echo's undelayed pulse (0 where there is none).
    bottom_tail_weight, bottom_tail_s : float64
        Share ``w`` of the bottom echo delayed by forward scattering and the mean ``tau`` (s)
        of its exponential delay (:mod:`pipeline.forward_scatter`); 0 where there is none.
    column_log_pe, column_start_s, column_width_s, column_rate_per_s, column_sigma_s : (n_pulses,)
        The pulse's water column as one truncated-exponential-plus-Gaussian component.
    background_rate_hz : (n_pulses,) float64
        Solar background plus dark counts, photoelectrons per second.
    log_layer, t_layer_s, sigma_layer_s : float64 or None
        ln expected photoelectrons, centre and sigma of each sub-ray's scattering-layer echo
        (``LOG_ZERO`` / 0 where a sub-ray has none); None when the scene has no layer, so a
        layer-free budget builds exactly the components it always did.
    """

    pulse_id: np.ndarray
    subray_flags: np.ndarray
    t0_s: np.ndarray
    sample_interval_s: float
    n_samples: int
    log_surface: np.ndarray
    log_land: np.ndarray
    log_bottom: np.ndarray
    log_column: np.ndarray
    t_surface_s: np.ndarray
    sigma_surface_s: np.ndarray
    t_bottom_s: np.ndarray
    sigma_bottom_s: np.ndarray
    bottom_tail_weight: np.ndarray
    bottom_tail_s: np.ndarray
    column_log_pe: np.ndarray
    column_start_s: np.ndarray
    column_width_s: np.ndarray
    column_rate_per_s: np.ndarray
    column_sigma_s: np.ndarray
    background_rate_hz: np.ndarray
    log_layer: np.ndarray | None = None
    t_layer_s: np.ndarray | None = None
    sigma_layer_s: np.ndarray | None = None

    @property
    def has_layer(self) -> bool:
        """Whether the budget carries scattering-layer echoes (the scene has a layer)."""
        return self.log_layer is not None

    @property
    def n_pulses(self) -> int:
        """Pulses in the chunk."""
        return int(self.pulse_id.shape[0])

    @property
    def window_start_s(self) -> np.ndarray:
        """(n_pulses,) opening time of the window (edge of sample 0's bin)."""
        return self.t0_s - 0.5 * self.sample_interval_s

    @property
    def window_length_s(self) -> float:
        """Length of the window, ``n_samples * dt``."""
        return self.n_samples * self.sample_interval_s

    def totals(self) -> dict[str, np.ndarray]:
        """(n_pulses,) expected photoelectrons of each return type (0.0 below float range)."""

        def lse(a):
            m = np.max(a, axis=1)
            return m + np.log(np.sum(np.exp(a - m[:, None]), axis=1))

        no_layer = np.full(self.n_pulses, LOG_ZERO)
        out = {
            "surface": lse(self.log_surface),
            "land": lse(self.log_land),
            "bottom": lse(self.log_bottom),
            "layer": lse(self.log_layer) if self.has_layer else no_layer,
            "column": self.column_log_pe,
        }
        out = {k: np.exp(np.maximum(v, -745.0)) * (v > LOG_ZERO / 2) for k, v in out.items()}
        out["background"] = self.background_rate_hz * self.window_length_s
        return out


def _log_common(scene) -> float:
    """Log of the factors every return shares: photons, efficiencies, aperture, overlap."""
    sysm = scene.system
    photons = float(optics.photons_per_pulse(sysm.pulse_energy_j, sysm.wavelength_nm * 1e-9))
    aperture_m2 = math.pi * (sysm.telescope_diameter_m / 2.0) ** 2
    terms = [photons, sysm.transmitter_efficiency, sysm.receiver_efficiency, aperture_m2]
    terms.append(sysm.overlap_factor)
    return float(sum(safe_log(t) for t in terms))


def return_budget(paths, scene, detector, settings: ReturnSettings | None = None) -> ReturnBudget:
    """Evaluate the lidar equation for every sub-ray of a chunk of traced pulses.

    Parameters
    ----------
    paths : Paths
        Traced geometry, ``(n_pulses, n_sub)``.
    scene : Scene
        Uses ``system``, ``scanner.receiver_fov_mrad``, ``atmosphere``, ``water``,
        ``seabed.reflectance`` and ``background``.
    detector : DetectorSettings
        For the window (sample rate, length, pre-trigger) and the detector's timing spread.
    settings : ReturnSettings, optional
        Model choices; default the scene's ``returns`` table.

    Returns
    -------
    ReturnBudget
    """
    rs = settings or scene.returns
    n_a = scene.atmosphere.refractive_index
    water = scene.water
    n_w, n_g = water.phase_index, water.group_index
    flags = np.asarray(paths.flags)
    n, k = flags.shape
    wet = (flags & (P.MISS | P.LAND)) == 0
    land = (flags & P.LAND) != 0
    bottom = flags == P.OK
    hit = (flags & P.MISS) == 0
    r_air = np.where(hit, paths.air_range_m, 0.0)
    cos_a = np.where(hit, np.cos(np.clip(paths.incidence_rad, 0.0, 0.5 * np.pi)), 0.0)
    length = np.where(bottom, paths.water_path_m, 0.0)

    # common factors per sub-ray: pulse, optics, sub-ray weight, air two-way, overlap, 1/R^2
    base = _log_common(scene) + safe_log(paths.subray_weight)[None, :]
    base = base + 2.0 * optics.log_transmittance(scene.atmosphere.extinction_per_m, r_air)
    if rs.full_overlap_range_m > 0.0:
        base = base + 2.0 * safe_log(np.minimum(r_air / rs.full_overlap_range_m, 1.0))
    inv_r2 = -2.0 * safe_log(r_air)

    r0, _ = optics.fresnel_unpolarised(n_a, n_w, 0.0)
    mss = float(surface_mean_square_slope(water.wind_speed_m_s, rs.resolved_mean_square_slope))
    white = float(le.whitecap_fraction(water.wind_speed_m_s))
    # the glint in slope space against the traced facet (wet sub-rays' normals are the water's)
    up = np.array([0.0, 0.0, 1.0])
    nrm = np.where(wet[..., None], np.asarray(paths.surface_normal), up)
    log_bs = log_surface_backscatter_per_sr(paths.direction, nrm, float(r0), mss, white)
    log_surface = np.where(wet, base + log_bs + inv_r2, LOG_ZERO)
    rho_land = land_power_reflectance(rs)
    log_land = np.where(
        land, base + safe_log(rho_land / math.pi) + safe_log(cos_a) + inv_r2, LOG_ZERO
    )

    log_t_bot, k_col, radius0, radius_rate = water_attenuation(
        scene, rs.lidar_attenuation, r_air, length
    )
    cos_b = np.cos(np.clip(paths.bottom_incidence_rad, 0.0, 0.5 * np.pi))
    log_bot = (
        base
        + safe_log(paths.transmittance_down)
        + safe_log(paths.transmittance_up)
        + 2.0 * log_t_bot
        + safe_log(scene.seabed.reflectance / math.pi)
        + safe_log(cos_b)
        + log_aperture_factor(np.where(bottom, r_air, 1.0), length, cos_a, n_a, n_w)
    )
    log_bot = np.where(bottom, np.maximum(log_bot, LOG_ZERO), LOG_ZERO)

    # times and widths
    dt = detector.sample_interval_s
    m = detector.n_samples
    t_surf = np.where(hit, 2.0 * n_a * r_air / C0, 0.0)
    t_bot = np.where(bottom, t_surf + 2.0 * n_g * length / C0, 0.0)
    sig_sys2 = (scene.system.pulse_fwhm_s * FWHM_TO_SIGMA) ** 2 + (
        detector.impulse_response_fwhm_s * FWHM_TO_SIGMA
    ) ** 2
    sig_bot = np.where(bottom, math.sqrt(sig_sys2), 0.0)
    fs = rs.forward_scatter == "small_angle"
    if fs:
        b_p, b_w = scattering_split(scene)
        a_w = max(scene.water.extinction_per_m - b_p - b_w, 0.0)  # absorption, 1/m
        delay = bottom_delay(
            length, radius0 + radius_rate * length, (b_p, b_w), water_tables(), a_w
        )
        tail_w = np.where(bottom, delay.tail_weight, 0.0)
        tail_s = np.where(bottom, delay.tail_mean_m * n_g / C0, 0.0)
    else:
        tail_w = tail_s = np.zeros((n, k))
    sig_surf = np.full((n, k), math.sqrt(sig_sys2))
    t_first = np.min(np.where(hit, t_surf, np.inf), axis=1)
    t_first = np.where(np.isfinite(t_first), t_first, detector.pre_trigger_s)
    t0 = np.floor((t_first - detector.pre_trigger_s) / dt) * dt
    t_end = t0 + (m - 0.5) * dt

    # water column: NO_BOTTOM sub-rays scatter until the window closes
    no_bottom = wet & ((flags & P.NO_BOTTOM) != 0)
    col_len = np.where(bottom | ((flags & P.TIR_RETURN) != 0), paths.water_path_m, 0.0)
    open_len = np.maximum(t_end[:, None] - t_surf, 0.0) * C0 / (2.0 * n_g)
    col_len = np.where(wet, np.where(no_bottom, open_len, col_len), 0.0)
    _, t_entry = optics.fresnel_unpolarised(n_a, n_w, np.arccos(np.where(wet, cos_a, 1.0)))
    log_col = (
        base
        + 2.0 * safe_log(np.where(wet, t_entry, 0.0))  # T_down and T_up by reciprocity
        + safe_log(water.beta_180_per_m_sr(scene.system.wavelength_nm))
        + log_column_integral(k_col, col_len, np.where(wet, r_air, 1.0), cos_a, n_a, n_w)
    )
    log_col = np.where(wet & (col_len > 0.0), np.maximum(log_col, LOG_ZERO), LOG_ZERO)
    col = column_aggregate(log_col, t_surf, col_len, r_air, cos_a, k_col, n_a, n_w, n_g, sig_sys2)

    # scattering layer: only when the scene has one, so layer-free budgets stay as they were
    layer = {}
    if water.has_layer:
        k_lay = float(np.median(k_col[wet])) if wet.any() else water.extinction_per_m
        lay_water = dataclasses.replace(
            water, extinction_per_m=k_lay, diffuse_attenuation_per_m=None
        )
        lay = layer_echo(paths, lay_water, scene.water_surface.level_m, n_a)
        log_lay = (
            base
            + 2.0 * safe_log(np.where(lay.present, t_entry, 0.0))  # T_down, T_up (reciprocity)
            + safe_log(water.layer_backscatter_per_m_sr)
            + lay.log_integral
        )
        to_time = 2.0 * n_g / C0
        d_mean = d_var = 0.0
        if fs:  # the layer's photons are delayed like the bottom's, as a Gaussian shift
            lay_r = radius0 + radius_rate * lay.path_mean_m
            d = bottom_delay(lay.path_mean_m, lay_r, (b_p, b_w), water_tables(), a_w)
            d_mean, d_var = 0.5 * to_time * d.mean_m, (0.5 * to_time) ** 2 * d.var_m2
        layer = {
            "log_layer": np.where(lay.present, np.maximum(log_lay, LOG_ZERO), LOG_ZERO),
            "t_layer_s": np.where(lay.present, t_surf + to_time * lay.path_mean_m + d_mean, 0.0),
            "sigma_layer_s": np.where(
                lay.present, np.sqrt(sig_sys2 + to_time**2 * lay.path_var_m2 + d_var), 0.0
            ),
        }

    # background: sunlight off water or land seen through the air, plus dark counts
    w = np.asarray(paths.subray_weight)[None, :] * hit
    wsum = np.maximum(w.sum(axis=1), 1e-300)
    r_axis = (w * r_air).sum(axis=1) / wsum
    f_land = (w * land).sum(axis=1) / wsum
    albedo = (1.0 - f_land) * scene.background.scene_reflectance + f_land * rho_land
    unit = dataclasses.replace(
        scene, background=dataclasses.replace(scene.background, scene_reflectance=1.0)
    )
    solar = le.solar_background_rate_hz(unit, 0.0)
    air = optics.beer_lambert_transmittance(scene.atmosphere.extinction_per_m, r_axis)
    bg = solar * albedo * air + scene.system.dark_count_rate_hz

    return ReturnBudget(
        pulse_id=np.asarray(paths.pulse_id, dtype=np.int64),
        subray_flags=flags,
        t0_s=t0,
        sample_interval_s=dt,
        n_samples=m,
        log_surface=log_surface,
        log_land=log_land,
        log_bottom=log_bot,
        log_column=log_col,
        t_surface_s=t_surf,
        sigma_surface_s=sig_surf,
        t_bottom_s=t_bot,
        sigma_bottom_s=sig_bot,
        bottom_tail_weight=tail_w,
        bottom_tail_s=tail_s,
        background_rate_hz=np.asarray(bg, dtype=np.float64),
        **col,
        **layer,
    )
