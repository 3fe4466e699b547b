"""``evaluation_points.npz``'s posterior truth over a moving sea: each pulse's own surface.

The truth is a hand-written per-pulse callable (the depth below the sea each pulse saw grows
with its pulse id; without an id it is the time-0 sea, 5 m everywhere), as the orchestrator's
``Truth.depth_at_pulses_m``; the points' and ``evaluation.json``'s posterior coverage already
evaluate it per pulse.
"""

from types import SimpleNamespace

import numpy as np

from pipeline.evaluation_points import _posterior_arrays
from pipeline.uncertainty.posterior_settings import PosteriorFlag
from pipeline.uncertainty.seabed_posterior import SeabedPosteriors


class PerPulseDepth:
    per_pulse = True

    def __call__(self, x_m, y_m, pulse_id=None):
        base = 5.0 + 0.01 * np.asarray(x_m)
        return base if pulse_id is None else base + 0.1 * np.asarray(pulse_id)


def test_posterior_truth_is_the_sea_each_pulse_saw():
    n = 4
    summ = {k: np.full(n, 5.2) for k in ("median", "lo68", "hi68", "lo95", "hi95", "std")}
    flags = np.zeros(n, dtype=np.uint16)
    flags[2] = PosteriorFlag.NO_START  # left out of the arrays
    post = SeabedPosteriors(
        pulse_id=np.array([3, 7, 11, 20]),
        row=np.arange(n),
        depth_m=summ,
        xyz_median_m=np.column_stack([np.arange(n) * 10.0, np.zeros(n), np.full(n, -5.0)]),
        xyz_std_m=np.zeros((n, 3)),
        sigma_h_m=np.zeros(n),
        acceptance=np.full(n, 0.3),
        tau_max_steps=np.ones(n),
        n_steps=np.full(n, 500),
        flags=flags,
    )
    out = _posterior_arrays(SimpleNamespace(posteriors=post), PerPulseDepth())
    x = np.array([0.0, 10.0, 30.0])
    np.testing.assert_allclose(
        out["post_true_depth_m"], 5.0 + 0.01 * x + 0.1 * np.array([3, 7, 20])
    )
    # without the nuisance summaries the waveform-only arrays are the posterior's own
    np.testing.assert_array_equal(out["post_wave_lo95_m"], out["post_lo95_m"])
