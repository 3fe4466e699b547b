"""A pulse's column level under the survey's decay: class-45 limits where its own column is faint.

**Why.** The per-pulse limit (:func:`pipeline.process.detection_limit.column_margins`) fits a
line through the log of the pulse's column samples that stand ``min_column_snr`` noise σ above
the baseline. In clear water seen from high up few pulses have such a run, and those that do
were chosen by their noise: their decays fall several times faster than the water's
(:mod:`pipeline.process.column_stack`). Suite held-out seed 189 (c 0.074 /m, 750 m altitude,
a 51 m seabed): 1 162 of 18 573 pulses without a bottom had a measurable column, their fits a
median 0.22 /m against the stack's 0.067 /m, their limits ~1.7 m deep, and the survey reported
an extinction depth of 1.7 m in water where the assumed bottom would be seen at ~16 m.

**The water's decay is the survey's.** The stack measures the column's decay ``α`` over every
pulse. With ``α`` known the column's level is linear in the samples: the weighted least squares
of ``C_f e^{−α (t − t_f)} + b`` over every column sample, not only those above the noise, is
unbiased whatever the pulse's noise, its standard error from the fit's covariance (the samples'
noise correlated over ``L = 2 √π σ`` samples by the matched filter, within a bin and across the
edge to the next, plus the column's own shot noise; taken as independent, the bins gave a sigma
5-8 % short, and claims less sure than stated). ``b`` is fitted, not read as column: the pulse's
baseline (the median of its leading noise samples) is one error shared by every sample, and a
bright echo off land leaves a slow tail of a noise σ or two; read as column over hundreds of
samples either would be a deep claim (suite tuning seed 24: limits 4 m deep over land; a faint
column's level was as unsure from the baseline as from its samples). Where the column does not
decay within its bins, the two cannot be told apart and no limit is drawn. The limit is drawn as
:mod:`pipeline.process.detection_limit` draws it, at the settings' detection probability ``p``:
the level as low as the samples allow at ``p``, ``Ĉ_f − z_p σ``, carried back to the surface
(``C0 = C_f e^{α t_f}``) meets the assumed bottom's threshold level ``C*`` after ``ln(C0 / C*) /
(α + δ)``.

**Kept per chunk, solved per survey.** The decay is known only once every chunk has been
stacked, and the waveforms are gone by then. Each chunk keeps, per pulse without a bottom, its
filtered column summed over bins of :func:`bin_width` samples (about two noise correlation
lengths; at most :data:`MAX_BINS` bins, the column past them left out, which costs precision,
not bias). The level is then the binned least squares, exact in the model: a bin's model is the
sum of its own samples' exponentials.

**An echo is no column.** An echo the detector did not report (a bright bottom a metre under a
weak surface echo) would raise the level: a pulse whose own run above the noise rises (as the
per-pulse fit tests it) gets no limit from here, nor one with a bin standing above its fitted
column by the detector's threshold in that bin's own noise, nor one whose bins do not follow
the survey's decay (a χ² test at :data:`FIT_P_VALUE`: the tail of a broad echo falls faster
than the water). Nor does a pulse behind a clipped surface echo (its tail is known only by its
Gaussian model; :func:`pipeline.process.no_bottom.chunk_inputs` keeps no bins for it).

Where the pulse's own fit also gives a limit, the shallower of the two is claimed
(:func:`pipeline.process.no_bottom.limit_times_s`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import special, stats

from pipeline.process.limit_model import DetectorModel, limit_time_s, threshold_level
from pipeline.process.no_bottom_settings import NoBottomSettings

__all__ = [
    "FIT_P_VALUE",
    "MAX_BINS",
    "ColumnBins",
    "bin_width",
    "column_bins",
    "column_level",
    "level_limit_s",
]

#: Bins a pulse's column keeps at most (past them the column is left out).
MAX_BINS = 64
#: A column is tested against the survey's decay at this false-rejection rate (a rejected
#: pulse loses only this limit, not its own fit's).
FIT_P_VALUE = 1e-3


def bin_width(det: DetectorModel) -> int:
    """Samples per bin: two of the filtered noise's correlation lengths (at least one)."""
    return max(1, round(2.0 * det.correlation_samples))


