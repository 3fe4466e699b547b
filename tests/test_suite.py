"""The scene suite: generator, split, strata against a hand-made table, and the CI subset.

The strata test builds two runs' ``evaluation_points`` arrays by hand (errors, sigmas,
posterior intervals and cube footprints chosen in the test) and checks every figure against
the value worked out here by hand. The CI-subset test runs eight small scenes end to end.
"""

from __future__ import annotations

import dataclasses
import math
import tomllib

import numpy as np
import pytest

from pipeline.suite.generate import CI_SCENES, ci_draws, draw, half, suite_seeds
from pipeline.suite.report import floors
from pipeline.suite.scene_file import scene_toml
from pipeline.suite.strata import (
    MIN_NO_BOTTOM,
    all_strata,
    extinction_depth_m,
    pool_rows,
    shallowest_unbiased_m,
)

# --- generator and split -------------------------------------------------------------------


def test_same_seed_same_scene_file():
    for seed in (0, 1, 17, 123):
        assert scene_toml(draw(seed)) == scene_toml(draw(seed))
    assert scene_toml(draw(1)) != scene_toml(draw(2))


def test_scene_files_are_valid_and_use_scene_keys_only():
    from pipeline.scene import parse_scene

    for d in [draw(s) for s in range(12)] + ci_draws():
        data = tomllib.loads(scene_toml(d))
        scene = parse_scene(data, f"seed {d.seed}")  # unknown keys or bounds raise SceneError
        assert scene.scene.seed == d.seed
        assert scene.detector.mode == d.receiver
        assert scene.scanner.kind == d.scanner
        assert scene.water_surface.kind == d.surface
        assert sorted(f.size_m for f in scene.seabed.features) == [0.5, 1.0, 2.0]


def test_draws_cover_the_conditions():
    ds = [draw(s) for s in range(200)]
    assert {d.receiver for d in ds} == {"full_waveform", "photon_counting"}
    assert {d.scanner for d in ds} == {"palmer", "oscillating", "profiler"}
    assert {d.surface for d in ds} == {"flat", "waves"}
    wind = np.array([d.wind_m_s for d in ds])
    c = np.array([d.attenuation_per_m for d in ds])
    alt = np.array([d.altitude_m for d in ds])
    slope = np.array([d.slope_deg for d in ds])
    assert wind.min() < 1.0 and wind.max() > 11.0 and wind.max() <= 12.0
    assert c.min() < 0.07 and c.max() > 0.6 and 0.05 <= c.min() and c.max() <= 0.8
    assert alt.min() < 260 and alt.max() > 740
    assert slope.min() < 1.0 and slope.max() > 19.0
    assert any(d.depth_centre_m < 0 for d in ds)  # shoreline and land
    assert any(d.depth_centre_m > 4.5 / d.attenuation_per_m for d in ds)  # past extinction


def test_cubes_lie_under_the_scan_on_reachable_seabed():
    """Each cube is under the nominal scan pattern, on seabed a survey reaches where the plane
    allows. Worked out here from the scene's keys: a Palmer scan's footprints lie on a circle
    of radius R = H tan 20 deg about the aircraft at (0, y), y along the line [0, L]; the
    oscillating scan sweeps |x| <= R; a profiler's track is x = 0. The plane's depth at
    (x, y) is d0 + tan(slope) (x sin(aspect) + y cos(aspect)).

    Before: cubes were drawn uniformly over the swath's square, inside the Palmer circle that a
    line shorter than its diameter never scans, and on land or past extinction."""
    seeds = range(0, 200)
    reachable = on_scan = 0
    n_allowed = n_palmer = 0
    for s in seeds:
        d = draw(s)
        r = d.altitude_m * math.tan(math.radians(20.0))
        g = math.tan(math.radians(d.slope_deg))
        lo, hi = 1.0, 0.8 * 4.5 / d.attenuation_per_m
        for x, y, _ in d.cubes:
            assert abs(x) <= r + 1e-9
            if d.scanner == "palmer":
                n_palmer += 1
                ys = np.linspace(0.0, d.line_length_m, 2001)
                on_scan += np.min(np.abs(np.hypot(x, y - ys) - r)) <= 1.0
            elif d.scanner == "profiler":
                assert x == 0.0
            depth = d.depth_centre_m + g * (x if d.aspect_deg == 90.0 else y)
            # where the plane is 1.5 m deep inside the swath (slope across it), the cube is in
            # the floors' depth window (its drawn depth, 1.5 m to half of 4.5/c, or the swath's
            # edge on the way there)
            if d.aspect_deg == 90.0 and g > 1e-3 and d.scanner != "profiler":
                if -0.9 * r <= (1.5 - d.depth_centre_m) / g <= 0.9 * r:
                    n_allowed += 1
                    reachable += lo <= depth < hi
    assert n_palmer > 50 and on_scan == n_palmer
    assert n_allowed > 30 and reachable == n_allowed


