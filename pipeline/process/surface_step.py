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
through the residuals. The echo term is taken as it is where the echo is clear: significant
(``echo_sigma`` standard errors, ``detect.surface_echo_sigma``) and above the onset's own
peak. A weaker echo is ambiguous: ``g`` is the shape of ``∂h/∂t_s``, so a weak echo and an
onset earlier by ``≈ A σ √(2π) / B`` samples are nearly the same waveform. Read as an onset,
the weak echoes of a wind sea time the surface early (−0.4 to −0.9 ns, issue 13); read as
echoes, the onset's noise of calm water off nadir (no specular echo) times it late (+0.5 to
+0.9 ns; free to sit on noise, the echo term pulls it late by ~0.5 sample at SNR 4 on
synthetic Poisson waveforms). A pulse alone cannot tell them apart; the survey's share of
clear echoes can: an ambiguous pulse's time is the onset alone's moved toward the echo-kept
one by :func:`echo_weight` of that share (empirical Bayes: the population sets the prior),
set by :func:`~pipeline.process.surface_echo_mix.mix_stored_echoes` once the survey's chunks
are all detected.

An onset alone whose best candidate is the first lies before the candidates: a weak column
under a slow decay rises for several samples after the surface and first crosses the peak
threshold late. Those pulses (not clear) are fitted again with the candidates moved back
(:data:`ONSET_LOOKBACK_SAMPLES`, at most :data:`ONSET_LOOKBACK_PASSES` times).

The candidates and the fitted samples sit at fixed offsets from the peak sample, so ``g`` and
``h_k`` at ``(j − c_k)/σ`` (sample offset ``j``, candidate offset ``c_k``) and their Gram sums
do not depend on the pulse: they are tabulated once per call for each decay of
:data:`DECAY_GRID` (a pulse's onset is interpolated, linearly in log decay, between the two
around its own), and a compiled kernel (numba, cached on disk) forms each pulse's Gram sums,
projections and residuals. Only a pulse whose window is cut by the waveform's ends evaluates
its own ``g`` and ``h_k``. Each pulse's fits depend on its own samples alone (a fixed loop
order), whatever the batch; with ``echo_sigma``, an ambiguous pulse's time also depends on
the batch's share of clear echoes (the survey's once :func:`mix_stored_echoes` has run).
"""

from __future__ import annotations

import functools
import math

import numba
import numpy as np
from scipy.special import ndtr

from pipeline.process.surface_echo_mix import (
    ECHO_FIELDS,
    StepParts,
    echo_weight,
    mix_stored_echoes,
    mixed_time,
)

__all__ = [
    "surface_step_fit",
    "StepParts",
    "echo_weight",
    "mixed_time",
    "mix_stored_echoes",
    "STEP_GRID",
    "DECAY_GRID",
    "ECHO_FIELDS",
    "column_onset",
]

#: Candidate surface times, samples from the peak sample (0.02-sample grid, 4 before to 0.5
#: after: the column onset only pulls the peak late, by up to ~3 samples when it is alone).
STEP_GRID = np.arange(-4.0, 0.5001, 0.02)
#: An onset-alone fit whose best candidate is the first is fitted again with the candidates
#: this many samples earlier (the grid's span before the peak), at most this many times.
ONSET_LOOKBACK_SAMPLES = 4
ONSET_LOOKBACK_PASSES = 6
#: Column decays tabulated (1/sample): 0 (a plain smoothed step) and 60 from 0.002 to 1 (11 %
#: apart; a pulse interpolates between the two around its own decay, linearly in log).
DECAY_GRID = np.concatenate([[0.0], np.geomspace(0.002, 1.0, 60)])


def column_onset(u: np.ndarray, sigma: float, decay: float | np.ndarray) -> np.ndarray:
    """The volume return's onset through the response: ``exp(−k u + (kσ)²/2) Φ(u/σ − kσ)``.

    Parameters
    ----------
    u : ndarray
        Time after the surface, samples (any shape).
    sigma : float
        σ of the (filtered) system response, samples.
    decay : float or ndarray
        Column decay ``k``, 1/sample (0: the smoothed step ``Φ(u/σ)``); an array broadcasts
        against ``u``.
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
    """``y ≈ a g + b h`` with ``a, b ≥ 0`` from the Gram sums: residual, ``a`` and ``b``."""
    det = gg * hh - gh * gh
    if det > 1e-12 * gg * hh:
        a = (hh * gy - gh * hy) / det
        b = (gg * hy - gh * gy) / det
        if a >= 0.0 and b >= 0.0:
            return yy - a * gy - b * hy, a, b
    # a bound is active: the better of the single terms (or neither)
    best, a_best, b_best = yy, 0.0, 0.0
    if gy > 0.0 and yy - gy * gy / gg < best:
        best, a_best, b_best = yy - gy * gy / gg, gy / gg, 0.0
    if hy > 0.0 and hh > 0.0 and yy - hy * hy / hh < best:
        best, a_best, b_best = yy - hy * hy / hh, 0.0, hy / hh
    return best, a_best, b_best


