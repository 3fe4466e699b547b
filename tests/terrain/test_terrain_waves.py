"""Wind waves: slopes against Cox-Munk, Hs against Pierson-Moskowitz, dispersion, water levels."""

import math

import numpy as np
import pytest
from scipy import integrate

from terrain import FlatWater, Tide, WaveField, depth_m, plane_seabed
from terrain import wave_spectra as ws

G = 9.80665


def _peak_wavelength(u10):
    """PM peak wavelength from U19.5: omega_p = 0.877 g / U19.5, k_p = omega_p**2 / g."""
    u195 = ws.wind_speed_at_height(u10, 10.0, 19.5)
    return 2 * math.pi / ((0.877 * G / u195) ** 2 / G)


def _spectral_slopes(z, dx, dy):
    """Slope fields of periodic node values by spectral differentiation (independent of spline)."""
    ny, nx = z.shape
    f = np.fft.fft2(z)
    kx = 2 * math.pi * np.fft.fftfreq(nx, dx)
    ky = 2 * math.pi * np.fft.fftfreq(ny, dy)
    return np.fft.ifft2(1j * kx[None, :] * f).real, np.fft.ifft2(1j * ky[:, None] * f).real


@pytest.fixture(scope="module", params=[5.0, 10.0], ids=["U10=5", "U10=10"])
def calibrated_sea(request):
    u10 = request.param
    side = 2 * _peak_wavelength(u10)  # 1024 nodes: cutoff pi/(2 dx) = 128 k_p
    return u10, WaveField(u10, extent=(0, side, 0, side), spacing_m=side / 1024, rng=42)


def test_mean_square_slope_matches_cox_munk(calibrated_sea):
    u10, sea = calibrated_sea
    u125 = ws.wind_speed_at_height(u10, 10.0, 12.5)
    cox_munk = 0.003 + 0.00512 * u125  # Cox & Munk (1954), wind at 12.5 m
    surf = sea.at_time(0.0)
    sx, sy = _spectral_slopes(surf.z_m, surf.dx_m, surf.dy_m)
    # the realised field's slopes; 10 % is the requested tolerance (realisation error ~2 %)
    assert np.mean(sx**2 + sy**2) == pytest.approx(cox_munk, rel=0.10)
    rng = np.random.default_rng(3)
    x, y = rng.uniform(0, surf.bounds[1], (2, 100_000))
    gx, gy = surf.gradient(x, y)
    # the truth (spline) between nodes has the same slopes: cutoff at 4 nodes per wavelength
    assert np.mean(gx**2 + gy**2) == pytest.approx(cox_munk, rel=0.10)
    # the model's own bookkeeping agrees with the independent spectral estimate to rounding
    assert sea.mean_square_slope() == pytest.approx(np.mean(sx**2 + sy**2), rel=1e-9)
    up, cross = sea.slope_variance()
    # cos-2s with s = 2 gives a fixed ratio ~1.4; Cox-Munk's fits (3.16e-3 U +- 0.004 upwind,
    # 0.003 + 1.92e-3 U +- 0.002 crosswind) make their ratio uncertain by ~30 % at 5 m/s
    assert up / cross == pytest.approx(3.16 * u125 / (3 + 1.92 * u125), rel=0.30)


def test_calibration_keeps_hs_near_pierson_moskowitz(calibrated_sea):
    u10, sea = calibrated_sea
    pm_hs = 0.21 * sea.u19_5_m_s**2 / G  # Pierson & Moskowitz (1964) Hs = 0.21 U19.5**2 / g
    # the spectral Hs of the calibrated, resolved spectrum: extra tail energy costs < 2 %;
    # 10 % is the requested tolerance
    assert sea.expected_hs_m == pytest.approx(pm_hs, rel=0.10)
    assert sea.tail_factor > 0  # the tail had to be raised: PM alone is short of Cox-Munk


def test_significant_wave_height_matches_pm():
    u10 = 8.0
    side = 16 * _peak_wavelength(u10)  # many peak waves -> small sampling error of m0 (< 1 %)
    sea = WaveField(
        u10, extent=(0, side, 0, side), spacing_m=side / 1024, rng=5, calibrate_mss=False
    )
    z = sea.at_time(12.0).z_m
    pm_hs = 0.21 * sea.u19_5_m_s**2 / G
    # 10 % is the requested tolerance; measured 0.4 %
    assert 4 * z.std() == pytest.approx(pm_hs, rel=0.10)
    assert abs(z.mean()) < 1e-12  # mean level 0 (no k = 0 mode), to rounding


def test_pm_spectrum_integral_matches_published_hs():
    u = 12.0
    m0, _ = integrate.quad(lambda w: ws.pierson_moskowitz(w, u), 0.05, 50.0, limit=200)
    # 0.21 is the published two-digit rounding of 0.2092: 1 %
    assert 4 * math.sqrt(m0) == pytest.approx(0.21 * u**2 / G, rel=0.01)


