"""The TPU's inputs measured from neighbouring soundings.

The seabed gradient, the depth scatter, the water surface over each sounding, and the timing
sigmas the scatter implies (:mod:`pipeline.uncertainty.tpu`).
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from pipeline.process.refraction import RefractionSettings
from pipeline.process.returns import DetectedReturns
from pipeline.process.surface_fit import WaterSurface
from pipeline.uncertainty.pair_scatter import pair_scatter
from pipeline.uncertainty.seabed_gradient import seabed_gradient
from pipeline.uncertainty.tpu_derivatives import Derivatives
from pipeline.uncertainty.tpu_settings import (
    DEPTH,
    RANDOM_TERMS,
    TIMING_TERMS,
    TpuSettings,
    Z,
)
from pipeline.uncertainty.tpu_terms import _inputs, _terms
from pipeline.uncertainty.wave_pool import surface_wave_sigma_m

__all__ = [
    "pair_scatter",
    "seabed_gradient",
    "surface_over_sounding",
    "surface_tilt_sigma",
    "timing_from_scatter",
    "amplitude_fill",
]

#: query points per neighbour search block (memory: ~1.5 kB each with 64 neighbours)
_QUERY_BLOCK = 65536


def surface_over_sounding(
    returns: DetectedReturns, surface: WaterSurface, xy_m: Any
) -> tuple[np.ndarray, np.ndarray]:
    """How the water plane of each bottom pulse turns against the surface over its sounding.

    A sounding's depth is measured below its own pulse's local plane (fitted around the water
    entry ``E``), read at the sounding ``B``, ``Delta`` away horizontally (the refracted beam's
    offset, about a quarter of the depth at 20°). The surface measured over the sounding is the
    local plane of the surface return nearest to ``B``. The difference of the two planes'
    heights at ``B`` less their difference at ``E`` is ``T = (s_B - s_E) . (B - E)``, their
    slopes' difference times the offset: free of any height offset between the two fits (e.g.
    navigation heights that differ between the passes that sampled them, which the depth does
    not see), it holds the two planes' tilt errors and the bending of the waves between ``E``
    and ``B`` that one plane cannot follow. Where ``B`` lies within the fit's own
    neighbourhood the two planes share their points and ``T`` understates the tilt error.
    The sea moves: with the fit's time window (``surface.time_window_s``), the surface return
    over ``B`` is the nearest of the 16 nearest that is within the window of the pulse's own
    time (the same look), else the nearest.

    Parameters
    ----------
    returns, surface
        As for :func:`point_tpu`.
    xy_m : (n_bottom, 2) array_like
        The soundings (rows of :func:`~pipeline.process.refraction.seabed_points`).

    Returns
    -------
    T_m, Delta_m : (n_bottom,) float64
        ``T`` is NaN where the pulse does not enter water or no surface return exists.
    """
    rows = np.flatnonzero(returns.has_bottom)
    xy = np.asarray(xy_m, dtype=np.float64).reshape(-1, 2)
    if xy.shape[0] != rows.size:
        raise ValueError(f"`xy_m` must be (n_bottom, 2) = ({rows.size}, 2); got {xy.shape}")
    entry = surface.entry_m[rows, :2]
    delta = np.hypot(*(xy - entry).T)
    ws = np.flatnonzero(surface.is_water & returns.has_surface)
    if ws.size == 0 or rows.size == 0:
        return np.full(rows.size, np.nan), delta
    tree = cKDTree(surface.surface_point_m[ws, :2])
    if surface.time_window_s is None or returns.t_emit_s is None:
        _, j = tree.query(xy, k=1, workers=-1)
    else:
        k = min(16, ws.size)
        j = np.empty(xy.shape[0], dtype=np.int64)
        for lo in range(0, xy.shape[0], _QUERY_BLOCK):  # (soundings, k) temporaries bounded
            b = slice(lo, lo + _QUERY_BLOCK)
            _, near = tree.query(xy[b], k=k, workers=-1)
            near = np.asarray(near).reshape(-1, k)
            dt = np.abs(returns.t_emit_s[ws[near]] - returns.t_emit_s[rows[b]][:, None])
            same = dt <= surface.time_window_s
            # argmax finds the first (nearest) in the window; none in it: the nearest
            pick = np.where(same.any(1), np.argmax(same, axis=1), 0)
            j[b] = near[np.arange(near.shape[0]), pick]

    def apart(x, y):  # the plane over the sounding less the pulse's own, at (x, y)
        return surface.surface_z_m(ws[j], x, y) - surface.surface_z_m(rows, x, y)

    turn = apart(xy[:, 0], xy[:, 1]) - apart(entry[:, 0], entry[:, 1])
    return np.where(surface.is_water[rows], turn, np.nan), delta


def _binned_table(x, v, *, per_bin=100, max_bins=40):
    """Median ``x`` and mean ``v`` of equal-count bins of ``x``; None without a finite pair."""
    ok = np.isfinite(x) & np.isfinite(v)
    x, v = x[ok], v[ok]
    if x.size == 0:
        return None
    order = np.argsort(x)
    x, v = x[order], v[order]
    nb = int(min(max(x.size // per_bin, 1), max_bins))
    edges = np.linspace(0, x.size, nb + 1).astype(np.int64)
    cx = np.array([np.median(x[a:b]) for a, b in zip(edges[:-1], edges[1:], strict=True)])
    cv = np.array([np.mean(v[a:b]) for a, b in zip(edges[:-1], edges[1:], strict=True)])
    return cx, cv


def _interp_table(table, query):
    """A :func:`_binned_table` interpolated at ``query`` (clamped; NaN without a table)."""
    if table is None:
        return np.full(np.shape(query), np.nan)
    return np.interp(query, *table)


def surface_tilt_sigma(
    returns: DetectedReturns,
    surface: WaterSurface,
    xy_m: Any,
    *,
    pool: Any = None,
    min_offset_m: float = 0.25,
    turn_table: Any = None,
    return_table: bool = False,
):
    """Tilt uncertainty of each bottom pulse's water plane, measured over its sounding (rad).

    The fit's own standard error (``WaterSurface.normal_sigma_rad``) assumes independent
    residuals: it sees neither the waves its neighbourhood does not follow nor the misfit of
    neighbours flown at different times (navigation errors that differ between the passes).
    The turn ``T`` of the pulse's plane against the plane over its sounding
    (:func:`surface_over_sounding`) measures both: with the two fits' tilt errors alike, of
    per-axis sigma ``tau``, ``E[T²] = 2 tau² Delta²``. ``E[T²]`` is averaged in bins of
    ``Delta`` over the ``pool`` rows (default all: a wave field is the same over a survey,
    and a single ``T`` is that point's error, not its spread). Returned as the total
    ``sqrt(2) tau``, like ``normal_sigma_rad``; 0 below ``min_offset_m`` and where the pulse
    does not enter water.

    Parameters
    ----------
    xy_m : (n_bottom, 2) array_like
        The soundings (rows of :func:`~pipeline.process.refraction.seabed_points`).
    pool : array_like of int or bool, optional
        The rows averaged (e.g. the bathymetric points').
    turn_table : tuple of two (k,) arrays, or None, optional
        ``E[T²]`` against ``Delta`` as measured over a whole survey whose part these pulses
        are (the ``table`` this function returns; None: nothing measured it): used as given,
        so a tile's pulses get the survey's figures and only their offsets are computed here.
    return_table : bool
        Also return the table used.

    Returns
    -------
    tilt : (n_bottom,) float64
    table : tuple of two (k,) arrays, or None
        The binned ``(Delta, E[T²])`` (only with ``return_table``).
    """
    rows = np.flatnonzero(returns.has_bottom)
    if turn_table is None:
        turn, delta = surface_over_sounding(returns, surface, xy_m)
        sel = np.arange(rows.size) if pool is None else np.asarray(pool)
        turn_table = _binned_table(delta[sel], (turn**2)[sel])
    else:  # the offsets alone: the turns are the survey's, in the table
        xy = np.asarray(xy_m, dtype=np.float64).reshape(-1, 2)
        delta = np.hypot(*(xy - surface.entry_m[rows, :2]).T)
    mst = np.maximum(np.nan_to_num(_interp_table(turn_table, delta)), 0.0)
    tilt = np.sqrt(mst) / np.maximum(delta, min_offset_m)
    ok = surface.is_water[rows] & (delta >= min_offset_m)
    tilt = np.where(ok, tilt, 0.0)
    return (tilt, turn_table) if return_table else tilt


def timing_from_scatter(
    returns: DetectedReturns,
    surface: WaterSurface,
    refraction_settings: RefractionSettings | None = None,
    settings: TpuSettings | None = None,
    *,
    depth_scatter_m: Any,
    seabed_gradient: Any = None,
    max_sigma_s: float = math.inf,
    raise_only: bool = False,
    amplitude_fill: tuple[float, float] | None = None,
    scatter_column: int = DEPTH,
    return_derivatives: bool = False,
):
    """``returns`` with the per-return timing sigmas that the measured depth scatter implies.

    For a detector that reports no timing sigma: the timing terms' depth variance is set to the
    measured random scatter of the soundings (:func:`pair_scatter`) less the other random
    terms', ``s_t² = max(scatter² - other², 0)``, split between the two returns (each through
    its own depth derivative: the surface's moves the entry by its weight) as for
    photon-limited timing, variance in proportion to ``1 / amplitude`` (equal without
    amplitudes); a NaN scatter keeps the a-priori sigma.

    The sigma is ``scatter / |d depth / d t|``, the derivative of the depth compared at the
    measured position: it tends to 0 where a beam runs along the local seabed gradient
    (``g . u tan(theta_w) -> 1``), or where false bottoms among the soundings make that
    gradient absurd, and the sigma then grows without bound (hundreds of µs). A detected
    return lies in the recorded window, so no timing sigma exceeds that of a time spread
    uniformly over it, ``window / sqrt(12)``: ``max_sigma_s`` (``bathy run`` passes that of
    the detector's window) bounds the sigmas set here. Pulses whose sigma still reaches their
    surface-bottom separation are left out by :func:`point_tpu`.

    Parameters
    ----------
    depth_scatter_m : (n_bottom,) array_like
        Measured one-sigma random depth error of each bottom point (rows of
        :func:`~pipeline.process.refraction.seabed_points`), or of its height with
        ``scatter_column``.
    seabed_gradient : (n_bottom, 2) array_like, optional
        As for :func:`point_tpu`.
    max_sigma_s : float, optional
        Upper bound of each sigma set from the scatter (default: none).
    raise_only : bool, optional
        Keep the detector's sigmas (``returns.t_*_sigma_s``) as a floor: each return's sigma
        is the larger of its own and the one the scatter implies (the detector's are a
        Cramér–Rao bound, which the timing achieved can only exceed). The scatter's excess is
        then that over every random term, the detector's timing included, split between the
        two returns as below and added in quadrature. Default: the scatter sets them.
    amplitude_fill : (float, float), optional
        The surface and bottom amplitude a return without one is weighted as
        (:func:`amplitude_fill`: the survey's median; default: that of ``returns``).
    scatter_column : int, optional
        What ``depth_scatter_m`` scatters: :data:`~pipeline.uncertainty.tpu_settings.DEPTH`
        (default) or :data:`~pipeline.uncertainty.tpu_settings.Z`, the seabed point's height
        (no sea between soundings). Its excess over the other random terms' height parts is
        ranging, carried to the depth by the bottom timing's depth-to-height ratio and split
        as a depth excess (not compared at the measured position: ~7 % off at 15° of slope).
    return_derivatives : bool, optional
        Also return the bottom pulses' points and their derivatives this pass made
        (:class:`~pipeline.uncertainty.tpu_derivatives.Derivatives`), for :func:`point_tpu` of the
        same pulses to read.

    Returns
    -------
    DetectedReturns
        And the :class:`~pipeline.uncertainty.tpu_derivatives.Derivatives` with
        ``return_derivatives``.
    """
    st = settings or TpuSettings()
    rst = refraction_settings or RefractionSettings()
    unit = 1e-10
    st_unit = dataclasses.replace(st, timing_sigma_s=unit)
    bare = dataclasses.replace(returns, t_surface_sigma_s=None, t_bottom_sigma_s=None)
    # the other terms' wave height as it always was here: each pulse's whole plane residual
    # (unit timing sigmas range ~nothing), pulse by pulse, not the TPU's pool (wave_pool)
    own_wave = surface_wave_sigma_m(bare, surface, unit, 0.0)
    inp = _inputs(bare, surface, rst, st_unit, seabed_gradient, wave_sigma_m=own_wave)
    n = len(inp.row)
    scatter = np.asarray(depth_scatter_m, dtype=np.float64).ravel()
    if scatter.shape != (n,):
        raise ValueError(f"`depth_scatter_m` must be (n_bottom,) = ({n},); got {scatter.shape}")
    if return_derivatives:
        _, terms, moves = _terms(inp, st_unit, RANDOM_TERMS, keep_moves=True)
        derivatives = Derivatives.made(inp, moves, surface, st)
        del moves
    else:
        _, terms = _terms(inp, st_unit, RANDOM_TERMS)
    if scatter_column not in (DEPTH, Z):
        raise ValueError(f"`scatter_column` must be DEPTH or Z; got {scatter_column!r}")
    col = scatter_column
    skip = TIMING_TERMS + (("footprint",) if col == Z else ())  # moves it along the plane
    other = sum(terms[k][:, col] ** 2 for k in RANDOM_TERMS if k not in skip)
    prior_s = returns.t_surface_sigma_s
    prior_b = returns.t_bottom_sigma_s
    if raise_only and prior_b is not None:
        ps = np.zeros(n) if prior_s is None else np.asarray(prior_s, np.float64)[inp.row]
        pb = np.asarray(prior_b, np.float64)[inp.row]
        for name, sig in (("timing_surface", ps), ("timing_bottom", pb)):
            other = other + (terms[name][:, col] / unit * sig) ** 2
    excess = np.maximum(np.nan_to_num(scatter) ** 2 - other, 0.0)
    js = terms["timing_surface"][:, DEPTH] / unit
    jb = terms["timing_bottom"][:, DEPTH] / unit
    if col == Z:
        # not split in heights: a surface timing moves a depth read against the sea at the
        # entry ~3 times as much as the height
        jbz = terms["timing_bottom"][:, Z] / unit
        ratio = np.divide(jb, jbz, out=np.ones(n), where=np.abs(jbz) > 0.0)
        excess = excess * ratio**2
    ret = inp.ret
    hs = ret.has_surface

    fill_s, fill_b = amplitude_fill or _amplitude_fill(ret)

    def inv_amp(a, fill):
        if a is None:
            return np.ones(n)
        a = np.asarray(a, dtype=np.float64)
        return 1.0 / np.where(a > 0, a, fill)

    ws = np.where(hs, inv_amp(ret.surface_amplitude, fill_s), 0.0)
    wb = inv_amp(ret.bottom_amplitude, fill_b)
    den = ws * js**2 + wb * jb**2
    c = np.where(den > 0, excess / np.where(den > 0, den, 1.0), 0.0)
    floor = 1e-15  # sigmas must be > 0 where a return exists
    sig_s = np.where(returns.has_surface, st.timing_sigma_s, 0.0) if prior_s is None else prior_s
    sig_b = np.where(returns.has_bottom, st.timing_sigma_s, 0.0) if prior_b is None else prior_b
    sig_s, sig_b = np.array(sig_s, dtype=np.float64), np.array(sig_b, dtype=np.float64)
    use = np.isfinite(scatter)
    rows = inp.row[use]
    if raise_only and prior_b is not None:
        # in quadrature on the detector's own, where the scatter shows more (never above the
        # window's bound once raised, never below the detector's)
        more = use & (c > 0.0)
        rows = inp.row[more]

        def raised(own, w):
            return np.maximum(np.minimum(np.hypot(own, np.sqrt(w * c)[more]), max_sigma_s), own)

        sig_b[rows] = raised(sig_b[rows], wb)
        sig_s[rows] = np.where(hs[more], raised(sig_s[rows], ws), 0.0)
    else:
        sig_b[rows] = np.clip(np.sqrt(wb * c)[use], floor, max_sigma_s)
        sig_s[rows] = np.where(hs[use], np.clip(np.sqrt(ws * c)[use], floor, max_sigma_s), 0.0)
    sig_s = np.where(returns.has_surface, np.maximum(sig_s, floor), 0.0)
    sig_b = np.where(returns.has_bottom, np.maximum(sig_b, floor), 0.0)
    out = dataclasses.replace(returns, t_surface_sigma_s=sig_s, t_bottom_sigma_s=sig_b)
    return (out, derivatives) if return_derivatives else out


def amplitude_fill(returns: DetectedReturns) -> tuple[float, float]:
    """The surface and bottom amplitude :func:`timing_from_scatter` gives returns without one.

    The median positive amplitude of the bottom pulses' returns (1 without any), as
    :func:`timing_from_scatter` weighs them: a survey-wide figure a tile is given.
    """
    return _amplitude_fill(returns.select(returns.has_bottom))


def _amplitude_fill(ret) -> tuple[float, float]:
    def fill(a):
        pos = None if a is None else np.asarray(a, dtype=np.float64)
        return float(np.median(pos[pos > 0])) if pos is not None and np.any(pos > 0) else 1.0

    return fill(ret.surface_amplitude), fill(ret.bottom_amplitude)
