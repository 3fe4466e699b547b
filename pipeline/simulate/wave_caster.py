"""Rays against the moving sea: each ray meets the surface of its own pulse's time.

The wave surface is a height field ``eta(x, y, t)`` (:class:`terrain.evolving_sea.EvolvingSea`),
so a ray ``p(s) = o + s d`` meets it at the root of ``f(s) = o_z + s d_z - eta(p_xy(s), t)``.
No mesh is built: a mesh per time slab would cost a rebuild of a million-triangle scene every
~0.07 s of survey, where the root is found directly on the exact (spline) surface:

* start at the mean level, ``s0 = (level - o_z) / d_z``;
* Newton steps ``s -= f / f'`` with ``f' = d_z - grad(eta) . d_xy``. ``f`` is monotonic along
  the ray (one root, the first hit) while ``|grad(eta)| tan(ray off-vertical) < 1``: slopes
  below 2.7 for a 20 degree ray, i.e. always for linear waves, so Newton converges in 3-5 steps;
* rays still off by more than :data:`TOLERANCE_M` after :data:`NEWTON_STEPS` are bisected on the
  bracket given by the sea's height bound (never silently left unsolved).

The normal is the spline's at the root, in float64; memory is O(rays) plus the sea's few cached
boundary grids. Same contract as :meth:`pipeline.simulate.trace.MeshCaster.cast`, plus the
rays' times.
"""

from __future__ import annotations

import numpy as np

__all__ = ["WaveCaster", "NEWTON_STEPS", "TOLERANCE_M", "unresolved_normals"]

NEWTON_STEPS = 8
TOLERANCE_M = 1e-6
_BISECTIONS = 60


class WaveCaster:
    """First hit of rays with an :class:`~terrain.evolving_sea.EvolvingSea` at their times.

    Parameters
    ----------
    sea : EvolvingSea
    unresolved_mss : float
        Slope variance of the waves the sea does not resolve (Cox-Munk minus the resolved);
        the tracer refracts each sub-ray through a facet tilted by a draw of it
        (:func:`unresolved_normals`).
    seed : int
        Seed of those draws.
    """

    def __init__(self, sea, unresolved_mss: float = 0.0, seed: int = 0) -> None:
        self.sea = sea
        self.unresolved_mss = float(unresolved_mss)
        self.seed = int(seed)
        self.level_m = sea.mean_level_m
        self.zmax = self.level_m + sea.height_bound_m
        self.zmin = self.level_m - sea.height_bound_m

    def _f(self, o, d, s, t):
        p = o + s[:, None] * d
        z, gx, gy = self.sea.height_and_gradient(p[:, 0], p[:, 1], t)
        f = p[:, 2] - z
        fp = d[:, 2] - gx * d[:, 0] - gy * d[:, 1]
        return f, fp, gx, gy

    def cast(self, origin_m: np.ndarray, direction: np.ndarray, nthreads: int = 0, t_s=None):
        """First hit of each ray with the surface at its time.

        Parameters
        ----------
        origin_m, direction : (n, 3) float64
            Ray origins and unit directions.
        nthreads : int
            Unused (numpy); kept for the caster contract.
        t_s : (n,) float64, optional
            Time of each ray (its pulse's emission time); default 0.

        Returns
        -------
        hit : (n,) bool
        t_m : (n,) float64
            Distance along the ray to the hit (0 where none).
        normal : (n, 3) float64
            Upward unit normal at the hit (0 where none).
        """
        o = np.asarray(origin_m, dtype=np.float64)
        d = np.asarray(direction, dtype=np.float64)
        n = o.shape[0]
        t = np.zeros(n) if t_s is None else np.broadcast_to(np.asarray(t_s, float), (n,))
        dz = d[:, 2]
        # a ray meets the sea only going down from above its crests or up from below its troughs
        # (the tracer's rays always start outside the slab of the waves, or on the seabed)
        going = ((dz < 0) & (o[:, 2] > self.zmin)) | ((dz > 0) & (o[:, 2] < self.zmax))
        hit = np.zeros(n, dtype=bool)
        s_out = np.zeros(n)
        nrm = np.zeros((n, 3))
        idx = np.flatnonzero(going)
        j, _ = self.sea.slabs(t[idx])
        order = np.argsort(j, kind="stable")
        # one slab at a time (a loop over slabs, not rays): its two boundary grids are
        # synthesised once and stay cached while its rays iterate
        for g in np.split(idx[order], np.flatnonzero(np.diff(j[order])) + 1):
            if g.size:
                hit[g], s_out[g], nrm[g] = self._solve(o[g], d[g], t[g])
        return hit, s_out, nrm

    def _solve(self, oi, di, ti):
        """Newton (then bisection where needed) for rays of one slab."""
        s = (self.level_m - oi[:, 2]) / di[:, 2]
        f, fp, gx, gy = self._f(oi, di, s, ti)
        act = np.arange(s.size)
        for _ in range(NEWTON_STEPS):  # only the rays not yet on the surface step again
            act = act[~(np.abs(f[act]) <= TOLERANCE_M)]
            if act.size == 0:
                break
            ok = np.abs(fp[act]) > 1e-12
            s[act] -= np.divide(f[act], fp[act], out=np.zeros(act.size), where=ok)
            f[act], fp[act], gx[act], gy[act] = self._f(oi[act], di[act], s[act], ti[act])
        bad = np.flatnonzero(~(np.abs(f) <= TOLERANCE_M) | (s < 0))
        if bad.size:
            s[bad], gx[bad], gy[bad], f_bad = self._bisect(oi[bad], di[bad], ti[bad])
            f[bad] = f_bad
        good = (np.abs(f) <= 10 * TOLERANCE_M) & (s >= 0)
        n_up = np.column_stack([-gx, -gy, np.ones_like(gx)])
        n_up /= np.linalg.norm(n_up, axis=1, keepdims=True)
        return good, np.where(good, s, 0.0), np.where(good[:, None], n_up, 0.0)

    def _bisect(self, o, d, t):
        """Bisection of ``f`` between the crest and trough planes (f changes sign there)."""
        dz = d[:, 2]
        s_top = np.maximum((self.zmax - o[:, 2]) / dz, 0.0)
        s_bot = np.maximum((self.zmin - o[:, 2]) / dz, 0.0)
        a, b = np.minimum(s_top, s_bot), np.maximum(s_top, s_bot)
        fa = self._f(o, d, a, t)[0]
        for _ in range(_BISECTIONS):
            m = 0.5 * (a + b)
            fm = self._f(o, d, m, t)[0]
            same = np.sign(fm) == np.sign(fa)
            a = np.where(same, m, a)
            fa = np.where(same, fm, fa)
            b = np.where(same, b, m)
        s = 0.5 * (a + b)
        f, _, gx, gy = self._f(o, d, s, t)
        return s, gx, gy, f


