"""A survey processed block by block (issue 15): the same outputs as processed whole.

``bathy run`` of a survey too large to hold reads it back from the store one block and its
halo at a time (:mod:`pipeline.survey_blocks`). With every block in the sample, the survey-wide
figures are the whole survey's, so each block's own points, cells and counts must be the ones
the whole survey's processing gives them: compared here, exactly, on a simulated wave survey
with a shore and class-45 claims (``tests/test_process_tiles.py``'s), against the same survey
processed whole. The parts the passes are built of are checked against brute force.
"""

from __future__ import annotations

import json
import tomllib

import numpy as np
import pytest

from pipeline.detection_store import DetectionStore, pulse_position_m
from pipeline.outputs.las_fields import LineEnds, scan_angle_rad
from pipeline.process.coverage import area_coverage
from pipeline.process.facet_excess import line_axes
from pipeline.process.returns import DetectedReturns
from pipeline.run import run_scene
from pipeline.scene import parse_scene
from pipeline.survey_blocks import LineSums, blocks_to_process, load_blocks, sample_blocks
from pipeline.survey_blocks_run import CoverageAccumulator
from pipeline.survey_tiles import TileLayout
from tests.conftest import ROOT
from tests.outputs.test_grid_tiles import assert_same_nc, assert_same_tif


def test_sample_blocks_take_every_block_under_the_cap_else_a_spread_set():
    counts = np.array([0, 5, 7, 0, 3, 9, 4, 6, 8, 2])
    used = np.flatnonzero(counts)
    np.testing.assert_array_equal(sample_blocks(counts, 44), used)  # 44 = all of them
    # one row of 10 blocks, centres at 0.05, 0.15, ...: the Halton points' x 1/2, 1/4, 3/4,
    # 1/8 take blocks 4 (tie with 5: the first), 2, 7, 1, holding 3, 7, 6, 5
    np.testing.assert_array_equal(sample_blocks(counts, 20), [2, 4, 7])  # + 5 = 21 > 20
    np.testing.assert_array_equal(sample_blocks(counts, 21), [1, 2, 4, 7])
    np.testing.assert_array_equal(sample_blocks(counts, 15), [2, 4])
    assert sample_blocks(counts, 1).size == 1  # at least one block
    assert sample_blocks(np.zeros(4, dtype=np.int64), 10).size == 0


