"""Water level and land: the global water plane, and which high surface points are land.

Water level (:func:`global_plane`): the mode of a histogram of surface heights (of the points
whose pulse has a bottom return well below them, when there are any, so that a flat, densely
sampled land level such as a beach berm cannot outvote a sea that waves spread over metres)
starts an iterated least-squares plane fitted to the points of the band
``[-below_margin_m, +land_margin_m]`` around it.

Land (:func:`land_surface_points`): a surface point higher than ``land_margin_m`` above the
water plane is only a land *candidate*. Under a wind sea, crests routinely stand that high (a
10 m/s sea has a significant wave height ``Hs ~ 2 m``: ~4 % of the surface points are more
than 1 m above the mean level), and crest regions are metres wide, so a high neighbourhood
alone does not make land. A candidate needs

1. no water under it: land is opaque, so a pulse with a later return (bottom or in-column)
   below the water level was on water (a crest over a seabed or a water column). Decided by a
   majority of the high points among its neighbours (a lone noise echo under land, or a lone
   missed bottom among crests that show theirs, does not decide alone);

and is land if it is linked to a *seed*, a candidate with

2. spatial support: at least ``land_support_fraction`` of its ``land_neighbours`` nearest
   surface points within ``land_radius_m`` are candidates too (an isolated high point among
   water that shows its bottom is spray or a crest whose bottom was missed). Taken over all
   neighbours, so a point on the edge of land (half of its neighbours water) keeps it;
3. a height above the measured sea: the median height of its candidate neighbours is at least
   ``land_sea_sigmas * sigma_sea`` above the level, ``sigma_sea`` being the robust standard
   deviation (1.4826 MAD) of the sea-surface heights measured in the survey (``Hs ~ 4
   sigma_sea``). Crest heights follow the sea's spread, land does not; this separates them
   where no pulse sees the seabed (deep or turbid water).

Linked (hysteresis, as in edge detection): candidates within ``land_link_m`` of each other
form regions. A region is land if it holds a seed (land lower than the waves, a beach face,
joined to land above them), or if it is wider (bounding-box diagonal) than
``land_extent_sigmas * sigma_sea`` and holds a point with spatial support (a berm lower than
the crests but far wider than a crest region: a fully developed sea has ``Hs / L_peak ~ 1/40``,
so its peak wavelength is ~150 sigma, and a region of crests higher than the margin spans
about one). A crest is cut off from land by the troughs and the swash zone below
``land_margin_m``.

``sigma_sea`` comes from the median absolute height of the surface points within the water
band, corrected for the band's truncation (:func:`sea_sigma_m`).
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import brentq
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree
from scipy.special import ndtr, ndtri

from pipeline.constants import MAD_TO_SIGMA

__all__ = [
    "global_plane",
    "land_surface_points",
    "masked_median",
    "sea_sigma_m",
    "where_certain",
]

#: Largest sea sigma reported, in water bands (a band filled uniformly has no finite one).
_MAX_SIGMA_BANDS = 100.0


def _plane_lstsq(x, y, z, tilt_prior_rad=None):
    """Least-squares ``z = z0 + gx x + gy y`` and the residual sigma.

    ``tilt_prior_rad``: a zero-mean normal prior of this one-sigma on ``gx`` and ``gy``
    (two pseudo-observations of weight ``sigma² / tilt_prior²``, ``sigma`` the unregularised
    fit's): a tilt the points' spread cannot tell from the waves stays level. None: no prior
    (minimum-norm slope if degenerate).
    """
    xm, ym = x.mean(), y.mean()
    a = np.column_stack([np.ones_like(x), x - xm, y - ym])
    coef, *_ = np.linalg.lstsq(a, z, rcond=1e-10)
    resid = z - a @ coef
    dof = max(len(z) - 3, 1)
    sigma = float(np.sqrt(np.sum(resid**2) / dof))
    if tilt_prior_rad is not None and sigma > 0.0:
        w = sigma / tilt_prior_rad
        prior = np.array([[0.0, w, 0.0], [0.0, 0.0, w]])
        coef, *_ = np.linalg.lstsq(np.vstack([a, prior]), np.r_[z, 0.0, 0.0], rcond=1e-10)
        sigma = float(np.sqrt(np.sum((z - a @ coef) ** 2) / dof))
    return np.array([coef[0] - coef[1] * xm - coef[2] * ym, coef[1], coef[2]]), sigma


def where_certain(mask: np.ndarray, wet: np.ndarray, st) -> np.ndarray:
    """``mask & wet`` where at least ``st.sea_min_wet_pulses`` are so, else ``mask``, ``(m,)``.

    The points of ``mask`` with water for certain under them (a bottom well below) measure the
    sea when there are enough of them: a calm sea seen off nadir from high up returns only the
    seabed on many pulses, whose lone echoes otherwise read as a rough, sunken sea.
    """
    both = mask & wet
    return both if np.count_nonzero(both) >= st.sea_min_wet_pulses else mask


def global_plane(ps: np.ndarray, st, wet: np.ndarray | None = None) -> tuple[np.ndarray, float]:
    """Water plane from surface points: histogram mode, then iterated band fit.

    Parameters
    ----------
    ps : (m, 3)
        Surface points.
    st : SurfaceFitSettings
    wet : (m,) bool, optional
        The point's pulse has a bottom return well below it (water under the surface); when
        at least 3 are wet, the histogram mode is theirs, and when at least
        ``sea_min_wet_pulses`` are, the plane is fitted to them alone.

    Returns
    -------
    plane : (3,)
        ``(z0_m, dz_dx, dz_dy)``.
    sigma_m : float
        Residual standard deviation of the band fit.
    """
    if wet is not None:
        # the plane of the water for certain: lone seabed echoes of a calm sea within the band
        # pulled its fit down
        certain = where_certain(np.ones(len(ps), dtype=bool), wet, st)
        if not certain.all():
            ps, wet = ps[certain], None
    z = ps[:, 2]
    if st.water_level_hint_m is not None:
        level = float(st.water_level_hint_m)
    else:
        zm = z[wet] if wet is not None and wet.sum() >= 3 else z
        lo, hi = float(zm.min()), float(zm.max())
        nbins = int(min(max(np.ceil((hi - lo) / st.level_bin_m), 1), 1_000_000))
        counts, edges = np.histogram(zm, bins=nbins, range=(lo, lo + nbins * st.level_bin_m))
        i = int(np.argmax(counts))
        level = 0.5 * (edges[i] + edges[i + 1])
    plane = np.array([level, 0.0, 0.0])
    sigma = 0.0
    used = None
    for _ in range(6):
        res = z - (plane[0] + plane[1] * ps[:, 0] + plane[2] * ps[:, 1])
        band = (res > -st.below_margin_m) & (res < st.land_margin_m)
        if band.sum() < 3:
            break
        new, sigma = _plane_lstsq(ps[band, 0], ps[band, 1], z[band])
        used = (ps[band, 0], ps[band, 1], z[band])
        # one robust pass: drop gross outliers of this fit, then refit
        r2 = z[band] - (new[0] + new[1] * ps[band, 0] + new[2] * ps[band, 1])
        keep = np.abs(r2) <= max(st.outlier_sigma * MAD_TO_SIGMA * np.median(np.abs(r2)), 1e-9)
        keep |= np.abs(r2) <= st.outlier_floor_m
        if keep.sum() >= 3:
            xb, yb, zb = ps[band, 0][keep], ps[band, 1][keep], z[band][keep]
            new, sigma = _plane_lstsq(xb, yb, zb)
            used = (xb, yb, zb)
        converged = np.allclose(new, plane, rtol=0.0, atol=1e-12)
        plane = new
        if converged:
            break
    if used is not None:
        # the band chosen, the tilt once more under its prior (the band iterations run without
        # it: a steep synthetic plane would otherwise never enter its own band)
        plane, sigma = _plane_lstsq(*used, st.global_tilt_prior_rad)
    return plane, sigma


def masked_median(v: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """Row medians of ``v`` (m, k) over ``valid`` entries; (m,), rows with none give 0."""
    cnt = valid.sum(axis=1)
    s = np.sort(np.where(valid, v, np.inf), axis=1)
    c = np.maximum(cnt, 1)
    lo = np.take_along_axis(s, ((c - 1) // 2)[:, None], axis=1)[:, 0]
    hi = np.take_along_axis(s, (c // 2)[:, None], axis=1)[:, 0]
    hi = np.where(cnt >= 2, hi, lo)
    return np.where(cnt > 0, 0.5 * (lo + hi), 0.0)


def sea_sigma_m(res_m: np.ndarray, st) -> float:
    """Robust standard deviation of the sea-surface heights about the water level.

    The median absolute height of the points within ``+-a`` of the level, ``a =
    min(land_margin_m, below_margin_m)``, corrected for that truncation as for a normal sea:
    ``median = sigma * Phi^-1((Phi(a / sigma) + 1/2) / 2)`` solved for ``sigma``. A fixed band
    keeps land above it out of the estimate (a band widened with the estimate would take in
    a beach face and feed on it).

    Parameters
    ----------
    res_m : (m,)
        Surface-point heights above the global water plane.
    st : SurfaceFitSettings
        ``land_margin_m``, ``below_margin_m``.

    Returns
    -------
    float
        The sea's sigma (0 if no point is in the band; ``_MAX_SIGMA_BANDS * a`` if the band is
        filled uniformly, a sea far rougher than the band).
    """
    a = min(st.land_margin_m, st.below_margin_m)
    band = np.abs(res_m) < a
    if not band.any():
        return 0.0
    med = float(np.median(np.abs(res_m[band])))
    hi = _MAX_SIGMA_BANDS * a

    def excess(sigma):
        return sigma * ndtri(0.5 * (ndtr(a / sigma) + 0.5)) - med

    if med <= 0.0:
        return 0.0
    if excess(hi) <= 0.0:
        return hi
    return float(brentq(excess, med, hi, xtol=1e-6 * a))


def _neighbours(tree, xy_m: np.ndarray, st) -> tuple[np.ndarray, np.ndarray]:
    """The ``land_neighbours`` nearest points within ``land_radius_m`` of ``xy_m`` (c, 2).

    Returns ``valid`` (c, k) bool and indices ``ic`` (c, k) (0 where not valid).
    """
    k = min(st.land_neighbours, tree.n)
    _, idx = tree.query(xy_m, k=k, distance_upper_bound=st.land_radius_m, workers=-1)
    idx = np.asarray(idx).reshape(len(xy_m), k)
    valid = idx < tree.n  # a point itself is always among its nearest neighbours
    return valid, np.where(valid, idx, 0)


def land_surface_points(
    xy_m: np.ndarray,
    res_m: np.ndarray,
    water_below: np.ndarray,
    st,
    *,
    sigma_m: float | None = None,
) -> tuple[np.ndarray, float, float]:
    """Which surface points are land (see the module docstring).

    Parameters
    ----------
    xy_m : (m, 2)
        Horizontal positions of the measured surface points.
    res_m : (m,)
        Their heights above the global water plane.
    water_below : (m,) bool
        Their pulse has a later return (bottom or in-column) below the water level.
    st : SurfaceFitSettings
        The ``land_*`` settings and ``below_margin_m``.
    sigma_m : float, optional
        The sea's sigma to use (the whole survey's, when these points are a tile of it);
        None: :func:`sea_sigma_m` of ``res_m``.

    Returns
    -------
    land : (m,) bool
        The surface point is on land.
    sigma_sea_m : float
        Measured robust standard deviation of the sea-surface heights.
    sea_margin_m : float
        ``max(land_margin_m, land_sea_sigmas * sigma_sea_m)``, the height of the seeds.

    Notes
    -----
    Tuning (seed 11 of a 10 m/s sea over a 10 m seabed, and of shorelines with and without
    waves, also with every bottom return removed): no crest was land from ``land_sea_sigmas``
    3.5 and ``land_extent_sigmas`` 150 up; the defaults (4, 400) keep a margin.
    """
    m = len(res_m)
    sigma = sea_sigma_m(res_m, st) if sigma_m is None else sigma_m
    sea_margin = max(st.land_margin_m, st.land_sea_sigmas * sigma)
    high = res_m >= st.land_margin_m
    land = np.zeros(m, dtype=bool)
    q = np.flatnonzero(high)
    if not len(q):
        return land, sigma, sea_margin
    tree = cKDTree(xy_m)
    chunks = [q[i : i + st.chunk_size] for i in range(0, len(q), st.chunk_size)]
    # water under the high region: a majority vote of the high neighbours (the point among
    # them), so that a lone late echo (noise under land) or a lone missed bottom (a crest
    # among crests that show the seabed) does not decide alone
    cand = np.zeros(m, dtype=bool)
    for qc in chunks:
        valid, ic = _neighbours(tree, xy_m[qc], st)
        nb_high = valid & high[ic]
        cand[qc] = (nb_high & water_below[ic]).sum(1) < 0.5 * nb_high.sum(1)
    support = np.zeros(len(q))
    height = np.zeros(len(q))
    for i, qc in zip(range(0, len(q), st.chunk_size), chunks, strict=True):
        valid, ic = _neighbours(tree, xy_m[qc], st)
        nb_cand = valid & cand[ic]
        support[i : i + len(qc)] = nb_cand.sum(1) / np.maximum(valid.sum(1), 1)
        # robust height of the high region around the point: median of candidate neighbours
        med = masked_median(res_m[ic], nb_cand)
        height[i : i + len(qc)] = np.where(nb_cand.any(1), med, -np.inf)
    q, support, height = q[cand[q]], support[cand[q]], height[cand[q]]
    if not len(q):
        return land, sigma, sea_margin
    supported = support >= st.land_support_fraction
    seed = supported & (height >= sea_margin)
    # candidates linked within land_link_m through other candidates form regions; a crest
    # region spans about a wavelength, land can span far more
    pairs = cKDTree(xy_m[q]).query_pairs(st.land_link_m, output_type="ndarray")
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(len(q),) * 2)
    n_comp, comp = connected_components(graph, directed=False)
    lo = np.full((n_comp, 2), np.inf)
    hi = np.full((n_comp, 2), -np.inf)
    np.minimum.at(lo, comp, xy_m[q])
    np.maximum.at(hi, comp, xy_m[q])
    extent = np.hypot(*(hi - lo).T)  # bounding-box diagonal of each region
    wide = extent >= st.land_extent_sigmas * sigma
    # hysteresis: a region is land if it holds a seed (land below the wave height, a beach
    # face, joined to land above it), or if it is much wider than the sea's crests and holds a
    # supported point (not a lone high point: on a calm sea the width bound is ~0)
    land[q] = np.isin(comp, comp[seed]) | (wide[comp] & np.isin(comp, comp[supported]))
    return land, sigma, sea_margin


def own_echo_weight(fit_sigma_m: np.ndarray, ranging_sigma_m: np.ndarray) -> np.ndarray:
    """How much of a pulse's own surface echo's offset from its local plane is the sea, (n,).

    The plane's residual scatter ``fit_sigma_m`` holds the waves the plane cannot follow and
    the surface points' ranging noise; with the echo's ranging sigma ``ranging_sigma_m`` (along
    the normal) the wave variance is ``fit² - ranging²``, and the weight of the echo's offset
    in the least-squares estimate of the height the pulse met (plane + weight * offset) is
    ``wave² / (wave² + ranging²) = 1 - (ranging / fit)²``, clipped to [0, 1]; 0 where the fit
    has no scatter (nothing is left to follow).
    """
    fit = np.asarray(fit_sigma_m, dtype=np.float64)
    ratio = np.asarray(ranging_sigma_m, dtype=np.float64) / np.where(fit > 0.0, fit, 1.0)
    return np.where(fit > 0.0, np.clip(1.0 - ratio**2, 0.0, 1.0), 0.0)
