"""Reference optics of the air/water lidar path: Snell, Fresnel, Brewster, Beer-Lambert.

Vectorised (broadcasting), float64, SI units, radians; scalars in, numpy scalars out; invalid
inputs raise :class:`ValueError` naming the parameter.

Conventions
-----------
* Time dependence ``exp(-i w t)``, so an absorbing medium has ``N = n + i kappa`` with
  ``kappa >= 0`` and a transmitted wave ``exp(i k0 q z)`` decays when ``Im q >= 0``.
* Fresnel amplitudes follow the reference document (eqs 5, 6, 9, 10) with its errata:
  ``t_s = 1 + r_s`` and ``t_p = (n1/n2)(1 + r_p)``. The p sign convention makes
  ``r_p(0) = (n2 - n1)/(n1 + n2) = -r_s(0)``, and ``r_s = r_p = -1`` at grazing incidence.
* Medium 1 holds the incident wave, ``z`` points into medium 2.

Examples
--------
>>> R, T = fresnel_unpolarised(1.0, 1.33, 0.0)
>>> round(float(R), 5), round(float(R + T), 12)
(0.02006, 1.0)
>>> round(float(np.degrees(brewster_angle(1.0, 1.33))), 2)
53.06
"""

from __future__ import annotations

import numpy as np
from scipy import constants

__all__ = [
    "SPEED_OF_LIGHT_M_S", "GRAYBODY_AMPLITUDE_PERCENT", "refraction_angle", "refract_direction",
    "reflect_direction", "fresnel_amplitude", "fresnel_power", "fresnel_unpolarised",
    "fresnel_jones", "jones_linear", "jones_circular", "brewster_angle",
    "brewster_angle_general", "critical_angle", "absorption_coefficient_from_index",
    "index_imag_from_absorption", "beer_lambert_transmittance", "log_transmittance",
    "total_extinction", "penetration_depth_m", "extinction_from_penetration_depth",
    "graybody_power_reflectance", "water_phase_index", "water_group_index", "photons_per_pulse",
]  # fmt: skip

SPEED_OF_LIGHT_M_S: float = constants.c

#: Table 1 of the reference: graybody *amplitude* reflectivity in percent, (low, high).
GRAYBODY_AMPLITUDE_PERCENT: dict[str, tuple[float, float]] = {
    "fresh_dry_snow": (70.0, 90.0),
    "desert_sand": (25.0, 40.0),
    "dry_vegetation": (20.0, 30.0),
    "grass": (15.0, 25.0),
    "bare_soil": (10.0, 25.0),
}

# Quan & Fry (1995), Appl. Opt. 34:3477: n(S, T, lambda) with S in psu, T in degC, lambda in nm.
_QF = (1.31405, 1.779e-4, -1.05e-6, 1.6e-8, -2.02e-6, 15.868, 0.01155, -0.00423, -4382.0, 1.1455e6)


# --- validation -------------------------------------------------------------------------------
def _check(name, a, ok, rule):
    """Raise ValueError naming ``name`` and the first value where ``ok`` is False."""
    ok = np.broadcast_to(ok, np.shape(a))
    if not np.all(ok):
        bad = np.asarray(a)[~ok].flat[0].item()
        bad = bad.real if isinstance(bad, complex) and bad.imag == 0 else bad
        raise ValueError(f"`{name}` must be {rule}; got {bad!r}")


def _real(name, value, rule, test):
    a = np.asarray(value, dtype=np.float64)
    _check(name, a, test(a) & np.isfinite(a), rule)  # NaN/inf fail every rule
    return a


def _positive(name, value):
    return _real(name, value, "finite and > 0", lambda a: a > 0)


def _nonneg(name, value):
    return _real(name, value, "finite and >= 0", lambda a: a >= 0)


def _within(name, value, lo, hi, unit=""):
    return _real(name, value, f"in [{lo}, {hi}]{unit}", lambda a: (a >= lo) & (a <= hi))


