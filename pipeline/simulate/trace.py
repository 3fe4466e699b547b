"""Trace pulses through air, the water surface and the water to the seabed.

Each pulse is split into ``n_sub`` sub-rays across its divergence cone (a deterministic
sunflower pattern weighted by the Gaussian beam profile), cast with open3d's
``RaycastingScene`` against the water-surface and seabed meshes, refracted by vector Snell at
the hit facet's normal with the water's phase index, and cast again to the seabed. The return
is traced back from the seabed hit along the reversed refracted ray to the surface, where total
internal reflection is flagged.

open3d works in float32; every hit is re-solved in float64 against the plane of the triangle
open3d reported, so hit points carry float64 accuracy (sub-micrometre) in the local frame.
Nothing here is random, so :class:`~pipeline.simulate.paths.Paths` are identical whatever the
chunk size.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import open3d as o3d

from pipeline import optics
from pipeline.simulate import paths as P
from pipeline.simulate.trace_settings import TraceSettings

__all__ = [
    "TraceSettings",
    "MeshCaster",
    "World",
    "subray_pattern",
    "subray_directions",
    "trace",
]

_INVALID = np.uint32(0xFFFFFFFF)
_GOLDEN_ANGLE = math.pi * (3.0 - math.sqrt(5.0))


class MeshCaster:
    """A triangle mesh ready for ray casting, with float64 hit refinement.

    Parameters
    ----------
    vertices : (n_vertices, 3) float64
        Local-frame vertex coordinates, metres.
    faces : (n_faces, 3) int
        Vertex indices of each triangle.
    """

    def __init__(self, vertices: np.ndarray, faces: np.ndarray) -> None:
        self.vertices = np.ascontiguousarray(vertices, dtype=np.float64)
        self.faces = np.ascontiguousarray(faces, dtype=np.int64)
        v0, v1, v2 = (self.vertices[self.faces[:, i]] for i in range(3))
        normal = np.cross(v1 - v0, v2 - v0)
        normal *= np.where(normal[:, 2:3] < 0.0, -1.0, 1.0)  # upward, whatever the winding
        length = np.linalg.norm(normal, axis=1, keepdims=True)
        if np.any(length == 0.0):
            raise ValueError("mesh has degenerate (zero-area) triangles")
        self.face_normal = normal / length
        self.face_point = v0
        self._scene = self._raycasting_scene()

    def _raycasting_scene(self):
        scene = o3d.t.geometry.RaycastingScene()
        scene.add_triangles(
            o3d.core.Tensor(self.vertices.astype(np.float32)),
            o3d.core.Tensor(self.faces.astype(np.uint32)),
        )
        return scene

    def __getstate__(self) -> dict:
        # open3d's scene cannot be pickled: the arrays travel (to a worker process) and the
        # scene is rebuilt from the same float32 triangles, so every cast gives the same hits
        return {k: v for k, v in self.__dict__.items() if k != "_scene"}

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)
        self._scene = self._raycasting_scene()

    @classmethod
    def from_trimesh(cls, mesh) -> MeshCaster:
        """Build from a :class:`trimesh.Trimesh`."""
        return cls(np.asarray(mesh.vertices), np.asarray(mesh.faces))

    def cast(self, origin_m: np.ndarray, direction: np.ndarray, nthreads: int = 0, t_s=None):
        """First hit of each ray.

        Parameters
        ----------
        origin_m, direction : (n, 3) float64
            Ray origins and unit directions.
        t_s : (n,) float64, optional
            Ray times; a mesh does not move, so they are ignored (the moving sea's caster,
            :class:`~pipeline.simulate.wave_caster.WaveCaster`, uses them).

        Returns
        -------
        hit : (n,) bool
        t_m : (n,) float64
            Distance to the hit along the ray (0 where no hit).
        normal : (n, 3) float64
            Upward unit normal of the hit triangle (0 where no hit).
        """
        hit, t, nrm, _ = self.cast_faces(origin_m, direction, nthreads)
        return hit, t, nrm

    def cast_faces(self, origin_m: np.ndarray, direction: np.ndarray, nthreads: int = 0):
        """:meth:`cast`'s results and the hit triangle of each ray, ``(n,)`` int64 (0: none)."""
        rays = np.empty((origin_m.shape[0], 6), dtype=np.float32)
        rays[:, :3] = origin_m
        rays[:, 3:] = direction
        ans = self._scene.cast_rays(o3d.core.Tensor(rays), nthreads=nthreads)
        prim = ans["primitive_ids"].numpy()
        hit = prim != _INVALID
        idx = np.where(hit, prim, 0).astype(np.int64)
        nrm = self.face_normal[idx]
        denom = np.einsum("ij,ij->i", direction, nrm)
        num = np.einsum("ij,ij->i", self.face_point[idx] - origin_m, nrm)
        # float64 re-solve against the hit triangle's plane; denom is never 0 for a real hit
        safe = hit & (np.abs(denom) > 1e-300)
        t = np.divide(num, denom, out=np.zeros_like(num), where=safe)
        hit &= safe & (t >= 0.0)
        t = np.where(hit, t, 0.0)
        nrm = np.where(hit[:, None], nrm, 0.0)
        return hit, t, nrm, idx


