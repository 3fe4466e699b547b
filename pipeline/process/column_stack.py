"""The survey's water-column decay from the stacked column of many pulses.

The forward-scattering range correction (:mod:`pipeline.process.scatter_bias`) needs the water's
lidar attenuation ``k`` (per metre of in-water path): the column return decays as
``C(t) = C0 exp(−2 k l)`` with the path ``l = v t / 2``, ``v = c / n_g``, so
``C(t) = C0 exp(−α t)`` and ``k = α n_g / c``.

**Why not per pulse.** A per-pulse fit (:func:`~pipeline.process.detection_limit.column_margins`)
uses the contiguous run of samples above ``min_column_snr`` noise σ: in clear water that run is
3-8 samples long and is chosen by the noise (a sample that happened to be high extends it, one
that happened to be low ends it), so the fitted decay is biased high, several times ``k`` (suite
tuning seed 54, c = 0.064 /m: median of per-pulse fits 1.28 /m against a lidar decay of 0.061 /m).

**Stacking.** Each pulse's filtered, baseline-subtracted column is aligned at its own first
column sample (surface echo + the detector's minimum separation) and added, bin by bin, into sums
``S_j = Σ y``, ``Q_j = Σ y²`` and counts ``N_j`` over the pulses that reach bin ``j`` (up to
their own end: the window's searched end, or a separation before their bottom or in-column
echo, so no echo enters the stack). The sums are additive across chunks (float64; the result
does not depend on the chunking beyond rounding). The mean ``μ_j = S_j / N_j`` has the standard
error ``σ_j = √((Q_j / N_j − μ_j²) / N_j)`` (spread across pulses: noise and the pulses' column
levels). The decay is the weighted least-squares slope of ``log μ_j`` on time over the leading run
of bins with ``μ_j > min_snr σ_j`` and ``N_j ≥`` :data:`MIN_PULSES`, weights ``(μ_j / σ_j)²``
(the inverse variance of ``log μ_j``); the run is chosen on the stack's mean, whose noise is
``√N`` times smaller than a pulse's, so its truncation bias is small. The run also stops at a
bin more than ``min_snr √2 σ_j`` above the lowest bin before it: a column only decays, and the
bottoms of pulses where none was found (each under the noise) add up to a bump in the stack
(suite tuning seed 19: a bump at the seabed's depth flattened the fit to 0.068 /m, stopping
there gives 0.087 /m against a lidar decay of 0.089 /m).

**Closed and open columns.** A column that ends a separation before an echo (a found bottom,
an in-column echo) is water all along. One that runs to the searched end (no echo found) also
runs past the seabed of a pulse whose bottom was too faint to be found, and stops there: the
stack sees that seabed, which no pulse does, and a stack of such cliffs falls faster than the
water decays (shoal tuning seed 7003, c = 0.73 /m over a 0-4.9 m plane: 21 500 open columns
gave 0.74 /m against the water's 0.21 /m). :func:`pipeline.process.no_bottom.chunk_inputs`
stacks the two apart, and the survey's decay is the closed columns', the open ones' only where
the closed show none (no bottom found anywhere).

Assumptions: the time after the surface measures the in-water path along the refracted beam at
the group speed, whatever the incidence (so ``k`` is per metre of path, not of depth); pulses of
different column levels (incidence, altitude, surface transmission) add exponentials of the same
decay, which is still that exponential, as long as the pulses reaching a bin do not change
systematically in level with the bin. They do over a sloping seabed (bottom pulses leave the
stack at their bottom, and a survey whose shallow part is brighter biases ``k`` high: suite
tuning seed 1617, 15.6°, 4 % in ``k``, 17 % in ``c`` through Gordon's bridge): so the stack
also keeps its sums per class of column end (:data:`END_CLASS_BINS`), and the decay is fitted
over the run (chosen on the whole stack) with only the pulses whose column reaches its end, one
fixed set (1617: ``c`` 0.309 -> 0.273 /m, its level twin's; true 0.264).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np

from pipeline.optics import SPEED_OF_LIGHT_M_S
from pipeline.process.detection_limit import (
    BLOCK,
    DetectorModel,
    column_first_index,
    filtered_waveforms,
)

__all__ = ["MIN_PULSES", "MIN_SNR", "ColumnStack", "stack_column", "stacked_decay_per_m"]

#: Pulses a stack bin needs to enter the fit (its standard error is estimated from them).
MIN_PULSES = 20
#: A stack bin enters the fit while its mean is above this many standard errors.
MIN_SNR = 3.0
#: Bins per class of column end whose sums a stack keeps apart (the decay is fitted over the
#: pulses whose column reaches the fit's last bin).
END_CLASS_BINS = 4


@dataclass(frozen=True)
class ColumnStack:
    """Bin-by-bin sums of the filtered column after each pulse's first column sample.

    ``sum_counts``, ``sum_sq_counts2`` (float64) and ``n_pulses`` (int64), shapes ``(n_bins,)``:
    ``Σ y``, ``Σ y²`` and the number of pulses over bin ``j``, the ``j``-th sample after
    the first column sample; ``dt_s`` the bin (sample) width.
    """

    sum_counts: np.ndarray
    sum_sq_counts2: np.ndarray
    n_pulses: np.ndarray
    dt_s: float
    by_end: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None

    @classmethod
    def empty(cls, dt_s: float) -> ColumnStack:
        """A stack of no pulse."""
        z = np.zeros((0, 0))
        return cls(
            np.zeros(0), np.zeros(0), np.zeros(0, dtype=np.int64), dt_s, (z, z, z.astype(np.int64))
        )

    def reaching(self, j: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(Σ y, Σ y², N)`` per bin over the pulses whose column reaches past bin ``j``.

        From the sums kept per class of column end (:data:`END_CLASS_BINS` bins each): the
        classes that all end after ``j``. Without them (older stacks): the whole stack's.
        """
        if self.by_end is None:
            return self.sum_counts, self.sum_sq_counts2, self.n_pulses
        first = (int(j) + 1 + END_CLASS_BINS - 1) // END_CLASS_BINS  # classes starting after j
        return tuple(a[first:].sum(axis=0) for a in self.by_end)

    def __add__(self, other: ColumnStack) -> ColumnStack:
        """The stack of both sets of pulses (the shorter one padded with empty bins)."""
        if not math.isclose(self.dt_s, other.dt_s, rel_tol=1e-12):
            raise ValueError(f"stacks of different bins: {self.dt_s} s and {other.dt_s} s")
        n = max(self.n_pulses.size, other.n_pulses.size)

        def pad(a):
            return np.pad(a, (0, n - a.size))

        by_end = None
        if self.by_end is not None and other.by_end is not None:
            rows = max(self.by_end[0].shape[0], other.by_end[0].shape[0])

            def pad2(a):
                return np.pad(a, ((0, rows - a.shape[0]), (0, n - a.shape[1])))

            by_end = tuple(
                pad2(a) + pad2(b) for a, b in zip(self.by_end, other.by_end, strict=True)
            )
        return ColumnStack(
            pad(self.sum_counts) + pad(other.sum_counts),
            pad(self.sum_sq_counts2) + pad(other.sum_sq_counts2),
            pad(self.n_pulses) + pad(other.n_pulses),
            self.dt_s,
            by_end,
        )

    @classmethod
    def total(cls, stacks: list[ColumnStack], dt_s: float) -> ColumnStack:
        """The sum of ``stacks`` (the empty stack if there are none)."""
        out = cls.empty(dt_s)
        for s in stacks:  # one per chunk
            out = out + s
        return out


