"""``bathy run`` after the chunk loop for a survey too large to hold, block by block.

The passes of :mod:`pipeline.survey_blocks`, wired and timed.
"""

from __future__ import annotations

import dataclasses
import functools
import gc
import time

import numpy as np

from pipeline.detection_store import SetAside
from pipeline.memory_budget import (
    BASE_BYTES,
    BYTES_PER_PULSE,
    MEMORY_SHARE,
    machine_memory_bytes,
)
from pipeline.outputs.grid_tiles import GridFrame, GridTiles, Overlay
from pipeline.outputs.las_fields import LineEnds
from pipeline.parallel import Executor
from pipeline.process.classify import (
    BATHYMETRIC_POINT,
    DERIVED_WATER_SURFACE,
    GROUND,
    HIGH_NOISE,
    LOW_NOISE,
    NO_BOTTOM_FOUND_AT,
    SUBMERGED_OBJECT,
    UNCLASSIFIED,
    WATER_COLUMN,
    WATER_SURFACE,
)
from pipeline.process.coverage import area_cells
from pipeline.rss_watch import current_rss_mb
from pipeline.stages import trim_heap
from pipeline.survey_block_reach import processing_reach_m
from pipeline.survey_block_task import BlockJob, blocks_side_by_side, run_block
from pipeline.survey_blocks import (
    LineSums,
    block_halo_m,
    block_layout,
    blocks_to_process,
    load_blocks,
    pulse_counts,
    sample_blocks,
    with_survey_lines,
)
from pipeline.survey_tiles import points_tile_order

__all__ = ["run_blocked", "CoverageAccumulator"]

#: Every class processing makes: the points file's header names them before any is written.
CLASSES = np.array(
    [
        UNCLASSIFIED,
        GROUND,
        LOW_NOISE,
        HIGH_NOISE,
        BATHYMETRIC_POINT,
        WATER_SURFACE,
        DERIVED_WATER_SURFACE,
        SUBMERGED_OBJECT,
        NO_BOTTOM_FOUND_AT,
        WATER_COLUMN,
    ],
    dtype=np.uint8,
)


class CoverageAccumulator:
    """:func:`~pipeline.process.coverage.area_coverage` of points given block by block."""

    def __init__(self, area_m, cell_m: float) -> None:
        self.area_m, self.cell_m = area_m, float(cell_m)
        self.seen = np.zeros(area_cells(np.zeros((0, 2)), area_m, cell_m)[1], dtype=bool)

    def add(self, xy_m: np.ndarray) -> None:
        """Mark the cells holding a point of ``xy_m`` ``(n, 2)``."""
        self.seen[area_cells(xy_m, self.area_m, self.cell_m)[0]] = True

    def fraction(self) -> float:
        """Fraction of the area's cells holding a point."""
        return float(self.seen.mean())


def _say_fewer(log, side: int, workers: int, loaded: float, whose: str) -> None:
    """Log that ``side`` blocks run at once, not ``workers``, as ``whose`` memory holds them."""
    if side < workers:
        log(
            f"  {side} block(s) at a time, not {workers}: each holds about {loaded:.3g}"
            f" pulses (run.block_pulses), more than {whose} memory holds side by side"
        )


