"""Trace throughput and peak memory for a 10-million-pulse Palmer survey streamed in chunks.

Run: .venv/bin/python benchmarks/bench_trace.py [--pulses 10000000] [--chunk 100000]
Writes nothing but stdout; results are recorded by hand in benchmarks/RESULTS_trace.md.
"""

from __future__ import annotations

import argparse
import math
import resource
import time
import tomllib
from pathlib import Path

from pipeline.run_survey import survey_extent_m
from pipeline.scene import parse_scene
from pipeline.simulate import paths as P
from pipeline.simulate import survey
from pipeline.simulate.trace import trace
from pipeline.simulate.world import build_truth, build_world

ROOT = Path(__file__).resolve().parents[1]


def peak_rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--pulses", type=int, default=10_000_000)
    ap.add_argument("--chunk", type=int, default=100_000)
    ap.add_argument("--subrays", type=int, default=1)
    ap.add_argument("--waves", action="store_true", help="wind-wave surface instead of flat")
    ap.add_argument("--mesh", type=float, default=2.0, help="seabed mesh resolution, m")
    args = ap.parse_args()

    data = tomllib.loads((ROOT / "data_synthetic/scenes/palmer_survey.toml").read_text())
    prf, speed = data["scanner"]["prf_hz"], data["flight"]["speed_m_s"]
    n_lines = 2
    length = args.pulses / prf * speed / n_lines
    data["flight"]["area_m"] = [0.0, 300.0, 0.0, math.ceil(length)]
    data["flight"]["run_in_m"] = 0.0
    data["seabed"]["mesh_resolution_m"] = args.mesh
    data["trace"] = {"subrays": args.subrays}
    data["run"] = {"chunk_pulses": args.chunk}
    if args.waves:
        data["water_surface"] = {"kind": "waves"}
    scene = parse_scene(data)

    t0 = time.perf_counter()
    lines = survey.plan_lines(scene.flight, scene.scanner)
    extent = survey_extent_m(scene, lines)
    truth = build_truth(scene, extent)
    world = build_world(scene, truth, extent)
    t_world = time.perf_counter() - t0
    rss_world = peak_rss_mb()
    ty, tx = world.seabed.shape
    print(f"world: {t_world:.1f} s, seabed {tx} x {ty} tiles, peak RSS {rss_world:.0f} MB")

    t_gen = t_trace = 0.0
    n = 0
    flags = {}
    for c in range(survey.n_chunks(lines, args.chunk)):
        t1 = time.perf_counter()
        pulses = survey.generate_pulses(
            scene.flight,
            scene.attitude,
            scene.navigation,
            scene.scanner,
            lines,
            c,
            args.chunk,
            scene.scene.seed,
        )
        t2 = time.perf_counter()
        paths = trace(pulses, world, scene.trace, 3e-3, scene.scanner.polarisation)
        t3 = time.perf_counter()
        t_gen += t2 - t1
        t_trace += t3 - t2
        n += paths.n_pulses
        for k, v in P.describe_flags(paths.flags).items():
            flags[k] = flags.get(k, 0) + v
    rays = n * args.subrays
    print(f"pulses {n}, sub-rays {rays}, chunk {args.chunk}, waves {args.waves}")
    print(f"survey generation: {t_gen:.1f} s = {n / t_gen:,.0f} pulses/s")
    print(
        f"trace: {t_trace:.1f} s = {rays / t_trace:,.0f} sub-rays/s "
        f"(each: 4 casts + float64 re-solve + Snell/Fresnel)"
    )
    print(f"flags: {flags}")
    print(f"peak RSS: {peak_rss_mb():.0f} MB (world alone {rss_world:.0f} MB)")


if __name__ == "__main__":
    main()
