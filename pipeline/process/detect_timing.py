"""Sub-sample timing of a detected peak (:mod:`pipeline.process.detect`).

:func:`parabolic_peak`: a parabola through the logarithm of the three samples around a peak,
exact for a Gaussian. :func:`surface_step_fit`: the surface echo with the water column's onset
step, fitted on a grid of candidate times.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.special import ndtr

__all__ = ["parabolic_peak", "surface_step_fit"]


def surface_step_fit(filt: np.ndarray, i_peak: np.ndarray, sg: float) -> np.ndarray:
    """Surface time from ``A g(t − t_s) + B Φ((t − t_s)/σ)`` fitted near the surface peak.

    The water-column return starts at the surface and, over a few samples, is a step smoothed
    by the system response; it pulls the plain peak late. For each candidate ``t_s`` on a
    0.02-sample grid around the peak, ``A`` and ``B`` follow by linear least squares; the
    candidate with the smallest residual wins (batched: pulses × candidates × samples).
    """
    n, m = filt.shape
    half_lo, half_hi = int(math.ceil(3.0 * sg)), int(math.ceil(2.0 * sg))
    cols = np.clip(i_peak[:, None] + np.arange(-half_lo, half_hi + 1), 0, m - 1)
    y = np.take_along_axis(filt, cols, axis=1)[:, None, :]  # (n, 1, w)
    cand = i_peak[:, None] + np.arange(-1.5, 0.5001, 0.02)[None, :]  # (n, k)
    z = (cols[:, None, :] - cand[:, :, None]) / sg  # (n, k, w)
    g = np.exp(-0.5 * z * z)
    h = ndtr(z)
    gg, hh, gh = (g * g).sum(2), (h * h).sum(2), (g * h).sum(2)
    gy, hy = (g * y).sum(2), (h * y).sum(2)
    det = gg * hh - gh * gh
    ok = det > 1e-12 * gg * hh
    a = np.where(ok, (hh * gy - gh * hy) / np.where(ok, det, 1.0), gy / gg)
    b = np.where(ok, (gg * hy - gh * gy) / np.where(ok, det, 1.0), 0.0)
    # negative amplitudes are not physical: fall back to the Gaussian alone there
    bad = (a <= 0) | (b < 0)
    a, b = np.where(bad, gy / gg, a), np.where(bad, 0.0, b)
    sse = (y * y).sum(2) - a * gy - b * hy
    k = np.clip(np.argmin(sse, axis=1), 1, cand.shape[1] - 2)
    rows = np.arange(n)
    s0, s1, s2 = sse[rows, k - 1], sse[rows, k], sse[rows, k + 1]
    # parabola through the three residuals around the minimum: sub-grid time
    curv = s0 - 2.0 * s1 + s2
    off = np.where(curv > 0, 0.5 * (s0 - s2) / np.where(curv > 0, curv, 1.0), 0.0)
    return cand[rows, k] + 0.02 * np.clip(off, -1.0, 1.0)


def parabolic_peak(y: np.ndarray, idx: np.ndarray):
    """Sub-sample peak position, height and σ (samples) from three samples (log-parabola)."""
    n = y.shape[1]
    rows = np.arange(y.shape[0])
    i = np.clip(idx, 1, n - 2)
    ym, y0, yp = y[rows, i - 1], y[rows, i], y[rows, i + 1]
    floor = 1e-12 * np.maximum(np.abs(y0), 1e-30)
    lm, l0, lp = (np.log(np.maximum(v, floor)) for v in (ym, y0, yp))
    den = lm - 2.0 * l0 + lp
    ok = (ym > 0) & (y0 > 0) & (yp > 0) & (den < 0)
    off = np.where(ok, 0.5 * (lm - lp) / np.where(ok, den, -1.0), 0.0)
    off = np.clip(off, -0.5, 0.5)
    height = np.where(ok, np.exp(l0 - 0.25 * (lm - lp) * off), y0)
    # a Gaussian's log has curvature -1/σ²
    width = np.where(ok, np.sqrt(-1.0 / np.where(ok, den, -1.0)), 0.0)
    return i + off, height, width
