"""The lidar equation for a nadir beam over flat water, term by term, in log space.

Expected photoelectrons of a return (reference document, Figure 11)::

    N = N_L · [β ΔR] · A/R² · [T(λ_L, R) T(λ, R)] · [η G] + N_B

Each factor is kept as a natural logarithm in :class:`PhotonBudget` so that terms spanning
hundreds of orders of magnitude (a 100 m deep floor in turbid water) never underflow, and so the
JSON budget can list every factor.

Notes
-----
Surface: specular reflection from wave facets (Cox & Munk 1954) plus whitecaps. A facet returns
light to a nadir receiver only if its normal is vertical; with the isotropic Gaussian slope
density p(0) = 1/(π s²), the backscattered intensity per steradian per unit incident power is
``R_F(0) / (4 π s²)`` (a reflected direction moves twice as fast as the facet normal, so the
reflected cone is 4× the normal cone). Whitecaps (fractional cover W, Monahan & O'Muircheartaigh
1980, ``W = 2.95e-6 U^3.52``) add a Lambertian ``W ρ_foam / π`` with ``ρ_foam = 0.22``
(Koepke 1984). s² = 0.003 + 5.12e-3 U (Cox & Munk 1954, U at 12.5 m).

Floor and water column: radiance leaving the water is divided by n² and the beam footprint seen
through the surface subtends ``a / (H + D/n)²``, so the aperture term becomes ``A / (n H + D)²``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from pipeline import optics

__all__ = [
    "COX_MUNK_INTERCEPT",
    "COX_MUNK_SLOPE_PER_M_S",
    "FOAM_REFLECTANCE",
    "PhotonBudget",
    "cox_munk_mean_square_slope",
    "whitecap_fraction",
    "surface_backscatter_per_sr",
    "nadir_budget",
    "column_log_photons_per_m",
    "solar_background_rate_hz",
]

#: Cox & Munk (1954) clean-surface mean-square slope: s² = 0.003 + 5.12e-3 U (U at 12.5 m, m/s).
COX_MUNK_INTERCEPT = 0.003
COX_MUNK_SLOPE_PER_M_S = 5.12e-3
#: Effective whitecap reflectance in the visible (Koepke 1984, Appl. Opt. 23:1816).
FOAM_REFLECTANCE = 0.22


def cox_munk_mean_square_slope(wind_speed_m_s):
    """Total mean-square slope s² of a wind-roughened sea (Cox & Munk 1954).

    Parameters
    ----------
    wind_speed_m_s : float or ndarray
        Wind speed at 12.5 m above the sea, m/s.
    """
    return COX_MUNK_INTERCEPT + COX_MUNK_SLOPE_PER_M_S * np.asarray(wind_speed_m_s, dtype=float)


def whitecap_fraction(wind_speed_m_s):
    """Fraction of the sea covered by whitecaps, ``2.95e-6 U^3.52`` capped at 1.

    Monahan & O'Muircheartaigh (1980, J. Phys. Oceanogr. 10:2094), U at 10 m in m/s; the
    difference from 12.5 m is below the scatter of the fit.
    """
    u = np.asarray(wind_speed_m_s, dtype=float)
    return np.minimum(2.95e-6 * u**3.52, 1.0)


def surface_backscatter_per_sr(fresnel_r0, wind_speed_m_s):
    """Backscattered fraction per steradian of a nadir beam from the sea surface, sr⁻¹.

    ``(1 − W) R_F(0) / (4 π s²) + W ρ_foam / π`` (see module Notes).
    """
    s2 = cox_munk_mean_square_slope(wind_speed_m_s)
    w = whitecap_fraction(wind_speed_m_s)
    return (1.0 - w) * fresnel_r0 / (4.0 * np.pi * s2) + w * FOAM_REFLECTANCE / np.pi


@dataclass(frozen=True)
class PhotonBudget:
    """Expected photoelectrons per shot from the surface and the floor, as log factors.

    Attributes
    ----------
    surface_log_terms, floor_log_terms : dict of str to float
        Natural-log factors whose sum is the log of the expected photoelectrons.
    """

    surface_log_terms: dict[str, float] = field(default_factory=dict)
    floor_log_terms: dict[str, float] = field(default_factory=dict)

    @property
    def surface_log_photons(self) -> float:
        """Ln of the expected surface photoelectrons per shot."""
        return math.fsum(self.surface_log_terms.values())

    @property
    def floor_log_photons(self) -> float:
        """Ln of the expected floor photoelectrons per shot."""
        return math.fsum(self.floor_log_terms.values())

    @property
    def surface_photons(self) -> float:
        """Expected surface photoelectrons per shot."""
        return math.exp(self.surface_log_photons)

    @property
    def floor_photons(self) -> float:
        """Expected floor photoelectrons per shot (0.0 when below float range)."""
        return math.exp(self.floor_log_photons) if self.floor_log_photons > -745 else 0.0


def _common_log_terms(scene, altitude_m: float) -> dict[str, float]:
    """Transmitter, receiver and two-way air terms shared by every return."""
    sysm = scene.system
    wavelength_m = sysm.wavelength_nm * 1e-9
    aperture_m2 = math.pi * (sysm.telescope_diameter_m / 2.0) ** 2
    log_g = math.log(sysm.overlap_factor) if sysm.overlap_factor > 0 else -math.inf
    return {
        "transmitted_photons": math.log(
            optics.photons_per_pulse(sysm.pulse_energy_j, wavelength_m)
        ),
        "transmitter_efficiency": math.log(sysm.transmitter_efficiency),
        "receiver_efficiency": math.log(sysm.receiver_efficiency),
        "overlap": log_g,
        "air_two_way": 2.0
        * float(optics.log_transmittance(scene.atmosphere.extinction_per_m, altitude_m)),
        "aperture_m2": math.log(aperture_m2),
    }


def _fresnel_r0(scene) -> float:
    r_unpol, _ = optics.fresnel_unpolarised(
        scene.atmosphere.refractive_index, scene.water.phase_index, 0.0
    )
    return float(r_unpol)


def nadir_budget(scene, altitude_m: float, depth_m: float) -> PhotonBudget:
    """Photon budget of one nadir shot over flat water of depth ``depth_m``.

    Parameters
    ----------
    scene : Scene
        Validated scene (system, atmosphere, water, seabed).
    altitude_m : float
        Height of the instrument above the water surface, metres.
    depth_m : float
        Water depth, metres (positive down).

    Returns
    -------
    PhotonBudget
    """
    common = _common_log_terms(scene, altitude_m)
    r0 = _fresnel_r0(scene)
    t0 = 1.0 - r0
    water = scene.water
    n = water.phase_index / scene.atmosphere.refractive_index
    surface = dict(common)
    surface["surface_backscatter_per_sr"] = math.log(
        float(surface_backscatter_per_sr(r0, water.wind_speed_m_s))
    )
    surface["inverse_range_squared"] = -2.0 * math.log(altitude_m)
    floor = dict(common)
    floor["fresnel_transmission_two_way"] = 2.0 * math.log(t0)
    floor["water_two_way"] = 2.0 * float(optics.log_transmittance(water.extinction_per_m, depth_m))
    rho = scene.seabed.reflectance
    floor["bottom_lambertian_per_sr"] = math.log(rho / math.pi) if rho > 0 else -math.inf
    # n² radiance law and the footprint seen through the surface: A / (n H + D)², with n the
    # relative index water/air
    floor["inverse_range_squared"] = -2.0 * math.log(n * altitude_m + depth_m)
    return PhotonBudget(surface_log_terms=surface, floor_log_terms=floor)


def column_log_photons_per_m(scene, altitude_m: float, z_m):
    """Ln of the expected water-column photoelectrons per metre of depth at depth ``z_m``.

    Parameters
    ----------
    z_m : ndarray, shape (n,)
        Depths below the surface, metres.

    Returns
    -------
    ndarray, shape (n,)
        ``-inf`` where the backscatter coefficient is zero.
    """
    common = _common_log_terms(scene, altitude_m)
    water = scene.water
    z = np.asarray(z_m, dtype=float)
    t0 = 1.0 - _fresnel_r0(scene)
    beta = water.beta_180_per_m_sr(scene.system.wavelength_nm)
    log_beta = math.log(beta) if beta > 0 else -math.inf
    return (
        math.fsum(common.values())
        + 2.0 * math.log(t0)
        + 2.0 * optics.log_transmittance(water.extinction_per_m, z)
        + log_beta
        - 2.0 * np.log(water.phase_index / scene.atmosphere.refractive_index * altitude_m + z)
    )


def solar_background_rate_hz(scene, altitude_m: float) -> float:
    """Solar background photoelectrons per second at the detector.

    ``E_sun Δλ (ρ_scene/π) Ω_FOV A η_r T_air(H) / (h c / λ)``: sunlight reflected by the sea
    as a Lambertian albedo, seen through the receiver's field of view and filter.
    """
    sysm = scene.system
    bg = scene.background
    wavelength_m = sysm.wavelength_nm * 1e-9
    half_fov_rad = scene.scanner.receiver_fov_mrad * 1e-3 / 2.0
    solid_angle_sr = 2.0 * math.pi * (1.0 - math.cos(half_fov_rad))
    aperture_m2 = math.pi * (sysm.telescope_diameter_m / 2.0) ** 2
    power_w = (
        bg.solar_irradiance_w_m2_nm
        * sysm.filter_bandwidth_nm
        * bg.scene_reflectance
        / math.pi
        * solid_angle_sr
        * aperture_m2
        * sysm.receiver_efficiency
        * float(optics.beer_lambert_transmittance(scene.atmosphere.extinction_per_m, altitude_m))
    )
    return power_w * float(optics.photons_per_pulse(1.0, wavelength_m))
