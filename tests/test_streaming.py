"""Streaming (issue 15): detections spilled to disk, grids and points file made tile by tile.

The outputs must not depend on the tile size or the chunk size: the untiled path (one tile,
one chunk per few thousand pulses) is the reference the tiled one is compared with, to the bit.
"""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path

import numpy as np
import pytest

from pipeline.detection_store import DetectionStore, SurveyAggregates
from pipeline.process.grid import grid_points
from pipeline.survey_tiles import GridAccumulator, TileLayout, chunks_meeting, snap_tile_m
from tests.test_parallel import _assert_same, _outputs, _scene


def _part(ids: np.ndarray, x0: float) -> dict[str, np.ndarray]:
    """A chunk's fields: nadir beams from 100 m over ``x = x0 + id``, a surface at 100 m range."""
    n = len(ids)
    t_s = 2.0 * 100.0 / 299_792_458.0  # straight down 100 m in vacuum (air index 1)
    origin = np.column_stack([x0 + ids.astype(float), np.zeros(n), np.full(n, 100.0)])
    return {
        "pulse_id": ids,
        "origin_meas_m": origin,
        "direction_meas": np.tile([0.0, 0.0, -1.0], (n, 1)),
        "has_surface": np.ones(n, dtype=bool),
        "t_surface_s": np.full(n, t_s),
        "has_bottom": np.zeros(n, dtype=bool),
        "t_bottom_s": np.zeros(n),
        "flags": np.arange(n, dtype=np.uint16),
    }


def test_store_round_trip_leaves_no_file(tmp_path):
    out = tmp_path / "run"  # not made yet: the store must not make it
    with DetectionStore(out, air_index=1.0) as store:
        a, b = _part(np.arange(0, 5), 10.0), _part(np.arange(5, 8), 10.0)
        store.append(a)
        store.append(b)
        store.replace_field(1, "t_bottom_s", np.array([1.0, 2.0, 3.0]))
        cat = store.load()
        assert list(cat["pulse_id"]) == list(range(8))
        assert cat["t_bottom_s"].tolist() == [0.0] * 5 + [1.0, 2.0, 3.0]
        np.testing.assert_array_equal(cat["origin_meas_m"][5:], b["origin_meas_m"])
        # the chunk's box: the surface points, 100 m straight below the origins
        np.testing.assert_allclose(store.chunks[1].bbox_m, [15.0, 17.0, 0.0, 0.0], atol=1e-9)
        assert store.chunks[1].pulse_id_range == (5, 7)
        assert chunks_meeting(store.chunks, np.array([16.5, 20.0, -1.0, 1.0]), 0.0) == [1]
        assert chunks_meeting(store.chunks, np.array([16.5, 20.0, -1.0, 1.0]), 3.0) == [0, 1]
        assert os.listdir(tmp_path) == []  # an unnamed file: nothing to leave behind
    assert not out.exists()


def test_aggregates_do_not_depend_on_the_chunking():
    rng = np.random.default_rng(3)
    n = 1000
    t_lim = np.where(rng.random(n) < 0.7, 1e-6 + rng.random(n) * 1e-7, 0.0)
    full = _part(np.arange(n), 0.0) | {"t_detection_limit_s": t_lim}
    full["t_surface_s"] = full["t_surface_s"] + rng.random(n) * 1e-8

    def run(bounds, n_total):
        agg = SurveyAggregates(n_total, seed=5, air_index=1.0)
        for lo, hi in zip(bounds[:-1], bounds[1:], strict=True):
            agg.add({k: v[lo:hi] for k, v in full.items()}, None, 1.34, 1)
        return agg

    for n_total in (n, 10_000_000):  # every pulse, and a sample of about a tenth of them
        one, many = run([0, n], n_total), run([0, 7, 300, 301, 999, n], n_total)
        assert one.photon_summary() == many.photon_summary()
        assert one.median_surface_range_m() == many.median_surface_range_m()
    # every pulse: the median is the plain one, the percentiles the plain ones
    r = 299_792_458.0 * full["t_surface_s"] / 2.0
    assert run([0, n], n).median_surface_range_m() == float(np.median(r))
    assert run([0, n], n).photon_summary()["photon_shots_with_detection_limit"] == int(
        np.count_nonzero(t_lim > 0)
    )


def test_snap_tile_to_whole_cells():
    assert snap_tile_m(21.0, 5.0, 100.0) == 20.0
    assert snap_tile_m(1.0, 5.0, 100.0) == 5.0  # at least one cell
    assert snap_tile_m(None, 5.0, 98.0) == 100.0  # one tile over everything


@pytest.mark.parametrize("tile_m", [2.0, 4.0, 6.0, 100.0])
def test_grid_by_tiles_is_the_grid_of_all_points(tile_m):
    rng = np.random.default_rng(7)
    n = 3000
    # points on cell edges and corners too (the half-open rule must give one cell, one tile)
    x = np.concatenate([rng.uniform(0.0, 20.0, n), np.arange(0.0, 20.0, 1.0)])
    y = np.concatenate([rng.uniform(-10.0, 10.0, n), np.arange(-10.0, 10.0, 1.0)])
    d = 5.0 + 0.1 * x + rng.normal(0.0, 0.3, x.size)
    bounds = np.array([0.0, 20.0, -10.0, 10.0])
    ref = grid_points(x, y, d, resolution_m=1.0, bounds_m=bounds)
    lay = TileLayout(bounds, 1.0, tile_m)
    acc = GridAccumulator(lay, (0.0, 0.0, 0.0), None, "median")
    tiles = lay.tile_of_xy(x, y)
    for t in np.unique(tiles):
        acc.add(x[tiles == t], y[tiles == t], d[tiles == t], -d[tiles == t], int(t))
    got = acc.grid()
    for name in ("depth_m", "median_depth_m", "mean_depth_m", "spread_m", "z_m", "count"):
        np.testing.assert_array_equal(getattr(got, name), getattr(ref, name), err_msg=name)
    # one cell by hand: the points of [3, 4) x (2, 3] (row 7 from the north, column 3)
    inside = (x >= 3.0) & (x < 4.0) & (y > 2.0) & (y <= 3.0)
    assert got.count[7, 3] == inside.sum()
    assert got.median_depth_m[7, 3] == np.median(d[inside])


def _sorted_outputs(out: Path):
    """:func:`tests.test_parallel._outputs` with the points in (pulse, kind, z) order: tiles
    write the pulses in their own order."""
    points, bands, ev = _outputs(out)
    order = np.lexsort((points["Z"], points["kind"], points["pulse_id"]))
    return {k: v[order] for k, v in points.items()}, bands, ev


@pytest.mark.slow
def test_tiles_and_chunks_give_the_same_outputs(tmp_path):
    from pipeline.run import run_scene

    runs = []
    for i, (chunk, tile_m) in enumerate(((4000, None), (900, 20.0), (4000, 5.0))):
        scene = _scene(chunk)
        # tiles of 4 and 1 grid cells (5 m): the smallest tiles the grid allows
        scene = dataclasses.replace(scene, run=dataclasses.replace(scene.run, tile_m=tile_m))
        out = tmp_path / f"out{i}"
        run_scene(scene, out, log=lambda _: None)
        runs.append(_sorted_outputs(out))
    assert len(runs[0][0]["X"]) > 1000 and runs[0][2]["pulses"] > 5000
    for got in runs[1:]:
        _assert_same(runs[0], got)
