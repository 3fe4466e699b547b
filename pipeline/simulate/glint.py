"""Surface glint of the wave facets a sub-ray meets, per sr per incident watt, in log space.

Quasi-specular reflection from wave facets (Kirchhoff geometric optics): a facet sends light
back to the receiver only when its normal points along the beam, at local normal incidence, with
Fresnel ``R_F(0)``. Two scales (Valenzuela 1978, Boundary-Layer Meteorol.
13:61): the traced surface has the slope ``g`` at the hit (the mesh or wave-field normal); the
facets it does not resolve add an isotropic Gaussian (Cox-Munk) slope ``u``,
``p(u) = exp(-|u|^2 / s^2) / (pi s^2)``, and slopes add: the sub-ray of off-nadir angle
``theta`` is sent back by facets of total slope ``m = d_xy / |d_z|``, i.e. ``u = m - g``. The
cross section per horizontal area is ``pi R_F(0) sec^4(theta) p(m - g)`` (Barrick 1968, IEEE
Trans. Antennas Propag. 16:449); the sub-ray lights ``n_z / cos(t)`` horizontal area per unit
beam area (``t`` its incidence on the traced facet), so the intensity per sr per incident watt is
``(1 - W) R_F(0) sec^4(theta) n_z p(m - g) / (4 cos t)``. Over a flat surface (``g = 0``,
``t = theta``) this is the Cox-Munk ``sec^5(theta) p(tan theta) / 4``, and its mean over the
traced slopes, which the sub-rays sample in proportion to ``cos t / (n_z cos theta)``, is the
Cox-Munk glint at the total variance ``s^2 + s^2_resolved`` (the Gaussian densities convolve).
Whitecaps add ``W rho_foam cos(t) / pi`` (Lambertian). At nadir this is
:func:`pipeline.lidar_equation.surface_backscatter_per_sr`. Slope variance (model choice):
``s^2 = max(s^2_CoxMunk(U) - s^2_resolved, 0.003)``: the traced facets already carry
``s^2_resolved`` (0 for flat water: the full Cox-Munk value); the floor 0.003 is Cox & Munk's
clean-sea value at zero wind, ripples no mesh resolves, which also keeps the specular lobe
wider than the beam so sub-ray sampling converges.
"""

from __future__ import annotations

import math

import numpy as np

from pipeline import lidar_equation as le
from pipeline.simulate.geometry import LOG_ZERO, safe_log

__all__ = ["MIN_MEAN_SQUARE_SLOPE", "surface_mean_square_slope", "log_surface_backscatter_per_sr"]

#: Cox & Munk (1954) clean-surface slope variance at zero wind: the unresolved floor.
MIN_MEAN_SQUARE_SLOPE = le.COX_MUNK_INTERCEPT


def surface_mean_square_slope(wind_speed_m_s, resolved_mss=0.0):
    """Unresolved slope variance ``max(s^2_CM(U) - resolved, 0.003)`` of the surface facets."""
    full = le.cox_munk_mean_square_slope(wind_speed_m_s)
    return np.maximum(full - resolved_mss, MIN_MEAN_SQUARE_SLOPE)


def log_surface_backscatter_per_sr(direction, normal, fresnel_r0, mss, whitecap):
    """Log of the surface backscatter per sr per incident watt of sub-rays (see module).

    Parameters
    ----------
    direction : (..., 3) ndarray
        Unit directions of the sub-rays (going down).
    normal : (..., 3) ndarray
        Upward unit normals of the traced surface where they hit it.
    fresnel_r0 : float
        Fresnel reflectance at normal incidence.
    mss : float
        Slope variance ``s^2`` of the unresolved facets.
    whitecap : float
        Whitecap cover fraction ``W``.

    Returns
    -------
    (...) ndarray
        ``ln[(1 - W) R0 sec^4(theta) n_z exp(-|m - g|^2 / s^2) / (4 pi s^2 cos t)
        + W rho_foam cos t / pi]``: ``theta`` the sub-ray's off-nadir angle, ``m`` the slope
        that faces it, ``g`` the traced slope, ``t`` the incidence on the traced facet. Flat
        (``normal`` vertical): ``ln[(1 - W) R0 sec^5 t exp(-tan^2 t / s^2) / (4 pi s^2) + ...]``.
    """
    d = np.asarray(direction, dtype=np.float64)
    nrm = np.asarray(normal, dtype=np.float64)
    cos_t = np.clip(-np.einsum("...i,...i->...", d, nrm), 0.0, 1.0)
    cos_off = np.clip(-d[..., 2], 0.0, 1.0)
    n_z = np.clip(nrm[..., 2], 0.0, 1.0)
    # facets seen edge-on, beams at the horizon or normals lying flat glint nothing; the
    # slope difference is kept finite there (exp(-1e200 / s^2) is 0 anyway)
    ok = (cos_t > 1e-100) & (cos_off > 1e-100) & (n_z > 1e-100)
    dz = np.where(ok, cos_off, 1.0)
    nz = np.where(ok, n_z, 1.0)
    mx = d[..., 0] / dz + nrm[..., 0] / nz  # m - g, with g = -n_xy / n_z
    my = d[..., 1] / dz + nrm[..., 1] / nz
    dm2 = np.where(ok, mx**2 + my**2, 1e200)
    glint = (
        math.log(fresnel_r0 / (4.0 * math.pi * mss)) + math.log1p(-whitecap)
        if whitecap < 1.0
        else LOG_ZERO
    )
    log_glint = (
        glint
        - 4.0 * safe_log(cos_off)
        + safe_log(n_z)
        - safe_log(np.where(ok, cos_t, 1.0))
        - dm2 / mss
    )
    log_glint = np.where(ok, log_glint, LOG_ZERO)
    log_foam = (
        math.log(whitecap * le.FOAM_REFLECTANCE / math.pi) + safe_log(cos_t)
        if whitecap > 0
        else LOG_ZERO
    )
    return np.maximum(np.logaddexp(log_glint, log_foam), LOG_ZERO)
