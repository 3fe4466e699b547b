"""Submerged objects (LAS class 43) from the measured seabed points alone.

A seabed point is a *submerged object* candidate when it stands above a robust fit of the
seabed around it by more than ``k_sigma`` times its expected deviation and by at least
``min_height_m``. This is the points-side half of IHO S-44 (6th ed., 2020) feature detection:
a cube of side 0.5-2 m standing on the seabed shows as soundings shallower than their
neighbours by about its height.

Method, per seabed point ``i`` (vectorised over all points):

1. **Reference set**: the points are thinned to the cell-median point of each
   ``reference_cell_m`` cell, so the neighbourhood spans metres even along a dense profiler
   line (where the nearest points of a raw cloud all lie on the object itself).
2. **Neighbours**: the ``neighbours`` nearest reference points within ``radius_m``.
3. **Robust local plane** through them, ``z = a + b dx + c dy`` about the point, by iteratively
   reweighted least squares with Tukey's biweight (tuning constant 4.685, 95 % efficiency at
   the normal), started from the neighbours' median height and a robust scale
   ``1.4826 MAD`` of the residuals (Huber 1981, *Robust Statistics*; the same M-estimator
   family as the robust surface fits of lidar ground filters). Points on the object itself are
   a minority of the neighbourhood for objects smaller than the neighbourhood, and the
   biweight gives them no weight. A small ridge on the slopes keeps a profiler's collinear
   neighbourhood solvable (its cross-track slope is then 0, which does not change the plane at
   the point, on the line).
4. **Test**: the height above the plane ``h = z_i - a`` against
   ``sigma = sqrt(sigma_i^2 + s_i^2 (1 + 1/m))``: ``sigma_i`` the point's own vertical TPU,
   ``s_i`` the robust scale of the ``m`` neighbours about the plane (the seabed's own relief
   and noise, which the TPU does not model; corrected for the 3 fitted parameters), ``s_i^2/m``
   the plane's own uncertainty. Candidate when ``h > k_sigma sigma`` and
   ``h >= min_height_m`` and the point has at least ``min_neighbours`` neighbours.

Only points *above* the seabed are objects (IHO features are hazards to navigation: shoal
side). Measured data only: coordinates, heights and the TPU of the points.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from pipeline.config import setting
from pipeline.parallel import thread_map_rows
from pipeline.process.classify import BATHYMETRIC_POINT, SUBMERGED_OBJECT
from pipeline.process.returns import Points, ReturnKind

__all__ = ["ObjectSettings", "ObjectDetections", "detect_objects", "classify_objects"]

#: Tukey biweight tuning constant (95 % efficiency at the normal distribution)
_TUKEY_C = 4.685
#: MAD to standard deviation at the normal distribution
_MAD_TO_SIGMA = 1.4826
#: points tested at once (memory: ~3 kB per point of temporaries with 48 neighbours)
_BLOCK_ROWS = 8192


@dataclass(frozen=True, kw_only=True)
class ObjectSettings:
    """Submerged-object detection (class 43) from the seabed points (``[process.objects]``)."""

    enabled: bool = setting(True, doc="reclassify seabed points standing above the seabed as 43")
    k_sigma: float = setting(
        4.0,
        gt=0.0,
        le=100.0,
        doc="height above the local seabed fit, in sigmas of the point (TPU) and the fit",
    )
    min_height_m: float = setting(
        0.25,
        ge=0.0,
        le=100.0,
        doc="smallest object height (half the smallest IHO S-44 cube, 0.5 m)",
    )
    radius_m: float = setting(10.0, gt=0.0, le=1000.0, doc="largest neighbour distance")
    neighbours: int = setting(48, ge=4, le=1000, doc="reference points in the local seabed fit")
    min_neighbours: int = setting(8, ge=4, le=1000, doc="fewer neighbours: no test")
    reference_cell_m: float = setting(
        0.5, gt=0.0, le=100.0, doc="thinning cell of the reference points (one median each)"
    )
    min_scale_m: float = setting(
        0.01, gt=0.0, le=10.0, doc="floor of the fit's robust scale (numerical)"
    )
    iterations: int = setting(4, ge=1, le=50, doc="reweighting iterations of the seabed fit")

    def __post_init__(self) -> None:
        if self.min_neighbours > self.neighbours:
            raise ValueError("`min_neighbours` must not exceed `neighbours`")


@dataclass(frozen=True)
class ObjectDetections:
    """Per input point: candidate flag, height above the seabed fit, and the test's sigma.

    Attributes
    ----------
    is_object : (n,) bool
    height_m : (n,) float64
        Height above the local seabed fit (NaN where too few neighbours).
    sigma_m : (n,) float64
        The test's sigma (module docstring; NaN where too few neighbours).
    """

    is_object: np.ndarray
    height_m: np.ndarray
    sigma_m: np.ndarray


#: Rows at least this long: ``np.nanmedian`` takes another path (:func:`_row_median`).
_SHORT_ROW = 600


def _reference(xy: np.ndarray, z: np.ndarray, cell_m: float) -> np.ndarray:
    """Indices of the cell-median point of each ``cell_m`` cell (by height)."""
    ij = np.floor(xy / cell_m).astype(np.int64)
    _, cell = np.unique(ij, axis=0, return_inverse=True)
    cell = cell.ravel()
    order = np.lexsort((z, cell))
    counts = np.bincount(cell)
    start = np.concatenate([[0], np.cumsum(counts)[:-1]])
    return order[start + (counts - 1) // 2]


def _row_median(v: np.ndarray, ok: np.ndarray) -> np.ndarray:
    """Median of each row over ``ok`` entries (NaN for a row without any).

    ``np.nanmedian(..., axis=1)``'s figures, the way it makes them for rows shorter than
    :data:`_SHORT_ROW` (``np.ma.median``: the masked entries filled with +inf, one argsort per
    row, the sum of the two middle entries over 2), without the masked arrays around it (most
    of the object test's time). The same argsort keeps even the order of ties (-0.0, +0.0).
    A row without any entry gives NaN here without nanmedian's "All-NaN slice" warning.
    """
    a = np.where(ok, v, np.nan)
    n_rows, n_cols = a.shape
    if n_cols == 0 or n_cols >= _SHORT_ROW:
        with np.errstate(all="ignore"):
            return np.nanmedian(a, axis=1)
    missing = np.isnan(a)
    order = np.where(missing, np.inf, a).argsort(axis=1)
    count = n_cols - np.count_nonzero(missing, axis=1)
    hi = count // 2
    lo = np.where(count % 2 == 1, hi, hi - 1)
    rows = np.arange(n_rows)
    pick = np.stack(
        [a[rows, order[rows, np.maximum(lo, 0)]], a[rows, order[rows, np.minimum(hi, n_cols - 1)]]],
        axis=1,
    )
    # summed as np.ma.median sums them (a reduction over the pair: -0.0 + -0.0 gives +0.0)
    with np.errstate(invalid="ignore"):
        return np.where(count > 0, pick.sum(axis=1) / 2.0, np.nan)


def detect_objects(xy_m, z_m, sigma_z_m, settings: ObjectSettings = ObjectSettings()):
    """Seabed points standing above a robust local seabed fit (see the module docstring).

    Parameters
    ----------
    xy_m : (n, 2) array_like
        Horizontal positions of the seabed points (local frame).
    z_m : (n,) array_like
        Their elevations (up positive).
    sigma_z_m : (n,) array_like
        Their vertical 1-sigma uncertainty (TPU); non-finite counts as 0.
    settings : ObjectSettings

    Returns
    -------
    ObjectDetections
    """
    xy = np.asarray(xy_m, dtype=np.float64).reshape(-1, 2)
    z = np.asarray(z_m, dtype=np.float64).ravel()
    sig = np.nan_to_num(np.asarray(sigma_z_m, dtype=np.float64).ravel(), nan=0.0, posinf=0.0)
    n = z.size
    nan = np.full(n, np.nan)
    if n == 0 or n < settings.min_neighbours:
        return ObjectDetections(np.zeros(n, bool), nan, nan.copy())
    ref = _reference(xy, z, settings.reference_cell_m)
    tree = cKDTree(xy[ref])
    # rows are independent: blocks keep the (rows, neighbours) temporaries bounded (a survey's
    # points at once took ~3 kB each), run side by side on the stage's threads and give the
    # same figures
    is_obj, height, sigma = thread_map_rows(
        lambda rows: _test_rows(xy, z, sig[rows], ref, tree, rows, settings), n, _BLOCK_ROWS
    )
    return ObjectDetections(is_obj, height, sigma)


def _test_rows(xy, z, sig, ref, tree, rows: slice, settings: ObjectSettings):
    """:func:`detect_objects`' test of the points ``rows``: (is_object, height_m, sigma_m)."""
    xy_r, z_r = xy[rows], z[rows]
    n = z_r.size
    k = int(min(settings.neighbours, ref.size))
    dist, idx = tree.query(xy_r, k=k, distance_upper_bound=settings.radius_m)
    dist, idx = dist.reshape(n, k), idx.reshape(n, k)
    ok = idx < ref.size
    j = ref[np.where(ok, idx, 0)]
    dx, dy = xy[j, 0] - xy_r[:, :1], xy[j, 1] - xy_r[:, 1:]
    dz = z[j] - z_r[:, None]  # neighbour heights relative to the point
    enough = ok.sum(axis=1) >= settings.min_neighbours

    a = np.nan_to_num(_row_median(dz, ok))
    b = np.zeros(n)
    c = np.zeros(n)
    scale = np.maximum(np.nan_to_num(_MAD_TO_SIGMA * _row_median(np.abs(dz - a[:, None]), ok)), 0)
    for _ in range(settings.iterations):
        scale = np.maximum(scale, settings.min_scale_m)
        r = dz - (a[:, None] + b[:, None] * dx + c[:, None] * dy)
        u = r / (_TUKEY_C * scale[:, None])
        w = np.where(ok & (np.abs(u) < 1.0), (1.0 - u * u) ** 2, 0.0)
        a, b, c = _weighted_plane(dx, dy, dz, w)
        r = dz - (a[:, None] + b[:, None] * dx + c[:, None] * dy)
        scale = np.nan_to_num(_MAD_TO_SIGMA * _row_median(np.abs(r), ok))
    # the residuals of a 3-parameter fit to m points shrink by sqrt((m - 3) / m); the plane's
    # own value at the point is uncertain by about scale / sqrt(m)
    m = np.maximum(ok.sum(axis=1), 4)
    scale = np.maximum(scale * np.sqrt(m / (m - 3.0)), settings.min_scale_m)
    height = np.where(enough, -a, np.nan)  # the plane passes a above the point: h = -a
    sigma = np.where(enough, np.sqrt(sig * sig + scale * scale * (1.0 + 1.0 / m)), np.nan)
    with np.errstate(invalid="ignore"):
        is_obj = enough & (height > settings.k_sigma * sigma) & (height >= settings.min_height_m)
    return is_obj, height, sigma


def _weighted_plane(dx, dy, dz, w):
    """Per row, the weighted least-squares plane ``dz = a + b dx + c dy`` (ridge on b, c)."""
    sw = w.sum(axis=1)
    sx, sy = (w * dx).sum(axis=1), (w * dy).sum(axis=1)
    sxx, syy, sxy = (w * dx * dx).sum(axis=1), (w * dy * dy).sum(axis=1), (w * dx * dy).sum(axis=1)
    # ridge: a tiny multiple of the neighbourhood's own spread (collinear profiler lines,
    # a single neighbour); without weight at all the plane falls back to a = 0 (no object)
    ridge = 1e-6 * (sxx + syy) + 1e-12
    m = np.empty((dx.shape[0], 3, 3))
    m[:, 0] = np.stack([sw + 1e-12, sx, sy], axis=1)
    m[:, 1] = np.stack([sx, sxx + ridge, sxy], axis=1)
    m[:, 2] = np.stack([sy, sxy, syy + ridge], axis=1)
    rhs = np.stack([(w * dz).sum(axis=1), (w * dx * dz).sum(axis=1), (w * dy * dz).sum(axis=1)], 1)
    sol = np.linalg.solve(m, rhs[..., None])[..., 0]
    return sol[:, 0], sol[:, 1], sol[:, 2]


def classify_objects(points: Points, settings: ObjectSettings) -> tuple[Points, int]:
    """Seabed points that stand above the seabed set to class 43; and how many.

    The class-40 bottom returns that :func:`detect_objects` finds become class 43.

    The test's sigma is each point's ``uncertainty_v_m`` (its TPU once
    :func:`pipeline.uncertainty.survey_uncertainty.with_tpu` has run).
    """
    sea = (points.classification == BATHYMETRIC_POINT) & (points.kind == ReturnKind.BOTTOM)
    if not settings.enabled or not sea.any():
        return points, 0
    idx = np.flatnonzero(sea)
    xyz = points.xyz_m[idx]
    found = detect_objects(xyz[:, :2], xyz[:, 2], points.uncertainty_v_m[idx], settings)
    cls = points.classification.copy()
    cls[idx[found.is_object]] = SUBMERGED_OBJECT
    return points.replace(classification=cls), int(found.is_object.sum())
