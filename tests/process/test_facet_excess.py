"""The facet path's second-order excess against closed forms and brute-force facet averages.

References written here, not taken from the module: the nadir small-angle form
``L (1 - 1/n)² mss / 2``; a Monte Carlo average over Gaussian facet slopes of the energy-weighted
in-water path ``D / -t_z(beta)`` (Snell's law by hand, not :func:`pipeline.optics.
refract_direction`), read along the level plane's direction; the sample variance of synthetic
plane slopes.
"""

import dataclasses

import numpy as np
import pytest

from pipeline.process.facet_excess import (
    expected_depth_excess_m,
    track_directions,
    unresolved_slope_var,
    wave_sea,
)
from pipeline.process.refraction import RefractionSettings, georeference, seabed_points
from pipeline.process.returns import DetectedReturns, PointFlag, ReturnKind
from pipeline.process.surface_fit import fit_water_surface
from tests.process.test_refraction import FIT, N_AIR, N_GROUP, N_PHASE, C, analytic_pulses

MSS = 0.054  # Cox-Munk at ~10 m/s


def _snell_tz(theta_air, beta_x, beta_y, azimuth=0.0):
    """Vertical component of the refracted direction through a facet of gradient (bx, by).

    The beam comes in at ``theta_air`` off nadir towards +x (azimuth 0). Snell by hand: the
    tangential part of the direction scales by n_air / n_w, the normal part follows.
    """
    d = np.array([np.sin(theta_air), 0.0, -np.cos(theta_air)])
    nrm = np.column_stack([-beta_x, -beta_y, np.ones_like(beta_x)])
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    cos_i = -(nrm @ d)
    tang = d[None, :] + cos_i[:, None] * nrm  # d minus its normal part
    eta = N_AIR / N_PHASE
    sin2_t = eta**2 * np.sum(tang**2, axis=1)
    t = eta * tang - np.sqrt(1.0 - sin2_t)[:, None] * nrm
    return t[:, 2]


def test_nadir_excess_is_the_small_angle_closed_form():
    length = np.array([0.5, 12.7, 60.0])
    d = np.tile([0.0, 0.0, -1.0], (3, 1))
    nrm = np.tile([0.0, 0.0, 1.0], (3, 1))
    got = expected_depth_excess_m(d, nrm, length, N_AIR, N_PHASE, np.full((3, 2), MSS / 2))
    # n_air enters Snell's ratio: (1 - n_air/n_w)² (= (1 - 1/n_w)² for n_air = 1)
    want = length * (1.0 - N_AIR / N_PHASE) ** 2 * MSS / 2.0
    np.testing.assert_allclose(got, want, rtol=2e-3)  # 4th order: mss² ~ 3e-3 relative
    # at nadir the weighting has no first-order turn to act on: no decay dependence
    heavy = expected_depth_excess_m(
        d, nrm, length, N_AIR, N_PHASE, np.full((3, 2), MSS / 2), decay_per_m=0.5
    )
    np.testing.assert_allclose(heavy, got, rtol=1e-9)


@pytest.mark.parametrize("theta_deg", [0.0, 12.0, 20.0])
@pytest.mark.parametrize("decay_per_m", [0.0, 0.15, 0.4])
def test_excess_matches_a_brute_force_facet_average(theta_deg, decay_per_m):
    rng = np.random.default_rng(7)
    theta = np.radians(theta_deg)
    s2 = np.array([0.030, 0.020])  # anisotropic: along x (the beam's plane), along y
    n = 1_000_000
    bx = rng.normal(0.0, np.sqrt(s2[0]), n)
    by = rng.normal(0.0, np.sqrt(s2[1]), n)
    tz = _snell_tz(theta, bx, by)
    tz0 = _snell_tz(theta, np.zeros(1), np.zeros(1))[0]
    depth = 12.0
    path = depth / -tz  # each facet's in-water path to a level seabed
    w = np.exp(-2.0 * decay_per_m * path)
    brute = np.sum(w * path) / np.sum(w) * -tz0 - depth
    scale = np.mean(path) * -tz0 - depth  # the unweighted excess: the size of the effect
    # its Monte Carlo error, by the same sum's sample spread
    se = np.std(path * -tz0) / np.sqrt(n)
    d = np.array([[np.sin(theta), 0.0, -np.cos(theta)]])
    got = expected_depth_excess_m(
        d,
        np.array([[0.0, 0.0, 1.0]]),
        np.array([depth / -tz0]),
        N_AIR,
        N_PHASE,
        s2[None, :],
        track_xy=np.array([[1.0, 0.0]]),
        decay_per_m=decay_per_m,
    )[0]
    # second order against the whole average. The next orders are a few per cent of the
    # effect's size; where the weighting nearly cancels the path's excess (20°, k = 0.4/m:
    # 0.8 mm left of 21 mm) they are what is left, so the bound is on the effect's size
    assert abs(got - brute) <= 4.0 * se + 0.06 * scale, (got, brute, scale, se)


