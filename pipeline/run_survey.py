"""Orchestration of a survey scene: simulate chunk by chunk, then process, grid and evaluate.

Simulation (terrain → survey → trace → receiver) runs in chunks of ``run.chunk_pulses`` pulses;
of each chunk only what a real system records is kept: the measured navigation and the
detections of the receiver's data (times, amplitudes, confidences). Processing then sees only
those (:mod:`pipeline.process`), and evaluation alone meets the truth.
"""

from __future__ import annotations

import dataclasses
import math
import time
from pathlib import Path
from typing import Any

import numpy as np

from pipeline.optics import SPEED_OF_LIGHT_M_S
from pipeline.outputs.atomic import write_json
from pipeline.process.context import processing_context
from pipeline.process.detect import detect_full_waveform
from pipeline.process.detect_photons import detect_photon_events
from pipeline.process.returns import PointFlag, Points

__all__ = ["survey_extent_m", "simulate_detections", "process_detections", "run_survey"]


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


def _system_fwhm_s(scene) -> float:
    """FWHM of the known system response: transmitted pulse ⊗ detector impulse response."""
    return math.hypot(scene.system.pulse_fwhm_s, scene.detector.impulse_response_fwhm_s)


def detect_noise(scene) -> tuple[int, float]:
    """``(noise_samples, shot_noise_counts)`` of the survey's full-waveform detector.

    The range gate opens ``pre_trigger_s`` before the first echo: those samples, less two
    system FWHM (so the echo's leading edge stays out of the baseline), are noise only.
    """
    det = scene.detector
    quiet_s = det.pre_trigger_s - 2.0 * _system_fwhm_s(scene)
    return (
        max(4, int(quiet_s * det.sample_rate_hz)),
        det.excess_noise_factor * det.counts_per_photoelectron,
    )


def kept_for_posterior(pulse_id: np.ndarray, fraction: float, seed: int) -> np.ndarray:
    """Pulses whose waveforms are kept for posteriors: a fixed share, by pulse id alone.

    A multiplicative (Weyl) hash of the id spreads the kept pulses evenly over the survey and
    does not depend on the chunking.
    """
    if fraction <= 0.0:
        return np.zeros(pulse_id.shape, dtype=bool)
    golden = np.uint64(0x9E3779B97F4A7C15)
    with np.errstate(over="ignore"):
        h = (pulse_id.astype(np.uint64) + np.uint64(seed)) * golden
    return (h >> np.uint64(11)).astype(np.float64) / 2.0**53 < fraction


def _detect_chunk(scene, paths, keep_fraction: float = 0.0):
    """Run the receiver on one chunk of traced pulses and detect its returns.

    Returns ``(photon events or None, detections or None, kept waveforms or None, no-bottom
    inputs or None)``; the kept waveforms (full waveform only) are ``(pulse_id, t0_s, samples)``
    of the pulses :func:`kept_for_posterior` selects; the no-bottom inputs are
    :func:`_no_bottom_inputs`'.
    """
    from pipeline.simulate.waveform import simulate_photon_events, simulate_waveforms

    det = scene.detector
    if det.mode == "photon_counting":
        ev = simulate_photon_events(paths, scene, det, scene.returns)
        return ev, None, None, None
    wf = simulate_waveforms(paths, scene, det, scene.returns)
    n_noise, shot = detect_noise(scene)
    found = detect_full_waveform(
        wf.samples,
        wf.sample_interval_s,
        _system_fwhm_s(scene),
        scene.process.detect,
        noise_samples=n_noise,
        shot_noise_counts=shot,
    )
    keep = kept_for_posterior(wf.pulse_id, keep_fraction, scene.scene.seed)
    kept = (wf.pulse_id[keep], wf.t0_s[keep], wf.samples[keep]) if keep.any() else None
    # detection times are from sample 0; sample 0 is t0_s after emission
    shift = np.where(found.has_surface, wf.t0_s, 0.0)
    shift_b = np.where(found.has_bottom, wf.t0_s, 0.0)
    shift_c = np.where(found.has_column, wf.t0_s, 0.0)
    found = dataclasses.replace(found, t_column_s=found.t_column_s + shift_c)
    nb = _no_bottom_inputs(scene, wf, found)
    found = dataclasses.replace(
        found, t_surface_s=found.t_surface_s + shift, t_bottom_s=found.t_bottom_s + shift_b
    )
    return None, found, kept, nb


