"""The seabed under a shared detection: the spread of depth over a photon window's footprint.

A photon-counting window accumulates ``shots_per_window`` shots into one height histogram and
detects one bottom for all of them (:mod:`pipeline.process.detect_photons`): every shot of the
window reports that one depth at its own position. Over a sloping seabed the true depth under
the shots differs by ``g . (p_i - p_mean)``, with ``g`` the seabed's depth gradient and
``p_mean`` the window's mean position, so the window's depth misses each shot's by that much.
The term (random: it averages over windows, not within one) is the rms of that spread over
the window,

    s_window = sqrt(mean_window((g . (p_i - p_mean))²))

both in elevation and in depth (the shots share the water surface). Relief within the window
that the local plane of ``g`` does not follow (roughness) is not in it: one depth per window
cannot show it.

The window's water surface is one detection too: every shot enters the sea at the window's
height carried along its fitted plane's slope from the window's centre
(:mod:`pipeline.process.surface_fit`, step 3), and its depth is read below that plane, while
the sea under each shot differs from both by the sea's slope that the plane does not follow.
With that slope random of covariance ``C`` (the wave facet's,
:func:`~pipeline.uncertainty.tpu_facet.unresolved_slope_sigma_rad`, measured about the same
planes), the depth spread gains ``mean_window((p_i - p_mean)^T C (p_i - p_mean))`` in variance
(depth only: the sounding's elevation does not see the sea above it). On suite tuning seed 79
(photon profiler, 11.1 m/s, 0.375 m windows over a 2.5° seabed), when the planes were still
fitted shot by shot and followed almost none of the sea's slope, the errors' spread within the
windows was 0.0126 m rms; the term was 0.0050 m (the seabed's part alone) and 0.0105 m with
the sea's.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from pipeline.constants import MAD_TO_SIGMA
from pipeline.uncertainty.seabed_gradient import group_means
from pipeline.uncertainty.tpu_settings import DEPTH, PointTpu, Z

__all__ = [
    "WINDOW_TERM",
    "cell_relief_sigma_m",
    "cell_relief_m",
    "cell_window_sigma_m",
    "window_footprint_sigma_m",
    "with_random_term",
]

#: Name of the term in ``PointTpu.terms``.
WINDOW_TERM = "window_footprint"


def window_footprint_sigma_m(
    xy_m, group, gradient, slope_cov=None, gradient_cov=None
) -> np.ndarray:
    """Rms depth spread of the seabed plane over each point's window, per point.

    Parameters
    ----------
    xy_m : (n, 2) array_like
        Positions of the points.
    group : (n,) array_like of int
        The window (shared detection) of each point.
    gradient : (n, 2) array_like
        Seabed depth gradient ``(d depth / dx, d depth / dy)`` at each point; NaN counts as
        flat.
    slope_cov : (n, 2, 2) array_like, optional
        Covariance of the sea's slope the fitted planes do not follow, at each point (module
        notes); default none.
    gradient_cov : (n, 2, 2) array_like, optional
        Covariance of ``gradient`` (its estimate's, :func:`~pipeline.uncertainty.
        seabed_gradient.seabed_gradient`): the spread's expectation over the gradient's
        uncertainty adds ``off^T G off`` (a window wider than the soundings around it, a
        scan's cell, has a gradient that is barely measured; ignoring it gave 10 m cells
        over a 19° slope a 0.1 mm term against 0.24 m rms errors). Default: the gradient
        taken as exact.

    Returns
    -------
    (n,) float64
        ``sqrt(mean over the window of (g . (p_i - p_mean))²)``, 0 for a window of one point.

    Examples
    --------
    Two shots 2 m apart along x over a slope of 0.1: each is 0.1 m off the window's depth.

    >>> window_footprint_sigma_m([[0.0, 0.0], [2.0, 0.0]], [7, 7], [[0.1, 0.0], [0.1, 0.0]])
    array([0.1, 0.1])
    """
    xy = np.asarray(xy_m, dtype=np.float64).reshape(-1, 2)
    g = np.nan_to_num(np.asarray(gradient, dtype=np.float64).reshape(-1, 2))
    if xy.shape[0] == 0:
        return np.zeros(0)
    _, inv = np.unique(np.asarray(group).ravel(), return_inverse=True)
    cnt = np.bincount(inv).astype(np.float64)
    mean = np.column_stack([np.bincount(inv, weights=xy[:, k]) / cnt for k in range(2)])
    off = xy - mean[inv]
    var = np.sum(g * off, axis=1) ** 2
    for cov in (slope_cov, gradient_cov):
        if cov is not None:
            c = np.nan_to_num(np.asarray(cov, dtype=np.float64).reshape(-1, 2, 2))
            var = var + np.einsum("ni,nij,nj->n", off, c, off)
    return np.sqrt(np.bincount(inv, weights=var)[inv] / cnt[inv])


def cell_relief_sigma_m(xy_m, z_m, group, cell_m, neighbour_cells=2.5) -> float:
    """Relief at a scan's cell scale that a plane through the neighbouring cells misses, m.

    A scan's cell window's bottom is carried to its shots along the seabed's slope
    (:mod:`pipeline.process.photon_carry`): what a plane cannot follow inside the cell, the
    seabed's relief at the cell's scale (roughness of a few metres' correlation), is left in
    every shot's sounding. It is measured where it shows: each window's mean height against
    the plane fitted to its neighbours' within ``neighbour_cells`` cell sides, the robust sd
    (1.4826 MAD) of those misses over the survey (the windows' own noise in it too). On suite
    tuning seed 54 (9° slope, 0.28 m rms relief of 9.5 m correlation, 12 m cells) the
    soundings missed their windows' plane by 0.16 m sd and the windows missed the truth by
    0.19 m, which the slope terms did not hold. 0 with fewer than 4 windows that tell.

    Parameters
    ----------
    xy_m : (n, 2) array_like
        Positions of the soundings.
    z_m : (n,) array_like
        Their heights (or depths).
    group : (n,) array_like
        Each sounding's window.
    cell_m : float
        The cells' side.
    """
    from scipy.spatial import cKDTree

    xy = np.asarray(xy_m, dtype=np.float64).reshape(-1, 2)
    z = np.asarray(z_m, dtype=np.float64).ravel()
    if xy.shape[0] == 0:
        return 0.0
    c, zc = group_means(group, xy, z)
    if zc.size < 5:
        return 0.0
    k = min(24, zc.size)
    dist, nb = cKDTree(c).query(c, k=k, distance_upper_bound=neighbour_cells * cell_m)
    ok = np.isfinite(dist) & (dist > 0.0)
    nb = np.where(ok, nb, 0)
    d = c[nb] - c[:, None, :]
    a = np.stack([np.ones_like(d[..., 0]), d[..., 0], d[..., 1]], axis=-1) * ok[..., None]
    ata = np.einsum("wki,wkj->wij", a, a) + np.eye(3) * 1e-9
    atz = np.einsum("wki,wk->wi", a, np.where(ok, zc[nb], 0.0))
    tell = ok.sum(axis=1) >= 4
    if tell.sum() < 4:
        return 0.0
    intercept = np.linalg.solve(ata[tell], atz[tell][..., None])[:, 0, 0]
    miss = zc[tell] - intercept
    return float(MAD_TO_SIGMA * np.median(np.abs(miss - np.median(miss))))


def cell_relief_m(xy_m, depth_m, height_m, group, cell_m, neighbour_cells=2.5) -> float:
    """The relief a carried cell's plane misses (m; :func:`cell_window_sigma_m`).

    :func:`cell_relief_sigma_m` of the soundings' heights or of their depths, whichever is
    smaller.
    A figure of the whole survey (a pooled MAD): a block of a survey is handed its survey's
    (``TpuSurveyWide.cell_relief_sigma``).
    """
    xy = np.asarray(xy_m, dtype=np.float64).reshape(-1, 2)
    return min(
        cell_relief_sigma_m(xy, depth_m, group, cell_m, neighbour_cells),
        cell_relief_sigma_m(xy, height_m, group, cell_m, neighbour_cells),
    )


def cell_window_sigma_m(
    xy_m,
    depth_m,
    height_m,
    group,
    cell_m,
    gradient,
    gradient_cov,
    neighbour_cells=2.5,
    relief_m: float | None = None,
) -> np.ndarray:
    """The window term of a scan's cell windows, per point, ``(n,)`` m.

    Where a window has at least 3 neighbouring windows of its slab within ``neighbour_cells``
    cell sides, the detector carried its bottom along their slope (:mod:`pipeline.process.
    photon_carry`, the same rule; ``group`` holds the windows' keys): the relief its plane
    misses is left, :func:`cell_relief_sigma_m` of the soundings' heights or of their depths,
    whichever is smaller (each carries a noise the other does not: heights the windows'
    surface detections, depths the waves; on suite tuning seed 46, flat water, 0.034 m from
    heights and 0.006 m from depths against errors of 0.010 m). An isolated window kept one
    height for all its shots: its term is the seabed's spread under them with the gradient's
    uncertainty (:func:`window_footprint_sigma_m`; on suite tuning seed 77, three windows of
    ~850 shots at a Palmer swath's edges over a 7.8° slope missed by 0.5-0.65 m sd while the
    relief term, without neighbours, was 0). ``relief_m``: the survey's relief figure
    (:func:`cell_relief_m`), when the soundings are a block of it.
    """
    from scipy.spatial import cKDTree

    from pipeline.process.photon_carry import SLAB_APART_M
    from pipeline.process.photon_windows import slab_of

    xy = np.asarray(xy_m, dtype=np.float64).reshape(-1, 2)
    if xy.shape[0] == 0:
        return np.zeros(0)
    keys, inv = np.unique(np.asarray(group).ravel(), return_inverse=True)
    c, _ = group_means(inv, xy, np.zeros(len(xy)))
    # neighbours of the same slab within the radius, the window itself left out
    c3 = np.column_stack([c, slab_of(keys) * SLAB_APART_M])
    n_near = cKDTree(c3).query_ball_point(c3, neighbour_cells * cell_m, return_length=True) - 1
    carried = (n_near >= 3)[inv]
    relief = relief_m
    if relief is None:
        relief = cell_relief_m(xy, depth_m, height_m, group, cell_m, neighbour_cells)
    spread = window_footprint_sigma_m(xy, group, gradient, gradient_cov=gradient_cov)
    return np.where(carried, relief, spread)


def with_random_term(
    tpu: PointTpu, name: str, sigma_z_m, sigma_depth_m, correlated: bool = False
) -> PointTpu:
    """``tpu`` with one more random term of the elevation and the depth (not horizontal).

    The totals and their random parts (their correlated parts with ``correlated``: one error
    shared by the survey's soundings) take it in quadrature; ``terms[name]`` holds it.
    """
    sz = np.asarray(sigma_z_m, dtype=np.float64).ravel()
    sd = np.asarray(sigma_depth_m, dtype=np.float64).ravel()
    if sz.shape != (len(tpu),) or sd.shape != (len(tpu),):
        raise ValueError(f"the term must have one value per point ({len(tpu)})")
    term = np.zeros((len(tpu), 4))
    term[:, Z], term[:, DEPTH] = sz, sd

    def add(a, b):
        return None if a is None else np.hypot(a, b)

    return dataclasses.replace(
        tpu,
        terms={**tpu.terms, name: term},
        sigma_v_m=add(tpu.sigma_v_m, sz),
        sigma_depth_m=add(tpu.sigma_depth_m, sd),
        **(
            {
                "sigma_v_correlated_m": add(tpu.sigma_v_correlated_m, sz),
                "sigma_depth_correlated_m": add(tpu.sigma_depth_correlated_m, sd),
            }
            if correlated
            else {
                "sigma_v_random_m": add(tpu.sigma_v_random_m, sz),
                "sigma_depth_random_m": add(tpu.sigma_depth_random_m, sd),
            }
        ),
    )
