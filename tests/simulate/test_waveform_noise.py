"""Statistics of the photon draws and of the two receivers; determinism and chunk invariance."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats
from waveform_support import clean_scene, detector, make_scene, replace

from pipeline.simulate import photon
from pipeline.simulate import waveform as W
from pipeline.simulate.budget import return_budget
from pipeline.simulate.flat_paths import flat_paths
from pipeline.simulate.paths import Paths
from pipeline.simulate.receivers import dead_time_filter


def test_poisson_quantile_matches_scipy_ppf():
    rng = np.random.default_rng(1)
    lam = np.concatenate([[0.0, 1e-9], 10 ** rng.uniform(-3, 5, 3000), [29.99, 30.0, 1e6]])
    u = rng.random(lam.size)
    u[:3] = [0.5, 0.999999, 1e-12]
    got = photon.poisson_quantile(u, lam)
    ref = stats.poisson.ppf(u, lam)
    # exact integers: both are the smallest k with F(k) >= u
    np.testing.assert_array_equal(got, ref.astype(np.int64))


def test_counter_uniforms_are_uniform_and_independent_of_chunking():
    keys = photon.pulse_keys(7, 3, np.arange(2000))
    u, v = photon.uniform_pair(np.repeat(keys, 50), np.tile(np.arange(50), 2000))
    # KS at 1e-3: 100 000 draws; a correct generator fails 0.1 % of seeds (this one is fixed)
    assert stats.kstest(u, "uniform").pvalue > 1e-3
    assert stats.kstest(v, "uniform").pvalue > 1e-3
    assert abs(np.corrcoef(u, v)[0, 1]) < 0.01  # 3 sigma of r for 1e5 pairs is 0.0095
    # the key of pulse 1234 does not depend on which other pulses are asked for
    assert photon.pulse_keys(7, 3, np.array([1234]))[0] == keys[1234]


def _window_stats(samples, lo, hi):
    s = samples[:, lo:hi].astype(np.float64).sum(axis=1)
    return s.mean(), s.var(ddof=1), s


@pytest.mark.parametrize("strong", [1e12, 1.0], ids=["photon_draws", "gaussian_strong"])
def test_full_waveform_mean_and_variance_follow_poisson_with_excess_noise(strong):
    # identical pulses; in windows around each return, sum(samples) has mean
    # sum(baseline + G lambda_i) and variance sum(F G^2 lambda_i + sigma_e^2 + 1/12)
    scene = make_scene(
        water={"extinction_per_m": 0.2, "backscatter_180_per_m_sr": 2e-3, "wind_speed_m_s": 5.0},
        background={"solar_irradiance_w_m2_nm": 1.0},
        system={"pulse_energy_j": 2.5e-7},
    )
    g, f, sig_e = 4.0, 1.6, 2.0
    det = detector(
        window_s=2.5e-7, pre_trigger_s=2e-8, counts_per_photoelectron=g, excess_noise_factor=f,
        electronic_noise_counts=sig_e, bit_depth=16, baseline_counts=500.0,
        strong_return_photoelectrons=strong,
    )  # fmt: skip
    n = 4000
    paths = flat_paths(n, altitude_m=300.0, depth_m=6.0)
    wf = W.simulate_waveforms(paths, scene, det)
    b = return_budget(paths, scene, det)
    lam = W.expected_waveform(b)["total"][0]
    i_s = round((b.t_surface_s[0, 0] - b.t0_s[0]) * 1e9)
    i_b = round((b.t_bottom_s[0, 0] - b.t0_s[0]) * 1e9)
    # surface echo, bottom echo (column underneath), and column + background after the bottom
    windows = [(i_s - 3, i_s + 4), (i_b - 4, i_b + 5), (i_b + 20, 250)]
    for lo, hi in windows:
        mean, var, s = _window_stats(wf.samples, lo, hi)
        mu = np.sum(500.0 + g * lam[lo:hi])
        v = np.sum(f * g * g * lam[lo:hi] + sig_e**2 + 1.0 / 12.0)  # 1/12: rounding (Sheppard)
        # 3 sigma: standard error of a mean, and of a variance from the sample 4th moment
        assert abs(mean - mu) < 3 * math.sqrt(v / n)
        m4 = np.mean((s - s.mean()) ** 4)
        se_var = math.sqrt(max(m4 - var**2 * (n - 3) / (n - 1), 0.0) / n)
        assert abs(var - v) < 3 * se_var


def test_photon_counting_counts_are_poisson_without_dead_time():
    scene = make_scene(
        water={"extinction_per_m": 0.1, "backscatter_180_per_m_sr": 2e-3},
        background={"solar_irradiance_w_m2_nm": 1.5},
        system={"pulse_energy_j": 1e-8},
    )
    det = detector(mode="photon_counting", window_s=4e-7, dead_time_s=0.0)
    n = 20000
    paths = flat_paths(n, altitude_m=300.0, depth_m=5.0)
    ev = W.simulate_photon_events(paths, scene, det)
    counts = np.diff(ev.offsets)
    lam = W.expected_waveform(return_budget(paths, scene, det))["total"][0].sum()
    # 3 sigma: the mean of n Poisson counts has sd sqrt(lam/n); the variance ~ lam sqrt(2/n)
    assert abs(counts.mean() - lam) < 3 * math.sqrt(lam / n)
    assert abs(counts.var(ddof=1) - lam) < 3 * lam * math.sqrt((2 + 1 / lam) / n)
    # and their distribution: chi-square over k = 0..kmax
    kmax = int(lam + 5 * math.sqrt(lam))
    obs = np.bincount(np.minimum(counts, kmax), minlength=kmax + 1)
    p = stats.poisson.pmf(np.arange(kmax + 1), lam)
    p[-1] = stats.poisson.sf(kmax - 1, lam)
    keep = p * n > 5
    chi2 = np.sum((obs[keep] - n * p[keep]) ** 2 / (n * p[keep]))
    assert stats.chi2.sf(chi2, keep.sum() - 1) > 1e-3  # 1e-3: fixed seed, correct model


def test_dead_time_respected_and_equal_to_sequential_reference():
    scene = make_scene(
        system={"pulse_energy_j": 1e-6}, background={"solar_irradiance_w_m2_nm": 2.0}
    )
    tau = 3e-9
    det = detector(mode="photon_counting", window_s=3e-7, dead_time_s=tau, n_channels=4)
    paths = flat_paths(300, altitude_m=200.0, depth_m=3.0)
    ev = W.simulate_photon_events(paths, scene, det)
    assert ev.times_s.size > 1000
    for i in range(paths.n_pulses):
        t = ev.shot(i)
        ch = ev.channel[ev.offsets[i] : ev.offsets[i + 1]]
        assert np.all(np.diff(t) >= 0.0)
        for c in range(4):
            # 1e-18 s: the only slack is rounding of t + tau at 2 us
            assert np.all(np.diff(t[ch == c]) >= tau - 1e-18)


def test_dead_time_filter_matches_a_plain_loop():
    rng = np.random.default_rng(5)
    group = rng.integers(0, 40, 5000)
    times = rng.uniform(0.0, 1e-7, 5000)
    tau = 4e-9
    order, kept = dead_time_filter(group, times, tau)
    got = set(order[kept].tolist())
    ref = set()
    for g in range(40):
        idx = np.flatnonzero(group == g)
        idx = idx[np.argsort(times[idx], kind="stable")]
        last = -np.inf
        for i in idx:  # non-paralyzable: only recorded events start a dead period
            if times[i] - last >= tau:
                ref.add(int(i))
                last = times[i]
    assert got == ref


def _chunks(paths: Paths, cuts):
    """Split Paths along the pulse axis at ``cuts``."""
    out = []
    edges = [0, *cuts, paths.n_pulses]
    for lo, hi in zip(edges[:-1], edges[1:], strict=True):
        kw = {}
        for name, val in vars(paths).items():
            per_pulse = name not in ("subray_weight", "subray_offset_rad")
            kw[name] = val[lo:hi] if per_pulse else val
        out.append(Paths(**kw))
    return out


def test_chunking_does_not_change_waveforms_or_events(monkeypatch):
    scene = make_scene(
        background={"solar_irradiance_w_m2_nm": 1.0}, system={"pulse_energy_j": 3e-7}
    )
    depths = np.linspace(0.5, 30.0, 700)
    paths = flat_paths(700, altitude_m=350.0, depth_m=depths, off_nadir_rad=0.2, first_pulse_id=250)
    det = detector(window_s=3e-7, electronic_noise_counts=1.0, strong_return_photoelectrons=50.0)
    pc = replace(det, mode="photon_counting", dead_time_s=2e-9)
    whole_wf = W.simulate_waveforms(paths, scene, det)
    whole_pc = W.simulate_photon_events(paths, scene, pc)
    monkeypatch.setattr(W, "SLICE_PULSES", 97)  # internal slices cross the noise blocks too
    parts = _chunks(paths, [5, 6, 300, 513])
    wf = [W.simulate_waveforms(p, scene, det) for p in parts]
    ev = [W.simulate_photon_events(p, scene, pc) for p in parts]
    np.testing.assert_array_equal(np.concatenate([w.samples for w in wf]), whole_wf.samples)
    np.testing.assert_array_equal(np.concatenate([w.flags for w in wf]), whole_wf.flags)
    np.testing.assert_array_equal(np.concatenate([e.times_s for e in ev]), whole_pc.times_s)
    np.testing.assert_array_equal(np.concatenate([e.channel for e in ev]), whole_pc.channel)
    counts = np.concatenate([np.diff(e.offsets) for e in ev])
    np.testing.assert_array_equal(counts, np.diff(whole_pc.offsets))


def test_seed_changes_the_noise_and_only_the_noise():
    scene = make_scene(system={"pulse_energy_j": 1e-7})
    other = replace(scene, scene=replace(scene.scene, seed=scene.scene.seed + 1))
    paths = flat_paths(50, altitude_m=300.0, depth_m=4.0)
    det = detector(window_s=2e-7, electronic_noise_counts=1.0)
    a = W.simulate_waveforms(paths, scene, det)
    b = W.simulate_waveforms(paths, other, det)
    c = W.simulate_waveforms(paths, scene, det)
    assert not np.array_equal(a.samples, b.samples)
    np.testing.assert_array_equal(a.samples, c.samples)
    np.testing.assert_array_equal(a.t0_s, b.t0_s)


def test_noise_free_waveform_is_gain_times_expected_plus_baseline():
    scene = clean_scene()
    det = detector(window_s=2e-7, counts_per_photoelectron=0.5, baseline_counts=40.0)
    paths = flat_paths(3, altitude_m=300.0, depth_m=[2.0, 5.0, 9.0])
    wf = W.simulate_waveforms(paths, scene, det, noise=False)
    lam = W.expected_waveform(return_budget(paths, scene, det))["total"]
    # float32 storage: 1e-6 relative
    np.testing.assert_allclose(wf.samples, 40.0 + 0.5 * lam, rtol=1e-6)
    times = wf.sample_times_s()
    assert times.shape == wf.samples.shape
    assert np.all(np.diff(times, axis=1) == pytest.approx(1e-9))


def test_digitise_drawn_is_digitise_of_the_sums_bit_for_bit():
    # the one-pass kernel against digitise of the whole-array sums it replaced: drawn counts,
    # strong expectations (or none), saturation and clipping at both ends
    from pipeline.simulate.detector import DetectorSettings
    from pipeline.simulate.receivers import digitise, digitise_drawn

    rng = np.random.default_rng(11)
    det = DetectorSettings(
        bit_depth=12, baseline_counts=11.0, counts_per_photoelectron=7.7, excess_noise_factor=1.3,
        electronic_noise_counts=2.1,
    )  # fmt: skip
    n, m = 64, 300
    drawn = rng.poisson(rng.uniform(0.0, 40.0, (n, 1)), (n, m)).astype(np.int64)
    mu = rng.exponential(30.0, (n, m)) * (rng.random((n, 1)) < 0.7)
    mu[:3] = 800.0  # saturated rows
    z = rng.standard_normal((n, m), dtype=np.float32) * 3.0  # some below 0 after rounding
    f = det.excess_noise_factor
    for strong in (mu, None):
        u = np.zeros((n, m)) if strong is None else strong
        k = drawn.astype(np.float64)
        want, want_sat = digitise(det, k + u, (f - 1.0) * k + f * u, z)
        got, got_sat = digitise_drawn(det, drawn.ravel(), strong, z)
        assert got.tobytes() == want.tobytes()
        assert np.array_equal(got_sat, want_sat)
        if strong is not None:
            assert want_sat[:3].all()  # the clipped rows are there
        assert (got == 0.0).any()  # and the floor