def _detector_model(scene, dt_s: float):
    """The full-waveform detector (sampling every ``dt_s``) as the class-45 limit needs it."""
    from pipeline.process.detection_limit import DetectorModel

    ps = scene.process
    n_noise, shot = detect_noise(scene)
    return DetectorModel(
        dt_s=dt_s,
        pulse_fwhm_s=_system_fwhm_s(scene),
        noise_samples=n_noise,
        threshold_sigma=ps.detect.threshold_sigma,
        min_separation_fwhm=ps.detect.min_separation_fwhm,
        group_index=processing_context(scene).refraction.group_index,
        shot_noise_counts=shot,
    )


def _no_bottom_inputs(scene, wf, found) -> dict[str, np.ndarray]:
    """Per chunk, what the class-45 detection limit needs of the waveforms (then dropped).

    The column margins of the pulses with a surface and no bottom
    (:func:`~pipeline.process.detection_limit.column_margins`; zeros elsewhere) and the losses
    of the well-detected bottoms, SNR ≥ 2 × threshold
    (:func:`~pipeline.process.detection_limit.bottom_losses`).
    """
    from pipeline.process.detection_limit import bottom_losses, column_margins

    ps = scene.process
    det = _detector_model(scene, wf.sample_interval_s)
    n = found.has_surface.shape[0]
    none = found.has_surface & ~found.has_bottom
    margin, alpha, t_max = np.zeros(n), np.ones(n), np.zeros(n)
    ok = np.zeros(n, dtype=bool)
    if none.any():
        cm = column_margins(
            wf.samples[none], found.t_surface_s[none], found.noise_sigma[none], det, ps.no_bottom
        )
        margin[none], alpha[none], t_max[none], ok[none] = (
            cm.log_margin,
            cm.alpha_per_s,
            cm.t_max_s,
            cm.ok,
        )
    # a bottom near the threshold is found only where it happened to be bright: its loss would
    # bias the extra decay low, so only clear detections are used
    strong = found.has_bottom & (
        found.bottom_amplitude >= 2.0 * ps.detect.threshold_sigma * found.noise_sigma
    )
    t_b, loss, ok_b = bottom_losses(
        wf.samples[strong],
        found.t_surface_s[strong],
        found.t_bottom_s[strong],
        found.bottom_amplitude[strong],
        found.noise_sigma[strong],
        det,
        ps.no_bottom,
    )
    return {
        "none": none,
        "margin": margin,
        "alpha": alpha,
        "t_max": t_max,
        "ok": ok,
        "t_b": t_b[ok_b],
        "loss": loss[ok_b],
    }


def _no_bottom_times(scene, inputs: list[dict], t_surface_s: np.ndarray):
    """``t_no_bottom_s`` from emission of every pulse (0 where none), and a summary.

    The extra decay is fitted once over the whole survey's bottoms, so the limits do not depend
    on the chunking.
    """
    from pipeline.process.detection_limit import (
        ColumnMargins,
        excess_decay_per_s,
        limit_after_surface_s,
    )

    cat = {k: np.concatenate([d[k] for d in inputs]) for k in inputs[0]}
    delta = excess_decay_per_s(cat["t_b"], cat["loss"])
    det = _detector_model(scene, 1.0 / scene.detector.sample_rate_hz)
    margins = ColumnMargins(
        log_margin=cat["margin"],
        alpha_per_s=cat["alpha"],
        t_max_s=cat["t_max"],
        ok=cat["ok"],
        t_min_s=det.min_separation_fwhm * det.pulse_fwhm_s,
    )
    t = limit_after_surface_s(margins, delta)
    summary = {
        "excess_decay_per_m": delta * 2.0 * det.group_index / SPEED_OF_LIGHT_M_S,
        "bottoms_used": int(cat["t_b"].size),
        "pulses_with_limit": int(np.count_nonzero(t > 0.0)),
        "pulses_without_measurable_column": int(np.count_nonzero(cat["none"] & ~cat["ok"])),
    }
    return np.where(t > 0.0, t_surface_s + t, 0.0), summary


