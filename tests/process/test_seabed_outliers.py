"""Gross seabed errors on hand-built soundings with known blunders and analytic seabeds."""

import math
from types import SimpleNamespace

import laspy
import numpy as np
import pytest

from pipeline.process.classify import BATHYMETRIC_POINT, LOW_NOISE, SUBMERGED_OBJECT
from pipeline.process.objects import ObjectSettings, classify_objects
from pipeline.process.returns import PointFlag, Points, ReturnKind
from pipeline.process.seabed_outliers import OutlierSettings, reject_seabed_outliers

LEVEL_M = 0.0  # the water level: depth = LEVEL_M - z


def seabed_z(x, y):
    """Analytic seabed: 10 m deep at the origin, a 5 % slope east, 2 % north."""
    return -10.0 - 0.05 * x + 0.02 * y


def cloud(rng, sigma_m=0.05, n=6400):
    """A 40 m x 40 m swath of soundings on the analytic seabed, each with TPU ``sigma_m``."""
    x, y = rng.uniform(-20, 20, n), rng.uniform(-20, 20, n)
    return x, y, seabed_z(x, y) + rng.normal(0.0, sigma_m, n), np.full(n, sigma_m)


def points(x, y, z, sigma_v):
    n = x.size
    return Points(
        pulse_id=np.arange(n),
        xyz_m=np.c_[x, y, z],
        depth_m=LEVEL_M - z,
        classification=np.full(n, BATHYMETRIC_POINT),
        kind=np.full(n, ReturnKind.BOTTOM),
        flags=np.zeros(n, np.uint16),
        detector_flags=np.zeros(n, np.uint16),
        return_number=np.ones(n, np.uint8),
        number_of_returns=np.ones(n, np.uint8),
        confidence=np.ones(n),
        uncertainty_v_m=sigma_v,
        uncertainty_h_m=np.full(n, 0.1),
    )


def has(p, flag):
    return (p.flags & np.uint16(flag)) != 0


def test_false_bottoms_below_the_seabed_are_rejected_and_kept_as_class_7():
    """Eight pulses met false bottoms 1.5-30 m below the seabed (after-pulses, noise past the
    bottom): all rejected; of 6400 good soundings (normal, 0.05 m) none is, since 5 sigma of a
    normal has a 3e-7 tail and 0.5 m is 10 sigma."""
    rng = np.random.default_rng(11)
    x, y, z, sig = cloud(rng)
    blunders = rng.choice(x.size, 8, replace=False)
    z[blunders] -= np.array([1.5, 2.0, 3.0, 5.0, 8.0, 12.0, 20.0, 30.0])
    out, counts = reject_seabed_outliers(points(x, y, z, sig), OutlierSettings(), ObjectSettings())
    rejected = has(out, PointFlag.SEABED_OUTLIER)
    assert set(np.flatnonzero(rejected)) == set(blunders)
    assert counts == {"tvu_exceeded": 0, "surface_implausible": 0, "seabed_outlier": 8}
    # not dropped: class 7, same position and depth
    assert np.all(out.classification[blunders] == LOW_NOISE)
    assert np.all(out.classification[~rejected] == BATHYMETRIC_POINT)
    np.testing.assert_array_equal(out.xyz_m, np.c_[x, y, z])


def test_small_deep_offsets_and_loose_soundings_stay():
    """0.3 m below the seabed is 6 sigma but under min_offset_m (0.5 m); 1.5 m below with a
    TPU of 0.35 m is 4.3 sigma: both are soundings, not blunders."""
    rng = np.random.default_rng(12)
    x, y, z, sig = cloud(rng)
    z[10] -= 0.3
    z[20] -= 1.5
    sig[20] = 0.35
    out, counts = reject_seabed_outliers(points(x, y, z, sig), OutlierSettings(), ObjectSettings())
    assert counts["seabed_outlier"] == 0
    assert out.classification[10] == out.classification[20] == BATHYMETRIC_POINT


