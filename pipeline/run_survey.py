"""Orchestration of a survey scene: the plan's survey stages, wired and timed, nothing else.

Simulation (terrain → survey → trace → receiver) runs in chunks of ``run.chunk_pulses`` pulses
(:mod:`pipeline.survey_chunks`), here or on workers (:mod:`pipeline.parallel`); of each chunk
only what a real system records is kept: the measured navigation and the detections of the
receiver's data, spilled chunk by chunk to disk (:mod:`pipeline.detection_store`; the
survey-wide statistics the later stages need are streamed). Processing, the grid and the TPU
(:func:`pipeline.survey_processing.process_survey`) then see only those and the
:class:`~pipeline.process.context.ProcessingContext`: loaded back whole, or, for a survey of
more pulses than ``run.whole_pulses`` or ``run.block_pulses``, block by block with a halo
(:mod:`pipeline.survey_blocks`) so memory stays bounded. The evaluate stage alone meets the truth
(:mod:`pipeline.survey_report`, :mod:`pipeline.survey_finish`). Every stage runs only where
the plan (:func:`pipeline.stages.plan`) says so, under the
:class:`~pipeline.stages.StageClock`. The grid and ``points.laz`` are made tile by tile
(:mod:`pipeline.survey_tiles`).
"""

from __future__ import annotations

import dataclasses
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from pipeline.detection_store import DetectionStore, SurveyAggregates
from pipeline.parallel import Executor
from pipeline.process.context import (
    ProcessingContext,
    processing_context,
    with_measured_attenuation,
)
from pipeline.process.returns import DetectedReturns, DetectorFlag
from pipeline.process.surface_echo_mix import NULL_FIELD, mix_stored_echoes
from pipeline.stages import Plan, StageClock, trim_heap
from pipeline.survey_blocks import is_blocked
from pipeline.survey_chunks import NB_FIELDS, ChunkJob, no_bottom_limits, run_chunk
from pipeline.survey_finish import finish_survey, log_cleanup
from pipeline.survey_tiles import tile_layout, write_points_by_tiles
from pipeline.uncertainty.photon_posterior import KeptPhotons
from pipeline.uncertainty.posterior_selection import KeptWaveforms, posterior_budget
from pipeline.worker_malloc import after_chunks

__all__ = ["SimulatedSurvey", "survey_extent_m", "simulate_detections", "run_survey"]


@dataclass(frozen=True)
class SimulatedSurvey:
    """What the chunk loop leaves: the recorded detections, and the truth for evaluation only.

    Attributes
    ----------
    returns : DetectedReturns or None
        Measured navigation and detections of every pulse, ``(n_pulses,)`` per field; None
        for a survey processed block by block (:func:`~pipeline.survey_blocks.is_blocked`):
        they stay on the store.
    kept : KeptWaveforms or KeptPhotons or None
        Waveforms (photon counting: the events of the windows) kept for posteriors.
    truth : Truth
        The exact world: read by the evaluate stage alone.
    lines : FlightLines
    extent_m : tuple of 4 float
        Local (xmin, xmax, ymin, ymax) of the simulated world.
    subray_flags, pulse_flags : dict of str to int
        Counts of the tracer's and the receiver's flags.
    no_bottom : dict or None
        Summary of the no-bottom limits (full waveform).
    median_surface_range_m : float or None
        Median slant range to the surface returns (on the bounded sample of
        :class:`~pipeline.detection_store.SurveyAggregates`); None without any.
    surface_echoes : dict or None
        How the survey timed its ambiguous surface echoes
        (:func:`~pipeline.process.surface_echo_mix.mix_stored_echoes`); None: photon counting.
    """

    returns: DetectedReturns | None
    kept: KeptWaveforms | KeptPhotons | None
    truth: Any
    lines: Any
    extent_m: tuple[float, float, float, float]
    subray_flags: dict[str, int]
    pulse_flags: dict[str, int]
    no_bottom: dict[str, Any] | None
    median_surface_range_m: float | None = None
    surface_echoes: dict[str, Any] | None = None


