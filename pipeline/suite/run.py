"""Run suite scenes with ``bathy run`` and collect what the strata need.

Each scene runs in its own process, ``bathy run SCENE --out DIR --overwrite --quiet --json``
(the project's own run machinery, exactly as a user runs it), ``K`` at a time, niced. A run
writes ``evaluation.json`` and ``evaluation_points.npz`` (:mod:`pipeline.evaluation_points`);
:func:`collect` reads them back for :mod:`pipeline.suite.strata`.

Folder layout under ``out``: ``scenes/suite_<seed>.toml``, ``runs/suite_<seed>/`` (the run's
outputs, ``stderr.txt`` and ``status.json``) and ``draws.json`` (every scene's drawn
conditions and half).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from pipeline.suite.generate import Draw
from pipeline.suite.scene_file import write_scene

__all__ = ["RunResult", "run_one", "run_suite", "collect"]


@dataclass(frozen=True)
class RunResult:
    """One scene's run: its draw, where its outputs are, exit status, wall and CPU seconds."""

    draw: Draw
    out: Path
    returncode: int
    wall_s: float
    cpu_s: float = float("nan")

    @property
    def ok(self) -> bool:
        """The run finished and wrote its evaluation."""
        return self.returncode == 0 and (self.out / "evaluation.json").is_file()


def _command(scene: Path, out: Path, nice: int) -> list[str]:
    cmd = [sys.executable, "-m", "pipeline.cli", "run", str(scene), "--out", str(out)]
    # scenes run side by side (``workers``), each on one core: no pool per scene
    cmd += ["--overwrite", "--quiet", "--json", "--workers", "1"]
    return (["nice", "-n", str(nice)] + cmd) if nice else cmd


def _earlier(d: Draw, out: Path) -> RunResult | None:
    """The finished earlier run of the same draw in ``out``, if any (``reuse``)."""
    try:
        status = json.loads((out / "status.json").read_text())
    except (OSError, ValueError):
        return None
    if status.get("draw") != d.to_dict() or status.get("returncode") != 0:
        return None
    r = RunResult(d, out, 0, float(status["wall_s"]), float(status.get("cpu_s", "nan")))
    return r if r.ok else None


def run_one(
    d: Draw, root: Path, nice: int = 10, timeout_s: float = 1800.0, reuse: bool = False
) -> RunResult:
    """Write ``d``'s scene under ``root/scenes`` and run it into ``root/runs/<name>``.

    ``reuse``: keep an earlier successful run of the identical draw instead of rerunning it.
    """
    scene = write_scene(d, root / "scenes")
    out = root / "runs" / scene.stem
    if reuse and (earlier := _earlier(d, out)) is not None:
        return earlier
    out.mkdir(parents=True, exist_ok=True)
    env = {**os.environ, "MPLBACKEND": "Agg"}
    # the project on the path of the child, wherever the suite is started from
    project = str(Path(__file__).resolve().parents[2])
    env["PYTHONPATH"] = os.pathsep.join(p for p in (project, env.get("PYTHONPATH")) if p)
    t0 = time.perf_counter()
    code, cpu = _run_child(_command(scene, out, nice), env, out / "stderr.txt", timeout_s)
    wall = time.perf_counter() - t0
    status = {"returncode": code, "wall_s": wall, "cpu_s": cpu, "draw": d.to_dict()}
    (out / "status.json").write_text(json.dumps(status, indent=2))
    return RunResult(d, out, code, wall, cpu)


def _run_child(cmd: list[str], env: dict, stderr_path: Path, timeout_s: float):
    """Run ``cmd`` (stdout dropped, stderr to a file); its exit code and CPU seconds.

    ``os.wait4`` gives the child's own rusage (user + system), which other workers' children
    do not blur; a child still running after ``timeout_s`` is killed (exit code -9).
    """
    with stderr_path.open("w") as err:
        proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=err, env=env)
        timer = threading.Timer(timeout_s, proc.kill)
        timer.start()
        try:
            _, status, usage = os.wait4(proc.pid, 0)
        finally:
            timer.cancel()
    proc.returncode = os.waitstatus_to_exitcode(status)
    return proc.returncode, usage.ru_utime + usage.ru_stime


def run_suite(
    draws: list[Draw],
    root: str | Path,
    workers: int = 1,
    nice: int = 10,
    log=print,
    reuse: bool = False,
) -> list[RunResult]:
    """Run every draw, ``workers`` at a time; log one line per finished scene.

    ``reuse``: keep earlier successful runs of identical draws (:func:`run_one`).

    Returns
    -------
    list of RunResult
        In the order of ``draws``.
    """
    root = Path(root)
    root.mkdir(parents=True, exist_ok=True)
    (root / "draws.json").write_text(json.dumps([d.to_dict() for d in draws], indent=2))

    def one(d: Draw) -> RunResult:
        r = run_one(d, root, nice, reuse=reuse)
        state = "ok" if r.ok else f"FAILED (exit {r.returncode}, see {r.out / 'stderr.txt'})"
        log(
            f"  seed {d.seed:>5} {d.half:<8} {d.receiver:<15} {d.scanner:<11}"
            f" {r.wall_s:6.1f} s wall {r.cpu_s:6.1f} s CPU {state}"
        )
        return r

    with ThreadPoolExecutor(max_workers=max(1, workers)) as pool:
        return list(pool.map(one, draws))


def collect(results: list[RunResult]) -> list[dict[str, Any]]:
    """The runs that finished: per run its draw, evaluation and point arrays.

    Returns
    -------
    list of dict
        ``draw`` (:class:`Draw`), ``evaluation`` (dict of ``evaluation.json``), ``arrays``
        (dict of the ``evaluation_points.npz`` arrays), ``wall_s`` and ``cpu_s``.
    """
    rows = []
    for r in results:
        if not r.ok:
            continue
        ev = json.loads((r.out / "evaluation.json").read_text())
        with np.load(r.out / "evaluation_points.npz") as z:
            arrays = {k: z[k] for k in z.files}
        cpu = r.cpu_s
        if not np.isfinite(cpu):  # a run from before CPU was recorded: its stages' CPU
            plan = json.loads((r.out / "manifest.json").read_text())["plan"]
            cpu = float(sum(s.get("cpu_s") or 0.0 for s in plan))
        rows.append(
            {
                "draw": r.draw,
                "evaluation": ev,
                "arrays": arrays,
                "wall_s": r.wall_s,
                "cpu_s": cpu,
            }
        )
    return rows
