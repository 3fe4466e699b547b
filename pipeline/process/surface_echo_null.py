"""Weak surface echoes told from noise, survey-wide: the echo-kept shift against its null.

Why
---
Each full-waveform pulse gives two surface times (:mod:`pipeline.process.surface_step`): the
column onset's alone and the fit that keeps a Gaussian echo on that onset. A weak echo and an
earlier onset are nearly the same waveform, so a pulse alone cannot say which it holds. Where
the survey's clear echoes are rare, :func:`~pipeline.process.surface_echo_mix.echo_weight`
takes the onset alone. Over flat water in a light wind, 20° off nadir, every footprint holds a
weak glint (Cox-Munk: the facets tilted 20° are ``exp(-tan²20° / mss)`` of nadir's, 4e-4 at
2.7 m/s) that is never clear by itself, and the onset alone then times the surface early: on
the light-wind cube scene (suite tuning seed 7102, 2.7 m/s, 246 m) by 0.42 ns, the depths
+0.045 m; at 3.5 m/s by 1.07 ns (``benchmarks/RESULTS_suite.md``, session 31).

The echo-kept fit moves off the onset on noise too: its echo amplitude is held at ``>= 0``,
so in calm water it fits the noise's positive bumps and times the surface late (+0.26 ns on
that scene's calm twin). Neither the clear-echo share nor a per-pulse significance separates
a sea of weak glints from that (session 17, ``RESULTS_cubes.md``).

What this does
--------------
A parametric bootstrap (Efron & Tibshirani 1993, *An Introduction to the Bootstrap*, ch. 6)
gives the shift the echo-kept fit shows on noise alone. For every ``every``-th ambiguous
pulse (by pulse number, so the subset does not depend on the chunking), the onset-alone fit
is made again into a raw waveform (the onset through the unfiltered response, at the fitted
time, amplitude and column decay), the receiver's noise as processing assumes it is added
(the pulse's own noise floor, from its pre-trigger samples, and the shot noise ``F G y``; a
counter-based generator keyed by the pulse number), and it goes through the same matched
filter and step fit. The pulse's observed shift less that null shift is, summed over the
survey, ~0 when the pulses hold no echo and positive when they hold one
(:func:`~pipeline.process.surface_echo_mix.weak_echo_test`). Where the survey's excess is
significant and large against the null's own shift, its ambiguous echoes are echoes: their
times take the echo-kept fit. On simulated flat water at the cube scene's geometry (4000
pulses, every one resampled; ``benchmarks/surface_glint.py``) the excess over the null's
shift was -4 / -4 / -3 % at 0.5 / 1 / 2 m/s and +15 / +42 / +121 / +310 % at 2.5 / 2.7 / 3.0
/ 3.5 m/s; over six geometries (246-761 m, ``c`` 0.05-0.73 /m, 15-20° off nadir) -8 to +16 %
on calm water (the most where the signal is weakest) and +27 to +42 % at 2.7 m/s. The
verdict therefore asks the excess beyond a margin of 20 % to be significant.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.ndimage import gaussian_filter1d
from scipy.special import ndtri

from pipeline.process.surface_step import (
    ONSET_LOOKBACK_PASSES,
    ONSET_LOOKBACK_SAMPLES,
    column_onset,
    decay_index,
    surface_step_fit,
)

__all__ = ["null_shifts"]

#: Salt of the null's noise (with the pulse number and the sample): one stream per pulse.
_NULL_KEY = 0x5EC0

_U64 = np.uint64


def _mix64(z: np.ndarray) -> np.ndarray:
    """SplitMix64's finaliser (Steele, Lea & Flood 2014), wrapping uint64 arithmetic.

    A bijection that scatters neighbouring inputs over the whole range.
    """
    z = z + _U64(0x9E3779B97F4A7C15)
    z = (z ^ (z >> _U64(30))) * _U64(0xBF58476D1CE4E5B9)
    z = (z ^ (z >> _U64(27))) * _U64(0x94D049BB133111EB)
    return z ^ (z >> _U64(31))


def keyed_normals(pulse_id: np.ndarray, m: int) -> np.ndarray:
    """Standard normals ``(n, m)``, each a function of its pulse number and sample alone.

    Counter-based (the pair hashed, its top 53 bits a uniform, the normal's quantile of it),
    so a pulse's draws are the same whatever batch it is in, made for all pulses at once
    without a generator per pulse.
    """
    key = _mix64(np.asarray(pulse_id, dtype=np.uint64) ^ _U64(_NULL_KEY << 48))
    z = _mix64(key[:, None] + np.arange(m, dtype=np.uint64)[None, :])
    u = ((z >> _U64(11)).astype(np.float64) + 0.5) * 2.0**-53  # in (0, 1): finite quantiles
    return ndtri(u)


#: Samples kept after the step fit's window in the null's waveform (the matched filter
#: reaches ~3 σ; its edge copies the end sample), and before it: as many again as the
#: onset-alone fit may look back (``ONSET_LOOKBACK_PASSES`` moves of
#: ``ONSET_LOOKBACK_SAMPLES``), so a slow calm-water onset's null is fitted where its own was.
_MARGIN = 12
_MARGIN_BEFORE = _MARGIN + ONSET_LOOKBACK_PASSES * ONSET_LOOKBACK_SAMPLES


def null_shifts(
    filt: np.ndarray,
    i_peak: np.ndarray,
    decay: np.ndarray | None,
    sigma_samples: float,
    parts,
    noise_floor: np.ndarray,
    shot_noise_counts: float,
    pulse_id: np.ndarray,
    every: int,
    echo_sigma: float,
) -> np.ndarray:
    """The echo-kept fit's shift on noise alone, for every ``every``-th ambiguous pulse.

    Parameters
    ----------
    filt : (n, m) ndarray
        Matched-filtered, baseline-free waveforms.
    i_peak : (n,) int ndarray
        Sample of each surface peak (the step fit's).
    decay : (n,) ndarray or None
        Each pulse's column decay, 1/sample (None: a plain step).
    sigma_samples : float
        σ of the unfiltered system response, samples (the filter's too).
    parts : StepParts
        The step fit's parts of the same pulses.
    noise_floor : (n,) ndarray
        Each raw waveform's noise floor σ (counts) where no return is (its pre-trigger
        samples): the noise a sample holds without signal. Not the waveform's whole
        difference-based σ, which holds the column's shot noise too (counted here by
        ``shot_noise_counts``: on the light-wind scene 6.05 against a floor of 3.49 counts).
    shot_noise_counts : float
        ``F G``: a sample of ``y`` counts has variance ``noise² + F G y``.
    pulse_id : (n,) int ndarray
        Pulse numbers: the subset (``pulse_id % every == 0``) and the noise's keys.
    every : int
        One pulse in ``every`` is resampled.
    echo_sigma : float
        As for :func:`~pipeline.process.surface_step.surface_step_fit`.

    Returns
    -------
    (n,) ndarray
        ``t_mix_echo - t_onset`` of the null waveform (samples) where resampled and ambiguous
        there too; NaN elsewhere.
    """
    n = filt.shape[0]
    out = np.full(n, np.nan)
    pid = np.asarray(pulse_id, dtype=np.int64)
    sub = np.flatnonzero(parts.mixable & (pid % every == 0))
    if sub.size == 0:
        return out
    sg_f = math.sqrt(2.0) * sigma_samples
    k = decay_index(decay, n)[0]  # the decay the step fit used (finite, capped, 0 below its grid)
    t_on = parts.t_onset[sub]
    # the onset alone's amplitude at its time, over the step fit's window (filtered domain,
    # where the response is σ√2; the raw onset of the same amplitude filters into it)
    lo = int(math.floor(-3.0 * sg_f - 4.0))
    hi = int(math.ceil(2.0 * sg_f + 0.5))
    off = np.arange(lo, hi + 1)
    cols = np.clip(i_peak[sub, None] + off[None, :], 0, filt.shape[1] - 1)
    h_f = column_onset(cols - t_on[:, None], sg_f, k[sub, None])
    y = np.take_along_axis(filt[sub], cols, axis=1)
    hh = np.sum(h_f * h_f, axis=1)
    amp = np.where(hh > 0.0, np.sum(h_f * y, axis=1) / np.where(hh > 0.0, hh, 1.0), 0.0)
    # the null waveform, local: the peak at a fixed sample, margins for the filter's reach
    seg = np.arange(lo - _MARGIN_BEFORE, hi + _MARGIN + 1)
    peak = np.full(sub.size, -seg[0], dtype=np.int64)
    t_local = t_on - i_peak[sub] - seg[0]
    model = amp[:, None] * column_onset(
        np.arange(seg.size)[None, :] - t_local[:, None], sigma_samples, k[sub, None]
    )
    sd = np.sqrt(noise_floor[sub, None] ** 2 + shot_noise_counts * np.maximum(model, 0.0))
    raw = model + sd * keyed_normals(pid[sub], seg.size)
    f0 = gaussian_filter1d(raw, sigma_samples, axis=1, mode="nearest")
    _, p0 = surface_step_fit(f0, peak, sg_f, k[sub], echo_sigma=echo_sigma, with_parts=True)
    out[sub] = np.where(p0.mixable, p0.t_mix_echo - p0.t_onset, np.nan)
    return out
