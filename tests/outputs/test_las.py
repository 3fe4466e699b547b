"""points.laz round trip with UTM-sized coordinates."""

import laspy
import numpy as np
import pyproj
import pytest

from pipeline.outputs.las import read_points_laz, write_points_laz
from pipeline.process.returns import PointFlag, Points

ORIGIN = (512_345.678, 5_432_109.876, 12.5)  # deliberately not whole metres


def sample_points(n=500, amplitude=True, seed=0):
    rng = np.random.default_rng(seed)
    xyz = np.column_stack(
        [rng.uniform(-800, 800, n), rng.uniform(-800, 800, n), rng.uniform(-40, 5, n)]
    )
    flags = np.where(rng.random(n) < 0.1, PointFlag.SYNTHETIC, 0).astype(np.uint16)
    return Points(
        pulse_id=rng.integers(0, 2**40, n),
        xyz_m=xyz,
        depth_m=-xyz[:, 2] + rng.normal(0, 0.01, n),
        classification=rng.choice(np.array([1, 2, 7, 18, 40, 41, 42], np.uint8), n),
        kind=rng.integers(1, 4, n).astype(np.uint8),
        flags=flags | rng.integers(0, 2, n).astype(np.uint16),
        detector_flags=rng.integers(0, 64, n).astype(np.uint16),
        return_number=np.ones(n, np.uint8) + (rng.random(n) < 0.5),
        number_of_returns=np.full(n, 2, np.uint8),
        confidence=rng.random(n),
        uncertainty_v_m=rng.uniform(0, 0.5, n),
        uncertainty_h_m=rng.uniform(0, 1.0, n),
        amplitude=rng.uniform(0, 1000, n) if amplitude else None,
    )


def test_round_trip(tmp_path):
    pts = sample_points()
    path = write_points_laz(tmp_path / "points.laz", pts, crs=32633, origin_m=ORIGIN)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["points.laz"]  # no temp left
    back = read_points_laz(path)
    # compound: the horizontal CRS given + the local vertical frame of z
    assert back.crs.is_compound and back.crs.sub_crs_list[0] == pyproj.CRS.from_epsg(32633)
    np.testing.assert_array_equal(back.origin_m, ORIGIN)
    np.testing.assert_array_equal(back.offsets, np.round(ORIGIN))
    q = back.points
    np.testing.assert_array_equal(q.classification, pts.classification)
    np.testing.assert_array_equal(q.pulse_id, pts.pulse_id)
    np.testing.assert_array_equal(q.kind, pts.kind)
    np.testing.assert_array_equal(q.flags, pts.flags)
    np.testing.assert_array_equal(q.detector_flags, pts.detector_flags)
    # one point per (random, 40-bit) pulse: "1 of 1" whatever numbering the points came with
    assert np.unique(pts.pulse_id).size == len(pts)
    np.testing.assert_array_equal(q.return_number, 1)
    np.testing.assert_array_equal(q.number_of_returns, 1)
    # quantisation: half a millimetre, plus float64 rounding of world = local + origin
    assert np.max(np.abs(q.xyz_m - pts.xyz_m)) <= 0.0005 + 1e-8
    np.testing.assert_array_equal(q.depth_m, pts.depth_m)  # stored as f8
    for name in ("uncertainty_v_m", "uncertainty_h_m", "confidence", "amplitude"):
        # stored as f4: relative rounding 2**-24
        np.testing.assert_allclose(getattr(q, name), getattr(pts, name), rtol=2**-23, atol=0)


def test_laz_header(tmp_path):
    pts = sample_points(amplitude=False)
    path = write_points_laz(tmp_path / "points.laz", pts, crs=32633, origin_m=ORIGIN)
    with laspy.open(path) as f:
        hdr = f.header
        assert f.header.are_points_compressed
    assert str(hdr.version) == "1.4" and hdr.point_format.id == 6
    assert hdr.global_encoding.wkt
    np.testing.assert_array_equal(hdr.scales, [0.001] * 3)
    las = laspy.read(path)
    # synthetic: flagged by processing, or a derived surface point (kind 3); no class 45 here
    assert 45 not in pts.classification
    np.testing.assert_array_equal(
        np.asarray(las.synthetic, bool), ((pts.flags & PointFlag.SYNTHETIC) != 0) | (pts.kind == 3)
    )
    assert "amplitude" not in las.point_format.extra_dimension_names
    assert read_points_laz(path).points.amplitude is None


@pytest.mark.parametrize("name, compress", [("a.laz", False), ("b.las", True), ("c.las", None)])
def test_compress_is_honoured_whatever_the_suffix(tmp_path, name, compress):
    pts = sample_points()
    path = write_points_laz(tmp_path / name, pts, crs=32633, origin_m=ORIGIN, compress=compress)
    with laspy.open(path) as f:
        assert f.header.are_points_compressed == bool(compress)
    np.testing.assert_array_equal(read_points_laz(path).points.pulse_id, pts.pulse_id)


def test_too_far_for_int32(tmp_path):
    pts = sample_points(n=3)
    with pytest.raises(ValueError, match="int32"):
        # 800 m / 1e-7 m > 2**31
        write_points_laz(tmp_path / "p.laz", pts, crs=32633, origin_m=ORIGIN, scale_m=1e-7)
    assert list(tmp_path.iterdir()) == []


def test_classification_lookup_names_the_classes_present(tmp_path):
    # water column (64, user-definable: LAS 1.4 has no water-column class) and the bathy classes
    pts = sample_points(n=300, amplitude=False)
    cls = np.asarray(pts.classification).copy()
    cls[:50] = 64
    cls[50:60] = 45
    pts = pts.replace(classification=cls)
    path = write_points_laz(tmp_path / "points.laz", pts, crs=32633, origin_m=ORIGIN)
    las = laspy.read(path)
    (vlr,) = las.header.vlrs.get("ClassificationLookupVlr")
    assert vlr.user_id == "LASF_Spec" and vlr.record_id == 0  # the LAS 1.4 record
    assert set(vlr.lookups) == set(np.unique(cls).tolist())
    assert vlr.lookups[64] == "water column"
    assert vlr.lookups[40] == "bathymetry" and vlr.lookups[41] == "water surface"
    assert vlr.lookups[45] == "no bottom found"
    back = read_points_laz(path)
    assert back.class_names[64] == "water column"
    np.testing.assert_array_equal(back.points.classification, cls)


def test_every_class_has_a_lookup_name_that_fits():
    from pipeline.outputs.las import LOOKUP_NAMES
    from pipeline.process.classify import CLASS_NAMES

    assert set(CLASS_NAMES) <= set(LOOKUP_NAMES)
    for name in LOOKUP_NAMES.values():
        # 15 bytes in the record; laspy drops anything but letters, digits and spaces
        assert len(name.encode("ascii")) <= 15
        assert all(ch.isalnum() or ch == " " for ch in name)
