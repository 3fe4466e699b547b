"""The sea kriging's per-row matrices, compiled (:mod:`pipeline.process.sea_kriging`).

Each row krigs one point from its ``k`` nearest echoes: the lags between every pair of them
and the ``(k, k)`` covariance matrix. Built with numpy's fancy indexing these took more time
than the solve itself (``(rows, k (k - 1) / 2)`` gathers and two scatters into ``(rows, k,
k)``); here one pass each. Only exact operations (subtraction, product, sum, square root,
copies): the same bits as the numpy expressions they replace (``tests/process/
test_kriging_kernels.py``).

The systems are solved by Cholesky factors (:func:`spd_solve`): a covariance matrix with its
nugget is symmetric positive definite, and a compiled ``12 x 12`` factorisation costs a
fraction of LAPACK's batched LU through numpy (its per-matrix call and copies). Not the same
bits as the LU (a few ``1e-16`` of the condition number); a row whose factor fails (a pivot
not positive: a matrix not positive definite) is left to ``np.linalg.solve``.
"""

from __future__ import annotations

import numba
import numpy as np

__all__ = ["fill_gram", "pair_lags", "spd_solve"]


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


@numba.njit(cache=True, nogil=True)
def _cholesky_solve(a, b):
    """Per row: ``a[r] x = b[r]`` by ``a[r] = L L^T``; ``x`` and ``(rows,)`` bool: factored."""
    rows, k = b.shape
    x = np.empty((rows, k))
    ok = np.ones(rows, np.bool_)
    f = np.empty((k, k))
    for r in range(rows):
        for j in range(k):
            s = a[r, j, j]
            for p in range(j):
                s -= f[j, p] * f[j, p]
            if not s > 0.0:  # also NaN
                ok[r] = False
                break
            d = np.sqrt(s)
            f[j, j] = d
            for i in range(j + 1, k):
                t = a[r, i, j]
                for p in range(j):
                    t -= f[i, p] * f[j, p]
                f[i, j] = t / d
        if not ok[r]:
            x[r, :] = np.nan
            continue
        for i in range(k):  # L y = b
            t = b[r, i]
            for p in range(i):
                t -= f[i, p] * x[r, p]
            x[r, i] = t / f[i, i]
        for i in range(k - 1, -1, -1):  # L^T x = y
            t = x[r, i]
            for p in range(i + 1, k):
                t -= f[p, i] * x[r, p]
            x[r, i] = t / f[i, i]
    return x, ok


def spd_solve(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Solutions of symmetric positive definite systems, ``(rows, k)``.

    Parameters
    ----------
    a : (rows, k, k) float64
        Symmetric (the lower triangle is read).
    b : (rows, k) float64

    Returns
    -------
    (rows, k) float64
        ``x`` with ``a[r] @ x[r] = b[r]``; rows that are not positive definite are solved by
        ``np.linalg.solve`` (which raises where one is singular).
    """
    a = np.ascontiguousarray(a, dtype=np.float64)
    b = np.ascontiguousarray(b, dtype=np.float64)
    if a.ndim != 3 or a.shape[1] != a.shape[2] or b.shape != a.shape[:2]:
        raise ValueError(f"spd_solve needs (rows, k, k) and (rows, k); got {a.shape}, {b.shape}")
    x, ok = _cholesky_solve(a, b)
    if not ok.all():
        bad = np.flatnonzero(~ok)
        x[bad] = np.linalg.solve(a[bad], b[bad][..., None])[..., 0]
    return x