def test_tpu_beyond_the_iho_order_is_rejected():
    """IHO S-44 Ed. 6 order 2 at 10 m allows TVU sqrt(1 + (0.023 * 10)^2) = 1.026 m at 95 %:
    a sounding of sigma 0.53 m (1.96 sigma = 1.039 m) fails it, one of 0.52 m (1.019 m)
    meets it; order 1a (sqrt(0.25 + 0.13^2) = 0.517 m) takes sigma 0.26 m but not 0.27 m."""
    tvu2 = math.sqrt(1.0 + (0.023 * 10.0) ** 2)
    assert 1.96 * 0.52 < tvu2 < 1.96 * 0.53
    x = np.array([0.0, 1.0, 2.0, 3.0])
    y = np.zeros(4)
    z = np.full(4, -10.0)
    sig = np.array([0.26, 0.27, 0.52, 0.53])
    out, counts = reject_seabed_outliers(points(x, y, z, sig), OutlierSettings(), ObjectSettings())
    assert has(out, PointFlag.TVU_EXCEEDED).tolist() == [False, False, False, True]
    assert out.classification.tolist() == [40, 40, 40, 7]
    assert counts["tvu_exceeded"] == 1
    out, _ = reject_seabed_outliers(
        points(x, y, z, sig), OutlierSettings(max_order="1a"), ObjectSettings()
    )
    assert has(out, PointFlag.TVU_EXCEEDED).tolist() == [False, True, True, True]
    out, _ = reject_seabed_outliers(
        points(x, y, z, sig), OutlierSettings(max_order="off"), ObjectSettings()
    )
    assert not has(out, PointFlag.TVU_EXCEEDED).any()


def test_depth_read_on_an_extrapolated_water_plane_is_rejected():
    """Water-surface returns between -1.2 and +1.3 m (a wave field) and 400 soundings on the
    analytic seabed whose depth is read on their local plane. Four planes were extrapolated
    (a tilted fit at a swath edge): their height at the point is +4.0, +1.6, -1.5 and +1.54 m,
    so the depths are 4.0, 1.6, -1.5 and 1.54 m off while the elevations are right. The
    envelope is [-1.2, 1.3] m; with the 0.25 m margin +4.0, +1.6 and -1.5 are out, +1.54
    (0.24 m beyond) stays; a plane at +1.3 m (inside) is a wave crest, kept."""
    rng = np.random.default_rng(15)
    x, y, z, sig = cloud(rng, n=400)
    plane = rng.uniform(-0.8, 0.8, x.size)  # the local planes at the points: inside
    plane[:5] = [4.0, 1.6, -1.5, 1.54, 1.3]
    bottoms = points(x, y, z, sig).replace(depth_m=plane - z)
    ns = 50
    xs, ys = rng.uniform(-20, 20, ns), rng.uniform(-20, 20, ns)
    zs = np.r_[-1.2, 1.3, rng.uniform(-1.0, 1.0, ns - 2)]
    surf = points(xs, ys, zs, np.full(ns, 0.05)).replace(
        classification=np.full(ns, 41, np.uint8),
        kind=np.full(ns, ReturnKind.SURFACE, np.uint8),
        depth_m=np.zeros(ns),
    )
    pts = Points.concatenate([bottoms, surf])
    out, counts = reject_seabed_outliers(pts, OutlierSettings(), ObjectSettings())
    assert np.flatnonzero(has(out, PointFlag.SURFACE_IMPLAUSIBLE)).tolist() == [0, 1, 2]
    assert counts["surface_implausible"] == 3 and counts["seabed_outlier"] == 0
    assert np.all(out.classification[:3] == LOW_NOISE)
    assert np.all(out.classification[3:400] == BATHYMETRIC_POINT)
    assert np.all(out.classification[400:] == 41)  # the surface returns are not tested


def test_cubes_are_objects_not_blunders():
    """0.5, 1 and 2 m cubes standing on the seabed: class 43 by the object test, and neither
    their points nor the seabed around them are rejected (a cube is above the seabed; the
    test looks below it, and leaves class 43 alone)."""
    rng = np.random.default_rng(13)
    x, y, z, sig = cloud(rng)
    top = np.zeros(x.size, bool)
    for cx, cy, s in ((-10.0, 5.0, 0.5), (0.0, -8.0, 1.0), (10.0, 10.0, 2.0)):
        on = (np.abs(x - cx) <= 0.5 * s) & (np.abs(y - cy) <= 0.5 * s)
        z[on] += s
        top |= on
    blunder = int(np.flatnonzero(~top)[0])
    z[blunder] -= 3.0
    pts, _ = classify_objects(points(x, y, z, sig), ObjectSettings())
    assert (pts.classification[top] == SUBMERGED_OBJECT).mean() >= 0.9
    out, counts = reject_seabed_outliers(pts, OutlierSettings(), ObjectSettings())
    assert np.flatnonzero(out.classification == LOW_NOISE).tolist() == [blunder]
    np.testing.assert_array_equal(out.classification[top], pts.classification[top])


def test_threshold_not_below_the_object_test():
    pts = points(np.zeros(1), np.zeros(1), np.full(1, -10.0), np.full(1, 0.05))
    with pytest.raises(ValueError, match="objects.k_sigma"):
        reject_seabed_outliers(pts, OutlierSettings(k_sigma=3.0), ObjectSettings())


