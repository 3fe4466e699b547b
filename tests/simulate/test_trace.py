import math

import numpy as np
import pytest

from pipeline.simulate import paths as P
from pipeline.simulate.survey import (
    AttitudeSettings,
    FlightSettings,
    NavigationNoiseSettings,
    ScannerSettings,
    iter_pulse_chunks,
    plan_lines,
)
from pipeline.simulate.trace import (
    MeshCaster,
    TraceSettings,
    World,
    subray_pattern,
    trace,
)

N_WATER = 1.3415
H_M = 400.0


def _plane_mesh(z0, gx=0.0, gy=0.0, half=2000.0, n=8):
    """A plane z = z0 + gx x + gy y triangulated on an n × n grid (written here, not terrain)."""
    xs = np.linspace(-half, half, n + 1)
    xx, yy = np.meshgrid(xs, xs)
    v = np.column_stack([xx.ravel(), yy.ravel(), (z0 + gx * xx + gy * yy).ravel()])
    idx = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, 1:].ravel(), idx[1:, :-1]
    faces = np.concatenate([np.column_stack([a, b, c]), np.column_stack([a, c, d.ravel()])])
    return MeshCaster(v, faces)


class _Pulses:
    """The few Pulses fields the tracer reads."""

    def __init__(self, origin, direction, yaw=None):
        self.origin_m = np.asarray(origin, float)
        self.direction = np.asarray(direction, float)
        self.pulse_id = np.arange(self.origin_m.shape[0], dtype=np.int64)
        self.yaw_rad = np.zeros(self.origin_m.shape[0]) if yaw is None else yaw


def _palmer_rays(theta_deg, n=36):
    th = math.radians(theta_deg)
    az = np.linspace(0, 2 * np.pi, n, endpoint=False)
    d = np.column_stack([np.sin(th) * np.sin(az), np.sin(th) * np.cos(az), -np.full(n, np.cos(th))])
    o = np.tile([0.0, 0.0, H_M], (n, 1))
    return _Pulses(o, d), th, az


def test_flat_water_flat_bottom_matches_analytic_snell():
    depth = 12.5
    world = World(water=_plane_mesh(0.0), seabed=_plane_mesh(-depth), n_air=1.0, n_water=N_WATER)
    pulses, th, az = _palmer_rays(20.0)
    p = trace(pulses, world, TraceSettings(), divergence_rad=1e-3)
    assert np.all(p.flags == P.OK)
    th_w = math.asin(math.sin(th) / N_WATER)
    r = H_M * math.tan(th) + depth * math.tan(th_w)
    expected = np.column_stack([r * np.sin(az), r * np.cos(az), np.full(az.size, -depth)])
    # 1 mm is the requirement; float64 re-solve gives ~1e-10 m
    np.testing.assert_allclose(p.bottom_xyz_m[:, 0], expected, atol=1e-3)
    np.testing.assert_allclose(p.incidence_rad[:, 0], th, atol=1e-12)
    np.testing.assert_allclose(p.water_path_m[:, 0], depth / math.cos(th_w), rtol=1e-12)
    np.testing.assert_allclose(p.air_range_m[:, 0], H_M / math.cos(th), rtol=1e-12)
    # unpolarised Fresnel transmission at 20° written out (eqs. 5, 9, 14, 15 with the errata)
    ci, ct = math.cos(th), math.cos(th_w)
    rs = (ci - N_WATER * ct) / (ci + N_WATER * ct)
    rp = (N_WATER * ci - ct) / (ct + N_WATER * ci)
    np.testing.assert_allclose(p.transmittance_down[:, 0], 1 - 0.5 * (rs**2 + rp**2), rtol=1e-12)
    # the return retraces the path: same Fresnel loss on the way up (reciprocity)
    np.testing.assert_allclose(p.transmittance_up[:, 0], p.transmittance_down[:, 0], rtol=1e-9)