def test_split_is_fixed_and_disjoint():
    tuning, held = set(suite_seeds(50, "tuning")), set(suite_seeds(50, "heldout"))
    assert not tuning & held
    assert all(half(s) == "tuning" for s in tuning) and all(half(s) == "heldout" for s in held)
    both = suite_seeds(40, "both")
    assert sum(half(s) == "tuning" for s in both) == 20 == sum(half(s) == "heldout" for s in both)
    # a larger suite keeps the smaller one's scenes (runs can be reused)
    assert set(both) <= set(suite_seeds(60, "both"))
    # the split is not the draw: roughly half of many seeds each way
    assert 0.4 < np.mean([half(s) == "heldout" for s in range(1000)]) < 0.6
    assert {d.half for d in ci_draws()} == {"tuning", "heldout"}
    assert len(CI_SCENES) == 8


# --- strata against a hand-made table --------------------------------------------------------


def _arrays(x, y, true_d, err, sigma, post, nb):
    """evaluation_points arrays of one run, built from hand-chosen values."""
    true_d, err = np.asarray(true_d, float), np.asarray(err, float)
    pt, lo68, hi68, lo95, hi95, conv = (np.asarray(v) for v in post)
    return {
        "pt_x_m": np.asarray(x, float),
        "pt_y_m": np.asarray(y, float),
        "pt_depth_m": true_d + err,
        "pt_true_depth_m": true_d,
        "pt_error_m": err,
        "tpu_true_depth_m": true_d,
        "tpu_error_m": err,
        "tpu_sigma_depth_m": np.asarray(sigma, float),
        "tpu_group": np.arange(err.size),
        "post_true_depth_m": np.asarray(pt, float),
        "post_median_m": np.asarray(pt, float),
        "post_lo68_m": np.asarray(lo68, float),
        "post_hi68_m": np.asarray(hi68, float),
        "post_lo95_m": np.asarray(lo95, float),
        "post_hi95_m": np.asarray(hi95, float),
        "post_converged": np.asarray(conv, bool),
        "cell_x_m": np.array([0.0, 2.0]),
        "cell_y_m": np.array([0.0, 0.0]),
        "cell_depth_m": np.array([2.1, 3.0]),
        "cell_true_depth_m": np.array([2.0, 3.2]),
        "cell_error_m": np.array([0.1, -0.2]),
        "cell_count": np.array([3, 4]),
        "nb_depth_m": np.asarray(nb, float),
    }


