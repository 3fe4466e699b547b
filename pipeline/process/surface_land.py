"""Land or wave crest: which high surface points are land, from measured data only.

A surface point higher than ``land_margin_m`` above the global water plane is only a land
*candidate*. Under a wind sea, crests routinely stand that high (a 10 m/s sea has a
significant wave height ``Hs ~ 2 m``, so ~4 % of the surface points are more than 1 m above
the mean level), and crest regions are metres wide, so a high neighbourhood alone does not make
land. Land needs all of:

1. No water under it. Land is opaque: a candidate whose pulse has a later return (bottom or
   in-column) below the water level was on water (a crest over a seabed or a water column).
2. Spatial support. At least ``land_support_fraction`` of its ``land_neighbours`` nearest
   surface points within ``land_radius_m`` are candidates too: an isolated high point whose
   neighbours have water under them (spray, a crest whose own bottom was missed) is not land.
   The fraction is taken over all neighbours, so a point on the edge of land (about half of
   its neighbours are water) keeps its support.
3. Higher than the measured sea. The robust (median) height of the candidate neighbours stands
   at least ``land_sea_sigmas * sigma_sea`` above the water level, with ``sigma_sea`` the robust
   standard deviation (1.4826 MAD) of the water-surface heights measured in the survey itself
   (``Hs ~ 4 sigma_sea``). This alone separates crests from land where no pulse sees the
   seabed (deep or turbid water): crest heights follow the sea's spread, land does not.

``sigma_sea`` is estimated from the surface points whose pulse has water under it, plus those
within the water band ``+-max(margin, land_sea_sigmas * sigma_sea)`` of the level (iterated from
the margins): without seabed returns the band must widen with the sea, or a rough sea's
truncated spread would be underestimated.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

__all__ = ["land_surface_points", "sea_sigma_m"]

#: 1.4826 * MAD estimates the standard deviation of normally distributed heights.
_MAD_TO_SIGMA = 1.4826
#: Band iterations of the sea-state estimate (the band settles in two or three).
_SEA_ITERATIONS = 5


def sea_sigma_m(res_m: np.ndarray, water_below: np.ndarray, st) -> float:
    """Robust standard deviation of the sea-surface heights about the water level.

    Parameters
    ----------
    res_m : (m,)
        Surface-point heights above the global water plane.
    water_below : (m,) bool
        The point's pulse has a later return below the water level (certainly water).
    st : SurfaceFitSettings
        ``land_margin_m``, ``below_margin_m``, ``land_sea_sigmas``.

    Returns
    -------
    float
        ``1.4826 * median(|res|)`` over the water points (0 if there are none).
    """
    sigma = 0.0
    for _ in range(_SEA_ITERATIONS):
        hi = max(st.land_margin_m, st.land_sea_sigmas * sigma)
        lo = max(st.below_margin_m, st.land_sea_sigmas * sigma)
        sea = water_below | ((res_m > -lo) & (res_m < hi))
        if not sea.any():
            return 0.0
        new = _MAD_TO_SIGMA * float(np.median(np.abs(res_m[sea])))
        if new == sigma:
            break
        sigma = new
    return sigma


def land_surface_points(
    xy_m: np.ndarray, res_m: np.ndarray, water_below: np.ndarray, st
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
        ``land_margin_m``, ``below_margin_m``, ``land_sea_sigmas``, ``land_radius_m``,
        ``land_neighbours``, ``land_support_fraction``.

    Returns
    -------
    land : (m,) bool
        The surface point is on land.
    sigma_sea_m : float
        Measured robust standard deviation of the sea-surface heights.
    sea_margin_m : float
        Height the candidate neighbourhood must reach: ``max(land_margin_m,
        land_sea_sigmas * sigma_sea_m)``.
    """
    m = len(res_m)
    sigma = sea_sigma_m(res_m, water_below, st)
    sea_margin = max(st.land_margin_m, st.land_sea_sigmas * sigma)
    cand = (res_m >= st.land_margin_m) & ~water_below
    land = np.zeros(m, dtype=bool)
    q = np.flatnonzero(cand)
    if not len(q):
        return land, sigma, sea_margin
    k = min(st.land_neighbours, m)
    _, idx = cKDTree(xy_m).query(xy_m[q], k=k, distance_upper_bound=st.land_radius_m, workers=-1)
    idx = np.asarray(idx).reshape(len(q), k)
    valid = idx < m  # the point itself is always its own nearest neighbour
    ic = np.where(valid, idx, 0)
    nb_cand = valid & cand[ic]
    support = nb_cand.sum(1) / valid.sum(1)
    # robust height of the high region around the point: median of the candidate neighbours
    h = np.sort(np.where(nb_cand, res_m[ic], np.inf), axis=1)
    cnt = nb_cand.sum(1)  # >= 1 unless k duplicates of the point's position crowd it out
    c = np.maximum(cnt, 1)
    lo_h = np.take_along_axis(h, ((c - 1) // 2)[:, None], axis=1)[:, 0]
    hi_h = np.take_along_axis(h, (c // 2)[:, None], axis=1)[:, 0]
    height = np.where(cnt > 0, 0.5 * (lo_h + hi_h), -np.inf)
    land[q] = (support >= st.land_support_fraction) & (height >= sea_margin)
    return land, sigma, sea_margin