def test_rejected_points_are_withheld_in_the_las_file(tmp_path):
    from pipeline.outputs.las import write_points_laz

    rng = np.random.default_rng(14)
    x, y, z, sig = cloud(rng, n=400)
    z[5] -= 4.0
    sig[7] = 2.0  # TVU beyond order 2
    out, counts = reject_seabed_outliers(points(x, y, z, sig), OutlierSettings(), ObjectSettings())
    assert counts == {"tvu_exceeded": 1, "surface_implausible": 0, "seabed_outlier": 1}
    path = write_points_laz(tmp_path / "p.laz", out, crs="EPSG:32631")
    las = laspy.read(path)
    assert np.flatnonzero(np.asarray(las.withheld)).tolist() == [5, 7]
    assert np.asarray(las.classification)[[5, 7]].tolist() == [7, 7]


def test_extinction_depth_summary_is_the_class_45_depths():
    """21 class-45 points at 10.0, 10.5, ... 20.0 m (and class-40 points deeper, which do not
    count): the survey's extinction depth is their median, 15 m; 5th/95th percentiles by
    linear interpolation at ranks 1 and 19: 10.5 and 19.5 m."""
    from pipeline.process.no_bottom import extinction_depth_summary

    d45 = np.arange(21) * 0.5 + 10.0
    d = np.r_[d45, [30.0, 40.0]]
    p = points(np.zeros(d.size), np.zeros(d.size), -d, np.full(d.size, 0.1))
    cls = np.r_[np.full(21, 45), [40, 40]].astype(np.uint8)
    s = extinction_depth_summary(p.replace(classification=cls))
    assert s == {
        "class45_points": 21,
        "class45_depth_m_p05": pytest.approx(10.5),
        "class45_depth_m_median": pytest.approx(15.0),
        "class45_depth_m_p95": pytest.approx(19.5),
        # the seabed was found at 30 and 40 m: limits shallower than the median sounding
        # (35 m) are local losses, so the survey did not reach its extinction depth
        "seabed_found_to_m": pytest.approx(39.5),
        "extinction_depth_m": None,
        "extinction_depth_source": "not_reached",
    }
    assert extinction_depth_summary(p)["class45_depth_m_median"] is None


def test_a_tested_subset_is_rejected_as_when_all_points_are_tested():
    """A block of a survey tests only the points whose class it keeps: every class-40 point
    is still a reference of their planes, so a tested point's flags are those of the test of
    all; the others are not tested by rule 3 (rules 1 and 2 test every point)."""
    rng = np.random.default_rng(23)
    x, y, z, sig = cloud(rng)
    blunders = rng.choice(x.size, 40, replace=False)
    z[blunders] -= rng.uniform(1.5, 10.0, blunders.size)
    sig[rng.choice(x.size, 20, replace=False)] = 5.0  # beyond order 2's TVU: rule 1
    pts = points(x, y, z, sig)
    whole, _ = reject_seabed_outliers(pts, OutlierSettings(), ObjectSettings())
    tested = x < 3.0
    got, counts = reject_seabed_outliers(pts, OutlierSettings(), ObjectSettings(), tested=tested)
    np.testing.assert_array_equal(got.flags[tested], whole.flags[tested])
    np.testing.assert_array_equal(got.classification[tested], whole.classification[tested])
    assert has(got, PointFlag.SEABED_OUTLIER)[tested].any()
    assert not has(got, PointFlag.SEABED_OUTLIER)[~tested].any()
    assert counts["tvu_exceeded"] == int(np.count_nonzero(has(whole, PointFlag.TVU_EXCEEDED)))