def _angle(name, value):
    return _real(name, value, "in [0, pi/2] rad", lambda a: (a >= 0) & (a <= np.pi / 2))


def _index(name, value):
    """Complex refractive index n + i kappa with n > 0 and kappa >= 0 (no gain media)."""
    a = np.asarray(value, dtype=np.complex128)
    ok = np.isfinite(a) & (a.real > 0) & (a.imag >= 0)
    _check(name, a, ok, "finite with real part > 0 and imaginary part >= 0")
    return a


def _unit(name, value):
    a = np.asarray(value, dtype=np.float64)
    if a.ndim == 0 or a.shape[-1] != 3:
        raise ValueError(f"`{name}` must have shape (..., 3); got {a.shape}")
    norm = np.linalg.norm(a, axis=-1)
    _check(name + " norm", norm, np.isfinite(norm) & (norm > 0), "finite and > 0")
    return a / norm[..., None]


# --- Snell --------------------------------------------------------------------------------------
def refraction_angle(n1, n2, theta_i_rad):
    """Refraction angle by Snell's law (eq 8), with a total-internal-reflection mask.

    Parameters
    ----------
    n1, n2 : array_like
        Real refractive indices (> 0) of the incidence and exit media; broadcast together.
    theta_i_rad : array_like
        Incidence angle from the normal, in [0, pi/2] rad.

    Returns
    -------
    theta_t_rad : ndarray
        Refraction angle (rad), broadcast shape; pi/2 where ``tir``.
    tir : ndarray of bool
        True where ``n1 sin(theta_i) > n2`` (total internal reflection).
    """
    n1, n2, th = _positive("n1", n1), _positive("n2", n2), _angle("theta_i_rad", theta_i_rad)
    s = n1 * np.sin(th) / n2
    tir = s > 1.0
    return np.arcsin(np.minimum(s, 1.0))[()], tir[()]  # arcsin(1) = pi/2 under TIR, never NaN


def reflect_direction(d, normal):
    """Specular reflection ``d - 2 (d . N) N`` of direction(s) ``d`` (..., 3); unit output."""
    d, nrm = _unit("d", d), _unit("normal", normal)
    r = d - 2.0 * np.sum(d * nrm, axis=-1, keepdims=True) * nrm
    return r / np.linalg.norm(r, axis=-1, keepdims=True)


def refract_direction(d, normal, n1, n2):
    """Refracted direction by the vector form of Snell's law.

    Parameters
    ----------
    d : array_like, shape (..., 3)
        Incident propagation direction (normalised internally).
    normal : array_like, shape (..., 3)
        Surface normal, either orientation (flipped internally to oppose ``d``).
    n1, n2 : array_like, shape (...)
        Real refractive indices of the incidence and exit media.

    Returns
    -------
    t : ndarray, shape (..., 3)
        Unit refracted direction; where ``tir`` the unit specular reflected direction instead.
    tir : ndarray of bool, shape (...)
        Total internal reflection mask.

    Notes
    -----
    With ``eta = n1/n2``, ``cos_i = -d.N`` and ``sin^2 t = eta^2 |d x N|^2``:
    ``t = eta d + (eta cos_i - cos_t) N``, which satisfies ``n1 (d x N) = n2 (t x N)``.
    """
    d, nrm = _unit("d", d), _unit("normal", normal)
    n1, n2 = _positive("n1", n1), _positive("n2", n2)
    dn = np.sum(d * nrm, axis=-1)
    nrm = np.where((dn > 0)[..., None], -nrm, nrm)
    cos_i = np.abs(dn)
    eta = n1 / n2
    # sin^2 from the cross product: accurate near normal incidence, where 1 - cos^2 cancels
    sin2_t = eta**2 * np.sum(np.cross(d, nrm) ** 2, axis=-1)
    tir = sin2_t > 1.0
    cos_t = np.sqrt(np.maximum(1.0 - sin2_t, 0.0))
    t = eta[..., None] * d + (eta * cos_i - cos_t)[..., None] * nrm
    t = np.where(tir[..., None], d + 2.0 * cos_i[..., None] * nrm, t)
    return t / np.linalg.norm(t, axis=-1, keepdims=True), tir[()]


