"""The kriging's compiled lags and matrices against the numpy expressions they replace."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.process.kriging_kernels import fill_gram, pair_lags, spd_solve


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


@pytest.mark.parametrize("k", [1, 5, 12, 20])
def test_spd_solve_matches_lapack_on_kriging_matrices(k):
    # exponential covariances of echoes 0.5-20 m apart with a small nugget: the matrices the
    # kriging solves, some ill-conditioned (near-duplicate echoes)
    rng = np.random.default_rng(100 + k)
    rows = 300
    x, y = rng.uniform(0.0, 20.0, (2, rows, k))
    x[::5, -1] = x[::5, 0] + 1e-3  # near-duplicates
    lag = np.hypot(x[:, :, None] - x[:, None, :], y[:, :, None] - y[:, None, :])
    a = 0.04 * np.exp(-lag / 8.0) + 1e-4 * np.eye(k)
    b = 0.04 * np.exp(-rng.uniform(0.0, 10.0, (rows, k)) / 8.0)
    got = spd_solve(a, b)
    want = np.linalg.solve(a, b[..., None])[..., 0]
    cond = np.linalg.cond(a)
    err = np.abs(got - want).max(axis=1) / np.abs(want).max(axis=1)
    assert np.all(err <= 1e-14 * cond)
    resid = np.einsum("rij,rj->ri", a, got) - b
    assert np.abs(resid).max() <= 1e-12 * np.abs(b).max()


def test_spd_solve_hands_indefinite_rows_to_lapack():
    a = np.stack([np.diag([2.0, 4.0]), np.array([[1.0, 2.0], [2.0, 1.0]])])  # 2nd: indefinite
    b = np.array([[2.0, 4.0], [3.0, 3.0]])
    np.testing.assert_allclose(spd_solve(a, b), [[1.0, 1.0], [1.0, 1.0]], rtol=1e-15)
    with pytest.raises(np.linalg.LinAlgError):
        spd_solve(np.zeros((1, 2, 2)), np.ones((1, 2)))
    with pytest.raises(ValueError, match="rows, k, k"):
        spd_solve(np.ones((1, 2, 3)), np.ones((1, 2)))
