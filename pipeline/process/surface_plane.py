"""Batched weighted least-squares planes for the surface fit (:mod:`pipeline.process.surface_fit`).

Every query's plane ``z = a + b dx + c dy`` is solved from its ``k`` neighbours at once, row
by row in stacked arrays: the full plane with a ridge on its slopes (:func:`solve_plane`), or,
where the neighbours lie along one axis, its slope along that axis only (:func:`major_axis`,
:func:`solve_along`); and one surface sample per photon-counting window
(:func:`window_samples`).
"""

from __future__ import annotations

import numpy as np

from pipeline.process.plane_kernels import normal_equations, plane_moments, sym3_inverse

__all__ = ["solve_plane", "major_axis", "solve_along", "window_samples"]


def solve_plane(w, dx, dy, z, lam):
    """Batched weighted least squares with a ridge ``lam`` on the slopes; params and inverse.

    The normal equations' sums and the ``3 x 3`` inverses are compiled
    (:mod:`pipeline.process.plane_kernels`); a row without weight gets the identity.
    """
    mom = plane_moments(w, dx, dy, z)
    sw = mom[:, 0]
    a, rhs = normal_equations(mom, lam)
    bad = sw <= 0
    a[bad] = np.eye(3)
    rhs[bad] = 0.0
    inv = sym3_inverse(a)
    params = np.einsum("mij,mj->mi", inv, rhs)
    return params, inv


def major_axis(w, dx, dy):
    """Unit major axis ``(m, 2)`` of weighted offsets ``(m, k)`` and the spread across it, m²."""
    sw = np.maximum(w.sum(1), 1.0)
    mx, my = (w * dx).sum(1) / sw, (w * dy).sum(1) / sw
    cxx = (w * dx * dx).sum(1) / sw - mx * mx
    cyy = (w * dy * dy).sum(1) / sw - my * my
    cxy = (w * dx * dy).sum(1) / sw - mx * my
    angle = 0.5 * np.arctan2(2.0 * cxy, cxx - cyy)
    half = 0.5 * (cxx + cyy)
    minor = half - np.sqrt(np.maximum(0.25 * (cxx - cyy) ** 2 + cxy**2, 0.0))
    return np.column_stack([np.cos(angle), np.sin(angle)]), minor


def solve_along(w, t, z, lam, e):
    """:func:`solve_plane` with the slope along the unit axes ``e`` (m, 2) only: params, inverse.

    ``t`` (m, k) are the offsets along ``e``. The plane is ``a + s t``: its slope ``(b, c) =
    s e``; the inverse is the ``(a, b, c)`` one of that model (rank 2).
    """
    sw, st_, stt = w.sum(1), (w * t).sum(1), (w * t * t).sum(1) + lam
    sz, stz = (w * z).sum(1), (w * t * z).sum(1)
    det = np.maximum(sw * stt - st_ * st_, 1e-300)
    a = (stt * sz - st_ * stz) / det
    slope = (sw * stz - st_ * sz) / det
    v_aa, v_as, v_ss = stt / det, -st_ / det, sw / det
    inv = np.empty((len(sw), 3, 3))
    inv[:, 0, 0] = v_aa
    inv[:, 0, 1:] = inv[:, 1:, 0] = v_as[:, None] * e
    inv[:, 1:, 1:] = v_ss[:, None, None] * e[:, :, None] * e[:, None, :]
    return np.column_stack([a, slope[:, None] * e]), inv


def window_samples(group, spts, t_s):
    """One surface sample per window: its shots' mean position, height and time.

    Parameters
    ----------
    group : (m,) array_like
        Window of each surface point.
    spts : (m, 3) ndarray
        ``(x, y, height)`` of the surface points.
    t_s : (m,) ndarray or None
        Their emission times.

    Returns
    -------
    samples : (w, 3) ndarray
    t_s : (w,) ndarray or None
    centre_xy : (m, 2) ndarray
        Each point's window centre.
    """
    _, inv = np.unique(np.asarray(group).ravel(), return_inverse=True)
    cnt = np.bincount(inv).astype(np.float64)
    samples = np.column_stack([np.bincount(inv, weights=spts[:, k]) / cnt for k in range(3)])
    t_w = None if t_s is None else np.bincount(inv, weights=t_s) / cnt
    return samples, t_w, samples[inv, :2]
