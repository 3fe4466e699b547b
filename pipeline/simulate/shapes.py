"""Time shapes of the returns: cumulative distributions and their bin integrals.

Two shapes cover every return of the waveform model:

* a **Gaussian** of standard deviation ``sigma`` (surface, land and bottom returns: the
  transmitted Gaussian pulse, widened by the detector and by forward scattering);
* a **truncated exponential convolved with a Gaussian** (the water column): photons
  backscattered at in-water path ``l`` come back at ``t = t_start + x`` with ``x`` distributed
  as ``r exp(-r x)`` on ``[0, w]`` (``r`` the two-way decay rate per second, ``w`` the water
  path's two-way travel time), blurred by the pulse.

Both are evaluated as CDFs so that a bin's expected count is a CDF difference: sums over a
window telescope to the exact total, whatever the sample rate.

Notes
-----
The exponentially modified Gaussian CDF is ``F(x) = Phi(x/s) - psi(x)`` with
``psi(x) = exp(-r x + r^2 s^2/2) Phi(x/s - r s)``. ``psi`` is evaluated as
``exp(-r x + r^2 s^2 / 2 + log Phi(x/s - r s))``: with ``b = x/s - r s`` the exponent equals
``-r s b - r^2 s^2/2 + log Phi(b)``, which is at most ``log Phi(b) + 5 r s`` for ``b >= -5`` and
``-x^2/(2 s^2) - log(-b sqrt(2 pi)) <= 0`` for ``b < -5`` (Mills ratio), so it never overflows,
even for a decay rate of 1e11 1/s far before the surface. Truncation at ``w``:
``F_w(x) = [F(x) - exp(-r w) F(x - w)] / (1 - exp(-r w))``; when ``r w < 5e-8`` the exponential
is replaced by its uniform limit (``G(y) = y Phi(y/s) + s phi(y/s)``,
``F_w = [G(x) - G(x - w)] / w``), and when ``w < 1e-6 s`` by a point at the start.
"""

from __future__ import annotations

import numpy as np
from scipy.special import log_ndtr, ndtr

from pipeline.simulate.column_kernel import column_rows

__all__ = [
    "fast_ndtr",
    "gauss_cdf",
    "column_cdf",
    "column_bin_integrals",
    "add_column_bins",
    "column_depth_time",
]

_INV_SQRT_2PI = 0.3989422804014327

# Tabulated standard normal CDF: cubic Hermite interpolation on a 1/256 grid over [-9, 9]
# (values and exact derivatives phi at the nodes); error <= h^4 max|phi'''| / 384 = 8e-13.
# Outside: 0 or 1 (Phi(-9) = 1e-19). About 3x faster than scipy.special.ndtr where measured.
_TAB_Z = 9.0
_TAB_N = 256
_tab_nodes = np.linspace(-_TAB_Z, _TAB_Z, int(2 * _TAB_Z * _TAB_N) + 1)
_tab_f = ndtr(_tab_nodes)
_tab_d = _INV_SQRT_2PI * np.exp(-0.5 * _tab_nodes**2) / _TAB_N  # derivative per grid step
_df = np.diff(_tab_f)
_TAB = np.stack(
    [
        _tab_f[:-1],
        _tab_d[:-1],
        3.0 * _df - 2.0 * _tab_d[:-1] - _tab_d[1:],
        -2.0 * _df + _tab_d[:-1] + _tab_d[1:],
    ],
    axis=1,
)  # Horner coefficients per interval
del _tab_nodes, _tab_f, _tab_d, _df


def fast_ndtr(z):
    """Standard normal CDF, tabulated (absolute error < 1e-12); any shape, float64."""
    u = (np.clip(np.asarray(z, dtype=np.float64), -_TAB_Z, _TAB_Z) + _TAB_Z) * _TAB_N
    i = np.minimum(u.astype(np.int64), _TAB.shape[0] - 1)
    t = u - i
    c = _TAB[i]
    return c[..., 0] + t * (c[..., 1] + t * (c[..., 2] + t * c[..., 3]))


def gauss_cdf(x_s, sigma_s):
    """Standard Gaussian CDF of ``x / sigma`` (tabulated, see :func:`fast_ndtr`)."""
    return fast_ndtr(np.asarray(x_s) / sigma_s)


def _psi(x, r, s):
    """``exp(-r x + r^2 s^2 / 2) Phi(x/s - r s)`` without overflow (see module Notes)."""
    rs = r * s
    return np.exp(-r * x + 0.5 * rs * rs + log_ndtr(x / s - rs))


