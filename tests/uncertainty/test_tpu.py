"""Propagated uncertainty: analytic terms at nadir, Monte Carlo through refraction.py (the
elevation and the depth below the measured surface), rigid navigation, the timing sigma
against the waveform model's Fisher information, and the estimators from measured soundings
(seabed gradient, pair scatter, timing from scatter, tilt of the plane over the sounding)."""

import dataclasses
import hashlib
import math

import numpy as np
import pytest
from scipy import constants

from pipeline.process.refraction import RefractionSettings, seabed_points
from pipeline.process.returns import DetectedReturns
from pipeline.process.surface_fit import SurfaceFitSettings, fit_water_surface
from pipeline.uncertainty.tpu import (
    CORRELATED_TERMS,
    RANDOM_TERMS,
    TpuSettings,
    cox_munk_slope_sigma,
    index_derivatives,
    monte_carlo_points,
    pair_scatter,
    point_tpu,
    seabed_gradient,
    surface_over_sounding,
    surface_tilt_sigma,
    timing_from_scatter,
    timing_sigma_s,
)
from pipeline.uncertainty.waveform_information import (
    fisher_information,
)
from pipeline.uncertainty.waveform_model import (
    WaveformSystem,
    expected_waveform,
)

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
    # the bottom's timing moves the bottom along the vertical beam by c sigma / (2 n_g), and
    # its depth by as much
    assert abs(t["timing_bottom"][2]) == pytest.approx(C * 2e-10 / (2 * N_G), rel=1e-4)
    assert t["timing_bottom"][3] == pytest.approx(-t["timing_bottom"][2], rel=1e-4)
    # the surface echo's (no detector sigma: the pulse enters at its own echo) moves the entry
    # down the beam by c sigma / (2 n_air) and shortens the path by c sigma / (2 n_g): the
    # point by c sigma (1/n_air - 1/n_g) / 2, and its depth below the unmoved plane as much
    ts = t["timing_surface"]
    assert abs(ts[2]) == pytest.approx(C * 2e-10 / 2 * (1 / N_AIR - 1 / N_G), rel=1e-3)
    assert ts[3] == pytest.approx(-ts[2], rel=1e-3)
    # navigation: a translation moves surface and seabed alike; the depth (flat seabed) keeps
    np.testing.assert_allclose(t["navigation"], [0.05, 0.05, 0.08, 0.0])
    # a roll about x turns the 412 m lever arm (0, 0, -R) into a y shift sigma R; the depth
    # below the turned plane keeps (second order)
    lever = ALT + 12.0
    np.testing.assert_allclose(
        np.abs(t["attitude_x"]), [0, np.radians(0.005) * lever, 0, 0], atol=1e-5
    )
    # nadir: heading turns nothing (the noisy fitted plane tilts the beam by ~1e-8 rad)
    np.testing.assert_allclose(t["heading"], 0.0, atol=1e-5)
    # the fitted surface's height moves the depth, not the point: the pulse entered where its
    # own surface return is, and its depth is below the plane
    sh = t["surface_height"]
    assert abs(sh[2]) < 1e-9 and abs(sh[3]) == pytest.approx(surf.height_sigma_m[0], rel=1e-3)
    # footprint of a 1 mrad beam: 1e-3 (r_air + L / n_w) / 4 per axis, times tan 10° up;
    # over a plane the return's centroid is the beam centre's range: no depth term
    fp = 1e-3 * (r_air + 12.0 / N_W) / 4.0
    # (the noisy fitted surface sits millimetres off z = 0: 1e-4)
    np.testing.assert_allclose(
        np.abs(t["footprint"]), [fp, fp, fp * math.tan(math.radians(10)), 0.0], rtol=1e-4
    )
    # the splits add up; the depth's sigma is the elevation's less the vertical navigation
    np.testing.assert_allclose(
        tpu.sigma_v_m**2, tpu.sigma_v_random_m**2 + tpu.sigma_v_correlated_m**2, rtol=1e-12
    )
    np.testing.assert_allclose(
        tpu.sigma_depth_m**2,
        tpu.sigma_depth_random_m**2 + tpu.sigma_depth_correlated_m**2,
        rtol=1e-12,
    )
    assert np.all(tpu.sigma_depth_m < tpu.sigma_v_m - 0.05)
    assert set(tpu.terms) == set(RANDOM_TERMS) | set(CORRELATED_TERMS)


