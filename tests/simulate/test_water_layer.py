"""The scattering layer's echo against an independent lidar equation, and its extremes."""

from __future__ import annotations

import dataclasses
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
)

from pipeline.errors import SceneError
from pipeline.simulate import paths as P
from pipeline.simulate import waveform as W
from pipeline.simulate.budget import layer_echo, return_budget
from pipeline.simulate.flat_paths import flat_paths
from pipeline.simulate.geometry import LOG_ZERO

SIGMA_PER_FWHM = 1.0 / (2.0 * math.sqrt(2.0 * math.log(2.0)))


def _layer(depth_m, thickness_m, beta=0.01, **water):
    return {
        "layer_depth_m": depth_m,
        "layer_thickness_m": thickness_m,
        "layer_backscatter_per_m_sr": beta,
        **water,
    }


def _moments(f, a, b):
    """Integral, mean and variance of the density ``f`` on ``[a, b]`` by adaptive quadrature."""
    kw = {"epsabs": 0, "epsrel": 1e-13, "limit": 200}
    m0 = quad(f, a, b, **kw)[0]
    m1 = quad(lambda z: z * f(z), a, b, **kw)[0] / m0
    m2 = quad(lambda z: (z - m1) ** 2 * f(z), a, b, **kw)[0] / m0
    return m0, m1, m2


@pytest.mark.parametrize(
    ("bottom_m", "layer_m", "thick_m", "c"),
    [
        (10.0, 4.0, 1.0, 0.15),  # the brief's case
        (40.0, 20.0, 3.0, 0.3),  # deep and thick: e^-12 at the layer
        (10.0, 9.8, 1.0, 0.15),  # straddles the seabed: the echo stops at 10 m
        (10.0, 4.0, 2.0, 0.0),  # no extinction
        (10.0, 0.25, 0.5, 0.15),  # touches the surface
        (10.0, 4.0, 1.0, 5.0),  # 10 attenuation lengths across the slab: the top dominates
    ],
)
def test_nadir_layer_echo_equals_hand_lidar_equation(bottom_m, layer_m, thick_m, c):
    scene = clean_scene(extinction_per_m=c, **_layer(layer_m, thick_m))
    h = 400.0
    paths = flat_paths(1, altitude_m=h, depth_m=bottom_m, air_index=1.0)
    b = return_budget(paths, scene, detector())
    sums = {k: v.sum(axis=1) for k, v in W.expected_waveform(b).items()}
    w, sysm = scene.water, scene.system
    # independent: photons x efficiencies x aperture x two-way air x T_down T_up x beta_L x
    # the in-water integral over the slab with the n^2 aperture law A / (n H + z)^2
    base = common_pe(scene) * math.exp(-2 * scene.atmosphere.extinction_per_m * h)
    t0 = fresnel_unpolarised_t(1.0, w.phase_index, 0.0)

    def dens(z):
        return math.exp(-2 * c * z) / (w.phase_index * h + z) ** 2

    top, end = max(layer_m - thick_m / 2, 0.0), min(layer_m + thick_m / 2, bottom_m)
    m0, mean, var = _moments(dens, top, end)
    ref = base * t0**2 * w.layer_backscatter_per_m_sr * m0
    # 1e-6: the brief's bound for the budget terms; the 6-node rule is exact to ~1e-12 here
    assert sums["layer"][0] == pytest.approx(ref, rel=1e-6)
    assert b.totals()["layer"][0] == pytest.approx(ref, rel=1e-6)
    # timing: the echo's mean path at the group speed; width: pulse, detector and the slab's
    # spread of paths (the frozen test scene has no forward-scattering delay)
    to_time = 2 * w.group_index / C_LIGHT
    assert b.t_layer_s[0, 0] - b.t_surface_s[0, 0] == pytest.approx(to_time * mean, rel=1e-9)
    sig2 = (sysm.pulse_fwhm_s * SIGMA_PER_FWHM) ** 2 + (1e-9 * SIGMA_PER_FWHM) ** 2
    assert b.sigma_layer_s[0, 0] ** 2 == pytest.approx(sig2 + to_time**2 * var, rel=1e-9)


