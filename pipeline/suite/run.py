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
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from pipeline.suite.generate import Draw, write_scene

__all__ = ["RunResult", "run_one", "run_suite", "collect"]


@dataclass(frozen=True)
class RunResult:
    """One scene's run: its draw, where its outputs are, exit status and wall time."""

    draw: Draw
    out: Path
    returncode: int
    wall_s: float

    @property
    def ok(self) -> bool:
        """The run finished and wrote its evaluation."""
        return self.returncode == 0 and (self.out / "evaluation.json").is_file()


def _command(scene: Path, out: Path, nice: int) -> list[str]:
    cmd = [sys.executable, "-m", "pipeline.cli", "run", str(scene), "--out", str(out)]
    cmd += ["--overwrite", "--quiet", "--json"]
    return (["nice", "-n", str(nice)] + cmd) if nice else cmd


def _earlier(d: Draw, out: Path) -> RunResult | None:
    """The finished earlier run of the same draw in ``out``, if any (``reuse``)."""
    try:
        status = json.loads((out / "status.json").read_text())
    except (OSError, ValueError):
        return None
    if status.get("draw") != d.to_dict() or status.get("returncode") != 0:
        return None
    r = RunResult(d, out, 0, float(status["wall_s"]))
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
    try:
        proc = subprocess.run(
            _command(scene, out, nice),
            capture_output=True,
            text=True,
            env=env,
            timeout=timeout_s,
            check=False,
        )
        code, err = proc.returncode, proc.stderr
    except subprocess.TimeoutExpired as exc:
        code, err = -9, f"timeout after {timeout_s:g} s\n{exc.stderr or ''}"
    wall = time.perf_counter() - t0
    (out / "stderr.txt").write_text(err if isinstance(err, str) else err.decode())
    status = {"returncode": code, "wall_s": wall, "draw": d.to_dict()}
    (out / "status.json").write_text(json.dumps(status, indent=2))
    return RunResult(d, out, code, wall)


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
            f" {r.wall_s:6.1f} s {state}"
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
        (dict of the ``evaluation_points.npz`` arrays) and ``wall_s``.
    """
    rows = []
    for r in results:
        if not r.ok:
            continue
        ev = json.loads((r.out / "evaluation.json").read_text())
        with np.load(r.out / "evaluation_points.npz") as z:
            arrays = {k: z[k] for k in z.files}
        rows.append({"draw": r.draw, "evaluation": ev, "arrays": arrays, "wall_s": r.wall_s})
    return rows
