"""emcee moves on independent blocks of the walker vector, one block per pulse.

:class:`BlockDEMove` (differential evolution) and :class:`BlockIndependenceMove`
(independence Metropolis–Hastings from a Student-t) each accept or reject every pulse's block
on its own log posterior (the ``blobs`` of
:func:`~pipeline.uncertainty.posterior_target.log_prob_blocks`): every pulse is an exact MCMC of
its own posterior, and the model is evaluated once for all pulses and walkers.
"""

from __future__ import annotations

import math

import emcee
import numpy as np

__all__ = ["BlockDEMove", "BlockIndependenceMove", "run_moves_python"]


class BlockDEMove(emcee.moves.Move):
    """Differential evolution on independent blocks of the parameter vector.

    The walkers carry ``n_blocks`` independent pulses side by side (``block`` parameters
    each). Every block gets emcee's :class:`~emcee.moves.DEMove` proposal from its own random
    pair of complementary walkers (red-blue halves, as in emcee) and its own Metropolis
    decision from its own log posterior (the log-probability function's blobs), so each block
    is exactly a DE ensemble sampler of its pulse; batching only shares the model evaluations.

    Parameters
    ----------
    n_blocks, block : int
        Pulses and parameters per pulse.
    sigma : float
        Jitter added to every proposal (emcee's default).
    gamma0 : float, optional
        Scale of the difference vector; default ``2.38 / sqrt(2 block)`` (optimal for a
        Gaussian target).
    """

    def __init__(self, n_blocks: int, block: int, sigma: float = 1e-5, gamma0=None):
        self.n_blocks, self.block, self.sigma = n_blocks, block, sigma
        self.g0 = 2.38 / math.sqrt(2.0 * block) if gamma0 is None else gamma0
        self.reset()

    def reset(self) -> None:
        """Zero the per-block acceptance counters."""
        self.accepted = np.zeros(self.n_blocks)
        self.proposed = 0

    def propose(self, model, state):
        """One red-blue DE update of every block; returns the new state and acceptances."""
        nw = state.coords.shape[0]
        nb, b = self.n_blocks, self.block
        rnd = model.random
        coords = state.coords.copy()
        blocks = np.reshape(state.blobs, (nw, nb)).copy()
        accepted = np.zeros(nw, dtype=bool)
        halves = np.arange(nw) % 2
        rnd.shuffle(halves)
        cols = np.arange(nb)
        for half in (0, 1):
            sel = halves == half
            s = coords[sel].reshape(-1, nb, b)
            c = coords[~sel].reshape(-1, nb, b)
            ns, nc = s.shape[0], c.shape[0]
            j1 = rnd.randint(nc, size=(ns, nb))
            j2 = (j1 + 1 + rnd.randint(nc - 1, size=(ns, nb))) % nc
            q = s + self.g0 * (c[j2, cols] - c[j1, cols]) + self.sigma * rnd.randn(ns, nb, 1)
            _, new_blobs = model.compute_log_prob_fn(q.reshape(ns, nb * b))
            new = np.reshape(new_blobs, (ns, nb))
            old = blocks[sel]
            acc = np.log(rnd.rand(ns, nb)) < new - old  # old is finite: inside the prior
            coords[sel] = np.where(acc[:, :, None], q, s).reshape(ns, nb * b)
            blocks[sel] = np.where(acc, new, old)
            accepted[sel] = acc.any(axis=1)
            self.accepted += acc.sum(axis=0)
        self.proposed += nw
        blobs = blocks if np.ndim(state.blobs) == 2 else blocks[:, 0]
        new_state = emcee.State(
            coords, log_prob=blocks.sum(axis=1), blobs=blobs, random_state=state.random_state
        )
        return new_state, accepted


