"""TPU terms of the water surface measured from the surface returns themselves.

A sounding's depth is its in-water range from where its pulse met the sea, read below the sea
above the sounding ``B`` (:func:`~pipeline.process.refraction.seabed_points`).
Two errors of the surface enter it that the per-echo timing sigmas and the fitted plane do not
show, and both are measured here from the **height variogram of the measured surface points**
(Matheron's semivariogram, estimated robustly after Cressie & Hawkins 1980), ``2 gamma(h) =
E[(s(p) - s(p + h))²]`` over pairs of surface points ``h`` apart horizontally and nearly
simultaneous (within ``max_dt_s``: the sea moves), both heights ``s`` taken above the earlier
pulse's own fitted plane (what a sounding's depth reads: its entry and the sea over it, against
its own plane):

**surface ranging** (random) - the nugget, ``gamma(h -> 0) = s_r²``: two surface points at the
same place differ by their ranging errors alone, whatever made them (noise, the calm-water
volume-backscatter onset under a vanished specular echo, a wave-spread echo). The detector's
Cramér-Rao sigma of each surface echo (:mod:`pipeline.process.detect_precision`) is a bound
that a poorly resolved onset does not reach; the measured ``s_r`` (vertical) raises the
pulse's surface timing sigma to ``2 n_a s_r / (c cos i)`` (``i`` its incidence on the local
plane; raise only), so the TPU carries it through the georeferencing like any timing error.
The nugget depends on the incidence (a specular echo near nadir, an onset off it): it is
estimated per band of incidence (:data:`INCIDENCE_BANDS_DEG`), as the intercept ``n`` of
``gamma(h) = n + a h²`` (a smooth sea rises as ``h²``) fitted to its three shortest lags with
at least ``min_pairs`` pairs each.

**wave height between entry and sounding** (random, depth only) - the in-water range starts
where the beam met the actual sea at ``E``, the depth is read against the sea above ``B``,
``Delta = |B - E|`` away (about a quarter of the depth at 20° off nadir), predicted from the
sea met at ``E`` as ``rho(Delta) w s_E`` above the plane
(:mod:`pipeline.process.sea_correlation`); the predictor's error variance is
``gamma_w(Delta) (1 + rho)``, ``gamma_w`` the wave part of the variogram (``gamma`` less the
nugget of its pooled fit, rising as ``h²`` below the shortest lag; ``2 gamma_w(Delta)``, the
variance of the difference of the heights, when the depth reads the sea at ``E`` itself)
(:func:`wave_entry_sigma_m`; Westfeld et al. 2017, "Analysis and correction
of ocean wave pattern induced systematic coordinate errors in airborne LiDAR bathymetry", ISPRS
J. Photogramm. Remote Sens. 128; the water-surface terms of the TPU of Eren et al. 2019,
"Total vertical uncertainty (TVU)
modeling for topo-bathymetric LIDAR systems", Photogramm. Eng. Remote Sens. 85). Zero on calm
water, where the variogram is flat. The fitted plane's tilt terms already hold the waves the
plane follows (the tilt is measured between entry and sounding,
:func:`~pipeline.uncertainty.tpu_neighbours.surface_tilt_sigma`): only the excess over them is
added (:func:`with_wave_entry`).

Only pairs of like incidence (within 2.5°) enter: their ranging errors are then alike at every
lag, and only the sea makes the variogram rise (an oscillating scanner would otherwise pair a
specular nadir echo with an oblique onset, a rise that is no wave).

Measured data only: surface points, their emission times, the fitted planes.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from pipeline.optics import SPEED_OF_LIGHT_M_S
from pipeline.process.returns import DetectedReturns
from pipeline.process.sea_correlation import reduced_surface_pairs
from pipeline.process.surface_fit import WaterSurface
from pipeline.uncertainty.tpu_settings import DEPTH, PointTpu
from pipeline.uncertainty.tpu_window import with_random_term

__all__ = [
    "INCIDENCE_BANDS_DEG",
    "LAG_EDGES_M",
    "WAVE_TERM",
    "SurfaceVariogram",
    "surface_variogram",
    "with_surface_ranging",
    "wave_entry_sigma_m",
    "with_wave_entry",
]

#: Name of the wave term in ``PointTpu.terms``.
WAVE_TERM = "wave_entry"
#: Lag bins of the variogram (m): fine at short lags, where the nugget and the wave rise are.
LAG_EDGES_M = (0.0, 0.25, 0.5, 1.0, 1.5, 2.0, 3.0, 4.0, 6.0, 8.0, 12.0, 16.0, 24.0, 32.0, 48.0)
#: Incidence bands of the nugget (deg): near-nadir specular echoes apart from oblique ones.
INCIDENCE_BANDS_DEG = (0.0, 5.0, 10.0, 15.0, 20.0, 25.0, 30.0, 90.0)
#: Cressie & Hawkins (1980) bias factor of the fourth power of the mean root: 0.457 + 0.494 / N.
_CH_A, _CH_B = 0.457, 0.494
#: Pairs whose incidences differ by more than this (deg) are not used.
_LIKE_INCIDENCE_DEG = 2.5
#: Lag bins of each incidence band the nugget is extrapolated from.
_NUGGET_BINS = 3
#: A lag bin with fewer pairs than this share of each neighbour's is not read by the wave term
#: (:meth:`SurfaceVariogram.wave_lags`; set on the suite's tuning half).
_SPARSE_SHARE = 0.1


@dataclass(frozen=True)
class SurfaceVariogram:
    """The measured surface-height semivariogram of a survey.

    Attributes
    ----------
    lag_m : (k,) float64
        Mean pair separation of each lag bin with enough pairs (ascending).
    gamma_m2 : (k,) float64
        Semivariogram ``gamma`` there (m²), all incidences pooled.
    nugget_m2 : (b,) float64
        Per incidence band (:data:`INCIDENCE_BANDS_DEG`): the nugget, the surface ranging
        variance ``s_r²``; NaN where the band has no lag with enough pairs.
    pairs : int
        Pairs used.
    rise_per_m2 : float
        ``a`` of ``gamma(h) = n + a h²`` over the shortest pooled lags (``>= 0``): half the
        mean-square slope of the heights above the pulses' own planes along the pairs'
        directions, i.e. of the slope the planes do not follow (0: no rise measured).
    raw_rise_per_m2 : float
        The same of the heights above the survey's global plane instead: half the mean-square
        slope of the whole sea along the pairs (what a plane that follows nothing misses).
    lag_pairs : (k,) int64 or None
        Pairs in each lag bin (None: not known, e.g. a variogram built by hand).
    """

    lag_m: np.ndarray
    gamma_m2: np.ndarray
    nugget_m2: np.ndarray
    pairs: int
    rise_per_m2: float = 0.0
    raw_rise_per_m2: float = 0.0
    lag_pairs: np.ndarray | None = None

    @classmethod
    def empty(cls) -> SurfaceVariogram:
        """No pairs: no lag bins, no nugget (the terms then add nothing)."""
        nb = len(INCIDENCE_BANDS_DEG) - 1
        return cls(np.zeros(0), np.zeros(0), np.full(nb, np.nan), 0)

    @property
    def pooled_nugget_m2(self) -> float:
        """``gamma(0)`` of the shortest pooled lags (:func:`_sea_nugget`: with their bend).

        The variogram's ranging part, what :func:`wave_entry_sigma_m` takes off; NaN without
        lag bins. A function of ``lag_m`` and ``gamma_m2`` alone, so a variogram handed to a
        tile (:mod:`pipeline.uncertainty.tpu_survey_wide`) or built by hand has it too.
        """
        lag, gamma = self.wave_lags()
        if lag.size == 0:
            return float("nan")
        return _sea_nugget(lag[:_NUGGET_BINS], gamma[:_NUGGET_BINS])

    def wave_lags(self) -> tuple[np.ndarray, np.ndarray]:
        """``(lag_m, gamma_m2)`` the wave term reads: without isolated sparse bins.

        A scan's pair separations come in classes (the n-th neighbour along a sweep, the next
        sweep), so a lag bin between two classes can hold a few pairs of another kind only.
        On suite shoal tuning seed 7004 (Palmer, 210 m, waves) the 1.0-1.5 m bin held 218
        pairs, all from successive sweeps at the circle's sides, against 28 000 and 27 000 in
        its neighbours. Their surface errors are alike, so its ``gamma`` (0.010² m²) lay below
        the ranging noise of the pairs around it (0.027² m²). The fit through the three
        shortest bins (:func:`_sea_nugget`) then fell (``a < 0``), and the wave term was 0
        where the sea read over the soundings erred by 0.05 m. A bin holding fewer than
        :data:`_SPARSE_SHARE` of the pairs of each of its neighbours is left out here (an end
        bin is compared with its one neighbour). Sparse bins that rise in a run of their own
        stay (an oscillating scanner's shortest lags: 220, 409 and 966 pairs). Without
        ``lag_pairs`` every bin is read.
        """
        if self.lag_pairs is None or self.lag_m.size < 3:
            return self.lag_m, self.gamma_m2
        n = np.asarray(self.lag_pairs, dtype=np.float64)
        left, right = np.r_[np.inf, n[:-1]], np.r_[n[1:], np.inf]
        keep = ~((n < _SPARSE_SHARE * left) & (n < _SPARSE_SHARE * right))
        return self.lag_m[keep], self.gamma_m2[keep]


def _robust_semivariance(d: np.ndarray) -> float:
    """Cressie-Hawkins semivariance of differences ``d``: ``(mean |d|^½)⁴ / (2 (a + b / N))``."""
    n = d.size
    return float(np.mean(np.sqrt(np.abs(d))) ** 4 / (2.0 * (_CH_A + _CH_B / n)))


def _nugget_and_rise(h: np.ndarray, g: np.ndarray) -> tuple[float, float]:
    """``(n, a)`` of ``gamma(h) = n + a h²`` fitted to the shortest lags (``a >= 0``).

    A smooth wave field rises as ``h²`` from the origin (half its slope variance along the
    lag); the intercept ``n`` is the part no lag removes, the ranging error. ``n`` at most
    ``g[0]``, at least 0; one lag, or a falling variogram (no wave rise to remove): the mean,
    and ``a = 0``.
    """
    if h.size >= 2:
        a_mat = np.column_stack([np.ones_like(h), h**2])
        (n, a), *_ = np.linalg.lstsq(a_mat, g, rcond=None)
        if a >= 0.0:
            return float(np.clip(n, 0.0, g[0])), float(a)
    return float(np.mean(g)) if g.size else float("nan"), 0.0


def _sea_nugget(h: np.ndarray, g: np.ndarray) -> float:
    """``gamma(0)`` of ``n + a h² + b h⁴`` through the three shortest lags (``a > 0``).

    What the sea's part of the variogram is measured from (:func:`wave_entry_sigma_m`). A
    scan's shortest lags can reach where the sea's rise bends (successive Palmer soundings
    1.7 m apart, 10-40 m waves: the ``h²`` line through lags 1.7-5.1 m puts ``n`` at 8 times
    the ranging variance, and the sea's part at half its own); the ``h⁴`` term follows the
    bend. Two lags: the line :func:`_nugget_and_rise`. A fit that does not rise from the
    origin (``a <= 0``: no sea measured at the shortest lags, e.g. a calm sea's variogram flat
    there and rising only farther out, where a line through all three put ``n`` under
    ``g[0]`` and read that as waves; suite tuning seed 20, 1.5 m/s), or one lag: ``g[0]``.
    Clipped to ``[0, g[0]]``.
    """
    if h.size >= 3:
        n, a, _ = np.linalg.solve(np.column_stack([np.ones(3), h[:3] ** 2, h[:3] ** 4]), g[:3])
    elif h.size == 2:
        n, a = _nugget_and_rise(h, g)
    else:
        return float(g[0]) if g.size else float("nan")
    if not (a > 0.0 and np.isfinite(n)):
        return float(g[0])
    return float(np.clip(n, 0.0, g[0]))


def _nugget(h: np.ndarray, g: np.ndarray) -> float:
    """``gamma(0)`` of :func:`_nugget_and_rise`."""
    return _nugget_and_rise(h, g)[0]


class _Bins:
    """The rows of each bin ``0 .. n - 1`` of ``bin_index``, ascending (others: in none)."""

    def __init__(self, bin_index: np.ndarray, n: int):
        self._order = np.argsort(bin_index, kind="stable")
        self._start = np.searchsorted(bin_index[self._order], np.arange(n + 1), side="left")

    def rows(self, b: int) -> np.ndarray:
        """Rows in bin ``b``, in ascending order."""
        return self._order[self._start[b] : self._start[b + 1]]


def surface_variogram(
    returns: DetectedReturns,
    surface: WaterSurface,
    *,
    max_dt_s: float = 0.2,
    min_pairs: int = 200,
    group=None,
) -> SurfaceVariogram:
    """The semivariogram of the measured surface heights (see the module notes).

    Parameters
    ----------
    returns : DetectedReturns
        Every pulse, ``(n,)`` per field; ``t_emit_s`` orders them in time (without it: the
        pulse id, and ``max_dt_s`` is not applied).
    surface : WaterSurface
        The fitted surface of the same pulses: which pulses enter water, their surface points
        and incidence, the global plane the heights are taken above.
    max_dt_s : float, optional
        Pairs at most this far apart in time (the sea moves between them).
    min_pairs : int, optional
        Pairs a lag bin (and a band's nugget) needs.
    group : (n,) array_like, optional
        Pulses sharing one detection (a photon-counting window): never paired with each other.

    Returns
    -------
    SurfaceVariogram
    """
    # each pulse's incidence once, gathered per pair (each point is in ~50 pairs)
    inc, _ = _incidence_deg(returns, surface, np.arange(len(returns)))

    def kept(pairs):
        # per block of pairs, only what the bins need of those kept: a survey's pairs and
        # their temporaries are never all held at once
        d = pairs.s_i_m - pairs.s_j_m
        # the local plane's own rise put back: heights above the global plane
        d_raw = d if pairs.rise_m is None else d - pairs.rise_m
        inc_i, inc_j = inc[pairs.row_i], inc[pairs.row_j]
        # pairs of like incidence only: the ranging error then is the same at every lag and
        # only the sea makes the variogram rise (an oscillating scanner pairs nadir and edge
        # otherwise)
        like = np.abs(inc_i - inc_j) <= _LIKE_INCIDENCE_DEG
        return d[like], d_raw[like], pairs.lag_m[like], 0.5 * (inc_i + inc_j)[like]

    made = reduced_surface_pairs(returns, surface, kept, max_dt_s=max_dt_s, group=group)
    if made is None:
        return SurfaceVariogram.empty()
    n_pairs, (d, d_raw, lag, inc_pair) = made
    edges = np.asarray(LAG_EDGES_M)
    n_lag = edges.size - 1
    lag_bin = np.digitize(lag, edges) - 1
    # the pairs of each lag bin, in their own order (a stable sort: each bin's mean sums the
    # same values in the same order as a mask would select them)
    by_lag = _Bins(lag_bin, n_lag)
    lags, gammas, gammas_raw, counts = [], [], [], []
    for b in range(n_lag):
        m = by_lag.rows(b)
        if m.size >= min_pairs:
            counts.append(m.size)
            lags.append(float(np.mean(lag[m])))
            gammas.append(_robust_semivariance(d[m]))
            gammas_raw.append(_robust_semivariance(d_raw[m]))
    # the rise at the shortest lags: the slope the planes do not follow (tpu_facet), and the
    # whole sea's (what a plane blind along some axis misses there)
    h0 = np.array(lags[:_NUGGET_BINS])
    rise = _nugget_and_rise(h0, np.array(gammas[:_NUGGET_BINS]))[1]
    raw_rise = _nugget_and_rise(h0, np.array(gammas_raw[:_NUGGET_BINS]))[1]
    bands = np.asarray(INCIDENCE_BANDS_DEG)
    inc_bin = np.digitize(inc_pair, bands) - 1
    n_band = bands.size - 1
    # one bin per (band, lag bin); pairs outside either get none
    inside = (inc_bin >= 0) & (inc_bin < n_band) & (lag_bin >= 0) & (lag_bin < n_lag)
    by_band_lag = _Bins(np.where(inside, inc_bin * n_lag + lag_bin, -1), n_band * n_lag)
    nugget = np.full(n_band, np.nan)
    for b in range(n_band):
        hs, gs = [], []
        for lb in range(n_lag):  # the shortest lags with enough pairs
            m = by_band_lag.rows(b * n_lag + lb)
            if m.size >= min_pairs:
                hs.append(float(np.mean(lag[m])))
                gs.append(_robust_semivariance(d[m]))
            if len(hs) == _NUGGET_BINS:
                break
        if hs:
            nugget[b] = _nugget(np.array(hs), np.array(gs))
    return SurfaceVariogram(
        np.array(lags), np.array(gammas), nugget, int(n_pairs), rise, raw_rise,
        np.array(counts, dtype=np.int64),
    )  # fmt: skip


def _incidence_deg(returns, surface, rows):
    cos_i = np.abs(np.sum(returns.direction_meas[rows] * surface.normal[rows], axis=1))
    return np.degrees(np.arccos(np.clip(cos_i, 0.0, 1.0))), cos_i


def with_surface_ranging(
    returns: DetectedReturns, surface: WaterSurface, vg: SurfaceVariogram
) -> DetectedReturns:
    """``returns`` whose surface timing sigmas are at least the measured surface ranging's.

    Each water pulse with a surface return gets ``max(own, 2 n_a s_r / (c cos i))``, ``s_r²``
    the nugget of its incidence band (module notes); the detector's own sigma stays where it
    is larger (raise only: a pulse whose echo is poor keeps its own). Bands without a nugget,
    and pulses without a surface return, keep theirs.
    """
    n = len(returns)
    own = returns.t_surface_sigma_s
    own = np.zeros(n) if own is None else np.asarray(own, dtype=np.float64)
    rows = np.flatnonzero(surface.is_water & returns.has_surface)
    if rows.size == 0 or not np.any(np.isfinite(vg.nugget_m2)):
        return returns
    inc, cos_i = _incidence_deg(returns, surface, rows)
    band = np.clip(np.digitize(inc, INCIDENCE_BANDS_DEG) - 1, 0, len(INCIDENCE_BANDS_DEG) - 2)
    s_r = np.sqrt(np.nan_to_num(vg.nugget_m2[band], nan=0.0))
    sig = 2.0 * surface.air_index * s_r / (SPEED_OF_LIGHT_M_S * np.maximum(cos_i, 1e-6))
    out = own.copy()
    out[rows] = np.maximum(own[rows], sig)
    return dataclasses.replace(returns, t_surface_sigma_s=out)


def wave_entry_sigma_m(vg: SurfaceVariogram, delta_m, rho=None) -> np.ndarray:
    """One-sigma depth error of the wave height between entry and sounding, ``(n,)`` m.

    The sea above the sounding is read as the plane plus ``rho w s_E``
    (:mod:`pipeline.process.sea_correlation`): with a wave variance ``sigma²`` about the
    plane and ``rho = 1 - gamma_w(Delta) / sigma²``, the predictor's error variance is
    ``sigma² (1 - rho²) = gamma_w(Delta) (1 + rho)`` (simple kriging from one observation).
    ``rho = None`` reads the sea above the sounding as the sea at the entry (``rho = 1`` in
    the depth): ``2 gamma_w(Delta)``. ``Delta``: the sounding's offset from its entry.

    ``gamma_w`` is the sea's part of the variogram, ``gamma`` less its ranging part (the
    pooled nugget ``n``, :func:`_sea_nugget`). From the shortest lag ``h_0`` down it is not
    measured: a smooth sea rises as ``h²`` from the origin, so it is
    ``gamma_w(h_0) (Delta / h_0)²`` there. A scan's shortest lag is often longer than
    ``Delta`` (successive Palmer soundings 1-2 m apart, a shallow sounding's ``Delta`` a few
    decimetres): read as 0 below ``h_0``, the term vanished over shallow water under waves,
    where the sea's change from entry to sounding (suite tuning seed 6: 0.03 m sd at 1-2 m)
    then had no sigma.

    Parameters
    ----------
    vg : SurfaceVariogram
    delta_m : (n,) array_like
        Horizontal offset of each sounding from its water entry.
    rho : (n,) array_like, optional
        The correlation the depth used at each ``Delta``.
    """
    delta = np.asarray(delta_m, dtype=np.float64)
    lag, gamma = vg.wave_lags()
    if lag.size == 0:
        return np.zeros(delta.shape)
    h0, g0, n = lag[0], gamma[0], vg.pooled_nugget_m2
    wave = np.where(
        delta >= h0, np.interp(delta, lag, gamma) - n, max(g0 - n, 0.0) * (delta / h0) ** 2
    )
    factor = 2.0 if rho is None else 1.0 + np.clip(np.asarray(rho, dtype=np.float64), 0.0, 1.0)
    return np.sqrt(factor * np.maximum(np.nan_to_num(wave), 0.0))


#: The fitted plane's tilt terms: they hold the waves the plane follows between entry and sounding.
_TILT_TERMS = ("surface_tilt_x", "surface_tilt_y")


def with_wave_entry(tpu: PointTpu, vg: SurfaceVariogram, entry_xy_m, sea=None) -> PointTpu:
    """``tpu`` with the wave term (:data:`WAVE_TERM`, random, depth only).

    Its variance is that of :func:`wave_entry_sigma_m` at each sounding's offset ``Delta``
    from its water entry, less what the fitted plane's tilt terms already give the depth
    (:func:`~pipeline.uncertainty.tpu_neighbours.surface_tilt_sigma` measures how the plane
    turns between entry and sounding, i.e. the waves longer than its neighbourhood): only the
    excess is added, never a double count. The elevation is not touched (the wave height at
    the entry is the ``wave_height`` term's).

    Parameters
    ----------
    tpu : PointTpu
    vg : SurfaceVariogram
    entry_xy_m : (n, 2) array_like
        Horizontal water entry of each row's pulse.
    sea : SeaCorrelation, optional
        The correlation the depths used (``WaterSurface.sea_correlation``); None: ``rho = 1``.
    """
    entry = np.asarray(entry_xy_m, dtype=np.float64).reshape(-1, 2)
    if entry.shape[0] != len(tpu):
        raise ValueError(f"`entry_xy_m` must be ({len(tpu)}, 2); got {entry.shape}")
    delta = np.hypot(*(tpu.xyz_m[:, :2] - entry).T)
    tilt_var = np.zeros(len(tpu))
    for k in _TILT_TERMS:
        if k in tpu.terms:
            tilt_var += tpu.terms[k][:, DEPTH] ** 2
    rho = None if sea is None else sea.at(delta)
    wave = np.sqrt(np.maximum(wave_entry_sigma_m(vg, delta, rho) ** 2 - tilt_var, 0.0))
    return with_random_term(tpu, WAVE_TERM, np.zeros(len(tpu)), wave)