def test_slope_couples_horizontal_errors_into_depth():
    """Over a seabed of gradient g a point moved by (dx, dy) is compared with the depth at
    where it was put: ``-g . (dx, dy)`` more; a translation's horizontal sigmas give
    ``|g| s_h``."""
    ret, surf = survey(n_side=4)
    flat = point_tpu(ret, surf, RST)
    g = np.tile([0.12, -0.05], (len(ret), 1))
    tilted = point_tpu(ret, surf, RST, seabed_gradient=g)
    for k in ("attitude_x", "attitude_y", "pointing_a", "timing_bottom"):
        want = flat.terms[k][:, 3] - np.sum(g * flat.terms[k][:, :2], axis=1)
        np.testing.assert_allclose(tilted.terms[k][:, 3], want, rtol=1e-6, atol=1e-12)
    np.testing.assert_allclose(tilted.terms["navigation"][:, 3], 0.05 * 0.13, rtol=1e-12)
    # x, y, z are those of the flat case
    np.testing.assert_allclose(tilted.sigma_v_m, flat.sigma_v_m, rtol=1e-12)
    with pytest.raises(ValueError, match="seabed_gradient"):
        point_tpu(ret, surf, RST, seabed_gradient=np.zeros((3, 2)))


def test_index_derivatives_of_quan_and_fry():
    der = index_derivatives(TpuSettings())
    # 532 nm, 35 psu, 20 °C: dn/dT ~ -1.0e-4 / °C, dn/dS ~ 1.9e-4 / psu (phase); the group
    # index moves ~8 % more
    assert der["temperature"][0] == pytest.approx(-1.03e-4, rel=0.02)
    assert der["salinity"][0] == pytest.approx(1.85e-4, rel=0.02)
    assert der["temperature"][1] / der["temperature"][0] == pytest.approx(1.077, rel=0.02)
    assert cox_munk_slope_sigma(5.0) == pytest.approx(math.sqrt(0.0286 / 2.0), rel=1e-12)


#: a seabed gradient for the Monte Carlo checks: the depth at the measured position
GRAD = (0.1, -0.06)


@pytest.fixture(scope="module")
def wavy():
    ret, _ = survey(wave_m=0.05)
    # the detector's 0.1 ns (the surface returns' noise): each echo's offset from its plane
    # is then part wave, part noise (own-echo weights ~0.9), so every surface term is in play
    n = len(ret)
    ret = dataclasses.replace(ret, t_surface_sigma_s=np.full(n, 1e-10), t_bottom_sigma_s=None)
    surf = fit_water_surface(ret, FIT)
    st = TpuSettings(wave_slope_sigma_rad=0.02, seabed_slope_deg=5.0)
    g = np.tile(GRAD, (len(ret), 1))
    tpu = point_tpu(ret, surf, RST, st, seabed_gradient=g)
    mc = monte_carlo_points(ret, surf, RST, st, n_draws=1000, seed=7, seabed_gradient=g)
    return ret, surf, tpu, mc


def test_tpu_matches_monte_carlo_through_refraction(wavy):
    _, surf, tpu, mc = wavy
    # 5 cm waves: the fit residual is mostly wave height, not ranging noise
    assert np.mean(surf.fit_sigma_m) > 0.03 and np.mean(tpu.terms["wave_height"][:, 2] != 0) > 0.9
    sd = mc.std(axis=0)
    sigmas = (tpu.sigma_x_m, tpu.sigma_y_m, tpu.sigma_v_m, tpu.sigma_depth_m)
    for axis, sig in enumerate(sigmas):
        ratio = sd[:, axis] / sig
        # 1000 draws: each ratio has a 2.2 % sampling sigma; the mean of 144 within 2 %
        # (linearisation error included), each within 12 % (5 sigma)
        assert abs(np.mean(ratio) - 1.0) < 0.02, (axis, np.mean(ratio))
        assert np.all(np.abs(ratio - 1.0) < 0.12), (axis, ratio.min(), ratio.max())
    # and the means: no bias from the full-size perturbations (within 4 standard errors);
    # the depth has a second-order one: a plane tilted by a (both ways) refracts the beam by
    # k a, k = 1 - n_air / n_w, and the depth L (cos(t + k a) + a sin(t + k a)) gains
    # L a² (k - k² / 2) cos t on average: 12 m x 2 axes x 0.0215² x 0.22 = 2.4 mm
    nominal = np.column_stack([tpu.xyz_m, surf.surface_z_m(tpu.row, *tpu.xyz_m[:, :2].T)])
    nominal[:, 3] -= tpu.xyz_m[:, 2]
    err = mc.mean(axis=0) - nominal
    assert np.all(np.abs(err[:, :3]) < 4 * sd[:, :3] / np.sqrt(1000) + 1e-4)
    k = 1.0 - N_AIR / N_W
    second = 12.0 * 2 * (0.008**2 + 0.02**2) * (k - k**2 / 2)
    assert np.all(np.abs(err[:, 3] - second) < 4 * sd[:, 3] / np.sqrt(1000) + 1e-3)


