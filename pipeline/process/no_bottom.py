"""Per-pulse no-bottom limits of a full-waveform survey, chunk by chunk then once per survey.

:func:`chunk_inputs` keeps, of each chunk's waveforms (then dropped), what the class-45
detection limit needs (:mod:`pipeline.process.detection_limit`); :func:`excess_decay_summary`
fits the bottoms' extra decay once over the whole survey (on the bounded sample of
:class:`pipeline.detection_store.SurveyAggregates`), so the limits do not depend on the
chunking, and :func:`limit_times_s` then gives each chunk's ``t_no_bottom_s``.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from pipeline.optics import SPEED_OF_LIGHT_M_S
from pipeline.process.classify import BATHYMETRIC_POINT, NO_BOTTOM_FOUND_AT
from pipeline.process.column_level import ColumnBins, level_limit_s
from pipeline.process.column_stack import ColumnStack, stack_column, stacked_decay_per_m
from pipeline.process.context import ProcessingContext
from pipeline.process.detect import DetectSettings
from pipeline.process.detection_limit import (
    ColumnMargins,
    DetectorModel,
    NoBottomSettings,
    bottom_losses,
    column_first_s,
    column_margins,
    limit_after_surface_s,
)
from pipeline.process.extinction import extinction_depth
from pipeline.process.returns import DetectedReturns, DetectorFlag, Points
from pipeline.process.truncated_regression import truncated_line_fit

__all__ = [
    "detector_model",
    "chunk_inputs",
    "excess_decay_per_s",
    "excess_decay_summary",
    "limit_times_s",
    "extinction_depth_summary",
]


def detector_model(ctx: ProcessingContext, detect: DetectSettings) -> DetectorModel:
    """The full-waveform detector as the class-45 limit needs it."""
    ins = ctx.instrument
    return DetectorModel(
        dt_s=ins.sample_interval_s,
        pulse_fwhm_s=ins.system_fwhm_s,
        noise_samples=ins.noise_samples,
        threshold_sigma=detect.threshold_sigma,
        min_separation_fwhm=detect.min_separation_fwhm,
        group_index=ctx.refraction.group_index,
        shot_noise_counts=ins.shot_noise_counts,
    )


def chunk_inputs(
    samples: np.ndarray,
    found: DetectedReturns,
    ctx: ProcessingContext,
    detect: DetectSettings,
    settings: NoBottomSettings,
) -> dict[str, np.ndarray]:
    """What the limit needs of one chunk's waveforms.

    Parameters
    ----------
    samples : (n_pulses, n_samples) array
        The chunk's waveforms.
    found : DetectedReturns
        Their detections, times from sample 0.
    ctx, detect, settings
        Processing context, detector and no-bottom settings.

    Returns
    -------
    dict
        The column margins of the pulses with a surface, no bottom and no saturation
        (:func:`~pipeline.process.detection_limit.column_margins`; zeros elsewhere) and the
        losses of the well-detected bottoms, SNR ≥ 2 × threshold
        (:func:`~pipeline.process.detection_limit.bottom_losses`); ``column_stack`` and
        ``column_stack_open``, the :class:`~pipeline.process.column_stack.ColumnStack` of the
        columns that end before an echo (the well-detected bottoms', and those above an
        in-column echo) and of those that run to the searched end (no echo found), added over
        the chunks, not concatenated.
    """
    det = detector_model(ctx, detect)
    n = found.has_surface.shape[0]
    m = samples.shape[1]
    first, clip_idx = _column_starts(samples, found, det, ctx)
    whole = clip_idx >= m  # no sample clipped from the column's start on
    none = found.has_surface & ~found.has_bottom & whole
    margin, alpha, t_max, alpha_fit = np.zeros(n), np.ones(n), np.zeros(n), np.ones(n)
    ok = np.zeros(n, dtype=bool)
    cm = column_margins(
        samples[none],
        found.t_surface_s[none],
        found.noise_sigma[none],
        det,
        settings,
        first_s=first[none],
        keep_bins=True,
    )
    # the columns whose level the survey's decay will read (pipeline.process.column_level):
    # not those with an echo, found in the column or seen rising in it, which would be read
    # as column, nor those behind a clipped surface echo, whose tail is known only by its
    # Gaussian model: a bright echo off a shore is wider, and its tail, read as column over
    # hundreds of samples, claimed no bottom metres under land (suite tuning seed 33: 23 of
    # its 50 claims more than 0.5 m under the seabed, against 13 of its 4 613 that hold)
    saturated = (found.flags & np.uint16(DetectorFlag.SATURATED)) != 0
    level = none & ~found.has_column & ~saturated
    level[none] &= ~cm.rises
    lv = level[none]
    if none.any():
        margin[none], alpha[none], t_max[none], ok[none], alpha_fit[none] = (
            cm.log_margin,
            cm.alpha_per_s,
            cm.t_max_s,
            cm.ok,
            cm.alpha_fit_per_s,
        )
    # a bottom near the threshold is found only where it happened to be bright: only clear
    # detections are used, and the fit of their losses takes that selection into account
    min_amp = 2.0 * detect.threshold_sigma * found.noise_sigma
    bright = found.has_bottom & (found.bottom_amplitude >= min_amp)
    strong = bright & whole  # (a clipped bottom's peak is not its amplitude)
    t_b, loss, ok_b = bottom_losses(
        samples[strong],
        found.t_surface_s[strong],
        found.t_bottom_s[strong],
        found.bottom_amplitude[strong],
        found.noise_sigma[strong],
        det,
        settings,
        first_s=first[strong],
    )
    # the stacked column (the survey's water decay, pipeline.process.column_stack) of the same
    # pulses, each up to its own end: the searched end, or one separation before its bottom or
    # in-column echo (no echo enters the stack)
    sep_s = det.min_separation_fwhm * det.pulse_fwhm_s
    searched_end_s = (m - max(2, math.ceil(1.5 * det.pulse_fwhm_s / det.dt_s))) * det.dt_s
    t_end = np.where(bright, found.t_bottom_s - sep_s, searched_end_s)
    t_end = np.where(found.has_column, np.minimum(t_end, found.t_column_s - sep_s), t_end)
    # two stacks: a column that ends before an echo is water all along; one that runs to the
    # searched end also runs past the seabed of a pulse whose bottom was too faint to be found,
    # where the column stops, and a stack of such cliffs falls faster than the water decays
    # (pipeline.process.column_stack). A column stacked up to a clipped bottom is whole.
    closed = (bright & (clip_idx >= t_end / det.dt_s)) | (none & found.has_column)
    open_ = none & ~found.has_column

    def stack_of(rows):
        return stack_column(samples[rows], found.t_surface_s[rows], t_end[rows], det, first[rows])

    return {
        "column_stack": stack_of(closed),
        "column_stack_open": stack_of(open_),
        "none": none,
        "margin": margin,
        "alpha": alpha,
        "t_max": t_max,
        "ok": ok,
        "alpha_fit": alpha_fit,
        "level": level,
        # per pulse of ``level``, in order: its binned column and filtered noise
        "level_t_first": cm.bins.t_first_s[lv],
        "level_count": cm.bins.count[lv],
        "level_bins": cm.bins.sums[lv],
        "level_noise": found.noise_sigma[level],
        "t_b": t_b[ok_b],
        "loss": loss[ok_b],
        # each loss's floor: the selection above in the loss's units (a bottom enters only
        # with a peak >= 2 k sigma_f: ln(2 k sigma_f / A_b) below its own loss), the
        # truncation the extra decay's fit undoes (pipeline.process.truncated_regression)
        "floor": (
            loss
            + np.log(
                np.maximum(min_amp[strong], 1e-300)
                / np.maximum(found.bottom_amplitude[strong], 1e-300)
            )
        )[ok_b],
        # the chunk rows of those bottoms (the survey-wide sample is by pulse)
        "b_row": np.flatnonzero(strong)[ok_b],
    }


def _column_starts(samples, found, det, ctx) -> tuple[np.ndarray, np.ndarray]:
    """Each pulse's first column time, and its first clipped sample from there on.

    A saturated pulse's surface echo, if clipped, hides the column under its tail: the column
    is read from past it (:func:`~pipeline.process.detection_limit.column_first_s`, the echo's
    amplitude from its plateau's edges). What is clipped from there on (the column itself, or
    a bright bottom) is not read; nothing is where the plateau runs on into the column
    (``CLIPPED_MERGED``).

    Returns
    -------
    first_s : (n,) float
        Seconds from the first sample.
    clip_idx : (n,) float
        Index of the first clipped sample at or after ``first_s`` (``m``: none; 0: the
        column cannot be read at all).
    """
    flags = found.flags
    n, m = samples.shape
    first = column_first_s(found.t_surface_s, found.surface_amplitude, det)
    clip_idx = np.full(n, float(m))
    merged = (flags & np.uint16(DetectorFlag.CLIPPED_MERGED)) != 0
    clip_idx[merged] = 0.0
    rows = np.flatnonzero(((flags & np.uint16(DetectorFlag.SATURATED)) != 0) & ~merged)
    if rows.size:
        top = ctx.instrument.amplitude_full_scale - 1.0  # the digitiser's top code
        y = np.asarray(samples[rows], dtype=np.float64)
        k = min(max(int(det.noise_samples), 4), max(m - 1, 1))
        base = np.median(y[:, :k], axis=1)  # as the filtered column's baseline
        f = column_first_s(found.t_surface_s[rows], found.surface_amplitude[rows], det, top - base)
        clipped = (y >= top) & (np.arange(m)[None, :] >= np.ceil(f / det.dt_s)[:, None])
        first[rows] = f
        clip_idx[rows] = np.where(clipped.any(axis=1), np.argmax(clipped, axis=1), m)
    return first, clip_idx


#: Bottoms the extra decay needs at least.
MIN_BOTTOMS = 20


def _fittable(t_after_surface_s: np.ndarray) -> bool:
    """Enough bottoms (:data:`MIN_BOTTOMS`), at more than one time, to fit ``δ``'s line."""
    t = np.asarray(t_after_surface_s)
    return t.size >= MIN_BOTTOMS and np.ptp(t) > 0.0


