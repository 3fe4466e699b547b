"""trim_heap hands freed heap pages back: the process's resident memory falls (psutil)."""

import sys

import numpy as np
import psutil
import pytest

from pipeline.stages import trim_heap


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's malloc_trim")
def test_freed_heap_pages_leave_the_resident_set():
    proc = psutil.Process()
    # 60 kB blocks sit under glibc's mmap threshold: they come from the heap, and every tenth
    # kept alive pins the heap's top, so freeing the rest returns nothing by itself
    blocks = [np.ones(7500) for _ in range(4000)]  # ~240 MB
    keep = blocks[::10]
    del blocks
    before = proc.memory_info().rss
    trim_heap()
    after = proc.memory_info().rss
    assert before - after > 100e6, (before, after)
    assert all(float(b[0]) == 1.0 for b in keep)  # what is alive stays
