"""The allocator's thresholds (glibc): the chunk loop's large arrays, Dask's worker processes.

A Dask nanny starts its workers with ``MALLOC_TRIM_THRESHOLD_=65536`` (its
``distributed.nanny.pre-spawn-environ``), so that a worker hands freed memory back at once.
Setting any threshold through the environment also stops glibc's dynamic mmap threshold
(128 KiB, rising to 32 MiB as large blocks are freed): every array above 128 KiB is then
mapped fresh and faulted in page by page, and freed back to the system. The pipeline's
stages make and drop many such temporaries per chunk: on a 2-process ``LocalCluster`` the
chunk loop's receiver took 12.6 CPU-s for 300 000 pulses against 6.9 without that variable
(``benchmarks/RESULTS_e2e.md``, session 36). The stages hand memory back themselves where it
matters (:func:`~pipeline.stages.trim_heap` at the end of a block and between stages), so
:class:`~pipeline.dask_malloc.GlibcThresholds` sets the two thresholds a process without the
variable reaches (:func:`for_blocks`), for as long as the run's client is connected, and puts
Dask's back when it leaves. The chunk loop sets its own, higher ones (:func:`for_chunks`);
on a Dask worker only while a run's plugin is set up there (:func:`for_chunk_task`), and
whatever ran in a process after chunks finds :func:`for_blocks` again (:func:`after_chunks`).
"""

from __future__ import annotations

import ctypes
import sys

__all__ = ["after_chunks", "for_blocks", "for_chunk_task", "for_chunks", "set_thresholds"]

#: glibc's ``mallopt`` parameters (malloc.h)
M_TRIM_THRESHOLD, M_MMAP_THRESHOLD = -1, -3
#: the mmap threshold glibc's dynamic rule rises to at most (``DEFAULT_MMAP_THRESHOLD_MAX``,
#: 64-bit) and the trim threshold it pairs with it (twice)
RISEN_MMAP_BYTES = 32 * 2**20
RISEN_TRIM_BYTES = 2 * RISEN_MMAP_BYTES
#: glibc's starting mmap threshold, where a set variable leaves it
DEFAULT_MMAP_BYTES = 128 * 2**10
ENV = "MALLOC_TRIM_THRESHOLD_"
#: the chunk loop's: a chunk's waveforms and the detector's temporaries are tens of MB each,
#: above what glibc's rule rises to, so each was mapped fresh and faulted in per chunk
CHUNK_MMAP_BYTES = 512 * 2**20
CHUNK_TRIM_BYTES = 2 * CHUNK_MMAP_BYTES
#: whether this process set the chunk loop's thresholds (and has not set others since)
_CHUNKS_HERE = False
#: runs whose Dask plugin is set up on this worker (pipeline.dask_malloc): while > 0 the
#: tasks here may set thresholds, which the last plugin's teardown puts back
DASK_RUNS = 0


def set_thresholds(mmap_bytes: int, trim_bytes: int) -> bool:
    """``mallopt`` the mmap and trim thresholds of this process; False where not glibc."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL("libc.so.6")
        return bool(libc.mallopt(M_MMAP_THRESHOLD, int(mmap_bytes))) and bool(
            libc.mallopt(M_TRIM_THRESHOLD, int(trim_bytes))
        )
    except (OSError, AttributeError):  # not glibc
        return False


def for_chunks() -> bool:
    """Set the chunk loop's thresholds, in the process running a chunk.

    A chunk's arrays (its waveforms, ``(n_pulses, n_samples)`` float32, and the detector's
    temporaries of that size) are made again for every chunk: kept in the heap rather than
    mapped afresh, the detection of 300 000 pulses at the default chunk size took 10.8 CPU-s
    instead of 12.4 and the run's sys time 3.6 s instead of 5.8 (``benchmarks/RESULTS_e2e.md``,
    session 36). A chunk worker's resident memory then stays near its largest chunk's (its
    peak on 1.5 M pulses 804 -> 868 MiB, below the run's largest process, 1676 MiB);
    :func:`for_blocks` is set again where the same process goes on to other work
    (:func:`after_chunks`: the run's process, a block's task).
    """
    global _CHUNKS_HERE
    _CHUNKS_HERE = set_thresholds(CHUNK_MMAP_BYTES, CHUNK_TRIM_BYTES)
    return _CHUNKS_HERE


def _on_dask_worker() -> bool:
    """Whether this runs inside a Dask worker's task (Dask imported and a worker found)."""
    distributed = sys.modules.get("distributed")
    if distributed is None:
        return False
    try:
        distributed.get_worker()
    except ValueError:
        return False
    return True


def for_chunk_task() -> bool:
    """:func:`for_chunks`, where a chunk's task runs.

    On a Dask worker only while a run's plugin is set up there (a worker its nanny started
    with ``MALLOC_TRIM_THRESHOLD_``, whose setting the plugin puts back when the run leaves):
    a worker without it keeps glibc's own rule, which nothing could turn on again.
    """
    if DASK_RUNS <= 0 and _on_dask_worker():
        return False
    return for_chunks()


def after_chunks() -> bool:
    """Set :func:`for_blocks` where this process ran chunks since it was last set.

    The run's process after a chunk loop on 1 worker; a Dask worker's block after its chunks.
    A process that never ran one keeps glibc's own rule (nothing is set).
    """
    global _CHUNKS_HERE
    if not _CHUNKS_HERE:
        return False
    _CHUNKS_HERE = False
    return for_blocks()


def for_blocks() -> bool:
    """Set glibc's risen thresholds (what its dynamic rule reaches): all but the chunk loop.

    Processing and the TPU gained nothing from the chunk loop's (their CPU unchanged) and
    their peaks rose with them (a 1.5 M-pulse run's process tree by 6 %).
    """
    global _CHUNKS_HERE
    _CHUNKS_HERE = False
    return set_thresholds(RISEN_MMAP_BYTES, RISEN_TRIM_BYTES)
