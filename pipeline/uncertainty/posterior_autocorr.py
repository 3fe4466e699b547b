"""Integrated autocorrelation times of many chains at once, as emcee estimates them.

:func:`integrated_time_blocks` is :func:`emcee.autocorr.integrated_time` (``tol=0``) for every
pulse and parameter of a batch: each walker's normalised autocorrelation function, averaged
over the walkers, summed to ``taus = 2 cumsum(f) - 1`` and cut at Sokal's window (the first lag
``M >= c taus[M]``). The sampler checks convergence with it every ``chunk_steps``.

Only the lags up to the window matter, and for a mixing chain the window is short (five
times its autocorrelation time, ~2 stored steps for most parameters here): those lags are
summed directly (:func:`_tau_direct`, ``n_walkers x n_steps`` products per lag), a fraction
of the cost of the FFT of the whole chain (the FFT was a fifth of the sampler's time); a
series whose window lies beyond ``MAX_DIRECT_LAGS`` takes the FFT
(:func:`_integrated_time_fft`). Both give emcee's figure to rounding
(``tests/uncertainty/test_waveform_kernel.py``).
"""

from __future__ import annotations

import numba
import numpy as np
import scipy.fft

__all__ = ["integrated_time_blocks", "MAX_DIRECT_LAGS"]

#: Lags summed directly before a series falls back to the FFT. The direct sums cost
#: ``n_walkers x n_steps`` products per lag (vectorised); a window of 256 stored lags is an
#: autocorrelation time of ~50 stored steps, a chain that cannot converge within
#: ``max_steps``; the FFT bounds the cost of such series.
MAX_DIRECT_LAGS = 256


def integrated_time_blocks(
    x: np.ndarray, pulses: np.ndarray | None = None, n_steps: int | None = None, c: float = 5.0
) -> np.ndarray:
    """Integrated autocorrelation times of many chains at once, as emcee estimates them.

    Parameters
    ----------
    x : (n, n_walkers, P_all, 9) ndarray
        Stored chains.
    pulses : (P,) int array, optional
        The pulses (third axis of ``x``) wanted; default all.
    n_steps : int, optional
        Their stored steps (the leading ``n_steps`` of ``x``); default ``n``.
    c : float
        Sokal's window constant (emcee's default 5).

    Returns
    -------
    (P, 9) ndarray
        In stored steps; NaN where a series is constant (emcee gives NaN there too).
    """
    pulses = np.arange(x.shape[2]) if pulses is None else np.asarray(pulses, dtype=np.int64)
    n_steps = x.shape[0] if n_steps is None else int(n_steps)
    tau = _tau_direct(np.ascontiguousarray(x), pulses, n_steps, float(c), MAX_DIRECT_LAGS)
    far = np.isinf(tau)  # a window beyond the direct lags: those series by FFT
    if far.any():
        sub = x[:n_steps][:, :, pulses][:, :, far]
        tau[far] = _integrated_time_fft(sub[:, :, :, None], c)[:, 0]
    return tau


# reassociated sums (vectorised lag products; rounding-level changes), 0/0 = NaN as numpy
@numba.njit(cache=True, nogil=True, error_model="numpy", fastmath={"reassoc", "contract"})
def _tau_direct(x, pulses, n_t, c, max_lags):
    """The emcee estimate per series of ``x[:n_t, :, pulses]`` by direct lag sums.

    ``x`` (steps, walkers, P_all, 9) as stored, read in place (no gathered copy).
    ``inf`` where no lag up to ``max_lags`` closes the window (the caller takes the FFT
    there); NaN where a walker's series is constant (its normalised function is 0/0).
    """
    nw, n_j = x.shape[1], x.shape[3]
    n_p = pulses.shape[0]
    out = np.empty((n_p, n_j))
    z = np.empty((nw, n_t))
    norm = np.empty(nw)
    for p in range(n_p):
        for j in range(n_j):
            for w in range(nw):
                mean = 0.0
                for t in range(n_t):
                    z[w, t] = x[t, w, pulses[p], j]  # one strided read, a contiguous series
                    mean += z[w, t]
                mean /= n_t
                a0 = 0.0
                for t in range(n_t):
                    z[w, t] -= mean
                    a0 += z[w, t] * z[w, t]
                norm[w] = a0
            cum, res = 0.0, np.inf
            for lag in range(min(n_t, max_lags + 1)):
                f = 0.0
                for w in range(nw):
                    a = 0.0
                    for t in range(n_t - lag):
                        a += z[w, t] * z[w, t + lag]
                    f += a / norm[w]
                cum += f / nw
                taus = 2.0 * cum - 1.0
                if lag >= c * taus:
                    res = taus
                    break
                if np.isnan(taus):
                    res = np.nan
                    break
            else:
                if n_t <= max_lags + 1:  # no lag closes the window: emcee takes taus[0]
                    res = 1.0
            out[p, j] = res
    return out


def _integrated_time_fft(x: np.ndarray, c: float = 5.0) -> np.ndarray:
    """Integrated autocorrelation times of many chains at once, as emcee estimates them.

    :func:`emcee.autocorr.integrated_time` (``tol=0``) for every pulse and parameter in one
    FFT along the steps: the normalised autocorrelation function of each walker's series,
    averaged over the walkers, summed to ``taus = 2 cumsum(f) - 1`` and cut at Sokal's window
    (the first lag ``M >= c taus[M]``). emcee loops over walkers and parameters in Python,
    which cost more than the model once the model was compiled.

    Parameters
    ----------
    x : (n_steps, n_walkers, P, 9) ndarray
        Stored chains.
    c : float
        Sokal's window constant (emcee's default 5).

    Returns
    -------
    (P, 9) ndarray
        In stored steps; NaN where a series is constant (emcee gives NaN there too).
    """
    n_t = x.shape[0]
    # zero padding to >= 2 n_t - 1 makes the circular correlation the linear one: emcee pads
    # to twice the next power of two, any 5-smooth length that long gives the same function
    # (to rounding) for up to half the transform
    n_fft = scipy.fft.next_fast_len(max(2 * n_t - 1, 1), real=True)
    y = np.moveaxis(x - x.mean(axis=0), 0, -1).copy()  # steps last: contiguous transforms
    f = np.fft.rfft(y, n=n_fft, axis=-1)
    acf = np.fft.irfft(f.real**2 + f.imag**2, n=n_fft, axis=-1)[..., :n_t]
    with np.errstate(invalid="ignore", divide="ignore"):  # a stuck chain: acf 0/0
        acf = acf / acf[..., :1]
    taus = 2.0 * np.cumsum(np.moveaxis(acf.mean(axis=0), -1, 0), axis=0) - 1.0  # (n_t, P, 9)
    m = np.arange(n_t)[:, None, None] < c * taus
    window = np.where(m.any(axis=0), np.argmin(m, axis=0), n_t - 1)
    return np.take_along_axis(taus, window[None], axis=0)[0]
