"""The water column's bin probabilities, compiled row by row (:func:`column_rows`).

:func:`pipeline.simulate.shapes.column_bin_integrals` in whole-array numpy formed a dozen
``(columns, bins)`` temporaries and gathered its edge zones by index: about half of the
full-waveform receiver's time. This kernel walks each row's bin edges once with the same
zones, the same formulas in the same order and the same tabulated normal CDF
(:func:`fast_ndtr_one`, :data:`pipeline.simulate.shapes._TAB` passed in). Not the same
figures to the bit: ``exp``, ``erfc`` and ``log`` are the C library's here and numpy's or
scipy's (Cephes) there, ``log_ndtr`` below -20 is summed from its asymptotic series, and the
probabilities divide by ``1 - exp(-r w)``, which magnifies a last-bit difference to ~eps / (r w)
(up to ~3e-11 of a probability in a near-uniform column, r w ~ 1e-5; as large as either
form's own rounding there). A digitised count could flip where ``v + 0.5`` falls that close
to an integer; on the two scenes compared (a 23 k-pulse Palmer run and the built-in scene)
the outputs were identical (``tests/simulate/test_column_kernel.py`` checks the special
functions against scipy; ``test_waveform_shapes.py`` the bins against :func:`~pipeline.
simulate.shapes.column_cdf`).
"""

from __future__ import annotations

import math

import numba
import numpy as np

__all__ = ["column_rows", "fast_ndtr_one", "ndtr_one", "log_ndtr_one"]

_SQRT1_2 = math.sqrt(0.5)
_LOG_SQRT_2PI = 0.5 * math.log(2.0 * math.pi)


@numba.njit(cache=True, nogil=True)
def fast_ndtr_one(z, tab, half_span, per_unit):
    """:func:`~pipeline.simulate.shapes.fast_ndtr` of one value (the same table, to the bit)."""
    if z != z:  # (a NaN would index the table anywhere)
        return z
    c = -half_span if z < -half_span else (half_span if z > half_span else z)
    u = (c + half_span) * per_unit
    i = min(int(u), tab.shape[0] - 1)
    t = u - i
    return tab[i, 0] + t * (tab[i, 1] + t * (tab[i, 2] + t * tab[i, 3]))


@numba.njit(cache=True, nogil=True)
def ndtr_one(z):
    """Standard normal CDF (Cephes' ``ndtr`` split: ``erf`` near 0, ``erfc`` in the tails)."""
    x = z * _SQRT1_2
    if abs(x) < _SQRT1_2:
        return 0.5 + 0.5 * math.erf(x)
    y = 0.5 * math.erfc(abs(x))
    return 1.0 - y if x > 0.0 else y


@numba.njit(cache=True, nogil=True)
def log_ndtr_one(z):
    """``log Phi(z)``: of :func:`ndtr_one` above -20, the asymptotic series below.

    Below -20 ``Phi(z) = phi(z) / |z| (1 - 1/z^2 + 3/z^4 - ...)``; twelve terms leave a
    relative error under 1e-16 there, and it holds where ``Phi`` itself underflows.
    """
    if z > -20.0:
        return math.log(ndtr_one(z))
    inv = 1.0 / (z * z)
    term, total = 1.0, 1.0
    for k in range(1, 12):
        term *= -(2 * k - 1) * inv
        total += term
    return -0.5 * z * z - math.log(-z) - _LOG_SQRT_2PI + math.log(total)


@numba.njit(cache=True, nogil=True)
def _edge_cdf(x, r, s, precise, tab, half_span, per_unit):
    """:func:`~pipeline.simulate.shapes._edge_cdf` of one value."""
    z = x / s
    rs = r * s
    b = z - rs
    expo = -r * x + 0.5 * rs * rs
    if b < -5.0:
        psi = math.exp(expo + log_ndtr_one(b))
    elif precise:
        psi = math.exp(expo) * ndtr_one(b)
    else:
        psi = math.exp(expo) * fast_ndtr_one(b, tab, half_span, per_unit)
    phi_z = ndtr_one(z) if precise else fast_ndtr_one(z, tab, half_span, per_unit)
    return phi_z - psi


