"""The compiled candidate kernels give the whole-array expressions' figures, to the bit.

The references below are the numpy code the kernels replaced in
``pipeline.process.detect._detect_block``, written out here.
"""

import math

import numpy as np
import pytest

from pipeline.process.detect_candidates import (
    bottom_candidates,
    local_variance,
    pick_bottom,
    strongest_before,
)


def _waveforms(seed: int, n: int = 400, m: int = 120):
    """Residual-like rows: noise, a few echoes, ties (integer steps) and a trend under them."""
    rng = np.random.default_rng(seed)
    resid = rng.normal(0.0, 1.0, (n, m))
    resid[::3] = np.round(resid[::3] * 2.0) / 2.0  # equal neighbours: the >= / > tests
    for _ in range(3):  # echoes of a few samples
        c = rng.integers(5, m - 5, n)
        amp = rng.uniform(0.0, 12.0, n)
        cols = np.arange(m)[None, :]
        resid += amp[:, None] * np.exp(-0.5 * ((cols - c[:, None]) / 1.3) ** 2)
    trend = np.maximum(rng.normal(3.0, 4.0, (n, 1)) - 0.02 * np.arange(m)[None, :], -1.0)
    filt = resid + trend  # filt - resid: the trend (negative in places: clipped at 0)
    noise_f = rng.uniform(0.3, 2.0, n)
    i_s = rng.integers(0, m // 2, n)
    has_s = rng.random(n) < 0.9
    width_s = rng.uniform(1.0, 4.0, n)
    return rng, filt, resid, noise_f, i_s, has_s, width_s


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("shot", [0.0, 0.37])
def test_candidates_and_pick_are_the_whole_array_expressions(seed, shot):
    rng, filt, resid, noise_f, i_s, has_s, width_s = _waveforms(seed)
    n, m = filt.shape
    sep, gap, kernel_sq, thr_sigma = 3.7, 4, 0.21, 3.0
    sigma_samples = 1.3
    i_zone = np.minimum(i_s + 20, m - 1)
    # the reference: detect.py's expressions before the kernels
    cols = np.arange(m)[None, :]
    rpeak = np.zeros((n, m), dtype=bool)
    rpeak[:, 1:-1] = (resid[:, 1:-1] >= resid[:, :-2]) & (resid[:, 1:-1] > resid[:, 2:])
    widen = np.maximum(width_s / (math.sqrt(2.0) * sigma_samples), 1.0)
    after = (cols > (i_s + sep * widen)[:, None]) & (cols < m - gap)
    trend = np.maximum(filt - resid, 0.0)
    local_var = noise_f[:, None] ** 2 + shot * trend * kernel_sq
    local_thr = thr_sigma * np.sqrt(local_var)
    want = rpeak & after & has_s[:, None] & (resid > local_thr)
    near = want & has_s[:, None] & (cols <= i_zone[:, None])

    cand, near_any = bottom_candidates(
        filt, resid, noise_f, i_s + sep * widen, gap, has_s, shot, kernel_sq, thr_sigma, i_zone
    )
    assert np.array_equal(cand, want)
    assert np.array_equal(near_any, near.any(axis=1))
    assert want.any() and (~want.any(axis=1)).any() and near.any()  # every branch is taken
    got_var = local_variance(filt, resid, noise_f[:, None], shot, kernel_sq)
    assert got_var.tobytes() == local_var.tobytes()

    for last in (True, False):
        has_b = want.any(axis=1)
        pick = want
        if last:
            latest = m - 1 - np.argmax(want[:, ::-1], axis=1)
            pick = want & (cols >= (latest - sep)[:, None])
        i_b = np.where(has_b, np.argmax(np.where(pick, resid, -np.inf), axis=1), 0)
        beyond = np.any(want & (cols > (i_b + sep)[:, None]), axis=1)
        g_has, g_i, g_beyond = pick_bottom(want, resid, sep, last)
        assert np.array_equal(g_has, has_b)
        assert np.array_equal(g_i, i_b)
        assert np.array_equal(g_beyond & g_has, beyond & has_b)
        if not last:  # (with "last" the pick is within sep of the latest: none beyond)
            assert (beyond & has_b).any()

    # the strongest candidate clear of (before) a later return, where there is one
    t_b = rng.uniform(0.0, m, n)
    has_b = rng.random(n) < 0.8
    ccand = want & has_b[:, None] & (cols < (t_b - sep)[:, None])
    has_c = ccand.any(axis=1)
    i_c = np.where(has_c, np.argmax(np.where(ccand, resid, -np.inf), axis=1), 0)
    g_has, g_i = strongest_before(want, resid, np.where(has_b, t_b - sep, -np.inf))
    assert np.array_equal(g_has, has_c) and np.array_equal(g_i, i_c)
    assert has_c.any() and (~has_c).any()


def test_equal_residuals_pick_the_first():
    # np.argmax's rule: of equal largest residuals, the earliest sample
    cand = np.zeros((1, 10), dtype=bool)
    cand[0, [2, 5, 7]] = True
    resid = np.zeros((1, 10))
    resid[0, [2, 5, 7]] = [4.0, 4.0, 3.0]
    has, i, beyond = pick_bottom(cand, resid, 1.5, False)
    assert has[0] and i[0] == 2 and beyond[0]
    has, i, _ = pick_bottom(cand, resid, 2.5, True)  # latest 7: samples >= 4.5 only
    assert i[0] == 5
    has, i = strongest_before(cand, resid, np.array([5.0]))
    assert has[0] and i[0] == 2


@pytest.mark.parametrize("seed", range(4))
def test_first_strong_peak_and_row_max_are_the_array_expressions(seed):
    from pipeline.process.detect_candidates import first_strong_peak, row_abs_max

    _, filt, _, noise_f, _, _, _ = _waveforms(seed)
    n, m = filt.shape
    thr = 3.0 * noise_f + np.where(np.arange(n) % 5 == 0, 30.0, 0.0)  # some rows: none
    k = 4 + seed
    peak = np.zeros((n, m), dtype=bool)
    peak[:, 1:-1] = (filt[:, 1:-1] >= filt[:, :-2]) & (filt[:, 1:-1] > filt[:, 2:])
    strong = peak & (filt > thr[:, None])
    strong[:, :k] = False
    has, i = first_strong_peak(filt, thr, k)
    assert np.array_equal(has, strong.any(axis=1))
    assert np.array_equal(i, np.where(has, np.argmax(strong, axis=1), 0))
    assert has.any() and (~has).any()
    x = filt.copy()
    x[3, 7] = np.nan
    assert np.array_equal(row_abs_max(x), np.max(np.abs(x), axis=1), equal_nan=True)