@dataclass(frozen=True)
class World:
    """The simulated world as the tracer sees it: water-surface and seabed meshes.

    Attributes
    ----------
    water : MeshCaster or pipeline.simulate.wave_caster.WaveCaster
    seabed : MeshCaster or pipeline.simulate.tiled_seabed.TiledSeabed
        Anything with :meth:`MeshCaster.cast`.
    n_air, n_water : float
        Phase indices (Snell and Fresnel).
    """

    water: Any
    seabed: Any
    n_air: float
    n_water: float


def subray_pattern(n_sub: int, divergence_rad: float, cone_extent: float = 1.5):
    """Angular offsets and energy weights of ``n_sub`` sub-rays across a Gaussian beam.

    A sunflower (Vogel) spiral fills a disc of radius ``cone_extent × w`` with equal-area
    cells, ``w`` being the 1/e² half-angle; each cell's weight is the Gaussian irradiance
    ``exp(−2 r²/w²)`` at its point, normalised to sum to 1. One sub-ray is the beam axis.

    Returns
    -------
    offsets : (n_sub, 2) float64
        Angular offsets from the axis, radians.
    weights : (n_sub,) float64
    """
    if n_sub == 1:
        return np.zeros((1, 2)), np.ones(1)
    w = 0.5 * divergence_rad
    k = np.arange(n_sub)
    r = cone_extent * w * np.sqrt((k + 0.5) / n_sub)
    phi = k * _GOLDEN_ANGLE
    offsets = np.column_stack([r * np.cos(phi), r * np.sin(phi)])
    weights = np.exp(-2.0 * (r / w) ** 2)
    return offsets, weights / weights.sum()


