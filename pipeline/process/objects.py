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

import math
from dataclasses import dataclass

import numba
import numpy as np
from scipy.spatial import cKDTree

from pipeline.cell_keys import cell_inverse
from pipeline.config import setting
from pipeline.parallel import thread_map_rows
from pipeline.process.classify import BATHYMETRIC_POINT, SUBMERGED_OBJECT
from pipeline.process.returns import Points, ReturnKind
from pipeline.process.row_kernels import median_of

__all__ = [
    "ObjectSettings",
    "ObjectDetections",
    "SeabedFit",
    "detect_objects",
    "classify_objects",
    "classify_objects_fit",
]

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


def _reference(xy: np.ndarray, z: np.ndarray, cell_m: float) -> np.ndarray:
    """Indices of the cell-median point of each ``cell_m`` cell (by height)."""
    cell = cell_inverse(np.floor(xy / cell_m).astype(np.int64))
    order = np.lexsort((z, cell))
    counts = np.bincount(cell)
    start = np.concatenate([[0], np.cumsum(counts)[:-1]])
    return order[start + (counts - 1) // 2]


def detect_objects(xy_m, z_m, sigma_z_m, settings: ObjectSettings = ObjectSettings(), tested=None):
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
    tested : (n,) bool, optional
        The points tested (default: all). Every point is still a reference point: a tested
        point's figures are those it gets when all are tested (a block of a survey tests only
        the points whose result it keeps, :mod:`pipeline.survey_blocks`). The others are not
        objects, their height and sigma NaN.

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
    query = np.arange(n) if tested is None else np.flatnonzero(np.asarray(tested, dtype=bool))
    if query.size == 0:
        return ObjectDetections(np.zeros(n, bool), nan, nan.copy())
    ref = _reference(xy, z, settings.reference_cell_m)
    tree = cKDTree(xy[ref])
    # rows are independent: blocks keep the (rows, neighbours) temporaries bounded (a survey's
    # points at once took ~3 kB each), run side by side on the stage's threads and give the
    # same figures
    is_obj, height, sigma = thread_map_rows(
        lambda rows: _test_rows(xy, z, sig, ref, tree, query[rows], settings),
        query.size,
        _BLOCK_ROWS,
    )
    if tested is None:
        return ObjectDetections(is_obj, height, sigma)
    full = ObjectDetections(np.zeros(n, bool), nan, nan.copy())
    full.is_object[query], full.height_m[query], full.sigma_m[query] = is_obj, height, sigma
    return full


def _test_rows(xy, z, sig, ref, tree, query: np.ndarray, settings: ObjectSettings):
    """:func:`detect_objects`' test of the points ``query`` ``(m,)``.

    Returns ``(is_object, height_m, sigma_m)``, ``(m,)`` each.
    """
    xy_r = xy[query]
    n = xy_r.shape[0]
    k = int(min(settings.neighbours, ref.size))
    _, idx = tree.query(xy_r, k=k, distance_upper_bound=settings.radius_m)
    idx = np.asarray(idx).reshape(n, k)
    return _test_kernel(
        xy,
        z,
        sig,
        ref,
        idx,
        query,
        settings.min_neighbours,
        settings.iterations,
        settings.min_scale_m,
        settings.k_sigma,
        settings.min_height_m,
    )


@numba.njit(cache=True, nogil=True)
def _test_kernel(xy, z, sig, ref, idx, query, min_nb, iterations, min_scale, k_sigma, min_h):
    """Per row: neighbours' robust plane (Tukey IRLS), height above it and the test's sigma.

    Row ``i`` tests point ``query[i]`` (``sig``: every point's); ``idx`` ``(n, k)``: the
    rows' nearest reference points (``ref.size`` where none). The
    figures of the vectorised test this replaced (medians of the same values; sums and the
    3 x 3 solve in another order: last-bit differences).
    """
    n, k = idx.shape
    n_ref = ref.size
    is_obj = np.zeros(n, np.bool_)
    height = np.full(n, np.nan)
    sigma = np.full(n, np.nan)
    dx = np.empty(k)
    dy = np.empty(k)
    dz = np.empty(k)
    buf = np.empty(k)
    for i in range(n):
        p = query[i]
        m = 0
        for c in range(k):
            if idx[i, c] < n_ref:
                j = ref[idx[i, c]]
                dx[m] = xy[j, 0] - xy[p, 0]
                dy[m] = xy[j, 1] - xy[p, 1]
                dz[m] = z[j] - z[p]
                m += 1
        if m < min_nb:
            continue
        buf[:m] = dz[:m]
        a = median_of(buf, m)
        for c in range(m):
            buf[c] = abs(dz[c] - a)
        scale = max(_MAD_TO_SIGMA * median_of(buf, m), 0.0)
        b = 0.0
        cc = 0.0
        for _ in range(iterations):
            scale = max(scale, min_scale)
            sw = sx = sy = sxx = syy = sxy = sz = sxz = syz = 0.0
            for c in range(m):
                u = (dz[c] - (a + b * dx[c] + cc * dy[c])) / (_TUKEY_C * scale)
                if abs(u) < 1.0:
                    w = (1.0 - u * u) ** 2
                    sw += w
                    sx += w * dx[c]
                    sy += w * dy[c]
                    sxx += w * dx[c] * dx[c]
                    syy += w * dy[c] * dy[c]
                    sxy += w * dx[c] * dy[c]
                    sz += w * dz[c]
                    sxz += w * dx[c] * dz[c]
                    syz += w * dy[c] * dz[c]
            a, b, cc = _plane3(sw, sx, sy, sxx, syy, sxy, sz, sxz, syz)
            for c in range(m):
                buf[c] = abs(dz[c] - (a + b * dx[c] + cc * dy[c]))
            scale = _MAD_TO_SIGMA * median_of(buf, m)
            if not np.isfinite(scale):
                scale = 0.0
        # the residuals of a 3-parameter fit to m points shrink by sqrt((m - 3) / m); the
        # plane's own value at the point is uncertain by about scale / sqrt(m)
        mm = max(m, 4)
        scale = max(scale * math.sqrt(mm / (mm - 3.0)), min_scale)
        h = -a  # the plane passes a above the point
        s = math.sqrt(sig[p] * sig[p] + scale * scale * (1.0 + 1.0 / mm))
        height[i] = h
        sigma[i] = s
        is_obj[i] = h > k_sigma * s and h >= min_h
    return is_obj, height, sigma


