"""Target density of the depth posterior: a batch of pulses and its log posterior.

Parameters and priors
---------------------
``theta`` follows :data:`pipeline.uncertainty.waveform_model.PARAM_NAMES`: depth (m), surface time
(ns), log surface / column / bottom areas (counts), log attenuation ``ln k`` (``k`` in 1/m),
background (counts per sample). Independent bounded priors
(:class:`~pipeline.uncertainty.posterior_settings.PosteriorSettings`), so the log prior is a
constant inside the box and ``-inf`` outside:

* depth: flat on ``depth_bounds_m``;
* surface time: flat over the window, and the bottom (``t_s + tau(depth)``) inside it;
* areas: **log-uniform** on ``area_bounds`` (1 count to 1e9: a return of less than a count is
  not in the data);
* attenuation: log-uniform on ``attenuation_bounds_per_m`` (0.01-2 1/m, clear ocean to turbid
  coast; a pulse alone barely constrains ``k``), or with ``attenuation_prior`` a log-normal
  prior (a survey's known water);
* background: flat on ``[0, background_max]`` (photon counting from ``1e-9``: a Poisson mean
  must be > 0);
* bottom and surface widths: log-uniform on ``bottom_width_ratio_bounds`` and
  ``surface_width_ratio_bounds`` times the system response's (forward scattering stretches a
  20 m bottom echo by a few ns in coastal water; the footprint and waves widen the surface).

:func:`log_prob_blocks` gives every pulse's own log posterior for all walkers from one model
evaluation (the sampler's ``blobs``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from pipeline.errors import NumericalError
from pipeline.uncertainty.posterior_settings import PosteriorSettings
from pipeline.uncertainty.waveform_kernel import log_post_rows
from pipeline.uncertainty.waveform_model import (
    N_PARAMS,
    WaveformSystem,
    th_str,
)

__all__ = ["PulseBatch", "make_pulse_batch", "log_prob", "log_prob_blocks"]


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
    lower, upper : (P, 9) float64
        Prior box per pulse and parameter.
    t_last_s : (P,) float64
        Centre of each waveform's last sample: surface and bottom must lie in
        ``[0, t_last_s]``.
    ln_k_prior : (P, 2) float64
        Mean and sigma of a normal prior on ``ln k`` (sigma ``inf``: flat, log-uniform ``k``).
    exposure : (P, m) float64
        Live share of each sample (photon counting's dead time: the recorded counts are
        Poisson of the model times it); 1 for a full waveform and where every channel was live.
    """

    samples: np.ndarray
    valid: np.ndarray
    cos_water: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    t_last_s: np.ndarray
    ln_k_prior: np.ndarray
    exposure: np.ndarray

    def __len__(self) -> int:
        return int(self.samples.shape[0])

    @property
    def n_valid(self) -> np.ndarray:
        """(P,) int64: real samples per waveform (the valid ones lead each row)."""
        return self.valid.sum(axis=1)

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
            self.exposure[i : i + 1, :m],
        )


def make_pulse_batch(
    waveforms: Any,
    system: WaveformSystem,
    settings: PosteriorSettings | None = None,
    cos_water: Any = 1.0,
    exposure: Any = None,
) -> PulseBatch:
    """Validate waveforms and build their :class:`PulseBatch` with the prior of ``settings``.

    Parameters
    ----------
    waveforms : (m,) or (P, m) array_like, or sequence of 1-D arrays of different lengths
    system : WaveformSystem
    settings : PosteriorSettings, optional
    cos_water : float or (P,) array_like
        In (0, 1].
    exposure : like ``waveforms``, optional
        Live share of each sample, in (0, 1] (:attr:`PulseBatch.exposure`); default 1.
    """
    st = settings or PosteriorSettings()
    rows = _rows(waveforms)
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
    live = np.ones((n, m))
    for i, w in enumerate(rows):
        samples[i, : w.size] = w
        valid[i, : w.size] = True
    if exposure is not None:
        ex = _rows(exposure)
        for i, e in enumerate(ex):
            if e.shape != rows[i].shape or not np.all((e > 0.0) & (e <= 1.0)):
                raise ValueError(f"`exposure[{i}]` must match `waveforms[{i}]`, in (0, 1]")
            live[i, : e.size] = e
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
            math.log(st.surface_width_ratio_bounds[0]),
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
            math.log(st.surface_width_ratio_bounds[1]),
        ]
    )
    upper = np.tile(upper, (n, 1))
    upper[:, 1] = t_last * 1e9
    if st.attenuation_prior is None:
        kp = (0.0, math.inf)
    else:
        kp = (math.log(st.attenuation_prior[0]), st.attenuation_prior[1])
    return PulseBatch(
        samples, valid, cw, np.tile(lower, (n, 1)), upper, t_last, np.tile(kp, (n, 1)), live
    )