def simulate_detections(scene, log=print) -> dict[str, Any]:
    """Simulate the survey chunk by chunk; keep the measured navigation and the detections.

    Returns
    -------
    dict
        ``returns`` (DetectedReturns), ``truth`` (for evaluation only), ``lines``, ``extent``,
        ``timings_s``, ``subray_flags`` and ``pulse_flags`` counts, and ``kept_waveforms``:
        ``(pulse_id, t0_s, samples)`` of the pulses kept for posteriors (or None).
    """
    from pipeline.process.returns import DetectedReturns
    from pipeline.simulate import paths as P
    from pipeline.simulate import survey
    from pipeline.simulate.detector import describe_pulse_flags
    from pipeline.simulate.trace import trace
    from pipeline.simulate.world import build_truth, build_world

    timings = dict.fromkeys(("terrain_s", "survey_s", "trace_s", "receiver_s", "detect_s"), 0.0)
    t0 = time.perf_counter()
    lines = survey.plan_lines(scene.flight, scene.scanner)
    extent = survey_extent_m(scene, lines)
    truth = build_truth(scene, extent)
    world = build_world(scene, truth, extent)
    if scene.water_surface.kind == "waves":
        # the wave mesh already tilts each facet: the return model adds only the slope
        # variance the mesh does not carry (Cox-Munk minus the mesh's own)
        w = truth.water
        xx, yy = np.meshgrid(
            w.x0_m + w.dx_m * np.arange(w.z_m.shape[1]), w.y0_m + w.dy_m * np.arange(w.z_m.shape[0])
        )
        gx, gy = w.gradient(xx, yy)
        resolved = float(np.mean(gx**2 + gy**2))
        scene = dataclasses.replace(
            scene, returns=dataclasses.replace(scene.returns, resolved_mean_square_slope=resolved)
        )
        log(f"  wave surface: mean-square slope {resolved:.4f} carried by the mesh")
    timings["terrain_s"] = time.perf_counter() - t0
    log(
        f"  {lines.n_lines} lines, {lines.n_pulses_total} pulses, swath "
        f"{lines.swath_width_m:.1f} m, line spacing {lines.line_spacing_m:.1f} m"
    )
    chunk = scene.run.chunk_pulses
    photon = scene.detector.mode == "photon_counting"
    if photon:  # whole accumulation windows per chunk, so chunking cannot change them
        spw = scene.process.photon_detect.shots_per_window
        chunk = max(spw, chunk // spw * spw)
    div_rad = scene.scanner.beam_divergence_mrad * 1e-3
    n_air = scene.atmosphere.refractive_index
    sub_flags: dict[str, int] = {}
    pulse_flags: dict[str, int] = {}
    parts: list[dict[str, np.ndarray]] = []
    kept: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
    nb_inputs: list[dict[str, np.ndarray]] = []
    # waveforms of a bounded share of the pulses are kept for posteriors (a few times the
    # pulses sampled, so the cells that matter can be chosen among them)
    from pipeline.survey_posterior import posterior_budget

    xmin, xmax, ymin, ymax = extent
    n_post = posterior_budget(scene, (xmax - xmin) * (ymax - ymin) / 1e6)
    keep_fraction = min(1.0, 4.0 * n_post / max(lines.n_pulses_total, 1))
    n_chunk = survey.n_chunks(lines, chunk)
    for c in range(n_chunk):
        t1 = time.perf_counter()
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
        t2 = time.perf_counter()
        paths = trace(pulses, world, scene.trace, div_rad, scene.scanner.polarisation)
        t3 = time.perf_counter()
        events, found, kept_wf, nb = _detect_chunk(scene, paths, keep_fraction)
        if nb is not None:
            nb_inputs.append(nb)
        if kept_wf is not None:
            kept.append(kept_wf)
        t4 = time.perf_counter()
        if photon:
            found = detect_photon_events(
                events.offsets,
                events.times_s,
                pulses.origin_meas_m,
                pulses.direction_meas,
                n_air,
                scene.process.photon_detect,
                pulse_id=pulses.pulse_id,
            )
            receiver_flags = events.flags
        else:
            receiver_flags = None
        t5 = time.perf_counter()
        timings["survey_s"] += t2 - t1
        timings["trace_s"] += t3 - t2
        timings["receiver_s"] += t4 - t3
        timings["detect_s"] += t5 - t4
        if (c + 1) % 5 == 0 or c + 1 == n_chunk:
            done = min((c + 1) * chunk, lines.n_pulses_total)
            log(f"  chunk {c + 1}/{n_chunk}: {done} pulses simulated and detected")
        for k, v in P.describe_flags(paths.flags).items():
            sub_flags[k] = sub_flags.get(k, 0) + v
        if receiver_flags is not None:
            for k, v in describe_pulse_flags(receiver_flags).items():
                pulse_flags[k] = pulse_flags.get(k, 0) + v
        parts.append(
            {
                "pulse_id": pulses.pulse_id,
                "origin_meas_m": pulses.origin_meas_m,
                "direction_meas": pulses.direction_meas,
                **{f.name: getattr(found, f.name) for f in dataclasses.fields(found)},
            }
        )
    cat = {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}
    t_no_bottom, no_bottom = None, None
    if nb_inputs:
        t_no_bottom, no_bottom = _no_bottom_times(scene, nb_inputs, cat["t_surface_s"])
        log(
            f"  no-bottom limits: {no_bottom['pulses_with_limit']} pulses; bottoms fade "
            f"{no_bottom['excess_decay_per_m']:.3f}/m (in-water path) faster than the column "
            f"({no_bottom['bottoms_used']} bottoms)"
        )
    returns = DetectedReturns(
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
        t_no_bottom_s=t_no_bottom,
    )
    return {
        "returns": returns,
        "truth": truth,
        "lines": lines,
        "extent": extent,
        "timings_s": timings,
        "no_bottom": no_bottom,
        "subray_flags": sub_flags,
        "pulse_flags": pulse_flags,
        "kept_waveforms": (
            tuple(np.concatenate([k[j] for k in kept]) for j in range(3)) if kept else None
        ),
    }


def process_detections(scene, returns, ctx=None):
    """Points from the detections, as ``bathy run`` makes them: measured data only.

    Surface fit, refraction correction and classes (:func:`~pipeline.process.refraction.
    georeference`), then the no-bottom-found-at and water-column points.

    Parameters
    ----------
    scene : Scene
    returns : DetectedReturns
    ctx : ProcessingContext, optional
        What processing assumes (:func:`pipeline.process.context.processing_context` of the
        scene by default).

    Returns
    -------
    processed : Processed
    refraction_settings : RefractionSettings
        The water indices the processing assumed.
    """
    from pipeline.process.refraction import georeference
    from pipeline.process.water_column import add_water_column_points

    ps = scene.process
    ctx = ctx or processing_context(scene)
    refr = ctx.refraction
    processed = georeference(
        returns,
        surface_settings=ctx.surface_fit,
        refraction_settings=refr,
        classify_settings=ps.classify,
    )
    processed = dataclasses.replace(
        processed,
        points=Points.concatenate(
            [processed.points, _no_bottom_points(scene, returns, processed, refr)]
        ),
    )
    processed = add_water_column_points(processed, returns, refr, ps.classify)
    return processed, refr


def run_survey(scene, out: Path, log=print) -> tuple[dict[str, Path], dict[str, float], dict]:
    """Simulate, process, grid, write and evaluate a survey scene.

    Returns
    -------
    files : dict of str to Path
    timings_s : dict of str to float
    evaluation : dict
        The error report (also written to ``evaluation.json``).
    """
    from pipeline.evaluate import evaluate, tpu_coverage, water_column_report
    from pipeline.outputs.las import write_points_laz
    from pipeline.outputs.raster import write_grid_tif
    from pipeline.process.datum import survey_datum
    from pipeline.process.grid import grid_seabed, snap_bounds_m

    sim = simulate_detections(scene, log)
    timings = sim["timings_s"]
    ps = scene.process
    t0 = time.perf_counter()
    ctx = processing_context(scene)
    processed, refr = process_detections(scene, sim["returns"], ctx)
    fr = scene.frame
    origin = (fr.origin_easting_m, fr.origin_northing_m, 0.0)
    xmin, xmax, ymin, ymax = sim["extent"]
    bounds = snap_bounds_m(
        np.array([xmin, xmax]), np.array([ymin, ymax]), ps.grid_resolution_m, origin
    )
    # one datum for the grid (the user's water level, else the median measured surface): depth
    # below the local fitted surface would carry the wave heights into the grid
    datum = survey_datum(processed.points, ps.datum)
    grid = grid_seabed(
        processed.points,
        ps.grid_resolution_m,
        bounds_m=bounds,
        origin_m=origin,
        crs=fr.crs,
        datum_m=datum.water_level_m,
    )
    timings["process_s"] = time.perf_counter() - t0
    t1 = time.perf_counter()
    unc = _uncertainty(scene, sim["returns"], processed, ctx, grid)
    processed = dataclasses.replace(
        processed, points=_with_tpu(processed.points, unc["is40"], unc["tpu40"], unc["no_tpu"])
    )
    timings["uncertainty_s"] = time.perf_counter() - t1
    t2 = time.perf_counter()
    from pipeline.survey_posterior import survey_posteriors

    post = survey_posteriors(scene, sim, processed, ctx, unc, grid)
    if post is not None and post["posteriors"] is not None:
        unc = _cells_with_posteriors(unc, grid, post)
    timings["posterior_s"] = time.perf_counter() - t2
    files = {
        "points": write_points_laz(
            out / "points.laz", processed.points, crs=fr.crs, origin_m=origin
        ),
        "grid": write_grid_tif(out / "grid.tif", grid),
    }
    truth = sim["truth"]
    # the true mean water level: the scene's level, about which the wave field has zero mean
    true_level_m = scene.water_surface.level_m
    report = evaluate(
        processed.points,
        uncorrected=processed.uncorrected,
        grid=grid,
        # points: depth below the local water surface (their depth_m's reference); GNSS
        # height errors common to the surface and the seabed returns cancel in it
        truth_depth_m=truth.depth_m,
        # grid: depth below the mean water level, as the grid's datum
        grid_truth_depth_m=lambda x, y: true_level_m - truth.seabed.height_m(x, y),
    ).to_dict()
    # the depth's sigma (below the measured surface, at the measured position) against the
    # true depth there; a photon-counting window's shots share one detection (one draw)
    group = None
    if scene.detector.mode == "photon_counting":
        group = unc["points40"].pulse_id // scene.process.photon_detect.shots_per_window
    coverage = tpu_coverage(
        unc["points40"], unc["tpu40"].sigma_depth_m, truth_depth_m=truth.depth_m, group=group
    )
    post_eval = None
    if post is not None:
        from pipeline.evaluate import posterior_coverage

        post_eval = {"n": 0}
        if post["posteriors"] is not None:
            post_eval = posterior_coverage(post["posteriors"], truth_depth_m=truth.depth_m)
            post_eval["seconds_per_pulse"] = post["cost_s"] / max(len(post["point_index"]), 1)
        post_eval["skipped_in_column_return"] = post["skipped_column"]
        post_eval["cells_with_posterior"] = int(np.count_nonzero(unc["cells"].n_posterior))
    evaluation = {
        "pulses": int(sim["returns"].pulse_id.size),
        "posterior_against_truth": post_eval,
        "iho_orders_from_uncertainty": unc["summary"],
        "tpu_coverage_against_truth": coverage,
        "tpu_left_out": unc["left_out"],
        "receiver": scene.detector.mode,
        "bottom_detected_fraction": float(np.mean(sim["returns"].has_bottom)),
        "datum": {**datum.to_dict(), "true_mean_water_level_m": true_level_m},
        "no_bottom": sim["no_bottom"],
        "water_column": water_column_report(processed.points, scene.water.layer_depth_m),
        "subray_flags": sim["subray_flags"],
        "receiver_pulse_flags": sim["pulse_flags"],
        "error": report,
        "timings_s": timings,
        "processing_context": ctx.to_dict(),
    }
    files["evaluation"] = out / "evaluation.json"
    write_json(files["evaluation"], evaluation)
    _log_report(report, log)
    log(
        f"  grid datum: water level {datum.water_level_m:+.3f} m ({datum.source}, "
        f"{datum.n_surface_points} surface points); true mean level {true_level_m:+.3f} m"
    )
    orders = unc["summary"].get("orders", {})
    log(
        "  strictest IHO S-44 order met per cell (from the propagated uncertainty): "
        + ", ".join(
            f"{k} {v['fraction']:.1%}" for k, v in orders.items() if v["fraction"] is not None
        )
    )
    lo = unc["left_out"]
    if lo["pulses"]:
        why = ", ".join(f"{k} {v}" for k, v in lo["by_reason"].items() if v)
        log(
            f"  {lo['pulses']} bottom pulses left out of the TPU ({why}); their"
            f" {lo['bathymetric_points']} bathymetric points keep the a-priori uncertainty"
            " (flag NO_TPU) and are not in the cell uncertainty or the TPU check"
        )
    if coverage["fraction_within"] is not None:
        log(
            "  TPU check (true depth within ±k σ_depth): "
            + ", ".join(
                f"k={c['k']:g}: {c['fraction_within']:.1%} ± {c['standard_error']:.1%}"
                f" (nominal {c['nominal']:.1%})"
                for c in coverage["intervals"]
            )
            + f" of {coverage['n']} points"
        )
    if post_eval is not None and post_eval.get("n"):
        log(
            f"  depth posteriors (emcee) of {post_eval['n']} points: the true depth lies in the"
            f" 68 % interval for {post_eval['coverage_68']:.1%}, in the 95 % for "
            f"{post_eval['coverage_95']:.1%}; {post_eval['converged_fraction']:.0%} converged, "
            f"{post_eval['seconds_per_pulse']:.2f} s per pulse"
        )
    if post_eval is not None and post_eval["skipped_in_column_return"]:
        log(
            f"  {post_eval['skipped_in_column_return']} candidate points got no posterior: their"
            " pulses have an in-column return, which the posterior's waveform model lacks"
        )
    return files, timings, evaluation


def _log_report(report: dict, log) -> None:
    def line(name, st):
        if not st or not st.get("n"):
            return f"  {name:<24} no points"
        return (
            f"  {name:<24} n={st['n']:<8} bias {st['bias_m']:+.3f} m  RMSE {st['rmse_m']:.3f} m"
            f"  |err|95 {st['p95_abs_m']:.3f} m"
        )

    log("  evaluation against the truth (measured minus true depth):")
    log(line("points, refraction corr.", report.get("points")))
    log(line("points, uncorrected", report.get("points_uncorrected")))
    log(line("grid cells", report.get("grid")))
    iho = report.get("iho_grid") or {}
    if iho:
        frac = ", ".join(
            f"{k} {v['fraction_within']:.1%}"
            for k, v in iho.items()
            if v.get("fraction_within") is not None
        )
        log(f"  grid cells within IHO S-44 TVU: {frac}")


def _uncertainty(scene, returns, processed, ctx, grid) -> dict[str, Any]:
    """TPU of the bathymetric points, cell uncertainty and the IHO order met per cell.

    Measured data only: the seabed gradient under every bottom point (which couples the
    horizontal errors into the depth compared at the measured position) is a local plane
    through the neighbouring bathymetric soundings (:func:`~pipeline.process.tpu.
    seabed_gradient`); the water plane's tilt uncertainty is the larger of the fit's and the
    one measured over the soundings (:func:`~pipeline.process.tpu.surface_tilt_sigma`). When
    the detector reports no per-return timing sigma, the timing terms are set from the
    scatter of successive soundings (:func:`~pipeline.process.tpu.pair_scatter`,
    :func:`~pipeline.process.tpu.timing_from_scatter`). A photon-counting window's shots
    share one detection: they count as one sounding.
    """
    from pipeline import iho
    from pipeline.process.cell_uncertainty import cell_uncertainty
    from pipeline.process.classify import BATHYMETRIC_POINT
    from pipeline.process.refraction import seabed_points
    from pipeline.process.returns import ReturnKind
    from pipeline.process.tpu import (
        pair_scatter,
        point_tpu,
        seabed_gradient,
        surface_tilt_sigma,
        timing_from_scatter,
    )

    # navigation quality, beam and wavelength: the user's values, else the scene's records
    st, refr = ctx.tpu, ctx.refraction
    pts = processed.points
    is40 = (pts.classification == BATHYMETRIC_POINT) & (pts.kind == ReturnKind.BOTTOM)
    points40 = pts.select(is40)
    bottom_xy = seabed_points(returns, processed.surface, refr).xyz_m[:, :2]
    xy40, d40 = points40.xyz_m[:, :2], points40.depth_m
    group = None
    if scene.detector.mode == "photon_counting":  # a window's shots share one detection
        group = points40.pulse_id // scene.process.photon_detect.shots_per_window
    near = {"neighbours": st.gradient_neighbours, "radius_m": st.gradient_radius_m}
    grad = seabed_gradient(xy40, d40, bottom_xy, group=group, **near)
    # the water surface measured over each sounding against its pulse's plane there: the
    # plane's tilt uncertainty, averaged over the bathymetric points
    bottom_ids = returns.pulse_id[returns.has_bottom]
    by_id = np.argsort(bottom_ids)
    rows40 = by_id[np.searchsorted(bottom_ids[by_id], points40.pulse_id)]
    tilt = surface_tilt_sigma(returns, processed.surface, bottom_xy, pool=rows40)
    if returns.t_bottom_sigma_s is None:
        # no timing sigma from the detector: from the scatter of successive soundings
        scatter = pair_scatter(
            xy40,
            d40,
            order=points40.pulse_id,
            group=group,
            query_xy_m=bottom_xy,
            max_separation_m=st.pair_max_separation_m,
            neighbours=st.scatter_neighbours,
        )
        returns = timing_from_scatter(
            returns,
            processed.surface,
            refr,
            st,
            depth_scatter_m=scatter,
            seabed_gradient=grad,
            # a return lies in the recorded window: its timing sigma is at most a uniform one's
            max_sigma_s=scene.detector.window_s / math.sqrt(12.0),
        )
    tpu = point_tpu(
        returns,
        processed.surface,
        refr,
        st,
        seabed_gradient=grad,
        surface_tilt_sigma_rad=tilt,
    )
    # pulses the TPU could not propagate: their points keep the a-priori uncertainty and are
    # left out of the cell uncertainty and the TPU check
    no_tpu = is40 & np.isin(pts.pulse_id, tpu.left_out.pulse_id)
    is40 = is40 & ~no_tpu
    points40 = pts.select(is40)
    # TPU rows are per pulse with a bottom; keep those of the bathymetric points, same order
    order = np.argsort(tpu.pulse_id)
    pos = order[np.searchsorted(tpu.pulse_id[order], points40.pulse_id)]
    tpu40 = _take_tpu(tpu, pos)
    cells = cell_uncertainty(grid, tpu40)
    return {
        "tpu40": tpu40,
        "points40": points40,
        "is40": is40,
        "no_tpu": no_tpu,
        "left_out": {
            "pulses": len(tpu.left_out),
            "bathymetric_points": int(np.count_nonzero(no_tpu)),
            "by_reason": tpu.left_out.counts(),
        },
        "cells": cells,
        "summary": iho.order_summary(cells.order).to_dict(),
    }


def _with_tpu(points, is40, tpu40, no_tpu=None):
    """``points`` whose bathymetric points carry their TPU as the per-point uncertainty.

    The points of ``no_tpu`` (bool, optional: pulses the TPU left out) get the
    ``PointFlag.NO_TPU`` bit and keep the a-priori values.

    ``uncertainty_v_m`` := ``PointTpu.sigma_v_m``, the one-sigma of the point's elevation ``z``
    (the LAS z; what IHO S-44's TVU bounds), and ``uncertainty_h_m`` := ``sigma_h_m``, per
    horizontal axis; the other points keep the a-priori values of
    :mod:`pipeline.process.refraction`. The depth's own sigma (below the measured water surface,
    smaller) is ``PointTpu.sigma_depth_m``, checked against the truth in ``evaluation.json``.
    """
    v, h = points.uncertainty_v_m.copy(), points.uncertainty_h_m.copy()
    v[is40], h[is40] = tpu40.sigma_v_m, tpu40.sigma_h_m
    flags = points.flags.copy()
    if no_tpu is not None:
        flags[no_tpu] |= np.uint16(PointFlag.NO_TPU)
    return points.replace(uncertainty_v_m=v, uncertainty_h_m=h, flags=flags)


def _cells_with_posteriors(unc: dict, grid, post: dict) -> dict:
    """Cell uncertainty again, the converged posteriors' depth sigma in place of the timing.

    The posterior covers the waveform timing of both returns (and its nuisances), which the
    TPU's timing terms approximate; in the cells where points were sampled their variance
    replaces those terms (:func:`pipeline.process.cell_uncertainty.cell_uncertainty`).
    """
    from pipeline import iho
    from pipeline.process.cell_uncertainty import cell_uncertainty

    n = len(unc["points40"])
    sampled = np.zeros(n, dtype=bool)
    sigma = np.zeros(n)
    ps = post["posteriors"]
    ok = ps.converged
    sampled[post["point_index"][ok]] = True
    sigma[post["point_index"][ok]] = ps.depth_m["std"][ok]
    cells = cell_uncertainty(grid, unc["tpu40"], posterior_sigma_v_m=sigma, has_posterior=sampled)
    return {**unc, "cells": cells, "summary": iho.order_summary(cells.order).to_dict()}


def _take_tpu(tpu, index: np.ndarray):
    """Rows ``index`` of a PointTpu (every per-point array and term)."""
    kw = {}
    for f in dataclasses.fields(tpu):
        v = getattr(tpu, f.name)
        if isinstance(v, dict):
            kw[f.name] = {k: a[index] for k, a in v.items()}
        elif isinstance(v, np.ndarray) and v.ndim >= 1 and v.shape[0] == len(tpu):
            kw[f.name] = v[index]
        else:
            kw[f.name] = v
    return dataclasses.replace(tpu, **kw)


def _no_bottom_points(scene, returns, processed, refr):
    """ASPRS class 45 "no-bottom-found-at" points of the water pulses that have no bottom.

    Each is placed, along the refracted beam, at the pulse's detection limit
    (``returns.t_no_bottom_s``, :mod:`pipeline.process.detection_limit`): the depth down to which
    a bottom of the assumed reflectance would have been detected, so the absence of a bottom is
    established there and no deeper. A full-waveform pulse whose column gave no limit (too weak
    or too short to measure its decay: over land, or a bottom merged with the surface in a metre
    of water) establishes nothing and gets no point. Photon-counting detections carry no limit
    (``t_no_bottom_s`` None): theirs stays the end of the recorded window, which the range gate
    fixes ``window_s − pre_trigger_s`` after the surface echo (system knowledge).
    """
    from pipeline.process.classify import NO_BOTTOM_FOUND_AT
    from pipeline.process.refraction import seabed_points
    from pipeline.process.returns import PointFlag

    det = scene.detector
    none = returns.has_surface & ~returns.has_bottom
    t_end = returns.t_surface_s + (det.window_s - det.pre_trigger_s)
    if returns.t_no_bottom_s is not None:
        none &= returns.t_no_bottom_s > 0.0
        t_end = returns.t_no_bottom_s
    probe = dataclasses.replace(
        returns,
        has_bottom=none,
        t_bottom_s=np.where(none, t_end, 0.0),
        bottom_confidence=np.where(none, 1.0, 0.0),
        bottom_amplitude=None,
        t_bottom_sigma_s=None,
        t_no_bottom_s=None,
    )
    pts = seabed_points(probe, processed.surface, refr)
    bad = PointFlag.LAND | PointFlag.GRAZING | PointFlag.ABOVE_SURFACE
    pts = pts.select((pts.flags & np.uint16(bad)) == 0)
    return pts.replace(
        classification=np.full(pts.pulse_id.shape, NO_BOTTOM_FOUND_AT, dtype=np.uint8)
    )
