"""Tests of the survey stage: line planning, scan patterns, attitude, navigation noise, chunking."""

from __future__ import annotations

import dataclasses
import functools
import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from pipeline.config import from_mapping
from pipeline.errors import SceneError
from pipeline.simulate.survey import (
    AttitudeSettings,
    FlightSettings,
    NavigationNoiseSettings,
    Pulses,
    ScannerSettings,
    beam_directions_body,
    body_to_local,
    flat_ground_hits,
    generate_pulses,
    iter_pulse_chunks,
    n_chunks,
    navigation_errors,
    plan_lines,
    pulses_for_range,
    rotate_body_to_local,
)

STILL = AttitudeSettings(
    roll_amplitude_deg=0.0, pitch_amplitude_deg=0.0, yaw_amplitude_deg=0.0, drift_sigma_deg=0.0
)
NO_NAV_NOISE = NavigationNoiseSettings(
    gnss_horizontal_sigma_m=0.0,
    gnss_vertical_sigma_m=0.0,
    ins_roll_sigma_deg=0.0,
    ins_pitch_sigma_deg=0.0,
    ins_heading_sigma_deg=0.0,
)
ENU_FROM_NED = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])


def all_pulses(flight, attitude, nav, scanner, seed=7, chunk_size=1_000_000):
    lines = plan_lines(flight, scanner)
    parts = list(iter_pulse_chunks(flight, attitude, nav, scanner, lines, chunk_size, seed))
    return lines, Pulses.concatenate(parts)


def line_frame(heading_rad):
    """Unit vectors along and to the right of a line with the given heading (clockwise from N)."""
    return (
        np.array([math.sin(heading_rad), math.cos(heading_rad)]),
        np.array([math.cos(heading_rad), -math.sin(heading_rad)]),
    )


# --------------------------------------------------------------------------- scan patterns


PALMER = ScannerSettings(kind="palmer", off_nadir_deg=20.0, prf_hz=20000.0, scan_rate_hz=25.0)
H = 400.0


@functools.cache
def palmer_survey():
    flight = FlightSettings(
        altitude_m=H, speed_m_s=60.0, heading_deg=30.0, area_m=(0.0, 600.0, 0.0, 600.0), n_lines=2
    )
    return all_pulses(flight, STILL, NO_NAV_NOISE, PALMER)


def test_palmer_footprints_on_circle_around_nadir():
    lines, p = palmer_survey()
    radius = H * math.tan(math.radians(20.0))
    for ground_z in (0.0, -7.5):
        hits = flat_ground_hits(p.origin_m, p.direction, ground_z)
        r = np.hypot(hits[:, 0] - p.origin_m[:, 0], hits[:, 1] - p.origin_m[:, 1])
        expected = (H - ground_z) * math.tan(math.radians(20.0))
        # 1 mm: the brief's requirement; float64 geometry is good to ~1e-10 m here.
        assert np.max(np.abs(r - expected)) < 1e-3
        assert np.allclose(hits[:, 2], ground_z, atol=1e-9)  # exact plane up to rounding
    # Azimuth of each footprint, measured clockwise (from above) from the flight direction,
    # equals the scan angle: rotation sense and zero of the Palmer pattern.
    hits = flat_ground_hits(p.origin_m, p.direction, 0.0)
    for j in range(lines.n_lines):
        sel = p.line_id == j
        fwd, right = line_frame(lines.heading_rad[j])
        off = hits[sel, :2] - p.origin_m[sel, :2]
        az = np.arctan2(off @ right, off @ fwd)
        diff = np.angle(np.exp(1j * (az - p.scan_angle_rad[sel])))
        assert np.max(np.abs(diff)) < 1e-9  # rounding only
        assert np.max(np.abs(np.hypot(off @ fwd, off @ right) - radius)) < 1e-3


