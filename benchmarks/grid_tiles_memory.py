"""Memory and time of a blocked survey's grid: filled block by block, then written (issue 15).

Usage: ``PYTHONPATH=CODE python benchmarks/grid_tiles_memory.py PULSES [--trace]``: one
process per figure. ``CODE`` is a checkout whose ``pipeline`` has
:class:`~pipeline.outputs.grid_tiles.GridTiles` (the grid written by tiles) or, before it,
``survey_blocks.SurveyGridAccumulator`` (every field of the whole area in memory); the script
uses whichever it finds.

The grid is square, of as many 5 m cells as a Palmer survey of ``PULSES`` covers at
``--density`` pulses per square metre of its grid (default 1.3: the Palmer benchmark scene's
pulses over its grid's bounds, session 28; over its flown area, :func:`density_per_m2`, it is
3.9: a 300 m wide strip's grid spans its swaths, about twice the area's width). It is filled
by blocks of 57 cells (285 m, the 1 M-pulse runs' blocks of session 28), each a block grid
with a halo of 34 cells (171 m) of random cells, 30 % empty; then come the overlay of a
sample's posterior cells (a whole-area ``CellUncertainty``, made before the figures start:
the run holds it either way) and ``grid.tif``, ``grid.nc``.

Prints, for the fill and for the writing: the wall seconds, the RSS high-water mark of the
phase above the RSS before the fill (``/proc/self/clear_refs`` resets ``VmHWM``), and with
``--trace`` the tracemalloc peak of the phase above the traced memory before the fill
(numpy's and Python's allocations; not GDAL's or HDF5's; wall seconds are then tracemalloc's,
not comparable). Results: ``RESULTS_e2e.md``, session 31.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys
import tempfile
import time
import tracemalloc
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

BLOCK, HALO, RES = 57, 34, 5.0


def density_per_m2() -> float:
    """Pulses per square metre of the Palmer benchmark scene (1 M pulses' area)."""
    from bench_e2e import palmer

    from pipeline.scene import parse_scene
    from pipeline.simulate import survey

    s = parse_scene(palmer(1_000_000, False, 20_000))
    w, e, so, n = s.flight.area_m
    return survey.plan_lines(s.flight, s.scanner).n_pulses_total / ((e - w) * (n - so))


def _kib(key: str) -> int:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith(key + ":"):
            return int(line.split()[1])
    raise KeyError(key)


def _reset_hwm() -> int:
    """Reset the RSS high-water mark; the RSS now (KiB)."""
    Path("/proc/self/clear_refs").write_text("5")
    return _kib("VmRSS")


def _cells(rng, shape, empty: float = 0.3):
    """A random grid and cell uncertainty of ``shape`` (every field), ``empty`` of it empty."""
    from pipeline.process.grid import Grid
    from pipeline.uncertainty.cell_uncertainty import CellUncertainty

    has = rng.random(shape) >= empty
    d = np.where(has, rng.uniform(0.5, 30.0, shape), np.nan)
    count = np.where(has, rng.integers(1, 40, shape), 0).astype(np.int64)
    grid = Grid(
        depth_m=d,
        median_depth_m=d,
        spread_m=np.where(count > 1, 0.05, np.nan),
        z_m=-d,
        count=count,
        x_m=np.arange(shape[1]) * RES,
        y_m=-np.arange(shape[0]) * RES,
        resolution_m=RES,
        bounds_m=np.array([0.0, shape[1] * RES, -shape[0] * RES, 0.0]),
        origin_m=np.zeros(3),
        crs=None,
        mean_depth_m=d,
    )
    tvu = np.where(has, rng.uniform(0.1, 1.0, shape), np.nan)
    cells = CellUncertainty(
        sigma_v_m=tvu / 1.96,
        sigma_h_m=tvu,
        tvu95_m=tvu,
        thu95_m=tvu * 2.45,
        count=count,
        n_posterior=np.zeros(shape, np.int64),
        order=np.where(has, rng.integers(0, 5, shape), -1).astype(np.int8),
    )
    return grid, cells


def _warm_up(out: Path, tiled: bool, origin, crs, datum) -> None:
    """Write a 10 x 10 grid both ways: the libraries' code and first buffers (GDAL's drivers,
    HDF5, dask) are loaded before the figures start."""
    import dask.array  # noqa: F401

    from pipeline.outputs.netcdf import write_grid_nc
    from pipeline.outputs.raster import write_grid_tif

    grid, cells = _cells(np.random.default_rng(2), (10, 10))
    grid = dataclasses.replace(
        grid, origin_m=np.asarray(origin), crs=__import__("pyproj").CRS.from_user_input(crs)
    )
    write_grid_tif(out / "grid.tif", grid, cells)
    write_grid_nc(out / "grid.nc", grid, cells)
    if tiled:
        from pipeline.outputs.grid_tiles import GridFrame, GridTiles

        frame = GridFrame.over(grid.bounds_m, RES, origin, crs, datum, "median")
        with GridTiles(frame) as tiles:
            tiles.put((slice(0, 10), slice(0, 10)), grid, cells, (slice(0, 10), slice(0, 10)))
            tiles.write_tif(out / "grid.tif", cells)
            tiles.write_nc(out / "grid.nc", cells)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("pulses", type=int)
    ap.add_argument("--trace", action="store_true", help="tracemalloc's peaks (slower)")
    ap.add_argument("--density", type=float, default=1.3, help="pulses per m2 of the grid")
    args = ap.parse_args()

    import pipeline.survey_blocks as sb
    from pipeline.survey_tiles import TileLayout

    density = args.density
    side = math.ceil(math.sqrt(args.pulses / density / RES**2))
    bounds = np.array([0.0, side * RES, 0.0, side * RES])
    layout = TileLayout(bounds, RES, BLOCK * RES)
    origin, crs, datum = (430_000.0, 6_120_000.0, 0.0), 32619, -0.2
    tiled = not hasattr(sb, "SurveyGridAccumulator")
    print(
        f"# {args.pulses} pulses at {density:.3f} pulses/m2 of the grid (Palmer: "
        f"{density_per_m2():.2f} of its area): {side} x {side} cells of {RES:g} m"
        f" ({side * side / 1e6:.2f} M), {layout.n_tiles} blocks of {BLOCK} cells + {HALO} halo;"
        f" {'tiles (GridTiles)' if tiled else 'in memory (SurveyGridAccumulator)'}"
    )
    rng = np.random.default_rng(1)
    # the sample's cells (the run holds them either way): posteriors in 5 % of the cells
    _, sample = _cells(rng, (side, side))
    sample = dataclasses.replace(
        sample, n_posterior=(rng.random((side, side)) < 0.05).astype(np.int64)
    )
    out = Path(tempfile.mkdtemp(prefix="grid-bench-"))
    _warm_up(out, tiled, origin, crs, datum)
    if args.trace:
        tracemalloc.start()
    figures = {}

    def phase(name, t0):
        # the peaks above the RSS and the traced memory before the fill
        peak = (tracemalloc.get_traced_memory()[1] / 2**20) if args.trace else float("nan")
        figures[name] = (time.perf_counter() - t0, (_kib("VmHWM") - rss0) / 1024, peak)
        if args.trace:
            tracemalloc.reset_peak()

    rss0, t0 = _reset_hwm(), time.perf_counter()
    if tiled:
        from pipeline.outputs.grid_tiles import GridFrame, GridTiles

        frame = GridFrame.over(bounds, RES, origin, crs, datum, "median")
        acc = GridTiles(frame)
    else:
        from pipeline.process.grid import Grid

        # what the run made: the empty grid and cells of the whole area, copied by the
        # accumulator
        empty_grid, empty_cells = _cells(np.random.default_rng(0), (side, side), empty=1.0)
        empty_grid = dataclasses.replace(
            empty_grid,
            x_m=RES * (np.arange(side) + 0.5),
            y_m=side * RES - RES * (np.arange(side) + 0.5),
            bounds_m=bounds,
            origin_m=np.asarray(origin, dtype=np.float64),
            crs=__import__("pyproj").CRS.from_user_input(crs),
            datum_m=datum,
        )
        assert isinstance(empty_grid, Grid)
        acc = sb.SurveyGridAccumulator(empty_grid, empty_cells)
        del empty_grid, empty_cells
    put_s = 0.0
    for b in range(layout.n_tiles):
        sub, row0, col0 = sb._sub_layout(layout, b, HALO * RES)
        grid, cells = _cells(rng, sub.grid_shape)  # a block's processing made these
        t = time.perf_counter()
        if tiled:
            dst, src = sb.own_cells(layout, b, row0, col0)
            acc.put(dst, grid, cells, src)
        else:
            acc.add(layout, b, grid, cells, row0, col0)
        put_s += time.perf_counter() - t
        del grid, cells
    phase("fill", t0)
    fill_all_s = figures["fill"][0]
    figures["fill"] = (put_s, *figures["fill"][1:])

    _reset_hwm()
    t0 = time.perf_counter()
    if tiled:
        acc.write_tif(out / "grid.tif", sample)
        t_tif = time.perf_counter() - t0
        acc.write_nc(out / "grid.nc", sample)
        acc.close()
    else:
        from pipeline.outputs.netcdf import write_grid_nc
        from pipeline.outputs.raster import write_grid_tif

        grid, cells = acc.result()
        del acc
        sampled = sample.n_posterior > 0
        out_cells = dataclasses.replace(
            cells,
            **{
                f.name: np.where(sampled, getattr(sample, f.name), getattr(cells, f.name))
                for f in dataclasses.fields(cells)
            },
        )
        write_grid_tif(out / "grid.tif", grid, out_cells)
        t_tif = time.perf_counter() - t0
        write_grid_nc(out / "grid.nc", grid, out_cells)
    phase("write", t0)
    sizes = {p.name: p.stat().st_size / 2**20 for p in out.iterdir()}
    for p in out.iterdir():
        p.unlink()
    out.rmdir()
    print(f"{'phase':6s} {'wall s':>8s} {'RSS peak MiB':>13s} {'traced peak MiB':>16s}")
    for name, (wall, rss, traced) in figures.items():
        print(f"{name:6s} {wall:8.2f} {rss:13.1f} {traced:16.1f}")
    print(
        f"# fill: {fill_all_s:.2f} s with the blocks' random cells made; writing grid.tif"
        f" {t_tif:.2f} s; files (MiB): {sizes}"
    )


if __name__ == "__main__":
    main()