class BlockIndependenceMove(emcee.moves.Move):
    """Independence Metropolis–Hastings on independent blocks, from a Student-t proposal.

    Each block (pulse) ``p`` proposes ``q = c_p + L_p z sqrt(dof / chi²_dof)``, a
    multivariate Student-t around ``c_p`` with scale matrix ``L_p L_p^T``, whatever the
    walker's position, and accepts with probability
    ``min(1, pi(q) g(x) / (pi(x) g(q)))`` (``g`` the proposal density): a valid kernel of each
    pulse's posterior for any fixed proposal. With a proposal close to the posterior (the
    burn-in walkers' mean and covariance), most proposals are accepted and successive draws
    are nearly independent; where the posterior is far from it (a weak, skewed column) the
    acceptance drops and the differential-evolution move it is mixed with does the work.
    One model evaluation per step for all the walkers (no red-blue halves).

    Parameters
    ----------
    centre : (n_blocks, block) ndarray
    scale : (n_blocks, block, block) ndarray
        Scale matrices (positive definite).
    dof : float
        Degrees of freedom (heavier tails than the posterior keep the weights bounded).
    """

    def __init__(self, centre: np.ndarray, scale: np.ndarray, dof: float = 5.0):
        self.centre = np.asarray(centre, dtype=np.float64)
        self.chol = np.linalg.cholesky(scale)
        self.inv_chol = np.linalg.inv(self.chol)
        self.dof = float(dof)
        self.reset()

    def reset(self) -> None:
        """Zero the per-block acceptance counters."""
        self.accepted = np.zeros(self.centre.shape[0])
        self.proposed = 0

    def _log_g(self, x: np.ndarray) -> np.ndarray:
        """Log proposal density (n, n_blocks), up to a per-block constant (cancels)."""
        z = (self.inv_chol @ (x - self.centre)[..., None])[..., 0]
        d = self.centre.shape[1]
        return -0.5 * (self.dof + d) * np.log1p(np.sum(z * z, axis=2) / self.dof)

    def propose(self, model, state):
        """One independence proposal per walker and block; returns the state and acceptances."""
        nw = state.coords.shape[0]
        nb, b = self.centre.shape
        rnd = model.random
        x = state.coords.reshape(nw, nb, b)
        z = rnd.randn(nw, nb, b)
        w = np.sqrt(self.dof / rnd.chisquare(self.dof, size=(nw, nb, 1)))
        q = self.centre + (self.chol @ z[..., None])[..., 0] * w
        _, new_blobs = model.compute_log_prob_fn(q.reshape(nw, nb * b))
        new = np.reshape(new_blobs, (nw, nb))
        old = np.reshape(state.blobs, (nw, nb))
        log_alpha = new - old + self._log_g(x) - self._log_g(q)
        acc = np.log(rnd.rand(nw, nb)) < log_alpha
        coords = np.where(acc[:, :, None], q, x).reshape(nw, nb * b)
        blocks = np.where(acc, new, old)
        self.accepted += acc.sum(axis=0)
        self.proposed += nw
        blobs = blocks if np.ndim(state.blobs) == 2 else blocks[:, 0]
        new_state = emcee.State(
            coords, log_prob=blocks.sum(axis=1), blobs=blobs, random_state=state.random_state
        )
        return new_state, acc.any(axis=1)


def run_moves_python(log_prob_fn, pos, st, n_steps: int, thin: int, rng, proposal):
    """The ``emcee.EnsembleSampler`` loop on the block moves, in Python, on any block density.

    The readable reference of :func:`pipeline.uncertainty.posterior_loop.run_steps` (same
    generator, move choice, moves and results) for a target the compiled loop does not hold:
    ``log_prob_fn(coords)`` gives ``(n_walkers, 1 + P)`` as
    :func:`~pipeline.uncertainty.posterior_target.log_prob_blocks` (a test's known density, or
    the numpy reference model). Arguments and returns as ``run_steps``.
    """
    nw, n_p = pos.shape[0], pos.shape[1]
    de = BlockDEMove(n_p, pos.shape[2])
    ind = BlockIndependenceMove(proposal[0], proposal[1], st.proposal_dof)
    w = st.independence_weight
    moves = [(de, 1.0 - w), (ind, w)] if 0.0 < w < 1.0 else [(ind if w >= 1.0 else de, 1.0)]
    weights = np.array([m[1] for m in moves])
    weights /= weights.sum()
    rnd = np.random.RandomState(int(rng.integers(2**31)))

    def evaluate(coords):
        out = log_prob_fn(coords)
        return out[:, 0], out[:, 1:]

    model = emcee.model.Model(None, evaluate, map, rnd)
    coords = pos.reshape(nw, -1).copy()
    state = emcee.State(coords, *evaluate(coords))
    chain = np.empty((n_steps // thin, nw, coords.shape[1]))
    for k in range(chain.shape[0]):
        for _ in range(thin):
            move = moves[rnd.choice(len(moves), p=weights)][0]
            state, _ = move.propose(model, state)
        chain[k] = state.coords
    acc = (de.accepted + ind.accepted) / max(de.proposed + ind.proposed, 1)
    return state.coords.reshape(pos.shape), (chain.reshape(-1, *pos.shape), acc)