def _accumulate(filt, first_idx, end_idx, dt_s) -> ColumnStack:
    """Stack of ``filt`` (n, m) from ``ceil(first_idx)`` to before ``end_idx``, shapes (n,)."""
    n, m = filt.shape
    first_idx = np.asarray(first_idx, dtype=np.float64)
    # a column without a finite start is not stacked (it starts past the window's end)
    off = np.where(np.isfinite(first_idx), np.ceil(np.minimum(first_idx, m)), m).astype(np.int64)
    if n and off.min() < 0:  # (a column from before sample 0 would need more than m bins)
        raise ValueError("a column starts before the first sample")
    # each pulse's column end (its first bin not stacked), by class
    end_bin = np.clip(np.ceil(end_idx).astype(np.int64) - off, 0, m)
    n_cls = m // END_CLASS_BINS + 1
    s1, s2, cnt = _stack_sums(
        np.ascontiguousarray(filt, dtype=np.float64),
        off,
        np.asarray(end_idx, dtype=np.float64),
        end_bin // END_CLASS_BINS,
        n_cls,
    )
    return ColumnStack(
        s1[n_cls], s2[n_cls], cnt[n_cls], dt_s, (s1[:n_cls], s2[:n_cls], cnt[:n_cls])
    )


@numba.njit(cache=True, nogil=True)
def _stack_sums(filt, off, end_idx, cls, n_cls):
    """Sums of ``y``, ``y²`` and counts per bin ``c - off`` of the samples ``off <= c < end``.

    Row ``n_cls`` of each ``(n_cls + 1, m)`` array: all pulses; rows ``0 .. n_cls - 1``: the
    pulses of each end class. Each bin's values are added in pulse order (as ``np.bincount``
    over the pulses' samples in turn adds them): the same sums to the bit.
    """
    n, m = filt.shape
    s1 = np.zeros((n_cls + 1, m))
    s2 = np.zeros((n_cls + 1, m))
    cnt = np.zeros((n_cls + 1, m), np.int64)
    for p in range(n):
        k = cls[p]
        for c in range(off[p], m):
            if not (c < end_idx[p]):
                break
            y = filt[p, c]
            j = c - off[p]
            s1[n_cls, j] += y
            s2[n_cls, j] += y * y
            cnt[n_cls, j] += 1
            s1[k, j] += y
            s2[k, j] += y * y
            cnt[k, j] += 1
    return s1, s2, cnt


