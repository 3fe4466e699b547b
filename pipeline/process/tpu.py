"""Total propagated uncertainty (TPU) of the refraction-corrected seabed points, first order.

Every input error is propagated through the processing's own georeferencing,
:func:`pipeline.process.refraction.seabed_points`, by central differences (vectorised: one call
per perturbed input for all points), except the rigid motions, whose effect is exact and
analytic. One-sigma terms are independent and add in quadrature per coordinate.

Each term is a one-sigma change of four numbers: the point's ``x``, ``y``, ``z`` and its
**depth below the measured water surface at the measured (x, y)**, ``depth_m - g . (dx, dy)``,
where ``depth_m`` is :func:`~pipeline.process.refraction.seabed_points`' depth (the fitted local
water plane above the point minus its height) and ``g`` the seabed's depth gradient: a point
moved sideways over a slope is compared with the depth where it was put, not where it was
measured. ``g`` comes from the measured soundings themselves (:func:`seabed_gradient`);
without it the depth terms assume a flat seabed.

Terms (defaults in :class:`TpuSettings`; ``R`` random per pulse, ``C`` correlated over a
grid cell: does not average down in a cell mean)
----------------------------------------------------------------------------------------------
=====================  ==  ====================================================================
navigation position    C   GNSS/INS error, slowly varying: the aircraft, its surface points and
                           the fitted surface move together, so the seabed point moves by the
                           same vector ``(s_h, s_h, s_v)``. Depth: the vertical part cancels
                           (surface and seabed move together); the horizontal part couples
                           through the slope, ``|g| s_h``.
attitude               C   IMU roll/pitch (isotropic tilt ``s_tilt``, so the aircraft heading
                           is not needed) and heading ``s_head``: the whole measured scene
                           rotates about the laser origin, ``dB = w x (B - o)``. Depth: the
                           distance to the (rotated) plane is unchanged, only its vertical
                           projection, ``-depth (w x N)_z / N_z`` (zero under a level plane),
                           plus the slope coupling of ``dB``.
surface fit height     C   standard error of the fitted plane at the entry point (depth: zero
                           with the pulse's own surface return, whose time fixes the in-water
                           range from wherever the surface is).
surface fit tilt       C   tilt sigma of the fitted plane (``/ sqrt 2`` per axis), the plane
                           turned about the entry point: the fit's standard error
                           (``normal_sigma_rad``) or, if larger, the tilt measured over the
                           sounding (:func:`surface_tilt_sigma`: how the plane turns against
                           the plane fitted over the sounding; waves the plane does not follow,
                           misfit of neighbours from passes with different navigation errors).
                           Depth: the plane's height at the sounding and the refraction.
water temperature,     C   unknown water mass: both indices move together, with the
salinity                   derivatives of Quan & Fry (1995) (:mod:`pipeline.optics`).
timing (surface,       R   the detector's per-return sigma (``DetectedReturns.t_*_sigma_s``), or
bottom)                    ``timing_sigma_s``; :func:`timing_sigma_s` gives it from the SNR;
                           when the detector gives none, :func:`timing_from_scatter` sets it
                           from the measured scatter of successive soundings
                           (:func:`pair_scatter`), which holds each pulse's own noise and not
                           what neighbours share.
pointing jitter        R   per-pulse beam direction noise (scanner encoder), two axes.
wave height            R   the local water surface off its fitted plane: the fit's residual
                           sigma in excess of its points' ranging noise (depth: as the fit
                           height).
wave slope             R   facet slope under the footprint not in the fitted plane
                           (``wave_slope_sigma_rad`` per axis; :func:`cox_munk_slope_sigma`).
footprint              R   the return's centroid within the beam footprint: per horizontal axis
                           ``D / 4`` (Gaussian beam, ``D`` its 1/e² diameter at the bottom
                           ``gamma (r_air + L / n_w)``), vertically ``D / 4 tan(seabed slope)``.
                           Depth: zero (over a plane the centroid of the return is the beam
                           centre's range; relief within the footprint shows in the measured
                           scatter, :func:`pair_scatter`).
=====================  ==  ====================================================================

The attenuation does not enter the georeferencing (only the waveform's timing, which the
posterior in :mod:`pipeline.process.posterior` covers). Systematic detector biases (a green
surface return late in waves, the first-photon bias of a dead-time-limited photon counter, the
merged returns of the shallowest metre) are not uncertainties: they are not in the TPU
(``benchmarks/RESULTS_tpu_calibration.md``).

Conventions
-----------
``sigma_v_m`` is the one-sigma error of the point's elevation ``z`` (what IHO S-44's TVU
bounds, :mod:`pipeline.iho`); ``sigma_depth_m`` that of its depth below the measured water
surface at the measured position (what a sounding reports; the navigation's vertical error and
the fitted surface height cancel in it); ``sigma_h_m`` is the *per-axis* horizontal sigma of a
circular normal, ``sqrt((s_x^2 + s_y^2) / 2)``. The IHO 95 % values are ``1.96 sigma_v`` and
``2.45 sigma_h``.
:func:`monte_carlo_points` redraws every input and recomputes the points with
:func:`~pipeline.process.refraction.seabed_points` (the check of the linearisation).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from pipeline.config import setting
from pipeline.errors import NumericalError
from pipeline.optics import SPEED_OF_LIGHT_M_S, water_group_index, water_phase_index
from pipeline.process.refraction import RefractionSettings, seabed_points
from pipeline.process.returns import DetectedReturns
from pipeline.process.surface_fit import WaterSurface
from pipeline.process.surface_land import masked_median as _masked_median

__all__ = [
    "TpuSettings",
    "PointTpu",
    "RANDOM_TERMS",
    "CORRELATED_TERMS",
    "TIMING_TERMS",
    "point_tpu",
    "monte_carlo_points",
    "timing_sigma_s",
    "timing_from_scatter",
    "seabed_gradient",
    "pair_scatter",
    "surface_over_sounding",
    "surface_tilt_sigma",
    "cox_munk_slope_sigma",
    "index_derivatives",
]

_C = SPEED_OF_LIGHT_M_S
FWHM_TO_SIGMA = 1.0 / (2.0 * math.sqrt(2.0 * math.log(2.0)))
_MAD_TO_SIGMA = 1.4826
#: Columns of a term: the point's x, y, z and its depth at the measured position.
X, Y, Z, DEPTH = 0, 1, 2, 3

RANDOM_TERMS = (
    "timing_surface",
    "timing_bottom",
    "pointing_a",
    "pointing_b",
    "wave_height",
    "wave_slope_x",
    "wave_slope_y",
    "footprint",
)
CORRELATED_TERMS = (
    "navigation",
    "attitude_x",
    "attitude_y",
    "heading",
    "surface_height",
    "surface_tilt_x",
    "surface_tilt_y",
    "temperature",
    "salinity",
)
#: The terms of the return timing (the part the detector's noise sets).
TIMING_TERMS = ("timing_surface", "timing_bottom")


@dataclass(frozen=True, kw_only=True)
class TpuSettings:
    """Input one-sigma uncertainties of the TPU.

    Defaults: navigation and attitude of a post-processed GNSS/INS of the Applanix POS AV 510
    class (datasheet, post-processed: roll/pitch 0.005°, heading 0.008°; position a few cm, as
    PP-RTX vs base-station solutions agree to 2 cm horizontally and 6 cm vertically, Applanix
    airborne accuracy assessment); scanner jitter at an encoder's 0.001°; water of ±2 °C and
    ±2 psu around the nominal (index derivatives by Quan & Fry 1995); a 1 mrad beam.
    """

    position_sigma_h_m: float = setting(0.05, ge=0.0, doc="navigation, per horizontal axis")
    position_sigma_v_m: float = setting(0.08, ge=0.0, doc="navigation, vertical")
    attitude_sigma_deg: float = setting(0.005, ge=0.0, le=10.0, doc="IMU roll and pitch")
    heading_sigma_deg: float = setting(0.008, ge=0.0, le=10.0, doc="IMU heading")
    pointing_jitter_deg: float = setting(0.001, ge=0.0, le=10.0, doc="per-pulse beam jitter")
    timing_sigma_s: float = setting(1e-10, ge=0.0, doc="per-return timing if not given")
    temperature_sigma_c: float = setting(2.0, ge=0.0, doc="water temperature uncertainty")
    salinity_sigma_psu: float = setting(2.0, ge=0.0, doc="salinity uncertainty")
    wavelength_nm: float = setting(532.0, ge=400.0, le=700.0, doc="for the index derivatives")
    temperature_c: float = setting(20.0, ge=-2.0, le=35.0, doc="nominal water temperature")
    salinity_psu: float = setting(35.0, ge=0.0, le=40.0, doc="nominal salinity")
    wave_slope_sigma_rad: float = setting(0.0, ge=0.0, le=1.0, doc="residual facet slope/axis")
    beam_divergence_mrad: float = setting(1.0, ge=0.0, le=100.0, doc="full angle, 1/e²")
    seabed_slope_deg: float = setting(0.0, ge=0.0, lt=90.0, doc="assumed seabed slope")
    gradient_neighbours: int = setting(
        16, ge=3, le=256, doc="soundings per local plane of the seabed gradient"
    )
    gradient_radius_m: float = setting(10.0, gt=0.0, doc="farthest sounding of that plane")
    pair_max_separation_m: float = setting(
        2.0, gt=0.0, doc="farthest partner of a sounding in the measured scatter"
    )
    scatter_neighbours: int = setting(
        64, ge=4, le=4096, doc="sounding pairs pooled per local scatter estimate"
    )


def timing_sigma_s(snr: Any, pulse_fwhm_s: float) -> np.ndarray:
    """Cramér–Rao timing sigma ``sqrt(2) sigma_p / SNR`` of a Gaussian return in white noise.

    ``snr`` is the matched-filter SNR (the detector's filtered peak over the filtered noise
    sigma, :func:`pipeline.process.detect.detect_full_waveform`): with ``rho² = sum s_i² /
    sigma_n²`` the Fisher information on the centre is ``rho² / (2 sigma_p²)``.
    """
    snr = np.asarray(snr, dtype=np.float64)
    return math.sqrt(2.0) * pulse_fwhm_s * FWHM_TO_SIGMA / np.maximum(snr, 1e-12)


def cox_munk_slope_sigma(wind_speed_m_s: float) -> float:
    """Per-axis sea-surface slope sigma of Cox & Munk (1954): ``sqrt((0.003 + 5.12e-3 U) / 2)``.

    This is the slope of the capillary-scale facets; a footprint of several metres averages
    much of it, so use it as an upper bound for ``wave_slope_sigma_rad``.
    """
    return math.sqrt((0.003 + 5.12e-3 * wind_speed_m_s) / 2.0)


def index_derivatives(settings: TpuSettings) -> dict[str, tuple[float, float]]:
    """``(d n_phase, d n_group)`` per unit of temperature (°C) and salinity (psu)."""
    lam = settings.wavelength_nm * 1e-9
    t, s = settings.temperature_c, settings.salinity_psu
    out = {}
    for name, lo, hi, step in (
        ("temperature", (lam, s, t - 0.5), (lam, s, t + 0.5), 1.0),
        ("salinity", (lam, max(s - 0.5, 0.0), t), (lam, min(s + 0.5, 40.0), t), None),
    ):
        h = step if step is not None else hi[1] - lo[1]
        dp = (float(water_phase_index(*hi)) - float(water_phase_index(*lo))) / h
        dg = (float(water_group_index(*hi)) - float(water_group_index(*lo))) / h
        out[name] = (dp, dg)
    return out


@dataclass(frozen=True)
class PointTpu:
    """Propagated one-sigma uncertainty of every bottom point.

    Attributes
    ----------
    row : (n,) int64
        Row of the pulse in the ``returns`` given (pulses with a bottom return, in order: the
        rows of :func:`~pipeline.process.refraction.seabed_points`).
    pulse_id : (n,) int64
    xyz_m : (n, 3) float64
        The nominal seabed points.
    terms : dict of str to (n, 4) float64
        One-sigma change per term (:data:`RANDOM_TERMS`, :data:`CORRELATED_TERMS`) of the
        point's x, y, z (columns 0-2) and of its depth below the measured water surface at the
        measured position (column 3, see the module notes); ``navigation`` holds the three
        axis sigmas and the depth sigma they make.
    sigma_x_m, sigma_y_m, sigma_v_m : (n,) float64
        Total one-sigma per coordinate (``sigma_v_m`` is z, the elevation).
    sigma_h_m : (n,) float64
        Per-axis horizontal sigma ``sqrt((s_x² + s_y²) / 2)``.
    sigma_v_random_m, sigma_v_correlated_m, sigma_h_random_m, sigma_h_correlated_m : (n,)
        The same split into random and correlated terms.
    sigma_depth_m, sigma_depth_random_m, sigma_depth_correlated_m : (n,) float64 or None
        One-sigma of the depth below the measured water surface at the measured position
        (what ``Points.depth_m`` reports), total and split; None only in a PointTpu built by
        hand without them.
    """

    row: np.ndarray
    pulse_id: np.ndarray
    xyz_m: np.ndarray
    terms: dict[str, np.ndarray]
    sigma_x_m: np.ndarray
    sigma_y_m: np.ndarray
    sigma_v_m: np.ndarray
    sigma_h_m: np.ndarray
    sigma_v_random_m: np.ndarray
    sigma_v_correlated_m: np.ndarray
    sigma_h_random_m: np.ndarray
    sigma_h_correlated_m: np.ndarray
    sigma_depth_m: np.ndarray | None = None
    sigma_depth_random_m: np.ndarray | None = None
    sigma_depth_correlated_m: np.ndarray | None = None

    def __len__(self) -> int:
        return int(self.row.shape[0])


def _take_surface(surface: WaterSurface, index: np.ndarray) -> WaterSurface:
    rows = {
        f.name: getattr(surface, f.name)[index]
        for f in dataclasses.fields(surface)
        if f.name not in ("global_plane", "global_sigma_m", "air_index")
    }
    return dataclasses.replace(surface, **rows)


def _on_plane(o, d, point, normal, water):
    """Range and entry of beams ``(o, d)`` on planes ``(point, normal)`` (water rows only)."""
    den = np.sum(normal * d, axis=1)
    den = np.where(water & (den < -1e-9), den, -1.0)
    r = np.sum(normal * (point - o), axis=1) / den
    return r, o + d * r[:, None]


def _rotate(v, axis, angle):
    """Rodrigues rotation of rows ``v`` about unit ``axis`` rows by ``angle`` (n,)."""
    c, s = np.cos(angle)[:, None], np.sin(angle)[:, None]
    return v * c + np.cross(axis, v) * s + axis * np.sum(axis * v, axis=1)[:, None] * (1.0 - c)


def _perp_axes(d):
    """Two unit vectors perpendicular to the unit rows ``d`` (and to each other)."""
    ref = np.where(np.abs(d[:, 2:3]) < 0.9, [[0.0, 0.0, 1.0]], [[1.0, 0.0, 0.0]])
    a = np.cross(d, ref)
    a /= np.linalg.norm(a, axis=1, keepdims=True)
    return a, np.cross(d, a)


@dataclass(frozen=True)
class _Inputs:
    """The bottom pulses and everything the perturbations need."""

    ret: DetectedReturns
    surf: WaterSurface
    rst: RefractionSettings
    sig_ts: np.ndarray
    sig_tb: np.ndarray
    wave_h: np.ndarray
    row: np.ndarray
    grad: np.ndarray


def _per_row(name, value, n, cols=None):
    """A per-bottom-row input, validated; None gives zeros; NaN becomes 0."""
    shape = (n,) if cols is None else (n, cols)
    if value is None:
        return np.zeros(shape)
    a = np.asarray(value, dtype=np.float64)
    if a.shape != shape:
        raise ValueError(f"`{name}` must have the shape (n_bottom[, 2]) = {shape}; got {a.shape}")
    return np.where(np.isfinite(a), a, 0.0)


def _inputs(returns, surface, rst, st, seabed_gradient=None, surface_tilt_sigma_rad=None):
    if len(surface) != len(returns):
        raise ValueError(f"`surface` has {len(surface)} pulses; `returns` has {len(returns)}")
    row = np.flatnonzero(returns.has_bottom)
    ret, surf = returns.select(row), _take_surface(surface, row)
    n = len(row)
    grad = _per_row("seabed_gradient", seabed_gradient, n, 2)
    if surface_tilt_sigma_rad is not None:
        tilt = np.maximum(
            surf.normal_sigma_rad, _per_row("surface_tilt_sigma_rad", surface_tilt_sigma_rad, n)
        )
        surf = dataclasses.replace(surf, normal_sigma_rad=tilt)
    sig_ts = (
        np.full(n, st.timing_sigma_s) if ret.t_surface_sigma_s is None else ret.t_surface_sigma_s
    )
    sig_ts = np.where(ret.has_surface, sig_ts, 0.0)
    sig_tb = np.full(n, st.timing_sigma_s) if ret.t_bottom_sigma_s is None else ret.t_bottom_sigma_s
    # wave height: the fit residual in excess of the surface points' own ranging noise
    cos_i = np.abs(np.sum(ret.direction_meas * surf.normal, axis=1))
    ranging = _C * np.where(ret.has_surface, sig_ts, st.timing_sigma_s) / 2.0 * cos_i
    wave_h = np.sqrt(np.maximum(surf.fit_sigma_m**2 - ranging**2, 0.0))
    wave_h = np.where(surf.is_water, wave_h, 0.0)
    return _Inputs(ret, surf, rst, sig_ts, sig_tb, wave_h, row, grad)


def _xyzd(inp: _Inputs, *, ret=None, surf=None, rst=None) -> np.ndarray:
    """Seabed points and their depths, ``(n, 4)``."""
    p = seabed_points(ret or inp.ret, surf or inp.surf, rst or inp.rst)
    return np.column_stack([p.xyz_m, p.depth_m])


def _at_measured(t: np.ndarray, grad: np.ndarray) -> np.ndarray:
    """A term's depth change compared at the measured position: ``depth - g . (dx, dy)``."""
    t = t.copy()
    t[:, DEPTH] -= np.sum(grad * t[:, :2], axis=1)
    return t


