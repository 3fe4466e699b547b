"""Meshes: vertices on the truth, piecewise-linear interpolation close to it."""

import math

import numpy as np
import pytest
import trimesh

from terrain import Plane, gaussian_roughness, plane_seabed


def _interpolate_on_mesh(mesh: trimesh.Trimesh, x, y, resolution):
    """Height of the mesh above (x, y): barycentric interpolation in the containing face.

    The containing face is searched among all faces whose vertices are within one cell of the
    point, so the test relies only on the mesh's vertices and faces, not on its grid layout.
    """
    tri = mesh.vertices[mesh.faces]  # (F, 3, 3)
    centroid = tri[:, :, :2].mean(axis=1)
    out = np.empty(x.shape)
    for i, (px, py) in enumerate(zip(x, y, strict=True)):
        near = np.flatnonzero(np.hypot(centroid[:, 0] - px, centroid[:, 1] - py) < resolution)
        a, b, c = tri[near, 0], tri[near, 1], tri[near, 2]
        det = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (c[:, 0] - a[:, 0]) * (b[:, 1] - a[:, 1])
        l1 = ((px - a[:, 0]) * (c[:, 1] - a[:, 1]) - (c[:, 0] - a[:, 0]) * (py - a[:, 1])) / det
        l2 = ((b[:, 0] - a[:, 0]) * (py - a[:, 1]) - (px - a[:, 0]) * (b[:, 1] - a[:, 1])) / det
        l0 = 1 - l1 - l2
        inside = np.flatnonzero((l0 >= -1e-12) & (l1 >= -1e-12) & (l2 >= -1e-12))
        j = inside[0]
        out[i] = l0[j] * a[j, 2] + l1[j] * b[j, 2] + l2[j] * c[j, 2]
    return out


def test_mesh_structure_and_vertices_on_truth():
    rough = gaussian_roughness(0.2, 4.0, extent=(0, 64, 0, 48), rng=3)
    m = rough.to_mesh(1.0)
    assert m.vertices.dtype == np.float64
    nx, ny = 65, 49
    assert len(m.vertices) == nx * ny and len(m.faces) == 2 * (nx - 1) * (ny - 1)
    # vertices are evaluations of the truth: equal to the last bit
    np.testing.assert_array_equal(
        m.vertices[:, 2], rough.height_m(m.vertices[:, 0], m.vertices[:, 1])
    )
    # faces wind counter-clockwise seen from above: all face normals point up
    assert np.all(m.face_normals[:, 2] > 0)
    lo, hi = m.bounds
    assert (lo[0], hi[0], lo[1], hi[1]) == (0.0, 64.0, 0.0, 48.0)


def test_plane_mesh_interpolates_truth_to_1e_9():
    p = plane_seabed(20.0, gradient=0.07, aspect_rad=0.4, extent=(-50.0, 50.0, -30.0, 30.0))
    m = p.to_mesh(3.0)
    rng = np.random.default_rng(0)
    x, y = rng.uniform(-50, 50, 300), rng.uniform(-30, 30, 300)
    # a plane is reproduced exactly by linear interpolation; 1e-9 m allows rounding
    np.testing.assert_allclose(_interpolate_on_mesh(m, x, y, 3.0), p.height_m(x, y), atol=1e-9)


def test_rough_mesh_error_small_against_resolution():
    rms, ell = 0.5, 8.0
    rough = gaussian_roughness(rms, ell, extent=(0, 128, 0, 128), rng=5)
    res = ell / 8
    m = rough.to_mesh(res, bounds=(0, 40, 0, 40))
    rng = np.random.default_rng(1)
    x, y = rng.uniform(0, 40, 400), rng.uniform(0, 40, 400)
    err = np.abs(_interpolate_on_mesh(m, x, y, res) - rough.height_m(x, y))
    # Linear interpolation on a triangle of circumradius R errs by <= R**2 / 2 * max|Hessian|
    # (Waldron 1998); R = res / sqrt(2) here. A Gaussian field has rms curvature
    # sqrt(12) rms / ell**2 (fourth derivative of its autocorrelation); 5 sigma bounds the max.
    bound = res**2 / 4 * 5 * math.sqrt(12) * rms / ell**2
    assert err.max() < bound
    # and small against the cell: 5 % of the resolution (measured 1.5 %)
    assert err.max() < 0.05 * res


def test_mesh_refuses_unbounded_and_huge():
    with pytest.raises(ValueError, match="`bounds` must be finite"):
        Plane(0.0).to_mesh(1.0)
    with pytest.raises(ValueError, match="`resolution_m` = 0.001 gives"):
        Plane(0.0, extent=(0, 100, 0, 100)).to_mesh(0.001)
    with pytest.raises(ValueError, match="`resolution_m` must be > 0; got -1"):
        Plane(0.0, extent=(0, 1, 0, 1)).to_mesh(-1)
