"""Evaluation: IHO allowances by hand, metrics against numpy, truth as callables."""

import json
import math

import numpy as np
import pytest

from pipeline.evaluate import (
    IHO_ORDERS,
    error_stats,
    evaluate,
    grid_errors_m,
    iho_fractions,
    tvu_allowance_m,
)
from pipeline.evaluate_coverage import tpu_coverage
from pipeline.process.grid import grid_points
from pipeline.process.returns import Points


@pytest.mark.parametrize(
    ("order", "depth", "expected"),
    [
        # sqrt(a^2 + (b d)^2) worked by hand
        ("exclusive", 0.0, 0.15),
        ("exclusive", 20.0, math.sqrt(0.0225 + 0.0225)),  # b d = 0.15
        ("special", 10.0, math.sqrt(0.0625 + 0.005625)),  # 0.261008
        ("1a", 40.0, math.sqrt(0.25 + 0.270400)),  # b d = 0.52
        ("1b", 100.0, math.sqrt(0.25 + 1.69)),  # b d = 1.3
        ("2", 50.0, math.sqrt(1.0 + 1.3225)),  # b d = 1.15
    ],
)
def test_tvu_by_hand(order, depth, expected):
    assert tvu_allowance_m(depth, order) == pytest.approx(expected, rel=1e-12)


def test_iho_table():
    assert IHO_ORDERS == {
        "exclusive": (0.15, 0.0075),
        "special": (0.25, 0.0075),
        "1a": (0.5, 0.013),
        "1b": (0.5, 0.013),
        "2": (1.0, 0.023),
    }
    with pytest.raises(ValueError, match="order"):
        tvu_allowance_m(1.0, "3")


def test_error_stats_against_numpy():
    rng = np.random.default_rng(2)
    e = rng.normal(0.05, 0.2, 10001)
    s = error_stats(np.append(e, np.nan))  # NaN (e.g. empty cells) is ignored
    assert s.n == e.size
    assert s.bias_m == pytest.approx(np.mean(e), rel=1e-12)
    assert s.std_m == pytest.approx(np.std(e), rel=1e-12)
    assert s.rmse_m == pytest.approx(np.sqrt(np.mean(e**2)), rel=1e-12)
    assert s.p95_abs_m == pytest.approx(np.percentile(np.abs(e), 95), rel=1e-12)
    assert s.max_abs_m == np.max(np.abs(e))
    empty = error_stats([])
    assert empty.n == 0 and empty.to_dict()["rmse_m"] is None


def test_iho_fractions_by_hand():
    depth = np.array([10.0, 10.0, 10.0, 10.0])
    err = np.array([0.1, -0.2, 0.3, 0.6])
    # special at 10 m: 0.2610 -> 2 of 4 within; 1a: 0.5154 -> 3 of 4; order 2: 1.026 -> 4 of 4
    res = {r.order: r for r in iho_fractions(err, depth)}
    assert res["special"].fraction_within == 0.5
    assert res["1a"].fraction_within == 0.75
    assert res["2"].fraction_within == 1.0 and res["2"].meets
    assert not res["1a"].meets


def make_points(xyz, depth, cls):
    n = len(xyz)
    return Points(
        pulse_id=np.arange(n),
        xyz_m=xyz,
        depth_m=depth,
        classification=np.asarray(cls, np.uint8),
        kind=np.full(n, 2, np.uint8),
        flags=np.zeros(n, np.uint16),
        detector_flags=np.zeros(n, np.uint16),
        return_number=np.ones(n, np.uint8),
        number_of_returns=np.ones(n, np.uint8),
        confidence=np.ones(n),
        uncertainty_v_m=np.zeros(n),
        uncertainty_h_m=np.zeros(n),
    )


def truth_depth(x, y):
    return 8.0 + 0.02 * np.asarray(x)


def truth_z(x, y):
    return -truth_depth(x, y)


