"""Discrete seabed features, added to a base: boxes (IHO S-44 cubes, wrecks), ridges, channels.

Every feature is a :class:`~terrain.surface.Surface` whose height is the *added* height (zero away
from the feature), to be summed with a base by :func:`terrain.seabed.compose`. On a sloping base a
box therefore follows the slope (its top is parallel to the seabed, ``box_height_m`` above it).

Boxes have vertical walls: the truth is a step, ``height_m`` is ``box_height_m`` on the closed
footprint (walls included) and the gradient is 0 everywhere (the walls have no defined gradient).
A regular-grid mesh turns each wall into a one-cell ramp; mesh finer than the feature.

Headings and azimuths are clockwise from north (+y), radians.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from terrain._validate import check_choice, check_number
from terrain.surface import UNBOUNDED, Bounds, Surface

__all__ = ["Box", "Ridge", "cube", "wreck", "ridge", "channel", "IHO_CUBE_SIDES_M"]

#: Cube sides (m) of the IHO S-44 (6th ed.) feature detection criteria: 2 m (Order 1a/1b),
#: 1 m (Special Order), 0.5 m (Exclusive Order).
IHO_CUBE_SIDES_M = (0.5, 1.0, 2.0)


def _along_across(x, y, x0, y0, azimuth):
    """Coordinates along the azimuth and across it (positive to the right/starboard)."""
    dx, dy = x - x0, y - y0
    s, c = math.sin(azimuth), math.cos(azimuth)
    return dx * s + dy * c, dx * c - dy * s


@dataclass(frozen=True)
class Box(Surface):
    """A rectangular block standing on the seabed (added height).

    Parameters
    ----------
    x_m, y_m : float
        Local coordinates of the footprint centre, metres.
    length_m, width_m : float
        Footprint size along and across the heading, metres (> 0).
    box_height_m : float
        Height above the seabed, metres (> 0).
    heading_rad : float
        Azimuth of the length axis, clockwise from north, radians.
    """

    x_m: float
    y_m: float
    length_m: float
    width_m: float
    box_height_m: float
    heading_rad: float = 0.0

    def __post_init__(self) -> None:
        for name in ("x_m", "y_m", "heading_rad"):
            object.__setattr__(self, name, check_number(name, getattr(self, name)))
        for name in ("length_m", "width_m", "box_height_m"):
            object.__setattr__(self, name, check_number(name, getattr(self, name), gt=0.0))

    @property
    def bounds(self) -> Bounds:
        """Unbounded: the added height is zero away from the box."""
        return UNBOUNDED

    @property
    def footprint_m(self) -> np.ndarray:
        """Footprint corners, shape (4, 2), local metres, counter-clockwise seen from above."""
        u = np.array([1, 1, -1, -1]) * self.length_m / 2
        v = np.array([1, -1, -1, 1]) * self.width_m / 2
        s, c = math.sin(self.heading_rad), math.cos(self.heading_rad)
        return np.column_stack([self.x_m + u * s + v * c, self.y_m + u * c - v * s])

    def _height(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        u, v = _along_across(x, y, self.x_m, self.y_m, self.heading_rad)
        inside = (np.abs(u) <= self.length_m / 2) & (np.abs(v) <= self.width_m / 2)
        return np.where(inside, self.box_height_m, 0.0)

    def _gradient(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return np.zeros(x.shape), np.zeros(x.shape)


def cube(x_m: float, y_m: float, side_m: float, heading_rad: float = 0.0) -> Box:
    """A cube of side ``side_m`` (e.g. one of :data:`IHO_CUBE_SIDES_M`) standing on the seabed."""
    side = check_number("side_m", side_m, gt=0.0)
    return Box(x_m, y_m, side, side, side, heading_rad)


def wreck(
    x_m: float,
    y_m: float,
    length_m: float,
    width_m: float,
    height_m: float,
    heading_rad: float = 0.0,
) -> Box:
    """A wreck-like box: ``length_m`` along ``heading_rad``, ``width_m`` beam, ``height_m`` tall."""
    return Box(x_m, y_m, length_m, width_m, check_number("height_m", height_m, gt=0.0), heading_rad)


@dataclass(frozen=True)
class Ridge(Surface):
    """A linear bump (``amplitude_m > 0``) or trough (``< 0``) along a line or segment.

    The added height is ``amplitude_m * p(d)`` where ``d`` is the distance from the axis (from the
    segment if ``length_m`` is finite, giving rounded ends) and ``p`` the cross-section:

    * ``"gaussian"``: ``p = exp(-4 ln2 d**2 / w**2)``;
    * ``"triangular"``: ``p = max(0, 1 - |d| / w)`` (base width ``2 w``),

    with ``w = width_m`` the full width at half maximum in both cases.

    Parameters
    ----------
    x_m, y_m : float
        A point on the axis (the segment centre), local metres.
    azimuth_rad : float
        Direction of the axis, clockwise from north, radians.
    amplitude_m : float
        Crest height (> 0) or minus the channel depth (< 0), metres; nonzero.
    width_m : float
        Full width at half maximum of the cross-section, metres (> 0).
    profile : {"gaussian", "triangular"}
    length_m : float
        Segment length in metres (> 0); ``inf`` for an infinite line.
    """

    x_m: float
    y_m: float
    azimuth_rad: float
    amplitude_m: float
    width_m: float
    profile: str = "gaussian"
    length_m: float = math.inf

    def __post_init__(self) -> None:
        for name in ("x_m", "y_m", "azimuth_rad", "amplitude_m"):
            object.__setattr__(self, name, check_number(name, getattr(self, name)))
        if self.amplitude_m == 0.0:
            raise ValueError("`amplitude_m` must be nonzero; got 0.0")
        object.__setattr__(self, "width_m", check_number("width_m", self.width_m, gt=0.0))
        object.__setattr__(
            self, "length_m", check_number("length_m", self.length_m, gt=0.0, allow_inf=True)
        )
        check_choice("profile", self.profile, ("gaussian", "triangular"))

    @property
    def bounds(self) -> Bounds:
        """Unbounded: the added height decays to zero away from the axis."""
        return UNBOUNDED

    def _distance(self, x: np.ndarray, y: np.ndarray):
        """Distance from the axis and its gradient (d dist / dx, d dist / dy)."""
        u, v = _along_across(x, y, self.x_m, self.y_m, self.azimuth_rad)
        s, c = math.sin(self.azimuth_rad), math.cos(self.azimuth_rad)
        if math.isinf(self.length_m):
            du = np.zeros(u.shape)
        else:  # along-axis overshoot past the nearer end
            du = np.sign(u) * np.maximum(np.abs(u) - self.length_m / 2, 0.0)
        d = np.hypot(du, v)
        safe = np.where(d > 0, d, 1.0)
        # gradient of d in (u, v), rotated back to (x, y): u = dx s + dy c, v = dx c - dy s
        gu, gv = du / safe, v / safe
        return d, gu * s + gv * c, gu * c - gv * s

    def _shape(self, d: np.ndarray):
        """Profile value and its derivative with respect to d."""
        w = self.width_m
        if self.profile == "gaussian":
            a = 4.0 * math.log(2.0) / w**2
            p = np.exp(-a * d * d)
            return p, -2.0 * a * d * p
        p = np.maximum(0.0, 1.0 - d / w)
        return p, np.where(d < w, -1.0 / w, 0.0)

    def _height(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        d, _, _ = self._distance(x, y)
        return self.amplitude_m * self._shape(d)[0]

    def _gradient(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        d, ddx, ddy = self._distance(x, y)
        dp = self.amplitude_m * self._shape(d)[1]
        return dp * ddx, dp * ddy


def ridge(
    x_m: float,
    y_m: float,
    azimuth_rad: float,
    height_m: float,
    width_m: float,
    *,
    profile: str = "gaussian",
    length_m: float = math.inf,
) -> Ridge:
    """A ridge of crest height ``height_m`` (> 0) and half-maximum width ``width_m``."""
    h = check_number("height_m", height_m, gt=0.0)
    return Ridge(x_m, y_m, azimuth_rad, h, width_m, profile, length_m)


def channel(
    x_m: float,
    y_m: float,
    azimuth_rad: float,
    depth_m: float,
    width_m: float,
    *,
    profile: str = "gaussian",
    length_m: float = math.inf,
) -> Ridge:
    """A channel cut ``depth_m`` (> 0, positive down) below the seabed, ``width_m`` FWHM wide."""
    d = check_number("depth_m", depth_m, gt=0.0)
    return Ridge(x_m, y_m, azimuth_rad, -d, width_m, profile, length_m)
