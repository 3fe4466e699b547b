"""The surface step fit (tabulated, compiled): hand-built echoes with a known surface time."""

from __future__ import annotations

import math

import numpy as np
from scipy.special import ndtr

from pipeline.process.surface_step import surface_step_fit

SG = 2.2  # σ of the filtered response, samples


def _echo(m: int, t_s: float, a: float = 100.0, b: float = 20.0) -> np.ndarray:
    """``a g(t − t_s) + b Φ((t − t_s)/σ)`` on samples 0..m-1: the model, with a known t_s."""
    t = np.arange(m, dtype=float)
    z = (t - t_s) / SG
    return a * np.exp(-0.5 * z * z) + b * ndtr(z)


def test_recovers_the_known_surface_time_inside_and_at_the_window_ends():
    m = 60
    # the peak sample of the sum sits at or just after t_s; candidates span 1.5 before it
    times = np.array([20.37, 31.9, 44.05, 1.2, 57.6])  # the last two cut the fitted window
    filt = np.stack([_echo(m, t) for t in times])
    i_peak = np.argmax(filt, axis=1)
    assert i_peak[3] - math.ceil(3 * SG) < 0 and i_peak[4] + math.ceil(2 * SG) > m - 1
    got = surface_step_fit(filt, i_peak, SG)
    # noise-free echoes: the 0.02-sample grid + parabola lands within a few thousandths
    np.testing.assert_allclose(got, times, atol=3e-3)
    # the plain peak is pulled late by the step: the fit is what removes it
    assert np.all(np.abs(got - times) < 0.1 * np.abs(i_peak - times) + 1e-3)


def test_each_pulse_alone_gives_the_same_time_as_in_a_batch():
    m = 50
    rng = np.random.default_rng(3)
    times = rng.uniform(3.0, 47.0, 40)
    filt = np.stack([_echo(m, t) for t in times]) + rng.normal(0.0, 0.5, (40, m))
    i_peak = np.argmax(filt, axis=1)
    batch = surface_step_fit(filt, i_peak, SG)
    one = np.array([surface_step_fit(filt[i : i + 1], i_peak[i : i + 1], SG)[0] for i in range(40)])
    np.testing.assert_array_equal(batch, one)


def test_onset_peak_is_the_whole_grids_maximum_bit_for_bit():
    # the two-pass search (every 10th grid point, then around the best) against the maximum
    # over the whole 0.02-sigma grid, for decays from none to very steep and several widths
    from pipeline.process.surface_step import DECAY_GRID, column_onset, onset_peak

    rng = np.random.default_rng(12)
    z = np.arange(-1.0, 4.0001, 0.02)
    decay = np.concatenate([[0.0, 1e-9, 1.0, 5.0, 50.0], 10.0 ** rng.uniform(-4, 1, 3000)])
    decay = np.concatenate([decay, DECAY_GRID])
    for sg in (0.5, 1.0, 1.7, 4.0):
        want = column_onset(z[None, :] * sg, sg, decay[:, None]).max(axis=1)
        assert onset_peak(sg, decay).tobytes() == want.tobytes(), sg
