"""Sub-sample timing of a detected peak (:mod:`pipeline.process.detect`).

:func:`parabolic_peak`: a parabola through the logarithm of the three samples around a peak,
exact for a Gaussian (the surface echo's step fit is in :mod:`pipeline.process.surface_step`).
"""

from __future__ import annotations

import numpy as np

__all__ = ["parabolic_peak"]


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
