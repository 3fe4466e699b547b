"""The echo of a scattering layer in the water column (``water.layer_*``), per sub-ray.

Each sub-ray's layer echo is the column lidar equation integrated exactly across the slab and
stopped at the seabed (see :mod:`pipeline.simulate.budget`, Notes, for the model); it is timed
with the group index.

layer echo of a sub-ray is centred at ``t_surface + 2 n_g l_mean / c0`` with
``sigma^2 = sigma_pulse^2 + sigma_detector^2 + (2 n_g / c0)^2 var(l) + sigma_fs(l_mean)^2``,
``l_mean`` and ``var(l)`` the moments of the path under ``exp(-2 c l) dOmega_w(l)`` on the segment
(a uniform slab of 1 m at nadir: ``sigma = 2 n_g / (c0 sqrt 12)`` = 2.6 ns before blurring).

Layer integral (:func:`layer_echo`): with ``y = 2 c (l2 - l1)``,
``∫ exp(-2 c l) h dl = exp(-2 c l1) (1 - e^-y) / (2 c) E[h]``, the expectation over the
truncated exponential on the segment taken by Gauss-Legendre in its probability (6 nodes at
its inverse CDF, as :func:`~pipeline.simulate.shapes.column_depth_time`): ``h = dOmega_w / A``
changes by ``(l2 - l1) / S`` across it (``S`` the virtual-source distance, >= the air range),
so the rule is exact to rounding for any layer and any extinction, and nothing overflows. The
path's mean and variance are the truncated exponential's, in closed form, plus the small shift
the slope of ``h`` gives them (from the same nodes).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from pipeline import optics
from pipeline.simulate import paths as P
from pipeline.simulate.geometry import (
    LOG_ZERO,
    log_aperture_factor,
    safe_log,
    virtual_source_slopes,
)

__all__ = ["LayerEcho", "layer_echo", "truncated_exponential_moments"]

C0 = optics.SPEED_OF_LIGHT_M_S
#: Gauss-Legendre rule on (0, 1) for the layer integral's expectation (see module Notes).
_LAYER_X, _LAYER_W = np.polynomial.legendre.leggauss(6)
_LAYER_X, _LAYER_W = 0.5 * (_LAYER_X + 1.0), 0.5 * _LAYER_W


@dataclass(frozen=True)
class LayerEcho:
    """The scattering layer as each sub-ray crosses it, shapes ``(n_pulses, n_sub)``.

    Attributes
    ----------
    present : bool
        The sub-ray is in water and crosses the layer above the seabed.
    log_integral : float64
        ``ln ∫_l1^l2 exp(-2 c l) (dOmega_w / A)(l) dl`` (ln of 1/m), ``LOG_ZERO`` where absent.
    path_mean_m, path_var_m2 : float64
        Mean (m) and variance (m²) of the in-water path of the echo's photons, 0 where absent.
    """

    present: np.ndarray
    log_integral: np.ndarray
    path_mean_m: np.ndarray
    path_var_m2: np.ndarray


def truncated_exponential_moments(rate, width):
    """Mean and variance of ``rate exp(-rate x)`` truncated to ``[0, width]``, no cancellation.

    With ``y = rate width``: mean ``width (1/y - e^-y / (1 - e^-y))`` and variance
    ``width^2 (1/y^2 - e^-y / (1 - e^-y)^2)``; below ``y = 0.1`` their series
    ``1/2 - y/12 + y^3/720 - y^5/30240`` and ``1/12 - y^2/240 + y^4/6048`` (error < 1e-10).
    """
    y = rate * np.asarray(width, dtype=np.float64)
    small = y < 0.1
    yl = np.where(small, 1.0, y)
    e = np.exp(-yl)
    d = -np.expm1(-yl)  # 1 - e^-y
    m = np.where(small, 0.5 - y / 12.0 + y**3 / 720.0 - y**5 / 30240.0, 1.0 / yl - e / d)
    v = np.where(small, 1.0 / 12.0 - y**2 / 240.0 + y**4 / 6048.0, 1.0 / yl**2 - e / d**2)
    return width * m, width**2 * np.maximum(v, 0.0)


def layer_echo(paths, water, level_m: float, n_air: float) -> LayerEcho:
    """Where each sub-ray crosses the scattering layer, and the layer's column integral.

    Parameters
    ----------
    paths : Paths
        Traced geometry, ``(n_pulses, n_sub)``.
    water : WaterSettings
        ``extinction_per_m``, ``phase_index`` and the ``layer_*`` keys.
    level_m : float
        Mean water level (local z) the layer depth is measured from.
    n_air : float
        Phase index of air.

    Returns
    -------
    LayerEcho
        See the module docstring ("Layer integral"); finite for any extinction (log space).
    """
    flags = np.asarray(paths.flags)
    wet = (flags & (P.MISS | P.LAND)) == 0
    cos_v = -np.asarray(paths.refracted_dir)[..., 2]  # the refracted ray's downward cosine
    ok = wet & (cos_v > 1e-12)
    inv = 1.0 / np.where(ok, cos_v, 1.0)
    surf_z = np.asarray(paths.surface_xyz_m)[..., 2]
    centre_z = level_m - water.layer_depth_m
    half = 0.5 * water.layer_thickness_m
    l1 = np.maximum((surf_z - (centre_z + half)) * inv, 0.0)  # a wave trough inside the layer
    l2 = (surf_z - (centre_z - half)) * inv
    known = (flags & P.NO_BOTTOM) == 0  # the seabed was hit: the segment ends there at most
    l2 = np.where(known, np.minimum(l2, paths.water_path_m), l2)
    present = ok & (l2 > l1)
    width = np.where(present, l2 - l1, 0.0)
    l1 = np.where(present, l1, 0.0)

    s = 2.0 * water.extinction_per_m
    cos_a = np.where(ok, np.cos(np.clip(paths.incidence_rad, 0.0, 0.5 * np.pi)), 1.0)
    r_air = np.where(present, paths.air_range_m, 1.0)
    # nodes: paths at the Gauss-Legendre probabilities u of the truncated exponential
    # exp(-s x) on [0, width], x = -log1p(u expm1(-s width)) / s (accurate for any s width > 0;
    # :func:`~pipeline.simulate.shapes.column_depth_time` is the same inverse), (nodes, n, k)
    u = _LAYER_X[:, None, None]
    x = -np.log1p(u * np.expm1(-s * width)) / s if s > 0.0 else u * width
    # h(l1 + x) / h(l1) = S_t S_s at l1 over S_t S_s at l1 + x (S = R + k l, :mod:`.geometry`):
    # a ratio near 1 (the layer is thin against the range), no logarithm per node
    k_t, k_s = virtual_source_slopes(cos_a, n_air, water.phase_index)
    s_t1, s_s1 = r_air + k_t * l1, r_air + k_s * l1
    w = _LAYER_W[:, None, None] * (s_t1 * s_s1) / ((s_t1 + k_t * x) * (s_s1 + k_s * x))
    wsum = w.sum(axis=0)
    # moments of x: exact for the truncated exponential, plus the (tiny) shift by h's slope
    # as the rule sees it (the rule alone misses the exponential's moments by 1-14 % when
    # s width > 5: its inverse CDF has a log singularity there)
    mean_h = (w * x).sum(axis=0) / wsum
    var_h = (w * (x - mean_h) ** 2).sum(axis=0) / wsum
    mean_0 = (_LAYER_W[:, None, None] * x).sum(axis=0)
    var_0 = (_LAYER_W[:, None, None] * (x - mean_0) ** 2).sum(axis=0)
    exact_mean, exact_var = truncated_exponential_moments(s, width)
    mean_x = exact_mean + (mean_h - mean_0)
    var = exact_var + (var_h - var_0)
    # ∫_l1^l2 exp(-s l) dl = exp(-s l1) (1 - exp(-s w)) / s, and w itself when s = 0
    if s > 0.0:
        log_seg = -s * l1 + safe_log(-np.expm1(-s * width)) - math.log(s)
    else:
        log_seg = safe_log(width)
    log_h1 = log_aperture_factor(r_air, l1, cos_a, n_air, water.phase_index)
    log_int = np.where(present, np.maximum(log_seg + log_h1 + np.log(wsum), LOG_ZERO), LOG_ZERO)
    mean = l1 + mean_x
    return LayerEcho(
        present=present,
        log_integral=log_int,
        path_mean_m=np.where(present, mean, 0.0),
        path_var_m2=np.where(present, np.maximum(var, 0.0), 0.0),
    )
