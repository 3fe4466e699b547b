"""Bottom candidates just below the surface, tested against the water column they sit on.

Within a few FWHM of the surface echo the waveform can be a hump: the surface echo and the
onset of the column's volume backscatter, which at low altitude or in bright water is as strong
as the surface echo itself (a 150 m survey: surface peak ~290 counts on a column of ~250). A
flank trend undershoots such a hump, and the noise bumps on its shoulder passed as bottoms
0.6-0.8 m deep over 14-34 m of water. The column there is known better from below: it decays
exponentially (Beer-Lambert down and up, a straight line in log space), so its level under a
candidate is the level of the samples after the candidate carried back along the pulse's
measured decay. A candidate must stand
above that. Where no column follows (the samples after it are at the noise: a seabed ended
it, or the column is too faint to matter), the flank-trend test stays as it was.
"""

from __future__ import annotations

import numba
import numpy as np

__all__ = ["column_excess"]

#: Steepest column decay carried back, per sample (the ln-slope fit of a faint column is noisy).
MAX_DECAY_PER_SAMPLE = 0.5


def column_excess(
    filt: np.ndarray, floor: np.ndarray, offset: int, width: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each sample's excess over the column carried back from the samples after it.

    The column after sample ``t`` is measured on two windows of ``width`` samples,
    ``[t + offset, t + offset + width)`` and the next; their means give its level and its
    decay rate ``k = ln(m1 / m2) / width`` (clipped to ``[0, MAX_DECAY_PER_SAMPLE]``), and the
    column under ``t`` is ``m1 exp(k (offset + (width − 1) / 2))``. Measured locally, the decay
    follows whatever lies below the candidate and not the shallower hump.

    Parameters
    ----------
    filt : (n_pulses, n_samples) float
        Matched-filtered waveforms, baseline removed.
    floor : (n_pulses,) float
        Level below which a sample holds no column (a few filtered noise σ).
    offset, width : int
        Where the windows start after ``t`` (clear of the candidate's own echo) and their length.

    Returns
    -------
    excess : (n_pulses, n_samples) float
        ``filt`` minus the column carried back.
    column : (n_pulses, n_samples) bool
        Where both windows lie within the waveform and most of their samples are above
        ``floor``: only there does a column follow, and is ``excess`` meaningful.
    carried : (n_pulses, n_samples) float
        The column carried back (its noise adds to the test's: the caller's business).
    """
    filt = np.ascontiguousarray(filt, dtype=np.float64)
    floor = np.ascontiguousarray(floor, dtype=np.float64)
    return _column_excess_kernel(filt, floor, int(offset), int(width))


@numba.njit(cache=True, nogil=True)
def _column_excess_kernel(filt, floor, offset, width):
    # one pass per waveform over its running sums (sequential, as np.cumsum's), without the
    # (n, m) temporaries of the array form; the same arithmetic in the same order
    n, m = filt.shape
    excess = np.empty((n, m))
    column = np.empty((n, m), dtype=np.bool_)
    carried = np.empty((n, m))
    c = np.empty(m + 1)
    ca = np.empty(m + 1)
    back = offset + 0.5 * (width - 1)
    for p in range(n):
        c[0] = ca[0] = 0.0
        for t in range(m):
            c[t + 1] = c[t] + filt[p, t]
            ca[t + 1] = ca[t] + (1.0 if filt[p, t] > floor[p] else 0.0)
        for t in range(m):
            lo1, hi1 = min(max(t + offset, 0), m), min(max(t + offset + width, 0), m)
            lo2, hi2 = min(max(t + offset + width, 0), m), min(max(t + offset + 2 * width, 0), m)
            s1, s2 = c[hi1] - c[lo1], c[hi2] - c[lo2]
            a1, a2 = ca[hi1] - ca[lo1], ca[hi2] - ca[lo2]
            inside = (hi1 - lo1 == width) and (hi2 - lo2 == width)
            column[p, t] = inside and a1 > 0.5 * width and a2 > 0.5 * width
            m1 = max(s1 / width, 1e-300)
            m2 = max(s2 / width, 1e-300)
            k = min(max(np.log(m1 / m2) / width, 0.0), MAX_DECAY_PER_SAMPLE)
            carried[p, t] = m1 * np.exp(k * back)
            excess[p, t] = filt[p, t] - carried[p, t]
    return excess, column, carried
