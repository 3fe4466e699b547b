"""The scenes of a ``bathy suite`` folder, one half at a time, for the TPU diagnostics.

Shared by ``benchmarks/tpu_pair_relief.py`` and ``benchmarks/tpu_shared_draws.py``
(evaluation side: they read the truth in each run's ``evaluation_points.npz``).
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from pipeline.suite.generate import half as half_of


def suite_scenes(doc: str, receiver: str | None = None) -> Iterator[tuple[dict, dict, np.ndarray]]:
    """``(draw, points, window)`` of each run of the half asked for on the command line.

    ``doc``: the script's docstring (its first line the command's description); the command
    line is ``SUITE_OUT [--half tuning|heldout]``. ``receiver``: only the scenes of that
    receiver. ``points``: the run's ``evaluation_points.npz``; ``window``: the indices of its
    TPU points whose true depth lies in the floors' window (1 m to 0.8 of the planning
    extinction depth) with a TPU.
    """
    ap = argparse.ArgumentParser(description=doc.splitlines()[0])
    ap.add_argument("suite_out", type=Path)
    ap.add_argument("--half", default="tuning", choices=("tuning", "heldout"))
    args = ap.parse_args()
    for d in json.loads((args.suite_out / "draws.json").read_text()):
        s = d["seed"]
        path = args.suite_out / "runs" / f"suite_{s:05d}" / "evaluation_points.npz"
        if half_of(s) != args.half or not path.is_file():
            continue
        if receiver is not None and d["receiver"] != receiver:
            continue
        z = np.load(path)
        e, t, sg = z["tpu_error_m"], z["tpu_true_depth_m"], z["tpu_sigma_depth_m"]
        d_ext = min(4.5 / d["attenuation_per_m"], 60.0)  # the planning extinction depth
        yield d, z, np.flatnonzero(np.isfinite(e) & (t >= 1.0) & (t < 0.8 * d_ext) & (sg > 0))