def test_surface_terms_follow_the_own_echo_weight(wavy):
    """Nadir: the pulse entered at plane + w (own echo - plane), w its echo's weight. The echo's
    timing moves the entry down the beam by w c dt / (2 n_air) and shortens the path by
    w c dt / (2 n_g); the plane's height moves the entry up by (1 - w) dh and lengthens the
    path by (1 - w) dh n_air / n_g. The point moves by the difference; its depth below the
    plane by the plane's move less the point's."""
    ret, surf, tpu, _ = wavy
    w = float(surf.own_weight[0])
    assert 0.5 < w < 0.99  # part wave, part noise
    dt = float(ret.t_surface_sigma_s[0])
    ts = tpu.terms["timing_surface"][0]
    assert abs(ts[2]) == pytest.approx(w * C * dt / 2 * (1 / N_AIR - 1 / N_G), rel=2e-3)
    assert ts[3] == pytest.approx(-ts[2], rel=2e-3)
    dh = float(surf.height_sigma_m[0])
    sh = tpu.terms["surface_height"][0]
    dz = (1 - w) * dh * (1 - N_AIR / N_G)
    assert abs(sh[2]) == pytest.approx(dz, rel=2e-3)
    assert abs(sh[3]) == pytest.approx(dh - dz, rel=2e-3)


def test_depth_sigma_is_not_the_elevation_sigma(wavy):
    """The vertical navigation (8 cm) moves z, not the depth below the measured surface; the
    slope (11.7 %) brings the horizontal errors into the depth."""
    _, _, tpu, mc = wavy
    assert np.mean(tpu.sigma_v_m) > 0.08
    # and the 5 cm waves the fitted plane does not follow are in the depth below it, hardly
    # in the point (the pulses enter at their echoes, weight ~0.9)
    wave = tpu.terms["wave_height"]
    assert np.median(np.abs(wave[:, 2])) < 0.1 * np.median(np.abs(wave[:, 3]))
    # the depth's draws are not the elevation's: their correlation is weak
    dz = mc[:, :, 2] - mc[:, :, 2].mean(axis=0)
    dd = mc[:, :, 3] - mc[:, :, 3].mean(axis=0)
    corr = np.sum(dz * dd, axis=0) / np.sqrt(np.sum(dz**2, axis=0) * np.sum(dd**2, axis=0))
    assert np.median(np.abs(corr)) < 0.5
    nav = tpu.terms["navigation"][:, 3]
    np.testing.assert_allclose(nav, 0.05 * math.hypot(*GRAD), rtol=1e-12)


def test_tpu_interval_coverage(wavy):
    _, _, tpu, mc = wavy
    dz = np.abs(mc[:, :, 2] - tpu.xyz_m[:, 2])
    cover_v = np.mean(dz <= 1.96 * tpu.sigma_v_m)
    dx = np.abs(mc[:, :, 0] - tpu.xyz_m[:, 0])
    cover_x = np.mean(dx <= 1.96 * tpu.sigma_x_m)
    dd = np.abs(mc[:, :, 3] - mc[:, :, 3].mean(axis=0))
    cover_d68 = np.mean(dd <= tpu.sigma_depth_m)
    cover_d95 = np.mean(dd <= 1.96 * tpu.sigma_depth_m)
    # 144 000 draws, but the 1000 water-index draws are shared by all points: +-1 %
    assert 0.94 < cover_v < 0.96, cover_v
    assert 0.94 < cover_x < 0.96, cover_x
    assert 0.67 < cover_d68 < 0.70, cover_d68
    assert 0.94 < cover_d95 < 0.96, cover_d95


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


