"""A shoreline: a beach profile whose depth goes to zero along a line and rises to dry land.

Profile across the shore, with ``s`` the distance seaward of the shoreline (negative on land)::

    z(s) = shoreline_z_m + min(-beach_gradient * s, berm_height_m) + dune(s)

* seaward (``s > 0``) the plane deepens with ``beach_gradient``: depth below the waterline
  ``shoreline_z_m`` is ``beach_gradient * s``;
* landward the foreshore keeps rising with the same gradient up to the flat berm
  ``berm_height_m`` above the waterline (``inf`` for no berm);
* a dune: raised-cosine bump ``dune_height_m * cos(pi (s + dune_distance_m) / dune_width_m)**2``
  for ``|s + dune_distance_m| < dune_width_m / 2`` (zero outside), crest ``dune_distance_m``
  landward of the shoreline. It is required to stay on land, so ``z = shoreline_z_m`` exactly on
  the shoreline.

The kink at the berm edge has a one-sided gradient (that of the foreshore).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from terrain._validate import check_number
from terrain.surface import UNBOUNDED, Bounds, Surface

__all__ = ["Beach"]


@dataclass(frozen=True)
class Beach(Surface):
    """Plane beach crossing the waterline along a straight shoreline, with berm and dune.

    Parameters
    ----------
    x_m, y_m : float
        A point on the shoreline, local metres.
    seaward_azimuth_rad : float
        Direction toward the sea (downslope), clockwise from north, radians; the shoreline runs
        perpendicular to it.
    beach_gradient : float
        Beach slope ``tan(angle)``, > 0 (typically 0.01-0.1).
    shoreline_z_m : float
        Height of the waterline (the water level the shoreline refers to), metres.
    berm_height_m : float
        Height of the flat berm above the waterline, metres (> 0); ``inf`` for none.
    dune_height_m : float
        Dune crest height above the berm/foreshore, metres (>= 0; 0 for no dune).
    dune_distance_m : float
        Distance of the dune crest landward of the shoreline, metres.
    dune_width_m : float
        Base width of the dune, metres (> 0, at most ``2 * dune_distance_m``).
    """

    x_m: float
    y_m: float
    seaward_azimuth_rad: float
    beach_gradient: float
    shoreline_z_m: float = 0.0
    berm_height_m: float = 2.0
    dune_height_m: float = 0.0
    dune_distance_m: float = 60.0
    dune_width_m: float = 30.0

    def __post_init__(self) -> None:
        for name in ("x_m", "y_m", "seaward_azimuth_rad", "shoreline_z_m"):
            object.__setattr__(self, name, check_number(name, getattr(self, name)))
        gradient = check_number("beach_gradient", self.beach_gradient, gt=0.0)
        object.__setattr__(self, "beach_gradient", gradient)
        berm = check_number("berm_height_m", self.berm_height_m, gt=0.0, allow_inf=True)
        object.__setattr__(self, "berm_height_m", berm)
        dune = check_number("dune_height_m", self.dune_height_m, ge=0.0)
        object.__setattr__(self, "dune_height_m", dune)
        dist = check_number("dune_distance_m", self.dune_distance_m, gt=0.0)
        object.__setattr__(self, "dune_distance_m", dist)
        width = check_number("dune_width_m", self.dune_width_m, gt=0.0, le=2.0 * dist)
        object.__setattr__(self, "dune_width_m", width)

    @property
    def bounds(self) -> Bounds:
        """Unbounded."""
        return UNBOUNDED

    def seaward_distance_m(self, x_m, y_m) -> np.ndarray:
        """Signed distance seaward of the shoreline (negative on land), metres."""
        a = self.seaward_azimuth_rad
        x = np.asarray(x_m, dtype=np.float64)
        y = np.asarray(y_m, dtype=np.float64)
        return (x - self.x_m) * math.sin(a) + (y - self.y_m) * math.cos(a)

    def _profile(self, s: np.ndarray):
        """Height above the waterline and its derivative d z / d s."""
        rise = -self.beach_gradient * s
        on_berm = rise > self.berm_height_m
        z = np.where(on_berm, self.berm_height_m, rise)
        dz = np.where(on_berm, 0.0, -self.beach_gradient)
        if self.dune_height_m > 0.0:
            phi = math.pi * (s + self.dune_distance_m) / self.dune_width_m
            in_dune = np.abs(phi) < math.pi / 2
            z = z + np.where(in_dune, self.dune_height_m * np.cos(phi) ** 2, 0.0)
            slope = -self.dune_height_m * np.sin(2.0 * phi) * math.pi / self.dune_width_m
            dz = dz + np.where(in_dune, slope, 0.0)
        return z, dz

    def _height(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        return self.shoreline_z_m + self._profile(self.seaward_distance_m(x, y))[0]

    def _gradient(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        _, dz = self._profile(self.seaward_distance_m(x, y))
        a = self.seaward_azimuth_rad
        return dz * math.sin(a), dz * math.cos(a)
