"""The sea above each sounding at its pulse's time, kriged from the surface echoes around it.

A sounding's depth is read below the water surface above it, ``B``, at its pulse's time ``t``
(what the depth under a moving sea means). ``B`` lies ``Delta`` (a quarter of the depth at 20° off
nadir) from where the pulse met the sea, and no echo was taken there at that instant; but a
scanner's other shots see the sea around ``B`` within tenths of a second (a Palmer scan's next
rotations, 0.05 s apart). The height of the sea there is predicted by **simple kriging** (the
best linear unbiased predictor for a known mean; Cressie 1993, *Statistics for Spatial Data*,
§3.2) from the ``kriging_neighbours`` surface echoes nearest to ``(B, t)`` in ``(x, y, v t)``
(``v = radius_m / time_window_s``, the surface fit's own space-time scale), those within
``kriging_window_s`` of ``t``, about the global water plane (the known mean).

The covariance is **measured** from the survey's own echoes: per lag bin
(:data:`~pipeline.process.sea_correlation.LAG_EDGES_M`), the mean product of the heights above
the global plane of pairs at most ``kriging_window_s`` apart in time; an exponential
``C(h) = s² exp(-h / L)`` is fitted to it (log-linear, through the shortest bin, over the bins
still correlated above 0.05): positive definite in the plane, where the binned covariance,
interpolated, is not (indefinite kriging matrices give wild weights). The echoes' own variance
less ``s²`` is the nugget (ranging noise). A shortest-lag covariance within 3 standard errors
of 0 (a calm sea, noise only), or none falling with lag: no field. The predictor is
``z(B) = z_global(B) + k^T K^-1 a``: ``a`` the neighbours' heights, ``K`` their covariances
(``s²`` plus the nugget on the diagonal), ``k`` their covariances with ``B``; its variance
``s² - k^T K^-1 k``.

On the 5 m/s wave scene of issue 13 (seed 7, tuning) the sea above ``B`` read as the local
plane carried to ``B`` erred by 0.21 m (sd), more than the sea's own 0.145 m; kriged from the
echoes within 0.3 s, by 0.072 m (12 neighbours; 8 to 20 neighbours and 0.2 to 0.5 s change the
depth RMSE by < 0.007 m).

Photon counting (a window's shots share one detection, one measurement repeated) and surveys
without emission times are not kriged (None): the depth then reads the local plane
(:mod:`pipeline.process.refraction`).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
from scipy.spatial import cKDTree

from pipeline.parallel import thread_map
from pipeline.process.kriging_kernels import fill_gram, pair_lags, spd_solve
from pipeline.process.returns import DetectedReturns, PointFlag
from pipeline.process.sea_correlation import LAG_EDGES_M, MIN_PAIRS, time_pairs

__all__ = [
    "SeaCovariance",
    "SeaField",
    "sea_covariance",
    "sea_field",
    "survey_sea_covariance",
]

#: Soundings per batched solve (``(chunk, k, k)`` matrices).
_CHUNK = 20_000
#: The shortest lag's covariance must stand this many standard errors above 0.
_MIN_T = 3.0
#: The nugget is at least this share of the sea's covariance: the matrices stay well
#: conditioned where echoes nearly coincide (numerical, not a model choice).
_NUGGET_FLOOR = 1e-3


@dataclass(frozen=True)
class SeaField:
    """The survey's surface echoes and their measured covariance, ready to krige.

    Attributes
    ----------
    xy_m : (m, 2) float64
        Horizontal positions of the water pulses' own, non-outlier surface echoes.
    t_s : (m,) float64
        Their emission times.
    height_m : (m,) float64
        Their heights above the global water plane.
    lag_m, cov_m2 : (k,) float64
        Lag bins (mean separation) and the measured covariance of the heights there.
    sill_m2, decay_per_m : float
        The fitted covariance ``sill exp(-decay h)``.
    nugget_m2 : float
        The echoes' variance less the sill (ranging noise).
    neighbours : int
        Echoes per prediction.
    window_s : float
        Echoes at most this far in time from the sounding's pulse.
    speed_m_s : float
        Time scale of the neighbour search, ``(x, y, speed t)``.
    """

    xy_m: np.ndarray
    t_s: np.ndarray
    height_m: np.ndarray
    lag_m: np.ndarray
    cov_m2: np.ndarray
    sill_m2: float
    decay_per_m: float
    nugget_m2: float
    neighbours: int
    window_s: float
    speed_m_s: float

    @cached_property
    def _tree(self) -> cKDTree:
        """The echoes in ``(x, y, speed t)``, built once per field (every prediction's search)."""
        return cKDTree(np.column_stack([self.xy_m, self.speed_m_s * self.t_s]))

    def covariance_m2(self, lag_m: np.ndarray) -> np.ndarray:
        """The fitted covariance ``s² exp(-h / L)`` at lags ``h``."""
        return self.sill_m2 * np.exp(-self.decay_per_m * np.asarray(lag_m, dtype=np.float64))

    def predict(self, xy_m: np.ndarray, t_s: np.ndarray):
        """Kriged sea height above the global plane at ``(xy_m, t_s)``.

        Parameters
        ----------
        xy_m : (n, 2) float64
        t_s : (n,) float64

        Returns
        -------
        height_m, sigma_m : (n,) float64
            The predicted height above the global plane and its kriging standard deviation.
        used : (n,) int64
            Echoes within the time window that entered (0: none, height 0, sigma the sea's).
        """
        xy = np.asarray(xy_m, dtype=np.float64).reshape(-1, 2)
        t = np.asarray(t_s, dtype=np.float64).ravel()
        n = len(t)
        height, sigma, used = np.zeros(n), np.zeros(n), np.zeros(n, dtype=np.int64)
        tree = self._tree  # built here, once, not raced for by the blocks' threads

        def block(lo: int) -> None:
            s = slice(lo, lo + _CHUNK)
            height[s], sigma[s], used[s] = self._predict_rows(tree, xy[s], t[s])

        # blocks of rows, each kriged on its own (the same figures in any order): side by
        # side on the stage's threads (pipeline.parallel.thread_map)
        thread_map(block, range(0, n, _CHUNK))
        return height, sigma, used

    def _predict_rows(self, tree: cKDTree, xy: np.ndarray, t: np.ndarray):
        """:meth:`predict` of one block of rows ``(b, 2)``, ``(b,)``."""
        k = min(self.neighbours, len(self.t_s))
        c0 = self.sill_m2
        ex, ey = self.xy_m[:, 0], self.xy_m[:, 1]
        # each pair of neighbours once: the distance matrix is symmetric, exactly (a - b is
        # -(b - a) in floating point), and its diagonal is set below
        iu, ju = np.triu_indices(k, 1)
        q = np.column_stack([xy, self.speed_m_s * t])
        _, nn = tree.query(q, k=k, workers=-1)
        nn = np.asarray(nn).reshape(len(q), k)
        ok = np.abs(self.t_s[nn] - t[:, None]) <= self.window_s
        x, y = ex[nn], ey[nn]
        # the pairs' lags and the matrix's filling compiled (exact operations: the same
        # bits), the covariance's exp in numpy's own (a compiled exp may round otherwise)
        upper = self.covariance_m2(pair_lags(x, y, iu, ju))
        gram = fill_gram(upper, ok, iu, ju, c0 + self.nugget_m2)  # out-of-window: decoupled
        kv = self.covariance_m2(_distance(x - xy[:, 0, None], y - xy[:, 1, None])) * ok
        w = spd_solve(gram, kv)
        height = np.sum(w * self.height_m[nn] * ok, axis=1)
        sigma = np.sqrt(np.maximum(c0 - np.sum(w * kv, axis=1), 0.0))
        return height, sigma, ok.sum(axis=1)


def _distance(dx_m: np.ndarray, dy_m: np.ndarray) -> np.ndarray:
    """``sqrt(dx² + dy²)``: what ``np.linalg.norm(..., axis=-1)`` of ``(dx, dy)`` computes.

    Not ``np.hypot`` (it rounds differently), so the kriging weights stay as they were.
    """
    return np.sqrt(dx_m * dx_m + dy_m * dy_m)


@dataclass(frozen=True)
class SeaCovariance:
    """The survey's measured sea covariance (:class:`SeaField`'s fields of the same names)."""

    lag_m: np.ndarray
    cov_m2: np.ndarray
    sill_m2: float
    decay_per_m: float
    nugget_m2: float


def _echoes(returns: DetectedReturns, surface):
    """The water pulses' own, non-outlier surface echoes in time order.

    Returns their emission times ``(m,)``, points ``(m, 3)`` and heights above the global
    plane ``(m,)``.
    """
    ok = surface.is_water & returns.has_surface
    ok &= (surface.flags & np.uint16(PointFlag.SURFACE_OUTLIER)) == 0
    idx = np.flatnonzero(ok)
    t = np.asarray(returns.t_emit_s, dtype=np.float64)[idx]
    order = np.argsort(t, kind="stable")
    idx, t = idx[order], t[order]
    p = surface.surface_point_m[idx]
    return t, p, p[:, 2] - surface.global_z_m(p[:, 0], p[:, 1])


def sea_covariance(t: np.ndarray, p: np.ndarray, a: np.ndarray, window_s: float):
    """The exponential covariance of echoes' heights (module notes); None: no sea resolved.

    Parameters
    ----------
    t : (m,) float64
        The echoes' emission times, ascending.
    p : (m, 3) float64
        Their points.
    a : (m,) float64
        Their heights above the global plane.
    window_s : float
        Pairs at most this far apart in time.

    Returns
    -------
    SeaCovariance or None
    """
    i, j = time_pairs(t, None, float(window_s))
    x, y = (np.ascontiguousarray(c) for c in p[:, :2].T)
    edges = np.asarray(LAG_EDGES_M)
    # each pair's separation once (binned, then summed per bin)
    sep = np.hypot(x[i] - x[j], y[i] - y[j])
    b = np.digitize(sep, edges) - 1
    inside = (b >= 0) & (b < edges.size - 1)
    b, i, j, sep = b[inside], i[inside], j[inside], sep[inside]
    nb = edges.size - 1
    count = np.bincount(b, minlength=nb)
    prod = np.bincount(b, weights=a[i] * a[j], minlength=nb)
    lag = np.bincount(b, weights=sep, minlength=nb)
    use = count >= MIN_PAIRS
    if not use.any():
        return None
    cov = prod[use] / count[use]
    # the shortest lag's covariance must stand _MIN_T standard errors above 0 (pairs as
    # independent): a sea the echoes do not resolve (calm water, noise) is not kriged
    first = b == np.flatnonzero(use)[0]
    se0 = np.std(a[i[first]] * a[j[first]]) / np.sqrt(max(int(first.sum()), 1))
    if not cov[0] > _MIN_T * se0:
        return None
    # an exponential covariance s² exp(-h / L) fitted to the bins (log-linear through the
    # shortest bin, where the correlation is above 0.05): positive definite in the plane, where
    # the binned one, interpolated, is not (indefinite kriging matrices give wild weights)
    h = lag[use] / count[use]
    rho = cov / cov[0]
    fit = (rho > 0.05) & (rho < 1.0)
    dh = h[fit] - h[0]
    decay = float(np.sum(dh * -np.log(rho[fit])) / np.sum(dh * dh)) if fit.any() else 0.0
    if not decay > 0.0:  # no fall with lag seen: the sea is not resolved at these lags
        return None
    sill = float(cov[0]) * float(np.exp(decay * h[0]))
    nugget = max(float(np.mean(a * a)) - sill, _NUGGET_FLOOR * sill)
    return SeaCovariance(h, cov, sill, decay, nugget)


def survey_sea_covariance(returns: DetectedReturns, surface, window_s: float):
    """:func:`sea_covariance` of a survey's echoes (None without emission times or echoes)."""
    if returns.t_emit_s is None:
        return None
    t, p, a = _echoes(returns, surface)
    return None if t.size < 2 else sea_covariance(t, p, a, window_s)


def sea_field(
    returns: DetectedReturns,
    surface,
    *,
    neighbours: int,
    window_s: float,
    speed_m_s: float,
    covariance: SeaCovariance | None = None,
) -> SeaField | None:
    """Measure the covariance of the surface echoes and keep them for kriging (module notes).

    Parameters
    ----------
    returns : DetectedReturns
        Every pulse; ``t_emit_s`` needed (None: no field).
    surface : WaterSurface
        The fitted surface of the same pulses (its global plane is the known mean).
    neighbours : int
        Echoes per prediction (0: no field).
    window_s : float
        Time window of the pairs and of the neighbours.
    speed_m_s : float
        Time scale of the neighbour search.
    covariance : SeaCovariance, optional
        The covariance to use instead of measuring it from these echoes (the whole survey's,
        when ``returns`` are a tile of it).

    Returns
    -------
    SeaField or None
        None without emission times, neighbours, enough pairs, or a positive covariance at
        the shortest lag (no sea seen: the plane is read).
    """
    if returns.t_emit_s is None or neighbours < 1:
        return None
    t, p, a = _echoes(returns, surface)
    if t.size < (1 if covariance is not None else 2):
        return None
    cov = covariance or sea_covariance(t, p, a, window_s)
    if cov is None:
        return None
    return SeaField(
        xy_m=p[:, :2].copy(),
        t_s=t,
        height_m=a,
        lag_m=cov.lag_m,
        cov_m2=cov.cov_m2,
        sill_m2=cov.sill_m2,
        decay_per_m=cov.decay_per_m,
        nugget_m2=cov.nugget_m2,
        neighbours=int(neighbours),
        window_s=float(window_s),
        speed_m_s=float(speed_m_s),
    )
