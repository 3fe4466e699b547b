"""Receiver geometry of the lidar equation through a refracting surface, and the column integral.

Aperture term through the water surface (generalises ``A / (n H + D)^2`` to slant paths)
-----------------------------------------------------------------------------------------
A point scatterer at in-water path ``l`` below a locally flat surface, seen by a receiver at
air range ``R`` beyond the surface along the refracted ray (incidence ``theta_a`` in air,
``theta_w`` in water, Snell ``n_a sin theta_a = n_w sin theta_w``), is imaged astigmatically:
its rays diverge from two virtual sources whose distances from the receiver along the air ray are

* sagittal (perpendicular to the plane of incidence): ``S_s = R + l n_a / n_w``,
* tangential (in the plane of incidence): ``S_t = R + l (n_a / n_w) cos^2 theta_a / cos^2 theta_w``.

The in-water solid angle that an aperture ``A`` (normal to the air ray) subtends is
``dOmega_w = A (n_a / n_w)^2 (cos theta_a / cos theta_w) / (S_t S_s)``, so radiant intensity
``I_w`` (W/sr, in water) delivers ``T_up I_w dOmega_w``. At nadir ``S_t = S_s = H + D/n`` and the
factor is ``A / (n H + D)^2``: the n² radiance law and the footprint seen through the surface of
:func:`pipeline.lidar_equation.nadir_budget`. Wave facets focus and defocus the beam; this
local flat-interface factor ignores the curvature of the facet.

Water-column integral
---------------------
The column return of one sub-ray is ``beta(180) ∫_0^L exp(-2 c l) h(l) dl`` with
``h = dOmega_w / A``; :func:`log_column_integral` evaluates its logarithm to ~1e-10 relative:
by Gauss-Laguerre on ``[0, inf)`` minus the tail beyond ``L`` when the attenuation length is
short against the virtual-source distance (``z = 2 c R n_w / n_a >= 20`` and ``2 c L >= 0.01``;
4 to 8 nodes, asymptotic error ``(2m)! / z^(2m)`` below 1e-10), by partial fractions and
exponential integrals for ``z < 20``, and by Gauss-Legendre in ``ln(1 + k_s l / R)`` (8 panels
x 8 nodes) for optically thin paths (``2 c L < 0.01``).
"""

from __future__ import annotations

import numpy as np
from scipy.special import exp1

from pipeline.optics import SPEED_OF_LIGHT_M_S as C0

__all__ = [
    "LOG_ZERO",
    "safe_log",
    "refracted_cosine",
    "virtual_source_slopes",
    "log_aperture_factor",
    "log_column_integral",
    "column_aggregate",
]

#: ln of "no photons": finite, so sums and differences of log terms never give NaN. Every real
#: budget (extinction <= 100 1/m over <= 1000 m: ln >= -2e5) stays far above it.
LOG_ZERO = -1.0e6

#: Gauss-Laguerre rules by the smallest ``z = 2 c R n_w / n_a`` they serve: the asymptotic
#: error ``(2m)! / z^(2m)`` stays below 1e-10 (8 nodes from z = 20, 6 from 40, 4 from 250).
_LAG_RULES = [(250.0, *np.polynomial.laguerre.laggauss(4)),
              (40.0, *np.polynomial.laguerre.laggauss(6)),
              (20.0, *np.polynomial.laguerre.laggauss(8))]  # fmt: skip
_GL_X, _GL_W = np.polynomial.legendre.leggauss(8)
_GL_PANELS = 8


def safe_log(x):
    """Natural log with ``LOG_ZERO`` for ``x <= 0`` (no warning, never -inf or NaN)."""
    x = np.asarray(x, dtype=np.float64)
    pos = x > 0.0
    return np.where(pos, np.log(np.where(pos, x, 1.0)), LOG_ZERO)


def refracted_cosine(cos_a, n_air: float, n_water: float):
    """``cos theta_w`` from ``cos theta_a`` by Snell's law (air to water, ``n_water >= n_air``)."""
    sin2_w = (n_air / n_water) ** 2 * (1.0 - np.asarray(cos_a) ** 2)
    return np.sqrt(np.clip(1.0 - sin2_w, 0.0, 1.0))


def virtual_source_slopes(cos_a, n_air: float, n_water: float):
    """Growth rates ``(k_t, k_s)`` of the tangential and sagittal virtual-source distances.

    Parameters
    ----------
    cos_a : ndarray
        Cosine of the incidence angle in air on the local surface.
    n_air, n_water : float
        Phase indices.

    Returns
    -------
    k_t, k_s : ndarray
        ``S_t = R + k_t l`` and ``S_s = R + k_s l`` (dimensionless).
    """
    cos_w = refracted_cosine(cos_a, n_air, n_water)
    k_s = np.full(np.shape(cos_a), n_air / n_water)
    k_t = k_s * (np.asarray(cos_a) / cos_w) ** 2
    return k_t, k_s


def _log_prefactor(cos_a, n_air: float, n_water: float):
    """``ln[(n_a / n_w)^2 cos theta_a / cos theta_w]``."""
    cos_w = refracted_cosine(cos_a, n_air, n_water)
    return 2.0 * np.log(n_air / n_water) + safe_log(cos_a) - np.log(cos_w)