def _rows(waveforms: Any) -> list[np.ndarray]:
    """A (P, m) array or a sequence of 1-D arrays as a list of float64 rows."""
    if isinstance(waveforms, np.ndarray) and waveforms.ndim <= 2:
        return list(np.atleast_2d(np.asarray(waveforms, dtype=np.float64)))
    return [np.asarray(w, dtype=np.float64) for w in waveforms]


def prior_box(data: PulseBatch) -> np.ndarray:
    """Prior box of each pulse as the compiled kernels take it.

    Returns
    -------
    (n_pulses, 3) float64
        Lower and upper bottom-time bounds and the last sample's time.
    """
    return np.column_stack([data.lower, data.upper, data.t_last_s])


def kernel_system(system) -> tuple:
    """The system figures the compiled kernels take, in their order.

    See :func:`~pipeline.uncertainty.waveform_kernel.log_post_rows`.
    """
    return (
        system.sample_interval_s,
        system.pulse_sigma_s,
        system.group_index,
        system.offset_counts,
        system.poisson,
        system.floor_variance,
        system.excess_noise_factor * system.counts_per_photoelectron,
        0.0 if system.poisson else system.surface_misfit,
    )


def _rows_log_post(th: np.ndarray, data: PulseBatch, system) -> np.ndarray:
    """Log posterior of walker rows ``th`` (N, 9), row ``k`` for pulse ``k % P``.

    ``-inf`` outside the prior box (flat inside, plus the optional normal prior on ``ln k``);
    NaN raised as :class:`NumericalError`. Compiled
    (:func:`~pipeline.uncertainty.waveform_kernel.log_post_rows`).
    """
    if np.isnan(th).any():
        raise NumericalError(f"`theta` holds NaN: {th_str(th[np.isnan(th).any(axis=1)][0])}")
    out = log_post_rows(
        np.ascontiguousarray(th),
        data.samples,
        data.n_valid,
        data.cos_water,
        prior_box(data),
        data.ln_k_prior,
        kernel_system(system),
        data.exposure,
    )
    if np.isnan(out).any() or np.isposinf(out).any():
        bad = th[~(np.isfinite(out) | np.isneginf(out))][0]
        raise NumericalError(f"log-likelihood is not finite at {th_str(bad)}")
    return out


def log_prob_blocks(theta: Any, data: PulseBatch, system: WaveformSystem) -> np.ndarray:
    """Per-pulse log posteriors of a batch, for the sampler (emcee ``blobs``).

    Parameters
    ----------
    theta : (n_walkers, 9 P) array_like
        Walker positions, pulse ``p`` in columns ``9p .. 9p + 8``.
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
    blocks = _rows_log_post(rows, data, system).reshape(n, p)
    return np.column_stack([np.sum(blocks, axis=1), blocks])


def log_prob(theta: Any, data: PulseBatch, system: WaveformSystem) -> Any:
    """Log posterior (up to a constant) of ``theta`` given the pulses of ``data``.

    Parameters
    ----------
    theta : (8 P,) or (n_walkers, 9 P) array_like
        Parameters in :data:`~pipeline.uncertainty.waveform_model.PARAM_NAMES` order, pulse by
        pulse (``P = len(data)``; one pulse: a 9-vector).
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