def _splitmix64(x: np.ndarray) -> np.ndarray:
    """Counter-based hash (SplitMix64) of uint64 counters: chunk-invariant random bits."""
    z = x + np.uint64(0x9E3779B97F4A7C15)
    z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return z ^ (z >> np.uint64(31))


def unresolved_normals(normal, pulse_id, n_sub, mss, seed):
    """Facet normals with the unresolved slopes added: what each sub-ray refracts through.

    The traced surface carries waves longer than a few footprints; the shorter ones (most of
    the Cox-Munk variance, capillary to decimetre scales, correlated over centimetres) tilt the
    facet each sub-ray enters. Their slopes add to the resolved gradient,
    ``grad = grad_resolved + g``, ``g`` Gaussian with variance ``mss / 2`` per axis (isotropic),
    drawn from a counter hash of ``(seed, pulse_id, sub-ray)`` so any chunking gives the same
    draws. Without them the in-water beam would not spread as it does under a real sea.

    Parameters
    ----------
    normal : (n_pulses * n_sub, 3) float64
        Upward unit normals of the resolved surface.
    pulse_id : (n_pulses,) int64
    n_sub : int
    mss : float
        Unresolved slope variance (total of both axes).
    seed : int

    Returns
    -------
    (n_pulses * n_sub, 3) float64
        Upward unit normals.
    """
    pid = np.repeat(np.asarray(pulse_id, dtype=np.uint64), n_sub)
    sub = np.tile(np.arange(n_sub, dtype=np.uint64), np.asarray(pulse_id).size)
    base = (pid * np.uint64(1024) + sub) * np.uint64(4) + np.uint64(seed) * np.uint64(0x10001)
    u1 = ((_splitmix64(base) >> np.uint64(11)).astype(np.float64) + 0.5) / 2.0**53
    u2 = ((_splitmix64(base + np.uint64(1)) >> np.uint64(11)).astype(np.float64) + 0.5) / 2.0**53
    r = np.sqrt(-2.0 * np.log(u1)) * np.sqrt(0.5 * mss)  # Box-Muller
    gx_u, gy_u = r * np.cos(2.0 * np.pi * u2), r * np.sin(2.0 * np.pi * u2)
    nz = np.where(normal[:, 2] > 0.0, normal[:, 2], 1.0)
    gx = -normal[:, 0] / nz + gx_u
    gy = -normal[:, 1] / nz + gy_u
    out = np.column_stack([-gx, -gy, np.ones_like(gx)])
    return out / np.linalg.norm(out, axis=1, keepdims=True)
