"""The surface time from a Gaussian echo on a smoothed step, fitted near the surface peak.

The water-column return starts at the surface and, over a few samples, is a step smoothed by
the system response; it pulls the plain peak late. :func:`surface_step_fit` fits
``A g(t − t_s) + B Φ((t − t_s)/σ)`` for each candidate ``t_s`` on a 0.02-sample grid around the
peak (``A`` and ``B`` by linear least squares) and keeps the candidate with the smallest
residual, refined by a parabola through the residuals.

The candidates and the fitted samples sit at fixed offsets from the peak sample, so ``g`` and
``Φ`` at ``(j − c_k)/σ`` (sample offset ``j``, candidate offset ``c_k``) and their Gram sums do
not depend on the pulse: they are tabulated once per call, and a compiled kernel
(numba, cached on disk) forms each pulse's two projections and residuals. Only a pulse whose
window is cut by the waveform's ends evaluates its own ``g`` and ``Φ``. Per pulse this is
``k × w`` multiply-adds instead of ``k × w`` evaluations of ``exp`` and ``ndtr`` (k = 101
candidates, w ≈ 15 samples), and each pulse's result depends on its own samples alone (a fixed
loop order), whatever the batch.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from scipy.special import ndtr

__all__ = ["surface_step_fit", "STEP_GRID"]

#: Candidate surface times, samples from the peak sample (0.02-sample grid, 1.5 before to 0.5
#: after: the column onset only pulls the peak late).
STEP_GRID = np.arange(-1.5, 0.5001, 0.02)


@numba.njit(cache=True, nogil=True)
def _step_sse(filt, i_peak, offsets, grid, sg, g_tab, h_tab, gg_tab, hh_tab, gh_tab):
    n, m = filt.shape
    k_n, w_n = g_tab.shape
    sse = np.empty((n, k_n))
    y = np.empty(w_n)
    g = np.empty(w_n)
    h = np.empty(w_n)
    for p in range(n):
        i = i_peak[p]
        cut = i + offsets[0] < 0 or i + offsets[w_n - 1] > m - 1
        yy = 0.0
        for j in range(w_n):
            c = min(max(i + offsets[j], 0), m - 1)
            y[j] = filt[p, c]
            yy += y[j] * y[j]
        for k in range(k_n):
            if cut:  # the window leaves the waveform: this pulse's own clipped columns
                gg = hh = gh = gy = hy = 0.0
                for j in range(w_n):
                    c = min(max(i + offsets[j], 0), m - 1)
                    z = (c - (i + grid[k])) / sg
                    g[j] = math.exp(-0.5 * z * z)
                    h[j] = 0.5 * math.erfc(-z / math.sqrt(2.0))
                    gg += g[j] * g[j]
                    hh += h[j] * h[j]
                    gh += g[j] * h[j]
                    gy += g[j] * y[j]
                    hy += h[j] * y[j]
            else:
                gg, hh, gh = gg_tab[k], hh_tab[k], gh_tab[k]
                gy = hy = 0.0
                for j in range(w_n):
                    gy += g_tab[k, j] * y[j]
                    hy += h_tab[k, j] * y[j]
            det = gg * hh - gh * gh
            if det > 1e-12 * gg * hh:
                a = (hh * gy - gh * hy) / det
                b = (gg * hy - gh * gy) / det
            else:
                a, b = gy / gg, 0.0
            # negative amplitudes are not physical: the Gaussian alone there
            if a <= 0.0 or b < 0.0:
                a, b = gy / gg, 0.0
            sse[p, k] = yy - a * gy - b * hy
    return sse


def surface_step_fit(filt: np.ndarray, i_peak: np.ndarray, sg: float) -> np.ndarray:
    """Surface time (fractional sample) of each waveform from the step fit.

    Parameters
    ----------
    filt : (n, m) ndarray
        Matched-filtered, baseline-free waveforms.
    i_peak : (n,) int ndarray
        Sample of each surface peak.
    sg : float
        σ of the filtered system response, samples.

    Returns
    -------
    (n,) ndarray
        Fitted surface time, samples from the first.
    """
    filt = np.ascontiguousarray(filt, dtype=np.float64)
    i_peak = np.asarray(i_peak, dtype=np.int64)
    n = filt.shape[0]
    half_lo, half_hi = int(math.ceil(3.0 * sg)), int(math.ceil(2.0 * sg))
    offsets = np.arange(-half_lo, half_hi + 1, dtype=np.int64)
    z = (offsets[None, :] - STEP_GRID[:, None]) / sg  # (k, w): the same for every pulse
    g, h = np.exp(-0.5 * z * z), ndtr(z)
    sse = _step_sse(
        filt, i_peak, offsets, STEP_GRID, float(sg), g, h,
        (g * g).sum(1), (h * h).sum(1), (g * h).sum(1),
    )  # fmt: skip
    k = np.clip(np.argmin(sse, axis=1), 1, STEP_GRID.size - 2)
    rows = np.arange(n)
    s0, s1, s2 = sse[rows, k - 1], sse[rows, k], sse[rows, k + 1]
    # parabola through the three residuals around the minimum: sub-grid time
    curv = s0 - 2.0 * s1 + s2
    off = np.where(curv > 0, 0.5 * (s0 - s2) / np.where(curv > 0, curv, 1.0), 0.0)
    return i_peak + STEP_GRID[k] + 0.02 * np.clip(off, -1.0, 1.0)
