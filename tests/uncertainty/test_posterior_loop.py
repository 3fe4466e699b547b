"""The compiled ensemble loop and the log-likelihood's shortcuts give the references' bits.

References: ``emcee.EnsembleSampler`` on the block moves of ``posterior_moves`` (the loop the
compiled one replaces) with the same generator; the log-likelihood summed term by term as
written in its docstring (every logarithm evaluated).
"""

import dataclasses
import math

import emcee
import numba
import numpy as np
import pytest

import pipeline.uncertainty.posterior_autocorr as autocorr_module
import pipeline.uncertainty.posterior_loop as loop_module
from pipeline.uncertainty.posterior import PosteriorSettings, log_prob_blocks, make_pulse_batch
from pipeline.uncertainty.posterior_loop import run_steps
from pipeline.uncertainty.posterior_moves import BlockDEMove, BlockIndependenceMove
from pipeline.uncertainty.waveform_kernel import expected_rows, log_lik_rows
from pipeline.uncertainty.waveform_model import N_PARAMS, draw_waveform
from tests.uncertainty.test_posterior import FW, PC


def _pulses(system, rng, n=3):
    """``n`` pulses 2-6 m deep with their true parameters (walkers start around them)."""
    th = np.zeros((n, N_PARAMS))
    th[:, 0] = np.linspace(2.0, 6.0, n)
    th[:, 1] = 12.0
    th[:, 2:5] = math.log(300.0 if system.poisson else 800.0)
    th[:, 5], th[:, 6] = math.log(0.15), 0.1 if system.poisson else 3.0
    waves = [draw_waveform(t, 90, system, rng) for t in th]
    return th, make_pulse_batch(waves, system)


@pytest.mark.parametrize(
    ("system", "n_walkers", "weight", "thin", "block_values"),
    [
        (FW, 16, 0.8, 5, None),  # production: both moves
        (PC, 17, 0.8, 1, 2000),  # odd walkers (unequal halves), many pre-drawn blocks
        (FW, 16, 0.0, 2, None),  # DE only
        (PC, 16, 1.0, 3, 3000),  # independence only, blocks of a multiple of thin
    ],
    ids=["fw-both", "pc-odd-blocks", "fw-de", "pc-independence"],
)
def test_compiled_loop_is_emcees_ensemble_sampler(
    system, n_walkers, weight, thin, block_values, monkeypatch
):
    """Same seed, same moves through emcee's own EnsembleSampler: the same chain, bit for bit,
    and the same acceptance (the proposals are wide enough that both moves accept and reject).
    """
    if block_values is not None:
        monkeypatch.setattr(loop_module, "_BLOCK_VALUES", block_values)
    rng = np.random.default_rng(11)
    th, data = _pulses(system, rng)
    st = PosteriorSettings(n_walkers=n_walkers, independence_weight=weight)
    pos = th[None] + 2e-3 * rng.normal(size=(n_walkers, 3, N_PARAMS))
    scale = np.tile(np.diag([1e-3, 1e-2, 1e-2, 1e-2, 1e-2, 1e-2, 1e-2, 1e-2, 1e-2]), (3, 1, 1))
    n_steps = 24 * thin
    new_pos, (chain, acc) = run_steps(
        data, pos.copy(), system, st, n_steps, thin, np.random.default_rng(5), (th, scale)
    )
    de, ind = BlockDEMove(3, N_PARAMS), BlockIndependenceMove(th, scale, st.proposal_dof)
    moves = [(de, 1.0 - weight), (ind, weight)] if 0.0 < weight < 1.0 else None
    moves = moves or [(ind if weight >= 1.0 else de, 1.0)]
    sampler = emcee.EnsembleSampler(
        n_walkers, 3 * N_PARAMS, log_prob_blocks, args=(data, system), vectorize=True,
        moves=moves,
    )  # fmt: skip
    seed = int(np.random.default_rng(5).integers(2**31))
    sampler.random_state = np.random.RandomState(seed).get_state()
    sampler.run_mcmc(pos.reshape(n_walkers, -1), 24, thin_by=thin, skip_initial_state_check=True)
    np.testing.assert_array_equal(chain.reshape(24, n_walkers, -1), sampler.get_chain())
    np.testing.assert_array_equal(new_pos.reshape(n_walkers, -1), sampler.get_last_sample().coords)
    ref_acc = (de.accepted + ind.accepted) / (de.proposed + ind.proposed)
    np.testing.assert_array_equal(acc, ref_acc)
    assert np.all((ref_acc > 0.05) & (ref_acc < 0.95))  # a test of both branches


