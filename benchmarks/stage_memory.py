"""Peak resident memory of each stage of a Palmer survey of about N pulses (issue 15).

Usage: ``PYTHONPATH=. python benchmarks/stage_memory.py N [--set run.KEY=VALUE ...]`` (1 worker,
posteriors off, chunks of 20 000 pulses; the scene is :func:`bench_e2e.palmer`). Prints each stage's
``peak_rss_mb`` from the run's manifest (:class:`pipeline.stages.StageClock`): "exact" where
the stage raised the process's high-water mark (the stage setting the run's peak is one),
"sampled" (every 10 ms, a lower bound) where it did not; then the run's peak. One survey per
invocation: the high-water mark never falls within a process. Results: ``RESULTS_e2e.md``.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_e2e import palmer  # noqa: E402

from pipeline.run import run_scene  # noqa: E402
from pipeline.scene import parse_scene  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("pulses", type=int)
    ap.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="run.KEY=VALUE",
        help="a run setting, e.g. run.block_pulses=200000 (repeatable)",
    )
    args = ap.parse_args()
    n = args.pulses
    data = palmer(n, False, 20_000)
    for kv in args.set:
        key, value = kv.split("=", 1)
        section, name = key.split(".", 1)
        data.setdefault(section, {})[name] = (
            None if value == "None" else float(value) if "." in value else int(value)
        )
    with tempfile.TemporaryDirectory() as tmp:
        scene = parse_scene(data)
        m = run_scene(scene, Path(tmp) / "out", log=lambda s: None, workers=1)
    print(f"# about {n} pulses ({m['evaluation'].get('pulses')} evaluated); {' '.join(args.set)}")
    stages = [s for s in m["plan"] if s.get("peak_rss_mb") is not None]
    stages += [{"stage": k, **v} for k, v in m.get("other_stages", {}).items()]
    for s in stages:
        if s.get("peak_rss_mb") is not None:
            how = "exact" if s.get("peak_exact") else "sampled"
            print(f"{s['stage']:20s} {s['peak_rss_mb']:8.0f} MB {how:8s} cpu {s['cpu_s']:.1f} s")
    print(f"{'run':20s} {m['memory']['peak_rss_mb']:8.0f} MB")
    if "blocked" in m["evaluation"]:
        print("blocked:", m["evaluation"]["blocked"])


if __name__ == "__main__":
    main()
