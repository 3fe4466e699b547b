"""Rough seabed from an isotropic roughness spectrum, synthesised by FFT on a periodic grid.

Spectral synthesis: white Gaussian noise on the grid is Fourier transformed, multiplied by
``sqrt(N P(k) dkx dky)`` and transformed back, so each Fourier mode is an independent complex
Gaussian with variance ``P(k) dkx dky``: the field is a stationary Gaussian random field whose
expected variance is the sum of the spectrum over the grid's modes. The realised field is *not*
rescaled to the requested RMS; it differs from it by sampling noise (relative standard error
about ``sqrt(pi) * l / L`` in variance for a Gaussian field on an ``L x L`` patch) and by the
spectral power the grid cannot carry (``k = 0``, which is removed so the field has zero mean, and
``|k|`` beyond the Nyquist wavenumber ``pi / spacing``). Use a patch much larger than the
correlation length.

Spectra (two-sided, 2-D, ``C(r) = integral P(k) exp(i k.r) d2k``, ``integral P d2k = rms**2``):

* Gaussian: ``C(r) = rms**2 exp(-r**2 / l**2)`` (falls to 1/e at ``r = l``),
  ``P(k) = rms**2 l**2 / (4 pi) exp(-k**2 l**2 / 4)``.
* von Karman (Matern) with Hurst exponent ``0 < H <= 1``:
  ``C(r) = rms**2 2**(1-H) / Gamma(H) (r/l)**H K_H(r/l)``,
  ``P(k) = rms**2 H l**2 / (pi (1 + k**2 l**2)**(1+H))``; ``l`` is the scale parameter
  (``C(l) / C(0)`` is 0.45 for H = 0.5, not 1/e). The fraction of variance above wavenumber
  ``k`` is ``(1 + k**2 l**2)**-H``, so small ``H`` needs a fine spacing.

The result is a periodic :class:`~terrain.gridded.GridSurface`: the truth is the cubic spline of
the synthesised node values.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np
import scipy.fft
from scipy import special

from terrain._validate import as_rng, check_number
from terrain.gridded import GridSurface, periodic_grid

__all__ = [
    "gaussian_psd",
    "von_karman_psd",
    "gaussian_autocorrelation",
    "von_karman_autocorrelation",
    "synthesise",
    "gaussian_roughness",
    "von_karman_roughness",
]


def gaussian_psd(k: Any, rms_height_m: float, correlation_length_m: float) -> np.ndarray:
    """2-D PSD (m**4) of a Gaussian-correlated surface at wavenumber magnitude ``k`` (rad/m)."""
    k = np.asarray(k, dtype=np.float64)
    s2, ell = rms_height_m**2, correlation_length_m
    return s2 * ell**2 / (4.0 * math.pi) * np.exp(-0.25 * (k * ell) ** 2)


def von_karman_psd(
    k: Any, rms_height_m: float, correlation_length_m: float, hurst: float
) -> np.ndarray:
    """2-D PSD (m**4) of a von Karman surface at wavenumber magnitude ``k`` (rad/m)."""
    k = np.asarray(k, dtype=np.float64)
    s2, ell = rms_height_m**2, correlation_length_m
    return s2 * hurst * ell**2 / (math.pi * (1.0 + (k * ell) ** 2) ** (1.0 + hurst))


def gaussian_autocorrelation(r: Any, rms_height_m: float, correlation_length_m: float):
    """Autocovariance (m**2) of the Gaussian model at lag ``r`` (m)."""
    r = np.asarray(r, dtype=np.float64)
    return rms_height_m**2 * np.exp(-((r / correlation_length_m) ** 2))


def von_karman_autocorrelation(r: Any, rms_height_m: float, correlation_length_m: float, hurst):
    """Autocovariance (m**2) of the von Karman model at lag ``r`` (m); ``rms**2`` at 0."""
    u = np.abs(np.asarray(r, dtype=np.float64)) / correlation_length_m
    safe = np.where(u > 0, u, 1.0)
    c = 2.0 ** (1.0 - hurst) / special.gamma(hurst) * safe**hurst * special.kv(hurst, safe)
    return rms_height_m**2 * np.where(u > 0, c, 1.0)


def synthesise(
    psd: Callable[[np.ndarray], np.ndarray],
    shape: tuple[int, int],
    spacing_m: tuple[float, float],
    rng: Any,
) -> np.ndarray:
    """Gaussian random field with 2-D spectrum ``psd`` on a periodic grid (zero mean).

    Parameters
    ----------
    psd : callable
        ``psd(k)`` -> two-sided 2-D PSD in m**4 at wavenumber magnitudes ``k`` (rad/m).
    shape : tuple of int
        ``(ny, nx)`` grid nodes.
    spacing_m : tuple of float
        ``(dy, dx)`` node spacing in metres.
    rng : numpy.random.Generator or int
        Random source or seed.

    Returns
    -------
    numpy.ndarray, shape (ny, nx)
        Field in metres; expected variance ``sum(P(k) dkx dky)`` over modes ``k != 0``.
    """
    ny, nx = shape
    dy, dx = spacing_m
    gen = as_rng(rng)
    kx = 2.0 * math.pi * scipy.fft.rfftfreq(nx, d=dx)
    ky = 2.0 * math.pi * scipy.fft.fftfreq(ny, d=dy)
    k = np.hypot(kx[None, :], ky[:, None])
    dk2 = (2.0 * math.pi / (nx * dx)) * (2.0 * math.pi / (ny * dy))
    amp = np.sqrt(nx * ny * dk2 * psd(k))
    amp[0, 0] = 0.0
    noise = gen.standard_normal((ny, nx))
    return scipy.fft.irfft2(scipy.fft.rfft2(noise) * amp, s=(ny, nx))


def gaussian_roughness(
    rms_height_m: float,
    correlation_length_m: float,
    *,
    extent: Any,
    rng: Any,
    spacing_m: float | None = None,
) -> GridSurface:
    """Zero-mean rough seabed with a Gaussian autocorrelation, periodic over ``extent``.

    Parameters
    ----------
    rms_height_m : float
        Requested RMS height in metres (>= 0).
    correlation_length_m : float
        Lag at which the autocorrelation falls to 1/e, metres (> 0).
    extent : tuple of 4 float
        ``(xmin, xmax, ymin, ymax)`` of one period, metres; make it >> the correlation length.
    rng : numpy.random.Generator or int
        Random source or seed (required: worlds are reproducible).
    spacing_m : float, optional
        Largest node spacing; default ``correlation_length_m / 8`` (spectrum at Nyquist is
        ``exp(-16 pi**2)`` of its peak). The grid is sized to an FFT-friendly node count.

    Returns
    -------
    GridSurface
        Periodic surface with ``bounds == extent``.
    """
    s = check_number("rms_height_m", rms_height_m, ge=0.0)
    ell = check_number("correlation_length_m", correlation_length_m, gt=0.0)
    b, nx, ny, dx, dy = periodic_grid(extent, ell / 8.0 if spacing_m is None else spacing_m)
    z = synthesise(lambda k: gaussian_psd(k, s, ell), (ny, nx), (dy, dx), rng)
    return GridSurface(b[0], b[2], dx, dy, z, periodic=True)


def von_karman_roughness(
    rms_height_m: float,
    correlation_length_m: float,
    hurst: float,
    *,
    extent: Any,
    rng: Any,
    spacing_m: float | None = None,
) -> GridSurface:
    """Zero-mean rough seabed with a von Karman spectrum (Hurst exponent ``hurst``).

    Parameters
    ----------
    rms_height_m : float
        Requested RMS height in metres (>= 0) of the full (unresolved) spectrum.
    correlation_length_m : float
        von Karman scale parameter ``l`` in metres (> 0).
    hurst : float
        Hurst exponent, ``0 < hurst <= 1`` (fractal dimension ``3 - hurst``).
    extent, rng : see :func:`gaussian_roughness`.
    spacing_m : float, optional
        Largest node spacing; default ``correlation_length_m / 8``. The variance fraction lost
        above Nyquist is about ``(1 + (pi l / spacing)**2)**-hurst``.

    Returns
    -------
    GridSurface
        Periodic surface with ``bounds == extent``.
    """
    s = check_number("rms_height_m", rms_height_m, ge=0.0)
    ell = check_number("correlation_length_m", correlation_length_m, gt=0.0)
    h = check_number("hurst", hurst, gt=0.0, le=1.0)
    b, nx, ny, dx, dy = periodic_grid(extent, ell / 8.0 if spacing_m is None else spacing_m)
    z = synthesise(lambda k: von_karman_psd(k, s, ell, h), (ny, nx), (dy, dx), rng)
    return GridSurface(b[0], b[2], dx, dy, z, periodic=True)