def test_track_axes_rotate_the_slope_variance_with_the_line():
    # the beam's plane along y: the larger variance must now be given across an x track
    theta = np.radians(20.0)
    d = np.array([[0.0, np.sin(theta), -np.cos(theta)]])
    up = np.array([[0.0, 0.0, 1.0]])
    along_y = expected_depth_excess_m(
        d, up, np.array([12.0]), N_AIR, N_PHASE, np.array([[0.03, 0.0]]), np.array([[0.0, 1.0]])
    )
    across_x = expected_depth_excess_m(
        d, up, np.array([12.0]), N_AIR, N_PHASE, np.array([[0.0, 0.03]]), np.array([[-1.0, 0.0]])
    )
    np.testing.assert_allclose(along_y, across_x, rtol=1e-7)
    assert along_y[0] > 0.0


def test_unresolved_variance_is_the_sea_less_what_the_planes_follow():
    rng = np.random.default_rng(3)
    n = 20000
    px, py = rng.normal(0.0, 0.08, n), rng.normal(0.0, 0.05, n)  # the planes' slopes
    normal = np.column_stack([-px, -py, np.ones(n)])
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    sig = np.full(n, 0.02)  # each plane's tilt sigma (both axes)
    water = np.ones(n, bool)
    flags = np.zeros(n, np.uint16)
    track = np.tile([1.0, 0.0], (n, 1))
    var = unresolved_slope_var(MSS, normal, sig, water, flags, track)
    e2 = 0.02**2 / 2.0
    np.testing.assert_allclose(var[:, 0], MSS / 2 - np.var(px) + 2 * e2, rtol=1e-9)
    np.testing.assert_allclose(var[:, 1], MSS / 2 - np.var(py) + 2 * e2, rtol=1e-9)
    # a profiler's plane, level across its track: the whole sea's slope is missed there
    blind = flags | np.uint16(PointFlag.SURFACE_ILL_CONDITIONED)
    normal_b = np.column_stack([-px, np.zeros(n), np.ones(n)])
    normal_b /= np.linalg.norm(normal_b, axis=1, keepdims=True)
    var_b = unresolved_slope_var(MSS, normal_b, sig, water, blind, track)
    np.testing.assert_allclose(var_b[:, 1], MSS / 2)
    # planes that follow more than the sea holds: nothing left (never negative)
    assert np.all(unresolved_slope_var(1e-4, normal, sig * 0, water, flags, track) == 0.0)
    # no water, no facets
    assert np.all(unresolved_slope_var(MSS, normal, sig, ~water, flags, track) == 0.0)


def test_track_directions_follow_each_line():
    t = np.linspace(0.0, 100.0, 50)
    xy = np.concatenate([np.column_stack([t, 0.01 * t]), np.column_stack([5.0 + 0 * t, t])])
    line = np.repeat([0, 1], 50)
    axis = track_directions(xy, line)
    assert np.all(np.abs(axis[:50, 0]) > 0.99) and np.all(np.abs(axis[50:, 1]) > 0.999)


