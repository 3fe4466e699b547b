"""Evaluation of a survey run against the truth: ``evaluation.json`` and the summary lines.

The truth side: only the evaluate stage of :mod:`pipeline.run_survey` calls this, with the
truth the simulation kept; processing never sees it.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from pipeline.evaluate import evaluate, truth_at, water_column_report
from pipeline.evaluate_coverage import tpu_coverage
from pipeline.evaluate_features import features_report
from pipeline.outputs.atomic import write_json
from pipeline.process.classify import SEABED_CLASSES
from pipeline.process.no_bottom import extinction_depth_summary

__all__ = ["evaluate_survey"]


def _meet_the_sea_once(truth_depth_m, processed, post) -> None:
    """Ask the truth once for every point the evaluation below reads it at.

    Over a moving sea the truth is the surface each pulse saw, and a call that meets new
    points walks the survey's time slabs, re-synthesising the wave field at each (the sea keeps
    only a few: :class:`terrain.evolving_sea.EvolvingSea`); the truth remembers what it met
    (:class:`pipeline.simulate.pulse_truth.PulseDepth`). The points, the uncorrected points
    and the posteriors' medians each walked them once (CI scene 9007: 2.7 s each, a
    photon-counting suite scene over waves: ~100 s of its 250); now one walk, the same values.
    """
    if not getattr(truth_depth_m, "per_pulse", False):
        return
    sets = [
        (p.xyz_m, p.pulse_id) for p in (processed.points, processed.uncorrected) if p is not None
    ]
    if post is not None and post.posteriors is not None:
        sets.append((post.posteriors.xyz_median_m, post.posteriors.pulse_id))
    if not sets:
        return
    xyz = np.concatenate([np.asarray(xyz, dtype=np.float64).reshape(-1, 3) for xyz, _ in sets])
    pid = np.concatenate([np.asarray(pid).ravel() for _, pid in sets])
    if pid.size:
        truth_at(truth_depth_m, xyz[:, 0], xyz[:, 1], pid)


def evaluate_survey(
    scene,
    sim,
    processed,
    ctx,
    grid,
    datum,
    unc,
    post,
    clock,
    path: Path,
    log=print,
    *,
    area_covered: float | None = None,
) -> dict[str, Any]:
    """Points, grid, TPU and posteriors against the truth; write ``evaluation.json`` at ``path``.

    Parameters
    ----------
    scene : Scene
    sim : SimulatedSurvey
        The simulation's detections and, for this stage alone, its truth.
    processed : ProcessedPoints
    ctx : ProcessingContext
    grid : Grid
    datum : Datum
    unc : SurveyUncertainty
    post : SurveyPosteriors or None
    clock : StageClock
        Stage timings so far (recorded in the file).
    path : Path
    log : callable
    area_covered : float, optional
        Fraction of ``flight.area_m`` with a sounding (recorded as ``area_covered``).

    Returns
    -------
    dict
        The evaluation, as written.
    """
    truth = sim.truth
    _meet_the_sea_once(truth.depth_at_pulses_m, processed, post)
    # the true mean water level: the scene's level, about which the wave field has zero mean
    true_level_m = scene.water_surface.level_m

    def grid_truth(x, y):
        return true_level_m - truth.seabed.height_m(x, y)

    report = evaluate(
        processed.points,
        uncorrected=processed.uncorrected,
        grid=grid,
        # points: depth below the local water surface (their depth_m's reference); GNSS
        # height errors common to the surface and the seabed returns cancel in it
        truth_depth_m=truth.depth_at_pulses_m,  # below the sea as each pulse saw it
        # grid: depth below the mean water level, as the grid's datum
        grid_truth_depth_m=grid_truth,
        classes=SEABED_CLASSES,  # bathymetric points and submerged objects: every sounding
    ).to_dict()
    # the depth's sigma (below the measured surface, at the measured position) against the
    # true depth there; a photon-counting window's shots share one detection (one draw)
    group = None
    if ctx.instrument.photon_counting:
        group = ctx.instrument.windows.of_points(unc.points40.pulse_id, sim.returns)
    coverage = tpu_coverage(
        unc.points40, unc.tpu40.sigma_depth_m, truth_depth_m=truth.depth_at_pulses_m, group=group
    )
    from pipeline.evaluation_points import (
        class45_report,
        gross_report,
        point_arrays,
        rejected_report,
        write_evaluation_points,
    )

    # per-point residuals and sigmas, so a scene suite can pool strata across runs
    arrays = point_arrays(
        processed,
        grid,
        unc,
        post,
        truth.depth_at_pulses_m,  # as evaluation.json: the sea each pulse saw
        grid_truth,
        group=group,
        seabed_height_m=truth.seabed.height_m,
    )
    write_evaluation_points(path.with_name("evaluation_points.npz"), arrays)
    post_eval = None
    if post is not None:
        from pipeline.evaluate_coverage import posterior_coverage

        post_eval = {"n": 0}
        if post.posteriors is not None:
            post_eval = posterior_coverage(post.posteriors, truth_depth_m=truth.depth_at_pulses_m)
            post_eval["seconds_per_pulse"] = post.cost_s / max(len(post.point_index), 1)
        post_eval["skipped_in_column_return"] = post.skipped_column
        post_eval["cells_with_posterior"] = int(np.count_nonzero(unc.cells.n_posterior))
    evaluation = {
        "pulses": int(sim.returns.pulse_id.size),
        "area_covered": area_covered,
        "posterior_against_truth": post_eval,
        "iho_orders_from_uncertainty": unc.summary,
        "tpu_coverage_against_truth": coverage,
        "tpu_left_out": unc.left_out,
        "receiver": scene.detector.mode,
        "bottom_detected_fraction": float(np.mean(sim.returns.has_bottom)),
        "datum": {**datum.to_dict(), "true_mean_water_level_m": true_level_m},
        # how the ambiguous surface echoes were timed: the clear share's weight, or the
        # weak-echo test's verdict (pipeline.process.surface_echo_mix)
        "surface_echoes": sim.surface_echoes,
        # the detection limits, and the depths of the class-45 points they placed: the
        # survey's measured extinction depth
        "no_bottom": {
            **(sim.no_bottom or {}),
            **extinction_depth_summary(processed.points),
            # their claims ("no bottom down to here") against the true seabed
            **class45_report(processed.points, truth.depth_at_pulses_m),
            # claims not made: a class-40 sounding nearby lies shallower
            "class45_withheld_by_soundings": processed.claims_withheld,
        },
        "water_column": water_column_report(processed.points, scene.water.layer_depth_m),
        "subray_flags": sim.subray_flags,
        "receiver_pulse_flags": sim.pulse_flags,
        "error": report,
        # soundings more than 1 m off: at their own position, and against every seabed within
        # their own THU95 (a sounding beside a wall, reading its top: pipeline.evaluate_thu)
        "gross_errors": gross_report(arrays["pt_error_m"], arrays["pt_error_thu_m"]),
        # the soundings processing rejected as gross errors (class 7, withheld), per rule
        "seabed_rejected": rejected_report(processed.points, truth.depth_at_pulses_m),
        # per IHO cube: detected by soundings on its top / a grid cell / class 43; the grid
        # as seabed elevation against the true seabed
        **features_report(
            scene,
            processed.points,
            truth.depth_at_pulses_m,
            grid,
            grid_truth,
            truth.seabed.height_m,
        ),
        "stages": clock.to_dict(),
        "processing_context": ctx.to_dict(),
    }
    write_json(path, evaluation)
    _log_report(report, log)
    gross = evaluation["gross_errors"]
    if gross["over_1m"]:
        log(
            f"  {gross['over_1m']} soundings more than 1 m off at their position; "
            f"{gross['over_1m_beyond_thu95']} of them with no seabed at their depth within their "
            f"THU95 (the others sit within it of a wall whose other side they read)"
        )
    ge = evaluation["grid_elevation"]
    if ge["n"]:
        log(
            f"  grid as seabed elevation: n={ge['n']} bias {ge['bias_m']:+.3f} m"
            f"  RMSE {ge['rmse_m']:.3f} m (cell z minus the true seabed at its centre)"
        )
    for c in evaluation["features"]["cubes"]:
        log(
            f"  cube {c['size_m']:g} m at ({c['x_m']:.1f}, {c['y_m']:.1f}), top"
            f" {c['top_depth_m']:.1f} m, {c['density_per_m2']:.2f} soundings/m²:"
            f" {c['points_on_top']} on top, grid {'shows' if c['grid_shows'] else 'no'},"
            f" class 43 {c['object_points']}: {'DETECTED' if c['detected'] else 'not detected'}"
        )
    log(
        f"  grid datum: water level {datum.water_level_m:+.3f} m ({datum.source}, "
        f"{datum.n_surface_points} surface points); true mean level {true_level_m:+.3f} m"
    )
    orders = unc.summary.get("orders", {})
    log(
        "  strictest IHO S-44 order met per cell (from the propagated uncertainty): "
        + ", ".join(
            f"{k} {v['fraction']:.1%}" for k, v in orders.items() if v["fraction"] is not None
        )
    )
    lo = unc.left_out
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
    return evaluation


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
