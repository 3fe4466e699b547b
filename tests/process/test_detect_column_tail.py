"""No phantom bottom in the surface echo's tail: the water column's exponential decay after
the surface echo is not a bottom (issue: phantom bottoms just under the surface).

The truth is written here: a Gaussian system response, a surface echo, the volume backscatter
of a homogeneous water column (a step at the surface decaying as ``exp(-k τ)`` down to the
bottom, seen through the same Gaussian response: an exponentially modified Gaussian),
Gaussian noise of a known level (electronic + shot noise of the signal), and either no bottom
or a faint one at a known time.
"""

import math

import numpy as np
from scipy.special import ndtr

from pipeline.process.detect import detect_full_waveform

DT_S = 1e-9  # 1 GS/s
FWHM_S = 1.8e-9  # system response (pulse ⊗ detector)
SIGMA_S = FWHM_S / (2.0 * math.sqrt(2.0 * math.log(2.0)))
T_SURFACE_S = 40e-9
BASELINE = 200.0
NOISE = 1.5  # counts rms, electronic (white)
SHOT = 1.3  # F·G: a sample holding y counts of signal has variance NOISE² + SHOT·y
SURFACE = 200.0  # counts above the baseline at the surface peak
COLUMN = 40.0  # counts of column backscatter just below the surface (before the decay)
DECAY_PER_S = 1.0 / 30e-9  # k = c v_water ≈ 0.15 m⁻¹ × 0.22 m/ns, round trip


def _waveforms(n, t_bottom_s=None, bottom=0.0, seed=0):
    """``(n, 300)`` waveforms: surface + column tail (+ bottom) + noise, in counts.

    The surface lies at ``T_SURFACE_S`` plus a uniform sub-sample phase (returned, ``(n,)``),
    the bottom ``t_bottom_s - T_SURFACE_S`` after it.
    """
    rng = np.random.default_rng(seed)
    t_s = T_SURFACE_S + rng.uniform(0.0, DT_S, n)[:, None]
    t = np.arange(300) * DT_S
    tau = t - t_s
    y = SURFACE * np.exp(-0.5 * (tau / SIGMA_S) ** 2)
    # the column between the surface and the bottom (τ in [0, T)), H e^{-kτ} convolved with
    # the Gaussian response: e^{-kτ + k²σ²/2} [Φ(τ/σ − kσ) − Φ((τ − T)/σ − kσ)]
    ks = DECAY_PER_S * SIGMA_S
    stop = np.inf if t_bottom_s is None else t_bottom_s - T_SURFACE_S
    window = ndtr(tau / SIGMA_S - ks) - ndtr((tau - stop) / SIGMA_S - ks)
    y = y + COLUMN * np.exp(-DECAY_PER_S * tau + 0.5 * ks**2) * window
    if t_bottom_s is not None:
        y = y + bottom * np.exp(-0.5 * ((tau - stop) / SIGMA_S) ** 2)
    sd = np.sqrt(NOISE**2 + SHOT * y)
    return BASELINE + y + sd * rng.standard_normal((n, t.size)), t_s[:, 0]


def _detect(w):
    return detect_full_waveform(w, DT_S, FWHM_S, noise_samples=20, shot_noise_counts=SHOT)


def test_column_tail_without_bottom_gives_no_bottom():
    w, _ = _waveforms(2000, seed=11)
    d = _detect(w)
    assert d.has_surface.all()
    # 5σ on the matched-filtered noise over ~250 samples: false alarms ~ 1e-4 per waveform;
    # the surface echo's noisy trailing flank and the column onset must not add any
    # (before the fix: 10 % of these waveforms had a "bottom" 3.4-4.1 ns below the surface)
    assert d.has_bottom.mean() < 0.01


def test_faint_bottom_on_the_column_tail_is_found_at_its_range():
    t_b = T_SURFACE_S + 60.4e-9  # ~6.6 m of water
    # 30 counts above the baseline (the column adds ~5 there): ~4.5 raw noise σ per sample
    w, t_s = _waveforms(2000, t_bottom_s=t_b, bottom=30.0, seed=12)
    d = _detect(w)
    # measured 93 % (seed 12): a 5σ detection of a 4.5σ-per-sample echo misses a few
    assert d.has_bottom.mean() > 0.9
    err = d.t_bottom_s[d.has_bottom] - (t_s[d.has_bottom] + 60.4e-9)
    # SNR ~10 per sample over ~2 samples per FWHM: timing σ ≈ 0.1 ns
    assert np.median(np.abs(err)) < 0.2e-9
    # the right range, not the surface tail: every detection within 1 ns (11 cm of water)
    assert np.mean(np.abs(err) < 1e-9) > 0.99


def test_merged_shallow_bottom_is_still_separated_and_timed():
    # 0.28 m of water: a bottom echo 2.5 ns (1.4 FWHM) after the surface, merged with it;
    # 120 counts, 0.6 of the surface echo. Not a regression test (the code before the fix
    # found 82 % within 0.5 ns, median -0.10 ns): the phantom fix must keep finding it
    sep_s = 2.5e-9
    w, t_s = _waveforms(1000, t_bottom_s=T_SURFACE_S + sep_s, bottom=120.0, seed=14)
    d = _detect(w)
    # measured 74 %: noise hides the merged peak's extra width in some waveforms (no fit is
    # tried there) and a free surface width absorbs some of the closest bottoms
    assert d.has_bottom.mean() > 0.65
    err = d.t_bottom_s[d.has_bottom] - (t_s[d.has_bottom] + sep_s)
    assert abs(np.median(err)) < 0.15e-9
    assert np.mean(np.abs(err) < 0.5e-9) > 0.95