def test_evaluate_points_and_grid():
    rng = np.random.default_rng(3)
    n = 2000
    x, y = rng.uniform(0, 50, n), rng.uniform(0, 50, n)
    err = rng.normal(0.03, 0.1, n)
    d = truth_depth(x, y) + err
    xyz = np.column_stack([x, y, -d])
    cls = np.where(rng.random(n) < 0.1, 7, 40)  # noise points are not compared
    raw = make_points(np.column_stack([x, y, -1.36 * d]), 1.36 * d, cls)
    pts = make_points(xyz, d, cls)
    grid = grid_points(x[cls == 40], y[cls == 40], d[cls == 40], resolution_m=5.0)

    rep = evaluate(pts, uncorrected=raw, grid=grid, truth_depth_m=truth_depth)
    e40 = err[cls == 40]
    assert rep.points.n == e40.size
    assert rep.points.bias_m == pytest.approx(np.mean(e40), rel=1e-9)
    assert rep.points.rmse_m == pytest.approx(np.sqrt(np.mean(e40**2)), rel=1e-9)
    raw_err = 0.36 * d[cls == 40] + e40
    assert rep.points_uncorrected.bias_m == pytest.approx(np.mean(raw_err), rel=1e-9)
    # grid: mean depth per cell minus truth at the centre (truth is linear: mean of truth at
    # the points differs from truth at the centre by 0.02 * (mean x - centre x))
    gerr, _ = grid_errors_m(grid, truth_depth_m=truth_depth)
    xx, _ = np.meshgrid(grid.x_m, grid.y_m)
    np.testing.assert_allclose(gerr, grid.depth_m - truth_depth(xx, 0), atol=1e-12)
    assert rep.grid.n == (grid.count > 0).sum()
    # with z truth the same errors come out
    rep_z = evaluate(pts, uncorrected=raw, grid=grid, truth_z_m=truth_z)
    assert rep_z.points.bias_m == pytest.approx(rep.points.bias_m, rel=1e-9)
    assert rep_z.grid.rmse_m == pytest.approx(rep.grid.rmse_m, rel=1e-9)
    frac = {r.order: r.fraction_within for r in rep.iho_points}
    tvu = tvu_allowance_m(truth_depth(x, y)[cls == 40], "special")
    assert frac["special"] == np.mean(np.abs(e40) <= tvu)
    json.dumps(rep.to_dict(), allow_nan=False)


def test_evaluate_needs_one_truth():
    pts = make_points(np.zeros((1, 3)), np.zeros(1), [40])
    with pytest.raises(ValueError, match="exactly one"):
        evaluate(pts)
    with pytest.raises(ValueError, match="exactly one"):
        evaluate(pts, truth_depth_m=truth_depth, truth_z_m=truth_z)


def test_tpu_coverage_of_normal_errors_and_its_standard_errors():
    """Errors drawn with the stated sigma: the 68 % and 95 % fractions within their binomial
    standard errors; a sigma half too small or too large is caught."""
    rng = np.random.default_rng(8)
    n = 20000
    x, y = rng.uniform(0, 50, n), rng.uniform(0, 50, n)
    sig = rng.uniform(0.01, 0.2, n)
    d = truth_depth(x, y) + rng.normal(size=n) * sig
    pts = make_points(np.column_stack([x, y, -d]), d, [40] * n)
    cov = tpu_coverage(pts, sig, truth_depth_m=truth_depth)
    assert cov["n"] == n and cov["n_groups"] == n and cov["k"] == 1.96
    (c68, c95) = cov["intervals"]
    assert (c68["k"], c95["k"]) == (1.0, 1.96)
    assert c68["nominal"] == pytest.approx(0.682689, abs=1e-6)
    assert c95["nominal"] == pytest.approx(0.950004, abs=1e-6)
    for c in (c68, c95):
        p = c["fraction_within"]
        assert c["standard_error"] == pytest.approx(math.sqrt(p * (1 - p) / n), rel=1e-12)
        assert abs(p - c["nominal"]) < 4 * c["standard_error"]
    # the headline (k = 1.96) is the 95 % interval's, as before
    assert cov["fraction_within"] == c95["fraction_within"]
    assert cov["standard_error"] == c95["standard_error"]
    assert cov["median_abs_error_over_sigma"] == pytest.approx(0.6745, abs=0.02)
    for scale, low in ((0.5, True), (2.0, False)):
        c68 = tpu_coverage(pts, scale * sig, truth_depth_m=truth_depth)["intervals"][0]
        assert (c68["fraction_within"] < 0.5) if low else (c68["fraction_within"] > 0.9)
    json.dumps(cov, allow_nan=False)


def test_tpu_coverage_counts_shared_measurements_once():
    """Shots of one window share one error: the fraction is the same, its standard error is
    that of the windows (cluster-robust), not of the shots."""
    rng = np.random.default_rng(9)
    n_win, shots = 400, 50
    err = np.repeat(rng.normal(0, 0.05, n_win), shots)
    x = rng.uniform(0, 50, n_win * shots)
    d = truth_depth(x, 0) + err
    pts = make_points(np.column_stack([x, np.zeros_like(x), -d]), d, [40] * x.size)
    sig = np.full(x.size, 0.05)
    group = np.repeat(np.arange(n_win), shots)
    shots_cov = tpu_coverage(pts, sig, truth_depth_m=truth_depth)
    win_cov = tpu_coverage(pts, sig, truth_depth_m=truth_depth, group=group)
    assert win_cov["n_groups"] == n_win
    p = win_cov["intervals"][0]["fraction_within"]
    assert p == shots_cov["intervals"][0]["fraction_within"]
    se = win_cov["intervals"][0]["standard_error"]
    assert se == pytest.approx(math.sqrt(p * (1 - p) / n_win), rel=0.01)
    assert se > 6 * shots_cov["intervals"][0]["standard_error"]
    # points without a finite positive sigma are left out
    sig[:shots] = 0.0
    assert tpu_coverage(pts, sig, truth_depth_m=truth_depth, group=group)["n_groups"] == n_win - 1


