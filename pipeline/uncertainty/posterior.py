"""Posterior of the bottom depth of pulses by MCMC (emcee) on the process-side waveform model.

Modules
-------
* :mod:`~pipeline.uncertainty.posterior_settings`: settings, prior bounds and per-pulse flags;
* :mod:`~pipeline.uncertainty.posterior_target`: the pulses' data, the priors and the log
  posterior;
* :mod:`~pipeline.uncertainty.posterior_start`: detector starts, posterior modes, start balls;
* :mod:`~pipeline.uncertainty.posterior_moves`: the block-wise emcee moves (and emcee's loop
  on them in Python, the reference);
* :mod:`~pipeline.uncertainty.posterior_loop`: that loop compiled (the same chains);
* :mod:`~pipeline.uncertainty.posterior_autocorr`: emcee's integrated autocorrelation times;
* this module: the sampler and its convergence (:func:`sample_batch`); it re-exports the
  public names of the modules above;
* :mod:`~pipeline.uncertainty.seabed_posterior`: the draws carried to the refracted seabed point.

Parameters and priors
---------------------
``theta`` follows :data:`pipeline.uncertainty.waveform_model.PARAM_NAMES` (depth, surface time,
log areas, log attenuation, background, widths) under independent bounded priors (see
:mod:`~pipeline.uncertainty.posterior_target`).

Sampling
--------
1. Start: the detector's estimate, moved to every pulse's posterior mode by batched damped
   Fisher scoring (:mod:`~pipeline.uncertainty.posterior_start`).
2. Walkers: the mode plus a small ball of the Laplace covariance times ``init_scale``.
3. emcee's ensemble loop (the :class:`emcee.EnsembleSampler` step: a move drawn by weight from
   one ``RandomState``, then proposed; compiled in :mod:`~pipeline.uncertainty.posterior_loop`
   with the same draws and decisions, so the same chains) with the pulses of a batch side by
   side in one walker vector: two emcee moves act on each pulse's block independently
   (:class:`BlockDEMove`, differential evolution, and :class:`BlockIndependenceMove`, an
   independence Metropolis–Hastings move from a Student-t fitted to the burn-in), each with
   its own accept/reject from the pulse's own log posterior (the ``blobs`` of
   :func:`log_prob_blocks`): every pulse is an exact MCMC of its own posterior, and the model
   is evaluated once for all pulses and walkers, compiled row by row
   (:mod:`~pipeline.uncertainty.waveform_kernel`). ``burn_steps`` are discarded (the
   independence proposal is adapted once, at their end, then fixed).
4. Convergence, per pulse: production in chunks of ``chunk_steps`` until the chain is at
   least ``tau_factor`` (35) integrated autocorrelation times long (emcee's
   ``integrated_time`` for all pulses at once, :func:`~pipeline.uncertainty.
   posterior_autocorr.integrated_time_blocks`; the largest over the parameters) or
   ``max_steps``; the mean
   acceptance fraction must lie in ``acceptance_range`` (0.15, 0.8). Otherwise the pulse is
   flagged :attr:`PosteriorFlag.NOT_CONVERGED` / :attr:`PosteriorFlag.ACCEPTANCE` (its
   summaries are still given). Converged pulses leave the batch; the rest continue.
5. Restart, once: the pulses still unconverged after ``restart_steps`` (1500) production
   steps refit their independence proposal to the second half of their own production, which
   becomes burn-in, and start a new chain (``max_steps`` counts both). The burn-in's walkers
   start in a ball of half the Laplace sigma and 150 steps do not spread them over a posterior
   much wider or more skewed than the Laplace estimate (weak water columns, a free bottom
   width): the proposal fitted to them is too narrow and the chain crawls. The new chains'
   moves are differential evolution but for ``restart_independence_weight`` (0.2) of them:
   a posterior the Student-t refitted to the chains' own production still cannot follow (a
   clipped surface echo's ridge: acceptance 0.01-0.13 on suite scenes) is followed by DE,
   which moves along its shape. Adaptation stops at the restart, so every chain is still an
   exact MCMC of its pulse's posterior; pulses converged earlier are untouched
   (``tests/uncertainty/test_posterior_restart.py``).

Seabed point
------------
The draws become 3-D seabed points with the processing's own refraction in
:mod:`pipeline.uncertainty.seabed_posterior`.

Cost: see ``benchmarks/RESULTS_posterior.md`` (tens of CPU milliseconds per pulse; the pulses
whose chains do not converge run to ``max_steps`` and dominate).
"""

