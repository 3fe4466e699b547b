"""Analytic :class:`~pipeline.simulate.paths.Paths` over flat water and a planar seabed.

For tests and benchmarks without the ray tracer (and without meshes): water surface ``z = 0``,
seabed a plane through the point ``depth_m`` below the beam axis's surface hit, tilted by
``seabed_slope_rad`` (downslope towards ``seabed_aspect_rad``, clockwise from north). A negative
``depth_m`` puts the plane above the water there: sub-rays meeting it in air are LAND. Sub-rays
use the tracer's Gaussian sunflower pattern (:func:`pipeline.simulate.trace.subray_pattern`, one
source of truth; imported only when ``n_sub > 1`` because it loads open3d), Fresnel coefficients
are unpolarised.
"""

from __future__ import annotations

import numpy as np

from pipeline import optics
from pipeline.simulate import paths as P

__all__ = ["flat_paths", "beam_axis"]


def beam_axis(off_nadir_rad, azimuth_rad) -> np.ndarray:
    """Unit beam directions ``(sin i sin a, sin i cos a, -cos i)``, shape ``(n, 3)``."""
    i, a = np.broadcast_arrays(np.atleast_1d(off_nadir_rad), np.atleast_1d(azimuth_rad))
    return np.stack([np.sin(i) * np.sin(a), np.sin(i) * np.cos(a), -np.cos(i)], axis=-1)


def _subrays(direction, n_sub, divergence_rad, cone_extent):
    if n_sub == 1:
        return direction[:, None, :], np.ones(1), np.zeros((1, 2))
    from pipeline.simulate.trace import subray_directions, subray_pattern

    offsets, weights = subray_pattern(n_sub, divergence_rad, cone_extent)
    return subray_directions(direction, offsets), weights, offsets


def _dot(a, b):
    return np.einsum("...i,...i->...", a, b)


def flat_paths(
    n_pulses: int = 1,
    *,
    altitude_m: float = 400.0,
    depth_m=10.0,
    off_nadir_rad=0.0,
    azimuth_rad=0.0,
    seabed_slope_rad: float = 0.0,
    seabed_aspect_rad: float = 0.0,
    n_sub: int = 1,
    divergence_rad: float = 1e-3,
    cone_extent: float = 1.5,
    water_phase_index: float = 1.3415,
    air_index: float = 1.000277,
    first_pulse_id: int = 0,
    spacing_m: float = 1.0,
) -> P.Paths:
    """Paths of ``n_pulses`` beams over flat water, computed in closed form.

    Parameters
    ----------
    n_pulses : int
        Pulses; pulse ``i`` fires from ``(i spacing_m, 0, altitude_m)``.
    altitude_m : float
        Height of the laser above the water surface, > 0.
    depth_m : float or (n_pulses,) array
        Seabed depth below the beam axis's surface hit (negative: land above the water).
    off_nadir_rad, azimuth_rad : float or (n_pulses,) array
        Beam axis: angle from nadir and azimuth clockwise from north.
    seabed_slope_rad, seabed_aspect_rad : float
        Seabed tilt and the azimuth it deepens towards.
    n_sub : int
        Sub-rays per pulse across the divergence cone.
    divergence_rad, cone_extent : float
        Full-angle 1/e² divergence and the extent of the sub-ray pattern (tracer's meaning).
    water_phase_index, air_index : float
        Phase indices (refraction and Fresnel).
    first_pulse_id : int
        Global id of the first pulse.
    spacing_m : float
        Along-x distance between pulse origins.

    Returns
    -------
    Paths
        Flags ``OK``, ``LAND`` or ``NO_BOTTOM`` (beam refracted away from a steep seabed).
    """
    n = int(n_pulses)
    n_a, n_w = float(air_index), float(water_phase_index)
    origin = np.zeros((n, 3))
    origin[:, 0] = spacing_m * np.arange(n)
    origin[:, 2] = altitude_m
    axis = np.broadcast_to(beam_axis(off_nadir_rad, azimuth_rad), (n, 3)).copy()
    d, weights, offsets = _subrays(axis, n_sub, divergence_rad, cone_extent)
    k = weights.size
    depth = np.broadcast_to(np.asarray(depth_m, dtype=np.float64), (n,))

    # seabed plane: through the point `depth` below the axis's surface hit, normal tilted
    axis_hit = origin + (altitude_m / -axis[:, 2])[:, None] * axis
    q0 = axis_hit - depth[:, None] * np.array([0.0, 0.0, 1.0])
    sb, cb = np.sin(seabed_slope_rad), np.cos(seabed_slope_rad)
    nb = np.array([sb * np.sin(seabed_aspect_rad), sb * np.cos(seabed_aspect_rad), cb])
    nb = np.broadcast_to(nb, (n, k, 3))

    t_air = altitude_m / -d[..., 2]
    surf = origin[:, None, :] + t_air[..., None] * d
    # land when the water surface hit lies below the seabed plane
    below = _dot(surf - q0[:, None, :], nb) < 0.0
    d_nb = _dot(d, nb)
    t_land = _dot(q0[:, None, :] - origin[:, None, :], nb) / np.where(d_nb < 0, d_nb, -1.0)
    land = below & (d_nb < 0)
    water = ~land

    up = np.broadcast_to(np.array([0.0, 0.0, 1.0]), (n, k, 3))
    cos_i = np.clip(-d[..., 2], 0.0, 1.0)
    theta = np.arccos(cos_i)
    r_surf, t_down = optics.fresnel_unpolarised(n_a, n_w, theta)
    refr, _ = optics.refract_direction(d, up, n_a, n_w)
    rb = _dot(refr, nb)
    s_b = _dot(q0[:, None, :] - surf, nb) / np.where(rb < 0, rb, -1.0)
    bottom = water & (rb < 0) & (s_b > 0)
    no_bottom = water & ~bottom
    water_path = np.where(bottom, s_b, 0.0)
    cos_w = np.clip(-refr[..., 2], 0.0, 1.0)
    _, t_up = optics.fresnel_unpolarised(n_w, n_a, np.arccos(cos_w))
    cos_bi = np.clip(-rb, 0.0, 1.0)

    flags = np.where(land, P.LAND, np.where(no_bottom, P.NO_BOTTOM, P.OK)).astype(np.uint8)
    land_cos = np.clip(-d_nb, 0.0, 1.0)
    air_range = np.where(land, t_land, t_air)
    hit_xyz = origin[:, None, :] + air_range[..., None] * d
    zeros3 = np.zeros((n, k, 3))
    return P.Paths(
        pulse_id=first_pulse_id + np.arange(n, dtype=np.int64),
        subray_weight=np.asarray(weights, dtype=np.float64),
        subray_offset_rad=np.asarray(offsets, dtype=np.float64),
        flags=flags,
        origin_m=origin,
        direction=d,
        air_range_m=air_range,
        surface_xyz_m=hit_xyz,
        surface_normal=np.where(land[..., None], nb, up),
        incidence_rad=np.where(land, np.arccos(land_cos), theta),
        transmittance_down=np.where(water, t_down, 0.0),
        reflectance_surface=np.where(water, r_surf, 0.0),
        refracted_dir=np.where(water[..., None], refr, zeros3),
        water_path_m=water_path,
        bottom_xyz_m=np.where(bottom[..., None], surf + water_path[..., None] * refr, zeros3),
        bottom_normal=np.where(bottom[..., None], nb, zeros3),
        bottom_incidence_rad=np.where(bottom, np.arccos(cos_bi), 0.0),
        transmittance_up=np.where(bottom, t_up, 0.0),
    )
