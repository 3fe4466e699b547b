"""A wind sea that evolves in time: the wave field at any instant, bounded in memory.

:class:`~terrain.water.WaveField` gives the exact Fourier field frozen at any time (one inverse
FFT). Evaluating it at every pulse's time would cost an FFT per pulse, so the time axis is cut
into slabs of ``slab_s`` seconds: the field and its exact time derivative ``eta_t`` are
synthesised on the grid at the slab boundaries ``t_j = j slab_s``, and the surface at
``t = t_j + a slab_s`` is their cubic Hermite interpolation in time,
``h00(a) eta_j + h01(a) eta_j+1 + slab (h10(a) eta_t,j + h11(a) eta_t,j+1)`` (each grid the
periodic cubic spline of its node values, as for the frozen sea). That interpolated surface *is*
the truth: the tracer and the evaluation read the same function, so they agree exactly.

Why Hermite, not linear: a linear blend of two surfaces is the sum of two partly decorrelated
fields, whose variance is lower between the boundaries: for a mode of phase advance
``phi = w slab`` the mid-slab amplitude is ``cos(phi / 2)``. Heights lose little (they live in the
slow waves), but slopes live in the fast short waves: at the 2 mm height slab the traced
mean-square slope was 2 % (7 m/s) to 23 % (1 m/s) low at mid-slab, which takes the glint at
20 deg off nadir 2-5 % low on average (it moves ~9 % per 1 % of slope variance at 3 m/s). The
Hermite mid-slab amplitude is ``cos(phi / 2) + (phi / 4) sin(phi / 2) = 1 - phi**4 / 384 + ...``
with the phase exact, and mid-slab is the worst point of the slab.

Slab length (documented criteria, :func:`slab_for_tolerances_s`): the shorter of

* heights: the Hermite error is at most ``slab**4 / 384 max|eta_tttt|``; with
  ``max|eta_tttt| ~ 3 sigma_4`` (``sigma_4 = sqrt(sum w**8 E)`` over the mode energies ``E``)
  the slab is ``(384 tol / (3 sigma_4))**(1/4)`` for a height tolerance ``tol``;
* slopes: the expected mean-square slope at mid-slab over the exact one,
  ``sum k**2 E (cos(phi / 2) + (phi / 4) sin(phi / 2))**2 / sum k**2 E``, at least
  ``1 - mss_tol``;

clipped to [0.005, 1] s. Only the last few boundaries are cached, so memory is a few grids
whatever the survey length; callers that go through time in order (the chunked tracer)
synthesise each boundary once.
"""

from __future__ import annotations

import math
from collections import OrderedDict
from typing import Any

import numpy as np

from terrain._validate import check_number, check_points
from terrain.gridded import GridSurface
from terrain.water import WaveField

__all__ = ["EvolvingSea", "mid_slab_mss_ratio", "slab_for_tolerances_s"]

#: Memory for cached boundary surfaces (node values and spline coefficients), bytes: at least
#: two (one slab), more when small so that a chunk's second pass (the returns) reuses them.
CACHE_BYTES = 256 * 2**20


#: Frequency bins of the slab search (:func:`_slope_weights_by_frequency`).
_OMEGA_BINS = 8192


def mid_slab_mss_ratio(energy_m2, k2_rad2_m2, omega_rad_s, slab_s: float) -> float:
    """Expected mean-square slope of the Hermite-interpolated sea at mid-slab over the exact one.

    Parameters
    ----------
    energy_m2, k2_rad2_m2, omega_rad_s : array_like, same shape
        Mode energies, squared wavenumbers and angular frequencies
        (:meth:`terrain.water.WaveField.mode_energies`).
    slab_s : float
    """
    w = np.asarray(k2_rad2_m2) * np.asarray(energy_m2)
    total = float(np.sum(w))
    if total <= 0.0:
        return 1.0
    phi = np.asarray(omega_rad_s) * slab_s
    amp = np.cos(0.5 * phi) + 0.25 * phi * np.sin(0.5 * phi)
    return float(np.sum(w * amp * amp)) / total


def _slope_weights_by_frequency(energy_m2, k2_rad2_m2, omega_rad_s):
    """The modes' slope weights ``k² E`` summed in ``_OMEGA_BINS`` bins of frequency.

    The mid-slab ratio depends on a mode only through its frequency and its slope weight, so
    the bins stand for the modes (each at its weighted mean frequency): 200 candidate slabs
    over a 4096² sea cost 200 passes over 8 M modes otherwise (~40 CPU-s). Within a bin the
    ratio's curvature times the frequencies' spread, ``(dω slab)² / 12 ~ 1e-5`` for
    ``dω = ω_max / 8192`` and a 1 s slab at ``ω_max ~ 100 rad/s``, is far below any tolerance.

    Returns
    -------
    weight, omega_rad_s : (_OMEGA_BINS,) float64
        Summed ``k² E`` per bin and its weighted mean frequency (0 in empty bins).
    """
    w = np.ravel(np.asarray(k2_rad2_m2) * np.asarray(energy_m2))
    om = np.ravel(np.broadcast_to(omega_rad_s, np.shape(energy_m2)))
    top = float(om.max()) if om.size else 0.0
    if top <= 0.0:
        return w, om
    b = np.minimum((om / top * _OMEGA_BINS).astype(np.int64), _OMEGA_BINS - 1)
    wb = np.bincount(b, weights=w, minlength=_OMEGA_BINS)
    ob = np.bincount(b, weights=w * om, minlength=_OMEGA_BINS)
    return wb, np.divide(ob, wb, out=np.zeros_like(ob), where=wb > 0)


