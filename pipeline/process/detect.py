"""Detect the water surface and the bottom in full waveforms (measured data only).

Per waveform, vectorised over the batch:

1. **Noise floor from the waveform itself**: the baseline is the clipped mean of the samples
   before the first return, the noise σ a clipped rms of the first differences
   (:mod:`pipeline.process.detect_noise`) (the range gate opens before the surface;
   the first ``noise_fraction`` of the window is used).
2. **Matched filter**: a Gaussian of the system pulse's σ (the known system response),
   which maximises the SNR of a Gaussian return in white noise.
3. **Surface**: the first local maximum whose filtered amplitude exceeds ``threshold_sigma``
   noise σ, timed by a fit of a Gaussian echo on the water column's onset, an exponentially
   modified Gaussian decaying at the pulse's own measured column rate
   (:mod:`pipeline.process.surface_step`; the onset alone where the echo is not significant:
   calm water off nadir has no specular echo). **Bottom**: the strongest local maximum after
   ``surface + min_separation`` of the filtered waveform minus its running median over
   ``trend_fwhm`` system widths: the water-column return decays smoothly over tens of ns and
   the median follows it, while a bottom echo a few samples wide stands out of it. No peak
   above the threshold: no bottom. With ``bottom_pick = "last"`` the bottom is the strongest
   candidate within ``min_separation`` of the latest one instead. A candidate more than
   ``min_separation`` after the reported bottom sets MULTIPLE_BOTTOM_CANDIDATES.
4. **Sub-sample timing**: a parabola through the logarithm of the three samples around the peak
   (exact for a Gaussian peak).
5. **Shallow regime**: where the bottom is closer than ``min_separation`` the two returns merge
   into one peak. When the merged peak is measurably wider than the system pulse the pulse is
   flagged MERGED and a fit of surface echo (free width) + bottom echo + water-column onset
   (:mod:`pipeline.process.detect_merged`) separates them; the bottom is kept only if its fitted
   amplitude is significant (``threshold_sigma``) against its own standard deviation, so the
   column onset and a broadened surface echo are not taken for a bottom.
6. **In-column return** (``column_returns``): the strongest other candidate of step 3 that lies
   between ``surface + min_separation`` and ``bottom − min_separation`` (a scattering layer,
   a fish school, a thermocline): the same residual, the same signal-dependent threshold and the
   same sub-sample timing as the bottom, so noise alone makes one only as often as it makes a
   false bottom. With the default ``bottom_pick`` a layer echo stronger than a deeper bottom
   is reported as the bottom (flagged MULTIPLE_BOTTOM_CANDIDATES; the real bottom is lost).
7. **Confidence**: ``1 − exp(−(SNR / threshold)^4 / 2)``, 0.4 at the threshold and → 1 above it.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np
from scipy.ndimage import gaussian_filter1d

from pipeline.constants import FWHM_TO_SIGMA
from pipeline.process.detect_candidates import (
    bottom_candidates,
    first_strong_peak,
    local_variance,
    pick_bottom,
    row_abs_max,
    strongest_before,
)
from pipeline.process.detect_clipped import clipped_bottom, clipped_echoes
from pipeline.process.detect_merged import column_decay, fit_merged, merged_bottoms
from pipeline.process.detect_near import column_excess
from pipeline.process.detect_noise import difference_noise_sigma, window_baseline
from pipeline.process.detect_precision import echo_timing_sigma_samples
from pipeline.process.detect_settings import DetectSettings
from pipeline.process.detect_timing import parabolic_peak
from pipeline.process.flank_trend import flank_trend
from pipeline.process.returns import DetectorFlag
from pipeline.process.row_kernels import gaussian_rows, gaussian_weights
from pipeline.process.surface_echo_null import null_shifts
from pipeline.process.surface_step import ECHO_FIELDS, surface_step_fit

__all__ = [
    "DetectSettings",
    "WaveformDetections",
    "detect_full_waveform",
    "column_decay",
    "fit_merged",
    "flank_trend",
]


_SIG = ("t_surface_sigma_s", "t_bottom_sigma_s")


@dataclass(frozen=True)
class WaveformDetections:
    """Detected returns per waveform, shapes ``(n_pulses,)``.

    Times are from the start of each waveform's time axis (``t0_s``): round-trip times.
    Absent returns have their mask False and 0 in the other fields (never NaN; but
    ``surface_echo_null_shift_s``, NaN where not resampled). The in-column
    return (``has_column`` ...) is optional: left out (None), it is filled with "none found".
    ``t_no_bottom_s`` (a pulse without a bottom: the time down to which none is established, 0
    where unknown) is the photon detector's; the full-waveform one comes from
    :mod:`pipeline.process.no_bottom`. ``t_detection_limit_s`` (photon counting: the time of the
    window's detection limit, :mod:`pipeline.process.photon_limit`; 0 where none) is reported.
    ``t_*_sigma_s``: each return's timing sigma from its own waveform
    (:mod:`pipeline.process.detect_precision`; 0 if absent or not given).
    ``surface_echo_state`` (1 a clear surface echo on a column onset, 2 a clear echo without
    one (land, or a column too weak to tell: not counted in the share), −1 an ambiguous one
    whose time the survey mixes, 0 neither), ``t_surface_onset_s`` and
    ``surface_echo_shift_s`` (the onset alone's time and the echo-kept fit's minus it, where
    −1; else 0): ``t_surface_s`` there is
    ``t_surface_onset_s + w surface_echo_shift_s``, ``w`` from the block's share of clear
    echoes until the survey sets it from all of them
    (:func:`~pipeline.process.surface_echo_mix.echo_weight`). ``surface_echo_null_shift_s``:
    that shift on noise alone, for the pulses resampled
    (:func:`~pipeline.process.surface_echo_null.null_shifts`; NaN elsewhere).
    """

    has_surface: np.ndarray
    t_surface_s: np.ndarray
    surface_amplitude: np.ndarray
    surface_confidence: np.ndarray
    has_bottom: np.ndarray
    t_bottom_s: np.ndarray
    bottom_amplitude: np.ndarray
    bottom_confidence: np.ndarray
    noise_sigma: np.ndarray
    flags: np.ndarray
    has_column: np.ndarray | None = None
    t_column_s: np.ndarray | None = None
    column_amplitude: np.ndarray | None = None
    column_confidence: np.ndarray | None = None
    t_no_bottom_s: np.ndarray | None = None
    t_detection_limit_s: np.ndarray | None = None
    t_surface_sigma_s: np.ndarray | None = None
    t_bottom_sigma_s: np.ndarray | None = None
    surface_echo_state: np.ndarray | None = None
    t_surface_onset_s: np.ndarray | None = None
    surface_echo_shift_s: np.ndarray | None = None
    surface_echo_null_shift_s: np.ndarray | None = None

    def __post_init__(self) -> None:
        # detectors without column returns (photon counting) leave them out; concatenating
        # chunks needs arrays in every field
        n = np.shape(self.has_surface)[0]
        if self.has_column is None:
            object.__setattr__(self, "has_column", np.zeros(n, dtype=bool))
        for name in (
            "t_column_s",
            "column_amplitude",
            "column_confidence",
            "t_no_bottom_s",
            "t_detection_limit_s",
            *_SIG,
            *ECHO_FIELDS,
        ):
            if getattr(self, name) is None:
                object.__setattr__(self, name, np.zeros(n))
        if self.surface_echo_null_shift_s is None:  # none resampled (surface_echo_null)
            object.__setattr__(self, "surface_echo_null_shift_s", np.full(n, np.nan))


def _confidence(snr: np.ndarray, threshold: float) -> np.ndarray:
    return 1.0 - np.exp(-0.5 * (np.maximum(snr, 0.0) / threshold) ** 4)


#: Waveforms detected at once (bounds the float64 temporaries to a few tens of MB).
BLOCK_PULSES = 8192
#: Candidates up to this many FWHM past the minimum separation are tested against the column
#: carried back from below them (:mod:`pipeline.process.detect_near`): the surface +
#: column-onset hump (2.5 + 5 FWHM of 1.8 ns: 13.5 ns, ~1.5 m of water).
NEAR_SURFACE_FWHM = 5.0


def detect_full_waveform(
    samples: np.ndarray,
    dt_s: float,
    pulse_fwhm_s: float,
    settings: DetectSettings | None = None,
    noise_samples: int | None = None,
    shot_noise_counts: float = 0.0,
    top_code: float | None = None,
    pulse_id: np.ndarray | None = None,
) -> WaveformDetections:
    """Find the surface and bottom returns in a batch of waveforms.

    Parameters
    ----------
    samples : (n_pulses, n_samples) array_like
        Digitised waveforms (any linear unit), baseline included.
    dt_s : float
        Sample interval, seconds.
    pulse_fwhm_s : float
        FWHM of the system response (transmitted pulse ⊗ detector), seconds.
    settings : DetectSettings, optional
    noise_samples : int, optional
        Leading samples known to hold no return (the range gate's pre-trigger); they set the
        baseline. Default: ``settings.noise_fraction`` of the window.
    shot_noise_counts : float
        ``F·G``: excess-noise factor × counts per photoelectron. The variance of a sample
        holding ``y`` counts of signal is then ``σ² + F·G·y``, so the bottom threshold rises
        over the water-column return, whose shot noise would otherwise pass as echoes.
        0 (default): signal-independent noise.
    top_code : float, optional
        The digitiser's top code (``2^bits − 1``): a pulse with a sample there is flagged
        SATURATED and its clipped echo timed from the plateau's edges
        (:mod:`pipeline.process.detect_clipped`). None: samples are never clipped.
    pulse_id : (n_pulses,) int array_like, optional
        Pulse numbers: every ``settings.surface_echo_null_every``-th ambiguous surface echo is
        resampled on noise alone, keyed by its number (:mod:`pipeline.process.surface_echo_null`).
        None: none is.

    Returns
    -------
    WaveformDetections
        Times relative to the first sample.
    """
    s = settings or DetectSettings()
    samples = np.asarray(samples)
    ids = None if pulse_id is None else np.asarray(pulse_id, dtype=np.int64)
    if samples.shape[0] <= BLOCK_PULSES:
        return _detect_block(
            samples, dt_s, pulse_fwhm_s, s, noise_samples, shot_noise_counts, top_code, ids
        )
    blocks = [
        _detect_block(
            samples[i : i + BLOCK_PULSES],
            dt_s,
            pulse_fwhm_s,
            s,
            noise_samples,
            shot_noise_counts,
            top_code,
            None if ids is None else ids[i : i + BLOCK_PULSES],
        )
        for i in range(0, samples.shape[0], BLOCK_PULSES)
    ]
    return WaveformDetections(
        *(
            np.concatenate([getattr(b, f.name) for b in blocks])
            for f in dataclasses.fields(WaveformDetections)
        )
    )


def _detect_block(
    samples, dt_s, pulse_fwhm_s, s, noise_samples, shot_noise_counts, top_code, pulse_id=None
):
    """:func:`detect_full_waveform` on one block of waveforms."""
    y = np.asarray(samples, dtype=np.float64)
    n, m = y.shape
    sigma_samples = pulse_fwhm_s * FWHM_TO_SIGMA / dt_s
    k = int(s.noise_fraction * m) if noise_samples is None else int(noise_samples)
    k = min(max(k, 4), m - 1)
    # raw noise σ from first differences over the whole waveform (returns are a few samples
    # wide and clipped out; a clipped second moment, not quantised on integer codes as the MAD
    # is: :mod:`pipeline.process.detect_noise`), then through the filter's own discrete kernel
    noise = difference_noise_sigma(y)
    baseline, baseline_sigma = window_baseline(y, k, noise)
    # gaussian_filter1d(y - baseline, σ, axis=1, mode="nearest"), compiled (row_kernels)
    filt = gaussian_rows(y, baseline, gaussian_weights(float(sigma_samples)))
    impulse = np.zeros(int(8 * sigma_samples) * 2 + 3)
    impulse[impulse.size // 2] = 1.0
    kernel = gaussian_filter1d(impulse, sigma_samples, mode="constant")
    kernel_sq = float(np.sum(kernel**2))
    noise_f = noise * math.sqrt(kernel_sq)
    # a noise-free waveform still needs a finite threshold: a tiny fraction of its peak
    noise_f = np.maximum(noise_f, 1e-9 * row_abs_max(filt) + 1e-300)
    # the surface stands on the baseline, whose own error shifts every filtered sample alike
    # (~0.4 σ with a 15-sample pre-trigger): it adds to the threshold (bottoms are measured on
    # the residual to a local trend and do not see it)
    thr = s.threshold_sigma * np.sqrt(noise_f**2 + baseline_sigma**2)
    # the first peak above it, past the noise window (which holds no return by construction)
    has_s, i_s = first_strong_peak(filt, thr, k)
    t_idx_s, amp_s, width_s = parabolic_peak(filt, i_s)
    sep = s.min_separation_fwhm * pulse_fwhm_s / dt_s
    fwhm_samples = pulse_fwhm_s / dt_s
    gap = max(2, math.ceil(1.5 * fwhm_samples))
    t_echo_s = t_idx_s  # the start of the merged fit, which models the echo itself
    echo_state = t_onset_s = shift_s = np.zeros(n)
    null_s = np.full(n, np.nan)
    if s.surface_step:
        # the column's own decay, past the surface echo: the onset the surface sits on
        k_col = None
        if s.surface_onset_decay:
            k_col = column_decay(filt, i_s, start=math.ceil(sep) + gap, length=2 * math.ceil(sep))
        t_fit, parts = surface_step_fit(
            filt,
            i_s,
            math.sqrt(2.0) * sigma_samples,
            k_col,
            echo_sigma=s.surface_echo_sigma,
            prevalence_half=s.surface_echo_prevalence_half,
            with_parts=True,
        )
        t_idx_s = np.where(has_s, t_fit, t_idx_s)
        t_echo_s = np.where(has_s, parts.t_echo, t_echo_s)
        # the survey sets an ambiguous echo's weight from all its pulses (this block's share
        # of clear echoes stands in until then, run_survey): the two times and the state
        echo_state = np.select(
            [has_s & parts.on_column, has_s & parts.clear, has_s & parts.mixable],
            [1.0, 2.0, -1.0],
            0.0,
        )
        t_onset_s = parts.t_onset
        shift_s = parts.t_mix_echo - parts.t_onset
        if pulse_id is not None and s.surface_echo_null_every > 0:
            floor = np.std(y[:, :k], axis=1, ddof=1)  # the pre-trigger's: no column in it
            null_s = null_shifts(
                filt, i_s, k_col, sigma_samples, parts, floor, shot_noise_counts, pulse_id,
                s.surface_echo_null_every, s.surface_echo_sigma,
            )  # fmt: skip
    # a surface echo clipped at the top code: its filtered peak sits anywhere on the plateau;
    # the plateau's edges time it (one echo), or bound it (run on into the column: "merged")
    clip_s = clip_merged = np.zeros(n, dtype=bool)
    saturated = clip_s
    if top_code is not None:
        clip = clipped_echoes(y, top_code, baseline, noise, sigma_samples, s.max_plateau_fwhm)
        saturated = clip.saturated
        clip_s = saturated & has_s & (i_s >= clip.first - 1)
        clip_merged = clip_s & clip.merged
        t_idx_s = np.where(clip_s, clip.t_idx, t_idx_s)
        echo_state = np.where(clip_s, 0.0, echo_state)
        # the filtered peak of a Gaussian of σ through the matched filter: A / √2
        amp_s = np.where(clip_s, clip.amplitude / math.sqrt(2.0), amp_s)
        width_s = np.where(clip_s, math.sqrt(2.0) * sigma_samples, width_s)
        # the bottom is searched for past the plateau
        i_s = np.where(clip_s, clip.stop, i_s)

    resid = filt - flank_trend(
        filt, gap=gap, length=max(3, round(0.5 * s.trend_fwhm * fwhm_samples))
    )
    # after the surface, and not in the last samples, where the trend is one-sided and an echo
    # would be cut by the end of the window
    cols = np.arange(m)[None, :]
    # a surface echo wider than the system response (a footprint over waves or a slope) needs
    # the separation in proportion: its own tail is not a bottom
    widen = np.maximum(width_s / (math.sqrt(2.0) * sigma_samples), 1.0)
    # just below the surface the flank trend undershoots the hump of the surface echo and the
    # column onset (worst where the column is as bright as the surface echo, at low altitude):
    # a candidate there must also stand above the column carried back from below it (the test
    # is one-sided: it only removes candidates)
    zone = math.ceil(sep + NEAR_SURFACE_FWHM * fwhm_samples)
    i_zone = np.minimum(i_s + zone, m - 1)
    # residual peaks above the local noise: electronic + shot noise of the trend the bottom
    # sits on (filtered domain), compiled row by row (pipeline.process.detect_candidates)
    cand, near_any = bottom_candidates(
        filt, resid, noise_f, i_s + sep * widen, gap, has_s, shot_noise_counts, kernel_sq,
        s.threshold_sigma, i_zone,
    )  # fmt: skip
    # (only the pulses with such a candidate: the column carried back costs a log and an exp
    # per sample, and a pulse's test reads its own samples alone)
    r_near = np.flatnonzero(near_any)
    if r_near.size:
        width = 4 * gap
        f_near, nf_near = filt[r_near], noise_f[r_near]
        near = cand[r_near] & (cols <= i_zone[r_near, None])
        excess, column, carried = column_excess(f_near, 3.0 * nf_near, gap + math.ceil(sep), width)
        # the carried-back level is a mean of ~width/2 independent filtered samples, scaled
        # up by the decay it is carried back over: its noise adds to the candidate's own
        col_var = nf_near[:, None] ** 2 + shot_noise_counts * np.maximum(carried, 0.0) * kernel_sq
        var_near = local_variance(
            f_near, resid[r_near], nf_near[:, None], shot_noise_counts, kernel_sq
        )
        thr_near = s.threshold_sigma * np.sqrt(var_near + col_var * 2.0 / width)
        cand[r_near] &= ~(near & column & (excess <= thr_near))
    cand &= ~clip_merged[:, None]
    # the strongest candidate, with bottom_pick = "last" near the latest one (not the latest
    # itself: noise bumps on the trailing flank of a wide bottom echo would bias it late)
    has_b, i_b, beyond = pick_bottom(cand, resid, sep, s.bottom_pick == "last")
    t_idx_b, _, width_b = parabolic_peak(resid, i_b)
    if top_code is not None and saturated.any():
        # a bottom clipped on a plateau of its own: timed from its edges, or no bottom
        on_top, t_clip = clipped_bottom(y, top_code, i_b, baseline, noise, sigma_samples, s)
        t_idx_b = np.where(on_top & has_b & np.isfinite(t_clip), t_clip, t_idx_b)
        has_b &= ~(on_top & ~np.isfinite(t_clip))
    amp_b = resid[np.arange(n), i_b]
    # the local noise at each picked sample (the candidates' threshold's)
    var_at_b = local_variance(filt[np.arange(n), i_b], amp_b, noise_f, shot_noise_counts, kernel_sq)
    snr_b_local = amp_b / np.sqrt(var_at_b)

    flags = np.zeros(n, dtype=np.uint16)
    flags[saturated] |= np.uint16(DetectorFlag.SATURATED)
    flags[clip_merged] |= np.uint16(DetectorFlag.CLIPPED_MERGED)
    # another significant return clearly after the reported bottom: a layer or object above
    # the seabed may have been taken for it (bottom_pick = "last" reports the later one)
    later = has_b & beyond
    flags[later] |= np.uint16(DetectorFlag.MULTIPLE_BOTTOM_CANDIDATES)
    # a surface peak wider than the system response hides a bottom just below it
    # (the filtered system response has σ √2 samples; 15 % wider means a second return)
    merged = has_s & ~has_b & ~clip_s & (width_s > 1.15 * math.sqrt(2.0) * sigma_samples)
    flags[merged] |= np.uint16(DetectorFlag.MERGED)
    if s.fit_merged and merged.any():
        idx = np.flatnonzero(merged)
        good, ts, tb, a_s, a_b, snr_fit = merged_bottoms(
            filt[idx], i_s[idx], t_echo_s[idx], sigma_samples, sep, gap, kernel, noise_f[idx],
            shot_noise_counts, s.threshold_sigma,
        )  # fmt: skip
        sel = idx[good]
        echo_state = echo_state.copy()
        echo_state[sel] = 0.0  # the merged fit times these surfaces itself
        t_idx_s[sel], t_idx_b[sel], amp_s[sel], amp_b[sel] = (
            ts[good],
            tb[good],
            a_s[good],
            a_b[good],
        )
        snr_b_local[sel] = snr_fit[good]
        has_b[sel] = True
        width_s[sel] = width_b[sel] = math.sqrt(2.0) * sigma_samples  # two system echoes
    snr_s = amp_s / noise_f
    snr_b = np.where(has_b, snr_b_local, amp_b / noise_f)
    # each return's timing sigma from its amplitude, width and the raw noise under it
    sig_ts = echo_timing_sigma_samples(amp_s, width_s, sigma_samples, noise**2, shot_noise_counts)
    var_b = var_at_b / kernel_sq
    sig_tb = echo_timing_sigma_samples(amp_b, width_b, sigma_samples, var_b, shot_noise_counts)
    flags[has_s & (snr_s < 2 * s.threshold_sigma)] |= np.uint16(DetectorFlag.LOW_SNR)
    zero = np.zeros(n)
    rows = np.arange(n)
    if s.column_returns:
        # the other candidates, clear of the bottom as the bottom is clear of the surface
        # (a merged, fitted bottom leaves no room: its candidates list is empty)
        has_c, i_c = strongest_before(cand, resid, np.where(has_b, t_idx_b - sep, -np.inf))
        # timed on the filtered waveform's own peak (within 2 samples): a layer echo wider
        # than the trend's gap raises its own flank trend, which would pull a residual peak
        # early; the column's slope under it moves the filtered peak far less
        near = np.clip(i_c[:, None] + np.arange(-2, 3), 0, m - 1)
        i_f = near[rows, np.argmax(np.take_along_axis(filt, near, axis=1), axis=1)]
        t_idx_c, _, _ = parabolic_peak(filt, i_f)
        # (with a separation under 2 samples that peak could pass a neighbour: keep the order)
        has_c &= (t_idx_c > t_idx_s) & (t_idx_c < t_idx_b)
        amp_c = resid[rows, i_c]
        var_c = local_variance(filt[rows, i_c], amp_c, noise_f, shot_noise_counts, kernel_sq)
        snr_c = amp_c / np.sqrt(var_c)
    else:
        has_c, t_idx_c, amp_c, snr_c = np.zeros(n, dtype=bool), zero, zero, zero
    return WaveformDetections(
        has_surface=has_s,
        t_surface_s=np.where(has_s, t_idx_s * dt_s, zero),
        surface_amplitude=np.where(has_s, amp_s, zero),
        surface_confidence=np.where(has_s, _confidence(snr_s, s.threshold_sigma), zero),
        has_bottom=has_b,
        t_bottom_s=np.where(has_b, t_idx_b * dt_s, zero),
        bottom_amplitude=np.where(has_b, amp_b, zero),
        bottom_confidence=np.where(has_b, _confidence(snr_b, s.threshold_sigma), zero),
        noise_sigma=noise_f,
        flags=flags,
        has_column=has_c,
        t_column_s=np.where(has_c, t_idx_c * dt_s, zero),
        column_amplitude=np.where(has_c, amp_c, zero),
        column_confidence=np.where(has_c, _confidence(snr_c, s.threshold_sigma), zero),
        t_surface_sigma_s=np.where(has_s, sig_ts * dt_s, zero),
        t_bottom_sigma_s=np.where(has_b, sig_tb * dt_s, zero),
        surface_echo_state=echo_state,
        t_surface_onset_s=np.where(echo_state < 0, t_onset_s * dt_s, zero),
        surface_echo_shift_s=np.where(echo_state < 0, shift_s * dt_s, zero),
        surface_echo_null_shift_s=np.where(echo_state < 0, null_s * dt_s, np.nan),
    )