def _with_times(inp, dts, dtb):
    r = inp.ret
    return dataclasses.replace(
        r,
        t_surface_s=np.where(r.has_surface, r.t_surface_s + dts, 0.0),
        t_bottom_s=r.t_bottom_s + dtb,
    )


def _with_direction(inp, d_new):
    """Beams turned to ``d_new``; entry re-intersected with the unchanged local planes."""
    s = inp.surf
    r, e = _on_plane(inp.ret.origin_meas_m, d_new, s.entry_m, s.normal, s.is_water)
    ret = dataclasses.replace(inp.ret, direction_meas=d_new)
    w = s.is_water
    surf = dataclasses.replace(
        s,
        entry_m=np.where(w[:, None], e, s.entry_m),
        range_to_entry_m=np.where(w, r, s.range_to_entry_m),
    )
    return ret, surf


def _with_plane(inp, dh, tilt_axis=None, tilt=None):
    """Local planes raised by ``dh`` and/or turned by ``tilt`` about ``tilt_axis``.

    The turn is about the entry point; the beams are re-intersected with the new planes.
    """
    s, o, d = inp.surf, inp.ret.origin_meas_m, inp.ret.direction_meas
    nrm = s.normal if tilt is None else _rotate(s.normal, tilt_axis, tilt)
    point = s.entry_m + np.column_stack([np.zeros((len(dh), 2)), dh])
    r, e = _on_plane(o, d, point, nrm, s.is_water)
    w = s.is_water[:, None]
    return dataclasses.replace(
        s,
        entry_m=np.where(w, e, s.entry_m),
        range_to_entry_m=np.where(w[:, 0], r, s.range_to_entry_m),
        normal=np.where(w, nrm, s.normal),
    )


