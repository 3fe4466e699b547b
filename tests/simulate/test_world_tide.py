"""The tide (``water_surface.level_m``) enters the seabed exactly once, for every seabed kind.

Each truth is written here from the scene's documented meaning, never from the simulator:
``seabed.depth_m`` is the depth below the water level at (0, 0), so for a plane or a beach the
seabed sits at ``z = level - depth`` there and a tide moves it in z by exactly the level and not at
all in depth; a GeoTIFF DEM holds absolute heights, so a tide leaves its z and deepens the water.
"""

import math
import tomllib
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import rasterio
from rasterio.transform import Affine

from pipeline.scene import parse_scene
from pipeline.simulate.world import FeatureSettings, build_truth

ROOT = Path(__file__).resolve().parents[2]
SCENE = ROOT / "data_synthetic" / "scenes" / "palmer_survey.toml"
EXTENT = (0.0, 300.0, 0.0, 600.0)
LEVEL = 1.25
X = np.array([0.0, 10.0, 150.0, 290.0])
Y = np.array([0.0, 300.0, 20.0, 580.0])


@pytest.fixture(scope="module")
def base_scene():
    scene = parse_scene(tomllib.loads(SCENE.read_text()))
    return replace(scene, seabed=replace(scene.seabed, roughness_rms_m=0.0))


def _with(scene, level_m, **seabed):
    return replace(
        scene,
        seabed=replace(scene.seabed, **seabed),
        water_surface=replace(scene.water_surface, level_m=level_m),
    )


@pytest.mark.parametrize("level", [0.0, LEVEL, -2.0])
def test_plane_seabed_with_a_tide_sits_at_level_minus_depth(base_scene, level):
    scene = _with(base_scene, level, depth_m=8.0, slope_deg=0.0)
    truth = build_truth(scene, EXTENT)
    np.testing.assert_allclose(truth.seabed.height_m(X, Y), level - 8.0, atol=1e-12)
    np.testing.assert_allclose(truth.depth_m(X, Y), 8.0, atol=1e-12)


def test_sloped_plane_with_a_tide(base_scene):
    # 5.33 deg down toward the east (aspect 90): z = level - depth - tan(slope) x
    scene = _with(base_scene, LEVEL, depth_m=2.0, slope_deg=5.33, aspect_deg=90.0)
    truth = build_truth(scene, EXTENT)
    z = LEVEL - 2.0 - math.tan(math.radians(5.33)) * X
    np.testing.assert_allclose(truth.seabed.height_m(X, Y), z, atol=1e-9)


def test_beach_with_a_tide(base_scene):
    # seaward toward the east, gradient 0.05: z = level - depth - 0.05 s on the foreshore
    scene = _with(
        base_scene, LEVEL, kind="beach", depth_m=2.0, beach_gradient=0.05, seaward_deg=90.0
    )
    truth = build_truth(scene, EXTENT)
    x = np.array([0.0, 20.0, 100.0])
    np.testing.assert_allclose(
        truth.seabed.height_m(x, np.zeros(3)), LEVEL - 2.0 - 0.05 * x, atol=1e-9
    )


def test_cube_on_a_plane_with_a_tide(base_scene):
    cube = FeatureSettings(kind="cube", x_m=100.0, y_m=100.0, size_m=2.0)
    scene = _with(base_scene, LEVEL, depth_m=8.0, slope_deg=0.0, features=(cube,))
    truth = build_truth(scene, EXTENT)
    # top of the cube: 2 m above a seabed at level - 8; away from it the bare seabed
    z = truth.seabed.height_m(np.array([100.0, 150.0]), np.array([100.0, 150.0]))
    np.testing.assert_allclose(z, [LEVEL - 8.0 + 2.0, LEVEL - 8.0], atol=1e-9)


def test_roughness_moves_with_the_tide_by_exactly_the_level(base_scene):
    rough = {"depth_m": 8.0, "slope_deg": 0.0, "roughness_rms_m": 0.3}
    calm = build_truth(_with(base_scene, 0.0, **rough), EXTENT)
    tide = build_truth(_with(base_scene, LEVEL, **rough), EXTENT)
    xx, yy = np.meshgrid(np.linspace(5, 295, 40), np.linspace(5, 595, 60))
    dz = tide.seabed.height_m(xx, yy) - calm.seabed.height_m(xx, yy)
    np.testing.assert_allclose(dz, LEVEL, atol=1e-9)
    np.testing.assert_allclose(tide.depth_m(xx, yy), calm.depth_m(xx, yy), atol=1e-9)


def test_dem_heights_are_absolute_so_a_tide_deepens_the_water(base_scene, tmp_path):
    # a 2 m DEM of z = -6 - 0.01 x (easting from the frame origin), written here
    e0, n0, pix = base_scene.frame.origin_easting_m, base_scene.frame.origin_northing_m, 2.0
    cols, rows = 200, 320
    west, north = e0 - 50.0, n0 + 620.0
    xc = west + (np.arange(cols) + 0.5) * pix - e0
    z = np.tile(-6.0 - 0.01 * xc, (rows, 1))
    path = tmp_path / "dem.tif"
    profile = {
        "driver": "GTiff",
        "height": rows,
        "width": cols,
        "count": 1,
        "dtype": "float64",
        "crs": base_scene.frame.crs,
        "transform": Affine(pix, 0.0, west, 0.0, -pix, north),
    }
    with rasterio.open(path, "w", **profile) as ds:
        ds.write(z, 1)
    scene = _with(base_scene, LEVEL, kind="dem", dem_path=str(path))
    truth = build_truth(scene, EXTENT)
    x, y = np.array([1.0, 101.0, 201.0]), np.array([11.0, 301.0, 501.0])
    np.testing.assert_allclose(truth.seabed.height_m(x, y), -6.0 - 0.01 * x, atol=1e-6)
    np.testing.assert_allclose(truth.depth_m(x, y), LEVEL + 6.0 + 0.01 * x, atol=1e-6)
