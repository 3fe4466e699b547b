"""The waveform model in vectorised numpy: the readable reference of the compiled kernel.

:func:`expected_waveform_numpy` evaluates the model of :mod:`pipeline.uncertainty.waveform_model`
(whose docstring derives it) for all rows at once with numpy. The production path is the
compiled :mod:`pipeline.uncertainty.waveform_kernel` (the sampler calls the model tens of
thousands of times per pulse on a few hundred rows, where numpy's temporaries and call overhead
dominated); this version is kept as the independent reference the kernel is tested against
(``tests/uncertainty/test_waveform_kernel.py``).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from scipy.special import erfcx, ndtr

from pipeline.uncertainty.waveform_kernel import BAND_Z as _BAND_Z
from pipeline.uncertainty.waveform_model import (
    _C,
    WaveformSystem,
    _as_2d,
    in_water_delay_s,
)

__all__ = ["expected_waveform_numpy"]

_SQRT1_2 = math.sqrt(0.5)


def _psi(u, r, s):
    """``psi(u) = exp(-r u + (r s)²/2) Phi(u/s - r s)`` without overflow.

    With ``z = u/s`` and ``a = (r s - z)/sqrt(2)``: ``psi = exp(-z²/2) erfcx(a) / 2`` for
    ``a >= 0`` (both factors <= 1) and, by ``erfcx(-x) = 2 exp(x²) - erfcx(x)``,
    ``psi = exp(-r u + (r s)²/2) - exp(-z²/2) erfcx(|a|) / 2`` for ``a < 0``, where the first
    exponent is <= ``-(r s)²/2`` (one ``erfcx`` call for both branches).
    """
    z = u / s
    rs = r * s
    a = (rs - z) * _SQRT1_2
    half_g = 0.5 * np.exp(-0.5 * z * z) * erfcx(np.abs(a))
    expo = np.minimum(-r * u + 0.5 * rs * rs, 0.0)  # clipped where unused (a >= 0)
    return np.where(a >= 0.0, half_g, np.exp(expo) - half_g)


def _band(centre_s, n_edges: int, s: float, dt: float) -> np.ndarray:
    """Edge indices (n, w) of the band ``|t - centre| <= 8.5 s`` of each row.

    Edges are at ``(j - 1/2) dt``; the band is shifted to stay inside ``[0, n_edges)``.
    """
    width = min(int(math.ceil(2.0 * _BAND_Z * s / dt)) + 2, n_edges)
    first = np.floor((centre_s - _BAND_Z * s) / dt + 0.5).astype(np.int64) + 1
    first = np.clip(first, 0, n_edges - width)
    return first[:, None] + np.arange(width)


def expected_waveform_numpy(
    theta: Any, n_samples: int, system: WaveformSystem, cos_water: Any = 1.0
) -> np.ndarray:
    """:func:`~pipeline.uncertainty.waveform_model.expected_waveform`, vectorised in numpy.

    Same arguments and result; bands as wide as the batch's widest echo (terms beyond
    8.5 sigma, < 2e-16 of the areas, may differ from the compiled kernel's).
    """
    th, single = _as_2d(theta)
    dt, s = system.sample_interval_s, system.pulse_sigma_s
    n = th.shape[0]
    cw = np.broadcast_to(np.asarray(cos_water, dtype=np.float64), (n,))
    depth, t_ns, la_s, la_c, la_b, lk, bg, lw, lws = th.T
    t_s = t_ns * 1e-9
    r = np.exp(lk) * _C / system.group_index  # two-way decay rate of the column, 1/s
    tau = in_water_delay_s(depth, cw, system.group_index)
    rs = r * s
    e = n_samples + 1
    edges = (np.arange(e) - 0.5) * dt
    # cumulative column C_tau(u) away from the two returns (|z| > 8.5): 0 before the surface,
    # 1 - exp(-r u + (r s)²/2) in the water, 1 - exp(-r tau) after the bottom (the two
    # exponential tails cancel there); exact inside the bands below
    u = edges[None, :] - t_s[:, None]
    inner = np.exp(np.minimum(-r[:, None] * u + (0.5 * rs * rs)[:, None], 0.0))
    cum = np.where(
        u <= 0.0, 0.0, 1.0 - np.where(u < tau[:, None], inner, np.exp(-r * tau)[:, None])
    )
    rows = np.arange(n)[:, None]
    rr, tt = r[:, None], tau[:, None]
    fall = np.exp(-rr * tt)
    # bands closer than 2 x 8.5 sigma overlap: there both parts are exact everywhere
    near = np.flatnonzero(tau < 2.0 * _BAND_Z * s)
    gauss = []
    for centre, is_surface in ((t_s, True), (t_s + tau, False)):
        cols = _band(centre, e, s, dt)
        ub = edges[cols] - t_s[:, None]
        own_u = ub if is_surface else ub - tt
        phi_own = ndtr(own_u / s)
        c_own = phi_own - _psi(own_u, rr, s)
        if is_surface:  # the bottom part C(u - tau) is 0 in the surface band ...
            c_other = np.zeros_like(ub)
        else:  # ... and the surface part 1 - its exponential tail in the bottom band
            c_other = 1.0 - np.exp(np.minimum(-rr * ub + 0.5 * (rr * s) ** 2, 0.0))
        if near.size:  # ... unless the bands overlap
            ou = ub[near] - tt[near] if is_surface else ub[near]
            c_other[near] = ndtr(ou / s) - _psi(ou, rr[near], s)
        c_s, c_b = (c_own, c_other) if is_surface else (c_other, c_own)
        cum[rows, cols] = c_s - fall * c_b
    # the surface and bottom echoes at their own widths (own bands, as wide as the widest
    # row needs)
    for centre, log_area, log_width in ((t_s, la_s, lws), (t_s + tau, la_b, lw)):
        s_e = s * np.exp(log_width)
        cols = _band(centre, e, float(np.max(s_e)), dt)
        phi = ndtr((edges[cols] - centre[:, None]) / s_e[:, None])
        gauss.append((cols[:, :-1], np.exp(log_area)[:, None] * np.diff(phi, axis=1)))
    # normalised to the column's total counts: C_tau(inf) = 1 - exp(-r tau)
    mu = np.diff(cum, axis=1) * (np.exp(la_c) / -np.expm1(-r * tau))[:, None]
    mu += (system.offset_counts + bg)[:, None]
    for cols, val in gauss:  # the returns vanish outside their bands (< 1e-17 of the area)
        mu[rows, cols] += val  # distinct columns per row: no repeated index
    return mu[0] if single else mu
