"""The end of ``bathy run``'s survey: posteriors, outputs, views, evaluation and the report.

Shared by a survey processed whole (:func:`pipeline.run_survey.run_survey`) and one processed
block by block (:mod:`pipeline.survey_blocks`), whose evaluation is that of its sample.
"""

from __future__ import annotations

from pipeline.stages import trim_heap

__all__ = ["log_cleanup", "finish_survey"]


def log_cleanup(log, processed, n_objects: int, rejected, ps, covered: float) -> None:
    """The coverage, objects, withheld claims and rejections, as ``bathy run`` reports them."""
    cell = ps.grid_resolution_m
    log(f"  coverage: {covered:.0%} of flight.area_m has a point in its {cell:g} m cell")
    if covered < 0.5:
        log(
            f"  WARNING: the flight plan leaves {1.0 - covered:.0%} of flight.area_m without a"
            " point: check flight.area_m, n_lines, line_length_m and the swath"
        )
    log(f"  submerged objects: {n_objects} seabed points stand above the local seabed (class 43)")
    n_held, cl = processed.claims_withheld, ps.classify
    log(
        f"  class-45 claims withheld (a sounding within {cl.no_bottom_radius_m:g} m or land "
        f"within {cl.no_bottom_land_radius_m:g} m shallower): {n_held}"
    )
    log(f"  rejected bathymetric points (class 7, withheld): {rejected}")


def finish_survey(
    scene, plan, out, clock, log, progress, executor, sim, ctx, made, covered, deliver, extra=None
):
    """Posteriors, outputs, views, evaluation and report of a processed survey.

    ``made``: :func:`~pipeline.survey_processing.process_survey` of ``sim.returns``;
    ``deliver(unc, grid) -> (files, view_order)`` writes the points and the grid (in the
    outputs stage) and gives the rows of ``made.processed.points`` in the points file's order
    (the views show them so: a view's point i is the LAS's point i);
    ``extra``: entries added to ``evaluation.json`` (and the report) before the report.

    Returns
    -------
    files : dict of str to Path
    evaluation : dict
    """
    fr = scene.frame
    origin = (fr.origin_easting_m, fr.origin_northing_m, 0.0)
    processed, unc, grid, datum = made.processed, made.unc, made.grid, made.datum
    post = None
    if plan.runs("posterior"):
        from pipeline.parallel import kernel_threads

        threads = executor.local_threads if executor is not None else 1
        with clock.stage("posterior"), kernel_threads(threads):
            # imported here: a survey without posteriors never imports emcee
            from pipeline.uncertainty.survey_posterior import survey_posteriors
            from pipeline.uncertainty.survey_uncertainty import with_posteriors

            post = survey_posteriors(
                scene, sim.returns, sim.kept, processed, ctx, unc, grid, progress=progress
            )
            if post is not None and post.posteriors is not None:
                p = post.posteriors
                # the waveform's own sigma: the cells add the TPU's other terms themselves
                std = p.depth_m["std"] if p.waveform_std_m is None else p.waveform_std_m
                unc = with_posteriors(unc, grid, post.point_index, p.converged, std)
    trim_heap()  # the TPU's and the cleanup's freed temporaries: the stages below start low
    with clock.stage("outputs"):
        files, view_order = deliver(unc, grid)
    trim_heap()
    pictures = None  # left out by the plan (run.views = false)
    if plan.runs("views"):
        with clock.stage("views"):
            # the evaluation side (the truth's seabed and water, the points' errors); a failure
            # costs only the views (one warning line)
            from pipeline.outputs.view_render import write_views

            # in the LAS's order, made here and let go after: ~80 B a point that the
            # evaluation does not need held beside its own arrays
            view_points = processed.points.select(view_order)
            vtp, pictures = write_views(out / "view", view_points, sim, origin, fr.crs, log)
            files.update({f"view_{k}": p for k, p in vtp.items()})
            del view_points
        trim_heap()  # the rendering's buffers
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
        if extra:
            from pipeline.outputs.atomic import write_json

            evaluation.update(extra)
            write_json(files["evaluation"], evaluation)
        files["evaluation_points"] = out / "evaluation_points.npz"
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
            views=pictures,
        )
    return files, evaluation
