import math
import tomllib
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from pipeline.errors import SceneError
from pipeline.scene import parse_scene
from pipeline.simulate import paths as P
from pipeline.simulate.trace import trace
from pipeline.simulate.world import (
    PeriodicCaster,
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
        water_surface=WaterSurfaceSettings(kind="waves", grid_nodes=320),
        seabed=replace(survey_scene.seabed, roughness_rms_m=0.0),
    )


def test_wave_caster_hits_lie_on_the_wave_truth(survey_scene):
    scene = _wave_scene(survey_scene)
    extent = (0.0, 300.0, 0.0, 600.0)
    truth = build_truth(scene, extent)
    world = build_world(scene, truth, extent)
    assert isinstance(world.water, PeriodicCaster)
    rng = np.random.default_rng(3)
    n = 2000
    xy = rng.uniform([0, 0], [300, 600], (n, 2))
    o = np.column_stack([xy, np.full(n, 400.0)])
    th = np.radians(rng.uniform(0, 25, n))
    az = rng.uniform(0, 2 * np.pi, n)
    d = np.column_stack([np.sin(th) * np.sin(az), np.sin(th) * np.cos(az), -np.cos(th)])
    hit, t, nrm = world.water.cast(o, d)
    assert hit.all()
    p = o + t[:, None] * d
    # the mesh is piecewise linear at half the wave grid spacing (8 nodes per shortest wave):
    # linear interpolation error up to ~8 % of the shortest waves' amplitude, a few mm
    err = p[:, 2] - truth.water.height_m(p[:, 0], p[:, 1])
    assert np.abs(err).max() < 0.01
    assert np.median(np.abs(err)) < 0.002
    # the wave surface is not flat: hit heights spread like the waves do
    assert p[:, 2].std() > 0.05


@pytest.mark.slow
def test_wave_surface_slopes_seen_by_the_tracer_match_cox_munk(survey_scene):
    wind = 8.0
    scene = _wave_scene(survey_scene, wind)
    extent = (0.0, 300.0, 0.0, 600.0)
    truth = build_truth(scene, extent)
    world = build_world(scene, truth, extent)
    rng = np.random.default_rng(4)
    n = 20000
    o = np.column_stack([rng.uniform([0, 0], [300, 600], (n, 2)), np.full(n, 400.0)])
    d = np.tile([0.0, 0.0, -1.0], (n, 1))
    hit, _, nrm = world.water.cast(o, d)
    slopes2 = (nrm[:, 0] ** 2 + nrm[:, 1] ** 2) / nrm[:, 2] ** 2
    # Cox & Munk: 0.003 + 0.00512 U (U at 12.5 m); 10 % as in the issue; the facet mesh
    # at the wave grid spacing keeps the calibrated slopes (terrain tests check the grid)
    assert slopes2.mean() == pytest.approx(0.003 + 0.00512 * wind, rel=0.10)


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
