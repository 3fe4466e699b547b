"""Inherent optics of the water that the scene leaves open: β(180), K_d and the lidar attenuation.

Phase functions (named, so every default below has a source)
------------------------------------------------------------
* **Particles**: the Fournier-Forand (FF) phase function (Fournier & Forand 1994, Proc. SPIE
  2258:194; closed form of Fournier & Jonasz 1999, Proc. SPIE 3761:62) with ``n = 1.10`` and
  Junge slope ``mu = 3.5835``, the fit to Petzold's (1972) average particle phase function of
  Mobley, Sundman & Boss (2002, Appl. Opt. 41:1035): backscatter fraction ``B = 0.0183``.
* **Sea water**: the molecular phase function ``(1 + 0.835 cos^2 psi) / (4 pi (1 + 0.835/3))``
  and ``b_sw(lambda) = 2.88e-3 (lambda / 500 nm)^-4.32`` 1/m (Morel 1974, in Mobley 1994,
  *Light and Water*, sec. 3.8).

``beta(180) = b_sw p_sw(180) + (b - b_sw) p_FF(180)`` with ``b = omega_0 c`` (single-scattering
albedo ``omega_0``): for ``c = 0.15`` 1/m and ``omega_0 = 0.55`` this is 4.8e-4 1/(m sr).

Lidar attenuation between c and K_d (Gordon 1982, Appl. Opt. 21:2996)
---------------------------------------------------------------------
Gordon's Monte Carlo of an airborne lidar found that the return decays with depth at a rate
``k`` that goes from the beam attenuation ``c`` for a narrow receiver field of view (``c R -> 0``,
``R`` the radius of the receiver's field of view at that depth) to the diffuse attenuation
``K_d`` for a wide one (``c R`` above ~5-6). Between the limits we use an exponential bridge in
the field-of-view diameter ``D = 2 R`` of the form used for Gordon's results in the
oceanographic-lidar literature (e.g. the review of Churnside 2014, Opt. Eng. 53:051405; the
coefficient 0.85 is as recalled from there and was not re-checked against the paper, the tests
check only Gordon's two limits and monotonicity):
``k(R) = K_d + (c - K_d) exp(-0.85 c D)``; it is within 1 % of ``c - K_d`` of ``K_d`` from
``c R = 2.7`` and within 1e-4 from ``c R = 5.4``. Along a refracted path the field of view
widens, ``R(l) = tan(fov/2) (R_air + l n_a / n_w)`` (the sagittal virtual-source distance of
:mod:`pipeline.simulate.geometry`), so the one-way transmittance is
``exp(-∫_0^L k(R(l)) dl)``, integrated in closed form here. When the scene gives no ``K_d``,
``K_d = min(0.2 c + 0.04, c)`` (the empirical bridge of the project's issue 12, model choice).

Secchi depth, for reporting penetration: ``Z_SD = 1.7 / K_d`` (Poole & Atkins 1926).
"""

from __future__ import annotations

import math

import numpy as np

__all__ = [
    "FF_PETZOLD_INDEX",
    "FF_PETZOLD_SLOPE",
    "GORDON_DIAMETER_COEFF",
    "SECCHI_KD_PRODUCT",
    "ff_phase_per_sr",
    "ff_backscatter_fraction",
    "seawater_phase_per_sr",
    "seawater_scattering_per_m",
    "default_backscatter_180_per_m_sr",
    "default_diffuse_attenuation_per_m",
    "lidar_attenuation_per_m",
    "log_lidar_transmittance",
    "secchi_depth_m",
    "water_attenuation",
    "scattering_split",
    "PURE_WATER_ABSORPTION_PER_M",
    "PETZOLD_NONWATER_ALBEDOS",
    "albedo_from_nonwater",
    "attenuation_from_column",
]

