"""Bytes per pulse of what a survey run holds after processing and the TPU (issue 15).

Usage: ``PYTHONPATH=. python benchmarks/resident_bytes.py N`` (the bench's Palmer scene of about
N pulses, 1 worker, posteriors off). At the evaluate stage it sums the ``nbytes`` of every array
of the detections (``sim.returns``), the processed points and surface, the TPU (``unc``), the
grid and the truth, and prints each per pulse with its largest fields: what stays in memory
and grows with the survey until the outputs are written (``RESULTS_e2e.md``).
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_e2e import palmer  # noqa: E402

import pipeline.survey_report as survey_report  # noqa: E402
from pipeline.run import run_scene  # noqa: E402
from pipeline.scene import parse_scene  # noqa: E402


def nbytes(obj) -> tuple[int, dict[str, int]]:
    """Total ``nbytes`` of the arrays in ``obj`` (dataclasses, dicts, sequences) and per field."""
    if isinstance(obj, np.ndarray):
        return obj.nbytes, {}
    items = []
    if dataclasses.is_dataclass(obj):
        items = [(f.name, getattr(obj, f.name)) for f in dataclasses.fields(obj)]
    elif isinstance(obj, dict):
        items = list(obj.items())
    elif isinstance(obj, (list, tuple)):
        items = [(str(i), v) for i, v in enumerate(obj)]
    parts = {str(k): nbytes(v)[0] for k, v in items}
    return sum(parts.values()), parts


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("pulses", type=int)
    n_req = ap.parse_args().pulses
    evaluate = survey_report.evaluate_survey

    def report(scene, sim, processed, ctx, grid, datum, unc, post, *args, **kw):
        n = len(sim.returns.pulse_id)
        print(f"# {n} pulses")
        held = [("returns", sim.returns), ("processed", processed), ("unc", unc)]
        held += [("grid", grid), ("truth", sim.truth)]
        for name, obj in held:
            total, parts = nbytes(obj)
            top = sorted(parts.items(), key=lambda kv: -kv[1])[:4]
            print(
                f"{name:10s} {total / n:6.0f} B/pulse ({total / 1e6:6.1f} MB): "
                + ", ".join(f"{k} {v / n:.0f}" for k, v in top if v)
            )
        return evaluate(scene, sim, processed, ctx, grid, datum, unc, post, *args, **kw)

    survey_report.evaluate_survey = report
    with tempfile.TemporaryDirectory() as tmp:
        scene = parse_scene(palmer(n_req, False, 20_000))
        run_scene(scene, Path(tmp) / "out", log=lambda s: None, workers=1)


if __name__ == "__main__":
    main()
