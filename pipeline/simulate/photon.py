"""The photon domain: chunk-invariant random numbers and photoelectron events per pulse.

Randomness is a pure function of ``(seed, stream, pulse_id, counter)``, so a pulse gets the same
photons whichever chunk it is simulated in:

* **Variable-length draws** (photoelectron events) use a counter-based generator: the
  SplitMix64 output function (Steele, Lea & Flood 2014, "Fast splittable pseudorandom number
  generators", OOPSLA) applied to a Weyl sequence, ``word = mix64(key_pulse + counter * golden)``
  with ``key_pulse = mix64(key_stream + pulse_id * golden)``. This is exactly the SplitMix64
  stream seeded with ``key_pulse``, evaluated at any position without state, vectorised in
  numpy's wrapping uint64 arithmetic. Each 64-bit word gives two 32-bit uniforms in (0, 1).
* **Fixed-length draws** (one normal per digitiser sample) use a numpy ``Generator`` on fixed
  blocks of :data:`PULSE_BLOCK` pulse ids, seeded ``SeedSequence([seed, stream, block + 2**40])``
  as in :mod:`pipeline.simulate.noise` (with the SFC64 bit generator, 20 % faster here than
  PCG64); a chunk slices the rows it needs (at most two partial blocks are drawn in excess).

Events of one pulse: the number of photoelectrons is ``Poisson(sum of the expected counts of
the components)``, drawn by inversion of one uniform (:func:`poisson_quantile`); each event then
picks its component with probability proportional to the component's expected count (a Poisson
total split multinomially is the same as independent Poisson counts per component) and its time
from the component's shape. The cost grows with photons, not samples.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.special import ndtri, pdtr

from pipeline.simulate.shapes import column_depth_time

__all__ = [
    "PULSE_BLOCK",
    "KIND_GAUSS",
    "KIND_COLUMN",
    "KIND_UNIFORM",
    "mix64",
    "pulse_keys",
    "uniform_pair",
    "poisson_quantile",
    "block_normals",
    "Components",
    "draw_events",
]

PULSE_BLOCK = 256
"""Pulses per block of fixed-length normal draws."""
KIND_GAUSS = 0
KIND_COLUMN = 1
KIND_UNIFORM = 2

_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)
_BLOCK_OFFSET = 1 << 40
_TWO_M32 = 2.0**-32


def mix64(z: np.ndarray) -> np.ndarray:
    """SplitMix64 output function of a uint64 array (returns a new array)."""
    z = z ^ (z >> np.uint64(30))
    z *= _M1
    z ^= z >> np.uint64(27)
    z *= _M2
    z ^= z >> np.uint64(31)
    return z


def pulse_keys(seed: int, stream: int, pulse_id: np.ndarray) -> np.ndarray:
    """(n,) uint64 key of each pulse's counter-based stream."""
    base = mix64(np.array([seed], dtype=np.uint64) * _GOLDEN + np.uint64(stream))
    base = mix64(base + np.uint64(0x632BE59BD9B4E019))
    return mix64(base + np.asarray(pulse_id).astype(np.uint64) * _GOLDEN)