@numba.njit(cache=True, nogil=True)
def _plane3(sw, sx, sy, sxx, syy, sxy, sz, sxz, syz):
    """The weighted least-squares plane ``dz = a + b dx + c dy`` from its sums (ridge on b, c).

    The 3 x 3 normal equations solved by Cramer's rule (symmetric, positive definite with
    the ridge).
    """
    # ridge: a tiny multiple of the neighbourhood's own spread (collinear profiler lines,
    # a single neighbour); without weight at all the plane falls back to a = 0 (no object)
    ridge = 1e-6 * (sxx + syy) + 1e-12
    m00, m01, m02 = sw + 1e-12, sx, sy
    m11, m12, m22 = sxx + ridge, sxy, syy + ridge
    c00 = m11 * m22 - m12 * m12
    c01 = m02 * m12 - m01 * m22
    c02 = m01 * m12 - m02 * m11
    det = m00 * c00 + m01 * c01 + m02 * c02
    a = (c00 * sz + c01 * sxz + c02 * syz) / det
    b = (c01 * sz + (m00 * m22 - m02 * m02) * sxz + (m01 * m02 - m00 * m12) * syz) / det
    c = (c02 * sz + (m01 * m02 - m00 * m12) * sxz + (m00 * m11 - m01 * m01) * syz) / det
    return a, b, c


def classify_objects(points: Points, settings: ObjectSettings, tested=None) -> tuple[Points, int]:
    """Seabed points that stand above the seabed set to class 43; and how many.

    The class-40 bottom returns that :func:`detect_objects` finds become class 43.

    The test's sigma is each point's ``uncertainty_v_m`` (its TPU once
    :func:`pipeline.uncertainty.survey_uncertainty.with_tpu` has run). ``tested``
    ``(n_points,)`` bool: the points tested (default: all); every class-40 bottom is still a
    reference point (:func:`detect_objects`), the others keep their class.
    """
    out, n, _ = classify_objects_fit(points, settings, tested)
    return out, n


@dataclass(frozen=True, eq=False)
class SeabedFit:
    """The object test's local seabed fits, kept for the far-below test of the same points.

    The rejection test (:func:`pipeline.process.seabed_outliers.reject_seabed_outliers`)
    fits the same robust planes to the class-40 bottoms left after the objects and its
    first two rules: where those are the very points fitted here (no object found, none
    rejected before), at the same positions, TPU and tested rows, its fit would be this one
    to the bit, and it reads this one instead (the fit is half of processing's class tests).

    Attributes
    ----------
    rows : (m,) int ndarray
        The fitted points (class-40 bottoms), indices into the classified points.
    xyz_m, sigma_z_m : (m, 3), (m,) ndarray
        Their positions and vertical TPU as fitted.
    tested : (m,) bool ndarray or None
        The rows tested (None: all).
    settings : ObjectSettings
    found : ObjectDetections
        Per row.
    """

    rows: np.ndarray
    xyz_m: np.ndarray
    sigma_z_m: np.ndarray
    tested: np.ndarray | None
    settings: ObjectSettings
    found: ObjectDetections

    def reads(self, xyz_m, sigma_z_m, tested, settings: ObjectSettings) -> bool:
        """Whether a fit of these rows' positions, TPU, tested rows and settings is this one."""
        if (self.tested is None) != (tested is None):
            return False
        if tested is not None and not np.array_equal(self.tested, tested):
            return False
        return (
            settings == self.settings
            and np.array_equal(self.xyz_m, xyz_m)
            and np.array_equal(self.sigma_z_m, sigma_z_m, equal_nan=True)
        )


def classify_objects_fit(
    points: Points, settings: ObjectSettings, tested=None
) -> tuple[Points, int, SeabedFit | None]:
    """:func:`classify_objects`, and its seabed fits for the rejection test (None: no fit)."""
    sea = (points.classification == BATHYMETRIC_POINT) & (points.kind == ReturnKind.BOTTOM)
    if not settings.enabled or not sea.any():
        return points, 0, None
    idx = np.flatnonzero(sea)
    xyz = points.xyz_m[idx]
    sig = points.uncertainty_v_m[idx]
    test = None if tested is None else np.asarray(tested, dtype=bool)[idx]
    found = detect_objects(xyz[:, :2], xyz[:, 2], sig, settings, test)
    cls = points.classification.copy()
    cls[idx[found.is_object]] = SUBMERGED_OBJECT
    # an object leaves the class-40 points the rejection test fits: never read then
    fit = None if found.is_object.any() else SeabedFit(idx, xyz, sig, test, settings, found)
    return points.replace(classification=cls), int(found.is_object.sum()), fit
