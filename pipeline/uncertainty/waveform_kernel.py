"""Compiled (numba) kernels of the waveform model and its log-likelihood, row by row.

The same model as :func:`pipeline.uncertainty.waveform_model.expected_waveform_numpy` (the
readable, vectorised reference; its module docstring derives it), evaluated one parameter row
at a time in a compiled loop: no temporary arrays of the size (rows x samples), no per-call
Python overhead beyond one dispatch, and the log-likelihood summed while the mean is formed.
The sampler evaluates the model tens of thousands of times per pulse, a few hundred rows per
call, which is where the vectorised numpy version spent its time (temporaries and call
overhead, not arithmetic).

The special functions are evaluated only within ``_BAND_Z`` (8.5) system-response sigmas of each
return, as in the reference: outside, the column's cumulative counts are exact closed forms (0
before the surface, ``1 - exp(-r u + (r s)^2 / 2)`` in the water, ``1 - exp(-r tau)`` after the
bottom) and the Gaussian echoes vanish (< 1e-17 of their areas). Results agree with the
reference to rounding (``tests/uncertainty/test_waveform_kernel.py``).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from pipeline.optics import SPEED_OF_LIGHT_M_S

#: Half-width, in sigmas, of the band where the special functions are used.
BAND_Z = 8.5
_SQRT1_2 = math.sqrt(0.5)
_INV_SQRT_PI = 1.0 / math.sqrt(math.pi)
_C = SPEED_OF_LIGHT_M_S


@numba.njit(cache=True, nogil=True)
def _erfcx(x):
    """Scaled complementary error function ``exp(x^2) erfc(x)`` for ``x >= 0``.

    ``exp(x^2) erfc(x)`` directly up to 26 (``erfc`` is still a normal double there), the
    asymptotic series beyond (10 terms: relative error < 1e-21 at 26).
    """
    if x < 26.0:
        return math.exp(x * x) * math.erfc(x)
    inv = 1.0 / (2.0 * x * x)
    term, total = 1.0, 1.0
    for k in range(1, 11):
        term *= -(2 * k - 1) * inv
        total += term
    return total * _INV_SQRT_PI / x


#: The standard normal CDF tabulated with its density for cubic Hermite interpolation: nodes
#: every 1/512 on [-12, 12]; interpolation error <= h^4 max|Phi^(4)| / 384 ~ 2e-14 absolute
#: (the bands themselves drop 2e-16 of the areas), a few loads and multiplies instead of an
#: ``erfc`` (which dominated the kernel's time).
_TAB_LO, _TAB_STEPS_PER_UNIT = -12.0, 512
_TAB_X = _TAB_LO + np.arange(int(2 * -_TAB_LO * _TAB_STEPS_PER_UNIT) + 1) / _TAB_STEPS_PER_UNIT
_TAB_PHI = np.array([0.5 * math.erfc(-x * _SQRT1_2) for x in _TAB_X])
_TAB_PDF = np.exp(-0.5 * _TAB_X**2) / math.sqrt(2.0 * math.pi) / _TAB_STEPS_PER_UNIT  # h phi
_TAB_LAST = _TAB_X.size - 1


@numba.njit(cache=True, nogil=True)
def _phi(z):
    """Standard normal CDF: the table inside [-12, 12], ``erfc`` outside."""
    t = (z - _TAB_LO) * _TAB_STEPS_PER_UNIT
    if not (0.0 <= t < _TAB_LAST):
        return 0.5 * math.erfc(-z * _SQRT1_2)
    i = int(t)
    f = t - i
    g = 1.0 - f
    # cubic Hermite basis on [x_i, x_i+1] with the exact values and slopes at both nodes
    return (
        (1.0 + 2.0 * f) * g * g * _TAB_PHI[i]
        + f * f * (3.0 - 2.0 * f) * _TAB_PHI[i + 1]
        + f * g * (g * _TAB_PDF[i] - f * _TAB_PDF[i + 1])
    )


@numba.njit(cache=True, nogil=True)
def _c_exact(u, r, s):
    """``Phi(u/s) - psi(u)``, ``psi(u) = exp(-r u + (r s)^2/2) Phi(u/s - r s)``, no overflow.

    With ``z = u / s`` and ``a = (r s - z)/sqrt(2)``: ``psi = exp((r s)^2/2 - r s z) Phi(z - r s)``
    while that exponent is below 600 (the usual case: ``r s`` < 1 and ``|z| <= 8.5`` in the
    band; ``erfc(a)`` stays a normal double for ``a`` < 26), else
    ``psi = exp(-z^2/2) erfcx(a) / 2`` for ``a >= 0``, and
    ``exp(-r u + (r s)^2/2) - exp(-z^2/2) erfcx(|a|) / 2`` otherwise (the exponent is then
    <= ``-(r s)^2 / 2``).
    """
    z = u / s
    rs = r * s
    a = (rs - z) * _SQRT1_2
    expo = 0.5 * rs * rs - rs * z
    if expo < 600.0:  # the direct form, one exp: erfc(a) / 2 = Phi(z - r s)
        return _phi(z) - math.exp(expo) * _phi(z - rs)
    half_g = 0.5 * math.exp(-0.5 * z * z) * _erfcx(abs(a))
    if a >= 0.0:
        psi = half_g
    else:
        psi = math.exp(min(-r * u + 0.5 * rs * rs, 0.0)) - half_g
    return _phi(z) - psi


@numba.njit(cache=True, nogil=True)
def _c_part(u, r, s, band):
    """Normalised cumulative column of one exponential part at ``u`` (exact inside the band)."""
    if u <= -band:
        return 0.0
    if u < band:
        return _c_exact(u, r, s)
    return 1.0 - math.exp(min(-r * u + 0.5 * (r * s) ** 2, 0.0))


@numba.njit(cache=True, nogil=True)
def _add_echo(mu, centre, sigma, area, dt):
    """Add a Gaussian echo of ``area`` counts at ``centre`` (s) to the samples ``mu`` in place.

    Sample ``i`` integrates over ``[(i - 1/2) dt, (i + 1/2) dt)``; only the edges within
    ``BAND_Z`` sigmas of the centre are evaluated.
    """
    m = mu.shape[0]
    j0 = max(int(math.floor((centre - BAND_Z * sigma) / dt + 0.5)), 0)
    j1 = min(int(math.ceil((centre + BAND_Z * sigma) / dt + 0.5)), m)
    if j1 <= j0:
        return
    prev = _phi(((j0 - 0.5) * dt - centre) / sigma)
    for j in range(j0, j1):
        nxt = _phi(((j + 0.5) * dt - centre) / sigma)
        mu[j] += area * (nxt - prev)
        prev = nxt


@numba.njit(cache=True, nogil=True)
def model_row(th, cos_water, mu, dt, s, group_index, offset):
    """Mean samples of one parameter row ``th`` (9,) into ``mu`` (m,), offset included.

    Units and parameters as :func:`pipeline.uncertainty.waveform_model.expected_waveform`.
    """
    m = mu.shape[0]
    t_s = th[1] * 1e-9
    r = math.exp(th[5]) * _C / group_index
    tau = 2.0 * group_index * th[0] / (_C * cos_water)
    fall = math.exp(-r * tau)
    band = BAND_Z * s
    base = offset + th[6]
    scale = math.exp(th[3]) / -math.expm1(-r * tau)
    # cumulative column C_tau(u) = C(u) - exp(-r tau) C(u - tau) at the sample edges
    u = -0.5 * dt - t_s
    prev = _c_part(u, r, s, band) - fall * _c_part(u - tau, r, s, band)
    for i in range(m):
        u = (i + 0.5) * dt - t_s
        if u >= tau + band:
            nxt = 1.0 - fall
        else:
            nxt = _c_part(u, r, s, band) - fall * _c_part(u - tau, r, s, band)
        mu[i] = base + (nxt - prev) * scale
        prev = nxt
    _add_echo(mu, t_s, s * math.exp(th[8]), math.exp(th[2]), dt)
    _add_echo(mu, t_s + tau, s * math.exp(th[7]), math.exp(th[4]), dt)


@numba.njit(cache=True, nogil=True)
def expected_rows(theta, cos_water, n_samples, dt, s, group_index, offset):
    """Mean samples (N, n_samples) of parameter rows ``theta`` (N, 9), ``cos_water`` (N,)."""
    n = theta.shape[0]
    out = np.empty((n, n_samples))
    for k in range(n):
        model_row(theta[k], cos_water[k], out[k], dt, s, group_index, offset)
    return out


@numba.njit(cache=True, nogil=True)
def log_post_rows(theta, samples, n_valid, cos_water, box, ln_k_prior, system, exposure):
    """Log posterior of walker rows ``theta`` (N, 9), row ``k`` for pulse ``k % P``.

    ``box`` (P, 19): each pulse's prior lower and upper bounds (9 + 9) and the last sample's
    time ``t_last_s``; ``ln_k_prior`` (P, 2) the normal prior's mean and sigma on ``ln k``
    (``inf``: none). ``-inf`` outside the box or with the bottom after ``t_last_s``, else
    :func:`log_lik_rows` plus the prior (flat in the box). ``system`` as
    :func:`log_lik_rows`' trailing arguments, in a tuple; ``exposure`` (P, m) as there.
    """
    n, n_p = theta.shape[0], samples.shape[0]
    dt, s, group_index, offset, poisson, floor, shot = system
    out = np.full(n, -np.inf)
    keep = np.zeros(n, dtype=np.bool_)
    for k in range(n):
        p = k % n_p
        inside = True
        for j in range(9):
            if not (box[p, j] <= theta[k, j] <= box[p, 9 + j]):
                inside = False
        t_b = theta[k, 1] * 1e-9 + 2.0 * group_index * theta[k, 0] / (_C * cos_water[p])
        keep[k] = inside and t_b <= box[p, 18]
    idx = np.flatnonzero(keep)
    ll = log_lik_rows(
        theta[idx], idx % n_p, samples, n_valid, cos_water, dt, s, group_index, offset, poisson,
        floor, shot, exposure,
    )  # fmt: skip
    for q in range(idx.size):
        k = idx[q]
        p = k % n_p
        sig = ln_k_prior[p, 1]
        z = (theta[k, 5] - ln_k_prior[p, 0]) / sig if np.isfinite(sig) else 0.0
        out[k] = ll[q] - 0.5 * z * z
    return out


@numba.njit(cache=True, nogil=True)
def log_lik_rows(
    theta, pulse, samples, n_valid, cos_water, dt, s, group_index, offset, poisson, floor, shot,
    exposure,
):  # fmt: skip
    """Log-likelihood of rows ``theta`` (N, 9), row ``k`` against ``samples[pulse[k]]``.

    Only the first ``n_valid[p]`` samples of pulse ``p`` count (the rest is padding). Gaussian
    law: ``-((y - mu)^2 / v + log v) / 2`` with ``v = floor + shot max(mu - offset, 0)``;
    Poisson: ``y log(e mu) - e mu`` with ``e = exposure[p, i]`` the live share of sample ``i``
    (dead time: a photon-counting record is Poisson of the rate times its live exposure;
    1 where every channel was live; ``-inf`` where ``e mu <= 0 < y``; the Gaussian law ignores
    it). Data-only constants dropped, as :func:`pipeline.uncertainty.waveform_model.
    log_likelihood`.
    """
    n = theta.shape[0]
    out = np.empty(n)
    mu = np.empty(samples.shape[1])
    for k in range(n):
        p = pulse[k]
        m = n_valid[p]
        row = mu[:m]
        model_row(theta[k], cos_water[p], row, dt, s, group_index, offset)
        y = samples[p]
        e = exposure[p]
        acc = 0.0
        if poisson:
            for i in range(m):
                lam = e[i] * row[i]
                if lam > 0.0:
                    acc += y[i] * math.log(lam) - lam
                elif y[i] > 0.0:
                    acc = -np.inf
                    break
        else:
            for i in range(m):
                v = floor + shot * max(row[i] - offset, 0.0)
                d = y[i] - row[i]
                acc -= 0.5 * (d * d / v + math.log(v))
        out[k] = acc
    return out
