import math

import numpy as np
import pytest

from pipeline import lidar_equation as le
from pipeline import profiler

# Independent constants (CODATA 2018 exact values), not taken from the code under test.
H_PLANCK = 6.62607015e-34
C_LIGHT = 299_792_458.0


def _independent_log10_photons(scene, depth_m):
    """The lidar equation as a sum of base-10 logarithms, from the scene values alone."""
    s, a, w = scene.system, scene.atmosphere, scene.water
    h = scene.profiler.altitude_m
    lam = s.wavelength_nm * 1e-9
    r0 = ((a.refractive_index - w.phase_index) / (a.refractive_index + w.phase_index)) ** 2
    aperture = math.pi * s.telescope_diameter_m**2 / 4.0
    common = [
        math.log10(s.pulse_energy_j / (H_PLANCK * C_LIGHT / lam)),
        math.log10(s.transmitter_efficiency * s.receiver_efficiency * s.overlap_factor),
        -2.0 * a.extinction_per_m * h / math.log(10.0),
        math.log10(aperture),
    ]
    mss = 0.003 + 0.00512 * w.wind_speed_m_s
    white = 2.95e-6 * w.wind_speed_m_s**3.52
    surf_sr = (1 - white) * r0 / (4 * math.pi * mss) + white * 0.22 / math.pi
    surface = sum(common) + math.log10(surf_sr) - 2 * math.log10(h)
    floor = (
        sum(common)
        + 2 * math.log10(1 - r0)
        - 2 * w.extinction_per_m * depth_m / math.log(10.0)
        + math.log10(scene.seabed.reflectance / math.pi)
        - 2 * math.log10(w.phase_index * h + depth_m)
    )
    return surface, floor


@pytest.mark.parametrize("depth_m", [0.05, 1.0, 30.0, 100.0])
def test_budget_equals_independent_lidar_equation(reference_scene, depth_m):
    b = le.nadir_budget(reference_scene, reference_scene.profiler.altitude_m, depth_m)
    surface10, floor10 = _independent_log10_photons(reference_scene, depth_m)
    # 1e-9 relative on the photon count = 4.3e-10 in log10; float64 sums are ~1e-15
    assert b.surface_photons == pytest.approx(10**surface10, rel=1e-9)
    assert b.floor_photons == pytest.approx(10**floor10, rel=1e-9)


def test_budget_stays_finite_in_log_space_for_huge_extinction(reference_scene):
    from dataclasses import replace

    murky = replace(reference_scene, water=replace(reference_scene.water, extinction_per_m=50.0))
    b = le.nadir_budget(murky, murky.profiler.altitude_m, 100.0)
    # e^(-2*50*100) = e^-10000 underflows float64; its log must stay exact
    assert math.isfinite(b.floor_log_photons)
    assert b.floor_photons == 0.0
    _, floor10 = _independent_log10_photons(murky, 100.0)
    assert b.floor_log_photons / math.log(10) == pytest.approx(floor10, rel=1e-12)


def test_floor_decay_is_twice_the_extinction(reference_scene):
    h = reference_scene.profiler.altitude_m
    n = reference_scene.water.phase_index
    depths = np.linspace(1.0, 60.0, 30)
    logs = [le.nadir_budget(reference_scene, h, d).floor_log_photons for d in depths]
    # remove the geometric 1/(nH + D)^2 factor, the rest is exp(-2 c D)
    y = np.array(logs) + 2 * np.log(n * h + depths)
    slope = np.polyfit(depths, y, 1)[0]
    assert slope == pytest.approx(-2 * reference_scene.water.extinction_per_m, rel=1e-9)


def test_transmittance_profile_matches_beer_lambert_and_fresnel(reference_scene):
    tp = profiler.transmittance_profile(reference_scene)
    s = reference_scene
    h, d = s.profiler.altitude_m, s.seabed.depth_m
    r0 = ((1.0 - 1.33) / (1.0 + 1.33)) ** 2
    expected_floor = math.exp(-0.0099 * h) * (1 - r0) * math.exp(-0.0199 * d)
    assert math.exp(tp.log_transmittance[-1]) == pytest.approx(expected_floor, rel=1e-12)
    at_surface = tp.log_transmittance[np.searchsorted(tp.path_m, h)]
    assert math.exp(at_surface) == pytest.approx(math.exp(-0.0099 * h), rel=1e-12)