_EDGE = 9.0  # sigmas: 1 - Phi(9) = 1e-19, below double precision next to 1


def _emg_cdf(x, r, s):
    """CDF of Exp(rate r) + N(0, s^2) at ``x`` (``r > 0``).

    Far before the start (``x < -9 s``) it is 0 to double precision, and well inside
    (``x/s - r s > 9``) both Gaussian CDFs are 1, leaving ``1 - exp(-r x + r^2 s^2 / 2)``: only
    the samples near the edge need the full formula.
    """
    z = x / s
    out = np.zeros(x.shape)
    inner = z - r * s > _EDGE
    edge = ~inner & (z >= -_EDGE)
    xi, ri, si = x[inner], r[inner], s[inner]
    out[inner] = -np.expm1(-ri * xi + 0.5 * (ri * si) ** 2)
    out[edge] = ndtr(z[edge]) - _psi(x[edge], r[edge], s[edge])
    return out


def _uniform_gauss_cdf(x, w, s):
    """CDF of Uniform[0, w] + N(0, s^2) at ``x`` (``w > 0``)."""

    def g(y):
        z = y / s
        return y * ndtr(z) + s * _INV_SQRT_2PI * np.exp(-0.5 * z * z)

    return (g(x) - g(x - w)) / w


def column_cdf(x_s, rate_per_s, width_s, sigma_s):
    """CDF of the water-column shape: truncated exponential on ``[0, w]`` plus a Gaussian.

    Parameters
    ----------
    x_s : ndarray
        Time after the column's start (the surface echo), seconds.
    rate_per_s : ndarray
        Decay rate ``r >= 0`` of the backscatter with time, 1/s.
    width_s : ndarray
        Duration ``w >= 0`` of the column (two-way water travel time), seconds.
    sigma_s : ndarray
        Gaussian blur (pulse and detector), seconds, > 0.

    Returns
    -------
    ndarray
        ``P(X <= x)`` in [0, 1], broadcast shape; finite for every finite input.
    """
    x, r, w, s = np.broadcast_arrays(
        *(np.asarray(a, dtype=np.float64) for a in (x_s, rate_per_s, width_s, sigma_s))
    )
    out = np.empty(x.shape)
    rw = r * w
    point = w < 1e-6 * s
    uniform = ~point & (rw < 5e-8)
    expo = ~point & ~uniform
    out[point] = ndtr(x[point] / s[point])
    if np.any(uniform):
        out[uniform] = _uniform_gauss_cdf(x[uniform], w[uniform], s[uniform])
    if np.any(expo):
        xe, re, we, se = x[expo], r[expo], w[expo], s[expo]
        tail = np.exp(-re * we)
        num = _emg_cdf(xe, re, se) - tail * _emg_cdf(xe - we, re, se)
        out[expo] = num / -np.expm1(-re * we)
    return np.clip(out, 0.0, 1.0)


def column_bin_integrals(x0_s, dt: float, m: int, rate_per_s, width_s, sigma_s):
    """Probabilities of the column shape in ``m`` contiguous bins, one row per column.

    Parameters
    ----------
    x0_s : (k,) float64
        Lower edge of the first bin, relative to each column's start, seconds.
    dt : float
        Bin width, seconds.
    m : int
        Bins per row.
    rate_per_s, width_s, sigma_s : (k,) float64
        Decay rate (>= 0), duration (>= 0) and Gaussian blur (> 0) of each column.

    Returns
    -------
    (k, m) float64
        ``F(x_{i+1}) - F(x_i)`` with ``F`` as in :func:`column_cdf`.

    Notes
    -----
    Same mathematics as :func:`column_cdf`, organised for speed. With ``e = exp(-r x +
    r^2 s^2 / 2)``, ``a = s (9 + r s)`` and ``b = -9 s``: bins below ``b`` hold 0, bins beyond
    ``a + w`` hold 0 (the two terms cancel), bins inside ``[a, b + w]`` hold
    ``(e(x_i) - e(x_{i+1})) / (1 - tau)`` (one exponential per edge), and only the bins that
    touch ``[b, a]`` or ``[b + w, a + w]`` need the full formula. Rows that :func:`column_cdf`
    treats as uniform or as a point (``r w < 5e-8`` or ``w < 1e-6 s``) are passed to it.
    """
    out = np.zeros((np.size(x0_s), m))
    add_column_bins(out, np.arange(out.shape[0]), np.ones(out.shape[0]), x0_s, dt, rate_per_s,
                    width_s, sigma_s)  # fmt: skip
    return out