def test_a_block_tests_its_points_and_those_their_rejection_reads():
    """The chain a block of a survey cuts (``pipeline.survey_cleanup``): a kept point's
    rejection plane reads which neighbours within ``tests_reach_m`` are still class 40 (their
    class-43 test and TVU rule, their own TPU), and those read only positions. Tested at the
    kept points and within that reach of them, the kept points' classes, flags and the
    rejection's figures are those of every point tested (cubes and blunders across the
    block's edge); tested at the kept points alone, the figures are not."""
    from pipeline.process.seabed_outliers import seabed_outliers, tvu_exceeded
    from pipeline.survey_blocks import tests_reach_m

    rng = np.random.default_rng(29)
    x, y, z, sig = cloud(rng, n=9000)
    for cx, cy in ((5.0, 0.0), (-5.0, 8.0), (12.0, -6.0)):  # cubes of 1.5 m, on the edges
        z[(np.abs(x - cx) <= 0.75) & (np.abs(y - cy) <= 0.75)] += 1.0
    blunders = rng.choice(x.size, 60, replace=False)
    z[blunders] -= rng.uniform(0.8, 6.0, blunders.size)
    sig[rng.choice(x.size, 60, replace=False)] = 5.0
    pts = points(x, y, z, sig)
    obj, out = ObjectSettings(), OutlierSettings()

    def cleaned(tested):
        found, _ = classify_objects(pts, obj, tested)
        # the rejection's plane figures, as rule 3 makes them (no class 41: rule 2 keeps all)
        sea = (found.classification == BATHYMETRIC_POINT) & ~tvu_exceeded(
            found.depth_m, sig, out.max_order
        )
        h = np.full(x.size, np.nan)
        test = None if tested is None else tested[sea]
        _, h[sea], _ = seabed_outliers(np.c_[x, y][sea], z[sea], sig[sea], out, obj, test)
        return reject_seabed_outliers(found, out, obj, tested=tested)[0], h

    whole, h_whole = cleaned(None)
    kept = np.abs(x) <= 5.0  # the block: a strip
    reach = tests_reach_m(SimpleNamespace(objects=obj))
    block, h_block = cleaned(np.abs(x) <= 5.0 + reach)
    np.testing.assert_array_equal(block.classification[kept], whole.classification[kept])
    np.testing.assert_array_equal(block.flags[kept], whole.flags[kept])
    np.testing.assert_array_equal(h_block[kept], h_whole[kept])
    assert (whole.classification[kept] == SUBMERGED_OBJECT).any()
    assert has(whole, PointFlag.SEABED_OUTLIER)[kept].any()
    # the cube on the edge: untested, its points outside stay class 40 and enter the planes
    _, h_alone = cleaned(kept)
    assert not np.array_equal(h_alone[kept], h_whole[kept], equal_nan=True)


@pytest.mark.parametrize("tested_half", [False, True])
def test_the_objects_fits_are_read_again_only_where_they_are_the_same_fits(
    tested_half, monkeypatch
):
    """The far-below test reads the object test's planes (``classify_objects_fit``) where it
    tests the very points they fitted: its flags are those of fitting again, and the fit is
    made once. Where an object or a rule-1 point leaves the class-40 set, it fits again
    (the fit is then another one: a cube's points are no longer its neighbours)."""
    import pipeline.process.seabed_outliers as so
    from pipeline.process.objects import classify_objects_fit

    rng = np.random.default_rng(31)
    x, y, z, sig = cloud(rng)
    blunders = rng.choice(x.size, 30, replace=False)
    z[blunders] -= rng.uniform(1.0, 8.0, blunders.size)
    tested = (x < 4.0) if tested_half else None
    calls = []
    real = so.detect_objects
    monkeypatch.setattr(so, "detect_objects", lambda *a, **k: calls.append(1) or real(*a, **k))
    obj, out = ObjectSettings(), OutlierSettings()

    def both(pts):
        found, n_obj, fitted = classify_objects_fit(pts, obj, tested)
        calls.clear()
        again, c_again = reject_seabed_outliers(found, out, obj, tested=tested)
        fit_again = len(calls)
        calls.clear()
        read, c_read = reject_seabed_outliers(found, out, obj, tested=tested, fitted=fitted)
        np.testing.assert_array_equal(read.flags, again.flags)
        np.testing.assert_array_equal(read.classification, again.classification)
        assert c_read == c_again
        return n_obj, fit_again, len(calls), c_read

    n_obj, fit_again, fit_read, counts = both(points(x, y, z, sig))
    assert (n_obj, fit_again, fit_read) == (0, 1, 0)
    assert counts["seabed_outlier"] > 0
    # a cube: its points become class 43, so the far-below test fits the others again
    on = (np.abs(x - 2.0) <= 1.0) & (np.abs(y - 2.0) <= 1.0)
    z2 = z.copy()
    z2[on] += 2.0
    n_obj, fit_again, fit_read, _ = both(points(x, y, z2, sig))
    assert n_obj > 0 and (fit_again, fit_read) == (1, 1)
    # a point beyond order 2's TVU (rule 1) leaves the set too
    sig2 = sig.copy()
    sig2[5] = 5.0
    n_obj, fit_again, fit_read, counts = both(points(x, y, z, sig2))
    assert counts["tvu_exceeded"] == 1 and (n_obj, fit_read) == (0, 1)
    # fits of other settings or of other TPU are not read, though they are of the same rows
    pts = points(x, y, z, sig)
    _, _, fitted = classify_objects_fit(pts, ObjectSettings(neighbours=24), tested)
    sig3 = sig * 1.5
    _, _, fitted_sig = classify_objects_fit(points(x, y, z, sig3), obj, tested)
    for stale in (fitted, fitted_sig):
        calls.clear()
        got, _ = reject_seabed_outliers(pts, out, obj, tested=tested, fitted=stale)
        assert len(calls) == 1
        fresh, _ = reject_seabed_outliers(pts, out, obj, tested=tested)
        np.testing.assert_array_equal(got.flags, fresh.flags)