def test_palmer_swath_width_and_mean_density():
    lines, p = palmer_survey()
    radius = H * math.tan(math.radians(20.0))
    swath = 2.0 * radius
    assert lines.swath_width_m == pytest.approx(swath, rel=1e-12)  # same formula, rounding
    hits = flat_ground_hits(p.origin_m, p.direction, 0.0)
    sel = p.line_id == 0
    fwd, right = line_frame(lines.heading_rad[0])
    rel = hits[sel, :2] - lines.start_xy[0]
    u, v = rel @ fwd, rel @ right
    # Widest footprint is at most half an azimuth step (pi f / PRF) from +-90 deg.
    tol = 2.0 * radius * (1.0 - math.cos(math.pi * PALMER.scan_rate_hz / PALMER.prf_hz)) + 1e-9
    assert abs((v.max() - v.min()) - swath) <= tol
    # Mean density over the full swath width in a window far (> radius) from the line ends.
    mid = 0.5 * lines.length_m
    window = 200.0
    assert mid - window / 2 > radius + 1 and lines.length_m - (mid + window / 2) > radius + 1
    count = np.count_nonzero((np.abs(u - mid) <= window / 2) & (np.abs(v) <= radius + 1e-6))
    density = count / (window * swath)
    expected = PALMER.prf_hz / (60.0 * swath)
    assert density == pytest.approx(expected, rel=0.05)  # brief: 5 %; measured ~0.1 %


def test_oscillating_scan_excursion_and_constant_angular_speed():
    # PRF / scan rate chosen so that pulses fall exactly on the turning points (t = (n + 1/4)/f).
    scanner = ScannerSettings(
        kind="oscillating", scan_half_angle_deg=15.0, prf_hz=40000.0, scan_rate_hz=20.0
    )
    flight = FlightSettings(altitude_m=H, area_m=(0.0, 100.0, 0.0, 300.0), n_lines=1)
    lines, p = all_pulses(flight, STILL, NO_NAV_NOISE, scanner)
    hits = flat_ground_hits(p.origin_m, p.direction, 0.0)
    fwd, right = line_frame(lines.heading_rad[0])
    off = hits[:, :2] - p.origin_m[:, :2]
    across, along = off @ right, off @ fwd
    limit = H * math.tan(math.radians(15.0))
    assert np.max(np.abs(along)) < 1e-9  # the mirror sweeps straight across track
    assert np.max(np.abs(across)) <= limit + 1e-9  # never beyond the half-angle
    assert abs(across.max() - limit) < 1e-3 and abs(across.min() + limit) < 1e-3  # 1 mm
    beta = np.arctan2(across, H)
    step = np.abs(np.diff(beta))
    nominal = 4.0 * math.radians(15.0) * scanner.scan_rate_hz / scanner.prf_hz
    assert np.max(step) < nominal * (1 + 1e-9)  # constant speed, smaller only at turnarounds
    assert np.median(step) == pytest.approx(nominal, rel=1e-9)


def test_profiler_hits_straight_below():
    scanner = ScannerSettings(kind="profiler", prf_hz=5000.0, beam_divergence_mrad=1.0)
    flight = FlightSettings(altitude_m=100.0, area_m=(0.0, 10.0, 0.0, 200.0), n_lines=2)
    lines, p = all_pulses(flight, STILL, NO_NAV_NOISE, scanner)
    hits = flat_ground_hits(p.origin_m, p.direction, 0.0)
    assert np.max(np.abs(hits[:, :2] - p.origin_m[:, :2])) < 1e-12  # exact nadir
    assert np.array_equal(p.direction, np.tile([0.0, 0.0, -1.0], (len(p), 1)))
    # Swath of a profiler = footprint diameter 2 H tan(1 mrad / 2).
    assert lines.swath_width_m == pytest.approx(2 * 100.0 * math.tan(0.5e-3), rel=1e-12)  # rounding


def test_flat_ground_hits_misses_are_nan():
    o = np.array([[0.0, 0.0, 10.0]] * 3)
    d = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.6, 0.0, -0.8]])
    hits = flat_ground_hits(o, d, 0.0)
    assert np.all(np.isnan(hits[:2]))
    assert np.allclose(hits[2], [7.5, 0.0, 0.0], atol=1e-12)  # 10 m down at 0.75 m/m sideways


# --------------------------------------------------------------------------- line planning


