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


@pytest.mark.parametrize("receiver", ["full_waveform", "photon_counting"])
def test_scan_start_without_the_bottom_basis_column_is_the_same_bit_for_bit(monkeypatch, receiver):
    """The depth scan's bottom basis leaves out its column's exp(-700) area (``echo_rows``):
    on waveforms drawn over depths, attenuations, angles, backgrounds and exposures, the scan's
    start is what the whole model row (``expected_waveform``, the column included) gives."""
    import pipeline.uncertainty.posterior_start as ps
    from pipeline.uncertainty.waveform_model import draw_waveform, expected_waveform

    system = WaveformSystem(
        sample_interval_s=1e-9,
        pulse_fwhm_s=3e-9,
        receiver=receiver,
        **(
            {
                "offset_counts": 100.0,
                "counts_per_photoelectron": 5.0,
                "electronic_noise_counts": 2.0,
            }
            if receiver == "full_waveform"
            else {}
        ),
    )

    def whole_rows(th, cos_water, m, dt, s, group_index, offset):
        return expected_waveform(th, m, system, cos_water)

    rng = np.random.default_rng(11)
    cases = 0
    for _ in range(40):
        depth, k = rng.uniform(0.3, 12.0), rng.uniform(0.05, 0.8)
        cos_w = rng.uniform(0.85, 1.0)
        th = np.array(
            [depth, 20.0, np.log(rng.uniform(5, 5e3)), np.log(rng.uniform(5, 500)),
             np.log(rng.uniform(0.5, 300)), np.log(k), rng.uniform(0, 3), 0.0, 0.0]
        )  # fmt: skip
        m = int(rng.integers(60, 320))
        y = draw_waveform(th, m, system, rng, cos_water=cos_w)
        ex = rng.uniform(0.6, 1.0, m) if receiver == "photon_counting" else None
        new = ps._scan_start(y, system, cos_w, 20e-9, th[6], ex)
        with monkeypatch.context() as mp:
            mp.setattr(ps, "echo_rows", whole_rows)
            old = ps._scan_start(y, system, cos_w, 20e-9, th[6], ex)
        assert (new is None) == (old is None)
        if new is not None:
            cases += 1
            assert np.array_equal(new, old), (new, old)
    assert cases >= 30
