"""The surface time from a Gaussian echo on the water-column onset, fitted near the surface peak.

The water-column (volume backscatter) return starts at the surface and decays at the rate
``k`` of the column (Beer-Lambert down and up, :func:`~pipeline.process.detect_merged.
column_decay`): through the system response it is an exponentially modified Gaussian,
``h_k(u) = exp(−k u + (k σ)²/2) Φ(u/σ − k σ)`` with ``u = t − t_s`` (``Φ(u/σ)`` for ``k = 0``).
It pulls the plain peak late, and where the specular echo vanishes (calm water off nadir,
Guenther 1985, "surface uncertainty": the interface return is then the volume onset alone)
its peak lies ``σ (u* + k σ)`` after the surface, ``φ(u*)/Φ(u*) = k σ``: one to two samples,
the slower the decay the later (the calm-water surface ~0.2 m low of issue 13). The
exponential-decomposition model of the column return follows Schwarz et al. (2017, PFG 85,
"Exponential decomposition with implicit deconvolution of lidar backscatter from the water
column").

:func:`surface_step_fit` fits ``A g(t − t_s) + B h_k(t − t_s)`` (``A, B ≥ 0`` by non-negative
linear least squares), and the onset ``B h_k`` alone, for each candidate ``t_s`` on a
0.02-sample grid from 4 samples before the peak to 0.5 after (:data:`STEP_GRID`; the volume
onset alone peaks up to ~3 samples after the surface), with ``k`` the pulse's own measured
column decay; it keeps the candidate with the smallest residual and refines it by a parabola
through the residuals. The echo term is kept only where its amplitude at the best candidate
is significant (``echo_sigma`` standard errors, ``detect.surface_echo_sigma``): free to sit on
the noise of a weak onset it pulls the time late by ~0.5 sample at SNR 4 (synthetic Poisson
waveforms), which the onset alone does not.

The candidates and the fitted samples sit at fixed offsets from the peak sample, so ``g`` and
``h_k`` at ``(j − c_k)/σ`` (sample offset ``j``, candidate offset ``c_k``) and their Gram sums
do not depend on the pulse: they are tabulated once per call for each decay of
:data:`DECAY_GRID` (a pulse's onset is interpolated, linearly in log decay, between the two
around its own), and a compiled kernel (numba, cached on disk) forms each pulse's Gram sums,
projections and residuals. Only a pulse whose window is cut by the waveform's ends evaluates
its own ``g`` and ``h_k``. Each pulse's result depends on its own samples alone (a fixed loop
order), whatever the batch.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from scipy.special import ndtr

__all__ = ["surface_step_fit", "STEP_GRID", "DECAY_GRID", "column_onset"]

#: Candidate surface times, samples from the peak sample (0.02-sample grid, 4 before to 0.5
#: after: the column onset only pulls the peak late, by up to ~3 samples when it is alone).
STEP_GRID = np.arange(-4.0, 0.5001, 0.02)
#: Column decays tabulated (1/sample): 0 (a plain smoothed step) and 60 from 0.002 to 1 (11 %
#: apart; a pulse interpolates between the two around its own decay, linearly in log).
DECAY_GRID = np.concatenate([[0.0], np.geomspace(0.002, 1.0, 60)])


def column_onset(u: np.ndarray, sigma: float, decay: float) -> np.ndarray:
    """The volume return's onset through the response: ``exp(−k u + (kσ)²/2) Φ(u/σ − kσ)``.

    Parameters
    ----------
    u : ndarray
        Time after the surface, samples (any shape).
    sigma : float
        σ of the (filtered) system response, samples.
    decay : float
        Column decay ``k``, 1/sample (0: the smoothed step ``Φ(u/σ)``).
    """
    ks = decay * sigma
    # the exponent is bounded where Φ is not negligible; clip it where Φ underflows anyway
    expo = np.minimum(-decay * u + 0.5 * ks * ks, 700.0)
    return np.exp(expo) * ndtr(u / sigma - ks)


@numba.njit(cache=True, nogil=True)
def _onset(z: float, ks: float) -> float:
    """:func:`column_onset` at ``z = u/σ`` with ``ks = k σ`` (compiled)."""
    expo = min(-ks * z + 0.5 * ks * ks, 700.0)
    return math.exp(expo) * 0.5 * math.erfc(-(z - ks) / math.sqrt(2.0))


@numba.njit(cache=True, nogil=True)
def _nnls2(yy, gg, hh, gh, gy, hy):
    """``y ≈ a g + b h`` with ``a, b ≥ 0`` from the Gram sums: residual and ``a``."""
    det = gg * hh - gh * gh
    if det > 1e-12 * gg * hh:
        a = (hh * gy - gh * hy) / det
        b = (gg * hy - gh * gy) / det
        if a >= 0.0 and b >= 0.0:
            return yy - a * gy - b * hy, a
    # a bound is active: the better of the single terms (or neither)
    best, a_best = yy, 0.0
    if gy > 0.0 and yy - gy * gy / gg < best:
        best, a_best = yy - gy * gy / gg, gy / gg
    if hy > 0.0 and hh > 0.0 and yy - hy * hy / hh < best:
        best, a_best = yy - hy * hy / hh, 0.0
    return best, a_best


@numba.njit(cache=True, nogil=True)
def _step_sse(filt, i_peak, k_idx, k_w, offsets, grid, sg, decay, g_tab, h_tab, gg_tab, infl):
    """Per pulse and candidate: residuals of echo + onset and of the onset alone; echo SNR.

    The echo's SNR is its amplitude over its standard error (residual noise, ``infl`` for the
    filtered samples' correlation).
    """
    n, m = filt.shape
    k_n, w_n = g_tab.shape
    sse = np.empty((n, k_n))
    sse1 = np.empty((n, k_n))
    snr = np.zeros((n, k_n))
    y = np.empty(w_n)
    for p in range(n):
        i = i_peak[p]
        q, wq = k_idx[p], k_w[p]
        ks = decay[p] * sg
        cut = i + offsets[0] < 0 or i + offsets[w_n - 1] > m - 1
        yy = 0.0
        for j in range(w_n):
            c = min(max(i + offsets[j], 0), m - 1)
            y[j] = filt[p, c]
            yy += y[j] * y[j]
        for k in range(k_n):
            gg = hh = gh = gy = hy = 0.0
            for j in range(w_n):
                if cut:  # the window leaves the waveform: this pulse's own clipped columns
                    c = min(max(i + offsets[j], 0), m - 1)
                    z = (c - (i + grid[k])) / sg
                    g = math.exp(-0.5 * z * z)
                    h = _onset(z, ks)
                    gg += g * g
                else:  # between the two tabulated decays around the pulse's own (log-linear)
                    g = g_tab[k, j]
                    h = (1.0 - wq) * h_tab[q, k, j] + wq * h_tab[q + 1, k, j]
                hh += h * h
                gh += g * h
                gy += g * y[j]
                hy += h * y[j]
            if not cut:
                gg = gg_tab[k]
            sse[p, k], a = _nnls2(yy, gg, hh, gh, gy, hy)
            sse1[p, k] = yy - hy * hy / hh if (hy > 0.0 and hh > 0.0) else yy
            det = gg * hh - gh * gh
            if a > 0.0 and det > 1e-12 * gg * hh:
                var_a = max(sse[p, k], 0.0) / max(w_n - 3, 1) * infl * hh / det
                snr[p, k] = a / math.sqrt(var_a) if var_a > 0.0 else np.inf
    return sse, sse1, snr


def decay_index(decay: np.ndarray | None, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each pulse's decay (≥ 0, finite), its :data:`DECAY_GRID` row and the next row's weight.

    The row is the tabulated decay below the pulse's, the weight linear in log decay; row 0,
    weight 0 (the step) below the smallest tabulated decay.
    """
    if decay is None:
        return np.zeros(n), np.zeros(n, dtype=np.int64), np.zeros(n)
    k = np.asarray(decay, dtype=np.float64)
    k = np.where(np.isfinite(k) & (k > 0.0), np.minimum(k, DECAY_GRID[-1]), 0.0)
    logs = np.log(DECAY_GRID[1:])
    lk = np.log(np.where(k > 0, k, 1.0))
    row = np.clip(np.searchsorted(logs, lk, side="right"), 1, logs.size - 1)  # grid[row] <= k
    w = np.clip((lk - logs[row - 1]) / (logs[row] - logs[row - 1]), 0.0, 1.0)
    # below the smallest tabulated decay the onset is a step over the fitted window
    small = k < DECAY_GRID[1]
    return np.where(small, 0.0, k), np.where(small, 0, row), np.where(small, 0.0, w)