def test_line_spacing_gives_requested_overlap():
    scanner = ScannerSettings(kind="palmer", off_nadir_deg=20.0)
    flight = FlightSettings(altitude_m=400.0, area_m=(-500.0, 500.0, -500.0, 500.0))
    lines = plan_lines(flight, scanner)
    swath = 2 * 400.0 * math.tan(math.radians(20.0))  # 291.18 m
    assert lines.swath_width_m == pytest.approx(swath, rel=1e-12)  # rounding
    # Hand count: (n - 1) * 0.7 * swath + swath >= 1000 m needs n = 5.
    assert lines.n_lines == 5
    fwd, right = line_frame(0.0)
    centres = lines.start_xy @ right
    overlap = (swath - np.diff(centres)) / swath
    assert np.allclose(overlap, 0.3, rtol=0, atol=1e-12)  # exact up to rounding
    assert centres.mean() == pytest.approx(0.0, abs=1e-9)  # centred on the area


@pytest.mark.parametrize("kind", ["palmer", "oscillating"])
def test_lines_cover_rotated_area_boustrophedon(kind):
    scanner = ScannerSettings(kind=kind, off_nadir_deg=15.0, scan_half_angle_deg=25.0)
    flight = FlightSettings(
        altitude_m=300.0,
        heading_deg=30.0,
        area_m=(100.0, 900.0, -200.0, 300.0),
        side_overlap_fraction=0.5,
        turn_time_s=40.0,
    )
    lines = plan_lines(flight, scanner)
    swath, spacing = lines.swath_width_m, lines.line_spacing_m
    assert spacing == pytest.approx(0.5 * swath, rel=1e-12)  # exact up to rounding
    xs, ys = np.meshgrid(np.linspace(100.0, 900.0, 41), np.linspace(-200.0, 300.0, 41))
    pts = np.column_stack([xs.ravel(), ys.ravel()])
    covered = np.zeros(len(pts), dtype=bool)
    for j in range(lines.n_lines):
        fwd, right = line_frame(lines.heading_rad[j])
        rel = pts - lines.start_xy[j]
        u, v = rel @ fwd, rel @ right
        covered |= (np.abs(v) <= swath / 2 + 1e-9) & (u >= -1e-9) & (u <= lines.length_m + 1e-9)
        assert np.allclose(lines.end_xy[j] - lines.start_xy[j], lines.length_m * fwd, atol=1e-9)
    assert covered.all()
    # Minimal: one line fewer could not span the across-track width of the area.
    _, right0 = line_frame(math.radians(30.0))
    corners = np.array([[100.0, -200.0], [100.0, 300.0], [900.0, -200.0], [900.0, 300.0]])
    width = np.ptp(corners @ right0)
    assert (lines.n_lines - 2) * spacing + swath < width
    # Boustrophedon: alternate headings, each line starts beside the previous line's end.
    dh = np.diff(lines.heading_rad)
    assert np.allclose(np.abs(dh), math.pi, atol=1e-12)  # rounding of the mod 2 pi
    gaps = np.linalg.norm(lines.start_xy[1:] - lines.end_xy[:-1], axis=1)
    assert np.allclose(gaps, spacing, atol=1e-9)  # rounding of metre-scale coordinates
    # Timing: each line takes n_pulses / PRF, then the turn.
    step = lines.n_pulses[0] / scanner.prf_hz + 40.0
    assert np.allclose(np.diff(lines.t_start_s), step, rtol=0, atol=1e-9)  # rounding


