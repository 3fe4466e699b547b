"""The ensemble loop of the depth posterior, compiled: emcee's step with the same draws.

:func:`run_steps` advances the walkers of a batch of pulses as ``emcee.EnsembleSampler``
would with the two block moves of :mod:`~pipeline.uncertainty.posterior_moves` (the readable
reference: ``tests/uncertainty/test_waveform_kernel.py`` checks this loop against
``EnsembleSampler`` on those moves bit for bit), without a Python round trip per step.

Why the chains stay the same: every random number a step uses depends on the move drawn, never
on the walkers' positions (the red-blue split, the complementary walkers, the jitter, the
Student-t draws and the uniforms of the Metropolis tests have fixed shapes). So the
``RandomState`` is asked for them in emcee's order, step by step, before the steps are run
(:func:`_draw_block`); the independence proposals and their proposal densities, which depend on
the draws only, are formed there with numpy's own operations (the same rounding); the compiled
kernel (:func:`_advance`) then runs the steps: the DE proposals (elementwise, same operation
order, so the same bits), the model (:func:`~pipeline.uncertainty.waveform_kernel.
log_post_one`, row by row as before) and the accept/reject tests. The proposal density of a
walker a DE step moved is computed in the kernel (its matrix product rounds differently from
numpy's BLAS by ~1e-16 relative: an accept decision could differ only for a uniform within
that of the threshold).

Every core: the pulses of a batch never share walkers, so :func:`_advance` runs each pulse's
steps on its own, the pulses on numba's threads (:func:`pipeline.parallel.kernel_threads` sets
how many; ``bathy run`` uses its ``--workers``): the same chains for any number of threads.
The kernels compile with ``error_model="numpy"``, as the model's
(:mod:`~pipeline.uncertainty.waveform_kernel`: the same values wherever the default model did not
raise).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from pipeline.errors import NumericalError
from pipeline.parallel import choose_threading_layer
from pipeline.uncertainty.posterior_moves import BlockIndependenceMove
from pipeline.uncertainty.posterior_target import (
    PulseBatch,
    kernel_system,
    log_prob_blocks,
    prior_box,
)
from pipeline.uncertainty.waveform_kernel import log_post_one
from pipeline.uncertainty.waveform_model import N_PARAMS

__all__ = ["run_steps", "term_bounds"]

choose_threading_layer()  # before any parallel kernel runs (no TBB warning)

_DE, _IND = 0, 1
#: emcee's DEMove defaults (as :class:`~pipeline.uncertainty.posterior_moves.BlockDEMove`).
_DE_SIGMA = 1e-5
_DE_GAMMA0 = 2.38 / math.sqrt(2.0 * N_PARAMS)
#: Pre-drawn numbers per block of steps (bounds the memory of a large batch: ~16 MB).
_BLOCK_VALUES = 1 << 21


def run_steps(data: PulseBatch, pos, system, st, n_steps: int, thin: int, rng, proposal):
    """Advance the walkers ``pos`` (n_walkers, P, 9) of the pulses of ``data`` ``n_steps``.

    Moves and weights as the sampler's (DE and Student-t independence, mixed with weight
    ``st.independence_weight``; ``proposal`` = centres (P, 9) and scale matrices (P, 9, 9)).
    The generator is ``RandomState(rng.integers(2**31))``, as before.

    Returns
    -------
    positions : (n_walkers, P, 9) ndarray
    chain : (n_steps // thin, n_walkers, P, 9) ndarray
        The stored chain (every ``thin``-th step).
    acceptance : (P,) ndarray
        Fraction of proposals accepted per pulse (both moves).
    """
    nw, n_p = pos.shape[0], pos.shape[1]
    ind = BlockIndependenceMove(proposal[0], proposal[1], st.proposal_dof)
    w = st.independence_weight
    kinds = [_DE, _IND] if 0.0 < w < 1.0 else [_IND if w >= 1.0 else _DE]
    weights = np.array([1.0 - w, w]) if len(kinds) == 2 else np.array([1.0])
    weights /= weights.sum()
    rnd = np.random.RandomState(int(rng.integers(2**31)))
    coords = np.ascontiguousarray(pos, dtype=np.float64).copy()
    lp = np.ascontiguousarray(log_prob_blocks(coords.reshape(nw, -1), data, system)[:, 1:])
    lg = ind._log_g(coords)
    lg_ok = np.ones((nw, n_p), dtype=np.bool_)
    n_store = n_steps // thin
    chain = np.empty((n_store, nw, n_p, N_PARAMS))
    box = prior_box(data)
    sysv = kernel_system(system)
    rest, b_abs = term_bounds(data, system)
    args = (
        rest, b_abs, data.samples, data.n_valid, data.cos_water, box, data.ln_k_prior, sysv,
        data.exposure,
    )  # fmt: skip
    counts = np.zeros((2, n_p))  # accepted by DE, independence
    proposed = np.zeros(2, dtype=np.int64)
    per_step = nw * n_p * (N_PARAMS + 3)
    block = max(thin, (_BLOCK_VALUES // per_step) // thin * thin)
    done = 0
    while done < n_store * thin:
        n = min(block, n_store * thin - done)
        drawn = _draw_block(rnd, n, kinds, weights, nw, n_p, ind)
        err = _advance(
            coords, lp, lg, lg_ok, *drawn, ind.centre, ind.inv_chol, ind.dof, chain, done, thin,
            counts, proposed, *args,
        )  # fmt: skip
        if err >= 0:  # as _rows_log_post raises it
            raise NumericalError(f"log-likelihood or parameters not finite in walker row {err}")
        done += n
    acc = (counts[0] + counts[1]) / max(int(proposed.sum()), 1)
    return coords, (chain, acc)


def _draw_block(rnd, n: int, kinds, weights, nw: int, n_p: int, ind: BlockIndependenceMove):
    """The random numbers of ``n`` steps, drawn in emcee's order (see the module docstring).

    Returns ``kind`` (n,) int8; for the DE steps in order: ``halves`` (k, nw) int64, the
    complementary walkers ``j1``, ``j2`` (k, 2, nw, P) int64, ``jitter`` (k, 2, nw, P) (times
    sigma) and ``de_log_u`` (k, 2, nw, P) (rows past a half's walker count unused); for the
    independence steps in order: proposals ``q`` (k', nw, P, 9), their ``lg_q`` (k', nw, P)
    and ``ind_log_u`` (k', nw, P).
    """
    kind = np.empty(n, dtype=np.int8)
    # RandomState.choice(len(kinds), p=weights) is this: one uniform against the cumulative
    # weights (numpy's mtrand), without its per-call checks
    cdf = weights.cumsum()
    cdf /= cdf[-1]
    n_half = [int(np.sum(np.arange(nw) % 2 == h)) for h in (0, 1)]
    halves = np.zeros((n, nw), dtype=np.int64)
    j1s = np.zeros((n, 2, nw, n_p), dtype=np.int64)
    j2s = np.zeros((n, 2, nw, n_p), dtype=np.int64)
    jit = np.zeros((n, 2, nw, n_p))
    de_u = np.ones((n, 2, nw, n_p))
    z = np.empty((n, nw, n_p, N_PARAMS))
    chi = np.empty((n, nw, n_p, 1))
    ind_u = np.empty((n, nw, n_p))
    k_de = k_ind = 0
    for t in range(n):
        kd = kinds[int(cdf.searchsorted(rnd.random_sample(), side="right"))]
        kind[t] = kd
        if kd == _DE:  # BlockDEMove.propose's draws, in its order
            h = np.arange(nw) % 2
            rnd.shuffle(h)
            halves[k_de] = h
            for half in (0, 1):
                ns = n_half[half]
                nc = nw - ns
                j1 = rnd.randint(nc, size=(ns, n_p))
                j1s[k_de, half, :ns] = j1
                j2s[k_de, half, :ns] = (j1 + 1 + rnd.randint(nc - 1, size=(ns, n_p))) % nc
                jit[k_de, half, :ns] = _DE_SIGMA * rnd.randn(ns, n_p, 1)[:, :, 0]
                de_u[k_de, half, :ns] = rnd.rand(ns, n_p)
            k_de += 1
        else:  # BlockIndependenceMove.propose's draws, in its order
            z[k_ind] = rnd.randn(nw, n_p, N_PARAMS)
            chi[k_ind] = rnd.chisquare(ind.dof, size=(nw, n_p, 1))
            ind_u[k_ind] = rnd.rand(nw, n_p)
            k_ind += 1
    # the proposal from its draws exactly as BlockIndependenceMove forms it (numpy's own
    # matrix product and reductions: the same rounding)
    w = np.sqrt(ind.dof / chi[:k_ind])
    q = ind.centre + (ind.chol @ z[:k_ind, ..., None])[..., 0] * w
    lg_q = _log_g_steps(ind, q)
    de = (halves[:k_de], j1s[:k_de], j2s[:k_de], jit[:k_de], np.log(de_u[:k_de]))
    return kind, *de, np.ascontiguousarray(q), lg_q, np.log(ind_u[:k_ind])


def _log_g_steps(ind: BlockIndependenceMove, x: np.ndarray) -> np.ndarray:
    """:meth:`BlockIndependenceMove._log_g` of many steps' walkers ``x`` (k, nw, P, 9) at once.

    The same operations (numpy's matrix product per block, the sum over the last axis), so
    the same values as step by step.
    """
    z = (ind.inv_chol @ (x - ind.centre)[..., None])[..., 0]
    d = ind.centre.shape[1]
    return -0.5 * (ind.dof + d) * np.log1p(np.sum(z * z, axis=-1) / ind.dof)


def term_bounds(data: PulseBatch, system) -> tuple[np.ndarray, np.ndarray]:
    """Upper bounds of the log-likelihood terms from each sample on, for the early rejection.

    Each sample's term is bounded over every mean ``mu`` it could take. Poisson:
    ``y log(e mu) - e mu <= y log y - y`` (0 for ``y = 0``). Gaussian,
    ``-((y - mu)^2 / v + log v) / 2`` with ``v = F + S max(mu - O, 0)``: for ``mu <= O``
    (``v = F``) the largest is at ``mu = min(y, O)``; for ``mu >= O``, with
    ``c = y - O + F / S`` the term is ``-(c^2 / v - 2 c / S + v / S^2 + log v) / 2``, whose
    only maximum over ``v > 0`` is the root of ``v^2 / S^2 + v - c^2 = 0``,
    ``v* = 2 c^2 / (1 + sqrt(1 + 4 c^2 / S^2))``, taken at ``max(v*, F)``.

    Returns
    -------
    rest : (P, m + 1) ndarray
        ``rest[p, i]``: sum of pulse ``p``'s bounds over its valid samples ``i`` and after
        (0 at ``m``).
    b_abs : (P,) ndarray
        Sum of the bounds' magnitudes (the scale of the thresholds' slack).
    """
    y = data.samples
    if system.poisson:
        b = np.where(y > 0.0, y * np.log(np.where(y > 0.0, y, 1.0)) - y, 0.0)
    else:
        f, o = system.floor_variance, system.offset_counts
        s = system.excess_noise_factor * system.counts_per_photoelectron
        b = np.where(y <= o, -0.5 * math.log(f), -0.5 * ((y - o) ** 2 / f + math.log(f)))
        if s > 0.0:
            c = y - o + f / s
            v = np.maximum(2.0 * c * c / (1.0 + np.sqrt(1.0 + 4.0 * c * c / s**2)), f)
            b = np.maximum(b, -0.5 * ((c - v / s) ** 2 / v + np.log(v)))
        else:
            b = np.full(y.shape, -0.5 * math.log(f))
        if system.surface_misfit > 0.0:
            # any extra variance: v >= F keeps every term below -log(F) / 2
            b = np.maximum(b, -0.5 * math.log(f))
    b = np.where(data.valid, b + 1e-9 * (1.0 + np.abs(b)), 0.0)
    rest = np.zeros((y.shape[0], y.shape[1] + 1))
    rest[:, :-1] = np.cumsum(b[:, ::-1], axis=1)[:, ::-1]
    return rest, np.abs(b).sum(axis=1)


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _log_g_one(x, centre, inv_chol, dof):
    """Log Student-t proposal density of one block ``x`` (9,) (as ``BlockIndependenceMove``)."""
    d = x.shape[0]
    diff = x - centre
    total = 0.0
    for i in range(d):
        acc = 0.0
        for j in range(d):
            acc += inv_chol[i, j] * diff[j]
        total += acc * acc
    return -0.5 * (dof + d) * math.log1p(total / dof)


@numba.njit(cache=True, nogil=True, error_model="numpy", parallel=True)
def _advance(
    coords, lp, lg, lg_ok, kind, halves, j1s, j2s, jit, de_log_u, q_ind, lg_q, ind_log_u,
    centre, inv_chol, dof, chain, done, thin, counts, proposed,
    rest, b_abs, samples, n_valid, cos_water, box, ln_k_prior, system, exposure,
):  # fmt: skip
    """Run the pre-drawn steps on ``coords`` (nw, P, 9) and ``lp`` (nw, P) in place.

    ``lg`` (nw, P) the walkers' log proposal densities (valid where ``lg_ok``), ``chain`` the
    stored steps (step ``done + t`` is stored after it when ``(done + t + 1) % thin == 0``),
    ``counts`` (2, P) the accepted proposals of DE / independence, ``proposed`` (2,) the
    walker updates of each. Returns -1, or a walker row (``walker * P + pulse``) whose log
    posterior is NaN or ``+inf`` (or whose proposal holds NaN): the caller raises.

    The pulses' ensembles never meet (a DE move's complementary walkers are the same pulse's),
    so each pulse runs all the steps on its own (:func:`_advance_pulse`), the pulses side by
    side on every core (``numba.set_num_threads``): the same bits for any number of threads.
    """
    n_p = coords.shape[1]
    bad = np.empty(n_p, dtype=np.int64)
    for p in numba.prange(n_p):
        bad[p] = _advance_pulse(
            p, coords, lp, lg, lg_ok, kind, halves, j1s, j2s, jit, de_log_u, q_ind, lg_q,
            ind_log_u, centre, inv_chol, dof, chain, done, thin, counts, rest, b_abs, samples,
            n_valid, cos_water, box, ln_k_prior, system, exposure,
        )  # fmt: skip
    for p in range(n_p):
        if bad[p] >= 0:
            return bad[p]
    for t in range(kind.shape[0]):  # every walker is proposed a move at every step
        proposed[kind[t]] += coords.shape[0]
    return -1


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _advance_pulse(
    p, coords, lp, lg, lg_ok, kind, halves, j1s, j2s, jit, de_log_u, q_ind, lg_q, ind_log_u,
    centre, inv_chol, dof, chain, done, thin, counts, rest, b_abs, samples, n_valid, cos_water,
    box, ln_k_prior, system, exposure,
):  # fmt: skip
    """:func:`_advance`'s steps for pulse ``p`` alone (its walkers, its draws, its counts)."""
    nw, n_p, d = coords.shape
    sel = np.empty(nw, dtype=np.int64)
    comp = np.empty(nw, dtype=np.int64)
    q = np.empty(d)
    k_de, k_ind = 0, 0
    for t in range(kind.shape[0]):
        if kind[t] == 0:  # DE: red-blue halves, each block on its own Metropolis test
            for half in range(2):
                ns, nc = 0, 0
                for w in range(nw):
                    if halves[k_de, w] == half:
                        sel[ns] = w
                        ns += 1
                    else:
                        comp[nc] = w
                        nc += 1
                # the complementary half does not move during this half's update: each
                # walker's proposal, value and test in turn are those of the whole half at once
                for a in range(ns):
                    wa = sel[a]
                    c2 = comp[j2s[k_de, half, a, p]]
                    c1 = comp[j1s[k_de, half, a, p]]
                    r = jit[k_de, half, a, p]
                    for i in range(d):
                        g = _DE_GAMMA0 * (coords[c2, p, i] - coords[c1, p, i])
                        q[i] = (coords[wa, p, i] + g) + r
                    if _has_nan(q):
                        return wa * n_p + p
                    # accepted iff log u < new - old: rows shown to fall below are cut short
                    th_ = de_log_u[k_de, half, a, p] + lp[wa, p]
                    v = log_post_one(
                        q, p, th_ - _margin(th_, lp[wa, p], b_abs[p]), rest, samples, n_valid,
                        cos_water, box, ln_k_prior, system, exposure,
                    )  # fmt: skip
                    if math.isnan(v) or v == np.inf:
                        return wa * n_p + p
                    if de_log_u[k_de, half, a, p] < v - lp[wa, p]:
                        coords[wa, p, :] = q
                        lp[wa, p] = v
                        lg_ok[wa, p] = False
                        counts[0, p] += 1.0
            k_de += 1
        else:  # independence Metropolis-Hastings from the fixed Student-t
            for w in range(nw):
                qw = q_ind[k_ind, w, p]
                if _has_nan(qw):
                    return w * n_p + p
                if not lg_ok[w, p]:
                    lg[w, p] = _log_g_one(coords[w, p], centre[p], inv_chol[p], dof)
                    lg_ok[w, p] = True
                # accepted iff log u < new - old + lg(x) - lg(q): rows shown below are cut short
                th_ = ind_log_u[k_ind, w, p] + lp[w, p] - lg[w, p] + lg_q[k_ind, w, p]
                v = log_post_one(
                    qw, p, th_ - _margin(th_, lp[w, p], b_abs[p] + abs(lg[w, p])), rest, samples,
                    n_valid, cos_water, box, ln_k_prior, system, exposure,
                )  # fmt: skip
                if math.isnan(v) or v == np.inf:
                    return w * n_p + p
                log_alpha = v - lp[w, p] + lg[w, p] - lg_q[k_ind, w, p]
                if ind_log_u[k_ind, w, p] < log_alpha:
                    coords[w, p, :] = qw
                    lp[w, p] = v
                    lg[w, p] = lg_q[k_ind, w, p]
                    counts[1, p] += 1.0
            k_ind += 1
        step = done + t + 1
        if step % thin == 0:
            chain[step // thin - 1, :, p, :] = coords[:, p, :]
    return -1


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _margin(thr, lp, scale):
    """Slack under a Metropolis threshold for the early rejection.

    Rounding moves the sums by ~1e-13 of these magnitudes; the slack is 1e-6 of them, so no
    row that could pass is cut.
    """
    return 1e-6 * (1.0 + abs(thr) + abs(lp) + scale)


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _has_nan(x):
    """Whether the vector ``x`` holds a NaN."""
    for i in range(x.shape[0]):
        if math.isnan(x[i]):
            return True
    return False
