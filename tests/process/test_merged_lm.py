"""The compiled merged-echo fit: two echoes on a column onset written out by hand."""

from __future__ import annotations

import math

import numpy as np
from scipy.special import ndtr

from pipeline.process.detect_merged import fit_merged

SIGMA = 1.0  # system response σ, samples; the filtered echoes have σ √2
SG = math.sqrt(2.0) * SIGMA


def _merged(t_s, t_b, a_s=100.0, a_b=40.0, b=10.0, k=0.05, m=70):
    """``a_s g(t − t_s) + a_b g(t − t_b) + b Φ((t − t_s)/σ) e^{−k (t − t_s)⁺}``, samples 0..m-1."""
    t = np.arange(m, dtype=float)
    tau = t - t_s
    return (
        a_s * np.exp(-0.5 * (tau / SG) ** 2)
        + a_b * np.exp(-0.5 * ((t - t_b) / SG) ** 2)
        + b * ndtr(tau / SG) * np.exp(-k * np.maximum(tau, 0.0))
    )


def test_noise_free_merged_echoes_are_recovered_and_each_pulse_fits_alone():
    t_s = np.array([30.0, 25.3, 40.7])
    t_b = t_s + np.array([2.4, 3.0, 2.7])  # closer than the detector's separation: merged
    filt = np.stack([_merged(a, b) for a, b in zip(t_s, t_b, strict=True)])
    guess = np.argmax(filt, axis=1).astype(float)
    decay = np.full(3, 0.05)
    lo, hi, a_lo, a_hi, ok, col, _ = fit_merged(filt, guess, SIGMA, decay=decay)
    assert ok.all()
    np.testing.assert_allclose(lo, t_s, atol=1e-3)
    np.testing.assert_allclose(hi, t_b, atol=1e-3)
    np.testing.assert_allclose(a_lo, 100.0, rtol=1e-3)
    np.testing.assert_allclose(a_hi, 40.0, rtol=1e-3)
    np.testing.assert_allclose(col[:, 0], 10.0, rtol=1e-2)
    # a pulse's fit does not depend on the others of its batch
    one = fit_merged(filt[1:2], guess[1:2], SIGMA, decay=decay[1:2])
    assert one[0][0] == lo[1] and one[1][0] == hi[1]
