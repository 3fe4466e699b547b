"""In-column returns of the full-waveform detector: found where they are, rarely from noise."""

import math

import numpy as np
import pytest

from pipeline.process.detect import DetectSettings, detect_full_waveform
from pipeline.process.returns import DetectorFlag

DT = 1e-9  # 1 GS/s
FWHM = 2.0e-9
SIG = FWHM / (2 * math.sqrt(2 * math.log(2)))


def _waveforms(n, t_s=60e-9, t_b=160e-9, t_c=None, a_s=100.0, a_b=20.0, a_c=0.0, sig_c=SIG,
               column=8.0, noise=1.0, baseline=10.0, seed=0):  # fmt: skip
    """Waveforms written independently: Gaussian surface, layer and bottom echoes on an
    exponential column (40 ns decay), white Gaussian noise."""
    t = np.arange(256) * DT
    y = a_s * np.exp(-0.5 * ((t - t_s) / SIG) ** 2) + a_b * np.exp(-0.5 * ((t - t_b) / SIG) ** 2)
    y = y + column * np.where(t > t_s, np.exp(-(t - t_s) / 40e-9), 0.0) * (t < t_b)
    if a_c:
        y = y + a_c * np.exp(-0.5 * ((t - np.asarray(t_c)[..., None]) / sig_c) ** 2)
    rng = np.random.default_rng(seed)
    return (baseline + y + noise * rng.standard_normal((n, t.size))).astype(np.float32)


@pytest.mark.parametrize(("sig_c", "tol_s"), [(SIG, 0.05e-9), (3e-9, 0.15e-9)])
def test_mid_column_echo_is_found_at_its_time(sig_c, tol_s):
    rng = np.random.default_rng(1)
    t_c = 100e-9 + rng.uniform(0, 1e-9, 400)  # sub-sample positions
    d = detect_full_waveform(_waveforms(400, t_c=t_c, a_c=10.0, sig_c=sig_c, seed=2), DT, FWHM)
    assert d.has_column.mean() > 0.98
    # the bottom is still the bottom (stronger, later)
    assert d.has_bottom.all() and np.median(np.abs(d.t_bottom_s - 160e-9)) < 0.2e-9
    got = d.has_column
    assert np.all(
        (d.t_column_s[got] > d.t_surface_s[got]) & (d.t_column_s[got] < d.t_bottom_s[got])
    )
    # the column's slope s under the echo moves the filtered peak by sigma_f^2 s / A: -0.02 ns
    # for a system-wide echo, -0.08 ns for one 3.5x wider (sigma_f^2 9.7 ns^2); the median of
    # 400 (single-echo sd 0.1 and 0.4 ns) adds < 0.03 ns
    assert abs(np.median(d.t_column_s[got] - t_c[got])) < tol_s
    assert np.all(d.column_confidence[got] > 0.4) and np.all(d.column_amplitude[got] > 0)
    assert np.all(d.t_column_s[~got] == 0) and np.all(d.column_confidence[~got] == 0)


def test_echo_too_close_to_the_bottom_or_surface_is_not_a_column_return():
    # echoes 8 ns from the bottom or the surface (a short trend keeps them out of the
    # neighbour's flanks): columns at the default 2.5 FWHM = 5 ns separation, not at 6 FWHM
    for t_c, seed in ((152e-9, 3), (68e-9, 4)):
        w = _waveforms(200, t_c=t_c, a_c=20.0, a_b=40.0, seed=seed)
        near = detect_full_waveform(w, DT, FWHM, DetectSettings(trend_fwhm=2.0))
        assert near.has_column.mean() > 0.95
        assert np.median(np.abs(near.t_column_s[near.has_column] - t_c)) < 0.2e-9
        wide = DetectSettings(trend_fwhm=2.0, min_separation_fwhm=6.0)
        assert not detect_full_waveform(w, DT, FWHM, wide).has_column.any()
    off = detect_full_waveform(
        _waveforms(200, t_c=100e-9, a_c=10.0, seed=5),
        DT,
        FWHM,
        DetectSettings(column_returns=False),
    )
    assert not off.has_column.any()


