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
#: fewest faults a 64 MiB array mapped afresh costs: one per 2 MiB huge page (32) where the
#: kernel gives transparent huge pages, 16 384 where it does not; reused from the heap, none
FRESH_64MIB = 16


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
    # glibc's rule maps a 64 MiB array afresh each time
    assert float(plain) > FRESH_64MIB and float(again) > FRESH_64MIB and left == "False"
    assert set_ == "True" and float(chunks) < 1.0  # the chunk loop's: reused from the heap
    assert reset == "True" and float(after) > FRESH_64MIB  # mapped afresh again after it


def _chunk_task(shared, i):
    """What a chunk's task does first: the chunk loop's thresholds, if it may set them here."""
    from pipeline.worker_malloc import for_chunk_task

    return for_chunk_task()


def _big_faults():
    return minor_faults_per_array(20, 64 * 256)


@pytest.mark.slow
def test_a_dask_clusters_workers_reuse_arrays_while_the_run_is_connected():
    from distributed import Client, LocalCluster

    from pipeline.parallel import Executor

    with LocalCluster(
        n_workers=1, threads_per_worker=1, processes=True, dashboard_address=None
    ) as cluster:
        with Client(cluster.scheduler_address) as other:
            (before,) = other.run(minor_faults_per_array).values()
            with Executor(scheduler=cluster.scheduler_address) as ex:
                (during,) = other.run(minor_faults_per_array).values()
                (set_,) = ex.map(_chunk_task, None, 1)
                (chunks,) = other.run(_big_faults).values()
            (after,) = other.run(minor_faults_per_array).values()
            (after_big,) = other.run(_big_faults).values()
    assert before > 0.9 * PAGES  # the nanny's variable, as Dask sets it
    assert during < 0.1 * PAGES  # the run's plugin: glibc's risen thresholds
    assert set_ and chunks < 1.0  # a chunk's task: its large arrays reused
    assert after > 0.9 * PAGES  # Dask's setting back once the run's client has left
    assert after_big > FRESH_64MIB


def test_a_task_on_a_dask_worker_without_the_variable_sets_nothing(monkeypatch):
    # this process's own workers (threads): no nanny, no variable, so the run's plugin is
    # not set up on them and a chunk's task leaves glibc's own rule alone
    from distributed import LocalCluster

    import pipeline.worker_malloc as wm
    from pipeline.parallel import Executor

    monkeypatch.delenv("MALLOC_TRIM_THRESHOLD_", raising=False)
    calls = []
    monkeypatch.setattr(wm, "set_thresholds", lambda *a: calls.append(a) or True)
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=False) as cluster:
        with Executor(scheduler=cluster.scheduler_address) as ex:
            assert list(ex.map(_chunk_task, None, 2)) == [False, False]
    assert calls == [] and wm.DASK_RUNS == 0
    assert wm.for_chunk_task() and calls  # outside a Dask worker: set