def test_end_to_end_noisy_survey(tmp_path):
    """Forward model written here: flat water at z = 0, a sloping seabed, a beach of land,
    timing and navigation noise; processing, gridding, files and evaluation together."""
    from scipy import constants

    from pipeline.outputs.las import read_points_laz, write_points_laz
    from pipeline.outputs.raster import read_grid_tif, write_grid_tif
    from pipeline.process.grid import grid_seabed
    from pipeline.process.refraction import georeference
    from pipeline.process.returns import DetectedReturns

    c, n_air, n_w, n_g = constants.c, 1.000277, 1.3415, 1.3638
    rng = np.random.default_rng(11)
    n = 30000
    x, y = rng.uniform(0, 150, n), rng.uniform(0, 100, n)  # where the beams hit z = 0
    theta = np.radians(15.0)
    phi = rng.uniform(0, 2 * np.pi, n)
    ux, uy = np.sin(phi), np.cos(phi)
    d = np.column_stack([ux * np.sin(theta), uy * np.sin(theta), np.full(n, -np.cos(theta))])
    r_air = 350.0 / np.cos(theta)
    o = np.column_stack([x, y, np.zeros(n)]) - d * r_air

    def seabed_z(px, py):  # 2 m deep at x = 0, 15 m at x = 130 (land, class 2, not compared)
        return -2.0 - 0.1 * np.asarray(px)

    land = x >= 130  # pulses hitting a plateau 3 m above the water
    sw = n_air * np.sin(theta) / n_w
    t = np.column_stack([ux * sw, uy * sw, np.full(n, -np.sqrt(1 - sw**2))])
    # seabed z = -2 - 0.1 x along the refracted ray from (x, y, 0): solve for the length
    length = (-2.0 - 0.1 * x) / (t[:, 2] + 0.1 * t[:, 0])
    t_s = 2 * r_air * n_air / c
    t_b = t_s + 2 * length * n_g / c
    # on land: one return, from the ground 3 m up along the straight beam
    r_land = (3.0 - o[:, 2]) / d[:, 2]
    t_land = 2 * r_land * n_air / c
    has_s = ~land & (rng.random(n) > 0.05)  # 5 % of water pulses miss the surface
    has_b = np.ones(n, bool)
    ts = np.where(has_s, np.full(n, t_s) + rng.normal(0, 0.1e-9, n), 0.0)
    tb = np.where(land, t_land, t_b) + rng.normal(0, 0.1e-9, n)
    ret = DetectedReturns(
        pulse_id=np.arange(n),
        origin_meas_m=o + rng.normal(0, 0.01, (n, 3)),
        direction_meas=d,
        has_surface=has_s,
        t_surface_s=ts,
        has_bottom=has_b,
        t_bottom_s=tb,
        surface_confidence=np.where(has_s, 0.9, 0.0),
        bottom_confidence=np.full(n, 0.9),
        flags=np.zeros(n, np.uint16),
    )
    out = georeference(ret)
    pts = out.points
    bottom = pts.select(pts.kind == 2)
    np.testing.assert_array_equal(bottom.classification == 2, land)  # ground exactly on land
    assert np.all(bottom.classification[~land] == 40)

    origin = (400_000.0, 6_000_000.0, 0.0)
    grid = grid_seabed(pts, 5.0, origin_m=origin, crs=32632)
    rep = evaluate(pts, uncorrected=out.uncorrected, grid=grid, truth_z_m=seabed_z)
    # timing noise 0.1 ns per return -> sqrt(2) * 0.1 ns * c / (2 n_g) = 1.6 cm in water;
    # navigation noise 1 cm mostly cancels (surface and bottom move together)
    assert abs(rep.points.bias_m) < 0.003 and rep.points.rmse_m < 0.03
    # uncorrected: depth too large by ~ n_g cos(theta) / (n_air cos(theta_w)) - 1 = 33 %
    assert 0.3 < rep.points_uncorrected.bias_m / 9.0 < 0.4
    # cell mean vs truth at the centre: on a 10 % slope the points' mean x sits off the centre
    # (0.2 m typical for ~40 points in 5 m, metres in the part-covered cells at x = 130)
    assert abs(rep.grid.bias_m) < 0.01 and rep.grid.rmse_m < 0.08
    assert {r.order: r.meets for r in rep.iho_grid}["exclusive"]

    laz = write_points_laz(tmp_path / "points.laz", pts, crs=32632, origin_m=origin)
    back = read_points_laz(laz).points
    np.testing.assert_array_equal(back.classification, pts.classification)
    tif = read_grid_tif(write_grid_tif(tmp_path / "grid.tif", grid))
    np.testing.assert_allclose(tif.bands["depth_m"], grid.depth_m, rtol=2**-23, equal_nan=True)
