"""Total propagated uncertainty (TPU) of the refraction-corrected seabed points, first order.

Every input error is propagated through the processing's own georeferencing,
:func:`pipeline.process.refraction.seabed_points`, by central differences (vectorised: one call
per perturbed input for all points; one derivative per input moved, shared by the terms that
move it and with :func:`timing_from_scatter`'s pass), except the rigid motions, whose effect
is exact and analytic. One-sigma terms are independent and add in quadrature per coordinate.

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
surface fit height     C   standard error of the fitted plane at the entry point: moves the
                           entry by ``1 - w`` of it (``w``: the own echo's weight,
                           ``WaterSurface.own_weight``; 0 without an own return) and the path
                           timed from it; the depth, below the plane, by the rest.
surface fit tilt       C   tilt sigma of the fitted plane (``/ sqrt 2`` per axis), the plane
                           turned about the entry point: the fit's standard error
                           (``normal_sigma_rad``) or, if larger, the tilt measured over the
                           sounding (:func:`surface_tilt_sigma`: how the plane turns against
                           the plane fitted over the sounding; waves the plane does not follow,
                           misfit of neighbours from passes with different navigation errors).
                           Depth: the plane's height at the sounding and the refraction.
water temperature,     C   unknown water mass: both indices move together, with the
salinity                   derivatives of Quan & Fry (1995) (:mod:`pipeline.optics`).
forward scattering     C   the processing's forward-scattering correction
                           (:mod:`pipeline.process.scatter_bias`) wrong by its
                           ``process.forward_scatter.relative_sigma``: one water per survey.
timing (surface,       R   the detector's per-return sigma (``DetectedReturns.t_*_sigma_s``), or
bottom)                    ``timing_sigma_s``; the full-waveform detector gives each echo's
                           from its own amplitude, width and noise
                           (:mod:`pipeline.process.detect_precision`: a wave-spread surface,
                           the calm-water volume onset, a stretched bottom are timed worse than
                           the system's Cramér–Rao bound :func:`timing_sigma_s`). The measured
                           scatter of successive soundings (:func:`pair_scatter`), which holds
                           each pulse's own noise and not what neighbours share, raises it
                           where it shows more (:func:`timing_from_scatter`, ``raise_only``)
                           or sets it when the detector gives none (photon counting).
pointing jitter        R   per-pulse beam direction noise (scanner encoder), two axes.
wave height            R   the local water surface off its fitted plane: the fit's residual
                           variance in excess of its points' ranging noise, averaged over a
                           cell of ``wave_pool_cell_m`` (:mod:`pipeline.uncertainty.wave_pool`;
                           as the fit height: with the own echo it is mostly in the depth
                           below the plane).
wave slope             R   facet slope under the footprint not in the fitted plane
                           (``wave_slope_sigma_rad`` per axis; :func:`cox_munk_slope_sigma`).
                           Default 0: the survey then measures it (``wave_facet_along/across``,
                           :mod:`pipeline.uncertainty.tpu_facet`: the sea's slope the fitted
                           planes do not follow, from the surface variogram's ``a h²`` rise;
                           refraction only, added after this function).
footprint              R   the return's centroid within the beam footprint: per horizontal axis
                           ``D / 4`` (Gaussian beam, ``D`` its 1/e² diameter at the bottom
                           ``gamma (r_air + L / n_w)``), vertically ``D / 4 tan(seabed slope)``.
                           Depth: zero (over a plane the centroid of the return is the beam
                           centre's range; relief within the footprint shows in the measured
                           scatter, :func:`pair_scatter`).
=====================  ==  ====================================================================

The attenuation does not enter the georeferencing (only the waveform's timing, which the
posterior in :mod:`pipeline.uncertainty.posterior` covers). Systematic detector biases (a green
surface return late in waves, the first-photon bias of a dead-time-limited photon counter (now
corrected by the detector, :mod:`pipeline.process.photon_livetime`), the
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
The survey also measures the water surface from its own surface returns
(:mod:`pipeline.uncertainty.tpu_measured`): the nugget of their height variogram raises each
surface timing sigma (the ranging error a calm-water onset or a spread echo makes, which the
per-echo bound misses), and its wave part at each sounding's entry offset adds one more random
depth term, ``wave_entry``, beyond what the fitted plane's tilt terms hold.
A photon-counting window's shots share one detected depth: the survey adds the spread of the
seabed plane under them as one more random term
(:mod:`pipeline.uncertainty.tpu_window`, :func:`~pipeline.uncertainty.tpu_window.
window_footprint_sigma_m`).
Pulses the linearisation cannot hold (a timing sigma reaching the surface-bottom separation, a
term not finite) are left out and counted, never fatal (:mod:`pipeline.uncertainty.tpu_screen`).
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from pipeline.process.refraction import RefractionSettings
from pipeline.process.returns import DetectedReturns
from pipeline.process.surface_fit import WaterSurface
from pipeline.uncertainty.tpu_derivatives import Derivatives
from pipeline.uncertainty.tpu_monte_carlo import monte_carlo_points
from pipeline.uncertainty.tpu_neighbours import (
    pair_scatter,
    seabed_gradient,
    surface_over_sounding,
    surface_tilt_sigma,
    timing_from_scatter,
)
from pipeline.uncertainty.tpu_screen import (
    TERM_NOT_FINITE,
    LeftOut,
    timing_unresolved,
)
from pipeline.uncertainty.tpu_settings import (
    CORRELATED_TERMS,
    DEPTH,
    RANDOM_TERMS,
    TIMING_TERMS,
    PointTpu,
    TpuSettings,
    X,
    Y,
    Z,
    cox_munk_slope_sigma,
    index_derivatives,
    timing_sigma_s,
)
from pipeline.uncertainty.tpu_terms import _inputs, _take_inputs, _terms

__all__ = [
    "DEPTH",
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


def point_tpu(
    returns: DetectedReturns,
    surface: WaterSurface,
    refraction_settings: RefractionSettings | None = None,
    settings: TpuSettings | None = None,
    *,
    seabed_gradient: Any = None,
    surface_tilt_sigma_rad: Any = None,
    wave_sigma_m: Any = None,
    derivatives: Derivatives | None = None,
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
    wave_sigma_m : (n_pulses,) array_like, optional
        The sea each pulse's plane cannot follow
        (:func:`~pipeline.uncertainty.wave_pool.surface_wave_sigma_m`). Default: pooled from
        ``returns`` and ``surface`` themselves.
    derivatives : Derivatives, optional
        The points and derivatives :func:`timing_from_scatter` made of these pulses
        (``return_derivatives``): read where they are of the same bottom pulses, surface and
        refraction (:meth:`~pipeline.uncertainty.tpu_derivatives.Derivatives.of`), else ignored.

    Returns
    -------
    PointTpu
        One row per pulse with a bottom return, in the order of
        :func:`~pipeline.process.refraction.seabed_points`, except the pulses left out
        (``PointTpu.left_out``): a timing sigma not below the surface-bottom separation, or a
        term not finite (e.g. a beam grazing its perturbed surface); see
        :mod:`pipeline.uncertainty.tpu_screen`.
    """
    st = settings or TpuSettings()
    rst = refraction_settings or RefractionSettings()
    inp = _inputs(returns, surface, rst, st, seabed_gradient, surface_tilt_sigma_rad, wave_sigma_m)
    if derivatives is not None:
        inp = dataclasses.replace(inp, derivatives=derivatives.of(inp, surface, st))
    code = timing_unresolved(inp.ret, inp.sig_ts, inp.sig_tb)
    out = code >= 0
    left = LeftOut(inp.ret.pulse_id[out], code[out])
    if out.any():  # (else the inputs as they are: no copy of them, nor of the derivatives)
        inp = _take_inputs(inp, ~out)
    xyzd0, terms = _terms(inp, st)
    inp = dataclasses.replace(inp, derivatives=None)  # not read again: not copied below
    finite = np.all(np.isfinite(xyzd0), axis=1)
    for v in terms.values():
        finite &= np.all(np.isfinite(v), axis=1)
    if not np.all(finite):
        left = left.concatenate(
            LeftOut(inp.ret.pulse_id[~finite], np.full(int(np.sum(~finite)), TERM_NOT_FINITE))
        )
        inp, xyzd0 = _take_inputs(inp, finite), xyzd0[finite]
        terms = {k: v[finite] for k, v in terms.items()}
    n = len(inp.row)

    def var(names):
        v = np.zeros((n, 4))
        for k in names:
            v += terms[k] ** 2
        return v

    vr, vc = var(RANDOM_TERMS), var(CORRELATED_TERMS)
    vt = vr + vc
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
        left_out=left,
    )