@numba.njit(cache=True, nogil=True)
def _step_sse(filt, i_peak, k_idx, k_w, decay, offsets, grid, sg, g_tab, h_tab, gg_tab, infl):
    """Per pulse and candidate the residuals; at the best candidate the SNRs and amplitudes.

    ``g_tab`` ``(w, k)`` and ``h_tab`` ``(decays, w, k)``: the echo and the onsets at each
    window sample and candidate (:func:`_step_tables`).

    Returns ``sse, sse1`` ``(n, k)``: the residuals of echo + onset and of the onset alone;
    ``best`` ``(n,)``: each pulse's ``np.argmin(sse, axis=1)``; ``snr, amp`` ``(n, 2)``: at
    that candidate, the echo's and the onset's amplitudes of the echo + onset fit and those
    over their standard errors (residual noise, ``infl`` for the filtered samples'
    correlation). Only the best candidate's are read: each would cost two square roots.

    Each candidate's Gram sums are added over the window's samples in order; the candidates
    are the inner loop (contiguous in the tables: the compiler vectorises it), each sum
    still added sample by sample, as one candidate at a time would.
    """
    n, m = filt.shape
    w_n, k_n = g_tab.shape
    sse = np.empty((n, k_n))
    sse1 = np.empty((n, k_n))
    best = np.zeros(n, np.int64)
    snr = np.zeros((n, 2))
    amp = np.zeros((n, 2))
    y = np.empty(w_n)
    # every candidate's Gram sums (separate arrays: the compiler sees they do not overlap)
    gg, hh, gh = np.empty(k_n), np.empty(k_n), np.empty(k_n)
    gy, hy = np.empty(k_n), np.empty(k_n)
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
        gg[:], hh[:], gh[:], gy[:], hy[:] = 0.0, 0.0, 0.0, 0.0, 0.0
        for j in range(w_n):
            yj = y[j]
            if cut:  # the window leaves the waveform: this pulse's own clipped columns
                c = min(max(i + offsets[j], 0), m - 1)
                for k in range(k_n):
                    z = (c - (i + grid[k])) / sg
                    g = math.exp(-0.5 * z * z)
                    h = _onset(z, ks)
                    gg[k] += g * g
                    hh[k] += h * h
                    gh[k] += g * h
                    gy[k] += g * yj
                    hy[k] += h * yj
            else:  # between the two tabulated decays around the pulse's own (log-linear)
                g_j, h0, h1 = g_tab[j], h_tab[q, j], h_tab[q + 1, j]
                for k in range(k_n):
                    g = g_j[k]
                    h = (1.0 - wq) * h0[k] + wq * h1[k]
                    hh[k] += h * h
                    gh[k] += g * h
                    gy[k] += g * yj
                    hy[k] += h * yj
        kb, low, nan = 0, np.inf, False
        for k in range(k_n):
            g2 = gg[k] if cut else gg_tab[k]
            v = _nnls2(yy, g2, hh[k], gh[k], gy[k], hy[k])[0]
            sse[p, k] = v
            sse1[p, k] = yy - hy[k] * hy[k] / hh[k] if (hy[k] > 0.0 and hh[k] > 0.0) else yy
            # np.argmin's pick: the first NaN, else the first smallest
            if not nan and (v != v or v < low):
                kb, low, nan = k, v, v != v
        best[p] = kb
        g2 = gg[kb] if cut else gg_tab[kb]
        v, a, b = _nnls2(yy, g2, hh[kb], gh[kb], gy[kb], hy[kb])
        amp[p, 0], amp[p, 1] = a, b
        det = g2 * hh[kb] - gh[kb] * gh[kb]
        if det > 1e-12 * g2 * hh[kb]:
            var1 = max(v, 0.0) / max(w_n - 3, 1) * infl / det
            if a > 0.0:
                snr[p, 0] = a / math.sqrt(var1 * hh[kb]) if var1 > 0.0 else np.inf
            if b > 0.0:
                snr[p, 1] = b / math.sqrt(var1 * g2) if var1 > 0.0 else np.inf
    return sse, sse1, best, snr, amp


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
    prevalence_half: float = 0.02,
    with_parts: bool = False,
) -> np.ndarray | tuple[np.ndarray, np.ndarray] | tuple[np.ndarray, StepParts]:
    """Surface time (fractional sample) of each waveform from the echo + column-onset fit.

    Parameters
    ----------
    filt : (n, m) ndarray
        Matched-filtered, baseline-free waveforms.
    i_peak : (n,) int ndarray
        Sample of each surface peak.
    sg : float
        σ of the (filtered) system response, samples.
    decay : (n,) ndarray, optional
        Each pulse's measured column decay, 1/sample (0 or None: the onset is a smoothed step).
    echo_sigma : float, optional
        The surface echo (Gaussian) term is taken as it is only where its fitted amplitude
        stands this many standard errors above 0 and above the onset's own peak (a clear
        echo); elsewhere the time is the onset alone's moved toward the echo-kept one by
        :func:`echo_weight` of this batch's share of clear echoes (a survey sets it from all
        its pulses: :func:`mixed_time` of ``with_parts``). None: the echo is always kept.
    with_echo_time : bool
        Also return the time of the fit with the echo term kept (a start for later fits that
        model the echo, :func:`~pipeline.process.detect_merged.merged_bottoms`).
    prevalence_half : float
        ``half`` of :func:`echo_weight`.
    with_parts : bool
        Return the :class:`StepParts` instead of the echo-kept time (needs ``echo_sigma``).

    Returns
    -------
    (n,) ndarray, or two
        Fitted surface time, samples from the first (and the echo-kept one, or the parts).
    """
    filt = np.ascontiguousarray(filt, dtype=np.float64)
    i_peak = np.asarray(i_peak, dtype=np.int64)
    n = filt.shape[0]
    k_dec, k_row, k_w = decay_index(decay, n)
    tabs = _step_tables(float(sg))
    sse2, sse1, _, snr, amp = _step_sse(filt, i_peak, k_row, k_w, k_dec, *tabs)
    t_echo = _refined(sse2, i_peak)
    if echo_sigma is None:
        return (t_echo, t_echo) if with_echo_time else t_echo
    # clear: significant, and the echo's peak above the onset's (a weaker "echo" is also an
    # onset earlier by ~ a σ √(2π) / b samples: the fit cannot tell which)
    a_best, b_best = amp[:, 0], amp[:, 1]
    clear = snr[:, 0] >= echo_sigma
    # the onset's peak is a 251-point exp and erfc per pulse (a tenth of detection): only
    # where the SNR test passed (elsewhere the pulse is not clear whatever it is), once per
    # distinct decay (a third of the pulses share 0, no column; each row is its own)
    k_clear, k_inv = np.unique(k_dec[clear], return_inverse=True)
    clear[clear] = a_best[clear] >= b_best[clear] * onset_peak(sg, k_clear)[k_inv]
    on_column = clear & (snr[:, 1] >= echo_sigma)
    # an onset alone whose best candidate is the first lies earlier than the candidates: a weak
    # column under a slow decay rises for several samples and first crosses the peak threshold
    # late (calm water off nadir, no echo: suite CI seed 9001, half its water pulses, the
    # surface +3.2 ns late). Its onset alone is fitted again with the candidates moved back,
    # kept where that finds a minimum inside them; the echo-kept time at the peak stays the
    # merged fit's start, the mixing reads the moved window's (t_mix_echo)
    i_fit, sse2_fit = _onset_lookback(filt, i_peak, sse1, sse2, ~clear, k_row, k_w, k_dec, tabs)
    # the onset alone only where it is whole in the waveform (a window cut by the record's
    # start repeats its first sample, which an onset fits as a step at the edge) and has a
    # minimum inside the candidates (at the first one it found no onset to time)
    cut = _cut(i_fit, tabs[0], filt.shape[1])
    inside = np.argmin(sse1, axis=1) > 0
    mixable = ~clear & ~cut & inside
    t_onset = np.where(mixable, _refined(sse1, i_fit), t_echo)
    moved = i_fit != i_peak
    t_mix_echo = t_echo.copy()
    t_mix_echo[moved] = _refined(sse2_fit[moved], i_fit[moved])
    parts = StepParts(t_echo, t_onset, clear, mixable, on_column, t_mix_echo)
    w = echo_weight(int(on_column.sum()), int(mixable.sum()), prevalence_half)
    t_sel = mixed_time(parts, w)
    if with_parts:
        return t_sel, parts
    return (t_sel, t_echo) if with_echo_time else t_sel