def survey_extent_m(scene, lines) -> tuple[float, float, float, float]:
    """Local (xmin, xmax, ymin, ymax) covering every line and its swath, plus a margin."""
    ends = np.concatenate([lines.start_xy, lines.end_xy])
    pad = 0.5 * lines.swath_width_m + 0.1 * scene.flight.altitude_m + 10.0
    return (
        float(ends[:, 0].min() - pad),
        float(ends[:, 0].max() + pad),
        float(ends[:, 1].min() - pad),
        float(ends[:, 1].max() + pad),
    )


def _count(into: dict[str, int], counts: dict[str, int]) -> None:
    for k, v in counts.items():
        into[k] = into.get(k, 0) + v


def simulate_detections(
    scene,
    plan: Plan,
    ctx: ProcessingContext,
    clock: StageClock,
    store: DetectionStore,
    log=print,
    progress=False,
    executor: Executor | None = None,
) -> SimulatedSurvey:
    """Simulate the survey chunk by chunk; keep the measured navigation and the detections.

    Each chunk's detections go to ``store`` (on disk) as they arrive; the survey-wide
    statistics are streamed (:class:`~pipeline.detection_store.SurveyAggregates`).
    ``progress``: a progress bar with ETA over the pulses (stderr). ``executor``: where the
    chunks run (:class:`~pipeline.parallel.Executor`; default: one by one in this process);
    the result is the same wherever they run.
    """
    from pipeline.simulate import survey
    from pipeline.simulate.trace_settings import resolved_trace_settings
    from pipeline.simulate.world import build_truth, build_world, wave_surface

    with clock.stage("terrain"):
        lines = survey.plan_lines(scene.flight, scene.scanner)
        extent = survey_extent_m(scene, lines)
    water = None
    if plan.runs("waves"):
        with clock.stage("waves"):
            water = wave_surface(scene)
    with clock.stage("terrain"):
        truth = build_truth(scene, extent, water=water)
        world = build_world(scene, truth, extent)
        # the evaluation takes the surface each pulse saw: pulse times by id, from the plan
        prf = scene.scanner.prf_hz
        truth = dataclasses.replace(
            truth, pulse_time_s=lambda ids: survey.pulse_times_s(lines, prf, ids)
        )
    if plan.runs("waves"):
        with clock.stage("waves"):
            # the footprint split: the traced surface tilts each footprint by the waves it
            # resolves; the surface echo adds, statistically, only the slope variance below
            # them (Cox-Munk minus the resolved waves' own, pipeline.simulate.budget)
            resolved = water.field.mean_square_slope(0.0)
            scene = dataclasses.replace(
                scene,
                returns=dataclasses.replace(scene.returns, resolved_mean_square_slope=resolved),
            )
        f = water.field
        log(
            f"  wave surface: tile {f.extent[1] - f.extent[0]:.0f} m ({f.shape[1]} nodes, Hs "
            f"sampling error {100 * f.hs_sampling_error:.1f} %), resolved mean-square slope "
            f"{resolved:.4f}, time slabs {water.slab_s:.3f} s"
            + ("" if water.evolving else " (frozen at t = 0)")
        )
    log(
        f"  {lines.n_lines} lines, {lines.n_pulses_total} pulses, swath "
        f"{lines.swath_width_m:.1f} m, line spacing {lines.line_spacing_m:.1f} m"
    )
    ps, ins = scene.process, ctx.instrument
    trace_settings = resolved_trace_settings(scene)
    # a chunk holds at most a million sub-rays (memory); results do not depend on the chunking
    chunk = max(1, min(scene.run.chunk_pulses, 1_000_000 // trace_settings.subrays))
    # whole accumulation windows (or slabs of cell windows) per chunk, so chunking cannot
    # change them
    if ins.photon_counting:
        unit = ins.windows.chunk_unit
        chunk = max(unit, chunk // unit * unit)
    # waveforms of a bounded share of the pulses are kept for posteriors (a few times the
    # pulses sampled, so the cells that matter can be chosen among them)
    # (photon counting: the events of a share of the windows, one posterior per window)
    keep_fraction = 0.0
    if plan.runs("posterior"):
        xmin, xmax, ymin, ymax = extent
        n_post = posterior_budget(ps, (xmax - xmin) * (ymax - ymin) / 1e6)
        n_units = lines.n_pulses_total
        if ins.photon_counting:
            # about shots_per_window shots per window, consecutive or a cell's
            n_units = -(-n_units // ins.shots_per_window)
        keep_fraction = min(1.0, 4.0 * n_post / max(n_units, 1))
    job = ChunkJob(
        scene=scene,
        ctx=ctx,
        world=world,
        lines=lines,
        chunk_pulses=chunk,
        keep_fraction=keep_fraction,
        waveform=plan.runs("receiver_waveform"),
        no_bottom=plan.runs("no_bottom_limit"),
    )
    sub_flags: dict[str, int] = {}
    pulse_flags: dict[str, int] = {}
    kept: list = []
    agg = SurveyAggregates(lines.n_pulses_total, scene.scene.seed, ins.air_index)
    beyond = int(DetectorFlag.BEYOND_DETECTION_LIMIT)
    n_chunk = survey.n_chunks(lines, chunk)
    executor = executor or Executor(workers=1)
    log(f"  chunks of {chunk} pulses on {executor.workers} worker(s)")
    win = ins.windows
    if win is not None and win.cell_m > 0.0:
        log(
            f"  photon windows: cells of {win.cell_m:g} m (~{win.shots_per_window} shots of one"
            f" look each) in slabs of {win.slab_shots} shots; bottoms read below the waves'"
            f" {win.sea_band_m:.2f} m band (process.photon_detect.window_cell_m)"
        )
    bar = tqdm(
        total=lines.n_pulses_total,
        unit="pulse",
        unit_scale=True,
        desc="simulate + detect",
        disable=not progress,
        file=sys.stderr,
    )
    # in chunk order, as they arrive; each chunk's stage seconds (in the process that ran it)
    # add to the clock, so CPU seconds count every worker, and its peak is the workers' largest.
    # Each chunk goes to disk at once (the store); only its summary and its share of the
    # survey-wide aggregates stay
    for c, res in enumerate(executor.map(run_chunk, job, n_chunk)):
        clock.add(res.stages)
        _count(sub_flags, res.subray_flags)
        _count(pulse_flags, res.pulse_flags)
        if res.kept is not None:
            kept.append(res.kept)
        agg.add(res.part, res.nb, ctx.refraction.group_index, beyond)
        part = res.part
        if res.nb is not None:  # the per-pulse inputs of the limits, until they are set
            part = {**part, **{f"nb_{k}": res.nb[k] for k in NB_FIELDS}}
        store.append(part)
        bar.update(res.n_pulses)
        del res, part
        if not progress and ((c + 1) % 5 == 0 or c + 1 == n_chunk):
            done = min((c + 1) * chunk, lines.n_pulses_total)
            log(f"  chunk {c + 1}/{n_chunk}: {done} pulses simulated and detected")
    bar.close()
    surface_echoes = None
    if not job.waveform:  # a photon detector resamples no surface echo
        store.drop_field(NULL_FIELD)
    if job.waveform:  # an ambiguous surface echo's time from the survey's share of clear ones
        dt = ps.detect
        _, surface_echoes = mix_stored_echoes(
            store,
            dt.surface_echo_prevalence_half,
            log,
            null_z=dt.surface_echo_null_z,
            null_excess=dt.surface_echo_null_excess,
            null_max_clear=dt.surface_echo_null_max_clear,
            band_deg=dt.surface_echo_angle_bin_deg,
            prior_pulses=dt.surface_echo_angle_prior_pulses,
        )
    no_bottom = None
    if not job.waveform:
        no_bottom = agg.photon_summary()
        log(f"  photon detection limits: {no_bottom}")
    if job.no_bottom:
        with clock.stage("no_bottom_limit"):
            no_bottom = no_bottom_limits(store, agg, ctx, ps.detect, ps.no_bottom)
        log(
            f"  no-bottom limits: {no_bottom['pulses_with_limit']} pulses "
            f"({no_bottom['limits_from_survey_decay']} from the column level at the survey's "
            "decay); bottoms fade "
            f"{no_bottom['excess_decay_per_m']:.3f}/m (in-water path) faster than the column "
            f"({no_bottom['bottoms_used']} bottoms: {no_bottom['excess_decay_from']})"
        )
    # a survey too large to hold stays on the store, read block by block (survey_blocks)
    blocked = is_blocked(scene, lines.n_pulses_total)
    return SimulatedSurvey(
        returns=None if blocked else store.returns(),
        kept=(KeptPhotons if not job.waveform else KeptWaveforms).concatenate(kept),
        truth=truth,
        lines=lines,
        extent_m=extent,
        subray_flags=sub_flags,
        pulse_flags=pulse_flags,
        no_bottom=no_bottom,
        median_surface_range_m=agg.median_surface_range_m(),
        surface_echoes=surface_echoes,
    )


def _measured_water(ctx: ProcessingContext, sim: SimulatedSurvey, log) -> ProcessingContext:
    """The context with the forward-scattering correction at the water the columns measured."""
    if sim.no_bottom is not None and sim.median_surface_range_m is not None:
        ctx = with_measured_attenuation(
            ctx, sim.no_bottom.get("column_decay_per_m"), sim.median_surface_range_m
        )
    fs = ctx.refraction.forward_scatter
    if fs is not None:
        where = ctx.sources["process.forward_scatter.beam_attenuation_per_m"]
        log(
            f"  forward-scattering correction at c = {fs.beam_attenuation_per_m:.3f}/m ({where}),"
            f" albedo {fs.single_scattering_albedo:.3f}"
        )
    return ctx


def run_survey(
    scene,
    plan: Plan,
    out: Path,
    clock: StageClock,
    log=print,
    progress: bool = False,
    executor: Executor | None = None,
):
    """Run the plan's survey stages and write the survey's outputs into ``out``.

    ``executor``: where the chunk loop runs (default: in this process).

    Returns
    -------
    files : dict of str to Path
    evaluation : dict
        The error report (also written to ``evaluation.json``).
    """
    from pipeline.process.coverage import area_coverage
    from pipeline.process.grid import snap_bounds_m
    from pipeline.survey_processing import process_survey

    ctx = processing_context(scene)
    ps, fr = scene.process, scene.frame
    origin = (fr.origin_easting_m, fr.origin_northing_m, 0.0)
    with DetectionStore(out, ctx.instrument.air_index) as store:
        sim = simulate_detections(scene, plan, ctx, clock, store, log, progress, executor)
        after_chunks()  # the allocator's thresholds for what follows, where chunks ran here
        trim_heap()  # the chunk loop's arrays and seabed tiles, when it ran in this process
        ctx = _measured_water(ctx, sim, log)
        xmin, xmax, ymin, ymax = sim.extent_m
        bounds = snap_bounds_m(
            np.array([xmin, xmax]), np.array([ymin, ymax]), ps.grid_resolution_m, origin
        )
        layout = tile_layout(scene, bounds)
        if sim.returns is None:  # too large to hold: block by block (pipeline.survey_blocks)
            from pipeline.survey_blocks_run import run_blocked

            return run_blocked(
                scene, plan, out, clock, log, progress, executor, store, sim, ctx, layout
            )
    made = process_survey(sim.returns, scene, plan, ctx, layout, clock, log)
    processed = made.processed
    covered = area_coverage(
        processed.points.xyz_m[:, :2], scene.flight.area_m, ps.grid_resolution_m
    )
    log_cleanup(log, processed, made.n_objects, made.rejected, ps, covered)

    def deliver(unc, grid):
        # the points tile by tile, the grid with its cells' uncertainty
        from pipeline.outputs.netcdf import write_grid_nc
        from pipeline.outputs.raster import write_grid_tif

        las_path, las_order = write_points_by_tiles(
            out / "points.laz", processed.points, sim.returns, layout, ctx, origin, fr.crs
        )
        files = {
            "points": las_path,
            "grid": write_grid_tif(out / "grid.tif", grid, unc.cells),
            "grid_nc": write_grid_nc(out / "grid.nc", grid, unc.cells),
        }
        return files, las_order

    return finish_survey(
        scene, plan, out, clock, log, progress, executor, sim, ctx, made, covered, deliver
    )