def _perpendicular_basis(d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors (n, 3) perpendicular to each unit direction in ``d`` and each other."""
    helper = np.zeros_like(d)
    use_x = np.abs(d[:, 0]) < 0.9
    helper[use_x, 0] = 1.0
    helper[~use_x, 1] = 1.0
    u = np.cross(d, helper)
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    return u, np.cross(d, u)


def subray_directions(direction: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """Sub-ray unit directions (n_pulses, n_sub, 3) around each beam axis (n_pulses, 3)."""
    u, v = _perpendicular_basis(direction)
    tx = np.tan(offsets[:, 0])[None, :, None]
    ty = np.tan(offsets[:, 1])[None, :, None]
    d = direction[:, None, :] + tx * u[:, None, :] + ty * v[:, None, :]
    return d / np.linalg.norm(d, axis=2, keepdims=True)


def _fresnel_down(d, normal, n1, n2, polarisation, across_track):
    """Fresnel R and T at the surface for the pulse's polarisation."""
    cos_i = np.clip(-np.einsum("ij,ij->i", d, normal), 0.0, 1.0)
    theta = np.arccos(cos_i)
    r_s, r_p, t_s, t_p = optics.fresnel_power(n1, n2, theta)
    if polarisation in ("unpolarised", "circular"):
        return theta, 0.5 * (r_s + r_p), 0.5 * (t_s + t_p)
    # linear: split the field into s (perpendicular to the plane of incidence) and p parts
    e = (
        across_track
        if polarisation == "linear_across_track"
        else np.cross(across_track, np.array([0.0, 0.0, 1.0]))
    )
    e = e - np.einsum("ij,ij->i", e, d)[:, None] * d
    e /= np.linalg.norm(e, axis=1, keepdims=True)
    s_hat = np.cross(d, normal)
    s_len = np.linalg.norm(s_hat, axis=1, keepdims=True)
    # at normal incidence the plane of incidence is undefined and R_s = R_p: any split works
    s_hat = np.where(s_len > 1e-12, s_hat / np.maximum(s_len, 1e-300), e)
    fs = np.einsum("ij,ij->i", e, s_hat) ** 2
    return theta, fs * r_s + (1 - fs) * r_p, fs * t_s + (1 - fs) * t_p


def trace(
    pulses,
    world: World,
    settings: TraceSettings,
    divergence_rad: float,
    polarisation: str = "unpolarised",
) -> P.Paths:
    """Trace one chunk of pulses to the seabed.

    Parameters
    ----------
    pulses : Pulses
        Needs ``pulse_id`` (n,), ``origin_m`` (n, 3), ``direction`` (n, 3) and ``yaw_rad`` (n,)
        (the true geometry: this is the simulation side); ``t_s`` (n,) emission times if the
        water surface moves (absent: t = 0).
    world : World
    settings : TraceSettings
    divergence_rad : float
        Full-angle 1/e² beam divergence.
    polarisation : {"unpolarised", "circular", "linear_across_track", "linear_along_track"}

    Returns
    -------
    Paths
        Shapes ``(n_pulses, n_sub)``; see :class:`~pipeline.simulate.paths.Paths`.
    """
    n = pulses.pulse_id.shape[0]
    # an undecided count (no scene to decide it, resolved_trace_settings) is the beam axis
    n_sub = settings.subrays or 1
    offsets, weights = subray_pattern(n_sub, divergence_rad, settings.cone_extent)
    k = weights.size
    d = subray_directions(np.asarray(pulses.direction, dtype=np.float64), offsets).reshape(-1, 3)
    o = np.repeat(np.asarray(pulses.origin_m, dtype=np.float64), k, axis=0)
    th = settings.nthreads
    # each sub-ray meets the sea as it is at its pulse's emission time (the flight time of
    # light, microseconds, is negligible against the waves' periods)
    t_emit = getattr(pulses, "t_s", None)
    t_ray = None if t_emit is None else np.repeat(np.asarray(t_emit, dtype=np.float64), k)
    timed = {} if t_ray is None else {"t_s": t_ray}
    hit_w, t_w, n_w = world.water.cast(o, d, th, **timed)
    hit_b, t_b, n_b = world.seabed.cast(o, d, th)
    land = hit_b & (~hit_w | (t_b < t_w))
    water = hit_w & ~land
    flags = np.where(hit_w | hit_b, P.OK, P.MISS).astype(np.uint8)
    flags[land] |= P.LAND

    air_range = np.where(land, t_b, np.where(water, t_w, 0.0))
    surf_xyz = np.where((land | water)[:, None], o + air_range[:, None] * d, 0.0)
    surf_nrm = np.where(land[:, None], n_b, np.where(water[:, None], n_w, 0.0))

    yaw = np.repeat(np.asarray(pulses.yaw_rad, dtype=np.float64), k)
    across = np.column_stack([np.cos(yaw), -np.sin(yaw), np.zeros_like(yaw)])
    safe_nrm = np.where(water[:, None], n_w, np.array([0.0, 0.0, 1.0]))
    theta, r_surf, t_down = _fresnel_down(
        d, safe_nrm, world.n_air, world.n_water, polarisation, across
    )
    cos_land = np.clip(-np.einsum("ij,ij->i", d, n_b), 0.0, 1.0)
    incidence = np.where(water, theta, np.where(land, np.arccos(cos_land), 0.0))
    refr_nrm = safe_nrm
    u_mss = getattr(world.water, "unresolved_mss", 0.0)
    if u_mss > 0.0:
        from pipeline.simulate.wave_caster import unresolved_normals

        # the waves below the traced scale tilt each sub-ray's entry facet (the glint takes
        # them as a density, the refracted beam as draws); a draw the ray cannot enter
        # (facing away) leaves the resolved facet
        tilted = unresolved_normals(safe_nrm, pulses.pulse_id, k, u_mss, world.water.seed)
        enters = np.einsum("ij,ij->i", d, tilted) < -1e-6
        refr_nrm = np.where((water & enters)[:, None], tilted, safe_nrm)
    refr, _ = optics.refract_direction(d, refr_nrm, world.n_air, world.n_water)

    hit_sb, t_sb, n_sb = world.seabed.cast(surf_xyz, refr, th)
    bottom_ok = water & hit_sb
    flags[water & ~hit_sb] |= P.NO_BOTTOM
    water_path = np.where(bottom_ok, t_sb, 0.0)
    bottom_xyz = np.where(bottom_ok[:, None], surf_xyz + water_path[:, None] * refr, 0.0)
    bottom_nrm = np.where(bottom_ok[:, None], n_sb, 0.0)
    cos_b = np.clip(-np.einsum("ij,ij->i", refr, n_sb), 0.0, 1.0)
    bottom_inc = np.where(bottom_ok, np.arccos(cos_b), 0.0)

    # the return: from the seabed back up the reversed refracted ray to the surface
    up = -refr
    hit_up, _, n_up = world.water.cast(bottom_xyz, up, th, **timed)
    exit_nrm = np.where((bottom_ok & hit_up)[:, None], n_up, safe_nrm)
    _, tir = optics.refract_direction(up, exit_nrm, world.n_water, world.n_air)
    cos_up = np.clip(np.einsum("ij,ij->i", up, exit_nrm), 0.0, 1.0)
    _, t_up = optics.fresnel_unpolarised(world.n_water, world.n_air, np.arccos(cos_up))
    tir_return = bottom_ok & tir
    flags[tir_return] |= P.TIR_RETURN
    t_up = np.where(bottom_ok & ~tir, t_up, 0.0)

    def shape(a: np.ndarray) -> np.ndarray:
        return a.reshape((n, k) + a.shape[1:])

    return P.Paths(
        pulse_id=np.asarray(pulses.pulse_id, dtype=np.int64).copy(),
        subray_weight=weights,
        subray_offset_rad=offsets,
        flags=shape(flags),
        origin_m=np.asarray(pulses.origin_m, dtype=np.float64).copy(),
        direction=shape(d),
        air_range_m=shape(air_range),
        surface_xyz_m=shape(surf_xyz),
        surface_normal=shape(surf_nrm),
        incidence_rad=shape(incidence),
        transmittance_down=shape(np.where(water, t_down, 0.0)),
        reflectance_surface=shape(np.where(water, r_surf, 0.0)),
        refracted_dir=shape(np.where(water[:, None], refr, 0.0)),
        water_path_m=shape(water_path),
        bottom_xyz_m=shape(bottom_xyz),
        bottom_normal=shape(bottom_nrm),
        bottom_incidence_rad=shape(bottom_inc),
        transmittance_up=shape(t_up),
    )
