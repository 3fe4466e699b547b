"""What a run may plan to hold in memory: the measured cost of a survey, and the machine's share.

Read by the feasibility checks (:mod:`pipeline.feasibility`) and by the blocked survey's
choice of how many blocks run at once (:mod:`pipeline.survey_blocks_run`).
"""

from __future__ import annotations

import os

__all__ = ["BASE_BYTES", "BYTES_PER_PULSE", "MEMORY_SHARE", "machine_memory_bytes"]

#: Peak memory of a survey run held whole: 434 MB + 1.44 kB per pulse (measured with
#: ``/usr/bin/time -v`` on the Palmer scene). A survey of more than ``run.block_pulses`` is
#: processed block by block (:mod:`pipeline.survey_blocks`): it holds about
#: ``max(run.block_pulses, run.sample_pulses)`` pulses at a time.
BASE_BYTES = 434e6
BYTES_PER_PULSE = 1.44e3
#: Share of the machine's memory a run may plan to use.
MEMORY_SHARE = 0.8


def machine_memory_bytes() -> float:
    """Physical memory of this machine in bytes."""
    return float(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))