@pytest.mark.parametrize("shape", [(8, 8), (6, 16), (16, 6), (1, 40), (40, 1)])
def test_a_sample_of_blocks_spreads_over_both_axes_of_the_survey(shape):
    # equal blocks, an eighth of them sampled: both halves of the rows and of the columns
    # have some, and no row or column holds more than half of them (row-major ranks alone
    # put every 8th block of an 8-wide layout in one column)
    counts = np.full(shape[0] * shape[1], 100)
    got = sample_blocks(counts, counts.sum() // 8, shape)
    assert got.size == counts.size // 8
    row, col = np.divmod(got, shape[1])
    for idx, n in ((row, shape[0]), (col, shape[1])):
        if n > 1:
            assert np.unique(2 * idx // n).size == 2, (shape, got)
            assert np.bincount(idx).max() <= max(1, got.size // 2), (shape, got)


def _part(rng, n, id0, line):
    d = rng.normal(size=(n, 3)) * [0.2, 0.2, 0.0] + [0.0, 0.0, -1.0]
    d /= np.linalg.norm(d, axis=1)[:, None]
    t_s = rng.uniform(1.5e-6, 1.7e-6, n)
    has_s, has_b = rng.random(n) < 0.8, rng.random(n) < 0.5
    return {
        "pulse_id": np.arange(id0, id0 + n, dtype=np.int64),
        "origin_meas_m": np.column_stack(
            [rng.uniform(-80, 80, n), rng.uniform(-80, 80, n), 250 + 0 * t_s]
        ),
        "direction_meas": d,
        "has_surface": has_s,
        "t_surface_s": np.where(has_s, t_s, 0.0),
        "has_bottom": has_b,
        "t_bottom_s": np.where(has_b, t_s + 5e-8, 0.0),
        "surface_confidence": has_s * 1.0,
        "bottom_confidence": has_b * 1.0,
        "flags": np.zeros(n, dtype=np.uint16),
        "surface_amplitude": has_s * 1.0,
        "bottom_amplitude": has_b * 1.0,
        "t_no_bottom_s": np.zeros(n),
        "t_emit_s": id0 * 1e-3 + np.arange(n) * 1e-4,
        "line_id": np.full(n, line, dtype=np.int64),
    }


def test_a_block_and_its_halo_are_the_stored_pulses_within_the_grown_box(tmp_path):
    rng = np.random.default_rng(3)
    parts = [_part(rng, 400, 400 * i, i % 2) for i in range(5)]
    layout = TileLayout(np.array([-100.0, 100.0, -100.0, 100.0]), 5.0, 50.0)  # 4 x 4 blocks
    with DetectionStore(tmp_path, 1.000277) as store:
        for p in parts:
            store.append(p)
        ret, own = load_blocks(store, layout, [5, 10], 12.0)
    # brute force over every pulse: block 5 is row 1, col 1 (x -50..0, y 0..50), block 10
    # row 2, col 2 (x 0..50, y -50..0); inner blocks, so their boxes are closed
    cat = {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}
    xy = pulse_position_m(cat, 1.000277)
    x, y = xy[:, 0], xy[:, 1]
    in5 = (x >= -50) & (x < 0) & (y > 0) & (y <= 50)
    in10 = (x >= 0) & (x < 50) & (y > -50) & (y <= 0)
    near = ((x >= -62) & (x <= 12) & (y >= -12) & (y <= 62)) | (
        (x >= -12) & (x <= 62) & (y >= -62) & (y <= 12)
    )
    want = np.flatnonzero(near | in5 | in10)
    np.testing.assert_array_equal(ret.pulse_id, cat["pulse_id"][want])  # in pulse order
    np.testing.assert_array_equal(own, (in5 | in10)[want])
    np.testing.assert_array_equal(ret.t_bottom_s, cat["t_bottom_s"][want])


def test_line_ends_gathered_part_by_part_give_the_whole_survey_scan_angles():
    rng = np.random.default_rng(5)
    parts = [_part(rng, 300, 300 * i, i % 3) for i in range(6)]
    cat = {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}
    rets = [DetectedReturns(**p) for p in parts]
    whole = DetectedReturns(**cat)
    ends = LineEnds()
    for r in rets[::-1]:  # any order of the parts
        ends.add(r)
    want = LineEnds.of(whole)
    for f in ("line", "t_first", "xy_first", "t_last", "xy_last"):
        np.testing.assert_array_equal(getattr(ends, f), getattr(want, f), err_msg=f)
    angle = scan_angle_rad(whole)
    np.testing.assert_array_equal(scan_angle_rad(rets[2], ends), angle[600:900])
    # the part's own ends give other angles: the lines' whole length matters
    assert not np.array_equal(scan_angle_rad(rets[2]), angle[600:900])


def test_blocks_to_process_are_those_within_a_beam_reach_of_a_block_with_pulses():
    layout = TileLayout(np.array([0.0, 70.0, 0.0, 50.0]), 5.0, 10.0)  # 5 rows, 7 columns
    rng = np.random.default_rng(2)
    counts = np.where(rng.random(35) < 0.15, 9, 0)
    for reach in (0.0, 3.0, 10.0, 14.0):
        k = int(np.ceil(reach / 10.0))
        row, col = np.divmod(np.arange(35), 7)
        with_pulses = np.flatnonzero(counts > 0)
        want = [
            b
            for b in range(35)
            if any(abs(row[b] - row[u]) <= k and abs(col[b] - col[u]) <= k for u in with_pulses)
        ]
        np.testing.assert_array_equal(blocks_to_process(layout, counts, reach), want)


def test_line_axes_summed_part_by_part_are_the_whole_lines_axes():
    rng = np.random.default_rng(9)
    parts = [_part(rng, 500, 500 * i, i % 3) for i in range(6)]
    for i, p in enumerate(parts):  # lines along three headings, with some scatter
        ang = 0.3 + 0.9 * (i % 3)
        t = np.arange(500) * 0.5 + 250.0 * (i // 3)
        p["origin_meas_m"][:, 0] = 1e4 + t * np.cos(ang) + rng.normal(0, 2, 500)
        p["origin_meas_m"][:, 1] = -3e3 + t * np.sin(ang) + rng.normal(0, 2, 500)
    sums = LineSums()
    for p in parts:
        sums.add(DetectedReturns(**p))
    cat = {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}
    ids, axes = line_axes(cat["origin_meas_m"][:, :2], cat["line_id"])
    got_ids, got_axes = sums.axes()
    np.testing.assert_array_equal(got_ids, ids)
    # the same axes up to rounding and sign (they enter squared)
    np.testing.assert_allclose(np.abs(np.sum(got_axes * axes, axis=1)), 1.0, atol=1e-12)


def test_coverage_gathered_block_by_block_is_the_whole_coverage():
    rng = np.random.default_rng(7)
    xy = rng.uniform(-20, 120, size=(300, 2)) * [1.0, 0.5]
    area = (0.0, 100.0, 0.0, 40.0)
    acc = CoverageAccumulator(area, 5.0)
    for part in np.array_split(xy, 7):
        acc.add(part)
    assert acc.fraction() == area_coverage(xy, area, 5.0)
    assert 0.2 < acc.fraction() < 1.0


#: ``[process.objects]`` and ``[process.outliers]`` thresholds lowered so that the class-43
#: and rejection tests fire on :func:`wave_survey_scene`'s survey (at the defaults neither
#: makes a point): of its 24 411 points 589 become class 43 and 681 are rejected (600 m long,
#: ``benchmarks/blocks_exact.py --fire``: 3468 and 4192)
FIRE = {
    "objects": {"k_sigma": 1.0, "min_height_m": 0.05},
    "outliers": {"k_sigma": 1.0, "min_offset_m": 0.05, "max_order": "special"},
}


def wave_survey_scene(area_m=(0.0, 60.0, 0.0, 60.0), prf_hz=15000.0, *, process=None, **run):
    """``tests/test_process_tiles.py``'s survey (one Palmer line over ``area_m``), ``run`` keys.

    ``process``: ``[process]`` sections' keys set on top of the scene's (e.g. :data:`FIRE`).
    Also flown 600 m long by ``benchmarks/blocks_exact.py``.
    """
    data = tomllib.loads(
        (ROOT / "data_synthetic" / "scenes" / "palmer_survey_waves.toml").read_text()
    )
    data["flight"]["area_m"] = list(area_m)
    data["flight"]["run_in_m"] = 0.0
    data["flight"]["altitude_m"] = 250.0
    data["scanner"]["prf_hz"] = prf_hz
    data["water"]["extinction_per_m"] = 0.4  # turbid: class-45 claims on the deep side
    data["trace"] = {"subrays": 3}
    data["process"]["posterior_pulses_per_km2"] = 0.0
    data["process"]["posterior_min_pulses"] = 0
    for section, keys in (process or {}).items():
        data["process"].setdefault(section, {}).update(keys)
    data["run"] = {"views": False, **run}
    return parse_scene(data)


def las_points_by_pulse(out):
    import laspy

    las = laspy.read(out / "points.laz")
    pts = {d: np.asarray(las[d]) for d in las.point_format.dimension_names}
    # the same pulses' points, whatever order the tiles or blocks wrote them in
    order = np.lexsort((pts["return_number"], pts["pulse_id"]))
    return {d: v[order] for d, v in pts.items()}


def evaluation_figures(out):
    """The evaluation's figures: the clock's readings and the blocks' own summary left out."""

    def drop(x):
        if isinstance(x, dict):
            skip = ("stages", "seconds_per_pulse", "timings_s", "blocked")
            return {k: drop(v) for k, v in x.items() if k not in skip}
        return [drop(v) for v in x] if isinstance(x, list) else x

    return drop(json.loads((out / "evaluation.json").read_text()))


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """The survey processed whole; by blocks of 100 m, every block in the sample; and by
    blocks of 60 m, a few of them in the sample: on 1 worker, and the blocked runs again on 2
    (a process pool) and on a Dask cluster of 2 threads."""
    from distributed import LocalCluster

    root = tmp_path_factory.mktemp("blocks")
    lines = {}
    blocks, sampled = {"block_m": 100.0}, {"block_m": 60.0, "sample_pulses": 3000}
    cases = (
        ("whole", {}, 1),
        ("blocks", blocks, 1),
        ("sampled", sampled, 1),
        ("blocks_w2", blocks, 2),
        ("sampled_w2", sampled, 2),
    )
    for name, run, workers in cases:
        got = []
        run_scene(wave_survey_scene(**run), root / name, log=got.append, workers=workers)
        lines[name] = got
    # 2 workers on a machine whose memory holds one block at a time (~0.46 GB each here)
    import pipeline.survey_blocks_run as sbr
    from pipeline.rss_watch import current_rss_mb

    with pytest.MonkeyPatch.context() as mp:
        rss = current_rss_mb() * 2.0**20
        mp.setattr(sbr, "machine_memory_bytes", lambda: (rss + 0.7e9) / sbr.MEMORY_SHARE)
        got = []
        run_scene(wave_survey_scene(**sampled), root / "sampled_tight", log=got.append, workers=2)
        lines["sampled_tight"] = got
    # threads, not processes: a process cluster would start 2 more interpreters on 2 cores
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=False) as cluster:
        got = []
        scene, address = wave_survey_scene(**sampled), cluster.scheduler_address
        run_scene(scene, root / "sampled_dask", log=got.append, workers=None, scheduler=address)
        lines["sampled_dask"] = got
        # the same cluster as if on another machine: it cannot read the store, so each block
        # is sent its pulses
        from pipeline.parallel import Executor

        with pytest.MonkeyPatch.context() as mp:
            mp.setattr(Executor, "shares_file", lambda self, path: False)
            got = []
            run_scene(scene, root / "sampled_sent", log=got.append, workers=None, scheduler=address)
            lines["sampled_sent"] = got
    # a pool whose workers cannot read the store (no /proc): each block's pulses pickled to it
    from pipeline.detection_store import DetectionStore

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(DetectionStore, "reader", lambda self: None)
        got = []
        run_scene(
            wave_survey_scene(**sampled), root / "sampled_sent_pool", log=got.append, workers=2
        )
        lines["sampled_sent_pool"] = got
    return root, lines


def assert_blocked_as_whole(root, lines, whole, blocks):
    """``blocks`` (a blocked run, every block in the sample) made ``whole``'s outputs: every LAS
    dimension, the grid's files, the evaluation's figures and the counts logged."""
    import rasterio

    ev = json.loads((root / blocks / "evaluation.json").read_text())["blocked"]
    # every block with pulses sampled (and processed, with the blocks next to them)
    assert ev["blocks_with_pulses"] >= 4 and ev["sample_blocks"] == ev["blocks_with_pulses"]
    assert ev["blocks"] >= ev["blocks_with_pulses"]
    assert ev["sample_pulses"] == ev["survey_pulses"] > 10_000
    a, b = las_points_by_pulse(root / whole), las_points_by_pulse(root / blocks)
    assert a.keys() == b.keys() and len(a["X"]) > 20_000
    for d in a:
        np.testing.assert_array_equal(a[d], b[d], err_msg=d)
    assert np.any(a["classification"] == 45)  # the claims are there to compare
    # the grid's files (the blocked run's written by tiles): values, overviews, metadata
    assert_same_tif(root / whole / "grid.tif", root / blocks / "grid.tif")
    assert_same_nc(root / whole / "grid.nc", root / blocks / "grid.nc")
    with rasterio.open(root / whole / "grid.tif") as r:
        assert np.count_nonzero(r.read(5)) > 500  # cells with points to compare (674)
    assert json.dumps(evaluation_figures(root / whole), sort_keys=True, default=str) == json.dumps(
        evaluation_figures(root / blocks), sort_keys=True, default=str
    )
    # the counts logged are the survey's, not the sum of the blocks' overlapping halos
    for key in ("submerged objects", "class-45 claims withheld", "rejected bathymetric"):
        want = [s for s in lines[whole] if key in s]
        assert want and want == [s for s in lines[blocks] if key in s], key


@pytest.mark.slow
def test_a_blocked_survey_gives_the_whole_survey_points_grid_and_evaluation(runs):
    root, lines = runs
    assert_blocked_as_whole(root, lines, "whole", "blocks")


@pytest.fixture(scope="module")
def fire_runs(tmp_path_factory):
    """The survey with :data:`FIRE`'s thresholds, processed whole and by blocks of 50 m
    (every block in the sample), the share of its loaded points each block kept (its TPU, its
    class-43 and rejection tests) and the shares of its loaded pulses whose local planes and
    kriged sea it made (``pipeline.survey_block_reach``)."""
    import pipeline.survey_block_reach as reach
    import pipeline.survey_blocks as sb

    root = tmp_path_factory.mktemp("blocks_fire")
    lines, kept, made = {}, [], []

    def tpu_points(points, *args, **kw):
        keep = sbr_tpu_points(points, *args, **kw)
        kept.append(np.count_nonzero(keep) / keep.size)
        return keep

    def processing_rows(*args, **kw):
        rows = sbr_processing_rows(*args, **kw)
        made.append(np.count_nonzero(rows) / rows.size)
        return rows

    # (pipeline.survey_block_task imports both when a block runs)
    sbr_tpu_points, sbr_processing_rows = sb.tpu_points, reach.processing_rows
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(sb, "tpu_points", tpu_points)
        mp.setattr(reach, "processing_rows", processing_rows)
        for name, run in (("whole", {}), ("blocks", {"block_m": 50.0})):
            got = []
            scene = wave_survey_scene(process=FIRE, **run)
            run_scene(scene, root / name, log=got.append, workers=1)
            lines[name] = got
    return root, lines, np.array(kept), np.array(made).reshape(-1, 2)


@pytest.mark.slow
def test_blocks_whose_class43_and_rejection_tests_fire_give_the_whole_survey_outputs(fire_runs):
    # the default thresholds make neither a class-43 point nor a rejection on this survey;
    # FIRE's make both, and each block tests only the points it keeps and their reach
    root, lines, kept, made = fire_runs
    ev = json.loads((root / "whole" / "evaluation.json").read_text())
    assert ev["features"]["object_points"] > 0  # 589
    rej = ev["seabed_rejected"]
    assert rej["n"] > 0 and rej["tvu_exceeded"] > 0 and rej["seabed_outlier"] > 0  # 58 + 623
    las = las_points_by_pulse(root / "whole")
    assert np.any(las["classification"] == 43) and np.any(las["classification"] == 7)
    # the halo (139 m) covers this whole survey, but each of the 27 blocks keeps and tests
    # only a part of it (1.5 to 24 %): what is compared is the tests made at a subset
    assert kept.size > 20 and np.all(kept > 0.0) and np.max(kept) < 0.5
    # and the blocks' local planes and kriged sea are made at a part of their pulses (planes
    # 74 to 100 %, the sea 63 to 94 %): what is compared is processing asked at a subset too
    assert len(made) == kept.size and np.all(made[:, 1] <= made[:, 0])
    assert made[:, 0].min() < 0.8 and made[:, 1].min() < 0.7
    assert_blocked_as_whole(root, lines, "whole", "blocks")


def test_lines_the_sample_missed_join_the_figures_and_its_own_keep_their_axes():
    from pipeline.process.facet_excess import FacetWide
    from pipeline.process.survey_wide import SeaWide, SurveyWide
    from pipeline.survey_blocks import with_survey_lines
    from pipeline.survey_processing import SurveyFigures
    from pipeline.uncertainty.tpu_survey_wide import TpuSurveyWide

    own = np.array([[1.0, 0.0], [0.0, 1.0]])  # the sample's lines 0 and 2
    facets = FacetWide(np.array([0, 2]), own, (1e-3, 2e-3))
    wide = SurveyWide(None, SeaWide(None, None, facets))
    tpu = TpuSurveyWide(None, None, None, None, (0.0, 0.0), None, np.array([0, 2]), own, facets)
    streamed = np.array([[0.6, 0.8], [0.8, 0.6], [0.0, -1.0], [-0.6, 0.8]])  # lines 0..3
    got = with_survey_lines(SurveyFigures(wide, tpu), np.arange(4), streamed)
    for ids, axes in (
        (got.wide.sea.facets.line_id, got.wide.sea.facets.axis_xy),
        (got.tpu_wide.line_ids, got.tpu_wide.line_axes),
        (got.tpu_wide.facets.line_id, got.tpu_wide.facets.axis_xy),
    ):
        np.testing.assert_array_equal(ids, [0, 1, 2, 3])
        np.testing.assert_array_equal(axes, [own[0], streamed[1], own[1], streamed[3]])
    assert got.wide.sea.facets.plane_var == (1e-3, 2e-3)


def test_a_rewritten_position_field_moves_the_chunks_box(tmp_path):
    rng = np.random.default_rng(4)
    part = _part(rng, 200, 0, 0)
    with DetectionStore(tmp_path, 1.0) as store:
        before = store.append(part).bbox_m
        # every surface return 30 m farther along its beam: the positions move with them
        later = np.where(part["has_surface"], part["t_surface_s"] + 2e-7, 0.0)
        store.replace_field(0, "t_surface_s", later)
        xy = pulse_position_m({**part, "t_surface_s": later}, 1.0)
        want = [xy[:, 0].min(), xy[:, 0].max(), xy[:, 1].min(), xy[:, 1].max()]
        np.testing.assert_array_equal(store.chunks[0].bbox_m, want)
        assert not np.array_equal(before, want)


@pytest.mark.slow
def test_blocks_side_by_side_give_the_outputs_of_blocks_one_after_another(runs):
    # every block in the sample: 2 workers give the whole survey's outputs, as 1 does
    root, lines = runs
    for name in ("blocks_w2", "sampled_w2", "sampled_dask"):
        assert any("blocks on 2 worker(s)" in s for s in lines[name]), name
        blocked = json.loads((root / name / "evaluation.json").read_text())["blocked"]
        assert blocked["block_workers"] == 2 and blocked["blocks_wall_s"] > 0.0
    assert any("blocks on 2 worker(s)" in s for s in lines["blocks_w2"])
    assert_blocked_as_whole(root, lines, "whole", "blocks_w2")
    # a sample of a few blocks (the others made with its figures): the same outputs on
    # 1 worker, 2 workers and a Dask cluster
    ref = las_points_by_pulse(root / "sampled")
    # (and on 2 workers whose machine holds one block at a time: one after another)
    assert any("1 block(s) at a time, not 2" in s for s in lines["sampled_tight"])
    assert any("blocks on 1 worker(s)" in s for s in lines["sampled_tight"])

    # (and on workers that cannot read the store, sent each block's pulses: a cluster on
    # "another machine" and a pool on a machine without /proc)
    def blocked(name):
        return json.loads((root / name / "evaluation.json").read_text())["blocked"]

    for name in ("sampled_sent", "sampled_sent_pool"):
        assert any("blocks sent to the" in s for s in lines[name]), name
        assert blocked(name)["blocks_sent"], name
    assert blocked("sampled_sent_pool")["block_workers"] == 2
    assert not any(blocked(name)["blocks_sent"] for name in ("sampled_w2", "sampled_dask"))
    for name in (
        "sampled_w2",
        "sampled_dask",
        "sampled_tight",
        "sampled_sent",
        "sampled_sent_pool",
    ):
        assert any(s.startswith("  blocks on ") for s in lines[name]), name
        got = las_points_by_pulse(root / name)
        assert got.keys() == ref.keys()
        for d in ref:
            np.testing.assert_array_equal(ref[d], got[d], err_msg=f"{name}: {d}")
        assert_same_tif(root / "sampled" / "grid.tif", root / name / "grid.tif")
        assert_same_nc(root / "sampled" / "grid.nc", root / name / "grid.nc")
        want = json.dumps(evaluation_figures(root / "sampled"), sort_keys=True, default=str)
        assert json.dumps(evaluation_figures(root / name), sort_keys=True, default=str) == want
        for key in ("submerged objects", "class-45 claims withheld", "rejected bathymetric"):
            want_line = [s for s in lines["sampled"] if key in s]
            assert want_line and want_line == [s for s in lines[name] if key in s], key


def test_a_store_read_from_another_process_gives_its_chunks(tmp_path):
    import multiprocessing
    import pickle

    rng = np.random.default_rng(3)
    with DetectionStore(tmp_path, 1.0) as store:
        for c in range(3):
            store.append(_part(rng, 50 + 10 * c, 1000 * c, c))
        reader = store.reader()
        assert reader.path.startswith("/proc/")
        want = store.load()
        with multiprocessing.get_context("spawn").Pool(1) as pool:
            got = pool.apply(_load_all, (pickle.dumps(reader),))
        assert got.keys() == want.keys()
        for k in want:
            np.testing.assert_array_equal(got[k], want[k], err_msg=k)
        # another file at the same path is refused, not read
        with DetectionStore(tmp_path, 1.0) as other:
            other.append(_part(rng, 5, 0, 0))
            wrong = other.reader()
            wrong.identity = reader.identity
            with pytest.raises(OSError, match="not the detection store"):
                wrong.load_chunk(0)


def test_blocks_run_side_by_side_as_memory_holds_sent_their_pulses_where_workers_cannot_read(
    tmp_path, monkeypatch
):
    import pipeline.survey_blocks_run as sbr
    from pipeline.detection_reader import StoreReader
    from pipeline.memory_budget import BASE_BYTES, BYTES_PER_PULSE
    from pipeline.parallel import Executor

    class Cluster(Executor):  # a Dask cluster's answer, without a cluster
        def __init__(self, workers, reads):
            super().__init__(workers)
            self.scheduler, self.reads = "tcp://elsewhere:8786", reads

        def shares_file(self, path):
            return self.reads

        def cluster_memory(self):  # two workers of 2 threads: memory for 3.5 blocks, and 0.5
            return [("tcp://a:1", 2, 3.5 * per_block), ("tcp://b:1", 2, 0.5 * per_block)]

    rng = np.random.default_rng(4)
    counts = np.array([0, 40_000, 25_000])  # loads 4 times its own: 160 000 pulses a block
    per_block = BASE_BYTES + BYTES_PER_PULSE * 160_000  # (0.66 GB)
    rss = sbr.current_rss_mb() * 2.0**20
    with DetectionStore(tmp_path, 1.0) as store:
        for c in range(4):
            store.append(_part(rng, 100_000, 100_000 * c, 0))

        def runner(executor, memory_blocks):
            mem = (rss + memory_blocks * per_block) / sbr.MEMORY_SHARE
            monkeypatch.setattr(sbr, "machine_memory_bytes", lambda: mem)
            said = []
            got = sbr._block_runner(executor, store, counts, 4.0, said.append)
            return got, said

        # a pool of 3, memory for 3.5 blocks: 3 at once, reading the store through /proc
        (ex, src, side, send), said = runner(Executor(3), 3.5)
        assert side == 3 and ex.workers == 3 and isinstance(src, StoreReader) and not said
        assert not send
        # memory for 2.5: a pool of 2
        (ex, src, side, send), said = runner(Executor(3), 2.5)
        assert side == 2 and ex.workers == 2 and isinstance(src, StoreReader) and not send
        assert "2 block(s) at a time, not 3" in said[0]
        # memory for 1.5: here, one after another, from the store itself
        (ex, src, side, send), said = runner(Executor(3), 1.5)
        assert side == 1 and ex.workers == 1 and src is store and not send
        # a cluster on this machine keeps its workers, at most `side` blocks in flight
        cluster = Cluster(4, reads=True)
        (ex, src, side, send), said = runner(cluster, 2.5)
        assert ex is cluster and side == 2 and isinstance(src, StoreReader) and not send
        # a cluster whose workers cannot read the store: each task sent its block's pulses,
        # as many at once as the workers' memory holds (2 + 0), not this machine's (9), and
        # only to the worker that holds them (twice: its two threads)
        cluster = Cluster(4, reads=False)
        (ex, src, side, send), said = runner(cluster, 9.0)
        assert ex is cluster and side == 2 and src is store and send == ["tcp://a:1"] * 2
        assert "cannot read" in said[0] and "2 block(s) at a time, not 4" in said[1]
        # a pool on a machine without /proc: as many as this machine holds, sent their pulses
        monkeypatch.setattr(store, "reader", lambda: None)
        (ex, src, side, send), said = runner(Executor(3), 3.5)
        assert side == 3 and ex.workers == 3 and src is store and send is True
        assert "no /proc" in said[0]


def _load_all(blob):
    import pickle

    return pickle.loads(blob).load()


@pytest.mark.slow
def test_a_sample_of_a_few_blocks_gives_the_survey_nearly_the_whole_runs_outputs(runs):
    import rasterio

    root, _ = runs
    ev = json.loads((root / "sampled" / "evaluation.json").read_text())
    blocked = ev["blocked"]
    assert 0 < blocked["sample_pulses"] <= 3000 < blocked["survey_pulses"]
    assert blocked["sample_blocks"] < blocked["blocks_with_pulses"]
    assert ev["pulses"] == blocked["sample_pulses"]  # the evaluation is the sample's
    a, b = las_points_by_pulse(root / "whole"), las_points_by_pulse(root / "sampled")
    # every pulse is written (once), its points made with the sample's figures
    np.testing.assert_array_equal(np.unique(a["pulse_id"]), np.unique(b["pulse_id"]))
    assert abs(len(b["X"]) - len(a["X"])) < 0.01 * len(a["X"])
    with (
        rasterio.open(root / "whole" / "grid.tif") as r,
        rasterio.open(root / "sampled" / "grid.tif") as s,
    ):
        x, y = r.read(1), s.read(1)
    both = np.isfinite(x) & np.isfinite(y)
    assert both.sum() > 0.95 * np.isfinite(x).sum()
    # the figures of a few blocks, not of the survey: depths a few cm apart at most
    assert np.median(np.abs(x[both] - y[both])) < 0.02
    assert np.percentile(np.abs(x[both] - y[both]), 95) < 0.10
