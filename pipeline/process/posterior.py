"""Posterior of the bottom depth of pulses by MCMC (emcee) on the process-side waveform model.

Parameters and priors
---------------------
``theta`` follows :data:`pipeline.process.waveform_model.PARAM_NAMES`: depth (m), surface time
(ns), log surface / column / bottom areas (counts), log attenuation ``ln k`` (``k`` in 1/m),
background (counts per sample). Independent bounded priors (:class:`PosteriorSettings`), so
the log prior is a constant inside the box and ``-inf`` outside:

* depth: flat on ``depth_bounds_m``;
* surface time: flat over the window, and the bottom (``t_s + tau(depth)``) inside it;
* areas: **log-uniform** on ``area_bounds`` (1 count to 1e9: a return of less than a count is
  not in the data);
* attenuation: log-uniform on ``attenuation_bounds_per_m`` (0.01-2 1/m, clear ocean to turbid
  coast; a pulse alone barely constrains ``k``), or with ``attenuation_prior`` a log-normal
  prior (a survey's known water);
* background: flat on ``[0, background_max]`` (photon counting from ``1e-9``: a Poisson mean
  must be > 0);
* bottom width: log-uniform on ``bottom_width_ratio_bounds`` times the system response's
  (forward scattering stretches a 20 m bottom echo by a few ns in coastal water).

Sampling
--------
1. Start: the detector's estimate (:func:`pipeline.process.detect.detect_full_waveform`):
   surface and bottom times and amplitudes, the background from the leading samples (a depth
   scan where the detector found the surface but no bottom, flagged START_SCANNED); batched
   damped Fisher scoring then moves every pulse to its posterior mode.
2. Walkers: the mode plus a small ball of the Laplace covariance (inverse Fisher information
   with the prior widths) times ``init_scale``, redrawn where outside the prior.
3. :class:`emcee.EnsembleSampler` (``vectorize=True``) with the pulses of a batch side by side
   in one walker vector: two emcee moves act on each pulse's block independently
   (:class:`BlockDEMove`, differential evolution, and :class:`BlockIndependenceMove`, an
   independence Metropolis–Hastings move from a Student-t fitted to the burn-in), each with
   its own accept/reject from the pulse's own log posterior (the ``blobs`` of
   :func:`log_prob_blocks`): every pulse is an exact MCMC of its own posterior, and the model
   is evaluated once for all pulses and walkers. ``burn_steps`` are discarded (the
   independence proposal is adapted once, at their end, then fixed).
4. Convergence, per pulse: production in chunks of ``chunk_steps`` until the chain is at
   least ``tau_factor`` (50) integrated autocorrelation times long (emcee's
   ``integrated_time``, the largest over the parameters) or ``max_steps``; the mean
   acceptance fraction must lie in ``acceptance_range`` (0.15, 0.8). Otherwise the pulse is
   flagged :attr:`PosteriorFlag.NOT_CONVERGED` / :attr:`PosteriorFlag.ACCEPTANCE` (its
   summaries are still given). Converged pulses leave the batch; the rest continue.

Seabed point
------------
The posterior draws of ``(depth, t_s)`` become round-trip times ``t0 + t_s`` and
``t0 + t_s + tau(depth)`` and go through :func:`pipeline.process.refraction.seabed_points`
(all draws of a pulse in one call), so the reported posterior is on the 3-D seabed point (and
its depth below the fitted surface), with the processing's own refraction.

Cost: see ``benchmarks/RESULTS_posterior.md`` (a few tenths of a second per pulse).
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass
from typing import Any

import emcee
import numpy as np

from pipeline.config import setting
from pipeline.errors import NumericalError
from pipeline.optics import SPEED_OF_LIGHT_M_S
from pipeline.process.detect import DetectSettings, detect_full_waveform
from pipeline.process.refraction import RefractionSettings, seabed_points
from pipeline.process.returns import DetectedReturns
from pipeline.process.surface_fit import WaterSurface
from pipeline.process.waveform_model import (
    N_PARAMS,
    WaveformSystem,
    covariance,
    expected_waveform,
    in_water_delay_s,
    log_likelihood,
    score,
    th_str,
)

__all__ = [
    "PosteriorFlag",
    "PosteriorSettings",
    "PulseBatch",
    "PulseChains",
    "BlockDEMove",
    "SeabedPosteriors",
    "make_pulse_batch",
    "log_prob",
    "log_prob_blocks",
    "start_theta",
    "posterior_modes",
    "sample_batch",
    "sample_pulse",
    "interval_summary",
    "water_cosine",
    "take_surface",
    "draws_to_seabed",
    "seabed_posteriors",
]

_C = SPEED_OF_LIGHT_M_S


class PosteriorFlag(enum.IntFlag):
    """Per-pulse bits of the posterior sampling."""

    #: The chain is shorter than ``tau_factor`` autocorrelation times after ``max_steps``.
    NOT_CONVERGED = 1 << 0
    #: Mean acceptance fraction outside ``acceptance_range``.
    ACCEPTANCE = 1 << 1
    #: No surface detected to start from: not sampled.
    NO_START = 1 << 2
    #: The 95 % depth interval reaches a prior bound (prior-dominated).
    AT_PRIOR_BOUND = 1 << 3
    #: The detector found no bottom: the start came from a depth scan (a weak bottom).
    START_SCANNED = 1 << 4


@dataclass(frozen=True, kw_only=True)
class PosteriorSettings:
    """Sampler settings and prior bounds."""

    n_walkers: int = setting(16, ge=16, le=1024, doc="emcee walkers (>= 2 x 8 parameters)")
    burn_steps: int = setting(150, ge=0, doc="steps discarded after the start")
    chunk_steps: int = setting(100, ge=10, doc="production steps between convergence checks")
    max_steps: int = setting(4000, ge=10, doc="production steps at most")
    tau_factor: float = setting(50.0, gt=0.0, doc="converged: chain >= this x autocorr. time")
    acceptance_range: tuple[float, float] = setting(
        (0.15, 0.8), ge=0.0, le=1.0, length=2, doc="converged: mean acceptance inside"
    )
    thin: int = setting(5, ge=1, le=100, doc="steps between stored chain samples")
    min_steps: int = setting(300, ge=0, doc="no convergence check before this many steps")
    independence_weight: float = setting(
        0.8, ge=0.0, le=1.0, doc="share of independence (Student-t) moves; the rest DE"
    )
    proposal_dof: float = setting(5.0, gt=2.0, doc="Student-t degrees of freedom")
    proposal_scale: float = setting(1.2, gt=0.0, doc="proposal scale / posterior sigma")
    batch_size: int = setting(32, ge=1, le=4096, doc="pulses sampled side by side")
    init_scale: float = setting(0.5, gt=0.0, le=10.0, doc="start ball / Laplace sigma")
    max_draws: int = setting(2000, ge=50, doc="thinned draws kept per pulse")
    depth_bounds_m: tuple[float, float] = setting(
        (0.01, 100.0), gt=0.0, length=2, doc="flat prior on the depth"
    )
    area_bounds: tuple[float, float] = setting(
        (1.0, 1e9), gt=0.0, length=2, doc="log-uniform prior on the return areas, counts"
    )
    attenuation_bounds_per_m: tuple[float, float] = setting(
        (0.01, 2.0), gt=0.0, length=2, doc="log-uniform prior on the attenuation"
    )
    background_max: float = setting(1e7, gt=0.0, doc="flat prior on the background up to this")
    bottom_width_ratio_bounds: tuple[float, float] = setting(
        (0.7, 20.0), gt=0.0, length=2, doc="log-uniform prior on bottom echo / response width"
    )
    attenuation_prior: tuple[float, float] | None = setting(
        None,
        gt=0.0,
        length=2,
        doc="(median k 1/m, sigma of ln k): log-normal prior on k; None: log-uniform",
    )

    def __post_init__(self) -> None:
        for name in (
            "depth_bounds_m",
            "area_bounds",
            "attenuation_bounds_per_m",
            "bottom_width_ratio_bounds",
        ):
            lo, hi = getattr(self, name)
            if not lo < hi:
                raise ValueError(f"`{name}` must be increasing; got {getattr(self, name)}")
        lo, hi = self.acceptance_range
        if not lo < hi:
            raise ValueError(f"`acceptance_range` must be increasing; got {(lo, hi)}")


@dataclass(frozen=True)
class PulseBatch:
    """Waveforms of ``P`` pulses and their prior boxes: the ``data`` of :func:`log_prob`.

    Attributes
    ----------
    samples : (P, m) float64
        Waveforms, zero-padded to the longest (``valid`` marks the real samples).
    valid : (P, m) bool
    cos_water : (P,) float64
        Cosine of each pulse's in-water angle from the vertical.
    lower, upper : (P, 8) float64
        Prior box per pulse and parameter.
    t_last_s : (P,) float64
        Centre of each waveform's last sample: surface and bottom must lie in
        ``[0, t_last_s]``.
    ln_k_prior : (P, 2) float64
        Mean and sigma of a normal prior on ``ln k`` (sigma ``inf``: flat, log-uniform ``k``).
    """

    samples: np.ndarray
    valid: np.ndarray
    cos_water: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    t_last_s: np.ndarray
    ln_k_prior: np.ndarray

    def __len__(self) -> int:
        return int(self.samples.shape[0])

    @property
    def n_samples(self) -> int:
        """Samples per (padded) waveform."""
        return int(self.samples.shape[1])

    def pulse(self, i: int) -> PulseBatch:
        """Pulse ``i`` alone, as a batch of one (padding removed)."""
        m = int(self.valid[i].sum())
        return PulseBatch(
            self.samples[i : i + 1, :m],
            self.valid[i : i + 1, :m],
            self.cos_water[i : i + 1],
            self.lower[i : i + 1],
            self.upper[i : i + 1],
            self.t_last_s[i : i + 1],
            self.ln_k_prior[i : i + 1],
        )


def make_pulse_batch(
    waveforms: Any,
    system: WaveformSystem,
    settings: PosteriorSettings | None = None,
    cos_water: Any = 1.0,
) -> PulseBatch:
    """Validate waveforms and build their :class:`PulseBatch` with the prior of ``settings``.

    Parameters
    ----------
    waveforms : (m,) or (P, m) array_like, or sequence of 1-D arrays of different lengths
    system : WaveformSystem
    settings : PosteriorSettings, optional
    cos_water : float or (P,) array_like
        In (0, 1].
    """
    st = settings or PosteriorSettings()
    if isinstance(waveforms, np.ndarray) and waveforms.ndim <= 2:
        rows = list(np.atleast_2d(np.asarray(waveforms, dtype=np.float64)))
    else:
        rows = [np.asarray(w, dtype=np.float64) for w in waveforms]
    if not rows:
        raise ValueError("`waveforms` must hold at least one waveform")
    for i, w in enumerate(rows):
        if w.ndim != 1 or w.size < 8:
            raise ValueError(f"`waveforms[{i}]` must be 1-D with >= 8 samples; got {w.shape}")
        if not np.all(np.isfinite(w)):
            raise NumericalError(f"`waveforms[{i}]` must be finite")
    n, m = len(rows), max(w.size for w in rows)
    cw = np.broadcast_to(np.asarray(cos_water, dtype=np.float64), (n,)).copy()
    if np.any(~(cw > 0.0) | (cw > 1.0)):
        raise ValueError(f"`cos_water` must be in (0, 1]; got {cw[~(cw > 0) | (cw > 1)][0]!r}")
    samples = np.zeros((n, m))
    valid = np.zeros((n, m), dtype=bool)
    for i, w in enumerate(rows):
        samples[i, : w.size] = w
        valid[i, : w.size] = True
    t_last = (valid.sum(axis=1) - 1) * system.sample_interval_s
    bg_min = 1e-9 if system.poisson else 0.0
    lower = np.array(
        [
            st.depth_bounds_m[0],
            0.0,
            math.log(st.area_bounds[0]),
            math.log(st.area_bounds[0]),
            math.log(st.area_bounds[0]),
            math.log(st.attenuation_bounds_per_m[0]),
            bg_min,
            math.log(st.bottom_width_ratio_bounds[0]),
        ]
    )
    upper = np.array(
        [
            st.depth_bounds_m[1],
            0.0,  # set per pulse below
            math.log(st.area_bounds[1]),
            math.log(st.area_bounds[1]),
            math.log(st.area_bounds[1]),
            math.log(st.attenuation_bounds_per_m[1]),
            st.background_max,
            math.log(st.bottom_width_ratio_bounds[1]),
        ]
    )
    upper = np.tile(upper, (n, 1))
    upper[:, 1] = t_last * 1e9
    if st.attenuation_prior is None:
        kp = (0.0, math.inf)
    else:
        kp = (math.log(st.attenuation_prior[0]), st.attenuation_prior[1])
    return PulseBatch(
        samples, valid, cw, np.tile(lower, (n, 1)), upper, t_last, np.tile(kp, (n, 1))
    )


def _rows_log_lik(th: np.ndarray, data: PulseBatch, pulse: np.ndarray, system) -> np.ndarray:
    """Log posterior of parameter rows ``th`` (N, 8), row ``j`` for pulse ``pulse[j]``.

    ``-inf`` outside the prior box (flat inside, plus the optional normal prior on ``ln k``);
    NaN raised as :class:`NumericalError`.
    """
    if np.isnan(th).any():
        raise NumericalError(f"`theta` holds NaN: {th_str(th[np.isnan(th).any(axis=1)][0])}")
    lo, hi = data.lower[pulse], data.upper[pulse]
    cw = data.cos_water[pulse]
    t_b = th[:, 1] * 1e-9 + in_water_delay_s(th[:, 0], cw, system.group_index)
    ok = np.all((th >= lo) & (th <= hi), axis=1) & (t_b <= data.t_last_s[pulse])
    out = np.full(th.shape[0], -np.inf)
    if ok.any():
        p = pulse[ok]
        mu = expected_waveform(th[ok], data.n_samples, system, cw[ok])
        ll = log_likelihood(data.samples[p], mu, system, data.valid[p])
        if np.isnan(ll).any() or np.isposinf(ll).any():
            raise NumericalError(
                f"log-likelihood is not finite at {th_str(th[ok][~np.isfinite(ll)][0])}"
            )
        mean, sig = data.ln_k_prior[p, 0], data.ln_k_prior[p, 1]
        z = np.where(np.isfinite(sig), (th[ok, 5] - mean) / np.where(np.isfinite(sig), sig, 1.0), 0)
        out[ok] = ll - 0.5 * z * z
    return out


def log_prob_blocks(theta: Any, data: PulseBatch, system: WaveformSystem) -> np.ndarray:
    """Per-pulse log posteriors of a batch, for the sampler (emcee ``blobs``).

    Parameters
    ----------
    theta : (n_walkers, 8 P) array_like
        Walker positions, pulse ``p`` in columns ``8p .. 8p + 7``.
    data : PulseBatch
    system : WaveformSystem

    Returns
    -------
    (n_walkers, 1 + P) ndarray
        Column 0 the total (the joint log posterior of independent pulses), columns ``1 + p``
        each pulse's own.
    """
    th = np.atleast_2d(np.asarray(theta, dtype=np.float64))
    n, p = th.shape[0], len(data)
    if th.shape[1] != N_PARAMS * p:
        raise ValueError(f"`theta` must have {N_PARAMS * p} columns; got {th.shape[1]}")
    rows = th.reshape(n * p, N_PARAMS)
    blocks = _rows_log_lik(rows, data, np.tile(np.arange(p), n), system).reshape(n, p)
    return np.column_stack([np.sum(blocks, axis=1), blocks])


def log_prob(theta: Any, data: PulseBatch, system: WaveformSystem) -> Any:
    """Log posterior (up to a constant) of ``theta`` given the pulses of ``data``.

    Parameters
    ----------
    theta : (8 P,) or (n_walkers, 8 P) array_like
        Parameters in :data:`~pipeline.process.waveform_model.PARAM_NAMES` order, pulse by
        pulse (``P = len(data)``; one pulse: an 8-vector).
    data : PulseBatch
    system : WaveformSystem

    Returns
    -------
    float or (n_walkers,) ndarray
        Sum over the pulses of the log-likelihood inside the prior box (the prior is flat
        there), ``-inf`` outside.

    Raises
    ------
    NumericalError
        If ``theta`` or the log-likelihood holds NaN.
    """
    th = np.asarray(theta, dtype=np.float64)
    total = log_prob_blocks(th, data, system)[:, 0]
    return float(total[0]) if th.ndim == 1 else total


def start_theta(
    samples: Any,
    system: WaveformSystem,
    cos_water: float = 1.0,
    detect_settings: DetectSettings | None = None,
) -> np.ndarray | None:
    """The detector's estimate as a parameter vector; None without a surface detection.

    Surface and bottom times from :func:`~pipeline.process.detect.detect_full_waveform`,
    areas from its matched-filter peaks (a Gaussian of area ``A`` and ``s`` samples filtered by
    the unit-sum Gaussian of the same width peaks at ``A / (2 sqrt(pi) s)``), background from
    the leading samples, column area from the samples between the returns, ``k = 0.1``.
    Where the detector found the surface but no bottom, the depth comes from a scan
    (:func:`_scan_start`).
    """
    return _start(samples, system, cos_water, detect_settings)[0]


def _start(samples, system, cos_water, detect_settings=None, detect_noise=None):
    """``(theta or None, scanned)``: see :func:`start_theta`.

    ``detect_noise``: ``(noise_samples, shot_noise_counts)`` of the survey's own detector run
    (leading samples that are noise only, and the shot-noise counts per photoelectron).
    """
    y = np.asarray(samples, dtype=np.float64)
    n_noise, shot = detect_noise if detect_noise is not None else (None, 0.0)
    det = detect_full_waveform(
        y[None, :],
        system.sample_interval_s,
        system.pulse_fwhm_s,
        detect_settings,
        noise_samples=n_noise,
        shot_noise_counts=shot,
    )
    if not det.has_surface[0]:
        return None, False
    dt = system.sample_interval_s
    k_lead = max(4, int((detect_settings or DetectSettings()).noise_fraction * y.size))
    base = float(np.median(y[:k_lead]))
    bg = max(base - (0.0 if system.poisson else system.offset_counts), 1e-3)
    ts = float(det.t_surface_s[0])
    if not det.has_bottom[0]:
        th = _scan_start(y, system, cos_water, ts, bg)
        return th, th is not None
    tb = float(det.t_bottom_s[0])
    to_area = 2.0 * math.sqrt(math.pi) * system.pulse_sigma_s / dt
    a_s = max(float(det.surface_amplitude[0]) * to_area, 1e-2)
    a_b = max(float(det.bottom_amplitude[0]) * to_area, 1e-2)
    i0 = int(math.ceil((ts + 3 * system.pulse_sigma_s) / dt))
    i1 = int(math.floor((tb - 3 * system.pulse_sigma_s) / dt))
    col = float(np.median(y[i0:i1]) - base) * (tb - ts) / dt if i1 > i0 else 0.0
    depth = (tb - ts) * cos_water * _C / (2.0 * system.group_index)
    th = [
        depth,
        ts * 1e9,
        math.log(a_s),
        math.log(max(col, 1e-2)),
        math.log(a_b),
        math.log(0.1),
        bg,
        0.0,
    ]
    return np.array(th), False


def _scan_start(y, system, cos_water, ts, bg):
    """Depth by a scan when the detector missed the bottom (None if nothing fits).

    For every candidate in-water delay on a half-sample grid, the four amplitudes (background,
    surface, column with ``k = 0.1``, bottom) are the linear least-squares fit of the waveform;
    the candidate with the smallest residual and a positive bottom area wins.
    """
    dt, s = system.sample_interval_s, system.pulse_sigma_s
    m = y.size
    taus = np.arange(3.0 * s, (m - 1) * dt - ts, 0.5 * dt)
    if taus.size == 0:
        return None
    depths = taus * cos_water * _C / (2.0 * system.group_index)
    off = -700.0  # log area of an absent return
    basis = []
    for j in (2, 3, 4):
        th = np.tile([0.0, ts * 1e9, off, off, off, math.log(0.1), 0.0, 0.0], (taus.size, 1))
        th[:, 0], th[:, j] = depths, 0.0
        basis.append(expected_waveform(th, m, system, cos_water) - system.offset_counts)
    a = np.stack([np.ones((taus.size, m)), *basis], axis=2)  # (K, m, 4)
    rhs = y - system.offset_counts
    ata = np.einsum("kmi,kmj->kij", a, a) + 1e-9 * np.eye(4)
    coef = np.linalg.solve(ata, np.einsum("kmi,m->ki", a, rhs)[:, :, None])[:, :, 0]
    resid = np.sum((np.einsum("kmi,ki->km", a, coef) - rhs) ** 2, axis=1)
    resid = np.where(coef[:, 3] > 0.0, resid, np.inf)
    if not np.isfinite(resid).any():
        return None
    b = int(np.argmin(resid))
    bgk, a_s, a_c, a_b = coef[b]
    return np.array(
        [
            depths[b],
            ts * 1e9,
            math.log(max(a_s, 1e-2)),
            math.log(max(a_c, 1e-2)),
            math.log(max(a_b, 1e-2)),
            math.log(0.1),
            max(bgk, bg * 1e-3, 1e-3),
            0.0,
        ]
    )


def _project(th: np.ndarray, data: PulseBatch, i: int, group_index: float) -> np.ndarray:
    """Clip into pulse ``i``'s prior box (with a margin); pull the bottom inside the window."""
    lo, hi = data.lower[i], data.upper[i]
    span = hi - lo
    out = np.clip(th, lo + 1e-12 * span, hi - 1e-12 * span)
    tau_max = data.t_last_s[i] - out[1] * 1e-9
    d_max = tau_max * _C * data.cos_water[i] / (2.0 * group_index)
    out[0] = min(out[0], (1.0 - 1e-6) * d_max)
    return out