@dataclass(frozen=True)
class ColumnBins:
    """Per pulse, shapes ``(n,)`` and ``(n, MAX_BINS)``: its filtered column, summed in bins.

    ``t_first_s`` is the first binned sample's time after the surface echo, ``count`` how many
    samples were binned (from there to the column's end, at most ``MAX_BINS`` bins), ``sums``
    the baseline-free, matched-filtered samples added over bins of :func:`bin_width` samples
    (float32; a bin past ``count`` holds 0).
    """

    t_first_s: np.ndarray
    count: np.ndarray
    sums: np.ndarray


def column_bins(
    filt: np.ndarray,
    first_idx: np.ndarray,
    end_idx: np.ndarray,
    t_surface_s: np.ndarray,
    det: DetectorModel,
) -> ColumnBins:
    """Bin each filtered column from past ``first_idx`` to before ``end_idx``.

    Parameters
    ----------
    filt : (n, m) ndarray
        Baseline-free, matched-filtered waveforms
        (:func:`~pipeline.process.detection_limit.filtered_waveforms`).
    first_idx, end_idx : (n,) ndarray
        The column runs over the samples after ``first_idx`` and before ``end_idx`` (as the
        per-pulse fit reads it).
    t_surface_s : (n,) ndarray
        Surface echo times from the first sample, seconds.
    det : DetectorModel

    Returns
    -------
    ColumnBins
    """
    n, m = filt.shape
    w = bin_width(det)
    start = np.floor(np.asarray(first_idx, dtype=np.float64)).astype(np.int64) + 1
    end = np.minimum(np.ceil(np.asarray(end_idx, dtype=np.float64)).astype(np.int64), m)
    count = np.clip(end - start, 0, MAX_BINS * w)
    # each bin's sum as a difference of the running sum (a gather of 2 samples per bin, not
    # of its w samples)
    run = np.zeros((n, m + 1))
    np.cumsum(filt, axis=1, out=run[:, 1:])
    edges = start[:, None] + np.minimum(w * np.arange(MAX_BINS + 1)[None, :], count[:, None])
    at = np.take_along_axis(run, np.clip(edges, 0, m), axis=1)
    sums = (at[:, 1:] - at[:, :-1]).astype(np.float32)
    t_first = (start - np.asarray(t_surface_s, dtype=np.float64) / det.dt_s) * det.dt_s
    return ColumnBins(t_first_s=t_first, count=count.astype(np.int32), sums=sums)


def _bin_noise_factor(n_samples: np.ndarray, det: DetectorModel) -> np.ndarray:
    """``√Var(Σ of n filtered noise samples) / σ_f``: their correlation ``e^{−d² / 4σ²}``."""
    s = det.sigma_samples
    n_max = int(np.max(n_samples, initial=1))
    d = np.arange(1, max(n_max, 1))
    rho = np.exp(-(d * d) / (4.0 * s * s))
    # Var = σ_f² (n + 2 Σ_{d<n} (n − d) ρ(d)), for every n up to n_max at once
    c1, c2 = np.concatenate(([0.0], np.cumsum(rho))), np.concatenate(([0.0], np.cumsum(d * rho)))
    nn = np.clip(np.asarray(n_samples, dtype=np.int64), 0, n_max)
    i = np.maximum(nn - 1, 0)
    return np.sqrt(np.maximum(nn + 2.0 * (nn * c1[i] - c2[i]), 0.0))


def _neighbour_covariance(n_b: np.ndarray, det: DetectorModel) -> np.ndarray:
    """``Cov(bin b, bin b+1) / σ_f²`` of filtered noise, ``(n, B)`` (0 past the last pair).

    Bins fill in order, so a bin followed by a non-empty one is whole (``w`` samples):
    ``Σ_{i<w} Σ_{j<m} ρ(w − i + j)`` with ``m`` the next bin's samples.
    """
    w = bin_width(det)
    s = det.sigma_samples
    i, j = np.arange(w)[:, None, None], np.arange(w)[None, :, None]
    m = np.arange(w + 1)[None, None, :]
    pair = np.where(j < m, np.exp(-((w - i + j) ** 2) / (4.0 * s * s)), 0.0).sum(axis=(0, 1))
    nxt = np.concatenate([n_b[:, 1:], np.zeros((len(n_b), 1), dtype=n_b.dtype)], axis=1)
    return np.where(n_b == w, pair[np.clip(nxt, 0, w)], 0.0)


