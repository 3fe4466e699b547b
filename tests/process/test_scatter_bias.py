"""Forward-scattering range-bias correction against references written here.

* The peak a matched filter sees of the delay mixture ``(1-w) delta + w Exp(tau)`` against a
  brute-force numerical convolution on a fine grid (no closed form).
* The processing detector on noise-free waveforms whose bottom echo is that mixture (built here
  by the same brute-force convolution, then sampled): its bottom time moves by the predicted
  peak shift.
* Seabed points over flat water and a sloping seabed (ray geometry by hand,
  ``tests/process/test_refraction.py``) whose bottom times carry the brute-force peak delay of
  the water's delay mixture: corrected, every point is on the analytic seabed; uncorrected, the
  bottoms are centimetres deep.
* The TPU's ``forward_scatter`` term: ``relative_sigma`` times the correction's depth change.
"""

import dataclasses
import math

import numpy as np
import pytest
from scipy import constants
from scipy.optimize import least_squares
from scipy.signal import fftconvolve
from test_refraction import D0_M, N_AIR, N_GROUP, N_PHASE, SX, SY, analytic_pulses

from pipeline.forward_scatter import bottom_delay
from pipeline.forward_scatter_mc import water_tables
from pipeline.process.detect import DetectSettings, detect_full_waveform
from pipeline.process.refraction import RefractionSettings, seabed_points
from pipeline.process.scatter_bias import (
    ForwardScatterSettings,
    bias_model,
    peak_shift,
)
from pipeline.process.surface_fit import SurfaceFitSettings, fit_water_surface
from pipeline.uncertainty.tpu import TpuSettings, point_tpu
from pipeline.water_optics import attenuation_from_column, lidar_attenuation_per_m

C = constants.c
FWHM_S = math.hypot(1.5e-9, 1.0e-9)  # the full-waveform preset's pulse and detector
SIGMA_S = FWHM_S / (2.0 * math.sqrt(2.0 * math.log(2.0)))
FOV_MRAD = 10.0


def _brute_filtered(w, tau, sigma, step):
    """``(x, f)``: the mixture convolved with N(0, sigma²) by a discrete convolution."""
    x = np.arange(-8.0 * sigma, 8.0 * sigma + 12.0 * tau, step)
    gauss = np.exp(-0.5 * (x / sigma) ** 2) / (sigma * math.sqrt(2.0 * math.pi))
    u = np.arange(0.0, 12.0 * tau + step, step)
    tail = np.exp(-u / tau) / tau * step  # delay probabilities on the grid (sum ~ 1)
    tail /= tail.sum()
    conv = fftconvolve(gauss, tail)[: x.size]
    return x, (1.0 - w) * gauss + w * conv


def _brute_peak(w, tau, sigma):
    step = min(sigma, tau) / 400.0
    x, f = _brute_filtered(w, tau, sigma, step)
    i = int(np.argmax(f))
    fm, f0, fp = f[i - 1], f[i], f[i + 1]
    return x[i] + 0.5 * (fm - fp) / (fm - 2.0 * f0 + fp) * step


@pytest.mark.parametrize(
    "w, tau",
    [(0.2, 0.1), (0.5, 0.5), (0.8, 2.0), (0.95, 5.0), (0.3, 20.0), (1.0, 0.3), (0.6, 0.02)],
)
def test_peak_shift_against_a_brute_force_convolution(w, tau):
    sigma = 0.7  # of the matched filter's output: the system response's is sigma / sqrt 2
    want = _brute_peak(w, tau * sigma, sigma)
    got = float(peak_shift(w, tau * sigma, sigma / math.sqrt(2.0)))
    assert got == pytest.approx(want, rel=0.01, abs=0.003 * sigma)


def test_the_detector_reports_the_peak_of_a_skewed_bottom_echo():
    # the preset's 1 GS/s digitiser: the detector's log-parabola sees the skewed peak through
    # three samples, so its time depends on where they fall; 32 phases per echo shape
    dt = 1.0e-9
    t = np.arange(300) * dt
    t_s = 40e-9
    t_b = 120e-9 + np.arange(32) * dt / 32
    cases = [(0.3, 0.2e-9), (0.6, 0.5e-9), (0.9, 1.5e-9), (0.5, 4e-9)]
    rows = []
    surface = np.exp(-0.5 * ((t - t_s) / SIGMA_S) ** 2)
    for w, tau in cases:
        # the echo (not yet filtered): the system response through the delay mixture
        x, f = _brute_filtered(w, tau, SIGMA_S, 1e-12)
        for tb in t_b:
            bottom = np.interp(t - tb, x, f, left=0.0, right=0.0) * SIGMA_S * math.sqrt(2 * math.pi)
            rows.append(10.0 + 200.0 * surface + 40.0 * bottom)
    d = detect_full_waveform(np.array(rows), dt, FWHM_S, noise_samples=30)
    assert d.has_bottom.all()
    shift = (d.t_bottom_s - np.tile(t_b, len(cases))).reshape(len(cases), -1).mean(axis=1)
    w, tau = (np.array([c[i] for c in cases]) for i in (0, 1))
    want = peak_shift(w, tau, SIGMA_S, _water_model(sample_interval_s=dt).detector())
    assert np.all(shift > 0.05e-9)  # the skew is seen at all
    np.testing.assert_allclose(shift, want, rtol=0.05, atol=5e-12)