def test_layer_echo_sums_over_slant_subrays():
    # 7 sub-rays at 20 deg: each crosses the slab along its refracted ray (path thickness /
    # cos theta_w), with the numerically derived aperture factor of the column test
    scene = make_scene(
        atmosphere={"extinction_per_m": 2e-4, "refractive_index": 1.000277},
        water={"extinction_per_m": 0.12, "backscatter_180_per_m_sr": 3e-3, **_layer(6.0, 1.5)},
    )
    w, na = scene.water, scene.atmosphere.refractive_index
    paths = flat_paths(
        1, altitude_m=500.0, depth_m=25.0, off_nadir_rad=math.radians(20), n_sub=7,
        divergence_rad=1e-3, air_index=na, water_phase_index=w.phase_index,
    )  # fmt: skip
    b = return_budget(paths, scene, detector())
    got = W.expected_waveform(b)["layer"].sum()
    ref = 0.0
    for j in range(paths.n_sub):
        r, th = paths.air_range_m[0, j], paths.incidence_rad[0, j]
        th_w = math.asin(na / w.phase_index * math.sin(th))
        base = common_pe(scene) * paths.subray_weight[j] * math.exp(-2 * 2e-4 * r)
        t_dn = fresnel_unpolarised_t(na, w.phase_index, th)

        def dens(length, r=r, th=th):
            d = numeric_domega_per_area(r, length, th, na, w.phase_index)
            return math.exp(-2 * w.extinction_per_m * length) * d

        lo, hi = (6.0 - 0.75) / math.cos(th_w), (6.0 + 0.75) / math.cos(th_w)
        seg = quad(dens, lo, hi, epsabs=0, epsrel=1e-10)[0]
        ref += base * t_dn**2 * w.layer_backscatter_per_m_sr * seg
    # 1e-6: as the column's slant test; the numerical Jacobian is good to ~1e-9
    assert got == pytest.approx(ref, rel=1e-6)


def test_layer_only_adds_components():
    # the surface, bottom, column and background components are those of the layer-free scene
    paths = flat_paths(4, altitude_m=300.0, depth_m=[2.0, 5.0, 9.0, 20.0], n_sub=1)
    plain = return_budget(paths, clean_scene(), detector())
    layered = return_budget(paths, clean_scene(**_layer(4.0, 1.0)), detector())
    assert not plain.has_layer and plain.log_layer is None
    c0, t0 = W.build_components(plain)
    c1, t1 = W.build_components(layered)
    keep = t1 != W.TYPES.index("layer")
    # per sub-ray: surface, undelayed bottom, delayed bottom tail (+ layer); column, background
    assert t0.size == 5 and t1.size == 6 and np.array_equal(t1[keep], t0)
    for f in dataclasses.fields(c0):
        assert np.array_equal(getattr(c1, f.name)[:, keep], getattr(c0, f.name)), f.name
    # the layer below the 2 m seabed gives nothing; the others are in the layer
    assert np.array_equal(layered.log_layer[:, 0] > LOG_ZERO, [False, True, True, True])


def test_layer_below_seabed_and_huge_extinction_stay_finite():
    det = detector(window_s=3e-7)
    paths = flat_paths(50, altitude_m=300.0, depth_m=np.linspace(1.0, 30.0, 50))
    # below every seabed: no echo at all
    deep = return_budget(paths, clean_scene(**_layer(40.0, 2.0)), det)
    assert np.all(deep.log_layer == LOG_ZERO) and np.all(deep.totals()["layer"] == 0.0)
    # c = 100 1/m: the echo underflows in linear space but its logarithm is exact and finite
    scene = clean_scene(extinction_per_m=100.0, **_layer(4.0, 1.0))
    b = return_budget(paths, scene, det)
    present = b.log_layer > LOG_ZERO
    assert present[paths.water_path_m > 3.5].all()
    assert np.all(np.isfinite(b.log_layer)) and np.all(np.isfinite(b.sigma_layer_s))
    # exp(-2 c l1) at the layer's top alone is e^-700: at the bottom of float's range
    assert np.all(b.log_layer[present] < -600.0)
    assert np.all(b.totals()["layer"] < 1e-250)
    wf = W.simulate_waveforms(paths, scene, det)
    ev = W.simulate_photon_events(paths, scene, dataclasses.replace(det, mode="photon_counting"))
    assert np.all(np.isfinite(wf.samples)) and np.all(np.isfinite(ev.times_s))


