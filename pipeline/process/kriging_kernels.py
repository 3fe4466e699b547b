"""The sea kriging's per-row matrices, compiled (:mod:`pipeline.process.sea_kriging`).

Each row krigs one point from its ``k`` nearest echoes: the lags between every pair of them
and the ``(k, k)`` covariance matrix. Built with numpy's fancy indexing these took more time
than the solve itself (``(rows, k (k - 1) / 2)`` gathers and two scatters into ``(rows, k,
k)``); here one pass each. Only exact operations (subtraction, product, sum, square root,
copies): the same bits as the numpy expressions they replace (``tests/process/
test_kriging_kernels.py``).
"""

from __future__ import annotations

import numba
import numpy as np

__all__ = ["fill_gram", "pair_lags"]


@numba.njit(cache=True, nogil=True)
def pair_lags(x, y, iu, ju):
    """``sqrt(dx² + dy²)`` of the pairs ``(iu[p], ju[p])`` of each row, ``(rows, n_pairs)``.

    ``x``, ``y``: ``(rows, k)`` float64; ``dx = x[:, iu] - x[:, ju]`` (and ``dy``), summed as
    ``dx * dx + dy * dy`` (no fused multiply-add: numba sets no fast-math).
    """
    rows, n_pairs = x.shape[0], iu.size
    out = np.empty((rows, n_pairs))
    for r in range(rows):
        for p in range(n_pairs):
            dx = x[r, iu[p]] - x[r, ju[p]]
            dy = y[r, iu[p]] - y[r, ju[p]]
            out[r, p] = np.sqrt(dx * dx + dy * dy)
    return out


@numba.njit(cache=True, nogil=True)
def fill_gram(upper, ok, iu, ju, diag_value):
    """Each row's symmetric ``(k, k)`` matrix, ``(rows, k, k)``.

    ``upper[:, p]`` (``(rows, n_pairs)``) at ``(iu[p], ju[p])`` and its mirror where both
    echoes are in their time window (``ok``, ``(rows, k)`` bool; else 0), ``diag_value`` on
    the diagonal.
    """
    rows, k = ok.shape
    gram = np.empty((rows, k, k))
    for r in range(rows):
        for p in range(iu.size):
            i, j = iu[p], ju[p]
            v = upper[r, p] * (1.0 if (ok[r, i] and ok[r, j]) else 0.0)
            gram[r, i, j] = v
            gram[r, j, i] = v
        for i in range(k):
            gram[r, i, i] = diag_value
    return gram