def stack_column(
    samples: np.ndarray,
    t_surface_s: np.ndarray,
    t_end_s: np.ndarray,
    det: DetectorModel,
    first_s: np.ndarray | None = None,
) -> ColumnStack:
    """Add the columns of a chunk's pulses, each aligned at its first column sample.

    Parameters
    ----------
    samples : (n, m) array_like
        Digitised waveforms, baseline included (the baseline is removed as the per-pulse fit
        removes it: :func:`~pipeline.process.detection_limit.filtered_waveforms`).
    t_surface_s : (n,) ndarray
        Surface echo time from the first sample, seconds.
    t_end_s : (n,) ndarray
        Each pulse's column ends before this time from the first sample (a separation before its
        bottom or in-column echo, or the detector's searched end), seconds.
    det : DetectorModel
    first_s : (n,) ndarray, optional
        Each pulse's first column time from the first sample
        (:func:`~pipeline.process.detection_limit.column_first_s`: later after a clipped
        surface echo); default ``surface + min_separation_fwhm × FWHM``.

    Returns
    -------
    ColumnStack
        Bins from each pulse's first column sample (where its surface echo no longer masks
        the column; a sum of exponentials of one decay, each aligned at its own start, is
        still that exponential); ``m`` bins.
    """
    samples = np.asarray(samples)
    n, m = samples.shape
    first = column_first_index(t_surface_s, det, first_s)
    end = np.asarray(t_end_s, dtype=np.float64) / det.dt_s
    out = ColumnStack.empty(det.dt_s)
    for i in range(0, n, BLOCK):  # blocks bound the (pulses × samples) temporaries
        b = slice(i, i + BLOCK)
        out = out + _accumulate(filtered_waveforms(samples[b], det), first[b], end[b], det.dt_s)
    return out