def _fit_level_offset(y, e, n_b, has, var_b, cov_next):
    """The weighted least squares of ``y = level · e + offset · n_b`` per column, and its χ².

    The offset is the pulse's baseline error (shared by every sample: the median of its
    leading noise samples, or a slow tail after a bright echo), fitted, not read as column.

    Returns
    -------
    level, sigma, offset : (n,) ndarray
        The level at the first binned sample, its standard error, the offset per sample.
    misfit : (n,) bool
        The χ² exceeds its law's (``bins − 2`` degrees of freedom) at :data:`FIT_P_VALUE`: the
        bins do not follow the decay (the tail of a broad echo off land or a shoal, a column
        over a faint unseen bottom).
    solvable : (n,) bool
        The level and the offset can be told apart (the column decays within its bins).
    """
    w = np.where(has, 1.0 / np.maximum(var_b, 1e-300), 0.0)
    nb = n_b.astype(np.float64)
    s11, s12, s22 = (w * e * e).sum(1), (w * e * nb).sum(1), (w * nb * nb).sum(1)
    t1, t2 = (w * e * y).sum(1), (w * nb * y).sum(1)
    det = s11 * s22 - s12 * s12
    solvable = det > 1e-9 * s11 * s22
    dd = np.where(solvable, det, 1.0)
    level = np.where(solvable, (s22 * t1 - s12 * t2) / dd, 0.0)
    offset = np.where(solvable, (s11 * t2 - s12 * t1) / dd, 0.0)
    # the fit weighs the bins as independent; adjacent bins share the filtered noise across
    # their edge (cov_next), which the fit's variance takes in: M⁻¹ + M⁻¹ C M⁻¹ with
    # C = Σ_b cov(b, b+1) w_b w_{b+1} (x_b x_{b+1}ᵀ + x_{b+1} x_bᵀ), x_b = (e_b, n_b)
    wc = (w * cov_next)[:, :-1] * w[:, 1:]
    c11 = 2.0 * (wc * e[:, :-1] * e[:, 1:]).sum(1)
    c22 = 2.0 * (wc * nb[:, :-1] * nb[:, 1:]).sum(1)
    c12 = (wc * (e[:, :-1] * nb[:, 1:] + nb[:, :-1] * e[:, 1:])).sum(1)
    # the first row of M⁻¹ is (s22, −s12) / det
    a1, a2 = s22 / dd, -s12 / dd
    var = a1 + a1 * a1 * c11 + 2.0 * a1 * a2 * c12 + a2 * a2 * c22
    sigma = np.where(solvable, np.sqrt(np.maximum(var, 0.0)), 0.0)
    chi2 = (w * (y - level[:, None] * e - offset[:, None] * nb) ** 2).sum(1)
    dof = has.sum(1) - 2
    # (the χ² law's quantile once per number of bins, not per pulse)
    quantile = stats.chi2.isf(FIT_P_VALUE, np.arange(1, MAX_BINS + 1))
    misfit = solvable & (dof >= 1) & (chi2 > quantile[np.clip(dof, 1, MAX_BINS) - 1])
    return level, sigma, offset, misfit, solvable