from __future__ import annotations

import dataclasses
import functools
from dataclasses import dataclass
from typing import Any

import numpy as np

from pipeline.process.detect import DetectSettings
from pipeline.uncertainty import posterior_target, waveform_kernel
from pipeline.uncertainty.posterior_autocorr import integrated_time_blocks
from pipeline.uncertainty.posterior_loop import run_steps
from pipeline.uncertainty.posterior_moves import (
    BlockDEMove,
    BlockIndependenceMove,
    run_moves_python,
)
from pipeline.uncertainty.posterior_settings import PosteriorFlag, PosteriorSettings
from pipeline.uncertainty.posterior_start import (
    _best_modes,
    _initial_ball,
    _start,
    posterior_modes,
    start_theta,
)
from pipeline.uncertainty.posterior_target import (
    PulseBatch,
    _prior_precision,
    log_prob,
    log_prob_blocks,
    make_pulse_batch,
)
from pipeline.uncertainty.waveform_model import N_PARAMS, WaveformSystem, covariance

__all__ = [
    "PosteriorFlag",
    "PosteriorSettings",
    "PulseBatch",
    "PulseChains",
    "BlockDEMove",
    "BlockIndependenceMove",
    "make_pulse_batch",
    "log_prob",
    "log_prob_blocks",
    "start_theta",
    "posterior_modes",
    "sample_batch",
    "integrated_time_blocks",
    "interval_summary",
]


@dataclass(frozen=True)
class PulseChains:
    """The sampled posteriors of a batch of pulses.

    Attributes
    ----------
    draws : (P, k, 9) ndarray
        Thinned production draws per pulse (NaN-free; pulses without a start hold their
        start-less zeros and the NO_START flag).
    mode : (P, 9) ndarray
        Posterior modes the walkers started around.
    acceptance : (P,) ndarray
        Per-pulse acceptance fraction of the production chain.
    tau_steps : (P, 9) ndarray
        Integrated autocorrelation time per pulse and parameter, in steps.
    n_steps : (P,) int64
        Production steps per pulse (a restarted pulse's: its new chain's; the steps its
        restart discarded are not counted).
    flags : (P,) uint16
        :class:`PosteriorFlag` bits.
    """

    draws: np.ndarray
    mode: np.ndarray
    acceptance: np.ndarray
    tau_steps: np.ndarray
    n_steps: int
    flags: np.ndarray

    @property
    def converged(self) -> np.ndarray:
        """(P,) bool: no NOT_CONVERGED, ACCEPTANCE or NO_START flag."""
        bad = PosteriorFlag.NOT_CONVERGED | PosteriorFlag.ACCEPTANCE | PosteriorFlag.NO_START
        return (self.flags & np.uint16(bad)) == 0