def posterior_modes(
    data: PulseBatch, system: WaveformSystem, theta0: Any, iterations: int = 40
) -> tuple[np.ndarray, np.ndarray]:
    """Damped Fisher scoring (Levenberg–Marquardt) from ``theta0`` to every pulse's mode.

    All pulses step together (one batched model evaluation per iteration), each with its own
    damping; a step is kept only if it raises that pulse's log posterior.

    Parameters
    ----------
    data : PulseBatch
    system : WaveformSystem
    theta0 : (P, 8) array_like
        Starting points.
    iterations : int

    Returns
    -------
    theta : (P, 8) ndarray
        The modes (inside the prior boxes).
    info : (P, 8, 8) ndarray
        Fisher information there.
    """
    p = len(data)
    th = np.array(
        [
            _project(t, data, i, system.group_index)
            for i, t in enumerate(np.asarray(theta0, dtype=np.float64))
        ]
    )
    res = score(data.samples, th, system, data.cos_water, data.valid)
    _, grad, info = _prior_score(res, th, data)
    lp = log_prob_blocks(th.reshape(1, -1), data, system)[0, 1:]
    lam = np.full(p, 1e-3)
    active = np.ones(p, dtype=bool)
    eye = np.eye(N_PARAMS)
    for _ in range(iterations):
        d = np.sqrt(np.maximum(np.diagonal(info, axis1=1, axis2=2), 1e-300))
        a = info / (d[:, :, None] * d[:, None, :]) + lam[:, None, None] * eye
        step = np.linalg.solve(a, (grad / d)[:, :, None])[:, :, 0] / d
        trial = np.array([_project(th[i] + step[i], data, i, system.group_index) for i in range(p)])
        lp_t = log_prob_blocks(trial.reshape(1, -1), data, system)[0, 1:]
        better = active & (lp_t > lp)
        if better.any():
            gain = np.where(better, lp_t, 0.0) - np.where(better, lp, 0.0)
            th[better] = trial[better]
            sub = (data.samples[better], th[better], system, data.cos_water[better])
            _, grad_n, info_n = score(*sub, data.valid[better])
            _, grad_n, info_n = _prior_score((None, grad_n, info_n), th[better], data, better)
            lp[better], grad[better], info[better] = lp_t[better], grad_n, info_n
            active &= ~(better & (gain < 1e-6))
        lam = np.where(better, np.maximum(lam * 0.3, 1e-6), lam * 10.0)
        active &= lam <= 1e8
        if not active.any():
            break
    return th, info