def log_aperture_factor(air_range_m, water_path_m, cos_a, n_air: float, n_water: float):
    """Natural log of ``dOmega_w / A`` (1/m²) for a scatterer at ``water_path_m`` below the surface.

    Parameters
    ----------
    air_range_m, water_path_m, cos_a : ndarray
        Air range R (> 0), in-water path l (>= 0) and cos of the air incidence angle,
        broadcast together.
    n_air, n_water : float
        Phase indices.

    Returns
    -------
    ndarray
        ``ln[(n_a/n_w)^2 (cos theta_a/cos theta_w) / (S_t S_s)]``; ``LOG_ZERO`` at grazing
        incidence (``cos_a = 0``).
    """
    k_t, k_s = virtual_source_slopes(cos_a, n_air, n_water)
    r = np.asarray(air_range_m, dtype=np.float64)
    s_t = r + k_t * water_path_m
    s_s = r + k_s * water_path_m
    out = _log_prefactor(cos_a, n_air, n_water) - safe_log(s_t) - safe_log(s_s)
    return np.maximum(out, LOG_ZERO)


def _laguerre(s, a_t, a_s, k_t, k_s, nodes, weights):
    """``∫_0^inf exp(-s l) / ((a_t + k_t l)(a_s + k_s l)) dl`` by Gauss-Laguerre."""
    u = nodes[None, :] / s[:, None]
    f = (a_t[:, None] + k_t[:, None] * u) * (a_s[:, None] + k_s[:, None] * u)
    return (weights / f).sum(axis=1) / s


def _laguerre_finite(s, r, length, k_t, k_s, z):
    """``∫_0^L`` as ``∫_0^inf - e^{-sL} ∫_0^inf f(L + l') dl'`` (log), rule chosen by ``z``."""
    out = np.empty(s.shape)
    done = np.zeros(s.shape, dtype=bool)
    for z_min, nodes, weights in _LAG_RULES:
        g = np.flatnonzero(~done & (z >= z_min))
        done[g] = True
        sg, rg, lg, kt, ks = s[g], r[g], length[g], k_t[g], k_s[g]
        whole = _laguerre(sg, rg, rg, kt, ks, nodes, weights)
        tail = np.exp(-sg * lg)
        far = tail > 4e-18  # below e^-40 the part beyond L is negligible
        ratio = np.zeros(g.size)
        if np.any(far):
            f = np.flatnonzero(far)
            beyond = _laguerre(sg[f], rg[f] + kt[f] * lg[f], rg[f] + ks[f] * lg[f], kt[f], ks[f],
                               nodes, weights)  # fmt: skip
            ratio[f] = tail[f] * beyond / whole[f]
        # s L >= 0.01 keeps 1 - ratio away from cancellation
        out[g] = np.log(whole) + np.log1p(-ratio)
    return out


def _thin(s, length, r, k_t, k_s):
    """The integral for optically thin paths (``s L < 0.01``) by Gauss-Legendre in ``v``.

    ``v = ln(1 + k_s l / R)`` turns ``dl / (R + k_s l)`` into ``dv / k_s``; what is left,
    ``exp(-s l) / (R + k_t l)``, is smooth in ``v`` (its poles are ``pi`` off the real axis).
    """
    v_end = np.log1p(k_s * length / r)
    h = v_end / _GL_PANELS
    nodes = (np.arange(_GL_PANELS)[:, None] + 0.5 * (_GL_X[None, :] + 1.0)).ravel()
    weights = np.tile(0.5 * _GL_W, _GL_PANELS)
    v = h[:, None] * nodes[None, :]
    depth = (r / k_s)[:, None] * np.expm1(v)
    f = np.exp(-s[:, None] * depth) / (k_s[:, None] * (r[:, None] + k_t[:, None] * depth))
    return h * (f @ weights)


def _exp_e1(z):
    """``exp(z) E1(z)`` for z > 0: direct below 50, asymptotic series (10 terms) above."""
    z = np.asarray(z, dtype=np.float64)
    small = z <= 50.0
    zs = np.where(small, z, 1.0)
    zl = np.where(small, 100.0, z)
    term, series = 1.0 / zl, np.zeros_like(zl)
    for k in range(10):  # error below 10!/50^11 relative to 1/z: 4e-11
        series += term
        term = -term * (k + 1) / zl
    return np.where(small, np.exp(zs) * exp1(zs), series)


def _j(z, x_end):
    """``J(z) = ∫_0^X exp(-x) / (z + x) dx = e^z [E1(z) - E1(z + X)]``, no overflow."""
    return _exp_e1(z) - np.exp(-x_end) * _exp_e1(z + x_end)