def excess_decay_per_s(
    t_after_surface_s: np.ndarray, log_loss: np.ndarray, floor: np.ndarray | None = None
) -> float:
    """``δ``: minus the slope of ``log_loss`` on time (≥ 0; 0 with < 20 bottoms).

    ``floor`` (the losses' selection floors): the slope of the truncated-normal line
    (:func:`~pipeline.process.truncated_regression.truncated_line_fit`); None: least squares.
    """
    t = np.asarray(t_after_surface_s, dtype=np.float64)
    y = np.asarray(log_loss, dtype=np.float64)
    if not _fittable(t):
        return 0.0
    if floor is None:
        slope = np.polyfit(t, y, 1)[0]
    else:
        slope = truncated_line_fit(t, y, floor)[1]
    return float(max(-slope, 0.0))


def excess_decay_summary(
    t_b: np.ndarray,
    loss: np.ndarray,
    floor: np.ndarray,
    alpha_ok: np.ndarray,
    stack: ColumnStack | None,
    counts: dict[str, int],
    ctx: ProcessingContext,
    detect: DetectSettings,
    open_stack: ColumnStack | None = None,
    settings: NoBottomSettings | None = None,
) -> tuple[float, dict[str, Any]]:
    """The bottoms' extra decay ``δ`` (1/s) fitted once per survey, and the survey's summary.

    Parameters
    ----------
    t_b, loss, floor : (m,) float
        :func:`chunk_inputs`' bottom times after the surface, log losses and the floors the
        losses were selected above (of every chunk, or of a bounded sample of the pulses,
        :class:`pipeline.detection_store.SurveyAggregates`), in pulse order.
    alpha_ok : (k,) float
        The measured column decays (1/s) of the pulses whose column was measured (same sample).
    stack, open_stack : ColumnStack or None
        The stacked columns of every chunk (:func:`chunk_inputs`' ``column_stack`` and
        ``column_stack_open``, added); None: no chunk. The decay is the closed columns' (water
        down to an echo), else, where they show none, the open columns'.
    counts : dict
        ``bottoms`` and ``no_column`` counted over every pulse.
    settings : NoBottomSettings, optional
        Its ``default_excess_decay_per_m`` is ``δ`` where fewer than :data:`MIN_BOTTOMS`
        bottoms enter the fit (or they all lie at one time).

    Returns
    -------
    delta : float
    summary : dict
        Without ``pulses_with_limit`` (counted by :func:`limit_times_s` chunk by chunk).
        ``excess_decay_from``: ``"fit"`` (the survey's bottoms) or ``"default"``.
        ``column_decay_per_m`` is the lidar decay of the survey's stacked column
        (:func:`~pipeline.process.column_stack.stacked_decay_per_m`, None without a measurable
        column) and ``column_decay_from`` which stack gave it (``closed``, ``open`` or None);
        ``column_decay_median_fit_per_m`` the median of the per-pulse fits (biased
        high in clear water; kept for the record). The limits use the per-pulse fits and,
        where the stack gives one, ``column_decay_per_m`` (:func:`limit_times_s`).
    """
    det = detector_model(ctx, detect)
    g = det.group_index
    fitted = _fittable(t_b)
    if fitted:
        delta = excess_decay_per_s(t_b, loss, floor)
    else:  # nothing to fit: the stated default, not the weakest fading (0)
        per_m = (settings or NoBottomSettings()).default_excess_decay_per_m
        delta = per_m * SPEED_OF_LIGHT_M_S / (2.0 * g)
    # closed columns first: an open one may run past a seabed whose echo was too faint to be
    # found, where it stops (shoal tuning seed 7003, c 0.73 /m, a plane 0-4.9 m deep: 21 500
    # open columns ended there and fell at 0.74 /m against the water's 0.21 /m; c through
    # Gordon's bridge 3.5 /m, the soundings 5-9 cm shallow from 2 m down)
    k, source = None, None
    for name, st in (("closed", stack), ("open", open_stack)):
        k = stacked_decay_per_m(ColumnStack.empty(det.dt_s) if st is None else st, g)
        if k is not None:
            source = name
            break
    summary = {
        "excess_decay_per_m": delta * 2.0 * g / SPEED_OF_LIGHT_M_S,
        "excess_decay_from": "fit" if fitted else "default",
        "bottoms_used": int(t_b.size),
        "pulses_with_limit": 0,
        "pulses_without_measurable_column": int(counts["no_column"]),
        # the lidar attenuation k of the measured columns: C ~ exp(-2 k L), L = c t / (2 n_g),
        # from their stack (the per-pulse fits are biased high in clear water, where a pulse's
        # column is a few noise-selected samples: pipeline.process.column_stack)
        "column_decay_per_m": k,
        "column_decay_from": source,
        # the median of the per-pulse fits, for the record
        "column_decay_median_fit_per_m": (
            float(np.median(alpha_ok)) * g / SPEED_OF_LIGHT_M_S if alpha_ok.size else None
        ),
    }
    return delta, summary