def test_plan_overrides_and_pulse_timing():
    scanner = ScannerSettings(prf_hz=1000.0)
    flight = FlightSettings(
        area_m=(0.0, 1000.0, 0.0, 1000.0),
        n_lines=3,
        line_length_m=120.0,
        run_in_m=10.0,
        speed_m_s=50.0,
        start_time_s=100.0,
        turn_time_s=30.0,
    )
    lines, p = all_pulses(flight, STILL, NO_NAV_NOISE, scanner, chunk_size=500)
    assert lines.n_lines == 3 and lines.length_m == pytest.approx(140.0, abs=1e-9)
    assert np.all(lines.n_pulses == math.floor(140.0 / 50.0 * 1000.0) + 1)
    assert np.array_equal(p.pulse_id, np.arange(lines.n_pulses_total))
    expected_t = (
        100.0
        + p.line_id * (lines.n_pulses[0] / 1000.0 + 30.0)
        + (p.pulse_id - lines.pulse_offset[p.line_id]) / 1000.0
    )
    assert np.allclose(p.t_s, expected_t, rtol=0, atol=1e-9)
    # Nadir track: first/last pulse of each line at the planned start/end (in general the last
    # pulse is within one pulse spacing of the end; here 140 m / 50 m/s * 1000 Hz is an
    # integer, so it is exact up to rounding).
    first = lines.pulse_offset[:-1]
    last = lines.pulse_offset[1:] - 1
    assert np.allclose(p.origin_m[first, :2], lines.start_xy, atol=1e-9)
    assert np.allclose(p.origin_m[last, :2], lines.end_xy, atol=1e-9)


# --------------------------------------------------------------------------- attitude


def test_rotation_signs_hand_computed():
    ten = math.radians(10.0)
    nadir = np.array([[0.0, 0.0, 1.0]])
    # Roll +10 deg (right wing down), heading north: nadir beam tilts LEFT (west).
    d = rotate_body_to_local(np.array([ten]), np.array([0.0]), np.array([0.0]), nadir)
    assert np.allclose(d[0], [-math.sin(ten), 0.0, -math.cos(ten)], atol=1e-15)
    wing = rotate_body_to_local(np.array([ten]), np.array([0.0]), np.array([0.0]), [[0, 1.0, 0]])
    assert np.allclose(wing[0], [math.cos(ten), 0.0, -math.sin(ten)], atol=1e-15)  # dips
    # Pitch +10 deg (nose up), heading north: nadir beam tilts forward (north).
    d = rotate_body_to_local(np.array([0.0]), np.array([ten]), np.array([0.0]), nadir)
    assert np.allclose(d[0], [0.0, math.sin(ten), -math.cos(ten)], atol=1e-15)
    # Yaw 90 deg: forward is east, right wing south.
    m = body_to_local(np.array([0.0]), np.array([0.0]), np.array([math.pi / 2]))[0]
    assert np.allclose(m @ [1.0, 0, 0], [1.0, 0, 0], atol=1e-15)
    assert np.allclose(m @ [0, 1.0, 0], [0, -1.0, 0], atol=1e-15)


def test_rotation_matches_scipy_zyx_euler():
    rng = np.random.default_rng(3)
    roll, pitch = rng.uniform(-0.5, 0.5, 200), rng.uniform(-0.5, 0.5, 200)
    yaw = rng.uniform(0.0, 2 * math.pi, 200)
    ref = ENU_FROM_NED @ Rotation.from_euler("ZYX", np.column_stack([yaw, pitch, roll])).as_matrix()
    assert np.allclose(body_to_local(roll, pitch, yaw), ref, atol=1e-14)  # rounding
    v = rng.normal(size=(200, 3))
    assert np.allclose(
        rotate_body_to_local(roll, pitch, yaw, v), np.einsum("nij,nj->ni", ref, v), atol=1e-14
    )  # rounding


def test_pulse_directions_use_attitude_and_body_scan():
    scanner = ScannerSettings(kind="palmer", prf_hz=5000.0)
    flight = FlightSettings(area_m=(0.0, 10.0, 0.0, 300.0), n_lines=2, heading_deg=200.0)
    attitude = AttitudeSettings(roll_amplitude_deg=3.0, drift_sigma_deg=0.5)
    _, p = all_pulses(flight, attitude, NavigationNoiseSettings(), scanner)
    body, _ = beam_directions_body(scanner, p.t_s)
    euler = np.column_stack([p.yaw_rad, p.pitch_rad, p.roll_rad])
    ref = np.einsum(
        "ij,njk,nk->ni", ENU_FROM_NED, Rotation.from_euler("ZYX", euler).as_matrix(), body
    )
    assert np.allclose(p.direction, ref, atol=1e-13)  # rounding
    assert np.allclose(np.linalg.norm(p.direction, axis=1), 1.0, atol=1e-14)  # rotation
    # Periodic part bounded by the amplitude; drift (sigma 0.5 deg) adds < 5 sigma.
    assert np.max(np.abs(p.roll_rad)) < math.radians(3.0 + 5 * 0.5)
    assert np.std(p.roll_rad) > math.radians(0.5)  # the motion is really on


