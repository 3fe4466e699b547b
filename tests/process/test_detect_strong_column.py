"""Low altitude: the water column outshines the surface echo, and its rounded onset is no bottom.

Flown at 150 m instead of 400 m, every return is ~7× brighter and the column's volume
backscatter just below the surface is as bright as the surface echo itself: the waveform is a
hump (surface + column onset) followed by the column's exponential decay. A flank trend
undershoots such a hump, and a noise bump on its shoulder, 5-8 ns after the surface, was taken
for a bottom 0.6-0.8 m deep (3 808 class-40 points over 14-34 m of water on a 1:5 slope).

The truth is written here: a Gaussian system response, a surface echo, the column as an
exponentially modified Gaussian (a step at the surface decaying as ``exp(-k τ)`` down to the
bottom), electronic + shot noise of known level, and no bottom or a shallow one.
"""

import math

import numpy as np
import pytest
from scipy.special import ndtr

from pipeline.process.detect import detect_full_waveform

DT_S = 1e-9
FWHM_S = 1.8e-9
SIGMA_S = FWHM_S / (2.0 * math.sqrt(2.0 * math.log(2.0)))
T_SURFACE_S = 40e-9
NOISE, SHOT = 1.5, 1.3
# measured on the 150 m survey's waveforms: surface peak ~290 counts on a column of ~250
# decaying to ~200 within 14 ns
SURFACE, COLUMN, DECAY_PER_S = 80.0, 250.0, 1.0 / 40e-9


def _waveforms(n, seed, depth_s=None, bottom=0.0):
    rng = np.random.default_rng(seed)
    t_s = T_SURFACE_S + rng.uniform(0.0, DT_S, n)[:, None]
    tau = np.arange(300) * DT_S - t_s
    ks = DECAY_PER_S * SIGMA_S
    stop = np.inf if depth_s is None else depth_s
    y = SURFACE * np.exp(-0.5 * (tau / SIGMA_S) ** 2)
    window = ndtr(tau / SIGMA_S - ks) - ndtr((tau - stop) / SIGMA_S - ks)
    y = y + COLUMN * np.exp(-DECAY_PER_S * tau + 0.5 * ks**2) * window
    if depth_s is not None:
        y = y + bottom * np.exp(-0.5 * ((tau - stop) / SIGMA_S) ** 2)
    y = y + np.sqrt(NOISE**2 + SHOT * y) * rng.standard_normal(y.shape)
    return 200.0 + y, t_s[:, 0]


def _detect(w):
    return detect_full_waveform(w, DT_S, FWHM_S, noise_samples=20, shot_noise_counts=SHOT)


def test_bright_column_onset_is_not_a_bottom():
    near, total, n = 0, 0, 0
    for seed in (21, 31, 41):
        w, _ = _waveforms(3000, seed=seed)
        d = _detect(w)
        assert d.has_surface.all()
        near += int(np.sum(d.has_bottom & (d.t_bottom_s - d.t_surface_s < 20e-9)))
        total += int(d.has_bottom.sum())
        n += len(w)
    # near-surface false bottoms in 9 000 waveforms: 1 077 (12 %) with the flank trend alone;
    # 12 with the column carried back from below (window width chosen on seed 22); 3 once the
    # separation also widens with the measured surface echo (the hump is wider than the
    # system response). A 5σ test lets through a few in ten thousand
    assert near <= 0.001 * n
    assert total <= 0.002 * n


@pytest.mark.xfail(
    strict=True,
    reason="known gap, before and after the phantom fix: a 150-count bottom 0.9 m / 1.3 m under "
    "a bright column is found at its range in 2.5 % / 0 % of pulses (the larger-flank trend's "
    "left flank is the surface + column hump; the one-sided column test only removes candidates)",
)
@pytest.mark.parametrize("depth_ns", [8.0, 12.0])
def test_shallow_bottom_under_a_bright_column_is_still_found(depth_ns):
    # 8 and 12 ns of round trip: 0.9 and 1.3 m of water; the bottom echo 150 counts
    w, t_s = _waveforms(1000, seed=22, depth_s=depth_ns * 1e-9, bottom=150.0)
    d = _detect(w)
    err = d.t_bottom_s - (t_s + depth_ns * 1e-9)
    right = d.has_bottom & (np.abs(err) < 1e-9)
    assert right.mean() > 0.95