# --- Fresnel ------------------------------------------------------------------------------------
def _normal_wavenumbers(n1, n2, theta):
    """Return q1 = n1 cos(theta_i), q2 = n2 cos(theta_t) (decaying branch), eps1, eps2."""
    cos_i = np.sin(np.pi / 2 - theta)  # exactly 0 at theta = pi/2, where np.cos gives 6e-17
    eps1, eps2 = n1 * n1, n2 * n2
    q2 = np.sqrt(eps2 - eps1 * np.sin(theta) ** 2)
    q2 = np.where(q2.imag < 0, -q2, q2)  # Im q2 >= 0: evanescent/absorbed wave decays in +z
    return n1 * cos_i, q2, eps1, eps2


def _ratio(num, den):
    """num/den, with the identical-media limit (den = 0 only if n1 = n2 at grazing) -> 0."""
    zero = den == 0
    return np.where(zero, 0.0, num / np.where(zero, 1.0, den)), zero


def fresnel_amplitude(n1, n2, theta_i_rad):
    """Fresnel amplitude coefficients for real or complex (absorbing) indices.

    Parameters
    ----------
    n1, n2 : array_like, complex
        Refractive indices ``n + i kappa`` (``n > 0``, ``kappa >= 0``); broadcast together.
    theta_i_rad : array_like
        Incidence angle in [0, pi/2] rad (for complex ``n1``, the analytic continuation).

    Returns
    -------
    r_s, r_p, t_s, t_p : ndarray, complex128
        Amplitude reflection and transmission coefficients (electric field), broadcast shape.

    Notes
    -----
    With ``q1 = n1 cos(theta_i)`` and ``q2 = n2 cos(theta_t) = sqrt(n2^2 - n1^2 sin^2 theta_i)``
    on the branch ``Im q2 >= 0`` (eqs 5, 6, 9, 10 multiplied through to avoid dividing by n2):
    ``r_s = (q1 - q2)/(q1 + q2)``, ``t_s = 1 + r_s``,
    ``r_p = (n2^2 q1 - n1^2 q2)/(n2^2 q1 + n1^2 q2)``, ``t_p = (n1/n2)(1 + r_p)``.
    Beyond the critical angle ``q2`` is imaginary and ``|r| = 1``.
    """
    n1, n2, th = _index("n1", n1), _index("n2", n2), _angle("theta_i_rad", theta_i_rad)
    q1, q2, e1, e2 = _normal_wavenumbers(n1, n2, th)
    r_s, _ = _ratio(q1 - q2, q1 + q2)
    r_p, _ = _ratio(e2 * q1 - e1 * q2, e2 * q1 + e1 * q2)
    return r_s[()], r_p[()], (1.0 + r_s)[()], (n1 / n2 * (1.0 + r_p))[()]


