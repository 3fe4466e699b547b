"""The live exposure of a photon window's histogram samples, weighted by where the light falls.

A non-paralyzable channel records the photons of a rate ``lambda(t)`` only while live: over a
window's shot-channels the expected count of sample ``j`` is ``int_j L(t) lambda(t) dt``, with
``L(t)`` the share of shot-channels live at ``t`` (known from the recorded events: each blinds
its channel for the dead time; Snyder & Miller 1991, *Random Point Processes in Time and
Space*, ch. 7). The posterior's likelihood takes it as ``L_j mu_j``, ``mu_j = int_j lambda``
(:class:`~pipeline.uncertainty.posterior_target.PulseBatch`'s ``exposure``), which is exact
only where ``L`` or ``lambda`` is constant across the sample. Neither is at a piled-up echo: a
bright surface (tens of photoelectrons per shot under a 1.6 ns dead time, samples of 0.67 ns)
fires every channel in the echo's first sample, so ``L`` falls from 1 to ~0 inside the very
sample where ``lambda`` rises. The plain mean of ``L`` over the sample
(:func:`~pipeline.process.photon_livetime.bin_live_fraction`) then credits the sample with
exposure after the events, where the echo's light fell on blind channels, and the fitted echo
moves early to make up for it: 0.16 ns (2.3 cm of range) on the surfaces of suite shoal tuning
seeds 7008 and 7009 (calm water, nadir profilers), their depth posteriors 0.6-0.9 cm shallow
with 0.5 cm sigmas.

Here ``L_j`` is the mean of ``L`` weighted by a reference rate ``lambda_ref`` over the sample,
``int_j L lambda_ref / int_j lambda_ref``, which makes ``L_j mu_j`` exact wherever ``lambda``
has the reference's shape within the sample. The reference is the window's own echoes as the
detector found them: Gaussians of the system response at the detected surface and bottom times,
of the areas the live-corrected counts give, over the background and the water column's level
between them. A reference wrong by 0.1 ns leaves ~0.01 ns (a test with first-photon events
drawn in it); the plain mean misses by ~0.09 ns at 20 photoelectrons per shot.
"""

from __future__ import annotations

import numpy as np
from scipy.special import ndtr

__all__ = ["ReferenceRate", "reference_rate", "weighted_live_fraction", "MIN_WEIGHTED_LIVE"]

#: Floor of a weighted live share. The likelihood multiplies by it and never divides (unlike
#: the rates of :mod:`pipeline.process.photon_livetime`, floored at 0.02): the samples just
#: after a piled-up echo's first one are live for a few thousandths of their light (0.0001-0.004
#: at 20 photoelectrons per shot), and held at 0.02 they moved the fitted echo by up to 0.2 ns.
#: The floor only keeps the logarithm finite.
MIN_WEIGHTED_LIVE = 1e-9


class ReferenceRate:
    """A window's reference rate along a shot's beam, as its cumulative count.

    Parameters
    ----------
    t_surface_s, t_bottom_s : float
        The detected echo times (round trip, seconds).
    area_surface, area_bottom : float
        Live-corrected counts of each echo (per window, >= 0).
    background_per_s : float
        Rate before the surface and after the bottom (> 0).
    column_per_s : float
        Rate added between the surface and the bottom (>= 0).
    sigma_s : float
        The system response's sigma.
    """

    def __init__(
        self, t_surface_s, t_bottom_s, area_surface, area_bottom, background_per_s,
        column_per_s, sigma_s,
    ):  # fmt: skip
        self.t_s, self.t_b = float(t_surface_s), float(max(t_bottom_s, t_surface_s))
        self.a_s, self.a_b = float(area_surface), float(area_bottom)
        self.bg, self.col, self.sigma = float(background_per_s), float(column_per_s), sigma_s

    @classmethod
    def uniform(cls) -> ReferenceRate:
        """A flat rate: the weighted live share is then the plain mean over each sample."""
        return cls(0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 1.0)

    def cumulative(self, t_s: np.ndarray) -> np.ndarray:
        """Expected count from the reference's origin to each time (increasing in ``t``)."""
        t = np.asarray(t_s, dtype=np.float64)
        echoes = self.a_s * ndtr((t - self.t_s) / self.sigma) + self.a_b * ndtr(
            (t - self.t_b) / self.sigma
        )
        return echoes + self.bg * t + self.col * (np.clip(t, self.t_s, self.t_b) - self.t_s)