def uniform_pair(keys: np.ndarray, counter: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two independent uniforms in (0, 1) (32-bit resolution) per ``(key, counter)`` pair."""
    w = mix64(keys + np.asarray(counter).astype(np.uint64) * _GOLDEN)
    hi = ((w >> np.uint64(32)).astype(np.float64) + 0.5) * _TWO_M32
    lo = ((w & np.uint64(0xFFFFFFFF)).astype(np.float64) + 0.5) * _TWO_M32
    return hi, lo


def poisson_quantile(u: np.ndarray, lam: np.ndarray) -> np.ndarray:
    """Smallest ``k`` with ``P(X <= k) >= u`` for ``X ~ Poisson(lam)``: inversion, vectorised.

    Parameters
    ----------
    u : (n,) float64
        Uniforms in (0, 1).
    lam : (n,) float64
        Means, >= 0 and finite.

    Returns
    -------
    (n,) int64

    Notes
    -----
    Means below 30: sequential summation of the pmf from 0 (at most ~80 steps, over the
    entries still searching). Larger means: a Cornish-Fisher start
    ``lam + sqrt(lam) (z + (z^2 - 1) / (6 sqrt(lam)))``, then corrected with the exact CDF
    (``scipy.special.pdtr``) until ``F(k - 1) < u <= F(k)``; typically two CDF evaluations.
    """
    u = np.asarray(u, dtype=np.float64)
    lam = np.asarray(lam, dtype=np.float64)
    k = np.zeros(u.shape, dtype=np.int64)
    small = np.flatnonzero((lam > 0.0) & (lam < 30.0))
    if small.size:
        ls, us = lam[small], u[small]
        p = np.exp(-ls)
        cdf = p.copy()
        ks = np.zeros(small.size, dtype=np.int64)
        act = np.flatnonzero(us > cdf)
        step = 0
        while act.size and step < 200:  # 200 steps cover lam < 30 to 1 - 1e-40
            step += 1
            ks[act] += 1
            p[act] *= ls[act] / ks[act]
            cdf[act] += p[act]
            act = act[us[act] > cdf[act]]
        k[small] = ks
    big = np.flatnonzero(lam >= 30.0)
    if big.size:
        lb, ub = lam[big], u[big]
        z = ndtri(ub)
        sq = np.sqrt(lb)
        kb = np.maximum(np.floor(lb + sq * z + (z * z - 1.0) / 6.0 + 0.5), 0.0)
        for _ in range(64):  # each pass moves every unfinished entry by one
            up = pdtr(kb, lb) < ub
            down = (kb > 0) & (pdtr(kb - 1.0, lb) >= ub)
            if not (up.any() or down.any()):
                break
            kb = kb + up - down
        k[big] = kb.astype(np.int64)
    return k


def block_normals(
    seed: int, stream: int, pulse_id: np.ndarray, n_cols: int, dtype=np.float32
) -> np.ndarray:
    """(n, n_cols) standard normals, row ``i`` a pure function of ``(seed, stream, pulse_id[i])``.

    Block ``b`` of :data:`PULSE_BLOCK` pulse ids is drawn whole from
    ``Generator(SFC64(SeedSequence([seed, stream, b + 2**40])))``; the loop is over blocks,
    not pulses.
    """
    pid = np.asarray(pulse_id, dtype=np.int64)
    out = np.empty((pid.size, n_cols), dtype=dtype)
    blocks = pid // PULSE_BLOCK
    order = np.argsort(blocks, kind="stable")
    sb = blocks[order]
    cuts = np.flatnonzero(np.diff(sb)) + 1
    for lo, hi in zip(np.r_[0, cuts], np.r_[cuts, sb.size], strict=True):
        b = int(sb[lo])
        seq = np.random.SeedSequence([seed, stream, b + _BLOCK_OFFSET])
        rng = np.random.Generator(np.random.SFC64(seq))
        rows = rng.standard_normal((PULSE_BLOCK, n_cols), dtype=dtype)
        idx = order[lo:hi]
        out[idx] = rows[pid[idx] - b * PULSE_BLOCK]
    return out


@dataclass(frozen=True)
class Components:
    """Expected photoelectrons and time shapes of a pulse's components, ``(n_pulses, n_comp)``.

    Attributes
    ----------
    expected : float64
        Expected photoelectrons of each component (0 for none).
    kind : int8
        :data:`KIND_GAUSS` (centre ``centre_s``, sigma ``sigma_s``), :data:`KIND_COLUMN`
        (start ``centre_s``, blur ``sigma_s``, ``rate_per_s``, ``width_s``) or
        :data:`KIND_UNIFORM` (from ``centre_s`` over ``width_s``).
    centre_s, sigma_s, rate_per_s, width_s : float64
    """

    expected: np.ndarray
    kind: np.ndarray
    centre_s: np.ndarray
    sigma_s: np.ndarray
    rate_per_s: np.ndarray
    width_s: np.ndarray

    def with_expected(self, expected: np.ndarray) -> Components:
        """The same shapes with other expected counts (e.g. the weak or strong part)."""
        return Components(
            expected, self.kind, self.centre_s, self.sigma_s, self.rate_per_s, self.width_s
        )


def draw_events(keys: np.ndarray, comps: Components, cap: float = np.inf):
    """Draw photoelectron events of every pulse from its components.

    Parameters
    ----------
    keys : (n,) uint64
        Per-pulse keys (:func:`pulse_keys`).
    comps : Components
        ``(n, n_comp)`` arrays.
    cap : float
        Largest number of events drawn per pulse (a saturated photon counter never records
        more); pulses reaching it are reported in ``capped``.

    Returns
    -------
    counts : (n,) int64
        Events per pulse.
    pulse : (n_events,) int64
        Row of each event's pulse, in pulse order.
    times_s : (n_events,) float64
        Arrival time after emission.
    component : (n_events,) int64
        Component index of each event.
    counter : (n_events,) int64
        Index of each event within its pulse (its position in the pulse's random stream).
    capped : (n,) bool
    """
    lam = comps.expected
    n, c = lam.shape
    total = lam.sum(axis=1)
    u0, _ = uniform_pair(keys, np.zeros(n, dtype=np.uint64))
    counts = poisson_quantile(u0, total)
    capped = counts > cap
    counts = np.where(capped, int(min(cap, 2**62)), counts)
    n_ev = int(counts.sum())
    pulse = np.repeat(np.arange(n), counts)
    start = np.cumsum(counts) - counts
    k = np.arange(n_ev, dtype=np.int64) - start[pulse]
    ev_keys = keys[pulse]
    u_comp, u_time = uniform_pair(ev_keys, 2 * k + 1)
    # component: inverse of each pulse's cumulative distribution over components
    cum = np.cumsum(lam, axis=1) / np.where(total > 0, total, 1.0)[:, None]
    cum[:, -1] = 1.0
    flat = (np.arange(n)[:, None] + cum).ravel()
    j = np.searchsorted(flat, pulse + u_comp, side="right")
    comp = np.minimum(j - pulse * c, c - 1)
    idx = pulse * c + comp
    kind = comps.kind.ravel()[idx]
    centre = comps.centre_s.ravel()[idx]
    times = np.empty(n_ev)
    gauss = kind != KIND_UNIFORM
    z = ndtri(u_time[gauss])
    times[gauss] = centre[gauss] + comps.sigma_s.ravel()[idx[gauss]] * z
    uni = ~gauss
    times[uni] = centre[uni] + u_time[uni] * comps.width_s.ravel()[idx[uni]]
    col = np.flatnonzero(kind == KIND_COLUMN)
    if col.size:
        u_depth, _ = uniform_pair(ev_keys[col], 2 * k[col] + 2)
        ci = idx[col]
        times[col] += column_depth_time(
            u_depth, comps.rate_per_s.ravel()[ci], comps.width_s.ravel()[ci]
        )
    return counts, pulse, times, comp, k, capped
