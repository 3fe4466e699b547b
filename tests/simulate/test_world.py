import math
import tomllib
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from pipeline.errors import SceneError
from pipeline.scene import parse_scene
from pipeline.simulate import paths as P
from pipeline.simulate.budget import surface_mean_square_slope
from pipeline.simulate.trace import trace
from pipeline.simulate.wave_caster import WaveCaster
from pipeline.simulate.world import (
    WaterSurfaceSettings,
    build_truth,
    build_world,
)

ROOT = Path(__file__).resolve().parents[2]

SCENE = ROOT / "data_synthetic" / "scenes" / "palmer_survey.toml"


@pytest.fixture(scope="module")
def survey_scene():
    return parse_scene(tomllib.loads(SCENE.read_text()))


def test_plane_truth_depths(survey_scene):
    scene = replace(survey_scene, seabed=replace(survey_scene.seabed, roughness_rms_m=0.0))
    truth = build_truth(scene, (0.0, 300.0, 0.0, 600.0))
    x = np.array([0.0, 150.0, 300.0])
    # depth 2 m at x = 0, deepening east with tan(5.33°)
    expected = 2.0 + math.tan(math.radians(5.33)) * x
    np.testing.assert_allclose(truth.depth_m(x, np.zeros(3)), expected, atol=1e-9)


def test_rough_seabed_truth_has_the_requested_rms(survey_scene):
    truth = build_truth(survey_scene, (0.0, 300.0, 0.0, 600.0))
    xx, yy = np.meshgrid(np.linspace(20, 280, 200), np.linspace(20, 580, 400))
    plane = 2.0 + math.tan(math.radians(5.33)) * xx
    resid = truth.depth_m(xx, yy) - plane
    # 0.2 m requested; a 300 × 600 m patch holds ~2800 correlation areas: a few per cent
    assert resid.std() == pytest.approx(0.2, rel=0.1)


def _wave_scene(survey_scene, wind=8.0):
    return replace(
        survey_scene,
        water=replace(survey_scene.water, wind_speed_m_s=wind),
        water_surface=WaterSurfaceSettings(kind="waves"),
        seabed=replace(survey_scene.seabed, roughness_rms_m=0.0),
    )


def test_wave_caster_hits_lie_on_the_wave_truth(survey_scene):
    scene = _wave_scene(survey_scene)
    extent = (0.0, 300.0, 0.0, 600.0)
    truth = build_truth(scene, extent)
    world = build_world(scene, truth, extent)
    assert isinstance(world.water, WaveCaster)
    rng = np.random.default_rng(3)
    n = 2000
    xy = rng.uniform([0, 0], [300, 600], (n, 2))
    o = np.column_stack([xy, np.full(n, 400.0)])
    th = np.radians(rng.uniform(0, 25, n))
    az = rng.uniform(0, 2 * np.pi, n)
    d = np.column_stack([np.sin(th) * np.sin(az), np.sin(th) * np.cos(az), -np.cos(th)])
    t = rng.uniform(0.0, 2.0, n)  # 30 time slabs
    hit, s, nrm = world.water.cast(o, d, t_s=t)
    assert hit.all()
    p = o + s[:, None] * d
    # the root is solved on the truth itself (the sea at each ray's time): micrometres
    err = p[:, 2] - truth.water.height_m(p[:, 0], p[:, 1], t)
    assert np.abs(err).max() < 1e-5
    # the wave surface is not flat: hit heights spread like the waves do
    assert p[:, 2].std() > 0.05


def test_the_tracer_sees_the_sea_move(survey_scene):
    """The same ray 2 s later meets another surface; at the same time, the same one."""
    scene = _wave_scene(survey_scene)
    extent = (0.0, 300.0, 0.0, 600.0)
    world = build_world(scene, build_truth(scene, extent), extent)
    n = 200

    class Pulses:
        origin_m = np.column_stack([np.linspace(10, 290, n), np.full(n, 300.0), np.full(n, 400.0)])
        direction = np.tile([0.0, 0.0, -1.0], (n, 1))
        pulse_id = np.arange(n)
        yaw_rad = np.zeros(n)
        t_s = np.zeros(n)

    z0 = trace(Pulses, world, scene.trace, 1e-3).surface_xyz_m[:, 0, 2]
    Pulses.t_s = np.full(n, 2.0)  # half a peak period at 8 m/s (T_p ~ 6 s)
    z2 = trace(Pulses, world, scene.trace, 1e-3).surface_xyz_m[:, 0, 2]
    # heights 2 s apart are nearly independent: their difference is of the waves' own size
    assert np.std(z2 - z0) > 0.5 * np.std(z0)
    Pulses.t_s = np.zeros(n)
    np.testing.assert_array_equal(
        trace(Pulses, world, scene.trace, 1e-3).surface_xyz_m[:, 0, 2], z0
    )