def test_seabed_gradient_of_a_noisy_plane_and_of_a_track():
    rng = np.random.default_rng(3)
    xy = rng.uniform(0, 60, (4000, 2))
    depth = 5.0 + 0.08 * xy[:, 0] - 0.03 * xy[:, 1] + rng.normal(0, 0.02, len(xy))
    depth[::97] += 3.0  # blunders: the robust pass drops them
    g = seabed_gradient(xy, depth, neighbours=24)
    inner = np.all((xy > 8) & (xy < 52), axis=1)
    np.testing.assert_allclose(np.median(g[inner], axis=0), [0.08, -0.03], atol=2e-3)
    assert np.percentile(np.abs(g[inner, 0] - 0.08), 90) < 0.03
    # a profiler's track (collinear soundings): the slope along it, none across
    y = np.linspace(0, 100, 500)
    track = np.column_stack([np.zeros_like(y), y])
    g = seabed_gradient(track, 2.0 + 0.03 * y, np.array([[0.0, 50.0]]), neighbours=24)
    np.testing.assert_allclose(g[0], [0.0, 0.03], atol=1e-4)
    # one depth per group: the shots of a window count as one sounding at their mean
    shots = np.repeat(track, 40, axis=0) + rng.normal(0, 0.01, (40 * len(y), 2))
    win = np.repeat(np.arange(len(y)), 40)
    g = seabed_gradient(shots, np.repeat(2.0 + 0.03 * y, 40), track[250:251], group=win)
    np.testing.assert_allclose(g[0, 1], 0.03, atol=1e-3)
    assert np.all(seabed_gradient(xy[:2], depth[:2]) == 0.0)


def test_seabed_gradient_blocks_on_threads_give_the_same_values():
    # blocks of queries (a prime: cut anywhere), side by side on threads: every gradient and
    # covariance as all queries at once
    from pipeline.parallel import stage_threads

    rng = np.random.default_rng(4)
    xy = rng.uniform(0, 80, (3000, 2))
    depth = 5.0 + 0.08 * xy[:, 0] + 0.5 * np.sin(xy[:, 1] / 7.0) + rng.normal(0, 0.03, len(xy))
    whole = seabed_gradient(xy, depth, return_cov=True, chunk=10**6)
    with stage_threads(3):
        blocks = seabed_gradient(xy, depth, return_cov=True, chunk=97)
    for a, b in zip(blocks, whole, strict=True):
        np.testing.assert_array_equal(a, b)


def test_seabed_gradient_across_a_drifting_profiler_track():
    """A dense profiler track drifting slowly across a seabed that slopes across it only
    (depth = 5 + 0.3 x, none along y): locally the track is a line, blind across; over tens of
    metres its drift shows the slope. The regional step recovers (0.3, 0); the local fit alone
    cannot, and its covariance says so (the slope prior's sigma across)."""
    rng = np.random.default_rng(5)
    y = np.arange(0.0, 300.0, 0.02)
    x = 6.0 * np.sin(2.0 * np.pi * y / 300.0)
    xy = np.column_stack([x, y])
    depth = 5.0 + 0.3 * x + rng.normal(0.0, 0.03, len(y))
    q = xy[(y > 60) & (y < 240)][::500]
    g = seabed_gradient(xy, depth, q)
    assert np.percentile(np.abs(g[:, 0] - 0.3), 90) < 0.03
    g0, c0 = seabed_gradient(xy, depth, q, regional_radius_m=0.0, return_cov=True)
    assert np.percentile(np.abs(g0[:, 0] - 0.3), 90) > 0.1  # the local fit alone is blind
    s0 = math.tan(math.radians(10.0))  # the default slope prior
    # ... and knows it: across the track (x, where the 16 soundings span < 1 cm) the prior
    assert np.median(np.sqrt(c0[:, 0, 0])) > 0.7 * s0
    # along: 16 soundings spanning 0.3 m with 3 cm of noise read a slope to ~0.09 alone
    assert np.percentile(np.abs(g[:, 1]), 90) < 0.07
    # a straight track stays blind across even with the regional step (no drift: nothing to
    # see): the slope prior's mean and sigma there (a plane: no relief measured to add), the
    # along-track slope measured
    line = np.column_stack([np.zeros_like(y), y])
    g, c = seabed_gradient(line, 2.0 + 0.03 * y, line[7500:7501], return_cov=True)
    np.testing.assert_allclose(g[0], [0.0, 0.03], atol=1e-3)
    assert math.sqrt(c[0, 0, 0]) == pytest.approx(s0, rel=0.02)
    # along: the noise floor (1 cm) over 16 soundings 2 cm apart, ~0.01 / sqrt(16 * 0.0085)
    assert math.sqrt(c[0, 1, 1]) < 0.03


