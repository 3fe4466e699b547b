"""Multiple small-angle forward scattering, tabulated once per phase function by photon tracing.

Why
---
:mod:`pipeline.forward_scatter` judges each scattering event alone against the field of view.
That is exact while at most one event per photon is accepted (``b L`` small) and errs as several
are: their sideways moves add as vectors (a photon two events out may be back in, or out after
two events each in), and photons that zig-zag inside a narrow field carry excess path no single
event explains. Against a brute-force Monte Carlo the single-event mean was 5-10 % high at
``R = 2 m``, ``b L`` 0.6-2.4, and 42 % low at ``R / L = 0.025``.

Method (model choice)
---------------------
The one-way statistics of the photons that reach the seabed inside the field of view depend
only on the optical scattering depth ``tau = b L``, on ``rho = R / L`` and on the phase function
(absorption multiplies every photon of a given path by the same factor and is left to the
energy budget). They are tabulated once per phase function by tracing photons in units of
``1 / b``: a vertical pencil enters at ``z = 0``, free paths are exponential (mean 1), directions
turn by angles drawn from the phase function (inverse CDF on a log grid of angles) with a uniform
azimuth, in three dimensions (no small-angle approximation). Each photon's *first* crossing of
every tabulated depth plane ``z = tau_i`` is a landing on a seabed at that depth: its radius and
excess path ``s - tau_i`` are binned by ``r / tau_i``, so one set of photons serves every depth
and every field of view. Photons that go back above the surface, or whose excess passes
:data:`MAX_EXCESS` scattering lengths, are lost (they leave any field of view of interest).
Tabulated per ``(tau, rho)``: ``h0 = -ln P(no scattering) / tau``, ``h1 = E[excess] / tau**2``,
``h2 = Var[excess] / tau**3`` (the single-event model's ``H_m(rho)``, to which they tend as
``tau -> 0``). Below :data:`TAU_BLEND` the single-event tables (exact there) are used, blended
linearly in ``ln tau`` into the traced ones over one factor of two, where the traced ones have
enough scattered photons.

The photons come from a fixed seed, so the tables, and every echo built from them, are the same
in every process and run.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numba
import numpy as np

from pipeline import water_optics as wo
from pipeline.forward_scatter import ScatterTables
from pipeline.table_cache import cached_table, code_key

__all__ = ["TracedTables", "water_tables", "MAX_EXCESS", "TAU_BLEND"]

#: Excess path (in scattering lengths) beyond which a photon is dropped.
MAX_EXCESS = 10.0
#: Optical scattering depth below which the single-event tables are used (blend to 2x this).
TAU_BLEND = 0.05
_LOG_TAU = np.linspace(math.log(TAU_BLEND), math.log(12.0), 40)
_LOG_RHO = np.linspace(math.log(1e-3), math.log(20.0), 61)
_PSI = np.concatenate([[0.0], np.geomspace(1e-7, math.pi, 4000)])
#: Absorption per scattering length, ``a / b = 1 / omega_0 - 1``: each landing is weighted by
#: ``exp(-(a / b) excess)`` (its extra absorption), tabulated on this grid.
_ALPHA = np.array([0.0, 0.05, 0.1, 0.2, 0.35, 0.6, 1.0, 1.6, 2.5, 4.0])


def _sample_angles(phase_per_sr, n: int, rng: np.random.Generator) -> np.ndarray:
    """Scattering angles (rad) drawn from ``p(psi)`` by inverse CDF on a log grid."""
    psi = _PSI[1:]
    f = 2.0 * math.pi * np.asarray(phase_per_sr(psi)) * np.sin(psi)
    cdf = np.concatenate([[0.0], np.cumsum(0.5 * (f[1:] + f[:-1]) * np.diff(psi))])
    cdf = np.concatenate([[0.0], cdf + f[0] * psi[0] / 2.0])  # the sliver below 1e-7 rad
    cdf /= cdf[-1]
    return np.interp(rng.random(n), cdf, _PSI)


def _turn(d: np.ndarray, psi: np.ndarray, phi: np.ndarray) -> np.ndarray:
    """Unit directions ``d`` (n, 3) turned by polar ``psi`` and azimuth ``phi``."""
    ref = np.where(np.abs(d[:, 2:3]) < 0.9, [[0.0, 0.0, 1.0]], [[1.0, 0.0, 0.0]])
    e1 = np.cross(d, ref)
    e1 /= np.linalg.norm(e1, axis=1)[:, None]
    e2 = np.cross(d, e1)
    c, s = np.cos(psi)[:, None], np.sin(psi)[:, None]
    out = c * d + s * (np.cos(phi)[:, None] * e1 + np.sin(phi)[:, None] * e2)
    return out / np.linalg.norm(out, axis=1)[:, None]


def _trace(phase_per_sr, n_photons: int, seed: int) -> tuple[np.ndarray, ...]:
    """Landing statistics per (a / b, depth plane, rho): weight, unscattered, sum e, sum e**2."""
    rng = np.random.default_rng(seed)
    tau = np.exp(_LOG_TAU)
    nt, nr = tau.size, _LOG_RHO.size
    shape = nt * (nr + 1)
    cnt, zero, s1, s2 = (np.zeros((_ALPHA.size, shape)) for _ in range(4))
    pos = np.zeros((n_photons, 3))
    d = np.tile([0.0, 0.0, 1.0], (n_photons, 1))
    s = np.zeros(n_photons)
    zmax = np.zeros(n_photons)
    scattered = np.zeros(n_photons, dtype=bool)
    idx = np.arange(n_photons)
    while idx.size:
        step = rng.exponential(1.0, idx.size)
        p0, di = pos[idx], d[idx]
        p1 = p0 + di * step[:, None]
        # first crossings of the depth planes in (zmax, z1]: a landing on each of those seabeds
        lo = np.searchsorted(tau, zmax[idx], side="right")
        hi = np.searchsorted(tau, p1[:, 2], side="right")
        k = np.maximum(hi - lo, 0)
        if k.sum():
            who = np.repeat(np.arange(idx.size), k)
            plane = np.repeat(lo, k) + (np.arange(k.sum()) - np.repeat(np.cumsum(k) - k, k))
            frac = (tau[plane] - p0[who, 2]) / di[who, 2]
            xy = p0[who, :2] + di[who, :2] * frac[:, None]
            excess = s[idx][who] + frac - tau[plane]
            r_rel = np.hypot(xy[:, 0], xy[:, 1]) / tau[plane]
            # rho bin: accepted by every rho >= r / tau (bin 0: r = 0, the unscattered)
            j = np.where(
                r_rel > 0.0, np.searchsorted(_LOG_RHO, np.log(np.maximum(r_rel, 1e-300))), 0
            )
            flat = plane * (nr + 1) + j
            # the unscattered landings do not depend on the absorption weight
            zero += np.bincount(flat, weights=~scattered[idx][who], minlength=shape)
            for i, alpha in enumerate(_ALPHA):
                w = np.exp(-alpha * excess)
                cnt[i] += np.bincount(flat, weights=w, minlength=shape)
                we = w * excess
                s1[i] += np.bincount(flat, weights=we, minlength=shape)
                s2[i] += np.bincount(flat, weights=we * excess, minlength=shape)
        pos[idx] = p1
        s[idx] += step
        zmax[idx] = np.maximum(zmax[idx], p1[:, 2])
        keep = (p1[:, 2] > 0.0) & (p1[:, 2] < tau[-1]) & (s[idx] - zmax[idx] < MAX_EXCESS)
        idx = idx[keep]
        psi = _sample_angles(phase_per_sr, idx.size, rng)
        d[idx] = _turn(d[idx], psi, 2.0 * math.pi * rng.random(idx.size))
        scattered[idx] = True
    return tuple(
        np.cumsum(a.reshape(_ALPHA.size, nt, nr + 1), axis=2)[:, :, :nr]
        for a in (cnt, zero, s1, s2)
    )


@dataclass(frozen=True)
class TracedTables:
    """``h0, h1, h2`` of one phase function on ``(a / b, ln tau, ln rho)`` grids.

    The single-event tables are used below :data:`TAU_BLEND` (module doc).
    """

    alpha: np.ndarray
    log_tau: np.ndarray
    log_rho: np.ndarray
    h: np.ndarray  # (3, n_alpha, n_tau, n_rho)
    single: ScatterTables

    @classmethod
    def from_phase(cls, phase_per_sr, n_photons: int = 200_000, seed: int = 2012) -> TracedTables:
        """Trace ``n_photons`` photons (fixed ``seed``) and tabulate (module doc)."""
        cnt, zero, s1, s2 = _trace(phase_per_sr, n_photons, seed)
        tau = np.exp(_LOG_TAU)[None, :, None]
        n = np.maximum(cnt, 1.0)
        p0 = np.clip(zero / n, 1e-300, 1.0)
        mean = s1 / n
        var = np.maximum(s2 / n - mean * mean, 0.0)
        h = np.stack([-np.log(p0) / tau, mean / tau**2, var / tau**3])
        single = ScatterTables.from_phase(phase_per_sr)
        return cls(_ALPHA.copy(), _LOG_TAU.copy(), _LOG_RHO.copy(), h, single)

    def at(self, tau, rho, alpha=0.0) -> np.ndarray:
        """``(3, ...)`` ``h0, h1, h2`` at optical depths ``tau``, ``rho = R / L``, ``a / b``."""
        lt = np.log(np.clip(np.asarray(tau, dtype=np.float64), 1e-300, None))
        lr = np.log(np.clip(np.asarray(rho, dtype=np.float64), 1e-300, None))
        al = np.clip(np.asarray(alpha, dtype=np.float64), self.alpha[0], self.alpha[-1])
        lt, lr, al = np.broadcast_arrays(lt, lr, al)
        ia = np.clip(np.searchsorted(self.alpha, al, side="right") - 1, 0, self.alpha.size - 2)
        wa = (al - self.alpha[ia]) / (self.alpha[ia + 1] - self.alpha[ia])
        ft = np.clip((lt - self.log_tau[0]) / (self.log_tau[1] - self.log_tau[0]), 0.0, None)
        fr = (np.clip(lr, self.log_rho[0], self.log_rho[-1]) - self.log_rho[0]) / (
            self.log_rho[1] - self.log_rho[0]
        )
        shape = ft.shape
        if not (np.all(np.isfinite(ft)) and np.all(np.isfinite(fr))):
            # (the compiled lookup reads the table unchecked: a NaN or infinite optical
            # depth or radius would index past it)
            raise ValueError("forward-scattering tables: optical depth and radius must be finite")
        traced = _trilinear(
            self.h,
            np.ascontiguousarray(ia, dtype=np.int64).ravel(),
            np.ascontiguousarray(wa, dtype=np.float64).ravel(),
            np.ascontiguousarray(ft).ravel(),
            np.ascontiguousarray(fr).ravel(),
        ).reshape((3, *shape))
        # the single-event tables below TAU_BLEND, blended over [TAU_BLEND, 2 TAU_BLEND]
        blend = np.clip((lt - math.log(TAU_BLEND)) / math.log(2.0), 0.0, 1.0)
        return blend * traced + (1.0 - blend) * self.single(rho)


@numba.njit(cache=True, nogil=True)
def _trilinear(h, ia, wa, ft, fr):
    """``TracedTables.at``'s interpolation of ``h`` (3, n_alpha, n_tau, n_rho), ``(3, n)``.

    Cell indices and weights from the fractional grid positions ``ft``, ``fr`` and the alpha
    cell ``ia`` (weight ``wa``); every product and sum in the order the whole-array numpy
    expression made them, so the same figures to the bit, without its ~30 gathered
    temporaries per call (the TPU calls it in each of its ~25 refraction passes).
    """
    n = ft.size
    n_tau, n_rho = h.shape[2], h.shape[3]
    out = np.empty((3, n))
    for p in range(n):
        it = min(int(ft[p]), n_tau - 2)
        ir = min(int(fr[p]), n_rho - 2)
        wt = min(max(ft[p] - it, 0.0), 1.0)
        wr = fr[p] - ir
        for q in range(3):
            traced = 0.0
            for a, wh in ((ia[p], 1.0 - wa[p]), (ia[p] + 1, wa[p])):
                traced = traced + wh * (
                    (1 - wt) * (1 - wr) * h[q, a, it, ir]
                    + wt * (1 - wr) * h[q, a, it + 1, ir]
                    + (1 - wt) * wr * h[q, a, it, ir + 1]
                    + wt * wr * h[q, a, it + 1, ir + 1]
                )
            out[q, p] = traced
    return out


@lru_cache(maxsize=1)
def water_tables() -> tuple[TracedTables, ScatterTables]:
    """Tables of the particles' (traced) and sea water's (single events) phase functions.

    Particles: Fournier-Forand, Petzold fit. Sea water: ``b_w L`` stays below ~0.1 at any depth
    a bottom is seen, and its wide phase function makes an accepted event rarer still.

    The traced tables are a constant of the code (fixed photons, fixed seed) that costs ~3 s of
    CPU to trace, in every process of every run: they are kept on disk once traced
    (:mod:`pipeline.table_cache`), under a name that changes with the code that makes them.
    """
    h = _cached_h(lambda: TracedTables.from_phase(wo.ff_phase_per_sr).h)
    single = ScatterTables.from_phase(wo.ff_phase_per_sr)
    traced = TracedTables(_ALPHA.copy(), _LOG_TAU.copy(), _LOG_RHO.copy(), h, single)
    return traced, ScatterTables.from_phase(wo.seawater_phase_per_sr)


#: What makes the traced tables: this module and the phase functions' (hashed at import).
_SOURCE_KEY = code_key([__file__, wo.__file__])


def _cached_h(trace) -> np.ndarray:
    """``trace()``'s array, kept on disk once traced (:func:`pipeline.table_cache.cached_table`)."""
    shape = (3, _ALPHA.size, _LOG_TAU.size, _LOG_RHO.size)
    return cached_table("forward_scatter", "traced Fournier-Forand", _SOURCE_KEY, trace, shape)
