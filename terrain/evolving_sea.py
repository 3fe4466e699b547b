"""A wind sea that evolves in time: the wave field at any instant, bounded in memory.

:class:`~terrain.water.WaveField` gives the exact Fourier field frozen at any time (one inverse
FFT). Evaluating it at every pulse's time would cost an FFT per pulse, so the time axis is cut
into slabs of ``slab_s`` seconds: the field is synthesised on the grid at the slab boundaries
``t_j = j slab_s`` and the surface at ``t`` in ``[t_j, t_j+1]`` is the linear interpolation in
time of the two boundary surfaces (each the periodic cubic spline of its node values, as for the
frozen sea). That interpolated surface *is* the truth: the tracer and the evaluation read the
same function, so they agree exactly.

Slab length (documented criterion): linear interpolation in time errs by at most
``slab**2 / 8 max|eta_tt|``; with ``max|eta_tt| ~ 3 sigma_tt`` (``sigma_tt`` the field's rms
vertical acceleration, :attr:`WaveField.acceleration_rms_m_s2`) the slab is
``sqrt(8 tol / (3 sigma_tt))`` for a height tolerance ``tol``, clipped to [0.005, 1] s
(e.g. 0.07 s for tol = 2 mm in a 5 m/s sea). Only the last few boundary surfaces are cached, so
memory is a few grids whatever the survey length; callers that go through time in order (the
chunked tracer) synthesise each boundary once.
"""

from __future__ import annotations

import math
from collections import OrderedDict
from typing import Any

import numpy as np

from terrain._validate import check_number, check_points
from terrain.gridded import GridSurface
from terrain.water import WaveField

__all__ = ["EvolvingSea", "slab_for_tolerance_s"]

#: Memory for cached boundary surfaces (node values and spline coefficients), bytes: at least
#: two (one slab), more when small so that a chunk's second pass (the returns) reuses them.
CACHE_BYTES = 256 * 2**20


def slab_for_tolerance_s(acceleration_rms_m_s2: float, tolerance_m: float) -> float:
    """Slab length (s) whose linear-in-time interpolation errs by at most ``tolerance_m``.

    ``sqrt(8 tol / (3 sigma_tt))``, clipped to [0.005, 1] s (module doc).
    """
    a = check_number("acceleration_rms_m_s2", acceleration_rms_m_s2, ge=0.0)
    tol = check_number("tolerance_m", tolerance_m, gt=0.0)
    if a == 0.0:
        return 1.0
    return float(min(max(math.sqrt(8.0 * tol / (3.0 * a)), 0.005), 1.0))


class EvolvingSea:
    """A :class:`WaveField` evaluated at any time, by slabs of linear interpolation.

    Parameters
    ----------
    field : WaveField
    slab_s : float
        Slab length, seconds (:func:`slab_for_tolerance_s`).
    evolving : bool
        False freezes the sea at t = 0 for every time (the surface of ``field.at_time(0)``).
    """

    def __init__(self, field: WaveField, slab_s: float, evolving: bool = True) -> None:
        self.field = field
        self.slab_s = check_number("slab_s", slab_s, gt=0.0)
        self.evolving = bool(evolving)
        self.mean_level_m = field.mean_level_m
        self._cache: OrderedDict[int, GridSurface] = OrderedDict()
        ny, nx = field.shape
        self._cache_size = max(2, CACHE_BYTES // (2 * 8 * (ny + 4) * (nx + 4)))
        x0, x1, y0, y1 = field.extent
        self.period_m = (x1 - x0, y1 - y0)
        # |eta - level| never exceeds the sum of the mode amplitudes (the spline overshoots a
        # little: 25 % margin); the caster brackets its roots with it
        amp = np.abs(field._h_plus) + np.abs(field._h_minus)
        self.height_bound_m = 1.25 * float(np.sum(amp * field._weight)) + 1e-3

    def surface_at_boundary(self, j: int) -> GridSurface:
        """The surface at ``t = j slab_s`` (cached)."""
        if j in self._cache:
            self._cache.move_to_end(j)
            return self._cache[j]
        s = self.field.at_time(j * self.slab_s)
        self._cache[j] = s
        while len(self._cache) > self._cache_size:
            self._cache.popitem(last=False)
        return s

    def at_time(self, t_s: float = 0.0) -> GridSurface:
        """The exact frozen Fourier field at ``t_s`` (not slab-interpolated)."""
        return self.field.at_time(t_s if self.evolving else 0.0)

    def slabs(self, t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Slab index ``j`` and interpolation weight ``a`` in [0, 1) of each time."""
        if not self.evolving:
            return np.zeros(t_s.shape, dtype=np.int64), np.zeros(t_s.shape)
        u = t_s / self.slab_s
        j = np.floor(u)
        return j.astype(np.int64), u - j

    def height_and_gradient(self, x_m: Any, y_m: Any, t_s: Any) -> tuple[np.ndarray, ...]:
        """Height (m) and gradient of the surface at points ``(x, y)`` and times ``t_s``.

        Parameters
        ----------
        x_m, y_m, t_s : array_like
            Broadcastable to one shape ``(n,)``.

        Returns
        -------
        z, dz_dx, dz_dy : (n,) float64
        """
        x, y = check_points(x_m, y_m)
        t = np.broadcast_to(np.asarray(t_s, dtype=np.float64), x.shape).ravel()
        x, y = x.ravel(), y.ravel()
        if not np.all(np.isfinite(t)):
            raise ValueError("`t_s` must be finite")
        out = np.empty((3, x.size))
        j, a = self.slabs(t)
        order = np.argsort(j, kind="stable")
        bounds = np.flatnonzero(np.diff(j[order])) + 1
        for idx in np.split(order, bounds):  # one group per slab: a loop over slabs, not rays
            if idx.size == 0:
                continue
            jj = int(j[idx[0]])
            lo = np.asarray(self.surface_at_boundary(jj).height_and_gradient(x[idx], y[idx]))
            w = a[idx]
            if self.evolving and np.any(w > 0.0):
                hi = np.asarray(
                    self.surface_at_boundary(jj + 1).height_and_gradient(x[idx], y[idx])
                )
                lo = lo + w * (hi - lo)
            out[:, idx] = lo
        return out[0], out[1], out[2]

    def height_m(self, x_m: Any, y_m: Any, t_s: Any = 0.0) -> np.ndarray:
        """Surface height (local z, m) at ``(x, y)`` and times ``t_s`` (broadcast)."""
        x, y = check_points(x_m, y_m)
        z = self.height_and_gradient(x, y, t_s)[0]
        return z.reshape(x.shape)