def add_column_bins(out, rows, scale, x0_s, dt: float, rate_per_s, width_s, sigma_s) -> None:
    """``out[rows] += scale[:, None] * column_bin_integrals(...)``, in place.

    Parameters
    ----------
    out : (n, m) float64
        Accumulated into; ``m`` bins per row.
    rows : (k,) int
        Row of ``out`` of each column (distinct).
    scale : (k,) float64
        Each column's expected count.
    x0_s, dt, rate_per_s, width_s, sigma_s
        As :func:`column_bin_integrals`.

    Notes
    -----
    The same products and sums as ``out[rows] += scale[:, None] * prob`` of the whole rows
    (a bin outside a column's block gains ``scale * 0``: nothing), without the ``(k, m)``
    array of probabilities for the regular columns.
    """
    m = out.shape[1]
    rows = np.asarray(rows, dtype=np.int64)
    scale = np.asarray(scale, dtype=np.float64)
    bad = ~np.isfinite(scale)
    if bad.any():
        # (the whole-row product made these rows NaN: the receiver's finiteness check reports
        # them, where only the column's block would show an infinite count, clipped)
        out[rows[bad]] = np.nan
    x0, r, w, s = (np.asarray(a, dtype=np.float64) for a in (x0_s, rate_per_s, width_s, sigma_s))
    special = (w < 1e-6 * s) | (r * w < 5e-8)
    if np.any(special):
        x = x0[special, None] + dt * np.arange(m + 1)
        sp = np.flatnonzero(special)
        prob = np.diff(column_cdf(x, r[sp, None], w[sp, None], s[sp, None]), axis=1)
        out[rows[sp]] += scale[sp, None] * prob
    reg = np.flatnonzero(~special)
    if reg.size == 0:
        return
    x0, r, w, s = x0[reg], r[reg], w[reg], s[reg]
    a, b = s * (_EDGE + r * s), -_EDGE * s
    tau = np.exp(-r * w)
    norm = -np.expm1(-r * w)
    # one block of bin edges from the earliest support start to the latest end (the window
    # opens a fixed time before the surface echo, so the starts nearly coincide); the clipped
    # exponent gives exactly 0 before b, and clipping to 1 handles edges past a + w
    first = int(np.clip(np.floor(np.min((b - x0) / dt)), 0, m))
    last = int(np.clip(np.ceil(np.max((a + w - x0) / dt)), 0, m))
    width = last - first
    if width <= 0:
        return
    # the two edge zones [b, a] and [b + w, a + w] by the full formula: each row's edges from
    # its zone's first one on (h edges); in a long column (w > a - b) the start zone only
    # needs the first term and the end zone only the second (the first is 1 - e there); the
    # clipped exponent gives exactly 0 before b, and clipping to 1 handles edges past a + w.
    # Compiled row by row (pipeline.simulate.column_kernel); bins past a row's end hold 0
    h = int(np.ceil(float(np.max((a - b) / dt)))) + 2
    column_rows(
        x0, float(dt), first, width, h, r, w, s, a, b, tau, norm, _EDGE, _TAB, _TAB_Z, _TAB_N,
        out, rows[reg], scale[reg],
    )  # fmt: skip


def column_depth_time(u, rate_per_s, width_s):
    """Inverse CDF of the truncated exponential on ``[0, w]``: time after the column start.

    Parameters
    ----------
    u : ndarray
        Uniform numbers in (0, 1).
    rate_per_s, width_s : ndarray
        Decay rate (>= 0, 1/s) and duration (>= 0, s), broadcast with ``u``.

    Returns
    -------
    ndarray
        ``x = -log1p(u expm1(-r w)) / r``, or ``u w`` in the uniform limit ``r w < 5e-8``.
    """
    u, r, w = np.broadcast_arrays(
        *(np.asarray(a, dtype=np.float64) for a in (u, rate_per_s, width_s))
    )
    rw = r * w
    small = rw < 5e-8
    safe_r = np.where(small, 1.0, r)
    x = -np.log1p(u * np.expm1(-np.where(small, 0.0, rw))) / safe_r
    return np.where(small, u * w, np.minimum(x, w))
