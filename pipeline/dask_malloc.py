"""A Dask worker plugin: the allocator's thresholds of :mod:`pipeline.worker_malloc`.

On workers a nanny started with ``MALLOC_TRIM_THRESHOLD_``, while the run's client is connected.
"""

from __future__ import annotations

import os

from distributed.diagnostics.plugin import WorkerPlugin

from pipeline.worker_malloc import DEFAULT_MMAP_BYTES, ENV, for_blocks, set_thresholds

__all__ = ["GlibcThresholds"]


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
            for_blocks()

    def teardown(self, worker=None) -> None:
        """Set the variable's trim threshold and glibc's starting mmap threshold again."""
        value = os.environ.get(ENV, "")
        if value.isdigit():
            set_thresholds(DEFAULT_MMAP_BYTES, int(value))