def _white_evaluations(inp: _Inputs, st: TpuSettings):
    """``(name, sigma, f)`` of every term that goes through ``seabed_points``.

    ``sigma`` is (n,); ``f`` maps a signed perturbation (n,) to the points and depths (n, 4).
    """
    n = len(inp.row)
    zeros = np.zeros(n)
    ex, ey = np.tile([1.0, 0.0, 0.0], (n, 1)), np.tile([0.0, 1.0, 0.0], (n, 1))
    pa, pb = _perp_axes(inp.ret.direction_meas)
    d = inp.ret.direction_meas
    water = inp.surf.is_water
    jitter = np.radians(st.pointing_jitter_deg)
    fit_tilt = np.where(water, inp.surf.normal_sigma_rad / math.sqrt(2.0), 0.0)
    wave_tilt = np.where(water, st.wave_slope_sigma_rad, 0.0)

    def turn(axis):
        def f(a):
            d_new = _rotate(d, axis, a)
            ret, surf = _with_direction(inp, d_new / np.linalg.norm(d_new, axis=1, keepdims=True))
            return _xyzd(inp, ret=ret, surf=surf)

        return f

    def plane(axis=None):
        if axis is None:
            return lambda a: _xyzd(inp, surf=_with_plane(inp, a))
        return lambda a: _xyzd(inp, surf=_with_plane(inp, zeros, axis, a))

    return [
        ("timing_surface", inp.sig_ts, lambda a: _xyzd(inp, ret=_with_times(inp, a, zeros))),
        ("timing_bottom", inp.sig_tb, lambda a: _xyzd(inp, ret=_with_times(inp, zeros, a))),
        ("pointing_a", np.full(n, jitter), turn(pa)),
        ("pointing_b", np.full(n, jitter), turn(pb)),
        ("wave_height", inp.wave_h, plane()),
        ("wave_slope_x", wave_tilt, plane(ex)),
        ("wave_slope_y", wave_tilt, plane(ey)),
        ("surface_height", np.where(water, inp.surf.height_sigma_m, 0.0), plane()),
        ("surface_tilt_x", fit_tilt, plane(ex)),
        ("surface_tilt_y", fit_tilt, plane(ey)),
    ]


