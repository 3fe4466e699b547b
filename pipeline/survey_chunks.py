"""One chunk of the survey: its pulses simulated (survey, trace, receiver) and detected.

:func:`run_chunk` is a pure function of ``(ChunkJob, chunk index)``: the pulses of chunk ``c``
and every random draw are functions of the global pulse ids and the scene seed (see
:mod:`pipeline.simulate.noise`), so the chunks can run in any order, in any process (see
:mod:`pipeline.parallel`), and their concatenation does not depend on the chunk size. Of each
chunk only what a real system records leaves the function: the measured navigation and the
detections (plus the few waveforms kept for posteriors and the no-bottom inputs).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

import numpy as np

from pipeline.constants import FWHM_TO_SIGMA
from pipeline.detection_store import DetectionStore, SurveyAggregates
from pipeline.process.context import ProcessingContext
from pipeline.stages import StageClock
from pipeline.uncertainty.photon_posterior import KeptPhotons, keep_windows
from pipeline.uncertainty.posterior_selection import KeptWaveforms, kept_for_posterior

__all__ = ["NB_FIELDS", "ChunkJob", "ChunkResult", "no_bottom_limits", "run_chunk"]


@dataclass(frozen=True)
class ChunkJob:
    """What every chunk shares (sent once to each worker).

    Attributes
    ----------
    scene : Scene
    ctx : ProcessingContext
    world : pipeline.simulate.trace.World
        Water-surface and seabed meshes.
    lines : FlightLines
    chunk_pulses : int
        Pulses per chunk (the last one may be shorter).
    keep_fraction : float
        Share of pulses whose waveforms are kept for posteriors (photon counting: share of the
        accumulation windows whose events are kept).
    waveform : bool
        Full-waveform receiver (else photon counting).
    no_bottom : bool
        Whether the no-bottom-limit stage runs (its per-chunk inputs are collected).
    """

    scene: Any
    ctx: ProcessingContext
    world: Any
    lines: Any
    chunk_pulses: int
    keep_fraction: float
    waveform: bool
    no_bottom: bool


@dataclass(frozen=True)
class ChunkResult:
    """What one chunk leaves.

    Attributes
    ----------
    part : dict of str to ndarray
        Measured navigation and detections, ``(n,)`` or ``(n, 3)`` per field.
    kept : KeptWaveforms or KeptPhotons or None
        Full waveform: the waveforms kept; photon counting: the kept windows' events.
    nb : dict or None
        No-bottom-limit inputs of the chunk.
    subray_flags, pulse_flags : dict of str to int
    stages : dict of str to dict
        Per stage, its seconds on this chunk and its memory peak in the process that ran it
        (:meth:`pipeline.stages.StageClock.to_dict`).
    """

    part: dict[str, np.ndarray]
    kept: KeptWaveforms | KeptPhotons | None
    nb: dict[str, np.ndarray] | None
    subray_flags: dict[str, int]
    pulse_flags: dict[str, int]
    stages: dict[str, dict[str, float]]

    @property
    def n_pulses(self) -> int:
        """Pulses of the chunk."""
        return len(self.part["pulse_id"])


def run_chunk(job: ChunkJob, c: int) -> ChunkResult:
    """Simulate and detect chunk ``c`` of the survey (a pure function of ``job`` and ``c``)."""
    from pipeline.simulate import paths as P
    from pipeline.simulate import survey
    from pipeline.simulate.detector import describe_pulse_flags
    from pipeline.simulate.trace import trace
    from pipeline.simulate.trace_settings import resolved_trace_settings
    from pipeline.worker_malloc import for_chunk_task

    for_chunk_task()  # a chunk's arrays reused from the heap, not mapped afresh
    scene, clock = job.scene, StageClock()
    with clock.stage("survey"):
        pulses = survey.generate_pulses(
            scene.flight,
            scene.attitude,
            scene.navigation,
            scene.scanner,
            job.lines,
            c,
            job.chunk_pulses,
            scene.scene.seed,
        )
    with clock.stage("trace"):
        div_rad = scene.scanner.beam_divergence_mrad * 1e-3
        # the scene's trace settings with the sub-rays a wave surface needs (a user's value wins)
        paths = trace(
            pulses, job.world, resolved_trace_settings(scene), div_rad, scene.scanner.polarisation
        )
    kept = nb = None
    pulse_flags: dict[str, int] = {}
    if job.waveform:
        found, kept, nb = _waveform_chunk(job, clock, paths)
    else:
        found, flags, kept = _photon_chunk(job, clock, paths, pulses)
        pulse_flags = describe_pulse_flags(flags)
    part = {
        "pulse_id": pulses.pulse_id,
        "origin_meas_m": pulses.origin_meas_m,
        "direction_meas": pulses.direction_meas,
        "t_emit_s": pulses.t_s,  # the shot's timestamp and flight line, as recorded
        "line_id": pulses.line_id,
        **{f.name: getattr(found, f.name) for f in dataclasses.fields(found)},
    }
    if not job.waveform:  # the photon detector gives no per-return timing sigma
        del part["t_surface_sigma_s"], part["t_bottom_sigma_s"]
    return ChunkResult(
        part=part,
        kept=kept,
        nb=nb,
        subray_flags=P.describe_flags(paths.flags),
        pulse_flags=pulse_flags,
        stages=clock.to_dict(),
    )


def _waveform_chunk(job: ChunkJob, clock: StageClock, paths):
    """Digitise one chunk, detect its returns, keep what the later stages need of it."""
    from pipeline.process.detect import detect_full_waveform
    from pipeline.simulate.waveform import simulate_waveforms

    scene, ctx = job.scene, job.ctx
    ins, ps = ctx.instrument, scene.process
    with clock.stage("receiver_waveform"):
        wf = simulate_waveforms(paths, scene, scene.detector, scene.returns)
    with clock.stage("detect_waveform"):
        found = detect_full_waveform(
            wf.samples,
            wf.sample_interval_s,
            ins.system_fwhm_s,
            ps.detect,
            noise_samples=ins.noise_samples,
            shot_noise_counts=ins.shot_noise_counts,
            # the digitiser's top code, 2^bit_depth − 1 (its datasheet)
            top_code=ins.amplitude_full_scale - 1.0,
            # the weak-echo test's resampled pulses and their noise keys (surface_echo_null)
            pulse_id=wf.pulse_id,
        )
    nb = None
    if job.no_bottom:
        from pipeline.process.no_bottom import chunk_inputs

        with clock.stage("no_bottom_limit"):  # times from sample 0, as the waveforms have them
            nb = chunk_inputs(wf.samples, found, ctx, ps.detect, ps.no_bottom)
    kept = None
    keep = kept_for_posterior(wf.pulse_id, job.keep_fraction, scene.scene.seed)
    if keep.any():
        kept = KeptWaveforms(wf.pulse_id[keep], wf.t0_s[keep], wf.samples[keep])
    # detection times are from sample 0; sample 0 is t0_s after emission
    found = dataclasses.replace(
        found,
        t_surface_s=found.t_surface_s + np.where(found.has_surface, wf.t0_s, 0.0),
        t_bottom_s=found.t_bottom_s + np.where(found.has_bottom, wf.t0_s, 0.0),
        t_column_s=found.t_column_s + np.where(found.has_column, wf.t0_s, 0.0),
        t_surface_onset_s=found.t_surface_onset_s
        + np.where(found.surface_echo_state < 0, wf.t0_s, 0.0),
    )
    return found, kept, nb


def _photon_chunk(job: ChunkJob, clock: StageClock, paths, pulses):
    """Photon events of one chunk, their window detections, flags and the windows kept."""
    from pipeline.process.detect_photons import detect_photon_events
    from pipeline.simulate.waveform import simulate_photon_events

    scene = job.scene
    with clock.stage("receiver_photon"):
        ev = simulate_photon_events(paths, scene, scene.detector, scene.returns)
    with clock.stage("detect_photon"):
        found = detect_photon_events(
            ev.offsets,
            ev.times_s,
            pulses.origin_meas_m,
            pulses.direction_meas,
            job.ctx.instrument.air_index,
            scene.process.photon_detect,
            pulse_id=pulses.pulse_id,
            # the detector's channels per beam (its datasheet): one event each per dead time
            n_channels=scene.detector.n_channels,
            # and its dead time (the datasheet's): the live-time correction of the histograms
            dead_time_s=scene.detector.dead_time_s,
            # the detection limit's assumptions (class 45), as the full-waveform one's
            no_bottom=scene.process.no_bottom,
            group_index=job.ctx.refraction.group_index,
            # the system response processing assumes (pulse and detector): the surface's pulse
            pulse_sigma_s=job.ctx.instrument.system_fwhm_s * FWHM_TO_SIGMA,
            # the survey's windows: consecutive shots, or cells of a scan
            windows=job.ctx.instrument.windows,
        )
    kept = keep_windows(
        pulses.pulse_id,
        ev.offsets,
        ev.times_s,
        pulses.origin_meas_m,
        pulses.direction_meas,
        job.ctx.instrument.air_index,
        job.ctx.instrument.windows,
        scene.detector.dead_time_s,
        job.keep_fraction,
        scene.scene.seed,
        detections=found,  # a scan's cells: their events as the detector's second pass saw them
        settings=scene.process.photon_detect,
    )
    return found, ev.flags, kept


#: :func:`~pipeline.process.no_bottom.chunk_inputs`' per-pulse fields, stored with the chunk
NB_FIELDS = (
    *("none", "margin", "alpha", "t_max", "ok", "level"),
    *("level_t_first", "level_count", "level_bins", "level_noise"),
)


def no_bottom_limits(store: DetectionStore, agg: SurveyAggregates, ctx, detect, settings) -> dict:
    """Fit the bottoms' extra decay once, then set every stored chunk's ``t_no_bottom_s``."""
    from pipeline.process.no_bottom import excess_decay_summary, limit_times_s

    args = (agg.nb_stack, agg.nb_counts, ctx, detect, agg.nb_stack_open, settings)
    delta, summary = excess_decay_summary(*agg.no_bottom_sample(), *args)
    n_limit = n_level = 0
    decay_k = summary["column_decay_per_m"]
    for c in range(len(store.chunks)):
        d = store.load_chunk(c, ["t_surface_s", *(f"nb_{k}" for k in NB_FIELDS)])
        inputs = {k: d[f"nb_{k}"] for k in NB_FIELDS}
        t, lv = limit_times_s(inputs, d["t_surface_s"], delta, ctx, detect, decay_k, settings)
        n_limit += int(np.count_nonzero(t > 0.0))
        n_level += int(np.count_nonzero(lv))
        store.replace_field(c, "t_no_bottom_s", t)
    for k in NB_FIELDS:
        store.drop_field(f"nb_{k}")
    summary["pulses_with_limit"] = n_limit
    # of which at the survey's decay (pipeline.process.column_level)
    summary["limits_from_survey_decay"] = n_level
    return summary
