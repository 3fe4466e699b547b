"""Seabed building blocks: the planar base and the composition of base + roughness + features.

Conventions: local x east, y north, z up (metres); depth positive down, ``depth = -z`` for a water
surface at z = 0. Aspect is the *downslope* azimuth, clockwise from north (+y): a seabed with
aspect ``a`` deepens fastest along ``(sin a, cos a)``; aspect 0 deepens northward, pi/2 eastward.

The other generators live beside this module, one job each: :mod:`terrain.roughness` (spectral
rough seabed), :mod:`terrain.features` (IHO S-44 cubes, ridge, channel, wreck),
:mod:`terrain.shoreline` (beach rising out of the water), :mod:`terrain.dem` (user GeoTIFF DEM).
"""

from __future__ import annotations

import math
from typing import Any

from terrain._validate import check_bounds, check_number
from terrain.surface import UNBOUNDED, CompositeSurface, Plane, Surface

__all__ = ["plane_seabed", "compose"]


def plane_seabed(
    depth_m: float,
    *,
    slope_rad: float | None = None,
    gradient: float | None = None,
    aspect_rad: float = 0.0,
    extent: Any = UNBOUNDED,
) -> Plane:
    """A planar seabed of any gradient and aspect.

    Parameters
    ----------
    depth_m : float
        Depth at the local origin in metres, positive down (the seabed height there is
        ``-depth_m``); negative means above z = 0 (dry).
    slope_rad : float, optional
        Slope angle below the horizontal in radians, ``0 <= slope_rad < pi/2``.
    gradient : float, optional
        Slope as ``tan(slope)`` (metres of depth per metre), ``>= 0``. Give at most one of
        ``slope_rad`` and ``gradient``; neither means flat.
    aspect_rad : float
        Downslope azimuth in radians, clockwise from north (+y).
    extent : tuple of 4 float
        ``(xmin, xmax, ymin, ymax)`` of the plane; unbounded by default.

    Returns
    -------
    Plane
        ``z = -depth_m - gradient * (x sin(aspect) + y cos(aspect))``.

    Examples
    --------
    >>> p = plane_seabed(10.0, gradient=0.1, aspect_rad=math.pi / 2)  # deepens eastward
    >>> float(p.height_m(100.0, 0.0))
    -20.0
    """
    d = check_number("depth_m", depth_m)
    if slope_rad is not None and gradient is not None:
        raise ValueError(
            f"give at most one of `slope_rad` and `gradient`; got {slope_rad!r} and {gradient!r}"
        )
    if slope_rad is not None:
        g = math.tan(check_number("slope_rad", slope_rad, ge=0.0, lt=math.pi / 2))
    elif gradient is not None:
        g = check_number("gradient", gradient, ge=0.0)
    else:
        g = 0.0
    a = check_number("aspect_rad", aspect_rad)
    return Plane(
        z0_m=-d,
        dz_dx=-g * math.sin(a),
        dz_dy=-g * math.cos(a),
        extent=check_bounds("extent", extent, allow_inf=True),
    )


def compose(base: Surface, *others: Surface) -> CompositeSurface:
    """Seabed as the sum of a base (plane, beach or DEM) and roughness and features.

    Parameters
    ----------
    base : Surface
        The base height field.
    *others : Surface
        Added heights (zero-mean roughness, features that are zero away from themselves).

    Returns
    -------
    CompositeSurface
        Height and gradient are sums; bounds are the intersection of the parts' bounds.
    """
    return CompositeSurface((base, *others))