def _footprint(inp: _Inputs, xyz: np.ndarray, st: TpuSettings) -> np.ndarray:
    """Per-axis horizontal sigma ``D / 4`` of the bottom footprint (n,)."""
    gamma = st.beam_divergence_mrad * 1e-3
    o = inp.ret.origin_meas_m
    water = inp.surf.is_water
    r_air = np.where(water, inp.surf.range_to_entry_m, np.linalg.norm(xyz - o, axis=1))
    in_water = np.where(water, np.linalg.norm(xyz - inp.surf.entry_m, axis=1), 0.0)
    return gamma * (r_air + in_water / inp.rst.phase_index) / 4.0


def _terms(inp: _Inputs, st: TpuSettings, names=None) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """The nominal points ``(n, 4)`` and the one-sigma term rows ``(n, 4)`` asked for."""
    n = len(inp.row)
    xyzd0 = _xyzd(inp) if n else np.zeros((0, 4))
    want = set(RANDOM_TERMS + CORRELATED_TERMS) if names is None else set(names)
    terms: dict[str, np.ndarray] = {}
    for name, sigma, f in _white_evaluations(inp, st):
        if name not in want:
            continue
        h = 0.01 * sigma  # a small fraction of the sigma: the tangent, not a secant
        if n == 0 or not np.any(h > 0):
            terms[name] = np.zeros((n, 4))
            continue
        jac = (f(h) - f(-h)) / np.where(h > 0, 2.0 * h, 1.0)[:, None]
        terms[name] = _at_measured(jac * sigma[:, None], inp.grad)
    for name, (dp, dg) in index_derivatives(st).items():
        if name not in want:
            continue
        sig = st.temperature_sigma_c if name == "temperature" else st.salinity_sigma_psu
        h = 0.01 * sig
        if n == 0 or h == 0.0:
            terms[name] = np.zeros((n, 4))
            continue

        def shifted(sign, dp=dp, dg=dg, h=h):
            r = dataclasses.replace(
                inp.rst,
                phase_index=inp.rst.phase_index + sign * h * dp,
                group_index=inp.rst.group_index + sign * h * dg,
            )
            return _xyzd(inp, rst=r)

        terms[name] = _at_measured((shifted(1.0) - shifted(-1.0)) / (2.0 * h) * sig, inp.grad)
    # rigid motions of the whole measured scene (exact): a rotation w about the origin keeps
    # the distance from the point to its (rotated) plane, N . (E - B); the depth is that over
    # N_z, so it changes by -depth (w x N)_z / N_z
    arm = xyzd0[:, :3] - inp.ret.origin_meas_m
    nrm = inp.surf.normal
    tilt, head = np.radians(st.attitude_sigma_deg), np.radians(st.heading_sigma_deg)
    for name, axis, sig in (
        ("attitude_x", [1.0, 0.0, 0.0], tilt),
        ("attitude_y", [0.0, 1.0, 0.0], tilt),
        ("heading", [0.0, 0.0, 1.0], head),
    ):
        if name not in want:
            continue
        w = sig * np.asarray(axis)
        dz_n = np.cross(w, nrm)[:, 2]
        ddepth = -xyzd0[:, DEPTH] * dz_n / np.where(np.abs(nrm[:, 2]) > 0, nrm[:, 2], 1.0)
        terms[name] = _at_measured(np.column_stack([np.cross(w, arm), ddepth]), inp.grad)
    if "navigation" in want:
        nav = np.tile([st.position_sigma_h_m, st.position_sigma_h_m, st.position_sigma_v_m], (n, 1))
        # a translation moves surface and seabed alike: only the sideways part, over the slope
        nav_depth = st.position_sigma_h_m * np.hypot(inp.grad[:, 0], inp.grad[:, 1])
        terms["navigation"] = np.column_stack([nav, nav_depth])
    if "footprint" in want:
        fp = _footprint(inp, xyzd0[:, :3], st) if n else np.zeros(0)
        slope = math.tan(math.radians(st.seabed_slope_deg))
        terms["footprint"] = np.column_stack([fp, fp, fp * slope, np.zeros(n)])
    return xyzd0, terms


