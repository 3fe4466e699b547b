"""The water surface: flat (with an optional tide) or a wind-driven linear random sea.

Every water model has ``at_time(t_s) -> Surface``, the surface frozen at time ``t_s`` (s).

Waves (:class:`WaveField`) are linear (Gaussian) deep-water waves synthesised by FFT on a periodic
grid (Tessendorf 2001): mode ``k`` has complex amplitude ``h0(k)``, an independent complex Gaussian
with ``E|h0|**2 = Psi(k) dkx dky / 2``, and
``eta(x, t) = mean_level + sum_k [h0(k) e^{-i w t} + conj(h0(-k)) e^{i w t}] e^{i k.x}`` with
``w**2 = g |k|`` (or ``g |k| tanh(|k| h)`` with ``water_depth_m``), so each component travels along
its own wavevector at its phase speed and the field is real; :mod:`terrain.evolving_sea` evaluates
it at every pulse's time.
``Psi(kx, ky) = F(k) D(theta - direction) / k`` from the Pierson-Moskowitz or JONSWAP spectrum and
cos-2s or cos**2 spreading (:mod:`terrain.wave_spectra`). The frozen surface is a periodic
:class:`~terrain.gridded.GridSurface`: the truth is the cubic spline of the node values.

Mean-square-slope calibration (documented model choice)
-------------------------------------------------------
The Phillips ``k**-3`` tail of PM/JONSWAP carries slope variance ``(alpha/2) ln(k_max/k_p)``,
which reaches the Cox-Munk value only for ``k_max`` of order 1e5 ``k_p`` (capillary scales): a grid
cannot resolve that. With ``calibrate_mss=True`` (default) the tail beyond
``k_t = 20 k_p`` (``omega ~ 4.5 omega_p``, clear of the peak that sets Hs) is scaled by
``1 + c (1 - exp(-(k/k_t)**4))``, with ``c`` solved (one linear equation) so that the *expected*
mean-square slope of the generated field, ``sum k**2 Psi dkx dky`` over the modes the grid carries
(``0 < |k| <= cutoff``), equals Cox-Munk ``0.003 + 5.12e-3 U12.5``. The slope variance that the
real sea holds in cm-scale waves is thus put into the resolved band; the extra energy raises the
expected Hs by 0.3 % (U10 = 5 m/s) to 1.2 % (10 m/s) at ``cutoff = 128 k_p``, more on coarser
grids (``expected_hs_m`` reports it). The grid must carry ``cutoff >= 2 k_t = 40 k_p`` or a
:class:`ValueError` is raised. With the default cutoff, ``cutoff / k_p = n lambda_p / (4 L)``
for ``n`` nodes over a side ``L``: 1024 nodes over 2 peak wavelengths give 128 ``k_p``; a
representative Hs needs more peak wavelengths (16 give < 1 % sampling error), i.e. more nodes or
``calibrate_mss=False`` for a wave-height-only study.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.fft

from terrain import wave_spectra as ws
from terrain._validate import as_rng, check_bounds, check_choice, check_number, check_points
from terrain.gridded import GridSurface, periodic_grid
from terrain.surface import UNBOUNDED, Bounds, Surface

__all__ = ["FlatWater", "Tide", "WaveField", "depth_m", "M2_PERIOD_S", "TAIL_START_KP"]

M2_PERIOD_S = 44714.16  # principal lunar semidiurnal tide, s
TAIL_START_KP = 20.0  # k_t / k_p of the mss calibration


@dataclass(frozen=True)
class FlatWater(Surface):
    """A flat water surface at ``level_m`` (local z, metres)."""

    level_m: float = 0.0
    extent: Bounds = UNBOUNDED

    def __post_init__(self) -> None:
        object.__setattr__(self, "level_m", check_number("level_m", self.level_m))
        object.__setattr__(self, "extent", check_bounds("extent", self.extent, allow_inf=True))

    @property
    def bounds(self) -> Bounds:
        """``extent``, unbounded by default."""
        return self.extent

    def at_time(self, t_s: float = 0.0) -> FlatWater:
        """The same surface (a flat level does not change)."""
        check_number("t_s", t_s)
        return self

    def _height(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        return np.full(x.shape, self.level_m)

    def _gradient(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return np.zeros(x.shape), np.zeros(x.shape)


@dataclass(frozen=True)
class Tide:
    """A harmonic tide: ``level(t) = mean_level_m + amplitude_m cos(2 pi t / period_s - phase)``."""

    mean_level_m: float = 0.0
    amplitude_m: float = 0.0
    period_s: float = M2_PERIOD_S
    phase_rad: float = 0.0

    def __post_init__(self) -> None:
        for name in ("mean_level_m", "phase_rad"):
            check_number(name, getattr(self, name))
        check_number("amplitude_m", self.amplitude_m, ge=0.0)
        check_number("period_s", self.period_s, gt=0.0)

    def level_m(self, t_s: Any) -> np.ndarray:
        """Water level (local z, metres) at times ``t_s`` (s)."""
        t = np.asarray(t_s, dtype=np.float64)
        arg = 2.0 * math.pi * t / self.period_s - self.phase_rad
        return self.mean_level_m + self.amplitude_m * np.cos(arg)

    def at_time(self, t_s: float = 0.0) -> FlatWater:
        """The flat surface at time ``t_s``."""
        return FlatWater(float(self.level_m(check_number("t_s", t_s))))


def depth_m(seabed: Surface, water: Surface, x_m: Any, y_m: Any) -> np.ndarray:
    """Water depth ``water - seabed`` (positive down) in metres; negative where dry."""
    x, y = check_points(x_m, y_m)
    return water._height(x, y) - seabed._height(x, y)


class WaveField:
    """A wind sea on a periodic patch; :meth:`at_time` gives the frozen surface.

    Parameters
    ----------
    wind_speed_m_s : float
        Neutral wind speed (> 0) at ``wind_height_m``, m/s.
    extent : tuple of 4 float
        ``(xmin, xmax, ymin, ymax)`` of one period, metres; several peak wavelengths
        (:attr:`peak_wavelength_m`) for a representative Hs.
    spacing_m : float
        Largest node spacing, metres; the node count is made FFT-friendly.
    rng : numpy.random.Generator or int
        Random source or seed.
    wind_height_m : float
        Height of the given wind speed, metres (default 10).
    direction_rad : float
        Azimuth the wind blows and the waves travel *toward*, clockwise from north (+y), rad.
    spectrum : {"pierson-moskowitz", "jonswap"}
        Fully developed PM (wind at 19.5 m) or fetch-limited JONSWAP (needs ``fetch_m``).
    fetch_m : float, optional
        JONSWAP fetch, metres.
    gamma : float
        JONSWAP peak enhancement (>= 1).
    spreading : {"cos-2s", "cos2"}
        Directional spreading; ``spreading_s`` is the cos-2s exponent (default 2, which gives the
        Cox-Munk upwind/crosswind slope ratio of about 1.4).
    spreading_s : float
        cos-2s exponent (> 0).
    cutoff_wavenumber_rad_m : float, optional
        Largest wavenumber carried, rad/m, at most the Nyquist ``pi / spacing``; default
        ``pi / (2 spacing)`` (4 nodes per shortest wave, so the spline and a grid-resolution mesh
        follow its slopes).
    calibrate_mss : bool
        Scale the spectral tail so the expected mean-square slope equals Cox-Munk (module doc).
    mean_level_m : float
        Mean water level (local z, metres).
    water_depth_m : float, optional
        Depth for the finite-depth dispersion ``w**2 = g k tanh(k h)`` of the phase evolution;
        None (default) is deep water ``w**2 = g k``. The spectrum itself stays the deep-water one.

    Attributes
    ----------
    hs_sampling_error : float
        Expected relative standard deviation of the realised Hs on this periodic patch, from the
        mode energies ``E``: each real mode's energy is exponentially distributed, so
        ``std(m0) / m0 = sqrt(sum E**2) / sum E`` over independent modes and Hs = 4 sqrt(m0)
        halves it. About ``0.2 / (patch side in peak wavelengths)`` for PM with cos-2s.
    acceleration_rms_m_s2 : float
        Expected rms vertical acceleration ``sqrt(sum w**4 Psi dk)``, m/s**2.
    """

    def __init__(
        self,
        wind_speed_m_s: float,
        *,
        extent: Any,
        spacing_m: float,
        rng: Any,
        wind_height_m: float = 10.0,
        direction_rad: float = 0.0,
        spectrum: str = "pierson-moskowitz",
        fetch_m: float | None = None,
        gamma: float = 3.3,
        spreading: str = "cos-2s",
        spreading_s: float = 2.0,
        cutoff_wavenumber_rad_m: float | None = None,
        calibrate_mss: bool = True,
        mean_level_m: float = 0.0,
        water_depth_m: float | None = None,
    ) -> None:
        u = check_number("wind_speed_m_s", wind_speed_m_s, gt=0.0)
        zw = check_number("wind_height_m", wind_height_m, gt=0.0)
        self.direction_rad = check_number("direction_rad", direction_rad)
        self.mean_level_m = check_number("mean_level_m", mean_level_m)
        self.spectrum = check_choice("spectrum", spectrum, ("pierson-moskowitz", "jonswap"))
        check_choice("spreading", spreading, ("cos-2s", "cos2"))
        s_exp = check_number("spreading_s", spreading_s, gt=0.0)
        self.u10_m_s = ws.wind_speed_at_height(u, zw, 10.0)
        self.u12_5_m_s = ws.wind_speed_at_height(u, zw, 12.5)
        self.u19_5_m_s = ws.wind_speed_at_height(u, zw, 19.5)
        if self.spectrum == "jonswap":
            if fetch_m is None:
                raise ValueError("`fetch_m` must be given for spectrum='jonswap'; got None")
            fetch = check_number("fetch_m", fetch_m, gt=0.0)
            gam = check_number("gamma", gamma, ge=1.0)
            s_omega = lambda w: ws.jonswap(w, self.u10_m_s, fetch, gam)  # noqa: E731
            wp = ws.jonswap_peak_rad_s(self.u10_m_s, fetch)
        else:
            s_omega = lambda w: ws.pierson_moskowitz(w, self.u19_5_m_s)  # noqa: E731
            wp = ws.pierson_moskowitz_peak_rad_s(self.u19_5_m_s)
        self.peak_wavenumber_rad_m = wp**2 / ws.GRAVITY_M_S2
        self.peak_wavelength_m = 2.0 * math.pi / self.peak_wavenumber_rad_m

        b, nx, ny, dx, dy = periodic_grid(extent, spacing_m)
        self.extent, self.shape, self.spacing_m = b, (ny, nx), (dy, dx)
        k_nyq = math.pi / max(dx, dy)
        if cutoff_wavenumber_rad_m is None:
            kmax = 0.5 * k_nyq
        else:
            kmax = check_number("cutoff_wavenumber_rad_m", cutoff_wavenumber_rad_m, gt=0.0)
            if kmax > k_nyq * (1 + 1e-12):
                raise ValueError(
                    f"`cutoff_wavenumber_rad_m` must be <= pi / spacing = {k_nyq:.6g}; got {kmax!r}"
                )
        self.cutoff_wavenumber_rad_m = kmax

        kx = 2.0 * math.pi * scipy.fft.fftfreq(nx, d=dx)
        ky = 2.0 * math.pi * scipy.fft.fftfreq(ny, d=dy)
        kxx, kyy = np.meshgrid(kx, ky)
        k = np.hypot(kxx, kyy)
        ix, iy = np.meshgrid(np.arange(nx), np.arange(ny))
        carried = (k > 0) & (k <= kmax) & (2 * ix != nx) & (2 * iy != ny)
        theta = np.arctan2(kxx, kyy) - self.direction_rad
        spread = (
            ws.cos2s_spreading(theta, s_exp) if spreading == "cos-2s" else ws.cos2_spreading(theta)
        )
        k_safe = np.where(carried, k, 1.0)
        psi = np.where(carried, ws.wavenumber_spectrum(s_omega, k_safe) * spread / k_safe, 0.0)
        dk2 = (2.0 * math.pi / (nx * dx)) * (2.0 * math.pi / (ny * dy))
        self.cox_munk_mss = float(ws.cox_munk_mss(self.u12_5_m_s))
        self.tail_start_rad_m = TAIL_START_KP * self.peak_wavenumber_rad_m
        self.tail_factor = 0.0
        if calibrate_mss:
            if kmax < 2.0 * self.tail_start_rad_m:
                raise ValueError(
                    f"`spacing_m` = {spacing_m!r} carries waves up to {kmax:.4g} rad/m, below "
                    f"2 k_t = {2 * self.tail_start_rad_m:.4g} rad/m (40 peak wavenumbers) needed "
                    "to calibrate the mean-square slope; refine it or set calibrate_mss=False"
                )
            shape = 1.0 - np.exp(-((k / self.tail_start_rad_m) ** 4))
            mss0 = float(np.sum(k * k * psi)) * dk2
            mss1 = float(np.sum(k * k * psi * shape)) * dk2
            self.tail_factor = (self.cox_munk_mss - mss0) / mss1
            if self.tail_factor <= -1.0:
                # no tail scaling helps: the waves below k_t alone hold more slope than Cox-Munk
                # (PM slopes depend on k / k_p only: ~0.0099 below 20 k_p at any wind, while
                # Cox-Munk is below that under ~1.35 m/s), so no field matches it at this wind
                raise ValueError(
                    f"mss calibration impossible at U12.5 = {self.u12_5_m_s:.3g} m/s: the "
                    f"spectrum's waves below the tail (k < {TAIL_START_KP:g} k_p) already carry "
                    f"a mean-square slope of {mss0 - mss1:.4g}, above Cox-Munk's "
                    f"{self.cox_munk_mss:.4g}; use calibrate_mss=False (the published spectrum) "
                    "at winds this low"
                )
            psi = psi * (1.0 + self.tail_factor * shape)
        self.expected_m0_m2 = float(np.sum(psi)) * dk2
        self.expected_mss = float(np.sum(k * k * psi)) * dk2
        self.expected_hs_m = 4.0 * math.sqrt(self.expected_m0_m2)
        # a real mode is the pair (k, -k); both are in the sums over the full plane, twice
        pair = psi + psi[(-np.arange(ny)) % ny][:, (-np.arange(nx)) % nx]
        s1, s2 = float(np.sum(pair)) / 2.0, float(np.sum(pair**2)) / 2.0
        self.hs_sampling_error = 0.5 * math.sqrt(s2) / s1 if s1 > 0 else math.inf
        if water_depth_m is None:
            omega = np.sqrt(ws.GRAVITY_M_S2 * k)
        else:
            h = check_number("water_depth_m", water_depth_m, gt=0.0)
            omega = np.sqrt(ws.GRAVITY_M_S2 * k * np.tanh(k * h))
        self.water_depth_m = water_depth_m
        self.acceleration_rms_m_s2 = math.sqrt(float(np.sum(omega**4 * psi)) * dk2)

        gen = as_rng(rng)
        noise = gen.standard_normal((2, ny, nx))
        h0 = np.sqrt(psi * dk2 / 2.0) * (noise[0] + 1j * noise[1]) / math.sqrt(2.0)
        nh = nx // 2 + 1
        neg = h0[(-np.arange(ny)) % ny][:, (-np.arange(nh)) % nx]
        self._h_plus = h0[:, :nh]
        self._h_minus = np.conj(neg)
        self._omega = omega[:, :nh]
        self._kx, self._ky = kxx[:, :nh], kyy[:, :nh]
        weight = np.full(nh, 2.0)
        weight[0] = 1.0
        if nx % 2 == 0:
            weight[-1] = 1.0
        self._weight = weight[None, :]

    def _parts(self, t_s: float) -> tuple[np.ndarray, np.ndarray]:
        """``h0(k) e^{-i w t}`` and ``conj(h0(-k)) e^{i w t}`` of every mode."""
        t = check_number("t_s", t_s)
        phase = np.exp(-1j * self._omega * t)
        return self._h_plus * phase, self._h_minus * np.conj(phase)

    def _modes(self, t_s: float) -> np.ndarray:
        up, down = self._parts(t_s)
        return up + down

    def at_time(self, t_s: float = 0.0) -> GridSurface:
        """The surface frozen at time ``t_s`` (s): periodic GridSurface over ``extent``."""
        return self._grid(self._modes(t_s), self.mean_level_m)

    def rate_at_time(self, t_s: float = 0.0) -> GridSurface:
        """The vertical rate ``d eta / dt`` (m/s) at time ``t_s``: periodic GridSurface, mean 0.

        Mode by mode ``-i w [h0(k) e^{-i w t} - conj(h0(-k)) e^{i w t}]``, the exact time
        derivative of :meth:`at_time`'s field (:mod:`terrain.evolving_sea` interpolates in time
        with it).
        """
        up, down = self._parts(t_s)
        return self._grid(-1j * self._omega * (up - down), 0.0)

    def surface_and_rate(self, t_s: float = 0.0) -> tuple[GridSurface, GridSurface]:
        """:meth:`at_time` and :meth:`rate_at_time` at ``t_s``: the same numbers.

        The modes' phases are computed once for both (an eighth of a boundary's cost on a
        4096-node tile: one complex ``exp`` over 8.4 M modes of the two).
        """
        up, down = self._parts(t_s)
        surface = self._grid(up + down, self.mean_level_m)
        up -= down  # in place: the same bits as up - down, one array fewer
        return surface, self._grid(-1j * self._omega * up, 0.0)

    def _grid(self, modes: np.ndarray, level_m: float) -> GridSurface:
        ny, nx = self.shape
        eta = scipy.fft.irfft2(modes * (nx * ny), s=(ny, nx))
        dy, dx = self.spacing_m
        return GridSurface(self.extent[0], self.extent[2], dx, dy, eta + level_m, True)

    def mode_energies(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Realised energy ``|h+|**2 + |h-|**2`` (m**2), ``|k|**2`` and ``w`` of each mode.

        Returns
        -------
        energy_m2, k2_rad2_m2, omega_rad_s : (ny, nx // 2 + 1) float64
            The energies carry the half-plane weights, so ``sum(energy)`` is the height variance
            and ``sum(k2 * energy)`` the mean-square slope, in the ensemble over time.
        """
        energy = self._weight * (np.abs(self._h_plus) ** 2 + np.abs(self._h_minus) ** 2)
        return energy, self._kx**2 + self._ky**2, self._omega

    def slope_variance(self, t_s: float = 0.0) -> tuple[float, float]:
        """Realised ``(upwind, crosswind)`` slope variances of the Fourier field at ``t_s``."""
        h2 = np.abs(self._modes(t_s)) ** 2 * self._weight
        s, c = math.sin(self.direction_rad), math.cos(self.direction_rad)
        k_up = self._kx * s + self._ky * c
        k_cross = self._kx * c - self._ky * s
        return float(np.sum(k_up**2 * h2)), float(np.sum(k_cross**2 * h2))

    def mean_square_slope(self, t_s: float = 0.0) -> float:
        """Realised mean-square slope ``<|grad eta|**2>`` of the Fourier field at ``t_s``."""
        return float(sum(self.slope_variance(t_s)))

    def significant_wave_height_m(self, t_s: float = 0.0) -> float:
        """Realised ``Hs = 4 sqrt(m0)`` with ``m0`` the spatial variance at ``t_s``, metres."""
        return 4.0 * math.sqrt(float(np.sum(np.abs(self._modes(t_s)) ** 2 * self._weight)))
