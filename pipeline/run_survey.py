"""Orchestration of a survey scene: the plan's survey stages, wired and timed, nothing else.

Simulation (terrain → survey → trace → receiver) runs in chunks of ``run.chunk_pulses`` pulses;
of each chunk only what a real system records is kept: the measured navigation and the
detections of the receiver's data. Processing (:mod:`pipeline.process`) then sees only those and
the :class:`~pipeline.process.context.ProcessingContext`; the evaluate stage alone meets the
truth (:mod:`pipeline.survey_report`). Every stage runs only where the plan
(:func:`pipeline.stages.plan`) says so, under the :class:`~pipeline.stages.StageClock`.
"""

from __future__ import annotations

import dataclasses
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from pipeline.process.context import ProcessingContext, processing_context
from pipeline.process.posterior_selection import (
    KeptWaveforms,
    kept_for_posterior,
    posterior_budget,
)
from pipeline.process.returns import DetectedReturns
from pipeline.stages import Plan, StageClock

__all__ = ["SimulatedSurvey", "survey_extent_m", "simulate_detections", "run_survey"]


@dataclass(frozen=True)
class SimulatedSurvey:
    """What the chunk loop leaves: the recorded detections, and the truth for evaluation only.

    Attributes
    ----------
    returns : DetectedReturns
        Measured navigation and detections of every pulse, ``(n_pulses,)`` per field.
    kept : KeptWaveforms or None
        Waveforms kept for posteriors.
    truth : Truth
        The exact world: read by the evaluate stage alone.
    lines : FlightLines
    extent_m : tuple of 4 float
        Local (xmin, xmax, ymin, ymax) of the simulated world.
    subray_flags, pulse_flags : dict of str to int
        Counts of the tracer's and the receiver's flags.
    no_bottom : dict or None
        Summary of the no-bottom limits (full waveform).
    """

    returns: DetectedReturns
    kept: KeptWaveforms | None
    truth: Any
    lines: Any
    extent_m: tuple[float, float, float, float]
    subray_flags: dict[str, int]
    pulse_flags: dict[str, int]
    no_bottom: dict[str, Any] | None


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
    scene, plan: Plan, ctx: ProcessingContext, clock: StageClock, log=print, progress=False
) -> SimulatedSurvey:
    """Simulate the survey chunk by chunk; keep the measured navigation and the detections.

    ``progress``: a progress bar with ETA over the pulses (stderr).
    """
    from pipeline.simulate import paths as P
    from pipeline.simulate import survey
    from pipeline.simulate.detector import describe_pulse_flags
    from pipeline.simulate.trace import trace
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
    if ins.photon_counting:  # whole accumulation windows per chunk, so chunking cannot change them
        chunk = max(ins.shots_per_window, chunk // ins.shots_per_window * ins.shots_per_window)
    div_rad = scene.scanner.beam_divergence_mrad * 1e-3
    # waveforms of a bounded share of the pulses are kept for posteriors (a few times the
    # pulses sampled, so the cells that matter can be chosen among them)
    keep_fraction = 0.0
    if plan.runs("posterior"):
        xmin, xmax, ymin, ymax = extent
        n_post = posterior_budget(ps, False, (xmax - xmin) * (ymax - ymin) / 1e6)
        keep_fraction = min(1.0, 4.0 * n_post / max(lines.n_pulses_total, 1))
    sub_flags: dict[str, int] = {}
    pulse_flags: dict[str, int] = {}
    parts: list[dict[str, np.ndarray]] = []
    kept: list[KeptWaveforms] = []
    nb_inputs: list[dict[str, np.ndarray]] = []
    n_chunk = survey.n_chunks(lines, chunk)
    bar = tqdm(
        total=lines.n_pulses_total,
        unit="pulse",
        unit_scale=True,
        desc="simulate + detect",
        disable=not progress,
        file=sys.stderr,
    )
    for c in range(n_chunk):
        with clock.stage("survey"):
            pulses = survey.generate_pulses(
                scene.flight,
                scene.attitude,
                scene.navigation,
                scene.scanner,
                lines,
                c,
                chunk,
                scene.scene.seed,
            )
        with clock.stage("trace"):
            paths = trace(pulses, world, trace_settings, div_rad, scene.scanner.polarisation)
        _count(sub_flags, P.describe_flags(paths.flags))
        if plan.runs("receiver_waveform"):
            found, k, nb = _waveform_chunk(scene, plan, ctx, clock, paths, keep_fraction)
            if k is not None:
                kept.append(k)
            if nb is not None:
                nb_inputs.append(nb)
        else:
            found, flags = _photon_chunk(scene, ctx, clock, paths, pulses)
            _count(pulse_flags, describe_pulse_flags(flags))
        parts.append(
            {
                "pulse_id": pulses.pulse_id,
                "origin_meas_m": pulses.origin_meas_m,
                "direction_meas": pulses.direction_meas,
                "t_emit_s": pulses.t_s,  # the shot's timestamp and flight line, as recorded
                "line_id": pulses.line_id,
                **{f.name: getattr(found, f.name) for f in dataclasses.fields(found)},
            }
        )
        bar.update(len(pulses.pulse_id))
        if not progress and ((c + 1) % 5 == 0 or c + 1 == n_chunk):
            done = min((c + 1) * chunk, lines.n_pulses_total)
            log(f"  chunk {c + 1}/{n_chunk}: {done} pulses simulated and detected")
    bar.close()
    returns = _returns(parts)
    no_bottom = None
    if nb_inputs:
        from pipeline.process.no_bottom import no_bottom_limits

        with clock.stage("no_bottom_limit"):
            t_nb, no_bottom = no_bottom_limits(nb_inputs, returns.t_surface_s, ctx, ps.detect)
            returns = dataclasses.replace(returns, t_no_bottom_s=t_nb)
        log(
            f"  no-bottom limits: {no_bottom['pulses_with_limit']} pulses; bottoms fade "
            f"{no_bottom['excess_decay_per_m']:.3f}/m (in-water path) faster than the column "
            f"({no_bottom['bottoms_used']} bottoms)"
        )
    return SimulatedSurvey(
        returns=returns,
        kept=KeptWaveforms.concatenate(kept),
        truth=truth,
        lines=lines,
        extent_m=extent,
        subray_flags=sub_flags,
        pulse_flags=pulse_flags,
        no_bottom=no_bottom,
    )


def _returns(parts: list[dict[str, np.ndarray]]) -> DetectedReturns:
    """The chunks' navigation and detections as one DetectedReturns, in pulse order."""
    cat = {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}
    return DetectedReturns(
        pulse_id=cat["pulse_id"],
        origin_meas_m=cat["origin_meas_m"],
        direction_meas=cat["direction_meas"],
        has_surface=cat["has_surface"],
        t_surface_s=cat["t_surface_s"],
        has_bottom=cat["has_bottom"],
        t_bottom_s=cat["t_bottom_s"],
        surface_confidence=cat["surface_confidence"],
        bottom_confidence=cat["bottom_confidence"],
        flags=cat["flags"],
        surface_amplitude=cat["surface_amplitude"],
        bottom_amplitude=cat["bottom_amplitude"],
        # in-column returns (full waveform only; photon detections leave them empty)
        **{k: cat[k] for k in DetectedReturns.COLUMN_FIELDS if k in cat},
        t_emit_s=cat["t_emit_s"],
        line_id=cat["line_id"],
    )


def _waveform_chunk(scene, plan, ctx, clock, paths, keep_fraction):
    """Digitise one chunk, detect its returns, keep what the later stages need of it."""
    from pipeline.process.detect import detect_full_waveform
    from pipeline.simulate.waveform import simulate_waveforms

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
        )
    nb = None
    if plan.runs("no_bottom_limit"):
        from pipeline.process.no_bottom import chunk_inputs

        with clock.stage("no_bottom_limit"):  # times from sample 0, as the waveforms have them
            nb = chunk_inputs(wf.samples, found, ctx, ps.detect, ps.no_bottom)
    kept = None
    keep = kept_for_posterior(wf.pulse_id, keep_fraction, scene.scene.seed)
    if keep.any():
        kept = KeptWaveforms(wf.pulse_id[keep], wf.t0_s[keep], wf.samples[keep])
    # detection times are from sample 0; sample 0 is t0_s after emission
    found = dataclasses.replace(
        found,
        t_surface_s=found.t_surface_s + np.where(found.has_surface, wf.t0_s, 0.0),
        t_bottom_s=found.t_bottom_s + np.where(found.has_bottom, wf.t0_s, 0.0),
        t_column_s=found.t_column_s + np.where(found.has_column, wf.t0_s, 0.0),
    )
    return found, kept, nb


