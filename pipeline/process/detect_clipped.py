"""Echoes clipped at the digitiser's top code: flag them, time them where the data allow.

A digitiser clips every sample above its top code ``2^bits − 1``: a strong echo becomes a
plateau, and its peak (what the matched filter and the log-parabola time) sits anywhere on it,
late for the surface. What the waveform still holds are the two edge samples, the last below
the plateau on each side. For a Gaussian echo ``A exp(−(t − t_c)² / 2σ²)`` of the known system
σ through ``(a, v_a)`` and ``(b, v_b)`` (``a < b``, values above the baseline)::

    t_c = (a + b) / 2 − σ² (ln v_a − ln v_b) / (b − a),   ln A = ln v_a + (t_c − a)² / 2σ²

exact for any amplitude: the plateau's centre, moved by the edges' imbalance (the term is
damped by the plateau's width, so a noisy edge sample moves it by ~σ²/(b − a) of its relative
error). That holds for ONE clipped echo. When the plateau runs on into the water column and
the bottom (a bright column at low altitude or high pulse energy), the surface's trailing edge
is hidden: its centre is not measurable (the leading edge alone leaves ``A``, and so the
offset ``σ √(2 ln(A / v_a))`` after the last sample below the plateau, free), nor is the
bottom's. A plateau longer than ``max_plateau_fwhm`` system FWHM is taken for that case: the
pulse is flagged ``CLIPPED_MERGED``, no bottom is reported, and its surface time is an early
bound: the centre of the weakest Gaussian of σ through ``(a, v_a)`` that reaches the top code
at the plateau's first sample ``a + 1``::

    t_lead = a + 1/2 + σ² ln((top − baseline) / v_a)

(the formula above with ``v_b`` = the top code above the baseline). A stronger echo through
``(a, v_a)`` peaks later, so ``t_lead`` never follows the true centre; it is within one
sample of it up to ``A ~ 10⁵ × v_a`` and loosens as ``√ln A`` beyond (σ = 0.77 samples). The
old bound, the plateau's first sample minus 1/2, was 0.6-3.5 samples early over ``A = 10⁴ …
10⁸`` counts (12 bits).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["ClippedEchoes", "clipped_echoes", "clipped_bottom"]


@dataclass(frozen=True)
class ClippedEchoes:
    """The first clipped plateau of each waveform, ``(n,)`` per field.

    Attributes
    ----------
    saturated : bool
        Some sample is at the top code.
    resolved : bool
        Saturated, and the plateau is one clipped echo: ``t_idx`` is its centre.
    merged : bool
        Saturated, and the plateau runs on past one echo (``max_plateau_fwhm``): ``t_idx`` is
        the earliest centre its leading edge allows (an early bound).
    t_idx : float
        Sample index of the echo's centre (resolved) or its early bound (merged).
    amplitude : float
        Resolved: the echo's amplitude ``A`` above the baseline; else the top code's.
    first, stop : int
        The plateau's samples ``[first, stop)``.
    """

    saturated: np.ndarray
    resolved: np.ndarray
    merged: np.ndarray
    t_idx: np.ndarray
    amplitude: np.ndarray
    first: np.ndarray
    stop: np.ndarray


def _plateau(y, first, stop, level, noise, sigma_samples, max_plateau_fwhm):
    """Centre, log amplitude and "one echo" of the plateaus ``[first, stop)`` (module doc)."""
    n, m = y.shape
    rows = np.arange(n)
    a, b = first - 1, stop
    # edge values above the level; a sample lost in the noise (or outside the window)
    # counts as one noise σ: the centre moves by σ²/(b − a) per unit of its log error
    floor = np.maximum(noise, 1e-6)

    def edge(i):
        v = y[rows, np.clip(i, 0, m - 1)] - level
        return np.where((i >= 0) & (i < m), np.maximum(v, floor), floor)

    log_a, log_b = np.log(edge(a)), np.log(edge(b))
    s2 = sigma_samples**2
    t_c = 0.5 * (a + b) - s2 * (log_a - log_b) / np.maximum(b - a, 1)
    log_amp = log_a + (t_c - a) ** 2 / (2.0 * s2)
    fwhm_samples = sigma_samples * 2.0 * np.sqrt(2.0 * np.log(2.0))
    single = (stop - first <= max_plateau_fwhm * fwhm_samples) & (a >= 0) & (b < m)
    return t_c, log_amp, single


def _leading_bound(y, first, top_code, baseline, noise, sigma_samples):
    """Earliest centre of a Gaussian echo clipped from sample ``first`` on (module doc).

    ``a = first − 1`` is the last sample below the top code; its value above ``baseline``
    counts at least one noise σ (an edge lost in the noise bounds the rise no tighter).
    """
    n, m = y.shape
    a = first - 1
    rows = np.arange(n)
    floor = np.maximum(noise, 1e-6)
    v_a = np.where(a >= 0, y[rows, np.clip(a, 0, m - 1)] - baseline, floor)
    v_a = np.maximum(v_a, floor)
    v_top = np.maximum(top_code - baseline, v_a)
    return a + 0.5 + sigma_samples**2 * (np.log(v_top) - np.log(v_a))


def clipped_bottom(
    y: np.ndarray,
    top_code: float,
    i_b: np.ndarray,
    level: np.ndarray,
    noise: np.ndarray,
    sigma_samples: float,
    settings,
) -> tuple[np.ndarray, np.ndarray]:
    """A bottom candidate on a clipped plateau of its own: is it, and its centre if one echo.

    The edges are measured from ``level``, the baseline: the column under a clipped echo is a
    few per cent of its edge samples, and the centre moves by σ²/(b − a) of their log error.

    Parameters
    ----------
    y : (n, m) ndarray
        Digitised waveforms.
    top_code : float
        The digitiser's top code.
    i_b : (n,) int
        Sample of each pulse's bottom peak.
    level : (n,) ndarray
        The waveforms' baseline, counts.
    noise : (n,) ndarray
        Noise σ of one sample.
    sigma_samples : float
        As :func:`clipped_echoes`.
    settings : DetectSettings
        Its ``max_plateau_fwhm``.

    Returns
    -------
    clipped : (n,) bool
        A sample within one of ``i_b`` is at the top code.
    t_idx : (n,) float
        The plateau's centre where it is one echo, else NaN (not measurable).
    """
    n, m = y.shape
    rows = np.arange(n)
    near = np.clip(i_b[:, None] + np.arange(-1, 2), 0, m - 1)
    hit = y[rows[:, None], near] >= top_code
    clipped = hit.any(axis=1)
    t_idx = np.full(n, np.nan)
    # only the clipped pulses' plateaus are timed (the others are NaN whatever their runs):
    # the run scans below cover the whole record, so they take those rows alone
    sub = np.flatnonzero(clipped)
    if sub.size == 0:
        return clipped, t_idx
    top, rs = y[sub] >= top_code, np.arange(sub.size)
    j = near[sub, np.argmax(hit[sub], axis=1)]
    cols = np.arange(m)
    # the run of clipped samples through j: after the last unclipped sample before it, up to
    # the first unclipped one after it
    last_below = np.maximum.accumulate(np.where(top, -1, cols[None, :]), axis=1)
    next_below = np.minimum.accumulate(np.where(top, m, cols[None, :])[:, ::-1], axis=1)[:, ::-1]
    first = last_below[rs, j] + 1
    stop = next_below[rs, j]
    t_c, _, single = _plateau(
        y[sub], first, stop, level[sub], noise[sub], sigma_samples, settings.max_plateau_fwhm
    )
    t_idx[sub] = np.where(single, t_c, np.nan)
    return clipped, t_idx


def clipped_echoes(
    y: np.ndarray,
    top_code: float,
    baseline: np.ndarray,
    noise: np.ndarray,
    sigma_samples: float,
    max_plateau_fwhm: float,
) -> ClippedEchoes:
    """Find and time the first clipped plateau of each waveform.

    Parameters
    ----------
    y : (n, m) ndarray
        Digitised waveforms.
    top_code : float
        The digitiser's top code (``2^bits − 1``); samples at or above it are clipped.
    baseline, noise : (n,) ndarray
        Baseline and noise σ of one sample.
    sigma_samples : float
        σ of the system response, samples.
    max_plateau_fwhm : float
        Longest plateau, in system FWHM, taken for one clipped echo.

    Returns
    -------
    ClippedEchoes
    """
    m = y.shape[1]
    cols = np.arange(m)[None, :]
    top = y >= top_code
    saturated = top.any(axis=1)
    first = np.where(saturated, np.argmax(top, axis=1), 0)
    # the plateau ends at the first unclipped sample after its start (m: runs to the end)
    below_after = ~top & (cols > first[:, None])
    stop = np.where(below_after.any(axis=1), np.argmax(below_after, axis=1), m)
    t_c, log_amp, single = _plateau(
        y, first, stop, baseline, noise, sigma_samples, max_plateau_fwhm
    )
    resolved = saturated & single
    merged = saturated & ~single
    # the leading edge: the weakest Gaussian through the last sample below the plateau that
    # reaches the top code at its first sample; a stronger one (A unknown) peaks later
    t_lead = _leading_bound(y, first, top_code, baseline, noise, sigma_samples)
    t_idx = np.where(resolved, t_c, np.where(merged, t_lead, 0.0))
    amp = np.where(resolved, np.exp(np.minimum(log_amp, 700.0)), top_code - baseline)
    return ClippedEchoes(saturated, resolved, merged, t_idx, amp, first, stop)
