"""The posterior starts' compiled and vectorised helpers give numpy's values bit for bit."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.uncertainty.posterior_settings import PosteriorSettings
from pipeline.uncertainty.posterior_start import (
    _normal_sums,
    _project,
    _project_all,
    _scan_sums,
)
from pipeline.uncertainty.posterior_target import make_pulse_batch
from pipeline.uncertainty.waveform_model import WaveformSystem


@pytest.mark.parametrize("m", [9, 40, 83, 257, 611])
def test_normal_sums_are_einsums_bit_for_bit(m):
    # the scan's layout: (K, m, 4) from np.stack(axis=2), a ones column and sparse bases
    rng = np.random.default_rng(m)
    k = 2 * m
    bases = [rng.gamma(0.3, 50.0, (k, m)) * (rng.random((k, m)) < 0.7) for _ in range(3)]
    a = np.stack([np.ones((k, m)), *bases], axis=2)
    a[:, : m // 3, 3] = -0.0  # signed zeros where a basis is absent
    rhs = rng.normal(100.0, 20.0, m)
    gram, proj = _normal_sums(a, rhs)
    assert np.array_equal(gram, np.einsum("kmi,kmj->kij", a, a))
    assert np.array_equal(proj, np.einsum("kmi,m->ki", a, rhs))


@pytest.mark.parametrize("m", [1, 9, 83, 611])
def test_scan_sums_are_einsums_bit_for_bit(m):
    # the scan's basis: background and surface columns shared by every candidate depth
    rng = np.random.default_rng(m + 1)
    k = 2 * m
    surface = rng.gamma(0.3, 50.0, m) * (rng.random(m) < 0.5)
    bases = [rng.gamma(0.3, 50.0, (k, m)) * (rng.random((k, m)) < 0.7) for _ in range(2)]
    a = np.stack([np.ones((k, m)), np.broadcast_to(surface, (k, m)), *bases], axis=2)
    a *= rng.uniform(0.5, 1.0, m)[None, :, None]  # an exposure per sample, as photon counting
    rhs = rng.normal(100.0, 20.0, m)
    gram, proj = _scan_sums(a, rhs)
    assert np.array_equal(gram, np.einsum("kmi,kmj->kij", a, a))
    assert np.array_equal(proj, np.einsum("kmi,m->ki", a, rhs))
    g0, p0 = _scan_sums(a[:0], rhs)
    assert g0.shape == (0, 4, 4) and p0.shape == (0, 4)


def test_projection_of_all_pulses_is_the_per_pulse_one():
    system = WaveformSystem(
        sample_interval_s=1e-9, pulse_fwhm_s=3e-9, offset_counts=100.0, electronic_noise_counts=2.0
    )
    rng = np.random.default_rng(3)
    waves = [rng.normal(110.0, 3.0, n) for n in rng.integers(40, 120, 16)]
    data = make_pulse_batch(waves, system, PosteriorSettings(), np.linspace(0.8, 1.0, 16), None)
    mid = 0.5 * (data.lower + data.upper)
    for scale in (0.1, 1.0, 10.0):  # inside, at and far beyond the prior boxes
        th = mid + scale * (data.upper - data.lower) * rng.standard_normal(mid.shape)
        th[:, 0] = np.abs(th[:, 0])
        each = np.array([_project(th[i], data, i, system.group_index) for i in range(16)])
        assert np.array_equal(_project_all(th, data, system.group_index), each)