@functools.lru_cache(maxsize=8)
def _step_tables(sg: float) -> tuple:
    """The candidates' tables of :func:`surface_step_fit` for a response σ ``sg`` (samples).

    ``(offsets, STEP_GRID, sg, g, h, gg, infl)``: the window's sample offsets, the echo ``g``
    (w, k) and the onsets ``h`` (decays, w, k) at every candidate, ``gg`` the echo's sums of
    squares and ``infl`` the noise correlation's inflation. The same for every pulse of a
    system (a posterior's start runs the detector on one pulse at a time: these were most of
    its cost), so kept, read-only.
    """
    half_lo = int(math.ceil(3.0 * sg - STEP_GRID[0]))
    half_hi = int(math.ceil(2.0 * sg + STEP_GRID[-1]))
    offsets = np.arange(-half_lo, half_hi + 1, dtype=np.int64)
    u = offsets[None, :] - STEP_GRID[:, None]  # (k, w): the same for every pulse
    g = np.exp(-0.5 * (u / sg) ** 2)
    h = np.stack([column_onset(u, sg, kd) for kd in DECAY_GRID])  # (decays, k, w)
    # noise of the filtered samples is correlated over ~2√π σ_raw samples (σ_raw = sg/√2)
    infl = max(1.0, 2.0 * math.sqrt(math.pi) * sg / math.sqrt(2.0))
    gg = (g * g).sum(1)
    # the kernel's layout: candidates last (its inner loop)
    g, h = np.ascontiguousarray(g.T), np.ascontiguousarray(h.transpose(0, 2, 1))
    for a in (offsets, g, h, gg):
        a.setflags(write=False)
    return offsets, STEP_GRID, sg, g, h, gg, infl


