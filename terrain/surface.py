"""Height fields z = f(x, y) in local coordinates: the truth of the simulated world.

Conventions
-----------
* Local coordinates in metres, float64, relative to a :class:`~terrain.frame.LocalFrame` origin:
  x east, y north, z up. Depth (positive down) is always named ``depth_m``.
* Azimuths are clockwise from north (+y), in radians: azimuth ``a`` points along
  ``(sin a, cos a)`` in (x, y).
* ``bounds`` is ``(xmin, xmax, ymin, ymax)``; analytic surfaces may be unbounded (+-inf).
* :meth:`Surface.height_m` is the exact truth at any point; a mesh from :meth:`Surface.to_mesh`
  samples it on a regular grid, so mesh and truth agree at the vertices exactly and in between to
  within the piecewise-linear discretisation error.

Surfaces add: ``plane + roughness + feature`` is a :class:`CompositeSurface` whose height and
gradient are the sums of the parts and whose bounds are the intersection of theirs.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import Any

import numpy as np
import trimesh

from terrain._validate import check_bounds, check_number, check_points

__all__ = ["Bounds", "Surface", "Plane", "CompositeSurface", "UNBOUNDED", "grid_axis", "grid_faces"]

Bounds = tuple[float, float, float, float]
UNBOUNDED: Bounds = (-math.inf, math.inf, -math.inf, math.inf)

#: Default limit on the number of triangles :meth:`Surface.to_mesh` builds (about 0.5 GB).
MAX_FACES = 20_000_000


def grid_faces(nx: int, ny: int) -> np.ndarray:
    """Triangles of a row-major ``(ny, nx)`` node grid, two per cell, ``(2 (nx-1)(ny-1), 3)``.

    Every cell's lower-left to upper-right diagonal splits it; all first triangles come
    before all second ones, wound counter-clockwise seen from above (normals up). A window
    of a grid triangulated alone gives the same triangles as the whole grid does over it.
    """
    idx = np.arange(nx * ny, dtype=np.int64).reshape(ny, nx)
    v00, v10 = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel()
    v01, v11 = idx[1:, :-1].ravel(), idx[1:, 1:].ravel()
    return np.concatenate(
        [np.column_stack([v00, v10, v11]), np.column_stack([v00, v11, v01])], axis=0
    )


def grid_axis(lo: float, hi: float, resolution_m: float) -> np.ndarray:
    """Evenly spaced nodes covering ``[lo, hi]`` with spacing at most ``resolution_m``.

    Parameters
    ----------
    lo, hi : float
        Interval ends in metres, ``lo < hi``, both finite.
    resolution_m : float
        Largest allowed spacing in metres.

    Returns
    -------
    numpy.ndarray, shape (n,)
        ``n = ceil((hi - lo) / resolution_m) + 1`` nodes; the first is ``lo`` and the last ``hi``.
    """
    return np.linspace(lo, hi, _n_cells(lo, hi, resolution_m) + 1)


def _n_cells(lo: float, hi: float, resolution_m: float) -> int:
    return max(1, math.ceil((hi - lo) / resolution_m * (1.0 - 1e-12)))


class Surface(ABC):
    """A single-valued height field z = f(x, y) in local coordinates (metres, z up).

    Subclasses implement :attr:`bounds`, ``_height(x, y)`` and ``_gradient(x, y)`` on finite
    float64 arrays of one common shape; the public methods validate and broadcast the input.
    """

    @property
    @abstractmethod
    def bounds(self) -> Bounds:
        """``(xmin, xmax, ymin, ymax)`` in local metres where the surface is defined."""

    @abstractmethod
    def _height(self, x: np.ndarray, y: np.ndarray) -> np.ndarray: ...

    @abstractmethod
    def _gradient(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]: ...

    def height_m(self, x_m: Any, y_m: Any) -> np.ndarray:
        """Height of the surface, positive up, in metres.

        Parameters
        ----------
        x_m, y_m : array_like
            Local easting and northing in metres; any broadcastable shapes.

        Returns
        -------
        numpy.ndarray
            float64 heights with the broadcast shape of the inputs.
        """
        x, y = check_points(x_m, y_m)
        return self._height(x, y)

    def gradient(self, x_m: Any, y_m: Any) -> tuple[np.ndarray, np.ndarray]:
        """Slope components ``(dz/dx, dz/dy)`` (dimensionless), each of the broadcast shape.

        At a step (a box wall) the gradient is that of either side; see the subclass.
        """
        x, y = check_points(x_m, y_m)
        return self._gradient(x, y)

    def normal(self, x_m: Any, y_m: Any) -> np.ndarray:
        """Unit upward normal ``(-dz/dx, -dz/dy, 1) / norm``.

        Returns
        -------
        numpy.ndarray, shape (..., 3)
            float64 unit vectors with positive z component; ``...`` is the broadcast shape.
        """
        gx, gy = self.gradient(x_m, y_m)
        n = np.stack([-gx, -gy, np.ones_like(gx)], axis=-1)
        return n / np.linalg.norm(n, axis=-1, keepdims=True)

    def _mesh_bounds(self, bounds: Any) -> Bounds:
        b = self.bounds if bounds is None else check_bounds("bounds", bounds)
        if not all(math.isfinite(v) for v in b):
            raise ValueError(
                f"`bounds` must be finite to build a grid; got {b!r} (pass bounds= explicitly)"
            )
        return b

    def sample_grid(
        self, resolution_m: float, bounds: Any = None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Sample the truth on a regular grid covering ``bounds``.

        Parameters
        ----------
        resolution_m : float
            Largest node spacing in metres (> 0); the spacing is shrunk to fit the bounds.
        bounds : tuple of 4 float, optional
            ``(xmin, xmax, ymin, ymax)``; defaults to :attr:`bounds` (must then be finite).

        Returns
        -------
        x : numpy.ndarray, shape (nx,)
        y : numpy.ndarray, shape (ny,)
        z : numpy.ndarray, shape (ny, nx)
            ``z[j, i]`` is the height at ``(x[i], y[j])``.
        """
        res = check_number("resolution_m", resolution_m, gt=0.0)
        xmin, xmax, ymin, ymax = self._mesh_bounds(bounds)
        if _n_cells(xmin, xmax, res) * _n_cells(ymin, ymax, res) > MAX_FACES:
            raise ValueError(f"`resolution_m` = {resolution_m!r} gives more than {MAX_FACES} nodes")
        x = grid_axis(xmin, xmax, res)
        y = grid_axis(ymin, ymax, res)
        xx, yy = np.meshgrid(x, y)
        return x, y, self._height(xx, yy)

    def to_mesh(
        self, resolution_m: float, bounds: Any = None, *, max_faces: int = MAX_FACES
    ) -> trimesh.Trimesh:
        """Triangulate the surface on a regular grid, two triangles per cell.

        Vertices are float64 ``(x, y, height_m(x, y))`` in local metres, so they lie on the
        truth exactly; faces wind counter-clockwise seen from above (normals point up). Cast to
        float32 only after the local origin is subtracted (it already is here).

        Parameters
        ----------
        resolution_m : float
            Largest grid spacing in metres (> 0).
        bounds : tuple of 4 float, optional
            Region to mesh; defaults to :attr:`bounds`.
        max_faces : int
            Refuse to build more triangles than this (memory guard).

        Returns
        -------
        trimesh.Trimesh
            ``nx * ny`` vertices and ``2 (nx - 1)(ny - 1)`` faces, built with ``process=False``
            so vertex order is the row-major grid order (index ``j * nx + i``).
        """
        res = check_number("resolution_m", resolution_m, gt=0.0)
        xmin, xmax, ymin, ymax = self._mesh_bounds(bounds)
        n_faces = 2 * _n_cells(xmin, xmax, res) * _n_cells(ymin, ymax, res)
        if n_faces > max_faces:
            raise ValueError(
                f"`resolution_m` = {resolution_m!r} gives {n_faces} triangles, more than "
                f"max_faces = {max_faces}; coarsen it or raise max_faces"
            )
        x, y = grid_axis(xmin, xmax, res), grid_axis(ymin, ymax, res)
        nx, ny = x.size, y.size
        xx, yy = np.meshgrid(x, y)
        z = self._height(xx, yy)
        vertices = np.column_stack([xx.ravel(), yy.ravel(), z.ravel()])
        faces = grid_faces(nx, ny)
        return trimesh.Trimesh(vertices=vertices, faces=faces, process=False, validate=False)

    def __add__(self, other: Surface) -> CompositeSurface:
        if not isinstance(other, Surface):
            return NotImplemented
        return CompositeSurface((self, other))


