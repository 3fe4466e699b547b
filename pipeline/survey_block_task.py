"""One block of a blocked survey as a task: run here, on a process pool or on a Dask cluster.

:func:`run_block` is a pure function of the survey's figures and the block's stored pulses
(:class:`BlockJob`, sent once to each worker by :class:`~pipeline.parallel.Executor`), so the
blocks can run side by side and the parent writes their results in block order: the outputs
are the same for any number of workers. What comes back is only what the parent writes: the
block's own points (in the points file's tile order), its own pulses (for the LAS fields),
its own cells as grid records, its counts, and its stage clock.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import Any

import numpy as np

from pipeline.memory_budget import BASE_BYTES, BYTES_PER_PULSE
from pipeline.process.classify import SUBMERGED_OBJECT
from pipeline.process.returns import PointFlag
from pipeline.stages import StageClock, trim_heap

__all__ = ["RULES", "BlockJob", "BlockResult", "blocks_side_by_side", "run_block"]

#: The rejection rules' counts (:func:`~pipeline.process.seabed_outliers.reject_seabed_outliers`)
#: by the flag each sets.
RULES = {
    "tvu_exceeded": PointFlag.TVU_EXCEEDED,
    "surface_implausible": PointFlag.SURFACE_IMPLAUSIBLE,
    "seabed_outlier": PointFlag.SEABED_OUTLIER,
}


@dataclass(frozen=True)
class BlockJob:
    """What every block's task reads (the same for all of them).

    Attributes
    ----------
    store : DetectionStore or StoreReader or None
        The survey's detections (a reader in another process; None: each task is sent its
        block's pulses, :func:`run_block`'s ``loaded``).
    blocks : TileLayout
        The blocks.
    todo : (n_tasks,) int
        The blocks to look at, task ``k`` is block ``todo[k]``.
    counts : (n_blocks,) int
        Stored pulses per block.
    halo_m, reach_m, planes_m, krige_m : float
        The blocks' halo, the beams' reach, and how far past a block its planes and kriged
        sea are read (:func:`~pipeline.survey_block_reach.processing_reach_m`).
    scene, plan, ctx
        The run's scene, plan and processing context.
    figures : SurveyFigures
        The sample's survey-wide figures.
    layout : TileLayout
        The survey grid's bounds and the points file's tiles.
    """

    store: Any
    blocks: Any
    todo: np.ndarray
    counts: np.ndarray
    halo_m: float
    reach_m: float
    planes_m: float
    krige_m: float
    scene: Any
    plan: Any
    ctx: Any
    figures: Any
    layout: Any


@dataclass
class BlockResult:
    """What a block gives the survey's files and counts (``points`` None: nothing to write).

    Attributes
    ----------
    block : int
        The block's number in the blocks' layout.
    points : Points or None
        The block's own pulses' points, in the points file's tile order, ``(n_points,)``.
    starts : (n_tiles + 1,) int
        Where each tile's points start in ``points``.
    returns : DetectedReturns or None
        The block's own pulses.
    dst : (slice, slice)
        The block's own cells in the survey's grid.
    records : (rows, cols) structured
        Those cells (:func:`~pipeline.outputs.grid_tiles.cell_records`).
    class43, withheld : int
        Its own pulses' class-43 points and withheld class-45 claims.
    rejected : dict
        Its own pulses' rejected points by rule (:data:`RULES`).
    stages : dict
        The task's :meth:`~pipeline.stages.StageClock.to_dict`.
    """

    block: int
    points: Any = None
    starts: np.ndarray | None = None
    returns: Any = None
    dst: tuple[slice, slice] | None = None
    records: np.ndarray | None = None
    class43: int = 0
    withheld: int = 0
    rejected: dict[str, int] | None = None
    stages: dict[str, Any] | None = None


def blocks_side_by_side(workers: int, loaded_pulses: float, free_bytes: float) -> int:
    """How many blocks may run at once: at most ``workers``, and as many as memory holds.

    Each running block is a process holding its loaded pulses
    (:data:`~pipeline.memory_budget.BASE_BYTES` + :data:`~pipeline.memory_budget.BYTES_PER_PULSE`
    each, a bound of a block's measured peak).

    Parameters
    ----------
    workers : int
        The executor's workers.
    loaded_pulses : float
        Pulses a block loads with its halo, at most.
    free_bytes : float
        What the run may still use: its share of the machine's memory less this process's
        resident memory.

    Returns
    -------
    int
        At least 1.
    """
    per_block = BASE_BYTES + BYTES_PER_PULSE * max(float(loaded_pulses), 0.0)
    return int(max(1, min(int(workers), free_bytes // per_block)))


def _reached(returns, blocks, b: int, reach_m: float, air_index: float) -> bool:
    """Whether a pulse of ``returns`` lies within a beam reach of block ``b``."""
    from pipeline.survey_tiles import returns_position_m

    xy = returns_position_m(returns, air_index)
    x0, x1, y0, y1 = blocks.box_m(b)
    x, y = xy[:, 0], xy[:, 1]
    return bool(
        np.any(
            (x >= x0 - reach_m) & (x <= x1 + reach_m) & (y >= y0 - reach_m) & (y <= y1 + reach_m)
        )
    )


def _quiet(*_args, **_kw) -> None:
    return None


def run_block(job: BlockJob, k: int, loaded: tuple | None = None) -> BlockResult:
    """Process block ``job.todo[k]`` with its halo and keep what is its own.

    Parameters
    ----------
    job : BlockJob
    k : int
        The task: block ``job.todo[k]``.
    loaded : (DetectedReturns or None, (n,) bool or None), optional
        The block's pulses with its halo and which are its own, as
        :func:`~pipeline.survey_blocks.load_blocks` gives them, where the run's process
        sends them (its workers cannot read the store: ``job.store`` is None). Default:
        read from ``job.store``.

    Returns
    -------
    BlockResult
        ``points`` None where no pulse lies near enough for a point to fall in the block.
    """
    try:
        return _run_block(job, k, loaded)
    except Exception as exc:
        b = int(job.todo[k])
        box = ", ".join(f"{v:.1f}" for v in job.blocks.box_m(b))
        raise RuntimeError(f"block {b} (local box w, e, s, n = {box} m) failed: {exc}") from exc


def _run_block(job: BlockJob, k: int, loaded: tuple | None) -> BlockResult:
    from pipeline.outputs.grid_tiles import cell_records
    from pipeline.survey_block_reach import processing_rows
    from pipeline.survey_blocks import (
        _sub_layout,
        load_blocks,
        own_cells,
        tests_reach_m,
        tpu_points,
    )
    from pipeline.survey_processing import process_survey
    from pipeline.survey_tiles import points_tile_order, returns_position_m
    from pipeline.worker_malloc import after_chunks

    after_chunks()  # a worker that ran chunks before (a Dask worker) leaves their thresholds
    b, clock = int(job.todo[k]), StageClock()
    ps, air, blocks = job.scene.process, job.ctx.instrument.air_index, job.blocks
    if loaded is None:
        with clock.stage("blocks"):
            loaded = load_blocks(job.store, blocks, [b], job.halo_m)
    ret, own = loaded
    if ret is None or (job.counts[b] == 0 and not _reached(ret, blocks, b, job.reach_m, air)):
        # no pulse near enough for a point of its to fall in the block
        return BlockResult(b, stages=clock.to_dict())
    sub, row0, col0 = _sub_layout(blocks, b, job.halo_m)
    # the TPU of the points the block keeps, and of those its tests read (one grid cell
    # more: a point on the block's edge may fall in either cell); the class-43 and rejection
    # tests are made at the same points
    keep = functools.partial(
        tpu_points,
        own_pulse_id=ret.pulse_id[own],
        box_m=blocks.box_m(b),
        reach_m=tests_reach_m(ps) + ps.grid_resolution_m,
    )
    pos, box = returns_position_m(ret, air), blocks.box_m(b)
    at = tuple(processing_rows(pos, own, box, r) for r in (job.planes_m, job.krige_m))
    blk = process_survey(
        ret, job.scene, job.plan, job.ctx, sub, clock, _quiet, job.figures, keep, process_at=at
    )
    with clock.stage("outputs"):
        pts = blk.processed.points
        pts = pts.select(np.isin(pts.pulse_id, ret.pulse_id[own]))
        order, starts = points_tile_order(pts, ret, job.layout, air)
        dst, src = own_cells(blocks, b, row0, col0)
        res = BlockResult(
            b,
            points=pts.select(order),
            starts=starts,
            returns=ret.select(own),
            dst=dst,
            records=cell_records(blk.grid, blk.unc.cells, src),
            # the block's own pulses' counts (its halo's are another block's)
            class43=int(np.count_nonzero(pts.classification == SUBMERGED_OBJECT)),
            withheld=int(
                np.count_nonzero(np.isin(blk.processed.withheld_pulse_id, ret.pulse_id[own]))
            ),
            rejected={
                name: int(np.count_nonzero((pts.flags & np.uint16(flag)) != 0))
                for name, flag in RULES.items()
            },
        )
    del ret, own, blk, pts
    trim_heap()
    res.stages = clock.to_dict()
    return res
