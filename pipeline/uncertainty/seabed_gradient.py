"""The seabed's depth gradient under each sounding, and how well the soundings know it.

A sounding put beside where it truly is (navigation, pointing, a wave facet the fitted water
plane did not follow) is read against the seabed at the measured position: the TPU couples its
horizontal errors into the depth through the seabed gradient ``g``
(:mod:`pipeline.uncertainty.tpu`). ``g`` is measured from the soundings themselves (their
heights below a level datum: depths below the sea at each pulse's time carry the waves'
slope), as a Bayesian linear regression at two scales (Gelman et al. 2013, *Bayesian Data
Analysis*, §14.8, the normal linear model with a normal prior on the coefficients):

1. **Regional**: at each ``regional_cell_m`` cell (a sounding takes its nearest cell's), a
   plane ``depth = a + b dx + c dy`` through the cells' mean soundings (the
   ``regional_neighbours`` nearest within ``regional_radius_m``),
   its slope under a normal prior ``N(0, s_0² I)`` (``s_0 = tan(prior_slope_deg)`` per axis, the
   slope assumed where no sounding tells), the noise variance the cells' residual variance
   (which holds the relief a plane over tens of metres does not follow).
2. **Local**: the same through the ``neighbours`` nearest soundings within ``radius_m``, under
   the regional posterior widened by ``local_sigma`` per axis: how far the seabed's local
   slope departs from the regional one, measured from neighbouring cells' mean depths about
   the regional planes (:func:`_relief_slope_sigma`; isotropic relief, so a profiler's
   along-track cells tell it across too).

Both fits drop residuals beyond 3 × 1.4826 MAD (at least 1 cm) once; the noise variance is
then the kept residuals' with their degrees of freedom. Each gives the posterior mean and
covariance of ``(b, c)``: along a direction the soundings span (a Palmer swath: all) the data
set both; across a profiler's single straight line they span nothing and the prior stands
(mean 0, variance ``s_0²``); a line that drifts across over tens of metres shows the slope
to the regional step. The TPU carries the covariance as its own term
(:func:`gradient_sigma_depth_m`): what the sounding's horizontal uncertainty makes of a
gradient not measured. The local fit reads the mean slope of its soundings' patch, the TPU
wants the slope at the sounding: the relief's curvature over the patch is not in the noise
model, which is why the patch stays small (16 soundings: the covariance matches the errors to
~25 % over 8 m relief; 64 would not).

Before, a ridge pulled the local slope to 0 across a profiler's line and the local fit's
noise went to the along-track slope: on suite tuning seed 19 (full-waveform profiler, a 14°
slope across the line) the gradient read 0.03 across and 0.12 along against a true 0.26 and
0, and the TPU covered 58 / 88 % of the errors at 1 and 1.96 sigma.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from pipeline.cell_keys import cell_inverse
from pipeline.constants import MAD_TO_SIGMA
from pipeline.parallel import thread_map_rows
from pipeline.process.plane_kernels import normal_equations, plane_moments, sym3_inverse
from pipeline.process.surface_land import masked_median
from pipeline.uncertainty.tpu_settings import X, Y

__all__ = [
    "GRADIENT_TERM",
    "seabed_gradient",
    "gradient_sigma_depth_m",
    "horizontal_cov",
    "plane_gradient",
    "group_means",
]

#: Name of the TPU term of the gradient's own uncertainty (random, depth only).
GRADIENT_TERM = "seabed_gradient"

#: Floor of the noise sigma of a plane fit (m): residuals of a few mm would make any prior moot.
_NOISE_FLOOR_M = 0.01


def group_means(group, xy, dep):
    """Mean position and depth of each group of soundings."""
    _, inv = np.unique(np.asarray(group).ravel(), return_inverse=True)
    cnt = np.bincount(inv).astype(np.float64)
    xy = np.column_stack([np.bincount(inv, weights=xy[:, k]) / cnt for k in range(2)])
    return xy, np.bincount(inv, weights=dep) / cnt


def _cells(xy, dep, cell_m):
    """Soundings binned in ``cell_m`` square cells.

    Returns the cell of each sounding, the cells' mean positions and depths, their counts.
    """
    inv = cell_inverse(np.floor(xy / cell_m).astype(np.int64))
    cxy, cdep = group_means(inv, xy, dep)
    return inv, cxy, cdep, np.bincount(inv).astype(np.float64)


#: Defaults of :func:`seabed_gradient`'s local plane radius, regional plane radius and cell
#: (m): what a gradient made without the TPU's settings (the pair scatter's own) reaches.
RADIUS_M, REGIONAL_RADIUS_M, REGIONAL_CELL_M = 10.0, 50.0, 5.0

#: Fewest pairs of cells the relief's slope is measured from (a 40 m profiler line has ~9).
_MIN_PAIRS = 5


def _relief_slope_sigma(xy, dep, cells, g_cell, cell_m) -> float | None:
    """One-sigma departure of the seabed's local slope from the regional one, measured.

    Neighbouring cells' mean depths differ by the regional plane's rise plus the relief's, and
    by their means' noise: ``D = d_i - d_j - g . (p_i - p_j)``, ``E[D²] = s² h² + v_i + v_j``
    at separation ``h`` (``s`` the relief's slope along the pair, ``v`` the variance of each
    cell's mean from its soundings' scatter about the plane). Pooled over the survey
    (isotropic relief: a profiler's along-track pairs speak for across too), blunders beyond
    5 × 1.4826 MAD of ``D`` dropped, pairs under half a cell apart too, as ``sum(D² - v_i -
    v_j) / sum(h²)``. None: fewer than :data:`_MIN_PAIRS` such pairs of cells with 2+
    soundings.
    """
    inv, cxy, cdep, cnt = cells
    r = dep - cdep[inv] - np.sum(g_cell[inv] * (xy - cxy[inv]), axis=1)
    var_mean = np.bincount(inv, weights=r**2) / np.maximum(cnt - 1.0, 1.0) / cnt
    ok = cnt >= 2
    if np.count_nonzero(ok) < 3:
        return None
    idx = np.flatnonzero(ok)
    dist, nb = cKDTree(cxy[idx]).query(cxy[idx], k=2, distance_upper_bound=2.0 * cell_m)
    has = np.isfinite(dist[:, 1])
    if np.count_nonzero(has) < _MIN_PAIRS:
        return None
    i, j = idx[has], idx[nb[has, 1]]
    sep = cxy[i] - cxy[j]
    h2 = np.sum(sep**2, axis=1)
    d = cdep[i] - cdep[j] - np.sum(0.5 * (g_cell[i] + g_cell[j]) * sep, axis=1)
    mad = MAD_TO_SIGMA * np.median(np.abs(d - np.median(d)))
    # cells whose centroids nearly touch (a line along a cell boundary) would divide their
    # noise by a tiny h²: pairs at least half a cell apart, pooled as sums
    keep = (np.abs(d - np.median(d)) <= max(5.0 * mad, 1e-9)) & (h2 >= (0.5 * cell_m) ** 2)
    if np.count_nonzero(keep) < _MIN_PAIRS:
        return None
    num = np.sum(d[keep] ** 2 - var_mean[i[keep]] - var_mean[j[keep]])
    return float(math.sqrt(max(num / np.sum(h2[keep]), 0.0)))


#: Fewest soundings a plane's slope is read from (fewer: the prior); with 3 or 4 the residuals
#: of an exact or nearly exact fit read no noise and the covariance would be ~10x too narrow.
_MIN_SOUNDINGS = 6


def _bayes_planes(w, dx, dy, z, noise_var, prior_mean, prior_prec):
    """Posterior mean and covariance of the slope of ``z = a + b dx + c dy``, batched.

    ``w`` (m, k) weights (0: unused), ``noise_var`` (m,), ``prior_mean`` (m, 2) and
    ``prior_prec`` (m, 2, 2) of ``(b, c)``; ``a`` is free. Rows with fewer than
    :data:`_MIN_SOUNDINGS` soundings: the prior.
    """
    mom = plane_moments(w, dx, dy, z)
    sw = mom[:, 0]
    a, rhs = normal_equations(mom)
    a /= noise_var[:, None, None]
    rhs /= noise_var[:, None]
    # a precision made by an LU inverse can be uneven in its last bit: the matrix's two halves
    # must agree, as the inverse reads one of them
    prior_prec = 0.5 * (prior_prec + np.swapaxes(prior_prec, 1, 2))
    a[:, 1:, 1:] += prior_prec
    rhs[:, 1:] += np.einsum("mij,mj->mi", prior_prec, prior_mean)
    bad = sw < _MIN_SOUNDINGS
    a[bad] = np.eye(3)
    rhs[bad] = 0.0
    inv = sym3_inverse(a)
    mean = np.ascontiguousarray(np.einsum("mij,mj->mi", inv, rhs)[:, 1:])
    cov = inv[:, 1:, 1:].copy()
    if bad.any():  # the prior's covariance: its precision's 2 x 2 inverse, by cofactors
        pp = prior_prec[bad]
        det = pp[:, 0, 0] * pp[:, 1, 1] - pp[:, 0, 1] * pp[:, 1, 0]
        adj = np.stack([pp[:, 1, 1], -pp[:, 0, 1], -pp[:, 1, 0], pp[:, 0, 0]], axis=1)
        mean[bad] = prior_mean[bad]
        cov[bad] = (adj / det[:, None]).reshape(-1, 2, 2)
    return mean, cov


def _robust_bayes(xy, dep, q, k, radius_m, prior_mean, prior_prec, tree=None):
    """:func:`_bayes_planes` through the ``k`` nearest of ``xy`` within ``radius_m`` of each row.

    The noise is the residual scale of a first fit; refitted once without outliers. ``tree``:
    a :class:`~scipy.spatial.cKDTree` of ``xy`` already built (else built here).
    """
    tree = cKDTree(xy) if tree is None else tree
    k = min(k, len(xy))
    _, idx = tree.query(q, k=k, distance_upper_bound=radius_m, workers=-1)
    idx = np.asarray(idx).reshape(len(q), k)
    valid = idx < len(xy)
    ic = np.where(valid, idx, 0)
    dx = np.where(valid, xy[ic, 0] - q[:, :1], 0.0)
    dy = np.where(valid, xy[ic, 1] - q[:, 1:], 0.0)
    z = np.where(valid, dep[ic], 0.0)
    w = valid.astype(np.float64)
    floor = np.full(len(q), _NOISE_FLOOR_M**2)
    prior = (prior_mean, prior_prec)
    mean, _ = _bayes_planes(w, dx, dy, z, floor, *prior)
    # the intercept at the query point given that slope: the soundings' mean less the slope
    # times their mean offset (a free intercept's least-squares value)
    sw = np.maximum(w.sum(1), 1.0)
    resid0 = z - (mean[:, :1] * dx + mean[:, 1:] * dy)
    a0 = (w * resid0).sum(1) / sw
    r = np.abs(resid0 - a0[:, None])
    scale = MAD_TO_SIGMA * masked_median(r, valid)
    keep = valid & (r <= np.maximum(3.0 * scale, 0.01)[:, None])
    w = keep.astype(np.float64)
    mean, _ = _bayes_planes(w, dx, dy, z, np.maximum(scale, _NOISE_FLOOR_M) ** 2, *prior)
    # the noise variance of the kept soundings with its degrees of freedom (the MAD of a
    # dozen residuals reads it ~25 % low, and so would the covariance)
    resid = z - (mean[:, :1] * dx + mean[:, 1:] * dy)
    sw = np.maximum(w.sum(1), 1.0)
    resid -= ((w * resid).sum(1) / sw)[:, None]
    var = (w * resid**2).sum(1) / np.maximum(w.sum(1) - 3.0, 1.0)
    noise = np.maximum(var, _NOISE_FLOOR_M**2)
    return _bayes_planes(w, dx, dy, z, noise, prior_mean, prior_prec)


def seabed_gradient(
    xy_m: Any,
    depth_m: Any,
    query_xy_m: Any = None,
    *,
    group: Any = None,
    neighbours: int = 16,
    radius_m: float = RADIUS_M,
    regional_radius_m: float = REGIONAL_RADIUS_M,
    regional_cell_m: float = REGIONAL_CELL_M,
    regional_neighbours: int = 64,
    prior_slope_deg: float = 10.0,
    local_sigma: float | None = None,
    return_cov: bool = False,
    return_local_sigma: bool = False,
    chunk: int = 32_768,
):
    """Depth gradient of the seabed from measured soundings, ``(m, 2)`` (m/m) (module notes).

    Parameters
    ----------
    xy_m : (n, 2) array_like
        Horizontal positions of the soundings.
    depth_m : (n,) array_like
        Their depths (positive down).
    query_xy_m : (m, 2) array_like, optional
        Where to give the gradient (default: each sounding).
    group : (n,) array_like, optional
        Soundings sharing one detection (a photon-counting window's shots: one depth) carry
        the same label and count as one, at their mean.
    neighbours, radius_m : int, float
        The local plane's soundings.
    regional_radius_m, regional_cell_m, regional_neighbours : float, float, int
        The regional plane's cells (``regional_radius_m = 0``: no regional step, the local
        plane's prior is the slope prior itself).
    prior_slope_deg : float
        One-sigma slope per axis assumed where no sounding tells (``tan`` of it).
    local_sigma : float, optional
        One-sigma departure of the local slope from the regional one, per axis; default
        measured from neighbouring cells (:func:`_relief_slope_sigma`), the slope prior's
        sigma where nothing measures it.
    return_cov : bool
        Also return the posterior covariance ``(m, 2, 2)``.
    return_local_sigma : bool
        Also return the ``local_sigma`` used (measured or given; None without a regional
        step): a survey-wide figure a tile of the survey is given back.
    chunk : int
        Queries per block (bounds the temporaries; blocks run on
        :func:`~pipeline.parallel.thread_map`'s threads; no effect on the values).

    Returns
    -------
    gradient : (m, 2) float64
    cov : (m, 2, 2) float64
        Only with ``return_cov``.
    local_sigma : float or None
        Only with ``return_local_sigma``.
    """
    xy = np.asarray(xy_m, dtype=np.float64).reshape(-1, 2)
    dep = np.asarray(depth_m, dtype=np.float64).ravel()
    q = xy if query_xy_m is None else np.asarray(query_xy_m, dtype=np.float64).reshape(-1, 2)
    if group is not None and len(xy):
        xy, dep = group_means(group, xy, dep)
    s0 = math.tan(math.radians(prior_slope_deg))
    out = np.zeros((len(q), 2))
    cov = np.tile(np.eye(2) * s0**2, (len(q), 1, 1))
    reg = None
    if len(xy) >= 3 and len(q):
        cells = _cells(xy, dep, regional_cell_m) if regional_radius_m > 0 else None
        if cells is not None and len(cells[1]) < 3:
            cells = None

        # the regional plane of each cell (64 neighbours); a query takes its nearest cell's
        # (the regional slope varies over tens of metres, a cell is 5 m)
        reg = None
        if cells is not None:
            tree = cKDTree(cells[1])
            # each cell's plane is its own: with the relief's figure given, only the cells
            # some query takes are fitted (the same values), else all (the relief reads them)
            at = slice(None) if local_sigma is None else np.unique(tree.query(q, workers=-1)[1])
            m = len(cells[1][at])
            fit = _robust_bayes(
                cells[1],
                cells[2],
                cells[1][at],
                regional_neighbours,
                regional_radius_m,
                np.zeros((m, 2)),
                np.tile(np.eye(2) / s0**2, (m, 1, 1)),
            )
            reg = fit
            if local_sigma is None:
                local_sigma = _relief_slope_sigma(xy, dep, cells, reg[0], regional_cell_m)
            else:  # the cells' rows (those no query takes stay 0: never read)
                n_cells = len(cells[1])
                reg = (np.zeros((n_cells, 2)), np.zeros((n_cells, 2, 2)))
                reg[0][at], reg[1][at] = fit
            if local_sigma is None:
                local_sigma = s0  # nothing measured it
        tree_xy = cKDTree(xy)

        def block(rows: slice):
            qq = q[rows]
            if reg is None:  # no regional step: the slope prior itself
                mean0 = np.zeros((len(qq), 2))
                prec0 = np.tile(np.eye(2) / s0**2, (len(qq), 1, 1))
            else:
                near = tree.query(qq, workers=-1)[1]
                mean0, cov0 = reg[0][near], reg[1][near]
                prec0 = np.linalg.inv(cov0 + np.eye(2) * local_sigma**2)
            return _robust_bayes(xy, dep, qq, neighbours, radius_m, mean0, prec0, tree_xy)

        # the queries are independent: blocks bound the (queries, neighbours) temporaries and
        # run side by side on the stage's threads, the same values for any block size
        out, cov = thread_map_rows(block, len(q), chunk)
    res = (out, cov) if return_cov else (out,)
    if return_local_sigma:
        res = (*res, None if reg is None else float(local_sigma))
    return res if len(res) > 1 else out


def gradient_sigma_depth_m(gradient_cov, horizontal_cov) -> np.ndarray:
    """Depth sigma of a sounding from the gradient's uncertainty, ``(n,)`` m.

    A sounding ``dp`` beside where it is put reads ``g . dp`` of depth; with ``g`` known to
    covariance ``G`` and ``dp`` random of covariance ``H`` (independent) the variance is
    ``E[(dg . dp)²] = tr(G H)``.

    Parameters
    ----------
    gradient_cov : (n, 2, 2) array_like
    horizontal_cov : (n, 2, 2) array_like
    """
    g = np.asarray(gradient_cov, dtype=np.float64)
    h = np.asarray(horizontal_cov, dtype=np.float64)
    return np.sqrt(np.maximum(np.einsum("nij,nji->n", g, h), 0.0))


def horizontal_cov(tpu) -> np.ndarray:
    """Horizontal covariance of each sounding from every term of ``tpu``, ``(n, 2, 2)``.

    ``tpu`` is a :class:`~pipeline.uncertainty.tpu_settings.PointTpu`; its terms are
    independent one-sigma displacements ``(n, 4)`` (x, y, z, depth).
    """
    out = np.zeros((len(tpu), 2, 2))
    for v in tpu.terms.values():
        h = np.asarray(v, dtype=np.float64)[:, [X, Y]]
        out += h[:, :, None] * h[:, None, :]
    return out


def plane_gradient(surface, rows) -> np.ndarray:
    """Height gradient of the fitted water planes of pulses ``rows``, ``(k, 2)``; 0 off water.

    ``surface`` is a :class:`~pipeline.process.surface_fit.WaterSurface`.
    """
    rows = np.asarray(rows, dtype=np.int64)
    nrm = np.asarray(surface.normal, dtype=np.float64)[rows]
    nz = np.where(np.abs(nrm[:, 2]) > 1e-12, nrm[:, 2], 1.0)
    p = -nrm[:, :2] / nz[:, None]
    ok = np.asarray(surface.is_water)[rows] & (np.abs(nrm[:, 2]) > 1e-12)
    return np.where(ok[:, None], np.nan_to_num(p), 0.0)
