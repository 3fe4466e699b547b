"""Noise floor of digitised (integer) waveforms: σ against the analytic variance of quantised
Gaussian and Poisson noise, and the false-alarm rate of noise-only waveforms at 5 σ.

The reference σ is the standard deviation of ``round(b + σ_e Z)`` summed over its codes,
``P(k) = Φ((k + ½ − b)/σ_e) − Φ((k − ½ − b)/σ_e)``; a Poisson count's is ``√λ``. Before the fix
the MAD of first differences gave 0.69 of it at σ_e = 1.5 and 0 for σ_e ≲ 0.5 or λ ≲ 0.5.
"""

import math

import numpy as np
import pytest
from scipy.special import ndtr

from pipeline.process.detect import detect_full_waveform

DT_S = 1e-9
#: 3 samples FWHM: the sampled matched filter is its continuous self to 0.1 %
FWHM_S = 3e-9
SIGMA_K = FWHM_S / DT_S / (2.0 * math.sqrt(2.0 * math.log(2.0)))
#: white noise of σ through a unit-area Gaussian of σ_k samples: σ / √(2 √π σ_k)
FILTER_GAIN = 1.0 / math.sqrt(2.0 * math.sqrt(math.pi) * SIGMA_K)


def quantised_sigma(sigma_e: float, offset: float) -> float:
    """Standard deviation of round(offset + sigma_e Z), from the code probabilities."""
    k = np.arange(-60, 61)
    p = ndtr((k + 0.5 - offset) / sigma_e) - ndtr((k - 0.5 - offset) / sigma_e)
    mean = float((k * p).sum())
    return math.sqrt(float(((k - mean) ** 2 * p).sum()))


@pytest.mark.parametrize("sigma_e", [0.5, 0.8, 1.5, 3.0])
@pytest.mark.parametrize("offset", [0.0, 0.3])
def test_noise_sigma_of_quantised_gaussian_noise(sigma_e, offset):
    rng = np.random.default_rng(5)
    y = np.floor(100.0 + offset + sigma_e * rng.standard_normal((300, 300)) + 0.5)
    det = detect_full_waveform(y, DT_S, FWHM_S, noise_samples=16)
    truth = quantised_sigma(sigma_e, offset) * FILTER_GAIN
    assert np.median(det.noise_sigma) == pytest.approx(truth, rel=0.04)


@pytest.mark.parametrize("lam", [0.2, 1.0, 3.0])
def test_noise_sigma_of_poisson_counts(lam):
    rng = np.random.default_rng(6)
    y = 50.0 + rng.poisson(lam, (300, 300))
    det = detect_full_waveform(y, DT_S, FWHM_S, noise_samples=16)
    assert np.median(det.noise_sigma) == pytest.approx(math.sqrt(lam) * FILTER_GAIN, rel=0.05)


def test_noise_sigma_ignores_echoes():
    # a 2000-count surface echo, a water column and a 300-count bottom on σ_e = 1.5 noise
    rng = np.random.default_rng(7)
    t = np.arange(300.0)
    s = SIGMA_K / 1.0
    y = 2000.0 * np.exp(-0.5 * ((t - 60.0) / s) ** 2) + 300.0 * np.exp(-0.5 * ((t - 150) / s) ** 2)
    y += np.where(t > 60, 80.0 * np.exp(-(t - 60.0) / 40.0), 0.0)
    y = np.floor(200.0 + y + 1.5 * rng.standard_normal((300, t.size)) + 0.5)
    det = detect_full_waveform(y, DT_S, FWHM_S, noise_samples=16)
    truth = quantised_sigma(1.5, 0.0) * FILTER_GAIN
    assert np.median(det.noise_sigma) == pytest.approx(truth, rel=0.06)


def test_noise_only_integer_waveforms_rarely_pass_five_sigma():
    # 1.5 counts of electronic noise, digitised: a 5 σ threshold over ~330 samples passes in
    # at most 330 × Φ(−5) ≈ 1e-4 of the pulses (union bound); before: ~15 %
    rng = np.random.default_rng(8)
    y = np.floor(200.0 + 1.5 * rng.standard_normal((20000, 350)) + 0.5).astype(np.float32)
    det = detect_full_waveform(y, DT_S, 1.8e-9, noise_samples=16)
    assert det.has_surface.mean() < 1e-3


@pytest.mark.parametrize("m", [1, 2, 7, 16, 349])
def test_row_median_is_numpys_bit_for_bit(m):
    """The partition median equals ``np.median(axis=1)`` exactly: odd and even rows, ties
    (integer codes), NaN and inf (the detection stage's outputs must not move a bit)."""
    from pipeline.process.detect_noise import _row_median

    rng = np.random.default_rng(m)
    x = np.vstack([rng.normal(size=(20, m)), np.round(rng.normal(0, 2, (20, m))), np.zeros((1, m))])
    x[3, m // 2] = np.nan
    x[4, 0] = np.inf
    x[5, -1] = -np.inf
    np.testing.assert_array_equal(_row_median(x), np.median(x, axis=1))
    np.testing.assert_array_equal(_row_median(x[6:]), np.median(x[6:], axis=1))
