"""Calm water off nadir: no specular echo, the surface is the water column's onset alone.

The waveform is written here: the volume backscatter of a homogeneous column starts at the
surface time ``t_s`` and decays as ``exp(−k (t − t_s))`` (Beer-Lambert down and up); through a
Gaussian system response of σ it is the exponentially modified Gaussian
``exp(−k u + (kσ)²/2) Φ(u/σ − kσ)``, ``u = t − t_s`` (the convolution done by hand). Its peak
lies 1-2 samples after ``t_s`` (issue 13: the calm-water surface ~0.2 m low); the detector
must time ``t_s`` itself.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.special import ndtr

from pipeline.process.detect import detect_full_waveform

DT = 1e-9
FWHM = 1.8e-9
SIG = FWHM / (2.0 * math.sqrt(2.0 * math.log(2.0))) / DT  # system σ, samples
T_S = 60.3  # surface time, samples


def _onset(t, t_s, k):
    """Step × exp(−k u) convolved with the unit-peak Gaussian of σ = SIG (analytic)."""
    u = t - t_s
    return np.exp(-k * u + 0.5 * (k * SIG) ** 2) * ndtr(u / SIG - k * SIG)


def _waves(n, peak_counts, k, specular=0.0, seed=0):
    t = np.arange(256.0)
    vol = _onset(t, T_S, k)
    lam = 10.0 + peak_counts * vol / vol.max() + specular * np.exp(-0.5 * ((t - T_S) / SIG) ** 2)
    rng = np.random.default_rng(seed)
    return rng.poisson(np.broadcast_to(lam, (n, t.size))).astype(np.float64)


def test_the_onset_alone_is_timed_at_the_surface_not_at_its_peak():
    # the decays of c ≈ 0.1-0.8 1/m water (k ≈ 2 c · 0.11 m/ns per ns); noise-free, then
    # Poisson photon noise at a calm-water column of ~60 counts
    for k in (0.02, 0.056, 0.15):
        clean = 10.0 + 300.0 * _onset(np.arange(256.0), T_S, k)[None, :]
        d = detect_full_waveform(clean, DT, FWHM)
        assert d.has_surface.all()
        # the plain peak is 1-3 samples late; the filter's discrete kernel leaves ~0.05
        assert abs(d.t_surface_s[0] / DT - T_S) < 0.1, k
        noisy = detect_full_waveform(_waves(400, 60.0, k, seed=1), DT, FWHM)
        err = noisy.t_surface_s[noisy.has_surface] / DT - T_S
        assert noisy.has_surface.mean() > 0.99
        # 0.2 sample = 3 cm of range
        assert abs(np.mean(err)) < 0.2, (k, np.mean(err))


def test_a_specular_echo_on_the_onset_is_still_timed_at_its_centre():
    # wind: the specular echo dominates; the onset under it must not pull it either way
    d = detect_full_waveform(_waves(400, 30.0, 0.056, specular=800.0, seed=2), DT, FWHM)
    err = d.t_surface_s[d.has_surface] / DT - T_S
    assert abs(np.mean(err)) < 0.03 and np.std(err) < 0.1
