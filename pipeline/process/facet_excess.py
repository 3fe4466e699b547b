"""The in-water path's second-order excess through wave facets the fitted planes do not follow.

Refraction (:mod:`pipeline.process.refraction`) turns each beam at its pulse's fitted local
water plane. The sea the beam met is tilted from that plane by the facet slope ``beta`` the
plane does not follow (waves shorter than its neighbourhood, and the plane's own tilt error).
The range in water is measured (the bottom's time), so the true sounding is
``B(beta) = E + L t(beta)``, ``t`` Snell's direction through the facet; processing puts it at
``B(0)``. To first order the difference ``J beta`` is zero-mean (the TPU's ``wave_facet``
terms, :mod:`pipeline.uncertainty.tpu_facet`); to second order it is not: a nadir beam through
a facet of slope ``beta`` turns by ``delta = beta (1 - 1/n_w)`` and rises by
``L (1 - cos delta) ≈ L delta² / 2``, never falls. Over facets of per-axis slope variance
``s_u²`` along two orthogonal axes,

    ``E[B(beta)] - B(0) = ½ Σ_u s_u² ∂²B/∂beta_u²``

(``∂²B/∂beta_u² = L ∂²t/∂beta_u²`` by central differences, any incidence): at nadir the
sounding is read deep by ``L (1 - 1/n_w)² mss / 2``, 1.7 mm per metre of water under a 10 m/s
sea (``mss`` = 0.054, Cox & Munk 1954). On suite tuning seed 205 (photon profiler, 9.9 m/s,
12.7 m) the seabed lay 0.020 m deep against 0.022 m predicted, 0.008 against 0.012 at 5 m/s
(``benchmarks/wave_refraction/RESULTS.md``). :func:`expected_facet_shift_m` gives that mean;
refraction adds it to each sounding.

What ``s_u²`` is: the facet's slope about the plane's. With the sea's whole mean-square slope
``mss`` (both axes), the planes' slopes ``p_u`` following a smoothed part ``S_u`` of it with
fit noise ``e_u``, and the rest ``r_u`` of the sea's slope uncorrelated with ``S_u``:
``s_u² = E(S_u + r_u - p_u)² = mss/2 - Var(S_u) + E e_u² = mss/2 - Var(p_u) + 2 E e_u²``,
``Var(p_u)`` measured over the survey's water pulses along each pulse's own track axes
(:func:`unresolved_slope_var`). Across a profiler's line the plane is held level (no slope,
no noise): ``s² = mss/2`` there. The sea's ``mss`` is the processing's assumption
(:mod:`pipeline.process.context`: Cox-Munk at the survey's logged wind), not the simulated
sea's own.

Held-out check (session 13, ``benchmarks/wave_refraction/RESULTS.md``): the correction is off
by default (``process.wave_facet_correction``). Over gentle seabeds it took off what the waves
added (held-out seeds 10 and 15, slopes under 3°: bias +0.009 -> -0.003 and +0.008 -> -0.004
m), but profilers over seabeds of 7.5-19° read no deeper under waves than over their flat twins
(held-out seeds 4, 5, 7: the waves' part -0.009 to +0.004 m against +0.015 to +0.035 m
predicted) and the correction made their bias worse (seed 5: +0.007 -> -0.032 m). Something
there lifts those soundings by about as much: not found (the energy weighting of paths up the
slope gives millimetres).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from pipeline.optics import refract_direction
from pipeline.process.returns import PointFlag
from pipeline.process.sea_correlation import LAG_EDGES_M, MIN_PAIRS, surface_point_pairs

__all__ = [
    "track_directions",
    "track_axes",
    "normal_with_slope",
    "expected_depth_excess_m",
    "unresolved_slope_var",
    "plane_slope_var",
    "wave_sea",
    "MIN_SLOPE_VAR",
    "FacetWide",
    "apply_facets",
    "facet_wide",
    "line_axes",
    "with_facets",
]

#: Step of the central second difference in facet slope (rad): its truncation error is
#: ``O(h²)`` relative (1e-6) and its rounding ``eps / h²`` (2e-10) of the path length.
_H = 1e-3


def line_axes(origin_xy_m: np.ndarray, line_id=None) -> tuple[np.ndarray, np.ndarray]:
    """Each flight line's id ``(u,)`` and unit horizontal direction ``(u, 2)``.

    The principal axis of the measured origins ``(n, 2)`` of the pulses of each line
    (``line_id`` ``(n,)``; all pulses as one line 0 without it); x where a line's origins do
    not spread (one pulse). The sign is arbitrary (the axes enter squared).
    """
    xy = np.asarray(origin_xy_m, dtype=np.float64).reshape(-1, 2)
    n = len(xy)
    line = np.zeros(n, np.int64) if line_id is None else np.asarray(line_id)
    lines, inv = np.unique(line, return_inverse=True)
    inv = inv.ravel()
    cnt = np.bincount(inv).astype(np.float64)
    mean = np.column_stack([np.bincount(inv, weights=xy[:, k]) / cnt for k in range(2)])
    d = xy - mean[inv]
    sxx = np.bincount(inv, weights=d[:, 0] ** 2)
    syy = np.bincount(inv, weights=d[:, 1] ** 2)
    sxy = np.bincount(inv, weights=d[:, 0] * d[:, 1])
    # the major axis of each line's 2x2 scatter, at angle atan2(2 sxy, sxx - syy) / 2
    ang = 0.5 * np.arctan2(2.0 * sxy, sxx - syy)
    return lines, np.column_stack([np.cos(ang), np.sin(ang)])


def track_directions(origin_xy_m: np.ndarray, line_id=None) -> np.ndarray:
    """Unit horizontal direction of each pulse's flight line, ``(n, 2)`` (:func:`line_axes`)."""
    n = len(np.asarray(origin_xy_m).reshape(-1, 2))
    lines, axes = line_axes(origin_xy_m, line_id)
    return _axes_of(lines, axes, line_id, n)