def _hand_rows():
    seeds = suite_seeds(1, "tuning") + suite_seeds(1, "heldout")
    base = [draw(s) for s in seeds]
    # run A (tuning): calm flat water, full waveform; D_ext from its class-45 points: median of
    # 25 detection limits 10, 11, 12 (11 m), all past 95 % of its soundings (9.1 m: the 10.5 m
    # one weighs) -> floor window [1 m, 8.8 m)
    a = dataclasses.replace(
        base[0], receiver="full_waveform", scanner="palmer", surface="flat", wind_m_s=1.0,
        attenuation_per_m=0.15, slope_deg=1.0, roughness_rms_m=0.0,
        cubes=((0.0, 0.0, 2.0), (50.0, 50.0, 1.0)),
    )  # fmt: skip
    nb_a = [10.0] * 8 + [11.0] * 9 + [12.0] * 8
    # six points: 0.5 m (too shallow) and 9 m (past 0.8 D_ext) are outside the window
    arrays_a = _arrays(
        x=[0.2, -0.5, 3.0, 4.0, 0.0, 4.5],
        y=[0.3, 0.5, 0.0, 0.0, 4.0, 0.0],
        true_d=[2.0, 3.0, 4.0, 5.0, 0.5, 9.0],
        err=[0.1, -0.1, 0.2, 0.0, 0.5, 1.5],
        sigma=[0.1, 0.1, 0.1, 0.1, 0.1, 0.1],
        # posteriors: truth 2, 3, 6 m; the 68 % interval holds it twice, the 95 % thrice
        post=([2.0, 3.0, 6.0], [1.9, 3.1, 5.9], [2.1, 3.2, 6.1], [1.8, 2.9, 5.8],
              [2.2, 3.3, 6.2], [True, True, False]),
        nb=nb_a,
    )  # fmt: skip
    # run B (held-out): photon counting, wind 10 m/s, c = 0.45 -> fewer than 20 class-45
    # points, so D_ext is the planning value 4.5 / 0.45 = 10 m: window [1 m, 8 m)
    b = dataclasses.replace(
        base[1], receiver="photon_counting", scanner="profiler", surface="waves",
        wind_m_s=10.0, attenuation_per_m=0.45, slope_deg=10.0, roughness_rms_m=0.1, cubes=(),
    )  # fmt: skip
    arrays_b = _arrays(
        x=[0.0] * 4, y=[0.0] * 4, true_d=[1.5, 2.5, 7.9, 8.5], err=[-0.3, -0.1, 1.2, 0.0],
        sigma=[0.2, 0.2, 0.2, 0.2], post=([], [], [], [], [], []), nb=[12.0] * 3,
    )  # fmt: skip
    # its 1.2 m error is a sounding beside a wall, within its THU of a seabed at its depth
    # (pipeline.evaluate_thu); run A's file predates the search: its strict errors stand
    arrays_b["pt_error_thu_m"] = np.array([-0.3, -0.1, 0.02, 0.0])
    return [
        {"draw": a, "evaluation": {}, "arrays": arrays_a, "wall_s": 1.0},
        {"draw": b, "evaluation": {}, "arrays": arrays_b, "wall_s": 1.0},
    ]


def test_extinction_depth_source():
    assert extinction_depth_m(np.full(MIN_NO_BOTTOM, 7.0), 0.3) == (7.0, "class45_beyond_found")
    d, src = extinction_depth_m(np.full(MIN_NO_BOTTOM - 1, 7.0), 0.3)
    assert src == "planning_4.5_over_c" and d == pytest.approx(15.0)
    # photon counting's class 45 sits at the range gate's end: never a detection limit
    d, src = extinction_depth_m(np.full(50, 90.0), 0.3, "photon_counting")
    assert src == "planning_4.5_over_c" and d == pytest.approx(15.0)


