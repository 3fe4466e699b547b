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
        Output folder, created with its first complete file (a run stopped before any output
        leaves no folder).
    log : callable
        Receives one line of progress at a time (``print`` by default).

    Returns
    -------
    dict
        The manifest also written to ``out_dir/manifest.json``: files, stage timings, plan.
    """
    out = Path(out_dir)  # made by the first atomic write, not before
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
    evaluation = None
    if scene.flight is not None:
        from pipeline.run_survey import run_survey

        survey_files, survey_timings, evaluation = run_survey(scene, out, log)
        files.update(survey_files)
        timings.update(survey_timings)
    manifest = {
        "scene": scene.to_dict(),
        "plan": [{"stage": s, "runs": r, "reason": why} for s, r, why in plan],
        "files": {k: str(v.name) for k, v in files.items()},
        "timings_s": timings,
        "evaluation": evaluation,
        "versions": {"python": platform.python_version(), "numpy": np.__version__},
    }
    write_json(out / "manifest.json", manifest)
    for key, path in files.items():
        log(f"  wrote {key}: {path}")
    return manifest