def slab_for_tolerances_s(field: WaveField, tolerance_m: float, mss_tolerance: float) -> float:
    """Slab length (s) meeting both the height and the slope-variance tolerance (module doc).

    Parameters
    ----------
    field : WaveField
    tolerance_m : float
        Largest height error of the time interpolation, metres (> 0).
    mss_tolerance : float
        Largest relative loss of mean-square slope at mid-slab (in (0, 1)).

    Returns
    -------
    float
        ``min(slab_height, slab_slope)`` clipped to [0.005, 1] s.
    """
    tol = check_number("tolerance_m", tolerance_m, gt=0.0)
    mtol = check_number("mss_tolerance", mss_tolerance, gt=0.0, lt=1.0)
    energy, k2, omega = field.mode_energies()
    sigma_4 = math.sqrt(float(np.sum(omega**8 * energy)))
    slab = 1.0 if sigma_4 == 0.0 else (384.0 * tol / (3.0 * sigma_4)) ** 0.25
    # the mid-slab ratio is not monotonic for phi > 2 pi: take the longest slab on a fine
    # log grid below which every slab meets the tolerance
    grid = np.geomspace(0.005, min(slab, 1.0), 200)
    w_bin, omega_bin = _slope_weights_by_frequency(energy, k2, omega)
    ok = np.array([mid_slab_mss_ratio(w_bin, 1.0, omega_bin, s) >= 1.0 - mtol for s in grid])
    first_bad = np.flatnonzero(~ok)
    if first_bad.size:
        slab = float(grid[max(first_bad[0] - 1, 0)])
    return float(min(max(slab, 0.005), 1.0))


class EvolvingSea:
    """A :class:`WaveField` evaluated at any time, by slabs of cubic Hermite interpolation.

    Parameters
    ----------
    field : WaveField
    slab_s : float
        Slab length, seconds (:func:`slab_for_tolerances_s`).
    evolving : bool
        False freezes the sea at t = 0 for every time (the surface of ``field.at_time(0)``).
    """

    def __init__(self, field: WaveField, slab_s: float, evolving: bool = True) -> None:
        self.field = field
        self.slab_s = check_number("slab_s", slab_s, gt=0.0)
        self.evolving = bool(evolving)
        self.mean_level_m = field.mean_level_m
        self._cache: OrderedDict[int, tuple[GridSurface, GridSurface]] = OrderedDict()
        ny, nx = field.shape
        # a boundary: the surface and its rate, each node values and spline coefficients
        self._cache_size = max(2, CACHE_BYTES // (4 * 8 * (ny + 4) * (nx + 4)))
        x0, x1, y0, y1 = field.extent
        self.period_m = (x1 - x0, y1 - y0)
        # |eta - level| never exceeds the sum of the mode amplitudes (the Hermite blend of a
        # mode is at most its amplitude, the spline overshoots a little: 25 % margin); the
        # caster brackets its roots with it
        amp = np.abs(field._h_plus) + np.abs(field._h_minus)
        self.height_bound_m = 1.25 * float(np.sum(amp * field._weight)) + 1e-3

    def boundary(self, j: int) -> tuple[GridSurface, GridSurface]:
        """The surface and its rate ``d eta / dt`` at ``t = j slab_s`` (cached)."""
        if j in self._cache:
            self._cache.move_to_end(j)
            return self._cache[j]
        t = j * self.slab_s
        pair = self.field.surface_and_rate(t)
        self._cache[j] = pair
        while len(self._cache) > self._cache_size:
            self._cache.popitem(last=False)
        return pair

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
            xi, yi = x[idx], y[idx]
            s0, r0 = self.boundary(jj)
            lo = np.asarray(s0.height_and_gradient(xi, yi))
            w = a[idx]
            if self.evolving and np.any(w > 0.0):
                s1, r1 = self.boundary(jj + 1)
                w2, w3 = w * w, w * w * w
                h01 = 3.0 * w2 - 2.0 * w3  # h00 = 1 - h01: the level is kept
                h10 = self.slab_s * (w3 - 2.0 * w2 + w)
                h11 = self.slab_s * (w3 - w2)
                lo = lo + h01 * (np.asarray(s1.height_and_gradient(xi, yi)) - lo)
                lo = lo + h10 * np.asarray(r0.height_and_gradient(xi, yi))
                lo = lo + h11 * np.asarray(r1.height_and_gradient(xi, yi))
            out[:, idx] = lo
        return out[0], out[1], out[2]

    def height_m(self, x_m: Any, y_m: Any, t_s: Any = 0.0) -> np.ndarray:
        """Surface height (local z, m) at ``(x, y)`` and times ``t_s`` (broadcast)."""
        x, y = check_points(x_m, y_m)
        z = self.height_and_gradient(x, y, t_s)[0]
        return z.reshape(x.shape)
