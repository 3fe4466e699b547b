"""How far the sea a pulse met at its water entry still tells the sea above its sounding.

A sounding's depth is read below the water surface above it, ``B``, at the pulse's time; the
pulse met the sea at its entry ``E``, ``Delta = |B - E|`` away horizontally (about a quarter of
the depth at 20° off nadir). The local fitted plane follows the waves longer than its
neighbourhood; the pulse's own surface echo tells, besides its ranging noise, the height of the
shorter waves at ``E`` above that plane, ``s_E``
(:func:`~pipeline.process.surface_land.own_echo_weight` takes the noise out: ``w s_E``). Above
``B`` the same wave has moved on by ``Delta``: the best linear predictor of the sea there above
the plane is ``rho(Delta) w s_E`` (simple kriging from one observation; Cressie 1993,
*Statistics for Spatial Data*, §3.4), ``rho`` the correlation of the heights above the plane at
horizontal lag ``Delta``. With ``rho = 1`` (the sea above ``B`` taken as at ``E``) a deep
sounding under a short sea inherits the wave at its entry; with ``rho = 0`` (the plane alone) a
shallow sounding under a 10 m/s sea carries the whole wave height it should have cancelled.

``rho`` is **measured** from the survey's own surface returns: pairs of surface points at most
the surface fit's time window apart (the sea moves), ``h`` apart horizontally, both heights
taken above the *earlier* pulse's local plane (what a sounding reads: its entry and the sea
over it, against its own plane). Per lag bin the regression of the partner's height on the
anchor's, ``beta(h) = sum(s_i s_j) / sum(s_i²)``, is the predictor's coefficient (the anchor's
ranging noise shrinks it, as ``w`` does: ``rho(h) = beta(h) / beta(h_0)`` divides it out at the
shortest lag ``h_0``); ``rho`` is clipped to ``[0, 1]`` and made non-increasing with lag (a
swell's negative lobe is not followed: the plane alone is the safer reading there). Without
pairs ``rho = 0`` everywhere: the depth is read below the plane.

**The plane's tilt** (``gamma``): the same pairs tell how far the anchor's local plane, carried
``h`` away, predicts the sea there. Per lag bin, ``gamma(h) = sum(r u) / sum(r²)``, the
regression of the partner's height above the anchor's level (its plane's height at the anchor,
carried by the global plane's tilt only) on the rise ``r`` the anchor plane's own tilt gives it
(clipped to ``[0, 1]``): ~1 where the planes follow the waves (a long swell), ~0 where their
tilt is fit noise (a wind sea moving through the 1 s window, noisy echoes). A sounding's depth
carries ``gamma(Delta)`` of its plane's rise to ``B``. Partners within the anchor's fit
radius helped fit its plane, which raises ``gamma`` there towards 1 (the whole tilt, as before).

Photon counting: a window's shots share one detection; pairs within one window are one
measurement twice and are left out.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.parallel import thread_map, thread_map_rows
from pipeline.process.returns import DetectedReturns, PointFlag

__all__ = [
    "LAG_EDGES_M",
    "SeaCorrelation",
    "SurfacePairs",
    "sea_correlation",
    "reduced_surface_pairs",
    "surface_pairs",
    "surface_point_pairs",
    "time_pairs",
]

#: Lag bins (m): fine at the lags of shallow soundings, up to those of 100 m depths.
LAG_EDGES_M = (0.0, 0.25, 0.5, 1.0, 1.5, 2.0, 3.0, 4.0, 6.0, 8.0, 12.0, 16.0, 24.0, 32.0, 48.0)
#: Pairs a lag bin needs.
MIN_PAIRS = 200
#: Anchors per time offset at most (drawn at random with a fixed seed: a stride would alias with
#: the scan pattern), and the farthest offset in time order looked at.
_MAX_PER_OFFSET = 50_000
_MAX_OFFSET = 2000
#: The shortest lag's regression must stand this many standard errors above 0.
_MIN_T = 3.0
#: Pairs per block of :func:`surface_pairs`' arithmetic (bounds its temporaries).
_PAIR_BLOCK = 65_536


@dataclass(frozen=True)
class SeaCorrelation:
    """Correlation of the sea's heights above the local plane against horizontal lag.

    Attributes
    ----------
    lag_m : (k,) float64
        Mean pair separation of each lag bin with enough pairs (ascending).
    rho : (k,) float64
        ``rho`` there, in ``[0, 1]``, non-increasing.
    pairs : int
        Pairs used.
    tilt_lag_m, tilt : (t,) float64 or None
        Lag bins and the share ``gamma`` of the local plane's own rise that comes true there
        (module notes); None: the whole rise (the plane as fitted).
    """

    lag_m: np.ndarray
    rho: np.ndarray
    pairs: int
    tilt_lag_m: np.ndarray | None = None
    tilt: np.ndarray | None = None

    def tilt_at(self, lag_m) -> np.ndarray:
        """Share of the local plane's own rise to carry ``lag_m`` away (1 without bins).

        Flat below the first bin and beyond the last, linear between.
        """
        lag = np.asarray(lag_m, dtype=np.float64)
        if self.tilt is None or self.tilt.size == 0:
            return np.ones(lag.shape)
        return np.interp(lag, self.tilt_lag_m, self.tilt)

    def at(self, lag_m) -> np.ndarray:
        """``rho`` at horizontal lags ``lag_m`` (1 at 0, linear between bins, the last beyond).

        Without bins: 0 (the plane alone).
        """
        lag = np.asarray(lag_m, dtype=np.float64)
        if self.lag_m.size == 0:
            return np.zeros(lag.shape)
        return np.interp(lag, np.r_[0.0, self.lag_m], np.r_[1.0, self.rho])


def time_pairs(t: np.ndarray, group, max_dt_s: float):
    """Pairs ``(i, j)``, ``i < j`` in time order, at most ``max_dt_s`` apart, not in one group."""
    n = t.size
    rng = np.random.default_rng(0)  # the same survey, the same pairs
    offsets = np.unique(np.round(np.geomspace(1, max(min(_MAX_OFFSET, n - 1), 1), 64)))
    ii, jj = [], []
    for k in offsets.astype(np.int64):
        if k >= n:
            break
        i = np.arange(n - k)
        if i.size > _MAX_PER_OFFSET:
            i = np.sort(rng.choice(i.size, _MAX_PER_OFFSET, replace=False))
        j = i + k
        ok = (t[j] - t[i]) <= max_dt_s
        if group is not None:
            ok &= group[i] != group[j]
        if not ok.any():
            break  # farther offsets lie farther apart in time still
        ii.append(i[ok])
        jj.append(j[ok])
    if not ii:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    return np.concatenate(ii), np.concatenate(jj)


@dataclass(frozen=True)
class SurfacePairs:
    """Pairs of near-simultaneous surface points, both heights above the earlier one's plane.

    Attributes
    ----------
    row_i, row_j : (p,) int64
        Pulse rows of the earlier (anchor) and the later point of each pair.
    s_i_m, s_j_m : (p,) float64
        Their heights above the anchor's local plane (what a sounding's depth reads: its
        entry and the sea over it, against its own plane).
    lag_m : (p,) float64
        Horizontal separation.
    rise_m : (p,) float64, optional
        The anchor's local plane's own rise from the anchor to the partner (beyond the global
        plane's): what its tilt, carried ``lag_m`` away, tells of the sea there.
    """

    row_i: np.ndarray
    row_j: np.ndarray
    s_i_m: np.ndarray
    s_j_m: np.ndarray
    lag_m: np.ndarray
    rise_m: np.ndarray | None = None


def surface_point_pairs(
    returns: DetectedReturns, surface, *, max_dt_s: float | None, group=None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The water pulses' own, non-outlier surface points in time order, and their pairs.

    Returns ``(idx, i, j)``: the points' pulse rows in emission-time order (pulse-id order,
    and no time limit, without ``t_emit_s``) and :func:`time_pairs` of them (positions in
    ``idx``); empty pairs with fewer than two points.
    """
    ok = surface.is_water & returns.has_surface
    ok &= (surface.flags & np.uint16(PointFlag.SURFACE_OUTLIER)) == 0
    idx = np.flatnonzero(ok)
    none = np.zeros(0, np.int64)
    if idx.size < 2:
        return idx, none, none
    if returns.t_emit_s is not None:
        t = np.asarray(returns.t_emit_s, dtype=np.float64)[idx]
    else:
        t, max_dt_s = returns.pulse_id[idx].astype(np.float64), None
    order = np.argsort(t, kind="stable")
    idx, t = idx[order], t[order]
    g = None if group is None else np.asarray(group).ravel()[idx]
    i, j = time_pairs(t, g, np.inf if max_dt_s is None else float(max_dt_s))
    return idx, i, j


def surface_pairs(
    returns: DetectedReturns, surface, *, max_dt_s: float | None, group=None
) -> SurfacePairs | None:
    """Pairs of the water pulses' own, non-outlier surface points; None without any.

    :func:`time_pairs` in emission-time order (pulse-id order, no time limit, without
    ``t_emit_s``); ``group``: pulses sharing one detection (never paired together).
    """
    made = _pair_maker(returns, surface, max_dt_s, group)
    if made is None:
        return None
    idx, i, j, pairs_of = made
    s_i, s_j, lag, rise = (np.empty(i.size) for _ in range(4))

    # side by side on the stage's threads (each block writes its own rows)
    def block(lo: int) -> None:
        b = slice(lo, lo + _PAIR_BLOCK)
        p = pairs_of(b)
        s_i[b], s_j[b], lag[b], rise[b] = p.s_i_m, p.s_j_m, p.lag_m, p.rise_m

    thread_map(block, range(0, i.size, _PAIR_BLOCK))
    return SurfacePairs(idx[i], idx[j], s_i, s_j, lag, rise)


def reduced_surface_pairs(
    returns: DetectedReturns, surface, reduce, *, max_dt_s: float | None, group=None
) -> tuple[int, tuple] | None:
    """:func:`surface_pairs` block by block, each block reduced by ``reduce`` as it is made.

    ``reduce(pairs)`` takes a block's :class:`SurfacePairs` and returns a tuple of arrays of
    what the caller keeps per pair (e.g. the pairs it uses, and only the figures it needs);
    they are concatenated over the blocks in pair order. A survey's pairs and their
    temporaries are then never all held at once: only the reduced figures.

    Returns
    -------
    (n_pairs, reduced) or None
        The number of pairs made and the concatenated tuple; None without any pair.
    """
    made = _pair_maker(returns, surface, max_dt_s, group)
    if made is None:
        return None
    _, i, _, pairs_of = made
    return i.size, thread_map_rows(lambda b: reduce(pairs_of(b)), i.size, _PAIR_BLOCK)


def _pair_maker(returns, surface, max_dt_s, group):
    """:func:`surface_point_pairs` and the maker of a slice's pairs.

    Returns ``(idx, i, j, pairs_of)``, ``pairs_of(slice)`` the :class:`SurfacePairs` of pairs
    ``i[slice], j[slice]``; None without pairs.
    """
    idx, i, j = surface_point_pairs(returns, surface, max_dt_s=max_dt_s, group=group)
    if i.size == 0:
        return None
    # what depends on one point alone (its own plane's height there, the global plane's) is
    # computed once per point and gathered per pair: the same float64 operations on the same
    # inputs, for a fraction of the count (a point is in up to 128 pairs: 64 offsets each way)
    x, y, z = (np.ascontiguousarray(c) for c in surface.surface_point_m[idx].T)
    z_own = surface.surface_z_m(idx, x, y)
    s_own = z - z_own
    gz = surface.global_z_m(x, y)

    # the pairs in blocks: elementwise, so the same figures, and the temporaries (the anchors'
    # planes gathered per pair) stay small instead of hundreds of MB for a survey's pairs
    def pairs_of(b: slice) -> SurfacePairs:
        a, p = i[b], j[b]
        x_j, y_j = x[p], y[p]
        g_j = gz[p]
        plane_j = surface.surface_z_m(idx[a], x_j, y_j)
        # the anchor's level carried to the partner (WaterSurface.level_z_m, with the anchor
        # plane's height at the anchor already in hand)
        rise = plane_j - (z_own[a] + g_j - gz[a])
        lag = np.hypot(x[a] - x_j, y[a] - y_j)
        return SurfacePairs(idx[a], idx[p], s_own[a], z[p] - plane_j, lag, rise)

    return idx, i, j, pairs_of


def sea_correlation(
    returns: DetectedReturns,
    surface,
    *,
    max_dt_s: float | None,
    group=None,
    min_pairs: int = MIN_PAIRS,
) -> SeaCorrelation:
    """Measure ``rho(h)`` from the surface returns (module notes).

    Parameters
    ----------
    returns : DetectedReturns
        Every pulse, ``(n,)`` per field; ``t_emit_s`` orders them in time (without it the pulse
        id does, and no time limit applies).
    surface : WaterSurface
        The fitted surface of the same pulses.
    max_dt_s : float or None
        Pairs at most this far apart in time (the surface fit's time window); None: no limit.
    group : (n,) array_like, optional
        Pulses sharing one detection (a photon-counting window): never paired together.
    min_pairs : int, optional
        Pairs a lag bin needs.

    Returns
    -------
    SeaCorrelation
    """
    pairs = surface_pairs(returns, surface, max_dt_s=max_dt_s, group=group)
    empty = SeaCorrelation(np.zeros(0), np.zeros(0), 0)
    if pairs is None:
        return empty
    i, s_i, s_j, lag = pairs.row_i, pairs.s_i_m, pairs.s_j_m, pairs.lag_m
    edges = np.asarray(LAG_EDGES_M)
    b = np.digitize(lag, edges) - 1
    inside = (b >= 0) & (b < edges.size - 1)
    b, s_i, s_j, lag = b[inside], s_i[inside], s_j[inside], lag[inside]
    nb = edges.size - 1
    count = np.bincount(b, minlength=nb)
    tilt = _tilt_share(b, lag, s_j, pairs.rise_m[inside], count, nb, min_pairs)
    sxy = np.bincount(b, weights=s_i * s_j, minlength=nb)
    sxx = np.bincount(b, weights=s_i * s_i, minlength=nb)
    slag = np.bincount(b, weights=lag, minlength=nb)
    use = (count >= min_pairs) & (sxx > 0.0)
    empty = SeaCorrelation(np.zeros(0), np.zeros(0), int(i.size), *tilt)
    if not use.any():
        return empty
    beta = sxy[use] / sxx[use]
    # the regression's standard error at the shortest lag (pairs as independent): a sea the
    # echoes do not resolve (calm water, noise only) gives a beta within noise of 0
    first = b == np.flatnonzero(use)[0]
    resid = s_j[first] - beta[0] * s_i[first]
    se0 = np.sqrt(np.sum((s_i[first] * resid) ** 2)) / sxx[use][0]
    if not beta[0] > _MIN_T * se0:  # no correlation even at the shortest lag: no sea told
        return empty
    rho = np.minimum.accumulate(np.clip(beta / beta[0], 0.0, 1.0))
    return SeaCorrelation(slag[use] / count[use], rho, int(i.size), *tilt)


def _tilt_share(b, lag, s_j, rise, count, nb, min_pairs):
    """Per lag bin, ``gamma = sum(r u) / sum(r²)``: the share of the plane's rise that comes true.

    ``r`` the anchor plane's own rise to the partner, ``u = s_j + r`` the partner's height above
    the anchor's level (:meth:`~pipeline.process.surface_fit.WaterSurface.level_z_m`); clipped
    to ``[0, 1]``. Bins with fewer than ``min_pairs`` pairs (or no rise) are left out; none:
    ``(None, None)`` (the whole rise).
    """
    if rise is None:
        return None, None
    u = s_j + rise
    srr = np.bincount(b, weights=rise * rise, minlength=nb)
    sru = np.bincount(b, weights=rise * u, minlength=nb)
    slag = np.bincount(b, weights=lag, minlength=nb)
    use = (count >= min_pairs) & (srr > 0.0)
    if not use.any():
        return None, None
    return slag[use] / count[use], np.clip(sru[use] / srr[use], 0.0, 1.0)
