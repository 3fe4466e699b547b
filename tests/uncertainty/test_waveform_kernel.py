"""The compiled waveform model and the sampler's own loop give the results of the references.

References: the vectorised numpy model (``waveform_reference.expected_waveform_numpy``, the
model as it was before it was compiled) with the numpy noise laws; emcee's own
``integrated_time`` and ``EnsembleSampler`` on the same moves and seed.
"""

import math

import emcee
import numpy as np
import pytest

import pipeline.uncertainty.posterior as posterior_module
import pipeline.uncertainty.posterior_target as target_module
from pipeline.uncertainty.posterior import (
    PosteriorSettings,
    integrated_time_blocks,
    log_prob_blocks,
    make_pulse_batch,
    sample_batch,
)
from pipeline.uncertainty.posterior_moves import BlockDEMove, BlockIndependenceMove
from pipeline.uncertainty.waveform_model import (
    N_PARAMS,
    WaveformSystem,
    draw_waveform,
    expected_waveform,
    in_water_delay_s,
    log_likelihood,
)
from pipeline.uncertainty.waveform_reference import expected_waveform_numpy
from tests.uncertainty.test_posterior import FW, PC

SHORT = WaveformSystem(
    sample_interval_s=5e-10, pulse_fwhm_s=1.2e-9, electronic_noise_counts=1.0, offset_counts=0.0
)


def random_thetas(rng, n):
    """Parameters over the whole prior box: depths 1 cm to 30 m, k 0.01-2 1/m, widths."""
    return np.column_stack(
        [
            np.exp(rng.uniform(math.log(0.01), math.log(30.0), n)),
            rng.uniform(0.0, 40.0, n),
            rng.uniform(0.0, 12.0, (n, 3)),
            rng.uniform(math.log(0.01), math.log(2.0), n),
            rng.uniform(0.0, 50.0, n),
            rng.uniform(math.log(0.7), math.log(20.0), n),
            rng.uniform(math.log(0.7), math.log(3.0), n),
        ]
    )


@pytest.mark.parametrize("system", [FW, SHORT, PC], ids=["fw", "short", "pc"])
def test_compiled_model_matches_the_numpy_reference(system):
    rng = np.random.default_rng(1)
    th = random_thetas(rng, 300)
    cw = rng.uniform(0.6, 1.0, 300)
    fast = expected_waveform(th, 400, system, cw)
    ref = expected_waveform_numpy(th, 400, system, cw)
    scale = np.max(np.abs(ref - system.offset_counts), axis=1, keepdims=True)
    # the tabulated normal CDF: <= 2e-14 absolute per edge, times exp(r s (r s / 2 + 8.5))
    # in the column's tail term; the numpy bands drop 2e-16 of the areas
    assert np.all(np.abs(fast - ref) <= 1e-10 * scale)
    one = expected_waveform(th[7], 400, system, cw[7])
    np.testing.assert_array_equal(one, fast[7])  # rows are independent


@pytest.mark.parametrize("system", [FW, PC], ids=["gaussian", "poisson"])
def test_log_prob_is_the_reference_likelihood(system):
    rng = np.random.default_rng(2)
    th = random_thetas(rng, 40)
    th[:, 0] = rng.uniform(1.0, 8.0, 40)
    th[:, 1] = rng.uniform(10.0, 20.0, 40)
    waves = [draw_waveform(t, 120, system, rng) for t in th[:4]]
    data = make_pulse_batch(waves, system)
    walkers = th[4:].reshape(-1, 4 * N_PARAMS)  # 9 walkers x 4 pulses
    got = log_prob_blocks(walkers, data, system)[:, 1:]
    rows = walkers.reshape(-1, 4, N_PARAMS)
    ref = np.array(
        [
            [
                log_likelihood(
                    data.samples[p], expected_waveform_numpy(rows[w, p], 120, system), system
                )
                for p in range(4)
            ]
            for w in range(rows.shape[0])
        ]
    )
    fin = np.isfinite(got)
    assert fin.sum() >= 30  # most rows inside the prior box
    np.testing.assert_allclose(got[fin], ref[fin], rtol=1e-10, atol=1e-7)


@pytest.mark.parametrize("n_t", [40, 64, 65, 333])
def test_integrated_time_is_emceees(n_t):
    rng = np.random.default_rng(n_t)
    x = np.cumsum(rng.normal(size=(n_t, 16, 3, N_PARAMS)), axis=0) * 0.1
    x += rng.normal(size=x.shape)
    x[:, :, 1, 4] = 2.0  # a stuck parameter: NaN as in emcee
    got = integrated_time_blocks(x)
    with np.errstate(invalid="ignore", divide="ignore"):
        ref = np.array([emcee.autocorr.integrated_time(x[:, :, p], tol=0) for p in range(3)])
    np.testing.assert_array_equal(np.isnan(got), np.isnan(ref))
    np.testing.assert_allclose(got[~np.isnan(ref)], ref[~np.isnan(ref)], rtol=1e-12)