def limit_times_s(
    inputs: dict[str, np.ndarray],
    t_surface_s: np.ndarray,
    delta_per_s: float,
    ctx: ProcessingContext,
    detect: DetectSettings,
    column_decay_per_m: float | None = None,
    settings: NoBottomSettings | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """``t_no_bottom_s`` from emission of one chunk's pulses (0 where none).

    Each pulse's limit from its own column fit (:func:`~pipeline.process.detection_limit.
    column_margins`) and, where the survey's stack measured the water's decay, from its
    column's level at that decay (:func:`~pipeline.process.column_level.level_limit_s`): the
    shallower where both hold, else the one that does.

    Parameters
    ----------
    inputs : dict
        :func:`chunk_inputs` of the chunk.
    t_surface_s : (n_pulses,) float
        The chunk's surface times from emission.
    delta_per_s : float
        The survey's :func:`excess_decay_summary`.
    column_decay_per_m : float, optional
        The survey's stacked column decay ``k`` (its summary's ``column_decay_per_m``); None:
        the pulses' own fits alone.

    Returns
    -------
    t_no_bottom_s : (n_pulses,) float
    from_level : (n_pulses,) bool
        The limit is the level's (the pulse's own fit gave none, or a deeper one).
    """
    det = detector_model(ctx, detect)
    margins = ColumnMargins(
        log_margin=inputs["margin"],
        alpha_per_s=inputs["alpha"],
        t_max_s=inputs["t_max"],
        ok=inputs["ok"],
        t_min_s=det.min_separation_fwhm * det.pulse_fwhm_s,
    )
    t = limit_after_surface_s(margins, delta_per_s)
    from_level = np.zeros(t.shape, dtype=bool)
    rows = np.flatnonzero(inputs["level"])
    if column_decay_per_m is not None and rows.size:
        bins = ColumnBins(inputs["level_t_first"], inputs["level_count"], inputs["level_bins"])
        alpha = column_decay_per_m * SPEED_OF_LIGHT_M_S / det.group_index
        t_lv, _ = level_limit_s(
            bins, inputs["level_noise"], inputs["t_max"][rows], alpha, delta_per_s, det, settings
        )
        own = t[rows]
        take = (t_lv > 0.0) & ((own <= 0.0) | (t_lv < own))
        t[rows[take]] = t_lv[take]
        from_level[rows[take]] = True
    return np.where(t > 0.0, t_surface_s + t, 0.0), from_level


def extinction_depth_summary(points: Points) -> dict[str, Any]:
    """The depths of the survey's class-45 points: how deep it could establish the seabed.

    Each class-45 point stands at its pulse's detection limit (full waveform:
    :mod:`pipeline.process.detection_limit`; photon counting: the window's limit), so, where
    the survey lost the bottom in deep or turbid water, their median is its measured
    extinction depth. Over a shore, pulses whose bottom merged with the surface also give
    shallow class-45 points and pull their median up (tuning seed 54 of the suite: 4.2 m in
    c = 0.064 /m water, its 95th percentile 60 m); the extinction depth reported keeps only the
    limits at least as deep as 95 % of the soundings (:mod:`pipeline.process.extinction`).

    Returns
    -------
    dict
        ``class45_points`` and the 5th, 50th and 95th percentiles of their depths below the
        local surface, ``class45_depth_m_p05``, ``class45_depth_m_median``,
        ``class45_depth_m_p95`` (None without class-45 points); ``seabed_found_to_m``,
        ``extinction_depth_m`` (None: not reached) and ``extinction_depth_source``
        (:func:`pipeline.process.extinction.extinction_depth`: the class-45 limits at least as
        deep as 95 % of the soundings).
    """
    d = points.depth_m[points.classification == NO_BOTTOM_FOUND_AT]
    d = d[np.isfinite(d)]
    q = np.percentile(d, [5.0, 50.0, 95.0]).tolist() if d.size else [None] * 3
    keys = ("class45_depth_m_p05", "class45_depth_m_median", "class45_depth_m_p95")
    ext, src, found = extinction_depth(
        d, points.depth_m[points.classification == BATHYMETRIC_POINT]
    )
    return {
        "class45_points": int(d.size),
        **dict(zip(keys, q, strict=True)),
        "seabed_found_to_m": found,
        "extinction_depth_m": ext,
        "extinction_depth_source": src,
    }
