"""A Dask worker plugin: the allocator's thresholds of :mod:`pipeline.worker_malloc`.

On workers a nanny started with ``MALLOC_TRIM_THRESHOLD_``, while the run's client is connected.
"""

from __future__ import annotations

import os
import uuid

from distributed.diagnostics.plugin import WorkerPlugin

import pipeline.worker_malloc as wm

__all__ = ["GlibcThresholds"]


class GlibcThresholds(WorkerPlugin):
    """On each worker started with ``MALLOC_TRIM_THRESHOLD_``: glibc's risen thresholds.

    Only where that variable is set (a worker without it keeps glibc's dynamic rule, and the
    run's tasks leave it so: :func:`~pipeline.worker_malloc.for_chunk_task`). Each run registers
    its own (``name``); when the last one set up on a worker is torn down (its client
    leaves), the variable's trim threshold and glibc's starting mmap threshold are set again.
    """

    def __init__(self) -> None:
        self.name = f"bathy-glibc-thresholds-{uuid.uuid4().hex}"
        self._here = False

    def setup(self, worker=None) -> None:
        """Raise the thresholds where the worker was started with the variable."""
        if os.environ.get(wm.ENV):
            wm.DASK_RUNS += 1
            self._here = True
            wm.for_blocks()

    def teardown(self, worker=None) -> None:
        """Set the variable's thresholds again when no run is left on this worker."""
        if not self._here:
            return
        self._here = False
        wm.DASK_RUNS -= 1
        value = os.environ.get(wm.ENV, "")
        if wm.DASK_RUNS <= 0 and value.isdigit():
            wm.set_thresholds(wm.DEFAULT_MMAP_BYTES, int(value))