def test_strata_against_a_hand_made_table():
    pool = pool_rows(_hand_rows())
    assert [m["d_ext_m"] for m in pool.meta] == pytest.approx([11.0, 10.0])
    rows = {(r["dimension"], r["label"]): r for r in all_strata(pool)}

    t = rows[("all", "all")]["tuning"]
    # in the window: errors 0.1, -0.1, 0.2, 0.0 (0.5 m and 9 m left out)
    assert t["points"]["n"] == 4
    assert t["points"]["bias_m"] == pytest.approx(0.05)
    assert t["points"]["rmse_m"] == pytest.approx(math.sqrt(0.06 / 4))
    assert t["points"]["max_m"] == pytest.approx(0.2)
    assert t["n_over_1m"] == 0
    # |e| / sigma = 1, 1, 2, 0: within 1 sigma 3 of 4, within 1.96 sigma 3 of 4
    assert t["tpu"] == {"n": 4, "cov68": 0.75, "cov95": 0.75}
    # truth 2 m: in both; 3 m: 68 % interval 3.1-3.2 misses, 95 % holds; 6 m: in both
    assert t["posterior"]["n"] == 3
    assert t["posterior"]["cov68"] == pytest.approx(2 / 3)
    assert t["posterior"]["cov95"] == pytest.approx(1.0)
    assert t["posterior"]["converged"] == pytest.approx(2 / 3)
    # cells: true depths 2 and 3.2 m, errors 0.1 and -0.2
    assert t["cells"]["rmse_m"] == pytest.approx(math.sqrt((0.01 + 0.04) / 2))
    # 2 m cube at (0, 0): points (0.2, 0.3) err 0.1 and (-0.5, 0.5) err -0.1 on its footprint
    # (|err| < 1 m: detected); all 6 points lie within 5 m: 6 / (25 pi) = 0.08 per m² (not
    # dense); its depth, the median true depth of those 6, is 3.5 m: inside the window
    assert t["cubes"]["2"] == {"n": 1, "detected": 1, "n_dense": 0, "detected_dense": 0}
    assert "1" not in t["cubes"]  # the 1 m cube has no point within 5 m: no depth, not counted

    h = rows[("all", "all")]["heldout"]
    # window [1, 8): errors -0.3, -0.1, 1.2 (8.5 m left out)
    assert h["points"]["n"] == 3
    assert h["points"]["bias_m"] == pytest.approx(0.8 / 3)
    assert h["n_over_1m"] == 1 and h["n_over_1m_thu"] == 0
    # |e| / sigma = 1.5, 0.5, 6: within 1 sigma 1 of 3, within 1.96 sigma 2 of 3
    assert h["tpu"]["cov68"] == pytest.approx(1 / 3)
    assert h["tpu"]["cov95"] == pytest.approx(2 / 3)
    assert h["posterior"]["n"] == 0

    # scene strata split the runs; the depth bands split the points
    assert rows[("receiver", "photon_counting")]["tuning"]["points"]["n"] == 0
    assert rows[("wind m/s", "8-12")]["heldout"]["points"]["n"] == 3
    assert rows[("wind m/s", "0-2")]["tuning"]["points"]["n"] == 4
    # bands include their lower edge: 2 m in 1-3; 3, 4, 5 m (errors -0.1, 0.2, 0) in 3-6
    assert rows[("depth m", "1-3")]["tuning"]["points"]["n"] == 1
    assert rows[("depth m", "3-6")]["tuning"]["points"]["bias_m"] == pytest.approx(0.1 / 3)
    assert rows[("depth m", "6-12")]["heldout"]["points"]["n"] == 1  # 7.9 m; 8.5 m is past
    assert rows[("depth m", "0.1-1")]["tuning"]["points"]["n"] == 1
    past = rows[("depth m", "past 0.8 D_ext")]
    assert past["tuning"]["points"]["n"] == 1 and past["tuning"]["n_over_1m"] == 1
    assert past["tuning"]["n_over_1m_thu"] == 1
    assert past["heldout"]["points"]["n"] == 1


def test_floors_of_a_hand_made_stratum():
    fig = {
        "points": {"n": 100, "bias_m": 0.04, "rmse_m": 0.12, "p95_m": 0.2, "max_m": 0.5},
        "n_over_1m": 0,
        "cells": {"n": 50, "bias_m": 0.0, "rmse_m": 0.09, "p95_m": 0.1, "max_m": 0.2},
        "tpu": {"n": 250, "cov68": 0.70, "cov95": 0.90},
        "posterior": {"n": 59, "cov68": 0.1, "cov95": 0.1, "converged": 0.1},
        "cubes": {"2": {"n": 4, "detected": 3, "n_dense": 2, "detected_dense": 2}},
    }
    f = floors(fig, wind_max_m_s=4.0)
    assert f["bias"] == "FAIL" and f["rmse"] == "FAIL" and f["grid"] == "PASS"
    assert f["gross"] == "PASS" and f["tpu68"] == "PASS" and f["tpu95"] == "FAIL"
    assert f["post68"] == f["post95"] == f["conv"] == "n/a"  # fewer than 60 posteriors
    assert f["cube2"] == "PASS"
    windy = floors(fig, wind_max_m_s=10.0)
    assert windy["rmse"] == "PASS" and windy["grid"] == "n/a"
    # gross: a point off at its position but within its THU of a seabed at its depth passes;
    # one off everywhere in its THU fails
    assert floors({**fig, "n_over_1m": 1, "n_over_1m_thu": 0}, 4.0)["gross"] == "PASS"
    assert floors({**fig, "n_over_1m": 1, "n_over_1m_thu": 1}, 4.0)["gross"] == "FAIL"


