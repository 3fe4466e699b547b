"""The planes' compiled normal equations and 3 x 3 inverses (pipeline/process/plane_kernels.py).

References: numpy's own sums of the same products (to the bit), ``np.linalg.inv`` (LAPACK's LU)
and exact planes recovered from their own samples.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as hs

from pipeline.process.plane_kernels import plane_moments, sym3_inverse
from pipeline.process.surface_plane import solve_plane
from pipeline.uncertainty.seabed_gradient import _bayes_planes


def _rows(seed: int, m: int, k: int):
    rng = np.random.default_rng(seed)
    w = (rng.random((m, k)) < 0.8) * rng.uniform(0.5, 2.0, (m, k))
    dx, dy = rng.normal(0.0, 3.0, (m, k)), rng.normal(0.0, 3.0, (m, k))
    z = rng.normal(-1.0, 0.2, (m, k))
    return w, dx, dy, z


@settings(max_examples=40, deadline=None)
@given(seed=hs.integers(0, 2**32 - 1), m=hs.integers(0, 6), k=hs.integers(1, 300))
def test_moments_are_numpys_sums_to_the_bit(seed, m, k):
    # rows shorter than numpy's 8-way block, between blocks, and past its 128-value halving
    w, dx, dy, z = _rows(seed, m, k)
    ref = [
        w.sum(1),
        (w * dx).sum(1),
        (w * dy).sum(1),
        (w * dx * dx).sum(1),
        (w * dy * dy).sum(1),
        (w * dx * dy).sum(1),
        (w * z).sum(1),
        (w * dx * z).sum(1),
        (w * dy * z).sum(1),
    ]
    np.testing.assert_array_equal(plane_moments(w, dx, dy, z), np.stack(ref, axis=1))


@settings(max_examples=40, deadline=None)
@given(seed=hs.integers(0, 2**32 - 1), scale=hs.floats(1e-3, 1e3))
def test_inverse_of_positive_definite_matrices_matches_lapack(seed, scale):
    rng = np.random.default_rng(seed)
    b = rng.normal(0.0, 1.0, (50, 3, 3)) * [[1.0, scale, scale]]
    a = np.einsum("mki,mkj->mij", b, b) + 1e-3 * np.eye(3)
    inv = sym3_inverse(a)
    ref = np.linalg.inv(a)
    cond = np.linalg.cond(a)
    err = np.abs(inv - ref).max(axis=(1, 2)) / np.abs(ref).max(axis=(1, 2))
    assert np.all(err <= 1e-13 * cond)
    np.testing.assert_array_equal(inv, np.swapaxes(inv, 1, 2))  # symmetric, exactly


def test_singular_and_non_finite_matrices_give_nan_rows():
    a = np.stack([np.zeros((3, 3)), np.full((3, 3), np.nan), 2.0 * np.eye(3)])
    inv = sym3_inverse(a)
    assert np.isnan(inv[:2]).all()
    np.testing.assert_array_equal(inv[2], 0.5 * np.eye(3))


def test_bad_shapes_are_refused():
    with pytest.raises(ValueError, match="3, 3"):
        sym3_inverse(np.eye(2)[None])
    with pytest.raises(ValueError, match="alike"):
        plane_moments(np.ones((2, 3)), np.ones((2, 3)), np.ones((2, 4)), np.ones((2, 3)))


def test_solve_plane_recovers_exact_planes():
    w, dx, dy, _ = _rows(7, 200, 24)
    rng = np.random.default_rng(8)
    abc = rng.normal(0.0, [1.0, 0.1, 0.1], (200, 3))
    z = abc[:, :1] + abc[:, 1:2] * dx + abc[:, 2:3] * dy
    params, inv = solve_plane(w, dx, dy, z, np.zeros(200))  # no ridge: the exact plane
    np.testing.assert_allclose(params, abc, rtol=0, atol=1e-12)
    # the inverse is the normal matrix's, as LAPACK gives it
    sw = w.sum(1)
    sx, sy = (w * dx).sum(1), (w * dy).sum(1)
    a = np.stack(
        [
            np.stack([sw, sx, sy], 1),
            np.stack([sx, (w * dx * dx).sum(1), (w * dx * dy).sum(1)], 1),
            np.stack([sy, (w * dx * dy).sum(1), (w * dy * dy).sum(1)], 1),
        ],
        1,
    )
    np.testing.assert_allclose(inv, np.linalg.inv(a), rtol=1e-10, atol=1e-15)


def test_solve_plane_without_weight_gives_zero_and_identity():
    w, dx, dy, z = _rows(3, 4, 10)
    w[1] = 0.0
    params, inv = solve_plane(w, dx, dy, z, np.ones(4))
    np.testing.assert_array_equal(params[1], 0.0)
    np.testing.assert_array_equal(inv[1], np.eye(3))


def test_bayes_planes_against_the_closed_form_posterior():
    # the posterior of the slope with a free intercept: (X'X / s2 + P0)^-1 on (b, c), solved
    # with numpy's LAPACK on the full matrix; rows under six soundings get the prior
    w, dx, dy, z = _rows(11, 60, 16)
    w[:5, 5:] = 0.0  # five soundings at most
    rng = np.random.default_rng(12)
    noise = rng.uniform(0.01, 0.1, 60) ** 2
    p_mean = rng.normal(0.0, 0.05, (60, 2))
    root = rng.normal(0.0, 10.0, (60, 2, 2))
    p_prec = np.einsum("mik,mjk->mij", root, root) + np.eye(2)
    mean, cov = _bayes_planes(w, dx, dy, z, noise, p_mean, p_prec)
    for r in range(60):
        x = np.column_stack([np.ones(16), dx[r], dy[r]])
        if w[r].sum() < 6:
            np.testing.assert_allclose(mean[r], p_mean[r], rtol=0, atol=0)
            np.testing.assert_allclose(cov[r], np.linalg.inv(p_prec[r]), rtol=1e-12)
            continue
        a = x.T @ (w[r][:, None] * x) / noise[r]
        a[1:, 1:] += p_prec[r]
        rhs = x.T @ (w[r] * z[r]) / noise[r]
        rhs[1:] += p_prec[r] @ p_mean[r]
        inv = np.linalg.inv(a)
        np.testing.assert_allclose(mean[r], (inv @ rhs)[1:], rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(cov[r], inv[1:, 1:], rtol=1e-9, atol=1e-15)