def _onset_lookback(filt, i_peak, sse1, sse2, candidates, k_row, k_w, k_dec, tabs):
    """Move the onset-alone fit back where its best candidate is the first; ``sse1`` in place.

    ``candidates`` (n,) bool: the pulses that may move. Up to :data:`ONSET_LOOKBACK_PASSES`
    times, a pulse whose onset-alone residual is smallest at the first candidate is fitted
    again with the candidates :data:`ONSET_LOOKBACK_SAMPLES` earlier (never leaving the
    waveform); a pulse that still finds no minimum inside them keeps its fit at the peak.
    Returns each pulse's fitted peak sample (``i_peak`` where not moved) and the echo-kept
    residuals there (``sse2`` where not moved; a copy).
    """
    offsets, m = tabs[0], filt.shape[1]
    i_fit = i_peak.copy()
    sse1_peak, sse2_fit = sse1.copy(), sse2.copy()
    for _ in range(ONSET_LOOKBACK_PASSES):
        edge = candidates & ~_cut(i_fit, offsets, m) & (np.argmin(sse1, axis=1) == 0)
        edge[edge] = ~_cut(i_fit[edge] - ONSET_LOOKBACK_SAMPLES, offsets, m)
        if not edge.any():
            break
        i_fit[edge] -= ONSET_LOOKBACK_SAMPLES
        sub = np.flatnonzero(edge)
        sse2_fit[sub], sse1[sub], _, _, _ = _step_sse(
            filt[sub], i_fit[sub], k_row[sub], k_w[sub], k_dec[sub], *tabs
        )
    lost = (i_fit != i_peak) & (np.argmin(sse1, axis=1) == 0)
    i_fit[lost] = i_peak[lost]
    sse1[lost], sse2_fit[lost] = sse1_peak[lost], sse2[lost]
    return i_fit, sse2_fit


def _cut(i_fit: np.ndarray, offsets: np.ndarray, m: int) -> np.ndarray:
    """Whether each fit's window leaves the ``m`` samples of the waveform."""
    return (i_fit + offsets[0] < 0) | (i_fit + offsets[-1] > m - 1)


#: Grid step of :func:`onset_peak`'s first pass.
_COARSE = 10


def onset_peak(sg: float, decay: np.ndarray) -> np.ndarray:
    """Peak value of each pulse's :func:`column_onset` (1 for a step; below for a decay).

    Parameters
    ----------
    sg : float
        σ of the response, samples.
    decay : (n,) ndarray
        Column decays, 1/sample.
    """
    # the peak lies within ~3 σ of the surface for every tabulated decay: a 0.02 σ grid
    z = np.arange(-1.0, 4.0001, 0.02)
    k = np.asarray(decay, dtype=np.float64)[:, None]
    # the onset is log-concave in u (an exponential times a normal CDF), so one peak: every
    # 10th grid point first, then the grid within one such step of the best of them. The
    # same values at the same points as the whole grid's, and its maximum (a fifth of the
    # evaluations)
    coarse = np.arange(0, z.size, _COARSE)
    best = coarse[column_onset(z[coarse][None, :] * sg, sg, k).argmax(axis=1)]
    near = np.clip(best[:, None] + np.arange(-_COARSE, _COARSE + 1), 0, z.size - 1)
    return column_onset(z[near] * sg, sg, k).max(axis=1)


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