def point_tpu(
    returns: DetectedReturns,
    surface: WaterSurface,
    refraction_settings: RefractionSettings | None = None,
    settings: TpuSettings | None = None,
    *,
    seabed_gradient: Any = None,
    surface_tilt_sigma_rad: Any = None,
) -> PointTpu:
    """First-order propagated uncertainty of the refraction-corrected bottom points.

    Parameters
    ----------
    returns : DetectedReturns
    surface : WaterSurface
        The fitted surface of the same pulses.
    refraction_settings : RefractionSettings, optional
        Water indices used by the georeferencing.
    settings : TpuSettings, optional
    seabed_gradient : (n_bottom, 2) array_like, optional
        Depth gradient ``(d depth / dx, d depth / dy)`` of the seabed under each bottom point
        (rows of :func:`~pipeline.process.refraction.seabed_points`), from the measured
        soundings (:func:`seabed_gradient`); it couples the horizontal errors into the depth
        compared at the measured position. Default: a flat seabed.
    surface_tilt_sigma_rad : (n_bottom,) array_like, optional
        A measured tilt uncertainty of each bottom pulse's local water plane
        (:func:`surface_tilt_sigma`); the fitted-tilt terms use the larger of it and the fit's
        own standard error (``WaterSurface.normal_sigma_rad``). Default: the fit's alone.

    Returns
    -------
    PointTpu
        One row per pulse with a bottom return, in the order of
        :func:`~pipeline.process.refraction.seabed_points`.

    Raises
    ------
    NumericalError
        If a term is not finite (e.g. a beam grazing its perturbed surface).
    """
    st = settings or TpuSettings()
    rst = refraction_settings or RefractionSettings()
    inp = _inputs(returns, surface, rst, st, seabed_gradient, surface_tilt_sigma_rad)
    n = len(inp.row)
    xyzd0, terms = _terms(inp, st)

    def var(names):
        v = np.zeros((n, 4))
        for k in names:
            v += terms[k] ** 2
        return v

    vr, vc = var(RANDOM_TERMS), var(CORRELATED_TERMS)
    vt = vr + vc
    if not np.all(np.isfinite(vt)):
        bad = int(np.flatnonzero(~np.all(np.isfinite(vt), axis=1))[0])
        names = [k for k, v in terms.items() if not np.all(np.isfinite(v[bad]))]
        raise NumericalError(
            f"TPU of pulse {int(inp.ret.pulse_id[bad])} is not finite (terms {', '.join(names)})"
        )
    return PointTpu(
        row=inp.row,
        pulse_id=inp.ret.pulse_id,
        xyz_m=xyzd0[:, :3],
        terms=terms,
        sigma_x_m=np.sqrt(vt[:, X]),
        sigma_y_m=np.sqrt(vt[:, Y]),
        sigma_v_m=np.sqrt(vt[:, Z]),
        sigma_h_m=np.sqrt(0.5 * (vt[:, X] + vt[:, Y])),
        sigma_v_random_m=np.sqrt(vr[:, Z]),
        sigma_v_correlated_m=np.sqrt(vc[:, Z]),
        sigma_h_random_m=np.sqrt(0.5 * (vr[:, X] + vr[:, Y])),
        sigma_h_correlated_m=np.sqrt(0.5 * (vc[:, X] + vc[:, Y])),
        sigma_depth_m=np.sqrt(vt[:, DEPTH]),
        sigma_depth_random_m=np.sqrt(vr[:, DEPTH]),
        sigma_depth_correlated_m=np.sqrt(vc[:, DEPTH]),
    )


def _plane_fit(w, dx, dy, z, ridge):
    """Batched weighted least-squares planes ``z = a + b dx + c dy``, ridge ``ridge`` on b, c."""
    sw = w.sum(1)
    sx, sy = (w * dx).sum(1), (w * dy).sum(1)
    a = np.empty((len(sw), 3, 3))
    a[:, 0, 0] = sw
    a[:, 0, 1] = a[:, 1, 0] = sx
    a[:, 0, 2] = a[:, 2, 0] = sy
    a[:, 1, 1] = (w * dx * dx).sum(1) + ridge * sw
    a[:, 2, 2] = (w * dy * dy).sum(1) + ridge * sw
    a[:, 1, 2] = a[:, 2, 1] = (w * dx * dy).sum(1)
    bad = sw < 3
    a[bad] = np.eye(3)
    rhs = np.stack([(w * z).sum(1), (w * dx * z).sum(1), (w * dy * z).sum(1)], axis=1)
    rhs[bad] = 0.0
    return np.linalg.solve(a, rhs[:, :, None])[:, :, 0]


def _group_means(group, xy, dep):
    """Mean position and depth of each group of soundings."""
    _, inv = np.unique(np.asarray(group).ravel(), return_inverse=True)
    cnt = np.bincount(inv).astype(np.float64)
    xy = np.column_stack([np.bincount(inv, weights=xy[:, k]) / cnt for k in range(2)])
    return xy, np.bincount(inv, weights=dep) / cnt


