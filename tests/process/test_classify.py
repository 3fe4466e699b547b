"""Classification rules, one hand-made point per rule."""

import numpy as np
import pytest

from pipeline.process.classify import (
    BATHYMETRIC_POINT,
    DERIVED_WATER_SURFACE,
    GROUND,
    HIGH_NOISE,
    LOW_NOISE,
    UNCLASSIFIED,
    WATER_SURFACE,
    ClassifySettings,
    classify_points,
)
from pipeline.process.returns import DetectorFlag, PointFlag, Points, ReturnKind

B, S, D = ReturnKind.BOTTOM, ReturnKind.SURFACE, ReturnKind.DERIVED_SURFACE
# (kind, processing flags, detector flags, confidence, depth_m, number_of_returns, expected)
CASES = [
    (B, 0, 0, 0.9, 5.0, 2, BATHYMETRIC_POINT),
    (B, PointFlag.SURFACE_INTERPOLATED, 0, 0.9, 5.0, 1, BATHYMETRIC_POINT),
    (B, PointFlag.GRAZING, 0, 0.9, 5.0, 2, UNCLASSIFIED),
    # saturated alone: the detector timed the clipped echo from its edges (detect_clipped)
    (B, 0, DetectorFlag.SATURATED, 0.9, 5.0, 2, BATHYMETRIC_POINT),
    (B, 0, DetectorFlag.SATURATED | DetectorFlag.CLIPPED_MERGED, 0.9, 5.0, 2, UNCLASSIFIED),
    (B, 0, DetectorFlag.MERGED, 0.9, 0.2, 2, UNCLASSIFIED),
    (B, 0, DetectorFlag.LOW_SNR, 0.9, 5.0, 2, BATHYMETRIC_POINT),
    (B, 0, 0, 0.2, 5.0, 2, LOW_NOISE),
    (B, PointFlag.LAND, 0, 0.9, -3.0, 2, GROUND),
    (B, PointFlag.LAND, 0, 0.1, -3.0, 2, LOW_NOISE),
    (B, PointFlag.ABOVE_SURFACE, 0, 0.9, -2.0, 1, HIGH_NOISE),
    (B, 0, 0, 0.9, -0.5, 2, HIGH_NOISE),
    (B, 0, 0, 0.9, 80.0, 2, LOW_NOISE),  # deeper than max_depth_m = 60
    (S, 0, 0, 0.9, 0.0, 2, WATER_SURFACE),
    (S, 0, DetectorFlag.SATURATED, 0.9, 0.0, 2, WATER_SURFACE),
    (S, 0, DetectorFlag.SATURATED | DetectorFlag.CLIPPED_MERGED, 0.9, 0.0, 1, UNCLASSIFIED),
    (S, 0, 0, 0.1, 0.0, 2, LOW_NOISE),
    (S, PointFlag.SURFACE_OUTLIER, 0, 0.9, -0.6, 2, HIGH_NOISE),
    (S, PointFlag.SURFACE_OUTLIER, 0, 0.9, 0.6, 2, LOW_NOISE),
    (S, PointFlag.LAND, 0, 0.9, -3.0, 1, GROUND),
    (S, PointFlag.LAND, 0, 0.9, -8.0, 2, UNCLASSIFIED),
    (S, PointFlag.GRAZING, 0, 0.9, 0.0, 1, UNCLASSIFIED),
    (D, PointFlag.SYNTHETIC, 0, 1.0, 0.0, 1, DERIVED_WATER_SURFACE),
]


def make(cases):
    n = len(cases)
    kind, flags, dflags, conf, depth, nret, _ = (np.array(c) for c in zip(*cases, strict=True))
    return Points(
        pulse_id=np.arange(n),
        xyz_m=np.column_stack([np.zeros(n), np.zeros(n), -depth]),
        depth_m=depth,
        classification=np.ones(n, np.uint8),
        kind=kind.astype(np.uint8),
        flags=flags.astype(np.uint16),
        detector_flags=dflags.astype(np.uint16),
        return_number=np.ones(n, np.uint8),
        number_of_returns=nret.astype(np.uint8),
        confidence=conf,
        uncertainty_v_m=np.zeros(n),
        uncertainty_h_m=np.zeros(n),
    )


def test_each_rule():
    out = classify_points(make(CASES), ClassifySettings(max_depth_m=60.0))
    expected = np.array([c[-1] for c in CASES], dtype=np.uint8)
    np.testing.assert_array_equal(out.classification, expected)


def test_settings_validate_flag_names():
    with pytest.raises(ValueError, match="unreliable_detector_flags"):
        ClassifySettings(unreliable_detector_flags=("SATURATD",))
    st = ClassifySettings(unreliable_detector_flags=())
    out = classify_points(make([CASES[3]]), st)
    assert out.classification[0] == BATHYMETRIC_POINT


def test_a_clipped_surface_merged_with_the_column_is_unclassified():
    # its time is only the plateau's leading edge, an early bound: not a water-surface point
    from pipeline.process.classify import classify_points
    from pipeline.process.returns import DetectorFlag, Points

    n = 4
    flags = np.array([0, DetectorFlag.SATURATED, DetectorFlag.CLIPPED_MERGED, 0], np.uint16)
    pts = Points(
        pulse_id=np.arange(n),
        xyz_m=np.zeros((n, 3)),
        depth_m=np.zeros(n),
        classification=np.ones(n, np.uint8),
        kind=np.ones(n, np.uint8),
        flags=np.zeros(n, np.uint16),
        detector_flags=flags | np.uint16(DetectorFlag.SATURATED) * (flags > 0),
        return_number=np.ones(n, np.uint8),
        number_of_returns=np.full(n, 2, np.uint8),
        confidence=np.ones(n),
        uncertainty_v_m=np.zeros(n),
        uncertainty_h_m=np.zeros(n),
    )
    # a saturated surface whose echo was timed from its plateau's edges stays water surface
    assert list(classify_points(pts).classification) == [41, 41, 1, 41]