def test_refraction_raises_soundings_by_the_excess_and_a_flat_sea_gets_none():
    ret, bottom, length, theta, _ = analytic_pulses()
    surface = fit_water_surface(ret, FIT)
    st = RefractionSettings(phase_index=N_PHASE, group_index=N_GROUP, facet_mss=MSS)
    plain = seabed_points(ret, surface, st)
    s2 = np.full((len(ret), 2), MSS / 2)
    faceted = dataclasses.replace(surface, facet_slope_var=s2)
    pts = seabed_points(ret, faceted, st)
    rise = pts.xyz_m[:, 2] - plain.xyz_m[:, 2]
    np.testing.assert_array_equal(pts.xyz_m[:, :2], plain.xyz_m[:, :2])  # vertical only
    np.testing.assert_allclose(plain.depth_m - pts.depth_m, rise, atol=1e-12)
    assert theta[0] == 0.0  # the nadir pulse: the closed form
    np.testing.assert_allclose(
        rise[0], length[0] * (1.0 - N_AIR / N_PHASE) ** 2 * MSS / 2.0, rtol=2e-3
    )
    assert np.all(rise > 0.0)
    # the whole chain: this sea's echoes are exact (no wave about the planes), so whatever the
    # logged wind there are no facets and the soundings stay on the seabed
    assert not wave_sea(ret, surface)
    proc = georeference(ret, surface_settings=FIT, refraction_settings=st)
    assert proc.surface.facet_slope_var is None
    on = proc.points.kind == ReturnKind.BOTTOM
    np.testing.assert_allclose(proc.points.xyz_m[on], bottom, atol=1e-3)


def _profile(sea, noise_m, n=4000, spacing_m=0.05, seed=5):
    """Nadir pulses along x at 60 m/s ranging the sea ``sea(x, t)`` with noise; exact bottoms."""
    rng = np.random.default_rng(seed)
    x = np.arange(n) * spacing_m
    return _nadir_pulses(x, sea, noise_m, rng)


def _nadir_pulses(x, sea, noise_m, rng):
    """Nadir pulses at ``x`` (60 m/s) ranging ``sea(x, t)`` with noise, bottoms 8 m under."""
    n = x.size
    t = x / 60.0
    r_air = 400.0 - (sea(x, t) + rng.normal(0.0, noise_m, n))
    ret = DetectedReturns(
        pulse_id=np.arange(n),
        origin_meas_m=np.column_stack([x, np.zeros(n), np.full(n, 400.0)]),
        direction_meas=np.tile([0.0, 0.0, -1.0], (n, 1)),
        has_surface=np.ones(n, bool),
        t_surface_s=2.0 * r_air * N_AIR / C,
        has_bottom=np.ones(n, bool),
        t_bottom_s=2.0 * (r_air * N_AIR + 8.0 * N_GROUP) / C,
        surface_confidence=np.ones(n),
        bottom_confidence=np.ones(n),
        flags=np.zeros(n, np.uint16),
        t_emit_s=t,
    )
    return ret, fit_water_surface(ret, FIT)