def column_level(
    bins: ColumnBins, noise_sigma: np.ndarray, alpha_per_s: float, det: DetectorModel
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Each column's level at its first binned sample, at the decay ``alpha_per_s``.

    Parameters
    ----------
    bins : ColumnBins
        :func:`column_bins` of ``n`` pulses.
    noise_sigma : (n,) ndarray
        Their filtered noise σ.
    alpha_per_s : float
        The column's decay, 1/s.
    det : DetectorModel

    Returns
    -------
    level, sigma : (n,) ndarray
        The level (counts per sample, filtered) and its standard error.
    echo : (n,) bool
        A bin stands above the fitted column by the detector's threshold, or the bins do not
        follow the decay (:func:`_fit_level_offset`).
    ok : (n,) bool
        The level was measurable (bins, and a decay that tells it from the offset).
    """
    w = bin_width(det)
    n_b = np.clip(bins.count[:, None] - w * np.arange(MAX_BINS)[None, :], 0, w)  # (n, B)
    q = math.exp(-alpha_per_s * det.dt_s)
    # each bin's model, relative to the first binned sample: Σ over its samples of e^{−α Δt}
    geo = (1.0 - q**n_b) / (1.0 - q) if q < 1.0 else n_b.astype(np.float64)
    e = np.exp(-alpha_per_s * det.dt_s * w * np.arange(MAX_BINS))[None, :] * geo
    has = n_b > 0
    nb = np.where(has, n_b, 1)
    y = bins.sums.astype(np.float64)
    nf = np.maximum(np.asarray(noise_sigma, dtype=np.float64), 1e-300)[:, None]
    # a rough level (no offset) for the column's shot noise, which the bins' variances hold
    den = np.where(has, e * e / nb, 0.0).sum(axis=1)
    rough = np.where(has, y * e / nb, 0.0).sum(axis=1) / np.where(den > 0.0, den, 1.0)
    shot = det.shot_noise_counts / det.correlation_samples * np.maximum(rough[:, None] * e / nb, 0)
    # a bin sum's variance: its samples' noise, correlated as the matched filter makes it
    var_sample = nf**2 + shot
    var_b = _bin_noise_factor(n_b, det) ** 2 * var_sample
    # (the shot noise of a bin pair: the geometric mean of theirs)
    nxt = np.concatenate([var_sample[:, 1:], var_sample[:, -1:]], axis=1)
    cov_next = _neighbour_covariance(n_b, det) * np.sqrt(var_sample * nxt)
    level, sigma, offset, misfit, ok = _fit_level_offset(y, e, n_b, has, var_b, cov_next)
    # an echo the detector did not report: a bin above the fitted column by its threshold
    resid = (y - level[:, None] * e - offset[:, None] * nb) / np.sqrt(np.maximum(var_b, 1e-300))
    echo = ok & (np.any(has & (resid > det.threshold_sigma), axis=1) | misfit)
    return level, sigma, echo, ok


def level_limit_s(
    bins: ColumnBins,
    noise_sigma: np.ndarray,
    t_max_s: np.ndarray,
    alpha_per_s: float,
    excess_decay_per_s: float,
    det: DetectorModel,
    settings: NoBottomSettings | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Each pulse's detection limit at the survey's column decay, seconds after the surface.

    Parameters
    ----------
    bins : ColumnBins
        :func:`column_bins` of the pulses, ``n`` of them.
    noise_sigma : (n,) ndarray
        The filtered noise σ (the detector's estimate).
    t_max_s : (n,) ndarray
        The last searched time after the surface.
    alpha_per_s : float
        The survey's column decay (``k c / n_g`` of :func:`~pipeline.process.column_stack.
        stacked_decay_per_m`), 1/s.
    excess_decay_per_s : float
        The bottoms' extra decay ``δ``.
    det : DetectorModel
    settings : NoBottomSettings, optional

    Returns
    -------
    t_limit_s : (n,) ndarray
        0 where no limit is established: the level is not above zero at ``p``, or an echo
        stands in the column.
    echo : (n,) bool
        An echo or a misfit in the column (:func:`column_level`).
    """
    s = settings or NoBottomSettings()
    level, sigma, echo, ok = column_level(bins, noise_sigma, alpha_per_s, det)
    nf = np.maximum(np.asarray(noise_sigma, dtype=np.float64), 1e-300)
    z = float(special.ndtri(s.detection_probability))
    claim = level - z * sigma
    ok &= (claim > 0.0) & ~echo
    c_star = threshold_level(nf, det, s, z)
    log_c0 = np.log(np.where(ok, claim, 1.0)) + alpha_per_s * bins.t_first_s
    decay = alpha_per_s + excess_decay_per_s
    if not decay > 0.0:  # no decay (or NaN): nothing established
        return np.zeros(len(nf)), echo
    t_min = det.min_separation_fwhm * det.pulse_fwhm_s
    t_max = np.asarray(t_max_s, dtype=np.float64)
    return limit_time_s(log_c0 - np.log(c_star), decay, t_max, ok, t_min), echo
