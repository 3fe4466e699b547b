"""Throughput of the waveform stage: full-waveform (1 GS/s) and photon-counting receivers.

Run: ``.venv/bin/python benchmarks/bench_waveform.py [--pulses N] [--quick]``. Not run by pytest.

Paths come from :func:`pipeline.simulate.flat_paths.flat_paths` (no ray tracer): flat water, a
planar seabed whose depth varies pulse to pulse, the preset's off-nadir angle and a random scan
azimuth. The clock covers the waveform stage only (return budget, photon draws, receiver),
chunk by chunk: on one core, on two threads, and on two processes (chunks are independent and
results do not depend on chunking, so either split is legitimate). Each number is the median of
``--repeats`` runs, because the virtual machine's timings vary by tens of percent. Peak memory
of one chunk is measured with tracemalloc in a separate run; peak RSS at the end.
"""

from __future__ import annotations

import argparse
import platform
import resource
import statistics
import time
import tomllib
import tracemalloc
from concurrent.futures import ProcessPoolExecutor, ThreadPoolExecutor

import numpy as np

from pipeline.config import from_mapping
from pipeline.scene import DEFAULT_SCENE_PATH, parse_scene
from pipeline.simulate.budget import ReturnSettings, return_budget
from pipeline.simulate.detector import DetectorSettings, describe_pulse_flags, load_preset
from pipeline.simulate.flat_paths import flat_paths
from pipeline.simulate.waveform import simulate_photon_events, simulate_waveforms

CASES = {
    # mode: (preset, altitude above the water (m), seabed depth range (m))
    "full_waveform": ("topobathy_full_waveform", 600.0, (0.5, 25.0)),
    "photon_counting": ("photon_counting", 2000.0, (0.5, 15.0)),
}


def setup(mode: str):
    """Scene (default scene + the preset's system and scanner), detector, return settings."""
    name, _, _ = CASES[mode]
    pre = load_preset(name)
    data = tomllib.loads(DEFAULT_SCENE_PATH.read_text(encoding="utf-8"))
    data["system"], data["scanner"] = pre["system"], pre["scanner"]
    scene = parse_scene(data)
    det = from_mapping(DetectorSettings, pre["detector"], "detector")
    rs = from_mapping(ReturnSettings, pre["returns"], "returns")
    return scene, det, rs


def make_paths(mode: str, n: int, first: int, n_sub: int, scene):
    _, altitude, (d0, d1) = CASES[mode]
    rng = np.random.default_rng(first)
    return flat_paths(
        n,
        altitude_m=altitude,
        depth_m=rng.uniform(d0, d1, n),
        off_nadir_rad=np.radians(scene.scanner.off_nadir_deg),
        azimuth_rad=rng.uniform(0, 2 * np.pi, n),
        n_sub=n_sub,
        divergence_rad=scene.scanner.beam_divergence_mrad * 1e-3,
        first_pulse_id=first,
    )


def run_chunk(mode, paths, scene, det, rs):
    if mode == "full_waveform":
        return simulate_waveforms(paths, scene, det, rs)
    return simulate_photon_events(paths, scene, det, rs)


def _worker(mode: str, n_sub: int, firsts: list[int], chunk: int) -> float:
    """One process: build its chunks, then time their simulation (seconds)."""
    scene, det, rs = setup(mode)
    chunks = [make_paths(mode, chunk, f, n_sub, scene) for f in firsts]
    run_chunk(mode, chunks[0], scene, det, rs)  # warm-up
    t0 = time.perf_counter()
    for p in chunks:
        run_chunk(mode, p, scene, det, rs)
    return time.perf_counter() - t0


def bench(mode: str, n_pulses: int, chunk: int, n_sub: int, repeats: int) -> dict:
    scene, det, rs = setup(mode)
    firsts = list(range(0, n_pulses, chunk))
    chunks = [make_paths(mode, chunk, f, n_sub, scene) for f in firsts]
    n_total = chunk * len(firsts)
    run_chunk(mode, chunks[0], scene, det, rs)  # warm-up (imports, caches)
    one, two_t, budget = [], [], []
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = [run_chunk(mode, p, scene, det, rs) for p in chunks]
        one.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        with ThreadPoolExecutor(2) as ex:
            list(ex.map(lambda p: run_chunk(mode, p, scene, det, rs), chunks))
        two_t.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        for p in chunks:
            return_budget(p, scene, det, rs)
        budget.append(time.perf_counter() - t0)
    two_p = []
    with ProcessPoolExecutor(2) as ex:
        for _ in range(repeats):
            halves = [firsts[0::2], firsts[1::2]]
            times = list(ex.map(_worker, [mode] * 2, [n_sub] * 2, halves, [chunk] * 2))
            two_p.append(max(times))  # both halves run at once: the slower one sets the pace
    tracemalloc.start()
    run_chunk(mode, chunks[0], scene, det, rs)
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    flags = np.concatenate([o.flags for o in out])
    res = {
        "mode": mode,
        "n_sub": n_sub,
        "pulses": n_total,
        "chunk": chunk,
        "one": n_total / statistics.median(one),
        "threads": n_total / statistics.median(two_t),
        "procs": n_total / statistics.median(two_p),
        "budget_share": statistics.median(budget) / statistics.median(one),
        "peak_chunk_mib": peak / 2**20,
        "flags": describe_pulse_flags(flags),
    }
    if mode == "full_waveform":
        res["per_pulse"] = f"{out[0].samples.shape[1]} samples/pulse"
    else:
        ev = np.mean([np.diff(o.offsets).mean() for o in out])
        res["per_pulse"] = f"{ev:.2f} recorded events/shot"
    return res


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--pulses", type=int, default=140_000, help="pulses per run (1 s at 140 kHz)")
    ap.add_argument("--chunk", type=int, default=35_000)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--quick", action="store_true", help="28 000 pulses, one repeat")
    args = ap.parse_args()
    n, reps = (28_000, 1) if args.quick else (args.pulses, args.repeats)
    chunk = min(args.chunk, n)
    print(f"# {platform.machine()}, Python {platform.python_version()}, numpy {np.__version__}")
    print(f"# {n} pulses per run in chunks of {chunk}; median of {reps}")
    for mode in CASES:
        for n_sub in (1, 7):
            r = bench(mode, n, chunk, n_sub, reps)
            print(
                f"{r['mode']:16s} n_sub={r['n_sub']}: {r['one']:8.0f} pulses/s on 1 core, "
                f"{r['threads']:8.0f} on 2 threads, {r['procs']:8.0f} on 2 processes; "
                f"budget {100 * r['budget_share']:.0f} % of the 1-core time; "
                f"tracemalloc peak {r['peak_chunk_mib']:.0f} MiB per {r['chunk']}-pulse chunk; "
                f"{r['per_pulse']}"
            )
            print("    flags:", {k: v for k, v in r["flags"].items() if v})
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"# peak RSS of the main process: {rss:.0f} MiB")


if __name__ == "__main__":
    main()
