# ruff: noqa: E501, E702, E731  (the diagnosis scripts as they were run; issue 13, session 7)
"""Scratch: class 40/43 errors and TPU coverage of processing on a cached simulation."""

import pickle
import sys

import numpy as np

from pipeline.evaluate_coverage import tpu_coverage
from pipeline.optics import SPEED_OF_LIGHT_M_S as C
from pipeline.process.classify import SEABED_CLASSES
from pipeline.process.context import processing_context, with_measured_attenuation
from pipeline.process.datum import survey_datum
from pipeline.process.grid import grid_seabed, snap_bounds_m
from pipeline.process.survey_points import process_detections
from pipeline.scene import load_scene
from pipeline.uncertainty.survey_uncertainty import survey_uncertainty

for pk in sys.argv[1:]:
    D = pickle.load(open(pk, "rb"))
    sim = D["sim"]
    scene = load_scene(D["scene_path"])
    ctx = processing_context(scene)
    ret = sim.returns
    if sim.no_bottom is not None:
        r_air = C * ret.t_surface_s[ret.has_surface] / (2.0 * ctx.instrument.air_index)
        ctx = with_measured_attenuation(
            ctx, sim.no_bottom.get("column_decay_per_m"), float(np.median(r_air))
        )
    ps, fr = scene.process, scene.frame
    proc = process_detections(ret, ctx, ps.classify, water_column=False)
    pts = proc.points
    sel = np.isin(pts.classification, np.asarray(SEABED_CLASSES, np.uint8))
    x, y, pid = pts.xyz_m[sel, 0], pts.xyz_m[sel, 1], pts.pulse_id[sel]
    td = sim.truth.depth_at_pulses_m(x, y, pid)
    e = pts.depth_m[sel] - td
    s = f"{pk.split('/')[-1]:24s} n {sel.sum()} bias {e.mean():+.4f} rmse {np.sqrt(np.mean(e * e)):.4f} |"
    for lo, hi in ((1, 3), (3, 6), (6, 10), (10, 20), (20, 40)):
        m = (td >= lo) & (td < hi)
        s += (
            f" {e[m].mean():+.3f}/{np.sqrt(np.mean(e[m] ** 2)):.3f}"
            if m.sum() > 50
            else "      -     "
        )
    origin = (fr.origin_easting_m, fr.origin_northing_m, 0.0)
    xmin, xmax, ymin, ymax = sim.extent_m
    bounds = snap_bounds_m(
        np.array([xmin, xmax]), np.array([ymin, ymax]), ps.grid_resolution_m, origin
    )
    datum = survey_datum(pts, ps.datum)
    grid = grid_seabed(
        pts,
        ps.grid_resolution_m,
        bounds_m=bounds,
        origin_m=origin,
        crs=fr.crs,
        datum_m=datum.water_level_m,
        statistic=ps.grid_statistic,
    )
    unc = survey_uncertainty(ret, proc, ctx, grid)
    cov = tpu_coverage(
        unc.points40, unc.tpu40.sigma_depth_m, truth_depth_m=sim.truth.depth_at_pulses_m
    )
    fr68 = [round(v["fraction_within"], 3) for v in cov["intervals"]]
    print(
        s, "| TPU 68/95", fr68, "med|e|/s", round(cov["median_abs_error_over_sigma"], 2), flush=True
    )
