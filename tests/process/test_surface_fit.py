"""Water-surface fit: a tilted plane, outliers, land, sparse pulses, a profiler line."""

import dataclasses

import numpy as np
import pytest
from scipy import constants

from pipeline.process.returns import DetectedReturns, DetectorFlag, PointFlag
from pipeline.process.surface_fit import SurfaceFitSettings, fit_water_surface

C = constants.c
N_AIR = 1.000277
FIT = SurfaceFitSettings(air_index=N_AIR)


def beams(n_side=35, spacing_m=1.2, seed=3):
    """Beam directions (up to 20 deg off nadir, any azimuth) hitting a regular xy grid."""
    rng = np.random.default_rng(seed)
    g = (np.arange(n_side) - n_side / 2) * spacing_m
    x, y = (a.ravel() for a in np.meshgrid(g, g))
    n = x.size
    theta = np.radians(rng.uniform(0, 20, n))
    phi = rng.uniform(0, 2 * np.pi, n)
    d = np.column_stack([np.sin(theta) * np.sin(phi), np.sin(theta) * np.cos(phi), -np.cos(theta)])
    return x, y, d


def from_hits(hits, d, range_m=300.0):
    """Origins ``range_m`` up each beam from its hit point: exact ranges by construction."""
    r = np.full(len(hits), range_m)
    return hits - d * r[:, None], r


def tilted_returns(tilt_deg=2.0, tilt_azimuth_deg=30.0, z0=0.3, **kw):
    """Surface returns from the plane z = z0 + gx x + gy y, hit on a regular grid.

    The plane's steepest ascent points along ``tilt_azimuth_deg`` (clockwise from north) with
    slope tan(tilt).
    """
    s = np.tan(np.radians(tilt_deg))
    az = np.radians(tilt_azimuth_deg)
    gx, gy = s * np.sin(az), s * np.cos(az)
    x, y, d = beams(**kw)
    o, r = from_hits(np.column_stack([x, y, z0 + gx * x + gy * y]), d)
    normal = np.array([-gx, -gy, 1.0]) / np.sqrt(1 + gx * gx + gy * gy)
    return o, d, r, normal, (z0, gx, gy)


def make_returns(o, d, r, has_surface=None, t_bottom_s=None):
    n = len(o)
    hs = np.ones(n, bool) if has_surface is None else has_surface
    ts = np.where(hs, 2 * r * N_AIR / C, 0.0)
    hb = np.zeros(n, bool) if t_bottom_s is None else t_bottom_s > 0
    tb = np.zeros(n) if t_bottom_s is None else t_bottom_s
    return DetectedReturns(
        pulse_id=np.arange(n),
        origin_meas_m=o,
        direction_meas=d,
        has_surface=hs,
        t_surface_s=ts,
        has_bottom=hb,
        t_bottom_s=tb,
        surface_confidence=np.where(hs, 1.0, 0.0),
        bottom_confidence=np.where(hb, 1.0, 0.0),
        flags=np.zeros(n, np.uint16),
    )


def angle_deg(a, b):
    return np.degrees(np.arctan2(np.linalg.norm(np.cross(a, b), axis=-1), np.sum(a * b, axis=-1)))


def test_tilted_plane_normal_recovered_despite_spikes():
    o, d, r, normal, (z0, gx, gy) = tilted_returns()
    # 2 % of the surface returns are spikes 0.4 m early or late (spray, bad picks)
    rng = np.random.default_rng(5)
    spikes = rng.random(len(r)) < 0.02
    r_meas = r + np.where(spikes, rng.choice([-0.4, 0.4], len(r)), 0.0)
    ws = fit_water_surface(make_returns(o, d, r_meas), FIT)
    assert ws.is_water.all()
    # brief: normal within 0.05 deg; exact inliers leave only rounding, the spikes are rejected
    assert angle_deg(ws.normal, normal).max() < 0.05
    # the entry points lie on the true plane (a spike's own entry is on the fit, not the spike)
    e = ws.entry_m
    assert np.max(np.abs(e[:, 2] - (z0 + gx * e[:, 0] + gy * e[:, 1]))) < 1e-6
    assert np.all(ws.flags[spikes] & PointFlag.SURFACE_OUTLIER)
    assert not np.any(ws.flags[~spikes] & PointFlag.SURFACE_OUTLIER)
    # global plane: slope of the tilt
    np.testing.assert_allclose(ws.global_plane[1:], [gx, gy], atol=1e-6)


