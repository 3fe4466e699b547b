"""Propagated uncertainty: analytic terms at nadir, Monte Carlo through refraction.py, rigid
navigation, the timing sigma against the waveform model's Fisher information."""

import dataclasses
import hashlib
import math

import numpy as np
import pytest
from scipy import constants

from pipeline.process.refraction import RefractionSettings, seabed_points
from pipeline.process.returns import DetectedReturns
from pipeline.process.surface_fit import SurfaceFitSettings, fit_water_surface
from pipeline.process.tpu import (
    CORRELATED_TERMS,
    RANDOM_TERMS,
    TpuSettings,
    cox_munk_slope_sigma,
    index_derivatives,
    monte_carlo_points,
    point_tpu,
    timing_sigma_s,
)
from pipeline.process.waveform_model import WaveformSystem, expected_waveform, fisher_information

C = constants.c
N_AIR, N_W, N_G = 1.000277, 1.3415, 1.3638
RST = RefractionSettings(phase_index=N_W, group_index=N_G)
FIT = SurfaceFitSettings(air_index=N_AIR)
ALT = 400.0


def survey(n_side=12, wave_m=0.0, seed=1):
    """Beams up to 20° off nadir over water at z = 0 and a 12 m flat seabed; the surface
    returns carry ``wave_m`` of wave height and 0.1 ns of timing noise, so that the fit
    has its own uncertainty."""
    rng = np.random.default_rng(seed)
    g = (np.arange(n_side) - n_side / 2) * 1.5
    ex, ey = (a.ravel() for a in np.meshgrid(g, g))
    n = ex.size
    inc = np.radians(rng.uniform(0.0, 20.0, n))
    inc[0] = 0.0
    az = rng.uniform(0.0, 2 * np.pi, n)
    d = np.column_stack([np.sin(az) * np.sin(inc), np.cos(az) * np.sin(inc), -np.cos(inc)])
    r_air = ALT / np.cos(inc)
    o = np.column_stack([ex, ey, np.zeros(n)]) - d * r_air[:, None]
    sw = N_AIR * np.sin(inc) / N_W
    length = 12.0 / np.sqrt(1.0 - sw**2)
    waves = rng.normal(0.0, wave_m, n) if wave_m else np.zeros(n)
    t_s = 2.0 * (r_air - waves / np.cos(inc)) * N_AIR / C + rng.normal(0, 1e-10, n)
    t_b = 2.0 * r_air * N_AIR / C + 2.0 * length * N_G / C
    ret = DetectedReturns(
        pulse_id=np.arange(n),
        origin_meas_m=o,
        direction_meas=d,
        has_surface=np.ones(n, bool),
        t_surface_s=t_s,
        has_bottom=np.ones(n, bool),
        t_bottom_s=t_b,
        surface_confidence=np.full(n, 0.9),
        bottom_confidence=np.full(n, 0.9),
        flags=np.zeros(n, np.uint16),
    )
    return ret, fit_water_surface(ret, FIT)


def test_nadir_terms_by_hand():
    ret, surf = survey()
    st = TpuSettings(timing_sigma_s=2e-10, wave_slope_sigma_rad=0.0, seabed_slope_deg=10.0)
    tpu = point_tpu(ret, surf, RST, st)
    t = {k: v[0] for k, v in tpu.terms.items()}  # pulse 0 points straight down
    r_air = float(surf.range_to_entry_m[0])
    # one return's timing moves the bottom along the vertical beam by c sigma / (2 n_g)
    assert abs(t["timing_bottom"][2]) == pytest.approx(C * 2e-10 / (2 * N_G), rel=1e-4)
    assert abs(t["timing_surface"][2]) == pytest.approx(C * 2e-10 / (2 * N_G), rel=1e-4)
    np.testing.assert_allclose(t["navigation"], [0.05, 0.05, 0.08])
    # a roll about x turns the 412 m lever arm (0, 0, -R) into a y shift sigma R
    lever = ALT + 12.0
    np.testing.assert_allclose(
        np.abs(t["attitude_x"]), [0, np.radians(0.005) * lever, 0], atol=1e-6
    )
    # nadir: heading turns nothing (the noisy fitted plane tilts the beam by ~1e-8 rad)
    np.testing.assert_allclose(t["heading"], 0.0, atol=1e-5)
    # footprint of a 1 mrad beam: 1e-3 (r_air + L / n_w) / 4 per axis, times tan 10° up
    fp = 1e-3 * (r_air + 12.0 / N_W) / 4.0
    # (the noisy fitted surface sits millimetres off z = 0: 1e-4)
    np.testing.assert_allclose(
        np.abs(t["footprint"]), [fp, fp, fp * math.tan(math.radians(10))], rtol=1e-4
    )
    # the split adds up
    np.testing.assert_allclose(
        tpu.sigma_v_m**2, tpu.sigma_v_random_m**2 + tpu.sigma_v_correlated_m**2, rtol=1e-12
    )
    assert set(tpu.terms) == set(RANDOM_TERMS) | set(CORRELATED_TERMS)


def test_index_derivatives_of_quan_and_fry():
    der = index_derivatives(TpuSettings())
    # 532 nm, 35 psu, 20 °C: dn/dT ~ -1.0e-4 / °C, dn/dS ~ 1.9e-4 / psu (phase); the group
    # index moves ~8 % more
    assert der["temperature"][0] == pytest.approx(-1.03e-4, rel=0.02)
    assert der["salinity"][0] == pytest.approx(1.85e-4, rel=0.02)
    assert der["temperature"][1] / der["temperature"][0] == pytest.approx(1.077, rel=0.02)
    assert cox_munk_slope_sigma(5.0) == pytest.approx(math.sqrt(0.0286 / 2.0), rel=1e-12)