def _water_model(c=0.15, sample_interval_s=0.0):
    return bias_model(
        ForwardScatterSettings(),
        fov_mrad=FOV_MRAD,
        system_fwhm_s=FWHM_S,
        # 0: the continuous peak, what the bottom times of _delayed_pulses carry
        sample_interval_s=sample_interval_s,
        trend_fwhm=DetectSettings().trend_fwhm,
        wavelength_nm=532.0,
        attenuation_per_m=c,
    )


def _delayed_pulses(c=0.15):
    """Analytic pulses whose bottom times carry the matched-filter peak of their delay mixture."""
    ret, bottom, length, theta, _ = analytic_pulses(n_side=12)
    r_air = 400.0 / np.cos(theta)
    tan_half = math.tan(0.5e-3 * FOV_MRAD)
    radius = tan_half * (r_air + length * N_AIR / N_PHASE)  # the field at the seabed
    b_w = 2.88e-3 * (532.0 / 500.0) ** -4.32  # sea water (Morel 1974)
    # the water processing assumes by default: sea water (absorbing 0.045 1/m, Pope & Fry
    # 1997) plus matter of Petzold's coastal albedo 0.618
    b = b_w + 0.618 * (c - 0.045 - b_w)
    delay = bottom_delay(length, radius, (b - b_w, b_w), water_tables(), c - b)
    # delays in time: two-way excess path at the group speed
    tail_s = delay.tail_mean_m * N_GROUP / C
    shift_s = np.array(
        [
            _brute_peak(w, tau, math.sqrt(2.0) * SIGMA_S) if w > 0 else 0.0
            for w, tau in zip(delay.tail_weight, tail_s, strict=True)
        ]
    )
    late = dataclasses.replace(ret, t_bottom_s=ret.t_bottom_s + shift_s)
    return late, bottom


def test_corrected_seabed_points_of_delayed_echoes_lie_on_the_seabed():
    ret, bottom = _delayed_pulses()
    surface = fit_water_surface(ret, SurfaceFitSettings(air_index=N_AIR))
    plain = RefractionSettings(phase_index=N_PHASE, group_index=N_GROUP)
    fixed = dataclasses.replace(plain, forward_scatter=_water_model())
    p = seabed_points(ret, surface, fixed)
    seabed_z = -D0_M + SX * p.xyz_m[:, 0] + SY * p.xyz_m[:, 1]
    np.testing.assert_allclose(p.xyz_m[:, 2], seabed_z, atol=1e-3)
    np.testing.assert_allclose(p.xyz_m, bottom, atol=1.5e-3)
    # without the correction the bottoms are deep by the delay (~1.5 cm at 12 m)
    raw = seabed_points(ret, surface, plain)
    late = seabed_z - raw.xyz_m[:, 2]
    assert np.all(late > 0.008) and np.all(late < 0.04)


def test_tpu_forward_scatter_term_is_the_relative_error_of_the_correction():
    ret, _ = _delayed_pulses()
    surface = fit_water_surface(ret, SurfaceFitSettings(air_index=N_AIR))
    plain = RefractionSettings(phase_index=N_PHASE, group_index=N_GROUP)
    model = _water_model()
    tpu = point_tpu(ret, surface, dataclasses.replace(plain, forward_scatter=model), TpuSettings())
    corrected = seabed_points(ret, surface, dataclasses.replace(plain, forward_scatter=model))
    raw = seabed_points(ret, surface, plain)
    change = np.abs(corrected.depth_m - raw.depth_m)[tpu.row]
    term = np.abs(tpu.terms["forward_scatter"][:, 3])
    np.testing.assert_allclose(term, model.relative_sigma * change, rtol=0.02)
    # without a correction there is no term
    none = point_tpu(ret, surface, plain, TpuSettings())
    assert np.all(none.terms["forward_scatter"] == 0.0)


