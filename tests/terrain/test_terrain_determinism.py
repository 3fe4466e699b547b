"""Determinism: the same seed gives identical worlds, different seeds differ."""

import numpy as np

from terrain import WaveField, gaussian_roughness, von_karman_roughness

EXTENT = (0.0, 64.0, 0.0, 64.0)


def test_roughness_same_seed_identical_different_seed_differs():
    a = gaussian_roughness(0.2, 4.0, extent=EXTENT, rng=1).z_m
    b = gaussian_roughness(0.2, 4.0, extent=EXTENT, rng=1).z_m
    c = gaussian_roughness(0.2, 4.0, extent=EXTENT, rng=2).z_m
    d = gaussian_roughness(0.2, 4.0, extent=EXTENT, rng=np.random.default_rng(1)).z_m
    np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(a, d)  # an int seed and a Generator from it agree
    assert not np.allclose(a, c)
    e = von_karman_roughness(0.2, 4.0, 0.5, extent=EXTENT, rng=1).z_m
    np.testing.assert_array_equal(e, von_karman_roughness(0.2, 4.0, 0.5, extent=EXTENT, rng=1).z_m)


def test_waves_same_seed_identical_different_seed_differs():
    def make(seed):
        return WaveField(7.0, extent=(0, 60, 0, 60), spacing_m=60 / 256, rng=seed).at_time(2.5).z_m

    np.testing.assert_array_equal(make(3), make(3))
    assert not np.allclose(make(3), make(4))
