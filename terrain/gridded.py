"""A height field given on a regular grid, with a cubic B-spline interpolant as the truth.

Spectral fields (rough seabed, waves) and DEMs are stored as node values. The truth between the
nodes *is* the interpolating cubic B-spline of those values (C2, passes through every node), so
``height_m`` and ``gradient`` are exact for it everywhere, and a mesh built from it agrees with it
at the vertices exactly.

* ``periodic=True``: periodic spline (``scipy.ndimage.spline_filter`` with ``mode='grid-wrap'``);
  the field repeats with periods ``nx * dx_m`` and ``ny * dy_m`` and can be queried anywhere.
* ``periodic=False``: the node values are extended past the edges by odd reflection (which keeps a
  linear trend) before prefiltering, giving a natural-spline-like edge (zero curvature at the
  boundary); a plane is reproduced to ~1e-9 of its rise across one cell. Queries outside
  ``bounds`` raise :class:`ValueError`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.fft
from scipy import ndimage

from terrain._validate import check_bounds, check_finite, check_number, check_points
from terrain.surface import Bounds, Surface

__all__ = ["GridSurface", "periodic_grid"]

_PAD = 16  # odd-reflection pad (cells) for non-periodic grids: edge influence 0.268**16 ~ 7e-10
_CHUNK = 1 << 20  # points evaluated per chunk, bounds temporary memory to ~ 0.3 GB


def periodic_grid(extent, spacing_m: float) -> tuple[tuple[float, ...], int, int, float, float]:
    """Size an FFT grid that exactly tiles one period ``extent`` with spacing <= ``spacing_m``.

    Parameters
    ----------
    extent : tuple of 4 float
        ``(xmin, xmax, ymin, ymax)`` of the period, metres.
    spacing_m : float
        Largest node spacing, metres (> 0).

    Returns
    -------
    extent, nx, ny, dx, dy
        The checked extent, FFT-friendly node counts (8..8192) and the actual spacings
        ``(xmax - xmin) / nx`` and ``(ymax - ymin) / ny``.
    """
    b = check_bounds("extent", extent)
    sp = check_number("spacing_m", spacing_m, gt=0.0)
    nx = scipy.fft.next_fast_len(math.ceil((b[1] - b[0]) / sp * (1 - 1e-12)))
    ny = scipy.fft.next_fast_len(math.ceil((b[3] - b[2]) / sp * (1 - 1e-12)))
    if max(nx, ny) > 8192 or min(nx, ny) < 8:
        raise ValueError(
            f"`spacing_m` = {spacing_m!r} gives a {ny} x {nx} grid over {b}; need 8..8192 nodes"
        )
    return b, nx, ny, (b[1] - b[0]) / nx, (b[3] - b[2]) / ny


def _weights(t: np.ndarray) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """Cubic B-spline weights and their derivatives for offsets -1, 0, 1, 2 at fraction t."""
    t2 = t * t
    t3 = t2 * t
    s = 1.0 - t
    w = [
        s * s * s / 6.0,
        (3 * t3 - 6 * t2 + 4) / 6.0,
        (-3 * t3 + 3 * t2 + 3 * t + 1) / 6.0,
        t3 / 6.0,
    ]
    dw = [-0.5 * s * s, 0.5 * (3 * t2 - 4 * t), 0.5 * (-3 * t2 + 2 * t + 1), 0.5 * t2]
    return w, dw


@dataclass(frozen=True, eq=False)
class GridSurface(Surface):
    """Height field from node values ``z_m[j, i]`` at ``(x0_m + i dx_m, y0_m + j dy_m)``.

    Parameters
    ----------
    x0_m, y0_m : float
        Local coordinates of node ``[0, 0]`` in metres.
    dx_m, dy_m : float
        Node spacing in metres (> 0).
    z_m : array_like, shape (ny, nx)
        Heights in metres (positive up), rows along y, finite; at least 2 x 2 (4 x 4 if periodic).
        Stored as a read-only float64 copy.
    periodic : bool
        Treat the grid as one period of a periodic field.
    """

    x0_m: float
    y0_m: float
    dx_m: float
    dy_m: float
    z_m: np.ndarray
    periodic: bool = False

    def __post_init__(self) -> None:
        for name in ("x0_m", "y0_m"):
            object.__setattr__(self, name, check_number(name, getattr(self, name)))
        for name in ("dx_m", "dy_m"):
            object.__setattr__(self, name, check_number(name, getattr(self, name), gt=0.0))
        z = np.array(check_finite("z_m", self.z_m), dtype=np.float64, copy=True)
        min_n = 4 if self.periodic else 2
        if z.ndim != 2 or min(z.shape) < min_n:
            raise ValueError(f"`z_m` must be a 2-D array at least {min_n} x {min_n}; got {z.shape}")
        z.flags.writeable = False
        object.__setattr__(self, "z_m", z)
        if self.periodic:
            coef = ndimage.spline_filter(z, order=3, mode="grid-wrap")
            coef = np.pad(coef, ((1, 2), (1, 2)), mode="wrap")
        else:
            padded = np.pad(z, _PAD, mode="reflect", reflect_type="odd")
            coef = ndimage.spline_filter(padded, order=3, mode="mirror")
        object.__setattr__(self, "_coef", np.ascontiguousarray(coef))

    @property
    def shape(self) -> tuple[int, int]:
        """``(ny, nx)`` number of nodes."""
        return self.z_m.shape

    @property
    def x_nodes_m(self) -> np.ndarray:
        """Node x coordinates, shape (nx,), metres."""
        return self.x0_m + self.dx_m * np.arange(self.shape[1])

    @property
    def y_nodes_m(self) -> np.ndarray:
        """Node y coordinates, shape (ny,), metres."""
        return self.y0_m + self.dy_m * np.arange(self.shape[0])

    @property
    def bounds(self) -> Bounds:
        """One period ``[x0, x0 + nx dx]`` if periodic, else the node extent."""
        ny, nx = self.shape
        ex = nx if self.periodic else nx - 1
        ey = ny if self.periodic else ny - 1
        return (self.x0_m, self.x0_m + ex * self.dx_m, self.y0_m, self.y0_m + ey * self.dy_m)

    def _index(self, name: str, v: np.ndarray, v0: float, d: float, n: int):
        """Index into the padded coefficients of the offset -1 neighbour, and the fraction."""
        u = (v - v0) / d
        if self.periodic:
            i = np.floor(u)
            return i.astype(np.int64) % n, u - i
        tol = 1e-9
        if u.size and (u.min() < -tol or u.max() > n - 1 + tol):
            bad = v.ravel()[np.argmax((u.ravel() < -tol) | (u.ravel() > n - 1 + tol))]
            raise ValueError(
                f"`{name}` must lie within [{v0!r}, {v0 + (n - 1) * d!r}] of the grid; "
                f"got {float(bad)!r}"
            )
        u = np.clip(u, 0.0, n - 1.0)
        i = np.minimum(np.floor(u), n - 2.0)
        return i.astype(np.int64) + (_PAD - 1), u - i

    def _eval(self, x: np.ndarray, y: np.ndarray, deriv: bool):
        ny, nx = self.shape
        coef = self._coef
        ncol = coef.shape[1]
        flat = coef.ravel()
        xs, ys = x.ravel(), y.ravel()
        z = np.empty(xs.shape)
        gx = np.empty(xs.shape) if deriv else None
        gy = np.empty(xs.shape) if deriv else None
        for start in range(0, xs.size, _CHUNK):
            sl = slice(start, start + _CHUNK)
            ix, tx = self._index("x_m", xs[sl], self.x0_m, self.dx_m, nx)
            iy, ty = self._index("y_m", ys[sl], self.y0_m, self.dy_m, ny)
            wx, dwx = _weights(tx)
            wy, dwy = _weights(ty)
            base = iy * ncol + ix
            zz = np.zeros(tx.shape)
            if deriv:
                zx, zy = np.zeros(tx.shape), np.zeros(tx.shape)
            for a in range(4):
                vals = [flat[base + (a * ncol + b)] for b in range(4)]
                r = wx[0] * vals[0] + wx[1] * vals[1] + wx[2] * vals[2] + wx[3] * vals[3]
                zz += wy[a] * r
                if deriv:
                    dr = dwx[0] * vals[0] + dwx[1] * vals[1] + dwx[2] * vals[2] + dwx[3] * vals[3]
                    zx += wy[a] * dr
                    zy += dwy[a] * r
            z[sl] = zz
            if deriv:
                gx[sl] = zx / self.dx_m
                gy[sl] = zy / self.dy_m
        if deriv:
            return z.reshape(x.shape), gx.reshape(x.shape), gy.reshape(x.shape)
        return z.reshape(x.shape)

    def _height(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        return self._eval(x, y, deriv=False)

    def _gradient(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        _, gx, gy = self._eval(x, y, deriv=True)
        return gx, gy

    def height_and_gradient(self, x_m: Any, y_m: Any) -> tuple[np.ndarray, ...]:
        """Height (m) and gradient ``(dz/dx, dz/dy)`` in one pass, each of the broadcast shape."""
        x, y = check_points(x_m, y_m)
        return self._eval(x, y, deriv=True)
