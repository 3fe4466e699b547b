"""Window histograms of photon heights: their background, range gate and box significance.

The photon-counting detector (:mod:`pipeline.process.detect_photons`) tests boxes of
``2 centroid_bins + 1`` height bins of each window's live-time corrected histogram against the
window's background, within its range gate; these are those measures, and the reach of an
echo's significant boxes past its reflector (where a class-45 claim from the column's extent
must stop short of the run's end).
"""

from __future__ import annotations

import math

import numpy as np
from scipy import special, stats

from pipeline import optics

__all__ = ["ECHO_TAIL_SIGMAS", "background", "echo_reach_bins", "gate_span", "significance"]

#: response sigmas past its peak from which an echo of the system's (Gaussian) response no
#: longer fills a box: its share beyond 3 sigma (0.13 %) of even a thousand-photon echo is
#: about one photon
ECHO_TAIL_SIGMAS = 3.0


def echo_reach_bins(
    lead: np.ndarray, cb: int, pulse_sigma_s: float, n_air: float, bin_m: float
) -> np.ndarray:
    """``(n_windows,)`` bins an echo's significant boxes reach past its reflector's peak.

    The larger of the box's half-width plus ``ECHO_TAIL_SIGMAS`` response sigmas (a lone
    echo of the system's response) and ``lead``, how far the window's own surface echo reaches
    above its peak (``top - i_s``: the same response, box and footprint spread; a trailing
    edge reaches as far as a leading one). The surface peak's search keeps ``lead`` within
    ``[-cb, 2 cb]``, so the reach lies in ``[cb + 3 sigma, max(2 cb, cb + 3 sigma)]``: with
    the photon-counting preset (0.7 ns FWHM, 0.1 m bins, ``cb`` 2) it is 4 bins in every
    window, and ``lead`` matters only for a response sharper than about 0.55 ns FWHM.
    Not included: the seabed's own relief across a window's shots (one claim per window).
    """
    sigma_bins = pulse_sigma_s * optics.SPEED_OF_LIGHT_M_S / (2.0 * n_air) / bin_m
    own = cb + int(math.ceil(ECHO_TAIL_SIGMAS * sigma_bins))
    return np.maximum(lead, own)


def significance(k: np.ndarray, b: np.ndarray, n_bins) -> np.ndarray:
    """Normal-σ equivalent of ``k`` Poisson counts over background ``b`` among ``n_bins`` bins.

    ``n_bins``: int, or per window ``(n_windows, 1)`` (the bins of each window's range gate).
    """
    # log P(X >= k) underflows to -inf for strong returns (all would tie at infinite σ):
    # log P(X = k), its dominant term, keeps it finite and ordered
    log_p = np.maximum(stats.poisson.logsf(k - 1, b), stats.poisson.logpmf(k, b))
    log_p = log_p + np.log(n_bins)
    # ndtri_exp works on log p, so p-values far below float range keep a finite σ
    return np.where(log_p < 0, -special.ndtri_exp(np.minimum(log_p, -1e-300)), 0.0)


def gate_span(hist: np.ndarray) -> np.ndarray:
    """(n_windows, n_bins) bool: the bins between each window's lowest and highest event."""
    nb = hist.shape[1]
    nz = hist > 0
    first = np.argmax(nz, axis=1)
    last = nb - 1 - np.argmax(nz[:, ::-1], axis=1)
    col = np.arange(nb)[None, :]
    return (col >= first[:, None]) & (col <= last[:, None])


def background(hist: np.ndarray) -> np.ndarray:
    """Background counts per bin of each window's histogram, robust to its few return bins.

    Parameters
    ----------
    hist : (n_windows, n_bins) float
        Event counts per window and height bin.

    Returns
    -------
    (n_windows,) float
        The larger of two estimates over the bins between the window's lowest and highest
        event (the range gate; bins outside it hold no events at all): the mean of the bins
        at or below the 90th percentile (returns fill few bins, so they are left out), and the
        Poisson rate of the share of empty bins, ``-ln P(0)``. The first alone is far too low
        when the background is sparse (then the 90th percentile is 0 and every lone photon
        would pass as a return); the second, unaffected by the few bins returns fill, is
        reliable exactly then, and saturates (no empty bins) only when the first is reliable.
    """
    nz = hist > 0
    span = gate_span(hist)
    n_span = np.maximum(span.sum(axis=1), 1)
    # the 90th percentile ("lower") of the span's bins alone: np.quantile over the NaN-padded
    # rows gave NaN (then 0) for every window narrower than the chunk's histogram, so the
    # estimate depended on the other windows of the chunk
    ordered = np.sort(np.where(span, hist, np.inf), axis=1)
    q90 = ordered[np.arange(hist.shape[0]), np.floor(0.9 * (n_span - 1)).astype(np.int64)]
    q90 = np.where(np.isfinite(q90), q90, 0.0)  # windows without events
    low = span & (hist <= q90[:, None])
    trimmed = np.sum(np.where(low, hist, 0.0), axis=1) / np.maximum(low.sum(axis=1), 1)
    empty = np.sum(span & ~nz, axis=1)
    rate = -np.log(np.maximum(empty, 0.5) / n_span)
    return np.maximum(trimmed, np.where(empty > 0, rate, 0.0))