def stacked_decay_per_m(
    stack: ColumnStack, group_index: float, min_snr: float = MIN_SNR, min_pulses: int = MIN_PULSES
) -> float | None:
    """The lidar attenuation ``k`` (per metre of in-water path) of the stacked column.

    Parameters
    ----------
    stack : ColumnStack
        The survey's stack (:meth:`ColumnStack.total` of the chunks').
    group_index : float
        Group index of the water processing assumes: ``k = α n_g / c``.
    min_snr : float
        A bin enters the fit while its mean is above ``min_snr`` standard errors (the leading
        run of such bins).
    min_pulses : int
        ... and while at least this many pulses reach it.

    Returns
    -------
    float or None
        ``k``, per metre; None where fewer than 3 bins qualify or the stack does not decay
        (no measurable column: clear water at night, a stack of no pulse).
    """
    n = stack.n_pulses.astype(np.float64)
    nn = np.maximum(n, 1.0)
    mean = stack.sum_counts / nn
    se = np.sqrt(np.maximum(stack.sum_sq_counts2 / nn - mean * mean, 0.0) / nn)
    good = (stack.n_pulses >= max(int(min_pulses), 2)) & (mean > min_snr * se) & (mean > 0.0)
    # a column only decays: a bin significantly above the lowest bin before it holds echoes
    # (bottoms too faint to be found, each under the noise, add up in the stack; a layer)
    lowest_before = np.concatenate(
        ([np.inf], np.minimum.accumulate(np.where(good, mean, np.inf))[:-1])
    )
    rise = mean - lowest_before > min_snr * math.sqrt(2.0) * se
    run = np.cumprod(good & ~rise).astype(bool)  # the leading run: the column, then it stops
    if np.count_nonzero(run) < 3:
        return None
    # fitted over one set of pulses, those whose column reaches the run's end: over a sloping
    # seabed the pulses reaching a bin thin out with it (each leaves at its bottom), and the
    # changing set steepened the decay (suite tuning seed 1617, 15.6°: -0.0320 per bin against
    # -0.0309 for one fixed set and -0.0305 over the seabed made level; c 17 % high through
    # Gordon's bridge, the forward-scattering correction too large: benchmarks/
    # wave_refraction/RESULTS.md, session 13)
    last = int(np.flatnonzero(run)[-1])
    s1, s2, nj = stack.reaching(last)
    nf = nj[: run.size].astype(np.float64)
    if np.all(nf[run] >= max(int(min_pulses), 2)):
        nnf = np.maximum(nf, 1.0)
        mean_f = s1[: run.size] / nnf
        se_f = np.sqrt(np.maximum(s2[: run.size] / nnf - mean_f * mean_f, 0.0) / nnf)
        if np.all(mean_f[run] > 0.0):
            mean, se = mean_f, se_f
    t = np.arange(run.size)[run] * stack.dt_s
    mu, s = mean[run], se[run]
    # a bin of zero spread (a noiseless stack): its weight is capped at the best finite one
    w = np.where(s > 0.0, (mu / np.where(s > 0.0, s, 1.0)) ** 2, np.inf)
    w = np.where(np.isfinite(w), w, np.max(w[np.isfinite(w)], initial=1.0))
    slope = np.polyfit(t, np.log(mu), 1, w=np.sqrt(w))[0]  # polyfit weights multiply residuals
    if not (np.isfinite(slope) and slope < 0.0):
        return None
    # the chunks' stacks add in an order that depends on the chunking, which moves the last
    # bits of the sums: 9 significant digits (far below the estimate's own precision) give the
    # same decay whatever the chunking or the workers
    return float(f"{-slope * group_index / SPEED_OF_LIGHT_M_S:.9g}")