# --------------------------------------------------------------------------- determinism


def noisy_setup():
    scanner = ScannerSettings(kind="palmer", prf_hz=35000.0, scan_rate_hz=20.0)
    flight = FlightSettings(area_m=(0.0, 400.0, 0.0, 250.0), n_lines=2, turn_time_s=3.0)
    attitude = AttitudeSettings(drift_correlation_time_s=2.0)
    # Short GNSS correlation time so the run crosses several blocks of knots; white INS noise
    # so it crosses many 4096-pulse blocks.
    nav = NavigationNoiseSettings(gnss_correlation_time_s=0.05, ins_correlation_time_s=0.0)
    return flight, attitude, nav, scanner, plan_lines(flight, scanner)


def test_chunk_size_does_not_change_pulses():
    flight, attitude, nav, scanner, lines = noisy_setup()
    assert 290_000 < lines.n_pulses_total < 310_000
    runs = {}
    for size in (100_000, 1000, 777):
        chunks = list(iter_pulse_chunks(flight, attitude, nav, scanner, lines, size, 11))
        assert len(chunks) == n_chunks(lines, size)
        assert all(len(c) <= size for c in chunks)
        runs[size] = Pulses.concatenate(chunks)
    ref = runs[100_000]
    assert np.array_equal(ref.pulse_id, np.arange(lines.n_pulses_total))
    for size in (1000, 777):
        for f in dataclasses.fields(Pulses):
            assert np.array_equal(getattr(runs[size], f.name), getattr(ref, f.name)), f.name
    # Single pulses around a noise-block boundary and a line boundary.
    for i in (4095, 4096, int(lines.pulse_offset[1]) - 1, int(lines.pulse_offset[1])):
        one = generate_pulses(flight, attitude, nav, scanner, lines, i, 1, 11)
        for f in dataclasses.fields(Pulses):
            assert np.array_equal(getattr(one, f.name), getattr(ref, f.name)[i : i + 1]), f.name
    # Another seed gives another realisation.
    other = pulses_for_range(flight, attitude, nav, scanner, lines, 0, 1000, 12)
    assert not np.array_equal(other.origin_meas_m, ref.origin_meas_m[:1000])


# --------------------------------------------------------------------------- navigation noise


def test_white_navigation_noise_has_configured_sigma():
    nav = NavigationNoiseSettings(
        gnss_horizontal_sigma_m=0.05,
        gnss_vertical_sigma_m=0.1,
        gnss_correlation_time_s=0.0,
        ins_roll_sigma_deg=0.01,
        ins_pitch_sigma_deg=0.02,
        ins_heading_sigma_deg=0.03,
        ins_correlation_time_s=0.0,
    )
    scanner = ScannerSettings(prf_hz=10000.0)
    flight = FlightSettings(area_m=(0.0, 10.0, 0.0, 600.0), n_lines=1)
    _, p = all_pulses(flight, STILL, nav, scanner)
    n = len(p)
    assert n > 100_000
    err = np.column_stack(
        [
            p.origin_meas_m - p.origin_m,
            p.roll_meas_rad - p.roll_rad,
            p.pitch_meas_rad - p.pitch_rad,
            p.yaw_meas_rad - p.yaw_rad,
        ]
    )
    sigma = np.array([0.05, 0.05, 0.1] + [math.radians(s) for s in (0.01, 0.02, 0.03)])
    # Standard error of a sample sigma is 1/sqrt(2n) = 0.22 %; 1.5 % is ~7 standard errors.
    assert np.allclose(err.std(axis=0) / sigma, 1.0, rtol=0, atol=0.015)
    assert np.all(np.abs(err.mean(axis=0)) < 5 * sigma / math.sqrt(n))  # 5 standard errors
    corr = np.corrcoef(err.T)  # independent axes and white in time: |r| < 5/sqrt(n)
    assert np.max(np.abs(corr - np.eye(6))) < 5 / math.sqrt(n)
    lag1 = [np.corrcoef(e[:-1], e[1:])[0, 1] for e in err.T]
    assert np.max(np.abs(lag1)) < 5 / math.sqrt(n)
    # Measured direction = body beam rotated with the measured attitude.
    body, _ = beam_directions_body(scanner, p.t_s)
    ref = rotate_body_to_local(p.roll_meas_rad, p.pitch_meas_rad, p.yaw_meas_rad, body)
    assert np.array_equal(p.direction_meas, ref)