def _axes_of(lines: np.ndarray, axes: np.ndarray, line_id, n: int) -> np.ndarray:
    """The axis ``(n, 2)`` of each pulse's line (``line_id`` None: line 0)."""
    line = np.zeros(n, np.int64) if line_id is None else np.asarray(line_id)
    return axes[np.searchsorted(lines, line)]


def track_axes(track_xy, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Unit along-track and across-track (90° to its left) axes, each ``(n, 2)``.

    Without a track: x and y.
    """
    if track_xy is None:
        return np.tile([1.0, 0.0], (n, 1)), np.tile([0.0, 1.0], (n, 1))
    u = np.asarray(track_xy, dtype=np.float64).reshape(-1, 2)
    u = u / np.maximum(np.linalg.norm(u, axis=1, keepdims=True), 1e-12)
    return u, np.column_stack([-u[:, 1], u[:, 0]])


def normal_with_slope(normal: np.ndarray, axis: np.ndarray, step: float) -> np.ndarray:
    """Upward unit normals ``(n, 3)`` whose slope along the unit ``axis`` ``(n, 2)`` moves.

    ``step``: the change of the gradient along ``axis`` (rad, small).
    """
    nz = np.where(np.abs(normal[:, 2]) > 1e-12, normal[:, 2], 1e-12)
    grad = -normal[:, :2] / nz[:, None] + step * axis
    out = np.column_stack([-grad, np.ones(len(normal))])
    return out / np.linalg.norm(out, axis=1, keepdims=True)


def expected_depth_excess_m(
    direction: np.ndarray,
    normal: np.ndarray,
    length_m: np.ndarray,
    n_air: float,
    n_water: float,
    slope_var: np.ndarray,
    track_xy: np.ndarray | None = None,
    decay_per_m: float = 0.0,
) -> np.ndarray:
    """How much deeper than the water each sounding reads through the facets, ``(n,)`` (m).

    Over a level seabed ``D`` below the entry, a sub-beam through facet ``beta`` runs
    ``L(beta) = D / (-t_z(beta))`` in water; the echo's range is the energy-weighted mean of
    those (weights ``exp(-2 k L)``, ``k`` the lidar attenuation: the shorter paths are
    brighter), read along the plane's direction: depth ``E_w[L(beta)] (-t_z(0))``. Its excess
    over ``D`` is ``D E_w[f - 1]``, ``f(beta) = t_z(0) / t_z(beta)``; to second order

        ``D [½ Σ_u s_u² f_uu - 2 k L Σ_u s_u² f_u²]``

    (central differences in ``beta_u``, any incidence). At nadir ``f_u = 0`` and
    ``f_uu = (1 - 1/n_w)²``: ``L (1 - 1/n_w)² mss / 2``. Off nadir the first-order turn of the
    path (``f_u``) brings the weighting's share, which lifts the soundings (suite tuning seed
    502, 20° Palmer under 9.8 m/s, 12 m: module notes of :mod:`pipeline.process.refraction`).

    Parameters
    ----------
    direction : (n, 3)
        Measured beam directions (unit, going down).
    normal : (n, 3)
        The fitted planes' upward normals.
    length_m : (n,)
        In-water path lengths ``L``.
    n_air, n_water : float
        Phase indices.
    slope_var : (n, 2)
        Facet slope variance about the plane along and across ``track_xy`` (rad²).
    track_xy : (n, 2), optional
        Unit horizontal direction of the first axis (default x).
    decay_per_m : float
        Lidar attenuation ``k`` of the bottom echo's energy (per metre of one-way path).

    Returns
    -------
    (n,) float64
        Positive: the plane's reading is deep by that much; take it off the depth (raise the
        sounding). Zero where ``slope_var`` is zero; finite wherever the inputs are.
    """
    n = len(direction)
    out = np.zeros(n)
    var = np.asarray(slope_var, dtype=np.float64).reshape(n, 2)
    rows = np.flatnonzero(np.any(var > 0.0, axis=1))
    if rows.size == 0:
        return out
    d, nrm = direction[rows], normal[rows]
    length = np.asarray(length_m, dtype=np.float64)[rows]
    t0, _ = refract_direction(d, nrm, n_air, n_water)
    tz0 = np.minimum(t0[:, 2], -1e-6)  # going down (a grazing beam: finite, not a NaN)
    axes = track_axes(None if track_xy is None else np.asarray(track_xy)[rows], rows.size)
    second = np.zeros(rows.size)
    weight = np.zeros(rows.size)
    for k, axis in enumerate(axes):
        f = []
        for step in (_H, -_H):
            t, _ = refract_direction(d, normal_with_slope(nrm, axis, step), n_air, n_water)
            f.append(tz0 / np.minimum(t[:, 2], -1e-6))
        second += var[rows, k] * (f[0] - 2.0 + f[1]) / _H**2
        weight += var[rows, k] * ((f[0] - f[1]) / (2.0 * _H)) ** 2
    depth = length * -tz0
    out[rows] = depth * (0.5 * second - 2.0 * decay_per_m * length * weight)
    return out


def unresolved_slope_var(
    mss: float,
    normal: np.ndarray,
    normal_sigma_rad: np.ndarray,
    is_water: np.ndarray,
    flags: np.ndarray,
    track_xy: np.ndarray,
    plane_var: tuple[float, float] | None = None,
) -> np.ndarray:
    """Facet slope variance about each pulse's plane, ``(n, 2)`` along and across its track.

    ``max(mss/2 - Var(p_u) + 2 e_u², 0)`` (module notes): ``Var(p_u)`` the variance of the
    water pulses' plane slopes along their own axis ``u``, ``e_u² = normal_sigma_rad² / 2``
    each plane's tilt variance per axis. Across a plane flagged ``SURFACE_ILL_CONDITIONED``
    (a profiler's collinear neighbours, held level across): ``mss / 2``. Zero without water
    or with ``mss = 0``.

    Parameters
    ----------
    mss : float
        The sea's whole mean-square slope (both axes).
    normal : (n, 3)
        Fitted planes' upward normals.
    normal_sigma_rad : (n,)
        Their tilt sigma (NaN: none known, taken as 0).
    is_water, flags : (n,)
        Which pulses entered water; the surface fit's flags.
    track_xy : (n, 2)
        Each pulse's flight-line direction (:func:`track_directions`).
    plane_var : (float, float), optional
        ``Var(p_u)`` along and across, as measured over a whole survey these pulses are part
        of (:func:`plane_slope_var`; None where no plane follows); default: of these pulses.
    """
    n = len(normal)
    out = np.zeros((n, 2))
    water = np.asarray(is_water, dtype=bool)
    if mss <= 0.0 or not water.any():
        return out
    if plane_var is None:
        plane_var = plane_slope_var(normal, is_water, flags, track_xy)
    blind = (np.asarray(flags) & np.uint16(PointFlag.SURFACE_ILL_CONDITIONED)) != 0
    e2 = np.nan_to_num(np.asarray(normal_sigma_rad, dtype=np.float64)) ** 2 / 2.0
    for k in range(2):
        if plane_var[k] is not None:
            out[:, k] = np.maximum(mss / 2.0 - plane_var[k] + 2.0 * e2, 0.0)
        if k == 1:
            out[blind, k] = mss / 2.0
    out[~water] = 0.0
    return out


def plane_slope_var(normal, is_water, flags, track_xy) -> tuple[float | None, float | None]:
    """``Var(p_u)`` of :func:`unresolved_slope_var`: the water planes' slope variance.

    Along each pulse's track over the water pulses, across it over those whose plane follows
    the sea across (not ``SURFACE_ILL_CONDITIONED``); None where no pulse counts. A survey's
    figure (one sea): a tile of the survey is given it.
    """
    n = len(normal)
    water = np.asarray(is_water, dtype=bool)
    nz = np.where(np.abs(normal[:, 2]) > 1e-12, normal[:, 2], 1e-12)
    grad = -normal[:, :2] / nz[:, None]
    along, across = track_axes(track_xy, n)
    blind = (np.asarray(flags) & np.uint16(PointFlag.SURFACE_ILL_CONDITIONED)) != 0
    out: list[float | None] = []
    for k, axis in enumerate((along, across)):
        p = np.sum(grad * axis, axis=1)
        follow = water & ~blind if k == 1 else water
        out.append(float(np.var(p[follow])) if follow.any() else None)
    return out[0], out[1]


#: Along-track slope variance (rad²) the echoes must show at their shortest lags for a wave
#: sea: 0.01 rad rms. Model choice, set on the suite's tuning scenes (a flat sea's echoes show
#: 0 to 8e-5, shallow and half on land; wind seas from 1e-3 up), judged on the held-out half.
MIN_SLOPE_VAR = 1e-4


def wave_sea(returns, surface, group=None) -> bool:
    """Whether the survey's surface echoes show a wave sea: facets to refract through.

    The structure function of the echoes' heights above the global plane,
    ``D(h) = mean (z_i - z_j)²`` over pairs of distinct detections at most the surface fit's
    time window apart (:func:`~pipeline.process.sea_correlation.surface_point_pairs`: the sea
    moves), is ``2 n² + s² h²`` at lags shorter than the waves (``n`` the ranging noise, ``s²``
    the slope variance along the pairs). Between the two shortest lags the noise cancels:
    ``s² = (D_2 - D_1) / (h_2² - h_1²)``, no ranging sigma needed (photon windows give none).
    The lag bins are pooled from the shortest on until each pool holds
    :data:`~pipeline.process.sea_correlation.MIN_PAIRS` pairs: a pool's mean ``D`` and mean
    ``h²`` keep the law's form (it is linear in ``h²``), and a scan whose shortest lags are
    each too sparse alone keeps them together. (Taking the two shortest bins that had enough
    pairs alone skipped them: suite tuning seed 502, a 20° Palmer under 9.8 m/s, has ~260
    pairs under 2 m spread over five bins, which show the rise, and then 2-4 m, where its
    short waves' ``D`` has levelled off: ``s² = -3e-6``, no waves told; pooled 1.6e-3.)
    A wave sea: ``s²`` above :data:`MIN_SLOPE_VAR`. A flat sea has
    ``s² = 0`` whatever the logged wind (a simulated flat sea whose wind only sets its glint),
    and so has one whose echoes carry a bias that drifts with the seabed over metres (a
    profiler over a sloping shoal: the rise between the longest and the shortest lags took
    those for waves). Fewer than two lag bins: no wave sea told.

    Parameters
    ----------
    returns : DetectedReturns
    surface : WaterSurface
        Its fit of the same pulses.
    group : (n,) array_like, optional
        Pulses sharing one detection (a photon window): never paired together.
    """
    idx, i, j = surface_point_pairs(returns, surface, max_dt_s=surface.time_window_s, group=group)
    if i.size == 0:
        return False
    p = surface.surface_point_m[idx]
    h = p[:, 2] - surface.global_z_m(p[:, 0], p[:, 1])
    lag = np.hypot(p[i, 0] - p[j, 0], p[i, 1] - p[j, 1])
    edges = np.asarray(LAG_EDGES_M)
    b = np.digitize(lag, edges) - 1
    inside = (b >= 0) & (b < edges.size - 1)
    nb = edges.size - 1
    b = b[inside]
    count = np.bincount(b, minlength=nb)
    d2 = np.bincount(b, weights=(h[i] - h[j])[inside] ** 2, minlength=nb)
    lag2 = np.bincount(b, weights=lag[inside] ** 2, minlength=nb)
    # two pools of consecutive bins from the shortest lag, each closed once it holds
    # MIN_PAIRS pairs (a bin that has them alone is a pool of its own)
    c = np.cumsum(count)
    e1 = int(np.searchsorted(c, MIN_PAIRS, side="left"))
    e2 = int(np.searchsorted(c, c[min(e1, nb - 1)] + MIN_PAIRS, side="left"))
    if e2 >= nb:
        return False
    pools = (slice(0, e1 + 1), slice(e1 + 1, e2 + 1))
    n_p = np.array([count[p].sum() for p in pools], dtype=np.float64)
    d_mean = np.array([d2[p].sum() for p in pools]) / n_p
    h2 = np.array([lag2[p].sum() for p in pools]) / n_p
    return bool((d_mean[1] - d_mean[0]) / (h2[1] - h2[0]) > MIN_SLOPE_VAR)


@dataclass(frozen=True)
class FacetWide:
    """A wave sea's survey-wide facet figures (:func:`facet_wide`).

    Attributes
    ----------
    line_id : (u,) int64
        The survey's flight lines (0: no line ids).
    axis_xy : (u, 2) float64
        Each line's unit direction (:func:`line_axes`).
    plane_var : (float or None, float or None)
        :func:`plane_slope_var` of the survey's water pulses.
    """

    line_id: np.ndarray
    axis_xy: np.ndarray
    plane_var: tuple[float | None, float | None]


def facet_wide(returns, surface, mss: float, group=None) -> FacetWide | None:
    """The survey's facet figures; None where ``mss`` is 0 or the echoes show no wave sea.

    ``group``: pulses sharing one detection (:func:`wave_sea`).
    """
    if mss <= 0.0 or not wave_sea(returns, surface, group):
        return None
    lines, axes = line_axes(returns.origin_meas_m[:, :2], returns.line_id)
    track = _axes_of(lines, axes, returns.line_id, len(returns))
    var = plane_slope_var(surface.normal, surface.is_water, surface.flags, track)
    return FacetWide(lines, axes, var)


def apply_facets(returns, surface, mss: float, facets: FacetWide | None):
    """``surface`` with the facets' slope variance about its planes and its flight lines.

    ``facets``: the survey's (:func:`facet_wide`); None: ``surface`` unchanged.
    """
    if facets is None:
        return surface
    track = _axes_of(facets.line_id, facets.axis_xy, returns.line_id, len(returns))
    var = unresolved_slope_var(
        mss,
        surface.normal,
        surface.normal_sigma_rad,
        surface.is_water,
        surface.flags,
        track,
        facets.plane_var,
    )
    return dataclasses.replace(surface, facet_slope_var=var, track_xy=track)


def with_facets(returns, surface, mss: float, group=None):
    """``surface`` with the facets' slope variance about its planes and its flight lines.

    ``mss``: the sea's whole mean-square slope processing assumes
    (``RefractionSettings.facet_mss``). Unchanged where it is 0 or the echoes show no wave sea
    (:func:`wave_sea`; ``group``: pulses sharing one detection).
    """
    return apply_facets(returns, surface, mss, facet_wide(returns, surface, mss, group))
