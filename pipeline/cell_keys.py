"""Which cell each point falls in, numbered as ``np.unique(ij, axis=0)`` numbers them, unsorted.

``np.unique(ij, axis=0, return_inverse=True)`` on ``(n, 2)`` integer cell indices sorts the rows
as records: on a survey block of a million points, about a second per call, and the TPU's
seabed gradient, its wave pool and the class-43 test's reference cells each make one
(``benchmarks/RESULTS_e2e.md``, session 36). :func:`cell_inverse` gives the same numbers from
one integer per row: cells present marked in a table over the rows' span where that is small
(no sort at all), else a sort of plain integers.
"""

from __future__ import annotations

import numpy as np

__all__ = ["cell_inverse"]

#: a table of the cells' span is used up to this many entries per point (and at least 1 M)
_DENSE_PER_POINT = 8


def cell_inverse(ij) -> np.ndarray:
    """``np.unique(ij, axis=0, return_inverse=True)[1]`` of integer rows, ``(n,)`` int64.

    Parameters
    ----------
    ij : (n, 2) array_like of int
        Cell indices (any sign).

    Returns
    -------
    (n,) int64
        Each row's rank among the distinct rows ordered by the first column, then the second
        (as :func:`numpy.unique` orders them).
    """
    k = np.asarray(ij, dtype=np.int64).reshape(-1, 2)
    n = len(k)
    if n == 0:
        return np.zeros(0, dtype=np.int64)
    lo, hi = k.min(axis=0), k.max(axis=0)
    # spans as Python ints: neither they nor their product can overflow
    s0, s1 = (int(b) - int(a) + 1 for a, b in zip(lo, hi, strict=True))
    if s0 * s1 >= 2**62:  # too wide for one integer per row: numpy's own
        return np.unique(k, axis=0, return_inverse=True)[1].ravel().astype(np.int64)
    flat = (k[:, 0] - lo[0]) * np.int64(s1) + (k[:, 1] - lo[1])
    if s0 * s1 <= max(_DENSE_PER_POINT * n, 2**20):
        present = np.zeros(s0 * s1, dtype=bool)
        present[flat] = True
        rank = np.cumsum(present, dtype=np.int64) - 1
        return rank[flat]
    return np.unique(flat, return_inverse=True)[1].ravel().astype(np.int64)
