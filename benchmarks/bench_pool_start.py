"""When each pool worker returns its first result, with a large shared object (issue 15).

    PYTHONPATH=. python benchmarks/bench_pool_start.py [WORKERS ...]

A 68 MB shared array (the size of a 300 k-pulse Palmer scene's meshes, pickled) and tasks of
0.5 s: the seconds from the map's start to each worker's first result. Workers that start
side by side return theirs together; workers started one after another, each waiting for
the one before to import the main module, return theirs one import time apart. The main
module imports :mod:`pipeline.cli`, as ``bathy`` does.
"""

from __future__ import annotations

import os
import sys
import time

import numpy as np

import pipeline.cli  # noqa: F401  (the main module's imports, as `bathy` has them)
from pipeline.parallel import Executor


def task(shared, i):
    time.sleep(0.5)
    return os.getpid(), time.time()


def first_results_s(workers: int, shared_mb: float = 68.0) -> list[float]:
    """Seconds from the map's start to each worker's first result, sorted."""
    shared = np.ones(int(shared_mb * 1e6) // 8)
    t0 = time.time()
    first: dict[int, float] = {}
    with Executor(workers=workers) as ex:
        for pid, t in ex.map(task, shared, 4 * workers):
            first.setdefault(pid, t - t0)
    return sorted(first.values())


if __name__ == "__main__":
    for n in [int(a) for a in sys.argv[1:]] or [2, 4]:
        print(
            f"workers {n}: first result per worker (s):", [round(v, 2) for v in first_results_s(n)]
        )