@pytest.fixture(scope="module")
def wavy():
    ret, surf = survey(wave_m=0.05)
    st = TpuSettings(wave_slope_sigma_rad=0.02, seabed_slope_deg=5.0)
    tpu = point_tpu(ret, surf, RST, st)
    mc = monte_carlo_points(ret, surf, RST, st, n_draws=1000, seed=7)
    return ret, surf, tpu, mc


def test_tpu_matches_monte_carlo_through_refraction(wavy):
    _, surf, tpu, mc = wavy
    # 5 cm waves: the fit residual is mostly wave height, not ranging noise
    assert np.mean(surf.fit_sigma_m) > 0.03 and np.mean(tpu.terms["wave_height"][:, 2] != 0) > 0.9
    sd = mc.std(axis=0)
    for axis, sig in enumerate((tpu.sigma_x_m, tpu.sigma_y_m, tpu.sigma_v_m)):
        ratio = sd[:, axis] / sig
        # 1000 draws: each ratio has a 2.2 % sampling sigma; the mean of 144 within 2 %
        # (linearisation error included), each within 12 % (5 sigma)
        assert abs(np.mean(ratio) - 1.0) < 0.02, (axis, np.mean(ratio))
        assert np.all(np.abs(ratio - 1.0) < 0.12), (axis, ratio.min(), ratio.max())
    # and the means: no bias from the full-size perturbations (within 4 standard errors)
    err = mc.mean(axis=0) - tpu.xyz_m
    assert np.all(np.abs(err) < 4 * sd / np.sqrt(1000) + 1e-4)


def test_tpu_interval_coverage(wavy):
    _, _, tpu, mc = wavy
    dz = np.abs(mc[:, :, 2] - tpu.xyz_m[:, 2])
    cover_v = np.mean(dz <= 1.96 * tpu.sigma_v_m)
    dx = np.abs(mc[:, :, 0] - tpu.xyz_m[:, 0])
    cover_x = np.mean(dx <= 1.96 * tpu.sigma_x_m)
    # 144 000 draws, but the 1000 water-index draws are shared by all points: +-1 %
    assert 0.94 < cover_v < 0.96, cover_v
    assert 0.94 < cover_x < 0.96, cover_x


def test_navigation_error_moves_everything_rigidly():
    """A navigation offset shared by the neighbourhood moves the surface points, hence the fit,
    hence the seabed point, by the same vector (the TPU's correlated navigation model)."""
    ret, surf = survey(wave_m=0.03)
    shift = np.array([0.31, -0.17, 0.23])
    moved = dataclasses.replace(ret, origin_meas_m=ret.origin_meas_m + shift)
    p0 = seabed_points(ret, surf, RST).xyz_m
    p1 = seabed_points(moved, fit_water_surface(moved, FIT), RST).xyz_m
    # float64 rounding of 400 m ranges
    np.testing.assert_allclose(p1 - p0, np.broadcast_to(shift, p0.shape), atol=1e-7)


def test_timing_sigma_is_the_cramer_rao_bound_of_a_gaussian_return():
    """sqrt(2) sigma_p / SNR against the model's own Fisher information: white noise (no shot
    noise), one return, fine sampling."""
    system = WaveformSystem(
        sample_interval_s=0.25e-9,
        pulse_fwhm_s=3e-9,
        counts_per_photoelectron=1e-12,
        electronic_noise_counts=3.0,
        quantisation_step_counts=0.0,
    )
    th = np.array([50.0, 30.0, math.log(400.0), -700.0, -700.0, math.log(0.1), 0.0, 0.0, 0.0])
    m = 240
    mu = expected_waveform(th, m, system)
    snr = math.sqrt(np.sum(mu**2)) / 3.0  # matched-filter SNR of the samples
    info = fisher_information(th, m, system)
    sigma_t = 1e-9 / math.sqrt(info[1, 1])  # t_surface is in ns
    assert timing_sigma_s(snr, 3e-9) == pytest.approx(sigma_t, rel=0.01)  # bins: dt²/12 σ²


def test_inputs_are_not_modified():
    ret, surf = survey()
    before = [
        hashlib.sha1(np.ascontiguousarray(a).tobytes()).hexdigest()
        for a in (ret.origin_meas_m, ret.t_bottom_s, surf.entry_m, surf.normal)
    ]
    point_tpu(ret, surf, RST)
    monte_carlo_points(ret, surf, RST, n_draws=3)
    after = [
        hashlib.sha1(np.ascontiguousarray(a).tobytes()).hexdigest()
        for a in (ret.origin_meas_m, ret.t_bottom_s, surf.entry_m, surf.normal)
    ]
    assert before == after


def test_detector_sigmas_are_used():
    ret, surf = survey(n_side=4)
    n = len(ret)
    with_sig = dataclasses.replace(
        ret, t_surface_sigma_s=np.full(n, 3e-10), t_bottom_sigma_s=np.full(n, 5e-10)
    )
    tpu = point_tpu(with_sig, surf, RST)
    assert abs(tpu.terms["timing_bottom"][0, 2]) == pytest.approx(C * 5e-10 / (2 * N_G), rel=1e-4)
    assert abs(tpu.terms["timing_surface"][0, 2]) == pytest.approx(C * 3e-10 / (2 * N_G), rel=1e-4)
