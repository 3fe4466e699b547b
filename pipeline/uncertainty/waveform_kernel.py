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

The kernels compile with ``error_model="numpy"``: a float division by zero gives IEEE inf / NaN
instead of raising ``ZeroDivisionError``, which takes a test and a branch off every division
(4 % of the sampler's CPU). Every value a call that did not raise computes is the same, bit for
bit; NaN and ``+inf`` still end as :class:`~pipeline.errors.NumericalError` in the callers.
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


@numba.njit(cache=True, nogil=True, error_model="numpy")
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


@numba.njit(cache=True, nogil=True, error_model="numpy")
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


@numba.njit(cache=True, nogil=True, error_model="numpy")
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


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _c_part(u, r, s, band):
    """Normalised cumulative column of one exponential part at ``u`` (exact inside the band)."""
    if u <= -band:
        return 0.0
    if u < band:
        return _c_exact(u, r, s)
    return 1.0 - math.exp(min(-r * u + 0.5 * (r * s) ** 2, 0.0))


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _echo_band(centre, sigma, dt, m):
    """Samples ``[j0, j1)`` within ``BAND_Z`` sigmas of an echo at ``centre`` (s), of ``m``."""
    j0 = max(int(math.floor((centre - BAND_Z * sigma) / dt + 0.5)), 0)
    j1 = min(int(math.ceil((centre + BAND_Z * sigma) / dt + 0.5)), m)
    return j0, j1


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _add_echo(mu, centre, sigma, area, dt):
    """Add a Gaussian echo of ``area`` counts at ``centre`` (s) to the samples ``mu`` in place.

    Sample ``i`` integrates over ``[(i - 1/2) dt, (i + 1/2) dt)``; only the edges within
    ``BAND_Z`` sigmas of the centre are evaluated.
    """
    j0, j1 = _echo_band(centre, sigma, dt, mu.shape[0])
    if j1 <= j0:
        return
    prev = _phi(((j0 - 0.5) * dt - centre) / sigma)
    for j in range(j0, j1):
        nxt = _phi(((j + 0.5) * dt - centre) / sigma)
        mu[j] += area * (nxt - prev)
        prev = nxt


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _row_setup(th, cos_water, s, group_index, offset):
    """``(t_s, r, tau, fall, base, scale)`` of one parameter row.

    Surface time (s), attenuation ``r`` (1/s), in-water delay ``tau`` (s), ``exp(-r tau)``,
    baseline and the column's area scale.
    """
    t_s = th[1] * 1e-9
    r = math.exp(th[5]) * _C / group_index
    tau = 2.0 * group_index * th[0] / (_C * cos_water)
    fall = math.exp(-r * tau)
    base = offset + th[6]
    scale = math.exp(th[3]) / -math.expm1(-r * tau)
    return t_s, r, tau, fall, base, scale


@numba.njit(cache=True, nogil=True, error_model="numpy")
def model_row(th, cos_water, mu, dt, s, group_index, offset):
    """Mean samples of one parameter row ``th`` (9,) into ``mu`` (m,), offset included.

    Units and parameters as :func:`pipeline.uncertainty.waveform_model.expected_waveform`.
    """
    m = mu.shape[0]
    t_s, r, tau, fall, base, scale = _row_setup(th, cos_water, s, group_index, offset)
    band = BAND_Z * s
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
    _add_echoes(mu, th, t_s, tau, s, dt)


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _add_echoes(mu, th, t_s, tau, s, dt):
    """Add row ``th``'s surface echo, then its bottom echo, to ``mu`` in place (that order)."""
    _add_echo(mu, t_s, s * math.exp(th[8]), math.exp(th[2]), dt)
    _add_echo(mu, t_s + tau, s * math.exp(th[7]), math.exp(th[4]), dt)


@numba.njit(cache=True, nogil=True, error_model="numpy")
def echo_rows(theta, cos_water, n_samples, dt, s, group_index, offset):
    """:func:`expected_rows` of rows without a water column (N, n_samples), one ``cos_water``.

    The baseline and the two echoes only, added as :func:`model_row` adds them. For rows whose
    column area ``exp(th[3])`` is ~1e-304 (the depth scan's echo bases) the column's samples
    lie below the last bit of any sum they enter (``tests/uncertainty/test_posterior_start.py``
    checks the scan's start bit for bit), and forming it was most of those rows' cost.
    """
    n = theta.shape[0]
    out = np.empty((n, n_samples))
    for k in range(n):
        t_s, _, tau, _, base, _ = _row_setup(theta[k], cos_water, s, group_index, offset)
        out[k, :] = base
        _add_echoes(out[k], theta[k], t_s, tau, s, dt)
    return out


@numba.njit(cache=True, nogil=True, error_model="numpy")
def expected_rows(theta, cos_water, n_samples, dt, s, group_index, offset):
    """Mean samples (N, n_samples) of parameter rows ``theta`` (N, 9), ``cos_water`` (N,)."""
    n = theta.shape[0]
    out = np.empty((n, n_samples))
    for k in range(n):
        model_row(theta[k], cos_water[k], out[k], dt, s, group_index, offset)
    return out


@numba.njit(cache=True, nogil=True, error_model="numpy")
def log_post_rows(theta, samples, n_valid, cos_water, box, ln_k_prior, system, exposure):
    """Log posterior of walker rows ``theta`` (N, 9), row ``k`` for pulse ``k % P``.

    ``box`` (P, 19): each pulse's prior lower and upper bounds (9 + 9) and the last sample's
    time ``t_last_s``; ``ln_k_prior`` (P, 2) the normal prior's mean and sigma on ``ln k``
    (``inf``: none). ``-inf`` outside the box or with the bottom after ``t_last_s``, else
    :func:`log_lik_rows` plus the prior (flat in the box). ``system`` as
    :func:`log_lik_rows`' trailing arguments, in a tuple; ``exposure`` (P, m) as there.
    """
    n = theta.shape[0]
    thr = np.full(n, -np.inf)
    rest = np.zeros((samples.shape[0], samples.shape[1] + 1))
    return log_post_rows_bounded(
        theta, thr, rest, samples, n_valid, cos_water, box, ln_k_prior, system, exposure
    )


@numba.njit(cache=True, nogil=True, error_model="numpy")
def log_post_rows_bounded(
    theta, thr, rest, samples, n_valid, cos_water, box, ln_k_prior, system, exposure
):
    """:func:`log_post_rows`, or ``-inf`` for rows shown early to stay below ``thr`` (N,).

    ``rest`` (P, m + 1): ``rest[p, i]`` an upper bound of pulse ``p``'s log-likelihood terms
    from sample ``i`` on (:func:`~pipeline.uncertainty.posterior_loop.term_bounds`). A row's
    sum is given, to the bit, unless its partial sum plus that bound falls below its
    threshold, when the full sum would too: a Metropolis test with that threshold rejects it
    either way (early rejection: Solonen et al. 2012, *Bayesian Analysis* 7(3), 715-736), and
    the rest of the row is not computed.
    """
    out = np.empty(theta.shape[0])
    n_p = samples.shape[0]
    for k in range(theta.shape[0]):
        out[k] = log_post_one(
            theta[k], k % n_p, thr[k], rest, samples, n_valid, cos_water, box, ln_k_prior,
            system, exposure,
        )  # fmt: skip
    return out


@numba.njit(cache=True, nogil=True, error_model="numpy")
def log_post_one(th, p, thr, rest, samples, n_valid, cos_water, box, ln_k_prior, system, exposure):
    """One row ``th`` (9,) of pulse ``p``: :func:`log_post_rows_bounded`'s value.

    ``thr`` is the row's threshold; a pure function of its inputs (rows may run in any order,
    on any thread).
    """
    dt, s, group_index, offset, poisson, floor, shot, misfit = system
    inside = True
    for j in range(9):
        if not (box[p, j] <= th[j] <= box[p, 9 + j]):
            inside = False
    t_b = th[1] * 1e-9 + 2.0 * group_index * th[0] / (_C * cos_water[p])
    if not (inside and t_b <= box[p, 18]):
        return -np.inf
    sig = ln_k_prior[p, 1]
    z = (th[5] - ln_k_prior[p, 0]) / sig if np.isfinite(sig) else 0.0
    ll = _log_lik_row(
        th, cos_water[p], samples[p], exposure[p], n_valid[p], dt, s, group_index, offset,
        poisson, floor, shot, misfit, rest[p], thr + 0.5 * z * z,
    )  # fmt: skip
    return ll - 0.5 * z * z


@numba.njit(cache=True, nogil=True, error_model="numpy")
def log_lik_rows(
    theta, pulse, samples, n_valid, cos_water, dt, s, group_index, offset, poisson, floor, shot,
    misfit, exposure,
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
    none = np.zeros(samples.shape[1] + 1)
    for k in range(n):
        p = pulse[k]
        out[k] = _log_lik_row(
            theta[k], cos_water[p], samples[p], exposure[p], n_valid[p], dt, s, group_index,
            offset, poisson, floor, shot, misfit, none, -np.inf,
        )  # fmt: skip
    return out


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _log_lik_row(
    th, cos_water, y, e, m, dt, s, group_index, offset, poisson, floor, shot, misfit, rest, thr
):  # fmt: skip
    """One row's log-likelihood (:func:`log_lik_rows`), the model formed sample by sample.

    The samples' means are :func:`model_row`'s, added in its order (column, surface echo,
    bottom echo), so the same bits; the terms are summed in sample order. Returns ``-inf``
    once the partial sum plus ``rest[i + 1]`` (a bound of the terms after sample ``i``) is
    below ``thr``.
    """
    t_s, r, tau, fall, base, scale = _row_setup(th, cos_water, s, group_index, offset)
    band = BAND_Z * s
    t_b = t_s + tau
    sig_s, sig_b = s * math.exp(th[8]), s * math.exp(th[7])
    a_s, a_b = math.exp(th[2]), math.exp(th[4])
    j0s, j1s = _echo_band(t_s, sig_s, dt, m)
    j0b, j1b = _echo_band(t_b, sig_b, dt, m)
    ps = _phi(((j0s - 0.5) * dt - t_s) / sig_s)
    pb = _phi(((j0b - 0.5) * dt - t_b) / sig_b)
    u = -0.5 * dt - t_s
    prev = _c_part(u, r, s, band) - fall * _c_part(u - tau, r, s, band)
    acc = 0.0
    # the logarithms are the cost: an empty sample needs none (0 log(lam) - lam is -lam
    # exactly) and a repeated argument (the background before the surface and after the
    # bottom, where the mean is the baseline) reuses the last one: the same sums, bit for bit
    arg, log_arg = -1.0, 0.0
    for i in range(m):
        u = (i + 0.5) * dt - t_s
        if u >= tau + band:
            nxt = 1.0 - fall
        else:
            nxt = _c_part(u, r, s, band) - fall * _c_part(u - tau, r, s, band)
        mu = base + (nxt - prev) * scale
        prev = nxt
        surf = 0.0
        if j0s <= i < j1s:
            q = _phi(((i + 0.5) * dt - t_s) / sig_s)
            surf = a_s * (q - ps)
            mu += surf
            ps = q
        if j0b <= i < j1b:
            q = _phi(((i + 0.5) * dt - t_b) / sig_b)
            mu += a_b * (q - pb)
            pb = q
        if poisson:
            lam = e[i] * mu
            if lam > 0.0:
                if y[i] == 0.0:
                    acc -= lam
                else:
                    if lam != arg:
                        arg, log_arg = lam, math.log(lam)
                    acc += y[i] * log_arg - lam
            elif y[i] > 0.0:
                return -np.inf
        else:
            v = floor + shot * max(mu - offset, 0.0)
            if misfit > 0.0:
                v += (misfit * surf) ** 2
            d = y[i] - mu
            if v != arg:
                arg, log_arg = v, math.log(v)
            acc -= 0.5 * (d * d / v + log_arg)
        if acc + rest[i + 1] < thr:
            return -np.inf
    return acc