@pytest.mark.parametrize("system", [FW, PC], ids=["gaussian", "poisson"])
def test_chains_do_not_depend_on_the_kernel_threads(system):
    """The log-densities of a step's walkers run on every core (``kernel_threads``); each row
    is a pure function of its inputs, so one thread and two give the same chains, bit for bit
    (a whole batch through the sampler: starts, burn-in, production and convergence)."""
    from pipeline.parallel import kernel_threads
    from pipeline.uncertainty.posterior import sample_batch

    rng = np.random.default_rng(21)
    th, data = _pulses(system, rng, n=5)
    waves = [data.samples[i, : int(data.n_valid[i])] for i in range(5)]
    st = PosteriorSettings(max_steps=400, min_steps=100)
    out = []
    before = numba.get_num_threads()
    for n in (1, 2):
        with kernel_threads(n) as used:
            assert used == min(n, numba.config.NUMBA_NUM_THREADS)
            out.append(sample_batch(waves, system, st, seed=4, theta0=th))
    np.testing.assert_array_equal(out[0].draws, out[1].draws)
    np.testing.assert_array_equal(out[0].n_steps, out[1].n_steps)
    assert numba.get_num_threads() == before  # restored


@pytest.mark.parametrize("system", [FW, PC], ids=["gaussian", "poisson"])
def test_log_likelihood_shortcuts_are_the_plain_sum(system):
    """Skipped logarithms (empty photon samples, repeated arguments on the baseline) change
    no bit of the log-likelihood: the reference evaluates every term as the docstring writes
    it, in the same order."""
    rng = np.random.default_rng(3)
    th, data = _pulses(system, rng, n=4)
    rows = th[rng.integers(0, 4, 40)] + 0.05 * rng.normal(size=(40, N_PARAMS))
    pulse = np.arange(40) % 4
    ex = data.exposure.copy()
    if system.poisson:  # a dead-time dip: exposure below 1 on the surface echo
        ex[:, 12:20] = rng.uniform(0.2, 1.0, (4, 8))
    sysv = (
        system.sample_interval_s, system.pulse_sigma_s, system.group_index,
        system.offset_counts, system.poisson, system.floor_variance,
        system.excess_noise_factor * system.counts_per_photoelectron, 0.0,
    )  # fmt: skip
    got = log_lik_rows(rows, pulse, data.samples, data.n_valid, data.cos_water, *sysv, ex)
    mu = expected_rows(rows, data.cos_water[pulse], data.n_samples, *sysv[:4])
    ref = np.empty(40)
    for k in range(40):
        y, e, acc = data.samples[pulse[k]], ex[pulse[k]], 0.0
        for i in range(int(data.n_valid[pulse[k]])):
            if system.poisson:
                lam = e[i] * mu[k, i]
                acc += y[i] * math.log(lam) - lam
            else:
                v = sysv[5] + sysv[6] * max(mu[k, i] - sysv[3], 0.0)
                d = y[i] - mu[k, i]
                acc -= 0.5 * (d * d / v + math.log(v))
        ref[k] = acc
    if system.poisson:
        assert np.mean(data.samples == 0.0) > 0.3  # the empty-sample branch is exercised
    np.testing.assert_array_equal(got, ref)


