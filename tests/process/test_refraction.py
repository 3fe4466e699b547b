"""Refraction and in-water range against ray geometry written out here by hand.

Flat water at z = 0, a planar sloping seabed, exact times: the processed seabed points must lie
on the plane (and at the analytic bottom point) to < 1 mm; the uncorrected points must be off by
the analytic amount.
"""

import numpy as np
import pytest
from scipy import constants

from pipeline.process.classify import BATHYMETRIC_POINT, WATER_SURFACE
from pipeline.process.refraction import (
    RefractionSettings,
    georeference,
    seabed_points,
    water_surface_points,
)
from pipeline.process.returns import DetectedReturns, PointFlag
from pipeline.process.surface_fit import SurfaceFitSettings, fit_water_surface

C = constants.c
N_AIR = 1.000277
N_PHASE = 1.3415
N_GROUP = 1.3638
ALTITUDE_M = 400.0
# seabed plane z = -D0 + SX x + SY y
D0_M, SX, SY = 12.0, 0.03, -0.02


def analytic_pulses(n_side=40, spacing_m=1.5, seed=1):
    """Pulses over flat water at z = 0, each with an exact surface and bottom time.

    Beams are off nadir by up to 20 deg in random azimuths; each pulse's origin is placed so
    that it hits the water on a regular grid of surface points.
    """
    rng = np.random.default_rng(seed)
    g = (np.arange(n_side) - n_side / 2) * spacing_m
    ex, ey = (a.ravel() for a in np.meshgrid(g, g))
    n = ex.size
    theta = np.radians(rng.uniform(0.0, 20.0, n))
    theta[:5] = np.radians([0.0, 5.0, 10.0, 15.0, 20.0])
    az = rng.uniform(0.0, 2 * np.pi, n)
    ux, uy = np.sin(az), np.cos(az)  # horizontal unit vector (azimuth from north)
    st, ct = np.sin(theta), np.cos(theta)
    d = np.column_stack([ux * st, uy * st, -ct])
    r_air = ALTITUDE_M / ct
    o = np.column_stack([ex, ey, np.zeros(n)]) - d * r_air[:, None]
    # Snell by hand: sin(tw) = n_air sin(t) / n_phase, same azimuth, going down
    sw = N_AIR * st / N_PHASE
    cw = np.sqrt(1.0 - sw**2)
    t = np.column_stack([ux * sw, uy * sw, -cw])
    # distance along t from the entry (ex, ey, 0) to the seabed plane
    length = (-D0_M + SX * ex + SY * ey) / (t[:, 2] - SX * t[:, 0] - SY * t[:, 1])
    bottom = np.column_stack([ex, ey, np.zeros(n)]) + t * length[:, None]
    t_s = 2.0 * r_air * N_AIR / C
    t_b = t_s + 2.0 * length * N_GROUP / C
    ret = DetectedReturns(
        pulse_id=np.arange(n),
        origin_meas_m=o,
        direction_meas=d,
        has_surface=np.ones(n, bool),
        t_surface_s=t_s,
        has_bottom=np.ones(n, bool),
        t_bottom_s=t_b,
        surface_confidence=np.full(n, 0.9),
        bottom_confidence=np.full(n, 0.8),
        flags=np.zeros(n, np.uint16),
    )
    return ret, bottom, length, theta, cw


SETTINGS = RefractionSettings(phase_index=N_PHASE, group_index=N_GROUP)
FIT = SurfaceFitSettings(air_index=N_AIR)


def test_corrected_points_lie_on_the_seabed_plane():
    ret, bottom, *_ = analytic_pulses()
    surface = fit_water_surface(ret, FIT)
    pts = seabed_points(ret, surface, SETTINGS)
    x, y, z = pts.xyz_m.T
    # 1 mm is the brief's bar; exact inputs leave only float64 rounding (~1e-12 m at 400 m)
    assert np.max(np.abs(z - (-D0_M + SX * x + SY * y))) < 1e-3
    assert np.max(np.linalg.norm(pts.xyz_m - bottom, axis=1)) < 1e-3
    # flat surface at z = 0: depth is -z
    np.testing.assert_allclose(pts.depth_m, -z, atol=1e-6)
    np.testing.assert_array_equal(pts.pulse_id, ret.pulse_id)
    assert np.all(pts.uncertainty_v_m > 0) and np.all(pts.uncertainty_h_m > 0)


