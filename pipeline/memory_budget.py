"""What a run may plan to hold in memory: the measured cost of a survey, and the machine's share.

Read by the feasibility checks (:mod:`pipeline.feasibility`) and by the blocked survey's
choice of how many blocks run at once (:mod:`pipeline.survey_blocks_run`).
"""

from __future__ import annotations

import os

__all__ = ["BASE_BYTES", "BYTES_PER_PULSE", "MEMORY_SHARE", "machine_memory_bytes"]

#: Peak memory of a survey run held whole: 434 MB + 1.44 kB per pulse (measured with
#: ``/usr/bin/time -v`` on the Palmer scene). A survey of more than ``run.block_pulses`` is
#: processed block by block (:mod:`pipeline.survey_blocks`): each process holds about
#: ``max(run.block_pulses, run.sample_pulses)`` pulses at a time, and as many blocks run at once
#: as the memory holds (:func:`~pipeline.survey_block_task.blocks_side_by_side`).
BASE_BYTES = 434e6
BYTES_PER_PULSE = 1.44e3
#: Share of the machine's memory a run may plan to use.
MEMORY_SHARE = 0.8
#: Where a control group's memory limit is read (cgroup v2, then v1).
CGROUP_LIMITS = ("/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory/memory.limit_in_bytes")


def machine_memory_bytes() -> float:
    """Memory this machine lets the run have, in bytes.

    Its physical memory, or the memory limit of the control group the run is in (a container's)
    where that is smaller.
    """
    limit = float(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))
    for path in CGROUP_LIMITS:
        try:
            with open(path, encoding="ascii") as f:
                value = f.read().strip()
        except OSError:
            continue
        if value.isdigit():  # "max": no limit
            limit = min(limit, float(value))
    return limit
