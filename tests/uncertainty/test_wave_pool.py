"""The planes' wave residual pooled over cells (pipeline.uncertainty.wave_pool)."""

import numpy as np
from scipy import integrate, stats

from pipeline.uncertainty.wave_pool import pooled_wave_sigma_m

#: A local plane's residual degrees of freedom: 16 neighbours, 3 parameters.
DOF = 13


def _sea(rng, n, ranging_m, wave_m, side_m=200.0):
    """Pulses over a square; each plane's fit² a chi-square draw about wave² + ranging²."""
    xy = rng.uniform(0.0, side_m, size=(n, 2))
    fit2 = (wave_m**2 + ranging_m**2) * rng.chisquare(DOF, size=n) / DOF
    return xy, np.sqrt(fit2), np.full(n, ranging_m), np.arange(n)


def test_flat_sea_pulse_by_pulse_is_biased_as_the_clipped_chi_square_says():
    # no sea: the pulse-by-pulse figure's mean square is r² E[max(X - 1, 0)], X ~ chi²_13 / 13
    rng = np.random.default_rng(1)
    r = 0.05
    xy, fit, rg, pid = _sea(rng, 200_000, r, 0.0)
    own = pooled_wave_sigma_m(xy, fit, rg, np.ones(len(fit), bool), pid, 0.0)
    law = stats.chi2(DOF, scale=1.0 / DOF)
    expect, _ = integrate.quad(lambda x: (x - 1.0) * law.pdf(x), 1.0, np.inf)
    assert abs(np.mean(own**2) / r**2 - expect) < 0.01 * expect + 0.002
    # pooled over 25 m cells (~3000 pulses each here): the mean of fit² - r² is ~0, so is
    # the clipped root: below 3 standard errors of the cell's mean
    pooled = pooled_wave_sigma_m(xy, fit, rg, np.ones(len(fit), bool), pid, 25.0)
    per_cell = len(fit) / (200.0 / 25.0) ** 2
    se = r**2 * np.sqrt(2.0 / DOF / per_cell)
    assert np.sqrt(np.mean(own**2)) > 0.35 * r
    assert np.max(pooled) <= np.sqrt(3.0 * se)


def test_a_wave_sea_is_kept():
    rng = np.random.default_rng(2)
    xy, fit, rg, pid = _sea(rng, 50_000, 0.05, 0.12)
    pooled = pooled_wave_sigma_m(xy, fit, rg, np.ones(len(fit), bool), pid, 25.0)
    per_cell = len(fit) / 64.0
    # the cell mean of fit² - r² scatters by (w² + r²) sqrt(2 / dof / n_cell)
    tol = 4.0 * (0.12**2 + 0.05**2) * np.sqrt(2.0 / DOF / per_cell)
    assert np.all(np.abs(pooled**2 - 0.12**2) < tol)


def test_same_bits_in_any_order_or_company():
    # a cell's figure from its own pulses alone, in any order, to the bit
    rng = np.random.default_rng(3)
    xy, fit, rg, pid = _sea(rng, 5000, 0.05, 0.03, side_m=100.0)
    contrib = rng.random(5000) < 0.8
    whole = pooled_wave_sigma_m(xy, fit, rg, contrib, pid, 25.0)
    cells = np.floor(xy / 25.0).astype(int)
    part = np.flatnonzero((cells[:, 0] == 1) & (cells[:, 1] <= 2))
    rng.shuffle(part)
    alone = pooled_wave_sigma_m(xy[part], fit[part], rg[part], contrib[part], pid[part], 25.0)
    assert np.array_equal(alone, whole[part])


def test_a_cell_without_contributors_keeps_each_pulse_own():
    xy = np.array([[1.0, 1.0], [2.0, 2.0], [40.0, 1.0], [41.0, 2.0]])
    fit = np.array([0.10, 0.06, 0.08, 0.02])
    rg = np.full(4, 0.05)
    contrib = np.array([True, True, False, False])
    got = pooled_wave_sigma_m(xy, fit, rg, contrib, np.arange(4), 25.0)
    cell_mean = np.sqrt(np.mean(fit[:2] ** 2 - rg[:2] ** 2))
    assert np.allclose(got[:2], cell_mean)
    assert np.allclose(got[2:], [np.sqrt(0.08**2 - 0.05**2), 0.0])


def test_no_contributor_anywhere_keeps_each_pulse_own():
    # a survey without a sounding (opaque water, all land): nothing to pool, nothing raised
    fit, rg = np.array([0.08, 0.02]), np.full(2, 0.05)
    got = pooled_wave_sigma_m(np.zeros((2, 2)), fit, rg, np.zeros(2, bool), np.arange(2), 25.0)
    assert np.allclose(got, [np.sqrt(0.08**2 - 0.05**2), 0.0])
    empty = pooled_wave_sigma_m(
        np.zeros((0, 2)), np.zeros(0), np.zeros(0), np.zeros(0, bool), np.zeros(0, int), 25.0
    )
    assert empty.shape == (0,)