def test_dispersion_of_time_evolution():
    # cos**2 spreading: no energy travels upwind, so each downwind mode evolves as exp(-i w t)
    sea = WaveField(
        6.0,
        extent=(0, 200, 0, 200),
        spacing_m=200 / 256,
        rng=1,
        spreading="cos2",
        direction_rad=0.7,
        calibrate_mss=False,
    )
    t = 3.7
    f0 = np.fft.fft2(sea.at_time(0.0).z_m)
    f1 = np.fft.fft2(sea.at_time(t).z_m)
    kx = 2 * math.pi * np.fft.fftfreq(256, 200 / 256)
    k = np.hypot(kx[None, :], kx[:, None])
    downwind = kx[None, :] * math.sin(0.7) + kx[:, None] * math.cos(0.7) > 0
    strong = (np.abs(f0) > 1e-3 * np.abs(f0).max()) & downwind  # upwind cells hold conj. pairs
    ratio = f1[strong] / f0[strong]
    # deep water: w**2 = g k; 1e-9 allows FFT rounding of the strong modes
    np.testing.assert_allclose(ratio, np.exp(-1j * np.sqrt(G * k[strong]) * t), atol=1e-9)


def test_spreading_functions_are_normalised():
    for s in (1.0, 2.0, 7.5):
        total, _ = integrate.quad(ws.cos2s_spreading, -math.pi, math.pi, args=(s,))
        assert total == pytest.approx(1.0, abs=1e-9)  # quadrature accuracy
    total, _ = integrate.quad(
        ws.cos2_spreading, -math.pi, math.pi, points=[-math.pi / 2, math.pi / 2]
    )
    assert total == pytest.approx(1.0, abs=1e-9)  # quadrature accuracy


def test_wind_profile_conversion():
    u195 = ws.wind_speed_at_height(10.0, 10.0, 19.5)
    # Pierson's U19.5 ~ 1.026-1.07 U10 depending on roughness; Charnock 0.011 gives ~1.06
    assert 1.02 < u195 / 10.0 < 1.08
    back = ws.wind_speed_at_height(u195, 19.5, 10.0)
    assert back == pytest.approx(10.0, rel=1e-12)  # fixed-point iteration converged


def test_jonswap_peak_enhancement():
    u, fetch, gamma = 10.0, 5e4, 3.3
    wp = ws.jonswap_peak_rad_s(u, fetch)
    alpha = 0.076 * (G * fetch / u**2) ** -0.22
    base = alpha * G**2 * wp**-5 * math.exp(-1.25)
    # at the peak r = 1 so S = gamma * (PM-shaped base); rounding only
    assert float(ws.jonswap(wp, u, fetch, gamma)) == pytest.approx(gamma * base, rel=1e-12)
    side = 2 * 2 * math.pi * G / wp**2  # two peak wavelengths: 512 nodes carry 64 k_p
    sea = WaveField(
        u, extent=(0, side, 0, side), spacing_m=side / 512, rng=0, spectrum="jonswap", fetch_m=fetch
    )
    assert sea.peak_wavenumber_rad_m == pytest.approx(wp**2 / G, rel=1e-12)  # rounding only


def test_flat_water_tide_and_depth():
    tide = Tide(mean_level_m=0.5, amplitude_m=1.2, period_s=1000.0)
    assert float(tide.at_time(250.0).height_m(3.0, 4.0)) == pytest.approx(0.5, abs=1e-12)
    assert float(tide.level_m(500.0)) == pytest.approx(-0.7, abs=1e-12)  # rounding only
    water = FlatWater(1.0)
    assert water.at_time(99.0) is water
    seabed = plane_seabed(10.0, gradient=0.1, aspect_rad=0.0)
    np.testing.assert_allclose(depth_m(seabed, water, [0.0, 0.0], [0.0, 10.0]), [11.0, 12.0])


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"wind_speed_m_s": 0.0}, "`wind_speed_m_s` must be > 0; got 0.0"),
        ({"spacing_m": 5.0}, "refine it or set calibrate_mss=False"),
        ({"spectrum": "jonswap"}, "`fetch_m` must be given"),
        ({"spreading": "cos4"}, "`spreading` must be one of"),
        ({"cutoff_wavenumber_rad_m": 100.0}, "`cutoff_wavenumber_rad_m` must be <="),
    ],
)
def test_bad_wave_arguments_raise(kwargs, message):
    args = {"wind_speed_m_s": 10.0, "extent": (0, 100, 0, 100), "spacing_m": 0.5, "rng": 0}
    args.update(kwargs)
    with pytest.raises(ValueError, match=message):
        WaveField(args.pop("wind_speed_m_s"), **args)


@pytest.mark.parametrize("u12", [0.5, 1.0, 2.0])
def test_low_wind_calibration_matches_cox_munk_or_says_why(u12):
    """At 2 m/s the calibrated field holds Cox & Munk's (1954) s^2 = 0.003 + 5.12e-3 U12.5; at
    0.5 and 1 m/s (0.0056, 0.0081) the PM waves below the tail alone hold ~0.0099, which no
    tail scaling removes: a clear error, not a failed number."""
    # a tile of one peak wavelength on 512 nodes: waves to 128 k_p, as the documented default
    probe = {"extent": (0, 100, 0, 100), "spacing_m": 100 / 64, "calibrate_mss": False}
    lp = WaveField(u12, rng=0, wind_height_m=12.5, **probe).peak_wavelength_m
    kwargs = {"extent": (0, lp, 0, lp), "spacing_m": lp / 512, "rng": 0, "wind_height_m": 12.5}
    cox_munk = 0.003 + 5.12e-3 * u12
    if cox_munk > 0.0099:
        sea = WaveField(u12, **kwargs)
        assert sea.expected_mss == pytest.approx(cox_munk, rel=1e-9)
        assert sea.mean_square_slope(0.0) == pytest.approx(cox_munk, rel=0.2)
    else:
        with pytest.raises(ValueError, match=r"impossible at U12.5 = .* above Cox-Munk"):
            WaveField(u12, **kwargs)