def test_waves_are_followed_locally():
    # a long swell (wavelength 60 m, amplitude 0.5 m) seen through 16-point planes of ~2 m
    # radius: the local normal follows the swell slope (max 3 deg) to within 0.2 deg
    x, y, d = beams()
    k, amp = 2 * np.pi / 60.0, 0.5
    p = np.column_stack([x, y, amp * np.sin(k * x)])
    o, r = from_hits(p, d)
    ws = fit_water_surface(make_returns(o, d, r), FIT)
    inner = np.all(np.abs(p[:, :2]) < 15, axis=1)
    slope = amp * k * np.cos(k * ws.entry_m[:, 0])
    true_n = np.column_stack([-slope, np.zeros_like(slope), np.ones_like(slope)])
    true_n /= np.linalg.norm(true_n, axis=1, keepdims=True)
    assert angle_deg(ws.normal[inner], true_n[inner]).max() < 0.2
    # the plane through the neighbours cuts the crest/trough curvature: k^2 amp R^2 / 2 ~ 1 cm
    e = ws.entry_m[inner]
    assert np.max(np.abs(e[:, 2] - amp * np.sin(k * e[:, 0]))) < 0.02


def test_land_and_isolated_pulses():
    o, d, r, normal, (z0, gx, gy) = tilted_returns(tilt_deg=0.0, z0=0.0)
    land = o[:, 0] + d[:, 0] * r > 12.0  # a plateau 3 m above the water east of x = 12 m
    r = np.where(land, r - 3.0 / -d[:, 2], r)
    # one isolated water pulse 200 m away: no neighbours within 5 m
    o = np.vstack([o, [200.0, 200.0, 300.0]])
    d = np.vstack([d, [0.0, 0.0, -1.0]])
    r = np.append(r, 300.0)
    land = np.append(land, False)
    ws = fit_water_surface(make_returns(o, d, r), FIT)
    np.testing.assert_array_equal(ws.is_land, land)
    assert np.all(ws.flags[land] & PointFlag.LAND)
    assert ws.flags[-1] & PointFlag.SURFACE_GLOBAL_FALLBACK
    assert not np.any(ws.flags[:-1] & PointFlag.SURFACE_GLOBAL_FALLBACK)
    assert abs(ws.entry_m[-1, 2]) < 1e-9
    np.testing.assert_allclose(ws.global_plane, [0.0, 0.0, 0.0], atol=1e-9)
    # land depth reference is the water level: a land point 3 m up is at depth -3 m
    idx = np.flatnonzero(land)
    pts = o[idx] + d[idx] * r[idx, None]
    np.testing.assert_allclose(ws.surface_z_m(idx, pts[:, 0], pts[:, 1]) - pts[:, 2], -3.0)


def test_bottom_only_pulse_over_land_is_land():
    o, d, r, *_ = tilted_returns(tilt_deg=0.0, z0=0.0, n_side=10)
    has_s = np.ones(len(o), bool)
    has_s[0] = False
    tb = np.zeros(len(o))
    tb[0] = 2 * (300.0 - 5.0) / -d[0, 2] * N_AIR / C  # ground 5 m above water, no surface
    ws = fit_water_surface(make_returns(o, d, r, has_surface=has_s, t_bottom_s=tb), FIT)
    assert ws.is_land[0] and not ws.is_land[1:].any()


def test_profiler_line_is_ill_conditioned_but_level():
    # a nadir profiler: every surface point on one line (x = 0); the cross-track slope cannot
    # be seen, so the fit keeps the global (level) one and flags the pulses
    n = 400
    y = np.arange(n) * 0.1
    o = np.column_stack([np.zeros(n), y, np.full(n, 300.0)])
    d = np.tile([0.0, 0.0, -1.0], (n, 1))
    r = o[:, 2] - 0.002 * y  # the water rises 2 mm per m northwards
    ws = fit_water_surface(make_returns(o, d, r), FIT)
    assert np.all(ws.flags & PointFlag.SURFACE_ILL_CONDITIONED)
    np.testing.assert_allclose(ws.normal[:, 0], 0.0, atol=1e-12)
    np.testing.assert_allclose(ws.entry_m[:, 2], 0.002 * y, atol=1e-9)
    assert np.all(np.isfinite(ws.normal))