def test_sampler_loop_is_emcees_ensemble_sampler():
    """The same moves, generator and seed through emcee's EnsembleSampler: the same chain."""
    rng = np.random.default_rng(3)
    th = random_thetas(rng, 3)
    th[:, 0], th[:, 1], th[:, 2:5] = [2.0, 4.0, 6.0], 12.0, math.log(800.0)
    waves = [draw_waveform(t, 90, FW, rng) for t in th]
    data = make_pulse_batch(waves, FW)
    st = PosteriorSettings()
    pos = th[None] + 1e-3 * rng.normal(size=(16, 3, N_PARAMS))
    scale = np.tile(np.eye(N_PARAMS) * 1e-4, (3, 1, 1))
    new_pos, (chain, acc) = posterior_module._run(
        data, np.arange(3), pos.copy(), FW, st, 60, 5, np.random.default_rng(9), (th, scale)
    )
    # the reference: emcee's own loop with the same moves and the same generator draw
    de, ind = BlockDEMove(3, N_PARAMS), BlockIndependenceMove(th, scale, st.proposal_dof)
    w = st.independence_weight
    sampler = emcee.EnsembleSampler(
        16, 3 * N_PARAMS, log_prob_blocks, args=(data, FW), vectorize=True,
        moves=[(de, 1.0 - w), (ind, w)],
    )  # fmt: skip
    seed = int(np.random.default_rng(9).integers(2**31))
    sampler.random_state = np.random.RandomState(seed).get_state()
    sampler.run_mcmc(pos.reshape(16, -1), 12, thin_by=5, skip_initial_state_check=True)
    np.testing.assert_array_equal(chain.reshape(12, 16, -1), sampler.get_chain())
    np.testing.assert_array_equal(acc, (de.accepted + ind.accepted) / (de.proposed + ind.proposed))


def test_sampler_on_the_compiled_model_gives_the_reference_posterior(monkeypatch):
    """The whole sampler with the numpy reference model in place of the compiled one: the
    same seed gives the same accept/reject path, so the draws agree far below the posterior
    sigma (only rounding in the starts differs)."""
    rng = np.random.default_rng(4)
    th = random_thetas(rng, 4)
    th[:, 0], th[:, 1] = [1.5, 3.0, 5.0, 7.0], 15.0
    th[:, 2:5] = np.log([[2000.0, 500.0, 900.0]])
    th[:, 5], th[:, 7], th[:, 8] = math.log(0.15), 0.2, 0.1
    waves = [draw_waveform(t, 110, FW, rng) for t in th]
    st = PosteriorSettings(max_steps=600)
    fast = sample_batch(waves, FW, st, seed=3)

    def numpy_rows(theta, samples, n_valid, cos_water, box, ln_k_prior, system, exposure):
        """The numpy log posterior as it was: prior box, bottom in the window, reference model."""
        pulse = np.arange(theta.shape[0]) % samples.shape[0]
        lo, hi, t_last = box[pulse, :9], box[pulse, 9:18], box[pulse, 18]
        t_b = theta[:, 1] * 1e-9 + in_water_delay_s(theta[:, 0], cos_water[pulse], FW.group_index)
        ok = np.all((theta >= lo) & (theta <= hi), axis=1) & (t_b <= t_last)
        out = np.full(theta.shape[0], -np.inf)
        mu = expected_waveform_numpy(theta[ok], samples.shape[1], FW, cos_water[pulse[ok]])
        valid = np.arange(samples.shape[1]) < n_valid[pulse[ok]][:, None]
        out[ok] = log_likelihood(samples[pulse[ok]], mu, FW, valid)  # no prior on ln k here
        return out

    monkeypatch.setattr(target_module, "log_post_rows", numpy_rows)
    ref = sample_batch(waves, FW, st, seed=3)
    np.testing.assert_array_equal(fast.n_steps, ref.n_steps)
    np.testing.assert_array_equal(fast.flags, ref.flags)
    sd = ref.draws[:, :, 0].std(axis=1)
    assert np.all(np.max(np.abs(fast.draws[:, :, 0] - ref.draws[:, :, 0]), axis=1) < 1e-4 * sd)