def _block_runner(executor, store, counts, load: float, log):
    """Where the blocks run: ``(runner, source, side, send)``.

    ``runner``: an executor; ``source``: the store as its workers read it; ``side``: blocks at
    once; ``send``: None where the workers read the store, else each task is sent its block's
    pulses, read here (:func:`run_block`'s ``loaded``): True, or for a cluster on other
    machines the workers' slots (:meth:`~pipeline.parallel.Executor.map`'s ``slots``: each
    worker once per block its memory holds). Side by side on a process pool or a Dask cluster,
    as many as the memory holds (:func:`blocks_side_by_side`: each block holds about its
    loaded pulses): this machine's, or for a cluster on other machines its workers' own
    (:meth:`~pipeline.parallel.Executor.cluster_memory`); one at a time here where only one
    fits.
    """
    n = store.n_pulses
    if executor is None or executor.workers <= 1:
        return Executor(workers=1), store, 1, None
    loaded = min(n, float(counts.max()) * load)
    reader = store.reader()
    reads = reader is not None and executor.shares_file(reader.path)
    if not reads and executor.scheduler is not None:
        # workers on other machines: their memory holds the blocks, not this one's; each
        # listed once per block it holds, the tasks sent to these slots in turn
        per_block = BASE_BYTES + BYTES_PER_PULSE * loaded
        slots = [
            address
            for address, threads, free in executor.cluster_memory()
            for _ in range(min(threads, int(free // per_block)))
        ][: executor.workers]
        side = max(1, len(slots))
        log(
            "  blocks sent to the cluster's workers with their pulses: the workers cannot"
            " read this process's detection store (a cluster on another machine)"
        )
        _say_fewer(log, side, executor.workers, loaded, "the workers'")
        # (no worker with room for one: one at a time, wherever Dask puts it)
        return executor, store, side, slots or True
    free = MEMORY_SHARE * machine_memory_bytes() - (current_rss_mb() or 0.0) * 2.0**20
    side = blocks_side_by_side(executor.workers, loaded, free)
    _say_fewer(log, side, executor.workers, loaded, "this machine's")
    if side == 1:
        return Executor(workers=1), store, 1, None
    if not reads:
        log("  blocks sent to the workers with their pulses: this machine has no /proc")
    source, send = (reader, None) if reads else (store, True)
    if executor.scheduler is None and side < executor.workers:
        return Executor(workers=side), source, side, send
    return executor, source, side, send


def _block_pulses(clock, store, blocks, todo, halo: float, k: int) -> tuple:
    """Task ``k``'s block's pulses with its halo, read here for workers that cannot."""
    with clock.stage("blocks"):
        return load_blocks(store, blocks, [int(todo[k])], halo)


def run_blocked(scene, plan, out, clock, log, progress, executor, store, sim, ctx, layout):
    """The passes of :mod:`pipeline.survey_blocks`; returns ``(files, evaluation)``.

    Parameters
    ----------
    store : DetectionStore
        The survey's detections (open).
    sim : SimulatedSurvey
        The chunk loop's result, ``returns`` None.
    layout : TileLayout
        The grid's bounds and the points file's tiles.
    """
    from pipeline.outputs.las import LazTileWriter, las_header
    from pipeline.process_tiles import beam_reach_m
    from pipeline.survey_finish import finish_survey, log_cleanup
    from pipeline.survey_processing import process_survey

    ps, fr, run = scene.process, scene.frame, scene.run
    origin = (fr.origin_easting_m, fr.origin_northing_m, 0.0)
    n_pulses = store.n_pulses
    why = (
        f"run.block_m = {run.block_m:g} m"
        if run.block_m is not None
        else f"more than run.whole_pulses = {run.whole_pulses} or run.block_pulses ="
        f" {run.block_pulses}"
    )
    log(f"  {n_pulses} pulses, processed block by block ({why})")
    with clock.stage("blocks"):
        # the sample's blocks: about an eighth of it each, so it spreads over the survey
        pre = block_layout(scene, layout.bounds_m, n_pulses, 0.0, run.sample_pulses // 8)
        pre_counts = pulse_counts(store, pre)
        sample = sample_blocks(pre_counts, run.sample_pulses, pre.shape)
        # the sample's own pulses only: a survey of its own, its blocks' edges its edges
        sample_returns, _ = load_blocks(store, pre, sample, 0.0)
    log(
        f"  sample: {sample.size} blocks of {pre.tile_m:g} m spread over the survey, "
        f"{len(sample_returns)} of its {n_pulses} pulses (run.sample_pulses)"
    )
    # the sample, processed as a survey of its own: the survey-wide figures
    # its grid and cells: only the rows and columns of the survey's grid its points are in
    made = process_survey(sample_returns, scene, plan, ctx, layout, clock, log, held_axes=True)
    with clock.stage("blocks"):
        # streamed: the beams' reach at the sample's level, the lines' ends and axes
        reach, lines, sums = 0.0, LineEnds(), LineSums()
        for c in range(len(store.chunks)):
            part = store.returns([c])
            reach = max(reach, beam_reach_m(part, ctx, made.figures.wide))
            lines.add(part)
            sums.add(part)
        figures = with_survey_lines(made.figures, *sums.axes())
        halo = block_halo_m(ctx, ps, reach)
        blocks = block_layout(scene, layout.bounds_m, n_pulses, halo)
        counts = pulse_counts(store, blocks)
        todo = blocks_to_process(blocks, counts, reach)
        # how far past a block its pulses' planes and kriged sea are read (survey_block_reach)
        krige_m, planes_m = processing_reach_m(ctx, ps, reach)
    used = np.flatnonzero(counts > 0)
    load = ((blocks.tile_m + 2.0 * halo) / blocks.tile_m) ** 2
    log(
        f"  blocks of {blocks.tile_m:g} m ({used.size} with pulses, at"
        f" most {int(counts.max())} each), halo {halo:.0f} m (beam reach {reach:.1f} m): each"
        f" loads ~{load:.1f} times its own area"
        + (" (raise run.block_pulses: the halo dominates)" if load > 4.0 else "")
    )
    water = figures.datum.water_level_m
    # the survey's grid, on disk: each block's own cells are written as the block ends
    # (pipeline.outputs.grid_tiles), never an array of the whole area
    frame = GridFrame.over(
        layout.bounds_m, layout.resolution_m, origin, fr.crs, water, ps.grid_statistic
    )
    cover = CoverageAccumulator(scene.flight.area_m, ps.grid_resolution_m)
    n_obj, rejected, withheld = 0, {}, 0
    header = las_header(CLASSES, made.processed.points.amplitude is not None, fr.crs, origin)
    air = ctx.instrument.air_index
    with clock.stage("blocks"):
        # the sample's products wait on disk while the blocks run (each block's memory)
        aside = SetAside(out, made, sample_returns)
        del made, sample_returns
        gc.collect()
        trim_heap()
    runner, source, side, send = _block_runner(executor, store, counts, load, log)
    job = BlockJob(
        None if send else source, blocks, todo, counts, halo, reach, planes_m, krige_m, scene,
        plan, ctx, figures, layout,
    )  # fmt: skip
    log(f"  blocks on {side} worker(s)")
    # the survey's grid on disk, removed when the survey is finished
    with GridTiles(frame) as tiles:
        t0, done = time.perf_counter(), 0
        with LazTileWriter(out / "points.laz", header, ctx.instrument.amplitude_full_scale) as w:
            # at most `side` blocks running (a pool of `side` keeps one more queued, so that
            # both run while this process writes; a cluster runs all it is given); the
            # manifest's map_wall_s stays the chunk loop's
            ahead = side + 1 if runner.scheduler is None and side > 1 else side
            tasks = runner.map(
                run_block, job, todo.size, ahead=ahead, timed=False,
                payload=functools.partial(_block_pulses, clock, store, blocks, todo, halo)
                if send else None,
                slots=send if isinstance(send, list) else None,
            )  # fmt: skip
            for k, res in enumerate(tasks):
                clock.add(res.stages)
                if res.points is not None:
                    done += 1
                    with clock.stage("outputs"):
                        pts = res.points
                        for i in range(res.starts.size - 1):
                            w.write(pts.select(slice(res.starts[i], res.starts[i + 1])),
                                    res.returns, lines)  # fmt: skip
                        tiles.put_records(res.dst, res.records)
                        cover.add(pts.xyz_m[:, :2])
                        del pts
                    n_obj += res.class43
                    withheld += res.withheld
                    for name, hits in res.rejected.items():
                        rejected[name] = rejected.get(name, 0) + hits
                del res
                if (k + 1) % 10 == 0 or k + 1 == todo.size:
                    log(
                        f"  {k + 1}/{todo.size} blocks looked at, {done} processed "
                        f"({time.perf_counter() - t0:.0f} s)"
                    )
        blocks_wall_s = time.perf_counter() - t0
        covered = cover.fraction()
        with clock.stage("blocks"):
            made, sample_returns = aside.take()
        log_cleanup(
            log,
            dataclasses.replace(made.processed, claims_withheld=withheld),
            n_obj,
            rejected,
            ps,
            covered,
        )
        sample_sim = dataclasses.replace(sim, returns=sample_returns)

        def deliver(unc, _grid):
            # the points are written; the survey's grid with its cells' TPU, and in the cells
            # where the sample's posteriors ran, the sample's cells (module notes), which hold
            # some of the grid's rows and columns
            overlay = Overlay(unc.cells, made.grid.rows, made.grid.cols)
            files = {
                "points": out / "points.laz",
                "grid": tiles.write_tif(out / "grid.tif", overlay),
                "grid_nc": tiles.write_nc(out / "grid.nc", overlay),
            }
            # the views' points in the order a points file of the sample would hold them
            order, _ = points_tile_order(made.processed.points, sample_returns, layout, air)
            return files, order

        blocked = {
            "block_m": blocks.tile_m,
            "blocks": done,
            "blocks_wall_s": blocks_wall_s,
            "block_workers": side,
            "blocks_sent": bool(send),
            "blocks_with_pulses": int(used.size),
            "halo_m": halo,
            "sample_blocks": int(sample.size),
            "sample_block_m": pre.tile_m,
            "sample_pulses": len(sample_returns),
            "survey_pulses": int(n_pulses),
            "evaluated_on": "the sample's blocks, processed as a survey of their own",
            "class43_points": n_obj,
            "rejected": rejected,
            "class45_withheld": withheld,
        }
        return finish_survey(
            scene,
            plan,
            out,
            clock,
            log,
            progress,
            executor,
            sample_sim,
            ctx,
            made,
            covered,
            deliver,
            extra={"blocked": blocked},
        )
