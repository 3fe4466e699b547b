"""Per-pulse no-bottom limits of a full-waveform survey, chunk by chunk then once per survey.

:func:`chunk_inputs` keeps, of each chunk's waveforms (then dropped), what the class-45
detection limit needs (:mod:`pipeline.process.detection_limit`); :func:`excess_decay_summary`
fits the bottoms' extra decay once over the whole survey (on the bounded sample of
:class:`pipeline.detection_store.SurveyAggregates`), so the limits do not depend on the
chunking, and :func:`limit_times_s` then gives each chunk's ``t_no_bottom_s``.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from pipeline.optics import SPEED_OF_LIGHT_M_S
from pipeline.process.context import ProcessingContext
from pipeline.process.detect import DetectSettings
from pipeline.process.detection_limit import (
    ColumnMargins,
    DetectorModel,
    NoBottomSettings,
    bottom_losses,
    column_margins,
    excess_decay_per_s,
    limit_after_surface_s,
)
from pipeline.process.returns import DetectedReturns, DetectorFlag

__all__ = ["detector_model", "chunk_inputs", "excess_decay_summary", "limit_times_s"]


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
        (:func:`~pipeline.process.detection_limit.bottom_losses`).
    """
    det = detector_model(ctx, detect)
    n = found.has_surface.shape[0]
    # a saturated pulse's column is clipped or follows a clipped surface: its decay, and so
    # the depth a bottom would have shown down to, is not measured
    saturated = (found.flags & np.uint16(DetectorFlag.SATURATED)) != 0
    none = found.has_surface & ~found.has_bottom & ~saturated
    margin, alpha, t_max = np.zeros(n), np.ones(n), np.zeros(n)
    ok = np.zeros(n, dtype=bool)
    if none.any():
        cm = column_margins(
            samples[none], found.t_surface_s[none], found.noise_sigma[none], det, settings
        )
        margin[none], alpha[none], t_max[none], ok[none] = (
            cm.log_margin,
            cm.alpha_per_s,
            cm.t_max_s,
            cm.ok,
        )
    # a bottom near the threshold is found only where it happened to be bright: its loss would
    # bias the extra decay low, so only clear detections are used
    strong = (
        found.has_bottom
        & ~saturated
        & (found.bottom_amplitude >= 2.0 * detect.threshold_sigma * found.noise_sigma)
    )
    t_b, loss, ok_b = bottom_losses(
        samples[strong],
        found.t_surface_s[strong],
        found.t_bottom_s[strong],
        found.bottom_amplitude[strong],
        found.noise_sigma[strong],
        det,
        settings,
    )
    return {
        "none": none,
        "margin": margin,
        "alpha": alpha,
        "t_max": t_max,
        "ok": ok,
        "t_b": t_b[ok_b],
        "loss": loss[ok_b],
        # the chunk rows of those bottoms (the survey-wide sample is by pulse)
        "b_row": np.flatnonzero(strong)[ok_b],
    }


def excess_decay_summary(
    t_b: np.ndarray,
    loss: np.ndarray,
    alpha_ok: np.ndarray,
    counts: dict[str, int],
    ctx: ProcessingContext,
    detect: DetectSettings,
) -> tuple[float, dict[str, Any]]:
    """The bottoms' extra decay ``δ`` (1/s) fitted once per survey, and the survey's summary.

    Parameters
    ----------
    t_b, loss : (m,) float
        :func:`chunk_inputs`' bottom times after the surface and log losses (of every chunk,
        or of a bounded sample of the pulses, :class:`pipeline.detection_store.
        SurveyAggregates`), in pulse order.
    alpha_ok : (k,) float
        The measured column decays (1/s) of the pulses whose column was measured (same sample).
    counts : dict
        ``bottoms`` and ``no_column`` counted over every pulse.

    Returns
    -------
    delta : float
    summary : dict
        Without ``pulses_with_limit`` (counted by :func:`limit_times_s` chunk by chunk).
    """
    delta = excess_decay_per_s(t_b, loss)
    g = ctx.refraction.group_index
    summary = {
        "excess_decay_per_m": delta * 2.0 * g / SPEED_OF_LIGHT_M_S,
        "bottoms_used": int(t_b.size),
        "pulses_with_limit": 0,
        "pulses_without_measurable_column": int(counts["no_column"]),
        # the lidar attenuation k of the measured columns: C ~ exp(-2 k L), L = c t / (2 n_g)
        "column_decay_per_m": (
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
) -> np.ndarray:
    """``t_no_bottom_s`` from emission of one chunk's pulses (0 where none).

    Parameters
    ----------
    inputs : dict
        :func:`chunk_inputs` of the chunk.
    t_surface_s : (n_pulses,) float
        The chunk's surface times from emission.
    delta_per_s : float
        The survey's :func:`excess_decay_summary`.
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
    return np.where(t > 0.0, t_surface_s + t, 0.0)