@pytest.mark.parametrize("system", [FW, PC], ids=["gaussian", "poisson"])
def test_term_bounds_hold_every_term(system):
    """Each sample's bound (``rest[i] - rest[i + 1]``) is at least its log-likelihood term for
    any mean: terms of 4000 rows (wild ones too) evaluated as the docstring writes them, and
    over a dense grid of means; a Gaussian without shot noise as well."""
    rng = np.random.default_rng(8)
    th, data = _pulses(system, rng, n=2)
    rest, _ = loop_module.term_bounds(data, system)
    b = rest[:, :-1] - rest[:, 1:]
    mu_grid = np.concatenate([np.linspace(0.0, 300.0, 3001), np.geomspace(1e-6, 1e5, 500)])
    fsys = (system.floor_variance, system.excess_noise_factor * system.counts_per_photoelectron)
    for p in range(2):
        y = data.samples[p, : int(data.n_valid[p])]
        mu = mu_grid[:, None] + (0.0 if system.poisson else system.offset_counts - 50.0)
        if system.poisson:
            mu = np.maximum(mu, 1e-12)
            terms = y * np.log(mu) - mu
        else:
            v = fsys[0] + fsys[1] * np.maximum(mu - system.offset_counts, 0.0)
            terms = -0.5 * ((y - mu) ** 2 / v + np.log(v))
        assert np.all(terms <= b[p, : y.size])
        # and nearly attained on the grid (0.1-count steps): a bound, not a loose one
        np.testing.assert_allclose(terms.max(axis=0), b[p, : y.size], rtol=0.0, atol=0.02)
    if not system.poisson:
        quiet = dataclasses.replace(system, excess_noise_factor=0.0)
        rest0, _ = loop_module.term_bounds(data, quiet)
        np.testing.assert_allclose(rest0[:, :-1] - rest0[:, 1:], -0.5 * np.log(FW.floor_variance))


@pytest.mark.parametrize("n_t", [3, 40, 333, 800])
@pytest.mark.parametrize("phi", [0.0, 0.5, 0.97], ids=["white", "ar-0.5", "ar-0.97"])
def test_direct_autocorrelation_time_is_emcees(n_t, phi, monkeypatch):
    """The direct lag sums (short windows) and their FFT fallback (long ones) give emcee's
    ``integrated_time`` to 1e-12: AR(1) series of every memory, a constant parameter (NaN as
    in emcee) and chains too short for any window (emcee then takes ``taus[0] = 1``)."""
    rng = np.random.default_rng(n_t)
    e = rng.normal(size=(n_t, 16, 4, N_PARAMS))
    x = np.empty_like(e)
    x[0] = e[0]
    for t in range(1, n_t):
        x[t] = phi * x[t - 1] + e[t]
    x[:, :, 2, 6] = 1.5  # a stuck parameter
    got = autocorr_module.integrated_time_blocks(x)
    with np.errstate(invalid="ignore", divide="ignore"):
        ref = np.array([emcee.autocorr.integrated_time(x[:, :, p], tol=0) for p in range(4)])
    np.testing.assert_array_equal(np.isnan(got), np.isnan(ref))
    # (atol: a 3-step chain's window can close on a sum that is 0 to rounding)
    np.testing.assert_allclose(got[~np.isnan(ref)], ref[~np.isnan(ref)], rtol=1e-12, atol=1e-12)
    direct = autocorr_module._tau_direct(x, np.arange(4), n_t, 5.0, autocorr_module.MAX_DIRECT_LAGS)
    if phi < 0.9 and n_t > 3:  # short windows: the direct sums did the work
        assert np.isfinite(direct[~np.isnan(ref)]).all()
    # the FFT fallback, forced on every window past 4 lags, agrees too
    monkeypatch.setattr(autocorr_module, "MAX_DIRECT_LAGS", 4)
    if phi > 0.9 and n_t > 40:
        assert np.isinf(autocorr_module._tau_direct(x, np.arange(4), n_t, 5.0, 4)).any()
    got = autocorr_module.integrated_time_blocks(x)
    np.testing.assert_array_equal(np.isnan(got), np.isnan(ref))
    np.testing.assert_allclose(got[~np.isnan(ref)], ref[~np.isnan(ref)], rtol=1e-12, atol=1e-12)
