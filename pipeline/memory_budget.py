"""What a run may plan to hold in memory: the measured cost of a survey, and the machine's share.

Read by the feasibility checks (:mod:`pipeline.feasibility`) and by the blocked survey's
choice of how many blocks run at once (:mod:`pipeline.survey_blocks_run`).
"""

from __future__ import annotations

import os

__all__ = [
    "BASE_BYTES",
    "BYTES_PER_PULSE",
    "MEMORY_SHARE",
    "VIEWS_CHILD_BYTES",
    "WHOLE_BASE_BYTES",
    "WHOLE_BYTES_PER_PULSE",
    "held_bytes",
    "held_whole",
    "machine_memory_bytes",
]

#: Peak memory of a survey run held whole (the largest process): 0.5 GB + 1.77 kB per pulse,
#: the line through 1316 MiB at 500 000 pulses (1 worker) and 2160 MiB at 1 000 000 (2
#: workers, whose parent peaks 100-200 MiB above one worker's), the Palmer scene, posteriors
#: off, session 38's code (``benchmarks/RESULTS_e2e.md``; 0.89 GB + 1.64 kB before its memory
#: changes). It under-plans 300 000 pulses (1 worker) by 4 % (983 against 1028 MiB). A survey of
#: up to :func:`held_whole`'s limit is held whole; a larger one holds its sample
#: (``run.sample_pulses``) whole and its blocks one per process (:data:`BASE_BYTES`).
WHOLE_BASE_BYTES = 0.5e9
WHOLE_BYTES_PER_PULSE = 1.77e3
#: Peak memory of a block's process (:mod:`pipeline.survey_blocks`) by the pulses it loads with
#: its halo: 434 MB + 1.44 kB per pulse, a bound measured on surveys held whole before session
#: 37, which holds a block's (1.56 GiB at blocks of about 1 M loaded pulses, 3 M and 10 M pulse
#: surveys; a block processes only what the points it keeps read). As many blocks run at once
#: as the memory holds by it (:func:`~pipeline.survey_block_task.blocks_side_by_side`).
BASE_BYTES = 434e6
BYTES_PER_PULSE = 1.44e3
#: The report's pictures' child interpreter (:mod:`pipeline.outputs.view_render`): Mesa's
#: OpenGL and the meshes read back, 400-500 MiB at 1 M pulses, beside the parent (which waits
#: holding its survey's evaluation arrays, below its own peak). Planned on top of the largest
#: process when the run makes its views.
VIEWS_CHILD_BYTES = 0.5e9
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


def held_whole(run, n_pulses: int) -> bool:
    """Whether a survey of ``n_pulses`` is processed whole, in one process, by ``run``.

    Not when ``run.block_m`` is set, nor beyond ``run.whole_pulses`` (the memory a survey held
    whole needs grows with it: :data:`WHOLE_BYTES_PER_PULSE`) or ``run.block_pulses`` (a
    survey larger than one block).
    """
    return run.block_m is None and int(n_pulses) <= min(run.whole_pulses, run.block_pulses)


def held_bytes(n_pulses: int, block_pulses: int, sample_pulses: int, blocked: bool) -> float:
    """Peak memory a survey's largest process plans for (bytes).

    Held whole: :data:`WHOLE_BASE_BYTES` + :data:`WHOLE_BYTES_PER_PULSE` per pulse. Blocked:
    the larger of its sample held whole (at most ``sample_pulses``) and one block of
    ``block_pulses`` loaded pulses (:data:`BASE_BYTES` + :data:`BYTES_PER_PULSE` each).
    """
    if not blocked:
        return WHOLE_BASE_BYTES + WHOLE_BYTES_PER_PULSE * n_pulses
    sample = WHOLE_BASE_BYTES + WHOLE_BYTES_PER_PULSE * min(n_pulses, sample_pulses)
    block = BASE_BYTES + BYTES_PER_PULSE * min(n_pulses, block_pulses)
    return max(sample, block)
