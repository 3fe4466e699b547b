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
