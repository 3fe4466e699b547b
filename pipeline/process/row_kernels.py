"""Compiled per-row helpers that give numpy's own figures: its sum, a median's value.

A compiled loop over a waveform's samples replaces a dozen ``(pulses, samples)`` temporaries,
but a plain running sum adds in another order than numpy's ``sum(axis=1)``, which adds a row
pairwise (blocks of 8 partial sums, halves above 128 values: ``pairwise_sum`` in numpy's
``loops_utils.h.src``). :func:`pairwise_sum` adds in numpy's order, so a kernel built on it
gives the vectorised code's figures to the bit, and a speed-up can be checked by comparing
outputs exactly (``tests/process/test_row_kernels.py`` compares it with ``np.sum``).
:func:`median_of` selects the middle values a sort would put there (quickselect): the same
values, so the same median.
"""

from __future__ import annotations

import functools
import math

import numba
import numpy as np

__all__ = [
    "pairwise_sum",
    "median_of",
    "counted_median",
    "COUNT_HALF",
    "gaussian_weights",
    "gaussian_rows",
]

#: numpy's block below which a row is added with 8 partial sums (``PW_BLOCKSIZE``)
_BLOCK = 128


@numba.njit(cache=True, nogil=True)
def _leaf(a, lo, n):
    """The sum of ``a[lo:lo + n]``, ``n <= 128``, as numpy adds it (a running sum below 8)."""
    if n < 8:
        res = 0.0
        for i in range(lo, lo + n):
            res += a[i]
        return res
    r0, r1, r2, r3 = a[lo], a[lo + 1], a[lo + 2], a[lo + 3]
    r4, r5, r6, r7 = a[lo + 4], a[lo + 5], a[lo + 6], a[lo + 7]
    i = 8
    stop = n - n % 8
    while i < stop:
        j = lo + i
        r0 += a[j]
        r1 += a[j + 1]
        r2 += a[j + 2]
        r3 += a[j + 3]
        r4 += a[j + 4]
        r5 += a[j + 5]
        r6 += a[j + 6]
        r7 += a[j + 7]
        i += 8
    res = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while i < n:
        res += a[lo + i]
        i += 1
    return res


@numba.njit(cache=True, nogil=True)
def pairwise_sum(a: np.ndarray, lo: int, n: int) -> float:
    """``a[lo:lo + n].sum()`` added in numpy's pairwise order (float64, contiguous ``a``).

    numpy halves a run longer than 128 (the first half a multiple of 8) and adds the halves'
    sums. Its recursion is walked here with an explicit stack (a compiled function that
    calls itself is not cached safely): ``size`` and ``start`` of the pending runs, their
    partial sums combined as the recursion returns.
    """
    if n <= _BLOCK:  # one leaf: no stack to allocate (a row's neighbours, a short waveform)
        return _leaf(a, lo, n)
    # depth: a run halves each level, 48 levels cover any array
    start = np.empty(48, np.int64)
    size = np.empty(48, np.int64)
    done = np.zeros(48, np.bool_)
    left = np.empty(48)
    start[0], size[0] = lo, n
    top = 0
    result = 0.0
    while top >= 0:
        if size[top] <= _BLOCK:
            value = _leaf(a, start[top], size[top])
            top -= 1
            # hand the value to the parent: its left half's sum, or the sum of both halves
            while top >= 0:
                if not done[top]:
                    done[top] = True
                    left[top] = value
                    n2 = size[top] // 2
                    n2 -= n2 % 8
                    # now the right half
                    start[top + 1], size[top + 1] = start[top] + n2, size[top] - n2
                    done[top + 1] = False
                    top += 1
                    break
                value = left[top] + value
                top -= 1
            else:
                result = value
        else:
            n2 = size[top] // 2
            n2 -= n2 % 8
            done[top] = False
            start[top + 1], size[top + 1] = start[top], n2
            done[top + 1] = False
            top += 1
    return result


