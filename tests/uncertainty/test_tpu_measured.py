"""The TPU's surface terms measured from the surface returns (pipeline.uncertainty.tpu_measured).

Every reference is analytic: a hand-built track of surface returns over a sea written in the
test (flat, or a random-phase sum of sinusoids ``a_i sin(k_i x + phi_i)``, whose height
difference over a lag ``h`` has the variance ``sum a_i² (1 - cos k_i h)``) with Gaussian
ranging noise of known sigma.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from scipy import constants

from pipeline.process.returns import DetectedReturns
from pipeline.process.sea_correlation import SeaCorrelation
from pipeline.process.surface_fit import SurfaceFitSettings, fit_water_surface
from pipeline.uncertainty.tpu import point_tpu
from pipeline.uncertainty.tpu_measured import (
    INCIDENCE_BANDS_DEG,
    WAVE_TERM,
    SurfaceVariogram,
    surface_variogram,
    wave_entry_sigma_m,
    with_surface_ranging,
    with_wave_entry,
)
from pipeline.uncertainty.tpu_settings import DEPTH

C = constants.c
N_AIR, N_G = 1.000277, 1.3638
ALT = 400.0
SPEED = 60.0  # m/s along the track


def track(sea, noise_m, n=6000, spacing_m=0.05, seed=3, inc_deg=0.0):
    """Pulses along x at ``spacing_m``, ``spacing_m / SPEED`` apart in time, each ranging the
    sea ``sea(x)`` with vertical noise ``noise_m``; the fitted planes are then set level at
    z = 0 (the test's own reference, so the measured heights are the sea plus the noise)."""
    rng = np.random.default_rng(seed)
    x = np.arange(n) * spacing_m
    inc = math.radians(inc_deg)
    d = np.tile([math.sin(inc), 0.0, -math.cos(inc)], (n, 1))
    z = sea(x) + rng.normal(0.0, noise_m, n)
    r_air = (ALT - z) / math.cos(inc)
    o = np.column_stack([x, np.zeros(n), np.zeros(n)]) - d * (ALT / math.cos(inc))
    o[:, 2] = ALT
    o[:, 0] = x - math.tan(inc) * ALT
    ret = DetectedReturns(
        pulse_id=np.arange(n),
        origin_meas_m=o,
        direction_meas=d,
        has_surface=np.ones(n, bool),
        t_surface_s=2.0 * r_air * N_AIR / C,
        has_bottom=np.ones(n, bool),
        t_bottom_s=2.0 * r_air * N_AIR / C + 2.0 * 5.0 * N_G / C,
        surface_confidence=np.full(n, 0.9),
        bottom_confidence=np.full(n, 0.9),
        flags=np.zeros(n, np.uint16),
        t_emit_s=x / SPEED,
        t_surface_sigma_s=np.full(n, 1e-12),
        t_bottom_sigma_s=np.full(n, 1e-11),
    )
    surf = fit_water_surface(ret, SurfaceFitSettings(air_index=N_AIR))
    level = dataclasses.replace(
        surf,
        normal=np.tile([0.0, 0.0, 1.0], (n, 1)),
        entry_m=np.column_stack([surf.entry_m[:, :2], np.zeros(n)]),
        is_water=np.ones(n, bool),
        is_land=np.zeros(n, bool),
    )
    return ret, level


def random_phase_sea(seed: int, lam_m: tuple[float, float], sigma_m: float):
    """A random-phase sea of 40 waves with wavelengths in ``lam_m`` and height sigma
    ``sigma_m``: ``(sea(x), height_difference_sd(Delta))``, the latter
    ``sqrt(sum_i a_i² (1 - cos k_i Delta))``."""
    rng = np.random.default_rng(seed)
    k = 2 * math.pi / rng.uniform(*lam_m, 40)
    a = np.full(40, sigma_m * math.sqrt(2.0 / 40))
    phi = rng.uniform(0.0, 2 * math.pi, 40)

    def sea(x):
        return np.sum(a * np.sin(np.outer(x, k) + phi), axis=1)

    def diff_sd(delta):
        return math.sqrt(np.sum(a**2 * (1.0 - np.cos(k * delta))))

    return sea, diff_sd


def test_flat_sea_nugget_is_the_ranging_variance_and_no_wave():
    """On a flat sea the variogram is flat at the ranging variance, at every incidence band
    with pairs; the wave term is zero."""
    noise = 0.04
    ret, surf = track(lambda x: np.zeros_like(x), noise)
    vg = surface_variogram(ret, surf)
    band0 = vg.nugget_m2[0]  # nadir
    assert math.sqrt(band0) == pytest.approx(noise, rel=0.05)
    assert np.all(np.abs(np.sqrt(vg.gamma_m2) - noise) < 0.1 * noise)
    # no wave: what is left is the estimator's sampling noise, a variance of a few per cent
    # of the ranging variance (a sigma under a quarter of the ranging sigma)
    assert np.all(wave_entry_sigma_m(vg, [0.5, 2.0, 5.0]) < 0.25 * noise)


def test_random_phase_sea_wave_term_is_its_height_difference():
    """A random-phase sea ``sum_i a_i sin(k_i x + phi_i)`` (Gaussian, as a linear sea is):
    the height difference over ``Delta`` has the variance ``sum_i a_i² (1 - cos k_i Delta)``;
    the nugget stays the noise (the wave rise is removed)."""
    sea, diff_sd = random_phase_sea(5, (5.0, 20.0), 0.10)
    noise = 0.01
    ret, surf = track(sea, noise, n=12000)
    vg = surface_variogram(ret, surf)
    assert math.sqrt(vg.nugget_m2[0]) == pytest.approx(noise, abs=0.004)
    for delta in vg.lag_m[(vg.lag_m > 0.7) & (vg.lag_m < 3.5)]:
        assert wave_entry_sigma_m(vg, [delta])[0] == pytest.approx(diff_sd(delta), rel=0.1)


def test_wave_term_below_the_shortest_lag_rises_from_the_origin():
    """Successive soundings 1.7 m apart (a Palmer scan's): every lag bin lies past a shallow
    sounding's ``Delta`` (0.3-1.2 m). The sea's height difference there (random-phase sea of
    10-40 m waves: ``sum a_i² (1 - cos k_i Delta)``, within 8 % of its ``Delta²`` rise up to
    the shortest lag) is the term's, not 0; past the shortest lag it is as before."""
    sea, diff_sd = random_phase_sea(9, (10.0, 40.0), 0.10)
    ret, surf = track(sea, 0.01, n=12000, spacing_m=1.7)
    vg = surface_variogram(ret, surf)
    assert vg.lag_m[0] > 1.5  # nothing measured below a shallow sounding's offset
    for delta in (0.3, 0.6, 1.2, 3.4, 5.1):
        assert wave_entry_sigma_m(vg, [delta])[0] == pytest.approx(diff_sd(delta), rel=0.1)


@pytest.mark.parametrize(
    ("lags", "gammas"),
    [
        # suite tuning seed 20 (1.5 m/s, flat sea): flat at the shortest lags, rising farther out
        ((2.41, 4.83, 7.24, 9.68), (2.61e-3, 2.74e-3, 3.84e-3, 4.71e-3)),
        # two lags, falling: no rise at all
        ((1.0, 2.0), (1.0e-3, 6.0e-4)),
    ],
)
def test_no_sea_rise_at_the_shortest_lags_gives_no_wave_term_below_them(lags, gammas):
    """A variogram that does not rise as a sea does from the origin measures no sea there: the
    term stays 0 below the shortest lag (a line's intercept under ``gamma(h_0)`` would read
    the ranging noise as waves), and past it is the variogram's rise over ``gamma(h_0)``."""
    nb = len(SurfaceVariogram.empty().nugget_m2)
    vg = SurfaceVariogram(np.array(lags), np.array(gammas), np.full(nb, gammas[0]), 1000)
    assert vg.pooled_nugget_m2 == gammas[0]
    below = np.array([0.3, 0.6, 0.99]) * lags[0]
    assert np.all(wave_entry_sigma_m(vg, below) == 0.0)
    past = lags[1]
    want = math.sqrt(2.0 * max(gammas[1] - gammas[0], 0.0))
    assert wave_entry_sigma_m(vg, [past])[0] == pytest.approx(want, rel=1e-12)


def test_pairs_too_far_apart_in_time_are_not_used():
    """A sea that changed between two passes (here: all of it, by pulse parity in time)
    is not paired across more than ``max_dt_s``."""
    ret, surf = track(lambda x: np.zeros_like(x), 0.02, n=2000)
    vg = surface_variogram(ret, surf, max_dt_s=0.5 * 0.05 / SPEED)  # not even neighbours
    assert vg.pairs == 0 and vg.lag_m.size == 0
    assert np.all(wave_entry_sigma_m(vg, [1.0]) == 0.0)


def test_photon_windows_are_not_paired_within():
    """Shots of one photon-counting window share one detection: pairs within a window would
    show no ranging error at all."""
    ret, surf = track(lambda x: np.zeros_like(x), 0.03, n=4000)
    group = np.arange(len(ret)) // 40
    vg = surface_variogram(ret, surf, group=group)
    assert math.sqrt(vg.nugget_m2[0]) == pytest.approx(0.03, rel=0.1)


def test_photon_windows_of_a_long_survey_still_pair_across():
    """More pulses than the pairs kept per offset (anchors subsampled): the pairs across
    window boundaries, the only ones a window's shared detection leaves, still give the
    ranging sigma."""
    ret, surf = track(lambda x: np.zeros_like(x), 0.03, n=120_000, spacing_m=0.002)
    vg = surface_variogram(ret, surf, group=np.arange(len(ret)) // 400)
    assert math.sqrt(vg.nugget_m2[0]) == pytest.approx(0.03, rel=0.1)


def test_surface_ranging_raises_the_timing_and_reaches_the_depth():
    """At nadir a surface timing error ``dt`` moves the surface point by ``dr = c dt / (2 n_a)``;
    where the pulse enters at its own echo (``w = 1``) and the sea above the sounding is the
    one met there (``rho = 1``), the entry, the sea above the sounding and the sounding all
    move by ``dr`` but the in-water path shortens by ``dr n_a / n_g``: a measured ranging sigma
    ``s_r`` gives the depth ``s_r n_a / n_g``. A detector sigma already larger is kept."""
    s_r = 0.05
    ret, surf = track(lambda x: np.zeros_like(x), 0.0, n=50)
    everywhere = SeaCorrelation(np.array([100.0]), np.array([1.0]), 1)
    surf = dataclasses.replace(surf, own_weight=np.ones(len(surf)), sea_correlation=everywhere)
    nb = len(SurfaceVariogram.empty().nugget_m2)
    vg = SurfaceVariogram(np.array([1.0]), np.array([s_r**2]), np.full(nb, s_r**2), 100)
    big = 2 * N_AIR * 0.2 / C  # 0.2 m of vertical ranging
    own = ret.t_surface_sigma_s.copy()
    own[0] = big
    ret = dataclasses.replace(ret, t_surface_sigma_s=own)
    raised = with_surface_ranging(ret, surf, vg)
    assert raised.t_surface_sigma_s[1] == pytest.approx(2 * N_AIR * s_r / C, rel=1e-9)
    assert raised.t_surface_sigma_s[0] == big
    tpu = point_tpu(raised, surf)
    assert abs(tpu.terms["timing_surface"][1, DEPTH]) == pytest.approx(s_r * N_AIR / N_G, rel=0.01)


def test_wave_term_adds_only_the_excess_over_the_plane_tilt():
    """The wave term's depth variance is the variogram's wave part less the tilt terms';
    it never takes from them and never touches the elevation."""
    ret, surf = track(lambda x: np.zeros_like(x), 0.0, n=50, inc_deg=15.0)
    tpu = point_tpu(ret, surf)
    # a sea whose wave part is 0.01 m² at every lag (gamma = 0.0004 + 0.005)
    nb = len(SurfaceVariogram.empty().nugget_m2)
    lags = np.array([0.1, 0.2, 0.4, 0.9, 10.0])
    vg = SurfaceVariogram(lags, np.array([4e-4, 4e-4, 4e-4, 5.4e-3, 5.4e-3]), np.full(nb, 4e-4), 10)
    entry = surf.entry_m[tpu.row, :2]
    delta = np.hypot(*(tpu.xyz_m[:, :2] - entry).T)
    assert np.all(delta > 0.9)  # 5 m deep at 15°: on the plateau
    tilt = np.zeros((len(tpu), 4))
    tilt[:, DEPTH] = 0.06
    tpu = dataclasses.replace(tpu, terms={**tpu.terms, "surface_tilt_x": tilt})
    out = with_wave_entry(tpu, vg, entry)
    want = math.sqrt(2 * 5e-3 - 0.06**2)
    assert np.allclose(out.terms[WAVE_TERM][:, DEPTH], want)
    assert np.allclose(out.terms[WAVE_TERM][:, :3], 0.0)
    assert np.allclose(out.sigma_depth_m, np.hypot(tpu.sigma_depth_m, want))
    assert np.allclose(out.sigma_v_m, tpu.sigma_v_m)


def test_wave_term_is_the_error_of_the_sea_predicted_at_the_sounding():
    """Heights above the plane at E and B, variance sigma², correlation rho: the depth reads
    ``rho s_E`` for the sea at B, whose error variance is sigma² (1 - rho²) (brute force over
    drawn pairs); the variogram with gamma(h_0) = 0 and gamma(Delta) = sigma² (1 - rho) gives it."""
    rng = np.random.default_rng(7)
    sigma, rho = 0.3, 0.6
    s_e = rng.normal(0, sigma, 200_000)
    s_b = rho * s_e + np.sqrt(1 - rho**2) * rng.normal(0, sigma, s_e.size)
    brute = np.var(s_b - rho * s_e)
    nb = len(SurfaceVariogram.empty().nugget_m2)
    vg = SurfaceVariogram(
        np.array([0.1, 4.0]), np.array([0.0, sigma**2 * (1 - rho)]), np.zeros(nb), 1000
    )
    got = wave_entry_sigma_m(vg, np.array([4.0]), np.array([rho]))[0] ** 2
    assert got == pytest.approx(brute, rel=0.02)
    # read as the sea at E itself (rho = 1 in the depth): the variance of the difference
    assert wave_entry_sigma_m(vg, np.array([4.0]))[0] ** 2 == pytest.approx(
        np.var(s_b - s_e), rel=0.02
    )


def _snell_depth_sd(slope_sigma_rad, length_m, gradient, n_water):
    """Depth error sd of a nadir beam through a facet of Gaussian slope (sigma per axis) over
    a seabed of depth gradient ``gradient`` across the facet's slope, by Snell's law written
    out: the facet at ``atan beta`` from level, the beam in water at ``asin(sin(atan beta) /
    n)`` from that normal, so ``delta = atan beta - asin(...)`` from the vertical; the sounding
    moves ``L sin delta`` sideways and ``L (1 - cos delta)`` up; Gauss-Hermite over beta."""
    x, w = np.polynomial.hermite_e.hermegauss(60)
    beta = slope_sigma_rad * x
    th_a = np.arctan(beta)
    delta = th_a - np.arcsin(np.sin(th_a) / n_water)
    err = gradient * length_m * np.sin(delta) + length_m * (1.0 - np.cos(delta))
    w = w / w.sum()
    mean = np.sum(w * err)
    return math.sqrt(np.sum(w * (err - mean) ** 2))


def test_nadir_beam_through_the_unresolved_wave_facet_over_a_slope():
    """A profiler along x over a random-phase sea (wavelengths 10-40 m) whose planes are level
    (they follow no wave): every beam is at nadir and refracts through the sea's facet at its
    entry, which no plane holds. The along-track slope variance of the sea is
    ``sum a_i² k_i² / 2`` (isotropic sea: the same across); over a seabed sloping 18.9° across
    the track, 5 m of water, the depth error sd is Snell's (``_snell_depth_sd``). The TPU
    must carry it, sized from the measured surface variogram alone."""
    from pipeline.process.refraction import RefractionSettings
    from pipeline.uncertainty.tpu_facet import FACET_TERMS, with_wave_facet

    rng = np.random.default_rng(8)
    lam = rng.uniform(10.0, 40.0, 40)
    k = 2 * math.pi / lam
    a = np.full(40, 0.3 * math.sqrt(2.0 / 40))  # sea sigma 0.3 m, slope sigma ~0.1
    phi = rng.uniform(0.0, 2 * math.pi, 40)

    def sea(x):
        return np.sum(a * np.sin(np.outer(x, k) + phi), axis=1)

    ret, surf = track(sea, 0.005, n=12000)
    mss_axis = float(np.sum(a**2 * k**2) / 2.0)
    vg = surface_variogram(ret, surf)
    g = math.tan(math.radians(18.9))
    grad = np.tile([0.0, g], (len(ret), 1))
    rst = RefractionSettings(phase_index=1.34, group_index=N_G)
    tpu = point_tpu(ret, surf, rst, seabed_gradient=grad)
    before = tpu.sigma_depth_m.copy()
    tpu = with_wave_facet(tpu, ret.direction_meas, surf, vg, grad[tpu.row], 1.34)
    want = _snell_depth_sd(math.sqrt(mss_axis), 5.0, g, 1.34 / N_AIR)
    facet = np.sqrt(sum(tpu.terms[t][:, DEPTH] ** 2 for t in FACET_TERMS))
    assert want > 1.5 * np.median(before)  # what the TPU had without the facet
    assert np.median(facet) == pytest.approx(want, rel=0.1)
    assert np.median(tpu.sigma_depth_m) == pytest.approx(
        math.hypot(want, np.median(before)), rel=0.1
    )


def test_wave_facet_across_a_profiler_whose_planes_follow_the_track():
    """The same sea, but each plane follows the sea's slope along the track exactly (as a
    profiler's fit does with its collinear neighbours) and stays level across it (flagged
    ill-conditioned). Heights above the planes then hardly rise along the track; across it the
    planes miss the whole sea's slope (isotropic), and over a seabed sloping 18.9° across, the
    depth error sd is Snell's with the sea's full slope sigma."""
    from pipeline.process.refraction import RefractionSettings
    from pipeline.process.returns import PointFlag
    from pipeline.uncertainty.tpu_facet import FACET_TERMS, track_directions, with_wave_facet

    rng = np.random.default_rng(8)
    lam = rng.uniform(10.0, 40.0, 40)
    k = 2 * math.pi / lam
    a = np.full(40, 0.3 * math.sqrt(2.0 / 40))
    phi = rng.uniform(0.0, 2 * math.pi, 40)

    def sea(x):
        return np.sum(a * np.sin(np.outer(x, k) + phi), axis=1)

    def slope(x):
        return np.sum(a * k * np.cos(np.outer(x, k) + phi), axis=1)

    ret, surf = track(sea, 0.005, n=12000)
    x = surf.entry_m[:, 0]
    nrm = np.column_stack([-slope(x), np.zeros_like(x), np.ones_like(x)])
    surf = dataclasses.replace(
        surf,
        normal=nrm / np.linalg.norm(nrm, axis=1, keepdims=True),
        entry_m=np.column_stack([surf.entry_m[:, :2], sea(x)]),
        flags=surf.flags | np.uint16(PointFlag.SURFACE_ILL_CONDITIONED),
    )
    mss_axis = float(np.sum(a**2 * k**2) / 2.0)
    vg = surface_variogram(ret, surf)
    assert 2.0 * vg.rise_per_m2 < 0.1 * mss_axis  # the planes follow the track's slope
    g = math.tan(math.radians(18.9))
    grad = np.tile([0.0, g], (len(ret), 1))
    rst = RefractionSettings(phase_index=1.34, group_index=N_G)
    tpu = point_tpu(ret, surf, rst, seabed_gradient=grad)
    along = track_directions(ret)
    np.testing.assert_allclose(np.abs(along), np.tile([1.0, 0.0], (len(ret), 1)), atol=1e-9)
    tpu = with_wave_facet(tpu, ret.direction_meas, surf, vg, grad[tpu.row], 1.34, track_xy=along)
    want = _snell_depth_sd(math.sqrt(mss_axis), 5.0, g, 1.34 / N_AIR)
    facet = np.sqrt(sum(tpu.terms[t][:, DEPTH] ** 2 for t in FACET_TERMS))
    assert np.median(facet) == pytest.approx(want, rel=0.1)


def test_no_wave_facet_on_a_flat_sea():
    """A flat sea (ranging noise only): the variogram does not rise, no facet term."""
    from pipeline.process.refraction import RefractionSettings
    from pipeline.uncertainty.tpu_facet import FACET_TERMS, with_wave_facet

    ret, surf = track(lambda x: np.zeros_like(x), 0.02)
    vg = surface_variogram(ret, surf)
    grad = np.tile([0.0, 0.3], (len(ret), 1))
    tpu = point_tpu(ret, surf, RefractionSettings(), seabed_gradient=grad)
    tpu = with_wave_facet(tpu, ret.direction_meas, surf, vg, grad[tpu.row], 1.34)
    facet = np.sqrt(sum(tpu.terms[t][:, DEPTH] ** 2 for t in FACET_TERMS))
    assert np.median(facet) < 0.1 * 0.02


def test_facet_excess_term_is_the_wind_sigma_share_of_the_correction():
    """Refraction raised each nadir sounding by ``L (1 - n_a/n_w)² mss / 2``; the logged wind's
    sigma ``sw`` makes ``mss`` uncertain by ``5.12e-3 sw`` (Cox-Munk): the term is that share of
    the excess, in the elevation and the depth, and correlated (one wind for the survey)."""
    from pipeline.process.refraction import RefractionSettings
    from pipeline.uncertainty.tpu_facet import EXCESS_TERM, with_facet_excess

    ret, surf = track(lambda x: 0.0 * x, 0.005, n=200)
    mss, mss_sigma = 0.054, 5.12e-3 * 2.0
    rst = RefractionSettings(
        phase_index=1.34, group_index=N_G, facet_mss=mss, facet_mss_sigma=mss_sigma
    )
    tpu = point_tpu(ret, surf, rst)
    assert with_facet_excess(tpu, ret.direction_meas, surf, rst) is tpu  # no facets, no term
    faceted = dataclasses.replace(surf, facet_slope_var=np.full((len(ret), 2), mss / 2))
    out = with_facet_excess(tpu, ret.direction_meas, faceted, rst)
    length = np.linalg.norm(tpu.xyz_m - faceted.entry_m[tpu.row], axis=1)
    want = length * (1.0 - N_AIR / 1.34) ** 2 * mss / 2.0 * mss_sigma / mss
    np.testing.assert_allclose(out.terms[EXCESS_TERM][:, DEPTH], want, rtol=3e-3)
    np.testing.assert_allclose(out.terms[EXCESS_TERM][:, 2], want, rtol=3e-3)
    np.testing.assert_allclose(
        out.sigma_depth_correlated_m, np.hypot(tpu.sigma_depth_correlated_m, want), rtol=3e-3
    )
    np.testing.assert_array_equal(out.sigma_depth_random_m, tpu.sigma_depth_random_m)


def test_an_isolated_sparse_lag_bin_is_not_read_by_the_wave_term():
    # suite shoal tuning 7004's shortest bins: pairs of a smooth sea over ranging noise
    # (gamma = s_r² + a h², written here) with, between two sweeps' classes, a bin of 218
    # pairs of another kind whose gamma lies below the ranging noise
    s_r, a = 0.023, 3.5e-4
    lags = np.array([0.77, 1.27, 1.53, 2.31, 3.44])
    gamma = s_r**2 + a * lags**2
    gamma[1] = 0.0104**2
    counts = np.array([28483, 218, 27562, 26660, 50708])
    nb = len(INCIDENCE_BANDS_DEG) - 1
    vg = SurfaceVariogram(lags, gamma, np.full(nb, s_r**2), int(counts.sum()), lag_pairs=counts)
    assert vg.pooled_nugget_m2 == pytest.approx(s_r**2, rel=1e-9)
    delta = np.array([0.3, 0.6, 1.0, 2.0])
    # the sea's part at each offset, rho = 1 read as the entry's (2 gamma_w): analytic below
    # the shortest lag (the h² rise from the origin), within the lag bins' linear
    # interpolation of the h² curve (< 10 % here) above it
    got = wave_entry_sigma_m(vg, delta)
    np.testing.assert_allclose(got[:2], np.sqrt(2 * a * delta[:2] ** 2), rtol=1e-9)
    np.testing.assert_allclose(got[2:], np.sqrt(2 * a * delta[2:] ** 2), rtol=0.1)
    # read with the sparse bin, the fit through the three shortest falls and the term vanishes
    blind = SurfaceVariogram(lags, gamma, np.full(nb, s_r**2), int(counts.sum()))
    assert blind.pooled_nugget_m2 == pytest.approx(gamma[0])
    assert np.all(wave_entry_sigma_m(blind, delta[:2]) == 0.0)


def test_sparse_bins_rising_in_a_run_of_their_own_are_read():
    # an oscillating scanner's shortest lags (suite tuning 33): few pairs, but no dip between
    # two dense neighbours
    lags = np.array([0.38, 0.76, 1.3, 1.78, 2.46])
    gamma = 1e-4 + 2e-4 * lags**2
    counts = np.array([220, 409, 966, 11528, 2082])
    nb = len(INCIDENCE_BANDS_DEG) - 1
    vg = SurfaceVariogram(lags, gamma, np.full(nb, 1e-4), int(counts.sum()), lag_pairs=counts)
    got_lag, got_gamma = vg.wave_lags()
    np.testing.assert_array_equal(got_lag, lags)
    np.testing.assert_array_equal(got_gamma, gamma)