def _photon_chunk(scene, ctx, clock, paths, pulses):
    """Photon events of one chunk and their window detections; the receiver's flags."""
    from pipeline.process.detect_photons import detect_photon_events
    from pipeline.simulate.waveform import simulate_photon_events

    with clock.stage("receiver_photon"):
        ev = simulate_photon_events(paths, scene, scene.detector, scene.returns)
    with clock.stage("detect_photon"):
        found = detect_photon_events(
            ev.offsets,
            ev.times_s,
            pulses.origin_meas_m,
            pulses.direction_meas,
            ctx.instrument.air_index,
            scene.process.photon_detect,
            pulse_id=pulses.pulse_id,
        )
    return found, ev.flags


def run_survey(scene, plan: Plan, out: Path, clock: StageClock, log=print, progress: bool = False):
    """Run the plan's survey stages and write the survey's outputs into ``out``.

    Returns
    -------
    files : dict of str to Path
    evaluation : dict
        The error report (also written to ``evaluation.json``).
    """
    from pipeline.process.coverage import area_coverage
    from pipeline.process.datum import survey_datum
    from pipeline.process.grid import grid_seabed, snap_bounds_m
    from pipeline.process.survey_points import process_detections
    from pipeline.process.survey_uncertainty import survey_uncertainty, with_tpu

    ctx = processing_context(scene)
    sim = simulate_detections(scene, plan, ctx, clock, log, progress)
    ps, fr = scene.process, scene.frame
    with clock.stage("process"):
        processed = process_detections(sim.returns, ctx, ps.classify, water_column=False)
    if plan.runs("water_column"):
        from pipeline.process.water_column import add_water_column_points

        with clock.stage("water_column"):
            processed = add_water_column_points(processed, sim.returns, ctx.refraction, ps.classify)
    with clock.stage("grid"):
        origin = (fr.origin_easting_m, fr.origin_northing_m, 0.0)
        xmin, xmax, ymin, ymax = sim.extent_m
        bounds = snap_bounds_m(
            np.array([xmin, xmax]), np.array([ymin, ymax]), ps.grid_resolution_m, origin
        )
        # one datum for the grid (the user's water level, else the mean measured surface):
        # depth below the local fitted surface would carry the wave heights into the grid
        datum = survey_datum(processed.points, ps.datum)
        grid = grid_seabed(
            processed.points,
            ps.grid_resolution_m,
            bounds_m=bounds,
            origin_m=origin,
            crs=fr.crs,
            datum_m=datum.water_level_m,
        )
        covered = area_coverage(
            processed.points.xyz_m[:, :2], scene.flight.area_m, ps.grid_resolution_m
        )
    cell = ps.grid_resolution_m
    log(f"  coverage: {covered:.0%} of flight.area_m has a point in its {cell:g} m cell")
    if covered < 0.5:
        log(
            f"  WARNING: the flight plan leaves {1.0 - covered:.0%} of flight.area_m without a"
            " point: check flight.area_m, n_lines, line_length_m and the swath"
        )
    with clock.stage("tpu"):
        unc = survey_uncertainty(sim.returns, processed, ctx, grid)
        processed = dataclasses.replace(processed, points=with_tpu(processed.points, unc))
    post = None
    if plan.runs("posterior"):
        with clock.stage("posterior"):
            # imported here: a survey without posteriors never imports emcee
            from pipeline.process.survey_posterior import survey_posteriors
            from pipeline.process.survey_uncertainty import with_posteriors

            post = survey_posteriors(scene, sim.returns, sim.kept, processed, ctx, unc, grid)
            if post is not None and post.posteriors is not None:
                p = post.posteriors
                unc = with_posteriors(unc, grid, post.point_index, p.converged, p.depth_m["std"])
    with clock.stage("outputs"):
        from pipeline.outputs.las import write_points_laz
        from pipeline.outputs.netcdf import write_grid_nc
        from pipeline.outputs.raster import write_grid_tif

        files = {
            "points": write_points_laz(
                out / "points.laz",
                processed.points,
                crs=fr.crs,
                origin_m=origin,
                returns=sim.returns,
                amplitude_full_scale=ctx.instrument.amplitude_full_scale,
            ),
            "grid": write_grid_tif(out / "grid.tif", grid, unc.cells),
            "grid_nc": write_grid_nc(out / "grid.nc", grid, unc.cells),
        }
    with clock.stage("evaluate"):
        from pipeline.survey_report import evaluate_survey

        files["evaluation"] = out / "evaluation.json"
        evaluation = evaluate_survey(
            scene,
            sim,
            processed,
            ctx,
            grid,
            datum,
            unc,
            post,
            clock,
            files["evaluation"],
            log,
            area_covered=covered,
        )
        from pipeline.outputs.report import write_survey_report

        files["report"] = write_survey_report(
            out / "report.html",
            scene,
            plan,
            sim,
            processed,
            ctx,
            grid,
            unc,
            post,
            evaluation,
            clock,
        )
    return files, evaluation