def surface_step_fit(
    filt: np.ndarray,
    i_peak: np.ndarray,
    sg: float,
    decay: np.ndarray | None = None,
    echo_sigma: float | None = None,
    with_echo_time: bool = False,
) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
    """Surface time (fractional sample) of each waveform from the echo + column-onset fit.

    Parameters
    ----------
    filt : (n, m) ndarray
        Matched-filtered, baseline-free waveforms.
    i_peak : (n,) int ndarray
        Sample of each surface peak.
    sg : float
        σ of the filtered system response, samples.
    decay : (n,) ndarray, optional
        Each pulse's measured column decay, 1/sample (0 or None: the onset is a smoothed step).
    echo_sigma : float, optional
        The surface echo (Gaussian) term is kept only where its fitted amplitude stands this
        many standard errors above 0; elsewhere the onset alone times the surface (an echo
        term free to sit on noise pulls a noisy onset late). None: always kept.
    with_echo_time : bool
        Also return the time of the fit with the echo term kept (a start for later fits that
        model the echo, :func:`~pipeline.process.detect_merged.merged_bottoms`).

    Returns
    -------
    (n,) ndarray, or two
        Fitted surface time, samples from the first (and the echo-kept one).
    """
    filt = np.ascontiguousarray(filt, dtype=np.float64)
    i_peak = np.asarray(i_peak, dtype=np.int64)
    n = filt.shape[0]
    half_lo = int(math.ceil(3.0 * sg - STEP_GRID[0]))
    half_hi = int(math.ceil(2.0 * sg + STEP_GRID[-1]))
    offsets = np.arange(-half_lo, half_hi + 1, dtype=np.int64)
    u = offsets[None, :] - STEP_GRID[:, None]  # (k, w): the same for every pulse
    g = np.exp(-0.5 * (u / sg) ** 2)
    h = np.stack([column_onset(u, sg, kd) for kd in DECAY_GRID])  # (decays, k, w)
    k_dec, k_row, k_w = decay_index(decay, n)
    # noise of the filtered samples is correlated over ~2√π σ_raw samples (σ_raw = sg/√2)
    infl = max(1.0, 2.0 * math.sqrt(math.pi) * sg / math.sqrt(2.0))
    sse2, sse1, snr = _step_sse(
        filt, i_peak, k_row, k_w, offsets, STEP_GRID, float(sg), k_dec, g, h, (g * g).sum(1), infl
    )
    sse = sse2
    if echo_sigma is not None:
        best = np.argmin(sse2, axis=1)
        echo = snr[np.arange(n), best] >= echo_sigma
        # the onset alone only where it is whole in the waveform (a window cut by the record's
        # start repeats its first sample, which an onset fits as a step at the edge) and has a
        # minimum inside the candidates (at the first one it found no onset to time)
        cut = (i_peak + offsets[0] < 0) | (i_peak + offsets[-1] > filt.shape[1] - 1)
        inside = np.argmin(sse1, axis=1) > 0
        sse = np.where((echo | cut | ~inside)[:, None], sse2, sse1)
    t_sel = _refined(sse, i_peak)
    return (t_sel, _refined(sse2, i_peak)) if with_echo_time else t_sel


def _refined(sse: np.ndarray, i_peak: np.ndarray) -> np.ndarray:
    """The best candidate of each row of ``sse``, refined by a parabola (fractional sample)."""
    n = sse.shape[0]
    k = np.clip(np.argmin(sse, axis=1), 1, STEP_GRID.size - 2)
    rows = np.arange(n)
    s0, s1, s2 = sse[rows, k - 1], sse[rows, k], sse[rows, k + 1]
    # parabola through the three residuals around the minimum: sub-grid time
    curv = s0 - 2.0 * s1 + s2
    off = np.where(curv > 0, 0.5 * (s0 - s2) / np.where(curv > 0, curv, 1.0), 0.0)
    return i_peak + STEP_GRID[k] + 0.02 * np.clip(off, -1.0, 1.0)