def test_seabed_gradient_covariance_is_calibrated():
    """Scattered soundings (a swath's, 600 over 30 m x 30 m, 5 cm of noise) over a plane plus
    Gaussian relief (rms 0.3 m, correlation 8 m), a new relief and noise each draw: the
    posterior sigma the fit reports matches the rms of its errors against the true local
    gradient (the plane's plus the relief's analytic derivative at the query), for the default
    local plane of 16 soundings (a wider patch reads its own mean slope, and the relief's
    curvature over it is not in the noise model: with 64 the errors are ~4x the sigma here).
    On the bare plane it may be wider than the spread (it cannot know the relief is exactly 0)
    but never narrower."""
    rng = np.random.default_rng(11)
    xy = rng.uniform(0.0, 30.0, (600, 2))
    q = np.array([[15.0, 15.0]])
    h, ell, n = 0.3, 8.0, 200
    for k in (16,):
        for with_relief in (False, True):
            err, var = [], []
            for _ in range(150):
                kv = rng.normal(0.0, math.sqrt(2.0) / ell, (n, 2))
                ph = rng.uniform(0.0, 2.0 * math.pi, n)
                amp = h * math.sqrt(2.0 / n) * with_relief
                relief = amp * np.cos(xy @ kv.T + ph).sum(axis=1)
                slope_q = -amp * (np.sin(q @ kv.T + ph)[0][:, None] * kv).sum(axis=0)
                depth = 4.0 + 0.1 * xy[:, 0] + 0.05 * xy[:, 1] + relief
                depth += rng.normal(0.0, 0.05, len(xy))
                gi, ci = seabed_gradient(xy, depth, q, neighbours=k, return_cov=True)
                err.append(gi[0] - [0.1, 0.05] - slope_q)
                var.append(np.diag(ci[0]))
            rms_err = np.sqrt(np.mean(np.square(err), axis=0))
            rms_sd = np.sqrt(np.mean(var, axis=0))
            if with_relief:
                # the fit reads the slope of the ~1.3 m patch of its soundings, the truth is the
                # point's: the relief's curvature over the patch (~0.007 here) is not in the
                # noise model, which the tolerance allows
                np.testing.assert_allclose(rms_sd, rms_err, rtol=0.3)
            else:
                assert np.all(rms_sd >= 0.9 * rms_err)


def test_relief_slope_is_measured_from_neighbouring_cells():
    """Soundings over a plane plus Gaussian relief of rms h and correlation length l
    (``h² exp(-r²/l²)``, a sum of random-phase cosines): the slope departure per axis is
    ``h sqrt(2) / l``. Measured from 5 m cells' mean depths (their separation a fraction of l)
    it comes out within 25 %; on the bare plane it is near 0."""
    from pipeline.uncertainty.seabed_gradient import _cells, _relief_slope_sigma

    rng = np.random.default_rng(2)
    xy = rng.uniform(0.0, 200.0, (40000, 2))
    h, ell, n = 0.3, 20.0, 400
    # Gaussian covariance h² exp(-r²/l²): wavevectors normal with sd sqrt(2)/l per axis
    kv = rng.normal(0.0, math.sqrt(2.0) / ell, (n, 2))
    ph = rng.uniform(0.0, 2.0 * math.pi, n)
    relief = h * math.sqrt(2.0 / n) * np.cos(xy @ kv.T + ph).sum(axis=1)
    plane = 3.0 + 0.1 * xy[:, 0]
    noise = rng.normal(0.0, 0.05, len(xy))
    for dep, want in ((plane + relief + noise, h * math.sqrt(2.0) / ell), (plane + noise, 0.0)):
        cells = _cells(xy, dep, 5.0)
        g = np.tile([0.1, 0.0], (len(cells[1]), 1))
        got = _relief_slope_sigma(xy, dep, cells, g, 5.0)
        if want > 0:
            assert got == pytest.approx(want, rel=0.25)
        else:
            assert got < 0.005


def test_gradient_from_too_few_soundings_is_the_prior():
    """Three soundings fit a plane exactly: their residuals read no noise, and a slope read
    from them would claim ~1 cm of noise whatever the truth (0.2 m here). Too few soundings
    give the prior's mean and sigma instead; from 8 on, the data speak."""
    rng = np.random.default_rng(4)
    s0 = math.tan(math.radians(10.0))
    for n, prior in ((3, True), (5, True), (8, False)):
        xy = rng.uniform(-1.0, 1.0, (n, 2))
        depth = 3.0 + 0.2 * xy[:, 0] + rng.normal(0.0, 0.2, n)
        g, c = seabed_gradient(xy, depth, np.zeros((1, 2)), regional_radius_m=0.0, return_cov=True)
        if prior:
            np.testing.assert_allclose(g[0], [0.0, 0.0], atol=1e-12)
            np.testing.assert_allclose(np.sqrt(np.diag(c[0])), [s0, s0], rtol=1e-9)
        else:
            assert np.all(np.sqrt(np.diag(c[0])) < s0)


