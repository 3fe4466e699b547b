"""Detect the water surface and the bottom in photon-counting data (measured data only).

A single shot holds a handful of photons, mostly background; returns emerge only when shots are
accumulated along track. Each event is placed on its measured beam at the range of its time of
flight (``r = c t / (2 n_air)``, no refraction yet), and its height is histogrammed over a window
of ``shots_per_window`` consecutive shots:

1. **Background** per window: the mean count of the bins below the 90th percentile (returns
   fill few bins, so they are left out).
2. **Surface**: the highest-count bin; **bottom**: the highest-count bin at least
   ``min_separation_m`` below the surface. Each is accepted when its count is significant over
   the background: counts are Poisson, the p-value is ``P(X >= k | b)``, and it must beat the
   one-sided normal tail of ``threshold_sigma`` divided by the number of bins searched (a
   Bonferroni look-elsewhere correction). The significance is reported back in normal σ.
3. **Sub-bin height**: the background-subtracted centroid of the events within ±``centroid_bins``
   of the peak bin.
4. Back to **per-shot times**: each shot of the window gets the time at which its own measured
   beam reaches the detected heights (``t = 2 n_air r / c``), so refraction correction then runs
   exactly as for full waveforms.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import special, stats

from pipeline import optics
from pipeline.config import setting
from pipeline.process.detect import WaveformDetections, flank_trend
from pipeline.process.returns import DetectorFlag

__all__ = ["PhotonDetectSettings", "detect_photon_events"]


@dataclass(frozen=True, kw_only=True)
class PhotonDetectSettings:
    """Along-track accumulation and thresholds of the photon-counting detector."""

    shots_per_window: int = setting(200, ge=1, le=10_000_000, doc="shots accumulated per window")
    bin_m: float = setting(0.1, gt=0.0, le=10.0, doc="height histogram bin")
    threshold_sigma: float = setting(5.0, gt=0.0, le=100.0, doc="bottom significance, Poisson σ")
    min_separation_m: float = setting(0.3, ge=0.0, le=100.0, doc="bottom below the surface by")
    centroid_bins: int = setting(2, ge=0, le=50, doc="bins each side used for the centroid")
    trend_bins: int = setting(20, ge=2, le=1000, doc="flank length of the column trend, bins")


def _significance(k: np.ndarray, b: np.ndarray, n_bins: int) -> np.ndarray:
    """Normal-σ equivalent of ``k`` Poisson counts over background ``b`` among ``n_bins`` bins."""
    log_p = stats.poisson.logsf(k - 1, b) + math.log(n_bins)
    # ndtri_exp works on log p, so p-values far below float range keep a finite σ
    return np.where(log_p < 0, -special.ndtri_exp(np.minimum(log_p, -1e-300)), 0.0)


def detect_photon_events(
    offsets: np.ndarray,
    times_s: np.ndarray,
    origin_m: np.ndarray,
    direction: np.ndarray,
    n_air: float,
    settings: PhotonDetectSettings | None = None,
    pulse_id: np.ndarray | None = None,
) -> WaveformDetections:
    """Surface and bottom per shot from photon events accumulated along track.

    Parameters
    ----------
    offsets : (n_shots + 1,) int
        Events of shot ``i`` are ``times_s[offsets[i]:offsets[i + 1]]``.
    times_s : (n_events,) float64
        Event times after emission, seconds.
    origin_m, direction : (n_shots, 3) float64
        Measured laser position and unit beam direction of each shot.
    n_air : float
        Phase index of air (ranges from times of flight).
    settings : PhotonDetectSettings, optional
    pulse_id : (n_shots,) int, optional
        Global shot numbers; windows are then ``pulse_id // shots_per_window``, so a survey
        split into chunks (of whole windows) gives the same windows as one piece.

    Returns
    -------
    WaveformDetections
        Round-trip times per shot (absolute, after emission); amplitudes are window counts.
    """
    s = settings or PhotonDetectSettings()
    n = origin_m.shape[0]
    c = optics.SPEED_OF_LIGHT_M_S
    counts = np.diff(offsets)
    shot = np.repeat(np.arange(n), counts)
    r = c * times_s / (2.0 * n_air)
    z = origin_m[shot, 2] + r * direction[shot, 2]
    ids = np.arange(n) if pulse_id is None else np.asarray(pulse_id)
    _, window = np.unique(ids // s.shots_per_window, return_inverse=True)
    n_win = int(window.max()) + 1 if n else 0
    ev_win = window[shot]
    empty = WaveformDetections(
        *(
            np.zeros(n, dtype=b)
            for b in (bool, float, float, float, bool, float, float, float, float, np.uint16)
        )
    )
    if z.size == 0:
        return empty
    z0 = math.floor(z.min() / s.bin_m) * s.bin_m
    nb = int((z.max() - z0) / s.bin_m) + 1
    b = np.minimum(((z - z0) / s.bin_m).astype(np.int64), nb - 1)
    hist = np.bincount(ev_win * nb + b, minlength=n_win * nb).reshape(n_win, nb).astype(float)
    q90 = np.quantile(hist, 0.9, axis=1)
    low = hist <= q90[:, None]
    bg = np.sum(np.where(low, hist, 0.0), axis=1) / np.maximum(low.sum(axis=1), 1)
    bg_safe = np.maximum(bg, 1e-3)  # an empty background still has a finite p-value scale
    rows = np.arange(n_win)
    i_s = np.argmax(hist, axis=1)
    sep_bins = int(math.ceil(s.min_separation_m / s.bin_m))
    # the bottom box (±centroid_bins) must not reach into the surface return
    below = np.arange(nb)[None, :] <= (i_s - sep_bins - s.centroid_bins)[:, None]
    # the water-column return decays smoothly below the surface: a bottom must stand out of
    # its local level (the larger mean of the flanking bins), not only of the background
    local = np.maximum(
        flank_trend(hist, gap=s.centroid_bins + 1, length=s.trend_bins), bg_safe[:, None]
    )
    # counts of a return spread over neighbouring bins: test the sum over the centroid window
    w = 2 * s.centroid_bins + 1
    csum = np.concatenate([np.zeros((n_win, 1)), np.cumsum(hist, axis=1)], axis=1)
    lo = np.clip(np.arange(nb) - s.centroid_bins, 0, nb)
    hi = np.clip(np.arange(nb) + s.centroid_bins + 1, 0, nb)
    box = csum[:, hi] - csum[:, lo]
    sig_all = _significance(box, local * w, nb)
    i_b = np.argmax(np.where(below, sig_all, -np.inf), axis=1)
    sig_s = _significance(hist[rows, i_s], bg_safe, nb)
    sig_b = np.where(below[rows, i_b], sig_all[rows, i_b], 0.0)
    has_s = sig_s >= s.threshold_sigma
    has_b = has_s & (sig_b >= s.threshold_sigma)

    def centroid(i_peak):
        lo = (i_peak - s.centroid_bins)[ev_win]
        hi = (i_peak + s.centroid_bins)[ev_win]
        near = (b >= lo) & (b <= hi)
        # subtract the background's share, spread uniformly over the centroid bins
        w = np.bincount(ev_win[near], minlength=n_win).astype(float)
        zsum = np.bincount(ev_win[near], weights=z[near], minlength=n_win)
        nbins = 2 * s.centroid_bins + 1
        centre = z0 + (i_peak + 0.5) * s.bin_m
        excess = np.maximum(w - bg * nbins, 1e-9)
        zc = (zsum - bg * nbins * centre) / excess
        return np.where(w > bg * nbins, zc, centre), w - bg * nbins

    z_s, amp_s = centroid(i_s)
    z_b, amp_b = centroid(i_b)
    # per shot: time at which its own measured beam reaches the window's detected heights
    dz = direction[:, 2]
    with np.errstate(divide="ignore"):
        scale = np.where(dz < 0, 2.0 * n_air / (c * -dz), 0.0)
    t_s = (origin_m[:, 2] - z_s[window]) * scale
    t_b = (origin_m[:, 2] - z_b[window]) * scale
    hs = has_s[window] & (t_s > 0)
    hb = has_b[window] & hs & (t_b > t_s)
    conf_s = 1.0 - np.exp(-0.5 * (np.maximum(sig_s, 0) / s.threshold_sigma) ** 4)
    conf_b = 1.0 - np.exp(-0.5 * (np.maximum(sig_b, 0) / s.threshold_sigma) ** 4)
    flags = np.zeros(n, dtype=np.uint16)
    flags[hs & (sig_s[window] < 2 * s.threshold_sigma)] |= np.uint16(DetectorFlag.LOW_SNR)
    zero = np.zeros(n)
    return WaveformDetections(
        has_surface=hs,
        t_surface_s=np.where(hs, t_s, zero),
        surface_amplitude=np.where(hs, amp_s[window], zero),
        surface_confidence=np.where(hs, conf_s[window], zero),
        has_bottom=hb,
        t_bottom_s=np.where(hb, t_b, zero),
        bottom_amplitude=np.where(hb, amp_b[window], zero),
        bottom_confidence=np.where(hb, conf_b[window], zero),
        noise_sigma=np.sqrt(bg_safe)[window],
        flags=flags,
    )