#: Fournier-Forand fit to Petzold's average particle phase function (Mobley et al. 2002).
FF_PETZOLD_INDEX = 1.10
FF_PETZOLD_SLOPE = 3.5835
#: Depolarisation term of the molecular phase function of sea water (Morel 1974).
SEAWATER_P = 0.835
#: Sea-water scattering at 500 nm (1/m) and its spectral slope (Morel 1974).
SEAWATER_B500 = 2.88e-3
SEAWATER_SLOPE = 4.32
#: ``k = K_d + (c - K_d) exp(-0.85 c D)``, D the field-of-view diameter (see module).
GORDON_DIAMETER_COEFF = 0.85
#: Poole & Atkins (1926): ``K_d Z_SD = 1.7``.
SECCHI_KD_PRODUCT = 1.7
#: Absorption of pure water near 532 nm (1/m; Pope & Fry 1997, Appl. Opt. 36:8710): the
#: green lidars' wavelength, used as the floor of every water's absorption (model choice: the
#: same value at any wavelength a scene names).
PURE_WATER_ABSORPTION_PER_M = 0.045
#: ``b_nw / c_nw`` of what is not sea water in Petzold's (1972) three waters (clear ocean,
#: coastal ocean, turbid harbour; ``b, c`` = 0.037, 0.151 / 0.219, 0.398 / 1.824, 2.19 1/m at
#: 530 nm, Mobley 1994 *Light and Water* table 3.10) once sea water's
#: :data:`PURE_WATER_ABSORPTION_PER_M` and its scattering at 530 nm are taken out.
PETZOLD_NONWATER_ALBEDOS = (0.335, 0.618, 0.850)


def _ff_delta(psi, n):
    return 4.0 / (3.0 * (n - 1.0) ** 2) * np.sin(0.5 * np.asarray(psi, dtype=np.float64)) ** 2


def ff_phase_per_sr(psi_rad, n=FF_PETZOLD_INDEX, mu=FF_PETZOLD_SLOPE):
    """Fournier-Forand phase function ``p(psi)`` (1/sr, integrates to 1 over the sphere).

    Parameters
    ----------
    psi_rad : ndarray
        Scattering angle in (0, pi], radians (``p`` diverges, integrably, at 0).
    n, mu : float
        Real refractive index of the particles relative to water and Junge slope.

    Returns
    -------
    ndarray
        Same shape as ``psi_rad``.
    """
    psi = np.asarray(psi_rad, dtype=np.float64)
    nu = 0.5 * (3.0 - mu)
    d = _ff_delta(psi, n)
    d180 = float(_ff_delta(math.pi, n))
    dn = d**nu
    s2 = np.sin(0.5 * psi) ** 2
    main = (nu * (1.0 - d) - (1.0 - dn) + (d * (1.0 - dn) - nu * (1.0 - d)) / s2) / (
        4.0 * math.pi * (1.0 - d) ** 2 * dn
    )
    d180n = d180**nu
    back = (1.0 - d180n) / (16.0 * math.pi * (d180 - 1.0) * d180n) * (3.0 * np.cos(psi) ** 2 - 1.0)
    return main + back


def ff_backscatter_fraction(n=FF_PETZOLD_INDEX, mu=FF_PETZOLD_SLOPE) -> float:
    """Closed-form backscatter fraction ``B`` of the Fournier-Forand phase function."""
    nu = 0.5 * (3.0 - mu)
    d90 = float(_ff_delta(0.5 * math.pi, n))
    return 1.0 - (1.0 - d90 ** (nu + 1.0) - 0.5 * (1.0 - d90**nu)) / ((1.0 - d90) * d90**nu)


def seawater_phase_per_sr(psi_rad):
    """Molecular phase function of sea water, ``(1 + 0.835 cos^2) / (4 pi (1 + 0.835 / 3))``."""
    cos = np.cos(np.asarray(psi_rad, dtype=np.float64))
    return (1.0 + SEAWATER_P * cos**2) / (4.0 * math.pi * (1.0 + SEAWATER_P / 3.0))