def seabed_gradient(
    xy_m: Any,
    depth_m: Any,
    query_xy_m: Any = None,
    *,
    group: Any = None,
    neighbours: int = 16,
    radius_m: float = 10.0,
    ridge_m: float = 0.05,
    chunk: int = 200_000,
) -> np.ndarray:
    """Depth gradient of the seabed from measured soundings, ``(m, 2)`` (m/m).

    At each query point (default: each sounding), a plane ``depth = a + b dx + c dy`` through
    the ``neighbours`` nearest soundings within ``radius_m``, by least squares with one robust
    pass (residuals beyond 3 × 1.4826 MAD, at least 1 cm, dropped). A ridge of
    ``count * ridge_m²`` on ``(b, c)`` keeps collinear soundings (a profiler track) solvable:
    the slope across them tends to 0. Fewer than 3 soundings: 0.

    Parameters
    ----------
    xy_m : (n, 2) array_like
        Horizontal positions of the soundings.
    depth_m : (n,) array_like
        Their depths (positive down).
    query_xy_m : (m, 2) array_like, optional
    group : (n,) array_like, optional
        Soundings sharing one detection (a photon-counting window's shots: one depth) carry
        the same label and count as one, at their mean.
    """
    xy = np.asarray(xy_m, dtype=np.float64).reshape(-1, 2)
    dep = np.asarray(depth_m, dtype=np.float64).ravel()
    q = xy if query_xy_m is None else np.asarray(query_xy_m, dtype=np.float64).reshape(-1, 2)
    if group is not None:
        xy, dep = _group_means(group, xy, dep)
    out = np.zeros((len(q), 2))
    if len(xy) < 3 or len(q) == 0:
        return out
    tree = cKDTree(xy)
    k = min(neighbours, len(xy))
    for lo in range(0, len(q), chunk):
        qq = q[lo : lo + chunk]
        _, idx = tree.query(qq, k=k, distance_upper_bound=radius_m, workers=-1)
        idx = np.asarray(idx).reshape(len(qq), k)
        valid = idx < len(xy)
        ic = np.where(valid, idx, 0)
        dx = np.where(valid, xy[ic, 0] - qq[:, :1], 0.0)
        dy = np.where(valid, xy[ic, 1] - qq[:, 1:], 0.0)
        z = np.where(valid, dep[ic], 0.0)
        w = valid.astype(np.float64)
        p = _plane_fit(w, dx, dy, z, ridge_m**2)
        r = np.abs(z - (p[:, :1] + p[:, 1:2] * dx + p[:, 2:3] * dy))
        scale = _MAD_TO_SIGMA * _masked_median(r, valid)
        keep = valid & (r <= np.maximum(3.0 * scale, 0.01)[:, None])
        w = keep.astype(np.float64)
        p = _plane_fit(w, dx, dy, z, ridge_m**2)
        out[lo : lo + chunk] = np.where((w.sum(1) >= 3)[:, None], p[:, 1:], 0.0)
    return out


def pair_scatter(
    xy_m: Any,
    depth_m: Any,
    gradient: Any = None,
    *,
    order: Any = None,
    group: Any = None,
    query_xy_m: Any = None,
    max_separation_m: float = 2.0,
    neighbours: int = 64,
) -> np.ndarray:
    """Local one-sigma random depth error of the soundings, measured from pairs of them.

    Each sounding (or each ``group`` of soundings sharing one detection, e.g. the shots of a
    photon-counting window, taken at their mean) is paired with the next one in ``order``
    (the acquisition order: the pulse number), or without ``order`` with its nearest one, if it
    lies within ``max_separation_m``. Their depth difference less the local slope times their
    separation, ``D = d_i - d_j - g . (p_i - p_j)``, holds the two soundings' own random errors
    (timing, jitter, relief at the footprint scale) and not what they share (navigation, the
    water surface over them, water indices): ``E[D²] = s_i² + s_j²``. Successive pulses share
    nearly all but their own noise, which makes ``order`` the clean choice. At each query point
    (default: each sounding) the estimate is ``sqrt(mean(D² / 2))`` over the ``neighbours``
    nearest pairs. ``gradient`` (``(n, 2)``, :func:`seabed_gradient`) defaults to the one of
    the (grouped) soundings themselves: a group's shots share one depth, so only the groups
    show the slope.

    Returns
    -------
    (m,) float64
        NaN where no pair exists at all.
    """
    xy = np.asarray(xy_m, dtype=np.float64).reshape(-1, 2)
    dep = np.asarray(depth_m, dtype=np.float64).ravel()
    g = None if gradient is None else np.asarray(gradient, dtype=np.float64).reshape(-1, 2)
    key = None if order is None else np.asarray(order, dtype=np.float64).ravel()
    q = xy if query_xy_m is None else np.asarray(query_xy_m, dtype=np.float64).reshape(-1, 2)
    if group is not None:
        _, inv = np.unique(np.asarray(group).ravel(), return_inverse=True)
        cnt = np.bincount(inv).astype(np.float64)
        if g is not None:
            g = np.column_stack([np.bincount(inv, weights=g[:, k]) / cnt for k in range(2)])
        xy, dep = _group_means(group, xy, dep)
        if key is not None:
            first = np.full(len(cnt), np.inf)
            np.minimum.at(first, inv, key)
            key = first
    out = np.full(len(q), np.nan)
    if len(xy) < 2 or len(q) == 0:
        return out
    if g is None:
        g = seabed_gradient(xy, dep)
    if key is None:
        _, idx = cKDTree(xy).query(xy, k=2, workers=-1)
        i, j = np.arange(len(xy)), idx[:, 1]
    else:
        seq = np.argsort(key, kind="stable")
        i, j = seq[:-1], seq[1:]
    sep = xy[i] - xy[j]
    ok = np.hypot(sep[:, 0], sep[:, 1]) <= max_separation_m
    i, j, sep = i[ok], j[ok], sep[ok]
    if i.size == 0:
        return out
    diff = dep[i] - dep[j] - np.sum(0.5 * (g[i] + g[j]) * sep, axis=1)
    half_sq = 0.5 * diff**2
    k = min(neighbours, half_sq.size)
    _, near = cKDTree(0.5 * (xy[i] + xy[j])).query(q, k=k, workers=-1)
    near = np.asarray(near).reshape(len(q), k)
    return np.sqrt(np.mean(half_sq[near], axis=1))


def surface_over_sounding(
    returns: DetectedReturns, surface: WaterSurface, xy_m: Any
) -> tuple[np.ndarray, np.ndarray]:
    """How the water plane of each bottom pulse turns against the surface over its sounding.

    A sounding's depth is measured below its own pulse's local plane (fitted around the water
    entry ``E``), read at the sounding ``B``, ``Delta`` away horizontally (the refracted beam's
    offset, about a quarter of the depth at 20°). The surface measured over the sounding is the
    local plane of the surface return nearest to ``B``. The difference of the two planes'
    heights at ``B`` less their difference at ``E`` is ``T = (s_B - s_E) . (B - E)``, their
    slopes' difference times the offset: free of any height offset between the two fits (e.g.
    navigation heights that differ between the passes that sampled them, which the depth does
    not see), it holds the two planes' tilt errors and the bending of the waves between ``E``
    and ``B`` that one plane cannot follow. Where ``B`` lies within the fit's own
    neighbourhood the two planes share their points and ``T`` understates the tilt error.

    Parameters
    ----------
    returns, surface
        As for :func:`point_tpu`.
    xy_m : (n_bottom, 2) array_like
        The soundings (rows of :func:`~pipeline.process.refraction.seabed_points`).

    Returns
    -------
    T_m, Delta_m : (n_bottom,) float64
        ``T`` is NaN where the pulse does not enter water or no surface return exists.
    """
    rows = np.flatnonzero(returns.has_bottom)
    xy = np.asarray(xy_m, dtype=np.float64).reshape(-1, 2)
    if xy.shape[0] != rows.size:
        raise ValueError(f"`xy_m` must be (n_bottom, 2) = ({rows.size}, 2); got {xy.shape}")
    entry = surface.entry_m[rows, :2]
    delta = np.hypot(*(xy - entry).T)
    ws = np.flatnonzero(surface.is_water & returns.has_surface)
    if ws.size == 0 or rows.size == 0:
        return np.full(rows.size, np.nan), delta
    _, j = cKDTree(surface.surface_point_m[ws, :2]).query(xy, k=1, workers=-1)

    def apart(x, y):  # the plane over the sounding less the pulse's own, at (x, y)
        return surface.surface_z_m(ws[j], x, y) - surface.surface_z_m(rows, x, y)

    turn = apart(xy[:, 0], xy[:, 1]) - apart(entry[:, 0], entry[:, 1])
    return np.where(surface.is_water[rows], turn, np.nan), delta


