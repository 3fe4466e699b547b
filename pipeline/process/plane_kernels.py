"""Compiled pieces of the batched weighted planes: their normal equations and 3 x 3 inverses.

The local water planes (:func:`pipeline.process.surface_plane.solve_plane`) and the seabed's
Bayesian planes (:func:`pipeline.uncertainty.seabed_gradient._bayes_planes`) solve, for each of
``m`` queries, ``z = a + b dx + c dy`` from its ``k`` weighted neighbours. In numpy that was
eleven ``(m, k)`` products and sums and a LAPACK inverse per ``3 x 3`` matrix: about 1.7 us a
matrix, a twentieth of a blocked survey's processing (``benchmarks/RESULTS_e2e.md``).

* :func:`plane_moments` gives the nine weighted sums of the normal equations in one pass over
  each row, added in numpy's pairwise order (:func:`~pipeline.process.row_kernels.pairwise_sum`):
  the figures of the ``(w * dx * dx).sum(1)`` expressions it replaces, to the bit.
* :func:`sym3_inverse` inverts symmetric ``3 x 3`` matrices by their cofactors. It is not
  LAPACK's LU (the last bits differ: about ``1e-16`` of the matrix's condition number), and it
  is exact where it matters to the callers: ``A @ inv = I`` to rounding on every positive
  definite matrix (``tests/process/test_plane_kernels.py`` checks it against
  ``np.linalg.inv``). A singular or non-finite matrix gives NaN rows, as a failed LAPACK
  inverse would raise: the callers replace such rows (no neighbour: the identity) before.
"""

from __future__ import annotations

import numba
import numpy as np

from pipeline.process.row_kernels import pairwise_sum

__all__ = ["MOMENTS", "normal_equations", "plane_moments", "sym3_inverse"]

#: The columns of :func:`plane_moments`, in order (``w`` weight, ``x = dx``, ``y = dy``).
MOMENTS = ("w", "wx", "wy", "wxx", "wyy", "wxy", "wz", "wxz", "wyz")


@numba.njit(cache=True, nogil=True)
def _moments(w, dx, dy, z):
    m, k = w.shape
    out = np.empty((m, 9))
    buf = np.empty((9, k))
    for p in range(m):
        for c in range(k):
            wc = w[p, c]
            wx = wc * dx[p, c]
            wy = wc * dy[p, c]
            buf[0, c] = wc
            buf[1, c] = wx
            buf[2, c] = wy
            buf[3, c] = wx * dx[p, c]
            buf[4, c] = wy * dy[p, c]
            buf[5, c] = wx * dy[p, c]
            buf[6, c] = wc * z[p, c]
            buf[7, c] = wx * z[p, c]
            buf[8, c] = wy * z[p, c]
        for j in range(9):
            out[p, j] = pairwise_sum(buf[j], 0, k)
    return out


def plane_moments(w, dx, dy, z) -> np.ndarray:
    """The weighted sums of the plane's normal equations, per row.

    Parameters
    ----------
    w, dx, dy, z : (m, k) array_like
        Weights (0: unused), offsets from the query (m) and values.

    Returns
    -------
    (m, 9) float64
        Columns :data:`MOMENTS`: ``sum(w)``, ``sum(w dx)``, ``sum(w dy)``, ``sum(w dx dx)``,
        ``sum(w dy dy)``, ``sum(w dx dy)``, ``sum(w z)``, ``sum(w dx z)``, ``sum(w dy z)``,
        each the value numpy's ``((w * dx) * dx).sum(1)`` gives.
    """
    arrays = [np.ascontiguousarray(a, dtype=np.float64) for a in (w, dx, dy, z)]
    shape = arrays[0].shape
    if len(shape) != 2 or any(a.shape != shape for a in arrays):
        raise ValueError(f"plane_moments needs four (m, k) arrays alike; got {shape}")
    return _moments(*arrays)


@numba.njit(cache=True, nogil=True)
def _sym3_inverse(a):
    m = a.shape[0]
    out = np.empty((m, 3, 3))
    for p in range(m):
        a00, a01, a02 = a[p, 0, 0], a[p, 0, 1], a[p, 0, 2]
        a11, a12, a22 = a[p, 1, 1], a[p, 1, 2], a[p, 2, 2]
        c00 = a11 * a22 - a12 * a12
        c01 = a02 * a12 - a01 * a22
        c02 = a01 * a12 - a02 * a11
        det = a00 * c00 + a01 * c01 + a02 * c02
        if det == 0.0 or not np.isfinite(det):
            out[p, :, :] = np.nan
            continue
        inv_det = 1.0 / det
        c11 = a00 * a22 - a02 * a02
        c12 = a01 * a02 - a00 * a12
        c22 = a00 * a11 - a01 * a01
        out[p, 0, 0] = c00 * inv_det
        out[p, 0, 1] = out[p, 1, 0] = c01 * inv_det
        out[p, 0, 2] = out[p, 2, 0] = c02 * inv_det
        out[p, 1, 1] = c11 * inv_det
        out[p, 1, 2] = out[p, 2, 1] = c12 * inv_det
        out[p, 2, 2] = c22 * inv_det
    return out


def sym3_inverse(a) -> np.ndarray:
    """Inverses of symmetric ``3 x 3`` matrices (their upper triangles are read).

    Parameters
    ----------
    a : (m, 3, 3) array_like

    Returns
    -------
    (m, 3, 3) float64
        Symmetric; NaN for a row whose determinant is 0 or not finite.
    """
    a = np.ascontiguousarray(a, dtype=np.float64)
    if a.ndim != 3 or a.shape[1:] != (3, 3):
        raise ValueError(f"sym3_inverse needs (m, 3, 3) matrices; got {a.shape}")
    return _sym3_inverse(a)


def normal_equations(mom: np.ndarray, ridge=0.0) -> tuple[np.ndarray, np.ndarray]:
    """The plane's normal matrix ``(m, 3, 3)`` and right-hand side ``(m, 3)`` from its moments.

    ``mom``: :func:`plane_moments`' ``(m, 9)``; ``ridge`` (scalar or ``(m,)``) is added to the
    two slopes' diagonal. Both are new arrays, free to be scaled in place.
    """
    a = np.empty((len(mom), 3, 3))
    a[:, 0, 0] = mom[:, 0]
    a[:, 0, 1] = a[:, 1, 0] = mom[:, 1]
    a[:, 0, 2] = a[:, 2, 0] = mom[:, 2]
    a[:, 1, 1] = mom[:, 3] + ridge
    a[:, 2, 2] = mom[:, 4] + ridge
    a[:, 1, 2] = a[:, 2, 1] = mom[:, 5]
    return a, mom[:, 6:9].copy()