@dataclass(frozen=True)
class Plane(Surface):
    """The plane ``z = z0_m + dz_dx * x + dz_dy * y``.

    Parameters
    ----------
    z0_m : float
        Height at the local origin in metres (positive up).
    dz_dx, dz_dy : float
        Gradient components (dimensionless, metres per metre).
    extent : tuple of 4 float
        ``bounds`` of the plane; unbounded by default.
    """

    z0_m: float
    dz_dx: float = 0.0
    dz_dy: float = 0.0
    extent: Bounds = UNBOUNDED

    def __post_init__(self) -> None:
        object.__setattr__(self, "z0_m", check_number("z0_m", self.z0_m))
        object.__setattr__(self, "dz_dx", check_number("dz_dx", self.dz_dx))
        object.__setattr__(self, "dz_dy", check_number("dz_dy", self.dz_dy))
        object.__setattr__(self, "extent", check_bounds("extent", self.extent, allow_inf=True))

    @property
    def bounds(self) -> Bounds:
        """``(xmin, xmax, ymin, ymax)`` given as ``extent``."""
        return self.extent

    @property
    def gradient_magnitude(self) -> float:
        """Steepest gradient ``tan(slope)``, dimensionless."""
        return math.hypot(self.dz_dx, self.dz_dy)

    @property
    def slope_rad(self) -> float:
        """Angle of steepest descent below the horizontal, radians."""
        return math.atan(self.gradient_magnitude)

    @property
    def downslope_azimuth_rad(self) -> float:
        """Azimuth of steepest descent, clockwise from north (+y), in [0, 2 pi); 0 if flat."""
        if self.gradient_magnitude == 0.0:
            return 0.0
        return math.atan2(-self.dz_dx, -self.dz_dy) % (2.0 * math.pi)

    def _height(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        return self.z0_m + self.dz_dx * x + self.dz_dy * y

    def _gradient(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return np.full(x.shape, self.dz_dx), np.full(x.shape, self.dz_dy)


@dataclass(frozen=True)
class CompositeSurface(Surface):
    """Sum of surfaces: height and gradient add; bounds are the intersection.

    Parameters
    ----------
    parts : tuple of Surface
        At least one surface; nested composites are flattened.
    """

    parts: tuple[Surface, ...]

    def __post_init__(self) -> None:
        flat: list[Surface] = []
        for p in tuple(self.parts):
            if not isinstance(p, Surface):
                raise ValueError(f"`parts` must hold Surface objects; got {p!r}")
            flat.extend(p.parts if isinstance(p, CompositeSurface) else (p,))
        if not flat:
            raise ValueError("`parts` must hold at least one Surface; got ()")
        object.__setattr__(self, "parts", tuple(flat))
        b = self.bounds
        if not (b[0] < b[1] and b[2] < b[3]):
            raise ValueError(f"`parts` have bounds that do not overlap; intersection is {b!r}")

    @property
    def bounds(self) -> Bounds:
        """Intersection of the parts' bounds."""
        bs = np.array([p.bounds for p in self.parts], dtype=np.float64)
        return (
            float(bs[:, 0].max()),
            float(bs[:, 1].min()),
            float(bs[:, 2].max()),
            float(bs[:, 3].min()),
        )

    def _height(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        z = self.parts[0]._height(x, y)
        for p in self.parts[1:]:
            z = z + p._height(x, y)
        return z

    def _gradient(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        gx, gy = self.parts[0]._gradient(x, y)
        for p in self.parts[1:]:
            px, py = p._gradient(x, y)
            gx, gy = gx + px, gy + py
        return gx, gy