def _binned_mean(x, v, query, *, per_bin=100, max_bins=40):
    """Mean of ``v`` in equal-count bins of ``x``, interpolated at ``query`` (clamped)."""
    ok = np.isfinite(x) & np.isfinite(v)
    x, v = x[ok], v[ok]
    if x.size == 0:
        return np.full(np.shape(query), np.nan)
    order = np.argsort(x)
    x, v = x[order], v[order]
    nb = int(min(max(x.size // per_bin, 1), max_bins))
    edges = np.linspace(0, x.size, nb + 1).astype(np.int64)
    cx = np.array([np.median(x[a:b]) for a, b in zip(edges[:-1], edges[1:], strict=True)])
    cv = np.array([np.mean(v[a:b]) for a, b in zip(edges[:-1], edges[1:], strict=True)])
    return np.interp(query, cx, cv)


def surface_tilt_sigma(
    returns: DetectedReturns,
    surface: WaterSurface,
    xy_m: Any,
    *,
    pool: Any = None,
    min_offset_m: float = 0.25,
) -> np.ndarray:
    """Tilt uncertainty of each bottom pulse's water plane, measured over its sounding (rad).

    The fit's own standard error (``WaterSurface.normal_sigma_rad``) assumes independent
    residuals: it sees neither the waves its neighbourhood does not follow nor the misfit of
    neighbours flown at different times (navigation errors that differ between the passes).
    The turn ``T`` of the pulse's plane against the plane over its sounding
    (:func:`surface_over_sounding`) measures both: with the two fits' tilt errors alike, of
    per-axis sigma ``tau``, ``E[T²] = 2 tau² Delta²``. ``E[T²]`` is averaged in bins of
    ``Delta`` over the ``pool`` rows (default all: a wave field is the same over a survey,
    and a single ``T`` is that point's error, not its spread). Returned as the total
    ``sqrt(2) tau``, like ``normal_sigma_rad``; 0 below ``min_offset_m`` and where the pulse
    does not enter water.

    Parameters
    ----------
    xy_m : (n_bottom, 2) array_like
        The soundings (rows of :func:`~pipeline.process.refraction.seabed_points`).
    pool : array_like of int or bool, optional
        The rows averaged (e.g. the bathymetric points').
    """
    rows = np.flatnonzero(returns.has_bottom)
    turn, delta = surface_over_sounding(returns, surface, xy_m)
    sel = np.arange(rows.size) if pool is None else np.asarray(pool)
    mst = np.maximum(np.nan_to_num(_binned_mean(delta[sel], (turn**2)[sel], delta)), 0.0)
    tilt = np.sqrt(mst) / np.maximum(delta, min_offset_m)
    ok = surface.is_water[rows] & (delta >= min_offset_m)
    return np.where(ok, tilt, 0.0)


def timing_from_scatter(
    returns: DetectedReturns,
    surface: WaterSurface,
    refraction_settings: RefractionSettings | None = None,
    settings: TpuSettings | None = None,
    *,
    depth_scatter_m: Any,
    seabed_gradient: Any = None,
) -> DetectedReturns:
    """``returns`` with the per-return timing sigmas that the measured depth scatter implies.

    For a detector that reports no timing sigma: the timing terms' depth variance is set to the
    measured random scatter of the soundings (:func:`pair_scatter`) less the other random
    terms', ``s_t² = max(scatter² - other², 0)``. With the pulse's own surface return the depth
    depends on ``t_b - t_s`` only, so the split between the two returns does not change it; it
    is made as for photon-limited timing, variance in proportion to ``1 / amplitude``
    (equal without amplitudes). Rows with a NaN scatter keep the a-priori sigma.

    Parameters
    ----------
    depth_scatter_m : (n_bottom,) array_like
        Measured one-sigma random depth error of each bottom point (rows of
        :func:`~pipeline.process.refraction.seabed_points`).
    seabed_gradient : (n_bottom, 2) array_like, optional
        As for :func:`point_tpu`.
    """
    st = settings or TpuSettings()
    rst = refraction_settings or RefractionSettings()
    unit = 1e-10
    st_unit = dataclasses.replace(st, timing_sigma_s=unit)
    bare = dataclasses.replace(returns, t_surface_sigma_s=None, t_bottom_sigma_s=None)
    inp = _inputs(bare, surface, rst, st_unit, seabed_gradient)
    n = len(inp.row)
    scatter = np.asarray(depth_scatter_m, dtype=np.float64).ravel()
    if scatter.shape != (n,):
        raise ValueError(f"`depth_scatter_m` must be (n_bottom,) = ({n},); got {scatter.shape}")
    _, terms = _terms(inp, st_unit, RANDOM_TERMS)
    js = terms["timing_surface"][:, DEPTH] / unit
    jb = terms["timing_bottom"][:, DEPTH] / unit
    other = sum(terms[k][:, DEPTH] ** 2 for k in RANDOM_TERMS if k not in TIMING_TERMS)
    excess = np.maximum(np.nan_to_num(scatter) ** 2 - other, 0.0)
    ret = inp.ret
    hs = ret.has_surface

    def inv_amp(a):
        if a is None:
            return np.ones(n)
        a = np.asarray(a, dtype=np.float64)
        pos = a > 0
        fill = np.median(a[pos]) if pos.any() else 1.0
        return 1.0 / np.where(pos, a, fill)

    ws = np.where(hs, inv_amp(ret.surface_amplitude), 0.0)
    wb = inv_amp(ret.bottom_amplitude)
    den = ws * js**2 + wb * jb**2
    c = np.where(den > 0, excess / np.where(den > 0, den, 1.0), 0.0)
    floor = 1e-15  # sigmas must be > 0 where a return exists
    prior_s = returns.t_surface_sigma_s
    prior_b = returns.t_bottom_sigma_s
    sig_s = np.where(returns.has_surface, st.timing_sigma_s, 0.0) if prior_s is None else prior_s
    sig_b = np.where(returns.has_bottom, st.timing_sigma_s, 0.0) if prior_b is None else prior_b
    sig_s, sig_b = np.array(sig_s, dtype=np.float64), np.array(sig_b, dtype=np.float64)
    use = np.isfinite(scatter)
    rows = inp.row[use]
    sig_b[rows] = np.maximum(np.sqrt(wb * c)[use], floor)
    sig_s[rows] = np.where(hs[use], np.maximum(np.sqrt(ws * c)[use], floor), 0.0)
    sig_s = np.where(returns.has_surface, np.maximum(sig_s, floor), 0.0)
    sig_b = np.where(returns.has_bottom, np.maximum(sig_b, floor), 0.0)
    return dataclasses.replace(returns, t_surface_sigma_s=sig_s, t_bottom_sigma_s=sig_b)


def monte_carlo_points(
    returns: DetectedReturns,
    surface: WaterSurface,
    refraction_settings: RefractionSettings | None = None,
    settings: TpuSettings | None = None,
    *,
    n_draws: int = 1000,
    seed: int = 0,
    seabed_gradient: Any = None,
    surface_tilt_sigma_rad: Any = None,
) -> np.ndarray:
    """Seabed points recomputed with every TPU input redrawn, ``(n_draws, n, 4)``.

    Columns: x, y, z and the depth at the measured position (the perturbed point's depth less
    ``g . (dx, dy)``, its horizontal displacement over the seabed gradient; see
    :func:`point_tpu`). Each draw perturbs the navigation (the origin, the beam and the fitted
    planes moved and turned together: the rigid-motion model), the per-pulse jitter, times and
    planes, and the water's temperature and salinity (both indices), then calls
    :func:`~pipeline.process.refraction.seabed_points`; the footprint centroid offset is added
    last to x, y, z (it is not a georeferencing input; over a plane it leaves the depth).
    Full-size (not infinitesimal) perturbations: the check of :func:`point_tpu`'s
    linearisation.
    """
    st = settings or TpuSettings()
    rst = refraction_settings or RefractionSettings()
    inp = _inputs(returns, surface, rst, st, seabed_gradient, surface_tilt_sigma_rad)
    n = len(inp.row)
    rng = np.random.default_rng(seed)
    out = np.empty((n_draws, n, 4))
    ex, ey, ez = (np.tile(v, (n, 1)) for v in np.eye(3))
    o0, d0 = inp.ret.origin_meas_m, inp.ret.direction_meas
    water = inp.surf.is_water
    deriv = index_derivatives(st)
    jitter = np.radians(st.pointing_jitter_deg)
    tilt, head = np.radians(st.attitude_sigma_deg), np.radians(st.heading_sigma_deg)
    fit_tilt = np.where(water, inp.surf.normal_sigma_rad / math.sqrt(2.0), 0.0)
    wave_tilt = np.where(water, st.wave_slope_sigma_rad, 0.0)
    nominal = _xyzd(inp)
    fp = _footprint(inp, nominal[:, :3], st)
    slope = math.tan(math.radians(st.seabed_slope_deg))
    pa, pb = _perp_axes(d0)
    for k in range(n_draws):
        g = rng.standard_normal((n, 16))
        # per-pulse: jitter, times, planes (fit and waves)
        d = _rotate(_rotate(d0, pa, jitter * g[:, 0]), pb, jitter * g[:, 1])
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        dh = np.where(water, inp.surf.height_sigma_m * g[:, 2] + inp.wave_h * g[:, 3], 0.0)
        nrm = _rotate(inp.surf.normal, ex, fit_tilt * g[:, 4] + wave_tilt * g[:, 5])
        nrm = _rotate(nrm, ey, fit_tilt * g[:, 6] + wave_tilt * g[:, 7])
        point = inp.surf.entry_m + np.column_stack([np.zeros((n, 2)), dh])
        # rigid motion of the scene about each origin: rotation, then translation
        rot_angles = np.column_stack([tilt * g[:, 8], tilt * g[:, 9], head * g[:, 10]])
        shift = g[:, 11:14] * [st.position_sigma_h_m, st.position_sigma_h_m, st.position_sigma_v_m]

        def rigid(v, about=None, rot_angles=rot_angles):
            w = v if about is None else v - about
            for j, ax in enumerate((ex, ey, ez)):
                w = _rotate(w, ax, rot_angles[:, j])
            return w if about is None else w + about

        d = rigid(d)
        nrm = rigid(nrm)
        point = rigid(point, o0) + shift
        o = o0 + shift
        r, e = _on_plane(o, d, point, nrm, water)
        ret = dataclasses.replace(
            inp.ret,
            origin_meas_m=o,
            direction_meas=d,
            t_surface_s=np.where(
                inp.ret.has_surface, inp.ret.t_surface_s + inp.sig_ts * g[:, 14], 0.0
            ),
            t_bottom_s=inp.ret.t_bottom_s + inp.sig_tb * g[:, 15],
        )
        w = water[:, None]
        surf = dataclasses.replace(
            inp.surf,
            entry_m=np.where(w, e, inp.surf.entry_m),
            range_to_entry_m=np.where(water, r, inp.surf.range_to_entry_m),
            normal=np.where(w, nrm, inp.surf.normal),
        )
        dt_, ds_ = rng.standard_normal(2)
        (tp, tg), (sp, sg) = deriv["temperature"], deriv["salinity"]
        dtemp, dsal = st.temperature_sigma_c * dt_, st.salinity_sigma_psu * ds_
        r_set = dataclasses.replace(
            rst,
            phase_index=rst.phase_index + tp * dtemp + sp * dsal,
            group_index=rst.group_index + tg * dtemp + sg * dsal,
        )
        p = seabed_points(ret, surf, r_set)
        out[k, :, :3] = p.xyz_m
        moved = p.xyz_m[:, :2] - nominal[:, :2]
        out[k, :, DEPTH] = p.depth_m - np.sum(inp.grad * moved, axis=1)
        out[k, :, :2] += rng.standard_normal((n, 2)) * fp[:, None]
        out[k, :, 2] += fp * slope * rng.standard_normal(n)
    return out
