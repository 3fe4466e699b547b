"""The simulated world (the truth side): seabed and water surfaces as height fields.

All geometry is in local coordinates (float64 metres, x east, y north, z up) relative to a
:class:`LocalFrame` origin; depth is positive down and named ``depth_m``; azimuths are clockwise
from north (+y) in radians. Every surface is a :class:`Surface` with an exact ``height_m(x, y)``,
``gradient``, ``normal``, ``bounds`` and ``to_mesh(resolution_m)``; surfaces add (``a + b``).

Modules: :mod:`~terrain.surface` (Surface, Plane, CompositeSurface), :mod:`~terrain.gridded`
(GridSurface, spline truth of gridded fields), :mod:`~terrain.frame` (LocalFrame),
:mod:`~terrain.seabed` (planar seabed, composition), :mod:`~terrain.roughness` (spectral
roughness), :mod:`~terrain.features` (cubes, wreck, ridge, channel), :mod:`~terrain.shoreline`
(Beach), :mod:`~terrain.dem` (GeoTIFF DEM), :mod:`~terrain.wave_spectra` (PM, JONSWAP, spreading,
Cox-Munk, wind profile), :mod:`~terrain.water` (FlatWater, Tide, WaveField).
"""

from terrain.dem import read_dem
from terrain.features import IHO_CUBE_SIDES_M, Box, Ridge, channel, cube, ridge, wreck
from terrain.frame import LocalFrame
from terrain.gridded import GridSurface
from terrain.roughness import gaussian_roughness, von_karman_roughness
from terrain.seabed import compose, plane_seabed
from terrain.shoreline import Beach
from terrain.surface import UNBOUNDED, CompositeSurface, Plane, Surface
from terrain.water import FlatWater, Tide, WaveField, depth_m

__all__ = [
    "UNBOUNDED",
    "Beach",
    "Box",
    "CompositeSurface",
    "FlatWater",
    "GridSurface",
    "IHO_CUBE_SIDES_M",
    "LocalFrame",
    "Plane",
    "Ridge",
    "Surface",
    "Tide",
    "WaveField",
    "channel",
    "compose",
    "cube",
    "depth_m",
    "gaussian_roughness",
    "plane_seabed",
    "read_dem",
    "ridge",
    "von_karman_roughness",
    "wreck",
]