def test_shallowest_unbiased_depth():
    rows = _hand_rows()
    a = rows[0]["arrays"]
    # 40 points each at 1.75, 1.25 and 0.8 m with biases 0.05, -0.08, 0.3: the search from
    # 1.5-2 m upward passes 1.5-2 and 1-1.5 and stops at 0.75-1
    d = np.repeat([1.75, 1.25, 0.8], 40)
    e = np.repeat([0.05, -0.08, 0.3], 40)
    for k, v in {"pt_true_depth_m": d, "pt_error_m": e, "pt_x_m": d * 0, "pt_y_m": d * 0}.items():
        a[k] = v
    pool = pool_rows(rows)
    res = shallowest_unbiased_m(pool, "full_waveform", (0.0, 2.0), "tuning")
    assert res["depth_m"] == 1.0
    assert res["scenes"] == 1


# --- the CI subset end to end ------------------------------------------------------------------
#
# Eight small scenes (pipeline.suite.generate.CI_SCENES), ~65 s of CPU in all, run once for the
# tests below. Their figures are deterministic for a given simulator and processing (seeded);
# the asserted bounds hold on the code of this commit with margins chosen to survive honest
# changes of the simulated physics (the realism work runs in parallel) while still catching a
# datum or refraction error of decimetres. Floors that fail today are strict xfails carrying
# the measured figure: when a fix makes one pass, the xfail fails and must become an assert.
# Measured on this commit (window [1 m, 0.8 D_ext)): tuning 22919 class-40 points, bias
# +0.009 m, RMSE 0.055 m, max |error| 0.98 m, TPU 42.8 % / 73.5 %; held-out 4756 points, bias
# +0.011 m, RMSE 0.108 m, max 1.56 m, TPU 64.0 % / 77.1 %; 2 and 14 posteriors (n/a: < 60).


@pytest.fixture(scope="module")
def ci_suite(tmp_path_factory):
    from pipeline.suite.main import suite

    out = tmp_path_factory.mktemp("ci_suite")
    status = suite(subset="ci", out=out, workers=2, log=lambda line: None)
    from pipeline.suite.run import RunResult, collect

    results = [RunResult(d, out / "runs" / f"suite_{d.seed:05d}", 0, 0.0) for d in ci_draws()]
    rows = collect(results)
    strata = {(r["dimension"], r["label"]): r for r in all_strata(pool_rows(rows))}
    return {"status": status, "out": out, "rows": rows, "strata": strata}


@pytest.mark.slow
def test_ci_subset_runs_every_scene(ci_suite):
    out = ci_suite["out"]
    assert ci_suite["status"] == 0
    assert len(ci_suite["rows"]) == len(CI_SCENES)
    for d in ci_draws():  # the files run are the generator's, byte for byte
        assert (out / "scenes" / f"suite_{d.seed:05d}.toml").read_text() == scene_toml(d)
    assert (out / "suite.csv").is_file() and (out / "RESULTS_suite.md").is_file()
    text = (out / "RESULTS_suite.md").read_text()
    for head in ("## Floors", "## Class-40 points", "## TPU and posterior", "## Cube", "## Sc"):
        assert head in text
    assert "a TPU exactly right would fail on average tpu68" in text  # shared-term chance


@pytest.mark.slow
def test_ci_points_file_matches_the_run_level_evaluation(ci_suite):
    # evaluation_points.npz holds the same points as evaluation.json's run-level figures:
    # its class-40 errors give the same count and bias, its TPU z-scores the same coverage
    for row in ci_suite["rows"]:
        ev, a = row["evaluation"], row["arrays"]
        p = ev["error"]["points"]
        assert a["pt_error_m"].size == p["n"] > 0
        assert a["pt_error_m"].mean() == pytest.approx(p["bias_m"], abs=1e-12)
        z = np.abs(a["tpu_error_m"]) / a["tpu_sigma_depth_m"]
        cov = ev["tpu_coverage_against_truth"]["intervals"]
        assert np.mean(z <= 1.0) == pytest.approx(cov[0]["fraction_within"], abs=1e-12)
        assert a["cell_error_m"].size == ev["error"]["grid"]["n"]
        assert np.all(np.isfinite(a["tpu_sigma_depth_m"])) and np.all(a["tpu_sigma_depth_m"] > 0)
        # every term the TPU added is exported: their squares add up to the depth variance
        # (a term added to the total but not to PointTpu.terms would leave a gap)
        terms = [k for k in a if k.startswith("tpu_term_")]
        total = np.sqrt(sum(a[k] ** 2 for k in terms))
        assert len(terms) >= 10
        np.testing.assert_allclose(total, a["tpu_sigma_depth_m"], rtol=1e-9)


