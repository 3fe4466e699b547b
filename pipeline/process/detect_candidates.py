"""The bottom candidates of a block of waveforms and the one picked, in compiled row loops.

:func:`~pipeline.process.detect.detect_full_waveform` looks for bottom echoes as peaks of the
residual to the flank trend that stand above the local noise (electronic plus the shot noise
of the trend they sit on), after the surface and before the window's last samples. Written as
whole-array numpy, that test made a dozen ``(pulses, samples)`` temporaries (a quarter of
detection's time); here each row is walked once. Every comparison and every product is the
one the array expressions made, in their order (no fused multiply-add), so the candidates,
the picked sample and the thresholds are the same, to the bit (``tests/process/
test_detect_candidates.py`` checks the kernels against those expressions).
"""

from __future__ import annotations

import math

import numba
import numpy as np

__all__ = [
    "bottom_candidates",
    "pick_bottom",
    "strongest_before",
    "local_variance",
    "first_strong_peak",
    "row_abs_max",
]


def local_variance(filt, resid, noise_f, shot_noise_counts: float, kernel_sq: float):
    """Electronic plus shot-noise variance of the filtered samples under a bottom candidate.

    ``noise_f² + F·G · max(filt − resid, 0) · Σk²``: the trend the candidate sits on
    (``filt − resid``) sets its shot noise. Shapes broadcast (``noise_f`` per row).
    """
    trend = np.maximum(filt - resid, 0.0)
    return noise_f**2 + shot_noise_counts * trend * kernel_sq


@numba.njit(cache=True, nogil=True)
def bottom_candidates(
    filt, resid, noise_f, after_s, gap, has_s, shot_noise_counts, kernel_sq, thr_sigma, i_zone
):
    """Which samples are bottom candidates, and which pulses have one near the surface.

    Parameters
    ----------
    filt, resid : (n, m) float64
        Filtered waveforms and their residual to the flank trend.
    noise_f : (n,) float64
        Noise σ of a filtered sample.
    after_s : (n,) float64
        A candidate lies after this sample (the surface plus the separation) ...
    gap : int
        ... and before sample ``m − gap``.
    has_s : (n,) bool
        The pulse has a surface (no candidate without one).
    shot_noise_counts, kernel_sq, thr_sigma : float
        ``F·G``, the filter's ``Σk²``, and the threshold in σ.
    i_zone : (n,) int64
        Last sample of the zone below the surface where the column is carried back.

    Returns
    -------
    cand : (n, m) bool
        A residual peak (``>=`` the sample before, ``>`` the one after) above the local
        threshold, inside the bounds.
    near : (n,) bool
        Some candidate at or before ``i_zone``.
    """
    n, m = filt.shape
    cand = np.zeros((n, m), np.bool_)
    near = np.zeros(n, np.bool_)
    for p in range(n):
        if not has_s[p]:
            continue
        nf2 = noise_f[p] * noise_f[p]
        for c in range(1, m - 1):
            if not (c > after_s[p] and c < m - gap):
                continue
            r = resid[p, c]
            if not (r >= resid[p, c - 1] and r > resid[p, c + 1]):
                continue
            var = nf2 + shot_noise_counts * max(filt[p, c] - r, 0.0) * kernel_sq
            if r > thr_sigma * math.sqrt(var):
                cand[p, c] = True
                if c <= i_zone[p]:
                    near[p] = True
    return cand, near


@numba.njit(cache=True, nogil=True)
def pick_bottom(cand, resid, sep, last):
    """Each pulse's bottom sample among its candidates, and whether one lies beyond it.

    Parameters
    ----------
    cand : (n, m) bool
    resid : (n, m) float64
    sep : float
        Minimum separation of two returns, samples.
    last : bool
        ``bottom_pick = "last"``: the strongest candidate within ``sep`` of the latest one;
        else the strongest of all.

    Returns
    -------
    has_b : (n,) bool
    i_b : (n,) int64
        The candidate of the largest residual (the first of equals; 0 without one).
    beyond : (n,) bool
        A candidate more than ``sep`` after ``i_b``.
    """
    n, m = cand.shape
    has_b = np.zeros(n, np.bool_)
    i_b = np.zeros(n, np.int64)
    beyond = np.zeros(n, np.bool_)
    for p in range(n):
        latest = -1
        for c in range(m - 1, -1, -1):
            if cand[p, c]:
                latest = c
                break
        if latest < 0:
            continue
        has_b[p] = True
        lo = latest - sep if last else -np.inf
        best, kb = -np.inf, 0
        for c in range(m):
            if cand[p, c] and c >= lo and resid[p, c] > best:
                best, kb = resid[p, c], c
        i_b[p] = kb
        beyond[p] = latest > kb + sep
    return has_b, i_b, beyond


@numba.njit(cache=True, nogil=True)
def strongest_before(cand, resid, stop):
    """Each pulse's candidate of the largest residual before sample ``stop`` (exclusive).

    Parameters
    ----------
    cand : (n, m) bool
    resid : (n, m) float64
    stop : (n,) float64
        Samples ``c < stop`` are looked at.

    Returns
    -------
    has : (n,) bool
    i : (n,) int64
        The first of the largest (0 without a candidate).
    """
    n, m = cand.shape
    has = np.zeros(n, np.bool_)
    idx = np.zeros(n, np.int64)
    for p in range(n):
        best = -np.inf
        for c in range(m):
            if not c < stop[p]:
                break
            if cand[p, c] and (not has[p] or resid[p, c] > best):
                best, idx[p], has[p] = resid[p, c], c, True
    return has, idx


@numba.njit(cache=True, nogil=True)
def row_abs_max(x):
    """``np.max(np.abs(x), axis=1)`` of ``(n, m)`` rows, ``m >= 1`` (NaN where a row has one)."""
    n, m = x.shape
    out = np.empty(n)
    for p in range(n):
        top = abs(x[p, 0])
        for c in range(1, m):
            v = abs(x[p, c])
            if v > top or v != v:
                top = v
                if v != v:
                    break
        out[p] = top
    return out


@numba.njit(cache=True, nogil=True)
def first_strong_peak(filt, thr, k):
    """Each row's first peak above its threshold, past the noise window.

    A peak: ``>=`` the sample before, ``>`` the one after (never the first or last sample);
    strong: above ``thr`` ``(n,)``; from sample ``k`` on. Returns ``has`` ``(n,)`` bool and
    the sample ``(n,)`` int64 (0 without one).
    """
    n, m = filt.shape
    has = np.zeros(n, np.bool_)
    idx = np.zeros(n, np.int64)
    for p in range(n):
        for c in range(max(k, 1), m - 1):
            v = filt[p, c]
            if v >= filt[p, c - 1] and v > filt[p, c + 1] and v > thr[p]:
                has[p], idx[p] = True, c
                break
    return has, idx
