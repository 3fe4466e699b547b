"""Dask's workers' allocator made to reuse freed arrays (pipeline.worker_malloc), by page faults.

A 1 MiB array made and dropped 200 times: with glibc's dynamic mmap threshold it is reused
from the heap after the first free (a few faults in all); with ``MALLOC_TRIM_THRESHOLD_`` set
(what a Dask nanny starts its workers with) each one is mapped fresh and faulted in page by
page (256 faults each). The page-fault counter is the kernel's, not the code's.
"""

from __future__ import annotations

import os
import resource
import subprocess
import sys
import textwrap

import numpy as np
import pytest

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc only")

#: pages of the array made and dropped (4 KiB pages: 1 MiB)
PAGES = 256


def minor_faults_per_array(n: int = 200) -> float:
    """Minor page faults per 1 MiB array made, written and dropped, in this process."""
    np.ones(PAGES * 512).sum()  # once first, so the heap's first growth is not counted
    before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    for _ in range(n):
        a = np.ones(PAGES * 512)  # float64: 1 MiB
        del a
    return (resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before) / n


def _in_subprocess(env_value: str | None, apply: bool) -> float:
    code = textwrap.dedent(
        f"""
        from tests.test_worker_malloc import minor_faults_per_array
        from pipeline.worker_malloc import GlibcThresholds
        if {apply!r}:
            GlibcThresholds().setup()
        print(minor_faults_per_array())
        """
    )
    env = {k: v for k, v in os.environ.items() if k != "MALLOC_TRIM_THRESHOLD_"}
    if env_value is not None:
        env["MALLOC_TRIM_THRESHOLD_"] = env_value
    out = subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True
    )
    return float(out.stdout.split()[-1])


def test_a_set_trim_threshold_faults_every_array_and_the_plugin_lets_it_reuse_them():
    plain = _in_subprocess(None, apply=False)
    dask_env = _in_subprocess("65536", apply=False)
    fixed = _in_subprocess("65536", apply=True)
    untouched = _in_subprocess(None, apply=True)  # no variable: glibc's own rule is kept
    assert plain < 0.1 * PAGES and untouched < 0.1 * PAGES
    assert dask_env > 0.9 * PAGES  # every page of every array, as Dask's workers run
    assert fixed < 0.1 * PAGES


@pytest.mark.slow
def test_a_dask_clusters_workers_reuse_arrays_while_the_run_is_connected():
    from distributed import Client, LocalCluster

    from pipeline.parallel import Executor

    with LocalCluster(
        n_workers=1, threads_per_worker=1, processes=True, dashboard_address=None
    ) as cluster:
        with Client(cluster.scheduler_address) as other:
            (before,) = other.run(minor_faults_per_array).values()
            with Executor(scheduler=cluster.scheduler_address):
                (during,) = other.run(minor_faults_per_array).values()
            (after,) = other.run(minor_faults_per_array).values()
    assert before > 0.9 * PAGES  # the nanny's variable, as Dask sets it
    assert during < 0.1 * PAGES
    assert after > 0.9 * PAGES  # Dask's setting back once the run's client has left
