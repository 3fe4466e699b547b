"""Rough seabed: statistics of large generated patches against the requested spectrum."""

import math

import numpy as np
import pytest
from scipy import special

from terrain import gaussian_roughness, von_karman_roughness


def _autocovariance(z):
    """Periodic autocovariance of the node values by Wiener-Khinchin (lags on the node grid)."""
    z = z - z.mean()
    f = np.fft.rfft2(z)
    return np.fft.irfft2(np.abs(f) ** 2, s=z.shape) / z.size


def _one_over_e_lag(profile, spacing):
    """First lag where a normalised autocorrelation profile drops below 1/e (linear interp.)."""
    i = int(np.argmax(profile < math.exp(-1)))
    frac = (profile[i - 1] - math.exp(-1)) / (profile[i - 1] - profile[i])
    return spacing * (i - 1 + frac)


def test_gaussian_rms_and_correlation_length_within_5_percent():
    rms, ell = 0.3, 10.0
    surf = gaussian_roughness(rms, ell, extent=(0.0, 1280.0, -640.0, 640.0), rng=2024)
    z = surf.z_m
    assert z.shape == (1024, 1024)  # spacing ell/8 -> 128 correlation lengths per side
    c = _autocovariance(z)
    # patch of 128 l per side: sampling error of the variance ~ sqrt(pi) l / L = 1.4 %,
    # so 5 % (the requested tolerance) is > 3 sigma
    assert math.sqrt(c[0, 0]) == pytest.approx(rms, rel=0.05)
    profile = 0.5 * (c[0, :40] + c[:40, 0]) / c[0, 0]  # along x and y, lags up to 5 l
    # same sampling argument; linear interpolation between lags l/8 apart adds < 0.5 %
    assert _one_over_e_lag(profile, surf.dx_m) == pytest.approx(ell, rel=0.05)
    # truth = spline through the nodes: it is zero-mean (k = 0 removed) to rounding
    assert abs(z.mean()) < 1e-12


def test_gaussian_truth_between_nodes_has_the_same_rms():
    rms, ell = 0.3, 10.0
    surf = gaussian_roughness(rms, ell, extent=(0.0, 640.0, 0.0, 640.0), rng=7)
    rng = np.random.default_rng(0)
    x, y = rng.uniform(0, 640, (2, 200_000))
    h = surf.height_m(x, y)
    # the spline truth tracks the band-limited field (spectrum negligible at Nyquist): same rms
    # as the nodes to sampling error of 2e5 random points (0.3 %) -> 1 %
    assert h.std() == pytest.approx(surf.z_m.std(), rel=0.01)


def test_von_karman_rms_within_5_percent_and_acf_shape():
    rms, ell, hurst = 0.5, 10.0, 0.8
    surf = von_karman_roughness(rms, ell, hurst, extent=(0, 1024, 0, 1024), spacing_m=1.0, rng=11)
    c = _autocovariance(surf.z_m)
    # grid carries all but (1 + (pi l / dx)**2)**-H = 0.3 % of the variance; sampling error of the
    # variance for 100 l patch ~ 2 %: 5 % is the requested tolerance
    assert math.sqrt(c[0, 0]) == pytest.approx(rms, rel=0.05)
    lags = np.array([5, 10, 20])
    expected = 2 ** (1 - hurst) / special.gamma(hurst) * (lags / ell) ** hurst
    expected *= special.kv(hurst, lags / ell)
    measured = 0.5 * (c[0, lags] + c[lags, 0]) / rms**2
    # normalised autocovariance at 0.5, 1, 2 l against the Matern formula: absolute error
    # 0.05 covers sampling (long-range correlation of von Karman fields) and rms error
    np.testing.assert_allclose(measured, expected, atol=0.05)


@pytest.mark.parametrize(
    ("call", "message"),
    [
        (
            lambda: gaussian_roughness(-1, 1, extent=(0, 10, 0, 10), rng=0),
            "`rms_height_m` must be >= 0; got -1",
        ),
        (
            lambda: gaussian_roughness(1, 0, extent=(0, 10, 0, 10), rng=0),
            "`correlation_length_m` must be > 0",
        ),
        (
            lambda: von_karman_roughness(1, 1, 1.5, extent=(0, 10, 0, 10), rng=0),
            "`hurst` must be <= 1",
        ),
        (lambda: gaussian_roughness(1, 1, extent=(0, 10, 5, 5), rng=0), "`extent` must have"),
        (lambda: gaussian_roughness(1, 1, extent=(0, 10, 0, 10), rng=None), "`rng` must be"),
        (lambda: gaussian_roughness(1, 1e-4, extent=(0, 10, 0, 10), rng=0), "`spacing_m` = "),
    ],
)
def test_bad_roughness_arguments_raise(call, message):
    with pytest.raises(ValueError, match=message):
        call()