def fresnel_power(n1, n2, theta_i_rad):
    """Fresnel reflectance and transmittance (eqs 12-15 generalised to complex ``n2``).

    Parameters
    ----------
    n1 : array_like
        Real index of the (lossless) incidence medium; complex dtype with zero imaginary part
        is accepted.
    n2 : array_like, complex
        Index of the exit medium, ``n + i kappa`` with ``kappa >= 0``.
    theta_i_rad : array_like
        Incidence angle in [0, pi/2] rad.

    Returns
    -------
    R_s, R_p, T_s, T_p : ndarray, float64
        Power coefficients, broadcast shape. ``T = 0`` under total internal reflection.

    Notes
    -----
    ``R = |r|^2``. ``T`` is the normal Poynting flux just inside medium 2 over the incident
    flux: ``T_s = Re(q2)/q1 |t_s|^2 = 4 q1 Re(q2)/|q1 + q2|^2`` and
    ``T_p = Re(q2/eps2)/(q1/eps1) |1 + r_p|^2 = 4 eps1 q1 Re(q2 conj(eps2))/|eps2 q1 + eps1 q2|^2``
    (written without the 0/0 of eq 14 at grazing incidence). This equals ``1 - R`` for any
    lossless ``n1``; for absorbing ``n2`` it is the power absorbed after crossing.
    """
    n1 = _index("n1", n1)
    _check("n1", n1, n1.imag == 0, "real (lossless incidence medium) for power coefficients")
    n2, th = _index("n2", n2), _angle("theta_i_rad", theta_i_rad)
    q1, q2, e1, e2 = _normal_wavenumbers(n1, n2, th)
    q1, e1 = q1.real, e1.real
    den_s, den_p = q1 + q2, e2 * q1 + e1 * q2
    r_s, same_s = _ratio(q1 - q2, den_s)
    r_p, same_p = _ratio(e2 * q1 - e1 * q2, den_p)
    t_s, _ = _ratio(4.0 * q1 * q2.real, np.abs(den_s) ** 2)
    t_p, _ = _ratio(4.0 * e1 * q1 * (q2 * np.conj(e2)).real, np.abs(den_p) ** 2)
    t_s, t_p = np.where(same_s, 1.0, t_s), np.where(same_p, 1.0, t_p)
    # "+ 0.0" turns the -0.0 that Re(q2 conj(eps2)) can give under TIR into +0.0
    return (np.abs(r_s) ** 2)[()], (np.abs(r_p) ** 2)[()], t_s[()] + 0.0, t_p[()] + 0.0


def fresnel_unpolarised(n1, n2, theta_i_rad):
    """Unpolarised ``(R, T)``: mean of the s and p coefficients of :func:`fresnel_power`."""
    r_s, r_p, t_s, t_p = fresnel_power(n1, n2, theta_i_rad)
    return 0.5 * (r_s + r_p), 0.5 * (t_s + t_p)


def jones_linear(angle_rad):
    """Jones vector ``(E_s, E_p) = (cos a, sin a)`` of linear polarisation at angle ``a`` (rad).

    ``a`` is measured from the s axis towards the p axis; returns complex shape (..., 2).
    """
    a = _real("angle_rad", angle_rad, "finite", np.isfinite)
    return np.stack([np.cos(a), np.sin(a)], axis=-1).astype(np.complex128)


def jones_circular(handedness="right"):
    """Jones vector ``(1, -i)/sqrt 2`` ("right") or ``(1, +i)/sqrt 2`` ("left").

    The p component lags (right) or leads (left) s by 90 degrees under ``exp(-i w t)``.
    Handedness does not change R or T at an isotropic interface.
    """
    signs = {"right": -1.0, "left": 1.0}
    if handedness not in signs:
        raise ValueError(f"`handedness` must be 'right' or 'left'; got {handedness!r}")
    return np.array([1.0, signs[handedness] * 1j]) / np.sqrt(2.0)


def fresnel_jones(n1, n2, theta_i_rad, jones):
    """``(R, T)`` for any polarisation given as a Jones vector ``(E_s, E_p)``, shape (..., 2).

    The vector is normalised internally. s and p stay orthogonal at a planar isotropic
    interface, so the powers add: ``R = w_s R_s + w_p R_p`` with ``w = |E|^2 / sum |E|^2``.
    """
    j = np.asarray(jones, dtype=np.complex128)
    if j.ndim == 0 or j.shape[-1] != 2:
        raise ValueError(f"`jones` must have shape (..., 2); got {j.shape}")
    w = np.abs(j) ** 2
    total = _real("jones power", w.sum(axis=-1), "finite and > 0", lambda x: x > 0)
    w_s, w_p = w[..., 0] / total, w[..., 1] / total
    r_s, r_p, t_s, t_p = fresnel_power(n1, n2, theta_i_rad)
    return (w_s * r_s + w_p * r_p)[()], (w_s * t_s + w_p * t_p)[()]


