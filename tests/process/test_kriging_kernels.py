"""The kriging's compiled lags and matrices against the numpy expressions they replace."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.process.kriging_kernels import fill_gram, pair_lags


@pytest.mark.parametrize("k", [1, 2, 12, 20])
def test_lags_and_matrices_are_numpys_to_the_bit(k):
    rng = np.random.default_rng(k)
    rows = 500
    # positions as the echoes' are: large local coordinates, some echoes shared by rows
    x = rng.uniform(-3000.0, 3000.0, (rows, k)) + rng.normal(0.0, 1e-3, (rows, k))
    y = rng.uniform(-3000.0, 3000.0, (rows, k))
    x[::7] = x[::7, :1]  # repeated points: zero lags
    ok = rng.uniform(size=(rows, k)) < 0.8
    iu, ju = np.triu_indices(k, 1)
    dx, dy = x[:, iu] - x[:, ju], y[:, iu] - y[:, ju]
    want_lag = np.sqrt(dx * dx + dy * dy)
    got_lag = pair_lags(x, y, iu, ju)
    np.testing.assert_array_equal(got_lag, want_lag)
    assert got_lag.tobytes() == want_lag.tobytes()  # the same bits, not only equal values
    upper = 0.37 * np.exp(-0.21 * want_lag)
    want = np.empty((rows, k, k))
    masked = upper * (ok[:, iu] & ok[:, ju])
    want[:, iu, ju] = want[:, ju, iu] = masked
    want[:, np.arange(k), np.arange(k)] = 0.41
    got = fill_gram(upper, ok, iu, ju, 0.41)
    assert got.tobytes() == want.tobytes()