@numba.njit(cache=True, nogil=True)
def _numerator(x, r, w, s, tau, e, edge, tab, half_span, per_unit):
    """:func:`~pipeline.simulate.shapes._numerator` of one value (``edge``: 9 σ)."""
    precise = tau > 0.99
    first = second = 0.0
    for q in range(2):
        shift, scale, plain = (0.0, 1.0, 1.0) if q == 0 else (w, tau, tau)
        xs = x - shift
        if xs > s * (edge + r * s):
            term = plain - e
        elif xs < -edge * s:
            term = 0.0
        else:
            term = scale * _edge_cdf(xs, r, s, precise, tab, half_span, per_unit)
        if q == 0:
            first = term
        else:
            second = term
    return first - second


@numba.njit(cache=True, nogil=True)
def column_rows(
    x0,
    dt,
    first,
    width,
    h,
    r,
    w,
    s,
    a,
    b,
    tau,
    norm,
    edge,
    tab,
    half_span,
    per_unit,
    out,
    rows,
    scale,
):
    """Bin probabilities of regular columns, times ``scale``, added to ``out[rows[i]]``.

    Parameters
    ----------
    x0, r, w, s, a, b, tau, norm : (k,) float64
        Per column: first bin's lower edge, decay rate, duration, blur, the zones' bounds
        ``a = s (9 + r s)`` and ``b = -9 s``, ``exp(-r w)`` and ``1 - exp(-r w)``.
    dt : float
        Bin width.
    first, width, h : int
        The block of bin edges (``first`` to ``first + width``, as
        :func:`~pipeline.simulate.shapes.column_bin_integrals` sets it) and the edge zones'
        length in edges.
    edge : float
        The zones' half-width in σ (9).
    tab, half_span, per_unit
        The normal CDF's table (:data:`~pipeline.simulate.shapes._TAB`), its span and step.
    out : (n, m) float64
        Added to, in ``[first, first + width)`` (the probabilities are 0 outside).
    rows : (k,) int64
        Row of ``out`` of each column.
    scale : (k,) float64
        Each column's expected count.
    """
    k = x0.size
    cdf = np.empty(width + 1)
    for p in range(k):
        rp, wp, sp = r[p], w[p], s[p]
        rs2 = 0.5 * ((rp * sp) * (rp * sp))
        start = x0[p] + dt * first
        for j in range(width + 1):
            e = math.exp(min(-rp * (start + dt * j) + rs2, 0.0))
            cdf[j] = (1.0 - e) / norm[p]
        long_ = wp > (a[p] - b[p]) + 2.0 * dt
        for zone in range(2):
            z0 = b[p] if zone == 0 else b[p] + wp
            j0 = math.ceil((z0 - x0[p]) / dt) - first
            for j in range(max(j0, 0), min(j0 + h, width + 1)):
                x = start + dt * j
                e = math.exp(min(-rp * x + rs2, 0.0))
                if long_ and zone == 0:
                    num = _edge_cdf(x, rp, sp, False, tab, half_span, per_unit)
                elif long_:
                    second = tau[p] * _edge_cdf(x - wp, rp, sp, False, tab, half_span, per_unit)
                    num = 1.0 - e - second
                else:
                    num = _numerator(x, rp, wp, sp, tau[p], e, edge, tab, half_span, per_unit)
                cdf[j] = num / norm[p]
        row = rows[p]
        prev = _unit(cdf[0])
        for j in range(width):
            cur = _unit(cdf[j + 1])
            out[row, first + j] += scale[p] * (cur - prev)
            prev = cur


@numba.njit(cache=True, nogil=True)
def _unit(v):
    """``np.clip(v, 0, 1)``: a NaN stays NaN (the receiver's finiteness check reports it)."""
    if v < 0.0:
        return 0.0
    if v > 1.0:
        return 1.0
    return v