def seawater_scattering_per_m(wavelength_nm: float) -> float:
    """Scattering coefficient of pure sea water, ``2.88e-3 (lambda / 500)^-4.32`` 1/m."""
    return SEAWATER_B500 * (wavelength_nm / 500.0) ** (-SEAWATER_SLOPE)


def default_backscatter_180_per_m_sr(
    extinction_per_m: float, albedo: float, wavelength_nm: float
) -> float:
    """``beta(180)`` of water of beam attenuation ``c`` and single-scattering albedo ``omega_0``.

    ``b = omega_0 c``; sea water scatters ``min(b_sw, b)`` with its molecular phase function, the
    rest is particles with the Petzold-fitted Fournier-Forand phase function (see module).
    """
    b = albedo * extinction_per_m
    b_w = min(seawater_scattering_per_m(wavelength_nm), b)
    p_w = float(seawater_phase_per_sr(math.pi))
    p_p = float(ff_phase_per_sr(math.pi))
    return b_w * p_w + (b - b_w) * p_p


def albedo_from_nonwater(
    extinction_per_m: float, nonwater_albedo: float, wavelength_nm: float
) -> float:
    """Single-scattering albedo ``omega_0`` of sea water plus matter of albedo ``omega_nw``.

    Sea water absorbs :data:`PURE_WATER_ABSORPTION_PER_M` and scatters
    :func:`seawater_scattering_per_m`; the rest of ``c`` (particles and dissolved matter)
    scatters the share ``omega_nw`` of what it takes out: ``omega_0 = (b_w + omega_nw (c - a_w -
    b_w)) / c``. So a clear water cannot scatter more than sea water does (``c = 0.05`` 1/m is
    nearly pure water: ``omega_0`` <= 0.1, where a fixed 0.55 would absorb half what pure water
    absorbs), and the absorption ``(1 - omega_0) c`` never falls below ``a_w``. Below sea water's
    own ``c`` (not a natural water) the scattering is ``min(b_w, c)``; 0 for ``c = 0``.
    """
    c = float(extinction_per_m)
    if c <= 0.0:
        return 0.0
    b_w = seawater_scattering_per_m(wavelength_nm)
    rest = max(c - PURE_WATER_ABSORPTION_PER_M - b_w, 0.0)
    return (min(b_w, c) + float(nonwater_albedo) * rest) / c


def default_diffuse_attenuation_per_m(extinction_per_m: float) -> float:
    """``K_d = min(0.2 c + 0.04, c)`` when the scene gives none (see module)."""
    return min(0.2 * extinction_per_m + 0.04, extinction_per_m)


def lidar_attenuation_per_m(c, kd, radius_m):
    """Decay rate ``k = K_d + (c - K_d) exp(-0.85 c 2 R)`` of the lidar return (1/m).

    Parameters
    ----------
    c, kd : float or ndarray
        Beam and diffuse attenuation (1/m), ``kd <= c``.
    radius_m : float or ndarray
        Radius of the receiver's field of view at the depth considered.
    """
    c = np.asarray(c, dtype=np.float64)
    return kd + (c - kd) * np.exp(-2.0 * GORDON_DIAMETER_COEFF * c * np.asarray(radius_m))