def _prior_score(res, th, data: PulseBatch, rows=slice(None)):
    """Add the normal prior on ``ln k`` (if any) to a ``score`` result of rows ``th``."""
    ll, grad, info = res
    mean, sig = data.ln_k_prior[rows, 0], data.ln_k_prior[rows, 1]
    fin = np.isfinite(sig)
    if fin.any():
        grad, info = grad.copy(), info.copy()
        s2 = np.where(fin, sig, 1.0) ** 2
        grad[:, 5] -= np.where(fin, (th[:, 5] - mean) / s2, 0.0)
        info[:, 5, 5] += np.where(fin, 1.0 / s2, 0.0)
    return ll, grad, info


def _initial_ball(
    data: PulseBatch, i: int, system, mode, info, n_walkers: int, scale: float, rng
) -> np.ndarray:
    """``n_walkers`` points around ``mode`` from the Laplace covariance, inside the prior."""
    one = data.pulse(i)
    cov = covariance(info + _prior_precision(one, 0))
    chol = np.linalg.cholesky(cov + np.diag(1e-12 * np.diag(cov) + 1e-300))
    p0 = np.empty((n_walkers, N_PARAMS))
    filled = 0
    for _ in range(100):
        cand = mode + scale * rng.standard_normal((n_walkers, N_PARAMS)) @ chol.T
        good = cand[np.isfinite(log_prob(cand, one, system))]
        take = min(len(good), n_walkers - filled)
        p0[filled : filled + take] = good[:take]
        filled += take
        if filled == n_walkers:
            return p0
    # pathological (a mode on a prior edge): a tiny ball, projected inside
    rest = mode + 1e-4 * np.sqrt(np.diag(cov)) * rng.standard_normal((n_walkers - filled, N_PARAMS))
    p0[filled:] = [_project(q, one, 0, system.group_index) for q in rest]
    return p0


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
        z = np.einsum("pij,npj->npi", self.inv_chol, x - self.centre)
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
        q = self.centre + np.einsum("pij,npj->npi", self.chol, z) * w
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