def sample_batch(
    waveforms: Any,
    system: WaveformSystem,
    settings: PosteriorSettings | None = None,
    *,
    cos_water: Any = 1.0,
    theta0: Any = None,
    seed: int = 0,
    detect_settings: DetectSettings | None = None,
    detect_noise: tuple[int | None, float] | None = None,
    exposure: Any = None,
) -> PulseChains:
    """Sample the posteriors of a batch of waveforms with one emcee ensemble.

    Parameters
    ----------
    waveforms : (P, m) array_like or sequence of 1-D arrays
    system : WaveformSystem
    settings : PosteriorSettings, optional
    cos_water : float or (P,) array_like
        Cosine of each pulse's in-water angle from the vertical.
    theta0 : (P, 9) array_like, optional
        Starting estimates; default :func:`start_theta` (the detector's) per pulse.
    seed : int
        Seeds the start balls and emcee's generator (results depend on the batch's make-up).
    detect_settings, detect_noise : optional
        The survey detector's settings and ``(noise_samples, shot_noise_counts)``, for the
        starts (:func:`start_theta`): the same detections the survey's points come from.
    exposure : like ``waveforms``, optional
        Live share of each sample (photon counting's dead time; see
        :class:`~pipeline.uncertainty.posterior_target.PulseBatch`); default 1.

    Returns
    -------
    PulseChains
        ``n_steps`` per pulse: a pulse stops at the first chunk boundary where it converged
        (a restarted pulse's: the steps of its new chain).
    """
    st = settings or PosteriorSettings()
    data = make_pulse_batch(waveforms, system, st, cos_water, exposure)
    n_p = len(data)
    rng = np.random.default_rng(seed)
    starts = [None] * n_p if theta0 is None else list(np.asarray(theta0, dtype=np.float64))
    flags = np.zeros(n_p, dtype=np.uint16)
    for i in range(n_p):
        if starts[i] is None:
            one = data.pulse(i)
            starts[i], scanned = _start(
                one.samples[0],
                system,
                float(one.cos_water[0]),
                detect_settings,
                detect_noise,
                exposure=one.exposure[0],
            )
            if scanned:
                flags[i] |= np.uint16(PosteriorFlag.START_SCANNED)
    has = np.array([th is not None for th in starts], dtype=bool)
    flags[~has] |= np.uint16(PosteriorFlag.NO_START)
    if not has.all():  # sample the others; the start-less pulses get zeros and the flag
        sub = (
            sample_batch(
                [data.samples[i, data.valid[i]] for i in np.flatnonzero(has)],
                system,
                st,
                cos_water=data.cos_water[has],
                theta0=np.array([starts[i] for i in np.flatnonzero(has)]),
                seed=seed,
                exposure=[data.exposure[i, data.valid[i]] for i in np.flatnonzero(has)],
            )
            if has.any()
            else None
        )
        k = sub.draws.shape[1] if sub is not None else 1
        draws, modes = np.zeros((n_p, k, N_PARAMS)), np.zeros((n_p, N_PARAMS))
        acc, tau = np.zeros(n_p), np.zeros((n_p, N_PARAMS))
        n_steps = np.zeros(n_p, dtype=np.int64)
        if sub is not None:
            draws[has], modes[has], acc[has], tau[has] = (
                sub.draws,
                sub.mode,
                sub.acceptance,
                sub.tau_steps,
            )
            n_steps[has], flags[has] = sub.n_steps, flags[has] | sub.flags
        return PulseChains(draws, modes, acc, tau, n_steps, flags)
    modes, infos = _best_modes(data, system, np.array(starts))
    scales = np.zeros((n_p, N_PARAMS, N_PARAMS))
    p0 = np.zeros((st.n_walkers, n_p * N_PARAMS))
    for i in range(n_p):
        scales[i] = covariance(infos[i] + _prior_precision(data, i))
        ball = _initial_ball(data, i, system, modes[i], infos[i], st.n_walkers, st.init_scale, rng)
        p0[:, N_PARAMS * i : N_PARAMS * (i + 1)] = ball
    pos = p0.reshape(st.n_walkers, n_p, N_PARAMS)
    centres = modes.copy()
    if st.burn_steps:
        pos, (burn, _) = _run(
            data,
            np.arange(n_p),
            pos,
            system,
            st,
            st.burn_steps,
            1,
            rng,
            (centres, scales * st.proposal_scale**2),
        )
        # adapt the independence proposal once, at the end of the burn-in (fixed afterwards,
        # but for one restart of the chains still unconverged after restart_steps)
        _refit_proposal(burn[burn.shape[0] // 2 :], range(n_p), centres, scales)
    proposal = (centres, scales * st.proposal_scale**2)
    # production in chunks; converged pulses leave, the others continue from where they are
    # the stored chains, (steps, walkers, P, 9), grown by doubling; n_stored per pulse
    stored = np.empty((0, st.n_walkers, n_p, N_PARAMS))
    n_stored = np.zeros(n_p, dtype=np.int64)
    acc_sum = np.zeros(n_p)
    n_steps = np.zeros(n_p, dtype=np.int64)
    tau = np.full((n_p, N_PARAMS), np.inf)
    active = np.arange(n_p)
    spent = np.zeros(n_p, dtype=np.int64)  # production steps discarded by a restart
    restarted = False
    st_run = st
    while active.size:
        a0 = active[0]
        chunk = min(st.chunk_steps, st.max_steps - int(spent[a0] + n_steps[a0]))
        chunk = max(st.thin, chunk - chunk % st.thin)  # whole stored steps
        sub_prop = (proposal[0][active], proposal[1][active])
        new_pos, (chain, acc) = _run(
            data, active, pos[:, active], system, st_run, chunk, st.thin, rng, sub_prop
        )
        pos[:, active] = new_pos
        n_steps[active] += chunk
        acc_sum[active] += acc * chunk
        k0 = int(n_stored[active[0]])  # the active pulses started together: same lengths
        if k0 + chain.shape[0] > stored.shape[0]:
            grown = np.empty((max(2 * stored.shape[0], k0 + chain.shape[0]), *stored.shape[1:]))
            grown[: stored.shape[0]] = stored
            stored = grown
        stored[k0 : k0 + chain.shape[0], :, active] = chain
        n_stored[active] += chain.shape[0]
        # the active pulses started together: their chains are equally long, checked at once
        steps = int(n_steps[active[0]])
        if steps < st.min_steps and spent[a0] + steps < st.max_steps:
            continue
        t_a = st.thin * integrated_time_blocks(stored, active, k0 + chain.shape[0])
        tau[active] = np.where(np.isfinite(t_a), t_a, np.inf)
        done = (steps >= st.tau_factor * tau[active].max(axis=1)) | (
            spent[active] + steps >= st.max_steps
        )
        active = active[~done]
        if (
            active.size
            and not restarted
            and st.restart_steps
            and steps >= st.restart_steps
            and st.max_steps - steps >= st.min_steps  # room for a new chain's first check
        ):
            # once: the chains still unconverged refit their proposal to their own production
            # so far (its second half) and start afresh, what came before becoming burn-in
            # (adaptation stops there, so each chain stays an exact MCMC: Roberts & Rosenthal
            # 2007 ask no more of finitely many adaptations). All of them restart (their
            # chains must stay equally long), a degenerate refit keeping its old proposal
            restarted = True
            # only the restarted chains run on (the converged ones have left). Where the
            # Student-t fitted to the burn-in could not follow their posterior, the one refitted
            # below to their own production seldom does better on suite scenes: differential
            # evolution, which moves along a posterior's own shape, takes the larger share
            st_run = dataclasses.replace(st, independence_weight=st.restart_independence_weight)
            k1 = k0 + chain.shape[0]
            _refit_proposal(stored[k1 // 2 : k1], active, centres, scales)
            proposal = (centres, scales * st.proposal_scale**2)
            spent[active] += n_steps[active]
            n_steps[active] = 0
            n_stored[active] = 0
            acc_sum[active] = 0.0
    short = n_steps < st.tau_factor * tau.max(axis=1)
    flags[short] |= np.uint16(PosteriorFlag.NOT_CONVERGED)
    acc = acc_sum / np.maximum(n_steps, 1)
    lo, hi = st.acceptance_range
    flags[(acc <= lo) | (acc >= hi)] |= np.uint16(PosteriorFlag.ACCEPTANCE)
    # the same number of draws for every pulse, evenly spread over each pulse's whole chain
    flats = [stored[: n_stored[i], :, i].reshape(-1, N_PARAMS) for i in range(n_p)]
    n_draws = min(st.max_draws, *(f.shape[0] for f in flats))
    draws = np.stack([f[np.linspace(0, f.shape[0] - 1, n_draws).astype(np.int64)] for f in flats])
    d_lo = np.quantile(draws[:, :, 0], 0.025, axis=1)
    d_hi = np.quantile(draws[:, :, 0], 0.975, axis=1)
    span = data.upper[:, 0] - data.lower[:, 0]
    edge = (d_lo <= data.lower[:, 0] + 1e-3 * span) | (d_hi >= data.upper[:, 0] - 1e-3 * span)
    flags[edge] |= np.uint16(PosteriorFlag.AT_PRIOR_BOUND)
    return PulseChains(draws, modes, acc, tau, n_steps, flags)


def _refit_proposal(chain, pulses, centres, scales) -> None:
    """Centre and scale the pulses' independence proposals on ``chain`` (steps, walkers, P, 9).

    In place; a pulse whose sample covariance is degenerate keeps its old proposal.
    """
    for i in pulses:
        x = chain[:, :, i].reshape(-1, N_PARAMS)
        cov = np.cov(x, rowvar=False)
        if np.all(np.linalg.eigvalsh(cov) > 1e-12 * np.max(np.diag(cov))):
            centres[i], scales[i] = x.mean(axis=0), cov


def _run(data: PulseBatch, pulses, pos, system, st, n_steps: int, thin: int, rng, proposal):
    """Advance the walkers ``pos`` (n_walkers, len(pulses), 9) of some pulses ``n_steps``.

    Moves: :class:`BlockDEMove` and :class:`BlockIndependenceMove` (``proposal`` = centres and
    scale matrices of these pulses), mixed with weight ``st.independence_weight``.

    Returns
    -------
    positions : (n_walkers, len(pulses), 9) ndarray
    chain : (n_steps // thin, n_walkers, len(pulses), 9) ndarray
        The stored chain.
    acceptance : (len(pulses),) ndarray
        Fraction of proposals accepted per pulse (both moves).
    """
    sub = PulseBatch(*(getattr(data, f)[pulses] for f in _BATCH_FIELDS))
    if log_prob_blocks is not posterior_target.log_prob_blocks or (
        posterior_target.log_post_rows is not waveform_kernel.log_post_rows
    ):  # another target (a test's known density, the numpy model): emcee's loop in Python
        fn = functools.partial(log_prob_blocks, data=sub, system=system)
        return run_moves_python(fn, pos, st, n_steps, thin, rng, proposal)
    # emcee's EnsembleSampler loop on these moves, compiled (posterior_loop: the same
    # generator, draws and decisions, so the same chains; without its per-step Python: the
    # moves' numpy and the sampler's bookkeeping cost more than the compiled model)
    return run_steps(sub, pos, system, st, n_steps, thin, rng, proposal)


_BATCH_FIELDS = (
    "samples",
    "valid",
    "cos_water",
    "lower",
    "upper",
    "t_last_s",
    "ln_k_prior",
    "exposure",
)


def interval_summary(values: Any, axis: int = -1) -> dict[str, np.ndarray]:
    """Median and central 68 % and 95 % intervals of posterior draws along ``axis``.

    Returns
    -------
    dict
        ``median``, ``lo68``, ``hi68``, ``lo95``, ``hi95`` and ``std`` (ddof 1).
    """
    v = np.asarray(values, dtype=np.float64)
    q = np.quantile(v, [0.5, 0.16, 0.84, 0.025, 0.975], axis=axis)
    return {
        "median": q[0],
        "lo68": q[1],
        "hi68": q[2],
        "lo95": q[3],
        "hi95": q[4],
        "std": np.std(v, axis=axis, ddof=1),
    }