# --- special angles -----------------------------------------------------------------------------
def brewster_angle(n1, n2):
    """Brewster angle ``arctan(n2/n1)`` (eq 20) for real, non-magnetic media, in rad."""
    return np.arctan2(_positive("n2", n2), _positive("n1", n1))[()]


def brewster_angle_general(eps1, mu1, eps2, mu2, polarisation="p"):
    """Brewster angle of magnetic media from eqs 18 (s) and 19 (p).

    Parameters
    ----------
    eps1, mu1, eps2, mu2 : array_like
        Real relative permittivities and permeabilities (> 0), broadcast together.
    polarisation : {"p", "s"}
        Which coefficient vanishes.

    Returns
    -------
    angle_rad : ndarray
        Brewster angle (rad); 0 where ``exists`` is False.
    exists : ndarray of bool
        True where a real angle in [0, pi/2) with zero reflection exists.

    Notes
    -----
    s: ``sin^2 = (1 - mu1 eps2/(mu2 eps1)) / (1 - (mu1/mu2)^2)``; p: swap eps and mu.
    For ``mu1 = mu2`` the s denominator is 0: there is no Brewster angle for s (no warning).
    """
    e1, m1 = _positive("eps1", eps1), _positive("mu1", mu1)
    e2, m2 = _positive("eps2", eps2), _positive("mu2", mu2)
    if polarisation == "p":
        e1, m1, e2, m2 = m1, e1, m2, e2  # eq 19 is eq 18 with eps and mu exchanged
    elif polarisation != "s":
        raise ValueError(f"`polarisation` must be 'p' or 's'; got {polarisation!r}")
    num = 1.0 - (m1 * e2) / (m2 * e1)
    den = 1.0 - (m1 / m2) ** 2
    sin2 = num / np.where(den == 0, 1.0, den)
    # sin^2 = 1 would need n1 = n2 at grazing, where r is not 0: exclude it
    exists = (den != 0) & (sin2 >= 0) & (sin2 < 1)
    angle = np.arcsin(np.sqrt(np.where(exists, sin2, 0.0)))
    return angle[()], exists[()]


def critical_angle(n1, n2):
    """Onset of total internal reflection, ``arcsin(n2/n1)``, as ``(angle_rad, exists)``.

    ``exists`` is True only where ``n1 > n2``; elsewhere the angle is pi/2, so that
    ``theta_i > angle`` is never True for a valid incidence angle.
    """
    n1, n2 = _positive("n1", n1), _positive("n2", n2)
    exists = n1 > n2
    return np.arcsin(np.where(exists, n2 / n1, 1.0))[()], exists[()]


# --- absorption and extinction ------------------------------------------------------------------
def absorption_coefficient_from_index(n_imag, wavelength_m):
    """Absorption coefficient ``beta_a = 4 pi n_i / lambda`` (eq 22), in 1/m."""
    return (4.0 * np.pi * _nonneg("n_imag", n_imag) / _positive("wavelength_m", wavelength_m))[()]


def index_imag_from_absorption(beta_per_m, wavelength_m):
    """Imaginary index ``n_i = beta lambda / (4 pi)``, the inverse of eq 22."""
    b = _nonneg("beta_per_m", beta_per_m)
    return (b * _positive("wavelength_m", wavelength_m) / (4.0 * np.pi))[()]


def log_transmittance(extinction_per_m, path_m):
    """Natural log of Beer's-law transmittance, ``-beta x``; finite for any finite input."""
    return (-_nonneg("extinction_per_m", extinction_per_m) * _nonneg("path_m", path_m))[()]


def beer_lambert_transmittance(extinction_per_m, path_m):
    """Beer's law ``t(x) = exp(-beta x)`` (eq 23); underflows silently to 0 for huge ``beta x``."""
    with np.errstate(under="ignore"):  # exp(-1e7) = 0 is the right answer, not an error
        return np.exp(log_transmittance(extinction_per_m, path_m))[()]


