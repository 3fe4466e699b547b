"""Submerged objects (class 43) on hand-built point clouds with analytic cubes."""

import numpy as np
import pytest

from pipeline.process.classify import BATHYMETRIC_POINT, SUBMERGED_OBJECT
from pipeline.process.objects import (
    ObjectSettings,
    classify_objects,
    detect_objects,
)
from pipeline.process.returns import ReturnKind


def seabed_z(x, y):
    """Analytic seabed: a 10 % slope east, 3 % north, 8 m deep at the origin."""
    return -8.0 - 0.10 * x + 0.03 * y


def on_cube(x, y, cx, cy, side):
    return (np.abs(x - cx) <= 0.5 * side) & (np.abs(y - cy) <= 0.5 * side)


def swath_cloud(rng, density_per_m2=4.0, sigma_m=0.05):
    """A 40 m x 40 m swath of soundings with three cubes (0.5, 1, 2 m) standing on the plane."""
    n = int(density_per_m2 * 1600)
    x, y = rng.uniform(-20, 20, n), rng.uniform(-20, 20, n)
    z = seabed_z(x, y) + rng.normal(0.0, sigma_m, n)
    cubes = ((-10.0, 5.0, 0.5), (0.0, -8.0, 1.0), (10.0, 10.0, 2.0))
    top = np.zeros(n, dtype=bool)
    for cx, cy, s in cubes:
        on = on_cube(x, y, cx, cy, s)
        z[on] += s  # the cube's top: its side above the seabed
        top |= on
    return x, y, z, np.full(n, sigma_m), cubes, top


def test_cubes_on_a_sloping_swath_are_found_and_the_seabed_is_not():
    rng = np.random.default_rng(5)
    x, y, z, sig, cubes, top = swath_cloud(rng)
    det = detect_objects(np.c_[x, y], z, sig)
    # every cube has points on its top, and (nearly) all of them stand out: 0.5 m is 10 sigma
    for cx, cy, s in cubes:
        on = on_cube(x, y, cx, cy, s)
        assert on.sum() >= 1
        assert det.is_object[on].mean() >= 0.9, s
        # the height above the seabed fit is the cube's side, to a few noise sigmas
        np.testing.assert_allclose(np.median(det.height_m[on]), s, atol=0.1)
    # the seabed itself: at 4 sigma a normal tail gives ~3e-5 of 6400 points, so none
    assert not det.is_object[~top].any()
    assert np.all(np.isfinite(det.height_m))


def test_rough_seabed_needs_more_height():
    """The fit's robust scale carries seabed relief the TPU does not: on a seabed with 0.3 m
    of relief a 0.5 m cube is within 4 sigma and not flagged, a 2 m cube still is."""
    rng = np.random.default_rng(6)
    x, y, z, sig, cubes, top = swath_cloud(rng, sigma_m=0.3)
    det = detect_objects(np.c_[x, y], z, np.full(x.size, 0.05))
    small, big = on_cube(x, y, -10.0, 5.0, 0.5), on_cube(x, y, 10.0, 10.0, 2.0)
    assert det.is_object[small].mean() < 0.1
    assert det.is_object[big].mean() >= 0.9
    # 4 sigma of a normal is 3e-5; the scale is itself estimated from 48 neighbours (its
    # MAD varies by ~10 %), which fattens the tail: well under 0.2 % of the seabed
    assert det.is_object[~top].mean() < 2e-3


def test_profiler_line_over_a_cube():
    """Collinear soundings (a profiler's line, 20 per metre) crossing a 1 m cube: the dense
    line's nearest points would all lie on the cube; the thinned reference set reaches the
    seabed either side."""
    y = np.arange(0.0, 60.0, 0.05)
    x = np.zeros_like(y)
    z = seabed_z(x, y) + np.random.default_rng(7).normal(0.0, 0.03, y.size)
    on = on_cube(x, y, 0.0, 30.0, 1.0)
    z[on] += 1.0
    det = detect_objects(np.c_[x, y], z, np.full(y.size, 0.03))
    assert det.is_object[on].mean() >= 0.9
    assert not det.is_object[~on].any()


def test_only_points_above_the_seabed():
    """A pit (points 1 m below the plane) is not an object: objects are shoal-side hazards."""
    rng = np.random.default_rng(8)
    x, y, z, sig, _, top = swath_cloud(rng)
    z = np.where(top, 2 * seabed_z(x, y) - z, z)  # the cubes mirrored into pits
    assert not detect_objects(np.c_[x, y], z, sig).is_object.any()


def test_classify_objects_sets_class_43_on_bottom_points_only():
    from types import SimpleNamespace

    rng = np.random.default_rng(9)
    x, y, z, sig, _, top = swath_cloud(rng)
    cls = np.full(x.size, BATHYMETRIC_POINT, dtype=np.uint8)
    kind = np.full(x.size, ReturnKind.BOTTOM, dtype=np.uint8)

    class Pts(SimpleNamespace):
        def replace(self, **kw):
            return Pts(**{**self.__dict__, **kw})

    pts = Pts(xyz_m=np.c_[x, y, z], classification=cls, kind=kind, uncertainty_v_m=sig)
    out, n = classify_objects(pts, ObjectSettings())
    assert n == int((out.classification == SUBMERGED_OBJECT).sum()) > 0
    assert set(np.flatnonzero(out.classification == SUBMERGED_OBJECT)) <= set(np.flatnonzero(top))
    off, n_off = classify_objects(pts, ObjectSettings(enabled=False))
    assert n_off == 0 and np.array_equal(off.classification, cls)


def test_settings_are_checked():
    with pytest.raises(ValueError):
        ObjectSettings(neighbours=8, min_neighbours=16)