def test_uncorrected_points_have_the_analytic_bias():
    ret, bottom, length, theta, cw = analytic_pulses()
    surface = fit_water_surface(ret, FIT)
    raw = seabed_points(ret, surface, SETTINGS, correct_refraction=False)
    assert np.all(raw.flags & PointFlag.NOT_REFRACTED)
    # straight beam at c/n_air: the in-water leg becomes length * n_group / n_air along the
    # unrefracted beam, so z = -length n_g cos(theta) / n_air and the depth error is
    # length (n_g cos(theta) / n_air - cos(theta_w)) (positive: too deep)
    expected_z = -length * N_GROUP * np.cos(theta) / N_AIR
    np.testing.assert_allclose(raw.xyz_m[:, 2], expected_z, atol=1e-6)
    bias = (bottom[:, 2] - raw.xyz_m[:, 2]) - length * (N_GROUP * np.cos(theta) / N_AIR - cw)
    assert np.max(np.abs(bias)) < 1e-6
    # at nadir the uncorrected depth is n_g / n_air times the true depth: ~36 % too deep
    nadir = np.argmin(theta)
    ratio = raw.depth_m[nadir] / (-bottom[nadir, 2])
    assert ratio == pytest.approx(N_GROUP / N_AIR, rel=1e-9)


def test_missing_surface_returns_use_the_fitted_surface():
    ret, bottom, *_ = analytic_pulses()
    drop = np.zeros(len(ret), bool)
    drop[::7] = True
    ret2 = DetectedReturns(
        pulse_id=ret.pulse_id,
        origin_meas_m=ret.origin_meas_m,
        direction_meas=ret.direction_meas,
        has_surface=~drop,
        t_surface_s=np.where(drop, 0.0, ret.t_surface_s),
        has_bottom=ret.has_bottom,
        t_bottom_s=ret.t_bottom_s,
        surface_confidence=np.where(drop, 0.0, ret.surface_confidence),
        bottom_confidence=ret.bottom_confidence,
        flags=ret.flags,
    )
    surface = fit_water_surface(ret2, FIT)
    pts = seabed_points(ret2, surface, SETTINGS)
    assert np.all((pts.flags[drop] & PointFlag.SURFACE_INTERPOLATED) != 0)
    assert np.all((pts.flags[~drop] & PointFlag.SURFACE_INTERPOLATED) == 0)
    # the air range to the fitted (exact) surface replaces t_s: same point to < 1 mm
    assert np.max(np.linalg.norm(pts.xyz_m - bottom, axis=1)) < 1e-3


def test_georeference_classifies_surface_and_seabed():
    ret, bottom, *_ = analytic_pulses(n_side=20)
    out = georeference(
        ret,
        surface_settings=FIT,
        refraction_settings=SETTINGS,
        include_derived_surface=True,
    )
    counts = np.bincount(out.points.classification, minlength=64)
    n = len(ret)
    assert counts[WATER_SURFACE] == n and counts[BATHYMETRIC_POINT] == n and counts[42] == n
    assert np.all(out.uncorrected.classification == BATHYMETRIC_POINT)
    surf = water_surface_points(ret, out.surface, SETTINGS)
    np.testing.assert_allclose(surf.xyz_m[:, 2], 0.0, atol=1e-9)
    # return numbering: surface 1 of 2, bottom 2 of 2; derived (synthetic) points 1 of 1
    kind = out.points.kind
    np.testing.assert_array_equal(out.points.return_number, np.select([kind == 2], [2], 1))
    np.testing.assert_array_equal(out.points.number_of_returns, np.select([kind == 3], [1], 2))


def with_surface_times(ret, t_surface_s):
    return DetectedReturns(
        pulse_id=ret.pulse_id,
        origin_meas_m=ret.origin_meas_m,
        direction_meas=ret.direction_meas,
        has_surface=ret.has_surface,
        t_surface_s=t_surface_s,
        has_bottom=ret.has_bottom,
        t_bottom_s=ret.t_bottom_s,
        surface_confidence=ret.surface_confidence,
        bottom_confidence=ret.bottom_confidence,
        flags=ret.flags,
    )


def test_a_bad_surface_pick_does_not_spoil_the_bottom():
    ret, bottom, *_ = analytic_pulses()
    bad = np.zeros(len(ret), bool)
    bad[100:1600:97] = True
    # a surface picked 0.5 m late (e.g. on the water column): flagged, and the bottom is then
    # ranged from the fitted surface instead of from the bad surface time
    ts = ret.t_surface_s + np.where(bad, 2 * 0.5 * N_AIR / C, 0.0)
    ret2 = with_surface_times(ret, ts)
    surface = fit_water_surface(ret2, FIT)
    pts = seabed_points(ret2, surface, SETTINGS)
    np.testing.assert_array_equal((pts.flags & PointFlag.SURFACE_OUTLIER) != 0, bad)
    np.testing.assert_array_equal((pts.flags & PointFlag.SURFACE_INTERPOLATED) != 0, bad)
    assert np.max(np.linalg.norm(pts.xyz_m - bottom, axis=1)) < 1e-3


def test_empty_input():
    ret, *_ = analytic_pulses(n_side=3)
    empty = ret.select(np.zeros(len(ret), bool))
    out = georeference(empty, surface_settings=FIT, refraction_settings=SETTINGS)
    assert len(out.points) == 0 and len(out.uncorrected) == 0 and len(out.surface) == 0
