"""The water surface from the surface returns: a robust local plane under every pulse.

Method
------
1. Surface points: ``p_s = origin + direction * c t_s / (2 n_air)`` for every pulse with a
   surface return.
2. Water level and land (:mod:`pipeline.process.surface_land`): the water surface is the
   densest level layer of surface points: the mode of a histogram of their heights (of those
   with a bottom return more than ``level_min_depth_m`` below them when there are any: water
   under them; or ``water_level_hint_m``) starts an iterated least-squares *global plane*
   fitted to the points within the band ``[-below_margin_m, +land_margin_m]`` around it. A
   surface point higher than the band is a land candidate unless its high neighbours mostly
   have a return below the water level (water under them), and land if it is linked to
   candidates whose neighbourhood is mostly candidates and stands ``land_sea_sigmas`` sea
   sigmas (measured from the surface heights with a bottom ``level_min_depth_m`` under them,
   when ``sea_min_wet_pulses`` have one: water for certain) above the level, or to a region of
   candidates far wider than a crest region: a wave crest is water, and so is a trough down to
   ``max(below_margin_m, below_sea_sigmas * sigma_sea)`` below the level. A
   pulse without a surface return whose straight (air) bottom point is higher than the band
   is land. Points below the band are not water surface (flagged outliers). With no water
   level given, a survey whose detector measured the water column (no-bottom limits given)
   and where fewer than ``min_wet_pulses`` pulses show light from under their surface return
   (a bottom, an in-column return, a measured column decay, a clipped plateau into the
   column) has no evidence of water: if its surface returns also stand ``dry_level_margin_m``
   above the expected level (``fallback_water_level_m``), every return is land
   (:mod:`pipeline.process.surface_evidence`, which also lets clipped surface bounds set the
   level when no unclipped return shows water).
3. Local fit, batched: for each water pulse, the ``k_neighbours`` nearest water-surface points
   (horizontally, within ``radius_m``, from a ``scipy.spatial.cKDTree``) give the plane
   ``z = z_global(x, y) + a + b dx + c dy`` by weighted least squares on stacked 3x3 normal
   equations (``numpy.linalg.inv`` on ``(m, 3, 3)``). Outliers are residuals above
   ``max(outlier_sigma * 1.4826 MAD, outlier_floor_m)``: first from the global slope through
   the neighbours' median height (robust start), then ``robust_iterations`` times from the
   latest fit. A ridge
   of ``count * slope_prior_m**2`` on ``(b, c)`` pulls the local slope towards the global
   slope, which keeps nearly collinear neighbourhoods (a profiler track) solvable; those are
   flagged ``SURFACE_ILL_CONDITIONED``. With fewer than ``min_neighbours`` neighbours the
   global plane is used, flagged ``SURFACE_GLOBAL_FALLBACK``.
   The sea moves: neighbours must also be close in time, within ``time_window_s`` of the
   pulse's recorded emission time (``DetectedReturns.t_emit_s``; no window when absent). The
   search runs in ``(x, y, v t)`` with ``v = radius_m / time_window_s`` (one k-d tree), and
   neighbours farther than ``radius_m`` across or ``time_window_s`` apart are dropped. The
   default, 1 s, keeps a Palmer scan's own look at a spot (its neighbours within 5 m are a few
   scan periods, < 0.3 s, apart at 20 Hz) and drops the other look (``2 H tan(theta) / v``
   later, ~5 s at 400 m and 60 m/s), during which a 5 m/s sea's peak waves (period ~4 s,
   speed ~6 m/s) have moved by tens of metres; and adjacent lines (minutes).
   Photon-counting windows (``group``) share one detection: every shot of a window carries the
   window's one surface height, so its nearest surface points are its own window's copies of
   that height, which span a few centimetres to decimetres and fix no slope (on suite tuning
   seed 79, a profiler under an 11 m/s sea, the planes took 0.25 % of the sea's along-track
   slope; where the sea rose along the track at 0.2 the soundings sat 3-8 cm deep and 28 %
   of them lay beyond 3 sigma). Each window is therefore one surface sample, at its shots'
   mean position, height and emission time, and the planes are fitted to those samples; a
   shot's own return (the window's height, measured at the window's centre) is carried along
   its plane's slope from the centre to the shot (``WaterSurface.own_shift_m``). Windows along
   a profiler's track spread centimetres across it: where the neighbours spread less than
   ``min_spread_m`` across their major axis, the slope is fitted along that axis only and the
   global slope kept across it (the ridge alone, an equivalent spread and not a slope prior,
   let the sea's scatter about the planes through as across-track slopes of +-0.3 there).
4. The beam meets its local plane at the entry point; the plane's upward unit normal is the
   surface normal for Snell's law. A plane over ``k`` neighbours smooths waves shorter than
   about twice the neighbourhood radius; longer waves and any tilt are kept.

Only measured navigation and detected times are used.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from pipeline.constants import MAD_TO_SIGMA
from pipeline.optics import SPEED_OF_LIGHT_M_S
from pipeline.parallel import thread_map_rows
from pipeline.process.returns import DetectedReturns, PointFlag
from pipeline.process.surface_land import land_surface_points, masked_median, own_echo_weight
from pipeline.process.surface_plane import major_axis, solve_along, solve_plane, window_samples
from pipeline.process.surface_settings import SurfaceFitSettings
from pipeline.process.surface_wide import (
    SurfaceWide,
    surface_inputs,
    surface_points_m,
    surface_wide,
)
from pipeline.process.water_surface import WaterSurface

__all__ = ["SurfaceFitSettings", "WaterSurface", "fit_water_surface", "surface_points_m"]

#: |N . d| below this: the beam runs along the surface (no usable entry point).
_GRAZING_COS = 1e-6
#: Queries whose local planes are fitted at once (:func:`_local_fit`).
FIT_BLOCK = 16384


def _local_fit(tree, spts, qxy, st, key=None, qkey=None, along_only=False):
    """Robust local planes of the residual heights ``spts[:, 2]`` around queries ``qxy``.

    ``key`` / ``qkey``: the tree's and the queries' search coordinates when they are not the
    horizontal positions (``(x, y, v t)`` with a time window, :func:`_search_keys`).
    ``along_only``: where the neighbours spread less than ``min_spread_m`` across their major
    axis, the plane's slope is fitted along that axis only (across it: the global slope).

    Each query's plane is its own (row by row), so the queries are fitted in blocks of
    :data:`FIT_BLOCK` (their ``(m, k)`` temporaries stay small), side by side on the stage's
    threads (:func:`~pipeline.parallel.thread_map`): the same figures as all at once.
    """

    def block(s: slice):
        qk = None if qkey is None else qkey[s]
        return _local_fit_rows(tree, spts, qxy[s], st, key, qk, along_only)

    return thread_map_rows(block, len(qxy), FIT_BLOCK)


def _local_fit_rows(tree, spts, qxy, st, key, qkey, along_only=False):
    """:func:`_local_fit` of one block of queries."""
    m, ns = len(qxy), len(spts)
    k = min(st.k_neighbours, ns)
    q = qxy if qkey is None else qkey
    bound = st.radius_m if qkey is None else st.radius_m * np.sqrt(2.0)
    _, idx = tree.query(q, k=k, distance_upper_bound=bound, workers=-1)
    idx = np.asarray(idx).reshape(m, k)
    valid = idx < ns
    ic = np.where(valid, idx, 0)
    dx = np.where(valid, spts[ic, 0] - qxy[:, :1], 0.0)
    dy = np.where(valid, spts[ic, 1] - qxy[:, 1:], 0.0)
    if qkey is not None:  # in the window: within the radius across and the time window apart
        dt_scaled = key[ic, 2] - qkey[:, 2:3]
        valid &= (dx * dx + dy * dy <= st.radius_m**2) & (np.abs(dt_scaled) <= st.radius_m)
    z = np.where(valid, spts[ic, 2], 0.0)
    count = valid.sum(1)
    lam = count * st.slope_prior_m**2

    def inliers(r):
        scale = MAD_TO_SIGMA * masked_median(np.abs(r), valid)
        thresh = np.maximum(st.outlier_sigma * scale, st.outlier_floor_m)
        return (valid & (np.abs(r) <= thresh[:, None])).astype(np.float64)

    along = None
    if along_only:
        # window samples along a track (a photon profiler's): the few centimetres they spread
        # across it fix no slope there, while the ridge (an equivalent spread, not a slope)
        # lets the sea's scatter about the plane through as wild across-track slopes (on suite
        # tuning seed 79, +-0.3 where the sea's own is 0.15)
        axis, minor = major_axis(valid * 1.0, dx, dy)
        along = np.flatnonzero(minor < st.min_spread_m**2)
        t_along = axis[along, :1] * dx[along] + axis[along, 1:] * dy[along]
    # robust start: residuals from the global slope through the neighbours' median height
    w = inliers(z - masked_median(z, valid)[:, None]) if st.robust_iterations else valid * 1.0
    for it in range(st.robust_iterations + 1):
        params, inv = solve_plane(w, dx, dy, z, lam)
        if along is not None and along.size:
            params[along], inv[along] = solve_along(
                w[along], t_along, z[along], lam[along], axis[along]
            )
        r = z - (params[:, :1] + params[:, 1:2] * dx + params[:, 2:3] * dy)
        if it == st.robust_iterations:
            break
        w = inliers(r)
    n_used = w.sum(1)
    sigma = np.sqrt((w * r * r).sum(1) / np.maximum(n_used - 3.0, 1.0))
    ill = major_axis(w, dx, dy)[1] < st.min_spread_m**2
    h_sigma = sigma * np.sqrt(np.maximum(inv[:, 0, 0], 0.0))
    n_sigma = sigma * np.sqrt(np.maximum(inv[:, 1, 1] + inv[:, 2, 2], 0.0))
    ok = count >= st.min_neighbours
    return params, ok, n_used.astype(np.int64), sigma, h_sigma, n_sigma, ill


def _search_keys(xy, t_s, st):
    """Search coordinates ``(x, y, v t)``, ``v = radius / window`` (None without a window)."""
    if st.time_window_s is None or t_s is None:
        return None
    return np.column_stack([xy, np.asarray(t_s, dtype=np.float64) * st.radius_m / st.time_window_s])


def _intersect(origin, direction, point, normal):
    """Range along ``direction`` from ``origin`` to the plane (point, normal); grazing mask."""
    den = np.sum(normal * direction, axis=1)
    grazing = den > -_GRAZING_COS  # the beam must go down through an upward normal
    num = np.sum(normal * (point - origin), axis=1)
    r = num / np.where(grazing, -1.0, den)
    grazing |= r <= 0.0
    return np.where(grazing, 0.0, r), grazing


def fit_water_surface(
    returns: DetectedReturns,
    settings: SurfaceFitSettings | None = None,
    wide: SurfaceWide | None = None,
    group=None,
    planes_at: np.ndarray | None = None,
) -> WaterSurface:
    """Fit the water surface under every pulse from the surface returns.

    Parameters
    ----------
    returns : DetectedReturns
        Measured navigation and detected return times.
    settings : SurfaceFitSettings, optional
        Defaults if omitted.
    wide : SurfaceWide, optional
        The survey-wide figures (water level, sea sigma, dry or wet) to use instead of
        measuring them from ``returns`` (:func:`~pipeline.process.surface_wide.surface_wide`
        of the whole survey, when ``returns`` are a tile of it).
    group : (n,) array_like, optional
        Pulses sharing one detection (photon-counting windows, ``pulse_id //
        shots_per_window``): one surface sample per window (module notes, step 3).
    planes_at : (n,) bool ndarray, optional
        Fit the local planes only under these pulses (a block's, whose results are read:
        :mod:`pipeline.survey_block_reach`); the other water pulses keep the global plane,
        unflagged. The planes' neighbours are still every water-surface point, and the land
        decision is still made for every pulse, so a pulse's plane is the one fitted with
        every pulse asked. Default: every water pulse.

    Returns
    -------
    WaterSurface
        Entry point, upward normal, land/water decision, uncertainties and flags per pulse.
    """
    st = settings or SurfaceFitSettings()
    n = len(returns)
    o, d = returns.origin_meas_m, returns.direction_meas
    c = SPEED_OF_LIGHT_M_S
    inputs = surface_inputs(returns, st)
    ps, pb, pc, bound, has_s = inputs.ps, inputs.pb, inputs.pc, inputs.bound, inputs.has_s
    wide = wide or surface_wide(returns, st, inputs)
    lvl = has_s | bound if wide.bounds_set_level else has_s
    flags = np.zeros(n, dtype=np.uint16)
    gplane, gsigma = wide.global_plane, wide.global_sigma_m
    z0, gx, gy = gplane

    def zg(x, y):
        return z0 + gx * x + gy * y

    # land / water decision per pulse: a high surface point is land only with no water under
    # it, neighbours that are land candidates too, and a height above the measured sea
    res_s = np.where(lvl, ps[:, 2] - zg(ps[:, 0], ps[:, 1]), 0.0)
    res_b = pb[:, 2] - zg(pb[:, 0], pb[:, 1])
    water_below = (returns.has_bottom & (res_b < 0.0)) | (
        returns.has_column & (pc[:, 2] - zg(pc[:, 0], pc[:, 1]) < 0.0)
    )
    land_s = np.zeros(n, dtype=bool)
    # clipped bounds that set the level are the sea the land stands above (water under them)
    water_below |= bound & lvl
    if lvl.any():
        land_s[lvl] = land_surface_points(
            ps[lvl, :2], res_s[lvl], water_below[lvl], st, sigma_m=wide.land_sigma_m
        )[0]
    land_s &= has_s
    # a trough is water, down to the band below the level the measured sea sets (SurfaceWide,
    # on the surface returns with water under them). Deeper is not the sea, even with a later
    # return under it: that is a lone seabed echo of a calm sea and a noise hit after it (suite
    # tuning seed 7201: 93 soundings 1-1.6 m short read from such "surfaces"); a rough sea's
    # troughs are inside the band its own measured sigma sets
    low_s = has_s & (res_s <= -wide.below_m)
    water_s = has_s & ~land_s & ~low_s
    land_b = ~has_s & returns.has_bottom & (res_b >= st.land_margin_m)
    if wide.no_water:
        # no pulse saw under its first return: no evidence of water, whatever level the
        # surface returns make (a flat field is as level as a calm sea)
        land_s, water_s, low_s = has_s.copy(), np.zeros(n, dtype=bool), np.zeros(n, dtype=bool)
        land_b = ~has_s & returns.has_bottom
    is_land = land_s | land_b

    # global plane: entry and normal for everyone to start with
    gnorm = np.array([-gx, -gy, 1.0]) / np.sqrt(1.0 + gx * gx + gy * gy)
    normal = np.broadcast_to(gnorm, (n, 3)).copy()
    r_g, grazing = _intersect(o, d, np.array([0.0, 0.0, z0]), normal)
    entry = o + d * r_g[:, None]
    rng = r_g.copy()

    fit_sigma = np.full(n, gsigma)
    height_sigma = np.full(n, gsigma)
    normal_sigma = np.full(n, gsigma / st.radius_m)
    n_used = np.zeros(n, dtype=np.int64)
    resid = np.zeros(n)

    water = ~is_land & ~grazing
    # each plane is its own query (row by row): asking fewer changes none of the others
    q = np.flatnonzero(water if planes_at is None else water & np.asarray(planes_at, bool))
    qxy = np.where(water_s[q, None], ps[q, :2], entry[q, :2])
    spts = np.column_stack([ps[water_s, :2], res_s[water_s]])
    t_emit = returns.t_emit_s
    t_s = None if t_emit is None else t_emit[water_s]
    own_shift = centre = None
    if group is not None and len(spts):
        spts, t_s, centre_w = window_samples(np.asarray(group)[water_s], spts, t_s)
        centre = np.zeros((n, 2))
        centre[water_s] = centre_w
        own_shift = np.zeros(n)
    key = _search_keys(spts[:, :2], t_s, st)
    qkey = _search_keys(qxy, None if t_emit is None else t_emit[q], st)
    fallback = np.ones(len(q), dtype=bool)
    if len(spts) >= 1 and len(q):
        tree = cKDTree(spts[:, :2] if key is None else key)
        for lo in range(0, len(q), st.chunk_size):
            sl = slice(lo, lo + st.chunk_size)
            qi, xy = q[sl], qxy[sl]
            params, ok, used, sig, hsig, nsig, ill = _local_fit(
                tree, spts, xy, st, key, None if qkey is None else qkey[sl], centre is not None
            )
            fallback[sl] = ~ok
            qi, xy, params = qi[ok], xy[ok], params[ok]
            sx, sy = gx + params[:, 1], gy + params[:, 2]
            nrm = np.column_stack([-sx, -sy, np.ones_like(sx)])
            nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
            p0 = np.column_stack([xy, zg(xy[:, 0], xy[:, 1]) + params[:, 0]])
            r, gr = _intersect(o[qi], d[qi], p0, nrm)
            normal[qi] = nrm
            rng[qi] = r
            entry[qi] = o[qi] + d[qi] * r[:, None]
            grazing[qi] = gr
            fit_sigma[qi], height_sigma[qi], normal_sigma[qi] = sig[ok], hsig[ok], nsig[ok]
            n_used[qi] = used[ok]
            flags[qi[ill[ok]]] |= np.uint16(PointFlag.SURFACE_ILL_CONDITIONED)
            own = water_s[qi]
            own_ps = ps[qi]
            if centre is not None:
                # the window's height, measured at its centre, carried along the plane to the
                # shot: a range along the beam (its height changes by d_z per metre of range)
                rise = np.sum(np.column_stack([sx, sy]) * (xy - centre[qi]), axis=1)
                dz = np.where(np.abs(d[qi, 2]) > _GRAZING_COS, d[qi, 2], -1.0)
                own_shift[qi] = np.where(own, rise / dz, 0.0)
                own_ps = own_ps + d[qi] * own_shift[qi, None]
            rs = np.sum(nrm * (own_ps - p0), axis=1)
            resid[qi] = np.where(own, rs, 0.0)
            tol = np.maximum(st.own_outlier_sigma * sig[ok], st.outlier_floor_m)
            out = own & (np.abs(rs) > tol)
            flags[qi[out]] |= np.uint16(PointFlag.SURFACE_OUTLIER)
    fb = q[fallback]
    flags[fb] |= np.uint16(PointFlag.SURFACE_GLOBAL_FALLBACK)
    resid[fb] = np.where(has_s[fb], np.sum(gnorm * (ps[fb] - entry[fb]), axis=1), 0.0)
    resid[land_s] = 0.0

    flags[low_s] |= np.uint16(PointFlag.SURFACE_OUTLIER)
    resid[low_s] = np.sum(normal[low_s] * (ps[low_s] - entry[low_s]), axis=1)
    flags[is_land] |= np.uint16(PointFlag.LAND)
    grazing &= ~is_land
    flags[grazing] |= np.uint16(PointFlag.GRAZING)
    entry[grazing] = o[grazing]
    rng[grazing] = 0.0
    is_water = ~is_land & ~grazing
    if wide.few_surface_returns:
        flags[is_water] |= np.uint16(PointFlag.SURFACE_GLOBAL_FALLBACK)
    # the echo's offset from the plane is wave where the fit scatters more than it ranges
    own_weight = np.ones(n)
    if returns.t_surface_sigma_s is not None:
        cos_i = np.abs(np.sum(d * normal, axis=1))
        ranging = c * returns.t_surface_sigma_s / (2.0 * st.air_index) * cos_i
        own_weight = own_echo_weight(fit_sigma, ranging)
    return WaterSurface(
        entry_m=entry,
        range_to_entry_m=rng,
        normal=normal,
        is_water=is_water,
        is_land=is_land,
        # photon windows: each shot's point carried along its plane from the window's centre
        surface_point_m=ps if own_shift is None else ps + d * own_shift[:, None],
        surface_residual_m=resid,
        fit_sigma_m=fit_sigma,
        height_sigma_m=height_sigma,
        normal_sigma_rad=normal_sigma,
        n_used=n_used,
        flags=flags,
        global_plane=gplane,
        global_sigma_m=float(gsigma),
        air_index=float(st.air_index),
        time_window_s=st.time_window_s if returns.t_emit_s is not None else None,
        own_weight=own_weight,
        own_shift_m=own_shift,
        wide=wide,
    )