@dataclass(frozen=True)
class PulseChains:
    """The sampled posteriors of a batch of pulses.

    Attributes
    ----------
    draws : (P, k, 8) ndarray
        Thinned production draws per pulse (NaN-free; pulses without a start hold their
        start-less zeros and the NO_START flag).
    mode : (P, 8) ndarray
        Posterior modes the walkers started around.
    acceptance : (P,) ndarray
        Per-pulse acceptance fraction of the production chain.
    tau_steps : (P, 8) ndarray
        Integrated autocorrelation time per pulse and parameter, in steps.
    n_steps : (P,) int64
        Production steps per pulse.
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
) -> PulseChains:
    """Sample the posteriors of a batch of waveforms with one emcee ensemble.

    Parameters
    ----------
    waveforms : (P, m) array_like or sequence of 1-D arrays
    system : WaveformSystem
    settings : PosteriorSettings, optional
    cos_water : float or (P,) array_like
        Cosine of each pulse's in-water angle from the vertical.
    theta0 : (P, 8) array_like, optional
        Starting estimates; default :func:`start_theta` (the detector's) per pulse.
    seed : int
        Seeds the start balls and emcee's generator (results depend on the batch's make-up).
    detect_settings, detect_noise : optional
        The survey detector's settings and ``(noise_samples, shot_noise_counts)``, for the
        starts (:func:`start_theta`): the same detections the survey's points come from.

    Returns
    -------
    PulseChains
        ``n_steps`` per pulse: a pulse stops at the first chunk boundary where it converged.
    """
    st = settings or PosteriorSettings()
    data = make_pulse_batch(waveforms, system, st, cos_water)
    n_p = len(data)
    rng = np.random.default_rng(seed)
    starts = [None] * n_p if theta0 is None else list(np.asarray(theta0, dtype=np.float64))
    flags = np.zeros(n_p, dtype=np.uint16)
    for i in range(n_p):
        if starts[i] is None:
            one = data.pulse(i)
            starts[i], scanned = _start(
                one.samples[0], system, float(one.cos_water[0]), detect_settings, detect_noise
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
    modes, infos = posterior_modes(data, system, np.array(starts))
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
        # adapt the independence proposal once, at the end of the burn-in (fixed afterwards)
        half = burn[burn.shape[0] // 2 :]
        for i in range(n_p):
            x = half[:, :, i].reshape(-1, N_PARAMS)
            cov = np.cov(x, rowvar=False)
            if np.all(np.linalg.eigvalsh(cov) > 1e-12 * np.max(np.diag(cov))):
                centres[i], scales[i] = x.mean(axis=0), cov
    proposal = (centres, scales * st.proposal_scale**2)
    # production in chunks; converged pulses leave, the others continue from where they are
    stored = [[] for _ in range(n_p)]
    acc_sum = np.zeros(n_p)
    n_steps = np.zeros(n_p, dtype=np.int64)
    tau = np.full((n_p, N_PARAMS), np.inf)
    active = np.arange(n_p)
    while active.size:
        chunk = min(st.chunk_steps, st.max_steps - int(n_steps[active[0]]))
        chunk = max(st.thin, chunk - chunk % st.thin)  # whole stored steps
        sub_prop = (proposal[0][active], proposal[1][active])
        new_pos, (chain, acc) = _run(
            data, active, pos[:, active], system, st, chunk, st.thin, rng, sub_prop
        )
        pos[:, active] = new_pos
        n_steps[active] += chunk
        acc_sum[active] += acc * chunk
        done = []
        for k, i in enumerate(active):
            stored[i].append(chain[:, :, k])
            if n_steps[i] < st.min_steps and n_steps[i] < st.max_steps:
                continue
            x = np.concatenate(stored[i], axis=0)
            with np.errstate(invalid="ignore", divide="ignore"):  # a stuck chain: acf 0/0
                t_i = st.thin * emcee.autocorr.integrated_time(x, tol=0)
            tau[i] = np.where(np.isfinite(t_i), t_i, np.inf)
            if n_steps[i] >= st.tau_factor * tau[i].max() or n_steps[i] >= st.max_steps:
                done.append(i)
        active = np.setdiff1d(active, done)
    short = n_steps < st.tau_factor * tau.max(axis=1)
    flags[short] |= np.uint16(PosteriorFlag.NOT_CONVERGED)
    acc = acc_sum / np.maximum(n_steps, 1)
    lo, hi = st.acceptance_range
    flags[(acc <= lo) | (acc >= hi)] |= np.uint16(PosteriorFlag.ACCEPTANCE)
    # the same number of draws for every pulse, evenly spread over each pulse's whole chain
    flats = [np.concatenate(x, axis=0).reshape(-1, N_PARAMS) for x in stored]
    n_draws = min(st.max_draws, *(f.shape[0] for f in flats))
    draws = np.stack([f[np.linspace(0, f.shape[0] - 1, n_draws).astype(np.int64)] for f in flats])
    d_lo = np.quantile(draws[:, :, 0], 0.025, axis=1)
    d_hi = np.quantile(draws[:, :, 0], 0.975, axis=1)
    span = data.upper[:, 0] - data.lower[:, 0]
    edge = (d_lo <= data.lower[:, 0] + 1e-3 * span) | (d_hi >= data.upper[:, 0] - 1e-3 * span)
    flags[edge] |= np.uint16(PosteriorFlag.AT_PRIOR_BOUND)
    return PulseChains(draws, modes, acc, tau, n_steps, flags)


def _run(data: PulseBatch, pulses, pos, system, st, n_steps: int, thin: int, rng, proposal):
    """Advance the walkers ``pos`` (n_walkers, len(pulses), 8) of some pulses ``n_steps``.

    Moves: :class:`BlockDEMove` and :class:`BlockIndependenceMove` (``proposal`` = centres and
    scale matrices of these pulses), mixed with weight ``st.independence_weight``.

    Returns
    -------
    positions : (n_walkers, len(pulses), 8) ndarray
    chain : (n_steps // thin, n_walkers, len(pulses), 8) ndarray
        The stored chain.
    acceptance : (len(pulses),) ndarray
        Fraction of proposals accepted per pulse (both moves).
    """
    sub = PulseBatch(*(getattr(data, f)[pulses] for f in _BATCH_FIELDS))
    nw, n_p = pos.shape[0], len(pulses)
    de = BlockDEMove(n_p, N_PARAMS)
    ind = BlockIndependenceMove(proposal[0], proposal[1], st.proposal_dof)
    w = st.independence_weight
    moves = [(de, 1.0 - w), (ind, w)] if 0.0 < w < 1.0 else [ind] if w >= 1.0 else [de]
    sampler = emcee.EnsembleSampler(
        nw, n_p * N_PARAMS, log_prob_blocks, args=(sub, system), vectorize=True, moves=moves
    )
    sampler.random_state = np.random.RandomState(int(rng.integers(2**31))).get_state()
    # each pulse's walkers are independent; the joint (8 P)-D check does not apply
    state = sampler.run_mcmc(
        pos.reshape(nw, n_p * N_PARAMS),
        n_steps // thin,
        thin_by=thin,
        skip_initial_state_check=True,
    )
    chain = sampler.get_chain().reshape(-1, nw, n_p, N_PARAMS)
    acc = (de.accepted + ind.accepted) / max(de.proposed + ind.proposed, 1)
    return state.coords.reshape(nw, n_p, N_PARAMS), (chain, acc)


_BATCH_FIELDS = ("samples", "valid", "cos_water", "lower", "upper", "t_last_s", "ln_k_prior")


def _prior_precision(data: PulseBatch, i: int) -> np.ndarray:
    """Diagonal precision of pulse ``i``'s prior.

    Box widths (a uniform's scale), and the normal prior on ``ln k`` if any: keeps the
    Laplace covariance finite for unconstrained parameters.
    """
    prec = 1.0 / (data.upper[i] - data.lower[i]) ** 2
    sig = data.ln_k_prior[i, 1]
    if np.isfinite(sig):
        prec[5] += 1.0 / sig**2
    return np.diag(prec)


def sample_pulse(
    samples: Any,
    system: WaveformSystem,
    settings: PosteriorSettings | None = None,
    *,
    cos_water: float = 1.0,
    theta0: Any = None,
    seed: int = 0,
) -> PulseChains:
    """:func:`sample_batch` of one waveform (a batch of one)."""
    th0 = None if theta0 is None else np.asarray(theta0, dtype=np.float64)[None, :]
    y = np.asarray(samples, dtype=np.float64)[None, :]
    return sample_batch(y, system, settings, cos_water=cos_water, theta0=th0, seed=seed)


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


def water_cosine(direction: Any, normal: Any, air_index: float, phase_index: float) -> np.ndarray:
    """Cosine of the refracted beam's angle to the surface normal, by Snell's law.

    ``direction`` and ``normal`` are (n, 3) unit vectors; grazing or totally reflected beams
    give the smallest positive cosine rather than NaN.
    """
    d = np.asarray(direction, dtype=np.float64)
    n = np.asarray(normal, dtype=np.float64)
    cos_i = np.abs(np.sum(d * n, axis=-1))
    sin_w = air_index / phase_index * np.sqrt(np.maximum(1.0 - cos_i**2, 0.0))
    return np.sqrt(np.maximum(1.0 - sin_w**2, 1e-12))


_SURFACE_ROWS = (
    "entry_m",
    "range_to_entry_m",
    "normal",
    "is_water",
    "is_land",
    "surface_point_m",
    "surface_residual_m",
    "fit_sigma_m",
    "height_sigma_m",
    "normal_sigma_rad",
    "n_used",
    "flags",
)


def take_surface(surface: WaterSurface, index: Any) -> WaterSurface:
    """The rows ``index`` of a fitted surface (repeats allowed), as a new object."""
    kw = {name: getattr(surface, name)[index] for name in _SURFACE_ROWS}
    return WaterSurface(
        **kw,
        global_plane=surface.global_plane,
        global_sigma_m=surface.global_sigma_m,
        air_index=surface.air_index,
    )


@dataclass(frozen=True)
class SeabedPosteriors:
    """Posterior summaries of the refraction-corrected seabed point per sampled pulse.

    Attributes
    ----------
    pulse_id : (n,) int64
    row : (n,) int64
        Row of the pulse in the input arrays.
    depth_m : dict of (n,) ndarray
        :func:`interval_summary` of the depth below the fitted surface (``median``, ``lo68``,
        ``hi68``, ``lo95``, ``hi95``, ``std``), metres.
    xyz_median_m : (n, 3) ndarray
        Per-coordinate posterior median of the seabed point.
    xyz_std_m : (n, 3) ndarray
        Per-coordinate posterior standard deviation.
    sigma_h_m : (n,) ndarray
        Horizontal per-axis (circular) standard deviation ``sqrt((var_x + var_y) / 2)``.
    acceptance, tau_max_steps : (n,) ndarray
    n_steps : (n,) int64
    flags : (n,) uint16
        :class:`PosteriorFlag` bits.
    """

    pulse_id: np.ndarray
    row: np.ndarray
    depth_m: dict[str, np.ndarray]
    xyz_median_m: np.ndarray
    xyz_std_m: np.ndarray
    sigma_h_m: np.ndarray
    acceptance: np.ndarray
    tau_max_steps: np.ndarray
    n_steps: np.ndarray
    flags: np.ndarray

    @property
    def converged(self) -> np.ndarray:
        """(n,) bool: neither NOT_CONVERGED nor ACCEPTANCE (nor NO_START)."""
        bad = PosteriorFlag.NOT_CONVERGED | PosteriorFlag.ACCEPTANCE | PosteriorFlag.NO_START
        return (self.flags & np.uint16(bad)) == 0


def draws_to_seabed(
    chain_draws: np.ndarray,
    row: int,
    t0_s: float,
    returns: DetectedReturns,
    surface: WaterSurface,
    system: WaveformSystem,
    cos_water: float,
    refraction_settings: RefractionSettings | None = None,
):
    """Refraction-corrected seabed points (``Points``) of every posterior draw of one pulse."""
    k = chain_draws.shape[0]
    ts = t0_s + chain_draws[:, 1] * 1e-9
    tb = ts + in_water_delay_s(chain_draws[:, 0], cos_water, system.group_index)
    idx = np.full(k, row)
    ones = np.ones(k, dtype=bool)
    ret = DetectedReturns(
        pulse_id=np.full(k, returns.pulse_id[row]),
        origin_meas_m=returns.origin_meas_m[idx],
        direction_meas=returns.direction_meas[idx],
        has_surface=ones,
        t_surface_s=ts,
        has_bottom=ones,
        t_bottom_s=tb,
        surface_confidence=np.full(k, max(returns.surface_confidence[row], 1e-6)),
        bottom_confidence=np.full(k, max(returns.bottom_confidence[row], 1e-6)),
        flags=returns.flags[idx],
    )
    return seabed_points(ret, take_surface(surface, idx), refraction_settings)


def seabed_posteriors(
    samples: Any,
    t0_s: Any,
    returns: DetectedReturns,
    surface: WaterSurface,
    system: WaveformSystem,
    settings: PosteriorSettings | None = None,
    refraction_settings: RefractionSettings | None = None,
    *,
    rows: Any = None,
    seed: int = 0,
    detect_settings: DetectSettings | None = None,
    detect_noise: tuple[int | None, float] | None = None,
) -> SeabedPosteriors:
    """Sample the depth posterior of pulses and carry it to the refracted seabed point.

    Parameters
    ----------
    samples : (n_pulses, m) array_like
        Waveforms, rows aligned with ``returns`` and ``surface``.
    t0_s : (n_pulses,) array_like
        Round-trip time of the centre of each waveform's sample 0, seconds.
    returns : DetectedReturns
        Measured navigation (origin, direction), confidences and flags of the pulses.
    surface : WaterSurface
        The fitted water surface of the same pulses.
    system : WaveformSystem
    settings : PosteriorSettings, optional
    refraction_settings : RefractionSettings, optional
        Water indices for :func:`~pipeline.process.refraction.seabed_points`.
    rows : array_like of int, optional
        Pulses to sample (default: all). Cost is linear in their number (see
        ``benchmarks/RESULTS_posterior.md``).
    seed : int
        Batch ``b`` (``settings.batch_size`` pulses side by side) is seeded ``seed + b0``.
    detect_settings, detect_noise : optional
        The survey detector's, for the starts (see :func:`sample_batch`).

    Returns
    -------
    SeabedPosteriors
    """
    st = settings or PosteriorSettings()
    rst = refraction_settings or RefractionSettings()
    y = np.asarray(samples, dtype=np.float64)
    t0 = np.asarray(t0_s, dtype=np.float64)
    n = len(returns)
    if y.ndim != 2 or y.shape[0] != n or t0.shape != (n,) or len(surface) != n:
        raise ValueError(
            f"`samples` {y.shape}, `t0_s` {t0.shape}, `surface` ({len(surface)}) must have "
            f"one row per pulse of `returns` ({n})"
        )
    rows = np.arange(n) if rows is None else np.asarray(rows, dtype=np.int64)
    cosw = water_cosine(returns.direction_meas, surface.normal, surface.air_index, rst.phase_index)
    m = len(rows)
    keys = ("median", "lo68", "hi68", "lo95", "hi95", "std")
    depth = {k: np.zeros(m) for k in keys}
    xyz_med, xyz_std, sig_h = np.zeros((m, 3)), np.zeros((m, 3)), np.zeros(m)
    acc, tau_max = np.zeros(m), np.zeros(m)
    n_steps, flags = np.zeros(m, dtype=np.int64), np.zeros(m, dtype=np.uint16)
    for b0 in range(0, m, st.batch_size):
        part = rows[b0 : b0 + st.batch_size]
        chains = sample_batch(
            y[part],
            system,
            st,
            cos_water=cosw[part],
            seed=seed + b0,
            detect_settings=detect_settings,
            detect_noise=detect_noise,
        )
        for k, r in enumerate(part):
            j = b0 + k
            acc[j], tau_max[j] = chains.acceptance[k], float(np.max(chains.tau_steps[k]))
            n_steps[j], flags[j] = chains.n_steps[k], chains.flags[k]
            if not surface.is_water[r]:
                flags[j] |= np.uint16(PosteriorFlag.NO_START)
            if flags[j] & PosteriorFlag.NO_START:
                continue
            pts = draws_to_seabed(
                chains.draws[k], int(r), float(t0[r]), returns, surface, system, float(cosw[r]), rst
            )
            summ = interval_summary(pts.depth_m)
            for key in keys:
                depth[key][j] = summ[key]
            xyz_med[j] = np.median(pts.xyz_m, axis=0)
            xyz_std[j] = np.std(pts.xyz_m, axis=0, ddof=1)
            sig_h[j] = math.sqrt(0.5 * (xyz_std[j, 0] ** 2 + xyz_std[j, 1] ** 2))
    return SeabedPosteriors(
        pulse_id=returns.pulse_id[rows],
        row=rows,
        depth_m=depth,
        xyz_median_m=xyz_med,
        xyz_std_m=xyz_std,
        sigma_h_m=sig_h,
        acceptance=acc,
        tau_max_steps=tau_max,
        n_steps=n_steps,
        flags=flags,
    )