def test_track_directions_per_line():
    """Each line's own axis (a line at atan(0.5) from x, one along y), any sign; a line of one
    pulse falls back to x."""
    from pipeline.uncertainty.tpu_facet import track_directions

    t = np.linspace(0.0, 100.0, 50)
    o = np.vstack(
        [
            np.column_stack([t, 0.5 * t, np.full(50, 400.0)]),
            np.column_stack([np.full(50, 30.0), t, np.full(50, 400.0)]),
            [[5.0, 5.0, 400.0]],
        ]
    )
    n = len(o)
    ret = DetectedReturns(
        pulse_id=np.arange(n),
        origin_meas_m=o,
        direction_meas=np.tile([0.0, 0.0, -1.0], (n, 1)),
        has_surface=np.zeros(n, bool),
        t_surface_s=np.zeros(n),
        has_bottom=np.zeros(n, bool),
        t_bottom_s=np.zeros(n),
        surface_confidence=np.zeros(n),
        bottom_confidence=np.zeros(n),
        flags=np.zeros(n, np.uint16),
        line_id=np.r_[np.zeros(50, int), np.ones(50, int), [7]],
    )
    d = track_directions(ret)
    np.testing.assert_allclose(np.abs(d[0]), np.array([1.0, 0.5]) / math.hypot(1.0, 0.5))
    np.testing.assert_allclose(np.abs(d[60]), [0.0, 1.0], atol=1e-12)
    np.testing.assert_allclose(d[-1], [1.0, 0.0])


def test_pair_scatter_recovers_the_random_error_not_the_shared_one():
    """Soundings along scan lines over a slope, each with its own noise (growing eastward) and
    a shared offset per scan line (navigation-like): successive soundings see the noise only."""
    rng = np.random.default_rng(5)
    n_line, per_line = 200, 150
    x = np.tile(np.linspace(0, 60, per_line), n_line) + rng.normal(0, 0.05, n_line * per_line)
    y = np.repeat(np.linspace(0, 80, n_line), per_line)
    sigma = 0.01 + 0.001 * x
    shared = np.repeat(rng.normal(0, 0.2, n_line), per_line)
    depth = 4 + 0.1 * x + 0.02 * y + shared + rng.normal(size=x.size) * sigma
    order = np.arange(x.size)
    xy = np.column_stack([x, y])
    est = pair_scatter(xy, depth, order=order, max_separation_m=1.0)
    for lo, hi in ((5, 15), (25, 35), (45, 55)):
        m = (x > lo) & (x < hi)
        assert np.median(est[m]) == pytest.approx(np.sqrt(np.mean(sigma[m] ** 2)), rel=0.08)
    # nearest pairs mix scan lines: the shared offsets show
    near = pair_scatter(xy, depth, max_separation_m=1.0)
    assert np.median(near) > 1.8 * np.median(est)
    # groups sharing one detection are one sounding each
    rep = np.repeat(np.arange(x.size), 3)
    grouped = pair_scatter(
        np.repeat(xy, 3, axis=0), np.repeat(depth, 3), order=rep, group=rep, max_separation_m=1.0
    )
    np.testing.assert_allclose(grouped[::3], est, rtol=1e-9)
    assert np.all(np.isnan(pair_scatter(xy[:1], depth[:1])))


def test_timing_from_scatter_explains_the_scatter():
    ret, surf = survey(n_side=6)
    n = len(ret)
    # a calm sea, no wave scatter about the planes: the TPU's wave height (in the depth below
    # the plane) is then 0 whatever timing sigmas the scatter sets
    surf = dataclasses.replace(surf, fit_sigma_m=np.zeros(n))
    amp = dict(surface_amplitude=np.full(n, 100.0), bottom_amplitude=np.linspace(20, 2000, n))
    ret = dataclasses.replace(ret, **amp)
    scatter = np.linspace(0.005, 0.06, n)
    scatter[3] = np.nan  # no pair: the a-priori sigma stays
    out = timing_from_scatter(ret, surf, RST, depth_scatter_m=scatter)
    tpu = point_tpu(out, surf, RST)
    ok = np.isfinite(scatter)
    np.testing.assert_allclose(tpu.sigma_depth_random_m[ok], scatter[ok], rtol=1e-3)
    # variance shared in proportion to 1 / amplitude: the weak bottoms take the larger share
    share = out.t_bottom_sigma_s**2 / out.t_surface_sigma_s**2
    np.testing.assert_allclose(share[ok], (100.0 / amp["bottom_amplitude"])[ok], rtol=1e-9)
    assert out.t_bottom_sigma_s[3] == TpuSettings().timing_sigma_s
    with pytest.raises(ValueError, match="depth_scatter_m"):
        timing_from_scatter(ret, surf, RST, depth_scatter_m=scatter[:-1])