def test_no_surface_returns_falls_back_to_the_level():
    o, d, r, *_ = tilted_returns(tilt_deg=0.0, z0=0.0, n_side=5)
    tb = 2 * (r + 5.0) * N_AIR / C
    ret = make_returns(o, d, r, has_surface=np.zeros(len(o), bool), t_bottom_s=tb)
    ws = fit_water_surface(ret, SurfaceFitSettings(air_index=N_AIR, fallback_water_level_m=0.0))
    assert ws.is_water.all()
    assert np.all(ws.flags & PointFlag.SURFACE_GLOBAL_FALLBACK)
    np.testing.assert_allclose(ws.entry_m[:, 2], 0.0, atol=1e-9)


#: The test sea: components of equal amplitude; sigma = amplitude * sqrt(components / 2).
SEA_COMPONENTS, SEA_AMPLITUDE_M = 8, 0.25


def sea_with_land(bottoms: bool, land_z=None):
    """A wind sea of eight sinusoids (sigma 0.5 m, crests above the 1 m land margin) west of
    x = 12 m and, east of it, land: a foreshore rising 0.5 m per m to 1 m at x = 14 m, then a
    beach face rising 0.3 m per m to 5.65 m (``land_z``: flat land at that height instead);
    optionally a seabed echo 10 m (air range) below every sea pulse's surface and none under
    the land (opaque).

    Returns the returns, the sea heights, the land mask and the land heights.
    """
    x, y, d = beams(n_side=60, spacing_m=1.0)
    j = np.arange(SEA_COMPONENTS)
    wavelength_m = 6.0 + 18.0 * j / (SEA_COMPONENTS - 1)  # 6 m to 24 m
    heading = 2.39996 * j  # golden-angle spread of directions
    phase = 1.0 + 2.0 * j
    arg = (x[:, None] * np.sin(heading) + y[:, None] * np.cos(heading)) / wavelength_m
    sea = SEA_AMPLITUDE_M * np.sin(2 * np.pi * arg + phase).sum(axis=1)
    land = x > 12.0
    face = np.where(x < 14.0, 0.5 * (x - 12.0), 1.0 + 0.3 * (x - 14.0))
    ground = face if land_z is None else np.full_like(x, land_z)
    z = np.where(land, ground, sea)
    o, r = from_hits(np.column_stack([x, y, z]), d)
    tb = np.where(land, 0.0, 2 * (r + 10.0) * N_AIR / C) if bottoms else None
    return make_returns(o, d, r, t_bottom_s=tb), sea, land, ground


def test_wave_crests_are_water_and_land_is_land():
    # the sea's sigma is 0.5 m, Hs = 4 sigma = 2 m: the beach face below Hs is land by its
    # link to the land above it
    hs_m = 4.0 * SEA_AMPLITUDE_M * np.sqrt(SEA_COMPONENTS / 2.0)
    for bottoms in (False, True):
        ret, sea, land, ground = sea_with_land(bottoms)
        # the test's premise: many crests of the sea stand above the land margin, and land
        # between the margin and the sea's Hs exists
        assert np.sum(~land & (sea > FIT.land_margin_m)) > 20
        assert np.sum(land & (ground > FIT.land_margin_m) & (ground < hs_m)) > 100
        ws = fit_water_surface(ret, FIT)
        assert not ws.is_land[~land].any()
        assert ws.is_water[~land].all()
        # land above the margin (the foreshore below it is in the water band: not asserted)
        assert ws.is_land[land & (ground > FIT.land_margin_m + 0.1)].all()


def test_isolated_high_point_over_water_is_not_land():
    # a level sea with a seabed echo under every pulse, but one pulse's surface return is 1.5 m
    # high (spray, a bird) and its bottom was missed: one high point is not land
    o, d, r, *_ = tilted_returns(tilt_deg=0.0, z0=0.0)
    tb = 2 * (r + 8.0) * N_AIR / C
    i = len(r) // 2
    r[i] -= 1.5 / -d[i, 2]
    tb[i] = 0.0
    ws = fit_water_surface(make_returns(o, d, r, t_bottom_s=tb), FIT)
    assert not ws.is_land.any()
    assert ws.flags[i] & PointFlag.SURFACE_OUTLIER
    np.testing.assert_allclose(ws.entry_m[:, 2], 0.0, atol=1e-9)


