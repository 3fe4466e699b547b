"""Orchestration: the only place that knows the order of the stages."""

from __future__ import annotations

import platform
import time
from pathlib import Path
from typing import Any

import numpy as np

from pipeline.outputs import profiler_report
from pipeline.outputs.atomic import write_json
from pipeline.scene import Scene, plan_stages

__all__ = ["run_scene"]


def run_scene(scene: Scene, out_dir: str | Path, log=print) -> dict[str, Any]:
    """Run every stage the scene needs and write its outputs into ``out_dir``.

    Parameters
    ----------
    scene : Scene
        A validated scene (:func:`pipeline.scene.load_scene`).
    out_dir : str or Path
        Output folder, created if missing.
    log : callable
        Receives one line of progress at a time (``print`` by default).

    Returns
    -------
    dict
        The manifest also written to ``out_dir/manifest.json``: files, stage timings, plan.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    plan = plan_stages(scene)
    for stage, runs, reason in plan:
        log(f"  {'run ' if runs else 'skip'} {stage:<18} {reason}")
    timings = {}
    files: dict[str, Path] = {}
    t0 = time.perf_counter()
    if scene.profiler is not None:
        results = profiler_report.compute(scene)
        timings["photon_budget+histograms_s"] = time.perf_counter() - t0
        t1 = time.perf_counter()
        files.update(profiler_report.write_report(scene, results, out))
        timings["figures_s"] = time.perf_counter() - t1
        b = results["budget"]
        log(
            f"  surface: {b.surface_photons:.4g} photoelectrons/shot; "
            f"floor at {scene.seabed.depth_m:g} m: {b.floor_photons:.4g} photoelectrons/shot"
        )
    if scene.flight is not None:
        survey_files, survey_timings = run_survey(scene, out, log)
        files.update(survey_files)
        timings.update(survey_timings)
    manifest = {
        "scene": scene.to_dict(),
        "plan": [{"stage": s, "runs": r, "reason": why} for s, r, why in plan],
        "files": {k: str(v.name) for k, v in files.items()},
        "timings_s": timings,
        "versions": {"python": platform.python_version(), "numpy": np.__version__},
    }
    write_json(out / "manifest.json", manifest)
    for key, path in files.items():
        log(f"  wrote {key}: {path}")
    return manifest


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


def run_survey(scene: Scene, out: Path, log=print) -> tuple[dict[str, Path], dict[str, float]]:
    """Terrain, survey and trace stages, streamed chunk by chunk.

    Returns
    -------
    files : dict of str to Path
    timings_s : dict of str to float
    """
    from pipeline.simulate import paths as P
    from pipeline.simulate import survey
    from pipeline.simulate.trace import trace
    from pipeline.simulate.world import build_truth, build_world

    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    lines = survey.plan_lines(scene.flight, scene.scanner)
    extent = survey_extent_m(scene, lines)
    truth = build_truth(scene, extent)
    world = build_world(scene, truth, extent)
    timings["terrain_s"] = time.perf_counter() - t0
    log(
        f"  {lines.n_lines} lines, {lines.n_pulses_total} pulses, swath "
        f"{lines.swath_width_m:.1f} m, spacing {lines.line_spacing_m:.1f} m"
    )
    div_rad = scene.scanner.beam_divergence_mrad * 1e-3
    counts = {"ok": 0, "miss": 0, "land": 0, "no_bottom": 0, "tir_return": 0}
    t_survey = t_trace = 0.0
    n_pulses = 0
    for chunk in range(survey.n_chunks(lines, scene.run.chunk_pulses)):
        t1 = time.perf_counter()
        pulses = survey.generate_pulses(
            scene.flight,
            scene.attitude,
            scene.navigation,
            scene.scanner,
            lines,
            chunk,
            scene.run.chunk_pulses,
            scene.scene.seed,
        )
        t2 = time.perf_counter()
        paths = trace(pulses, world, scene.trace, div_rad, scene.scanner.polarisation)
        t3 = time.perf_counter()
        t_survey += t2 - t1
        t_trace += t3 - t2
        n_pulses += paths.n_pulses
        for key, value in P.describe_flags(paths.flags).items():
            counts[key] += value
    timings["survey_s"] = t_survey
    timings["trace_s"] = t_trace
    n_rays = n_pulses * scene.trace.subrays
    summary = {
        "lines": lines.n_lines,
        "pulses": n_pulses,
        "subrays_per_pulse": scene.trace.subrays,
        "swath_width_m": lines.swath_width_m,
        "line_spacing_m": lines.line_spacing_m,
        "extent_m": list(extent),
        "subray_flags": counts,
        "trace_rays_per_s": n_rays / t_trace if t_trace > 0 else None,
    }
    path = out / "trace_summary.json"
    write_json(path, summary)
    log(f"  traced {n_rays} sub-rays in {t_trace:.2f} s; flags {counts}")
    return {"trace_summary": path}, timings
