"""A cube in the tracer's seabed mesh: its flat top and vertical walls, as the truth's step.

Truth written in the tests: a plane at z = -10 (or tilted, z = -10 - 0.1 x) and a cube of side
s centred at (x0, y0): the height is the plane + s on the closed footprint, the plane elsewhere.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import terrain
from pipeline.simulate.trace import MeshCaster
from pipeline.simulate.world import build_world
from terrain.box_mesh import seabed_mesh


def _down_hits(mesh, x, y):
    """Heights where vertical rays from z = 0 meet the mesh."""
    caster = MeshCaster.from_trimesh(mesh)
    n = x.size
    origin = np.column_stack([x, y, np.zeros(n)])
    direction = np.tile([0.0, 0.0, -1.0], (n, 1))
    hit, t, normal = caster.cast(origin, direction)
    assert hit.all()
    return -t, normal


@pytest.mark.parametrize("side_m", [0.5, 1.0, 2.0])
def test_cube_top_is_flat_over_its_footprint_on_a_coarse_mesh(side_m):
    x0, y0 = 9.44, -3.31  # off the 1 m grid's nodes
    seabed = terrain.compose(terrain.plane_seabed(10.0), terrain.cube(x0, y0, side_m))
    mesh = seabed_mesh(seabed, 1.0, (0.0, 20.0, -10.0, 10.0))
    g = np.linspace(-0.49, 0.49, 15) * side_m
    x, y = (a.ravel() for a in np.meshgrid(x0 + g, y0 + g))
    z, normal = _down_hits(mesh, x, y)
    np.testing.assert_allclose(z, -10.0 + side_m, atol=1e-5)  # float32 casting
    np.testing.assert_allclose(normal[:, 2], 1.0, atol=1e-6)
    # just outside the walls: the plane
    ring = side_m / 2 + 0.02
    xo = np.array([x0 - ring, x0 + ring, x0, x0])
    yo = np.array([y0, y0, y0 - ring, y0 + ring])
    zo, _ = _down_hits(mesh, xo, yo)
    np.testing.assert_allclose(zo, -10.0, atol=1e-5)


def test_rotated_cube_on_a_slope_follows_the_base():
    x0, y0, s, h = 3.3, 4.7, 2.0, math.radians(30.0)
    base = terrain.plane_seabed(10.0, gradient=0.1, aspect_rad=math.pi / 2)  # z = -10 - 0.1 x
    seabed = terrain.compose(base, terrain.cube(x0, y0, s, h))
    mesh = seabed_mesh(seabed, 1.0, (-10.0, 20.0, -10.0, 20.0))
    # points inside the rotated footprint: along/across offsets within s/2
    u, v = np.meshgrid(np.linspace(-0.9, 0.9, 7), np.linspace(-0.9, 0.9, 7))
    x = x0 + u.ravel() * math.sin(h) + v.ravel() * math.cos(h)
    y = y0 + u.ravel() * math.cos(h) - v.ravel() * math.sin(h)
    z, _ = _down_hits(mesh, x, y)
    np.testing.assert_allclose(z, -10.0 - 0.1 * x + s, atol=1e-4)


def test_a_ray_off_nadir_meets_the_lit_wall():
    """A ray slanting east meets the west wall at the height the geometry gives."""
    seabed = terrain.compose(terrain.plane_seabed(10.0), terrain.cube(0.0, 0.0, 2.0))
    caster = MeshCaster.from_trimesh(seabed_mesh(seabed, 1.0, (-10.0, 10.0, -10.0, 10.0)))
    # the cube spans x, y in [-1, 1] and z in [-10, -8]: from (-1.5, 0, -8.5) down at 45 deg
    # towards +x the ray reaches x = -1 at z = -9, on the west wall
    origin = np.array([[-1.5, 0.0, -8.5]])
    d = np.array([[1.0, 0.0, -1.0]]) / math.sqrt(2.0)
    hit, t, normal = caster.cast(origin, d)
    assert hit[0]
    p = origin[0] + t[0] * d[0]
    np.testing.assert_allclose(p, [-1.0, 0.0, -9.0], atol=1e-5)
    np.testing.assert_allclose(normal[0], [-1.0, 0.0, 0.0], atol=1e-6)  # facing the ray


def test_build_world_uses_the_exact_cube():
    """The tracer's world (not only the helper): a 1 m cube on a 1 m mesh keeps its top."""
    from types import SimpleNamespace

    seabed = terrain.compose(terrain.plane_seabed(10.0), terrain.cube(0.37, 0.41, 1.0))
    scene = SimpleNamespace(
        seabed=SimpleNamespace(mesh_resolution_m=1.0),
        water_surface=SimpleNamespace(kind="flat", level_m=0.0),
        atmosphere=SimpleNamespace(refractive_index=1.0003),
        water=SimpleNamespace(phase_index=1.34),
    )
    truth = SimpleNamespace(seabed=seabed)
    world = build_world(scene, truth, (-5.0, 5.0, -5.0, 5.0))
    x = np.array([0.0, 0.37, 0.8])
    y = np.array([0.0, 0.41, 0.85])
    origin = np.column_stack([x, y, np.full(3, -1.0)])
    hit, t, _ = world.seabed.cast(origin, np.tile([0.0, 0.0, -1.0], (3, 1)))
    assert hit.all()
    np.testing.assert_allclose(-1.0 - t, -9.0, atol=1e-5)
