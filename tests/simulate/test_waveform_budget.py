"""The return budget against independent lidar equations (noise off)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import quad
from waveform_support import (
    C_LIGHT,
    clean_scene,
    common_pe,
    detector,
    fresnel_unpolarised_t,
    make_scene,
    numeric_domega_per_area,
    surface_sr,
)

from pipeline import lidar_equation as le
from pipeline.simulate import paths as P
from pipeline.simulate.budget import ReturnSettings, return_budget
from pipeline.simulate.flat_paths import flat_paths
from pipeline.simulate.geometry import log_aperture_factor, log_column_integral
from pipeline.simulate.waveform import expected_waveform


def _sums(paths, scene, det=None, rs=None):
    b = return_budget(paths, scene, det or detector(), rs)
    return b, {k: v.sum(axis=1) for k, v in expected_waveform(b).items()}


@pytest.mark.parametrize("depth_m", [0.05, 1.0, 12.0, 40.0])
def test_nadir_terms_equal_lidar_equation_and_nadir_budget(depth_m):
    scene = clean_scene()
    h = 400.0
    paths = flat_paths(1, altitude_m=h, depth_m=depth_m, air_index=1.0)
    b, sums = _sums(paths, scene)
    nb = le.nadir_budget(scene, h, depth_m)
    w = scene.water
    # independent: photons x efficiencies x aperture x two-way air x the return's own factors
    base = common_pe(scene) * math.exp(-2 * scene.atmosphere.extinction_per_m * h)
    t0 = fresnel_unpolarised_t(1.0, w.phase_index, 0.0)
    surface = base * surface_sr(scene, 0.0) / h**2
    floor = base * t0**2 * math.exp(-2 * w.extinction_per_m * depth_m) * 0.25 / math.pi
    floor /= (w.phase_index * h + depth_m) ** 2

    def dens(z):
        return (
            base
            * t0**2
            * w.backscatter_180_per_m_sr
            * math.exp(-2 * w.extinction_per_m * z)
            / (w.phase_index * h + z) ** 2
        )

    column = quad(dens, 0.0, depth_m, epsabs=0, epsrel=1e-13)[0]
    # 1e-6: the brief's bound; the sums telescope CDFs, so only rounding (~1e-14) remains
    assert sums["surface"][0] == pytest.approx(surface, rel=1e-6)
    assert sums["bottom"][0] == pytest.approx(floor, rel=1e-6)
    assert sums["column"][0] == pytest.approx(column, rel=1e-6)
    assert sums["surface"][0] == pytest.approx(nb.surface_photons, rel=1e-6)
    assert sums["bottom"][0] == pytest.approx(nb.floor_photons, rel=1e-6)
    # the log budget itself agrees to rounding
    assert b.log_bottom[0, 0] == pytest.approx(nb.floor_log_photons, abs=1e-12)


def test_air_index_enters_as_relative_index():
    # with n_air != 1 the n^2 law uses n_w / n_air: the floor is the A / ((n_w/n_a) H + D)^2
    # of both the waveform budget and nadir_budget, i.e. ((n_w H + D) / (n_w H / n_a + D))^2
    # above the n_air = 1 formula
    scene = make_scene(atmosphere={"refractive_index": 1.000277})
    h, d = 500.0, 12.0
    b = return_budget(flat_paths(1, altitude_m=h, depth_m=d, air_index=1.000277), scene, detector())
    nw = scene.water.phase_index
    # 1e-12: two log sums of ~10 terms; the Fresnel terms use the same indices on both sides
    got = b.log_bottom[0, 0] - le.nadir_budget(scene, h, d).floor_log_photons
    assert got == pytest.approx(0.0, abs=1e-12)
    scene1 = make_scene(atmosphere={"refractive_index": 1.0})
    ratio = ((nw * h + d) / (nw / 1.000277 * h + d)) ** 2
    diff = b.log_bottom[0, 0] - le.nadir_budget(scene1, h, d).floor_log_photons
    fresnel = 2 * (
        math.log1p(-(((1.000277 - nw) / (1.000277 + nw)) ** 2))
        - math.log1p(-(((1.0 - nw) / (1.0 + nw)) ** 2))
    )
    # the air-index change moves only the geometry, the air Fresnel loss and nothing else
    assert diff == pytest.approx(math.log(ratio) + fresnel, abs=1e-9)


@pytest.mark.parametrize(
    ("theta_deg", "air_range", "water_path"),
    [(5.0, 600.0, 10.0), (20.0, 400.0, 25.0), (60.0, 80.0, 3.0)],
)
def test_slant_aperture_factor_matches_ray_bundle_jacobian(theta_deg, air_range, water_path):
    na, nw = 1.000277, 1.3415
    ref = numeric_domega_per_area(air_range, water_path, math.radians(theta_deg), na, nw)
    got = math.exp(
        float(log_aperture_factor(air_range, water_path, math.cos(math.radians(theta_deg)), na, nw))
    )
    # 1e-7: central differences with h = 1e-6 rad carry O(h^2) and rounding ~1e-10/1e-6
    assert got == pytest.approx(ref, rel=1e-7)


@pytest.mark.parametrize("c", [0.0, 1e-3, 0.05, 0.3, 5.0])
@pytest.mark.parametrize(
    ("r", "length", "theta"), [(20.0, 200.0, 0.0), (600.0, 30.0, 0.4), (150.0, 0.5, 1.2)]
)
def test_column_integral_against_adaptive_quadrature(c, r, length, theta):
    na, nw = 1.000277, 1.3415
    cos_a = math.cos(theta)

    def f(depth):
        return math.exp(-2 * c * depth + float(log_aperture_factor(r, depth, cos_a, na, nw)))

    # split at e-folding depths so quad sees the exponential's scale
    cuts = [x / (2 * c) for x in (0.5, 5.0, 30.0) if c > 0 and x / (2 * c) < length]
    edges = [0.0, *cuts, length]
    ref = sum(
        quad(f, a, b, epsabs=0, epsrel=1e-13, limit=200)[0]
        for a, b in zip(edges[:-1], edges[1:], strict=True)
    )
    got = math.exp(float(log_column_integral(c, length, r, cos_a, na, nw)))
    # 1e-9: Gauss-Laguerre / exponential-integral / Gauss-Legendre errors are below 1e-10
    assert got == pytest.approx(ref, rel=1e-9)


def test_tilted_footprint_terms_sum_over_subrays():
    # 7 sub-rays, 20 deg off nadir, 1 mrad beam: every term equals the sum over sub-rays of the
    # independent lidar equation with the numerically derived aperture factor
    scene = make_scene(
        atmosphere={"extinction_per_m": 2e-4, "refractive_index": 1.000277},
        water={"extinction_per_m": 0.12, "backscatter_180_per_m_sr": 3e-3, "wind_speed_m_s": 6.0},
        background={"solar_irradiance_w_m2_nm": 1.0},
    )
    det = detector()
    paths = flat_paths(
        2, altitude_m=500.0, depth_m=[8.0, 25.0], off_nadir_rad=math.radians(20), n_sub=7,
        divergence_rad=1e-3, air_index=1.000277, water_phase_index=scene.water.phase_index,
    )  # fmt: skip
    b, sums = _sums(paths, scene, det)
    w, na = scene.water, scene.atmosphere.refractive_index
    alpha = scene.atmosphere.extinction_per_m
    for i in range(2):
        surf = bottom = column = 0.0
        for j in range(paths.n_sub):
            r = paths.air_range_m[i, j]
            th = paths.incidence_rad[i, j]
            length = paths.water_path_m[i, j]
            base = common_pe(scene) * paths.subray_weight[j] * math.exp(-2 * alpha * r)
            surf += base * surface_sr(scene, th) / r**2
            t_dn = fresnel_unpolarised_t(na, w.phase_index, th)
            th_w = math.asin(na / w.phase_index * math.sin(th))
            t_up = fresnel_unpolarised_t(w.phase_index, na, th_w)
            cos_b = math.cos(paths.bottom_incidence_rad[i, j])
            dom = numeric_domega_per_area(r, length, th, na, w.phase_index)
            bottom += (
                base
                * t_dn
                * t_up
                * math.exp(-2 * w.extinction_per_m * length)
                * (scene.seabed.reflectance * cos_b / math.pi)
                * dom
            )

            def dens(z, r=r, th=th, base=base, t_dn=t_dn):
                d = numeric_domega_per_area(r, z, th, na, w.phase_index)
                att = math.exp(-2 * w.extinction_per_m * z)
                # T_up of the column by reciprocity: the unpolarised T_down at the same angles
                return base * t_dn**2 * w.backscatter_180_per_m_sr * att * d

            column += quad(dens, 0.0, length, epsabs=0, epsrel=1e-10, limit=200)[0]
        # 1e-6: brief's bound; the numerical Jacobian itself is good to ~1e-9 here
        assert sums["surface"][i] == pytest.approx(surf, rel=1e-6)
        assert sums["bottom"][i] == pytest.approx(bottom, rel=1e-6)
        assert sums["column"][i] == pytest.approx(column, rel=1e-6)
    # background: solar (the reference document's radiometry) + dark, uniform over the window
    r_mean = float(np.sum(paths.subray_weight * paths.air_range_m[0]))
    bg_rate = le.solar_background_rate_hz(scene, 0.0) * math.exp(-alpha * r_mean)
    bg_rate += scene.system.dark_count_rate_hz
    assert sums["background"][0] == pytest.approx(bg_rate * det.window_s, rel=1e-6)


def test_bottom_energy_decays_as_exp_minus_2kd_over_range_squared():
    # noise-free bottom energies at 12 depths; fitted slope of ln(E (n H + D)^2) is -2k
    k = 0.11
    scene = clean_scene(extinction_per_m=k, backscatter_180_per_m_sr=0.0)
    h = 300.0
    depths = np.linspace(1.0, 40.0, 12)
    paths = flat_paths(depths.size, altitude_m=h, depth_m=depths, air_index=1.0)
    _, sums = _sums(paths, scene)
    y = np.log(sums["bottom"] * (scene.water.phase_index * h + depths) ** 2)
    slope = np.polyfit(depths, y, 1)[0]
    # 1 %: the brief's bound (noise-free, the fit is exact to ~1e-12)
    assert -slope == pytest.approx(2 * k, rel=0.01)


def test_surface_glint_follows_cox_munk_with_angle():
    scene = clean_scene(wind_speed_m_s=7.0)
    angles = np.radians([0.0, 5.0, 10.0, 15.0, 20.0])
    paths = flat_paths(
        angles.size, altitude_m=400.0, depth_m=10.0, off_nadir_rad=angles, air_index=1.0
    )
    _, sums = _sums(paths, scene)
    ref = [
        common_pe(scene)
        * math.exp(-2 * scene.atmosphere.extinction_per_m * 400 / math.cos(a))
        * surface_sr(scene, a)
        / (400 / math.cos(a)) ** 2
        for a in angles
    ]
    # 1e-6: closed-form Cox-Munk facet density, same as the nadir test
    np.testing.assert_allclose(sums["surface"], ref, rtol=1e-6)


@pytest.mark.parametrize(("resolved", "residual"), [(0.03, 0.0242), (0.06, 0.003)])
def test_resolved_waves_use_the_residual_slope_variance(resolved, residual):
    # Cox-Munk at 10 m/s: 0.003 + 5.12e-3 * 10 = 0.0542; what the mesh resolves is removed,
    # down to the 0.003 clean-sea floor
    scene = clean_scene(wind_speed_m_s=10.0)
    paths = flat_paths(1, altitude_m=400.0, depth_m=10.0, off_nadir_rad=0.1, air_index=1.0)
    full = return_budget(paths, scene, detector()).log_surface[0, 0]
    rs = ReturnSettings(resolved_mean_square_slope=resolved)
    part = return_budget(paths, scene, detector(), rs).log_surface[0, 0]
    cover = 2.95e-6 * 10.0**3.52
    r0 = ((1.3415 - 1) / (1.3415 + 1)) ** 2
    c = math.cos(0.1)

    def glint(mss):
        return (1 - cover) * r0 * math.exp(-(math.tan(0.1) ** 2) / mss) / (4 * math.pi * mss * c**5)

    foam = cover * 0.22 * c / math.pi
    expected = math.log(glint(residual) + foam) - math.log(glint(0.0542) + foam)
    # 1e-12: both are sums of the same log terms apart from the backscatter factor
    assert part - full == pytest.approx(expected, abs=1e-12)


def test_land_subrays_return_table1_graybody():
    scene = clean_scene()
    paths = flat_paths(1, altitude_m=300.0, depth_m=-4.0, air_index=1.0)  # land 4 m above water
    assert paths.flags[0, 0] == P.LAND
    b, sums = _sums(paths, scene)
    r = 296.0
    rho = (0.325) ** 2  # desert sand, middle of Table 1's 25-40 % amplitude range, squared
    ref = (
        common_pe(scene)
        * math.exp(-2 * scene.atmosphere.extinction_per_m * r)
        * rho
        / math.pi
        / r**2
    )
    # 1e-6: closed form
    assert sums["land"][0] == pytest.approx(ref, rel=1e-6)
    assert sums["surface"][0] == 0.0 and sums["bottom"][0] == 0.0 and sums["column"][0] == 0.0
    grass = ReturnSettings(land_surface="grass", land_reflectivity_position=1.0)
    b2 = return_budget(paths, scene, detector(), grass)
    assert b2.log_land[0, 0] - b.log_land[0, 0] == pytest.approx(2 * math.log(25 / 32.5), abs=1e-12)


def test_times_use_group_index_in_water_and_air_index_in_air():
    scene = make_scene(atmosphere={"refractive_index": 1.0003})
    paths = flat_paths(1, altitude_m=250.0, depth_m=7.0, air_index=1.0003)
    b = return_budget(paths, scene, detector())
    assert b.t_surface_s[0, 0] == pytest.approx(2 * 1.0003 * 250.0 / C_LIGHT, rel=1e-14)
    dt = b.t_bottom_s[0, 0] - b.t_surface_s[0, 0]
    # 1e-12: one subtraction of ~1.7 us values
    assert dt == pytest.approx(2 * scene.water.group_index * 7.0 / C_LIGHT, rel=1e-9)


def test_budget_does_not_modify_paths():
    paths = flat_paths(3, altitude_m=200.0, depth_m=5.0)
    before = {k: np.copy(v) for k, v in vars(paths).items()}
    return_budget(paths, clean_scene(), detector())
    assert all(np.array_equal(before[k], v) for k, v in vars(paths).items())


def test_noisy_bottom_energy_fit_recovers_2k():
    # the same law measured on digitised, noisy waveforms: bottom energy = sum of
    # (samples - baseline) / G around the bottom echo (no column, no sun: nothing else there)
    from pipeline.simulate.waveform import simulate_waveforms

    k = 0.11
    scene = clean_scene(extinction_per_m=k, backscatter_180_per_m_sr=0.0)
    h, per_depth = 300.0, 400
    depths = np.repeat(np.linspace(2.0, 14.0, 7), per_depth)
    paths = flat_paths(depths.size, altitude_m=h, depth_m=depths, air_index=1.0)
    det = detector(window_s=2.5e-7, pre_trigger_s=2e-8, counts_per_photoelectron=2.0,
                   electronic_noise_counts=1.0, excess_noise_factor=1.3, bit_depth=16)  # fmt: skip
    wf = simulate_waveforms(paths, scene, det)
    b = return_budget(paths, scene, det)
    i_b = np.rint((b.t_bottom_s[:, 0] - b.t0_s) / det.sample_interval_s).astype(int)
    cols = i_b[:, None] + np.arange(-8, 9)  # +-8 samples: > 8 sigma of the ~1 ns echo
    energy = (np.take_along_axis(wf.samples, cols, axis=1) - det.baseline_counts).sum(1) / 2.0
    mean_e = energy.reshape(-1, per_depth).mean(axis=1)
    d = depths[::per_depth]
    slope = np.polyfit(d, np.log(mean_e * (scene.water.phase_index * h + d) ** 2), 1)[0]
    # 1 %: the brief's bound; the statistical error of the slope here is ~0.3 %
    assert -slope == pytest.approx(2 * k, rel=0.01)
