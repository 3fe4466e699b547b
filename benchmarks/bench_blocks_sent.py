"""A blocked survey on a Dask cluster as if on another machine: its blocks sent their pulses.

Runs ``bathy run``'s pipeline (:func:`pipeline.run.run_scene`) on the Palmer benchmark scene
(``benchmarks/bench_e2e.py``'s, posteriors off) in blocks of 100 000 loaded pulses with a
sample of 100 000, on a ``LocalCluster`` of 2 worker processes (1 thread each) started as
Dask starts them (its nanny's environment), and tells the run that the workers cannot read
its detection store (``Executor.shares_file`` answers False), as a cluster on other machines
would. Prints the blocks' lines of the log, the evaluation's ``blocked`` summary, the run's
wall seconds and each stage's wall and CPU seconds (the workers' summed).

Run: PYTHONPATH=. .venv/bin/python benchmarks/bench_blocks_sent.py OUT [--pulses 300000]
     [--dask-env]

``--dask-env`` keeps Dask's ``MALLOC_TRIM_THRESHOLD_`` on the workers for the whole run (the
run's plugin, :mod:`pipeline.dask_malloc`, is then not registered, and the tasks then set no
thresholds on the workers either): what the workers cost before it. Results:
``benchmarks/RESULTS_e2e.md``, session 36.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from distributed import LocalCluster

from benchmarks.bench_e2e import palmer
from pipeline.parallel import Executor
from pipeline.run import run_scene
from pipeline.scene import parse_scene


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", type=Path)
    ap.add_argument("--pulses", type=int, default=300_000)
    ap.add_argument("--dask-env", action="store_true")
    args = ap.parse_args()
    data = palmer(args.pulses, False, 50_000)
    data["run"].update({"block_pulses": 100_000, "sample_pulses": 100_000, "views": False})
    Executor.shares_file = lambda self, path: False  # workers "on another machine"
    if args.dask_env:  # the run's client registers no plugin (the workers keep Dask's)
        from distributed import Client

        Client.register_plugin = lambda self, plugin, name=None: None
    with LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None
    ) as cluster:
        t0, lines = time.perf_counter(), []
        run_scene(
            parse_scene(data),
            args.out,
            log=lines.append,
            workers=None,
            scheduler=cluster.scheduler_address,
        )
        wall = time.perf_counter() - t0
    blocked = json.loads((args.out / "evaluation.json").read_text())["blocked"]
    print("\n".join(line for line in lines if "block" in line))
    keys = ("blocks", "blocks_wall_s", "block_workers", "blocks_sent", "block_m", "halo_m")
    print(json.dumps({k: blocked.get(k) for k in (*keys, "survey_pulses")}))
    print(f"run wall {wall:.1f} s")
    stages = json.loads((args.out / "manifest.json").read_text())["evaluation"]["stages"]
    print({k: (round(v["wall_s"], 1), round(v["cpu_s"], 1)) for k, v in stages.items()})


if __name__ == "__main__":
    main()