@pytest.mark.parametrize("c", [0.08, 0.15, 0.4])
def test_attenuation_from_the_column_inverts_gordons_bridge(c):
    tan_half = math.tan(0.5e-3 * FOV_MRAD)
    k = float(lidar_attenuation_per_m(c, min(0.2 * c + 0.04, c), tan_half * 425.0))
    kd = min(0.2 * c + 0.04, c)
    assert kd < k < c  # the column decays slower than c with a wide field
    assert attenuation_from_column(k, tan_half, 425.0) == pytest.approx(c, rel=2e-3)


def test_posterior_correction_is_where_a_gaussian_fit_centres_the_echo():
    # the depth posteriors fit a symmetric Gaussian of free width: on a skewed echo its centre
    # is neither the detector's peak nor the mean delay; reference: scipy's least squares on
    # the brute-force echo, shot-noise weights, 16 sample phases
    dt = 1.0e-9
    det = _water_model(sample_interval_s=dt).detector()
    for w, tau in [(0.5, 0.3 * SIGMA_S), (0.6, 1.0 * SIGMA_S), (0.8, 3.0 * SIGMA_S)]:
        x, f = _brute_filtered(w, tau, SIGMA_S, 1e-12)
        centres = []
        for phase in (np.arange(16) + 0.5) / 16:
            t = (np.arange(-10, 30) + phase) * dt
            y = np.interp(t, x, f)
            y /= y.max()
            wt = 1.0 / np.sqrt(y + 1e-3)
            u = t / SIGMA_S  # fitted in units of sigma

            def resid(p, u=u, y=y, wt=wt):
                return (p[0] * np.exp(-0.5 * ((u - p[1]) / p[2]) ** 2) - y) * wt

            fit = least_squares(resid, [1.0, 0.0, 1.0], xtol=1e-12, ftol=1e-12)
            centres.append(fit.x[1] * SIGMA_S)
        got = float(peak_shift(w, tau, SIGMA_S, det, estimator="gaussian_fit"))
        detector = float(peak_shift(w, tau, SIGMA_S, det))
        assert got == pytest.approx(np.mean(centres), rel=0.05, abs=0.01 * SIGMA_S)
        if tau > SIGMA_S:  # long tails: the fit is pulled later than the detector's peak
            assert got > 1.1 * detector


def test_peak_shift_tables_from_the_disk_cache_are_the_computed_ones(tmp_path, monkeypatch):
    """The peak-shift tables kept on disk (``pipeline.table_cache``) are the computation's,
    bit for bit, for each estimator; a second process (the in-memory cache cleared) reads
    them instead of computing; a changed source changes the key."""
    import pipeline.process.scatter_bias as sb
    from pipeline.table_cache import code_key

    monkeypatch.setenv("BATHY_CACHE_DIR", str(tmp_path / "cache"))
    det = sb.DetectorTiming(step=0.785398, gap=4, length=3)
    cases = ((None, "detector"), (det, "detector"), (det, "gaussian_fit"))
    direct = []
    for d, est in cases:  # computed and kept
        coarse = est == "gaussian_fit"
        grids = (sb._W_GRID[::4], sb._LOG_TAU[::4]) if coarse else (sb._W_GRID, sb._LOG_TAU)
        direct.append(sb._shift_values(d, est, *grids))
        sb._shift_table.cache_clear()
        np.testing.assert_array_equal(sb._shift_table(d, est).values, direct[-1])
    assert len(list((tmp_path / "cache").iterdir())) == 3

    def computed(*args):
        raise AssertionError("computed again: not read from the cache")

    monkeypatch.setattr(sb, "_shift_values", computed)
    for (d, est), values in zip(cases, direct, strict=True):  # read
        sb._shift_table.cache_clear()
        np.testing.assert_array_equal(sb._shift_table(d, est).values, values)
    sb._shift_table.cache_clear()
    src = tmp_path / "src.py"
    src.write_text("x = 1\n")
    before = code_key([src])
    src.write_text("x = 2\n")
    assert code_key([src]) != before and code_key([tmp_path / "missing.py"]) is None


def test_the_tpus_points_are_seabed_points_own():
    # the TPU's passes take the points and depths alone (seabed_xyz_depth): the same values
    from pipeline.process.refraction import seabed_xyz_depth

    ret, _ = _delayed_pulses()
    surface = fit_water_surface(ret, SurfaceFitSettings(air_index=N_AIR))
    plain = RefractionSettings(phase_index=N_PHASE, group_index=N_GROUP)
    for rst in (plain, dataclasses.replace(plain, forward_scatter=_water_model())):
        p = seabed_points(ret, surface, rst)
        xyzd = seabed_xyz_depth(ret, surface, rst)
        np.testing.assert_array_equal(xyzd, np.column_stack([p.xyz_m, p.depth_m]))