@pytest.mark.slow
def test_traced_and_unresolved_slopes_add_up_to_cox_munk(survey_scene):
    wind = 8.0
    scene = _wave_scene(survey_scene, wind)
    extent = (0.0, 300.0, 0.0, 600.0)
    truth = build_truth(scene, extent)
    world = build_world(scene, truth, extent)
    rng = np.random.default_rng(4)
    n = 20000
    o = np.column_stack([rng.uniform([0, 0], [300, 600], (n, 2)), np.full(n, 400.0)])
    d = np.tile([0.0, 0.0, -1.0], (n, 1))
    hit, _, nrm = world.water.cast(o, d, t_s=rng.uniform(0, 1, n))
    traced = np.mean((nrm[:, 0] ** 2 + nrm[:, 1] ** 2) / nrm[:, 2] ** 2)
    # the footprint split: the traced waves carry a part of the slopes (PM up to 4 footprints)
    cox_munk = 0.003 + 0.00512 * wind  # Cox & Munk (1954); the scene's wind is at 12.5 m
    assert 0.2 * cox_munk < traced < 0.8 * cox_munk
    # and the surface echo's statistical part makes up the rest
    unresolved = float(surface_mean_square_slope(wind, traced))
    assert traced + unresolved == pytest.approx(cox_munk, rel=0.02)


def test_trace_through_waves_reaches_the_bottom(survey_scene):
    scene = _wave_scene(survey_scene)
    extent = (0.0, 300.0, 0.0, 600.0)
    truth = build_truth(scene, extent)
    world = build_world(scene, truth, extent)

    class Pulses:
        origin_m = np.tile([150.0, 300.0, 400.0], (50, 1))
        direction = np.tile([0.0, math.sin(0.35), -math.cos(0.35)], (50, 1))
        pulse_id = np.arange(50)
        yaw_rad = np.zeros(50)

    Pulses.origin_m[:, 0] += np.arange(50) * 0.37
    p = trace(Pulses, world, scene.trace, 3e-3)
    assert np.all(p.flags == P.OK)
    b = p.bottom_xyz_m[:, 0]
    np.testing.assert_allclose(b[:, 2], truth.seabed.height_m(b[:, 0], b[:, 1]), atol=1e-3)
    # incidence angles now vary with the wave facets around 20°
    assert p.incidence_rad.std() > 0.01


def test_waves_without_wind_is_a_clear_error(survey_scene):
    scene = _wave_scene(survey_scene, wind=0.0)
    with pytest.raises(SceneError, match="`water.wind_speed_m_s` must be > 0"):
        build_truth(scene, (0.0, 10.0, 0.0, 10.0))


def test_moving_sea_paths_do_not_depend_on_the_chunking(survey_scene):
    scene = _wave_scene(survey_scene, wind=5.0)
    extent = (0.0, 300.0, 0.0, 600.0)
    world = build_world(scene, build_truth(scene, extent), extent)
    rng = np.random.default_rng(9)
    n = 300

    class Pulses:
        def __init__(self, sl):
            self.origin_m = origin[sl]
            self.direction = direction[sl]
            self.pulse_id = np.arange(n)[sl]
            self.yaw_rad = np.zeros(n)[sl]
            self.t_s = times[sl]

    origin = np.column_stack([rng.uniform(50, 250, (n, 2)), np.full(n, 400.0)])
    az = rng.uniform(0, 2 * np.pi, n)
    s, c = math.sin(0.35), math.cos(0.35)
    direction = np.column_stack([s * np.sin(az), s * np.cos(az), np.full(n, -c)])
    times = np.sort(rng.uniform(0.0, 1.0, n))
    settings = replace(scene.trace, subrays=7)
    whole = trace(Pulses(slice(None)), world, settings, 1e-3)
    parts = [trace(Pulses(slice(a, b)), world, settings, 1e-3) for a, b in ((0, 120), (120, n))]
    for name in ("surface_xyz_m", "refracted_dir", "bottom_xyz_m", "flags"):
        np.testing.assert_array_equal(
            np.concatenate([getattr(p, name) for p in parts]), getattr(whole, name)
        )


def test_a_large_world_holds_a_bounded_roughness_tile_and_no_mesh(survey_scene):
    """20 x 30 km: the roughness repeats every 2048 nodes, the seabed is meshed only on demand."""
    import tracemalloc

    from pipeline.simulate.world import ROUGHNESS_MAX_NODES

    extent = (0.0, 20_000.0, -1000.0, 29_000.0)
    tracemalloc.start()
    truth = build_truth(survey_scene, extent)
    world = build_world(survey_scene, truth, extent)
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    # the roughness tile alone is 2048^2 float64 = 34 MB (plus its FFT while made): not 600 M
    # nodes of the whole extent, and no triangle yet
    assert peak < 400e6
    assert world.seabed.tiles_built == 0 and world.seabed.shape == (118, 79)
    rough = truth.seabed.parts[1]
    side = ROUGHNESS_MAX_NODES * survey_scene.seabed.roughness_spacing_m
    assert rough.bounds == (0.0, side, -1000.0, -1000.0 + side)
    x, y = np.array([10.3, 7000.7]), np.array([55.5, 20_000.2])
    np.testing.assert_allclose(rough.height_m(x + side, y - side), rough.height_m(x, y), atol=1e-12)


def test_the_roughness_period_is_the_users(survey_scene):
    sb = replace(survey_scene.seabed, roughness_period_m=512.0)
    truth = build_truth(replace(survey_scene, seabed=sb), (0.0, 300.0, 0.0, 600.0))
    assert truth.seabed.parts[1].bounds == (0.0, 512.0, 0.0, 512.0)
    with pytest.raises(SceneError, match="roughness_period_m"):
        replace(survey_scene.seabed, roughness_period_m=10_000.0)
