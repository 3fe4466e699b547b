"""Photon-counting detection limit per window: the depth past which a bottom cannot be told.

The photon counterpart of :mod:`pipeline.process.detection_limit` (same model, same named
assumptions :class:`~pipeline.process.detection_limit.NoBottomSettings`), on a window's
live-time corrected height histogram instead of a waveform (measured photons only):

* the **water column** below the surface, ``C(k)`` corrected counts per bin at bin ``k``, is
  measured: a weighted least-squares line through ``ln E`` of the excess ``E`` of the
  ``2 m + 1``-bin boxes over the background (weights ``E² / counts``, the inverse variance of
  ``ln E``; boxes of at least ``min_column_snr`` σ, entirely below the surface's box), so
  ``C(k) = exp(a + b k) / (2 m + 1)``;
* a Lambertian **bottom** of reflectance ``ρ`` at the same depth returns ``B(k) = r C(k)``
  photons in all, ``r = ρ / (π β_π Δl)``, ``Δl = bin n_air / n_g`` the in-water path of one bin
  (the column's counts per bin are ``K β_π Δl T²``, the bottom's ``K (ρ/π) T²``: the lidar
  equation's single-scattering terms, Guenther 1985, NOAA Prof. Paper 1, ch. 3);
* the detector declares a bottom where a box's counts reach ``k*``, the smallest count whose
  Poisson p-value over the box's expected level ``μ = (C + background) (2 m + 1)`` beats the
  detector's threshold with its look-elsewhere (Bonferroni) correction (the false-alarm
  criterion of :func:`~pipeline.process.detect_photons.detect_photon_events`);
* a bottom is detectable there with probability ``p`` (``detection_probability``) while its
  box's expected count ``λ = μ + B`` stands ``z_p √λ`` above ``k*`` (the normal approximation
  of the Poisson count, as the full-waveform limit stands ``z_p`` noise σ above its
  threshold): ``λ ≥ λ* = ((z_p + √(z_p² + 4 k*)) / 2)²``; at ``p = 1/2``, ``λ* = k*``.

The limit is the deepest bin down to which every bin below the surface's box is detectable
(capped at the window's lowest event). A window whose column gives no such fit (fewer than 3
boxes, or no decay) gets none.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import special

from pipeline.optics import SPEED_OF_LIGHT_M_S

__all__ = ["photon_detection_limit", "photon_limit_summary"]


def _poisson_threshold(q: np.ndarray, mu: np.ndarray) -> np.ndarray:
    """Smallest integer ``k`` with ``P(X >= k | mu) <= q``, elementwise.

    Bisection on ``P(X > j) = pdtrc(j, mu)`` (a ufunc: ``scipy.stats.poisson.isf`` is far
    slower on a window-by-bin array).
    """
    lo = np.zeros(mu.shape)  # P(X > lo - 1) = 1 > q: k > lo - 1
    hi = np.ceil(mu + 40.0 * np.sqrt(mu) + 60.0)  # far in the tail: P(X >= hi) <= q
    for _ in range(int(np.ceil(np.log2(max(float(hi.max()), 2.0)))) + 1):
        mid = np.floor(0.5 * (lo + hi))
        ok = special.pdtrc(mid - 1.0, mu) <= q  # P(X >= mid) <= q
        hi = np.where(ok, mid, hi)
        lo = np.where(ok, lo, mid + 1.0)
    return hi


def photon_detection_limit(
    hist: np.ndarray,
    box: np.ndarray,
    bg: np.ndarray,
    below: np.ndarray,
    n_searched: np.ndarray,
    column: np.ndarray,
    *,
    half_box: int,
    bin_m: float,
    n_air: float,
    group_index: float,
    bottom_reflectance: float,
    backscatter_180_per_m_sr: float,
    threshold_sigma: float,
    min_column_snr: float,
    detection_probability: float | np.ndarray = 0.5,
) -> np.ndarray:
    """Deepest histogram bin at which each window could still detect a bottom.

    Parameters
    ----------
    hist : (n_windows, n_bins) float
        Live-time corrected counts per height bin (bin index grows upward).
    box : (n_windows, n_bins) float
        ``hist`` summed over the ``2 half_box + 1`` bins centred on each bin.
    bg : (n_windows,) float
        Background counts per bin.
    below : (n_windows, n_bins) bool
        Measured bins of the range gate whose box lies wholly below the surface's box.
    n_searched : (n_windows, 1) float
        Bins searched (the detector's look-elsewhere count).
    column : (n_windows, n_bins) bool
        The bins of ``below`` the column fit may use (a bottom's box left out).
    half_box : int
        The detector's ``centroid_bins``.
    bin_m, n_air, group_index : float
        Bin height (air range), phase index of air, group index of water.
    bottom_reflectance, backscatter_180_per_m_sr : float
        The assumed ``ρ`` and ``β_π`` (:class:`~pipeline.process.detection_limit.NoBottomSettings`).
    threshold_sigma, min_column_snr : float
        The detector's significance and the column boxes' minimum SNR.
    detection_probability : float or (n_windows,) array
        The probability with which the assumed bottom is detected at the limit (per window).

    Returns
    -------
    (n_windows,) int
        The limit's bin, -1 where the window's column gives no limit.
    """
    n_win, nb = hist.shape
    width = 2 * half_box + 1
    col = np.arange(nb, dtype=np.float64)[None, :]
    excess = box - bg[:, None] * width
    snr = excess / np.sqrt(np.maximum(box, 1.0))
    use = below & column & (snr >= min_column_snr)
    w = np.where(use, excess**2 / np.maximum(box, 1.0), 0.0)
    ln_e = np.log(np.where(use, excess, 1.0))
    # weighted least squares of ln E on the bin index, per window
    sw = w.sum(axis=1)
    mx = (w * col).sum(axis=1) / np.maximum(sw, 1e-300)
    my = (w * ln_e).sum(axis=1) / np.maximum(sw, 1e-300)
    dx = col - mx[:, None]
    sxx = (w * dx**2).sum(axis=1)
    slope = (w * dx * (ln_e - my[:, None])).sum(axis=1) / np.maximum(sxx, 1e-300)
    # light decays downward: ln E must grow with the bin index (upward)
    fit = (use.sum(axis=1) >= 3) & (sxx > 0) & (slope > 0)
    # the fitted column, below the surface only (above it the line is extrapolated upward)
    c_bin = (
        np.where(
            below & fit[:, None], np.exp(np.minimum(my[:, None] + slope[:, None] * dx, 50.0)), 0.0
        )
        / width
    )
    ratio = bottom_reflectance / (math.pi * backscatter_180_per_m_sr * bin_m * n_air / group_index)
    mu = (c_bin + bg[:, None]) * width
    # k*: smallest count with P(X >= k | mu) <= p / n_searched, p the one-sided normal tail
    q = np.broadcast_to(special.ndtr(-threshold_sigma) / n_searched, mu.shape)
    k_star = _poisson_threshold(q, mu)
    z = special.ndtri(np.broadcast_to(np.asarray(detection_probability, float), (n_win,)))
    z = z[:, None]
    lam_star = np.where(z == 0.0, k_star, (0.5 * (z + np.sqrt(z * z + 4.0 * k_star))) ** 2)
    undetectable = below & (ratio * c_bin < lam_star - mu)
    # the shallowest undetectable bin below the surface; the limit is the bin above it, or the
    # lowest searched bin when none is
    first_bad = np.where(undetectable, col, -1.0).max(axis=1)
    lowest = np.where(below, col, np.inf).min(axis=1)
    limit = np.where(first_bad >= 0, first_bad + 1.0, lowest)
    ok = fit & np.isfinite(limit) & below.any(axis=1)
    return np.where(ok, limit, -1).astype(np.int64)


def photon_limit_summary(
    t_limit_s: np.ndarray,
    t_surface_s: np.ndarray,
    flags: np.ndarray,
    has_bottom: np.ndarray,
    group_index: float,
    beyond_bit: int,
) -> dict[str, float | int | None]:
    """The survey's photon detection limits, flat (the evaluation's ``no_bottom``).

    Parameters
    ----------
    t_limit_s, t_surface_s : (n_shots,) float
        Each shot's detection-limit and surface times (0 where none).
    flags : (n_shots,) uint16
        Detector flags.
    has_bottom : (n_shots,) bool
    group_index : float
        Processing's group index of water.
    beyond_bit : int
        The BEYOND_DETECTION_LIMIT flag.

    Returns
    -------
    dict
        Shots with a limit, the 5th / 50th / 95th percentiles of its in-water path below the
        surface along the beam (m; ``c (t_lim - t_s) / (2 n_g)``), and the bottoms flagged past it.
    """
    ok = t_limit_s > 0
    path = (t_limit_s - t_surface_s)[ok] * SPEED_OF_LIGHT_M_S / (2.0 * group_index)
    pct = np.percentile(path, [5, 50, 95]) if path.size else [None] * 3
    beyond = has_bottom & ((flags & np.uint16(beyond_bit)) != 0)
    return {
        "photon_shots_with_detection_limit": int(ok.sum()),
        "photon_detection_limit_path_m_p05": None if pct[0] is None else float(pct[0]),
        "photon_detection_limit_path_m_median": None if pct[1] is None else float(pct[1]),
        "photon_detection_limit_path_m_p95": None if pct[2] is None else float(pct[2]),
        "photon_bottoms_beyond_detection_limit": int(beyond.sum()),
    }
