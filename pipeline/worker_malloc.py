"""glibc's allocator on Dask's worker processes as it is in ours: large arrays reuse freed memory.

A Dask nanny starts its workers with ``MALLOC_TRIM_THRESHOLD_=65536`` (its
``distributed.nanny.pre-spawn-environ``), so that a worker hands freed memory back at once.
Setting any threshold through the environment also stops glibc's dynamic mmap threshold
(128 KiB, rising to 32 MiB as large blocks are freed): every array above 128 KiB is then
mapped fresh and faulted in page by page, and freed back to the system. The pipeline's
stages make and drop many such temporaries per chunk: on a 2-process ``LocalCluster`` the
chunk loop's receiver took 12.9 CPU-s for 300 000 pulses against 6.9 without that variable
(``benchmarks/RESULTS_e2e.md``, session 36). The stages hand memory back themselves where it
matters (:func:`~pipeline.stages.trim_heap` at the end of a block and between stages), so
:class:`GlibcThresholds` sets the two thresholds a process without the variable reaches,
for as long as the run's client is connected, and puts Dask's back when it leaves.
"""

from __future__ import annotations

import ctypes
import os
import sys

from distributed.diagnostics.plugin import WorkerPlugin

__all__ = ["GlibcThresholds", "set_thresholds"]

#: glibc's ``mallopt`` parameters (malloc.h)
M_TRIM_THRESHOLD, M_MMAP_THRESHOLD = -1, -3
#: the mmap threshold glibc's dynamic rule rises to at most (``DEFAULT_MMAP_THRESHOLD_MAX``,
#: 64-bit) and the trim threshold it pairs with it (twice)
RISEN_MMAP_BYTES = 32 * 2**20
RISEN_TRIM_BYTES = 2 * RISEN_MMAP_BYTES
#: glibc's starting mmap threshold, where a set variable leaves it
DEFAULT_MMAP_BYTES = 128 * 2**10
ENV = "MALLOC_TRIM_THRESHOLD_"


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


class GlibcThresholds(WorkerPlugin):
    """On each worker started with ``MALLOC_TRIM_THRESHOLD_``: glibc's risen thresholds.

    Only where that variable is set (a worker without it keeps glibc's dynamic rule); on
    teardown (the run's client leaves) the variable's trim threshold and glibc's starting
    mmap threshold are set again.
    """

    name = "bathy-glibc-thresholds"

    def setup(self, worker=None) -> None:
        """Raise the thresholds where the worker was started with the variable."""
        if os.environ.get(ENV):
            set_thresholds(RISEN_MMAP_BYTES, RISEN_TRIM_BYTES)

    def teardown(self, worker=None) -> None:
        """Set the variable's trim threshold and glibc's starting mmap threshold again."""
        value = os.environ.get(ENV, "")
        if value.isdigit():
            set_thresholds(DEFAULT_MMAP_BYTES, int(value))
