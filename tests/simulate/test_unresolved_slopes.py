"""The slopes the traced sea does not resolve still tilt each sub-ray's refraction."""

import math

import numpy as np
import pytest

from pipeline.simulate.wave_caster import unresolved_normals


def _slopes(nrm):
    return -nrm[:, 0] / nrm[:, 2], -nrm[:, 1] / nrm[:, 2]


def test_draws_add_gaussian_slopes_of_the_unresolved_variance():
    mss = 0.0196  # Cox-Munk at 5 m/s less the resolved 0.0090
    n_pulses, n_sub = 4000, 19
    up = np.tile([0.0, 0.0, 1.0], (n_pulses * n_sub, 1))
    gx, gy = _slopes(unresolved_normals(up, np.arange(n_pulses), n_sub, mss, seed=3))
    # each axis N(0, mss / 2): variance to ~1 % with 76000 draws, no correlation, zero mean
    assert np.var(gx) == pytest.approx(mss / 2, rel=0.03)
    assert np.var(gy) == pytest.approx(mss / 2, rel=0.03)
    assert abs(np.corrcoef(gx, gy)[0, 1]) < 0.02
    assert abs(np.mean(gx)) < 3 * math.sqrt(mss / 2 / gx.size)
    # Gaussian: the share beyond 2 sigma
    assert np.mean(np.abs(gx) > 2 * math.sqrt(mss / 2)) == pytest.approx(0.0455, abs=0.004)


def test_draws_add_to_a_tilted_facet_and_ignore_the_chunking():
    tilt = np.array([-0.1, 0.05, 1.0]) / math.sqrt(1.0125)  # gradient (0.1, -0.05)
    ids = np.arange(100, 300)
    nrm = np.tile(tilt, (ids.size * 7, 1))
    whole = unresolved_normals(nrm, ids, 7, 0.01, seed=5)
    halves = np.concatenate(
        [
            unresolved_normals(nrm[:700], ids[:100], 7, 0.01, 5),
            unresolved_normals(nrm[700:], ids[100:], 7, 0.01, 5),
        ]
    )
    np.testing.assert_array_equal(whole, halves)
    gx, gy = _slopes(whole)
    assert np.mean(gx) == pytest.approx(0.1, abs=0.01)
    assert np.mean(gy) == pytest.approx(-0.05, abs=0.01)
    np.testing.assert_allclose(np.linalg.norm(whole, axis=1), 1.0, atol=1e-12)
