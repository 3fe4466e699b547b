"""The sampler's one restart (``PosteriorSettings.restart_steps``) against posteriors known in
closed form.

The independence proposal is fitted to the burn-in, whose walkers start in a small ball around
the mode (half the Laplace sigma). When the posterior is much wider than the Laplace estimate
(a weak water column, a barely constrained bottom width), 150 steps do not spread them: the
fitted proposal is far too narrow, the chains crawl and never reach ``tau_factor``
autocorrelation times.
The restart refits the proposal to the chains' own production and discards it. The reference
is the target itself: a Gaussian likelihood under a flat prior, whose posterior is normal with a
mean and covariance written in the test.
"""

import numpy as np
import pytest

from pipeline.uncertainty.posterior import PosteriorSettings, sample_batch
from pipeline.uncertainty.waveform_information import (
    fisher_information,
)
from pipeline.uncertainty.waveform_model import (
    N_PARAMS,
    covariance,
    draw_waveform,
)
from tests.uncertainty.test_posterior import FW, gaussian_target, theta, window

DEPTHS_K = [(2, 0.2), (4, 0.3), (6, 0.15), (3, 0.4), (5, 0.25), (7, 0.2), (2.5, 0.3), (4.5, 0.2)]


def _gaussian_targets(monkeypatch, width):
    """Pulses whose log posterior is a Gaussian ``width`` times wider than the Laplace one.

    Returns the waveforms and each pulse's target mean and covariance.
    """
    rng = np.random.default_rng(5)
    thetas = [theta(depth=d, k=k) for d, k in DEPTHS_K]
    waves = [draw_waveform(t, window(t), FW, rng) for t in thetas]
    cov = [
        width**2 * covariance(fisher_information(t, w.size, FW))
        for t, w in zip(thetas, waves, strict=True)
    ]
    # the target's mean half a target sigma from the start (the waveform's mode)
    mean = [t + 0.5 * np.sqrt(np.diag(c)) for t, c in zip(thetas, cov, strict=True)]
    gaussian_target(monkeypatch, waves, mean, cov)
    return waves, mean, cov


def _whitened(draws, mean, cov):
    return np.linalg.solve(np.linalg.cholesky(cov), (draws - mean).T).T


@pytest.mark.parametrize("restart_weight", [0.2, 0.8])
def test_restart_finds_a_posterior_twenty_times_wider_than_the_start(monkeypatch, restart_weight):
    """Without the restart no chain converges in 4000 steps (acceptance ~0.06); with it every
    one does, and its draws have the target's mean and covariance (whitened: mean 0 and
    covariance I; ~2000 thinned draws of several hundred independent ones), whichever share
    of independence moves the restarted chains run with (the default 0.2, or the 0.8 of
    the chains before)."""
    waves, mean, cov = _gaussian_targets(monkeypatch, width=20.0)
    stuck = sample_batch(waves, FW, PosteriorSettings(restart_steps=None), seed=3)
    assert stuck.converged.sum() <= 2, stuck.flags
    st = PosteriorSettings(restart_independence_weight=restart_weight)
    chains = sample_batch(waves, FW, st, seed=3)
    assert chains.converged.all(), chains.flags
    for i in range(len(waves)):
        z = _whitened(chains.draws[i], mean[i], cov[i])
        assert np.all(np.abs(z.mean(axis=0)) < 0.2), z.mean(axis=0)
        np.testing.assert_allclose(np.cov(z, rowvar=False), np.eye(N_PARAMS), atol=0.25)


@pytest.mark.parametrize("restart_steps", [1500, 2000])
def test_chains_converged_before_the_restart_are_untouched(monkeypatch, restart_steps):
    """A pulse that converges before ``restart_steps`` leaves the batch before any refit: its
    chain is the chain of a sampler without restarts, to the bit."""
    waves, _, _ = _gaussian_targets(monkeypatch, width=5.0)
    plain = sample_batch(waves, FW, PosteriorSettings(restart_steps=None), seed=3)
    with_restart = sample_batch(waves, FW, PosteriorSettings(restart_steps=restart_steps), seed=3)
    early = plain.converged & (plain.n_steps <= restart_steps)
    assert early.any() and (~early).any(), plain.n_steps
    np.testing.assert_array_equal(with_restart.n_steps[early], plain.n_steps[early])
    np.testing.assert_array_equal(with_restart.acceptance[early], plain.acceptance[early])
    np.testing.assert_array_equal(with_restart.tau_steps[early], plain.tau_steps[early])
    # the draws kept per pulse are as many as the batch's shortest chain gives (a restarted
    # chain is shorter): where both batches keep as many, they are the same draws
    if plain.draws.shape == with_restart.draws.shape:
        np.testing.assert_array_equal(with_restart.draws[early], plain.draws[early])


def test_only_the_restarted_chains_run_with_the_restart_weight(monkeypatch):
    """The restart's move mix reaches the restarted chains and no other: at 0.2 and 0.8 the
    pulses converged before the restart are the same to the bit, the restarted ones differ."""
    waves, _, _ = _gaussian_targets(monkeypatch, width=5.0)
    runs = [
        sample_batch(waves, FW, PosteriorSettings(restart_independence_weight=w), seed=3)
        for w in (0.2, 0.8)
    ]
    plain = sample_batch(waves, FW, PosteriorSettings(restart_steps=None), seed=3)
    early = plain.converged & (plain.n_steps <= PosteriorSettings().restart_steps)
    assert early.any() and (~early).any(), plain.n_steps
    np.testing.assert_array_equal(runs[0].n_steps[early], runs[1].n_steps[early])
    np.testing.assert_array_equal(runs[0].acceptance[early], runs[1].acceptance[early])
    np.testing.assert_array_equal(runs[0].tau_steps[early], runs[1].tau_steps[early])
    late = ~early
    assert not np.array_equal(runs[0].acceptance[late], runs[1].acceptance[late])