def test_gauss_markov_navigation_noise_sigma_and_correlation():
    tau = 2.0
    nav = NavigationNoiseSettings(
        gnss_horizontal_sigma_m=0.04,
        gnss_vertical_sigma_m=0.08,
        gnss_correlation_time_s=tau,
        ins_roll_sigma_deg=0.005,
        ins_pitch_sigma_deg=0.005,
        ins_heading_sigma_deg=0.01,
        ins_correlation_time_s=tau,
    )
    n = 40_000
    # Sample every tau/4, off the knot grid (knots every tau/16), over 10 000 tau.
    t = (np.arange(n) + 0.37 / 4) * (tau / 4)
    pos, att = navigation_errors(np.arange(n), t, nav, seed=5)
    err = np.column_stack([pos, att])
    sigma = np.array([0.04, 0.04, 0.08] + [math.radians(s) for s in (0.005, 0.005, 0.01)])
    # AR(1) with rho = exp(-1/4): sample-sigma standard error ~ 0.7 %; 4 % is ~5.7 of them.
    assert np.allclose(err.std(axis=0) / sigma, 1.0, rtol=0, atol=0.04)
    for e in err.T:
        r1 = np.corrcoef(e[:-4], e[4:])[0, 1]  # lag tau
        r2 = np.corrcoef(e[:-8], e[8:])[0, 1]  # lag 2 tau
        # Bartlett standard error ~0.008; interpolation between knots adds ~+0.01 at lag tau.
        assert r1 == pytest.approx(math.exp(-1.0), abs=0.04)
        assert r2 == pytest.approx(math.exp(-2.0), abs=0.04)
    # Same errors through the Pulses interface.
    scanner = ScannerSettings(prf_hz=2000.0)
    flight = FlightSettings(area_m=(0.0, 10.0, 0.0, 100.0), n_lines=1)
    _, p = all_pulses(flight, STILL, nav, scanner, seed=5)
    pos, att = navigation_errors(p.pulse_id, p.t_s, nav, seed=5)
    # origin + error - origin loses bits of the error at the metre scale: 1e-12 m.
    assert np.allclose(p.origin_meas_m - p.origin_m, pos, rtol=0, atol=1e-12)
    assert np.array_equal(p.roll_meas_rad - p.roll_rad, att[:, 0])


# --------------------------------------------------------------------------- settings


def test_settings_validation_via_from_mapping():
    s = from_mapping(ScannerSettings, {"kind": "oscillating", "prf_hz": 10000}, "scanner")
    assert s.kind == "oscillating" and s.prf_hz == 10000.0
    with pytest.raises(SceneError, match="scanner.kind"):
        from_mapping(ScannerSettings, {"kind": "rosette"}, "scanner")
    with pytest.raises(SceneError, match="flight.side_overlap_fraction"):
        from_mapping(FlightSettings, {"side_overlap_fraction": 0.95}, "flight")
    with pytest.raises(SceneError, match="area_m"):
        from_mapping(FlightSettings, {"area_m": [5.0, 1.0, 0.0, 1.0]}, "flight")
    with pytest.raises(SceneError, match="gnss_correlation_time_s"):
        from_mapping(NavigationNoiseSettings, {"gnss_correlation_time_s": 1e-5}, "navigation")
    f = from_mapping(FlightSettings, {"n_lines": 4, "line_length_m": 250}, "flight")
    assert f.n_lines == 4 and f.line_length_m == 250.0
