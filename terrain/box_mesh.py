"""A seabed mesh in which boxes (IHO cubes, wrecks) keep their flat tops and vertical walls.

A regular-grid mesh samples the seabed's height at its nodes only (:meth:`Surface.to_mesh`):
a box narrower than two cells loses its top (a 1 m cube on a 1 m grid becomes a pyramid two
cells wide whose apex is the only node at the top height; a 0.5 m cube can fall between nodes
and vanish). The tracer then sees another seabed than the truth (:meth:`Box.height_m`, a step)
that the evaluation scores the soundings against, so a sounding on the cube's top reads
metres too deep for the simulator's reason, not the survey's.

:func:`seabed_mesh` meshes the seabed *without* its boxes on the regular grid, and adds each
box as its own triangles: a top grid on the exact footprint (spacing at most the mesh
resolution, at least 2 nodes a side) at the base's height plus the box height (the truth's
top, which follows the base), and four vertical walls from the top's rim down to
:data:`WALL_FOOT_M` below the base (under the base mesh, so no gap opens at the foot). A ray
meets the top, a wall, or the base around the box, as over the true step. Wall normals point
out of the box, so a beam meets a wall's lit side only.
"""

from __future__ import annotations

import math

import numpy as np
import trimesh

from terrain.features import Box
from terrain.surface import CompositeSurface, Surface, grid_axis

__all__ = ["WALL_FOOT_M", "box_triangles", "seabed_mesh", "split_boxes"]

#: walls reach this far below the base: under the base mesh's interpolation error
WALL_FOOT_M = 0.5


def box_triangles(box: Box, base: Surface, resolution_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Vertices ``(n, 3)`` and faces ``(m, 3)`` of a box standing on ``base``.

    The top: a grid over the footprint, ``height = base + box_height_m`` at each node. The
    walls: one quad (two triangles) per rim edge, from the top's rim down to
    :data:`WALL_FOOT_M` below the base, wound so their normals point outwards.
    """
    u = grid_axis(-0.5 * box.length_m, 0.5 * box.length_m, resolution_m)
    v = grid_axis(-0.5 * box.width_m, 0.5 * box.width_m, resolution_m)
    nu, nv = u.size, v.size
    uu, vv = np.meshgrid(u, v)  # (nv, nu)
    s, c = math.sin(box.heading_rad), math.cos(box.heading_rad)
    # along the heading (u) and across it to starboard (v), as Box._height measures them
    xx = box.x_m + uu * s + vv * c
    yy = box.y_m + uu * c - vv * s
    zb = np.asarray(base.height_m(xx, yy), dtype=np.float64)
    top = np.column_stack([xx.ravel(), yy.ravel(), (zb + box.box_height_m).ravel()])
    idx = np.arange(nu * nv).reshape(nv, nu)
    a, b = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel()
    d, e = idx[1:, :-1].ravel(), idx[1:, 1:].ravel()
    faces = [np.column_stack([a, b, e]), np.column_stack([a, e, d])]
    # the rim, once round (each node once)
    rim = np.concatenate([idx[0, :], idx[1:, -1], idx[-1, -2::-1], idx[-2:0:-1, 0]]).astype(
        np.int64
    )
    foot = top[rim].copy()
    foot[:, 2] = zb.ravel()[rim] - WALL_FOOT_M
    n_top, k = top.shape[0], rim.size
    f_idx = n_top + np.arange(k)
    t0, t1 = rim, np.roll(rim, -1)
    b0, b1 = f_idx, np.roll(f_idx, -1)
    walls = np.concatenate([np.column_stack([t0, t1, b1]), np.column_stack([t0, b1, b0])])
    verts = np.vstack([top, foot])
    # outward: the (horizontal) normal points away from the box's centre
    p0, p1, p2 = (verts[walls[:, i]] for i in range(3))
    nrm = np.cross(p1 - p0, p2 - p0)
    mid = (p0 + p1 + p2) / 3.0
    out = nrm[:, 0] * (mid[:, 0] - box.x_m) + nrm[:, 1] * (mid[:, 1] - box.y_m)
    walls = np.where((out < 0.0)[:, None], walls[:, [0, 2, 1]], walls)
    faces.append(walls)
    return verts, np.concatenate(faces, axis=0)


def split_boxes(seabed: Surface) -> tuple[Surface, tuple[Box, ...]]:
    """``(base, boxes)``: the seabed without its boxes, and the boxes meshed exactly.

    A seabed of boxes alone (or none) is all base: it is meshed on the grid.
    """
    parts = seabed.parts if isinstance(seabed, CompositeSurface) else (seabed,)
    boxes = tuple(p for p in parts if isinstance(p, Box))
    rest = [p for p in parts if not isinstance(p, Box)]
    if not boxes or not rest:
        return seabed, ()
    return (rest[0] if len(rest) == 1 else CompositeSurface(tuple(rest))), boxes


def seabed_mesh(seabed: Surface, resolution_m: float, bounds=None) -> trimesh.Trimesh:
    """The seabed on a regular grid with its boxes as exact tops and walls (module docstring).

    Parameters
    ----------
    seabed : Surface
        A plain surface, or a :class:`CompositeSurface` whose :class:`Box` parts are meshed
        exactly; without boxes the result is ``seabed.to_mesh(resolution_m, bounds)``.
    resolution_m : float
        Grid spacing of the base (and largest spacing of the box tops), metres.
    bounds : tuple of 4 float, optional
        Region to mesh (:meth:`Surface.to_mesh`).

    Returns
    -------
    trimesh.Trimesh
        The base grid's vertices first (row-major, as :meth:`Surface.to_mesh`), then each box's.
    """
    base, boxes = split_boxes(seabed)
    if not boxes:
        return seabed.to_mesh(resolution_m, bounds)
    mesh = base.to_mesh(resolution_m, bounds)
    verts, faces = [np.asarray(mesh.vertices)], [np.asarray(mesh.faces)]
    n = verts[0].shape[0]
    for box in boxes:
        v, f = box_triangles(box, base, resolution_m)
        verts.append(v)
        faces.append(f + n)
        n += v.shape[0]
    return trimesh.Trimesh(
        vertices=np.vstack(verts), faces=np.vstack(faces), process=False, validate=False
    )
