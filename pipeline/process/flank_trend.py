"""The slow trend under narrow echoes (the bottom detector's baseline), compiled."""

from __future__ import annotations

import numba
import numpy as np

__all__ = ["flank_trend"]


def flank_trend(
    y: np.ndarray, gap: int, length: int, valid: np.ndarray | None = None
) -> np.ndarray:
    """Slow trend under narrow echoes: the mean of both flanks, ``gap`` samples away.

    At sample ``t`` the trend is the larger of the means of ``y`` over ``[t-gap-length, t-gap)``
    and ``(t+gap, t+gap+length]`` (one side alone at the window's ends). An echo narrower than
    ``gap`` does not raise its own trend, while the smooth water-column return is followed; the
    larger flank keeps the falling edge of the surface echo (whose earlier flank is high) from
    passing as a bottom. Running sums make it O(n_samples), unlike a running median.

    ``valid`` (same shape as ``y``, bool), if given, leaves the other samples out of the flank
    means (a flank with no valid sample takes the other side's mean).
    """
    y = np.ascontiguousarray(y, dtype=np.float64)
    w = np.ones_like(y) if valid is None else np.ascontiguousarray(valid, dtype=np.float64)
    return _flank_trend_kernel(y, w, int(gap), int(length))


@numba.njit(cache=True, nogil=True)
def _flank_trend_kernel(y, w, gap, length):
    # one pass per waveform over its running sums (the same sequential sums as np.cumsum, so
    # the same values as the array form, without its (n, m) temporaries)
    n, m = y.shape
    out = np.empty((n, m))
    c = np.empty(m + 1)
    cw = np.empty(m + 1)
    for p in range(n):
        c[0] = cw[0] = 0.0
        for t in range(m):
            c[t + 1] = c[t] + y[p, t] * w[p, t]
            cw[t + 1] = cw[t] + w[p, t]
        for t in range(m):
            l0, l1 = min(max(t - gap - length, 0), m), min(max(t - gap, 0), m)
            r0, r1 = min(max(t + gap + 1, 0), m), min(max(t + gap + 1 + length, 0), m)
            n_left, n_right = cw[l1] - cw[l0], cw[r1] - cw[r0]
            left = (c[l1] - c[l0]) / max(n_left, 1.0)
            right = (c[r1] - c[r0]) / max(n_right, 1.0)
            if not n_left > 0:
                left = right
            if not n_right > 0:
                right = left
            out[p, t] = max(left, right)
    return out
