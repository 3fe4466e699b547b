"""The allocator's thresholds (pipeline.worker_malloc, pipeline.dask_malloc), by page faults.

A 1 MiB array made and dropped 200 times: with glibc's dynamic mmap threshold it is reused
from the heap after the first free (a few faults in all); with ``MALLOC_TRIM_THRESHOLD_`` set
(what a Dask nanny starts its workers with) each one is mapped fresh and faulted in page by
page (256 faults each). A 64 MiB array (a chunk's waveforms) lies above anything glibc's rule
reaches: mapped afresh each time unless the chunk loop's thresholds are set. The page-fault
counter is the kernel's, not the code's.
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


def minor_faults_per_array(n: int = 200, pages: int = PAGES) -> float:
    """Minor page faults per array of ``pages`` 4 KiB pages made, written and dropped here."""
    np.ones(pages * 512).sum()  # once first, so the heap's first growth is not counted
    before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    for _ in range(n):
        a = np.ones(pages * 512)  # float64
        del a
    return (resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before) / n


def _in_subprocess(env_value: str | None, apply: bool) -> float:
    code = textwrap.dedent(
        f"""
        from tests.test_worker_malloc import minor_faults_per_array
        from pipeline.dask_malloc import GlibcThresholds
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


def test_the_chunk_loops_thresholds_keep_a_chunks_arrays_and_are_left_after_it():
    code = textwrap.dedent(
        """
        from tests.test_worker_malloc import minor_faults_per_array as f
        from pipeline import worker_malloc as wm
        big = 64 * 256  # pages: 64 MiB
        out = [f(20, big), wm.after_chunks()]  # nothing to leave: the rule kept
        out += [f(20, big), wm.for_chunks(), f(20, big), wm.after_chunks(), f(20, big)]
        print(*out)
        """
    )
    env = {k: v for k, v in os.environ.items() if k != "MALLOC_TRIM_THRESHOLD_"}
    run = subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True
    )
    plain, left, again, set_, chunks, reset, after = run.stdout.split()
    big = 64 * 256
    # glibc's rule maps a 64 MiB array afresh each time (huge pages may serve part of it)
    assert float(plain) > 0.02 * big and float(again) > 0.02 * big and left == "False"
    assert set_ == "True" and float(chunks) < 1.0  # the chunk loop's: reused from the heap
    assert reset == "True" and float(after) > 0.02 * big  # mapped afresh again after it


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