def test_flat_berm_does_not_take_the_water_level():
    # a flat berm 3 m up is a denser height layer than a wave-spread sea; the sea's pulses see a
    # seabed 10 m below, so the water level is the sea's, and the berm is land
    ret, _, land, _ = sea_with_land(bottoms=True, land_z=3.0)
    ws = fit_water_surface(ret, FIT)
    # the sinusoids have zero mean; a plane fitted to a 45 m patch of them keeps a little tilt
    # and offset (0.1 m here), far from the berm's 3 m
    assert abs(ws.global_plane[0]) < 0.3
    np.testing.assert_array_equal(ws.is_land, land)


def wide_berm():
    """A flat berm 1.6 m up (above the 1 m margin, below Hs = 2 m of the test sea) over 160 m
    by 240 m, east of x = 44 m behind a foreshore, and the sea west of x = 40 m showing its
    seabed. Returns the returns, the sea heights, the land mask and the land heights."""
    x, y, d = beams(n_side=160, spacing_m=1.5)  # 240 m square
    j = np.arange(SEA_COMPONENTS)
    wavelength_m = 6.0 + 18.0 * j / (SEA_COMPONENTS - 1)
    heading, phase = 2.39996 * j, 1.0 + 2.0 * j
    arg = (x[:, None] * np.sin(heading) + y[:, None] * np.cos(heading)) / wavelength_m
    sea = SEA_AMPLITUDE_M * np.sin(2 * np.pi * arg + phase).sum(axis=1)
    land = x > 40.0
    ground = np.minimum(0.4 * (x - 40.0), 1.6)  # foreshore to the berm at x = 44 m
    z = np.where(land, ground, sea)
    o, r = from_hits(np.column_stack([x, y, z]), d)
    tb = np.where(land, 0.0, 2 * (r + 10.0) * N_AIR / C)
    return make_returns(o, d, r, t_bottom_s=tb), sea, land, ground


def test_wide_berm_below_the_wave_height_is_land():
    # no part of the berm stands above the sea's crests, but it spans far more than a crest
    # region (a few wavelengths of <= 24 m)
    ret, sea, land, ground = wide_berm()
    ws = fit_water_surface(ret, FIT)
    assert np.sum(~land & (sea > FIT.land_margin_m)) > 100  # crests above the margin
    assert not ws.is_land[~land].any()
    assert ws.is_land[land & (ground > FIT.land_margin_m + 0.1)].all()


def test_level_land_with_no_light_under_it_is_land():
    # a flat field 5 m up, seen by a detector that looked for a water column under every
    # surface return (no-bottom limits given) and found none, nor any bottom: no water, and
    # 5 m above the level processing expects (0, fallback_water_level_m): land, by default.
    # Before the fix (the rule off by default) the field was taken for the water level.
    o, d, r, *_ = tilted_returns(tilt_deg=0.0, z0=5.0)
    dry = dataclasses.replace(make_returns(o, d, r), t_no_bottom_s=np.zeros(len(o)))
    ws = fit_water_surface(dry, FIT)
    assert ws.is_land.all() and not ws.is_water.any()
    # control: the same returns, a column measured under each (2 m of water below them)
    wet = dataclasses.replace(dry, t_no_bottom_s=dry.t_surface_s + 2 * 2.0 * 1.34 / C)
    ws = fit_water_surface(wet, FIT)
    assert ws.is_water.all()
    assert abs(ws.global_plane[0] - 5.0) < 1e-6


def test_a_calm_sea_seen_only_through_its_seabed_echoes_stays_water():
    # calm water returns no glint: the only echo of each pulse is the seabed, 4 m deep, seen
    # 4 x 1.31 = 5.24 m below the water level (air range), nothing under it. No light under
    # any return, as over land, but the echoes lie below the expected level, not above it:
    # they stay water (as with the all-land rule off, which is what made this survey all land)
    for z0 in (-5.24, 0.0, 1.9):  # 1.9 m: within dry_level_margin_m (2 m) of the level
        o, d, r, *_ = tilted_returns(tilt_deg=0.0, z0=z0)
        dry = dataclasses.replace(make_returns(o, d, r), t_no_bottom_s=np.zeros(len(o)))
        ws = fit_water_surface(dry, FIT)
        assert ws.is_water.all() and not ws.is_land.any(), z0
    # a user who expects the water 4 m up makes the 5 m field water too
    o, d, r, *_ = tilted_returns(tilt_deg=0.0, z0=5.0)
    dry = dataclasses.replace(make_returns(o, d, r), t_no_bottom_s=np.zeros(len(o)))
    ws = fit_water_surface(dry, dataclasses.replace(FIT, fallback_water_level_m=4.0))
    assert ws.is_water.all()


