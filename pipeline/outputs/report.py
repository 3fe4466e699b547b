"""``report.html``: one self-contained page per survey run, in the order a hydrographer reads.

Scene and stage plan (with times), coverage, example waveforms, depth, TVU, IHO S-44 orders,
error against the truth, uncertainty calibration, depth limits, feature detection. Figures are
PNGs embedded as base64 ``data:`` URIs: the page loads no external resource.

Written by the evaluate stage of :mod:`pipeline.run_survey`, which alone may meet the truth
(``sim.truth``): the errors are recomputed here with the same functions and truth callables as
:mod:`pipeline.survey_report` (the maps and histograms need them per point and per cell).
Profiler scenes get no report: their figures are their output
(:mod:`pipeline.outputs.profiler_report`).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from pipeline.evaluate import error_stats, grid_errors_m, point_errors_m
from pipeline.evaluate_coverage import tpu_coverage
from pipeline.iho import tvu_allowance_m
from pipeline.outputs import report_figures as F
from pipeline.outputs.atomic import atomic_path
from pipeline.outputs.report_html import img, page, para, table
from pipeline.outputs.report_view3d import view3d_section
from pipeline.outputs.report_waveforms import posterior_system, waveform_section
from pipeline.outputs.sweep_report import run_report_section
from pipeline.process.classify import BATHYMETRIC_POINT, NO_BOTTOM_FOUND_AT
from pipeline.process.grid import cell_centres_m
from pipeline.process.grid_axes import held_index

__all__ = ["write_survey_report", "depth_bands"]

#: Class of the no-bottom-found-at points (pipeline.process.classify).
NO_BOTTOM_CLASS = NO_BOTTOM_FOUND_AT
#: Coverage factors of the TPU calibration plot.
CALIBRATION_KS = (0.5, 1.0, 1.5, 1.96, 2.5, 3.0)


def depth_bands(true_depth_m: np.ndarray, err_m: np.ndarray, n_target: int = 6) -> list[dict]:
    """Error statistics per band of true depth (bands 1, 2 or 5 × 10^n m wide, ~``n_target``).

    Returns one dict per non-empty band: ``from_m``, ``to_m``, the :class:`ErrorStats` fields
    and ``special_m``, the Special-order TVU allowance at the band's middle.
    """
    ok = np.isfinite(true_depth_m) & np.isfinite(err_m)
    d, e = true_depth_m[ok], err_m[ok]
    if not d.size:
        return []
    raw = max(float(d.max() - d.min()), 1e-3) / n_target
    decade = 10.0 ** math.floor(math.log10(raw))
    step = next(m * decade for m in (1, 2, 5, 10) if m * decade >= raw)
    start = math.floor(d.min() / step) * step
    # the last band holds the deepest point (bands are [from, to))
    edges = start + step * np.arange(int((d.max() - start) // step) + 2)
    out = []
    for lo, hi in zip(edges[:-1], edges[1:], strict=True):
        sel = (d >= lo) & (d < hi)
        if sel.any():
            st = error_stats(e[sel]).to_dict()
            special = float(tvu_allowance_m(0.5 * (lo + hi), "special"))
            out.append({"from_m": float(lo), "to_m": float(hi), **st, "special_m": special})
    return out


def _stage_rows(plan, clock) -> list[list[Any]]:
    times = clock.to_dict()
    rows = []
    for st in plan:
        t = times.get(st.name)
        if st.runs and t is None and st.name == "evaluate":
            wall = cpu = "running (writes this report)"
        else:
            wall = None if t is None else t["wall_s"]
            cpu = None if t is None else t["cpu_s"]
        rows.append([st.name, "run" if st.runs else "skip", wall, cpu, st.reason])
    wall, cpu = (sum(t[k] for t in times.values()) for k in ("wall_s", "cpu_s"))
    return [*rows, ["total so far", "", wall, cpu, "the stages timed before this report"]]


def write_survey_report(
    path: Path, scene, plan, sim, processed, ctx, grid, unc, post, evaluation, clock, views=None
) -> Path:
    """Write ``report.html`` at ``path`` (atomically) and return the path.

    Parameters are those of :func:`pipeline.survey_report.evaluate_survey` (plus the ``plan``
    and the ``evaluation`` it returned); ``sim.truth`` is read for the errors only. ``views``:
    the 3D pictures, ``(png, alt)`` each (:func:`pipeline.outputs.view_render.write_views`); None
    when the run left the views out.
    """
    truth, pts = sim.truth, processed.points
    level_m = scene.water_surface.level_m
    fl, res = scene.flight, grid.resolution_m
    gx, gy, shown = map_cells(grid)
    s = []
    info = [
        ["scene", scene.scene.name],
        ["description", scene.scene.description],
        ["receiver", scene.detector.mode],
        ["pulses", evaluation["pulses"]],
        ["lines", f"{sim.lines.n_lines}, swath {sim.lines.swath_width_m:.1f} m"],
        ["altitude (m), pulse rate (Hz)", f"{fl.altitude_m:g}, {scene.scanner.prf_hz:g}"],
        ["area asked: flight.area_m (m)", str(list(fl.area_m))],
        ["grid cell (m)", res],
        ["seed", scene.scene.seed],
    ]
    echoes = evaluation.get("surface_echoes")
    if echoes:  # how the surface was timed where its echo was ambiguous (surface_echo_mix)
        weak = echoes.get("weak_echoes") or {}
        found = (
            f"; weak echoes found (excess {100.0 * weak['excess']:.0f} % over noise's, "
            f"z {weak['z']:.1f}){'' if weak['taken'] else ', not taken: clear echoes common'}"
            if weak.get("echoes")
            else ""
        )
        ws = [b["weight"] for b in echoes.get("bands") or []]
        weighs = f"{echoes['weight']:.3f}"
        if len(ws) > 1:  # one weight per band of the beams' off-nadir angle
            weighs = f"{min(ws):.3f}-{max(ws):.3f} by off-nadir angle"
        info.append(
            [
                "surface echoes: clear, ambiguous",
                f"{echoes['clear']}, {echoes['ambiguous']}: an ambiguous one weighs the "
                f"echo-kept fit {weighs}{found}",
            ]
        )
    s.append("<h2 id='scene'>1. Scene and stage plan</h2>" + table(["", ""], info))
    s.append(
        table(["stage", "", "wall (s)", "CPU (s)", "what / why not"], _stage_rows(plan, clock))
    )
    s.append("<h2 id='coverage'>2. Coverage</h2>")
    s.append(
        img(
            F.coverage_map(
                gx,
                gy,
                res,
                shown(grid.count, 0),
                fl.area_m,
                evaluation["area_covered"],
                colour_limits(np.where(grid.count > 0, grid.count / res**2, np.nan)),
            ),
            "coverage",
        )
    )
    s.append(
        "<h2 id='waveforms'>3. Example waveforms</h2>"
        + waveform_section(sim, ctx, pts, post, posterior_system(scene, ctx, post))
    )
    depth = np.where(grid.count > 0, grid.depth_m, np.nan)
    for sec, values, label, title, cmap in (
        (
            "depth",
            depth,
            "depth below the datum (m)",
            "Gridded depth (mean of class 40)",
            "viridis_r",
        ),
        ("tvu", unc.cells.tvu95_m, "TVU at 95 % (m)", "Propagated TVU (95 %) per cell", "magma_r"),
    ):
        heading = "4. Depth" if sec == "depth" else "5. Total vertical uncertainty"
        fig = F.grid_map(
            gx, gy, res, shown(values, np.nan), fl.area_m, label, title, cmap,
            colour_limits(values),
        )  # fmt: skip
        s.append(f"<h2 id='{sec}'>{heading}</h2>" + img(fig, f"{sec} map"))
    s.append("<h2 id='iho'>6. IHO S-44 orders</h2>")
    labels = list(unc.summary["orders"])
    codes = shown(unc.cells.order, -1)
    s.append(img(F.order_map(gx, gy, res, codes, labels, fl.area_m), "IHO order map"))
    iho_truth = evaluation["error"].get("iho_grid") or {}
    rows = []
    for lab, v in unc.summary["orders"].items():
        key = "1a" if lab == "1a/1b" else lab
        t = iho_truth.get(key, {}).get("fraction_within")
        rows.append([lab, v["count"], v["fraction"], v["at_least"], t])
    s.append(
        table(
            [
                "order",
                "cells (strictest met)",
                "fraction",
                "this or stricter",
                "grid cells within its TVU (truth)",
            ],
            rows,
        )
    )
    s.append(
        para(
            f"{unc.summary['n_cells']} cells with data; the order met comes from the propagated"
            " uncertainty, the last column from the error against the truth."
        )
    )
    s.append(_error_section(truth, pts, grid, level_m, fl.area_m, evaluation))
    s.append(_calibration_section(unc, ctx, truth, evaluation, sim.returns))
    s.append(_limits_section(pts, evaluation))
    s.append(_features_section(scene, evaluation))
    s.append(view3d_section(views))
    s.append(run_report_section(Path(path).parent))
    with atomic_path(path) as tmp:
        tmp.write_text(page(f"bathy report: {scene.scene.name}", s), encoding="utf-8")
    return Path(path)


def map_cells(grid):
    """What a map of ``grid`` shows: ``x_m (nx,)``, ``y_m (ny,)`` and ``shown(values, empty)``.

    ``x_m``, ``y_m``: the whole grid's cell centres (the map's extent). ``shown`` gives a field
    ``(ny, nx)`` of ``grid`` at most :data:`~pipeline.outputs.report_figures.MAP_CELLS` cells
    a side of the whole grid (nearest, :func:`~pipeline.outputs.report_figures.nearest_cells`),
    ``empty`` in the cells a grid of some rows and columns (a blocked survey's sample) does not
    hold.
    """
    if getattr(grid, "rows", None) is None:
        ri, ci = (F.nearest_cells(n) for n in grid.shape)
        return grid.x_m, grid.y_m, lambda values, empty: np.asarray(values)[np.ix_(ri, ci)]
    x_m, y_m = cell_centres_m(grid.bounds_m, grid.resolution_m)
    ri, ci = F.nearest_cells(y_m.size), F.nearest_cells(x_m.size)
    (r, r_ok), (c, c_ok) = held_index(ri, grid.rows), held_index(ci, grid.cols)
    held = r_ok[:, None] & c_ok[None, :]

    def shown(values, empty):
        values = np.asarray(values)
        if values.size == 0:  # no cell held: nothing to index
            return np.full(held.shape, empty, dtype=np.result_type(values, type(empty)))
        return np.where(held, values[np.ix_(r, c)], empty)

    return x_m, y_m, shown


def colour_limits(values) -> tuple[float | None, float | None]:
    """``(min, max)`` of the finite ``values`` (all of a field's cells, not those a map shows)."""
    v = np.asarray(values, dtype=np.float64)
    ok = np.isfinite(v)
    return (float(v[ok].min()), float(v[ok].max())) if ok.any() else (None, None)


def _error_section(truth, pts, grid, level_m, area_m, evaluation) -> str:
    is40 = pts.select(pts.classification == BATHYMETRIC_POINT)
    err, true_d = point_errors_m(is40, truth_depth_m=truth.depth_at_pulses_m)
    gerr, _ = grid_errors_m(grid, truth_depth_m=lambda x, y: level_m - truth.seabed.height_m(x, y))
    bands = depth_bands(true_d, err)
    gx, gy, shown = map_cells(grid)
    lim = float(np.nanpercentile(np.abs(gerr), 98)) if np.isfinite(gerr).any() else 1.0
    fig = F.error_figure(
        gx, gy, grid.resolution_m, shown(gerr, np.nan), area_m, err, true_d, bands, lim
    )
    ev = evaluation["error"]
    rows = [
        [name, st["n"], st["bias_m"], st["std_m"], st["rmse_m"], st["p95_abs_m"], st["max_abs_m"]]
        for name, st in (
            ("points, refraction corrected", ev["points"]),
            ("points, uncorrected", ev.get("points_uncorrected")),
            ("grid cells", ev.get("grid")),
        )
        if st
    ]
    band_rows = [
        [
            f"{b['from_m']:g}–{b['to_m']:g}",
            b["n"],
            b["bias_m"],
            b["rmse_m"],
            b["p95_abs_m"],
            b["special_m"],
        ]
        for b in bands
    ]
    return (
        "<h2 id='error'>7. Error against the truth</h2>"
        + img(fig, "error against truth")
        + para(ev["sign"] + "; points: depth below the local water surface, grid: below the datum.")
        + table(["", "n", "bias (m)", "sd (m)", "RMSE (m)", "|error| 95 % (m)", "max (m)"], rows)
        + table(
            [
                "true depth (m)",
                "points",
                "bias (m)",
                "RMSE (m)",
                "|error| 95 % (m)",
                "Special TVU (m)",
            ],
            band_rows,
        )
    )


def _calibration_section(unc, ctx, truth, evaluation, returns) -> str:
    group = None
    if ctx.instrument.photon_counting:  # as the evaluate stage: a window's shots are one draw
        group = ctx.instrument.windows.of_points(unc.points40.pulse_id, returns)
    cov = tpu_coverage(
        unc.points40,
        unc.tpu40.sigma_depth_m,
        truth_depth_m=truth.depth_at_pulses_m,
        ks=CALIBRATION_KS,
        group=group,
    )
    post = evaluation.get("posterior_against_truth")
    post = post if post and post.get("n") else None
    rows = [
        [c["k"], c["nominal"], c["fraction_within"], c["standard_error"]] for c in cov["intervals"]
    ]
    text = (
        f"True depth within ±k σ_depth of the measured depth, {cov['n']} class-40 points with a "
        "TPU; a calibrated σ follows the nominal curve."
    )
    if post is None:
        text += " Depth posteriors did not run: no posterior coverage."
    return (
        "<h2 id='calibration'>8. Uncertainty calibration</h2>"
        + img(F.calibration(cov["intervals"], post), "calibration")
        + para(text)
        + table(["k", "nominal", "observed", "standard error"], rows)
    )


def _limits_section(pts, evaluation) -> str:
    d40 = pts.depth_m[pts.classification == BATHYMETRIC_POINT]
    d45 = pts.depth_m[pts.classification == NO_BOTTOM_CLASS]
    shallow = float(np.percentile(d40, 1)) if d40.size else None
    deep = float(np.percentile(d40, 99)) if d40.size else None
    nb = evaluation.get("no_bottom")
    rows = [
        ["shallow limit: 1st percentile of class-40 depths (m)", shallow],
        ["shallowest class-40 depth (m)", float(d40.min()) if d40.size else None],
        ["extinction depth: 99th percentile of class-40 depths (m)", deep],
        ["deepest class-40 depth (m)", float(d40.max()) if d40.size else None],
        ["class-45 (no bottom down to) points", int(d45.size)],
        ["median class-45 limit depth (m)", float(np.median(d45)) if d45.size else None],
    ]
    if nb:
        rows += [[f"no_bottom: {k}", v] for k, v in nb.items()]
    text = (
        "The deepest bottoms found are the extinction depth only where the bottom was lost "
        f"there: class-45 points (no bottom down to the pulse's detection limit) mark it; here "
        f"{d45.size} class-45 against {d40.size} class-40 points. Without them, the deepest "
        "bottoms found are the deepest seabed the survey covered."
    )
    return (
        "<h2 id='limits'>9. Depth limits</h2>"
        + img(F.depth_limits(d40, d45, shallow, deep), "depth limits")
        + para(text)
        + table(["", "value"], rows)
    )


def _features_section(scene, evaluation) -> str:
    head = "<h2 id='features'>10. Feature detection</h2>"
    if not scene.seabed.features:
        return head + para("The scene has no seabed features.")
    feats = evaluation.get("features") or {}
    found = feats.get("cubes") or []
    rule = (
        "Rule: a cube is detected when a seabed sounding (class 40 or 43) inside its "
        "footprint lies within half its side of the true depth of its top, or when the grid "
        "cell at its centre is shallower than its neighbours' median by more than half its "
        "side (IHO S-44 cubes; other features are not scored). Class 43: submerged-object points "
        "found by processing within 1 m of it. Density: soundings per m² in its footprint "
        f"grown by 1 m. Class-43 points in the survey: {feats.get('object_points', 0)}, "
        f"{feats.get('object_points_elsewhere', 0)} of them away from every cube."
    )
    if not found:
        return head + para(rule) + para("The scene's features include no cube.")
    rows = [
        [
            f["x_m"],
            f["y_m"],
            f["size_m"],
            f["top_depth_m"],
            f["density_per_m2"],
            f["points_in_footprint"],
            f["points_on_top"],
            "yes" if f["grid_shows"] else "no",
            f["object_points"],
            "yes" if f["detected"] else "no",
        ]
        for f in found
    ]
    hdr = [
        "x (m)",
        "y (m)",
        "side (m)",
        "top depth (m)",
        "soundings/m²",
        "points in footprint",
        "on top",
        "grid shows",
        "class 43",
        "detected",
    ]
    return head + para(rule) + table(hdr, rows)
