"""Memory of a blocked survey's sample grid and cell uncertainty, by the survey's area (issue 15).

Usage: ``PYTHONPATH=. python benchmarks/sample_grid_memory.py PULSES [--sample PULSES]``.

A blocked survey processes a sample of whole blocks as a survey of its own
(:func:`~pipeline.survey_processing.process_survey`). Until 053f084 it was gridded over the
*whole survey's* bounds; now only on the rows and columns of that grid its points are in
(:mod:`pipeline.process.grid_axes`). This measures what the grid costs, both ways, at the
grid size a survey of ``PULSES`` pulses gives (the square grid of 5 m cells of
``benchmarks/grid_tiles_memory.py``: 1.3 pulses per square metre of the grid), against the
same sample gridded block by block over each block grown by 4 cells (a beam reach: what a
grid of the sample's own blocks would hold).

The sample: ``--sample`` pulses (default 500 000, ``run.sample_pulses``) in blocks of an eighth
of it each, chosen by :func:`~pipeline.survey_blocks.sample_blocks` from a layout of equal
counts (Halton points: spread over the survey); one sounding per pulse, uniform in its block.
Per phase, tracemalloc's peak above its start (numpy's and Python's allocations) and the
bytes the phase's results hold: the grid (:class:`~pipeline.survey_tiles.GridAccumulator`
over the run's 250 m tiles, as :func:`~pipeline.survey_tiles.grid_by_tiles`), the cells'
uncertainty (:func:`~pipeline.uncertainty.cell_uncertainty.cell_uncertainty`, a synthetic
TPU), and the evaluation's cell errors (:func:`~pipeline.evaluate.grid_errors_m`, a plane as
the truth). Results: ``RESULTS_e2e.md``, session 31.
"""

from __future__ import annotations

import argparse
import math
import tracemalloc
from types import SimpleNamespace

import numpy as np

RES, DENSITY, MARGIN = 5.0, 1.3, 4


def _held(*objs) -> int:
    """Bytes of the numpy arrays among the attributes of ``objs`` (and arrays themselves)."""
    total = 0
    for o in objs:
        items = [o] if isinstance(o, np.ndarray) else list(vars(o).values())
        total += sum(a.nbytes for a in items if isinstance(a, np.ndarray))
    return total


def _phase(fn):
    """``(fn(), tracemalloc's peak during it above its start, B)``."""
    tracemalloc.reset_peak()
    start = tracemalloc.get_traced_memory()[0]
    out = fn()
    return out, tracemalloc.get_traced_memory()[1] - start


def grid_cells(bounds_m, x, y, depth, held_axes=False):
    """The grid, its cells and the evaluation's errors of soundings ``x, y, depth`` on ``bounds_m``.

    ``held_axes``: only the rows and columns the soundings are in (``bathy run``'s sample).

    Returns ``{phase: (traced peak B, held B)}``.
    """
    from pipeline.evaluate import grid_errors_m
    from pipeline.process.grid_axes import occupied_axes
    from pipeline.survey_tiles import GridAccumulator, TileLayout, snap_tile_m
    from pipeline.uncertainty.cell_uncertainty import cell_uncertainty

    w, e, s, n = bounds_m
    layout = TileLayout(
        np.asarray(bounds_m, float), RES, snap_tile_m(250.0, RES, max(e - w, n - s))
    )

    def make_grid():
        axes = occupied_axes(x, y, layout.bounds_m, RES) if held_axes else None
        acc = GridAccumulator(layout, (0.0, 0.0, 0.0), None, "median", axes)
        tiles = layout.tile_of_xy(x, y)
        for t in np.unique(tiles):
            sel = tiles == t
            acc.add(x[sel], y[sel], depth[sel], -depth[sel], int(t))
        return acc.grid()

    grid, g_peak = _phase(make_grid)
    sig = np.full(x.size, 0.1)
    tpu = SimpleNamespace(
        xyz_m=np.column_stack([x, y, -depth]),
        sigma_v_correlated_m=sig,
        sigma_v_random_m=sig,
        sigma_h_correlated_m=sig,
        sigma_h_random_m=sig,
    )
    cells, c_peak = _phase(lambda: cell_uncertainty(grid, tpu))
    errs, e_peak = _phase(lambda: grid_errors_m(grid, truth_depth_m=lambda a, b: 20.0 + 0 * a))
    return {
        "grid": (g_peak, _held(grid)),
        "cells": (c_peak, _held(cells)),
        "evaluation's cell errors": (e_peak, _held(*errs)),
    }


def main() -> None:
    from pipeline.survey_blocks import sample_blocks

    ap = argparse.ArgumentParser()
    ap.add_argument("pulses", type=int)
    ap.add_argument("--sample", type=int, default=500_000)
    a = ap.parse_args()
    side = int(round(math.sqrt(a.pulses / DENSITY) / RES))  # cells
    block = max(1, int(round(math.sqrt(a.sample / 8 / DENSITY) / RES)))
    nb = max(1, side // block)
    counts = np.full(nb * nb, a.sample // 8, dtype=np.int64)
    picked = sample_blocks(counts, a.sample, (nb, nb))
    rng = np.random.default_rng(0)
    per = a.sample // picked.size
    xs, ys = [], []
    boxes = []
    for b in picked:
        i, j = divmod(int(b), nb)
        x0, y1 = j * block * RES, -i * block * RES  # north-west corner; rows go south
        xs.append(x0 + rng.random(per) * block * RES)
        ys.append(y1 - rng.random(per) * block * RES)
        m = MARGIN * RES
        boxes.append([x0 - m, x0 + block * RES + m, y1 - block * RES - m, y1 + m])
    x, y = np.concatenate(xs), np.concatenate(ys)
    depth = 20.0 + rng.normal(0.0, 0.2, x.size)
    whole = np.array([0.0, side * RES, -side * RES, 0.0])
    print(
        f"grid {side} x {side} cells ({side * side / 1e6:.2f} M) of {RES:g} m; sample "
        f"{picked.size} blocks of {block} x {block} cells, {x.size} soundings"
    )
    tracemalloc.start()
    rows = {
        "whole survey's bounds (before 053f084)": grid_cells(whole, x, y, depth),
        "its rows and columns (grid_axes, now)": grid_cells(whole, x, y, depth, True),
    }
    own = {}
    for x0, x1, y0, y1 in boxes:
        sel = (x >= x0) & (x < x1) & (y > y0) & (y <= y1)
        one = grid_cells(np.array([x0, x1, y0, y1]), x[sel], y[sel], depth[sel])
        for ph, (peak, held) in one.items():
            p0, h0 = own.get(ph, (0, 0))
            own[ph] = (max(p0, peak), h0 + held)
    rows[f"each sample block + {MARGIN} cells (largest peak, held summed)"] = own
    tracemalloc.stop()
    for name, phases in rows.items():
        print(name)
        held = sum(h for _, h in phases.values())
        for ph, (peak, h) in phases.items():
            print(f"  {ph:26s} traced peak {peak / 2**20:8.1f} MiB, held {h / 2**20:8.1f} MiB")
        print(f"  {'held in all':26s} {held / 2**20:8.1f} MiB")


if __name__ == "__main__":
    main()