def test_clipped_water_sets_the_level_under_land_that_is_still_timed():
    """Every water pulse saturated into one plateau from the surface to the bottom (1 J
    pulses): its surface time is only an early bound, here 0.15 m high (one sample), flagged
    CLIPPED_MERGED; no bottom. Land 6 m up (x < 0) clips on its own and is timed exactly.
    The water level must be the water's (within the bound), the land land. Before the fix the
    clipped pulses were left out of the level search, which then found the land: level 6 m,
    the land taken for water."""
    x, y, d = beams()
    land = x < 0.0
    z = np.where(land, 6.0, 0.0)
    o, r = from_hits(np.column_stack([x, y, z]), d)
    bound_m = 0.15  # the early bound's height above the true surface
    r_meas = np.where(land, r, r - bound_m / -d[:, 2])
    ret = make_returns(o, d, r_meas)
    flags = np.where(land, 0, DetectorFlag.SATURATED | DetectorFlag.CLIPPED_MERGED)
    ret = dataclasses.replace(ret, flags=flags.astype(np.uint16), t_no_bottom_s=np.zeros(len(o)))
    ws = fit_water_surface(ret, FIT)
    assert abs(ws.global_plane[0] - bound_m) < 0.02, ws.global_plane
    assert ws.is_land[land].all() and ws.is_water[~land].all()


def test_neighbours_are_taken_from_the_pulses_own_look():
    """Two looks at one spot 5 s apart (a Palmer scan's fore and aft): the sea moved between.

    Look A sees the plane z = +0.25 m at t = 0-0.2 s, look B z = -0.25 m at t = 5-5.2 s, their
    pulses interleaved on one grid. Each pulse's local plane must be its own look's (the time
    window); without it, the neighbours mix the looks and the heights land in between.
    """
    x, y, d = beams(n_side=30, spacing_m=0.8)
    n = x.size
    look_b = (np.arange(n) % 2) == 1
    z = np.where(look_b, -0.25, 0.25)
    o, r = from_hits(np.column_stack([x, y, z]), d)
    rng = np.random.default_rng(7)
    t = np.where(look_b, 5.0, 0.0) + rng.uniform(0.0, 0.2, n)
    ret = make_returns(o, d, r)
    ret = dataclasses.replace(ret, t_emit_s=t)
    ws = fit_water_surface(ret, FIT)
    inner = (np.abs(x) < 8) & (np.abs(y) < 8)  # whole neighbourhoods of both looks
    np.testing.assert_allclose(ws.entry_m[inner, 2], z[inner], atol=0.02)
    # the window is a setting: without it the looks mix
    mixed = fit_water_surface(ret, SurfaceFitSettings(air_index=N_AIR, time_window_s=None))
    assert np.abs(mixed.entry_m[inner, 2] - z[inner]).mean() > 0.1


def test_the_sea_is_measured_on_the_surface_returns_with_water_under_them():
    """A calm sea (2 cm of ranging noise about z = 0) seen off nadir from high up: 40 % of the
    pulses return the surface and a bottom 3 m under it; the others return only a shallow
    seabed 0.3-0.9 m down (air range), inside the band around the level. The sea's sigma is
    the wet surfaces' 2 cm (the band's truncation at 1 m is negligible at that size), so the
    not-surface band keeps its 1 m floor; measured on every surface return, the seabed echoes
    made a sea of ~0.3 m and a band reaching 1.2 m down, which took them in as troughs."""
    from pipeline.process.surface_wide import surface_wide

    rng = np.random.default_rng(11)
    x, y, d = beams(n_side=40)
    n = x.size
    wet = rng.random(n) < 0.4
    z = np.where(wet, rng.normal(0.0, 0.02, n), -rng.uniform(0.3, 0.9, n))
    o, r = from_hits(np.column_stack([x, y, z]), d)
    tb = np.where(wet, 2 * (r + 3.0) * N_AIR / C, 0.0)
    ret = make_returns(o, d, r, t_bottom_s=tb)
    wide = surface_wide(ret, FIT)
    assert wide.land_sigma_m == pytest.approx(0.02, rel=0.15)
    assert wide.below_m == FIT.below_margin_m
    # with too few wet pulses the sea is measured on every surface return, as before
    few = make_returns(o, d, r, t_bottom_s=np.where(np.arange(n) < 10, tb, 0.0))
    assert surface_wide(few, FIT).land_sigma_m > 0.2