def test_ideal_times_of_flight(reference_scene):
    s = reference_scene
    t = profiler.ideal_times(s, [0.05, 10.0, 50.0])
    h = s.profiler.altitude_m
    assert t["t_surface_s"][0] == pytest.approx(2 * h * 1.00 / C_LIGHT, rel=1e-14)
    assert t["t_floor_s"][1] - t["t_surface_s"][1] == pytest.approx(2 * 10.0 * 1.33 / C_LIGHT)
    np.testing.assert_allclose(t["depth_from_tof_m"], [0.05, 10.0, 50.0], rtol=1e-9)


def test_phase_index_for_travel_time_biases_depth(reference_scene):
    from dataclasses import replace

    s = replace(
        reference_scene,
        water=replace(reference_scene.water, phase_index=1.3415, group_index=1.3638),
    )
    t = profiler.ideal_times(s, [10.0])
    # errata: using the phase index for time of flight biases depth by n_g/n - 1 = 1.66 %
    assert t["depth_if_phase_index_m"][0] / 10.0 - 1 == pytest.approx(1.3638 / 1.3415 - 1)


def test_expected_histogram_conserves_photons(reference_scene):
    gate = profiler.range_gate(reference_scene)
    exp = profiler.expected_histogram(reference_scene, gate)
    # the gate spans ±50 ns around returns of σ = 0.42 ns: all of each pulse is inside
    assert exp["surface"].sum() == pytest.approx(gate.surface_photons, rel=1e-12)
    assert exp["floor"].sum() == pytest.approx(gate.floor_photons, rel=1e-12)
    assert exp["column"].sum() == pytest.approx(gate.column_photons, rel=1e-9)
    assert exp["background"].sum() == pytest.approx(gate.background_rate_hz * gate.duration_s)


def _poisson_sample_variance_sigma(lam, r):
    # Var(s^2) = mu4/r - sigma^4 (r-3)/(r(r-1)); Poisson: sigma^2 = lam, mu4 = lam + 3 lam^2
    return math.sqrt((lam + 3 * lam**2) / r - lam**2 * (r - 3) / (r * (r - 1)))


@pytest.mark.parametrize("n_shots", [1, 10, 100, 1000, 10000])
def test_accumulated_counts_are_poisson_with_mean_n_lambda(reference_scene, n_shots):
    gate = profiler.range_gate(reference_scene)
    exp = profiler.expected_histogram(reference_scene, gate)
    centres = 0.5 * (gate.edges_s[1:] + gate.edges_s[:-1])
    windows = {
        "surface": np.abs(centres - gate.t_surface_s) <= 1e-9,
        "floor": np.abs(centres - gate.t_floor_s) <= 1e-9,
        "gate": np.ones(centres.size, bool),
    }
    reps = 400
    rng = np.random.default_rng([7, n_shots])
    sims = np.array(
        [profiler.simulate_histogram(reference_scene, gate, n_shots, rng) for _ in range(reps)]
    )
    for name, win in windows.items():
        lam = n_shots * exp["total"][win].sum()
        counts = sims[:, win].sum(axis=1)
        mean_sigma = math.sqrt(lam / reps)
        assert abs(counts.mean() - lam) <= 3 * mean_sigma, (name, counts.mean(), lam)
        var_sigma = _poisson_sample_variance_sigma(lam, reps)
        assert abs(counts.var(ddof=1) - lam) <= 3 * var_sigma, (name, counts.var(ddof=1), lam)


def test_direct_poisson_sums_match_event_simulation(reference_scene):
    # the shortcut for bright scenes draws Poisson(N λ) per bin: same mean and variance as
    # summing per-shot events; compared here on the reference scene with the shortcut forced
    gate = profiler.range_gate(reference_scene)
    exp = profiler.expected_histogram(reference_scene, gate)
    rng = np.random.default_rng(12)
    sims = np.array(
        [
            profiler.simulate_histogram(
                reference_scene, gate, 1000, rng, max_events=0.0, expected_total=exp["total"]
            ).sum()
            for _ in range(400)
        ]
    )
    lam = 1000 * exp["total"].sum()
    assert abs(sims.mean() - lam) <= 3 * math.sqrt(lam / 400)
    assert abs(sims.var(ddof=1) - lam) <= 3 * _poisson_sample_variance_sigma(lam, 400)