def test_surface_tilt_is_measured_over_the_sounding():
    """Planes turned at random by ``tau`` per axis and raised at random (heights that differ
    between the fits do not matter): the plane over each sounding turns against the pulse's
    by both tilts times the offset."""
    ret, surf = survey(n_side=24)
    rng = np.random.default_rng(11)
    tau = 0.01
    ex, ey = np.eye(3)[0], np.eye(3)[1]

    def turn(v, axis, a):
        axis = np.broadcast_to(axis, v.shape)
        c, s = np.cos(a)[:, None], np.sin(a)[:, None]
        return v * c + np.cross(axis, v) * s + axis * np.sum(axis * v, 1)[:, None] * (1 - c)

    n = len(ret)
    nrm = turn(turn(surf.normal, ex, rng.normal(0, tau, n)), ey, rng.normal(0, tau, n))
    entry = surf.entry_m + np.column_stack([np.zeros((n, 2)), rng.normal(0, 0.05, n)])
    turned = dataclasses.replace(surf, normal=nrm, entry_m=entry)
    xy = seabed_points(ret, turned, RST).xyz_m[:, :2]
    t, delta = surface_over_sounding(ret, turned, xy)
    far = delta > 1.5
    assert np.all(np.isfinite(t)) and far.sum() > 150
    assert np.sqrt(np.mean(t[far] ** 2) / np.mean(2 * delta[far] ** 2)) == pytest.approx(
        tau, rel=0.15
    )
    tilt = surface_tilt_sigma(ret, turned, xy)
    # the total sigma of the turn, sqrt(2) tau
    assert np.median(tilt[far]) == pytest.approx(math.sqrt(2) * tau, rel=0.2)
    # the TPU takes the larger of it and the fit's own
    tpu = point_tpu(ret, turned, RST, surface_tilt_sigma_rad=tilt)
    fit_only = point_tpu(ret, turned, RST)
    assert np.all(tpu.sigma_depth_m >= fit_only.sigma_depth_m - 1e-12)

    def tilt_depth(p):
        return np.hypot(p.terms["surface_tilt_x"][:, 3], p.terms["surface_tilt_y"][:, 3])

    assert np.median(tilt_depth(tpu)[far]) > 3 * np.median(tilt_depth(fit_only)[far])


def test_detector_sigmas_are_used():
    ret, surf = survey(n_side=4)
    n = len(ret)
    with_sig = dataclasses.replace(
        ret, t_surface_sigma_s=np.full(n, 3e-10), t_bottom_sigma_s=np.full(n, 5e-10)
    )
    tpu = point_tpu(with_sig, surf, RST)
    assert abs(tpu.terms["timing_bottom"][0, 2]) == pytest.approx(C * 5e-10 / (2 * N_G), rel=1e-4)
    # the own echo carries the entry (fitted without detector sigmas): the surface's timing
    # moves the entry by c dt / (2 n_air) and the path by c dt / (2 n_g)
    dz_s = C * 3e-10 / 2 * (1 / N_AIR - 1 / N_G)
    assert abs(tpu.terms["timing_surface"][0, 2]) == pytest.approx(dz_s, rel=1e-3)