@pytest.mark.parametrize(
    ("name", "sea", "noise_m", "want"),
    [
        # a 10 m/s sea's long waves (sd 0.5 m, 80 m crests) under 1 cm of ranging noise
        ("waves", lambda x, t: 0.7 * np.cos(2 * np.pi * (x - 11.0 * t) / 80.0), 0.01, True),
        # a 2 m/s sea's short ones (sd 2 cm, 3.3 m) under 5 mm: still more wave than noise
        ("short", lambda x, t: 0.03 * np.cos(2 * np.pi * (x - 2.3 * t) / 3.3), 0.005, True),
        ("flat", lambda x, t: 0.0 * x, 0.01, False),
        # a rising tide (0.5 m/h, ten times M2's fastest) under noise: flat, no waves
        ("tide", lambda x, t: 0.5 / 3600.0 * t, 0.005, False),
        # a flat sea whose echoes' bias drifts 0.2 m over the track's shoal (suite held-out
        # seeds 1, 8: the rise between the longest and shortest lags took it for waves)
        ("drift", lambda x, t: 0.1 * np.tanh((x - 100.0) / 20.0), 0.005, False),
    ],
)
def test_wave_sea_is_the_heights_rise_with_lag(name, sea, noise_m, want):
    ret, surface = _profile(sea, noise_m)
    assert wave_sea(ret, surface) is want, name
    # photon windows of 20 shots share one detection: never paired within, same verdict
    assert wave_sea(ret, surface, group=ret.pulse_id // 20) is want, name


@pytest.mark.parametrize("sea_kind", ["waves", "flat"])
def test_tpu_budgets_the_uncorrected_excess_as_the_correction_would_take_it(sea_kind):
    """With the correction off, the TPU's term is the rise the correction would have given
    each sounding (refraction's own path: depth off less depth on), and nothing over a sea
    whose echoes show no waves; with it on, no such term."""
    from pipeline.uncertainty.tpu import point_tpu
    from pipeline.uncertainty.tpu_facet import UNCORRECTED_TERM, with_uncorrected_facet_excess
    from pipeline.uncertainty.tpu_settings import DEPTH

    sea = {
        "waves": lambda x, t: 0.7 * np.cos(2 * np.pi * (x - 11.0 * t) / 80.0),
        "flat": lambda x, t: 0.0 * x,
    }[sea_kind]
    ret, _ = _profile(sea, 0.01, n=1500)
    off = RefractionSettings(phase_index=N_PHASE, group_index=N_GROUP, facet_mss_uncorrected=MSS)
    on = RefractionSettings(phase_index=N_PHASE, group_index=N_GROUP, facet_mss=MSS)
    p_off = georeference(ret, surface_settings=FIT, refraction_settings=off)
    p_on = georeference(ret, surface_settings=FIT, refraction_settings=on)
    tpu = point_tpu(ret, p_off.surface, off)
    got = with_uncorrected_facet_excess(tpu, ret, p_off.surface, off)
    if sea_kind == "flat":
        assert UNCORRECTED_TERM not in got.terms
        np.testing.assert_array_equal(got.sigma_depth_m, tpu.sigma_depth_m)
        return
    b_off = p_off.points.select(p_off.points.kind == ReturnKind.BOTTOM)
    b_on = p_on.points.select(p_on.points.kind == ReturnKind.BOTTOM)
    rise = b_off.depth_m - b_on.depth_m
    pos = np.searchsorted(b_off.pulse_id, ret.pulse_id[tpu.row])
    term = got.terms[UNCORRECTED_TERM][:, DEPTH]
    assert np.all(rise[pos] > 0.0)
    np.testing.assert_allclose(term, rise[pos], rtol=0.02)
    # correlated: the totals grow by it in quadrature, the random part does not
    np.testing.assert_allclose(got.sigma_depth_m, np.hypot(tpu.sigma_depth_m, term), rtol=1e-12)
    np.testing.assert_array_equal(got.sigma_depth_random_m, tpu.sigma_depth_random_m)
    # with the correction on, its own (wind-sigma) term stands and this one is not added
    tpu_on = point_tpu(ret, p_on.surface, on)
    assert with_uncorrected_facet_excess(tpu_on, ret, p_on.surface, on) is tpu_on


def _sparse_short_lags(sea, noise_m, seed=5):
    """Nadir pulses 2.5 m apart along x (a scan's own spacing) and 300 close second looks.

    Pairs under 2 m are ~300, spread over the five shortest lag bins (each under
    MIN_PAIRS alone): suite tuning seed 502's Palmer geometry.
    """
    rng = np.random.default_rng(seed)
    base = np.arange(1200) * 2.5
    x = np.sort(np.concatenate([base, rng.choice(base, 300) + rng.uniform(0.1, 1.9, 300)]))
    return _nadir_pulses(x, sea, noise_m, rng)


def test_wave_sea_pools_sparse_short_lags():
    # short waves (4-6 m, sd 5 cm) whose heights' D(h) has levelled off by 2.5 m and falls
    # again by 5 m: the two bins that hold enough pairs alone (2-3 m, 4-6 m) show no rise,
    # and the sparse pairs under 2 m, pooled, show it (before: no wave sea told here)
    rng = np.random.default_rng(1)
    lam, phase = rng.uniform(4.0, 6.0, 12), rng.uniform(0.0, 2.0 * np.pi, 12)

    def sea(x, t):
        waves = zip(lam, phase, strict=True)
        return sum(0.02 * np.cos(2 * np.pi * (x - 2.5 * t) / w + p) for w, p in waves)

    assert wave_sea(*_sparse_short_lags(sea, 0.005))
    # the same scan over a flat sea: still none
    assert not wave_sea(*_sparse_short_lags(lambda x, t: 0.0 * x, 0.005))