def total_extinction(absorption_per_m, scattering_per_m):
    """Total extinction ``beta = beta_absorption + beta_scattering`` (eq 24), in 1/m."""
    a = _nonneg("absorption_per_m", absorption_per_m)
    return (a + _nonneg("scattering_per_m", scattering_per_m))[()]


def penetration_depth_m(extinction_per_m):
    """Penetration depth ``D = 1/beta`` (eq 25), in m; inf for ``beta = 0`` (no warning)."""
    b = _nonneg("extinction_per_m", extinction_per_m)
    return np.divide(1.0, b, out=np.full(b.shape, np.inf), where=b > 0)[()]


def extinction_from_penetration_depth(depth_m):
    """Extinction ``beta = 1/D`` in 1/m from a penetration depth ``D`` > 0 (inf gives 0)."""
    d = np.asarray(depth_m, dtype=np.float64)
    _check("depth_m", d, d > 0, "> 0 (inf allowed)")  # NaN fails the comparison
    return (1.0 / d)[()]


def graybody_power_reflectance(amplitude_percent):
    """Power reflectance ``(p/100)^2`` from a Table 1 amplitude reflectivity ``p`` in percent."""
    p = _within("amplitude_percent", amplitude_percent, 0, 100)
    return ((p / 100.0) ** 2)[()]


def _quan_fry(wavelength_m, salinity_psu, temperature_c):
    lam = _within("wavelength_m", wavelength_m, 400e-9, 700e-9, " m (fit range)") * 1e9
    s = _within("salinity_psu", salinity_psu, 0, 40)
    t = _within("temperature_c", temperature_c, -2, 35)
    c0, c1, c2, c3, c4, c5, c6, c7, c8, c9 = _QF
    a1 = c5 + c6 * s + c7 * t  # coefficient of 1/lambda
    n = c0 + (c1 + c2 * t + c3 * t**2) * s + c4 * t**2 + a1 / lam + c8 / lam**2 + c9 / lam**3
    minus_lam_dn = a1 / lam + 2.0 * c8 / lam**2 + 3.0 * c9 / lam**3  # -lambda dn/dlambda
    return n, minus_lam_dn


def water_phase_index(wavelength_m=532e-9, salinity_psu=35.0, temperature_c=20.0):
    """Phase refractive index of (sea) water by Quan & Fry (1995), broadcast shape.

    Parameters
    ----------
    wavelength_m : array_like
        Vacuum wavelength in m, within 400-700 nm (the fit range).
    salinity_psu : array_like
        Salinity in psu, 0-40 (fitted 0-35; the S terms are linear).
    temperature_c : array_like
        Temperature in degC, -2 to 35 (fitted 0-30; the T terms are quadratic).

    Notes
    -----
    ``n = n0 + (n1 + n2 T + n3 T^2) S + n4 T^2 + (n5 + n6 S + n7 T)/lam + n8/lam^2 + n9/lam^3``
    with ``lam`` in nm (Quan & Fry 1995, Appl. Opt. 34:3477). 532 nm, 35 psu, 20 degC: 1.3415.
    """
    return _quan_fry(wavelength_m, salinity_psu, temperature_c)[0][()]


def water_group_index(wavelength_m=532e-9, salinity_psu=35.0, temperature_c=20.0):
    """Group index ``n_g = n - lambda dn/dlambda`` of the Quan & Fry formula (analytic derivative).

    Same parameters as :func:`water_phase_index`. The group index sets a pulse's travel time:
    532 nm, 35 psu, 20 degC gives 1.3638 (phase index 1.3415).
    """
    n, minus_lam_dn = _quan_fry(wavelength_m, salinity_psu, temperature_c)
    return (n + minus_lam_dn)[()]


def photons_per_pulse(pulse_energy_j, wavelength_m):
    """Photons in a pulse, ``E lambda / (h c)``, for energy in J and vacuum wavelength in m."""
    e = _nonneg("pulse_energy_j", pulse_energy_j)
    lam = _positive("wavelength_m", wavelength_m)
    return (e * lam / (constants.h * constants.c))[()]