def log_lidar_transmittance(c, kd, path_m, radius0_m, radius_rate):
    """One-way ``-∫_0^L k(R(l)) dl`` with ``R(l) = R0 + g l`` (natural log, <= 0).

    Parameters
    ----------
    c, kd : float
        Beam and diffuse attenuation (1/m), ``0 <= kd <= c``.
    path_m : ndarray
        In-water path ``L`` (>= 0).
    radius0_m : ndarray
        Field-of-view radius where the path enters the water.
    radius_rate : ndarray
        Growth ``g >= 0`` of the radius per metre of in-water path.

    Returns
    -------
    ndarray
        ``-(K_d L + (c - K_d) exp(-a R0) (1 - exp(-a g L)) / (a g))`` with ``a = 1.7 c``; the
        bracket tends to ``L exp(-a R0)`` as ``a g L -> 0`` (evaluated with ``expm1``).
    """
    path = np.asarray(path_m, dtype=np.float64)
    a = 2.0 * GORDON_DIAMETER_COEFF * c
    x = a * np.asarray(radius_rate, dtype=np.float64) * path
    small = x < 1e-12
    frac = np.where(small, 1.0, -np.expm1(-x) / np.where(small, 1.0, x))  # (1 - e^-x) / x
    excess = (c - kd) * np.exp(-a * np.asarray(radius0_m)) * path * frac
    return -(kd * path + excess)


def secchi_depth_m(kd_per_m: float) -> float:
    """Secchi depth ``1.7 / K_d`` (Poole & Atkins 1926)."""
    return SECCHI_KD_PRODUCT / kd_per_m


def water_attenuation(scene, model: str, r_air, length):
    """One-way log transmittance to the seabed and column decay rate, per sub-ray.

    Parameters
    ----------
    scene : Scene
        ``water``, ``atmosphere.refractive_index`` and ``scanner.receiver_fov_mrad``.
    model : str
        ``"fov"`` (between c and K_d, see module) or ``"beam"`` (``k = c``).
    r_air, length : ndarray
        Air range to the surface hit and in-water path of each sub-ray (m).

    Returns
    -------
    log_t_bottom : ndarray
        ``-∫_0^L k(R(l)) dl`` (``-c L`` for ``lidar_attenuation = "beam"``).
    k_column : ndarray
        ``k`` at the field-of-view radius where the sub-ray enters the water (1/m).
    radius0_m, radius_rate : ndarray
        Field-of-view radius at the water entry and its growth per metre of in-water path.
    """
    water = scene.water
    c = water.extinction_per_m
    tan_half = math.tan(0.5e-3 * scene.scanner.receiver_fov_mrad)
    radius0 = tan_half * np.asarray(r_air, dtype=np.float64)
    rate = np.full(radius0.shape, tan_half * scene.atmosphere.refractive_index / water.phase_index)
    if model == "beam":
        return -c * np.asarray(length), np.full(radius0.shape, c), radius0, rate
    kd = water.kd_per_m
    log_t = log_lidar_transmittance(c, kd, length, radius0, rate)
    return log_t, lidar_attenuation_per_m(c, kd, radius0), radius0, rate


def scattering_split(scene) -> tuple[float, float]:
    """Scattering coefficients of particles and of sea water, ``b_p + b_w = omega_0 c``."""
    b = scene.water.scattering_per_m
    b_w = min(seawater_scattering_per_m(scene.system.wavelength_nm), b)
    return b - b_w, b_w


def attenuation_from_column(
    column_decay_per_m: float, fov_half_tan: float, r_air_m: float
) -> float:
    """Beam attenuation ``c`` whose lidar decay at the water entry is the measured one.

    Inverts ``k = K_d + (c - K_d) exp(-0.85 c 2 R)`` with ``K_d = min(0.2 c + 0.04, c)``
    (Gordon 1982; see the module), ``R = tan(FOV/2) r_air``, on a log grid of ``c``
    (``k`` rises with ``c``). Raises ValueError for a decay that is not positive and finite.
    """
    if not (math.isfinite(column_decay_per_m) and column_decay_per_m > 0.0):
        raise ValueError(f"`column_decay_per_m` must be > 0; got {column_decay_per_m!r}")
    c = np.geomspace(1e-3, 100.0, 4001)
    kd = np.minimum(0.2 * c + 0.04, c)
    k = lidar_attenuation_per_m(c, kd, fov_half_tan * r_air_m)
    return float(np.interp(column_decay_per_m, np.maximum.accumulate(k), c))