def test_pair_scatter_leaves_out_the_seabed_relief_between_the_pairs():
    """Scan lines of soundings 1.5 m apart (an oscillating scanner's spacing) over a plane with
    a smooth relief ``A sin(k x)`` (wavelength 40 m, A = 0.3 m: real seabed, no error) and iid
    noise of 1 cm. Successive soundings differ by the relief too: its semivariogram at the
    lag h = 1.5 m is ``A² (1 - cos(k h)) / 2`` (3.5 cm as a sigma), which the noise estimate must
    not take for timing noise. Before: 2.3 cm (the local plane takes part of the relief)."""
    rng = np.random.default_rng(11)
    h, n_line, per_line = 1.5, 40, 60
    x = np.tile(np.arange(per_line) * h, n_line)
    y = np.repeat(np.arange(n_line) * 2.0, per_line)
    k = 2.0 * np.pi / 40.0
    sigma = 0.01
    depth = 6.0 + 0.05 * x + 0.3 * np.sin(k * x + 0.7 * y) + rng.normal(0, sigma, x.size)
    est = pair_scatter(np.column_stack([x, y]), depth, order=np.arange(x.size))
    relief = np.sqrt(0.3**2 * (1.0 - np.cos(k * h)) / 2.0)
    assert relief > 3.0 * sigma  # the relief would dominate
    assert np.median(est) == pytest.approx(sigma, rel=0.25)


def test_the_tpu_reads_the_derivatives_the_scatter_pass_made(monkeypatch):
    """``timing_from_scatter`` moves the times, the beam and the plane's height of every
    bottom pulse; ``point_tpu`` of the same pulses reads those derivatives and its figures
    are those it makes without them, to the bit (the steps are the inputs', not the terms'
    sigmas). Another surface object, or other times, and it makes them itself."""
    import pipeline.uncertainty.tpu_terms as tt

    ret, _ = survey(n_side=10, wave_m=0.05, seed=3)
    n = len(ret)
    ret = dataclasses.replace(ret, t_surface_sigma_s=np.full(n, 1e-10), t_bottom_sigma_s=None)
    surf = fit_water_surface(ret, FIT)
    st = TpuSettings(wave_slope_sigma_rad=0.02)
    g = np.tile(GRAD, (n, 1))
    scatter = np.linspace(0.01, 0.04, n)
    passes = []
    real = tt.seabed_xyz_depth
    monkeypatch.setattr(tt, "seabed_xyz_depth", lambda *a: passes.append(1) or real(*a))
    out, der = timing_from_scatter(
        ret, surf, RST, st, depth_scatter_m=scatter, seabed_gradient=g, return_derivatives=True
    )
    # the points, and the two times, the two pointing turns, the plane's height and its two
    # tilts (the waves' slopes are random terms), each moved both ways
    moves = ["t_surface", "t_bottom", "pointing_a", "pointing_b", "plane_height"]
    moves += ["plane_tilt_x", "plane_tilt_y"]
    assert sorted(der.moves) == sorted(["xyzd", *moves])
    assert len(passes) == 1 + 2 * len(moves)

    def tpu(**k):
        passes.clear()
        got = point_tpu(out, surf, RST, st, seabed_gradient=g, **k)
        return got, len(passes)

    alone, n_alone = tpu()
    read, n_read = tpu(derivatives=der)
    assert n_read == n_alone - (1 + 2 * len(moves))
    for name, v in alone.terms.items():
        np.testing.assert_array_equal(read.terms[name], v, err_msg=name)
    np.testing.assert_array_equal(read.sigma_depth_m, alone.sigma_depth_m)
    # in blocks of rows on threads (both passes), the same figures and the same saving
    n_block = tt.TERMS_BLOCK
    monkeypatch.setattr(tt, "TERMS_BLOCK", 16)
    out16, der16 = timing_from_scatter(
        ret, surf, RST, st, depth_scatter_m=scatter, seabed_gradient=g, return_derivatives=True
    )
    np.testing.assert_array_equal(out16.t_bottom_sigma_s, out.t_bottom_sigma_s)
    for k, v in der.moves.items():
        np.testing.assert_array_equal(der16.moves[k], v, err_msg=k)
    read16, n_read16 = tpu(derivatives=der16)
    assert n_read16 == -(-len(alone.row) // 16) * n_read  # each block: only what is not read
    for name, v in alone.terms.items():
        np.testing.assert_array_equal(read16.terms[name], v, err_msg=name)
    monkeypatch.setattr(tt, "TERMS_BLOCK", n_block)
    # another surface (equal, but not the one the derivatives were made on): not read
    other = dataclasses.replace(surf)
    passes.clear()
    point_tpu(out, other, RST, st, seabed_gradient=g, derivatives=der)
    assert len(passes) == n_alone
    # other times: not read
    moved = dataclasses.replace(out, t_bottom_s=out.t_bottom_s + 1e-12)
    passes.clear()
    point_tpu(moved, surf, RST, st, seabed_gradient=g, derivatives=der)
    assert len(passes) == n_alone
