"""The tiled seabed caster against the whole mesh (brute force) and analytic planes."""

import math
import pickle

import numpy as np
import pytest

import terrain
from pipeline.simulate.tiled_seabed import TiledSeabed
from pipeline.simulate.trace import MeshCaster
from terrain.box_mesh import seabed_mesh

EXTENT = (-3.3, 96.1, -7.9, 71.4)


def _rough_with_boxes():
    rough = terrain.gaussian_roughness(
        0.3, 4.0, extent=(-10.0, 110.0, -10.0, 90.0), rng=5, spacing_m=0.5
    )
    # cubes and a wreck across tile edges (tiles of 16 cells start at x = -3.3 + 16 k ...)
    return terrain.compose(
        terrain.plane_seabed(8.0, slope_rad=math.radians(6.0), aspect_rad=math.radians(60.0)),
        rough,
        terrain.cube(12.7, 8.1, 2.0),
        terrain.cube(28.7, 24.1, 1.0),
        terrain.cube(60.0, 40.0, 0.5),
    )


def _rays(rng, n, z0):
    """Rays from height ``z0`` over and around the extent, up to 45 deg off nadir."""
    x = rng.uniform(EXTENT[0] - 30, EXTENT[1] + 30, n)
    y = rng.uniform(EXTENT[2] - 30, EXTENT[3] + 30, n)
    theta = rng.uniform(0.0, math.radians(45.0), n)
    az = rng.uniform(0.0, 2 * math.pi, n)
    d = np.column_stack([np.sin(theta) * np.sin(az), np.sin(theta) * np.cos(az), -np.cos(theta)])
    d[: n // 50] = [0.0, 0.0, -1.0]  # some straight down
    d[n // 50 : n // 25, 1] = 0.0  # some with no northing
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return np.column_stack([x, y, np.full(n, z0)]), d


@pytest.mark.parametrize("z0", [40.0, -1.0])
def test_tiles_give_the_whole_meshs_hits(z0):
    """Every hit, distance and normal of a whole-extent mesh (open3d over all triangles)."""
    seabed = _rough_with_boxes()
    whole = MeshCaster.from_trimesh(seabed_mesh(seabed, 1.0, EXTENT))
    tiled = TiledSeabed(seabed, 1.0, EXTENT, tile_cells=16, cache_tiles=4)
    assert tiled.shape == (5, 7)
    o, d = _rays(np.random.default_rng(3), 40_000, z0)
    h0, t0, n0 = whole.cast(o, d)
    h1, t1, n1 = tiled.cast(o, d)
    assert h0.sum() > 10_000 and (~h0).sum() > 1000  # hits, and rays off the extent
    np.testing.assert_array_equal(h1, h0)
    # the same triangle: the same float64 distance, except a ray through an edge shared by
    # two tiles, which may take the neighbour's triangle at the same point
    same = t1 == t0
    assert same.mean() > 0.999
    np.testing.assert_allclose(t1, t0, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(n1[same], n0[same])
    assert len(tiled._tiles) <= 4


def test_a_slanted_ray_crosses_tiles_to_the_analytic_plane():
    """Over a plane, rays crossing many tiles meet it where geometry says."""
    plane = terrain.plane_seabed(10.0, slope_rad=math.radians(10.0), aspect_rad=0.3)
    tiled = TiledSeabed(plane, 2.0, (0.0, 400.0, 0.0, 300.0), tile_cells=16, cache_tiles=200)
    rng = np.random.default_rng(1)
    n = 5000
    o = np.column_stack([rng.uniform(0, 400, n), rng.uniform(0, 300, n), np.full(n, 200.0)])
    theta = rng.uniform(0.0, math.radians(60.0), n)
    az = rng.uniform(0, 2 * math.pi, n)
    d = np.column_stack([np.sin(theta) * np.sin(az), np.sin(theta) * np.cos(az), -np.cos(theta)])
    hit, t, nrm = tiled.cast(o, d)
    # z = -10 + tan(10 deg) (x sin a + y cos a) . (downslope toward azimuth a deepens)
    g = -math.tan(math.radians(10.0)) * np.array([math.sin(0.3), math.cos(0.3)])
    # o_z + t d_z = z0 + g . (o_xy + t d_xy)  ->  t = (z0 + g.o - o_z) / (d_z - g.d)
    t_exact = (-10.0 + o[:, :2] @ g - o[:, 2]) / (d[:, 2] - d[:, :2] @ g)
    p = o + t_exact[:, None] * d
    inside = (p[:, 0] > 0) & (p[:, 0] < 400) & (p[:, 1] > 0) & (p[:, 1] < 300)
    np.testing.assert_array_equal(hit, inside)
    np.testing.assert_allclose(t[hit], t_exact[hit], rtol=1e-9, atol=1e-7)
    up = np.array([-g[0], -g[1], 1.0]) / math.sqrt(1.0 + g @ g)
    np.testing.assert_allclose(nrm[hit], np.broadcast_to(up, nrm[hit].shape), atol=1e-12)
    # a ray's path over 60 deg crosses many 32 m tiles: the walk went past the first
    assert np.any(np.abs(p[hit, 0] - o[hit, 0]) > 64.0)


def test_a_cube_on_a_tile_corner_keeps_its_top():
    """A 1 m cube centred on the corner of four tiles: its top from each quarter."""
    seabed = terrain.compose(terrain.plane_seabed(10.0), terrain.cube(16.0, 16.0, 1.0))
    tiled = TiledSeabed(seabed, 1.0, (0.0, 64.0, 0.0, 64.0), tile_cells=16)
    assert tiled.bx[1] == 16.0 and tiled.by[1] == 16.0
    xy = np.array([[15.7, 15.7], [16.3, 15.6], [15.8, 16.4], [16.2, 16.2], [17.0, 17.0]])
    o = np.column_stack([xy, np.zeros(5)])
    hit, t, _ = tiled.cast(o, np.tile([0.0, 0.0, -1.0], (5, 1)))
    assert hit.all()
    np.testing.assert_allclose(-t, [-9.0, -9.0, -9.0, -9.0, -10.0], atol=1e-6)


def test_meshing_is_bounded_and_lazy():
    """No tile before a ray asks; at most ``cache_tiles`` held; a pickle carries none."""
    plane = terrain.plane_seabed(5.0)
    tiled = TiledSeabed(plane, 1.0, (0.0, 2000.0, 0.0, 1200.0), tile_cells=128, cache_tiles=3)
    assert tiled.shape == (10, 16) and tiled.tiles_built == 0
    o = np.column_stack([np.linspace(1, 1999, 50), np.linspace(1, 1199, 50), np.zeros(50)])
    hit, t, _ = tiled.cast(o, np.tile([0.0, 0.0, -1.0], (50, 1)))
    assert hit.all()
    np.testing.assert_allclose(t, 5.0, atol=1e-6)
    assert len(tiled._tiles) == 3 and tiled.tiles_built >= 12
    again = pickle.loads(pickle.dumps(tiled))
    assert len(again._tiles) == 0
    np.testing.assert_array_equal(again.cast(o, np.tile([0.0, 0.0, -1.0], (50, 1)))[1], t)


def test_rays_from_high_up_mesh_only_the_tiles_they_reach():
    """From 3 km at 20 deg a ray passes over ~8 tiles of 128 m: only where it lands is meshed."""
    plane = terrain.plane_seabed(5.0)
    tiled = TiledSeabed(plane, 1.0, (0.0, 2000.0, 0.0, 1200.0), tile_cells=128, cache_tiles=50)
    n = 20
    o = np.column_stack([np.full(n, 100.0), np.linspace(100.0, 1100.0, n), np.full(n, 3000.0)])
    a = math.radians(20.0)
    d = np.tile([math.sin(a), 0.0, -math.cos(a)], (n, 1))
    hit, t, _ = tiled.cast(o, d)
    assert hit.all()
    np.testing.assert_allclose(t, 3005.0 / math.cos(a), rtol=1e-12)
    landed = {(int((100.0 + 3005.0 * math.tan(a)) // 128), int(y // 128)) for y in o[:, 1]}
    assert len(tiled._zmax) > 5 * len(landed)  # heights looked at along the way
    assert tiled.tiles_built == len(landed)  # meshed only where they land


def test_hits_on_a_tile_edge_far_from_the_origin_are_kept():
    """10 km out, float32 picks the triangle: rays landing within 2 mm of a tile edge all hit."""
    extent = (10_000.0, 10_512.0, 8000.0, 8256.0)
    plane = terrain.plane_seabed(20.0)
    whole = MeshCaster.from_trimesh(seabed_mesh(plane, 1.0, extent))
    tiled = TiledSeabed(plane, 1.0, extent)
    assert tiled.bx[1] == 10_256.0
    off = np.linspace(-2e-3, 2e-3, 4001)
    a = math.radians(20.0)
    d = np.tile([math.sin(a), 0.0, -math.cos(a)], (off.size, 1))
    o = np.column_stack(
        [10_256.0 + off - 520.0 * math.tan(a), np.full(off.size, 8128.3), np.full(off.size, 500.0)]
    )
    h0, t0, _ = whole.cast(o, d)
    h1, t1, _ = tiled.cast(o, d)
    assert h0.all() and h1.all()
    np.testing.assert_allclose(t1, t0, rtol=0, atol=1e-6)
    np.testing.assert_allclose(t1, 520.0 / math.cos(a), rtol=0, atol=1e-3)  # z = -20 exactly


def test_a_box_past_the_extent_edge_is_met():
    """A 4 m cube across the extent's east edge and a tile row: its outer half, as one mesh."""
    seabed = terrain.compose(terrain.plane_seabed(10.0), terrain.cube(64.0, 16.0, 4.0))
    tiled = TiledSeabed(seabed, 1.0, (0.0, 64.0, 0.0, 64.0), tile_cells=16)
    # straight down outside the extent onto the top (z = -6); and a ray leaving the extent in
    # tile row 0 that meets the top's part over row 1, past the extent
    o = np.array([[65.0, 17.0, 0.0], [63.0, 14.0, 0.0]])
    d = np.array([[0.0, 0.0, -1.0], [2.0, 3.0, -7.0]])
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    hit, t, nrm = tiled.cast(o, d)
    assert hit.all()
    np.testing.assert_allclose((o + t[:, None] * d)[:, 2], -6.0, atol=1e-9)
    np.testing.assert_allclose(nrm, [[0, 0, 1], [0, 0, 1]], atol=1e-12)


def test_a_seabed_smaller_than_the_extent_fails_when_built():
    """A DEM-like grid not covering the extent: an error at build time, not in a worker's cast."""
    from terrain.gridded import GridSurface

    dem = GridSurface(0.0, 0.0, 1.0, 1.0, np.zeros((301, 301)))
    with pytest.raises(ValueError, match="x_m"):
        TiledSeabed(dem, 1.0, (-20.0, 280.0, 0.0, 300.0))
