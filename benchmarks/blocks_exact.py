"""A survey longer than its blocks' halo, processed whole and in blocks: the same outputs?

Usage: ``PYTHONPATH=. python benchmarks/blocks_exact.py OUT [--block-m 100] [--fire]`` (~4 min
on 2 cores).

``tests/test_survey_blocks.py`` makes the comparison on a survey small enough for CI, whose
blocks' halo covers all of it. Here the survey of that test is flown 600 m long (one line, a
7.5 kHz Palmer scan from 250 m over ``palmer_survey_waves.toml``'s wave sea, shore and turbid
water: 75 000 pulses), so each block of 100 m loads only its halo's share: what is compared
is whether every neighbour search stays inside the halo. Prints which outputs differ: every
LAS dimension (points sorted by pulse and return), every ``grid.tif`` band and every figure
of ``evaluation.json`` (the clock's readings and the blocks' own summary left out), and each
run's wall and CPU seconds with its stages' CPU. Results: ``RESULTS_e2e.md``.

At the default settings this survey has no class-43 point and no rejection, so the blocks'
class-43 and rejection tests (made only at the points a block keeps and their reach) are not
compared. ``--fire`` lowers their thresholds (``tests/test_survey_blocks.py``'s ``FIRE``:
objects ``k_sigma`` 1, ``min_height_m`` 0.05; outliers ``k_sigma`` 1, ``min_offset_m`` 0.05,
``max_order`` "special") so that both fire, and prints how many class-43 points and rejections
the whole run made (``evaluation.json``'s ``features.object_points`` and ``seabed_rejected``)
before comparing.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from pipeline.run import run_scene  # noqa: E402
from tests.test_survey_blocks import (  # noqa: E402
    FIRE,
    evaluation_figures,
    las_points_by_pulse,
    wave_survey_scene,
)


def scene(block_m: float | None, fire: bool = False):
    """The 600 m survey; ``block_m`` set: processed in blocks, every block in the sample;
    ``fire``: with the class-43 and rejection thresholds lowered (:data:`FIRE`)."""
    run = {} if block_m is None else {"block_m": block_m}
    return wave_survey_scene((0.0, 60.0, 0.0, 600.0), 7500.0, process=FIRE if fire else None, **run)


def compare(whole: Path, blocks: Path) -> list[str]:
    """Lines naming what differs (none: the same outputs)."""
    import rasterio

    out = []
    a, b = las_points_by_pulse(whole), las_points_by_pulse(blocks)
    if len(a["X"]) != len(b["X"]):
        return [f"points: {len(a['X'])} whole, {len(b['X'])} in blocks"]
    for d in a:
        if not np.array_equal(a[d], b[d]):
            out.append(f"LAS {d}: {int(np.count_nonzero(a[d] != b[d]))} points differ")
    with rasterio.open(whole / "grid.tif") as r, rasterio.open(blocks / "grid.tif") as s:
        for i, name in enumerate(r.descriptions):
            x, y = r.read(i + 1), s.read(i + 1)
            if not np.array_equal(x, y, equal_nan=True):
                same = (x == y) | (np.isnan(x) & np.isnan(y))
                out.append(f"grid band {name}: {int(np.sum(~same))} cells differ")
    if json.dumps(evaluation_figures(whole), sort_keys=True) != json.dumps(
        evaluation_figures(blocks), sort_keys=True
    ):
        out.append("evaluation.json figures differ")
    return out


def timed(data: dict, out: Path, log) -> None:
    """``run_scene`` with 1 worker; prints its wall and CPU seconds and its stages' CPU."""
    w0, c0 = time.perf_counter(), time.process_time()
    manifest = run_scene(data, out, log=log, workers=1)
    wall, cpu = time.perf_counter() - w0, time.process_time() - c0
    stages = {s["stage"]: s.get("cpu_s") for s in manifest["plan"]}
    parts = ", ".join(f"{k} {v:.1f}" for k, v in stages.items() if v is not None and v > 0.5)
    print(f"{out.name}: wall {wall:.1f} s, CPU {cpu:.1f} s (stages, CPU s: {parts})")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", type=Path)
    ap.add_argument("--block-m", type=float, default=100.0)
    ap.add_argument(
        "--fire", action="store_true", help="lower the class-43 and rejection thresholds (FIRE)"
    )
    args = ap.parse_args()
    lines: list[str] = []
    timed(scene(None, args.fire), args.out / "whole", lambda s: None)
    timed(scene(args.block_m, args.fire), args.out / "blocks", lines.append)
    print("\n".join(s for s in lines if "blocks of" in s or "halo" in s))
    print(f"points: {len(las_points_by_pulse(args.out / 'whole')['X'])}")
    ev = json.loads((args.out / "whole" / "evaluation.json").read_text())
    rej = ev["seabed_rejected"]
    print(
        f"whole run: class-43 points {ev['features']['object_points']}, rejected {rej['n']}"
        f" (TVU {rej['tvu_exceeded']}, below the seabed {rej['seabed_outlier']},"
        f" surface implausible {rej['surface_implausible']})"
    )
    diff = compare(args.out / "whole", args.out / "blocks")
    print("\n".join(diff) if diff else "identical: every LAS dimension, grid band and figure")


if __name__ == "__main__":
    main()
