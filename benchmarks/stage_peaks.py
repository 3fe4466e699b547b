"""The resident memory's true peak inside each stage of a Palmer survey of about N pulses.

Usage: ``PYTHONPATH=. python benchmarks/stage_peaks.py N [BLOCK_PULSES SAMPLE_PULSES]``
(1 worker, posteriors off; the scene is :func:`bench_e2e.palmer`). A thread samples the RSS
every 5 ms and keeps its largest value under the innermost :class:`pipeline.stages.StageClock`
stage running (``(none)``: between stages). The manifest's ``peak_rss_mb`` (what
``stage_memory.py`` prints) is exact only for the stages that raised the process's high-water
mark and otherwise is sampled every 10 ms itself (:mod:`pipeline.rss_watch`); this script's
5 ms samples also label the time between stages. Short spikes between two samples, or while a
thread holds the GIL, can be missed.
Results: ``RESULTS_e2e.md``.
"""

from __future__ import annotations

import contextlib
import sys
import tempfile
import threading
import time
from pathlib import Path

import psutil

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_e2e import palmer  # noqa: E402

import pipeline.stages as stages  # noqa: E402
from pipeline.run import run_scene  # noqa: E402
from pipeline.scene import parse_scene  # noqa: E402

_PROC = psutil.Process()
_LABELS = ["(none)"]
_PEAKS: dict[str, float] = {}
_ORDER: list[str] = []
_STAGE = stages.StageClock.stage


@contextlib.contextmanager
def _labelled(self, name):
    _LABELS.append(name)
    if name not in _ORDER:
        _ORDER.append(name)
    try:
        with _STAGE(self, name):
            yield
    finally:
        _LABELS.pop()


def _sample() -> None:
    while True:
        rss, label = _PROC.memory_info().rss / 2**20, _LABELS[-1]
        if rss > _PEAKS.get(label, 0.0):
            _PEAKS[label] = rss
        time.sleep(0.005)


def main() -> None:
    n = int(sys.argv[1])
    data = palmer(n, False, 20_000)
    run = data.setdefault("run", {})
    if len(sys.argv) > 3:
        run.update(block_pulses=int(sys.argv[2]), sample_pulses=int(sys.argv[3]))
    else:
        run["block_pulses"] = run["whole_pulses"] = 10 * n  # one piece
    stages.StageClock.stage = _labelled
    threading.Thread(target=_sample, daemon=True).start()
    with tempfile.TemporaryDirectory() as tmp:
        run_scene(parse_scene(data), Path(tmp) / "out", log=lambda s: None, workers=1)
    print(f"# {n} pulses {' '.join(sys.argv[2:])}: sampled RSS peak per stage (MiB)")
    for k in ["(none)", *_ORDER]:
        if k in _PEAKS:
            print(f"{k:22s} {_PEAKS[k]:8.0f}")
    print(f"overall {max(_PEAKS.values()):.0f}")


if __name__ == "__main__":
    main()
