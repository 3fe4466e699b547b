"""Photon-counting windows under a wave sea: the local planes see the sea's slope.

A window's shots share one detected surface height. Fitted shot by shot, a plane's nearest
surface points were its own window's copies of that height, which fix no slope: the beam
refracted as through a level sea and every shot entered at the window's height. The sea and
the rays are written in :mod:`tests.process.test_wave_entry` (Snell's law by hand at the sea's
own facet, a flat seabed, exact times): here a nadir profiler along ``x`` over the sea
``z = a cos(2π x / λ)``, whose windows of ``W`` shots report the mean of the sea under their
shots as their surface height (what the window's histogram measures). The seabed points
must land on the seabed, where the photons hit it.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from scipy import constants

from pipeline.process.refraction import RefractionSettings, seabed_points
from pipeline.process.surface_fit import SurfaceFitSettings, fit_water_surface
from tests.process.test_wave_entry import N_AIR, N_GROUP, N_PHASE, sine_sea_pulses

C = constants.c
SEABED_Z_M = -10.0
ALTITUDE_M = 400.0
FIT = SurfaceFitSettings(air_index=N_AIR)
REFR = RefractionSettings(phase_index=N_PHASE, group_index=N_GROUP)
AMP_M, WAVELENGTH_M = 1.0, 40.0  # slopes up to 0.157
SHOTS_PER_WINDOW, SHOT_SPACING_M = 50, 0.0075  # windows 0.375 m long, as 200 shots at 32 kHz


def window_profile(length_m=80.0):
    """Returns of the profiler's shots (window heights), the truth, and the shots' windows.

    :func:`~tests.process.test_wave_entry.sine_sea_pulses` (a nadir track along ``x``, exact
    times) with each shot's surface and bottom times replaced by its window's: the mean of
    the sea under the window's shots and the mean of their bottom times, what the window's
    histogram measures.
    """
    x = np.arange(0.0, length_m, SHOT_SPACING_M)
    ret, bottom = sine_sea_pulses(
        AMP_M, WAVELENGTH_M, x, np.zeros(x.size), altitude_m=ALTITUDE_M, seabed_z_m=SEABED_Z_M
    )
    k = 2.0 * np.pi / WAVELENGTH_M
    zs, slope = AMP_M * np.cos(k * x), -AMP_M * k * np.sin(k * x)  # height, dz/dx
    window = np.arange(x.size) // SHOTS_PER_WINDOW
    z_window = (np.bincount(window, weights=zs) / np.bincount(window))[window]
    # the bottom too: one apparent (air-equivalent) range per window, its shots' mean
    t_bottom = (np.bincount(window, weights=ret.t_bottom_s) / np.bincount(window))[window]
    ret = dataclasses.replace(
        ret, t_surface_s=2.0 * (ALTITUDE_M - z_window) * N_AIR / C, t_bottom_s=t_bottom
    )
    return ret, bottom, slope, window


def test_window_planes_follow_the_seas_slope_and_soundings_land_where_the_photons_hit():
    ret, bottom, slope, window = window_profile()
    surf = fit_water_surface(ret, FIT, group=window)
    inner = (bottom[:, 0] > 10.0) & (bottom[:, 0] < 70.0)  # planes with neighbours both sides
    # the planes' along-track slope: a line through 16 windows (6 m) of a 40 m sine takes
    # 3 (sin u - u cos u) / u³ of it (u = k 3 m: 0.978, 0.0035 of the 0.157 peak slope), and
    # centred up to half a window (0.19 m) off the shot it reads the slope there (the
    # curvature a k² times 0.19 m: 0.0047); shot by shot it took ~0 (the peak slope missed)
    fitted = -surf.normal[:, 0] / surf.normal[:, 2]
    assert np.max(np.abs(fitted[inner] - slope[inner])) < 0.0035 + 0.0047
    pts = seabed_points(ret, surf, REFR)
    # the entry height is the window's (its centre's sea to 0.2 mm) carried along the fitted
    # slope: the seabed is read within millimetres (shot by shot: 1.0 cm, a window's step)
    assert np.max(np.abs(pts.xyz_m[inner, 2] - SEABED_Z_M)) < 2e-3
    # refracted at the fitted facet: the slope's error turns the beam by (1 - 1/n) of it over
    # the ~11 m path, <= 0.0082 x 0.255 x 11 m = 2.3 cm (shot by shot: 0.40 m off)
    horizontal = np.hypot(*(pts.xyz_m[inner, :2] - bottom[inner, :2]).T)
    assert horizontal.max() < 0.023


def test_windows_along_a_jittering_track_fix_no_slope_across_it():
    # the shots wander 2 cm across the track (roll), each window's height is noisy by 1 cm:
    # across the track the windows span centimetres, so the planes keep the global slope there
    # (the ridge alone let the noise through as across-track slopes of 0.02; on suite tuning
    # seed 79's real sea, +-0.3)
    ret, bottom, slope, window = window_profile()
    rng = np.random.default_rng(3)
    o = ret.origin_meas_m.copy()
    o[:, 1] += 0.02 * rng.standard_normal(len(ret))
    noise_m = (0.01 * rng.standard_normal(window.max() + 1))[window]
    ret = dataclasses.replace(
        ret, origin_meas_m=o, t_surface_s=ret.t_surface_s - 2 * noise_m * N_AIR / C
    )
    surf = fit_water_surface(ret, FIT, group=window)
    inner = (bottom[:, 0] > 10.0) & (bottom[:, 0] < 70.0)
    across = -surf.normal[inner, 1] / surf.normal[inner, 2]
    assert np.max(np.abs(across)) < 0.002
    # along: the curvature bound above plus 3 sigma of 1 cm over 16 windows spread 1.8 m rms
    along = -surf.normal[inner, 0] / surf.normal[inner, 2]
    assert np.max(np.abs(along - slope[inner])) < 0.0082 + 3 * 0.01 / (1.8 * 4.0)


def test_posterior_surface_reads_the_depth_below_the_windows_sea_over_the_sounding():
    # the photon posterior's surface (pipeline.uncertainty.photon_posterior.at_detected_surface):
    # each plane moved to its own detected return, the plane alone read above the sounding
    # (its tilt carried whole): at the detected times the depth is the sine's sea over the
    # sounding down to the seabed, to the sine's curvature over the refracted beam's offset
    # (a k² (0.4 m)² / 2 = 2 mm) and the fitted slope's error times that offset (3 mm)
    from pipeline.uncertainty.photon_posterior import at_detected_surface

    ret, bottom, slope, window = window_profile()
    surf = at_detected_surface(fit_water_surface(ret, FIT, group=window), ret)
    pts = seabed_points(ret, surf, REFR)
    inner = (bottom[:, 0] > 10.0) & (bottom[:, 0] < 70.0)
    sea_m = AMP_M * np.cos(2.0 * np.pi * pts.xyz_m[:, 0] / WAVELENGTH_M)
    assert np.max(np.abs(pts.depth_m[inner] - (sea_m[inner] - SEABED_Z_M))) < 5e-3