@pytest.mark.slow
@pytest.mark.parametrize("half_name", ["tuning", "heldout"])
def test_ci_figures_that_hold_today(ci_suite, half_name):
    fig = ci_suite["strata"][("all", "all")][half_name]
    # measured +0.004 / +0.010 m (tuning / held-out, 2026-11-24); the scenes had
    # -0.13 m: 0.03 m is the floor itself
    assert abs(fig["points"]["bias_m"]) <= 0.03
    # measured 0.049 / 0.071 m; 0.15 m is the floor for winds above 5 m/s
    assert fig["points"]["rmse_m"] <= 0.15
    # measured 96.7 / 96.1 % (tpustrata after the merge of main: timing from the scatter
    # without the relief and the sea between the pairs, forward-scatter relative sigma 0.5,
    # the wave facet term; 98.6 / 96.5 % before the branch)
    assert fig["tpu"]["cov95"] >= 0.6
    assert fig["points"]["n"] >= 2000


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason="measured: held-out max |error| 2.00 m at its position")
def test_ci_no_gross_error_held_out(ci_suite):
    # at the point's own position: one held-out sounding beside a cube's wall reads the top
    assert ci_suite["strata"][("all", "all")]["heldout"]["n_over_1m"] == 0


@pytest.mark.slow
@pytest.mark.parametrize("half_name", ["tuning", "heldout"])
def test_ci_no_gross_error_within_thu(ci_suite, half_name):
    # the floor as the suite reads it (pipeline.evaluate_thu): no sounding more than 1 m off
    # every true depth within its own THU95. Measured (2026-11-28): 0 and 0; at the points'
    # positions 0 and 1 (the xfail above)
    assert ci_suite["strata"][("all", "all")][half_name]["n_over_1m_thu"] == 0


def _halves(heldout_xfail_reason: str) -> list:
    """Both halves; the held-out one a strict xfail carrying its measured figure."""
    return [
        "tuning",
        pytest.param("heldout", marks=pytest.mark.xfail(strict=True, reason=heldout_xfail_reason)),
    ]


@pytest.mark.slow
@pytest.mark.parametrize(
    "half_name",
    _halves(
        "measured: held-out TPU 95 % coverage 98.3 % (2026-12-01, the sea from the surface "
        "returns with water under them; 97.9 % on 2026-11-30 and 2026-11-25: too "
        "wide, its points gained, RMSE 0.057 -> 0.049 m, from the surface echo's population "
        "weighting and the kriged sea change, the TPU's sea and surface timing terms did not "
        "shrink with them); 93.9 % before the kriged sea, 97.7 % before the seabed gradient's "
        "covariance"
    ),
)
def test_ci_tpu_95_coverage_floor(ci_suite, half_name):
    # measured 95.9 % tuning (2026-12-01; 95.8 % on 2026-11-30; 95.5 % on 2026-11-25: the
    # seabed gradient with its covariance, the wave facet across a profiler's line, the sea's
    # slope under a photon window; 96.7 % before)
    assert 0.93 <= ci_suite["strata"][("all", "all")][half_name]["tpu"]["cov95"] <= 0.97


@pytest.mark.slow
@pytest.mark.parametrize(
    "half_name",
    _halves(
        "measured: held-out TPU 68 % coverage 85.0 % (2026-12-01; 83.4 % on 2026-11-30; 85.8 % "
        "on 2026-11-25: too "
        "wide; 85.1 % before the seabed gradient's covariance: the held-out scenes' widest "
        "terms are the surface and bottom timing, seeds 9002, 9005, 9006; not the gradient)"
    ),
)
def test_ci_tpu_68_coverage_floor(ci_suite, half_name):
    # measured 68.3 % tuning (2026-12-01; 68.2 % on 2026-11-30; 69.0 % on 2026-11-25, the
    # seabed gradient; 75.2 % before, too wide)
    assert 0.64 <= ci_suite["strata"][("all", "all")][half_name]["tpu"]["cov68"] <= 0.72