def reference_rate(y, exposure, t0_s, t_surface_s, t_bottom_s, dt_s, sigma_s) -> ReferenceRate:
    """The reference of one window from its recorded counts and plain live shares.

    Areas are the live-corrected counts within 2 samples of each detected echo less the
    background there, the background the corrected rate of the leading tenth of the samples
    (where :func:`~pipeline.uncertainty.photon_posterior.window_histograms` keeps background
    only), the column the corrected rate between the echoes less the background.

    Parameters
    ----------
    y, exposure : (m,) ndarray
        Recorded counts and plain live shares of the window's samples.
    t0_s : float
        Time of sample 0's centre.
    t_surface_s, t_bottom_s : float
        The detector's echo times.
    dt_s, sigma_s : float
        Sample interval and system response sigma.
    """
    rate = np.asarray(y, dtype=np.float64) / np.asarray(exposure, dtype=np.float64)
    m = rate.size
    bg = max(float(rate[: max(m // 10, 1)].mean()), 1e-3)  # per sample
    i_s = int(np.clip(round((t_surface_s - t0_s) / dt_s), 0, m - 1))
    i_b = int(np.clip(round((t_bottom_s - t0_s) / dt_s), i_s, m - 1))

    def area(i):
        return max(float(rate[max(i - 2, 0) : i + 3].sum()) - 5.0 * bg, 0.0)

    between = rate[i_s + 3 : i_b - 2]
    col = max(float(between.mean()) - bg, 0.0) if between.size else 0.0
    a_b = area(i_b) if i_b - i_s >= 3 else 0.0  # merged with the surface: one echo
    return ReferenceRate(t_surface_s, t_bottom_s, area(i_s), a_b, bg / dt_s, col / dt_s, sigma_s)


def weighted_live_fraction(
    t_event_s: np.ndarray,
    dead_s: np.ndarray,
    t0_s: float,
    dt_s: float,
    n_samples: int,
    n_live: int,
    ref: ReferenceRate,
) -> np.ndarray:
    """Each sample's live share weighted by the reference rate, ``(n_samples,)``.

    Parameters
    ----------
    t_event_s : (n,) ndarray
        The window's events as times along the shot's beam.
    dead_s : (n,) ndarray
        Each event's blind span after it, in the same time.
    t0_s, dt_s : float
        Sample ``j`` spans ``t0 + (j -+ 1/2) dt``.
    n_samples : int
    n_live : int
        Shot-channels of the window (shots times channels).
    ref : ReferenceRate

    Returns
    -------
    (n_samples,) ndarray
        ``1 - D_j / n_live``, ``D_j`` the events' blind intervals' share of the sample's
        reference count, floored at :data:`MIN_WEIGHTED_LIVE`. A uniform reference gives the
        plain share (unfloored).
    """
    t = np.asarray(t_event_s, dtype=np.float64)
    dead = np.asarray(dead_s, dtype=np.float64)
    edges = t0_s + (np.arange(n_samples + 1) - 0.5) * dt_s
    cum = ref.cumulative(edges)
    per_sample = np.maximum(np.diff(cum), 1e-300)
    d = np.zeros(n_samples)
    if t.size:
        lo, hi = (t - edges[0]) / dt_s, (t + dead - edges[0]) / dt_s  # in samples
        k_lo = np.floor(lo).astype(np.int64)
        for j in range(int(np.ceil(float(np.max(hi - lo)))) + 2):
            k = k_lo + j
            ok = (k >= 0) & (k < n_samples)
            a = np.maximum(t, edges[np.clip(k, 0, n_samples)])
            b = np.minimum(t + dead, edges[np.clip(k + 1, 0, n_samples)])
            ok &= b > a
            if not ok.any():
                continue
            share = (ref.cumulative(b[ok]) - ref.cumulative(a[ok])) / per_sample[k[ok]]
            d += np.bincount(k[ok], weights=np.clip(share, 0.0, 1.0), minlength=n_samples)
    return np.maximum(1.0 - d / max(int(n_live), 1), MIN_WEIGHTED_LIVE)
