"""The two receivers' views of the photon model: digitised waveforms and dead-time-thinned events.

Full waveform
-------------
Sample ``i`` of a pulse integrates ``[t0 + (i - 1/2) dt, t0 + (i + 1/2) dt)``. Weak components
arrive as drawn photoelectrons, binned; strong ones as their expected bin integrals
(:func:`expected_samples`). Each photoelectron's charge has mean ``G`` and variance
``(F - 1) G^2`` (excess-noise factor ``F``), so a Poisson count of mean ``N`` has variance
``F G^2 N``. Per sample, with ``n`` drawn photoelectrons and strong expectation ``mu``:
``v = baseline + G (n + mu) + sqrt(G^2 ((F - 1) n + F mu) + sigma_e^2) z``, ``z`` standard normal:
the summed single-photoelectron gains and the strong returns' photon noise are taken Gaussian
given ``n`` (exact mean and variance; the shape of a single photoelectron's pulse-height
distribution is not modelled), then rounded and clipped to ``[0, 2^bits - 1]``.

Photon counting
---------------
A channel is blind for ``tau`` after each *recorded* event (non-paralyzable dead time: photons
arriving while it is dead are lost and do not extend it), which is how actively quenched SPADs
and PMT/MCP counters with a fixed electronic hold-off behave. Exact vectorised thinning: sort the
events by (shot, channel, time); an event less than ``tau`` after the previous *arrival* can only
be recorded by a chain that starts at the last event of its run whose gap is >= ``tau`` (always
recorded); each run's chain is followed with ``next[i] = first j with t_j >= t_i + tau`` (one
``searchsorted``), all runs at once, one step per recorded event of the longest chain.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from pipeline.simulate.photon import KIND_COLUMN, KIND_GAUSS, KIND_UNIFORM, Components
from pipeline.simulate.shapes import add_column_bins, gauss_cdf

__all__ = ["expected_samples", "digitise", "digitise_drawn", "dead_time_filter"]

_GAUSS_HALF_WIDTH = 8.5  # sigmas: the mass outside is 2e-17


def _add_gauss(out, comps, sel, t0, dt, m):
    """Add the Gaussian components marked in ``sel`` (n, c) to ``out`` (n, m) in place."""
    p, ci = np.nonzero(sel)
    if p.size == 0:
        return
    mu = (comps.centre_s[p, ci] - t0[p]) / dt  # centre in samples
    sg = comps.sigma_s[p, ci] / dt
    h = int(math.ceil(_GAUSS_HALF_WIDTH * float(sg.max()))) + 1
    if 2 * h + 1 >= m:
        taps = np.broadcast_to(np.arange(m), (p.size, m))
    else:
        taps = np.floor(mu + 0.5).astype(np.int64)[:, None] + np.arange(-h, h + 1)
    # one CDF per bin edge, differenced: the bins of a component telescope to its total
    edges = np.concatenate([taps, taps[:, -1:] + 1], axis=1) - 0.5 - mu[:, None]
    val = comps.expected[p, ci][:, None] * np.diff(gauss_cdf(edges, sg[:, None]), axis=1)
    ok = (taps >= 0) & (taps < m)
    idx = (p[:, None] * m + taps)[ok]
    out += np.bincount(idx, weights=val[ok], minlength=out.size).reshape(out.shape)


def _width_groups(sigma_s, sel):
    """Components grouped by width (powers of two), so each group's tap window fits its members.

    Returns a list of boolean (n, c) masks; a bottom echo stretched to 10 ns does not make every
    1 ns surface echo pay for 170 taps.
    """
    if not sel.any():
        return []
    octave = np.floor(np.log2(np.where(sel, sigma_s, 1.0))).astype(np.int64)
    return [sel & (octave == o) for o in np.unique(octave[sel])]


def _add_column(out, comps, t0, dt, m):
    """Add the column-shaped components (water column, delayed bottom tails) to ``out``."""
    is_col = (comps.kind == KIND_COLUMN) & (comps.expected > 0.0)
    for col in np.flatnonzero(is_col.any(axis=0)):
        p = np.flatnonzero(is_col[:, col])
        x0 = t0[p] - 0.5 * dt - comps.centre_s[p, col]
        add_column_bins(
            out, p, comps.expected[p, col], x0, dt, comps.rate_per_s[p, col],
            comps.width_s[p, col], comps.sigma_s[p, col],
        )  # fmt: skip


def expected_samples(comps: Components, t0_s: np.ndarray, dt: float, m: int) -> np.ndarray:
    """Expected photoelectrons per sample of the components, ``(n_pulses, m)`` float64.

    Parameters
    ----------
    comps : Components
        ``(n_pulses, n_comp)``; uniform components are spread over the whole window.
    t0_s : (n_pulses,) float64
        Centre time of sample 0.
    dt : float
        Sample interval, seconds.
    m : int
        Samples per window.
    """
    n = t0_s.shape[0]
    out = np.zeros((n, m))
    gauss = (comps.expected > 0.0) & (comps.kind == KIND_GAUSS)
    for group in _width_groups(comps.sigma_s, gauss):
        _add_gauss(out, comps, group, t0_s, dt, m)
    _add_column(out, comps, t0_s, dt, m)
    uni = np.where(comps.kind == KIND_UNIFORM, comps.expected, 0.0).sum(axis=1)
    out += (uni / m)[:, None]
    return out


def digitise(detector, mean_pe, excess_pe=None, normals=None):
    """Digitiser counts from photoelectrons per sample, with gain, noise and clipping.

    Parameters
    ----------
    detector : DetectorSettings
    mean_pe : (n, m) float64
        Photoelectrons per sample (drawn counts plus strong expectations).
    excess_pe : (n, m) float64, optional
        ``(F - 1) n + F mu`` per sample, the photoelectron variance that is not in ``mean_pe``'s
        own draw; None for noise-free output.
    normals : (n, m) float32, optional
        Standard normals, one per sample; None for noise-free (unrounded) output.

    Returns
    -------
    samples : (n, m) float32
        Counts in ``[0, 2^bits - 1]``.
    saturated : (n,) bool
        Some sample reached the top code.
    """
    g = detector.counts_per_photoelectron
    v = detector.baseline_counts + g * mean_pe
    if normals is not None:
        var = g * g * excess_pe + detector.electronic_noise_counts**2
        v += np.sqrt(var) * normals
        v = np.floor(v + 0.5)
    top = float(detector.top_code)
    saturated = np.any(v >= top, axis=1)
    return np.clip(v, 0.0, top).astype(np.float32), saturated


def digitise_drawn(detector, drawn, mu, normals):
    """:func:`digitise` of drawn photoelectron counts plus strong expectations, in one pass.

    The same figures as ``digitise(detector, n + mu, (F - 1) n + F mu, normals)`` with
    ``n = drawn.reshape(mu.shape)``, every product and sum in that order, without its five
    ``(n, m)`` float64 temporaries (:func:`_digitise_rows`).

    Parameters
    ----------
    detector : DetectorSettings
    drawn : (n * m,) int64
        Drawn photoelectrons per sample, row by row (a ``bincount``).
    mu : (n, m) float64 or None
        Expected photoelectrons of the strong components (None: none).
    normals : (n, m) float32
        Standard normals, one per sample.

    Returns
    -------
    samples : (n, m) float32
    saturated : (n,) bool
    """
    n, m = normals.shape
    f = float(detector.excess_noise_factor)
    g = float(detector.counts_per_photoelectron)
    en2 = float(detector.electronic_noise_counts) ** 2
    strong = mu is not None
    mu_arr = mu if strong else np.zeros((1, 1))
    out = np.empty((n, m), dtype=np.float32)
    sat = np.zeros(n, dtype=bool)
    _digitise_rows(
        drawn, mu_arr, strong, normals, f, g, float(detector.baseline_counts), en2,
        float(detector.top_code), out, sat,
    )  # fmt: skip
    return out, sat


@numba.njit(cache=True, nogil=True)
def _digitise_rows(drawn, mu, strong, normals, f, g, base, en2, top, out, sat):
    """:func:`digitise_drawn`'s loop: each sample once, in :func:`digitise`'s order."""
    n, m = out.shape
    for p in range(n):
        hit = False
        for c in range(m):
            k = float(drawn[p * m + c])
            u = mu[p, c] if strong else 0.0
            mean = k + u
            excess = (f - 1.0) * k + f * u
            v = base + g * mean
            var = g * g * excess + en2
            v = v + math.sqrt(var) * np.float64(normals[p, c])
            v = np.floor(v + 0.5)
            hit |= v >= top
            out[p, c] = np.float32(0.0 if v < 0.0 else (top if v > top else v))
        sat[p] = hit


def dead_time_filter(group: np.ndarray, times_s: np.ndarray, dead_time_s: float):
    """Events kept by a non-paralyzable dead time, per group (shot and channel).

    Parameters
    ----------
    group : (k,) int64
        Group of each event (e.g. ``shot * n_channels + channel``).
    times_s : (k,) float64
        Arrival times.
    dead_time_s : float
        Dead time >= 0.

    Returns
    -------
    order : (k,) int64
        Indices sorting the events by group, then time.
    kept : (k,) bool
        In that order: the event was recorded.
    """
    key = group.astype(np.float64) + 1j * times_s  # exact lexicographic (group, time) order
    order = np.argsort(key, kind="stable")
    k = key[order]
    kept = np.ones(k.size, dtype=bool)
    if k.size < 2 or dead_time_s <= 0.0:
        return order, kept
    g, t = k.real, k.imag
    same = g[1:] == g[:-1]
    close = same & (t[1:] - t[:-1] < dead_time_s)
    # run starts (first of a group, or >= tau after the previous arrival) are always recorded
    start = np.r_[True, ~close]
    kept[1:] = ~close
    starts = np.flatnonzero(start)
    ends = np.r_[starts[1:], k.size]  # run i is [starts[i], ends[i])
    multi = ends - starts > 1
    cur = starts[multi]
    end = ends[multi]
    while cur.size:
        nxt = np.searchsorted(k, k[cur] + 1j * dead_time_s, side="left")
        ok = nxt < end
        cur, end = nxt[ok], end[ok]
        kept[cur] = True
    return order, kept