@numba.njit(cache=True, nogil=True)
def median_of(buf: np.ndarray, m: int) -> float:
    """Median of ``buf[:m]`` (reordered in place), ``m >= 1``: the middle pair's sum over 2.

    The middle order statistics by quickselect (Hoare's partition): the values a sort would
    put there. No NaN may be among them.
    """
    hi = m // 2
    left, right = 0, m - 1
    while left < right:
        pivot = buf[(left + right) // 2]
        i, j = left, right
        while i <= j:
            while buf[i] < pivot:
                i += 1
            while buf[j] > pivot:
                j -= 1
            if i <= j:
                buf[i], buf[j] = buf[j], buf[i]
                i += 1
                j -= 1
        if hi <= j:
            right = j
        elif hi >= i:
            left = i
        else:
            break
    upper = buf[hi]
    if m % 2 == 1:
        return upper
    lower = buf[0]  # the largest of the values before the middle
    for c in range(1, hi):
        if buf[c] > lower:
            lower = buf[c]
    return (lower + upper) / 2.0


#: Half-width of :func:`counted_median`'s band of integer values (counts array ``2 h + 1``).
COUNT_HALF = 1024


@numba.njit(cache=True, nogil=True)
def _rank_value(counts, below: int, r: int, half: int, lo: int, hi: int) -> float:
    """The ``r``-th smallest value (0-based) from a band's counts; NaN outside the band."""
    if r < below:
        return np.nan
    seen = below
    for b in range(lo, hi + 1):
        seen += counts[b]
        if seen > r:
            return float(b - half)
    return np.nan


@numba.njit(cache=True, nogil=True)
def counted_median(buf: np.ndarray, m: int, counts: np.ndarray) -> float:
    """:func:`median_of` ``buf[:m]`` for integer values, by counting; NaN where it cannot.

    The values are counted in a band of integers ``[-h, h]`` (``counts``: ``2 h + 1`` zeros,
    given back zeroed; ``h`` = :data:`COUNT_HALF`), the middle rank(s) read from the running
    count: ``O(m + range)``, not quickselect's data-dependent swaps. The same middle values as
    a sort, so the same median to the bit (``(lower + upper) / 2`` for even ``m``). NaN
    (nothing counted, ``buf`` untouched) where a value is not an integer or a middle rank lies
    outside the band: the caller then selects (:func:`median_of`).
    """
    half = (counts.size - 1) // 2
    for c in range(m):
        v = buf[c]
        if v != math.floor(v):
            return np.nan
    below = 0
    lo, hi = counts.size, -1
    for c in range(m):
        v = buf[c]
        if v < -half:
            below += 1
        elif v <= half:
            b = int(v) + half
            counts[b] += 1
            lo = min(lo, b)
            hi = max(hi, b)
    h = m // 2
    upper = _rank_value(counts, below, h, half, lo, hi)
    lower = upper if m % 2 == 1 else _rank_value(counts, below, h - 1, half, lo, hi)
    for c in range(m):  # only the touched bins: the band can be much wider than the values
        v = buf[c]
        if -half <= v <= half:
            counts[int(v) + half] = 0
    if m % 2 == 1:
        return upper
    return (lower + upper) / 2.0


@functools.lru_cache(maxsize=16)
def gaussian_weights(sigma: float, truncate: float = 4.0) -> np.ndarray:
    """The weights ``scipy.ndimage.gaussian_filter1d`` correlates with, to the bit.

    Filtering a unit impulse returns them exactly (each output is ``1 · w`` plus zeros).
    """
    from scipy.ndimage import gaussian_filter1d

    half = int(truncate * float(sigma) + 0.5)
    impulse = np.zeros(2 * half + 1)
    impulse[half] = 1.0
    weights = gaussian_filter1d(impulse, sigma, mode="constant", truncate=truncate)
    weights.setflags(write=False)  # cached: shared by every caller
    return weights


@numba.njit(cache=True, nogil=True)
def gaussian_rows(y, base, weights):
    """``gaussian_filter1d(y - base[:, None], σ, axis=1, mode="nearest")``, to the bit.

    Parameters
    ----------
    y : (n, m) float32 or float64
        Rows.
    base : (n,) float64
        Subtracted from each row first.
    weights : (2 r + 1,) float64
        :func:`gaussian_weights` (symmetric).

    Notes
    -----
    scipy's symmetric correlation (``NI_Correlate1D``): ``w_0 x_i`` plus, from the outermost
    tap in, ``(x_{i-j} + x_{i+j}) w_j``; the row extended by its end samples ("nearest").
    """
    n, m = y.shape
    r = (weights.size - 1) // 2
    line = np.empty(m + 2 * r)
    out = np.empty((n, m))
    for p in range(n):
        acc = out[p]
        for c in range(m):
            line[r + c] = np.float64(y[p, c]) - base[p]
        for c in range(r):
            line[c] = line[r]
            line[r + m + c] = line[r + m - 1]
        # tap by tap over the whole row (each output's sum in scipy's order; the compiler
        # vectorises the inner loop)
        w0 = weights[r]
        for i in range(m):
            acc[i] = line[r + i] * w0
        for j in range(r, 0, -1):
            wj = weights[r - j]
            for i in range(m):
                acc[i] += (line[r + i - j] + line[r + i + j]) * wj
    return out