def test_blocks_of_points_give_the_same_detections_as_all_at_once(monkeypatch):
    import pipeline.process.objects as objects
    from pipeline.parallel import stage_threads

    rng = np.random.default_rng(11)
    x, y, z, sig, _, _ = swath_cloud(rng)
    whole = detect_objects(np.c_[x, y], z, sig)
    monkeypatch.setattr(objects, "_BLOCK_ROWS", 97)  # a prime: blocks cut anywhere
    blocks = detect_objects(np.c_[x, y], z, sig)
    with stage_threads(3):  # and the blocks side by side on threads, finishing in any order
        threaded = detect_objects(np.c_[x, y], z, sig)
    assert x.size > 50 * 97
    for got in (blocks, threaded):
        np.testing.assert_array_equal(got.is_object, whole.is_object)
        np.testing.assert_array_equal(got.height_m, whole.height_m)
        np.testing.assert_array_equal(got.sigma_m, whole.sigma_m)


def _brute_force_test(xy, z, sig, settings, i):
    """The module docstring's test of point ``i``, one point at a time with numpy's own tools.

    Neighbours by distance over every reference point (no k-d tree), ``np.median`` and a
    weighted ``np.linalg.lstsq`` (the same ridge rows) in each reweighting: an independent
    reading of the method, not the kernel's code.
    """
    from pipeline.process.objects import _reference

    ref = _reference(xy, z, settings.reference_cell_m)
    d = np.hypot(*(xy[ref] - xy[i]).T)
    near = np.argsort(d, kind="stable")[: settings.neighbours]
    j = ref[near[d[near] <= settings.radius_m]]
    if j.size < settings.min_neighbours:
        return False, np.nan, np.nan
    dx, dy, dz = xy[j, 0] - xy[i, 0], xy[j, 1] - xy[i, 1], z[j] - z[i]
    a, b, c = np.median(dz), 0.0, 0.0
    scale = 1.4826 * np.median(np.abs(dz - a))
    for _ in range(settings.iterations):
        scale = max(scale, settings.min_scale_m)
        u = (dz - (a + b * dx + c * dy)) / (4.685 * scale)
        w = np.where(np.abs(u) < 1.0, (1.0 - u * u) ** 2, 0.0)
        ridge = 1e-6 * (np.sum(w * dx * dx) + np.sum(w * dy * dy)) + 1e-12
        rows = np.sqrt(w)[:, None] * np.c_[np.ones_like(dx), dx, dy]
        design = np.vstack([rows, np.diag(np.sqrt([1e-12, ridge, ridge]))])
        rhs = np.concatenate([np.sqrt(w) * dz, np.zeros(3)])
        a, b, c = np.linalg.lstsq(design, rhs, rcond=None)[0]
        scale = 1.4826 * np.median(np.abs(dz - (a + b * dx + c * dy)))
    m = max(j.size, 4)
    scale = max(scale * np.sqrt(m / (m - 3.0)), settings.min_scale_m)
    sigma = np.sqrt(sig[i] ** 2 + scale**2 * (1.0 + 1.0 / m))
    return bool(-a > settings.k_sigma * sigma and -a >= settings.min_height_m), -a, sigma


def test_the_compiled_test_is_the_method_point_by_point():
    # a cube's points (objects), its edges (partly in the neighbourhood), the seabed, a sparse
    # edge of the swath (few neighbours): every figure as the brute-force reading makes it
    rng = np.random.default_rng(5)
    x, y, z, sig, cubes, top = swath_cloud(rng, density_per_m2=3.0)
    settings = ObjectSettings()
    got = detect_objects(np.c_[x, y], z, sig, settings)
    edge = np.flatnonzero(np.abs(x) > 19.0)[:10]
    picks = np.concatenate([np.flatnonzero(top)[:30], rng.choice(x.size, 60, replace=False), edge])
    xy = np.c_[x, y]
    for i in picks:
        want_obj, want_h, want_s = _brute_force_test(xy, z, sig, settings, i)
        assert got.is_object[i] == want_obj, i
        np.testing.assert_allclose(got.height_m[i], want_h, rtol=1e-9, atol=1e-12, err_msg=str(i))
        np.testing.assert_allclose(got.sigma_m[i], want_s, rtol=1e-9, atol=1e-12, err_msg=str(i))
    assert got.is_object[picks].sum() >= 10 and (~got.is_object[picks]).sum() >= 50


def test_a_tested_subset_gets_the_figures_of_all_points_tested(monkeypatch):
    # a block of a survey tests only the points it keeps; every point stays a reference, so
    # a tested point's figures are those of the test of all (to the bit), in any block size
    import pipeline.process.objects as objects

    rng = np.random.default_rng(17)
    x, y, z, sig, _, top = swath_cloud(rng)
    xy = np.c_[x, y]
    whole = detect_objects(xy, z, sig)
    tested = (np.abs(x) < 6.0) | top  # a strip, and every cube's top (found when tested)
    monkeypatch.setattr(objects, "_BLOCK_ROWS", 97)
    got = detect_objects(xy, z, sig, tested=tested)
    np.testing.assert_array_equal(got.is_object[tested], whole.is_object[tested])
    np.testing.assert_array_equal(got.height_m[tested], whole.height_m[tested])
    np.testing.assert_array_equal(got.sigma_m[tested], whole.sigma_m[tested])
    assert got.is_object[top].any() and not got.is_object[~tested].any()
    assert np.isnan(got.height_m[~tested]).all() and np.isnan(got.sigma_m[~tested]).all()
    none = detect_objects(xy, z, sig, tested=np.zeros(x.size, bool))
    assert not none.is_object.any() and np.isnan(none.height_m).all()