def test_layer_without_seabed_and_in_a_wave_trough():
    scene = clean_scene(**_layer(4.0, 1.0))
    paths = flat_paths(2, altitude_m=300.0, depth_m=10.0, air_index=1.0)
    # pulse 0 found no seabed: the slab is crossed whole; pulse 1's surface hit is in a trough
    # 3.8 m below the mean level, inside the slab: the echo starts at the surface
    flags = paths.flags.copy()
    flags[0] = P.NO_BOTTOM
    surf = paths.surface_xyz_m.copy()
    surf[1, :, 2] = -3.8
    odd = dataclasses.replace(
        paths, flags=flags, water_path_m=np.where(flags == P.OK, paths.water_path_m, 0.0),
        surface_xyz_m=surf,
    )  # fmt: skip
    lay = layer_echo(odd, scene.water, 0.0, 1.0)
    assert lay.present.all()
    c = scene.water.extinction_per_m
    # path means: the slab's [3.5, 4.5] m, and [0, 0.7] m below the trough, each weighted by
    # exp(-2 c l) (the aperture term changes by < 1e-2 across them)
    for row, (a, b) in enumerate([(3.5, 4.5), (0.0, 0.7)]):
        _, mean, _ = _moments(lambda z: math.exp(-2 * c * z), a, b)
        assert lay.path_mean_m[row, 0] == pytest.approx(mean, abs=2e-3)


def test_both_receivers_carry_the_layer():
    # one photon model: photon-counting events (no dead time) and full-waveform samples in
    # a window around the layer echo both have the expected waveform's mean there
    scene = make_scene(
        water={"extinction_per_m": 0.15, "backscatter_180_per_m_sr": 2e-3, **_layer(4.0, 0.5)},
        background={"solar_irradiance_w_m2_nm": 1.0},
        system={"pulse_energy_j": 2.5e-7},
    )
    n = 4000
    paths = flat_paths(n, altitude_m=300.0, depth_m=10.0)
    det = detector(window_s=2.5e-7, pre_trigger_s=2e-8, bit_depth=16, baseline_counts=500.0)
    b = return_budget(paths, scene, det)
    exp = W.expected_waveform(b)
    i_l = round((b.t_layer_s[0, 0] - b.t0_s[0]) / det.sample_interval_s)
    lo, hi = i_l - 6, i_l + 7  # +-2.3 sigma of the 2.6 ns echo
    lam = exp["total"][0, lo:hi].sum()
    assert exp["layer"][0, lo:hi].sum() > 0.5 * lam  # the window is mostly the layer
    pc = dataclasses.replace(det, mode="photon_counting", dead_time_s=0.0)
    ev = W.simulate_photon_events(paths, scene, pc)
    shot = np.repeat(np.arange(n), np.diff(ev.offsets))
    k = np.floor((ev.times_s - b.t0_s[shot]) / det.sample_interval_s + 0.5)
    counts = np.bincount(shot[(k >= lo) & (k < hi)], minlength=n)
    # 3 sigma of the mean of n Poisson counts
    assert abs(counts.mean() - lam) < 3 * math.sqrt(lam / n)
    wf = W.simulate_waveforms(paths, scene, det)
    g, f = det.counts_per_photoelectron, det.excess_noise_factor
    s = wf.samples[:, lo:hi].astype(np.float64).sum(axis=1) - (hi - lo) * det.baseline_counts
    var = f * g * g * lam + (hi - lo) * (det.electronic_noise_counts**2 + 1 / 12)
    assert abs(s.mean() - g * lam) < 3 * math.sqrt(var / n)


@pytest.mark.parametrize(
    ("water", "match"),
    [
        ({"layer_depth_m": 4.0}, r"`water.layer_backscatter_per_m_sr` must be > 0"),
        ({"layer_backscatter_per_m_sr": 0.01}, r"`water.layer_depth_m` must be > 0"),
        (_layer(1.0, 3.0), r"`water.layer_thickness_m` must be <= 2 x .* = 2.0 m.*got 3.0"),
        ({"layer_thickness_m": 0.0}, r"`water.layer_thickness_m` must be > 0"),
        ({"layer_depth_m": -1.0}, r"`water.layer_depth_m` must be >= 0"),
    ],
)
def test_bad_layer_settings_name_key_value_and_rule(water, match):
    with pytest.raises(SceneError, match=match):
        make_scene(water={"extinction_per_m": 0.1, **water})
