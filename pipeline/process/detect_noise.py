"""Noise σ of digitised waveforms from their first differences, right for integer samples.

The median absolute deviation (MAD) of first differences ignores the few samples a return
spans, but on integer samples it is quantised: with σ = 1.5 counts of Gaussian noise half the
differences are 0 or ±1, the MAD is 1 and σ comes out 1.05 (the digitised noise has 1.53), so
a "5 σ" threshold sits at ~3.4 σ. With σ well under a count (or Poisson noise of a dim
background) more than half the differences are 0 and the MAD collapses to 0.

:func:`difference_noise_sigma` starts from the MAD (raised to the smallest non-zero difference,
the data's own quantum, so it cannot collapse) and refines it by a clipped second moment, the
standard iterated "sigma clipping" (e.g. Stetson's robust rms; astropy ``sigma_clipped_stats``):
the mean square of the differences within ``clip`` σ of their median, divided by the share of a
Gaussian's variance inside ``±clip`` σ. A second moment, unlike a rank statistic, is not
quantised: it is the variance of the digitised samples, quantisation noise included (Sheppard:
σ² + Δ²/12 for σ ≳ Δ/2), which is what the matched filter passes. Echoes, many σ out, stay clipped.

:func:`window_baseline`: the baseline is the mean of the noise window's samples within
``CLIP_SIGMA`` σ of their median, not their median: a median of a few integer samples is itself
an integer, off by a whole count (~1 σ of the filtered noise) in a third of the pulses. The
baseline's own error (σ/√k, the same for every sample of the pulse) is returned so the surface
threshold can add it.
"""

from __future__ import annotations

import numba
import numpy as np
from scipy.special import ndtr

from pipeline.constants import MAD_TO_SIGMA
from pipeline.process.row_kernels import COUNT_HALF, counted_median, median_of, pairwise_sum

__all__ = ["difference_noise_sigma", "window_baseline"]

#: Clip at this many σ: a Gaussian loses 0.05 % of its samples and 0.6 % of its variance there
#: (corrected), while an echo's edges, tens of σ, stay out.
CLIP_SIGMA = 4.0
#: Refinements of the clipped moment; from the MAD start (within ~30 % of σ) two converge.
N_ITER = 3


def _inside_variance_share(c: np.ndarray) -> np.ndarray:
    """Variance of a standard normal truncated to ``|z| <= c``: ``1 − 2 c φ(c) / (2Φ(c) − 1)``."""
    c = np.maximum(c, 1e-3)
    phi = np.exp(-0.5 * c * c) / np.sqrt(2.0 * np.pi)
    return 1.0 - 2.0 * c * phi / (2.0 * ndtr(c) - 1.0)


def _row_median(x: np.ndarray) -> np.ndarray:
    """``np.median(x, axis=1)``, bit for bit, from one partition at the middle rank(s).

    ``np.median`` also partitions at the last rank to find NaNs (a second selection
    over every row: ~70 % more than the middle rank alone); a NaN check is cheaper.
    The middle pair is averaged as ``np.mean`` does it, ``(lo + hi) / 2``.

    Parameters
    ----------
    x : (n, m) ndarray
        Float rows, ``m >= 1``.

    Returns
    -------
    (n,) ndarray
        Each row's median (NaN for a row holding a NaN).
    """
    m = x.shape[1]
    h = m // 2
    if m % 2:
        med = np.partition(x, h, axis=1)[:, h]
    else:
        part = np.partition(x, [h - 1, h], axis=1)
        med = (part[:, h - 1] + part[:, h]) / 2.0
    nan = np.isnan(x).any(axis=1)
    return np.where(nan, np.nan, med) if nan.any() else med