@pytest.mark.parametrize("gx, gy", [(0.05, 0.0), (-0.03, 0.08), (0.2, 0.2)])
def test_sloped_bottom_hits_lie_on_the_analytic_plane(gx, gy):
    z0 = -60.0  # deep enough that the steepest plane stays under water across the 145 m circle
    world = World(
        water=_plane_mesh(0.0), seabed=_plane_mesh(z0, gx, gy), n_air=1.0, n_water=N_WATER
    )
    pulses, th, az = _palmer_rays(20.0, n=72)
    p = trace(pulses, world, TraceSettings(), divergence_rad=1e-3)
    assert np.all(p.flags == P.OK)
    b = p.bottom_xyz_m[:, 0]
    np.testing.assert_allclose(b[:, 2], z0 + gx * b[:, 0] + gy * b[:, 1], atol=1e-3)
    # and the hit is where the refracted ray meets that plane (solved here analytically)
    s = p.surface_xyz_m[:, 0]
    r = p.refracted_dir[:, 0]
    t = (z0 + gx * s[:, 0] + gy * s[:, 1] - s[:, 2]) / (r[:, 2] - gx * r[:, 0] - gy * r[:, 1])
    np.testing.assert_allclose(b, s + t[:, None] * r, atol=1e-3)
    # bottom incidence: angle between the reversed ray and the plane's upward normal
    nrm = np.array([-gx, -gy, 1.0]) / math.sqrt(gx * gx + gy * gy + 1)
    np.testing.assert_allclose(np.cos(p.bottom_incidence_rad[:, 0]), -(r @ nrm), atol=1e-9)


def test_flags_for_land_miss_and_no_bottom():
    water = _plane_mesh(0.0, half=100.0)
    # seabed rising through the water surface at x = 50 m: land beyond
    seabed = _plane_mesh(-5.0, gx=0.1, half=80.0)
    world = World(water=water, seabed=seabed, n_air=1.0, n_water=N_WATER)
    origins = np.array(
        [[0.0, 0, 100], [70.0, 0, 100], [500.0, 0, 100], [0.0, 0, 100], [-90.0, 0, 100]]
    )
    dirs = np.array([[0, 0, -1.0], [0, 0, -1.0], [0, 0, -1.0], [0, 0, 1.0], [0, 0, -1.0]])
    p = trace(_Pulses(origins, dirs), world, TraceSettings(), divergence_rad=1e-3)
    f = p.flags[:, 0]
    assert f[0] == P.OK
    assert f[1] == P.LAND and p.surface_xyz_m[1, 0, 2] == pytest.approx(2.0, abs=1e-9)
    assert f[2] == P.MISS and f[3] == P.MISS
    assert f[4] == P.NO_BOTTOM  # water there but the seabed mesh ends at x = -80 m
    for name in ("air_range_m", "water_path_m", "transmittance_down", "bottom_xyz_m"):
        assert np.all(np.isfinite(getattr(p, name)))
    assert P.describe_flags(p.flags) == {
        "ok": 1,
        "miss": 2,
        "land": 1,
        "no_bottom": 1,
        "tir_return": 0,
    }


def test_subray_pattern_weights_and_spread():
    offsets, w = subray_pattern(61, divergence_rad=2e-3, cone_extent=1.5)
    assert w.sum() == pytest.approx(1.0, abs=1e-15)
    r = np.hypot(offsets[:, 0], offsets[:, 1])
    assert r.max() <= 1.5e-3 + 1e-15
    # Gaussian beam: the weighted mean of r² equals w²/2 for an untruncated beam; the
    # truncation at 1.5 w and 61 samples bias it by a few per cent
    assert np.sum(w * r**2) == pytest.approx(0.5 * 1e-3**2, rel=0.15)