def _closed_form(s, length, r, k_t, k_s):
    """The integral by partial fractions and exponential integrals (``s > 0``).

    With ``x = s l``, ``z = s R / k`` and ``X = s L``:
    ``I = (z_t z_s / (s R^2)) (J(z_s) - J(z_t)) / (z_t - z_s)``; near nadir (``z_t -> z_s``)
    the divided difference becomes ``-J'(z) = 1/z - e^-X / (z + X) - J(z)``.
    """
    x_end = s * length
    z_s = s * r / k_s
    z_t = s * r / k_t  # >= z_s
    delta = (z_t - z_s) / z_s
    near = delta < 1e-4  # divided difference ~ derivative at the midpoint, error ~ delta^2
    zm = 0.5 * (z_t + z_s)
    deriv = 1.0 / zm - np.exp(-x_end) / (zm + x_end) - _j(zm, x_end)
    dz = np.where(near, 1.0, z_t - z_s)
    diff = (_j(z_s, x_end) - _j(np.where(near, z_s + 1.0, z_t), x_end)) / dz
    return z_t * z_s * np.where(near, deriv, diff) / (s * r * r)


def log_column_integral(
    extinction_per_m, water_path_m, air_range_m, cos_a, n_air: float, n_water: float
):
    """Log of ``∫_0^L exp(-2 c l) (dOmega_w / A)(l) dl`` (1/m): the column's geometry and decay.

    Parameters
    ----------
    extinction_per_m : float or ndarray
        Beam attenuation ``c`` of the water (>= 0).
    water_path_m : ndarray
        In-water path ``L`` of the column (>= 0).
    air_range_m : ndarray
        Air range ``R`` to the surface hit (> 0).
    cos_a : ndarray
        Cosine of the incidence angle in air on the local surface.
    n_air, n_water : float
        Phase indices.

    Returns
    -------
    ndarray
        Broadcast shape; ``LOG_ZERO`` where ``L = 0`` or at grazing incidence.
    """
    c, length, r, cos_a = np.broadcast_arrays(
        *(
            np.asarray(a, dtype=np.float64)
            for a in (extinction_per_m, water_path_m, air_range_m, cos_a)
        )
    )
    shape = c.shape
    c, length, r, cos_a = (a.ravel() for a in (c, length, r, cos_a))
    s = 2.0 * c
    k_t, k_s = virtual_source_slopes(cos_a, n_air, n_water)
    out = np.full(c.shape, LOG_ZERO)
    ok = (length > 0.0) & (r > 0.0) & (cos_a > 0.0)
    thin = ok & (s * length < 0.01)
    lag = ok & ~thin & (s * r / np.maximum(k_s, 1e-300) >= 20.0)
    mid = ok & ~thin & ~lag
    if np.any(lag):
        z = s[lag] * r[lag] / k_s[lag]
        out[lag] = _laguerre_finite(s[lag], r[lag], length[lag], k_t[lag], k_s[lag], z)
    if np.any(mid):
        out[mid] = np.log(_closed_form(s[mid], length[mid], r[mid], k_t[mid], k_s[mid]))
    if np.any(thin):
        out[thin] = np.log(_thin(s[thin], length[thin], r[thin], k_t[thin], k_s[thin]))
    out[ok] += _log_prefactor(cos_a[ok], n_air, n_water)
    return np.maximum(out, LOG_ZERO).reshape(shape)


def column_aggregate(log_col, t_surf, col_len, r_air, cos_a, k_col, n_a, n_w, n_g, sig_sys2):
    """One column component per pulse: N-weighted start, duration, decay rate and blur.

    ``log_col`` (n, k) are the sub-rays' ln expected column photoelectrons, ``k_col`` their
    attenuation (1/m); returns the ``column_*`` fields of
    :class:`~pipeline.simulate.budget.ReturnBudget`.
    """
    lmax = np.max(log_col, axis=1)
    present = log_col > LOG_ZERO / 2
    q = np.where(present, np.exp(log_col - lmax[:, None]), 0.0)  # relative: never overflows
    qsum = q.sum(axis=1)
    has = qsum > 0.0
    wq = q / np.where(has, qsum, 1.0)[:, None]
    log_total = np.where(has, lmax + np.log(np.where(has, qsum, 1.0)), LOG_ZERO)
    start = (wq * t_surf).sum(axis=1)
    spread2 = (wq * (t_surf - start[:, None]) ** 2).sum(axis=1)
    to_time = 2.0 * n_g / C0  # seconds per metre of in-water path, two-way
    width = (wq * col_len).sum(axis=1) * to_time
    # decay per metre: 2k plus the slope of the aperture term at the mean scattering depth
    s = 2.0 * np.asarray(k_col, dtype=np.float64)
    mean_l = np.minimum(1.0 / np.where(s > 0, s, 1e-300), 0.5 * col_len)
    k_t, k_s = virtual_source_slopes(cos_a, n_a, n_w)
    r = np.where(present, r_air, 1.0)
    gamma = np.where(present, k_t / (r + k_t * mean_l) + k_s / (r + k_s * mean_l), 0.0)
    rate = (wq * (s + gamma)).sum(axis=1) / to_time
    return {
        "column_log_pe": log_total,
        "column_start_s": start,
        "column_width_s": width,
        "column_rate_per_s": rate,
        "column_sigma_s": np.sqrt(sig_sys2 + spread2),
    }
