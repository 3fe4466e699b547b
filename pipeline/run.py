"""Orchestration: the only place that knows the order of the stages; it runs the plan."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

from pipeline.outputs.atomic import write_json
from pipeline.provenance import provenance
from pipeline.scene import Scene
from pipeline.stages import StageClock, peak_rss_mb, plan

__all__ = ["run_scene", "existing_outputs", "clear_outputs"]

#: Files a run writes (the figure names by pattern): an output folder holding any of them
#: already holds outputs.
OUTPUT_PATTERNS = (
    "manifest.json",
    "evaluation.json",
    "evaluation_points.npz",
    "points.laz",
    "grid.tif",
    "grid.nc",
    "photon_budget.json",
    "fig*.png",
    "report.html",
    "view/*.vtp",
    "view/screenshot.png",
)


def existing_outputs(out_dir: str | Path) -> list[str]:
    """Earlier outputs in ``out_dir``, relative to it (empty when it is missing or holds none)."""
    out = Path(out_dir)
    if not out.is_dir():
        return []
    return sorted({p.relative_to(out).as_posix() for pat in OUTPUT_PATTERNS for p in out.glob(pat)})


def clear_outputs(out_dir: str | Path) -> None:
    """Remove earlier outputs from ``out_dir`` (only the files a run writes), so none mixes in."""
    for name in existing_outputs(out_dir):
        (Path(out_dir) / name).unlink()


def run_scene(
    scene: Scene,
    out_dir: str | Path,
    log=print,
    *,
    progress: bool = False,
    workers: int | None = 1,
    scheduler: str | None = None,
) -> dict[str, Any]:
    """Run exactly the stages the scene's plan selects and write its outputs into ``out_dir``.

    Parameters
    ----------
    scene : Scene
        A validated scene (:func:`pipeline.scene.load_scene`).
    out_dir : str or Path
        Output folder, created if missing.
    log : callable
        Receives one line of progress at a time (``print`` by default).
    progress : bool
        Show progress bars with ETA (on stderr) for the long stages.
    workers : int or None
        Processes for the survey's chunk loop: 1 runs it here, ``None`` uses every core (or,
        with ``scheduler``, the cluster's threads). The outputs do not depend on it.
    scheduler : str or None
        Address of a Dask distributed scheduler to run the chunk loop on.

    Returns
    -------
    dict
        The manifest also written to ``out_dir/manifest.json``: the scene, the plan with each
        stage's wall and CPU seconds, the files and the evaluation.
    """
    out = Path(out_dir)
    the_plan = plan(scene)
    for line in the_plan.lines():
        log(line)
    clock = StageClock()
    files: dict[str, Path] = {}
    t0 = time.perf_counter()
    if the_plan.runs("photon_budget"):
        from pipeline.outputs import profiler_report

        with clock.stage("photon_budget"):
            res = profiler_report.compute_budget(scene)
        with clock.stage("photon_histograms"):
            res.update(profiler_report.compute_histograms(scene))
        with clock.stage("profiler_figures"):
            files.update(
                profiler_report.write_report(scene, profiler_report.ProfilerResults(res), out)
            )
        b = res["budget"]
        log(
            f"  surface: {b.surface_photons:.4g} photoelectrons/shot; "
            f"floor at {scene.seabed.depth_m:g} m: {b.floor_photons:.4g} photoelectrons/shot"
        )
    evaluation = None
    execution = {"workers": 1, "scheduler": None, "engine": "serial", "map_wall_s": 0.0}
    if the_plan.runs("terrain"):
        from pipeline.feasibility import blocked_grid_cells, check_disk
        from pipeline.parallel import Executor, stage_threads
        from pipeline.run_survey import run_survey
        from pipeline.simulate.trajectory import plan_lines

        lines = plan_lines(scene.flight, scene.scanner)
        cells = blocked_grid_cells(scene, lines)
        check_disk(lines.n_pulses_total, out, cells, scene.process.grid_resolution_m)

        with Executor(workers, scheduler) as executor, stage_threads(executor.local_threads):
            survey_files, evaluation = run_survey(
                scene, the_plan, out, clock, log, progress, executor=executor
            )
            execution = executor.describe()
        files.update(survey_files)
    stages = clock.to_dict()
    manifest = {
        "scene": scene.to_dict(),
        "plan": [
            {"stage": s.name, "runs": s.runs, "reason": s.reason, **stages.get(s.name, {})}
            for s in the_plan
        ],
        # timed parts outside the plan's stages (a blocked survey's block passes)
        "other_stages": {k: v for k, v in stages.items() if k not in {s.name for s in the_plan}},
        "files": {k: Path(v).relative_to(out).as_posix() for k, v in files.items()},
        "timings_s": {"total_wall_s": time.perf_counter() - t0},
        # this process's high-water mark (each stage's own peak is in its plan entry)
        "memory": {"peak_rss_mb": peak_rss_mb()},
        # where the chunk loop ran (the chunk and block stages' seconds add up every worker's)
        "execution": execution,
        "evaluation": evaluation,
        "provenance": provenance(scene),
    }
    write_json(out / "manifest.json", manifest)
    for key, path in files.items():
        log(f"  wrote {key}: {path}")
    return manifest
