"""Timing precision of each detected return from its own waveform.

The detector times an echo at the peak of the waveform correlated with the system response
``h`` (a Gaussian of the system's sigma ``s_p``: :func:`pipeline.process.detect.
detect_full_waveform`). For an echo ``s(t - t0)`` in white noise of sigma ``s_n`` per sample,
the peak of that correlation has the variance (the correlator's time-delay variance, to first
order in the noise)

    var(t0) = s_n² ∫ h'² / (∫ s' h')²

which for an echo of the system's own width (``h`` then *is* the matched filter) is the
Cramér–Rao bound ``2 s_e / sqrt(pi) (s_n / A)²`` (Kay, *Fundamentals of Statistical Signal
Processing: Estimation Theory*, 1993, §3.11, range estimation). For a Gaussian echo of
amplitude ``A`` and its own sigma ``s_e >= s_p`` (a surface echo spread over waves, or in calm
water off nadir only the volume-backscatter onset, a bottom stretched by forward scattering
and a slope), with ``s_f² = s_e² + s_p²`` the width of the filtered echo and
``a_f = A s_e / s_f`` its filtered peak, both of which the detector measures
(:func:`pipeline.process.detect_timing.parabolic_peak`), the integrals give

    sigma_t = (s_n / a_f) s_f² / (2 pi^(1/4) s_p^(3/2))          (samples)

so a return wider than the system response is timed worse than the system's bound in two
ways: less signal per sample for its energy, and a filter that no longer matches it.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["echo_timing_sigma_samples"]


def echo_timing_sigma_samples(
    filtered_amplitude, filtered_width, system_sigma, noise_var, shot_noise_counts=0.0
) -> np.ndarray:
    """Timing sigma of echoes timed on the filtered waveform, in samples.

    Parameters
    ----------
    filtered_amplitude : (n,) array_like
        The echo's peak height on the filtered waveform (counts).
    filtered_width : (n,) array_like
        Its sigma on the filtered waveform (samples); 0 or non-finite where the peak fit
        failed, and never below the filtered system response ``sqrt(2) system_sigma`` (an
        echo is no narrower than the system response): that is taken then.
    system_sigma : float
        Sigma of the system response (the transmitted pulse through the receiver), samples:
        the detector's filter.
    noise_var : (n,) array_like
        Noise variance of one raw sample under the echo without its own signal (counts²):
        electronic, and the shot noise of what it stands on.
    shot_noise_counts : float, optional
        ``F G`` (excess-noise factor x counts per photoelectron): the echo's own shot noise,
        variance ``F G s(t)`` under it. For a Gaussian echo of peak ``A = a_f s_f / s_e``
        in that noise alone the Fisher information on its time is ``A sqrt(2 pi) /
        (F G s_e)``, that of white noise of variance ``F G A / (2 sqrt(2))``, which is what
        it adds here (the timing is set on the echo's flanks, not at its peak).

    Returns
    -------
    (n,) float64
        ``(s_n / a_f) s_f² / (2 pi^(1/4) s_p^(3/2))``; ``inf`` where the amplitude is not
        positive.

    Examples
    --------
    An echo of the system width ``s_p = 2`` samples and amplitude ``A = 100`` in noise of 1:
    filtered width ``2 sqrt(2)``, filtered peak ``A / sqrt(2)``; the Cramér–Rao bound is
    ``sqrt(2 * 2 / sqrt(pi)) / 100`` = 0.0150 samples.

    >>> s = echo_timing_sigma_samples([100 / 2**0.5], [2 * 2**0.5], 2.0, [1.0])
    >>> round(float(s[0]), 4)
    0.015
    """
    amp_f = np.asarray(filtered_amplitude, dtype=np.float64)
    w_f = np.asarray(filtered_width, dtype=np.float64)
    sp = float(system_sigma)
    floor = math.sqrt(2.0) * sp
    w_f = np.where(np.isfinite(w_f) & (w_f > floor), w_f, floor)
    ok = amp_f > 0.0
    s_e = np.sqrt(np.maximum(w_f**2 - sp**2, sp**2))
    peak = np.maximum(amp_f, 0.0) * w_f / s_e
    shot_var = float(shot_noise_counts) * peak / (2.0 * math.sqrt(2.0))
    s_n = np.sqrt(np.asarray(noise_var, dtype=np.float64) + shot_var)
    gain = w_f**2 / (2.0 * math.pi**0.25 * sp**1.5)
    return np.where(ok, s_n / np.where(ok, amp_f, 1.0) * gain, np.inf)
