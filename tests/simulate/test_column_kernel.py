"""The column kernel's special functions against scipy's (pipeline.simulate.column_kernel)."""

import numpy as np
from scipy.special import log_ndtr, ndtr

from pipeline.simulate.column_kernel import fast_ndtr_one, log_ndtr_one, ndtr_one
from pipeline.simulate.shapes import _TAB, _TAB_N, _TAB_Z, fast_ndtr


def test_ndtr_one_is_scipys_to_rounding():
    z = np.concatenate([np.linspace(-37.0, 9.0, 20_001), [-0.7071, 0.7071, 0.0, -1e-300]])
    got = np.array([ndtr_one(v) for v in z])
    want = ndtr(z)
    # relative: in the far tail the two erfc's (the C library's, Cephes') differ by ~1e-14
    # of these tiny values; within 5 sigma by rounding
    np.testing.assert_allclose(got, want, rtol=1e-13, atol=0.0)
    mid = np.abs(z) <= 5.0
    np.testing.assert_allclose(got[mid], want[mid], rtol=2e-15, atol=0.0)
    # below -37.5 scipy gives 0, the C library a subnormal: both nothing next to any term
    assert 0.0 <= ndtr_one(-38.5) < 1e-300


def test_log_ndtr_one_holds_where_phi_underflows():
    z = np.concatenate([np.linspace(-300.0, 5.0, 30_001), [-20.0, -20.0001, -19.9999]])
    got = np.array([log_ndtr_one(v) for v in z])
    want = log_ndtr(z)
    assert np.all(np.isfinite(got))  # down to -300 sigma: Phi itself is 0 below ~-38
    np.testing.assert_allclose(got, want, rtol=1e-13, atol=1e-15)


def test_fast_ndtr_one_is_the_tables_value_bit_for_bit():
    z = np.random.default_rng(1).uniform(-12.0, 12.0, 5000)
    got = np.array([fast_ndtr_one(v, _TAB, _TAB_Z, _TAB_N) for v in z])
    assert got.tobytes() == fast_ndtr(z).tobytes()


def test_add_column_bins_adds_scaled_bins_to_their_rows_only():
    from pipeline.simulate.shapes import add_column_bins, column_cdf

    rng = np.random.default_rng(4)
    n, m, dt, k = 50, 200, 1e-9, 20
    rows = rng.choice(n, k, replace=False)
    r = 10 ** rng.uniform(6, 10, k)
    w = 10 ** rng.uniform(-9, -6.8, k)
    w[:3] = 1e-16  # a point-like column: the special path
    s = 10 ** rng.uniform(-10, -8.7, k)
    x0 = rng.uniform(-40, 0, k) * dt
    scale = rng.uniform(0.5, 500.0, k)
    start = rng.uniform(0.0, 3.0, (n, m))
    out = start.copy()
    add_column_bins(out, rows, scale, x0, dt, r, w, s)
    edges = x0[:, None] + dt * np.arange(m + 1)
    bins = np.diff(column_cdf(edges, r[:, None], w[:, None], s[:, None]), axis=1)
    want = start.copy()
    want[rows] += scale[:, None] * bins
    # 1e-8 of the count: both forms lose eps/(r w) near the uniform limit
    np.testing.assert_allclose(out, want, rtol=0.0, atol=1e-8 * scale.max())
    others = np.setdiff1d(np.arange(n), rows)
    assert np.array_equal(out[others], start[others])  # untouched, to the bit
    # an infinite count is not clipped away: its row turns NaN (the receiver reports it)
    scale[5] = np.inf
    out = start.copy()
    add_column_bins(out, rows, scale, x0, dt, r, w, s)
    assert np.isnan(out[rows[5]]).all() and np.isfinite(np.delete(out, rows[5], 0)).all()
