"""Total propagated uncertainty (TPU) of the refraction-corrected seabed points, first order.

Every input error is propagated through the processing's own georeferencing,
:func:`pipeline.process.refraction.seabed_points`, by central differences (vectorised: one call
per perturbed input for all points), except the rigid motions, whose effect is exact and
analytic. One-sigma terms are independent and add in quadrature per coordinate.

Terms (defaults in :class:`TpuSettings`; ``R`` random per pulse, ``C`` correlated over a
grid cell: does not average down in a cell mean)
----------------------------------------------------------------------------------------------
=====================  ==  ====================================================================
navigation position    C   GNSS/INS error, slowly varying: the aircraft, its surface points and
                           the fitted surface move together, so the seabed point moves by the
                           same vector ``(s_h, s_h, s_v)``.
attitude               C   IMU roll/pitch (isotropic tilt ``s_tilt``, so the aircraft heading
                           is not needed) and heading ``s_head``: the whole measured scene
                           rotates about the laser origin, ``dB = w x (B - o)``.
surface fit height     C   standard error of the fitted plane at the entry point.
surface fit tilt       C   standard error of the fitted tilt (``normal_sigma_rad / sqrt 2`` per
                           axis), the plane turned about the entry point.
water temperature,     C   unknown water mass: both indices move together, with the
salinity                   derivatives of Quan & Fry (1995) (:mod:`pipeline.optics`).
timing (surface,       R   the detector's per-return sigma (``DetectedReturns.t_*_sigma_s``), or
bottom)                    ``timing_sigma_s``; :func:`timing_sigma_s` gives it from the SNR.
pointing jitter        R   per-pulse beam direction noise (scanner encoder), two axes.
wave height            R   the local water surface off its fitted plane: the fit's residual
                           sigma in excess of its points' ranging noise.
wave slope             R   facet slope under the footprint not in the fitted plane
                           (``wave_slope_sigma_rad`` per axis; :func:`cox_munk_slope_sigma`).
footprint              R   the return's centroid within the beam footprint: per horizontal axis
                           ``D / 4`` (Gaussian beam, ``D`` its 1/e² diameter at the bottom
                           ``gamma (r_air + L / n_w)``), vertically ``D / 4 tan(seabed slope)``.
=====================  ==  ====================================================================

The attenuation does not enter the georeferencing (only the waveform's timing, which the
posterior in :mod:`pipeline.process.posterior` covers).

Conventions
-----------
``sigma_v_m`` is the one-sigma error of the point's elevation ``z``; ``sigma_h_m`` is the
*per-axis* horizontal sigma of a circular normal, ``sqrt((s_x^2 + s_y^2) / 2)``. The IHO 95 %
values are ``1.96 sigma_v`` and ``2.45 sigma_h`` (:mod:`pipeline.iho`).
:func:`monte_carlo_points` redraws every input and recomputes the points with
:func:`~pipeline.process.refraction.seabed_points` (the check of the linearisation).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from pipeline.config import setting
from pipeline.errors import NumericalError
from pipeline.optics import SPEED_OF_LIGHT_M_S, water_group_index, water_phase_index
from pipeline.process.refraction import RefractionSettings, seabed_points
from pipeline.process.returns import DetectedReturns
from pipeline.process.surface_fit import WaterSurface

__all__ = [
    "TpuSettings",
    "PointTpu",
    "RANDOM_TERMS",
    "CORRELATED_TERMS",
    "point_tpu",
    "monte_carlo_points",
    "timing_sigma_s",
    "cox_munk_slope_sigma",
    "index_derivatives",
]

_C = SPEED_OF_LIGHT_M_S
FWHM_TO_SIGMA = 1.0 / (2.0 * math.sqrt(2.0 * math.log(2.0)))

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
    terms : dict of str to (n, 3) float64
        One-sigma displacement of the point per term (:data:`RANDOM_TERMS`,
        :data:`CORRELATED_TERMS`); ``navigation`` holds the three axis sigmas.
    sigma_x_m, sigma_y_m, sigma_v_m : (n,) float64
        Total one-sigma per coordinate (``sigma_v_m`` is z).
    sigma_h_m : (n,) float64
        Per-axis horizontal sigma ``sqrt((s_x² + s_y²) / 2)``.
    sigma_v_random_m, sigma_v_correlated_m, sigma_h_random_m, sigma_h_correlated_m : (n,)
        The same split into random and correlated terms.
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


def _inputs(returns, surface, rst, st) -> _Inputs:
    if len(surface) != len(returns):
        raise ValueError(f"`surface` has {len(surface)} pulses; `returns` has {len(returns)}")
    row = np.flatnonzero(returns.has_bottom)
    ret, surf = returns.select(row), _take_surface(surface, row)
    n = len(row)
    sig_ts = (
        np.full(n, st.timing_sigma_s) if ret.t_surface_sigma_s is None else ret.t_surface_sigma_s
    )
    sig_ts = np.where(ret.has_surface, sig_ts, 0.0)
    sig_tb = np.full(n, st.timing_sigma_s) if ret.t_bottom_sigma_s is None else ret.t_bottom_sigma_s
    # wave height: the fit residual in excess of the surface points' own ranging noise
    cos_i = np.abs(np.sum(ret.direction_meas * surf.normal, axis=1))
    ranging = _C * np.where(ret.has_surface, sig_ts, st.timing_sigma_s) / 2.0 * cos_i
    wave_h = np.sqrt(np.maximum(surf.fit_sigma_m**2 - ranging**2, 0.0))
    return _Inputs(ret, surf, rst, sig_ts, sig_tb, np.where(surf.is_water, wave_h, 0.0), row)


def _xyz(inp: _Inputs, *, ret=None, surf=None, rst=None) -> np.ndarray:
    return seabed_points(ret or inp.ret, surf or inp.surf, rst or inp.rst).xyz_m


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

    ``sigma`` is (n,); ``f`` maps a signed perturbation (n,) to the points (n, 3).
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
            return _xyz(inp, ret=ret, surf=surf)

        return f

    def plane(axis=None):
        if axis is None:
            return lambda a: _xyz(inp, surf=_with_plane(inp, a))
        return lambda a: _xyz(inp, surf=_with_plane(inp, zeros, axis, a))

    return [
        ("timing_surface", inp.sig_ts, lambda a: _xyz(inp, ret=_with_times(inp, a, zeros))),
        ("timing_bottom", inp.sig_tb, lambda a: _xyz(inp, ret=_with_times(inp, zeros, a))),
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


def point_tpu(
    returns: DetectedReturns,
    surface: WaterSurface,
    refraction_settings: RefractionSettings | None = None,
    settings: TpuSettings | None = None,
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
    inp = _inputs(returns, surface, rst, st)
    n = len(inp.row)
    xyz0 = _xyz(inp) if n else np.zeros((0, 3))
    terms: dict[str, np.ndarray] = {}
    for name, sigma, f in _white_evaluations(inp, st):
        h = 0.01 * sigma  # a small fraction of the sigma: the tangent, not a secant
        if n == 0 or not np.any(h > 0):
            terms[name] = np.zeros((n, 3))
            continue
        jac = (f(h) - f(-h)) / np.where(h > 0, 2.0 * h, 1.0)[:, None]
        terms[name] = jac * sigma[:, None]
    for name, (dp, dg) in index_derivatives(st).items():
        sig = st.temperature_sigma_c if name == "temperature" else st.salinity_sigma_psu
        h = 0.01 * sig
        if n == 0 or h == 0.0:
            terms[name] = np.zeros((n, 3))
            continue

        def shifted(sign, dp=dp, dg=dg, h=h):
            r = dataclasses.replace(
                rst,
                phase_index=rst.phase_index + sign * h * dp,
                group_index=rst.group_index + sign * h * dg,
            )
            return _xyz(inp, rst=r)

        terms[name] = (shifted(1.0) - shifted(-1.0)) / (2.0 * h) * sig
    # rigid motions of the whole measured scene (exact)
    arm = xyz0 - inp.ret.origin_meas_m
    tilt, head = np.radians(st.attitude_sigma_deg), np.radians(st.heading_sigma_deg)
    for name, axis, sig in (
        ("attitude_x", [1.0, 0.0, 0.0], tilt),
        ("attitude_y", [0.0, 1.0, 0.0], tilt),
        ("heading", [0.0, 0.0, 1.0], head),
    ):
        terms[name] = sig * np.cross(np.asarray(axis), arm)
    nav = [st.position_sigma_h_m, st.position_sigma_h_m, st.position_sigma_v_m]
    terms["navigation"] = np.tile(nav, (n, 1))
    fp = _footprint(inp, xyz0, st) if n else np.zeros(0)
    slope = math.tan(math.radians(st.seabed_slope_deg))
    terms["footprint"] = np.column_stack([fp, fp, fp * slope])

    def var(names):
        v = np.zeros((n, 3))
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
        xyz_m=xyz0,
        terms=terms,
        sigma_x_m=np.sqrt(vt[:, 0]),
        sigma_y_m=np.sqrt(vt[:, 1]),
        sigma_v_m=np.sqrt(vt[:, 2]),
        sigma_h_m=np.sqrt(0.5 * (vt[:, 0] + vt[:, 1])),
        sigma_v_random_m=np.sqrt(vr[:, 2]),
        sigma_v_correlated_m=np.sqrt(vc[:, 2]),
        sigma_h_random_m=np.sqrt(0.5 * (vr[:, 0] + vr[:, 1])),
        sigma_h_correlated_m=np.sqrt(0.5 * (vc[:, 0] + vc[:, 1])),
    )


def monte_carlo_points(
    returns: DetectedReturns,
    surface: WaterSurface,
    refraction_settings: RefractionSettings | None = None,
    settings: TpuSettings | None = None,
    *,
    n_draws: int = 1000,
    seed: int = 0,
) -> np.ndarray:
    """Seabed points recomputed with every TPU input redrawn, ``(n_draws, n, 3)``.

    Each draw perturbs the navigation (the origin, the beam and the fitted planes moved and
    turned together: the rigid-motion model), the per-pulse jitter, times and planes, and the
    water's temperature and salinity (both indices), then calls
    :func:`~pipeline.process.refraction.seabed_points`; the footprint centroid offset is added
    last (it is not a georeferencing input). Full-size (not infinitesimal) perturbations: the
    check of :func:`point_tpu`'s linearisation.
    """
    st = settings or TpuSettings()
    rst = refraction_settings or RefractionSettings()
    inp = _inputs(returns, surface, rst, st)
    n = len(inp.row)
    rng = np.random.default_rng(seed)
    out = np.empty((n_draws, n, 3))
    ex, ey, ez = (np.tile(v, (n, 1)) for v in np.eye(3))
    o0, d0 = inp.ret.origin_meas_m, inp.ret.direction_meas
    water = inp.surf.is_water
    deriv = index_derivatives(st)
    jitter = np.radians(st.pointing_jitter_deg)
    tilt, head = np.radians(st.attitude_sigma_deg), np.radians(st.heading_sigma_deg)
    fit_tilt = np.where(water, inp.surf.normal_sigma_rad / math.sqrt(2.0), 0.0)
    wave_tilt = np.where(water, st.wave_slope_sigma_rad, 0.0)
    nominal = _xyz(inp)
    fp = _footprint(inp, nominal, st)
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
        xyz = seabed_points(ret, surf, r_set).xyz_m
        out[k] = xyz
        out[k, :, :2] += rng.standard_normal((n, 2)) * fp[:, None]
        out[k, :, 2] += fp * slope * rng.standard_normal(n)
    return out
