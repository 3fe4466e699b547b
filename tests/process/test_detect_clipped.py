"""Echoes clipped at the digitiser's top code: flagged SATURATED, a lone clipped echo timed at
its centre, a plateau running on into the column flagged CLIPPED_MERGED with no bottom.

The waveforms are written here: Gaussian echoes of known centre and amplitude (the system
response, σ = FWHM / 2.3548), an exponential water column, 1.5 counts of noise, rounded and
clipped at 4095 (12 bits). Before the fix nothing was flagged and a clipped surface was timed
on its plateau (several ns late).
"""

import math

import numpy as np

from pipeline.process.detect import detect_full_waveform
from pipeline.process.returns import DetectorFlag

DT_S, FWHM_S = 1e-9, 1.8e-9
SIG = FWHM_S / (2.0 * math.sqrt(2.0 * math.log(2.0))) / DT_S  # samples
TOP = 4095.0


def digitise(y, seed):
    rng = np.random.default_rng(seed)
    return np.clip(np.floor(200.0 + y + 1.5 * rng.standard_normal(y.shape) + 0.5), 0.0, TOP)


def gauss(t, centre, amp):
    return np.reshape(amp, (-1, 1)) * np.exp(-0.5 * ((t - centre[:, None]) / SIG) ** 2)


def test_a_lone_clipped_echo_is_flagged_and_timed_at_its_centre():
    # land: one echo, 30 to 3000 times full scale (plateaus of 4-8 samples)
    n = 400
    rng = np.random.default_rng(1)
    centre = 60.0 + rng.uniform(0.0, 1.0, n)
    amp = TOP * 10.0 ** rng.uniform(1.5, 3.5, n)
    t = np.arange(300.0)
    det = detect_full_waveform(
        digitise(gauss(t, centre, amp), 2), DT_S, FWHM_S, noise_samples=16, top_code=TOP
    )
    assert det.has_surface.all() and not det.has_bottom.any()
    assert np.all(det.flags & np.uint16(DetectorFlag.SATURATED))
    assert not np.any(det.flags & np.uint16(DetectorFlag.CLIPPED_MERGED))
    err_ns = (det.t_surface_s - centre * DT_S) * 1e9
    # 0.1 ns is 1.5 cm of range
    assert np.abs(err_ns).max() < 0.1, np.abs(err_ns).max()


def test_a_clipped_surface_over_a_clipped_column_gives_no_timing_reference_and_no_bottom():
    # water 4 m deep: surface, a column far above full scale and the bottom make one plateau
    n = 200
    t = np.arange(300.0)
    t_s = np.full(n, 40.3)
    t_b = t_s + 2.0 * 4.0 * 1.34 / 0.299792458
    column = np.where(t > t_s[:, None], 5e4 * np.exp(-(t - t_s[:, None]) / 40.0), 0.0)
    column *= t < t_b[:, None]
    y = gauss(t, t_s, 1e6) + column + gauss(t, t_b, 1e5)
    det = detect_full_waveform(digitise(y, 3), DT_S, FWHM_S, noise_samples=16, top_code=TOP)
    merged = (det.flags & np.uint16(DetectorFlag.CLIPPED_MERGED)) != 0
    assert merged.all() and np.all(det.flags & np.uint16(DetectorFlag.SATURATED))
    assert not det.has_bottom.any() and not det.has_column.any()
    # the surface time is the plateau's leading edge: never after the true surface
    assert np.all(det.t_surface_s <= t_s * DT_S)


def test_an_unclipped_waveform_is_not_flagged():
    t = np.arange(300.0)
    y = gauss(t, np.full(50, 60.2), 2000.0) + gauss(t, np.full(50, 120.7), 300.0)
    det = detect_full_waveform(digitise(y, 4), DT_S, FWHM_S, noise_samples=16, top_code=TOP)
    assert det.has_surface.all() and det.has_bottom.all()
    assert not np.any(det.flags & np.uint16(DetectorFlag.SATURATED | DetectorFlag.CLIPPED_MERGED))


def test_a_bright_shallow_seabed_clipped_on_its_own_is_timed_at_its_centre():
    # an unclipped surface (2000 counts) and a seabed echo 30-300 x full scale, 60 ns later
    n = 300
    rng = np.random.default_rng(5)
    t = np.arange(300.0)
    t_s = 50.0 + rng.uniform(0.0, 1.0, n)
    t_b = t_s + 60.0 + rng.uniform(0.0, 1.0, n)
    y = gauss(t, t_s, np.full(n, 2000.0)) + gauss(t, t_b, TOP * 10.0 ** rng.uniform(1.5, 2.5, n))
    det = detect_full_waveform(digitise(y, 6), DT_S, FWHM_S, noise_samples=16, top_code=TOP)
    assert det.has_surface.all() and det.has_bottom.all()
    assert np.all(det.flags & np.uint16(DetectorFlag.SATURATED))
    err_ns = (det.t_bottom_s - t_b * DT_S) * 1e9
    assert np.abs(err_ns).max() < 0.1, np.abs(err_ns).max()


def test_a_clipped_surface_merged_with_the_column_is_bounded_within_a_sample_or_two():
    # the surface echo 2.5-250 x full scale (A = 1e4-1e6 counts) at a random phase, run on into
    # a clipped column and bottom: only its leading edge is measured. The weakest Gaussian of
    # the system sigma through the last sample below the plateau that reaches the top code at
    # the next one peaks at t_lead = a + 1/2 + sigma^2 ln(top / v_a): never after the true
    # centre (a stronger echo through that sample peaks later), and here within 2 samples
    # (t - t_lead = sigma sqrt(2 ln(A / v_a)) - 1/2 - sigma^2 ln(top / v_a) <= 1.96 for A <= 1e6).
    # Before the fix the bound was the plateau's first sample - 1/2: 0.6-3.0 samples early.
    n = 400
    rng = np.random.default_rng(8)
    t = np.arange(300.0)
    t_s = 40.0 + rng.uniform(0.0, 1.0, n)
    amp = 10.0 ** rng.uniform(4.0, 6.0, n)
    t_b = t_s + 2.0 * 4.0 * 1.34 / 0.299792458
    column = np.where(t > t_s[:, None], 5e4 * np.exp(-(t - t_s[:, None]) / 40.0), 0.0)
    column *= t < t_b[:, None]
    y = gauss(t, t_s, amp) + column + gauss(t, t_b, 1e5)
    det = detect_full_waveform(digitise(y, 9), DT_S, FWHM_S, noise_samples=16, top_code=TOP)
    assert np.all(det.flags & np.uint16(DetectorFlag.CLIPPED_MERGED))
    early_ns = (t_s * DT_S - det.t_surface_s) * 1e9
    # never late (0.05 ns: the noise of the edge sample's log)
    assert early_ns.min() > -0.05, early_ns.min()
    assert early_ns.max() < 2.2, early_ns.max()  # 1.96 noise-free, plus noise
    assert np.mean(early_ns) < 1.0, np.mean(early_ns)