@pytest.mark.slow
def test_false_alarms_on_layer_free_waveforms_are_rare():
    # 20 000 noisy waveforms with a surface, a column and a bottom but no layer: a column
    # return is a noise peak above the bottom's 5 sigma threshold among ~90 samples between
    # surface + 5 ns and bottom - 5 ns. Gaussian noise, filtered: ~3e-7 per independent
    # sample, so ~1e-5 per waveform; the bound 1e-3 (20 of 20 000) leaves room for the
    # threshold's noise estimate (the MAD of first differences, ~1 % error per waveform)
    n = 20000
    d = detect_full_waveform(_waveforms(n, seed=6), DT, FWHM)
    assert d.has_bottom.mean() > 0.99
    assert d.has_column.mean() < 1e-3
    # and with shot noise on the column (the run's signal-dependent threshold)
    d2 = detect_full_waveform(_waveforms(n, column=40.0, seed=7), DT, FWHM, shot_noise_counts=1.3)
    assert d2.has_column.mean() < 1e-3


def test_layer_stronger_than_the_bottom():
    # a layer 3x the bottom: by default it is reported as the bottom, flagged; with
    # bottom_pick = "last" the seabed is the bottom and the layer a column return
    w = _waveforms(300, t_c=100e-9, a_c=60.0, seed=8)
    d = detect_full_waveform(w, DT, FWHM)
    assert np.median(np.abs(d.t_bottom_s - 100e-9)) < 0.2e-9
    assert np.mean((d.flags & DetectorFlag.MULTIPLE_BOTTOM_CANDIDATES) > 0) > 0.98
    last = detect_full_waveform(w, DT, FWHM, DetectSettings(bottom_pick="last"))
    assert np.median(np.abs(last.t_bottom_s - 160e-9)) < 0.2e-9
    assert last.has_column.mean() > 0.98
    assert np.median(np.abs(last.t_column_s - 100e-9)) < 0.2e-9
    assert not np.any(last.flags & DetectorFlag.MULTIPLE_BOTTOM_CANDIDATES)
    # without a layer, both choices give the same bottoms
    plain = _waveforms(300, seed=9)
    a = detect_full_waveform(plain, DT, FWHM)
    b = detect_full_waveform(plain, DT, FWHM, DetectSettings(bottom_pick="last"))
    assert np.array_equal(a.t_bottom_s, b.t_bottom_s)


def test_false_alarms_on_simulated_layer_free_waveforms_are_rare():
    # the simulator's noise (Poisson photons, PMT gain, digitiser) over the Palmer scene's
    # 1-30 m seabed without a layer: measured 2 column returns in 40 000 pulses (5e-5); the
    # bound 1e-3 (8 of 8000) is 20 times that
    import tomllib
    from pathlib import Path

    from pipeline.scene import parse_scene
    from pipeline.simulate.flat_paths import flat_paths
    from pipeline.simulate.waveform import simulate_waveforms

    scenes = Path(__file__).resolve().parents[2] / "data_synthetic" / "scenes"
    scene = parse_scene(tomllib.loads((scenes / "palmer_survey.toml").read_text()))
    n = 8000
    rng = np.random.default_rng(4)
    paths = flat_paths(
        n, altitude_m=400.0, depth_m=rng.uniform(1.0, 30.0, n), off_nadir_rad=math.radians(20),
        azimuth_rad=rng.uniform(0, 2 * np.pi, n), n_sub=7, divergence_rad=1e-3,
    )  # fmt: skip
    wf = simulate_waveforms(paths, scene, scene.detector, scene.returns)
    fwhm = math.hypot(scene.system.pulse_fwhm_s, scene.detector.impulse_response_fwhm_s)
    d = detect_full_waveform(
        wf.samples, wf.sample_interval_s, fwhm, scene.process.detect,
        noise_samples=int((scene.detector.pre_trigger_s - 2 * fwhm) / wf.sample_interval_s),
        shot_noise_counts=scene.detector.excess_noise_factor,
    )  # fmt: skip
    # about half of the 1-30 m slope is within reach: measured 46.3 %, all at the right
    # range (74 % "bottoms" before the column-aware merged fit: the surplus were false
    # bottoms in the surface echo's tail, within 0.5 m of the surface)
    assert d.has_bottom.mean() > 0.45
    assert d.has_column.mean() < 1e-3