def difference_noise_sigma(y: np.ndarray) -> np.ndarray:
    """Per-row noise σ of the samples, from their first differences (clipped second moment).

    Parameters
    ----------
    y : (n, m) ndarray
        Waveforms (any linear unit; integer codes or floats), ``m >= 3``.

    Returns
    -------
    sigma : (n,) ndarray
        Noise σ of one sample (≥ 0; 0 only for a row whose differences are all equal). For
        white noise it is ``std(diff) / √2``; slow trends (a baseline, the water column's
        decay) cancel in the differences, and echoes are clipped out.

    Notes
    -----
    Each row's differences are formed, centred and clipped inside compiled loops
    (:func:`_difference_start`, :func:`_clipped_moment`), their squares added in numpy's
    order (:func:`~pipeline.process.row_kernels.pairwise_sum`): the figures of the
    whole-array code this replaced, to the bit, without its ``(n, m)`` temporaries.
    """
    y = np.ascontiguousarray(y, dtype=np.float64)
    if y.ndim != 2 or y.shape[1] < 2:
        raise ValueError(f"difference_noise_sigma needs rows of >= 2 samples; got {y.shape}")
    # (the constant is passed, not read by the kernel: a cached kernel keeps the values it
    # was compiled with, and numba checks only this file's date)
    counts = np.zeros(2 * COUNT_HALF + 1, np.int64)  # the counted medians' band
    med, quantum, s = _difference_start(y, MAD_TO_SIGMA, counts)
    for _ in range(N_ITER):
        # never clip a one-quantum step: at σ under a count it is most of the noise
        lim = np.maximum(CLIP_SIGMA * s, 1.5 * quantum)
        total, count = _clipped_moment(y, med, lim)
        ms = total / np.maximum(count, 1)
        share = _inside_variance_share(lim / np.maximum(s, 1e-300))
        s = np.sqrt(ms / share)
    return s / np.sqrt(2.0)


@numba.njit(cache=True, nogil=True)
def _difference_start(y, mad_to_sigma, counts):
    """Per row: the differences' median, their quantum and the MAD start of σ, each ``(n,)``.

    The quantum is the smallest non-zero centred difference (integer codes: 1; 0 without
    any); the start ``max(MAD_TO_SIGMA · MAD, quantum)``. A row holding a NaN gives NaN.
    ``counts``: :func:`~pipeline.process.row_kernels.counted_median`'s zeroed band.
    """
    n, m = y.shape
    k = m - 1
    med = np.empty(n)
    quantum = np.zeros(n)
    start = np.empty(n)
    buf = np.empty(k)
    twice = np.empty(k)
    for p in range(n):
        nan = False
        for c in range(k):
            buf[c] = y[p, c + 1] - y[p, c]
            nan |= buf[c] != buf[c]
        if nan:
            med[p] = np.nan
            start[p] = np.nan
            continue
        # integer codes: counted (the same median, ~4x faster than selecting); else selected
        md = counted_median(buf, k, counts)
        if md != md:
            md = median_of(buf, k)
        q = np.inf
        for c in range(k):
            a = abs((y[p, c + 1] - y[p, c]) - md)
            buf[c] = a
            twice[c] = 2.0 * a  # an integer also where the median is a half-integer
            if a > 0.0 and a < q:
                q = a
        q = q if q < np.inf else 0.0
        # (2 lower + 2 upper) / 2 is lower + upper exactly: halved, median_of's own figure
        mad_a = 0.5 * counted_median(twice, k, counts)
        if mad_a != mad_a:
            mad_a = median_of(buf, k)
        mad = mad_to_sigma * mad_a
        med[p] = md
        quantum[p] = q
        start[p] = mad if (mad >= q or mad != mad) else q
    return med, quantum, start


@numba.njit(cache=True, nogil=True)
def _clipped_moment(y, med, lim):
    """Per row: the sum of the centred differences' squares within ``lim``, and their count."""
    n, m = y.shape
    k = m - 1
    total = np.empty(n)
    count = np.zeros(n, np.int64)
    sq = np.empty(k)
    for p in range(n):
        c_in = 0
        for c in range(k):
            d = (y[p, c + 1] - y[p, c]) - med[p]
            if abs(d) <= lim[p]:
                sq[c] = d * d
                c_in += 1
            else:
                sq[c] = 0.0
        total[p] = pairwise_sum(sq, 0, k)
        count[p] = c_in
    return total, count


def window_baseline(y: np.ndarray, k: int, sigma: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-row baseline from the leading ``k`` samples, and its standard error.

    Parameters
    ----------
    y : (n, m) ndarray
        Waveforms.
    k : int
        Leading samples holding noise only (``1 <= k <= m``).
    sigma : (n,) ndarray
        Noise σ of one sample (:func:`difference_noise_sigma`).

    Returns
    -------
    baseline, baseline_sigma : (n,) ndarray
        Clipped mean of the window, and σ / √(samples averaged).
    """
    w = np.asarray(y[:, :k], dtype=np.float64)
    med = _row_median(w)
    inside = np.abs(w - med[:, None]) <= CLIP_SIGMA * sigma[:, None]
    n_in = inside.sum(axis=1)
    # an all-equal window (noise-free) keeps every sample: n_in >= 1 always (the median's own)
    mean = np.where(inside, w, 0.0).sum(axis=1) / np.maximum(n_in, 1)
    base = np.where(n_in > 0, mean, med)
    return base, sigma / np.sqrt(np.maximum(n_in, 1))