def test_subrays_spread_the_footprint_on_the_bottom():
    depth = 10.0
    world = World(water=_plane_mesh(0.0), seabed=_plane_mesh(-depth), n_air=1.0, n_water=N_WATER)
    pulses = _Pulses([[0.0, 0.0, H_M]], [[0.0, 0.0, -1.0]])
    div = 2e-3
    p = trace(pulses, world, TraceSettings(subrays=37, cone_extent=1.0), divergence_rad=div)
    b = p.bottom_xyz_m[0]
    r = np.hypot(b[:, 0], b[:, 1])
    # the outermost sub-ray is at angle ~w: footprint radius H tan w + D tan(asin(sin w / n))
    w = 0.5 * div
    edge = H_M * math.tan(w) + depth * math.tan(math.asin(math.sin(w) / N_WATER))
    assert r.max() == pytest.approx(edge, rel=0.02)
    assert np.all(p.flags == P.OK)


@pytest.mark.slow
def test_identical_paths_for_chunk_sizes_1000_and_100000():
    flight = FlightSettings(
        altitude_m=300.0, speed_m_s=60.0, area_m=(0.0, 100.0, 0.0, 400.0), side_overlap_fraction=0.2
    )
    scanner = ScannerSettings(kind="palmer", off_nadir_deg=20.0, prf_hz=20000.0)
    lines = plan_lines(flight, scanner)
    water = _plane_mesh(0.0, half=3000.0, n=64)
    seabed = _plane_mesh(-8.0, gx=0.01, gy=-0.004, half=3000.0, n=64)
    world = World(water=water, seabed=seabed, n_air=1.000277, n_water=N_WATER)
    settings = TraceSettings(subrays=2)

    def run(chunk):
        chunks = iter_pulse_chunks(
            flight, AttitudeSettings(), NavigationNoiseSettings(), scanner, lines, chunk, seed=5
        )
        return P.Paths.concatenate(
            [trace(c, world, settings, 1e-3, "linear_across_track") for c in chunks]
        )

    a, b = run(1000), run(100_000)
    assert a.n_pulses == lines.n_pulses_total > 100_000
    assert a.equals(b)


class _StubWater:
    """Flat water at z = 0 seen from above; seen from below, a facet tilted ``tilt_deg``."""

    def __init__(self, tilt_deg):
        t = math.radians(tilt_deg)
        self.up_normal = np.array([math.sin(t), 0.0, math.cos(t)])

    def cast(self, origin_m, direction, nthreads=0):
        t = -origin_m[:, 2] / direction[:, 2]
        nrm = np.where((direction[:, 2] > 0)[:, None], self.up_normal, [0.0, 0.0, 1.0])
        return np.ones(len(t), bool), t, nrm


@pytest.mark.parametrize("tilt_deg, tir_expected", [(0.0, False), (40.0, False), (60.0, True)])
def test_total_internal_reflection_on_the_way_back_is_flagged(tilt_deg, tir_expected):
    # a nadir return meets a facet tilted by tilt_deg: TIR when tilt > critical 48.2° (n 1.3415)
    world = World(water=_StubWater(tilt_deg), seabed=_plane_mesh(-5.0), n_air=1.0, n_water=N_WATER)
    p = trace(_Pulses([[0.0, 0.0, 100.0]], [[0.0, 0.0, -1.0]]), world, TraceSettings(), 1e-3)
    assert bool(p.flags[0, 0] & P.TIR_RETURN) is tir_expected
    assert math.degrees(math.asin(1 / N_WATER)) == pytest.approx(48.2, abs=0.05)
    if tir_expected:
        assert p.transmittance_up[0, 0] == 0.0
    else:
        ci = math.cos(math.radians(tilt_deg))
        ct = math.sqrt(1 - (N_WATER * math.sin(math.radians(tilt_deg))) ** 2)
        rs = (N_WATER * ci - ct) / (N_WATER * ci + ct)
        rp = (ci - N_WATER * ct) / (N_WATER * ct + ci)
        assert p.transmittance_up[0, 0] == pytest.approx(1 - 0.5 * (rs**2 + rp**2), rel=1e-9)
