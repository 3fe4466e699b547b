"""Wind-sea spectra and the empirical relations they are checked against.

Frequency spectra ``S(omega)`` (m**2 s, one-sided, ``m0 = integral S d omega``), directional
spreading ``D(theta)`` (1/rad, ``integral D d theta = 1`` over a full turn), the neutral log wind
profile to move wind speeds between heights, the Cox-Munk (1954) clean-surface mean-square slope
and deep-water conversion to wavenumber spectra.

Wind heights: Pierson-Moskowitz is defined with the wind at 19.5 m, JONSWAP with the wind at 10 m,
Cox-Munk with the wind at 12.5 m (41 ft anemometer). :func:`wind_speed_at_height` converts with a
neutral logarithmic profile ``U(z) = u* / kappa ln(z / z0)`` and the Charnock roughness
``z0 = 0.011 u*^2 / g`` (Smith 1988); e.g. U19.5 / U10 = 1.05 and U12.5 / U10 = 1.02 at 10 m/s.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from scipy import special

from pipeline.lidar_equation import cox_munk_mean_square_slope
from terrain._validate import check_number

__all__ = [
    "GRAVITY_M_S2",
    "wind_speed_at_height",
    "cox_munk_mss",
    "pierson_moskowitz",
    "pierson_moskowitz_peak_rad_s",
    "pierson_moskowitz_hs_m",
    "jonswap",
    "jonswap_peak_rad_s",
    "cos2s_spreading",
    "cos2_spreading",
    "wavenumber_spectrum",
]

GRAVITY_M_S2 = 9.80665
KAPPA = 0.40  # von Karman constant
CHARNOCK = 0.011  # Charnock constant (Smith 1988, open ocean)
PM_ALPHA = 8.1e-3  # Phillips constant of Pierson & Moskowitz (1964)
PM_BETA = 0.74


def wind_speed_at_height(
    u_m_s: float, from_height_m: float, to_height_m: float, *, charnock: float = CHARNOCK
) -> float:
    """Convert a neutral wind speed between heights above the sea with the log profile.

    Parameters
    ----------
    u_m_s : float
        Wind speed at ``from_height_m`` in m/s (>= 0).
    from_height_m, to_height_m : float
        Heights above mean sea level in metres (> 0).
    charnock : float
        Charnock constant of the roughness length ``z0 = charnock u*^2 / g``.

    Returns
    -------
    float
        Wind speed at ``to_height_m`` in m/s.
    """
    u = check_number("u_m_s", u_m_s, ge=0.0)
    z1 = check_number("from_height_m", from_height_m, gt=0.0)
    z2 = check_number("to_height_m", to_height_m, gt=0.0)
    if u == 0.0:
        return 0.0
    ustar = 0.035 * u
    for _ in range(100):  # fixed point, contracts by ~1/ln(z/z0) per step
        z0 = charnock * ustar**2 / GRAVITY_M_S2
        new = KAPPA * u / math.log(z1 / z0)
        if abs(new - ustar) <= 1e-14 * new:
            break
        ustar = new
    z0 = charnock * ustar**2 / GRAVITY_M_S2
    return ustar / KAPPA * math.log(z2 / z0)


def cox_munk_mss(u12_5_m_s: Any) -> np.ndarray:
    """Cox & Munk (1954) clean-sea mean-square slope ``0.003 + 5.12e-3 U12.5`` (U in m/s)."""
    u = np.asarray(u12_5_m_s, dtype=np.float64)
    return cox_munk_mean_square_slope(u)


def pierson_moskowitz_peak_rad_s(u19_5_m_s: float) -> float:
    """Peak angular frequency ``(0.8 beta)**0.25 g / U19.5`` (= 0.877 g / U19.5), rad/s."""
    return (0.8 * PM_BETA) ** 0.25 * GRAVITY_M_S2 / u19_5_m_s


def pierson_moskowitz(omega_rad_s: Any, u19_5_m_s: float) -> np.ndarray:
    """Pierson-Moskowitz (1964) fully developed sea ``S(omega)`` in m**2 s.

    ``S = alpha g**2 omega**-5 exp(-beta (g / (U19.5 omega))**4)``, alpha = 8.1e-3, beta = 0.74;
    zero at ``omega <= 0``.
    """
    w = np.asarray(omega_rad_s, dtype=np.float64)
    g = GRAVITY_M_S2
    safe = np.where(w > 0, w, 1.0)
    s = PM_ALPHA * g**2 * safe**-5 * np.exp(-PM_BETA * (g / (u19_5_m_s * safe)) ** 4)
    return np.where(w > 0, s, 0.0)


def pierson_moskowitz_hs_m(u19_5_m_s: float) -> float:
    """Significant wave height ``4 sqrt(m0)`` of the PM spectrum, ``0.209 U19.5**2 / g``, m."""
    m0 = PM_ALPHA * u19_5_m_s**4 / (4.0 * PM_BETA * GRAVITY_M_S2**2)
    return 4.0 * math.sqrt(m0)


def jonswap_peak_rad_s(u10_m_s: float, fetch_m: float) -> float:
    """JONSWAP (Hasselmann et al. 1973) peak ``22 (g**2 / (U10 F))**(1/3)``, rad/s."""
    return 22.0 * (GRAVITY_M_S2**2 / (u10_m_s * fetch_m)) ** (1.0 / 3.0)


def jonswap(omega_rad_s: Any, u10_m_s: float, fetch_m: float, gamma: float = 3.3) -> np.ndarray:
    """Fetch-limited JONSWAP ``S(omega)`` in m**2 s (Hasselmann et al. 1973).

    ``S = alpha g**2 omega**-5 exp(-5/4 (omega_p/omega)**4) gamma**r``,
    ``r = exp(-(omega - omega_p)**2 / (2 sigma**2 omega_p**2))``, sigma 0.07 / 0.09 below / above
    the peak, ``alpha = 0.076 (g F / U10**2)**-0.22``, peak from :func:`jonswap_peak_rad_s`.
    Valid for fetch-limited seas (``g F / U10**2`` below ~2e4; beyond, use Pierson-Moskowitz).
    """
    w = np.asarray(omega_rad_s, dtype=np.float64)
    g = GRAVITY_M_S2
    alpha = 0.076 * (g * fetch_m / u10_m_s**2) ** -0.22
    wp = jonswap_peak_rad_s(u10_m_s, fetch_m)
    safe = np.where(w > 0, w, 1.0)
    sigma = np.where(safe <= wp, 0.07, 0.09)
    r = np.exp(-((safe - wp) ** 2) / (2.0 * sigma**2 * wp**2))
    s = alpha * g**2 * safe**-5 * np.exp(-1.25 * (wp / safe) ** 4) * gamma**r
    return np.where(w > 0, s, 0.0)


def cos2s_spreading(theta_rad: Any, s: float) -> np.ndarray:
    """Longuet-Higgins et al. (1963) ``D = N(s) cos(theta/2)**(2s)``, theta from the mean direction.

    ``N(s) = Gamma(s+1) / (2 sqrt(pi) Gamma(s+1/2))``; defined over the full circle.
    """
    th = np.asarray(theta_rad, dtype=np.float64)
    norm = math.exp(special.gammaln(s + 1.0) - special.gammaln(s + 0.5)) / (
        2.0 * math.sqrt(math.pi)
    )
    return norm * np.abs(np.cos(0.5 * th)) ** (2.0 * s)


def cos2_spreading(theta_rad: Any) -> np.ndarray:
    """``D = (2/pi) cos(theta)**2`` for ``|theta| < pi/2`` (downwind half-plane), else 0."""
    th = np.asarray(theta_rad, dtype=np.float64)
    c = np.cos(th)
    return np.where(c > 0, (2.0 / math.pi) * c * c, 0.0)


def wavenumber_spectrum(spectrum_omega, k_rad_m: Any) -> np.ndarray:
    """Omnidirectional ``F(k)`` (m**3) from ``S(omega)`` by deep-water dispersion ``w**2 = g k``.

    ``F(k) = S(sqrt(g k)) d omega / d k`` with ``d omega / d k = g / (2 omega)``; zero at k <= 0.
    """
    k = np.asarray(k_rad_m, dtype=np.float64)
    safe = np.where(k > 0, k, 1.0)
    w = np.sqrt(GRAVITY_M_S2 * safe)
    return np.where(k > 0, spectrum_omega(w) * GRAVITY_M_S2 / (2.0 * w), 0.0)
